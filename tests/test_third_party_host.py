"""A non-Python FMI host (tests/host/fmi2_host.c, compiled here) runs Traction.fmu with its
default parameters once the environment `railcosim fmu-env` prints is set (docs/third_party.md)."""
import os
import shutil
import subprocess
import zipfile
from pathlib import Path

import fmpy
import pytest
from fmpy import read_model_description

from orchestrator.hostenv import host_environment

HOST_SOURCE = Path(__file__).resolve().parent / "host" / "fmi2_host.c"


@pytest.fixture(scope="module")
def host_binary(tmp_path_factory):
    compiler = shutil.which("gcc") or shutil.which("cc")
    assert compiler, "a C compiler is part of this machine kind (docs/third_party.md)"
    binary = tmp_path_factory.mktemp("host") / "fmi2_host"
    headers = Path(fmpy.__file__).parent / "c-code"
    subprocess.run([compiler, "-O1", f"-I{headers}", "-o", str(binary), str(HOST_SOURCE), "-ldl"], check=True)
    return binary


def _run(host_binary, fmu: Path, workdir: Path, env):
    folder = workdir / "fmu"
    with zipfile.ZipFile(fmu) as archive:
        archive.extractall(folder)
    md = read_model_description(str(fmu))
    vr = {v.name: str(v.valueReference) for v in md.modelVariables}
    binary = folder / "binaries" / "linux64" / f"{md.coSimulation.modelIdentifier}.so"
    return subprocess.run([str(host_binary), str(binary), (folder / "resources").as_uri(), md.guid, "60", "0.5",
                           vr["command"], "1.0", vr["x"], vr["v"]],
                          capture_output=True, text=True, env=env, timeout=120, cwd=workdir)


def test_traction_fmu_in_a_c_host_with_fmu_env(tmp_path, host_binary, product_fmus):
    env = {k: v for k, v in os.environ.items() if k not in ("LD_PRELOAD", "PYTHONHOME", "PYTHONPATH")}
    env.update(host_environment())
    proc = _run(host_binary, product_fmus / "Traction.fmu", tmp_path, env)
    assert proc.returncode == 0, proc.stderr[-800:]
    x, v = (float(line.split()[1]) for line in proc.stdout.split("\n") if line.strip())
    assert x > 900.0 and 15.0 < v < 25.0    # a minute of full traction from station A


def test_without_libpython_preloaded_the_host_cannot_load_the_fmu(tmp_path, host_binary, product_fmus):
    env = {k: v for k, v in os.environ.items() if k not in ("LD_PRELOAD", "PYTHONHOME", "PYTHONPATH")}
    proc = _run(host_binary, product_fmus / "Traction.fmu", tmp_path, env)
    assert proc.returncode != 0 and "undefined symbol" in proc.stderr

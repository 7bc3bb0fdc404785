"""The wheel: `pip install` of it (not editable) builds and runs a shipped system.

The wheel is built from a copy of the source (setuptools leaves build/lib and *.egg-info
behind, and a stale build/lib would leak into the next wheel), with pip's usual isolated build.
It is installed into a fresh virtual environment that sees the site-packages of the environment
running the tests (numpy, scipy … are not downloaded again), whether that is a virtual
environment or a system Python, and used from an empty folder, so nothing can be imported from
the checkout. About 25 s, most of it the five FMU builds.
"""
import json
import os
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent
PACKAGES = ("fmus", "orchestrator")


def _run(command, cwd: Path, env=None):
    done = subprocess.run([str(c) for c in command], cwd=cwd, env=env, capture_output=True, text=True)
    assert done.returncode == 0, f"{' '.join(map(str, command))}:\n{done.stdout}\n{done.stderr}"
    return done.stdout


def _source_files():
    """Files of the two packages as they are in the work tree (what `pip install .` reads)."""
    return sorted(p.relative_to(REPO).as_posix() for package in PACKAGES for p in (REPO / package).rglob("*")
                  if p.is_file() and "__pycache__" not in p.parts and p.suffix != ".pyc")


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> Path:
    source = tmp_path_factory.mktemp("source")
    for name in ("pyproject.toml", "README.md"):
        shutil.copy2(REPO / name, source / name)
    for package in PACKAGES:
        shutil.copytree(REPO / package, source / package, ignore=shutil.ignore_patterns("__pycache__"))
    out = tmp_path_factory.mktemp("wheel")
    _run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--quiet", "-w", out, source], cwd=out)
    (built,) = out.glob("railcosim-*.whl")
    return built


def test_wheel_holds_the_two_packages_with_all_their_data(wheel):
    with zipfile.ZipFile(wheel) as archive:
        names = set(archive.namelist())
    assert {name.split("/")[0] for name in names if ".dist-info/" not in name} == set(PACKAGES)
    missing = [name for name in _source_files() if name not in names]
    assert not missing, f"not in the wheel: {missing}"
    for data in ("fmus/data/schemas/line.schema.json", "fmus/data/shipped/default_line.json",
                 "fmus/signalling/alsn_codes.json", "fmus/traction/contract.json",
                 "orchestrator/packaging/builder.py"):
        assert data in names


def _running_site_packages():
    """The folders the running interpreter imports installed packages from: a virtual
    environment's own site-packages (and its base's, with --system-site-packages), a system
    Python's, the user's."""
    return [path for path in dict.fromkeys(sys.path) if Path(path).name in ("site-packages", "dist-packages")
            and Path(path).is_dir()]


def _fresh_venv_seeing_this_environment(venv: Path) -> Path:
    """A virtual environment whose own site-packages come first, then the running environment's.

    `python -m venv --system-site-packages` from a virtual environment's Python sees the base
    interpreter's site-packages, not the environment's (lxml and the rest missing): the running
    environment's folders are named in a .pth file instead. A .pth line only adds its folder to
    sys.path; the .pth files inside it (an editable install of this checkout) are not run, so
    the checkout stays out of reach."""
    _run([sys.executable, "-m", "venv", "--without-pip", venv], cwd=venv.parent)
    python = venv / "bin" / "python"
    own = _run([python, "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"], cwd=venv.parent).strip()
    (Path(own) / "_running_environment.pth").write_text("".join(f"{path}\n" for path in _running_site_packages()))
    return python


def test_installed_wheel_builds_and_runs_a_shipped_system(wheel, tmp_path):
    venv, work = tmp_path / "venv", tmp_path / "work"
    work.mkdir()
    python = _fresh_venv_seeing_this_environment(venv)
    _run([sys.executable, "-m", "pip", "--python", python, "install", "--quiet", "--no-deps", "--no-index",
          wheel], cwd=tmp_path)
    env = {key: value for key, value in os.environ.items() if key not in ("PYTHONPATH", "PYTHONHOME")}
    env["PATH"] = f"{venv / 'bin'}{os.pathsep}{env.get('PATH', '')}"

    where = _run([python, "-c", "import fmus, orchestrator, orchestrator.cli as cli; "
                  "print(fmus.__file__, orchestrator.__file__, cli.IN_CHECKOUT)"], cwd=work, env=env).split()
    assert all(Path(path).is_relative_to(venv) for path in where[:2]), where   # the wheel, not the checkout
    assert where[2] == "False"

    railcosim = venv / "bin" / "railcosim"
    _run([railcosim, "build"], cwd=work, env=env)
    assert sorted(p.name for p in (work / "build" / "fmus").glob("*.fmu")) == [
        "AtoController.fmu", "LocoReceiver.fmu", "RailLine.fmu", "Traction.fmu", "WaysideCoder.fmu"]
    assert (work / "build" / "ato_only.ssp").is_file() and (work / "build" / "free_run.ssp").is_file()

    _run([railcosim, "run", "ato_only"], cwd=work, env=env)   # finds the FMUs up to date
    summary = json.loads((work / "results" / "summary.json").read_text())
    assert summary["system"] == "ato_only"
    (train,) = summary["trains"]
    assert train["energy_kwh"] > 0 and any(s.get("arrival_deviation_s") is not None for s in train["stops"])

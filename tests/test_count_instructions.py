"""benchmarks/count_instructions.py (docs/performance.md#instructions-per-frame) run from a virtual
environment counts in that environment: valgrind runs the interpreter the script was started
with, so the environment's packages are the ones imported (it once ran the base interpreter the
environment's python links to, which does not see them)."""
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent
#: a line of a .pth file runs at every start of the environment's interpreter (site.py): it
#: notes the prefix each interpreter started from the environment runs in
PROBE = ("import os, sys; p = os.environ.get('RAILCOSIM_VENV_PROBE'); "
         "p and open(p, 'a').write(f'{os.getpid()} {sys.prefix}\\n')\n")


@pytest.mark.skipif(shutil.which("valgrind") is None,
                    reason="valgrind is not installed (apt-get install valgrind): count_instructions.py runs under it")
def test_instructions_are_counted_in_the_virtual_environment_the_script_runs_in(tmp_path):
    venv = tmp_path / "v"
    subprocess.run([sys.executable, "-m", "venv", "--system-site-packages", "--without-pip", str(venv)], check=True)
    python = venv / "bin" / "python"
    site = subprocess.run([python, "-c", "import site; print(site.getsitepackages()[0])"], capture_output=True,
                          text=True, check=True).stdout.strip()
    assert site.startswith(str(venv)), site
    Path(site, "railcosim_venv_probe.pth").write_text(PROBE)
    probe = tmp_path / "started.txt"
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONHOME", "VIRTUAL_ENV")}
    env.update(RAILCOSIM_VENV_PROBE=str(probe), PYTHONPATH=str(REPO))
    done = subprocess.run([python, REPO / "benchmarks" / "count_instructions.py", "--warm", "2", "--frames", "20"],
                          cwd=tmp_path, env=env, capture_output=True, text=True, timeout=900)
    assert done.returncode == 0, done.stderr[-3000:]
    assert "instructions per frame (20 frames after 2 s)" in done.stdout, done.stdout
    started = {tuple(line.split(" ", 1)) for line in probe.read_text().splitlines()}   # (pid, prefix)
    # the script itself, and the run valgrind counted: two interpreters, both in the environment
    # (the environment's site-packages is read twice, through lib and its link lib64: one pid twice)
    assert len({pid for pid, _ in started}) == 2 and {prefix for _, prefix in started} == {str(venv)}, started

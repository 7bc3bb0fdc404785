"""Small helpers the tests share: write a system, run it through the CLI entry point."""
import csv
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np

from orchestrator.sspgen import ComponentSpec, ConnectionSpec, frame_connections, write_ssd  # noqa: F401  (re-exported for the tests)

REPO = Path(__file__).resolve().parent.parent


def read_csv(path: Path):
    with open(path) as handle:
        rows = list(csv.reader(handle))
    header, data = rows[0], np.array(rows[1:], dtype=float) if len(rows) > 1 else np.zeros((0, len(rows[0])))
    return header, data


def cli_environment(**extra) -> dict:
    """The environment of a CLI subprocess: this checkout's orchestrator first on the path (not
    whichever copy is installed), plus ``extra`` (e.g. a private TMPDIR)."""
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(REPO)] + [p for p in env.get("PYTHONPATH", "").split(os.pathsep) if p])
    env.update({key: str(value) for key, value in extra.items()})
    return env


#: a run's progress on stderr without a terminal (``--progress lines``, orchestrator/observers.py
#: Progress): written every few seconds of a long run, before whatever ends it
PROGRESS_LINE = re.compile(r"^(t=[\d.]+/[\d.e+-]+ s  \d+%  elapsed |initialis(ing|ed) \d+ components?)")


def without_progress(stderr: str) -> str:
    """``stderr`` without the run's progress lines (a long run's failure comes after them)."""
    return "\n".join(line for line in stderr.splitlines() if not PROGRESS_LINE.match(line))


def railcosim(*args, cwd=None, env=None, **popen):
    """Run the CLI as a user does (this checkout's code); returns (exit code, stdout, stderr)."""
    proc = subprocess.run([sys.executable, "-m", "orchestrator", *map(str, args)], cwd=cwd,
                          env=cli_environment(**(env or {})), capture_output=True, text=True, timeout=600,
                          **popen)
    return proc.returncode, proc.stdout, proc.stderr

"""Small helpers the tests share: write a system, run it through the CLI entry point."""
import csv
import os
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


def railcosim(*args, cwd=None):
    """Run the CLI as a user does; returns (exit code, stdout, stderr). The CLI is this
    checkout's (its root first on PYTHONPATH), whatever checkout an editable install points at."""
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(filter(None, [str(REPO), os.environ.get("PYTHONPATH")])))
    proc = subprocess.run([sys.executable, "-m", "orchestrator", *map(str, args)], cwd=cwd,
                          capture_output=True, text=True, timeout=600, env=env)
    return proc.returncode, proc.stdout, proc.stderr

"""Run a small system N times as separate `railcosim run` processes and count abnormal exits.

pythonfmu 0.7.0 corrupts the heap at process exit unless its interpreter state is released
before exit (orchestrator/fmu.py FmuSlave.free). Before that fix ~9 % of runs of a two-FMU
process aborted with exit 134.

    python benchmarks/clean_exit.py [--runs 200]
"""
import argparse
import collections
import subprocess
import sys
import tempfile
from pathlib import Path

from _systems import trivial_system


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--runs", type=int, default=200)
    args = parser.parse_args()
    codes = collections.Counter()
    with tempfile.TemporaryDirectory() as tmp:
        folder = trivial_system(Path(tmp) / "sys", stop_time=0.2)
        for k in range(args.runs):
            proc = subprocess.run([sys.executable, "-m", "orchestrator", "run", str(folder), "--no-build",
                                   "--output", str(Path(tmp) / "out")], capture_output=True)
            codes[proc.returncode] += 1
    print(f"{args.runs} runs: exit codes {dict(codes)}")
    return 0 if set(codes) == {0} else 1


if __name__ == "__main__":
    sys.exit(main())

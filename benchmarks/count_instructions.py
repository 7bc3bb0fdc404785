"""Instructions per 10 ms frame of free_run, counted by valgrind (callgrind): a measure that,
unlike wall or CPU time, does not move with the machine's load, for comparing two versions or
the two modes on a shared machine.

    python benchmarks/count_instructions.py [--warm 20] [--frames 200] [--fmi] [--no-bulk]

Runs free_run under ``valgrind --tool=callgrind --instr-atstart=no`` (about 50 times slower
while counting, 5–10 times before), steps ``--warm`` seconds uncounted (the rail line's
model generation, the first cycles), switches counting on with ``callgrind_control`` for
``--frames`` frames and prints the instructions per frame. In process by default; ``--fmi``
through FMI (needs `railcosim build`), ``--no-bulk`` with the forwarding binary's bulk route
off (RAILCOSIM_NO_BULK=1, docs/performance.md).

The train of free_run stands at its first station until about 65 s: ``--warm 20`` counts a
standing train, ``--warm 150`` one running at about 22 m/s (most of the timetable).
"""
import argparse
import os
import re
import subprocess
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))   # `python benchmarks/X.py` from anywhere

COUNTING = "RAILCOSIM_COUNTING"


def counted_run(warm_s: float, stop_s: float, in_process: bool) -> None:
    """Inside valgrind: step free_run to ``warm_s`` uncounted, then to ``stop_s`` counted."""
    from orchestrator import master
    from benchmarks.harness.runs import scratch_run
    from orchestrator.cli import SSP_ROOT, _build_dir
    from orchestrator.graph import TICKS_PER_SECOND

    run_until = master.Master.run_until

    def counted(self, stop_ticks):
        run_until(self, round(warm_s * TICKS_PER_SECOND))
        subprocess.run(["callgrind_control", "-i", "on", str(os.getpid())], capture_output=True, check=True)
        run_until(self, stop_ticks)
        subprocess.run(["callgrind_control", "-i", "off", str(os.getpid())], capture_output=True, check=True)

    master.Master.run_until = counted
    scratch_run(SSP_ROOT / "free_run", in_process, [_build_dir()], stop_s)


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--warm", type=float, default=20.0)
    parser.add_argument("--frames", type=int, default=200)
    parser.add_argument("--fmi", action="store_true")
    parser.add_argument("--no-bulk", action="store_true")
    args = parser.parse_args()
    stop_s = args.warm + args.frames * 0.01
    if os.environ.get(COUNTING):
        counted_run(args.warm, stop_s, not args.fmi)
        return
    env = dict(os.environ, **{COUNTING: "1"})
    if args.no_bulk:
        env["RAILCOSIM_NO_BULK"] = "1"
    with tempfile.TemporaryDirectory() as folder:
        out = Path(folder) / "callgrind.out"
        # the interpreter itself (a launcher script such as pyenv's would be what valgrind counts)
        subprocess.run(["valgrind", "--tool=callgrind", "--instr-atstart=no", f"--callgrind-out-file={out}",
                        os.path.realpath(sys.executable), *sys.argv], env=env, check=True,
                       stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        total = int(re.search(r"^totals:\s*(\d+)", out.read_text(), re.M).group(1))
    mode = "in process" if not args.fmi else ("through FMI" + (", bulk route off" if args.no_bulk else ""))
    print(f"free_run {mode}: {total / args.frames:,.0f} instructions per frame "
          f"({args.frames} frames after {args.warm:g} s)")


if __name__ == "__main__":
    main()

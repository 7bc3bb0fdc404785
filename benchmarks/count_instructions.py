"""Instructions per 10 ms frame of free_run, counted by valgrind (callgrind): a measure that,
unlike wall or CPU time, does not move with the machine's load, for comparing two versions or
the two modes on a shared machine.

    python benchmarks/count_instructions.py [--warm 20] [--frames 200] [--fmi] [--no-bulk] [--sample-by-sample]

Runs free_run under ``valgrind --tool=callgrind --instr-atstart=no`` (about 50 times slower
while counting, 5–10 times before), steps ``--warm`` seconds uncounted (the rail line's
model generation, the first cycles), switches counting on with ``callgrind_control`` for
``--frames`` frames and prints the instructions per frame. In process by default; ``--fmi``
through FMI (needs `railcosim build`), ``--no-bulk`` with the forwarding binary's bulk route
off (RAILCOSIM_NO_BULK=1, docs/performance.md). ``--sample-by-sample`` counts the build with
one sample per frame instead (bench_sample_by_sample.py's system: a frame is then one 0.25 ms
tick of coder, rail line and receiver; try ``--warm 2 --frames 2000``).

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


def counted_run(warm_s: float, stop_s: float, in_process: bool, sample_by_sample: bool) -> None:
    """Inside valgrind: step free_run to ``warm_s`` uncounted, then to ``stop_s`` counted."""
    from orchestrator import master
    from benchmarks._runs import scratch_run
    from orchestrator.cli import SSP_ROOT, _build_dir
    from orchestrator.graph import TICKS_PER_SECOND
    from orchestrator.protocols import Observer

    run_until = master.Master.run_until
    warm_ticks = round(warm_s * TICKS_PER_SECOND)

    class CountFromWarm(Observer):
        """Switches counting on after the tick that reaches ``warm_s``: one run_until, as a
        user's run makes (two calls would plan the master's steps twice)."""

        def after_tick(self, master_view, step):
            if step.tick == warm_ticks:
                subprocess.run(["callgrind_control", "-i", "on", str(os.getpid())], capture_output=True, check=True)

    def counted(self, stop_ticks):
        self.observers.append(CountFromWarm())
        run_until(self, stop_ticks)
        subprocess.run(["callgrind_control", "-i", "off", str(os.getpid())], capture_output=True, check=True)

    master.Master.run_until = counted
    if not sample_by_sample:
        scratch_run(SSP_ROOT / "free_run", in_process, [_build_dir()], stop_s)
        return
    from benchmarks.bench_sample_by_sample import REPO, sample_by_sample_system
    fmus = REPO / "build" / "fmus_n1"
    with tempfile.TemporaryDirectory() as folder:
        scratch_run(sample_by_sample_system(Path(folder), fmus), in_process, [fmus], stop_s)


def counted_interpreter(env: dict) -> str:
    """The interpreter valgrind runs: this one as it was started (``sys.executable``). In a
    virtual environment that is the environment's ``bin/python``, a link to the base
    interpreter: started by that name it finds the environment's pyvenv.cfg and its packages,
    where the link's target, the base interpreter, finds neither. An executable that is a script
    (a launcher) would be what valgrind counts instead: then the base interpreter is run, given
    this one's import path (the environment's packages included) in ``env``."""
    with open(sys.executable, "rb") as f:
        script = f.read(2) == b"#!"
    if not script:
        return sys.executable
    env["PYTHONPATH"] = os.pathsep.join(p for p in sys.path if p)
    return getattr(sys, "_base_executable", None) or os.path.realpath(sys.executable)


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--warm", type=float, default=20.0)
    parser.add_argument("--frames", type=int, default=200)
    parser.add_argument("--fmi", action="store_true")
    parser.add_argument("--no-bulk", action="store_true")
    parser.add_argument("--sample-by-sample", action="store_true", help="the N = 1 build (frame = one sample)")
    args = parser.parse_args()
    stop_s = args.warm + args.frames * (0.00025 if args.sample_by_sample else 0.01)
    if os.environ.get(COUNTING):
        counted_run(args.warm, stop_s, not args.fmi, args.sample_by_sample)
        return
    if args.sample_by_sample:                 # the N = 1 FMUs made (or found up to date) outside valgrind
        from benchmarks.bench_sample_by_sample import REPO
        from fmus.sizes import BuildConfig
        from orchestrator.packaging.builder import build_all
        build_all(REPO / "build" / "fmus_n1", BuildConfig(frame=1))
    env = dict(os.environ, **{COUNTING: "1"})
    if args.no_bulk:
        env["RAILCOSIM_NO_BULK"] = "1"
    with tempfile.TemporaryDirectory() as folder:
        out = Path(folder) / "callgrind.out"
        subprocess.run(["valgrind", "--tool=callgrind", "--instr-atstart=no", f"--callgrind-out-file={out}",
                        counted_interpreter(env), *sys.argv], env=env, check=True,
                       stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        total = int(re.search(r"^totals:\s*(\d+)", out.read_text(), re.M).group(1))
    mode = "in process" if not args.fmi else ("through FMI" + (", bulk route off" if args.no_bulk else ""))
    if args.sample_by_sample:
        mode += ", N = 1"
    print(f"free_run {mode}: {total / args.frames:,.0f} instructions per frame "
          f"({args.frames} frames after {args.warm:g} s)")


if __name__ == "__main__":
    main()

"""Count process exit codes: N runs of a non-Python FMI host per product FMU, and N runs of
`railcosim run` on a small two-FMU system (figures in docs/third_party.md and
docs/performance.md).

pythonfmu 0.7.0's own binary corrupts the heap at process exit unless its interpreter state is
released first (an abort in ~9 % of two-FMU orchestrator runs before that; SIGSEGV/SIGABRT in 37
of 50 FMU Compliance Checker runs). Our FMUs' forwarding binary releases it itself
(orchestrator/packaging/forwarder/), so neither host does anything pythonfmu-specific: the C host
(tests/host/fmi2_host.c) runs with no LD_PRELOAD, PYTHONHOME or PYTHONPATH set, a few steps at
each FMU's DefaultExperiment step.

    python benchmarks/clean_exit.py [--runs 200] [--fmus Traction,RailLine] [--no-orchestrator]
                                    [--no-host] [--cycles 1|2|2r]

Negative exit codes are signals (-6 SIGABRT, -11 SIGSEGV).
"""
import argparse
import collections
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from _systems import REPO, trivial_system

sys.path.insert(0, str(REPO / "tests"))
from test_third_party_host import PRODUCT, clean_environment, compile_host, host_arguments  # noqa: E402


def count(command, runs, env=None):
    codes = collections.Counter()
    began = time.perf_counter()
    for _ in range(runs):
        codes[subprocess.run(command, capture_output=True, env=env).returncode] += 1
    return dict(codes), (time.perf_counter() - began) / max(runs, 1)


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--runs", type=int, default=200)
    parser.add_argument("--fmus", default=",".join(PRODUCT), help="product FMUs for the C host")
    parser.add_argument("--cycles", default="1", help="instantiate/free cycles per host process (2r: reload)")
    parser.add_argument("--no-host", action="store_true")
    parser.add_argument("--no-orchestrator", action="store_true")
    args = parser.parse_args()
    if args.runs < 1:
        print(f"clean_exit.py: --runs {args.runs}: must be at least 1", file=sys.stderr)
        return 2
    from orchestrator.packaging.builder import build_all, default_build_dir

    unknown = [name for name in args.fmus.split(",") if name not in PRODUCT]
    if unknown:
        print(f"clean_exit.py: --fmus: unknown {', '.join(unknown)} (known: {', '.join(PRODUCT)})", file=sys.stderr)
        return 2
    clean = True
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        if not args.no_host:
            fmus = default_build_dir(REPO)
            build_all(fmus)
            host = compile_host(tmp)
            for name in args.fmus.split(","):
                arguments = host_arguments(fmus / f"{name}.fmu", tmp / name, args.cycles)
                codes, seconds = count([str(host), *arguments], args.runs, clean_environment())
                clean &= set(codes) == {0}
                print(f"C host, {name}: {args.runs} runs: exit codes {codes} ({seconds:.1f} s per run)", flush=True)
        if not args.no_orchestrator:
            folder = trivial_system(tmp / "sys", stop_time=0.2)
            codes, seconds = count([sys.executable, "-m", "orchestrator", "run", str(folder), "--no-build",
                                    "--output", str(tmp / "out")], args.runs)
            clean &= set(codes) == {0}
            print(f"railcosim run (two FMUs): {args.runs} runs: exit codes {codes} ({seconds:.1f} s per run)")
    return 0 if clean else 1


if __name__ == "__main__":
    sys.exit(main())

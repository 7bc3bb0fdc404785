"""Interrupt N consecutive `railcosim run` processes at a random instant and count what is left.

Each run gets SIGINT (or --signal TERM/HUP) at an instant drawn uniformly over the duration
of an uninterrupted run (measured first: start-up, loading, initialisation, stepping and
writing are all hit). All runs write into one results folder, as a user repeating a command
does. Counted: exit codes, whether summary.json is this run's (written after it started) and
says completed false with the signal, torn rows in results.csv, railcosim temp folders left
(each run has a private TMPDIR). docs/reliability.md quotes the figure.

    python benchmarks/interrupt_campaign.py [--runs 200] [--system ato_only] [--signal INT] [--seed 1]
"""
import argparse
import collections
import csv
import json
import os
import random
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent


def _command(system, out):
    return [sys.executable, "-m", "orchestrator", "run", system, "--no-build", "--output", str(out)]


def _environment(tmpdir):
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(REPO)] + [p for p in env.get("PYTHONPATH", "").split(os.pathsep) if p])
    env["TMPDIR"] = str(tmpdir)
    return env


def _before_command(code: int, signum: int, stderr: str) -> bool:
    """The signal came before `railcosim run` had installed its handlers: while the interpreter
    started (site's .pth files: a KeyboardInterrupt traceback with no railcosim frame, exit 1 or
    death by the signal) or while railcosim loaded (one line, exit 128 + n)."""
    if code == 128 + signum:
        return stderr.strip() in ("railcosim: interrupted",
                                  "railcosim: interrupted before the command started; nothing was written")
    return code in (1, -signum) and "orchestrator" not in stderr and (
        "KeyboardInterrupt" in stderr or not stderr.strip())


def _start_phase(code: int, stderr: str) -> str:
    return "railcosim loading (exit 130, one line)" if code > 1 else f"interpreter start-up (exit {code})"


def _torn_rows(path: Path) -> int:
    if not path.is_file():
        return 0
    with open(path, newline="") as handle:
        rows = list(csv.reader(handle))
    if not rows:
        return 1
    torn = 0
    for row in rows[1:]:
        try:
            if len(row) != len(rows[0]):
                raise ValueError
            [float(x) for x in row]
        except ValueError:
            torn += 1
    return torn


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--runs", type=int, default=200)
    parser.add_argument("--system", default="ato_only")
    parser.add_argument("--signal", default="INT", choices=["INT", "TERM", "HUP"])
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--min-instant", type=float, default=0.0)
    parser.add_argument("--max-instant", type=float, default=None,
                        help="draw the instants in 0..this many seconds (default: a whole run's duration)")
    args = parser.parse_args()
    signum = getattr(signal, f"SIG{args.signal}")
    rng = random.Random(args.seed)
    codes = collections.Counter()
    unusual = collections.Counter()            # last stderr line of exits other than 0 and 128+n
    own_summary = interrupted_summary = torn = leftovers = finished_first = before_start = 0
    starts = collections.Counter()
    began = time.monotonic()
    with tempfile.TemporaryDirectory() as work:
        work = Path(work)
        out = work / "out"
        durations = []
        for _ in range(2):                      # an uninterrupted run, for the instants' range
            t0 = time.monotonic()
            subprocess.run(_command(args.system, out), env=_environment(work), capture_output=True, check=True)
            durations.append(time.monotonic() - t0)
        duration = statistics.median(durations) if args.max_instant is None else args.max_instant
        for k in range(args.runs):
            tmpdir = work / f"tmp{k}"
            tmpdir.mkdir()
            instant = rng.uniform(args.min_instant, duration)
            started = time.time()
            proc = subprocess.Popen(_command(args.system, out), env=_environment(tmpdir),
                                    stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
            time.sleep(instant)
            if proc.poll() is None:
                proc.send_signal(signum)
            _, stderr = proc.communicate()
            summary_path = out / "summary.json"
            own = summary_path.is_file() and summary_path.stat().st_mtime >= started
            text = stderr.decode(errors="replace")
            lines = text.strip().splitlines()
            if not own and _before_command(proc.returncode, signum, text):
                before_start += 1           # still loading Python and railcosim: no run, nothing written
                starts[_start_phase(proc.returncode, text)] += 1
                run_started = False
            else:
                codes[proc.returncode] += 1
                run_started = True
            if run_started and proc.returncode not in (0, 128 + signum):
                unusual[f"{proc.returncode}: {lines[-1] if lines else '(no message)'}"] += 1
            elif run_started and not own:
                unusual[f"{proc.returncode} without summary: {lines[-1] if lines else '(no message)'}"] += 1
            if own:
                own_summary += 1
                summary = json.loads(summary_path.read_text())
                if summary.get("completed") is False and summary.get("interrupted") == f"SIG{args.signal}":
                    interrupted_summary += 1
                elif summary.get("completed") is True and proc.returncode == 0:
                    finished_first += 1
            torn += _torn_rows(out / "results.csv")
            left = list(tmpdir.iterdir())
            leftovers += len(left)
    wall = time.monotonic() - began
    print(f"{args.runs} runs of `railcosim run {args.system}` (FMI), SIG{args.signal} at a uniform instant in "
          f"{args.min_instant:g}-{duration:.1f} s: exit codes of the runs that had started {dict(sorted(codes.items()))}; this run's summary.json present "
          f"{own_summary}/{args.runs} (completed false + interrupted {interrupted_summary}, finished before the "
          f"signal {finished_first}; interrupted before the command started, nothing written: {before_start}); torn results rows {torn}; temp entries left {leftovers}; {wall / 60:.1f} min")
    for phase, count in starts.most_common():
        print(f"  {count} x before the command started, during {phase}")
    for line, count in unusual.most_common():
        print(f"  {count} x exit {line}")
    expected = 128 + signum
    ok = set(codes) <= {expected, 0} and own_summary + before_start == args.runs and torn == 0 and leftovers == 0
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())

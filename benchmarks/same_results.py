"""Fingerprints of every shipped system's results, for a refactoring that must not change them.

    python benchmarks/same_results.py record FILE [--fmi] [--stop-time S] [--only NAME ...]
    python benchmarks/same_results.py compare BEFORE AFTER

``record`` runs each shipped system (in process by default, ``--fmi`` through the built FMUs;
``--stop-time`` caps the long ones) into a scratch folder and writes, per system, the SHA-256
of results.csv and summary.json without its wall-clock keys (``wall_time_s``, ``realtime_factor``,
``real_time``: they move with the machine). ``compare`` prints every system whose
fingerprint differs and exits 1 if any does. How it was used: docs/architecture.md (the third
step's acceptance) and docs/changelog.md.
"""
from __future__ import annotations

import argparse
import hashlib
import json
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

#: summary keys that measure the machine, not the run
_WALL_WORDS = ("wall", "realtime", "real_time")


def _without_wall(value):
    """The summary without its wall-clock keys, and paths inside the checkout relative to it (a
    scenario's file: two checkouts of one commit must fingerprint alike)."""
    if isinstance(value, dict):
        return {k: _without_wall(v) for k, v in value.items()
                if not any(word in k.lower() for word in _WALL_WORDS)}
    if isinstance(value, list):
        return [_without_wall(v) for v in value]
    if isinstance(value, str) and value.startswith(str(ROOT)):
        return value[len(str(ROOT)):]
    return value


def fingerprint(run_dir: Path) -> dict:
    summary = json.loads((run_dir / "summary.json").read_text())
    summary.pop("output_dir", None)
    return {"results_csv": hashlib.sha256((run_dir / "results.csv").read_bytes()).hexdigest(),
            "summary": hashlib.sha256(json.dumps(_without_wall(summary), sort_keys=True).encode()).hexdigest()}


def record(out: Path, fmi: bool, stop_time: float | None, only: list[str]) -> None:
    from orchestrator.systems.shipped import SHIPPED
    names = only or list(SHIPPED)
    prints = {}
    with tempfile.TemporaryDirectory() as scratch:
        for name in names:
            run_dir = Path(scratch) / name
            cmd = [sys.executable, "-m", "orchestrator", "run", name, "--output", str(run_dir), "--no-build"]
            if not fmi:
                cmd.append("--in-process")
            if stop_time is not None:
                cmd += ["--stop-time", str(stop_time)]
            done = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True)
            if done.returncode not in (0, 3):     # 3: an unsafe verdict is still a result
                print(f"{name}: run failed ({done.returncode}): {done.stderr.strip()[-300:]}", file=sys.stderr)
                prints[name] = {"failed": done.returncode}
                continue
            prints[name] = fingerprint(run_dir)
            print(f"{name}: {prints[name]['results_csv'][:12]} {prints[name]['summary'][:12]}", flush=True)
    out.write_text(json.dumps(prints, indent=1, sort_keys=True) + "\n")


def compare(before: Path, after: Path) -> int:
    a, b = json.loads(before.read_text()), json.loads(after.read_text())
    differ = [name for name in sorted(set(a) | set(b)) if a.get(name) != b.get(name)]
    for name in differ:
        print(f"{name}: {a.get(name)} -> {b.get(name)}")
    print(f"{len(set(a) | set(b)) - len(differ)} systems the same, {len(differ)} differ")
    return 1 if differ else 0


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)
    rec = sub.add_parser("record")
    rec.add_argument("file", type=Path)
    rec.add_argument("--fmi", action="store_true")
    rec.add_argument("--stop-time", type=float)
    rec.add_argument("--only", nargs="*", default=[])
    cmp_ = sub.add_parser("compare")
    cmp_.add_argument("before", type=Path)
    cmp_.add_argument("after", type=Path)
    args = parser.parse_args()
    if args.command == "record":
        record(args.file, args.fmi, args.stop_time, args.only)
        return 0
    return compare(args.before, args.after)


if __name__ == "__main__":
    sys.exit(main())

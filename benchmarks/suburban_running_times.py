"""The fastest run of one ЭР2 EMU over the suburban line, stopping at every station, and the
running-time supplement of the shipped timetable over it (docs/rail_line.md#the-suburban-line).

    python benchmarks/suburban_running_times.py [--dwell 30]

The system is ``ato_only``'s (train + ATO, cab signal off: the ATP on line limits only) with the
ATO's ``flat_out`` strategy under a generous timetable (harness/suburban.py
``fastest_stage_times``): the train runs each stage as fast as the line allows, arrives early
and departs on time. Printed per stage, with the shipped timetable's scheduled running time
and its supplement over the fastest.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))   # `python benchmarks/X.py` from anywhere

from fmus.data.loader import DATA  # noqa: E402
from harness.suburban import SUBURBAN_TIMETABLE, fastest_stage_times  # noqa: E402
from orchestrator.packaging.builder import build_all, default_build_dir  # noqa: E402

def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--dwell", type=float, default=30.0)
    args = parser.parse_args()
    build_all(default_build_dir())
    stages = fastest_stage_times([default_build_dir()], args.dwell)
    shipped = json.loads((DATA / SUBURBAN_TIMETABLE).read_text())["stops"]
    total_fast = total_scheduled = 0.0
    for k, (origin, to, fastest) in enumerate(stages):
        scheduled = shipped[k + 1]["arrival_s"] - shipped[k]["departure_s"]
        total_fast, total_scheduled = total_fast + fastest, total_scheduled + scheduled
        print(f"{origin:>11} → {to:<11} fastest {fastest:6.1f} s  scheduled {scheduled:4.0f} s  "
              f"supplement {100 * (scheduled / fastest - 1):+5.1f} %")
    print(f"whole line: fastest {total_fast:.1f} s running, scheduled {total_scheduled:.0f} s: "
          f"supplement {100 * (total_scheduled / total_fast - 1):+.1f} %")


if __name__ == "__main__":
    main()

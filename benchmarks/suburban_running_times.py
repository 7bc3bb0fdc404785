"""The fastest run of one ЭР2 EMU over the suburban line, stopping at every station, and the
running-time supplement of the shipped timetable over it (docs/rail_line.md#the-suburban-line).

    python benchmarks/suburban_running_times.py [--dwell 30]

The system is ``ato_only``'s (train + ATO, cab signal off: the ATP on line limits only) with the
ATO's ``flat_out`` strategy under a generous timetable (every stage at 10 m/s plus a minute),
so the train runs each stage as fast as the line allows, arrives early and departs on time: a
stage's fastest running time is its arrival less the departure before it. Printed per stage,
with the shipped timetable's scheduled running time and its supplement over the fastest.
"""
from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))   # `python benchmarks/X.py` from anywhere

from benchmarks._runs import scratch_run  # noqa: E402
from fmus.data.loader import DATA  # noqa: E402
from orchestrator.analysis.systems import train_and_ato, write_ssd  # noqa: E402
from orchestrator.packaging.builder import build_all, default_build_dir  # noqa: E402

LINE, STOCK, TIMETABLE = "suburban_line.json", "emu_er2.json", "suburban_timetable.json"


def generous_timetable(line: dict, dwell_s: float) -> dict:
    stops, t, previous = [], 30.0, None
    for station in line["stations"]:
        if previous is None:
            stops.append({"station": station["name"], "departure_s": t})
        else:
            t += (station["stop_m"] - previous) / 10.0 + 60.0
            stops.append({"station": station["name"], "arrival_s": round(t), "departure_s": round(t + dwell_s)})
            t = round(t + dwell_s)
        previous = station["stop_m"]
    stops[-1].pop("departure_s")
    return {"train": "fastest run", "stops": stops}


def fastest_stage_times(dwell_s: float) -> list:
    """(from, to, fastest running time s) of each stage."""
    line = json.loads((DATA / LINE).read_text())
    timetable = generous_timetable(line, dwell_s)
    files = {"line_file": LINE, "rolling_stock_file": STOCK}
    with tempfile.TemporaryDirectory() as folder:
        folder = Path(folder)
        components, connections = train_and_ato(
            train_parameters={**files, "x0": float(line["stations"][0]["stop_m"])},
            ato_parameters={**files, "cab_signal": "off", "strategy": "flat_out", "timetable_file": "fastest.json"})
        (folder / "resources").mkdir()
        (folder / "resources" / "fastest.json").write_text(json.dumps(timetable))
        for name in (LINE, STOCK):
            (folder / "resources" / name).write_bytes((DATA / name).read_bytes())
        write_ssd(folder, "suburban_fastest", components, connections,
                  stop_time=timetable["stops"][-1]["arrival_s"] + 60.0)
        summary = scratch_run(folder, True, [default_build_dir()], record=None).summary
    reached = summary["trains"][0]["stops"]
    departures = [s.get("departure_s") for s in timetable["stops"]]
    stages = []
    for k, stop in enumerate(reached):
        if stop["arrival_s"] is None:
            raise SystemExit(f"{stop['station']} not reached in the fastest run")
        stages.append((timetable["stops"][k]["station"], stop["station"], stop["arrival_s"] - departures[k]))
    return stages


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--dwell", type=float, default=30.0)
    args = parser.parse_args()
    build_all(default_build_dir())
    stages = fastest_stage_times(args.dwell)
    shipped = json.loads((DATA / TIMETABLE).read_text())["stops"]
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

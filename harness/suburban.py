"""The suburban line's systems for the tests and benchmarks (docs/rail_line.md#the-suburban-line):
one ЭР2 EMU over the line to its timetable with the ALSN chain, and the fastest run of that
EMU stopping at every station (train + ATO without the signal chain), against which the
timetable's running-time supplement is set.
"""
from __future__ import annotations

import json
import tempfile
from pathlib import Path
from typing import List, Sequence, Tuple

from fmus.data.loader import DATA
from fmus.signalling import cab_systems
from fmus.sizes import BuildConfig
from harness.queued_trains import _write_json, sections_for
from orchestrator.systems.chain import (cab_settings, check_placements, signal_chain, stock_length_m, train_and_ato,
                                        write_ssd)
from orchestrator.verdicts.verdict import railway_verdicts
from orchestrator.run import RunOptions, run_system

SUBURBAN_LINE, SUBURBAN_TIMETABLE, EMU = "suburban_line.json", "suburban_timetable.json", "emu_er2.json"


def write_suburban_emu(folder: Path, stop_time_s: float, system: str = cab_systems.DEFAULT.name) -> Path:
    """One ЭР2 EMU over the suburban line to its timetable (every station), the ALSN chain on
    the line's 4-aspect block in a build of 32 sections; its SSD path."""
    line = json.loads((DATA / SUBURBAN_LINE).read_text())
    origin_m = float(line["stations"][0]["stop_m"])
    check_placements(line, [("train", origin_m, stock_length_m(EMU))])
    files = {"line_file": SUBURBAN_LINE, "rolling_stock_file": EMU}
    sizes = BuildConfig(sections=sections_for(line), trains=1)
    coder, rail, receiver, ato = cab_settings(system)
    components, connections = train_and_ato(
        train_parameters={**files, "x0": origin_m},
        ato_parameters={**ato, **files, "timetable_file": SUBURBAN_TIMETABLE})
    line_only = {"line_file": SUBURBAN_LINE}
    chain, links = signal_chain(sections=sizes.sections, fmu_folder=f"resources/{sizes.folder_name}",
                                coder={**coder, **line_only, "block_aspects": 4}, rail={**rail, **line_only},
                                receiver=receiver, stocks=[EMU])
    path = write_ssd(folder, "suburban_emu", chain + components, links + connections, stop_time=stop_time_s)
    for name in (SUBURBAN_LINE, SUBURBAN_TIMETABLE, EMU):
        _write_json(folder / "resources" / name, json.loads((DATA / name).read_text()))
    return path


def generous_timetable(line: dict, dwell_s: float) -> dict:
    """Every stage at 10 m/s plus a minute, ``dwell_s`` at each station: time to spare everywhere."""
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


def fastest_stage_times(fmu_dirs: Sequence[Path], dwell_s: float = 30.0) -> List[Tuple[str, str, float]]:
    """(from, to, fastest running time s) of each stage of the suburban line: ``ato_only``'s
    system (train + ATO, cab signal off) with the ``flat_out`` strategy under
    :func:`generous_timetable`, run in process; the train arrives early and departs on time, so a
    stage's fastest running time is its arrival less the departure before it."""
    line = json.loads((DATA / SUBURBAN_LINE).read_text())
    timetable = generous_timetable(line, dwell_s)
    files = {"line_file": SUBURBAN_LINE, "rolling_stock_file": EMU}
    with tempfile.TemporaryDirectory() as scratch:
        folder = Path(scratch) / "suburban_fastest"
        components, connections = train_and_ato(
            train_parameters={**files, "x0": float(line["stations"][0]["stop_m"])},
            ato_parameters={**files, "cab_signal": "off", "strategy": "flat_out", "timetable_file": "fastest.json"})
        write_ssd(folder, "suburban_fastest", components, connections,
                  stop_time=timetable["stops"][-1]["arrival_s"] + 60.0)
        _write_json(folder / "resources" / "fastest.json", timetable)
        for name in (SUBURBAN_LINE, EMU):
            _write_json(folder / "resources" / name, json.loads((DATA / name).read_text()))
        options = RunOptions(summaries=railway_verdicts, output_dir=Path(scratch) / "out", in_process=True,
                             fmu_dirs=list(fmu_dirs), record=["train.x"])
        reached = run_system(folder, options).summary["trains"][0]["stops"]
    stages = []
    for k, stop in enumerate(reached):
        if stop["arrival_s"] is None:
            raise RuntimeError(f"{stop['station']} not reached in the fastest run")
        stages.append((timetable["stops"][k]["station"], stop["station"],
                       stop["arrival_s"] - timetable["stops"][k]["departure_s"]))
    return stages

"""A system of many identical trains queued one behind another on one line, for the tests and
benchmarks of many trains (benchmarks/bench_trains.py, tests/test_many_trains.py): each train
stands at a stopping point of its own added to a copy of the line, the foremost departs first,
the others at a fixed interval after it, front to back, and every train runs to the line's last
station. The signal chain is the shipped systems' (orchestrator/systems/chain.py
``signal_chain``: coder → rail line → one receiver per train → its ATO), in a build of K
sections and M = the number of trains (a sized folder ``resources/k{K}m{M}n40/``, which
``railcosim run`` builds on demand, fmus/sizes.py).
"""
from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import List, Optional, Tuple

from fmus.data.loader import DATA
from fmus.signalling import cab_systems
from fmus.sizes import BuildConfig
from orchestrator.systems.chain import (cab_settings, check_placements, signal_chain, stock_length_m, train_and_ato,
                                        write_ssd)


@dataclass(frozen=True)
class Queue:
    """Where the queue stands and when it leaves."""

    trains: int
    line_file: str = "default_line.json"        # a bundled line
    stock_file: Optional[str] = None            # a bundled rolling stock; None: the default train
    rear_head_m: float = 400.0                  # head of the last train (the default line's A)
    spacing_m: float = 1200.0                   # from one train's head to the next one's
    first_departure_s: float = 30.0             # the foremost train
    departure_interval_s: float = 120.0         # each train behind it that much later
    sections: Optional[int] = None              # K of the build; None: the line's sections rounded up to 8
    block_aspects: int = 3                      # the coder's block (the suburban line's is 4-aspect)
    stop_time_s: float = 60.0
    scheduled_speed_mps: float = 16.0           # the timetable's average speed, origin to terminus,
    start_allowance_s: float = 120.0            # plus this for starting and stopping


def _line(queue: Queue) -> dict:
    return json.loads((DATA / queue.line_file).read_text())


def origins(queue: Queue) -> List[Tuple[str, float]]:
    """(stopping point, head position) of each train, front first: ``q1`` is the foremost; a
    train whose head stands at a station of the line starts from it (the rear one at A)."""
    stations = {float(s["stop_m"]): s["name"] for s in _line(queue)["stations"]}
    heads = [queue.rear_head_m + (queue.trains - j) * queue.spacing_m for j in range(1, queue.trains + 1)]
    return [(stations.get(head_m, f"q{j}"), head_m) for j, head_m in enumerate(heads, start=1)]


def queued_line(queue: Queue) -> dict:
    """A copy of the line with one stopping point per train."""
    line = _line(queue)
    known = {s["name"] for s in line["stations"]}
    added = [{"name": name, "stop_m": head_m, "platform_length_m": 0}
             for name, head_m in origins(queue) if name not in known]
    line["description"] = (f"{line.get('description', line['name'])}; {queue.trains} trains queued "
                           f"{queue.spacing_m:g} m apart, the last at {queue.rear_head_m:g} m")
    line["stations"] = sorted(line["stations"] + added, key=lambda s: s["stop_m"])
    return line


def build_sizes(queue: Queue, line: dict) -> BuildConfig:
    return BuildConfig(sections=queue.sections or sections_for(line), trains=queue.trains)


def sections_for(line: dict) -> int:
    """The build's K for a line: its block sections rounded up to a multiple of 8."""
    return 8 * -(-len(line["block_sections"]) // 8)


def write_queued_trains(folder: Path, queue: Queue, system: str = cab_systems.DEFAULT.name) -> Path:
    """Write the system into ``folder``; its SSD path."""
    line = queued_line(queue)
    terminus = max(line["stations"], key=lambda s: s["stop_m"])
    length_m = stock_length_m(queue.stock_file)
    heads = origins(queue)
    check_placements(line, [(name, head_m, length_m) for name, head_m in heads])
    sizes = build_sizes(queue, line)
    files = {"line_file": "queued_line.json"}
    stock = {"rolling_stock_file": queue.stock_file} if queue.stock_file else {}
    coder, rail, receiver, ato = cab_settings(system)
    coder = {**coder, "block_aspects": queue.block_aspects}
    components, connections = [], []
    pairs = []
    for j, (origin, head_m) in enumerate(heads, start=1):
        train, driver = f"train{j}", f"ato{j}"
        timetable = f"timetable{j}.json"
        parts, links = train_and_ato(train, driver, train_parameters={**files, **stock, "x0": head_m},
                                     ato_parameters={**ato, **files, **stock, "timetable_file": timetable})
        components += parts
        connections += links
        pairs.append((train, driver))
        departure_s = queue.first_departure_s + (j - 1) * queue.departure_interval_s
        arrival_s = departure_s + (terminus["stop_m"] - head_m) / queue.scheduled_speed_mps + queue.start_allowance_s
        _write_json(folder / "resources" / timetable, {"train": f"queued {j}", "stops": [
            {"station": origin, "departure_s": departure_s},
            {"station": terminus["name"], "arrival_s": round(arrival_s)}]})
    chain, links = signal_chain(pairs, sections=sizes.sections, fmu_folder=f"resources/{sizes.folder_name}".rstrip("/"),
                                coder={**coder, **files}, rail={**rail, **files}, receiver=receiver,
                                stocks=[queue.stock_file] * queue.trains if queue.stock_file else None)
    path = write_ssd(folder, f"queued_{queue.trains}", chain + components, links + connections,
                     stop_time=queue.stop_time_s)
    _write_json(folder / "resources" / "queued_line.json", line)
    if queue.stock_file:
        _write_json(folder / "resources" / queue.stock_file, json.loads((DATA / queue.stock_file).read_text()))
    return path


def _write_json(path: Path, document: dict) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(document, indent=1, ensure_ascii=False) + "\n")

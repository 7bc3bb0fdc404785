"""A system's rail line as its core would be set up, read from the system description without
running it (for ``railcosim netlist`` and ``railcosim crosscheck spice``): its line file, its
parameters as rail-line settings, and the trains on its slots — each train's rolling stock and
its head at an instant (its Traction's x0 at t = 0, or a finished run's results.csv at a time).
"""
from __future__ import annotations

import inspect
import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Dict, List, Optional, Tuple

import numpy as np

from fmus.data.loader import DEFAULT_LINE, DEFAULT_ROLLING_STOCK, Line, load_line, load_rolling_stock
from fmus.errors import FmuInputError
from fmus.rail_line.core import RailSettings
from fmus.rail_line.track_circuit import CircuitParameters
from fmus.traction.core import TractionCore
from orchestrator.errors import UserError
from orchestrator.graph import resolve_data_file
from orchestrator.ports import split_element
from orchestrator.ssp import SystemDescription

# rail-line parameters → CircuitParameters fields (docs/interfaces.md, RailLine)
# a Traction's x0 when its system does not set it: the core's default
DEFAULT_X0_M = inspect.signature(TractionCore.__init__).parameters["x0_m"].default
_CIRCUIT = {"rail_r": "rail_r_ohm_per_km", "rail_l": "rail_l_h_per_km", "ballast": "ballast_ohm_km",
            "feed_r": "feed_r_ohm", "relay_r": "relay_r_ohm", "bond_r": "bond_r_ohm", "bond_l": "bond_l_h",
            "shunt_r": "shunt_r_ohm", "segment": "segment_m"}


@dataclass
class TrainOnLine:
    name: str                      # the component driving the slot, or the rolling-stock file
    stock_file: str
    length_m: float
    wheelsets_m: np.ndarray        # behind the first wheelset, ascending from 0
    head_m: float


@dataclass
class RailSetup:
    line: Line
    settings: RailSettings
    trains: List[TrainOnLine] = field(default_factory=list)

    def section(self, number: int) -> int:
        """A 1-based section number checked against the line, as an index."""
        if not 1 <= number <= len(self.line.sections):
            raise UserError(f"--section {number}: the line {self.line.path.name} has sections 1–{len(self.line.sections)}")
        return number - 1


def _parameters(component) -> Dict[str, object]:
    return {p.name.split(".")[-1] if "." in p.name else p.name: p.value for p in component.parameters}


def _load(loader, path, what: str):
    try:
        return loader(path)
    except FmuInputError as error:
        raise UserError(f"{what}: {error}") from None


def _heads_at(results: Path, time_s: float, names: List[str]) -> Dict[str, float]:
    """Each component's ``x`` in a run's results.csv at the row nearest ``time_s``, which must
    lie within the rows' span (one output interval either side at most)."""
    from orchestrator.reports.report import results_rows

    if not results.is_file():
        raise UserError(f"--results: {results}: no results.csv there")
    rows = results_rows(results)
    _, header = next(rows)
    columns = {name: header.index(f"{name}.x") for name in names if f"{name}.x" in header}
    missing = [name for name in names if name not in columns]
    if missing:
        raise UserError(f"--results: {results}: no column {missing[0]}.x")
    best, best_row, first, last, interval = None, None, None, None, 0.0
    for number, row in rows:
        if last is not None:
            interval = row[0] - last
        first = row[0] if first is None else first
        last = row[0]
        gap = abs(row[0] - time_s)
        if best is None or gap < best:
            best, best_row = gap, (number, row)
    if best_row is None:
        raise UserError(f"--results: {results}: no rows")
    if not first - interval <= time_s <= last + interval:
        raise UserError(f"--time {time_s:g}: {results} holds the run from {first:g} to {last:g} s")
    number, row = best_row
    heads = {name: row[index] for name, index in columns.items()}
    for name, head in heads.items():
        if not math.isfinite(head):
            raise UserError(f"--results: {results}:{number}: {name}.x = {head} is not a position")
    return heads


def rail_setup(system: SystemDescription, time_s: float = 0.0, results: Optional[Path] = None) -> RailSetup:
    """The system's (first) rail line: its line, settings and trains, heads at ``time_s`` (0:
    the Traction's x0; else from ``results``, a run's folder)."""
    rails = [c for c in system.components.values() if "x_head[1]" in c.connectors]
    if not rails:
        raise UserError(f"{system.ssd_path}: no rail line (a component with x_head ports) in the system")
    rail = rails[0]
    params = _parameters(rail)

    def data_file(name: str, default: Path) -> str:
        value = params.get(name) or ""
        return str(resolve_data_file(value, system.folder)) if value else str(default)
    line = _load(load_line, data_file("line_file", DEFAULT_LINE), f"{rail.name}.line_file")
    circuit = CircuitParameters(**{field_name: float(params[name]) for name, field_name in _CIRCUIT.items()
                                   if name in params})
    defaults = RailSettings()
    settings = RailSettings(circuit=circuit,
                            transformer_ratio=float(params.get("transformer_ratio", defaults.transformer_ratio)),
                            carrier_hz=float(params.get("carrier", 0.0) or 0.0),
                            fs_hz=float(params.get("fs", defaults.fs_hz)))
    # train slots: the components whose x feeds x_head[j]
    slots: Dict[int, str] = {}
    for connection in system.connections:
        port, index = split_element(connection.end_connector) or ("", ())
        if connection.end_element == rail.name and port == "x_head" and len(index) == 1:
            slots[index[0]] = connection.start_element
    heads = _heads_at(results / "results.csv", time_s, list(slots.values())) if results is not None else {}
    trains = []
    for slot, name in sorted(slots.items()):
        traction = _parameters(system.components[name])
        stock_name = params.get(f"rolling_stock_file[{slot}]") or traction.get("rolling_stock_file") or ""
        stock_path = str(resolve_data_file(stock_name, system.folder)) if stock_name else str(DEFAULT_ROLLING_STOCK)
        stock = _load(load_rolling_stock, stock_path, f"{name}.rolling_stock_file")
        length = float(params.get(f"train_length[{slot}]", stock.length_m))
        head = heads[name] if results is not None else float(traction.get("x0", DEFAULT_X0_M))
        trains.append(TrainOnLine(name, Path(stock_path).name, length, stock.wheelset_offsets_m, head))
    return RailSetup(line, settings, trains)


def line_setup(line_file: str, ballast_ohm_km: float = 0.0, carrier_hz: float = 0.0) -> RailSetup:
    """A line file alone: default rail-line settings, no trains yet."""
    line = _load(load_line, line_file, "--line")
    return RailSetup(line, RailSettings(circuit=CircuitParameters(ballast_ohm_km=ballast_ohm_km), carrier_hz=carrier_hz))


def add_train(setup: RailSetup, spec: str) -> None:
    """``--train FILE@HEAD``: a rolling-stock file with its first wheelset at HEAD metres."""
    stock_file, at, head = spec.rpartition("@")
    if not at:
        raise UserError(f"--train {spec}: FILE@HEAD expected (a rolling-stock JSON and its head position, m)")
    try:
        head_m = float(head)
    except ValueError:
        raise UserError(f"--train {spec}: the head position {head!r} is not a number") from None
    if not math.isfinite(head_m):      # float() reads nan and inf: such a train would be left out
        raise UserError(f"--train {spec}: the head position {head!r} is not a finite number of metres")
    from fmus.data.loader import DATA
    path = stock_file if Path(stock_file).is_file() else str(DATA / stock_file)
    stock = _load(load_rolling_stock, path, f"--train {spec}")
    setup.trains.append(TrainOnLine(Path(path).stem, Path(path).name, stock.length_m, stock.wheelset_offsets_m, head_m))


def line_ballast_range() -> Tuple[float, float]:
    """The ballast resistances a line file's block section may have, Ω·km (its schema's)."""
    from fmus.data.loader import SCHEMAS

    schema = json.loads((SCHEMAS / "line.schema.json").read_text(encoding="utf-8"))
    ballast = schema["properties"]["block_sections"]["items"]["properties"]["ballast_ohm_km"]
    return float(ballast["minimum"]), float(ballast["maximum"])


def settings_with_trains(setup: RailSetup) -> RailSettings:
    """The setup's settings with its trains' lengths and wheelsets (at least one slot)."""
    from dataclasses import replace

    trains = setup.trains or [TrainOnLine("none", "", 1.0, np.zeros(1), -1000.0)]
    return replace(setup.settings, train_length_m=tuple(t.length_m for t in trains),
                   wheelset_offsets_m=tuple(t.wheelsets_m for t in trains))


def heads_of(setup: RailSetup) -> List[float]:
    return [t.head_m for t in setup.trains] or [-1000.0]


def section_netlist(setup: RailSetup, k: int, wheelsets: str = "nodes", segment_m: float = 1.0,
                    frequency_hz: Optional[float] = None, tran_s: Optional[float] = None, time_s: float = 0.0,
                    ballast_ohm_km: float = 0.0):
    """Section k of the setup as a netlist with its trains where they are: their wheelsets lumped
    as the rail line lumps them (``nodes``) or at their axles (``axles``, rails in pieces of at
    most ``segment_m``); excited by a 1 V sine at the section's carrier (or ``frequency_hz``) for
    .ac, or, with ``tran_s``, by the wayside coder's code for the section over that many
    seconds from ``time_s`` (the occupancy the trains' extents give, held) for .tran.
    ``ballast_ohm_km`` > 0 replaces the section's ballast (as the rail line's ballast_override)."""
    from fmus.rail_line.core import RailLineCore
    from fmus.rail_line.track_circuit import Faults
    from fmus.wayside_coder.core import CoderSettings, WaysideCoderCore
    from orchestrator.circuits.netlist import (MAX_AXLE_PIECES, ac_source, axle_netlist, lumped_netlist,
                                               print_probes, tran_source)

    settings = settings_with_trains(setup)
    core = RailLineCore(setup.line, len(setup.line.sections), len(settings.train_length_m), 40, settings)
    circuit = core.circuits[k]
    geometry = core.bank.geometry
    frequency = float(geometry.carriers[k]) if frequency_hz is None else float(frequency_hz)
    heads = heads_of(setup)
    inside = [t for t in setup.trains if circuit.start_m <= t.head_m < circuit.end_m]
    described = ", ".join(f"{t.name} ({t.stock_file}) head {t.head_m:g} m" for t in setup.trains
                          if t.head_m >= circuit.start_m and t.head_m - t.length_m <= circuit.end_m) or "no train"
    title = f"railcosim: {setup.line.path.name} section {k + 1} ({setup.line.sections[k].name}), {described}"
    lowest, highest = line_ballast_range()
    if ballast_ohm_km != 0 and not lowest <= ballast_ohm_km <= highest:   # (NaN too)
        raise UserError(f"--ballast {ballast_ohm_km:g}: a ballast resistance from {lowest:g} to {highest:g} Ω·km, "
                        "as a line file's (0: the section's own)")
    faults = Faults(ballast_ohm_km)
    if wheelsets == "nodes":
        configs, rows = core.bank.configuration(heads)
        shunts, head_nodes = configs[k]
        netlist = lumped_netlist(circuit, shunts, head_nodes, faults, frequency, settings.transformer_ratio, title)
        named = {f"head{h}": next(t.name for j, t in enumerate(setup.trains) if rows[k].get(j) == h)
                 for h in range(len(head_nodes))}
    elif wheelsets == "axles":
        rails_m = float(circuit.end_m - circuit.start_m)
        if not rails_m / segment_m <= MAX_AXLE_PIECES:        # before any array is made (NaN too)
            raise UserError(f"--segment {segment_m:g}: section {k + 1}'s {rails_m:g} m of rails would be "
                            f"{rails_m / segment_m:.3g} pieces; at most {MAX_AXLE_PIECES} "
                            f"(--segment {rails_m / MAX_AXLE_PIECES:.3g} or more)")
        axles = [t.head_m - float(o) for t in setup.trains for o in t.wheelsets_m]
        netlist = axle_netlist(circuit, axles, [t.head_m for t in inside], faults, frequency,
                               settings.transformer_ratio, segment_m, title)
        named = {f"head{h}": t.name for h, t in enumerate(inside)}
    else:
        raise UserError(f"--wheelsets {wheelsets}: nodes or axles")
    if tran_s is None:
        ac_source(netlist, frequency)
    else:
        if not 0.0 < tran_s <= 60.0:
            raise UserError(f"--tran {tran_s:g}: a window of more than 0 and at most 60 s")
        fs, frame = settings.fs_hz, 40
        coder = WaysideCoderCore(setup.line, len(setup.line.sections), frame,
                                 CoderSettings(fs_hz=fs, carrier_hz=setup.settings.carrier_hz))
        occupied = np.array([any(t.head_m - t.length_m < circuit_k.end_m and t.head_m >= circuit_k.start_m
                                 for t in setup.trains) for circuit_k in core.circuits])
        first = int(round(time_s * fs / frame))
        samples = np.concatenate([coder.step((first + i) * frame / fs, occupied).u_tx[k].copy()
                                  for i in range(int(np.ceil(tran_s * fs / frame)))])[:int(round(tran_s * fs))]
        tran_source(netlist, np.arange(len(samples)) / fs, samples, (len(samples) - 1) / fs, 1.0 / fs)
    print_probes(netlist, {"relay": "relay-end voltage", "entry": "current arriving at the relay end",
                           **{key: f"current arriving at {name}'s first wheelset" for key, name in named.items()}},
                 tran=tran_s is not None)
    return netlist

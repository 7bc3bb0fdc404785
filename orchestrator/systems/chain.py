"""The building blocks of every system railcosim writes (the shipped ones,
orchestrator/systems/shipped.py; ``railcosim new``; the headway trials,
orchestrator/systems/queued.py): one train and its ATO, the signal chain for any number of
trains, each cab system's settings, train lengths from the rolling-stock files, placements
checked, and SSDs written from the committed contract manifests."""
from __future__ import annotations

import json
from pathlib import Path
from typing import Dict, List, Optional, Sequence, Tuple

import fmus
from fmus import ato_controller, loco_receiver, rail_line, traction, wayside_coder
from fmus.signalling import cab_systems
from fmus.sizes import DEFAULT_SAMPLE_RATE_HZ, BuildConfig, sizes_of_source
from orchestrator.verdicts.system_checks import span_defects
from orchestrator.ports import read_manifest
from orchestrator.sspgen import ComponentSpec, ConnectionSpec, Ports
from orchestrator.sspgen import write_ssd as _write_ssd

TRAIN_STEP_S = 0.5
ATO_STEP_S = 0.5
_UNITS = (wayside_coder, rail_line, loco_receiver, traction, ato_controller)
#: each unit's FMU file, named by the model identifier its package declares (fmus/<unit>/__init__.py)
CODER_FMU, RAIL_FMU, RECEIVER_FMU, TRAIN_FMU, ATO_FMU = (f"{unit.MODEL_IDENTIFIER}.fmu" for unit in _UNITS)
#: the folder of each railcosim unit (fmus/<unit>/) by its model identifier
UNIT_OF_MODEL = {unit.MODEL_IDENTIFIER: unit.__name__.rpartition(".")[2] for unit in _UNITS}


def committed_ports(folder: Path, source: str) -> Optional[Ports]:
    """The committed contract manifest of a railcosim FMU (``fmus/<unit>/contract.json``, checked
    against the built FMU by tests/test_build_and_contracts.py), found by the FMU's file name
    (``Traction.fmu`` → ``fmus/traction``), its arrays sized as the source's folder says
    (``k32m2n40/RailLine.fmu``: 32 sections); None for any other FMU."""
    unit = UNIT_OF_MODEL.get(Path(source).stem)
    manifest = Path(fmus.__file__).parent / str(unit) / "contract.json"
    if unit is None or not manifest.is_file():
        return None
    ports = read_manifest(manifest)
    sizes = sizes_of_source(source)
    if sizes is None:
        return ports
    # the manifests are the default build's: its K, M, N are distinct numbers, so every array
    # dimension says which size it is
    default = BuildConfig()
    scale = {default.sections: sizes.sections, default.trains: sizes.trains, default.frame: sizes.frame}
    return {name: ({**port, "shape": [scale.get(d, d) for d in port["shape"]]} if port.get("shape") else port)
            for name, port in ports.items()}


def write_ssd(folder: Path, name: str, components, connections, **options) -> Path:
    """A shipped system's SSD: its connectors come from the committed contract manifests, so
    the files do not depend on what is built (tests/test_shipped_systems.py compares bytes)."""
    return _write_ssd(folder, name, components, connections, ports=committed_ports, **options)


def _shipped_json(name: str) -> dict:
    from fmus.data.loader import DATA

    return json.loads((DATA / name).read_text())


def stock_length_m(stock_file=None) -> float:
    """A train's length from its rolling-stock file: a bundled one by name, or a path (None or
    empty: the bundled default, as the FMUs read it). The one source of every train length a
    system carries (the rail line's ``train_length[j]``; the Traction and ATO read the same file)."""
    from fmus.data.loader import DATA, DEFAULT_ROLLING_STOCK, load_rolling_stock

    if not stock_file:
        return float(load_rolling_stock(DEFAULT_ROLLING_STOCK).length_m)
    path = Path(stock_file)
    return float(load_rolling_stock(path if path.is_file() else DATA / path).length_m)


def check_placements(line: dict, trains: Sequence[Tuple[str, float, float]]) -> None:
    """Refuse (ValueError) initial placements (name, head position, length) with a tail before
    the line start or two trains overlapping: the rail line refuses them at initialisation
    (the rule: orchestrator/verdicts/system_checks.py ``span_defects``)."""
    off, overlaps = span_defects(line["length_m"], trains)
    if off:
        name, tail, head = off[0]
        raise ValueError(f"{name}: {tail:g}..{head:g} m is not on the line (0..{line['length_m']:g} m)")
    if overlaps:
        (name, _, head), (other, tail, _) = overlaps[0]
        raise ValueError(f"{name} (head {head:g} m) overlaps {other} (tail {tail:g} m)")


def _stop_m(line: dict, station: str) -> float:
    return float(next(s["stop_m"] for s in line["stations"] if s["name"] == station))


def _with_station(line: dict, name: str, stop_m: float, description: str) -> dict:
    """A copy of a line with one more stopping point (stations in running order)."""
    copy = json.loads(json.dumps(line))
    copy["description"] = f"{line.get('description', line['name'])}; {description}"
    copy["stations"] = sorted(copy["stations"] + [{"name": name, "stop_m": stop_m, "platform_length_m": 400}],
                              key=lambda s: s["stop_m"])
    return copy


def train_and_ato(train: str = "train", ato: str = "ato", train_parameters: Dict[str, object] = None,
                  ato_parameters: Dict[str, object] = None, fmu_folder: str = "resources",
                  step_s: Tuple[float, float] = (TRAIN_STEP_S, ATO_STEP_S)):
    """Components and connections of one train driven by its ATO (closed loop)."""
    components = [
        ComponentSpec(train, f"{fmu_folder}/{TRAIN_FMU}", step_s[0], dict(train_parameters or {})),
        ComponentSpec(ato, f"{fmu_folder}/{ATO_FMU}", step_s[1], dict(ato_parameters or {})),
    ]
    connections: List[ConnectionSpec] = [
        ConnectionSpec(f"{train}.x", f"{ato}.x"),
        ConnectionSpec(f"{train}.v", f"{ato}.v"),
        ConnectionSpec(f"{ato}.command", f"{train}.command"),
        ConnectionSpec(f"{ato}.emergency_brake", f"{train}.emergency_brake"),
    ]
    return components, connections


CHAIN_PORTS = ("aspect", "code_valid", "v_permitted", "v_target", "free_blocks")


def signal_chain(trains: Sequence[Tuple[str, str]] = (("train", "ato"),), sections: int = 8, frame: int = 40,
                 fmu_folder: str = "resources", coder: Dict[str, object] = None, rail: Dict[str, object] = None,
                 receiver: Dict[str, object] = None, stocks: Optional[Sequence] = None,
                 parameter_file: Optional[str] = None, fs_hz: float = DEFAULT_SAMPLE_RATE_HZ):
    """Coder → rail line → one receiver per train (``rx``, or ``rx1``, ``rx2`` … for several) →
    its ATO, and each train's position back into the rail line (train j on slot j). The rail
    line's ``train_length[j]`` is the length in train j's rolling-stock file (``stocks[j-1]``,
    default the bundled default stock) and its ``rolling_stock_file[j]`` that file, so the rail
    line shunts the train the Traction moves, at its wheelsets.
    ``parameter_file``: an .ssv the coder and the rail line also bind (e.g. the line file);
    ``fs_hz``: the chain's sample rate (set on the three signal FMUs when not the default)."""
    step = frame / fs_hz                         # a signal FMU steps one frame
    if fs_hz != DEFAULT_SAMPLE_RATE_HZ:
        coder, rail, receiver = ({**(part or {}), "fs": fs_hz} for part in (coder, rail, receiver))
    stocks = list(stocks) if stocks is not None else [None] * len(trains)
    lengths = {f"train_length[{j}]": stock_length_m(stock) for j, stock in enumerate(stocks, start=1)}
    # where each train's wheelsets are (an empty file name: the bundled default stock's)
    lengths.update({f"rolling_stock_file[{j}]": str(stock) for j, stock in enumerate(stocks, start=1) if stock})
    components = [
        ComponentSpec("coder", f"{fmu_folder}/{CODER_FMU}", step, dict(coder or {}), parameter_file),
        ComponentSpec("rail", f"{fmu_folder}/{RAIL_FMU}", step, {**lengths, **(rail or {})}, parameter_file),
    ]
    connections = [ConnectionSpec(f"coder.u_tx[{k},{n}]", f"rail.u_tx[{k},{n}]")
                   for k in range(1, sections + 1) for n in range(1, frame + 1)]
    connections += [ConnectionSpec(f"rail.occupied[{k}]", f"coder.occupied[{k}]") for k in range(1, sections + 1)]
    # the system's own receiver → ATO links (ALSU's code shown, TVM-430's target and gradient, …)
    own_links = cab_systems.of_parameters(receiver or {}).ato_links
    for j, (train, ato) in enumerate(trains, start=1):
        rx = "rx" if len(trains) == 1 else f"rx{j}"
        components.append(ComponentSpec(rx, f"{fmu_folder}/{RECEIVER_FMU}", step, dict(receiver or {})))
        connections += [ConnectionSpec(f"rail.e_coil[{j},{n}]", f"{rx}.e_coil[{n}]") for n in range(1, frame + 1)]
        # linear: the train publishes its state at the end of its 0.5 s step; the rail line needs
        # the position at each 10 ms frame, not half a second ahead (the master interpolates)
        connections += [ConnectionSpec(f"{train}.{a}", f"rail.{b}[{j}]", transition="linear")
                        for a, b in (("x", "x_head"), ("v", "v"), ("i_traction", "i_traction"))]
        connections += [ConnectionSpec(f"{rx}.{port}", f"{ato}.{port}") for port in CHAIN_PORTS]
        connections += [ConnectionSpec(f"{rx}.{output}", f"{ato}.{input_}") for output, input_ in own_links]
    return components, connections


#: the trains a sized build holds at least (the shipped two-train systems' build)
SIZED_BUILD_TRAINS = 2


def sized_build(cab: cab_systems.CabSystem, sections: int, trains: int) -> BuildConfig:
    """The build sizes of the signal FMUs of a system with build sizes of its own (its
    descriptor's ``build_sections``): the smallest holding the line's ``sections``, so every line of
    17 to 32 sections shares one build with the shipped tvm430 (k32m2n120) and a few builds serve
    every line, at the cost of idle sections; room for ``trains`` (at least SIZED_BUILD_TRAINS);
    10 ms frames at its sample rate."""
    if sections > cab.build_sections[-1]:
        raise ValueError(f"the line has {sections} block sections; a {cab.name} system holds at most "
                        f"{cab.build_sections[-1]}")
    return BuildConfig(sections=next(k for k in cab.build_sections if k >= sections),
                       trains=max(SIZED_BUILD_TRAINS, trains),
                       frame=int(round(cab.sample_rate_hz * cab_systems.FRAME_S)))


# ---- each cab system's settings ------------------------------------------------------------------------
def cab_settings(system: str) -> Tuple[dict, dict, dict, dict]:
    """(coder, rail, receiver, ATO) parameters of a cab-signal system (its descriptor,
    fmus/signalling/cab_systems.py)."""
    cab = cab_systems.lookup(system)
    coder, rail, receiver = cab.chain_parameters()
    return coder, rail, receiver, cab.ato_parameters()

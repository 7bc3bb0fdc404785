"""``railcosim new NAME``: a system folder of one's own from a line file, timetables and a
rolling-stock file (docs/your_own_system.md).

The folder holds what ``railcosim run NAME`` needs:

* ``SystemStructure.ssd`` — the signal chain (wayside coder → rail line → one locomotive receiver
  per train) and per train its Traction and ATO, written with orchestrator/sspgen.py the way the
  shipped systems are (orchestrator/systems/shipped.py);
* ``line.ssv`` — one SSP parameter set holding ``line_file``, bound by every component that
  reads the line (coder, rail line, every train and ATO): one line for the whole system;
* ``resources/`` — copies of the data files (the line, each train's timetable, the rolling stock).

Each train starts standing at its timetable's first station (its head at the stopping point);
the rail line's train lengths come from the rolling-stock file; the receivers are tuned to the
line's ALSN carrier and to the stock's category. Everything a run would refuse is refused here
first, in one line naming the file and the field.

``--system S`` is any registered cab system (fmus/signalling/cab_systems.py) on a line of the
track circuits it codes (the descriptor's ``transmitter``: KPT circuits with joints, or UM71
jointless circuits, docs/rail_line.md#tvm-430-track-circuits); any other pairing is refused in
one line naming the section. A system whose descriptor names build sizes of its own (TVM-430,
TVM-300) gets the chain its shipped systems have (orchestrator/systems/shipped.py): its sample
rate, 10 ms frames (120 samples at 12 kHz), its signal FMUs named in a sized folder of the
sources (``resources/k32m2n120/RailLine.fmu``, docs/architecture.md#build-sizes) that
``railcosim run`` builds, and its default stock (the high-speed set).
"""
from __future__ import annotations

import contextlib
import errno
import os
import secrets
import shutil
from dataclasses import dataclass
from pathlib import Path
from typing import Optional, Sequence

from fmus.data.loader import (DATA, DEFAULT_ROLLING_STOCK, TVM_TRANSMITTER, Line, RollingStock, load_line,
                              load_rolling_stock, load_timetable)
from fmus.errors import FmuInputError
from fmus.signalling import cab_systems
from fmus.sizes import BuildConfig, sizes_of_source
from orchestrator.verdicts.system_checks import check_sections_contiguous, load_data_file
from orchestrator.systems.chain import (RAIL_FMU, cab_settings, check_placements, committed_ports, signal_chain, sized_build,
                                        train_and_ato)
from orchestrator.errors import UserError
from orchestrator.sspgen import fmu_ports, write_ssd, write_ssv

CAB_SYSTEMS = cab_systems.NAMES
TRACTION = {"dc": "DC3000", "ac": "AC25000", "none": "none"}
#: the stock a train gets without --rolling-stock, by traction (bundled files)
DEFAULT_STOCK = {"dc": Path(DEFAULT_ROLLING_STOCK), "ac": DATA / "freight_vl80.json",
                 "none": Path(DEFAULT_ROLLING_STOCK)}
LINE_PARAMETER_SET = "line.ssv"
#: seconds the run goes on after the last scheduled arrival
STOP_MARGIN_S = 120.0


@dataclass
class Sizes:
    """The built FMUs' array sizes: block sections K, trains M, samples per frame N."""
    sections: int
    trains: int
    frame: int


def built_sizes(fmu_dir: Optional[Path]) -> Sizes:
    """K, M, N of the rail line FMU in ``fmu_dir`` (``railcosim build --sections/--trains/
    --frame``), else of the committed contract (8, 2, 40)."""
    ports = built_ports(fmu_dir, RAIL_FMU)
    k, n = ports["u_tx"]["shape"]
    return Sizes(int(k), int(ports["x_head"]["shape"][0]), int(n))


def default_stock(system: str, traction: str) -> Path:
    """The rolling-stock file a train gets without --rolling-stock: the system's own (the
    high-speed set for TVM), else the traction's."""
    cab = cab_systems.REGISTRY.get(cab_systems.spelled(system))     # an unknown one: refused by new_system
    return DATA / cab.default_stock if cab is not None and cab.default_stock else DEFAULT_STOCK[traction]


def check_track_circuits(line: Line, system: str) -> None:
    """A system codes the track circuits its descriptor names and no others: the TVM coders
    refuse any carrier not of UM71, the others' coders know KPT transmitters only."""
    cab = cab_systems.lookup(system)
    um71 = [s.transmitter == TVM_TRANSMITTER for s in line.sections]
    if cab.transmitter == cab_systems.UM71:
        if not any(um71):
            raise UserError(f"--system {system}: {line.path} has no {TVM_TRANSMITTER} sections (field "
                            f"block_sections[].transmitter); {cab.title} codes {TVM_TRANSMITTER} track circuits")
        k = um71.index(False) if False in um71 else None
        if k is not None:
            raise UserError(f"--system {system}: {line.path} field block_sections[{k}].transmitter is "
                            f"{line.sections[k].transmitter!r}; {cab.title} codes {TVM_TRANSMITTER} track circuits only")
    elif True in um71:
        k = um71.index(True)
        others = ", ".join(c.name for c in cab_systems.REGISTRY.values() if c.transmitter == cab_systems.UM71)
        raise UserError(f"--system {system}: {line.path} field block_sections[{k}].transmitter is "
                        f"{TVM_TRANSMITTER!r}, a jointless track circuit {cab.title} cannot code; give --system "
                        f"{others.replace(', ', ' or ')}")


def _load(loader, path: Path, option: str):
    return load_data_file(loader, path, lambda problem: f"{option}: {problem}")


def new_system(folder: Path, line_file: Path, timetable_files: Sequence[Path],
               rolling_stock_file: Optional[Path] = None, system: str = cab_systems.DEFAULT.name, trains: Optional[int] = None,
               traction: Optional[str] = None, fmu_dir: Optional[Path] = None) -> Path:
    """Write the system folder (module docstring); its SSD path. Bad input is a UserError."""
    folder = Path(folder)
    _refuse_existing(folder)
    system = cab_systems.spelled(system)
    if system not in CAB_SYSTEMS:
        raise UserError(f"--system {system}: choose one of {', '.join(CAB_SYSTEMS)}")
    timetable_files = [Path(p) for p in timetable_files]
    count = len(timetable_files) if trains is None else trains
    if count != len(timetable_files):
        raise UserError(f"--trains {count}: give one --timetable per train ({len(timetable_files)} given); "
                        "each train starts at its own timetable's first station")
    cab = cab_systems.lookup(system)
    # a system with build sizes of its own is sized for its line and trains below; the others are the build's
    sizes = built_sizes(fmu_dir) if not cab.build_sections else BuildConfig(trains=max(count, 1))
    if not 1 <= count <= sizes.trains:
        raise UserError(f"--trains {count}: the FMUs are built for 1 to {sizes.trains} trains "
                        f"(railcosim build --trains {count})")
    line: Line = _load(load_line, Path(line_file), "--line")
    try:
        check_sections_contiguous(line)
    except UserError as error:
        raise UserError(f"--line: {error}") from None
    check_track_circuits(line, system)
    if cab.build_sections:   # its own build sizes, named in the sources and built by railcosim run
        try:
            sizes = sized_build(cab, len(line.sections), count)
        except ValueError as error:
            raise UserError(f"--line: {line.path}: {error}") from None
    if len(line.sections) > sizes.sections:
        raise UserError(f"--line: {line.path} has {len(line.sections)} block sections; the FMUs are built for "
                        f"{sizes.sections} (railcosim build --sections {len(line.sections)})")
    traction = traction or next(k for k, v in TRACTION.items() if v == line.electrification)
    if traction not in TRACTION:
        raise UserError(f"--traction {traction}: choose one of {', '.join(TRACTION)}")
    if TRACTION[traction] != line.electrification:
        raise UserError(f"--traction {traction}: {line.path} field electrification.system is "
                        f"{line.electrification!r}; the traction must be the line's")
    stock_path = Path(rolling_stock_file) if rolling_stock_file else default_stock(system, traction)
    stock: RollingStock = _load(load_rolling_stock, stock_path, "--rolling-stock")
    if stock.electrical_system not in ("none", line.electrification) and line.electrification != "none":
        raise UserError(f"--rolling-stock: {stock_path} (field electrical.system {stock.electrical_system!r}) "
                        f"cannot run on {line.path} (electrification {line.electrification!r})")
    timetables = [_load(lambda p: load_timetable(p, line), path, "--timetable") for path in timetable_files]
    carriers = sorted({s.carrier_hz for s in line.sections})
    if cab.line_carrier and len(carriers) > 1:
        raise UserError(f"--line: {line.path} field block_sections[].carrier_hz: the sections use "
                        f"{', '.join(f'{c:g}' for c in carriers)} Hz; one receiver is tuned to one carrier")
    names = [("train", "ato")] if count == 1 else [(f"train{j}", f"ato{j}") for j in range(1, count + 1)]
    origins = [timetable[0].stop_m for timetable in timetables]
    try:
        check_placements({"length_m": line.length_m},
                         [(name, x0, stock.length_m) for (name, _), x0 in zip(names, origins)])
    except ValueError as error:
        raise UserError(f"--timetable: each train stands at its first station at t = 0: {error}") from None
    resource_names = [Path(line_file).name, stock_path.name, *(p.name for p in timetable_files)]
    if len(set(resource_names)) != len(resource_names):
        raise UserError(f"--line, --timetable, --rolling-stock: files of one name ({', '.join(resource_names)}) "
                        "would overwrite each other in resources/; rename them")

    coder, rail, receiver, ato = cab_settings(system)
    receiver = {**receiver, "train_category": stock.category}
    if cab.line_carrier:
        receiver["carrier"] = float(carriers[0])
    stock_parameters = {"rolling_stock_file": stock_path.name}
    components, connections = [], []
    for (train, ato_name), x0, timetable_path in zip(names, origins, timetable_files):
        parts, links = train_and_ato(train, ato_name, train_parameters={**stock_parameters, "x0": float(x0)},
                                     ato_parameters={**ato, **stock_parameters, "timetable_file": timetable_path.name})
        for part in parts:
            part.parameter_file = LINE_PARAMETER_SET
        components += parts
        connections += links
    tvm = {"fmu_folder": f"resources/{sizes.folder_name}", "fs_hz": cab.sample_rate_hz} if cab.build_sections else {}
    chain, links = signal_chain(names, sections=sizes.sections, frame=sizes.frame, coder=coder, rail=rail,
                                receiver=receiver, stocks=[stock_path] * count, parameter_file=LINE_PARAMETER_SET,
                                **tvm)
    stop_time = max(stop.arrival_s or stop.departure_s or 0.0 for timetable in timetables for stop in timetable)

    def ports(_, source: str):
        return built_ports(fmu_dir, source)

    with _new_folder(folder) as staging:
        resources = staging / "resources"
        resources.mkdir()
        for source in [Path(line_file), stock_path, *timetable_files]:
            shutil.copyfile(source, resources / source.name)
        write_ssv(staging / LINE_PARAMETER_SET, "line", {"line_file": Path(line_file).name})
        write_ssd(staging, folder.name, chain + components, connections + links,
                  stop_time=float(stop_time) + STOP_MARGIN_S, ports=ports)
    return folder / "SystemStructure.ssd"


def _refuse_existing(folder: Path) -> None:
    if os.path.lexists(folder) and (not folder.is_dir() or folder.is_symlink() or any(folder.iterdir())):
        raise UserError(f"{folder}: already exists; give a new name (railcosim new never overwrites)")


@contextlib.contextmanager
def _new_folder(folder: Path):
    """A folder beside ``folder``, written by the caller, then renamed to ``folder`` in one
    step: of two ``railcosim new`` into one name, one gets the folder and the other is refused
    in one line (``rename`` replaces nothing but an empty folder), and a ``new`` that fails or
    is interrupted leaves no half-written system."""
    try:
        folder.parent.mkdir(parents=True, exist_ok=True)
        staging = folder.parent / f".{folder.name}.{os.getpid()}.{secrets.token_hex(4)}.new"
        staging.mkdir()
    except OSError as error:
        raise UserError(f"{folder}: cannot create the folder ({error.strerror or error})") from None
    try:
        yield staging
        try:
            os.rename(staging, folder)
        except OSError as error:
            if error.errno in (errno.EEXIST, errno.ENOTEMPTY, errno.ENOTDIR, errno.EISDIR):
                raise UserError(f"{folder}: already exists (made while this system was written); "
                                "give a new name (railcosim new never overwrites)") from None
            raise UserError(f"{folder}: cannot create the folder ({error.strerror or error})") from None
    finally:
        shutil.rmtree(staging, ignore_errors=True)


def built_ports(fmu_dir: Optional[Path], source: str):
    """An FMU's ports from the build folder when it is built there, else its committed contract;
    an FMU of other sizes (in a sized folder, fmus/sizes.py): its contract at those sizes."""
    if sizes_of_source(source) is None and fmu_dir is not None and (Path(fmu_dir) / Path(source).name).is_file():
        return fmu_ports(Path(fmu_dir), Path(source).name)
    return committed_ports(Path("."), source)



#: a generated timetable runs each stage in its minimum running time plus this share, rounded up
#: to TIMETABLE_ROUND_S, and stops DWELL_S at every station (docs/railml.md#timetable)
TIMETABLE_MARGIN = 0.15
TIMETABLE_ROUND_S = 5.0
DWELL_S = 60.0
FIRST_DEPARTURE_S = 60.0


def timetable_for(line_path: Path, stock_path: Path) -> dict:
    """A timetable over every station of the line where the train fits: from the first station
    with room for the train behind its stop point, stopping at each following one, each stage
    in its minimum running time (the ATO's own planner, its default settings) + 15 %."""
    import math

    from fmus.ato_controller.core import AtoSettings
    from fmus.ato_controller.planner import InfeasibleStage, StagePlanner
    from fmus.ato_controller.train_model import NominalTrain

    line = _load(load_line, Path(line_path), "--railml")
    stock = _load(load_rolling_stock, Path(stock_path), "--rolling-stock")
    try:
        train = NominalTrain(stock, line)
    except FmuInputError as error:
        raise UserError(f"--rolling-stock: {stock_path} cannot run on the imported line "
                        f"(electrification {line.electrification!r}): {error}") from None
    planner = StagePlanner(train, line, stock.category, min(0.5, 0.6 * stock.service_decel),
                           AtoSettings().speed_margin_mps)
    stations = [s for s in line.stations if s.stop_m - stock.length_m >= 0.0]
    if len(stations) < 2:
        raise UserError(f"--railml: the line has {len(stations)} station(s) with room for the {stock.length_m:g} m "
                        f"train behind its stop point ({', '.join(s.name for s in line.stations)}); a timetable "
                        "needs two: give a shorter train with --rolling-stock, or a --timetable")
    stops, time = [{"station": stations[0].name, "departure_s": FIRST_DEPARTURE_S}], FIRST_DEPARTURE_S
    for origin, destination in zip(stations[:-1], stations[1:]):
        try:
            minimum = planner.plan(origin.stop_m, destination.stop_m, None).minimum_time_s
        except InfeasibleStage:
            raise UserError(f"--railml: the train cannot run from {origin.name} to {destination.name}") from None
        time += math.ceil(minimum * (1 + TIMETABLE_MARGIN) / TIMETABLE_ROUND_S) * TIMETABLE_ROUND_S
        stop = {"station": destination.name, "arrival_s": time}
        if destination is not stations[-1]:
            time += DWELL_S
            stop["departure_s"] = time
        stops.append(stop)
    return {"train": f"{stock.name} over {line.name}", "stops": stops}


def new_system_from_railml(folder: Path, railml_file: Path, timetable_files: Sequence[Path], line_id=None,
                           sidecar=None, schema_dir=None, rolling_stock_file=None, system: str = cab_systems.DEFAULT.name,
                           trains=None, traction=None, fmu_dir=None):
    """``railcosim new NAME --railml FILE``: the railML line imported (orchestrator/railml/
    read.py), written as a line file into the system's resources/, and the system made from it
    as from a line file; without --timetable one timetable is made (:func:`timetable_for`).
    Returns (SSD path, the import's notes)."""
    import json
    import tempfile

    from orchestrator.railml.read import import_railml
    from orchestrator.railml.validate import validate_railml

    folder, railml_file = Path(folder), Path(railml_file)
    _refuse_existing(folder)
    if schema_dir is not None:
        valid, errors = validate_railml(railml_file, schema_dir)
        if not valid:
            more = f" (and {len(errors) - 1} more)" if len(errors) > 1 else ""
            raise UserError(f"{railml_file}: not valid against the railML schema in {schema_dir}: {errors[0]}{more}")
    imported = import_railml(railml_file, line_id=line_id, sidecar=sidecar)
    with tempfile.TemporaryDirectory(prefix="railcosim_railml_") as work:
        line_path = Path(work) / f"{railml_file.stem}.json"
        generated = Path(work) / f"{railml_file.stem}_timetable.json"
        line_path.write_text(json.dumps(imported.document, indent=1, ensure_ascii=False) + "\n", encoding="utf-8")
        try:
            load_line(line_path)
        except FmuInputError as error:
            raise UserError(f"{railml_file}: the imported line is refused: {str(error).split(': ', 1)[1]}") from None
        try:
            if not timetable_files:
                stock = Path(rolling_stock_file) if rolling_stock_file else default_stock(system, (
                    traction or next(k for k, v in TRACTION.items()
                                     if v == imported.document["electrification"]["system"])))
                generated.write_text(json.dumps(timetable_for(line_path, stock), indent=1, ensure_ascii=False) + "\n",
                                     encoding="utf-8")
                timetable_files = [generated]
                imported.notes.append(f"no --timetable: {generated.name} made (every station with room for the "
                                      f"train, minimum running times + {TIMETABLE_MARGIN:.0%}, {DWELL_S:g} s stops)")
            ssd = new_system(folder, line_path, timetable_files, rolling_stock_file, system, trains, traction, fmu_dir)
        except UserError as error:
            # the files made here are the user's railML file to the user, not a temporary folder
            raise UserError(str(error).replace(str(line_path), f"{railml_file} (the line imported from it)")
                            .replace(str(generated), f"the timetable made for {railml_file}")) from None
    return ssd, imported.notes

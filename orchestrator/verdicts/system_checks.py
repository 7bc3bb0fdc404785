"""Checks of a system's railway data made before a run (and by ``railcosim validate``): what the
engine cannot check because it knows no railway (docs/architecture.md), and what the FMUs would
find only at initialisation, or never.

* every data file a component names (``line_file``, ``rolling_stock_file``, ``timetable_file``,
  ``codes_file``) loads, with the same loaders and defaults the FMUs use; a file that does not
  is an error naming the file and the field (a JSON document nested too deeply included);
* the block sections of a line file follow each other without a gap: a stretch of track with
  no track circuit is a place where no train is detected;
* connected components that both take a line file (an ATO and the train it drives, a train and
  its rail line, the rail line and its coder) run on one line: the same file, or files of
  identical content;
* every train (Traction component) starts on its line, tail included (its length is the one in
  its rolling-stock file), and no two trains on one rail line overlap at t = 0;
* a rail line's ``train_length[j]`` is the length in the rolling-stock file of the train on its
  slot j: a different one is a warning (the rail line would shunt a train of another length).

Every defect is one line (exit 2; docs/scenarios.md, "Systems, parameter sets and scenarios:
bad input"): a run stops at the first, ``railcosim validate`` lists them all.
"""
from __future__ import annotations

import filecmp
import math
from pathlib import Path
from typing import Callable, Dict, FrozenSet, Iterable, List, Optional, Tuple

import numpy as np

import fmus
from fmus import traction
from fmus.data.loader import (DEFAULT_LINE, DEFAULT_ROLLING_STOCK, DEFAULT_TIMETABLE, Line, RollingStock,
                              load_line, load_rolling_stock, load_timetable)
from fmus.errors import FmuInputError
from fmus.signalling import cab_systems
from orchestrator.errors import RefusedComponents, UserError, print_warning
from orchestrator.graph import SystemGraph
from orchestrator.ports import split_element

#: a relative data file the graph did not resolve in the system is one of the FMU's own
#: resources/, which mirror the source tree (resources/fmus/data/shipped/…)
FMU_RESOURCES_ROOT = Path(fmus.__file__).resolve().parent.parent
SECTION_GAP_TOLERANCE_M = 1e-6
LENGTH_TOLERANCE_M = 0.5        # a rail line's train_length against the rolling-stock file's
TRAIN_MODEL = traction.MODEL_IDENTIFIER


def check_railway_data(graph: SystemGraph, warn: Callable[[str], None] = print_warning) -> None:
    """Raise a :class:`RefusedComponents` holding every defect of the system's data files
    (module docstring), its message the first; ``warn`` gets what is suspicious but runs."""
    defects: List[Tuple[str, FrozenSet[str]]] = []

    def note(error: UserError, refused: Iterable[str] = ()) -> None:
        defects.append((str(error), frozenset(refused)))

    def load(field: str, loader: Callable, default: Path, names: Iterable[str]) -> dict:
        """Each component's file of ``field``, loaded once per file; a file that does not load
        is one defect refusing every component that opens it. Returns component → loaded."""
        paths, cache = {}, {}
        for name in names:
            node = graph.nodes[name]
            path = _data_path(node.parameters.get(field), default) if field in node.interface.variables else None
            if path is not None:
                paths[name] = path
        for name, path in paths.items():
            if path not in cache:
                try:
                    cache[path] = _load(loader, path, f"{name}.{field}")
                except UserError as error:
                    cache[path] = None
                    note(error, [other for other, p in paths.items() if p == path])
        return {name: cache[path] for name, path in paths.items() if cache[path] is not None}

    lines: Dict[str, Line] = load("line_file", load_line, DEFAULT_LINE, graph.nodes)
    for line in {id(line): line for line in lines.values()}.values():
        try:
            check_sections_contiguous(line)
        except UserError as error:        # the FMUs run on such a line: nothing refuses it
            note(error)
    stocks: Dict[str, RollingStock] = load("rolling_stock_file", load_rolling_stock, DEFAULT_ROLLING_STOCK,
                                           graph.nodes)
    for name in lines:                    # a timetable is read against its component's line
        load("timetable_file", lambda p: load_timetable(p, lines[name]), DEFAULT_TIMETABLE, [name])
    # a code table is the one its component's system reads (ALSN's transmitters otherwise)
    for system, (loader, default) in CODE_TABLES.items():
        load("codes_file", loader, default, [name for name in graph.nodes if _system_of(graph, name) == system])
    paths = {name: _data_path(graph.nodes[name].parameters.get("line_file"), DEFAULT_LINE) for name in lines}
    for error in shared_line_problems(graph, paths):
        note(error)
    for error, refused in placement_problems(graph, lines, stocks, warn):
        note(error, refused)
    if defects:
        raise RefusedComponents(defects)


#: system → (loader, bundled default) of a ``codes_file``, from the cab-system descriptors; a
#: system without a table of its own (the digital ones): the default system's
CODE_TABLES = {cab.name: (cab.load_codes, cab.codes_file) for cab in cab_systems.REGISTRY.values() if cab.load_codes}


def _system_of(graph: SystemGraph, name: str) -> str:
    """The system whose code table a component's ``codes_file`` is (an unknown name: the default
    system's, the FMU refuses the name itself)."""
    system = str(graph.nodes[name].parameters.get("system", cab_systems.DEFAULT.name))
    return system if system in CODE_TABLES else cab_systems.DEFAULT.name


def check_sections_contiguous(line: Line) -> None:
    """Block sections follow each other without a gap (the loader refuses overlaps)."""
    for k in range(1, len(line.sections)):
        previous, section = line.sections[k - 1], line.sections[k]
        gap = section.start_m - previous.end_m
        if gap > SECTION_GAP_TOLERANCE_M:
            raise UserError(f"{line.path}: field block_sections[{k}].start_m: {section.start_m:g} m leaves a "
                            f"{gap:g} m gap after block_sections[{k - 1}] (ends {previous.end_m:g} m); "
                            "block sections must follow each other without a gap (no train is "
                            "detected on track without a track circuit)")


def shared_line_problems(graph: SystemGraph, lines: Dict[str, Path]) -> List[UserError]:
    """Components connected to each other that both take a line file run on the same line:
    one problem per connection between two different lines (nothing refuses it at
    initialisation: each component runs on its own)."""
    problems = []
    for edge in graph.edges:
        a, b = edge.source, edge.target
        if a == b or a not in lines or b not in lines or _same_file(lines[a], lines[b]):
            continue
        first, second = sorted((a, b))
        problems.append(UserError(
            f"{edge.origin}: {first}.line_file ({_shown(graph, first, lines)}) and "
            f"{second}.line_file ({_shown(graph, second, lines)}) differ, but "
            f"{edge.source}.{edge.source_var.name} feeds {edge.target}.{edge.target_var.name}: "
            "connected components (an ATO and its train, a train and its rail line, "
            "the rail line and its coder) must run on one line file"))
    return problems


def placement_problems(graph: SystemGraph, lines: Dict[str, Line], stocks: Dict[str, RollingStock],
                       warn: Callable[[str], None]) -> List[Tuple[UserError, FrozenSet[str]]]:
    """Every train on its line at t = 0, tail included; no two trains of one rail line
    overlapping (the rail line refuses that at initialisation: it is the component named);
    each rail line's ``train_length[j]`` the length of the train on slot j (a warning)."""
    problems: List[Tuple[UserError, FrozenSet[str]]] = []
    spans = {}                      # train → (name, head, length) at t = 0
    for name, node in graph.nodes.items():
        if node.interface.model_identifier != TRAIN_MODEL or name not in stocks or name not in lines:
            continue
        head_m, length_m, line = float(_parameter(node, "x0", 0.0)), stocks[name].length_m, lines[name]
        spans[name] = (name, head_m, length_m)
        for _, tail_m, _ in span_defects(line.length_m, [spans[name]])[0]:
            where = f"its tail at {tail_m:g} m is before the line start" if tail_m < 0.0 else "its head is beyond the line end"
            problems.append((UserError(
                f"{node.origin}: train {name!r} (head x0 = {head_m:g} m, {length_m:g} m long in "
                f"{_stock_name(node)}) is not on its line {Path(line.path).name} "
                f"(0..{line.length_m:g} m): {where}; place its head (x0) from {length_m:g} m to "
                f"{line.length_m:g} m"), frozenset()))
    for rail, node in graph.nodes.items():
        slots = sorted((split_element(e.target_var.name)[1][0], e.source) for e in graph.edges
                       if e.target == rail and e.target_var.name.startswith("x_head[") and e.source in spans)
        for slot, train in slots:
            given = _parameter(node, f"train_length[{slot}]", None)
            length_m = spans[train][2]
            if given is not None and abs(float(given) - length_m) > LENGTH_TOLERANCE_M:
                warn(f"{rail}.train_length[{slot}] = {float(given):g} m, but train {train!r} on that slot is "
                     f"{length_m:g} m long ({_stock_name(graph.nodes[train])}): the rail line shunts a train of "
                     f"another length; set {rail}.train_length[{slot}] = {length_m:g}")
            # where the rail line puts the wheelsets: the file it is given for the slot
            wheelsets = _parameter(node, f"rolling_stock_file[{slot}]", "") or str(DEFAULT_ROLLING_STOCK)
            try:
                theirs = load_rolling_stock(wheelsets).wheelset_offsets_m
            except (FmuInputError, OSError):
                theirs = None              # the rail line itself refuses it, naming the file
            ours = stocks[train].wheelset_offsets_m
            if theirs is not None and (len(theirs) != len(ours) or not np.allclose(theirs, ours, atol=1e-6)):
                warn(f"{rail}.rolling_stock_file[{slot}] is {Path(wheelsets).name}, but train {train!r} on that "
                     f"slot runs on {_stock_name(graph.nodes[train])}: the rail line shunts another train's "
                     f"wheelsets; set {rail}.rolling_stock_file[{slot}] to its file")
        if not slots:
            continue
        line_m = lines[rail].length_m if rail in lines else math.inf
        for (behind, _, head_m), (ahead, tail_m, _) in span_defects(line_m, [spans[t] for _, t in slots])[1]:
            problems.append((UserError(
                f"{node.origin}: trains {behind!r} (head {head_m:g} m) and {ahead!r} (tail "
                f"{tail_m:g} m) overlap at t = 0 on rail line {rail!r}; place them apart (x0)"), frozenset([rail])))
    return problems


Span = Tuple[str, float, float]                  # (train, tail_m, head_m)


def span_defects(line_length_m: float, trains: Iterable[Tuple[str, float, float]]
                 ) -> Tuple[List[Span], List[Tuple[Span, Span]]]:
    """The placement rule at t = 0 for trains given as (name, head_m, length_m): each must lie
    on the line 0..``line_length_m``, tail included, and no two of those on it may overlap
    (touching counts). Returns (the spans off the line, the overlapping pairs (behind, ahead)),
    spans as (name, tail_m, head_m), in order along the line; the callers word them."""
    spans = sorted(((name, head - length, head) for name, head, length in trains), key=lambda s: (s[1], s[2], s[0]))
    off = [s for s in spans if s[1] < 0.0 or s[2] > line_length_m]
    on = [s for s in spans if not (s[1] < 0.0 or s[2] > line_length_m)]
    return off, [(a, b) for a, b in zip(on, on[1:]) if b[1] <= a[2]]


# ---- helpers -------------------------------------------------------------------------------------
def _data_path(value, default: Path) -> Optional[Path]:
    """The file the FMU will open for a ``*_file`` parameter (resolved by the graph,
    orchestrator/graph.py resolve_data_file); None when the orchestrator cannot see it."""
    if not value:
        return Path(default)
    path = Path(str(value))
    if path.is_absolute() or path.is_file():
        return path
    candidate = FMU_RESOURCES_ROOT / path
    return candidate if candidate.is_file() else None


def _parameter(node, name: str, default):
    """A parameter as the FMU will read it: the system's value, else the FMU's start value."""
    if name in node.parameters:
        return node.parameters[name]
    var = node.interface.variables.get(name)
    return default if var is None or var.start is None else var.start


def _stock_name(node) -> str:
    value = node.parameters.get("rolling_stock_file")
    return f"{Path(str(value)).name}" if value else f"the bundled default {Path(DEFAULT_ROLLING_STOCK).name}"


def load_data_file(loader: Callable, path: Path, labelled: Callable[[str], str]):
    """``loader(path)``, a file it refuses a UserError: the loader's one line (or what Python's
    JSON reader met: a document nested too deeply, bytes that are not UTF-8) as ``labelled``
    words it with what names the file (a component's field, a command-line option)."""
    try:
        return loader(path)
    except FmuInputError as error:
        problem = str(error)
    except RecursionError:
        problem = f"{path}: not valid JSON (nested too deeply)"
    except UnicodeDecodeError:
        problem = f"{path}: not valid JSON (not UTF-8 text)"
    raise UserError(labelled(problem))


def _load(loader: Callable, path: Path, what: str):
    return load_data_file(loader, path, lambda problem: f"{problem} ({what})")


def _same_file(a: Path, b: Path) -> bool:
    try:
        return a == b or a.resolve() == b.resolve() or filecmp.cmp(a, b, shallow=False)
    except OSError:
        return False


def _shown(graph: SystemGraph, name: str, lines: Dict[str, Path]) -> str:
    value = graph.nodes[name].parameters.get("line_file")
    return str(lines[name]) if value else f"the bundled default {Path(DEFAULT_LINE).name}"

"""System graph: components resolved against their FMUs, checked connections, rates, order.

Pure data and checks: nothing here steps an FMU. Every defect is a UserError naming the
file and line of the SSD element it comes from. :func:`graph_of` builds a graph in memory,
without an SSD or FMU files (slaves that are not FMUs: tests, studies).
"""
from __future__ import annotations

import math
import os
import zipfile
from dataclasses import dataclass, field
from functools import reduce
from pathlib import Path
from typing import Callable, Dict, List, Optional, Sequence, Tuple

from orchestrator.errors import UserError, did_you_mean
from orchestrator.fmu import Interface, Variable, read_interface
from orchestrator.ports import base_of
from orchestrator.protocols import TRANSITIONS, Transition, UnitDef
from orchestrator.ssp import Component, Connection, SystemDescription

TICKS_PER_SECOND = 1_000_000_000  # the master's clock: integer nanoseconds
#: the longest time a run may reach or name, its one bound (the stop time, the output interval,
#: a capture window, a scenario event): 10⁶ s, 11.6 days of simulated time. The master's clock
#: (int64 nanoseconds) alone would hold 292 years, but a frame's sample instants are computed
#: as the integers start·N + k·h (orchestrator/observers.py sample_times), within int64 up to
#: 10⁶ s for frames of up to 9223 samples (the build's largest frame is 4096)
MAX_TIME_S = 1e6


def seconds_to_ticks(seconds: float, what: str) -> int:
    if not math.isfinite(seconds * TICKS_PER_SECOND):
        raise UserError(f"{what}: {seconds!r} s is not a finite number of seconds")
    ticks = round(seconds * TICKS_PER_SECOND)
    if ticks <= 0 or abs(ticks - seconds * TICKS_PER_SECOND) > 1e-3:
        raise UserError(f"{what}: {seconds!r} s is not a positive whole number of nanoseconds")
    return ticks


def convert_unit(from_unit: Optional[str], to_unit: Optional[str],
                 units: Dict[str, UnitDef], origin: str) -> Tuple[float, float]:
    """(factor, offset) mapping a value in ``from_unit`` to ``to_unit``; identity when equal."""
    if not from_unit or not to_unit or from_unit == to_unit:
        return 1.0, 0.0
    src, dst = units.get(from_unit), units.get(to_unit)
    if src is None or dst is None:
        missing = from_unit if src is None else to_unit
        raise UserError(f"{origin}: unit {missing!r} has no definition; cannot convert "
                        f"{from_unit!r} to {to_unit!r}")
    if src.exponents != dst.exponents:
        raise UserError(f"{origin}: units {from_unit!r} and {to_unit!r} are of different kinds")
    factor = src.factor / dst.factor
    return factor, (src.offset - dst.offset) / dst.factor


def check_connectors(component: Component, variables: Dict[str, Tuple[str, str, Optional[str]]]) -> None:
    """A component's declared connectors against its FMU's variables (name → causality, type,
    unit): a connector the FMU lacks, of another kind (causality) or type, or in another unit
    (we convert units along connections from the FMUs' units, not at connectors) is an error
    naming the SSD line and the component. A component without connectors is not checked."""
    for name, (kind, ctype, cunit) in component.connectors.items():
        what = f"{component.origin}: component {component.name!r}: connector {name!r}"
        if name not in variables:
            raise UserError(f"{what} does not exist in {component.fmu_path}")
        causality, vtype, vunit = variables[name]
        if kind != causality:
            raise UserError(f"{what} is declared kind={kind!r} but the FMU has causality {causality!r}")
        if ctype and ctype != vtype:
            raise UserError(f"{what} is declared {ctype} but the FMU has {vtype}")
        if cunit and vunit and cunit != vunit:
            raise UserError(f"{what} is declared in {cunit!r} but the FMU's unit is {vunit!r} "
                            "(conversion at a connector is not supported)")


@dataclass
class Node:
    name: str
    interface: Interface
    fmu_path: str
    step_ticks: int
    origin: str
    parameters: Dict[str, object] = field(default_factory=dict)


@dataclass
class Edge:
    source: str
    source_var: Variable
    target: str
    target_var: Variable
    factor: float
    offset: float
    transition: Transition
    origin: str


@dataclass
class SystemGraph:
    name: str
    nodes: Dict[str, Node]
    edges: List[Edge]
    order: List[str]
    base_ticks: int
    cycles: List[List[str]]


def build_graph(system: SystemDescription, overrides: Dict[str, object] = None,
                extra_parameters=(), interface_of: Callable[[str], Interface] = read_interface) -> SystemGraph:
    """The graph of ``system``: ``interface_of`` reads a component's ports from its source (an
    FMU by default; a run passes one that also reads a DCP slave's .dcpx, orchestrator/dcp/)."""
    nodes: Dict[str, Node] = {}
    for comp in system.components.values():
        if comp.fmu_path is None:
            raise UserError(f"{comp.origin}: component {comp.name!r} has no source FMU")
        interface = interface_of(comp.fmu_path)
        step = comp.step_size_s if comp.step_size_s is not None else interface.default_step_s
        if step is None:
            raise UserError(f"{comp.origin}: component {comp.name!r} has no step size "
                            "(add <rcs:StepSize> or osp:StepSizeHint)")
        ticks = seconds_to_ticks(step, f"{comp.step_origin}: step size of {comp.name!r}")
        nodes[comp.name] = Node(comp.name, interface, str(comp.fmu_path), ticks, comp.origin)
        check_connectors(comp, {v.name: (v.causality, v.type, v.unit) for v in interface.variables.values()})
        units = {**interface.units, **system.units}
        for value in comp.parameters:
            _bind_parameter(nodes[comp.name], value.name, value, units)
    for value in list(system.system_parameters) + list(extra_parameters):
        comp_name, _, var_name = value.name.partition(".")
        if comp_name not in nodes or not var_name:
            raise UserError(f"{value.origin}: parameter {value.name!r} names no component of the system")
        units = {**nodes[comp_name].interface.units, **system.units}
        _bind_parameter(nodes[comp_name], var_name, value, units)
    for key, raw in (overrides or {}).items():
        comp_name, _, var_name = key.partition(".")
        node = nodes.get(comp_name)
        if node is None or var_name not in node.interface.variables:
            raise UserError(f"--set {key}: no such variable (component {comp_name!r}"
                            f"{' exists' if node else ' does not exist'})"
                            + closest_variable(nodes, key, lambda v: v.causality in ("parameter", "input")))
        var = node.interface.variables[var_name]
        if var.causality not in ("parameter", "input"):
            raise UserError(f"--set {key}: {var.causality} variables cannot be set")
        node.parameters[var_name] = _parse_value(var, raw, f"--set {key}")
    for node in nodes.values():
        for name, value in node.parameters.items():
            if base_of(name).endswith("_file"):       # rolling_stock_file[2] too
                node.parameters[name] = resolve_data_file(value, system.folder)
                _check_data_file(node, name, system.folder)

    edges = [_edge(system, nodes, conn) for conn in system.connections]
    _check_one_driver(edges)
    base = _base_ticks(nodes, system.base_step_s, f"{system.ssd_path}: BaseStep")
    order, cycles = _order(list(nodes), edges)
    return SystemGraph(system.name, nodes, edges, order, base, cycles)


def closest_variable(nodes: Dict[str, "Node"], key: str, accept: Callable[[Variable], bool]) -> str:
    """``; did you mean COMPONENT.VARIABLE?`` for a mistyped ``COMP.VAR`` (--set, --record,
    --capture): among the component's variables that ``accept`` takes, or, for a component the
    system has not, among the components with that variable, else among the components."""
    component, _, variable = key.partition(".")
    node = nodes.get(component)
    if node is not None:
        return did_you_mean(key, [f"{component}.{v.name}" for v in node.interface.variables.values() if accept(v)])
    having = [f"{name}.{variable}" for name, other in nodes.items()
              if variable in other.interface.variables and accept(other.interface.variables[variable])]
    return did_you_mean(key, having) if having else did_you_mean(component, nodes)


def resolve_data_file(value, system_folder: Path):
    """The one rule for a relative ``*_file`` parameter (docs/interfaces.md, SSP conventions,
    "Data files"): a file in the system's resources/ folder, else in the system folder;
    anything else (an absolute path, an empty value for the bundled default, a name found in
    neither) is left as given, for the FMU to resolve against its own resources."""
    if not isinstance(value, str) or not value or os.path.isabs(value):
        return value
    for folder in (Path(system_folder) / "resources", Path(system_folder)):
        if (folder / value).is_file():
            return str((folder / value).resolve())
    return value


def _check_data_file(node: Node, name: str, system_folder: Path) -> None:
    """A ``*_file`` parameter must name a file the FMU will find: resolved in the system
    (absolute by now), absolute, relative to the working folder, or one of the FMU's own
    resources/ — else an error naming where it was looked for first (the system's resources/;
    inside an .ssp: ``<archive>!resources/<name>``), instead of the FMU failing later with
    its own extraction folder in the message."""
    value = node.parameters[name]
    if not isinstance(value, str) or not value:
        return                                   # the FMU's bundled default
    if os.path.isabs(value):
        if not os.path.isfile(value):
            raise UserError(f"{value}: file not found ({node.name}.{name})")
        return
    if os.path.isfile(value) or _in_fmu_resources(node.fmu_path, value):
        return
    raise UserError(f"{Path(system_folder) / 'resources' / value}: file not found ({node.name}.{name} = "
                    f"{value!r}: looked for in the system's resources/ and folder and in "
                    f"{Path(node.fmu_path).name}'s resources/)")


def _in_fmu_resources(fmu_path: str, value: str) -> bool:
    member = "resources/" + Path(value).as_posix().lstrip("./")
    try:
        with zipfile.ZipFile(fmu_path) as archive:
            return member in archive.namelist()
    except (OSError, zipfile.BadZipFile):
        return False


def _check_one_driver(edges: List[Edge]) -> None:
    """An input takes one connection: a second one ending at the same input is refused, with or
    without ``suppressUnitConversion`` or a transformation (which value would it see?)."""
    drivers: Dict[Tuple[str, str], Edge] = {}
    for edge in edges:
        key = (edge.target, edge.target_var.name)
        first = drivers.setdefault(key, edge)
        if first is not edge:
            raise UserError(f"{edge.origin}: input {edge.target}.{edge.target_var.name} already has a "
                            f"connection (from {first.source}.{first.source_var.name}, {first.origin}); "
                            "an input takes exactly one")


def graph_of(name: str, components: Sequence[Tuple[str, Interface, float]],
             connections: Sequence[tuple], base_step_s: Optional[float] = None) -> SystemGraph:
    """A graph built in memory from its parts, with the checks and the ordering of
    :func:`build_graph` (no SSD, no FMU files, no units, no parameters).

    ``components``: (name, interface, step in s) in declaration order (it breaks cycles);
    ``connections``: ("source.output", "target.input") or ("source.output", "target.input",
    transition)."""
    nodes: Dict[str, Node] = {}
    for component, interface, step_s in components:
        origin = f"{name}: component {component!r}"
        nodes[component] = Node(component, interface, "", seconds_to_ticks(step_s, f"{origin}: step size"), origin)
    edges = []
    for index, (start, end, *rest) in enumerate(connections):
        origin = f"{name}: connection {index} ({start} → {end})"
        transition = rest[0] if rest else "hold"
        if transition not in TRANSITIONS:
            raise UserError(f"{origin}: rate transition {transition!r} unknown (use {', '.join(TRANSITIONS)})")
        ends = []
        for path, role in ((start, "start"), (end, "end")):
            element, _, connector = path.partition(".")
            ends.append(_connection_end(nodes, element, connector, role, origin))
        (src, svar), (dst, dvar) = ends
        _check_connection(src, svar, dst, dvar, origin)
        _check_transition(svar, transition, origin)
        edges.append(Edge(src.name, svar, dst.name, dvar, 1.0, 0.0, transition, origin))
    _check_one_driver(edges)
    base = _base_ticks(nodes, base_step_s, f"{name}: base step")
    order, cycles = _order(list(nodes), edges)
    return SystemGraph(name, nodes, edges, order, base, cycles)


def _parse_value(var: Variable, raw, what: str):
    if not isinstance(raw, str):
        return raw
    try:
        if var.type == "Real":
            if not math.isfinite(float(raw)):
                raise ValueError
            return float(raw)
        if var.type == "Integer":
            if not -2 ** 31 <= int(raw) < 2 ** 31:
                raise ValueError
            return int(raw)
        if var.type == "Boolean":
            if raw.lower() not in ("true", "false", "1", "0"):
                raise ValueError
            return raw.lower() in ("true", "1")
    except ValueError:
        raise UserError(f"{what}: {raw!r} is not a valid {var.type}") from None
    return raw


def _bind_parameter(node: Node, var_name: str, value, units) -> None:
    var = node.interface.variables.get(var_name)
    if var is None:
        raise UserError(f"{value.origin}: parameter {var_name!r} does not exist in component {node.name!r}")
    if var.causality not in ("parameter", "input"):
        raise UserError(f"{value.origin}: {node.name}.{var_name} is an {var.causality}; "
                        "only parameters and inputs can be bound")
    if var.type != value.type:
        raise UserError(f"{value.origin}: {node.name}.{var_name} is {var.type}, the binding gives {value.type}")
    result = value.value
    if var.type == "Real":
        factor, offset = convert_unit(value.unit, var.unit, units, value.origin)
        result = result * factor + offset
    node.parameters[var_name] = result


def _connection_end(nodes: Dict[str, Node], element: str, connector: str, role: str,
                    origin: str) -> Tuple[Node, Variable]:
    node = nodes.get(element)
    if node is None:
        raise UserError(f"{origin}: connection {role} names component {element!r}, "
                        "which is not in the system")
    var = node.interface.variables.get(connector)
    if var is None:
        raise UserError(f"{origin}: connection {role} {element}.{connector} does not exist")
    return node, var


def _check_connection(src: Node, svar: Variable, dst: Node, dvar: Variable, origin: str) -> None:
    if svar.causality != "output":
        raise UserError(f"{origin}: connection starts at {src.name}.{svar.name}, which is "
                        f"an {svar.causality}, not an output")
    if dvar.causality != "input":
        raise UserError(f"{origin}: connection ends at {dst.name}.{dvar.name}, which is "
                        f"an {dvar.causality}, not an input")
    if svar.type != dvar.type:
        raise UserError(f"{origin}: type mismatch: {src.name}.{svar.name} is {svar.type}, "
                        f"{dst.name}.{dvar.name} is {dvar.type}")


def _check_transition(svar: Variable, transition: str, origin: str) -> None:
    if transition != "hold" and svar.type != "Real":
        raise UserError(f"{origin}: rate transition {transition!r} needs Real values")


def _edge(system: SystemDescription, nodes: Dict[str, Node], conn: Connection) -> Edge:
    (src, svar), (dst, dvar) = (
        _connection_end(nodes, element, connector, role, conn.origin)
        for element, connector, role in ((conn.start_element, conn.start_connector, "start"),
                                         (conn.end_element, conn.end_connector, "end")))
    _check_connection(src, svar, dst, dvar, conn.origin)
    factor, offset = conn.factor, conn.offset
    if (factor, offset) != (1.0, 0.0) and svar.type != "Real":
        raise UserError(f"{conn.origin}: LinearTransformation applies to Real connections only")
    if svar.type == "Real" and not conn.suppress_unit_conversion:
        units = {**src.interface.units, **dst.interface.units, **system.units}
        # SSP: the transformation acts on the start value in the start connector's unit,
        # then the result is converted to the end connector's unit.
        unit_factor, unit_offset = convert_unit(svar.unit, dvar.unit, units, conn.origin)
        factor, offset = factor * unit_factor, offset * unit_factor + unit_offset
    _check_transition(svar, conn.transition, conn.origin)
    return Edge(src.name, svar, dst.name, dvar, factor, offset, conn.transition, conn.origin)


def _base_ticks(nodes: Dict[str, Node], base_step_s: Optional[float], where: str) -> int:
    """The declared base step, checked against every component's step; by default their
    greatest common divisor."""
    steps = [n.step_ticks for n in nodes.values()]
    if base_step_s is None:
        return reduce(math.gcd, steps)
    base = seconds_to_ticks(base_step_s, where)
    for node in nodes.values():
        if node.step_ticks % base:
            raise UserError(f"{node.origin}: step size {node.step_ticks / TICKS_PER_SECOND:g} s of "
                            f"{node.name!r} is not a multiple of the base step {base / TICKS_PER_SECOND:g} s")
    return base


def _order(names: List[str], edges: List[Edge]) -> Tuple[List[str], List[List[str]]]:
    """Topological order along the data flow; cycles are broken by declaration order."""
    successors = {n: set() for n in names}
    indegree = {n: 0 for n in names}
    for edge in edges:
        if edge.source != edge.target and edge.target not in successors[edge.source]:
            successors[edge.source].add(edge.target)
            indegree[edge.target] += 1
    order, cycles = [], []
    remaining = list(names)
    while remaining:
        ready = [n for n in remaining if indegree[n] == 0]
        if not ready:
            # a cycle: take the first declared component among those left, and report the
            # components in a cycle with it (not all those left: with N trains that listed
            # every later train's loop again, N² names in metadata.json)
            cycles.append(_cycle_through(remaining, successors))
            ready = [remaining[0]]
        for name in ready[:1]:
            order.append(name)
            remaining.remove(name)
            for succ in successors[name]:
                indegree[succ] -= 1
    return order, cycles


def _cycle_through(remaining: List[str], successors: Dict[str, set]) -> List[str]:
    """The components among ``remaining`` in a cycle with its first (its strongly connected
    component), in declaration order."""
    left = set(remaining)
    predecessors: Dict[str, set] = {n: set() for n in remaining}
    for name in remaining:
        for succ in successors[name] & left:
            predecessors[succ].add(name)

    def reached(links: Dict[str, set]) -> set:
        seen, todo = {remaining[0]}, [remaining[0]]
        while todo:
            for other in links[todo.pop()] & left:
                if other not in seen:
                    seen.add(other)
                    todo.append(other)
        return seen

    both = reached({n: successors[n] for n in remaining}) & reached(predecessors)
    return [n for n in remaining if n in both]

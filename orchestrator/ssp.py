"""SSP 1.0 loading: system description, parameter values and mappings → plain dataclasses.

Files are validated against the SSP 1.0 schemas that fmpy ships, then read with lxml so that
every error can name file, line and element. Supported exactly as the standard says:
ParameterBindings (external .ssv and inline ParameterValues, prefix), SSM ParameterMapping
(with Linear, Boolean and Integer mapping transformations), LinearTransformation and
connector units on connections (unit definitions from the SSD, the SSV or the FMU's
modelDescription). Anything else that would change the result (Enumeration or Binary
parameters, EnumerationMappingTransformation, sub-systems, signal dictionaries) is an error
naming the element; it is never silently ignored.
"""
from __future__ import annotations

import math
import shutil
import tempfile
from dataclasses import dataclass, field
from pathlib import Path, PurePosixPath
from typing import Dict, List, Optional, Tuple

from lxml import etree

from orchestrator.archives import safe_extract
from orchestrator.errors import UserError, forget_archive, register_archive, where
from orchestrator.library_shortcuts import ssp_schema
from orchestrator.protocols import TRANSITIONS, UnitDef

NS = {
    "ssc": "http://ssp-standard.org/SSP1/SystemStructureCommon",
    "ssd": "http://ssp-standard.org/SSP1/SystemStructureDescription",
    "ssv": "http://ssp-standard.org/SSP1/SystemStructureParameterValues",
    "ssm": "http://ssp-standard.org/SSP1/SystemStructureParameterMapping",
}
RCS_ANNOTATION = "org.railcosim"
RCS_NS = "http://railcosim.org/SSP/1"
OSP_ANNOTATION = "com.opensimulationplatform"
OSP_NS = "http://opensimulationplatform.com/SSP/OSPAnnotations"
RATE_TRANSITIONS = TRANSITIONS            # hold, linear, mean (orchestrator/protocols.py)
_SCHEMAS: Dict[str, etree.XMLSchema] = {}


@dataclass
class ParameterValue:
    name: str            # name as it resolves in the element ("var" or "component.var")
    type: str            # Real | Integer | Boolean | String
    value: object
    unit: Optional[str]
    origin: str          # file:line for messages


@dataclass
class Component:
    name: str
    source: str          # as written in the SSD
    fmu_path: Optional[Path]
    step_size_s: Optional[float]
    step_origin: str
    connectors: Dict[str, Tuple[str, str, Optional[str]]]  # name → (kind, type, unit)
    parameters: List[ParameterValue]
    origin: str
    #: a DCP slave's address (host, port and options as written in rcs:DcpSlave), else None
    dcp_slave: Optional[Dict[str, str]] = None


@dataclass
class Connection:
    start_element: str
    start_connector: str
    end_element: str
    end_connector: str
    factor: float = 1.0
    offset: float = 0.0
    transition: str = "hold"
    suppress_unit_conversion: bool = False
    origin: str = ""


@dataclass
class SystemDescription:
    name: str
    folder: Path
    ssd_path: Path
    components: Dict[str, Component]
    connections: List[Connection]
    start_time: float = 0.0
    stop_time: Optional[float] = None
    base_step_s: Optional[float] = None
    units: Dict[str, UnitDef] = field(default_factory=dict)
    system_parameters: List[ParameterValue] = field(default_factory=list)
    temp_dir: Optional[str] = None

    def close(self) -> None:
        if self.temp_dir:
            shutil.rmtree(self.temp_dir, ignore_errors=True)
            forget_archive(self.temp_dir)
            self.temp_dir = None


def _unpack_archive(path: Path) -> str:
    """Unpack an .ssp into a new temporary folder; from now on messages naming a file in it
    name ``<archive>!<member>`` (orchestrator/errors.py, shown_paths)."""
    temp_dir = tempfile.mkdtemp(prefix="railcosim_ssp_")
    register_archive(temp_dir, path)
    try:
        safe_extract(path, Path(temp_dir))
    except BaseException:
        shutil.rmtree(temp_dir, ignore_errors=True)
        forget_archive(temp_dir)
        raise
    return temp_dir


# ---- schema validation -------------------------------------------------------------------------
def _schema(name: str) -> etree.XMLSchema:
    if name not in _SCHEMAS:
        _SCHEMAS[name] = etree.XMLSchema(file=str(ssp_schema(name)))
    return _SCHEMAS[name]


def parse_validated(path: Path, schema_name: str) -> etree._Element:
    if not path.is_file():
        raise UserError(f"{path}: file not found")
    try:
        tree = etree.parse(str(path))
    except etree.XMLSyntaxError as error:
        raise UserError(f"{path}:{error.lineno}: not well-formed XML: {error.msg}") from None
    schema = _schema(schema_name)
    if not schema.validate(tree):
        entry = schema.error_log[0]
        raise UserError(f"{path}:{entry.line}: fails the SSP 1.0 schema {schema_name}: {entry.message}")
    return tree.getroot()


def _local(element) -> str:
    return etree.QName(element).localname


def _float(element, attribute, default=None):
    value = element.get(attribute)
    return default if value is None else _finite(value, element, attribute)


def _finite(text: str, element, what: str) -> float:
    """A number from the file that must be finite (the schemas' xs:double admits NaN and INF);
    else an error naming file, line and ``what``."""
    try:
        value = float(text)
    except (TypeError, ValueError):
        value = None
    if value is None or not math.isfinite(value):
        origin = where(element.getroottree().docinfo.URL, element.sourceline)
        raise UserError(f"{origin}: {what} = {text!r} is not a finite number")
    return value


def _annotation_seconds(child, ssd_path: Path, attribute: str = "value") -> Tuple[float, str]:
    """The ``value`` of a step annotation (rcs:StepSize, osp:StepSizeHint, rcs:BaseStep; the
    ``baseStepSize`` of osp:FixedStepAlgorithm): a positive finite number of seconds, else an
    error naming file, line and the annotation."""
    origin = where(ssd_path, child.sourceline)
    text = child.get(attribute)
    try:
        value = float(text)
    except (TypeError, ValueError):
        value = None
    if value is None or not math.isfinite(value) or value <= 0:
        raise UserError(f"{origin}: {etree.QName(child).localname} {attribute} {text!r} is not a "
                        "positive number of seconds")
    return value, origin


# ---- units ------------------------------------------------------------------------------------
_BASE_ORDER = ("kg", "m", "s", "A", "K", "mol", "cd", "rad")


def read_units(units_element, path: Path) -> Dict[str, UnitDef]:
    units = {}
    if units_element is None:
        return units
    for unit in units_element.findall("ssc:Unit", NS):
        base = unit.find("ssc:BaseUnit", NS)
        exps = tuple(int(base.get(k, 0)) for k in _BASE_ORDER)
        units[unit.get("name")] = UnitDef(unit.get("name"), exps, _float(base, "factor", 1.0),
                                          _float(base, "offset", 0.0))
    return units


# ---- parameter values and mappings -------------------------------------------------------------
def _read_parameter_set(parameter_set, path: Path, prefix: str) -> Tuple[List[ParameterValue], Dict[str, UnitDef]]:
    values = []
    for parameter in parameter_set.findall("ssv:Parameters/ssv:Parameter", NS):
        name = prefix + parameter.get("name")
        typed = [child for child in parameter if _local(child) != "Annotations"][0]
        kind = _local(typed)
        origin = where(path, typed.sourceline)
        if kind == "Real":
            value = _finite(typed.get("value"), typed, f"Real parameter {name!r}")
        elif kind == "Integer":
            value = int(typed.get("value"))
        elif kind == "Boolean":
            value = typed.get("value") in ("true", "1")
        elif kind == "String":
            value = typed.get("value")
        else:
            raise UserError(f"{origin}: ssv:{kind} parameter {name!r} is not supported "
                            "(Real, Integer, Boolean and String are)")
        values.append(ParameterValue(name, kind, value, typed.get("unit"), origin))
    return values, read_units(parameter_set.find("ssv:Units", NS), path)


def _read_mapping(path: Path) -> Dict[str, Tuple[str, Optional[tuple], str]]:
    root = parse_validated(path, "SystemStructureParameterMapping.xsd")
    mapping = {}
    for entry in root.findall("ssm:MappingEntry", NS):
        origin = where(path, entry.sourceline)
        transform = None
        for child in entry:
            kind = _local(child)
            if kind == "LinearTransformation":
                transform = ("linear", _float(child, "factor", 1.0), _float(child, "offset", 0.0))
            elif kind in ("BooleanMappingTransformation", "IntegerMappingTransformation"):
                table = {}
                for item in child.findall("ssc:MapEntry", NS):
                    cast = (lambda v: v in ("true", "1")) if kind.startswith("Boolean") else int
                    table[cast(item.get("source"))] = cast(item.get("target"))
                transform = ("table", table)
            elif kind != "Annotations":
                raise UserError(f"{where(path, child.sourceline)}: ssc:{kind} is not supported "
                                "in a parameter mapping")
        mapping[entry.get("source")] = (entry.get("target"), transform, origin)
    return mapping


def _apply_mapping(values: List[ParameterValue], mapping) -> List[ParameterValue]:
    if mapping is None:
        return values
    mapped = []
    for value in values:
        if value.name not in mapping:
            mapped.append(value)
            continue
        target, transform, origin = mapping[value.name]
        new_value = value.value
        if transform and transform[0] == "linear":
            if value.type != "Real":
                raise UserError(f"{origin}: LinearTransformation applies to Real parameters, "
                                f"{value.name!r} is {value.type}")
            new_value = value.value * transform[1] + transform[2]
        elif transform and transform[0] == "table":
            if value.value not in transform[1]:
                raise UserError(f"{origin}: value {value.value!r} of {value.name!r} has no map entry")
            new_value = transform[1][value.value]
        mapped.append(ParameterValue(target, value.type, new_value, value.unit, origin))
    return mapped


def _read_bindings(bindings_element, folder: Path, ssd_path: Path,
                   units: Dict[str, UnitDef]) -> List[ParameterValue]:
    values: List[ParameterValue] = []
    if bindings_element is None:
        return values
    for binding in bindings_element.findall("ssd:ParameterBinding", NS):
        origin = where(ssd_path, binding.sourceline)
        kind = binding.get("type", "application/x-ssp-parameter-set")
        if kind != "application/x-ssp-parameter-set":
            raise UserError(f"{origin}: ParameterBinding type {kind!r} is not supported")
        prefix = binding.get("prefix", "")
        source = binding.get("source")
        if source:
            ssv_path = folder / source
            root = parse_validated(ssv_path, "SystemStructureParameterValues.xsd")
            binding_values, ssv_units = _read_parameter_set(root, ssv_path, prefix)
        else:
            inline = binding.find("ssd:ParameterValues/ssv:ParameterSet", NS)
            if inline is None:
                raise UserError(f"{origin}: ParameterBinding has neither a source nor inline ParameterValues")
            binding_values, ssv_units = _read_parameter_set(inline, ssd_path, prefix)
        units.update(ssv_units)
        mapping_element = binding.find("ssd:ParameterMapping", NS)
        mapping = None
        if mapping_element is not None:
            if mapping_element.get("source"):
                mapping = _read_mapping(folder / mapping_element.get("source"))
            else:
                raise UserError(f"{where(ssd_path, mapping_element.sourceline)}: inline parameter "
                                "mappings are not supported; reference an .ssm file")
        values.extend(_apply_mapping(binding_values, mapping))
    return values


# ---- annotations -------------------------------------------------------------------------------
def _step_size(component, ssd_path: Path) -> Tuple[Optional[float], str]:
    ours, osp = None, None
    for annotation in component.findall("ssd:Annotations/ssc:Annotation", NS):
        for child in annotation:
            if _local(child) == "StepSize" and annotation.get("type") == RCS_ANNOTATION:
                ours = _annotation_seconds(child, ssd_path)
            elif _local(child) == "StepSizeHint" and annotation.get("type") == OSP_ANNOTATION:
                osp = _annotation_seconds(child, ssd_path)
    chosen = ours or osp
    return (chosen[0], chosen[1]) if chosen else (None, where(ssd_path, component.sourceline))


#: [U] the component type of a DCP slave (SSP names no type for one)
DCP_COMPONENT_TYPE = "application/x-dcp-slave"


def _dcp_slave(component, ssd_path: Path) -> Optional[Dict[str, str]]:
    """``<rcs:DcpSlave host=… port=… [deadline_ms=…] [timeout_s=…]/>`` in the component's
    railcosim annotation; its source must be the slave's .dcpx."""
    for annotation in component.findall("ssd:Annotations/ssc:Annotation", NS):
        for child in annotation:
            if _local(child) == "DcpSlave" and annotation.get("type") == RCS_ANNOTATION:
                if not (component.get("source") or "").endswith(".dcpx"):
                    raise UserError(f"{where(ssd_path, child.sourceline)}: component {component.get('name')!r}: "
                                    "a DcpSlave's source must be its .dcpx")
                return dict(child.attrib)
    return None


def _transition(connection, ssd_path: Path) -> str:
    for annotation in connection.findall("ssd:Annotations/ssc:Annotation", NS):
        if annotation.get("type") != RCS_ANNOTATION:
            continue
        for child in annotation:
            if _local(child) == "RateTransition":
                kind = child.get("kind", "hold")
                if kind not in RATE_TRANSITIONS:
                    raise UserError(f"{where(ssd_path, child.sourceline)}: rate transition {kind!r} "
                                    f"unknown (use {', '.join(RATE_TRANSITIONS)})")
                return kind
    return "hold"


def _base_step(experiment, ssd_path: Path) -> Optional[float]:
    """The DefaultExperiment's base step: ``rcs:BaseStep``, else the baseStepSize of
    ``osp:Algorithm/osp:FixedStepAlgorithm`` (what libcosim reads); None when neither is given."""
    ours, osp = None, None
    for annotation in experiment.findall("ssd:Annotations/ssc:Annotation", NS):
        for child in annotation:
            if _local(child) == "BaseStep" and annotation.get("type") == RCS_ANNOTATION:
                ours = _annotation_seconds(child, ssd_path)[0]
            elif _local(child) == "Algorithm" and annotation.get("type") == OSP_ANNOTATION:
                fixed = [a for a in child if _local(a) == "FixedStepAlgorithm" and a.get("baseStepSize")]
                osp = _annotation_seconds(fixed[0], ssd_path, "baseStepSize")[0] if fixed else osp
    return ours if ours is not None else osp


# ---- system ------------------------------------------------------------------------------------
def open_system(path: Path, fmu_dirs: List[Path] = ()) -> SystemDescription:
    """Load a system from a folder holding SystemStructure.ssd or from a .ssp archive."""
    path = Path(path)
    temp_dir = None
    if not path.is_file() and not path.is_dir():
        raise UserError(f"{path}: no such system (give a folder with SystemStructure.ssd or a .ssp file)")
    try:  # the extraction folder goes whatever fails while opening (a refused or corrupt archive too)
        if path.is_file():
            temp_dir = _unpack_archive(path)
            folder = Path(temp_dir)
        else:
            folder = path
        system = read_ssd(folder / "SystemStructure.ssd", folder, fmu_dirs)
    except BaseException:
        if temp_dir:
            shutil.rmtree(temp_dir, ignore_errors=True)
            forget_archive(temp_dir)
        raise
    system.temp_dir = temp_dir
    return system


def read_ssd(ssd_path: Path, folder: Path, fmu_dirs: List[Path] = ()) -> SystemDescription:
    root = parse_validated(ssd_path, "SystemStructureDescription.xsd")
    system = root.find("ssd:System", NS)
    units = read_units(root.find("ssd:Units", NS), ssd_path)
    for unsupported in ("ssd:SignalDictionaries", "ssd:Elements/ssd:System",
                        "ssd:Elements/ssd:SignalDictionaryReference"):
        found = system.find(unsupported, NS)
        if found is not None:
            raise UserError(f"{where(ssd_path, found.sourceline)}: {unsupported.split('/')[-1]} "
                            "is not supported (flat systems of FMU components only)")
    components: Dict[str, Component] = {}
    for element in system.findall("ssd:Elements/ssd:Component", NS):
        origin = where(ssd_path, element.sourceline)
        name = element.get("name")
        _check_unique_component(components, name, origin)
        kind = element.get("type", "application/x-fmu-sharedlibrary")
        dcp = _dcp_slave(element, ssd_path)       # a DCP slave: a .dcpx and its address
        if kind != "application/x-fmu-sharedlibrary" and not (dcp and kind == DCP_COMPONENT_TYPE):
            raise UserError(f"{origin}: component {name!r} of type {kind!r} is not supported")
        if element.get("implementation", "any") not in ("any", "CoSimulation"):
            raise UserError(f"{origin}: component {name!r} asks for implementation "
                            f"{element.get('implementation')!r}; only CoSimulation is supported")
        connectors = {}
        for connector in element.findall("ssd:Connectors/ssd:Connector", NS):
            typed = [c for c in connector if _local(c) in ("Real", "Integer", "Boolean", "String", "Enumeration", "Binary")]
            ctype = _local(typed[0]) if typed else None
            cunit = typed[0].get("unit") if typed else None
            connectors[connector.get("name")] = (connector.get("kind"), ctype, cunit)
        step, step_origin = _step_size(element, ssd_path)
        source = element.get("source")
        components[name] = Component(
            name=name, source=source, fmu_path=resolve_fmu(folder, source, fmu_dirs),
            step_size_s=step, step_origin=step_origin, connectors=connectors,
            parameters=_read_bindings(element.find("ssd:ParameterBindings", NS), folder, ssd_path, units),
            origin=origin, dcp_slave=dcp)
    if not components:
        raise UserError(f"{ssd_path}: the system has no components")
    connections = []
    for connection in system.findall("ssd:Connections/ssd:Connection", NS):
        origin = where(ssd_path, connection.sourceline)
        factor, offset = 1.0, 0.0
        for child in connection:
            kind = _local(child)
            if kind == "LinearTransformation":
                factor, offset = _float(child, "factor", 1.0), _float(child, "offset", 0.0)
            elif kind in ("BooleanMappingTransformation", "IntegerMappingTransformation",
                          "EnumerationMappingTransformation"):
                raise UserError(f"{where(ssd_path, child.sourceline)}: ssc:{kind} on a connection "
                                "is not supported")
        if not connection.get("startElement") or not connection.get("endElement"):
            raise UserError(f"{origin}: connections to system connectors are not supported; "
                            "connect component to component")
        connections.append(Connection(
            connection.get("startElement"), connection.get("startConnector"),
            connection.get("endElement"), connection.get("endConnector"), factor, offset,
            _transition(connection, ssd_path),
            connection.get("suppressUnitConversion", "false") == "true", origin))
    experiment = root.find("ssd:DefaultExperiment", NS)
    start, stop, base = 0.0, None, None
    if experiment is not None:
        start = _float(experiment, "startTime", 0.0)
        stop = _float(experiment, "stopTime")
        base = _base_step(experiment, ssd_path)
    return SystemDescription(
        name=system.get("name") or root.get("name"), folder=folder, ssd_path=ssd_path,
        components=components, connections=connections, start_time=start, stop_time=stop,
        base_step_s=base, units=units,
        system_parameters=_read_bindings(system.find("ssd:ParameterBindings", NS), folder, ssd_path, units))


def _check_unique_component(components: Dict[str, Component], name: str, origin: str) -> None:
    """A component name names one component: a second one of the same name is refused (it would
    silently replace the first, and its connections would reach the wrong FMU)."""
    if name in components:
        raise UserError(f"{origin}: component name {name!r} is used twice (first at "
                        f"{components[name].origin}); component names must be unique")


def resolve_fmu(folder: Path, source: str, fmu_dirs) -> Optional[Path]:
    """The FMU a component names: in the system folder first, then in the build folders."""
    if not source:
        return None
    candidate = folder / source
    if candidate.is_file():
        return candidate
    for directory in fmu_dirs:
        other = Path(directory) / in_build_folder(source)
        if other.is_file():
            return other
    return candidate


def in_build_folder(source: str) -> str:
    """Where a build folder keeps the FMU a component source names: the source's path below its
    first folder (``resources/k32m2n40/RailLine.fmu`` → ``k32m2n40/RailLine.fmu``: FMUs built
    with other sizes live in a folder of their own, docs/architecture.md#build-sizes)."""
    parts = PurePosixPath(source).parts
    return str(PurePosixPath(*parts[1:])) if len(parts) > 1 else parts[0]


def load_parameter_set(system: SystemDescription, name: str) -> List[ParameterValue]:
    """A named parameter set: ``NAME.ssv`` in the system folder or its resources/ (system level)."""
    for candidate in (system.folder / f"{name}.ssv", system.folder / "resources" / f"{name}.ssv"):
        if candidate.is_file():
            root = parse_validated(candidate, "SystemStructureParameterValues.xsd")
            values, units = _read_parameter_set(root, candidate, "")
            system.units.update(units)
            return values
    available = sorted(p.stem for p in list(system.folder.glob("*.ssv")) +
                       list((system.folder / "resources").glob("*.ssv")))
    raise UserError(f"--param-set {name}: no {name}.ssv in {system.folder} "
                    f"(available: {', '.join(available) or 'none'})")

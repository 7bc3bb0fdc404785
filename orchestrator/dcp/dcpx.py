"""DCP slave descriptions (``.dcpx``, root element ``dcpSlaveDescription``): read, write and
validate against the DCP 1.0 schema shipped in orchestrator/dcp/schema/ (docs/hil.md#the-slave-description-dcpx),
and the description of an FMI 2.0 co-simulation FMU served as a DCP slave.

An FMU variable becomes a DCP variable of the same name and value reference. An FMI array
(``e_coil[1]`` … ``e_coil[40]``, ``u_tx[1,1]`` …) becomes ONE DCP array variable ``e_coil``
with ``<Dimensions>`` (row-major elements, value reference of its first element): a frame
travels as one entry of a DAT payload and is configured with one CFG_input/CFG_output
(docs/hil.md#arrays says why).
"""
from __future__ import annotations

import uuid as uuidlib
from dataclasses import dataclass, field
from fractions import Fraction
from pathlib import Path
from typing import Dict, List, Optional, Tuple

from lxml import etree

from orchestrator.dcp.pdu import DCP_MAJOR_VERSION, DCP_MINOR_VERSION, UDP_MAX_PDU_SIZE, DataType, OpMode
from orchestrator.errors import UserError
from orchestrator.ports import split_element

SCHEMA_DIR = Path(__file__).resolve().parent / "schema"
_SCHEMA: Optional[etree.XMLSchema] = None

#: DCP data type ↔ the element naming it in a .dcpx
TYPE_ELEMENTS: Dict[DataType, str] = {
    DataType.uint8: "Uint8", DataType.uint16: "Uint16", DataType.uint32: "Uint32",
    DataType.uint64: "Uint64", DataType.int8: "Int8", DataType.int16: "Int16",
    DataType.int32: "Int32", DataType.int64: "Int64", DataType.float32: "Float32",
    DataType.float64: "Float64", DataType.string: "String", DataType.binary: "Binary"}
_ELEMENT_TYPES = {v: k for k, v in TYPE_ELEMENTS.items()}
#: FMI 2.0 type → DCP data type (DCP has no Boolean: false/true travel as uint8 0/1)
FMI_TO_DCP: Dict[str, DataType] = {"Real": DataType.float64, "Integer": DataType.int32,
                                    "Enumeration": DataType.int32, "Boolean": DataType.uint8,
                                    "String": DataType.string}
_CAUSALITIES = ("Input", "Output", "Parameter", "StructuralParameter")
UINT32_MAX = 0xFFFFFFFF
#: where a variable's fail-safe value is annotated (as in the FMU's modelDescription)
_FAIL_SAFE = "Annotations/Tool[@name='railcosim']/FailSafe"
#: ticks of 1 ns per second: the orchestrator's own clock counts integer nanoseconds
NS_PER_SECOND = 1_000_000_000
#: the step assumed for an FMU that declares none (its DefaultExperiment has no stepSize)
DEFAULT_STEP_S = 0.01


@dataclass
class DcpVariable:
    name: str
    vr: int
    causality: str                        # input | output | parameter | structuralParameter
    data_type: DataType
    dims: Tuple[int, ...] = ()            # () for a scalar
    start: Optional[List] = None          # element values (numbers, or one str/bytes)
    variability: str = "continuous"
    description: Optional[str] = None
    # outputs: how often they may be sent, in steps of the time resolution
    default_steps: int = 1
    fixed_steps: bool = True
    min_steps: Optional[int] = None
    max_steps: Optional[int] = None
    max_consec_missed_pdus: Optional[int] = None
    #: FMI variable names of the elements (row-major) when the description comes from an FMU
    fmi_names: Tuple[str, ...] = ()
    #: a scalar output: what a master shows in its place while it is lost (our annotation
    #: ``<Annotations><Tool name="railcosim"><FailSafe value="…"/>``, the FMU's own; docs/hil.md)
    fail_safe: Optional[float] = None

    @property
    def count(self) -> int:
        n = 1
        for d in self.dims:
            n *= d
        return n

    def steps_supported(self, steps: int) -> bool:
        if self.fixed_steps:
            return steps == self.default_steps
        return (self.min_steps or 1) <= steps <= (self.max_steps or UINT32_MAX)


@dataclass
class SlaveDescription:
    name: str
    uuid: uuidlib.UUID
    variables: List[DcpVariable]
    op_modes: Tuple[OpMode, ...] = (OpMode.NRT,)
    nrt_default_steps: int = 1
    nrt_fixed_steps: bool = True
    nrt_min_steps: Optional[int] = None
    nrt_max_steps: Optional[int] = None
    #: (numerator, denominator, fixed, recommended)
    resolutions: List[Tuple[int, int, bool, Optional[bool]]] = field(default_factory=list)
    #: (numeratorFrom, numeratorTo, denominator)
    resolution_ranges: List[Tuple[int, int, int]] = field(default_factory=list)
    control_host: Optional[str] = None
    control_port: Optional[int] = None
    dat_host: Optional[str] = None
    dat_ports: List[int] = field(default_factory=list)
    dat_port_ranges: List[Tuple[int, int]] = field(default_factory=list)
    max_pdu_size: int = UDP_MAX_PDU_SIZE
    can_accept_config_pdus: bool = False
    can_handle_reset: bool = False
    can_handle_variable_steps: bool = False
    can_monitor_heartbeat: bool = False
    can_provide_log_on_request: bool = False
    can_provide_log_on_notification: bool = False
    major_version: int = DCP_MAJOR_VERSION
    minor_version: int = DCP_MINOR_VERSION
    description: Optional[str] = None
    generation_tool: Optional[str] = None
    udp: bool = True                     # offers UDP_IPv4

    # ---- look-ups -------------------------------------------------------------------------
    def variable(self, vr: int) -> Optional[DcpVariable]:
        return self._by_vr().get(vr)

    def by_name(self, name: str) -> Optional[DcpVariable]:
        return next((v for v in self.variables if v.name == name), None)

    def _by_vr(self) -> Dict[int, DcpVariable]:
        cache = self.__dict__.get("_vr_cache")
        if cache is None or len(cache) != len(self.variables):
            cache = {v.vr: v for v in self.variables}
            self.__dict__["_vr_cache"] = cache
        return cache

    def of_causality(self, causality: str) -> List[DcpVariable]:
        return [v for v in self.variables if v.causality == causality]

    def offered_resolutions(self) -> List[Tuple[int, int]]:
        """(numerator, denominator) of each Resolution, the schema's default 1/1000 s when the
        description names neither a Resolution nor a ResolutionRange."""
        if not self.resolutions and not self.resolution_ranges:
            return [(1, 1000)]
        return [(num, den) for num, den, _fixed, _rec in self.resolutions]

    def supports_time_resolution(self, numerator: int, denominator: int) -> bool:
        """Does the description offer this resolution? The same ratio as a Resolution (2/200
        is 1/100), or inside a ResolutionRange (numeratorFrom/denominator … numeratorTo/denominator)."""
        if numerator < 1 or denominator < 1:
            return False
        asked = Fraction(numerator, denominator)
        if any(asked == Fraction(num, den) for num, den in self.offered_resolutions()):
            return True
        return any((asked * den).denominator == 1 and lo <= asked * den <= hi for lo, hi, den in self.resolution_ranges)

    def resolution_for(self, step_s: Fraction) -> Tuple[Fraction, int]:
        """(time resolution, steps) with steps × resolution = ``step_s``, as a master picks them:
        the first Resolution that divides the step, else the step itself where a range offers
        it. A ValueError says what is offered when nothing fits."""
        for num, den in self.offered_resolutions():
            steps = step_s / Fraction(num, den)
            if steps.denominator == 1 and steps >= 1:
                return Fraction(num, den), int(steps)
        for lo, hi, den in self.resolution_ranges:
            if (step_s * den).denominator == 1 and lo <= step_s * den <= hi:
                return step_s, 1
        offered = [f"{num}/{den} s" for num, den in self.offered_resolutions()] + \
                  [f"{lo}/{den}…{hi}/{den} s" for lo, hi, den in self.resolution_ranges]
        raise ValueError(f"no time resolution divides the step {float(step_s):g} s "
                         f"(offered: {', '.join(offered) or 'none'})")

    def supports_nrt_steps(self, steps: int) -> bool:
        if steps < 1 or OpMode.NRT not in self.op_modes:
            return False
        if self.nrt_fixed_steps:
            return steps == self.nrt_default_steps
        return (self.nrt_min_steps or 1) <= steps <= (self.nrt_max_steps or UINT32_MAX)

    def supports_dat_port(self, port: int) -> bool:
        if not self.dat_ports and not self.dat_port_ranges:
            return True
        return port in self.dat_ports or any(lo <= port <= hi for lo, hi in self.dat_port_ranges)

    def logs(self) -> bool:
        """Does the description promise logging (which railcosim dcp-slave does not provide)?"""
        return self.can_provide_log_on_request or self.can_provide_log_on_notification


# ---- schema -----------------------------------------------------------------------------------

def schema() -> etree.XMLSchema:
    global _SCHEMA
    if _SCHEMA is None:
        _SCHEMA = etree.XMLSchema(etree.parse(str(SCHEMA_DIR / "dcpSlaveDescription.xsd")))
    return _SCHEMA


def validation_errors(root: etree._Element) -> List[str]:
    """The schema's complaints about a parsed description ('line N: message'), none if valid."""
    s = schema()
    if s.validate(etree.ElementTree(root)):
        return []
    return [f"line {e.line}: {e.message}" for e in s.error_log]


# ---- reading ----------------------------------------------------------------------------------

def _bool(text: Optional[str], default: bool) -> bool:
    return default if text is None else text.strip() in ("true", "1")


def _opt_int(text: Optional[str]) -> Optional[int]:
    return None if text is None else int(text)


def _start_values(data_type: DataType, text: Optional[str]) -> Optional[List]:
    if text is None:
        return None
    if data_type == DataType.string:
        return [text]
    if data_type == DataType.binary:
        return [bytes.fromhex(text)]
    convert = float if data_type in (DataType.float32, DataType.float64) else int
    return [convert(item) for item in text.split()]


def read_dcpx(path) -> SlaveDescription:
    """Parse and validate a ``.dcpx`` file; any defect is one UserError naming the file."""
    path = Path(path)
    try:
        root = etree.parse(str(path)).getroot()
    except OSError:
        raise UserError(f"{path}: DCP slave description not found") from None
    except etree.XMLSyntaxError as error:
        raise UserError(f"{path}: not an XML file: {error}") from None
    return from_xml(root, where=str(path))


def from_xml(root: etree._Element, where: str = "DCP slave description") -> SlaveDescription:
    errors = validation_errors(root)
    if errors:
        raise UserError(f"{where}: not a valid DCP 1.0 slave description ({errors[0]})")
    try:
        return _parse(root)
    except (ValueError, TypeError) as error:
        raise UserError(f"{where}: {error}") from None


def _parse(root) -> SlaveDescription:
    op = root.find("OpMode")
    modes, nrt = [], op.find("NonRealTime")
    for tag, mode in (("HardRealTime", OpMode.HRT), ("SoftRealTime", OpMode.SRT), ("NonRealTime", OpMode.NRT)):
        if op.find(tag) is not None:
            modes.append(mode)
    desc = SlaveDescription(
        name=root.get("dcpSlaveName"), uuid=uuidlib.UUID(root.get("uuid")), variables=[],
        op_modes=tuple(modes), major_version=int(root.get("dcpMajorVersion")),
        minor_version=int(root.get("dcpMinorVersion")), description=root.get("description"),
        generation_tool=root.get("generationTool"))
    if nrt is not None:
        desc.nrt_default_steps = int(nrt.get("defaultSteps", "1"))
        desc.nrt_fixed_steps = _bool(nrt.get("fixedSteps"), True)
        desc.nrt_min_steps, desc.nrt_max_steps = _opt_int(nrt.get("minSteps")), _opt_int(nrt.get("maxSteps"))
    for node in root.find("TimeRes"):
        if node.tag == "Resolution":
            rec = node.get("recommended")
            desc.resolutions.append((int(node.get("numerator", "1")), int(node.get("denominator", "1000")),
                                     _bool(node.get("fixed"), True), None if rec is None else _bool(rec, False)))
        elif node.tag == "ResolutionRange":
            desc.resolution_ranges.append((int(node.get("numeratorFrom")), int(node.get("numeratorTo")),
                                           int(node.get("denominator"))))
    udp = root.find("TransportProtocols/UDP_IPv4")
    desc.udp = udp is not None
    if udp is not None:
        desc.max_pdu_size = int(udp.get("maxPduSize", str(UDP_MAX_PDU_SIZE)))
        control = udp.find("Control")
        if control is not None:
            desc.control_host, desc.control_port = control.get("host"), _opt_int(control.get("port"))
        dat = udp.find("DAT_input_output")
        if dat is not None:
            desc.dat_host = dat.get("host")
            desc.dat_ports = [int(p.get("port")) for p in dat.findall("AvailablePort")]
            desc.dat_port_ranges = [(int(r.get("from")), int(r.get("to"))) for r in dat.findall("AvailablePortRange")]
    flags = root.find("CapabilityFlags")
    desc.can_accept_config_pdus = _bool(flags.get("canAcceptConfigPdus"), False)
    desc.can_handle_reset = _bool(flags.get("canHandleReset"), False)
    desc.can_handle_variable_steps = _bool(flags.get("canHandleVariableSteps"), False)
    desc.can_monitor_heartbeat = _bool(flags.get("canMonitorHeartbeat"), False)
    desc.can_provide_log_on_request = _bool(flags.get("canProvideLogOnRequest"), False)
    desc.can_provide_log_on_notification = _bool(flags.get("canProvideLogOnNotification"), False)
    for node in root.find("Variables"):
        kind = next(child for child in node if child.tag in _CAUSALITIES)
        typed = next(child for child in kind if child.tag in _ELEMENT_TYPES)
        data_type = _ELEMENT_TYPES[typed.tag]
        dims = tuple(int(d.get("constant")) for d in kind.findall("Dimensions/Dimension") if d.get("constant"))
        if any(d.get("constant") is None for d in kind.findall("Dimensions/Dimension")):
            raise ValueError(f"variable {node.get('name')!r}: dimensions linked to structural parameters "
                             f"(linkedVR) are not supported")
        var = DcpVariable(
            name=node.get("name"), vr=int(node.get("valueReference")),
            causality=kind.tag[0].lower() + kind.tag[1:], data_type=data_type, dims=dims,
            start=_start_values(data_type, typed.get("start")),
            variability=node.get("variability", "continuous"), description=node.get("description"),
            max_consec_missed_pdus=_opt_int(node.get("maxConsecMissedPdus")))
        fail_safe = node.find(_FAIL_SAFE)
        if fail_safe is not None:
            try:
                var.fail_safe = float(fail_safe.get("value"))
            except (TypeError, ValueError):
                raise ValueError(f"variable {var.name!r}: fail-safe value {fail_safe.get('value')!r} is not a "
                                 "number") from None
        if kind.tag == "Output":
            var.default_steps = int(kind.get("defaultSteps", "1"))
            var.fixed_steps = _bool(kind.get("fixedSteps"), True)
            var.min_steps, var.max_steps = _opt_int(kind.get("minSteps")), _opt_int(kind.get("maxSteps"))
        if var.start is not None and data_type not in (DataType.string, DataType.binary) \
                and len(var.start) not in (1, var.count):
            raise ValueError(f"variable {var.name!r}: {len(var.start)} start values for {var.count} elements")
        desc.variables.append(var)
    return desc


# ---- writing ----------------------------------------------------------------------------------

def _fmt(value) -> str:
    if isinstance(value, bool):
        return "1" if value else "0"
    if isinstance(value, float):
        return repr(value)
    if isinstance(value, bytes):
        return value.hex()
    return str(value)


def to_xml(desc: SlaveDescription) -> etree._Element:
    root = etree.Element("dcpSlaveDescription", dcpMajorVersion=str(desc.major_version),
                         dcpMinorVersion=str(desc.minor_version), dcpSlaveName=desc.name,
                         uuid=str(desc.uuid))
    if desc.description:
        root.set("description", desc.description)
    if desc.generation_tool:
        root.set("generationTool", desc.generation_tool)
    op = etree.SubElement(root, "OpMode")
    if OpMode.HRT in desc.op_modes:
        etree.SubElement(op, "HardRealTime")
    if OpMode.SRT in desc.op_modes:
        etree.SubElement(op, "SoftRealTime")
    if OpMode.NRT in desc.op_modes:
        nrt = etree.SubElement(op, "NonRealTime", defaultSteps=str(desc.nrt_default_steps),
                               fixedSteps=_fmt(desc.nrt_fixed_steps).replace("1", "true").replace("0", "false"))
        if desc.nrt_min_steps is not None:
            nrt.set("minSteps", str(desc.nrt_min_steps))
        if desc.nrt_max_steps is not None:
            nrt.set("maxSteps", str(desc.nrt_max_steps))
    res = etree.SubElement(root, "TimeRes")
    for num, den, fixed, rec in desc.resolutions:
        node = etree.SubElement(res, "Resolution", numerator=str(num), denominator=str(den),
                                fixed="true" if fixed else "false")
        if rec is not None:
            node.set("recommended", "true" if rec else "false")
    for lo, hi, den in desc.resolution_ranges:
        etree.SubElement(res, "ResolutionRange", numeratorFrom=str(lo), numeratorTo=str(hi), denominator=str(den))
    protocols = etree.SubElement(root, "TransportProtocols")
    if desc.udp:
        udp = etree.SubElement(protocols, "UDP_IPv4", maxPduSize=str(desc.max_pdu_size))
        control = etree.SubElement(udp, "Control")
        if desc.control_host:
            control.set("host", desc.control_host)
        if desc.control_port is not None:
            control.set("port", str(desc.control_port))
        dat = etree.SubElement(udp, "DAT_input_output")
        if desc.dat_host:
            dat.set("host", desc.dat_host)
        for lo, hi in desc.dat_port_ranges:
            etree.SubElement(dat, "AvailablePortRange", {"from": str(lo), "to": str(hi)})
        for port in desc.dat_ports:
            etree.SubElement(dat, "AvailablePort", port=str(port))
    tf = {True: "true", False: "false"}
    etree.SubElement(root, "CapabilityFlags", canAcceptConfigPdus=tf[desc.can_accept_config_pdus],
                     canHandleReset=tf[desc.can_handle_reset],
                     canHandleVariableSteps=tf[desc.can_handle_variable_steps],
                     canMonitorHeartbeat=tf[desc.can_monitor_heartbeat],
                     canProvideLogOnRequest=tf[desc.can_provide_log_on_request],
                     canProvideLogOnNotification=tf[desc.can_provide_log_on_notification])
    variables = etree.SubElement(root, "Variables")
    for var in desc.variables:
        node = etree.SubElement(variables, "Variable", name=var.name, valueReference=str(var.vr))
        if var.description:
            node.set("description", var.description)
        if var.variability != "continuous":
            node.set("variability", var.variability)
        if var.max_consec_missed_pdus is not None:
            node.set("maxConsecMissedPdus", str(var.max_consec_missed_pdus))
        kind = etree.SubElement(node, var.causality[0].upper() + var.causality[1:])
        typed = etree.SubElement(kind, TYPE_ELEMENTS[var.data_type])
        if var.start is not None:
            typed.set("start", " ".join(_fmt(v) for v in var.start))
        elif var.causality in ("input", "parameter", "structuralParameter"):
            raise ValueError(f"variable {var.name!r}: an {var.causality} needs a start value")
        if var.dims:
            dims = etree.SubElement(kind, "Dimensions")
            for d in var.dims:
                etree.SubElement(dims, "Dimension", constant=str(d))
        if var.causality == "output":
            kind.set("defaultSteps", str(var.default_steps))
            kind.set("fixedSteps", tf[var.fixed_steps])
            if var.min_steps is not None:
                kind.set("minSteps", str(var.min_steps))
            if var.max_steps is not None:
                kind.set("maxSteps", str(var.max_steps))
        if var.fail_safe is not None:
            tool = etree.SubElement(etree.SubElement(node, "Annotations"), "Tool", name="railcosim")
            real = var.data_type in (DataType.float32, DataType.float64)
            etree.SubElement(tool, "FailSafe", value=_fmt(float(var.fail_safe) if real else int(var.fail_safe)))
    return root


def write_dcpx(desc: SlaveDescription, path) -> None:
    """Write ``desc`` as a .dcpx, checked against the schema first."""
    root = to_xml(desc)
    errors = validation_errors(root)
    if errors:   # our own writer's defect: say so plainly
        raise ValueError(f"generated DCP slave description is invalid: {errors[0]}")
    Path(path).write_bytes(etree.tostring(root, xml_declaration=True, encoding="UTF-8", pretty_print=True))


# ---- an FMU as a DCP slave ---------------------------------------------------------------------

def slave_uuid(fmu_guid: str) -> uuidlib.UUID:
    """The DCP uuid of the slave serving an FMU: its GUID when that is a UUID (pythonfmu's
    are), else a name-based UUID of it, so that master and slave derive the same one."""
    try:
        return uuidlib.UUID(fmu_guid.strip("{}"))
    except ValueError:
        return uuidlib.uuid5(uuidlib.NAMESPACE_URL, f"urn:fmi:guid:{fmu_guid}")


def _start_of(fmi_var, data_type: DataType):
    value = fmi_var.start
    if data_type == DataType.string:
        return "" if value is None else str(value)
    if value is None:
        return 0.0 if data_type == DataType.float64 else 0
    if data_type == DataType.uint8:          # an FMI Boolean
        return 1 if str(value).lower() in ("true", "1") else 0
    return float(value) if data_type == DataType.float64 else int(value)


def _fmu_arrays(interface) -> Dict[str, list]:
    """The FMU's inputs, outputs and parameters grouped as DCP variables: base name → its
    members (index tuple, FMI variable), sorted row-major; a scalar has one member of index ()."""
    groups: Dict[str, list] = {}
    for fmi_var in interface.variables.values():
        if fmi_var.causality not in ("input", "output", "parameter") or fmi_var.type not in FMI_TO_DCP:
            continue
        base, index = split_element(fmi_var.name) or (fmi_var.name, ())
        groups.setdefault(base, []).append((index, fmi_var))
    for members in groups.values():
        members.sort(key=lambda m: m[0])
    return groups


def offered_resolutions(step_s: Fraction) -> List[Tuple[int, int, bool, Optional[bool]]]:
    """The time resolutions our slave offers for an FMU of step ``step_s``: those in which the
    step is a whole number of ticks and that a master is likely to ask for: the step itself
    first and recommended (a master that takes the first resolution offered, as DCPLib's
    example master does, then steps the FMU by its own step), 1 ns (the orchestrator's own
    clock), and every decimal fraction of a second (1/10 … 1/10⁸ s) that divides the step. All
    non-fixed, as the schema wants several."""
    candidates = [step_s, Fraction(1, NS_PER_SECOND)] + [Fraction(1, 10 ** k) for k in range(1, 9)]
    offered: List[Tuple[int, int, bool, Optional[bool]]] = []
    for resolution in candidates:
        entry = (resolution.numerator, resolution.denominator)
        if (step_s / resolution).denominator == 1 and entry not in [o[:2] for o in offered]:
            offered.append((*entry, False, True if not offered else None))
    return offered


def description_from_fmu(interface, host: str = "127.0.0.1", port: Optional[int] = None,
                         real_time: bool = True) -> SlaveDescription:
    """The DCP description of an FMU (orchestrator.fmu.Interface) served by our slave:
    inputs, outputs and parameters with the FMU's value references, arrays grouped, the time
    resolutions in which the FMU's step is a whole number of ticks (:func:`offered_resolutions`),
    non-real-time with any number of steps, soft real-time if asked."""
    step_ns = round((interface.default_step_s or DEFAULT_STEP_S) * NS_PER_SECOND)
    variables = []
    for base, members in _fmu_arrays(interface).items():
        first = members[0][1]
        kinds = {(m[1].causality, m[1].type) for m in members}
        if len(kinds) != 1:
            raise UserError(f"{interface.model_identifier}: array {base!r} mixes causalities or types")
        data_type = FMI_TO_DCP[first.type]
        if members[0][0]:
            dims = tuple(max(m[0][k] for m in members) for k in range(len(members[0][0])))
            expected = 1
            for d in dims:
                expected *= d
            if expected != len(members):
                raise UserError(f"{interface.model_identifier}: array {base!r} has gaps in its indices")
        else:
            dims = ()
        starts = [_start_of(m[1], data_type) for m in members]
        if data_type == DataType.string and len(starts) > 1:
            raise UserError(f"{interface.model_identifier}: string array {base!r} cannot be served over DCP")
        if len(set(map(repr, starts))) == 1 and dims:
            starts = starts[:1]        # one start for every element (the schema's list form)
        variability = first.variability if first.variability in ("fixed", "tunable", "discrete") else "continuous"
        var = DcpVariable(name=base, vr=first.vr, causality=first.causality, data_type=data_type, dims=dims,
                          start=starts, variability=variability,
                          fmi_names=tuple(m[1].name for m in members),
                          fail_safe=None if dims else interface.fail_safe.get(base))
        if first.causality == "output":     # steps in the recommended resolution: one FMU step
            var.default_steps, var.fixed_steps, var.min_steps, var.max_steps = 1, False, 1, UINT32_MAX
        variables.append(var)
    # FMI value references are unique per type only; DCP's are unique over all variables
    used, taken = {v.vr for v in variables}, set()
    spare = max(used, default=-1) + 1
    for var in variables:
        if var.vr in taken:
            var.vr, spare = spare, spare + 1
        taken.add(var.vr)
    modes = (OpMode.SRT, OpMode.NRT) if real_time else (OpMode.NRT,)
    return SlaveDescription(
        name=interface.model_identifier, uuid=slave_uuid(interface.guid), variables=variables,
        op_modes=modes, nrt_default_steps=1, nrt_fixed_steps=False, nrt_min_steps=1,
        nrt_max_steps=UINT32_MAX, resolutions=offered_resolutions(Fraction(step_ns, NS_PER_SECOND)),
        control_host=host, control_port=port, dat_host=host,
        dat_ports=[port] if port is not None else [], dat_port_ranges=[(1024, 65535)],
        can_accept_config_pdus=True, can_handle_reset=True, can_handle_variable_steps=True,
        description=f"FMU {interface.model_identifier} served as a DCP slave by railcosim dcp-slave",
        generation_tool="railcosim")


#: which DCP data types may carry each FMI type when a given description is served over an FMU
_CARRIES = {"Real": {DataType.float64, DataType.float32},
            "Integer": {DataType.int8, DataType.int16, DataType.int32, DataType.int64, DataType.uint8,
                        DataType.uint16, DataType.uint32},
            "Enumeration": {DataType.int8, DataType.int16, DataType.int32, DataType.uint8, DataType.uint16},
            "Boolean": {DataType.uint8, DataType.int8, DataType.uint16, DataType.int16, DataType.int32},
            "String": {DataType.string}}


def serve_over_fmu(desc: SlaveDescription, interface, where: str) -> SlaveDescription:
    """A given description (a bench device's .dcpx) served by an FMU: each DCP variable is the
    FMU variable of its name, or the FMI array of that base name (``e_coil`` → ``e_coil[1]`` …),
    of the same causality and a type the DCP type can carry. Every mismatch is listed in one
    UserError naming ``where``."""
    groups = _fmu_arrays(interface)
    problems = []
    for var in desc.variables:
        members = groups.get(var.name)
        causality = "parameter" if var.causality == "structuralParameter" else var.causality
        if members is None:
            problems.append(f"{var.name!r}: the FMU has no variable of that name")
            continue
        fmi = members[0][1]
        if fmi.causality != causality:
            problems.append(f"{var.name!r}: {var.causality} in the description, {fmi.causality} in the FMU")
        elif var.data_type not in _CARRIES.get(fmi.type, ()):
            problems.append(f"{var.name!r}: {var.data_type.name} cannot carry the FMU's {fmi.type}")
        elif len(members) != var.count:
            problems.append(f"{var.name!r}: {var.count} element(s) in the description, {len(members)} in the FMU")
        var.fmi_names = tuple(m[1].name for m in members)
    if problems:
        raise UserError(f"{where}: does not fit {interface.model_identifier}: " + "; ".join(problems))
    return desc

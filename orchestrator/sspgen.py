"""Write SSP 1.0 system descriptions from Python (shipped systems, tests, studies).

Frame ports are FMI structured arrays, so one frame link is N (or K·N) scalar connections;
``frame_connections`` expands them. Step sizes are written both as our annotation and as
``osp:StepSizeHint``, and the base step as ``osp:Algorithm/osp:FixedStepAlgorithm``, so
libcosim-based tools run the system multi-rate too; every component declares its connectors
(from its FMU's variables) so that tools which resolve connections through them (libcosim, FMPy)
make every connection (docs/interfaces.md#ssp-conventions).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Dict, List, Optional, Sequence, Tuple

from lxml import etree

from orchestrator.ssp import NS, OSP_ANNOTATION, OSP_NS, RCS_ANNOTATION, RCS_NS
from orchestrator.ports import element_names

SSD = "{%s}" % NS["ssd"]
SSC = "{%s}" % NS["ssc"]
SSV = "{%s}" % NS["ssv"]
_NSMAP = {"ssd": NS["ssd"], "ssc": NS["ssc"], "ssv": NS["ssv"], "rcs": RCS_NS, "osp": OSP_NS}


@dataclass
class ComponentSpec:
    name: str
    source: str                     # e.g. "resources/Traction.fmu"
    step_size_s: Optional[float] = None
    parameters: Dict[str, object] = field(default_factory=dict)   # inline binding
    parameter_file: Optional[str] = None                          # external .ssv
    parameter_mapping: Optional[str] = None                       # .ssm for the external binding
    prefix: str = ""


@dataclass
class ConnectionSpec:
    start: str                      # "component.connector"
    end: str
    factor: float = 1.0
    offset: float = 0.0
    transition: str = "hold"
    suppress_unit_conversion: bool = False


def frame_connections(start: str, end: str, shape: Sequence[int]) -> List[ConnectionSpec]:
    """All element connections between two ports of equal shape, e.g. u_tx[8,40] → u_tx[8,40]."""
    return [ConnectionSpec(a, b) for a, b in zip(element_names(start, shape), element_names(end, shape))]


def _typed(parent, value, unit: Optional[str] = None, namespace: str = SSV):
    if isinstance(value, bool):
        node = etree.SubElement(parent, namespace + "Boolean", value="true" if value else "false")
    elif isinstance(value, int):
        node = etree.SubElement(parent, namespace + "Integer", value=str(value))
    elif isinstance(value, float):
        node = etree.SubElement(parent, namespace + "Real", value=repr(value))
        if unit:
            node.set("unit", unit)
    else:
        node = etree.SubElement(parent, namespace + "String", value=str(value))
    return node


def _annotation(parent, annotation_type: str, namespace: str, tag: str, **attrs):
    annotations = parent.find(SSD + "Annotations")
    if annotations is None:
        annotations = etree.SubElement(parent, SSD + "Annotations")
    annotation = etree.SubElement(annotations, SSC + "Annotation", type=annotation_type)
    etree.SubElement(annotation, "{%s}%s" % (namespace, tag), **{k: str(v) for k, v in attrs.items()})


def parameter_set(name: str, values: Dict[str, object], units: Dict[str, str] = None) -> etree._Element:
    root = etree.Element(SSV + "ParameterSet", nsmap={"ssv": NS["ssv"]}, version="1.0", name=name)
    parameters = etree.SubElement(root, SSV + "Parameters")
    for key, value in values.items():
        parameter = etree.SubElement(parameters, SSV + "Parameter", name=key)
        _typed(parameter, value, (units or {}).get(key))
    return root


def write_ssv(path: Path, name: str, values: Dict[str, object], units: Dict[str, str] = None) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    etree.ElementTree(parameter_set(name, values, units)).write(
        str(path), pretty_print=True, xml_declaration=True, encoding="UTF-8")
    return path


# ---- connectors --------------------------------------------------------------------------------
# An FMU's variables as its contract manifest lists them (orchestrator/conformance/roles.py): name →
# causality, type, unit and, for an array, shape. ``PortsOf(folder, source)`` gives them for a
# component's source, or None when they are unknown.
Ports = Dict[str, dict]
PortsOf = Callable[[Path, str], Optional[Ports]]
_CONNECTOR_TYPES = ("Real", "Integer", "Boolean", "String")


def fmu_ports(folder: Path, source: str) -> Optional[Ports]:
    """The variables of the FMU at ``folder / source`` (its modelDescription), or None when no
    FMU is there (the SSD then declares no connectors: they are optional for our loader). The
    shipped systems are written from the committed contract manifests instead
    (orchestrator/systems/chain.py ``committed_ports``), so their bytes do not depend on a build."""
    from orchestrator.ports import manifest_of

    path = Path(folder) / source
    return manifest_of(path) if path.is_file() else None


def connectors_of(ports: Ports, connected_inputs: Sequence[str] = ()) -> List[Tuple[str, str, str, Optional[str]]]:
    """(name, kind, type, unit) of the connectors a component declares: one per scalar variable
    (an array's elements one by one, as connections link them), in name order — every output,
    parameter and calculated parameter, and the inputs the system connects. An unconnected input
    is left out: it keeps the FMU's start value in every tool (FMPy 0.3.32 sets each declared
    input from a connection and, for one without, reuses the previous input's source)."""
    connected = set(connected_inputs)
    result = []
    for base in sorted(ports):
        port = ports[base]
        kind, ctype = port["causality"], port["type"]
        if kind not in ("input", "output", "parameter", "calculatedParameter") or ctype not in _CONNECTOR_TYPES:
            continue
        shape = port.get("shape")
        names = element_names(base, shape or ())
        result += [(name, kind, ctype, port.get("unit")) for name in names
                   if kind != "input" or name in connected]
    return result


def _connectors(node, connectors) -> None:
    if not connectors:
        return
    parent = etree.SubElement(node, SSD + "Connectors")
    for name, kind, ctype, unit in connectors:
        connector = etree.SubElement(parent, SSD + "Connector", name=name, kind=kind)
        typed = etree.SubElement(connector, SSC + ctype)
        if unit and ctype == "Real":
            typed.set("unit", unit)


def _base_step(components: Sequence[ComponentSpec], base_step_s: Optional[float]) -> Optional[float]:
    """The system's base step: the given one, else the greatest common divisor of the
    components' steps (in whole nanoseconds, as the master counts); None when a step is unknown."""
    if base_step_s is not None:
        return base_step_s
    steps = [c.step_size_s for c in components]
    if not steps or None in steps:
        return None
    return math.gcd(*(round(step * 1e9) for step in steps)) / 1e9


def write_ssd(folder: Path, name: str, components: Sequence[ComponentSpec],
              connections: Sequence[ConnectionSpec], stop_time: Optional[float] = None,
              start_time: float = 0.0, base_step_s: Optional[float] = None,
              ports: PortsOf = fmu_ports) -> Path:
    """Write ``folder/SystemStructure.ssd``. Each component declares the connectors
    :func:`connectors_of` lists, from ``ports(folder, source)`` (default :func:`fmu_ports`: the
    FMU at the component's source). The DefaultExperiment carries ``osp:FixedStepAlgorithm`` with the
    base step (the given one or the gcd of the component steps) and, when given, ``rcs:BaseStep``.
    """
    folder.mkdir(parents=True, exist_ok=True)
    root = etree.Element(SSD + "SystemStructureDescription", nsmap=_NSMAP, version="1.0", name=name)
    system = etree.SubElement(root, SSD + "System", name=name)
    elements = etree.SubElement(system, SSD + "Elements")
    connected_inputs: Dict[str, List[str]] = {}
    for conn in connections:
        element, _, connector = conn.end.partition(".")
        connected_inputs.setdefault(element, []).append(connector)
    for comp in components:
        node = etree.SubElement(elements, SSD + "Component", name=comp.name, source=comp.source,
                                type="application/x-fmu-sharedlibrary")
        component_ports = ports(folder, comp.source)
        if component_ports is not None:
            _connectors(node, connectors_of(component_ports, connected_inputs.get(comp.name, ())))
        if comp.parameters or comp.parameter_file:
            bindings = etree.SubElement(node, SSD + "ParameterBindings")
            if comp.parameter_file:
                binding = etree.SubElement(bindings, SSD + "ParameterBinding", source=comp.parameter_file)
                if comp.prefix:
                    binding.set("prefix", comp.prefix)
                if comp.parameter_mapping:
                    etree.SubElement(binding, SSD + "ParameterMapping", source=comp.parameter_mapping)
            if comp.parameters:
                binding = etree.SubElement(bindings, SSD + "ParameterBinding")
                values = etree.SubElement(binding, SSD + "ParameterValues")
                values.append(parameter_set(f"{comp.name}_inline", comp.parameters))
        if comp.step_size_s is not None:
            _annotation(node, RCS_ANNOTATION, RCS_NS, "StepSize", value=repr(comp.step_size_s))
            _annotation(node, OSP_ANNOTATION, OSP_NS, "StepSizeHint", value=repr(comp.step_size_s))
    if connections:
        links = etree.SubElement(system, SSD + "Connections")
        for conn in connections:
            start_element, _, start_connector = conn.start.partition(".")
            end_element, _, end_connector = conn.end.partition(".")
            node = etree.SubElement(links, SSD + "Connection", startElement=start_element,
                                    startConnector=start_connector, endElement=end_element,
                                    endConnector=end_connector)
            if conn.suppress_unit_conversion:
                node.set("suppressUnitConversion", "true")
            if (conn.factor, conn.offset) != (1.0, 0.0):
                etree.SubElement(node, SSC + "LinearTransformation", factor=repr(conn.factor),
                                 offset=repr(conn.offset))
            if conn.transition != "hold":
                _annotation(node, RCS_ANNOTATION, RCS_NS, "RateTransition", kind=conn.transition)
    experiment = etree.SubElement(root, SSD + "DefaultExperiment", startTime=repr(start_time))
    if stop_time is not None:
        experiment.set("stopTime", repr(stop_time))
    if base_step_s is not None:
        _annotation(experiment, RCS_ANNOTATION, RCS_NS, "BaseStep", value=repr(base_step_s))
    base = _base_step(components, base_step_s)
    if base is not None:
        _annotation(experiment, OSP_ANNOTATION, OSP_NS, "Algorithm")
        algorithm = experiment.find(SSD + "Annotations")[-1][0]
        etree.SubElement(algorithm, "{%s}FixedStepAlgorithm" % OSP_NS, baseStepSize=repr(base))
    path = folder / "SystemStructure.ssd"
    etree.ElementTree(root).write(str(path), pretty_print=True, xml_declaration=True, encoding="UTF-8")
    return path

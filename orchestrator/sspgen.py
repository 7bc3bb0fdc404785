"""Write SSP 1.0 system descriptions from Python (shipped systems, tests, studies).

Frame ports are FMI structured arrays, so one frame link is N (or K·N) scalar connections;
``frame_connections`` expands them. Step sizes are written both as our annotation and as
``osp:StepSizeHint`` so libcosim-based tools run the system multi-rate too (docs/interfaces.md#ssp-conventions).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Dict, List, Optional, Sequence

from lxml import etree

from orchestrator.ssp import NS, OSP_ANNOTATION, OSP_NS, RCS_ANNOTATION, RCS_NS

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
    import itertools

    connections = []
    for index in itertools.product(*(range(1, n + 1) for n in shape)):
        suffix = "[" + ",".join(map(str, index)) + "]"
        connections.append(ConnectionSpec(start + suffix, end + suffix))
    return connections


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


def write_ssd(folder: Path, name: str, components: Sequence[ComponentSpec],
              connections: Sequence[ConnectionSpec], stop_time: Optional[float] = None,
              start_time: float = 0.0, base_step_s: Optional[float] = None) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    root = etree.Element(SSD + "SystemStructureDescription", nsmap=_NSMAP, version="1.0", name=name)
    system = etree.SubElement(root, SSD + "System", name=name)
    elements = etree.SubElement(system, SSD + "Elements")
    for comp in components:
        node = etree.SubElement(elements, SSD + "Component", name=comp.name, source=comp.source,
                                type="application/x-fmu-sharedlibrary")
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
    path = folder / "SystemStructure.ssd"
    etree.ElementTree(root).write(str(path), pretty_print=True, xml_declaration=True, encoding="UTF-8")
    return path

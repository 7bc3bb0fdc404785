"""What pythonfmu leaves out of a facade's modelDescription.xml, added from its ports so that
``fmpy validate`` reports nothing: units and min/max on the variables, UnitDefinitions (SI base
exponents), a vendor annotation naming the frame ports, on each output with a fail-safe value
a variable annotation holding it (``<Annotations><Tool name="railcosim"><FailSafe value="0"/>``,
read by a DCP master: docs/hil.md), ModelStructure Outputs (no direct feedthrough: outputs are
computed in doStep) and InitialUnknowns, and whether the communication step may vary."""
from __future__ import annotations

from typing import Sequence
from xml.etree.ElementTree import Element, SubElement

from fmus.fmi.ports import Port
from fmus.fmi.unit_definitions import unit_definition


def complete(root: Element, ports: Sequence[Port], variable_step: bool) -> Element:
    """``root`` (pythonfmu's modelDescription) with our additions."""
    root.find("CoSimulation").set("canHandleVariableCommunicationStepSize",
                                  "true" if variable_step else "false")
    port_of_element = {}
    for port in ports:
        for element in port.element_names():
            port_of_element[element] = port
    units = []
    variables = root.find("ModelVariables")
    output_indices = []
    for index, sv in enumerate(variables.findall("ScalarVariable"), start=1):
        port = port_of_element[sv.get("name")]
        type_node = sv[0]
        if port.unit and port.type == "Real":
            type_node.set("unit", port.unit)
            if port.unit not in units:
                units.append(port.unit)
        for bound in ("min", "max"):
            value = getattr(port, bound)
            if value is not None and port.type in ("Real", "Integer"):
                type_node.set(bound, f"{value:.16g}" if port.type == "Real" else str(int(value)))
        if port.causality == "output":
            output_indices.append(index)
        if port.fail_safe is not None:
            tool = SubElement(SubElement(sv, "Annotations"), "Tool", name="railcosim")
            SubElement(tool, "FailSafe", value=_typed_value(port.type, port.fail_safe))
    if units:
        position = list(root).index(root.find("CoSimulation")) + 1
        unit_defs = Element("UnitDefinitions")
        for unit in units:
            unit_defs.append(unit_definition(unit))
        root.insert(position, unit_defs)
    frame_ports = [p.name for p in ports if p.frame]
    if frame_ports:
        vendor = Element("VendorAnnotations")
        tool = SubElement(vendor, "Tool", name="railcosim")
        SubElement(tool, "FramePorts").text = " ".join(frame_ports)
        root.insert(list(root).index(variables), vendor)
    structure = root.find("ModelStructure")
    for child in list(structure):
        structure.remove(child)
    if output_indices:
        outputs = SubElement(structure, "Outputs")
        initial = SubElement(structure, "InitialUnknowns")
        for index in output_indices:
            # Outputs are computed in doStep: no direct feedthrough from inputs.
            SubElement(outputs, "Unknown", index=str(index), dependencies="")
            SubElement(initial, "Unknown", index=str(index))
    return root


def _typed_value(fmi_type: str, value) -> str:
    """A value as the modelDescription writes one of its type (``true``, ``-1``, ``0.5``)."""
    if fmi_type == "Boolean":
        return "true" if value else "false"
    return str(int(value)) if fmi_type == "Integer" else f"{float(value):.16g}"

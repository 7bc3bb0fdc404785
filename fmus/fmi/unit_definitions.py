"""SI unit definitions written into every modelDescription's UnitDefinitions."""
from xml.etree.ElementTree import Element, SubElement

# exponents of the SI base units (kg, m, s, A) and factor to SI, per unit string used at a port
_BASE_UNITS = {
    "m": {"m": 1},
    "s": {"s": 1},
    "m/s": {"m": 1, "s": -1},
    "m/s2": {"m": 1, "s": -2},
    "kg": {"kg": 1},
    "N": {"kg": 1, "m": 1, "s": -2},
    "J": {"kg": 1, "m": 2, "s": -2},
    "W": {"kg": 1, "m": 2, "s": -3},
    "A": {"A": 1},
    "V": {"kg": 1, "m": 2, "s": -3, "A": -1},
    "Ohm": {"kg": 1, "m": 2, "s": -3, "A": -2},
    "Hz": {"s": -1},
    "1/s": {"s": -1},
    # a level rate: the decibel is a dimensionless ratio, so its SI base is 1/s like Hz; the
    # unit's name tells a tool (and a reader) that the quantity is logarithmic
    "dB/s": {"s": -1},
    "H": {"kg": 1, "m": 2, "s": -2, "A": -2},
    "Ohm/km": {"kg": 1, "m": 1, "s": -3, "A": -2, "factor": 1e-3},
    "H/km": {"kg": 1, "m": 1, "s": -2, "A": -2, "factor": 1e-3},
    "Ohm.km": {"kg": 1, "m": 3, "s": -3, "A": -2, "factor": 1e3},
    "1": {},
}


def unit_definition(unit: str) -> Element:
    """FMI 2.0 <Unit> element for one of the units railcosim uses at its ports."""
    if unit not in _BASE_UNITS:
        raise KeyError(f"unit {unit!r} has no SI definition in fmus/fmi/unit_definitions.py")
    node = Element("Unit", name=unit)
    SubElement(node, "BaseUnit", {k: str(v) for k, v in _BASE_UNITS[unit].items()})
    return node

"""The coder of each cab system, by its ``system`` name (fmus/signalling/cab_systems.py): how its
core is made from the line, the build sizes, the settings and the system's code table. The
facade looks the system up here; no other module of the coder tells the systems apart."""
from __future__ import annotations

from typing import Callable, Dict

from fmus.signalling import cab_systems
from fmus.wayside_coder.alsu import AlsuCoderCore
from fmus.wayside_coder.core import WaysideCoderCore
from fmus.wayside_coder.digital_generator import DigitalCoderCore
from fmus.wayside_coder.tvm300 import Tvm300CoderCore
from fmus.wayside_coder.tvm430 import Tvm430CoderCore

#: (line, sections, frame, settings, code table, system object, parameter getter) → core; the
#: code table is the system's ``load_codes`` of the ``codes_file`` parameter (or the bundled one)
CoreMaker = Callable[..., object]

CODERS: Dict[str, CoreMaker] = {
    cab_systems.ALSN.name: lambda line, k, n, settings, codes, system, param:
        WaysideCoderCore(line, k, n, settings, codes),
    cab_systems.ALSU.name: lambda line, k, n, settings, codes, system, param:
        AlsuCoderCore(line, k, n, settings, codes),
    cab_systems.TVM430.name: lambda line, k, n, settings, codes, system, param:
        Tvm430CoderCore(line, k, n, settings, codes, param("address") or None),
    cab_systems.TVM300.name: lambda line, k, n, settings, codes, system, param:
        Tvm300CoderCore(line, k, n, settings, codes),
}
for _name, _cab in cab_systems.REGISTRY.items():
    if _cab.family == cab_systems.DIGITAL_FAMILY:
        CODERS[_name] = lambda line, k, n, settings, codes, system, param: \
            DigitalCoderCore(system, line, k, n, settings)


def make_coder(name: str, line, sections: int, frame: int, settings, codes_path, param):
    """The coder core of system ``name`` (an unknown name is an input error); ``codes_path`` the
    code table to read (None: the bundled one), ``param`` reads a further parameter by name."""
    cab = cab_systems.lookup(name)
    codes = cab.load_codes(codes_path or cab.codes_file) if cab.load_codes else None
    return CODERS[cab.name](line, sections, frame, settings, codes, cab.system(), param)

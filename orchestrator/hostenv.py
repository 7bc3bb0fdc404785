"""This machine's Python as an FMU sees it: the libpython, PYTHONHOME and PYTHONPATH that
`railcosim build` writes into every FMU's resources (resources/railcosim_python.txt, read by
the FMU's forwarding binary, orchestrator/packaging/forwarder/) and that `railcosim fmu-env`
prints as overrides. docs/third_party.md explains each item."""
from __future__ import annotations

import os
import sys
import sysconfig
from pathlib import Path
from typing import Dict, List

from orchestrator.errors import UserError


def libpython_candidates() -> List[Path]:
    """Where this Python's shared library can be (sysconfig LIBDIR with LDLIBRARY/INSTSONAME)."""
    folders = [sysconfig.get_config_var("LIBDIR"), sysconfig.get_config_var("LIBPL"),
               str(Path(sys.base_prefix) / "lib")]
    names = [sysconfig.get_config_var("INSTSONAME"), sysconfig.get_config_var("LDLIBRARY"),
             f"libpython{sysconfig.get_python_version()}.so"]
    # a static build's LDLIBRARY is libpythonX.Y.a: only shared objects can be loaded
    found = [Path(folder) / name for folder in folders if folder
             for name in names if name and ".so" in name]
    return list(dict.fromkeys(found))


def libpython_path() -> str:
    """This Python's shared libpython; a UserError naming the places looked at if there is none
    (a Python built without --enable-shared cannot be loaded by a non-Python host)."""
    candidates = libpython_candidates()
    for path in candidates:
        if path.is_file():
            return str(path)
    looked = ", ".join(str(p) for p in candidates) or "sysconfig LIBDIR/LDLIBRARY (both empty)"
    raise UserError(f"no shared libpython for {sys.executable} (looked for {looked}); "
                    "FMUs need a Python built with --enable-shared")


def site_packages() -> List[str]:
    """The folders holding the FMUs' Python dependencies (numpy, scipy, control, jsonschema)."""
    import numpy

    site = str(Path(numpy.__file__).resolve().parent.parent)
    paths = [site] + [p for p in sys.path if p.endswith("site-packages") and p != site]
    return list(dict.fromkeys(paths))


def fmu_python_settings() -> Dict[str, str]:
    """What an FMU built here starts Python with in a process that has none."""
    return {
        "LIBPYTHON": libpython_path(),
        "PYTHONHOME": sys.base_prefix,
        "PYTHONPATH": os.pathsep.join(site_packages()),
    }


def host_environment() -> Dict[str, str]:
    """The environment variables that override an FMU's built-in Python settings (all optional
    for FMUs built on this machine; docs/third_party.md)."""
    settings = fmu_python_settings()
    return {"RAILCOSIM_LIBPYTHON": settings["LIBPYTHON"], "PYTHONHOME": settings["PYTHONHOME"],
            "PYTHONPATH": settings["PYTHONPATH"]}

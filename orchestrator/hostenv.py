"""What a non-Python FMI host (fmusim, the FMU Compliance Checker, Simulink …) must set so
that a pythonfmu FMU finds this machine's Python: docs/third_party.md explains each item."""
from __future__ import annotations

import os
import sys
import sysconfig
from pathlib import Path
from typing import Dict


def libpython_path() -> str:
    libdir = sysconfig.get_config_var("LIBDIR") or ""
    for name in (sysconfig.get_config_var("LDLIBRARY"), sysconfig.get_config_var("INSTSONAME")):
        if name and (Path(libdir) / name).exists():
            return str(Path(libdir) / name)
    return str(Path(libdir) / f"libpython{sysconfig.get_python_version()}.so")


def host_environment() -> Dict[str, str]:
    import numpy

    site = str(Path(numpy.__file__).resolve().parent.parent)
    paths = [site] + [p for p in sys.path if p.endswith("site-packages") and p != site]
    repo = str(Path(__file__).resolve().parent.parent)
    return {
        # the wrapper calls the CPython API but does not link libpython: it must be loaded first
        "LD_PRELOAD": libpython_path(),
        "PYTHONHOME": sys.base_prefix,
        "PYTHONPATH": os.pathsep.join(dict.fromkeys(paths + [repo])),
    }

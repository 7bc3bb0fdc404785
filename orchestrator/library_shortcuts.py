"""What the engine takes from inside numpy and fmpy, past their public functions, in one place
(the FMU side has its own, fmus/library_shortcuts.py: the engine imports nothing of ``fmus``).
Each is checked against a release line (CHECKED_AGAINST: the code read, the answers compared
by tests/test_library_shortcuts.py) and falls back to the public way on another one; what the
fallbacks cost: benchmarks/bench_library_shortcuts.py (docs/performance.md).

* ``count_nonzero(flags)`` — np.count_nonzero's routine, for the FMI host's unchanged-input
  test (once per input buffer and step; fmu.py).
* ``raw_function(fmu, name)`` — an FMI function of an FMU's binary as a ctypes function of its
  own returning the status as an int, without fmpy's wrapper around it (a dictionary look-up,
  the call logger's test and the status check: two Python calls more per call); the caller
  checks the status. Fallback: fmpy's wrapper (same arguments; it raises fmpy's
  FMICallException on an error status itself, as the caller does).
* ``library_function(fmu, name)`` — a function the FMU's binary exports besides FMI's
  (pythonfmu's ``finalizePythonInterpreter``), or None.
* ``ssp_schema(name)`` — the path of an SSP 1.0 XSD in fmpy's package (fmpy ships the schemas
  for its own validation but has no function naming them). No public fallback: a fmpy without
  them is an error naming the file looked for.
* ``fmi_headers()`` — fmpy's folder of the FMI 2.0 C headers (for compiling the forwarding
  binary and the test hosts).
"""
from __future__ import annotations

import ctypes
from pathlib import Path
import numpy as np

from orchestrator.errors import UserError

#: the release lines whose internals were read and compared: numpy 2.4.6; fmpy 0.3.32 (pinned
#: in pyproject.toml)
CHECKED_AGAINST = {"numpy": "2.4", "fmpy": "0.3.32"}


def _line(version: str, parts: int) -> str:
    return ".".join(version.split(".")[:parts])


count_nonzero = np.count_nonzero
if _line(np.__version__, 2) == CHECKED_AGAINST["numpy"]:
    try:
        from numpy._core.multiarray import count_nonzero
    except ImportError:                  # the checked line without it: the public function
        count_nonzero = np.count_nonzero


def _fmpy_checked() -> bool:
    import fmpy

    return fmpy.__version__ == CHECKED_AGAINST["fmpy"]


def raw_function(fmu, name: str):
    """FMI function ``name`` of an fmpy FMU object's binary, called as (component, *arguments)
    and returning the status (int); the caller raises on an error status."""
    if _fmpy_checked() and isinstance(getattr(fmu, "dll", None), ctypes.CDLL):
        function = fmu.dll[name]          # a new function object: fmpy's argtypes are on its own
        function.restype = ctypes.c_int
        return function
    return getattr(fmu, name)


def library_function(fmu, name: str):
    """A function the binary exports besides FMI's, or None when it has none (or fmpy keeps no
    handle of its library where we look)."""
    return getattr(getattr(fmu, "dll", None), name, None)


def _fmpy_folder() -> Path:
    import fmpy

    return Path(fmpy.__file__).resolve().parent


def ssp_schema(name: str) -> Path:
    """The XSD ``name`` of SSP 1.0 (SystemStructureDescription.xsd, …) as fmpy ships it."""
    path = _fmpy_folder() / "ssp" / "schema" / name
    if not path.is_file():
        raise UserError(f"{path}: not found: this fmpy has no SSP schemas there (checked against fmpy "
                        f"{CHECKED_AGAINST['fmpy']})")
    return path


def fmi_headers() -> Path:
    """fmpy's folder of the FMI 2.0 C headers (fmi2Functions.h …)."""
    return _fmpy_folder() / "c-code"


def in_use() -> dict:
    """Which shortcuts this machine takes (False: the public way is used)."""
    return {"count_nonzero": count_nonzero is not np.count_nonzero, "raw_function": _fmpy_checked(),
            "ssp_schema": (_fmpy_folder() / "ssp" / "schema").is_dir(), "fmi_headers": (fmi_headers() / "fmi2Functions.h").is_file()}

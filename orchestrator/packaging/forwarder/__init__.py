"""The FMU's own FMI binary: fmi2_forward.c (the forwarder), fmi2_direct.c (the slave's
objects through the Python C API: the references held, the direct value route) and
fmi2_checks.c (a get or set checked against the value references), sharing fmi2_instance.h,
compiled at `railcosim build` with the system C compiler and put in front of
pythonfmu's library (docs/architecture.md, "Forwarding binary").

``plan()`` decides once per build whether FMUs get it: a C compiler and this Python's headers
are needed (else the FMUs stay plain pythonfmu FMUs and the build says so on stderr); this
Python's shared libpython must exist (else a UserError naming where it looked). ``install``
rewrites a built FMU: pythonfmu's ``binaries/linux64/<id>.so`` becomes ``<id>_pythonfmu.so``,
the forwarder takes its name, ``resources/railcosim_python.txt`` holds the Python the
forwarder starts in a process that has none, ``resources/railcosim_value_references.txt``
the value references it lets through to pythonfmu (``value_reference_text``), and
``resources/railcosim_description.txt`` the GUID and capabilities fmi2Instantiate and the other
calls are checked against (``description_text``).
"""
from __future__ import annotations

import os
import shutil
import subprocess
import sysconfig
import tempfile
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Optional, Union

from orchestrator.errors import UserError
from orchestrator.library_shortcuts import fmi_headers

HERE = Path(__file__).resolve().parent
#: the C files compiled into one library, and the header they share
SOURCES = (HERE / "fmi2_forward.c", HERE / "fmi2_direct.c", HERE / "fmi2_checks.c")
HEADER = HERE / "fmi2_instance.h"
SETTINGS_MEMBER = "resources/railcosim_python.txt"
VALUE_REFERENCES_MEMBER = "resources/railcosim_value_references.txt"
DESCRIPTION_MEMBER = "resources/railcosim_description.txt"
#: the CoSimulation attributes the forwarder answers by (a call the FMU does not offer: fmi2Error)
CAPABILITIES = ("canGetAndSetFMUstate", "canSerializeFMUstate", "providesDirectionalDerivative",
                "canInterpolateInputs", "maxOutputDerivativeOrder")
FMI_TYPES = ("Real", "Integer", "Boolean", "String")
MARKER_SYMBOL = "railcosim_forwarder"
PLATFORM = "linux64"


@dataclass(frozen=True)
class Forwarder:
    compiler: str
    settings: str          # the text of resources/railcosim_python.txt

    def fingerprint(self) -> bytes:
        """What an FMU's content hash must change with: the forwarder's sources, this module
        (it writes the value-reference table) and the Python settings. The table's content is
        the modelDescription's, which the hashed sources already determine."""
        return b"".join(path.read_bytes() for path in (*SOURCES, HEADER)) + Path(__file__).read_bytes() \
            + self.settings.encode()


@dataclass(frozen=True)
class NoForwarder:
    reason: str

    def fingerprint(self) -> bytes:
        return b"plain pythonfmu binary"


def find_compiler() -> Optional[str]:
    for name in (os.environ.get("CC"), "cc", "gcc", "clang"):
        if name:
            found = shutil.which(name)
            if found:
                return found
    return None


def plan() -> Union[Forwarder, NoForwarder]:
    import platform
    import sys

    if not sys.platform.startswith("linux") or platform.machine() not in ("x86_64", "AMD64"):
        return NoForwarder(f"the forwarding binary is built for linux64 only, not {sys.platform}/{platform.machine()}")
    compiler = find_compiler()
    if compiler is None:
        return NoForwarder("no C compiler (looked for $CC, cc, gcc, clang)")
    include = sysconfig.get_config_var("INCLUDEPY") or ""
    if not (Path(include) / "Python.h").is_file():
        return NoForwarder(f"no Python.h in {include or '(sysconfig INCLUDEPY empty)'}")
    from orchestrator.hostenv import fmu_python_settings

    settings = "".join(f"{key}={value}\n" for key, value in fmu_python_settings().items())
    return Forwarder(compiler, settings)


def compile_forwarder(forwarder: Forwarder, output: Path) -> None:
    command = [forwarder.compiler, "-shared", "-fPIC", "-O2", "-fvisibility=hidden",
               f"-I{fmi_headers()}", f"-I{sysconfig.get_config_var('INCLUDEPY')}",
               "-o", str(output), *map(str, SOURCES), "-ldl", "-lpthread"]
    proc = subprocess.run(command, capture_output=True, text=True)
    if proc.returncode != 0:
        first = (proc.stderr.strip().splitlines() or [f"exit {proc.returncode}"])[0]
        raise UserError(f"compiling {', '.join(p.name for p in SOURCES)} in {HERE} with {forwarder.compiler} "
                        f"failed: {first}")


def value_reference_text(model_description: bytes) -> str:
    """The forwarder's table (resources/railcosim_value_references.txt) from a modelDescription.xml.

    One line per FMI type with every value reference of that type (``Real 0 1 2``; an
    Enumeration is read and written as Integer), and one line ``<Type>:set`` with those
    fmi2Set<Type> may write: FMI 2.0 allows a set of an input, a parameter, or a variable with
    initial exact or approx, never of a constant, an independent variable or a calculated output.
    """
    from xml.etree import ElementTree

    valid = {t: [] for t in FMI_TYPES}
    settable = {t: [] for t in FMI_TYPES}
    root = ElementTree.fromstring(model_description)
    for variable in root.iter("ScalarVariable"):
        kinds = [child.tag for child in variable if child.tag in (*FMI_TYPES, "Enumeration")]
        if not kinds:
            continue
        fmi_type = "Integer" if kinds[0] == "Enumeration" else kinds[0]
        vr = int(variable.get("valueReference"))
        valid[fmi_type].append(vr)
        causality = variable.get("causality", "local")
        initial = variable.get("initial")
        if variable.get("variability") != "constant" and causality != "independent" and (
                causality in ("parameter", "input") or initial in ("exact", "approx")):
            settable[fmi_type].append(vr)
    lines = ["# railcosim_value_references 1: written by `railcosim build` from modelDescription.xml,"
             " read by the FMU's forwarding binary (docs/architecture.md, \"Forwarding binary\")"]
    for fmi_type in FMI_TYPES:
        lines.append(" ".join([fmi_type, *map(str, sorted(valid[fmi_type]))]))
        lines.append(" ".join([f"{fmi_type}:set", *map(str, sorted(settable[fmi_type]))]))
    return "\n".join(lines) + "\n"


def description_text(model_description: bytes) -> str:
    """The forwarder's copy of what it checks (resources/railcosim_description.txt): ``guid=``,
    ``CoSimulation=1`` when the FMU has that interface, and each of CAPABILITIES as a number (a
    boolean 1/0). A host need not extract modelDescription.xml (fmpy.simulate_fmu does not), so
    the binary cannot read it there."""
    from xml.etree import ElementTree

    root = ElementTree.fromstring(model_description)
    co_simulation = root.find("CoSimulation")
    lines = ["# railcosim_description 1: written by `railcosim build` from modelDescription.xml,"
             " read by the FMU's forwarding binary (docs/architecture.md, \"Forwarding binary\")",
             f"guid={root.get('guid')}", f"CoSimulation={int(co_simulation is not None)}"]
    for name in CAPABILITIES:
        value = co_simulation.get(name, "0") if co_simulation is not None else "0"
        lines.append(f"{name}={ {'true': 1, 'false': 0}.get(value, value) }")
    return "\n".join(lines) + "\n"


def install(fmu_path: Path, model_identifier: str, forwarder: Forwarder) -> None:
    """Put the forwarder in front of pythonfmu's linux64 binary inside ``fmu_path``."""
    binary = f"binaries/{PLATFORM}/{model_identifier}.so"
    renamed = f"binaries/{PLATFORM}/{model_identifier}_pythonfmu.so"
    with tempfile.TemporaryDirectory(prefix="railcosim_forwarder_") as tmp:
        compiled = Path(tmp) / f"{model_identifier}.so"
        compile_forwarder(forwarder, compiled)
        rewritten = Path(tmp) / "out.fmu"
        with zipfile.ZipFile(fmu_path) as source, \
                zipfile.ZipFile(rewritten, "w", zipfile.ZIP_DEFLATED) as target:
            names = source.namelist()
            if binary not in names:
                raise RuntimeError(f"{fmu_path}: pythonfmu wrote no {binary}")
            description = source.read("modelDescription.xml")  # before writestr moves the infos
            table = value_reference_text(description)
            for info in source.infolist():
                data = source.read(info)
                if info.filename == binary:
                    info.filename = renamed
                if info.filename in (SETTINGS_MEMBER, VALUE_REFERENCES_MEMBER, DESCRIPTION_MEMBER):
                    continue
                target.writestr(info, data)
            target.write(compiled, binary)
            target.writestr(SETTINGS_MEMBER, forwarder.settings)
            target.writestr(VALUE_REFERENCES_MEMBER, table)
            target.writestr(DESCRIPTION_MEMBER, description_text(description))
        shutil.move(str(rewritten), fmu_path)

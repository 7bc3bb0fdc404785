"""Where the DCP slaves of a run are, the master's side of hardware in the loop (docs/hil.md):
``--swap NAME=dcp://HOST:PORT[?dcpx=FILE&deadline_ms=D&timeout_s=T]`` (:func:`parse_swap`) or
a component declared as a DCP slave in the SSD (:func:`declared_targets`), each slave's
``.dcpx`` read and checked against the system before anything starts, and a DCP component's
ports from its ``.dcpx``. The slave itself, driven as a component, is
orchestrator/dcp/remote_slave.py's :class:`RemoteDcpSlave`.
"""
from __future__ import annotations

import socket
import urllib.parse
from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path
from typing import Dict, Mapping, Optional, Tuple

from orchestrator.dcp import dcpx
from orchestrator.dcp.dcpx import SlaveDescription
from orchestrator.errors import UserError
from orchestrator.fmu import Interface
from orchestrator.graph import TICKS_PER_SECOND
from orchestrator.ports import element_names

DEFAULT_DEADLINE_MS = 50.0
DEFAULT_TIMEOUT_S = 2.0


# ---- where the slave is ------------------------------------------------------------------------
@dataclass(frozen=True)
class DcpTarget:
    """A swapped component's slave: its control address, its .dcpx and the loss parameters."""

    component: str
    host: str
    port: int
    dcpx: Optional[Path]
    deadline_s: float = DEFAULT_DEADLINE_MS / 1e3
    timeout_s: float = DEFAULT_TIMEOUT_S
    text: str = ""

    @property
    def url(self) -> str:
        return f"dcp://{self.host}:{self.port}"


def parse_swap(text: str) -> DcpTarget:
    """``NAME=dcp://HOST:PORT[?dcpx=FILE&deadline_ms=D&timeout_s=T]`` → :class:`DcpTarget`; a
    malformed one is a UserError naming it."""
    what = f"--swap {text}"
    name, sep, url = text.partition("=")
    if not sep or not name.strip():
        raise UserError(f"{what}: expected NAME=dcp://HOST:PORT[?dcpx=FILE]")
    parsed = urllib.parse.urlsplit(url.strip())
    if parsed.scheme != "dcp":
        raise UserError(f"{what}: only dcp:// addresses are supported (DCP 1.0 over UDP_IPv4)")
    try:
        host, port = parsed.hostname, parsed.port
    except ValueError:
        host, port = None, None
    if not host or not port:
        raise UserError(f"{what}: expected dcp://HOST:PORT with a port from 1 to 65535")
    try:
        socket.inet_aton(socket.gethostbyname(host))
    except OSError:
        raise UserError(f"{what}: host {host!r} cannot be resolved") from None
    query = urllib.parse.parse_qs(parsed.query, keep_blank_values=True)
    unknown = set(query) - {"dcpx", "deadline_ms", "timeout_s"}
    if unknown:
        raise UserError(f"{what}: unknown option(s) {', '.join(sorted(unknown))} (dcpx, deadline_ms, timeout_s)")

    def number(key, default, low, high):
        if key not in query:
            return default
        try:
            value = float(query[key][-1])
        except ValueError:
            value = float("nan")
        if not low <= value <= high:
            raise UserError(f"{what}: {key} must be a number from {low:g} to {high:g}")
        return value

    deadline_ms = number("deadline_ms", DEFAULT_DEADLINE_MS, 0.1, 60_000)
    timeout_s = number("timeout_s", DEFAULT_TIMEOUT_S, 0.01, 600)
    dcpx = Path(query["dcpx"][-1]) if "dcpx" in query else None
    return DcpTarget(name.strip(), socket.gethostbyname(host), port, dcpx, deadline_ms / 1e3, timeout_s, text)


# ---- the slave description ---------------------------------------------------------------------
def read_description(path: Path) -> SlaveDescription:
    """A slave's .dcpx as the master reads it (validated against the standard's schema by
    orchestrator/dcp/dcpx.py); a missing or malformed file is one UserError."""
    path = Path(path)
    if not path.is_file():
        raise UserError(f"{path}: DCP slave description (.dcpx) not found")
    description = dcpx.read_dcpx(path)
    description.path = path
    return description


def resolution_for(description: SlaveDescription, step_s: Fraction) -> Tuple[Fraction, int]:
    """(time resolution, steps) for a component's step, or one UserError naming the .dcpx."""
    try:
        return description.resolution_for(step_s)
    except ValueError as error:
        raise UserError(f"{description.path}: {error}") from None


def dcpx_for(target: DcpTarget, fmu_path: Path) -> Path:
    """The .dcpx of a swap: the one given (``?dcpx=``), else the one beside the component's FMU
    (``LocoReceiver.fmu`` → ``LocoReceiver.dcpx``, where ``railcosim dcp-slave`` writes it)."""
    if target.dcpx is not None:
        return target.dcpx
    beside = Path(fmu_path).with_suffix(".dcpx")
    if not beside.is_file():
        raise UserError(f"--swap {target.text}: no {beside.name} beside {fmu_path}; give the slave's "
                        f"description with ?dcpx=FILE (DCP has no request for it)")
    return beside


def declared_targets(system) -> Dict[str, DcpTarget]:
    """The system's components declared as DCP slaves (a .dcpx source and ``rcs:DcpSlave``)."""
    targets = {}
    for name, component in system.components.items():
        address = component.dcp_slave
        if address is None:
            continue
        options = "&".join(f"{key}={address[key]}" for key in ("deadline_ms", "timeout_s") if key in address)
        text = f"{name}=dcp://{address.get('host', '')}:{address.get('port', '')}?dcpx={component.fmu_path}" \
               + (f"&{options}" if options else "")
        try:
            targets[name] = parse_swap(text)
        except UserError as error:
            raise UserError(f"{component.origin}: DcpSlave of {name!r}: {str(error).partition(': ')[2]}") from None
    return targets


#: DCP data type → the FMI type a port of a .dcpx-declared component gets ([U] uint8 is Boolean,
#: as railcosim dcp-slave carries FMI Booleans)
_FMI_TYPES = {"float64": "Real", "float32": "Real", "uint8": "Boolean", "string": "String"}


def dcpx_interface(path: Path) -> Interface:
    """A component's ports from its .dcpx (a component declared as a DCP slave in the SSD): one
    port per scalar variable, one per element of an array (``e_coil[3]``, ``u[2,1]``)."""
    from orchestrator.fmu import Variable

    description = read_description(path)
    variables, fail_safe = {}, {}
    for variable in description.variables:
        names = element_names(variable.name, variable.dims)
        if variable.fail_safe is not None and not variable.dims:
            fail_safe[variable.name] = variable.fail_safe
        fmi_type = _FMI_TYPES.get(variable.data_type.name, "Integer")
        for name in names:
            # value references of their own: an array's elements share the slave's one
            parameter = variable.causality in ("parameter", "structuralParameter")
            variables[name] = Variable(name, len(variables), fmi_type, "parameter" if parameter else variable.causality,
                                       "fixed" if parameter else "discrete" if fmi_type != "Real" else "continuous",
                                       None, None)
    return Interface(description.name or Path(path).stem, variables, {}, None, str(description.uuid),
                     "DCP slave", None, fail_safe=fail_safe)


def swapped_descriptions(swaps: Mapping[str, DcpTarget], graph) -> Dict[str, SlaveDescription]:
    """Each swap's slave description, checked against the system before anything starts: the
    component exists, the .dcpx reads, a time resolution fits the component's step."""
    descriptions = {}
    for name, target in swaps.items():
        node = graph.nodes.get(name)
        if node is None:
            raise UserError(f"--swap {target.text}: the system has no component {name!r} "
                            f"(components: {', '.join(graph.order)})")
        description = read_description(dcpx_for(target, Path(node.fmu_path)))
        resolution_for(description, Fraction(node.step_ticks, TICKS_PER_SECOND))
        descriptions[name] = description
    return descriptions

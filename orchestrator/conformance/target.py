"""What `conform` tests: a target named on the command line, opened as a slave of the master's
protocol (orchestrator/protocols.py), so the runner drives an FMU as the master does and a
`dcp://host:port` device can be one more branch of :func:`open_target`."""
from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Dict, List, Tuple

from orchestrator.errors import UserError
from orchestrator.fmu import FmuSlave, Interface, new_workdir, read_interface, remove_workdir
from orchestrator.protocols import Slave

_ELEMENT = re.compile(r"^(?P<base>[^\[]+)\[(?P<index>[0-9, ]+)\]$")


@dataclass
class Target:
    """An opened target: its variables and a factory of fresh instances (one per vector)."""

    name: str                               # as the user gave it
    interface: Interface
    make_slave: Callable[[str], Slave]
    close: Callable[[], None]

    def elements(self, port: str) -> List[str]:
        """The variables of a port: itself if scalar, else its elements in index order
        (``occupied`` → occupied[1] … occupied[K]; ``u_tx[2]`` → u_tx[2,1] … u_tx[2,N])."""
        variables = self.interface.variables
        if port in variables:
            return [port]
        match = _ELEMENT.match(port)
        base, prefix = (match["base"], tuple(int(i) for i in match["index"].split(","))) if match else (port, ())
        found: List[Tuple[Tuple[int, ...], str]] = []
        for name in variables:
            m = _ELEMENT.match(name)
            if m and m["base"] == base:
                index = tuple(int(i) for i in m["index"].split(","))
                if index[:len(prefix)] == prefix and len(index) > len(prefix):
                    found.append((index, name))
        return [name for _, name in sorted(found)]

    def shape(self, port: str) -> Tuple[int, ...]:
        """Array shape of a port from its element names (() for a scalar)."""
        names = self.elements(port)
        if names == [port]:
            return ()
        indices = [tuple(int(i) for i in _ELEMENT.match(n)["index"].split(",")) for n in names]
        return tuple(max(column) for column in zip(*indices))


def open_target(target: str, role: str, required_ports: List[str]) -> Target:
    """Open ``target`` for ``role``; a target that is not an FMI 2.0 co-simulation FMU, or lacks
    one of the role's ports, is a UserError naming it."""
    if target.startswith("dcp://"):
        raise UserError(f"{target}: dcp:// targets are not supported yet (give an .fmu)")
    path = Path(target)
    if path.is_dir() or not path.exists():
        raise UserError(f"{target}: no such FMU file")
    interface = read_interface(path)
    missing = [port for port in required_ports if not _has_port(interface, port)]
    if missing:
        raise UserError(f"{target}: does not have the ports of role {role} "
                        f"(missing: {', '.join(missing)}; model {interface.model_identifier})")
    workdir = new_workdir()
    count = [0]

    def make_slave(label: str) -> Slave:
        count[0] += 1
        slave = FmuSlave(f"conform{count[0]}_{label}", path, interface, workdir)
        return slave

    return Target(target, interface, make_slave, lambda: remove_workdir(workdir))


def _has_port(interface: Interface, port: str) -> bool:
    if port in interface.variables:
        return True
    return any(_ELEMENT.match(name) and _ELEMENT.match(name)["base"] == port for name in interface.variables)


def variable_types(interface: Interface, names: List[str]) -> Dict[str, str]:
    return {name: interface.variables[name].type for name in names}

"""What `conform` tests: a target named on the command line, opened as a slave of the master's
protocol (orchestrator/protocols.py), so the runner drives an FMU as the master does and a
`dcp://host:port` device can be one more branch of :func:`open_target`."""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Callable, List, Optional, Tuple

from orchestrator.errors import UserError
from orchestrator.fmu import FmuSlave, Interface, new_workdir, read_interface, remove_workdir
from orchestrator.ports import split_element
from orchestrator.protocols import Slave



def _element(name: str) -> Optional[Tuple[str, Tuple[int, ...]]]:
    """(base, index) of an array element's name, None for any other name."""
    split = split_element(name)
    return split if split and split[1] else None


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
        base, prefix = _element(port) or (port, ())
        found: List[Tuple[Tuple[int, ...], str]] = []
        for name in variables:
            element = _element(name)
            if element and element[0] == base:
                index = element[1]
                if index[:len(prefix)] == prefix and len(index) > len(prefix):
                    found.append((index, name))
        return [name for _, name in sorted(found)]

    def shape(self, port: str) -> Tuple[int, ...]:
        """Array shape of a port from its element names (() for a scalar)."""
        names = self.elements(port)
        if names == [port]:
            return ()
        indices = [_element(n)[1] for n in names]
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
    return any((_element(name) or ("",))[0] == port for name in interface.variables)

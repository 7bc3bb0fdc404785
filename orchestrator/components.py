"""What each component of a run is made as, decided in one place: an FMU through fmpy, the same
FMU's facade in this interpreter (``--in-process``), or a remote DCP slave (``--swap``, or a
.dcpx source the SSD declares ``rcs:DcpSlave``: orchestrator/dcp/, docs/hil.md).

The graph reads each component's ports through :func:`interface_of` (orchestrator/graph.py takes
it as ``interface_of``); a run decides the kinds before anything starts (:func:`plan_components`,
every remote slave's description checked against the system) and makes each component through
:meth:`Components.make`; validation (orchestrator/validation.py) makes them the same way with the
rig not contacted. Nothing else names a kind.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Dict, Mapping, Optional

from orchestrator.dcp.dcpx import SlaveDescription
from orchestrator.dcp.master import DcpTarget, dcpx_interface, declared_targets, swapped_descriptions
from orchestrator.dcp.pdu import OpMode
from orchestrator.fmu import Interface, make_slave, read_interface
from orchestrator.graph import Node, SystemGraph
from orchestrator.protocols import Slave
from orchestrator.ssp import SystemDescription

#: the kinds of component, as :meth:`Components.kind` names them
FMU, IN_PROCESS, DCP_SLAVE = "FMU", "in process", "DCP slave"


def interface_of(source: str) -> Interface:
    """A component's ports from its source: a DCP slave's .dcpx, else an FMU's modelDescription."""
    if Path(source).suffix == ".dcpx":
        return dcpx_interface(Path(source))
    return read_interface(source)


@dataclass(frozen=True)
class RemoteComponent:
    """A component driven as a remote DCP slave: where it is, and its description (.dcpx)."""

    target: DcpTarget
    description: SlaveDescription


@dataclass(frozen=True)
class Components:
    """How the components of one run are made: the remote DCP slaves by name, every other one
    an FMU, through fmpy or (``in_process``) as its facade in this interpreter."""

    in_process: bool = False
    remote: Mapping[str, RemoteComponent] = field(default_factory=dict)

    def kind(self, name: str) -> str:
        return DCP_SLAVE if name in self.remote else IN_PROCESS if self.in_process else FMU

    def make(self, name: str, node: Node, workdir: Optional[Path], contact: bool = True) -> Slave:
        """Component ``name`` as a slave; its FMU extracted into ``workdir`` (None: where the
        process keeps its extractions). ``contact`` False (validation): a remote slave checked
        against its description, nothing sent to the rig."""
        if self.kind(name) == DCP_SLAVE:
            from orchestrator.dcp.remote_slave import OfflineRemoteDcpSlave, RemoteDcpSlave

            remote = self.remote[name]
            made = RemoteDcpSlave if contact else OfflineRemoteDcpSlave
            return made(name, node.interface, remote.target, remote.description, node.step_ticks)
        return make_slave(name, Path(node.fmu_path), node.interface, workdir, self.kind(name) == IN_PROCESS)

    @property
    def needs_real_time(self) -> bool:
        """A remote slave that steps on its own clock only (no NonRealTime mode) needs the
        master paced at real time."""
        return any(OpMode.NRT not in remote.description.op_modes for remote in self.remote.values())


def plan_components(system: SystemDescription, graph: SystemGraph, swaps: Mapping[str, DcpTarget],
                    in_process: bool, attempt: Callable[[Callable[[], object]], object]) -> Components:
    """The run's components: those the SSD declares DCP slaves and the ``swaps`` (which win),
    each slave's description read and checked against its component (it exists, its time
    resolution fits the step); each part through ``attempt`` (orchestrator/plan.py plan_run)."""
    targets: Dict[str, DcpTarget] = {**(attempt(lambda: declared_targets(system)) or {}), **swaps}
    descriptions = attempt(lambda: swapped_descriptions(targets, graph)) or {}
    return Components(in_process, {name: RemoteComponent(targets[name], description)
                                   for name, description in descriptions.items()})

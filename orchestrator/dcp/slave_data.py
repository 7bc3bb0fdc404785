"""The data exchange of ``railcosim dcp-slave``: the FMU's inputs and outputs bound to the DCP
variables, DAT PDUs in (decoded, their sequence ids judged, applied to the FMU's inputs) and
out (each data_id's outputs, its sequence ids), the sockets inputs arrive on, and what a
session counts. DAT PDUs are never answered: a malformed, unknown or out-of-date one is dropped
and counted.
"""
from __future__ import annotations

import socket
from dataclasses import dataclass
from typing import Dict, Tuple

import numpy as np

from orchestrator.dcp import states
from orchestrator.dcp.pdu import Pdu, PduError, PduType, Scope, next_seq
from orchestrator.dcp.slave_config import DataIdConfig

#: a DAT whose sequence id is more than this ahead of the last one applied is not taken as the
#: stream's new position unless the next one follows it within the window
DAT_SEQ_WINDOW = 1024
#: a DAT at most this many behind the last one applied is a repeat or reordered (stale); one
#: farther behind is judged as a jump, so a datagram injected ahead of the stream costs the real
#: stream at most this many datagrams plus one, not the whole forward window
DAT_STALE_WINDOW = 16
#: addresses other than the master's each named in one line, up to this many (then only counted)
FOREIGN_ADDRESSES_NAMED = 8


@dataclass
class Counters:
    """What a session counts (printed when the slave ends)."""
    dat_received: int = 0
    dat_missing: int = 0          # gaps in the incoming sequence ids
    dat_stale: int = 0            # older than one already applied: dropped
    dat_rejected: int = 0         # unknown data_id, wrong length, not allowed in this state
    dat_out_of_window: int = 0    # sequence id too far from the last applied, not confirmed: dropped
    dat_sent: int = 0
    dat_dropped: int = 0          # by --drop-data
    nacks: int = 0
    malformed: int = 0            # datagrams that are no PDU at all (unanswerable)
    foreign: int = 0              # datagrams from addresses other than the registered master's: ignored
    foreign_addresses: int = 0    # how many such addresses (counted up to FOREIGN_ADDRESSES_NAMED + 1)
    steps: int = 0
    overruns: int = 0             # SRT: steps started after their deadline
    worst_lateness_s: float = 0.0

    def line(self) -> str:
        addresses = (f"{self.foreign_addresses}" if self.foreign_addresses <= FOREIGN_ADDRESSES_NAMED
                     else f"more than {FOREIGN_ADDRESSES_NAMED}")
        return (f"{self.steps} steps, DAT in {self.dat_received} (missing {self.dat_missing}, "
                f"stale {self.dat_stale}, outside the window {self.dat_out_of_window}, rejected {self.dat_rejected}), "
                f"DAT out {self.dat_sent} (dropped {self.dat_dropped}), RSP_nack {self.nacks}, "
                f"malformed {self.malformed}, ignored from other addresses {self.foreign} ({addresses} addresses), "
                f"overruns {self.overruns} (worst {self.worst_lateness_s * 1e3:.3f} ms late)")


def is_local(ip: str) -> bool:
    """Is ``ip`` an address of this machine (one a socket can be bound to)?"""
    probe = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        probe.bind((ip, 0))
        return True
    except OSError:
        return False
    finally:
        probe.close()


@dataclass
class _Binding:
    """One DCP variable's place in the FMU's value buffers."""
    var: object                 # DcpVariable
    fmi_type: str
    index: np.ndarray           # positions in the FMU buffer of that type


class DataExchange:
    """One slave's data (``slave``: its DcpSlaveServer): its FMU's bound values, its DAT PDUs, its
    data sockets."""

    def __init__(self, slave):
        self.slave = slave
        self.host, self.port = slave.host, slave.port
        self.data_sockets: Dict[Tuple[str, int], socket.socket] = {}
        self._local_addresses: Dict[str, bool] = {}     # sender IP → an address of this machine
        self.bindings: Dict[int, _Binding] = {}
        self.fmi_types: Dict[str, str] = {}

    # ---- the FMU's values ----------------------------------------------------------------
    def bind_fmu(self) -> None:
        """Bind every input and output of the slave's FMU; remember where each DCP variable lives."""
        fmu = self.slave.fmu
        interface = fmu.interface
        self.fmi_types = {name: v.type for name, v in interface.variables.items()}
        tables = {"input": {}, "output": {}}
        self.bindings = {}
        for var in self.slave.desc.variables:
            if var.causality not in tables:
                continue
            names = var.fmi_names or (var.name,)
            fmi_type = interface.variables[names[0]].type
            vrs = tables[var.causality].setdefault(fmi_type, [])
            start = len(vrs)
            vrs.extend(interface.variables[n].vr for n in names)
            self.bindings[var.vr] = _Binding(var, fmi_type, np.arange(start, start + len(names)))
        fmu.bind(tables["input"], tables["output"])
        for binding in self.bindings.values():            # inputs start at their start values
            var = binding.var
            if var.causality == "input" and var.start is not None:
                self._put(binding, var.start if len(var.start) == var.count else var.start * var.count)

    def _put(self, binding: _Binding, values) -> None:
        buffer = self.slave.fmu.inputs[binding.fmi_type]
        if binding.fmi_type == "String":
            buffer.values[binding.index[0]] = values if isinstance(values, str) else str(values[0])
        else:
            buffer.values[binding.index] = values

    # ---- DAT in --------------------------------------------------------------------------
    def receive(self, pdu: Pdu) -> None:
        """A DAT_input_output: its values into the FMU's inputs, or dropped and counted."""
        slave, counters = self.slave, self.slave.counters
        config = slave.config.inputs.get(pdu.data_id)
        if config is None or config.codec is None or not states.allowed(slave.state, PduType.DAT_input_output) \
                or slave.fmu is None:
            counters.dat_rejected += 1
            return
        try:
            values = config.codec.decode(pdu.payload)
        except PduError:
            counters.dat_rejected += 1
            return
        if config.last_seq is not None and not self._in_sequence(config, pdu.pdu_seq_id):
            return
        config.last_seq, config.jump_seq = pdu.pdu_seq_id, None
        counters.dat_received += 1
        for vr, value in zip(config.order, values):
            self._put(self.bindings[vr], value)

    def _in_sequence(self, config: DataIdConfig, seq: int) -> bool:
        """Sequence ids in DCP's modular arithmetic (uint16): 1 … DAT_SEQ_WINDOW ahead of the last
        one applied is next (the ids between are missing); 0 or up to DAT_STALE_WINDOW behind is
        a repeat or reordered (stale). Farther either way, a datagram is taken only when it
        follows the previous such one within the window (the stream really jumped, e.g. after a
        long loss, or a datagram injected ahead of it moved the position), so no single datagram
        can make more than DAT_STALE_WINDOW + 1 later ones of the stream look stale."""
        counters = self.slave.counters
        gap = (seq - config.last_seq) & 0xFFFF
        if 1 <= gap <= DAT_SEQ_WINDOW:
            counters.dat_missing += gap - 1
            return True
        if gap == 0 or gap >= 0x10000 - DAT_STALE_WINDOW:
            counters.dat_stale += 1
            return False
        if config.jump_seq is not None and 1 <= (seq - config.jump_seq) & 0xFFFF <= DAT_SEQ_WINDOW:
            ahead = (config.jump_seq - config.last_seq) & 0xFFFF     # a jump back misses nothing
            counters.dat_missing += (ahead - 1 if ahead < 0x8000 else 0) + ((seq - config.jump_seq) & 0xFFFF) - 1
            return True
        config.jump_seq = seq
        counters.dat_out_of_window += 1
        return False

    # ---- DAT out -------------------------------------------------------------------------
    def send_outputs(self, initialization: bool, due=None) -> None:
        """Every output data_id of the scope (initialization or run), or those in ``due``."""
        slave, counters = self.slave, self.slave.counters
        wanted = (Scope.Initialization_Run_NonRealTime, Scope.Initialization) if initialization \
            else (Scope.Initialization_Run_NonRealTime, Scope.Run_NonRealTime)
        for data_id, config in slave.config.outputs.items():
            if config.scope not in wanted or (due is not None and data_id not in due):
                continue
            values = []
            for vr in config.order:
                binding = self.bindings[vr]
                buffer = slave.fmu.outputs[binding.fmi_type]
                if binding.fmi_type == "String":
                    values.append(buffer.values[binding.index[0]])
                else:
                    values.append(buffer.values[binding.index])
            pdu = Pdu(PduType.DAT_input_output, pdu_seq_id=config.send_seq, data_id=data_id,
                      payload=config.codec.encode(values))
            config.send_seq = next_seq(config.send_seq)
            if slave.drop_data and slave.rng.random() < slave.drop_data:
                counters.dat_dropped += 1
                continue
            counters.dat_sent += 1
            slave.send(pdu, config.address)

    # ---- the sockets ---------------------------------------------------------------------
    def bind_sources(self) -> None:
        """A socket for every address inputs arrive on other than the control port."""
        for address in set(self.slave.config.sources.values()):
            if address[1] == self.port or address in self.data_sockets:
                continue          # inputs on the control port arrive on the control socket
            s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            try:
                s.bind(address)
            except OSError:
                s.close()
                raise
            s.setblocking(False)
            self.data_sockets[address] = s

    def close_data_sockets(self) -> None:
        for s in self.data_sockets.values():
            s.close()
        self.data_sockets.clear()

    def is_own(self, address: Tuple[str, int]) -> bool:
        """Sent by one of this slave's own sockets: its outputs looped back to its inputs (a
        CFG_target_network_information naming the slave itself, as DCPLib's example does)."""
        ports = {self.port} | {s.getsockname()[1] for s in self.data_sockets.values()}
        if address[1] not in ports:
            return False
        if self.host != "0.0.0.0":
            return address[0] == self.host
        # serving every interface: the sender must be an address of this machine, not any host
        # that sends from a port number the slave happens to use
        local = self._local_addresses.get(address[0])
        if local is None:
            local = self._local_addresses[address[0]] = is_local(address[0])
        return local

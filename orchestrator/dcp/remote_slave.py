"""A remote DCP slave as a component of a system: the orchestrator as DCP master (hardware in
the loop).

:class:`RemoteDcpSlave` implements the engine's slave protocol (orchestrator/protocols.py) by
driving a remote DCP 1.0 slave over UDP_IPv4 with the PDUs of orchestrator/dcp/pdu.py, so the
master steps it like any FMU. The component keeps the ports its FMU declares in the system; the
slave's ``.dcpx`` must have a variable of the same name for every port the system uses
(connected, recorded or set). Which slave stands in for a component is said on the command
line, ``--swap NAME=dcp://HOST:PORT[?dcpx=FILE&deadline_ms=D&timeout_s=T]``, or in the SSD
(orchestrator/dcp/master.py reads both); :class:`SlaveLink` is its UDP link to the slave.

Operating modes (docs/hil.md):

* **non-real-time** (the slave offers NonRealTime): each step of the component sends its
  inputs (DAT_input_output), then STC_do_step, waits for COMPUTED, then STC_send_outputs and
  the outputs (DAT_input_output) — the slave steps exactly when the master says;
* **soft real time** (a slave that offers only SoftRealTime, as bench hardware does): the slave
  runs on its own clock; the master is paced to the wall clock (orchestrator/pacing.py), sends
  the inputs each step and uses the newest outputs received.

Loss: outputs that do not arrive are *lost* — in non-real-time mode, those not received within
``deadline_ms`` after the slave announced it sent them (RUNNING after STC_send_outputs); in soft
real time, when the newest outputs arrived more than ``deadline_ms`` before the step that needs
them (arrival times from the kernel's receive timestamps where it gives them). The component's
outputs then go to their fail-safe values at once (the component's, ``Interface.fail_safe``: the
FMU declares them, docs/hil.md; never a permissive value
held past the deadline), counted in summary.json ``hil``. Outputs arriving out of sequence are
counted as *late* and dropped. A slave that does not answer a control request within
``timeout_s`` ends the run with one line naming it (results so far kept, exit 2).
"""
from __future__ import annotations

import socket
import struct
import sys
import time
from fractions import Fraction
from typing import Dict, List, Mapping, Optional, Sequence, Tuple

import numpy as np

from orchestrator.dcp.dcpx import DcpVariable, SlaveDescription
from orchestrator.dcp.master import DcpTarget, resolution_for
from orchestrator.dcp.pdu import (UDP_MAX_PDU_SIZE, DataType, OpMode, PayloadCodec, Pdu, PduError, PduType, Scope,
                                  State, decode, next_seq)
from orchestrator.errors import SimulationError, UserError
from orchestrator.fmu import Interface, ValueBuffer, make_buffers
from orchestrator.graph import TICKS_PER_SECOND
from orchestrator.ports import split_element
from orchestrator.protocols import Slave

P = PduType
_NUMERIC = {"Real", "Integer", "Boolean"}
#: data ids of the two DAT_input_output streams the master configures
INPUTS_ID, OUTPUTS_ID = 1, 2
SLAVE_ID = 1                                   # the one slave each RemoteDcpSlave drives
#: set-up requests whose state change may take a model's initialisation (SETTLE_S)
_SLOW = frozenset({P.STC_prepare, P.STC_configure, P.STC_initialize, P.STC_run, P.STC_stop})
_RESPONSES = frozenset({P.RSP_ack, P.RSP_nack, P.RSP_state_ack, P.RSP_error_ack, P.RSP_log_ack})
#: the kernel's receive timestamps (Linux socket(7): SO_TIMESTAMPNS, a struct timespec of
#: CLOCK_REALTIME per datagram), which Python's socket module does not name
_SO_TIMESTAMPNS = 35 if sys.platform.startswith("linux") else None
_TIMESPEC = struct.Struct("@qq")
#: [U] the longest a slave may take to reach the state a set-up request leads to once it has
#: acknowledged it (a model's initialisation: the ATO plans its whole trajectory there)
SETTLE_S = 120.0


# ---- statistics ----------------------------------------------------------------------------------
class HilStats:
    """What summary.json ``hil`` says of one swapped component."""

    def __init__(self, target: DcpTarget, mode: str):
        self.target, self.mode = target, mode
        self.sent = self.received = self.lost = self.late = self.overruns = self.ignored = 0
        self.fail_safe_steps = 0
        self.rtt_s: List[float] = []
        self.error: Optional[str] = None

    def section(self) -> Dict[str, object]:
        rtt = np.asarray(self.rtt_s) * 1e3
        pick = (lambda q: float(np.percentile(rtt, q))) if rtt.size else (lambda q: None)
        return {"slave": self.target.url, "mode": self.mode, "pdus_sent": self.sent,
                "pdus_received": self.received, "lost": self.lost, "late": self.late,
                "fail_safe_steps": self.fail_safe_steps, "exchanges": int(rtt.size),
                "rtt_median_ms": pick(50), "rtt_p99_ms": pick(99),
                "rtt_max_ms": float(rtt.max()) if rtt.size else None,
                "overruns": self.overruns, "ignored": self.ignored, "deadline_ms": self.target.deadline_s * 1e3,
                **({"error": self.error} if self.error else {})}


# ---- the link ---------------------------------------------------------------------------------
class SlaveLink:
    """The master's link to one remote slave over UDP: a request and its answer matched by
    sequence id, the state the slave announces, the newest outputs it sent (out-of-sequence ones
    counted late and dropped; in soft real time a gap counted as outputs lost), datagrams from
    any other address ignored."""

    def __init__(self, name: str, target: DcpTarget, stats: HilStats, mode: OpMode):
        self.name, self.target, self.stats, self.mode = name, target, stats, mode
        self.sock: Optional[socket.socket] = None
        self.timestamps = False             # the socket gives each datagram's arrival time
        self.address = (target.host, target.port)
        self.slave_address: Optional[Tuple[str, int]] = None     # resolved: answers come from there
        self.seq = 0
        self.state = State.ALIVE
        self.acks: Dict[int, Pdu] = {}
        self.out_codec: Optional[PayloadCodec] = None       # the outputs' payload (set when bound)
        self.fresh_outputs: Optional[Tuple[int, List]] = None     # (seq, values) of the newest outputs
        self.newest_at = 0.0               # wall-clock arrival (time.time) of the newest outputs
        self.last_out_seq: Optional[int] = None

    def open(self) -> None:
        """The socket, bound towards the slave (its arrival timestamps where the kernel gives them)."""
        try:
            self.slave_address = (socket.gethostbyname(self.target.host), self.target.port)
        except OSError:
            self.slave_address = None       # the registration below fails and says so
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1" if self.target.host.startswith("127.") else "0.0.0.0", 0))
        if _SO_TIMESTAMPNS is not None:
            try:
                self.sock.setsockopt(socket.SOL_SOCKET, _SO_TIMESTAMPNS, 1)
                self.timestamps = True
            except OSError:
                self.timestamps = False

    def send(self, message: Pdu) -> None:
        try:
            self.sock.sendto(message.encode(), self.address)
        except OSError as error:
            raise self.gone(f"cannot send {message.type_id.name} ({error.strerror or error})") from None
        self.stats.sent += 1

    def gone(self, why: str) -> SimulationError:
        self.stats.error = f"{self.target.url} {why}"
        return SimulationError(f"{self.name}: the DCP slave at {self.target.url} {why}")

    def receive(self, until: float) -> bool:
        """Take one datagram (waiting at most until ``until``, perf_counter); False on timeout."""
        wait = until - time.perf_counter()
        if wait <= 0:
            return False
        self.sock.settimeout(wait)
        return self._take_one()

    def drain(self) -> None:
        """Take every datagram that has arrived, without waiting."""
        self.sock.setblocking(False)
        while self._take_one():
            pass

    def _take_one(self) -> bool:
        try:
            if self.timestamps:
                data, ancillary, _, sender = self.sock.recvmsg(UDP_MAX_PDU_SIZE, 64)
            else:
                (data, sender), ancillary = self.sock.recvfrom(UDP_MAX_PDU_SIZE), ()
        except (socket.timeout, BlockingIOError):
            return False
        except OSError:               # e.g. ICMP port unreachable reported on the socket
            return False
        if self.slave_address is not None and sender != self.slave_address:
            self.stats.ignored += 1   # not the slave's: DCP has no authentication, so nothing else is taken
            return True
        arrived = time.time()
        for level, kind, value in ancillary:
            if level == socket.SOL_SOCKET and kind == _SO_TIMESTAMPNS and len(value) >= _TIMESPEC.size:
                seconds, nanoseconds = _TIMESPEC.unpack_from(value)
                arrived = seconds + nanoseconds * 1e-9
        self.stats.received += 1
        try:
            message = decode(data)
        except PduError:
            return True               # a malformed datagram is dropped (it answers nothing we asked)
        kind = message.type_id
        if kind in _RESPONSES:
            self.acks[message.resp_seq_id] = message
        elif kind == P.NTF_state_changed:
            self.state = message.state_id
        elif kind == P.DAT_input_output and message.data_id == OUTPUTS_ID:
            self._take_outputs(message, arrived)
        return True

    def _take_outputs(self, message: Pdu, arrived: float) -> None:
        if self.out_codec is None:
            return
        try:
            values = self.out_codec.decode(message.payload)
        except PduError:
            return
        seq = message.pdu_seq_id
        if self.last_out_seq is not None:
            gap = (seq - self.last_out_seq) & 0xFFFF
            if gap == 0 or gap >= 0x8000:
                self.stats.late += 1       # not newer than what we have: out of sequence, dropped
                return
            if self.mode == OpMode.SRT:
                self.stats.lost += gap - 1     # sent on the slave's clock: a gap is outputs lost
        self.last_out_seq = seq
        self.fresh_outputs = (seq, values)
        self.newest_at = arrived

    def request(self, message: Pdu, reaches: Optional[State] = None) -> None:
        """Send a request; wait for its RSP_ack (RSP_nack: an error naming the code) and, with
        ``reaches``, for the slave to announce that state."""
        self.send(message)
        until = time.perf_counter() + self.target.timeout_s
        seq = message.pdu_seq_id
        while seq not in self.acks:
            if not self.receive(until):
                raise self.gone(f"stopped answering (no answer to {message.type_id.name} within "
                                 f"{self.target.timeout_s:g} s)")
        answer = self.acks.pop(seq)
        if answer.type_id == P.RSP_nack:
            code = getattr(answer.error_code, "name", f"error 0x{int(answer.error_code):04X}")
            raise self.gone(f"refused {message.type_id.name}: {code}")
        if reaches is not None:
            # the work behind a state change (loading, initialising a model) may take longer
            # than an answer: the slave has acknowledged, so it is there
            settle_s = max(self.target.timeout_s, SETTLE_S) if message.type_id in _SLOW else self.target.timeout_s
            self.await_state(reaches, message.type_id.name, time.perf_counter() + settle_s, settle_s)

    def await_state(self, state: State, after: str, until: float, within_s: Optional[float] = None) -> None:
        while self.state != state:
            if not self.receive(until):
                raise self.gone(f"stopped answering (state {state.name} not reached after {after} within "
                                 f"{within_s or self.target.timeout_s:g} s)")

    def next_seq(self) -> int:
        self.seq = next_seq(self.seq)
        return self.seq

    def stc(self, kind: PduType, reaches: Optional[State] = None) -> None:
        self.request(Pdu(kind, pdu_seq_id=self.next_seq(), receiver=SLAVE_ID, state_id=self.state), reaches)


# ---- the slave ---------------------------------------------------------------------------------
class RemoteDcpSlave(Slave):
    """One remote DCP slave driven as a component (see the module docstring)."""

    in_process = False

    def __init__(self, name: str, interface: Interface, target: DcpTarget, description: SlaveDescription,
                 step_ticks: int):
        self.name, self.interface, self.target, self.description = name, interface, target, description
        self.step_s = Fraction(step_ticks, TICKS_PER_SECOND)
        self.resolution, self.steps = resolution_for(description, self.step_s)
        if OpMode.NRT in description.op_modes:
            if not description.supports_nrt_steps(self.steps):
                raise UserError(f"{description.path}: the slave cannot step {self.steps} × {self.resolution} s "
                                f"at a time (the component's step {float(self.step_s):g} s)")
            self.mode = OpMode.NRT
        elif OpMode.SRT in description.op_modes:
            self.mode = OpMode.SRT
        else:
            raise UserError(f"{description.path}: the slave offers neither NonRealTime nor SoftRealTime "
                            "(hard real time needs a real-time master)")
        self.stats = HilStats(target, self.mode.name)
        self.link = SlaveLink(name, target, self.stats, self.mode)
        self.inputs: Dict[str, ValueBuffer] = {}
        self.outputs: Dict[str, ValueBuffer] = {}
        self._dat_seq = 0
        self._registered = False
        self._exchanged = False             # an initialisation exchange took place
        self._in_map: List[tuple] = []      # (buffer, index, payload entry, element, port name)
        self._out_map: List[tuple] = []
        self._constant_inputs: List[tuple] = []     # (payload entry, element, value): set, not connected
        self._out_values: Optional[List[float]] = None              # the values the outputs show now
        self._fail_safe: List[Optional[float]] = []
        self._in_codec = None
        self._in_remotes: List[DcpVariable] = []
        self._out_remotes: List[DcpVariable] = []
        self._in_arrays: List[np.ndarray] = []

    # ---- lifecycle -------------------------------------------------------------------------
    def instantiate(self) -> None:
        self.link.open()
        try:
            self.link.request(Pdu(P.STC_register, pdu_seq_id=self.link.next_seq(), receiver=SLAVE_ID, state_id=State.ALIVE,
                              slave_uuid=self.description.uuid, op_mode=self.mode),
                          reaches=State.CONFIGURATION)
        except SimulationError as error:
            raise UserError(str(error)) from None     # never started: bad input (address), exit 2
        self._registered = True

    def bind(self, inputs: Mapping[str, Sequence[int]], outputs: Mapping[str, Sequence[int]]) -> None:
        """Map every bound port to a slave variable of its name, or to an element of a DCP array
        (``e_coil[3]`` → element 3 of ``e_coil``, row-major); one payload entry per variable."""
        self.inputs, self.outputs = make_buffers(dict(inputs)), make_buffers(dict(outputs))
        by_vr = {var.vr: var for var in self.interface.variables.values()}
        # the component's own fail-safe values (its FMU's, or its .dcpx's); an output without
        # one keeps its last value (counters, diagnostics)
        fail_safe = self.interface.fail_safe
        for direction, buffers, causality in (("in", self.inputs, "input"), ("out", self.outputs, "output")):
            entries: Dict[str, int] = {}
            remotes: List[DcpVariable] = []
            slots = []
            for buffer in buffers.values():
                for index, vr in enumerate(buffer.vr_array):
                    port = by_vr[int(vr)]
                    remote, element = self._remote(port.name, causality)
                    if (port.type in _NUMERIC) == (remote.data_type == DataType.string):
                        raise UserError(f"{self.description.path}: {port.name!r} is {remote.data_type.name} on the "
                                        f"slave but {port.type} on component {self.name!r}")
                    if remote.name not in entries:
                        entries[remote.name] = len(remotes)
                        remotes.append(remote)
                    slots.append((buffer, index, entries[remote.name], element, port.name))
            if direction == "in":
                self._in_map, self._in_remotes = slots, remotes
            else:
                self._out_map, self._out_remotes = slots, remotes
                self.link.out_codec = PayloadCodec([(r.data_type, r.count) for r in remotes])
        self._fail_safe = [fail_safe.get(name) for *_, name in self._out_map]

    def _remote(self, name: str, causality: str) -> Tuple[DcpVariable, int]:
        remote, element = self.description.by_name(name), 0
        base, index = split_element(name) or (name, ())
        if remote is None and index:
            remote = self.description.by_name(base)
            if remote is not None and remote.dims:
                try:
                    element = int(np.ravel_multi_index(tuple(i - 1 for i in index), remote.dims))
                except ValueError:
                    remote = None
        if remote is None or remote.causality != causality:
            raise UserError(f"{self.description.path}: the slave has no {causality} {name!r}, "
                            f"which component {self.name!r} uses in this system")
        return remote, element

    def setup_experiment(self, start_time: float, stop_time: Optional[float]) -> None:
        return None

    def set_values(self, values: Mapping[str, object]) -> None:
        """Parameters as CFG_parameter, in the CONFIGURATION state. An input set this way (one no
        connection feeds) travels as data on the inputs' data_id, as every input does: DCP
        configures only parameters with CFG_parameter."""
        for name, value in values.items():
            remote, element = self._settable(name)
            if remote.causality == "input":
                self._set_constant_input(name, remote, element, value)
                continue
            data_type = remote.data_type
            if data_type == DataType.string:
                value = str(value)
            elif isinstance(value, str):
                value = float(value.lower() in ("1", "true")) if value.lower() in ("true", "false") else float(value)
            payload = PayloadCodec([(data_type, 1)]).encode([value])
            self.link.request(Pdu(P.CFG_parameter, pdu_seq_id=self.link.next_seq(), receiver=SLAVE_ID,
                              parameter_vr=remote.vr, source_data_type=data_type, configuration=payload))

    def _settable(self, name: str) -> Tuple[DcpVariable, int]:
        """The slave variable a value set on the component goes to: a parameter, or an input."""
        remote = self.description.by_name(name)
        if remote is not None and remote.causality in ("parameter", "structuralParameter"):
            return remote, 0
        try:
            return self._remote(name, "input")
        except UserError:
            raise UserError(f"{self.description.path}: the slave has no parameter or input {name!r}, which the "
                            f"system sets on component {self.name!r}") from None

    def _set_constant_input(self, name: str, remote: DcpVariable, element: int, value) -> None:
        for buffer, index, _, _, port in self._in_map:
            if port == name:                 # bound (a scenario may change it): its buffer holds it
                buffer.values[index] = float(value) if not isinstance(value, str) else value
                return
        if remote not in self._in_remotes:
            self._in_remotes.append(remote)
        entry = self._in_remotes.index(remote)
        self._constant_inputs.append((entry, element, float(value) if remote.data_type != DataType.string else value))

    def enter_initialization(self) -> None:
        """Configure the exchange (CFG_*), prepare and configure the slave."""
        sock_host, sock_port = self.link.sock.getsockname()
        own_host = sock_host if sock_host != "0.0.0.0" else _own_address(self.target.host)
        self._in_codec = PayloadCodec([(r.data_type, r.count) for r in self._in_remotes])
        self._in_arrays = [np.zeros(r.count) if r.data_type != DataType.string else [""] for r in self._in_remotes]
        for entry, element, value in self._constant_inputs:
            self._in_arrays[entry][element] = value
        nxt = self.link.next_seq
        requests = [Pdu(P.CFG_time_res, pdu_seq_id=nxt(), receiver=SLAVE_ID,
                        numerator=self.resolution.numerator, denominator=self.resolution.denominator)]
        if self._out_remotes:
            requests.append(Pdu(P.CFG_steps, pdu_seq_id=nxt(), receiver=SLAVE_ID, steps=self.steps,
                                data_id=OUTPUTS_ID))
        for data_id, remotes in ((INPUTS_ID, self._in_remotes), (OUTPUTS_ID, self._out_remotes)):
            if remotes:
                requests.append(Pdu(P.CFG_scope, pdu_seq_id=nxt(), receiver=SLAVE_ID, data_id=data_id,
                                    scope=Scope.Initialization_Run_NonRealTime))
        for pos, remote in enumerate(self._in_remotes):
            requests.append(Pdu(P.CFG_input, pdu_seq_id=nxt(), receiver=SLAVE_ID, data_id=INPUTS_ID, pos=pos,
                                target_vr=remote.vr, source_data_type=remote.data_type))
        for pos, remote in enumerate(self._out_remotes):
            requests.append(Pdu(P.CFG_output, pdu_seq_id=nxt(), receiver=SLAVE_ID, data_id=OUTPUTS_ID, pos=pos,
                                source_vr=remote.vr))
        if self._in_remotes:
            requests.append(Pdu(P.CFG_source_network_information, pdu_seq_id=nxt(), receiver=SLAVE_ID,
                                data_id=INPUTS_ID, port=self.target.port, ip_address=self.target.host))
        if self._out_remotes:
            requests.append(Pdu(P.CFG_target_network_information, pdu_seq_id=nxt(), receiver=SLAVE_ID,
                                data_id=OUTPUTS_ID, port=sock_port, ip_address=own_host))
        for request in requests:
            self.link.request(request)
        self.link.stc(P.STC_prepare, reaches=State.PREPARED)
        self.link.stc(P.STC_configure, reaches=State.CONFIGURED)
        # the first initialisation exchange waits for the inputs the master gathers
        # (write_inputs), as an FMU's initial inputs are set before it leaves initialisation

    def _initialise(self) -> None:
        """One initialisation exchange: the inputs written, STC_initialize, the outputs sent."""
        self._exchanged = True
        self._send_inputs()
        self.link.stc(P.STC_initialize, reaches=State.INITIALIZED)
        before = self.link.fresh_outputs
        self.link.stc(P.STC_send_outputs, reaches=State.CONFIGURED)
        self._collect_outputs(before, time.perf_counter() + self.target.timeout_s, during="initialisation")

    def exit_initialization(self) -> None:
        if not self._exchanged:              # never exchanged (no input written): once now
            self._initialise()
        self._stc_run(State.SYNCHRONIZED)
        self._stc_run(State.RUNNING)          # soft real time: the slave's clock starts here

    def _stc_run(self, reaches: State) -> None:
        self.link.request(Pdu(P.STC_run, pdu_seq_id=self.link.next_seq(), receiver=SLAVE_ID, state_id=self.link.state,
                          start_time=0), reaches)

    # ---- the exchange each step ------------------------------------------------------------
    def _send_inputs(self) -> None:
        if not self._in_remotes:
            return
        arrays = self._in_arrays
        for buffer, index, entry, element, _ in self._in_map:
            arrays[entry][element] = buffer.values[index]
        self.link.send(Pdu(P.DAT_input_output, pdu_seq_id=self._dat_seq, data_id=INPUTS_ID,
                       payload=self._in_codec.encode(arrays)))
        self._dat_seq = next_seq(self._dat_seq)      # a data_id's sequence ids start at 0

    def _collect_outputs(self, before, until: float, during: Optional[str] = None) -> bool:
        """Wait for outputs newer than ``before`` (what was newest when they were asked for), at
        most until ``until``; False: none came."""
        if not self._out_map:
            return True
        while self.link.fresh_outputs is before:
            if not self.link.receive(until):
                if during is not None:
                    raise self.link.gone(f"sent no outputs during {during} within {self.target.timeout_s:g} s")
                return False
        self._out_values = self._slot_values(self.link.fresh_outputs[1])
        return True

    def _slot_values(self, decoded) -> List:
        """The value of each bound output from the decoded payload entries."""
        return [decoded[entry] if isinstance(decoded[entry], str) else float(decoded[entry][element])
                for _, _, entry, element, _ in self._out_map]

    def _apply_fail_safe(self) -> None:
        if self.mode == OpMode.NRT:
            self.stats.lost += 1           # the outputs this step asked for did not come
        self.stats.fail_safe_steps += 1
        if self._out_values is not None:
            self._out_values = [safe if safe is not None else value
                                for safe, value in zip(self._fail_safe, self._out_values)]

    def write_inputs(self) -> None:
        """In initialisation: an initialisation exchange with these inputs; while running the
        inputs go with the step (:meth:`do_step`)."""
        if self.link.state == State.CONFIGURED:
            self._initialise()

    def do_step(self, time_s: float, step_s: float) -> None:
        began = time.perf_counter()
        self._send_inputs()
        if self.mode == OpMode.NRT:
            self._stc_do_step()
            before = self.link.fresh_outputs
            # the slave sends its outputs, then says RUNNING: outputs still missing then were
            # lost on the way (however long the slave took), unless they trail within the deadline
            self.link.stc(P.STC_send_outputs, reaches=State.RUNNING)
            got = self._collect_outputs(before, time.perf_counter() + self.target.deadline_s)
            age_s = time.perf_counter() - began          # the round trip
        else:       # soft real time: the newest outputs, if they arrived recently enough
            now = time.time()
            self.link.drain()
            age_s = now - self.link.newest_at
            got = self.link.fresh_outputs is not None and age_s <= self.target.deadline_s
            if got:
                self._out_values = self._slot_values(self.link.fresh_outputs[1])
        if got:
            self.stats.rtt_s.append(max(age_s, 0.0))
        else:
            self._apply_fail_safe()
        if time.perf_counter() - began > float(self.step_s):
            self.stats.overruns += 1

    def _stc_do_step(self) -> None:
        self.link.request(Pdu(P.STC_do_step, pdu_seq_id=self.link.next_seq(), receiver=SLAVE_ID, state_id=self.link.state,
                          steps=self.steps), reaches=State.COMPUTED)

    def read_outputs(self, types=None) -> None:
        values = self._out_values
        if values is None:
            return
        for (buffer, index, *_), value in zip(self._out_map, values):
            if types is None or buffer.type in types:
                buffer.values[index] = value

    def terminate(self) -> None:
        """Stop and deregister (best effort: a slave already gone is not waited for long)."""
        if self.link.sock is None or not self._registered or self.stats.error:
            return
        self._registered = False
        self.link.sock.setblocking(True)
        try:
            self.link.stc(P.STC_stop, reaches=State.STOPPED)
            self.link.stc(P.STC_deregister, reaches=State.ALIVE)
        except SimulationError as error:
            raise SimulationError(f"{error} (while stopping)") from None

    def free(self) -> None:
        if self.link.sock is not None:
            self.link.sock.close()
            self.link.sock = None

    def summary_section(self) -> Dict[str, object]:
        return self.stats.section()


class OfflineRemoteDcpSlave(RemoteDcpSlave):
    """A DCP component as ``railcosim validate`` checks it: the slave description against the
    system as :class:`RemoteDcpSlave` checks it (time resolution, operating mode, a variable of
    the right causality and type for every port used, the parameters and inputs set), with
    nothing sent — validating a hardware-in-the-loop system does not register with the rig (our
    emulator would end after the deregistration). Its outputs read 0 while the others initialise."""

    def instantiate(self) -> None:
        return None

    def set_values(self, values: Mapping[str, object]) -> None:
        for name in values:
            self._settable(name)

    def enter_initialization(self) -> None:
        return None

    def exit_initialization(self) -> None:
        return None

    def write_inputs(self) -> None:
        return None

    def do_step(self, time_s: float, step_s: float) -> None:
        raise SimulationError(f"{self.name}: a DCP component checked offline is not stepped")


def _own_address(peer_host: str) -> str:
    """The local address the slave reaches us at (the route towards it)."""
    probe = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        probe.connect((peer_host, 9))
        return probe.getsockname()[0]
    finally:
        probe.close()

"""``railcosim dcp-slave``: any FMI 2.0 co-simulation FMU served as a DCP 1.0 slave over UDP_IPv4.

:class:`DcpSlaveServer` follows the standard's state machine (orchestrator/dcp/states.py) from
STC_register to STC_deregister, checks every request in the order the reference implementation
does (receiver, sequence id, length, state, state_id, then the request's own fields) and
answers RSP_ack or RSP_nack with the standard's error code; each state change is announced
with NTF_state_changed. DAT PDUs are never answered: a malformed, unknown or out-of-date one is
dropped and counted. docs/hil.md says how each rule was checked against DCPLib.

Operating modes (docs/hil.md#operating-modes):

* NRT — the master steps the slave: STC_do_step(steps) advances the FMU by steps × time
  resolution, STC_send_outputs sends the outputs it computed.
* SRT — the slave follows its own monotonic clock once running: every output period it
  applies the latest inputs, steps the FMU and sends its outputs, whether or not the master
  keeps up (late steps are counted, none skipped).

The slave describes itself with the FMU's own description (:func:`dcpx.description_from_fmu`)
or with a given one (a bench device's ``.dcpx``, :func:`dcpx.serve_over_fmu`). The FMU itself
is driven through orchestrator/fmu.py's slaves, as in a run.
"""
from __future__ import annotations

import ipaddress
import math
import selectors
import signal
import socket
import sys
import time
from dataclasses import dataclass, field
from fractions import Fraction
from pathlib import Path
from typing import Callable, Dict, List, Optional, Tuple

import numpy as np

from orchestrator.dcp import dcpx, states
from orchestrator.dcp.dcpx import SlaveDescription
from orchestrator.dcp.pdu import (NUMPY_DTYPES, VARIABLE_LENGTH, DataType, ErrorCode, OpMode, PayloadCodec, Pdu,
                                  PduError, PduType, Scope, State, TransportProtocol, decode, next_seq)
from orchestrator.errors import SimulationError, UserError

_RECV_BYTES = 65536          # more than the largest UDP payload: a datagram is never cut
P = PduType
_DAT_TYPE_ID = bytes([P.DAT_input_output])

# Bounds of what a master may ask (docs/hil.md#bounds-of-a-session says why each):
#: a DAT whose sequence id is more than this ahead of the last one applied is not taken as the
#: stream's new position unless the next one follows it within the window
DAT_SEQ_WINDOW = 1024
#: a DAT at most this many behind the last one applied is a repeat or reordered (stale); one
#: farther behind is judged as a jump, so a datagram injected ahead of the stream costs the real
#: stream at most this many datagrams plus one, not the whole forward window
DAT_STALE_WINDOW = 16
#: one STC_do_step advances the FMU by at most this many of its own steps
MAX_FMU_STEPS_PER_DO_STEP = 1000
#: STC_run's start time at most this far ahead of the slave's clock, in seconds
MAX_START_DELAY_S = 3600
#: a real-time period at least this long when the FMU declares no step of its own, in seconds
MIN_RT_PERIOD_S = 0.001
#: a soft real-time session stops when, over a window of this many seconds holding at least this
#: many steps, at least this share of the steps overran: a stall caught up (the steps after it
#: on time) stays far below the share, an FMU that cannot keep its period (or a host that gives it
#: too little time) stays above it, whether or not a step now and then is on time
OVERRUN_STOP_S, OVERRUN_STOP_STEPS, OVERRUN_STOP_SHARE = 2.0, 50, 0.9
#: overruns are reported as they happen, at most one line per this many seconds
OVERRUN_REPORT_S = 1.0
#: addresses other than the master's each named in one line, up to this many (then only counted)
FOREIGN_ADDRESSES_NAMED = 8


def castable(source: DataType, target: DataType) -> bool:
    """May values of ``source`` type feed a variable of ``target`` type? Equal types, or a
    numeric widening that loses nothing (numpy's 'safe' casting)."""
    if source == target:
        return True
    if source in VARIABLE_LENGTH or target in VARIABLE_LENGTH:
        return False
    return bool(np.can_cast(NUMPY_DTYPES[source], NUMPY_DTYPES[target], casting="safe"))


@dataclass
class _Binding:
    """One DCP variable's place in the FMU's value buffers."""
    var: object                 # DcpVariable
    fmi_type: str
    index: np.ndarray           # positions in the FMU buffer of that type


@dataclass
class _DataId:
    """Configuration of one data_id (CFG_input/CFG_output/CFG_steps/CFG_scope/network)."""
    positions: Dict[int, Tuple[int, DataType]] = field(default_factory=dict)   # pos → (vr, source type)
    steps: Optional[int] = None
    scope: Scope = Scope.Initialization_Run_NonRealTime
    address: Optional[Tuple[str, int]] = None
    codec: Optional[PayloadCodec] = None
    order: List[int] = field(default_factory=list)      # vrs in pos order
    last_seq: Optional[int] = None
    jump_seq: Optional[int] = None    # a DAT out of the window, waiting for the next to confirm it
    send_seq: int = 0


@dataclass
class Counters:
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


class DcpSlaveServer:
    """The protocol engine of one DCP slave around one FMU (``fmu`` follows orchestrator's
    Slave protocol; ``make_fmu`` makes a fresh instance after STC_reset or a failure)."""

    def __init__(self, description: SlaveDescription, make_fmu, sock: socket.socket,
                 drop_data: float = 0.0, seed: Optional[int] = None, log=None, warn=None):
        self.desc = description
        self.make_fmu = make_fmu
        self.sock = sock
        self.host = sock.getsockname()[0]
        self.port = sock.getsockname()[1]
        self.drop_data = float(drop_data)
        self.rng = np.random.default_rng(seed)
        self.log = log or (lambda message: None)
        self.warn = warn or self.log       # what the user must see even with --quiet
        self.foreign_seen: set = set()
        self._local_addresses: Dict[str, bool] = {}     # sender IP → an address of this machine
        self.counters = Counters()
        self.state = State.ALIVE
        self.error = ErrorCode.NONE
        self.slave_id = 0
        self.master: Optional[Tuple[str, int]] = None
        # sequence ids: the next one expected (DCPLib starts from 0, so a refusal before any
        # registration names 1); STC_register's own id is the base
        self.expected_seq = 1
        self.seq_at_register = 0
        self.continuing_seq: Optional[int] = None
        self.op_mode = OpMode.NRT
        self.deregistered = False
        self.data_sockets: Dict[Tuple[str, int], socket.socket] = {}
        self.fmu = None
        self._fresh_fmu = True
        self.vars_by_vr = {v.vr: v for v in description.variables}
        # the request's own checks, and what an accepted request does (checks run after the
        # state and state_id checks; a request without an entry needs none / does nothing)
        self._checks: Dict[PduType, Callable[[Pdu], ErrorCode]] = {
            P.CFG_time_res: self._check_time_resolution, P.CFG_steps: self._check_steps,
            P.CFG_input: self._check_input, P.CFG_output: self._check_output,
            P.CFG_source_network_information: self._check_network,
            P.CFG_target_network_information: self._check_network,
            P.CFG_parameter: self._check_parameter, P.CFG_scope: self._check_scope,
            P.STC_prepare: self._check_prepare, P.STC_do_step: self._check_do_step,
            P.STC_run: self._check_run,
        }
        self._actions: Dict[PduType, Callable[[Pdu], None]] = {
            P.CFG_time_res: self._set_time_resolution, P.CFG_steps: self._set_steps,
            P.CFG_input: self._add_input, P.CFG_output: self._add_output, P.CFG_clear: self._clear,
            P.CFG_source_network_information: self._set_source, P.CFG_target_network_information: self._set_target,
            P.CFG_parameter: self._set_parameter, P.CFG_scope: self._set_scope,
            P.STC_prepare: self._prepare, P.STC_configure: self._configure, P.STC_initialize: self._initialize,
            P.STC_send_outputs: self._send_outputs_now, P.STC_run: self._run, P.STC_do_step: self._do_step,
            P.STC_stop: self._stop, P.STC_reset: self._reset, P.STC_deregister: self._deregister,
        }
        self._clear_configuration()

    # ---- configuration -------------------------------------------------------------------
    def _clear_configuration(self) -> None:
        self.inputs: Dict[int, _DataId] = {}
        self.outputs: Dict[int, _DataId] = {}
        self.sources: Dict[int, Tuple[str, int]] = {}    # data_id → where its inputs arrive
        self.scopes: Dict[int, Scope] = {}
        self.steps: Dict[int, int] = {}
        self.resolution: Optional[Tuple[int, int]] = self._preset_resolution()
        self.parameters: Dict[int, list] = {}
        self.initialised = False
        self.fmi_initialised = False
        self.units = 0                 # simulation time in resolution units since the start
        self.run_state = State.RUNNING

    def _preset_resolution(self) -> Optional[Tuple[int, int]]:
        """A description with one fixed resolution needs no CFG_time_res: it is in use from the
        start (as the reference implementation does)."""
        fixed = [(num, den) for num, den, is_fixed, _ in self.desc.resolutions if is_fixed]
        return fixed[0] if fixed else None

    def _close_data_sockets(self) -> None:
        for s in self.data_sockets.values():
            s.close()
        self.data_sockets.clear()

    # ---- sending -------------------------------------------------------------------------
    def _send(self, pdu: Pdu, address=None) -> None:
        target = address or self.master
        if target is None:
            return
        try:
            self.sock.sendto(pdu.encode(), target)
        except OSError as error:          # e.g. the master's port closed: keep serving
            self.log(f"send to {target[0]}:{target[1]} failed: {error}")

    def _set_state(self, state: State) -> None:
        self.state = state
        self._send(Pdu(P.NTF_state_changed, sender=self.slave_id, state_id=state))

    def _nack(self, seq: int, code: ErrorCode, sender: Optional[int] = None, address=None,
              expected: Optional[int] = None) -> None:
        self.counters.nacks += 1
        self._send(Pdu(P.RSP_nack, resp_seq_id=seq, sender=self.slave_id if sender is None else sender,
                       exp_seq_id=self.expected_seq if expected is None else expected, error_code=code), address)

    def _ack(self, seq: int, address=None) -> None:
        self._send(Pdu(P.RSP_ack, resp_seq_id=seq, sender=self.slave_id), address)

    # ---- receiving -----------------------------------------------------------------------
    def handle(self, data: bytes, address: Tuple[str, int]) -> None:
        """Act on one datagram; never raises for anything a peer can send."""
        try:
            self._handle(data, address)
        except Exception as error:     # a defect of ours must not end a bench session
            self.counters.malformed += 1
            self.log(f"internal error on a {len(data)}-byte datagram from {address[0]}:{address[1]}: "
                     f"{type(error).__name__}: {error}")

    def _handle(self, data: bytes, address: Tuple[str, int]) -> None:
        own = self.master is not None and address != self.master and self._is_own(address)
        if self.master is not None and address != self.master and not (own and data[:1] == _DAT_TYPE_ID):
            self._foreign(address)      # bound to the master that registered it (DCP has no authentication)
            return
        try:
            pdu = decode(data)
        except PduError as error:
            self._malformed(error, address)
            return
        if pdu.type_id == P.DAT_input_output:
            self._data(pdu)
            return
        if pdu.type_id not in states.REQUESTS:
            return      # tunable parameters are not offered; responses/notifications are not ours
        self._request(pdu, address)

    def _is_own(self, address: Tuple[str, int]) -> bool:
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
            local = self._local_addresses[address[0]] = _is_local(address[0])
        return local

    def _foreign(self, address: Tuple[str, int]) -> None:
        self.counters.foreign += 1
        if address in self.foreign_seen or len(self.foreign_seen) > FOREIGN_ADDRESSES_NAMED:
            return
        self.foreign_seen.add(address)
        self.counters.foreign_addresses = len(self.foreign_seen)
        if len(self.foreign_seen) > FOREIGN_ADDRESSES_NAMED:
            self.warn(f"datagrams from more than {FOREIGN_ADDRESSES_NAMED} other addresses: ignored, only counted")
            return
        self.warn(f"ignored a datagram from {address[0]}:{address[1]}: this slave is registered by "
                  f"{self.master[0]}:{self.master[1]} and obeys no one else (further ones only counted)")

    def _malformed(self, error: PduError, address) -> None:
        if error.type_id == P.DAT_input_output:
            self.counters.dat_rejected += 1
            return
        if error.pdu_seq_id is None or error.type_id not in states.REQUESTS \
                or error.error_code == ErrorCode.NOT_SUPPORTED_PDU:
            self.counters.malformed += 1          # no header to answer to
            return
        if self.state == State.ALIVE:
            if error.type_id in (P.STC_register, P.INF_state):
                self._nack(error.pdu_seq_id, error.error_code, sender=error.receiver, address=address,
                           expected=next_seq(error.pdu_seq_id))
            return
        if error.receiver != self.slave_id:
            return
        if not self._sequence_ok(error.pdu_seq_id, address):
            return
        self._nack(error.pdu_seq_id, error.error_code, address=address)

    def _sequence_ok(self, seq: int, address) -> bool:
        """The next request must carry the expected id; one that does not is refused and does
        not use it up. After CFG_clear and STC_reset the reference implementation's slave expects
        STC_register's id + 1 again; its master rewinds after CFG_clear but continues counting
        after STC_reset, so after STC_reset the continuing id is accepted too."""
        if seq != self.expected_seq and seq != self.continuing_seq:
            self._nack(seq, ErrorCode.INVALID_SEQUENCE_ID, address=address)
            return False
        self.expected_seq, self.continuing_seq = next_seq(seq), None
        return True

    def _request(self, pdu: Pdu, address) -> None:
        type_id = pdu.type_id
        if self.state == State.ALIVE:     # sequence ids are not checked before a registration
            if type_id == P.INF_state:
                self._send(Pdu(P.RSP_state_ack, resp_seq_id=pdu.pdu_seq_id, sender=pdu.receiver,
                               state_id=self.state), address)
            elif type_id == P.STC_register:
                self._register(pdu, address)
            else:
                self._nack(pdu.pdu_seq_id, ErrorCode.PROTOCOL_ERROR_PDU_NOT_ALLOWED_IN_THIS_STATE, address=address)
            return
        if pdu.receiver != self.slave_id:
            return                                   # addressed to another slave
        if not self._sequence_ok(pdu.pdu_seq_id, address):
            return
        code = self._check(pdu)
        if code != ErrorCode.NONE:
            self._nack(pdu.pdu_seq_id, code, address=address)
            return
        if type_id == P.INF_state:
            self._send(Pdu(P.RSP_state_ack, resp_seq_id=pdu.pdu_seq_id, sender=self.slave_id, state_id=self.state),
                       address)
            return
        if type_id == P.INF_error:
            self._send(Pdu(P.RSP_error_ack, resp_seq_id=pdu.pdu_seq_id, sender=self.slave_id, error_code=self.error),
                       address)
            return
        self._ack(pdu.pdu_seq_id, address)
        action = self._actions.get(type_id)
        if action is None:
            return
        try:
            action(pdu)
        except (SimulationError, UserError) as error:
            self._fail(str(error))
        except Exception as error:     # anything else the FMU or fmpy raises
            self._fail(f"{type(error).__name__}: {error}")

    def _register(self, pdu: Pdu, address) -> None:
        code = ErrorCode.NONE
        if pdu.state_id != self.state:
            code = ErrorCode.INVALID_STATE_ID
        elif pdu.slave_uuid != self.desc.uuid:
            code = ErrorCode.INVALID_UUID
        elif pdu.op_mode not in self.desc.op_modes:
            code = ErrorCode.INVALID_OP_MODE
        elif pdu.major_version != self.desc.major_version:
            code = ErrorCode.INVALID_MAJOR_VERSION
        elif pdu.minor_version != self.desc.minor_version:
            code = ErrorCode.INVALID_MINOR_VERSION
        if code != ErrorCode.NONE:
            self._nack(pdu.pdu_seq_id, code, sender=pdu.receiver, address=address, expected=next_seq(pdu.pdu_seq_id))
            return
        self.slave_id, self.master, self.op_mode = pdu.receiver, address, pdu.op_mode
        self.seq_at_register = pdu.pdu_seq_id
        self.expected_seq, self.continuing_seq = next_seq(pdu.pdu_seq_id), None
        self.error = ErrorCode.NONE
        self._ack(pdu.pdu_seq_id)
        self.log(f"registered by {address[0]}:{address[1]} as slave {self.slave_id}, {self.op_mode.name}")
        self._set_state(State.CONFIGURATION)

    def _rewind_sequence(self, accept_continuing: bool) -> None:
        """After CFG_clear and STC_reset: STC_register's id + 1 next (and, after STC_reset, the
        continuing one; see :meth:`_sequence_ok`)."""
        self.continuing_seq = self.expected_seq if accept_continuing else None
        self.expected_seq = next_seq(self.seq_at_register)

    # ---- checks (the standard's order: state, state_id, then the request's fields) ---------
    def _check(self, pdu: Pdu) -> ErrorCode:
        type_id = pdu.type_id
        if type_id == P.STC_do_step and self.op_mode != OpMode.NRT:
            return ErrorCode.NOT_SUPPORTED_PDU
        if type_id in states.NOT_OFFERED:
            return ErrorCode.NOT_SUPPORTED_PDU
        if not states.allowed(self.state, type_id):
            return ErrorCode.PROTOCOL_ERROR_PDU_NOT_ALLOWED_IN_THIS_STATE
        if "state_id" in pdu.fields and pdu.state_id != self.state:
            return ErrorCode.INVALID_STATE_ID
        check = self._checks.get(type_id)
        return check(pdu) if check is not None else ErrorCode.NONE

    def _check_time_resolution(self, pdu: Pdu) -> ErrorCode:
        """Offered by the description, and the FMU's step a whole number of its ticks (an FMU
        stepped in another size than its own would refuse, or be stepped at other instants)."""
        num, den = pdu.numerator, pdu.denominator
        if not self.desc.supports_time_resolution(num, den):
            return ErrorCode.INVALID_TIME_RESOLUTION
        fixed = self._preset_resolution()
        if fixed is not None and Fraction(num, den) != Fraction(*fixed):
            return ErrorCode.INVALID_TIME_RESOLUTION
        step_s = self._fmu_step_s()
        if step_s is not None and (step_s / Fraction(num, den)).denominator != 1:
            return ErrorCode.INVALID_TIME_RESOLUTION
        if any(not self._real_time_period_ok(steps, Fraction(num, den)) for steps in self.steps.values()):
            return ErrorCode.INVALID_TIME_RESOLUTION     # the outputs' periods already set would not fit
        return ErrorCode.NONE

    def _check_steps(self, pdu: Pdu) -> ErrorCode:
        if pdu.steps < 1:
            return ErrorCode.INVALID_STEPS
        config = self.outputs.get(pdu.data_id)
        for vr, _ in (config.positions.values() if config else ()):
            if not self.vars_by_vr[vr].steps_supported(pdu.steps):
                return ErrorCode.INVALID_STEPS
        if self.resolution is not None and not self._real_time_period_ok(pdu.steps, Fraction(*self.resolution)):
            return ErrorCode.INVALID_STEPS
        return ErrorCode.NONE

    def _real_time_period_ok(self, steps: int, resolution: Fraction) -> bool:
        """In soft real time an output period is stepped on the wall clock: it must be a whole
        number of the FMU's own steps (the FMU takes no smaller one, and a period of 1 ns cannot
        be kept), or at least MIN_RT_PERIOD_S for an FMU that declares no step."""
        if self.op_mode == OpMode.NRT:
            return True          # outputs go out on STC_send_outputs: the period does not pace anything
        period_s, own_s = steps * resolution, self._fmu_step_s()
        if own_s is None:
            return period_s >= Fraction(MIN_RT_PERIOD_S)
        return (period_s / own_s).denominator == 1

    def _max_do_step_s(self) -> Fraction:
        """The longest simulated span one STC_do_step may ask for: the slave answers nothing
        while it steps, so a step is bounded by the FMU's own step (MAX_FMU_STEPS_PER_DO_STEP of
        them), not only by the 2³²−1 ticks the PDU can carry."""
        own_s = self._fmu_step_s() or Fraction(dcpx.DEFAULT_STEP_S)
        return MAX_FMU_STEPS_PER_DO_STEP * own_s

    def _check_input(self, pdu: Pdu) -> ErrorCode:
        var = self.vars_by_vr.get(pdu.target_vr)
        if var is None or var.causality != "input":
            return ErrorCode.INVALID_VALUE_REFERENCE
        return ErrorCode.NONE if castable(pdu.source_data_type, var.data_type) else ErrorCode.INVALID_SOURCE_DATA_TYPE

    def _check_output(self, pdu: Pdu) -> ErrorCode:
        var = self.vars_by_vr.get(pdu.source_vr)
        if var is None or var.causality != "output":
            return ErrorCode.INVALID_VALUE_REFERENCE
        steps = self.steps.get(pdu.data_id)
        if steps is not None and not var.steps_supported(steps):
            return ErrorCode.INVALID_STEPS
        return ErrorCode.NONE

    def _check_network(self, pdu: Pdu) -> ErrorCode:
        """Inputs are received only on the address this slave serves (0.0.0.0 in the PDU means
        it); outputs go only to the master's host or back to this slave itself, so a master
        cannot make the slave listen elsewhere or send its data to a third party."""
        if pdu.transport_protocol != TransportProtocol.UDP_IPv4:
            return ErrorCode.INVALID_TRANSPORT_PROTOCOL
        if not 1 <= pdu.port <= 65535:
            return ErrorCode.INVALID_NETWORK_INFORMATION
        if pdu.type_id == P.CFG_source_network_information:
            if not self.desc.supports_dat_port(pdu.port) and pdu.port != self.port:
                return ErrorCode.INVALID_NETWORK_INFORMATION
            if pdu.ip_address not in ("0.0.0.0", self.host) and not (self.host == "0.0.0.0"
                                                                     and _is_local(pdu.ip_address)):
                return ErrorCode.INVALID_NETWORK_INFORMATION
        elif pdu.ip_address not in (self.master[0], self.host):
            return ErrorCode.INVALID_NETWORK_INFORMATION
        return ErrorCode.NONE

    def _check_parameter(self, pdu: Pdu) -> ErrorCode:
        var = self.vars_by_vr.get(pdu.parameter_vr)
        if var is None or var.causality not in ("parameter", "structuralParameter"):
            return ErrorCode.INVALID_VALUE_REFERENCE
        if not castable(pdu.source_data_type, var.data_type):
            return ErrorCode.INVALID_SOURCE_DATA_TYPE
        try:
            PayloadCodec([(pdu.source_data_type, var.count)]).decode(pdu.configuration)
        except PduError as error:
            return error.error_code
        return ErrorCode.NONE

    def _check_scope(self, pdu: Pdu) -> ErrorCode:
        return ErrorCode.NONE

    def _check_prepare(self, pdu: Pdu) -> ErrorCode:
        for table, gap in ((self.inputs, ErrorCode.INCOMPLETE_CONFIG_GAP_INPUT_POS),
                           (self.outputs, ErrorCode.INCOMPLETE_CONFIG_GAP_OUTPUT_POS)):
            for config in table.values():
                if sorted(config.positions) != list(range(len(config.positions))):
                    return gap
        if any(data_id not in self.sources for data_id in self.inputs):
            return ErrorCode.INCOMPLETE_CONFIG_NW_INFO_INPUT
        if any(config.address is None for config in self.outputs.values()):
            return ErrorCode.INCOMPLETE_CONFIG_NW_INFO_OUTPUT
        if any(data_id not in self.steps for data_id in self.outputs):
            return ErrorCode.INCOMPLETE_CONFIG_STEPS
        if self.resolution is None:
            return ErrorCode.INCOMPLETE_CONFIG_TIME_RESOLUTION
        try:   # the transport is prepared here so that a port that cannot be bound is refused
            self._bind_sources()
        except OSError:
            self._close_data_sockets()
            return ErrorCode.INVALID_NETWORK_INFORMATION
        return ErrorCode.NONE

    def _check_do_step(self, pdu: Pdu) -> ErrorCode:
        if not self.desc.supports_nrt_steps(pdu.steps) \
                or pdu.steps * Fraction(*self.resolution) > self._max_do_step_s():
            return ErrorCode.INVALID_STEPS
        return ErrorCode.NONE

    def _check_run(self, pdu: Pdu) -> ErrorCode:
        """Real time: a start time in the past, or more than MAX_START_DELAY_S ahead, is refused."""
        if self.op_mode != OpMode.NRT and pdu.start_time > 0:
            now = int(time.time())
            if not now <= pdu.start_time <= now + MAX_START_DELAY_S:
                return ErrorCode.INVALID_START_TIME
        return ErrorCode.NONE

    # ---- actions -------------------------------------------------------------------------
    def _fail(self, message: str) -> None:
        """The FMU failed: ERROR_HANDLING, clean up, ERROR_RESOLVED (reset or deregister next)."""
        self.warn(f"error: {message}")
        self.error = ErrorCode.PROTOCOL_ERROR_GENERIC
        self._set_state(State.ERROR_HANDLING)
        self._free_fmu()
        self._set_state(State.ERROR_RESOLVED)

    def _set_time_resolution(self, pdu: Pdu) -> None:
        self.resolution = (pdu.numerator, pdu.denominator)

    def _set_steps(self, pdu: Pdu) -> None:
        self.steps[pdu.data_id] = pdu.steps

    def _add_input(self, pdu: Pdu) -> None:
        self.inputs.setdefault(pdu.data_id, _DataId()).positions[pdu.pos] = (pdu.target_vr, pdu.source_data_type)

    def _add_output(self, pdu: Pdu) -> None:
        var = self.vars_by_vr[pdu.source_vr]
        self.outputs.setdefault(pdu.data_id, _DataId()).positions[pdu.pos] = (pdu.source_vr, var.data_type)

    def _clear(self, pdu: Pdu) -> None:
        self._close_data_sockets()
        self._clear_configuration()
        self._rewind_sequence(accept_continuing=False)

    def _set_source(self, pdu: Pdu) -> None:
        ip = pdu.ip_address if pdu.ip_address != "0.0.0.0" else self.host
        self.sources[pdu.data_id] = (ip, pdu.port)

    def _set_target(self, pdu: Pdu) -> None:
        self.outputs.setdefault(pdu.data_id, _DataId()).address = (pdu.ip_address, pdu.port)

    def _set_parameter(self, pdu: Pdu) -> None:
        var = self.vars_by_vr[pdu.parameter_vr]
        value = PayloadCodec([(pdu.source_data_type, var.count)]).decode(pdu.configuration)[0]
        self.parameters[var.vr] = [value] if isinstance(value, str) else list(np.asarray(value).tolist())

    def _set_scope(self, pdu: Pdu) -> None:
        self.scopes[pdu.data_id] = pdu.scope

    def _bind_sources(self) -> None:
        for address in set(self.sources.values()):
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

    def _prepare(self, pdu: Pdu) -> None:
        self._set_state(State.PREPARING)
        for config in list(self.inputs.values()) + list(self.outputs.values()):
            config.order = [config.positions[p][0] for p in sorted(config.positions)]
            config.codec = PayloadCodec([(config.positions[p][1], self.vars_by_vr[config.positions[p][0]].count)
                                         for p in sorted(config.positions)])
        for data_id, config in self.outputs.items():
            config.steps = self.steps[data_id]
            config.scope = self.scopes.get(data_id, Scope.Initialization_Run_NonRealTime)
        self._set_state(State.PREPARED)

    def _configure(self, pdu: Pdu) -> None:
        self._set_state(State.CONFIGURING)
        if not self._fresh_fmu or self.fmu is None:
            self._free_fmu()
            self.fmu = self.make_fmu()
            self.fmu.instantiate()
            self._bind_fmu()
        self._fresh_fmu = False
        self.fmu.setup_experiment(0.0, None)
        values = {}
        for vr, elements in self.parameters.items():
            var = self.vars_by_vr[vr]
            names = var.fmi_names or (var.name,)
            for name, value in zip(names, elements if len(elements) == len(names) else elements * len(names)):
                values[name] = bool(value) if self.fmi_types[name] == "Boolean" else value
        if values:
            self.fmu.set_values(values)
        self.fmu.enter_initialization()
        self._set_state(State.CONFIGURED)

    def _initialize(self, pdu: Pdu) -> None:
        self._set_state(State.INITIALIZING)
        self._initialise_fmu()
        self._set_state(State.INITIALIZED)

    def _send_outputs_now(self, pdu: Pdu) -> None:
        if self.state == State.INITIALIZED:
            self._set_state(State.SENDING_I)
            self._send_outputs(initialization=True)
            self._set_state(State.CONFIGURED)
        else:
            self._set_state(State.SENDING_D)
            self._send_outputs(initialization=False)
            self._set_state(self.run_state)

    def _run(self, pdu: Pdu) -> None:
        """From CONFIGURED: run. Non-real-time the slave is synchronised at once. In real time
        it is SYNCHRONIZING until its clock reaches start_time (0: at once); there it takes its
        first step, sends its outputs and says SYNCHRONIZED, as the reference implementation
        does, and steps on in SYNCHRONIZED and RUNNING alike (the standard's real-time states
        all exchange data). A second STC_run (SYNCHRONIZED → RUNNING) only changes the state."""
        if self.state == State.CONFIGURED:
            self._initialise_fmu()
            self._set_state(State.SYNCHRONIZING)
            if self.op_mode == OpMode.NRT:
                self._set_state(State.SYNCHRONIZED)
            else:
                self._start_clock(pdu.start_time)
        else:
            self._set_state(State.RUNNING)

    def _do_step(self, pdu: Pdu) -> None:
        self.run_state = self.state
        self._set_state(State.COMPUTING)
        self._step(pdu.steps)
        self._set_state(State.COMPUTED)

    def _stop(self, pdu: Pdu) -> None:
        self._set_state(State.STOPPING)
        self.clock = None
        self._terminate_fmu()
        self._set_state(State.STOPPED)

    def _reset(self, pdu: Pdu) -> None:
        self._close_data_sockets()
        self._clear_configuration()
        self.error = ErrorCode.NONE
        self._rewind_sequence(accept_continuing=True)
        self._set_state(State.CONFIGURATION)

    def _deregister(self, pdu: Pdu) -> None:
        self._close_data_sockets()
        self._clear_configuration()
        self._set_state(State.ALIVE)
        self.master, self.slave_id = None, 0
        self.deregistered = True

    # ---- the FMU -------------------------------------------------------------------------
    def _bind_fmu(self) -> None:
        """Bind every input and output of the FMU; remember where each DCP variable lives."""
        interface = self.fmu.interface
        self.fmi_types = {name: v.type for name, v in interface.variables.items()}
        tables = {"input": {}, "output": {}}
        self.bindings: Dict[int, _Binding] = {}
        for var in self.desc.variables:
            if var.causality not in tables:
                continue
            names = var.fmi_names or (var.name,)
            fmi_type = interface.variables[names[0]].type
            vrs = tables[var.causality].setdefault(fmi_type, [])
            start = len(vrs)
            vrs.extend(interface.variables[n].vr for n in names)
            self.bindings[var.vr] = _Binding(var, fmi_type, np.arange(start, start + len(names)))
        self.fmu.bind(tables["input"], tables["output"])
        for binding in self.bindings.values():            # inputs start at their start values
            var = binding.var
            if var.causality == "input" and var.start is not None:
                self._put(binding, var.start if len(var.start) == var.count else var.start * var.count)

    def _put(self, binding: _Binding, values) -> None:
        buffer = self.fmu.inputs[binding.fmi_type]
        if binding.fmi_type == "String":
            buffer.values[binding.index[0]] = values if isinstance(values, str) else str(values[0])
        else:
            buffer.values[binding.index] = values

    def _initialise_fmu(self) -> None:
        self.fmu.write_inputs()
        if not self.fmi_initialised:
            self.fmu.exit_initialization()
            self.fmi_initialised = True
        self.fmu.read_outputs()

    def _fmu_step_s(self) -> Optional[Fraction]:
        """The FMU's own step (None: it states none), exact to the nanosecond."""
        step_s = self.fmu.interface.default_step_s if self.fmu is not None else None
        return Fraction(round(step_s * dcpx.NS_PER_SECOND), dcpx.NS_PER_SECOND) if step_s else None

    def _fmu_step_units(self) -> Optional[int]:
        """The FMU's own step in units of the time resolution (None: not a whole number)."""
        step_s = self._fmu_step_s()
        if step_s is None:
            return None
        units = step_s / Fraction(*self.resolution)
        return int(units) if units.denominator == 1 else None

    def _step(self, steps: int) -> None:
        """Advance the FMU by ``steps`` resolution units: in steps of its own size when they
        divide the request (an FMU that accepts only its own step, as ours, can then be asked
        for several at once), else in one."""
        num, den = self.resolution
        own = self._fmu_step_units()
        parts = (steps // own, own) if own and steps > own and steps % own == 0 else (1, steps)
        self.fmu.write_inputs()
        for _ in range(parts[0]):
            self.fmu.do_step(self.units * num / den, parts[1] * num / den)
            self.units += parts[1]
        self.fmu.read_outputs()
        self.counters.steps += 1

    def _terminate_fmu(self) -> None:
        if self.fmu is not None:
            try:
                self.fmu.terminate()
            except (SimulationError, UserError) as error:
                self.log(f"terminate: {error}")
        self._fresh_fmu = False

    def _free_fmu(self) -> None:
        if self.fmu is not None:
            fmu, self.fmu = self.fmu, None
            try:
                fmu.free()
            except Exception as error:      # an FMU's own failure to free: report, keep serving
                self.log(f"freeInstance: {error}")

    def shutdown(self) -> None:
        if self.fmu is not None and self.state not in (State.STOPPED, State.ALIVE, State.ERROR_RESOLVED):
            self._terminate_fmu()
        self._free_fmu()
        self._close_data_sockets()

    # ---- data ----------------------------------------------------------------------------
    def _data(self, pdu: Pdu) -> None:
        config = self.inputs.get(pdu.data_id)
        if config is None or config.codec is None or not states.allowed(self.state, P.DAT_input_output) \
                or self.fmu is None:
            self.counters.dat_rejected += 1
            return
        try:
            values = config.codec.decode(pdu.payload)
        except PduError:
            self.counters.dat_rejected += 1
            return
        if config.last_seq is not None and not self._in_sequence(config, pdu.pdu_seq_id):
            return
        config.last_seq, config.jump_seq = pdu.pdu_seq_id, None
        self.counters.dat_received += 1
        for vr, value in zip(config.order, values):
            self._put(self.bindings[vr], value)

    def _in_sequence(self, config: _DataId, seq: int) -> bool:
        """Sequence ids in DCP's modular arithmetic (uint16): 1 … DAT_SEQ_WINDOW ahead of the last
        one applied is next (the ids between are missing); 0 or up to DAT_STALE_WINDOW behind is
        a repeat or reordered (stale). Farther either way, a datagram is taken only when it
        follows the previous such one within the window (the stream really jumped, e.g. after a
        long loss, or a datagram injected ahead of it moved the position), so no single datagram
        can make more than DAT_STALE_WINDOW + 1 later ones of the stream look stale."""
        gap = (seq - config.last_seq) & 0xFFFF
        if 1 <= gap <= DAT_SEQ_WINDOW:
            self.counters.dat_missing += gap - 1
            return True
        if gap == 0 or gap >= 0x10000 - DAT_STALE_WINDOW:
            self.counters.dat_stale += 1
            return False
        if config.jump_seq is not None and 1 <= (seq - config.jump_seq) & 0xFFFF <= DAT_SEQ_WINDOW:
            ahead = (config.jump_seq - config.last_seq) & 0xFFFF     # a jump back misses nothing
            self.counters.dat_missing += (ahead - 1 if ahead < 0x8000 else 0) + ((seq - config.jump_seq) & 0xFFFF) - 1
            return True
        config.jump_seq = seq
        self.counters.dat_out_of_window += 1
        return False

    def _send_outputs(self, initialization: bool, due=None) -> None:
        wanted = (Scope.Initialization_Run_NonRealTime, Scope.Initialization) if initialization \
            else (Scope.Initialization_Run_NonRealTime, Scope.Run_NonRealTime)
        for data_id, config in self.outputs.items():
            if config.scope not in wanted or (due is not None and data_id not in due):
                continue
            values = []
            for vr in config.order:
                binding = self.bindings[vr]
                buffer = self.fmu.outputs[binding.fmi_type]
                if binding.fmi_type == "String":
                    values.append(buffer.values[binding.index[0]])
                else:
                    values.append(buffer.values[binding.index])
            pdu = Pdu(P.DAT_input_output, pdu_seq_id=config.send_seq, data_id=data_id,
                      payload=config.codec.encode(values))
            config.send_seq = next_seq(config.send_seq)
            if self.drop_data and self.rng.random() < self.drop_data:
                self.counters.dat_dropped += 1
                continue
            self.counters.dat_sent += 1
            self._send(pdu, config.address)

    # ---- soft real time ------------------------------------------------------------------
    clock = None

    def _start_clock(self, start_time: int) -> None:
        """The FMU steps by the greatest common divisor of the outputs' periods; each output
        goes out at its own period."""
        periods = [config.steps for config in self.outputs.values()]
        own = self._fmu_step_units()
        self.rt_steps = math.gcd(*periods, *([own] if own else [])) or 1
        num, den = self.resolution
        self.rt_period_s = self.rt_steps * num / den
        start = time.time() if start_time <= 0 else float(start_time)
        # the first step at the start time (wall clock), mapped onto the monotonic clock
        self.clock = time.monotonic() + max(0.0, start - time.time())
        self.rt_count = 0
        self.overrun_reported = -math.inf
        self._new_overrun_window(time.monotonic())

    def _new_overrun_window(self, now: float) -> None:
        self.window_start, self.window_steps, self.window_overruns = now, 0, 0

    def _kept_real_time(self, now: float, late: bool, lateness: float) -> bool:
        """Count one real-time step in the current window of OVERRUN_STOP_S; at the window's end,
        stop the session (False) when it held OVERRUN_STOP_STEPS steps or more of which the share
        OVERRUN_STOP_SHARE or more overran: the FMU cannot be stepped at this period in real time."""
        self.window_steps += 1
        self.window_overruns += late
        if now - self.window_start < OVERRUN_STOP_S:
            return True
        steps, overruns = self.window_steps, self.window_overruns
        self._new_overrun_window(now)
        if steps < OVERRUN_STOP_STEPS or overruns < OVERRUN_STOP_SHARE * steps:
            return True
        self.clock = None
        self._fail(f"real time not kept, session stopped: {overruns} of the last {steps} real-time steps started more "
                   f"than a period ({self.rt_period_s * 1e3:g} ms) late, {lateness * 1e3:.1f} ms at the last: the FMU "
                   "cannot be stepped at this period in real time")
        return False

    def _overrun(self, now: float, lateness: float) -> None:
        """Count and report an overrun as it happens (one line at most every OVERRUN_REPORT_S)."""
        self.counters.overruns += 1
        period_ms = self.rt_period_s * 1e3
        if now - self.overrun_reported >= OVERRUN_REPORT_S:
            self.overrun_reported = now
            self.warn(f"overrun: real-time step {self.rt_count // self.rt_steps + 1} started "
                      f"{lateness * 1e3:.1f} ms late (period {period_ms:g} ms); {self.counters.overruns} "
                      f"overrun(s) so far")

    def next_deadline(self) -> Optional[float]:
        return self.clock if self.clock is not None and self.state in states.RUN_STATES else None

    def tick(self) -> None:
        """One real-time step (called at or after its deadline)."""
        now = time.monotonic()
        lateness = now - self.clock
        self.counters.worst_lateness_s = max(self.counters.worst_lateness_s, lateness)
        late = lateness > self.rt_period_s      # started more than a period late
        if late:
            self._overrun(now, lateness)
        if not self._kept_real_time(now, late, lateness):
            return
        try:
            self._step(self.rt_steps)
        except (SimulationError, UserError) as error:
            self.clock = None
            self._fail(str(error))
            return
        self.rt_count += self.rt_steps
        due = {d for d, c in self.outputs.items() if self.rt_count % c.steps == 0}
        self._send_outputs(initialization=False, due=due)
        self.clock += self.rt_period_s
        if self.state == State.SYNCHRONIZING:       # the clock has started: synchronised
            self._set_state(State.SYNCHRONIZED)


def _is_local(ip: str) -> bool:
    """Is ``ip`` an address of this machine (one a socket can be bound to)?"""
    probe = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        probe.bind((ip, 0))
        return True
    except OSError:
        return False
    finally:
        probe.close()


# ---- the command ---------------------------------------------------------------------------

def exposure_warning(host: str, port: int) -> Optional[str]:
    """The one warning line for a control port that is reachable from outside this machine
    (None on a loopback address)."""
    if ipaddress.ip_address(host).is_loopback:
        return None
    where = "every interface of this machine" if host == "0.0.0.0" else "a network interface"
    return (f"warning: the control port {host}:{port} is open on {where}: DCP has no authentication, so "
            f"anyone who reaches it can register this slave and drive the FMU (once registered, it obeys "
            f"only its master's address)")


def serve(fmu_path: Path, host: str, port: int, real_time: bool, dcpx_out: Optional[Path],
          drop_data: float, seed: Optional[int], quiet: bool = False, dcpx_in: Optional[Path] = None) -> int:
    """Run ``railcosim dcp-slave`` until deregistered (exit 0) or a signal (128 + signal).
    ``dcpx_in``: serve that description (a bench device's) instead of the FMU's own."""
    from orchestrator.fmu import make_slave, new_workdir, read_interface, remove_workdir
    from orchestrator.interrupts import FLAG, deferred

    fmu_path = Path(fmu_path)
    if not host.strip():        # an unset variable: the socket would listen on every interface
        raise UserError(f"dcp-slave: --host {host!r}: an IPv4 address is expected (127.0.0.1 for this machine only, "
                        "0.0.0.0 for every interface)")
    if not 0.0 <= drop_data < 1.0:
        raise UserError(f"dcp-slave: --drop-data {drop_data:g}: a fraction in [0, 1) is expected")
    interface = read_interface(fmu_path)
    if dcpx_in is not None:
        description = dcpx.serve_over_fmu(dcpx.read_dcpx(dcpx_in), interface, str(dcpx_in))
        if real_time and OpMode.SRT not in description.op_modes:
            raise UserError(f"dcp-slave: --real-time: {dcpx_in} offers no SoftRealTime mode")
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        sock.bind((host, port))
    except (OSError, OverflowError) as error:
        sock.close()
        raise UserError(f"dcp-slave: cannot listen on {host}:{port}: {error}") from None
    host, port = sock.getsockname()
    if dcpx_in is None:
        description = dcpx.description_from_fmu(interface, host, port, real_time=False)
        description.op_modes = (OpMode.SRT,) if real_time else (OpMode.NRT,)
    else:
        description.control_host, description.control_port = host, port
    if dcpx_out is not None:
        try:
            dcpx.write_dcpx(description, dcpx_out)
        except OSError as error:
            sock.close()
            raise UserError(f"dcp-slave: --dcpx-out {dcpx_out}: {error.strerror}") from None
    workdir = new_workdir()

    def warn(message: str) -> None:
        print(f"railcosim dcp-slave: {message}", file=sys.stderr, flush=True)

    def log(message: str) -> None:
        if not quiet:
            warn(message)

    exposure = exposure_warning(host, port)
    if exposure:
        warn(exposure)

    if description.logs():
        log("the description offers logging, which this slave does not provide: CFG_logging and INF_log "
            "are answered NOT_SUPPORTED_PDU")

    def make_fmu():
        return make_slave(interface.model_identifier, fmu_path, interface, workdir, in_process=False)

    slave = DcpSlaveServer(description, make_fmu, sock, drop_data=drop_data, seed=seed, log=log, warn=warn)
    wake_r, wake_w = socket.socketpair()
    wake_r.setblocking(False)
    wake_w.setblocking(False)
    status = 0
    with deferred():
        previous_fd = signal.set_wakeup_fd(wake_w.fileno(), warn_on_full_buffer=False)
        selector = selectors.DefaultSelector()
        selector.register(sock, selectors.EVENT_READ)
        selector.register(wake_r, selectors.EVENT_READ)
        registered = {sock.fileno(): sock}
        try:
            # the first instance is made now: an FMU that cannot load fails at once, and the
            # slave is ready when it says so
            slave.fmu = make_fmu()
            slave.fmu.instantiate()
            slave._bind_fmu()
            modes = " and ".join({OpMode.SRT: "soft real-time", OpMode.NRT: "non-real-time",
                                  OpMode.HRT: "hard real-time"}[m] for m in description.op_modes)
            log(f"{interface.model_identifier} serving DCP 1.0 on udp://{host}:{port} ({modes})")
            print(f"LISTENING {host}:{port}", flush=True)
            while not slave.deregistered and not FLAG.signum:
                # data sockets come and go with the configuration
                current = {s.fileno(): s for s in slave.data_sockets.values()}
                for fd in set(registered) - set(current) - {sock.fileno()}:
                    selector.unregister(registered.pop(fd))
                for fd, s in current.items():
                    if fd not in registered:
                        selector.register(s, selectors.EVENT_READ)
                        registered[fd] = s
                deadline = slave.next_deadline()
                timeout = None if deadline is None else max(0.0, deadline - time.monotonic())
                for key, _ in selector.select(timeout):
                    if key.fileobj is wake_r:
                        try:
                            wake_r.recv(64)
                        except BlockingIOError:
                            pass
                        continue
                    _drain(key.fileobj, slave)
                deadline = slave.next_deadline()
                if deadline is not None and time.monotonic() >= deadline:
                    slave.tick()
            if FLAG.signum:
                status = 128 + FLAG.signum
                log(f"stopped by {signal.Signals(FLAG.signum).name}")
        finally:
            signal.set_wakeup_fd(previous_fd)
            slave.shutdown()
            selector.close()
            sock.close()
            wake_r.close()
            wake_w.close()
            remove_workdir(workdir)
            log(slave.counters.line())
    return status


def _drain(sock: socket.socket, slave: DcpSlaveServer) -> None:
    """Handle every datagram waiting on ``sock``."""
    while True:
        try:
            data, address = sock.recvfrom(_RECV_BYTES, socket.MSG_DONTWAIT)
        except (BlockingIOError, InterruptedError):
            return
        except OSError:          # e.g. ICMP port unreachable reported on Linux: ignore
            continue
        slave.handle(data, address)

"""``railcosim dcp-slave``: any FMI 2.0 co-simulation FMU served as a DCP 1.0 slave over UDP_IPv4.

:class:`DcpSlaveServer` follows the standard's state machine (orchestrator/dcp/states.py) from
STC_register to STC_deregister, checks every request in the order the reference implementation
does (receiver, sequence id, length, state, state_id, then the request's own fields) and
answers RSP_ack or RSP_nack with the standard's error code; each state change is announced
with NTF_state_changed. DAT PDUs are never answered: a malformed, unknown or out-of-date one is
dropped and counted. docs/hil.md says how each rule was checked against DCPLib.

The engine is here; its parts are in modules of their own: the checks of a request
(slave_checks.py), what a master configures (slave_config.py), the data exchange with the FMU
and the counters (slave_data.py), soft real time (slave_real_time.py).

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
import selectors
import signal
import socket
import sys
import time
from pathlib import Path
from typing import Callable, Dict, Optional, Tuple

import numpy as np

from orchestrator.dcp import dcpx, states
from orchestrator.dcp.dcpx import SlaveDescription
from orchestrator.dcp.pdu import ErrorCode, OpMode, Pdu, PduError, PduType, State, decode, next_seq
from orchestrator.dcp.slave_checks import RequestChecks
from orchestrator.dcp.slave_config import SlaveConfiguration
from orchestrator.dcp.slave_data import FOREIGN_ADDRESSES_NAMED, Counters, DataExchange
from orchestrator.dcp.slave_fmu import ServedFmu
from orchestrator.dcp.slave_real_time import SoftRealTime
from orchestrator.errors import SimulationError, UserError

_RECV_BYTES = 65536          # more than the largest UDP payload: a datagram is never cut
P = PduType
_DAT_TYPE_ID = bytes([P.DAT_input_output])
#: the CFG requests, once accepted: the SlaveConfiguration method that records each
_CONFIGURATION = {P.CFG_time_res: "set_time_resolution", P.CFG_steps: "set_steps", P.CFG_input: "add_input",
                  P.CFG_output: "add_output", P.CFG_source_network_information: "set_source",
                  P.CFG_target_network_information: "set_target", P.CFG_parameter: "set_parameter",
                  P.CFG_scope: "set_scope"}


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
        self.served = ServedFmu(make_fmu, self.log)
        self.clock: Optional[SoftRealTime] = None
        self.vars_by_vr = {v.vr: v for v in description.variables}
        self.checks = RequestChecks(self)
        self.exchange = DataExchange(self)
        # what an accepted STC request does (the CFG requests: _CONFIGURATION)
        self._actions: Dict[PduType, Callable[[Pdu], None]] = {
            P.CFG_clear: self._clear, P.STC_prepare: self._prepare, P.STC_configure: self._configure,
            P.STC_initialize: self._initialize, P.STC_send_outputs: self._send_outputs_now, P.STC_run: self._run,
            P.STC_do_step: self._do_step, P.STC_stop: self._stop, P.STC_reset: self._reset,
            P.STC_deregister: self._deregister,
        }
        self._clear_configuration()

    def _clear_configuration(self) -> None:
        self.config = SlaveConfiguration(self.desc, self.vars_by_vr, self.host)
        self.served.new_session()
        self.run_state = State.RUNNING

    # ---- sending -------------------------------------------------------------------------
    def send(self, pdu: Pdu, address=None) -> None:
        target = address or self.master
        if target is None:
            return
        try:
            self.sock.sendto(pdu.encode(), target)
        except OSError as error:          # e.g. the master's port closed: keep serving
            self.log(f"send to {target[0]}:{target[1]} failed: {error}")

    def set_state(self, state: State) -> None:
        self.state = state
        self.send(Pdu(P.NTF_state_changed, sender=self.slave_id, state_id=state))

    def _nack(self, seq: int, code: ErrorCode, sender: Optional[int] = None, address=None,
              expected: Optional[int] = None) -> None:
        self.counters.nacks += 1
        self.send(Pdu(P.RSP_nack, resp_seq_id=seq, sender=self.slave_id if sender is None else sender,
                      exp_seq_id=self.expected_seq if expected is None else expected, error_code=code), address)

    def _ack(self, seq: int, address=None) -> None:
        self.send(Pdu(P.RSP_ack, resp_seq_id=seq, sender=self.slave_id), address)

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
        own = self.master is not None and address != self.master and self.exchange.is_own(address)
        if self.master is not None and address != self.master and not (own and data[:1] == _DAT_TYPE_ID):
            self._foreign(address)      # bound to the master that registered it (DCP has no authentication)
            return
        try:
            pdu = decode(data)
        except PduError as error:
            self._malformed(error, address)
            return
        if pdu.type_id == P.DAT_input_output:
            self.exchange.receive(pdu)
            return
        if pdu.type_id not in states.REQUESTS:
            return      # tunable parameters are not offered; responses/notifications are not ours
        self._request(pdu, address)

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
                self.send(Pdu(P.RSP_state_ack, resp_seq_id=pdu.pdu_seq_id, sender=pdu.receiver,
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
        code = self.checks.check(pdu)
        if code != ErrorCode.NONE:
            self._nack(pdu.pdu_seq_id, code, address=address)
            return
        if type_id == P.INF_state:
            self.send(Pdu(P.RSP_state_ack, resp_seq_id=pdu.pdu_seq_id, sender=self.slave_id, state_id=self.state),
                      address)
            return
        if type_id == P.INF_error:
            self.send(Pdu(P.RSP_error_ack, resp_seq_id=pdu.pdu_seq_id, sender=self.slave_id, error_code=self.error),
                      address)
            return
        self._ack(pdu.pdu_seq_id, address)
        action = getattr(self.config, _CONFIGURATION[type_id]) if type_id in _CONFIGURATION \
            else self._actions.get(type_id)
        if action is None:
            return
        try:
            action(pdu)
        except (SimulationError, UserError) as error:
            self.fail(str(error))
        except Exception as error:     # anything else the FMU or fmpy raises
            self.fail(f"{type(error).__name__}: {error}")

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
        self.set_state(State.CONFIGURATION)

    def _rewind_sequence(self, accept_continuing: bool) -> None:
        """After CFG_clear and STC_reset: STC_register's id + 1 next (and, after STC_reset, the
        continuing one; see :meth:`_sequence_ok`)."""
        self.continuing_seq = self.expected_seq if accept_continuing else None
        self.expected_seq = next_seq(self.seq_at_register)

    # ---- actions -------------------------------------------------------------------------
    def fail(self, message: str) -> None:
        """The FMU failed: ERROR_HANDLING, clean up, ERROR_RESOLVED (reset or deregister next)."""
        self.warn(f"error: {message}")
        self.error = ErrorCode.PROTOCOL_ERROR_GENERIC
        self.set_state(State.ERROR_HANDLING)
        self.served.free()
        self.set_state(State.ERROR_RESOLVED)

    def _clear(self, pdu: Pdu) -> None:
        self.exchange.close_data_sockets()
        self._clear_configuration()
        self._rewind_sequence(accept_continuing=False)

    def _prepare(self, pdu: Pdu) -> None:
        self.set_state(State.PREPARING)
        self.config.prepare()
        self.set_state(State.PREPARED)

    def _configure(self, pdu: Pdu) -> None:
        self.set_state(State.CONFIGURING)
        if not self.served.fresh or self.fmu is None:
            self.load_fmu()
        self.served.fresh = False
        self.fmu.setup_experiment(0.0, None)
        values = {}
        for vr, elements in self.config.parameters.items():
            var = self.vars_by_vr[vr]
            names = var.fmi_names or (var.name,)
            for name, value in zip(names, elements if len(elements) == len(names) else elements * len(names)):
                values[name] = bool(value) if self.exchange.fmi_types[name] == "Boolean" else value
        if values:
            self.fmu.set_values(values)
        self.fmu.enter_initialization()
        self.set_state(State.CONFIGURED)

    def _initialize(self, pdu: Pdu) -> None:
        self.set_state(State.INITIALIZING)
        self.served.initialise()
        self.set_state(State.INITIALIZED)

    def _send_outputs_now(self, pdu: Pdu) -> None:
        if self.state == State.INITIALIZED:
            self.set_state(State.SENDING_I)
            self.exchange.send_outputs(initialization=True)
            self.set_state(State.CONFIGURED)
        else:
            self.set_state(State.SENDING_D)
            self.exchange.send_outputs(initialization=False)
            self.set_state(self.run_state)

    def _run(self, pdu: Pdu) -> None:
        """From CONFIGURED: run. Non-real-time the slave is synchronised at once. In real time
        it is SYNCHRONIZING until its clock reaches start_time (0: at once); there it takes its
        first step, sends its outputs and says SYNCHRONIZED, as the reference implementation
        does, and steps on in SYNCHRONIZED and RUNNING alike (the standard's real-time states
        all exchange data). A second STC_run (SYNCHRONIZED → RUNNING) only changes the state."""
        if self.state == State.CONFIGURED:
            self.served.initialise()
            self.set_state(State.SYNCHRONIZING)
            if self.op_mode == OpMode.NRT:
                self.set_state(State.SYNCHRONIZED)
            else:
                self.clock = SoftRealTime(self, pdu.start_time)
        else:
            self.set_state(State.RUNNING)

    def _do_step(self, pdu: Pdu) -> None:
        self.run_state = self.state
        self.set_state(State.COMPUTING)
        self.step(pdu.steps)
        self.set_state(State.COMPUTED)

    def _stop(self, pdu: Pdu) -> None:
        self.set_state(State.STOPPING)
        self.clock = None
        self.served.terminate()
        self.set_state(State.STOPPED)

    def _reset(self, pdu: Pdu) -> None:
        self.exchange.close_data_sockets()
        self._clear_configuration()
        self.error = ErrorCode.NONE
        self._rewind_sequence(accept_continuing=True)
        self.set_state(State.CONFIGURATION)

    def _deregister(self, pdu: Pdu) -> None:
        self.exchange.close_data_sockets()
        self._clear_configuration()
        self.set_state(State.ALIVE)
        self.master, self.slave_id = None, 0
        self.deregistered = True

    # ---- the FMU -------------------------------------------------------------------------
    @property
    def fmu(self):
        """The FMU instance served now (None between a failure and the next STC_configure)."""
        return self.served.fmu

    def load_fmu(self) -> None:
        """A fresh instance of the FMU, instantiated, its variables bound."""
        self.served.load()
        self.exchange.bind_fmu()

    def step(self, steps: int) -> None:
        """Advance the FMU by ``steps`` resolution units (ServedFmu.step)."""
        self.served.step(steps, self.config.resolution)
        self.counters.steps += 1

    def shutdown(self) -> None:
        if self.fmu is not None and self.state not in (State.STOPPED, State.ALIVE, State.ERROR_RESOLVED):
            self.served.terminate()
        self.served.free()
        self.exchange.close_data_sockets()

    # ---- soft real time ------------------------------------------------------------------
    def next_deadline(self) -> Optional[float]:
        return self.clock.deadline if self.clock is not None and self.state in states.RUN_STATES else None

    def tick(self) -> None:
        """One real-time step (called at or after its deadline)."""
        self.clock.tick()


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
            slave.load_fmu()
            modes = " and ".join({OpMode.SRT: "soft real-time", OpMode.NRT: "non-real-time",
                                  OpMode.HRT: "hard real-time"}[m] for m in description.op_modes)
            log(f"{interface.model_identifier} serving DCP 1.0 on udp://{host}:{port} ({modes})")
            print(f"LISTENING {host}:{port}", flush=True)
            while not slave.deregistered and not FLAG.signum:
                # data sockets come and go with the configuration
                current = {s.fileno(): s for s in slave.exchange.data_sockets.values()}
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

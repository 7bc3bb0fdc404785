"""Whether ``railcosim dcp-slave`` takes a request, checked in the order the reference
implementation does once the receiver and the sequence id have passed: not offered, not
allowed in the slave's state, a wrong state_id, then the request's own fields (docs/hil.md
says how each rule was checked against DCPLib, docs/hil.md#bounds-of-a-session why each bound).
"""
from __future__ import annotations

import time
from fractions import Fraction
from typing import Callable, Dict

from orchestrator.dcp import dcpx, states
from orchestrator.dcp.pdu import ErrorCode, OpMode, PayloadCodec, Pdu, PduError, PduType, TransportProtocol
from orchestrator.dcp.slave_config import castable
from orchestrator.dcp.slave_data import is_local

P = PduType

#: one STC_do_step advances the FMU by at most this many of its own steps
MAX_FMU_STEPS_PER_DO_STEP = 1000
#: STC_run's start time at most this far ahead of the slave's clock, in seconds
MAX_START_DELAY_S = 3600
#: a real-time period at least this long when the FMU declares no step of its own, in seconds
MIN_RT_PERIOD_S = 0.001


class RequestChecks:
    """The checks of one slave's requests (``slave``: its DcpSlaveServer), reading its state,
    description and configuration."""

    def __init__(self, slave):
        self.slave = slave
        # the request's own checks (after the state and state_id checks; a request without an
        # entry needs none)
        self._fields: Dict[PduType, Callable[[Pdu], ErrorCode]] = {
            P.CFG_time_res: self._time_resolution, P.CFG_steps: self._steps,
            P.CFG_input: self._input, P.CFG_output: self._output,
            P.CFG_source_network_information: self._network, P.CFG_target_network_information: self._network,
            P.CFG_parameter: self._parameter, P.STC_prepare: self._prepare, P.STC_do_step: self._do_step,
            P.STC_run: self._run,
        }

    def check(self, pdu: Pdu) -> ErrorCode:
        """ErrorCode.NONE when the slave takes ``pdu``, else the code its RSP_nack carries."""
        type_id, slave = pdu.type_id, self.slave
        if type_id == P.STC_do_step and slave.op_mode != OpMode.NRT:
            return ErrorCode.NOT_SUPPORTED_PDU
        if type_id in states.NOT_OFFERED:
            return ErrorCode.NOT_SUPPORTED_PDU
        if not states.allowed(slave.state, type_id):
            return ErrorCode.PROTOCOL_ERROR_PDU_NOT_ALLOWED_IN_THIS_STATE
        if "state_id" in pdu.fields and pdu.state_id != slave.state:
            return ErrorCode.INVALID_STATE_ID
        check = self._fields.get(type_id)
        return check(pdu) if check is not None else ErrorCode.NONE

    def _time_resolution(self, pdu: Pdu) -> ErrorCode:
        """Offered by the description, and the FMU's step a whole number of its ticks (an FMU
        stepped in another size than its own would refuse, or be stepped at other instants)."""
        slave, config = self.slave, self.slave.config
        num, den = pdu.numerator, pdu.denominator
        if not slave.desc.supports_time_resolution(num, den):
            return ErrorCode.INVALID_TIME_RESOLUTION
        fixed = config.preset_resolution()
        if fixed is not None and Fraction(num, den) != Fraction(*fixed):
            return ErrorCode.INVALID_TIME_RESOLUTION
        step_s = slave.served.own_step_s()
        if step_s is not None and (step_s / Fraction(num, den)).denominator != 1:
            return ErrorCode.INVALID_TIME_RESOLUTION
        if any(not self.real_time_period_ok(steps, Fraction(num, den)) for steps in config.steps.values()):
            return ErrorCode.INVALID_TIME_RESOLUTION     # the outputs' periods already set would not fit
        return ErrorCode.NONE

    def _steps(self, pdu: Pdu) -> ErrorCode:
        config = self.slave.config
        if pdu.steps < 1:
            return ErrorCode.INVALID_STEPS
        output = config.outputs.get(pdu.data_id)
        for vr, _ in (output.positions.values() if output else ()):
            if not self.slave.vars_by_vr[vr].steps_supported(pdu.steps):
                return ErrorCode.INVALID_STEPS
        if config.resolution is not None and not self.real_time_period_ok(pdu.steps, Fraction(*config.resolution)):
            return ErrorCode.INVALID_STEPS
        return ErrorCode.NONE

    def real_time_period_ok(self, steps: int, resolution: Fraction) -> bool:
        """In soft real time an output period is stepped on the wall clock: it must be a whole
        number of the FMU's own steps (the FMU takes no smaller one, and a period of 1 ns cannot
        be kept), or at least MIN_RT_PERIOD_S for an FMU that declares no step."""
        if self.slave.op_mode == OpMode.NRT:
            return True          # outputs go out on STC_send_outputs: the period does not pace anything
        period_s, own_s = steps * resolution, self.slave.served.own_step_s()
        if own_s is None:
            return period_s >= Fraction(MIN_RT_PERIOD_S)
        return (period_s / own_s).denominator == 1

    def _max_do_step_s(self) -> Fraction:
        """The longest simulated span one STC_do_step may ask for: the slave answers nothing
        while it steps, so a step is bounded by the FMU's own step (MAX_FMU_STEPS_PER_DO_STEP of
        them), not only by the 2³²−1 ticks the PDU can carry."""
        own_s = self.slave.served.own_step_s() or Fraction(dcpx.DEFAULT_STEP_S)
        return MAX_FMU_STEPS_PER_DO_STEP * own_s

    def _input(self, pdu: Pdu) -> ErrorCode:
        var = self.slave.vars_by_vr.get(pdu.target_vr)
        if var is None or var.causality != "input":
            return ErrorCode.INVALID_VALUE_REFERENCE
        return ErrorCode.NONE if castable(pdu.source_data_type, var.data_type) else ErrorCode.INVALID_SOURCE_DATA_TYPE

    def _output(self, pdu: Pdu) -> ErrorCode:
        var = self.slave.vars_by_vr.get(pdu.source_vr)
        if var is None or var.causality != "output":
            return ErrorCode.INVALID_VALUE_REFERENCE
        steps = self.slave.config.steps.get(pdu.data_id)
        if steps is not None and not var.steps_supported(steps):
            return ErrorCode.INVALID_STEPS
        return ErrorCode.NONE

    def _network(self, pdu: Pdu) -> ErrorCode:
        """Inputs are received only on the address this slave serves (0.0.0.0 in the PDU means
        it); outputs go only to the master's host or back to this slave itself, so a master
        cannot make the slave listen elsewhere or send its data to a third party."""
        slave = self.slave
        if pdu.transport_protocol != TransportProtocol.UDP_IPv4:
            return ErrorCode.INVALID_TRANSPORT_PROTOCOL
        if not 1 <= pdu.port <= 65535:
            return ErrorCode.INVALID_NETWORK_INFORMATION
        if pdu.type_id == P.CFG_source_network_information:
            if not slave.desc.supports_dat_port(pdu.port) and pdu.port != slave.port:
                return ErrorCode.INVALID_NETWORK_INFORMATION
            if pdu.ip_address not in ("0.0.0.0", slave.host) and not (slave.host == "0.0.0.0"
                                                                      and is_local(pdu.ip_address)):
                return ErrorCode.INVALID_NETWORK_INFORMATION
        elif pdu.ip_address not in (slave.master[0], slave.host):
            return ErrorCode.INVALID_NETWORK_INFORMATION
        return ErrorCode.NONE

    def _parameter(self, pdu: Pdu) -> ErrorCode:
        var = self.slave.vars_by_vr.get(pdu.parameter_vr)
        if var is None or var.causality not in ("parameter", "structuralParameter"):
            return ErrorCode.INVALID_VALUE_REFERENCE
        if not castable(pdu.source_data_type, var.data_type):
            return ErrorCode.INVALID_SOURCE_DATA_TYPE
        try:
            PayloadCodec([(pdu.source_data_type, var.count)]).decode(pdu.configuration)
        except PduError as error:
            return error.error_code
        return ErrorCode.NONE

    def _prepare(self, pdu: Pdu) -> ErrorCode:
        code = self.slave.config.incomplete()
        if code != ErrorCode.NONE:
            return code
        exchange = self.slave.exchange
        try:   # the transport is prepared here so that a port that cannot be bound is refused
            exchange.bind_sources()
        except OSError:
            exchange.close_data_sockets()
            return ErrorCode.INVALID_NETWORK_INFORMATION
        return ErrorCode.NONE

    def _do_step(self, pdu: Pdu) -> ErrorCode:
        if not self.slave.desc.supports_nrt_steps(pdu.steps) \
                or pdu.steps * Fraction(*self.slave.config.resolution) > self._max_do_step_s():
            return ErrorCode.INVALID_STEPS
        return ErrorCode.NONE

    def _run(self, pdu: Pdu) -> ErrorCode:
        """Real time: a start time in the past, or more than MAX_START_DELAY_S ahead, is refused."""
        if self.slave.op_mode != OpMode.NRT and pdu.start_time > 0:
            now = int(time.time())
            if not now <= pdu.start_time <= now + MAX_START_DELAY_S:
                return ErrorCode.INVALID_START_TIME
        return ErrorCode.NONE

"""The DCP 1.0 slave state machine: which request a slave accepts in which state, and where
each state-changing request (STC_*) leads (docs/hil.md#state-machine).

A request not allowed in the slave's state is answered with RSP_nack
PROTOCOL_ERROR_PDU_NOT_ALLOWED_IN_THIS_STATE (a DAT PDU is dropped without answer). The
intermediate states a request enters (PREPARING, CONFIGURING, INITIALIZING, COMPUTING,
SENDING_I, SENDING_D, STOPPING) are left by the slave itself when its work is done, each
change announced with NTF_state_changed.
"""
from __future__ import annotations

from typing import Dict, FrozenSet, Optional

from orchestrator.dcp.pdu import PduType as P
from orchestrator.dcp.pdu import State as S

#: requests a master may send in every state of a registered slave (state and error queries)
_ALWAYS = frozenset({P.INF_state, P.INF_log})
_DATA = frozenset({P.DAT_input_output, P.DAT_parameter})
_CONFIG = frozenset({P.CFG_time_res, P.CFG_steps, P.CFG_input, P.CFG_output, P.CFG_clear,
                     P.CFG_target_network_information, P.CFG_source_network_information,
                     P.CFG_parameter, P.CFG_tunable_parameter, P.CFG_param_network_information,
                     P.CFG_logging, P.CFG_scope})

ALLOWED: Dict[S, FrozenSet[P]] = {
    S.ALIVE: frozenset({P.STC_register, P.INF_state}),
    S.CONFIGURATION: _ALWAYS | _CONFIG | {P.STC_deregister, P.STC_prepare},
    S.PREPARING: _ALWAYS | {P.STC_stop},
    S.PREPARED: _ALWAYS | {P.STC_configure, P.STC_stop},
    S.CONFIGURING: _ALWAYS | {P.STC_stop},
    S.CONFIGURED: _ALWAYS | _DATA | {P.STC_initialize, P.STC_run, P.STC_stop},
    S.INITIALIZING: _ALWAYS | _DATA | {P.STC_stop},
    S.INITIALIZED: _ALWAYS | _DATA | {P.STC_send_outputs, P.STC_stop},
    S.SENDING_I: _ALWAYS | _DATA | {P.STC_stop},
    S.SYNCHRONIZING: _ALWAYS | _DATA | {P.STC_do_step, P.STC_stop},
    S.SYNCHRONIZED: _ALWAYS | _DATA | {P.STC_run, P.STC_do_step, P.STC_stop},
    S.RUNNING: _ALWAYS | _DATA | {P.STC_do_step, P.STC_stop},
    S.COMPUTING: _ALWAYS | _DATA | {P.STC_stop},
    S.COMPUTED: _ALWAYS | _DATA | {P.STC_send_outputs, P.STC_stop},
    S.SENDING_D: _ALWAYS | _DATA | {P.STC_stop},
    S.STOPPING: _ALWAYS | _DATA,
    S.STOPPED: _ALWAYS | _DATA | {P.STC_deregister, P.STC_reset},
    S.ERROR_HANDLING: _ALWAYS | _DATA | {P.INF_error},
    S.ERROR_RESOLVED: _ALWAYS | _DATA | {P.INF_error, P.STC_reset, P.STC_deregister},
}

#: the requests a slave answers (every STC_, CFG_ and INF_ PDU)
REQUESTS = frozenset(t for t in P if t < P.RSP_ack) - _DATA
#: requests our slave refuses with NOT_SUPPORTED_PDU: logging and tunable parameters
NOT_OFFERED = frozenset({P.CFG_tunable_parameter, P.CFG_param_network_information, P.CFG_logging, P.INF_log})

#: the states in which the slave runs (its simulation time can advance)
RUN_STATES = frozenset({S.SYNCHRONIZING, S.SYNCHRONIZED, S.RUNNING})

#: (request, state it is accepted in) → the state the slave enters at once
_ENTERS: Dict[P, Dict[S, S]] = {
    P.STC_register: {S.ALIVE: S.CONFIGURATION},
    P.STC_deregister: {S.CONFIGURATION: S.ALIVE, S.STOPPED: S.ALIVE, S.ERROR_RESOLVED: S.ALIVE},
    P.STC_prepare: {S.CONFIGURATION: S.PREPARING},
    P.STC_configure: {S.PREPARED: S.CONFIGURING},
    P.STC_initialize: {S.CONFIGURED: S.INITIALIZING},
    P.STC_run: {S.CONFIGURED: S.SYNCHRONIZING, S.SYNCHRONIZED: S.RUNNING},
    P.STC_do_step: {s: S.COMPUTING for s in RUN_STATES},
    P.STC_send_outputs: {S.INITIALIZED: S.SENDING_I, S.COMPUTED: S.SENDING_D},
    P.STC_stop: {s: S.STOPPING for s in (S.PREPARING, S.PREPARED, S.CONFIGURING, S.CONFIGURED,
                                         S.INITIALIZING, S.INITIALIZED, S.SENDING_I,
                                         S.SYNCHRONIZING, S.SYNCHRONIZED, S.RUNNING,
                                         S.COMPUTING, S.COMPUTED, S.SENDING_D)},
    P.STC_reset: {S.STOPPED: S.CONFIGURATION, S.ERROR_RESOLVED: S.CONFIGURATION},
}

#: an intermediate state → the state the slave moves to by itself when its work is done
#: (COMPUTING, SENDING_D return to the run state the step started from: see Slave code)
COMPLETES: Dict[S, S] = {
    S.PREPARING: S.PREPARED,
    S.CONFIGURING: S.CONFIGURED,
    S.INITIALIZING: S.INITIALIZED,
    S.SENDING_I: S.CONFIGURED,
    S.COMPUTING: S.COMPUTED,
    S.SYNCHRONIZING: S.SYNCHRONIZED,
    S.STOPPING: S.STOPPED,
    S.ERROR_HANDLING: S.ERROR_RESOLVED,
}


def allowed(state: S, type_id: P) -> bool:
    """May a slave in ``state`` act on a request of ``type_id``?"""
    return type_id in ALLOWED[state]


def enters(state: S, type_id: P) -> Optional[S]:
    """The state an accepted state-changing request leads to from ``state`` (None: the request
    does not change the state, or is not allowed there)."""
    return _ENTERS.get(type_id, {}).get(state)

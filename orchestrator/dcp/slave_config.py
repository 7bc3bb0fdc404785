"""What a DCP master configures on ``railcosim dcp-slave`` (the CFG_* requests, once the checks
of orchestrator/dcp/slave_checks.py have accepted them): the time resolution, each data_id's
variables by position, steps, scope and address, the parameters, and at STC_prepare each
data_id's payload layout. Cleared by CFG_clear, STC_reset and STC_deregister.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Dict, List, Optional, Tuple

import numpy as np

from orchestrator.dcp.dcpx import SlaveDescription
from orchestrator.dcp.pdu import NUMPY_DTYPES, VARIABLE_LENGTH, DataType, ErrorCode, PayloadCodec, Pdu, Scope


def castable(source: DataType, target: DataType) -> bool:
    """May values of ``source`` type feed a variable of ``target`` type? Equal types, or a
    numeric widening that loses nothing (numpy's 'safe' casting)."""
    if source == target:
        return True
    if source in VARIABLE_LENGTH or target in VARIABLE_LENGTH:
        return False
    return bool(np.can_cast(NUMPY_DTYPES[source], NUMPY_DTYPES[target], casting="safe"))


@dataclass
class DataIdConfig:
    """Configuration of one data_id (CFG_input/CFG_output/CFG_steps/CFG_scope/network), and
    the sequence ids of its DAT PDUs."""
    positions: Dict[int, Tuple[int, DataType]] = field(default_factory=dict)   # pos → (vr, source type)
    steps: Optional[int] = None
    scope: Scope = Scope.Initialization_Run_NonRealTime
    address: Optional[Tuple[str, int]] = None
    codec: Optional[PayloadCodec] = None
    order: List[int] = field(default_factory=list)      # vrs in pos order
    last_seq: Optional[int] = None
    jump_seq: Optional[int] = None    # a DAT out of the window, waiting for the next to confirm it
    send_seq: int = 0


class SlaveConfiguration:
    """The configuration of one session, from nothing (a description's one fixed resolution
    aside) to what STC_prepare needs."""

    def __init__(self, description: SlaveDescription, vars_by_vr: Dict[int, object], host: str):
        self.desc, self.vars_by_vr, self.host = description, vars_by_vr, host
        self.inputs: Dict[int, DataIdConfig] = {}
        self.outputs: Dict[int, DataIdConfig] = {}
        self.sources: Dict[int, Tuple[str, int]] = {}    # data_id → where its inputs arrive
        self.scopes: Dict[int, Scope] = {}
        self.steps: Dict[int, int] = {}
        self.resolution: Optional[Tuple[int, int]] = self.preset_resolution()
        self.parameters: Dict[int, list] = {}

    def preset_resolution(self) -> Optional[Tuple[int, int]]:
        """A description with one fixed resolution needs no CFG_time_res: it is in use from the
        start (as the reference implementation does)."""
        fixed = [(num, den) for num, den, is_fixed, _ in self.desc.resolutions if is_fixed]
        return fixed[0] if fixed else None

    # ---- the CFG requests ----------------------------------------------------------------
    def set_time_resolution(self, pdu: Pdu) -> None:
        self.resolution = (pdu.numerator, pdu.denominator)

    def set_steps(self, pdu: Pdu) -> None:
        self.steps[pdu.data_id] = pdu.steps

    def add_input(self, pdu: Pdu) -> None:
        self.inputs.setdefault(pdu.data_id, DataIdConfig()).positions[pdu.pos] = (pdu.target_vr, pdu.source_data_type)

    def add_output(self, pdu: Pdu) -> None:
        var = self.vars_by_vr[pdu.source_vr]
        self.outputs.setdefault(pdu.data_id, DataIdConfig()).positions[pdu.pos] = (pdu.source_vr, var.data_type)

    def set_source(self, pdu: Pdu) -> None:
        ip = pdu.ip_address if pdu.ip_address != "0.0.0.0" else self.host
        self.sources[pdu.data_id] = (ip, pdu.port)

    def set_target(self, pdu: Pdu) -> None:
        self.outputs.setdefault(pdu.data_id, DataIdConfig()).address = (pdu.ip_address, pdu.port)

    def set_parameter(self, pdu: Pdu) -> None:
        var = self.vars_by_vr[pdu.parameter_vr]
        value = PayloadCodec([(pdu.source_data_type, var.count)]).decode(pdu.configuration)[0]
        self.parameters[var.vr] = [value] if isinstance(value, str) else list(np.asarray(value).tolist())

    def set_scope(self, pdu: Pdu) -> None:
        self.scopes[pdu.data_id] = pdu.scope

    # ---- STC_prepare ---------------------------------------------------------------------
    def incomplete(self) -> ErrorCode:
        """What STC_prepare still lacks, in the standard's order (ErrorCode.NONE: nothing): a gap
        in a data_id's positions, an input's or output's network information, an output's
        steps, the time resolution."""
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
        return ErrorCode.NONE

    def prepare(self) -> None:
        """Each data_id's variables in position order and its payload's codec; each output's
        steps and scope."""
        for config in list(self.inputs.values()) + list(self.outputs.values()):
            config.order = [config.positions[p][0] for p in sorted(config.positions)]
            config.codec = PayloadCodec([(config.positions[p][1], self.vars_by_vr[config.positions[p][0]].count)
                                         for p in sorted(config.positions)])
        for data_id, config in self.outputs.items():
            config.steps = self.steps[data_id]
            config.scope = self.scopes.get(data_id, Scope.Initialization_Run_NonRealTime)

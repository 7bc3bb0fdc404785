"""The approach part of a block's blocking time: what a following train's cab shows behind an
occupied block, and the ATP's permitted speed under it — derived from the system's own rules,
never from a table of aspects written here.

Blocking-time theory (docs/capacity.md) blocks a section from the moment the follower would first
be affected by it being occupied: the *approach*. With cab signalling that is where the
follower's cab would show something more restrictive than on a free line, and the ATP would
supervise a curve below the follower's unhindered run. This module gives both, for one block
``k`` occupied and every other block free. A *block* is ``Line.block_bounds``: signal to signal
(track circuits without a signal, e.g. in a station throat, belong to the block of the circuits
after them).

Derivation, for the occupancy "every track circuit of block k occupied, all others free":

1. **The coder's code** of every track circuit, by the functions the wayside coder cores call
   (fmus/wayside_coder/): the block rules ``block_rules.block_codes`` (exit signal, free blocks
   ahead, code cut behind an occupied circuit of the same block), then per system —
   ALSN the rules' ALSN code (red → КЖ, yellow → Ж, green and yellow-green → З); ALSU
   ``alsu.BlockCoding.codes`` (1 / 6 / 9, 4-aspect 1 / 4 / 6, route, restriction and high-speed
   codes from the line); ALS-EN and FIRE_DQPSK the system's ``command_for(free blocks)``
   (capped at ``FREE_BLOCKS_OPEN``, as digital_generator.py does); TVM-430
   ``tvm430.BlockWords.words`` (the speed pair from the blocks before the target point, the
   target at the entry of the buffer block, the line's last stop, the step caps, the gradient).
   The leader's occupancy of any one circuit of block k gives the same codes behind it: the
   rules are per block. tests/test_headway_approach.py checks these codes against the real
   coder cores stepped with that occupancy.
2. **What the receiver hands the ATP** for a valid code, as the receivers publish it
   (fmus/loco_receiver/: ``alsn.speeds_for``; ALSU and digital: the system's ``indication`` for
   the receiver's ``train_category``, the ceiling capped by its ``v_max``; TVM-430 the word's
   ``reading``: step, next step, target distance, gradient, and the circuit's carrier). The
   receiver's latency and display hold are not here: they are the reaction/decoding time of the
   blocking time, ``setup.atp.latency_s`` (the ATO's ``decoding_latency``).
3. **The ATP's constraints** for that indication, by its own builders
   (``Atp.indication_constraints``: ``_alsn``, ``_alsu``, ``_digital``, ``_tvm430``) for the
   block (TVM-430: the track circuit) holding the head: a ceiling and targets ahead.
4. **The permitted speed** at each head position: atp.py's service curve
   min(ceiling, sqrt(v_t² + 2·a·s·(x_t − x))) over the targets ahead (a target behind the head:
   its speed), a = the ATP's supervision deceleration, s = the target's braking share (ALSU:
   ½ for a permanent restriction); TVM-430 besides each target's curve at a less the transmitted
   falling gradient's pull (at least a/10), and towards a stop no higher than its trip curve
   (emergency deceleration less the gradient, the brake's lead time, to the end of the buffer
   section) less 2·dV_sbi(v). Vectorised here from atp.py's ``supervise``, atp_tvm430.py's
   ``levels``, ``trip_curve`` and ``tvm_decel`` and supervision.py's ``dv_sbi_mps``; the test compares them with
   ``Atp.supervise`` position by position. Without the dV_sbi / dV_ebi intervention margins
   and without the line's static limits (the unhindered run obeys those already).

Not included [U]: the ATP's fail-safe additions — after passing a signal it assumes, for its
decoding latency, the worst code the new block could carry (atp.py ``_passed_signal``); on the
shipped lines that assumption lies far above the unhindered run — and a falling cab ceiling
reached on a braking curve after the driver's reaction time (both depend on the run, not on
the indication).

A block's indication is **free-line** when its coder sends the same code as with the whole line
free (a block before a station or a permanent restriction may carry a restrictive code on a
free line too: that is no approach); there the permitted speed is +inf.
"""
from __future__ import annotations

import functools
from dataclasses import dataclass, field
from pathlib import Path
from typing import List, Mapping, Optional

import numpy as np

from fmus.ato_controller.atp import Atp
from fmus.ato_controller.atp_tvm430 import tvm_decel
from fmus.ato_controller.supervision import Constraints
from fmus.ato_controller.core import AtoSettings, default_atp_decel_mps2
from fmus.data.loader import DATA, DEFAULT_LINE, DEFAULT_ROLLING_STOCK, Line, RollingStock, load_line, load_rolling_stock
from fmus.errors import FmuInputError
from fmus.loco_receiver.parameters import receiver_settings
from fmus.signalling import cab_systems
from fmus.train_categories import TRAIN_CATEGORIES
from fmus.signalling.block_rules import block_codes
from fmus.signalling.digital_messages import FREE_BLOCKS_OPEN
from fmus.traction.brake_pipeline import brake_lead_s
from fmus.units import KMH_PER_MPS, MPS_PER_KMH
from orchestrator.systems.chain import cab_settings
from orchestrator.errors import UserError

NO_OUTPUT = -1             # a digital circuit whose code is cut (the generator sends nothing)
# supervision.dv_sbi_mps, vectorised: 5.5 km/h up to 110 km/h, rising linearly to 10 km/h at 210 km/h
_DV_SBI_KMH = ((110.0, 210.0), (5.5, 10.0))
# the stop curve at the train's own speed: each round cuts the error by 2 × 0.045 (dV_sbi's slope)
_FIXED_POINT_ROUNDS = 12


@dataclass(frozen=True)
class CabSetup:
    """One system's cab signalling as a follower sees it: the coder's rules on the line, the
    receiver's reading, the ATP as the ATO builds it (:func:`cab_setup`)."""

    system: str                 # the coder's `system`: ALSN, ALSU, ALS-EN, FIRE_DQPSK, TVM430
    block_aspects: int          # 3 or 4 (the coder's block_aspects; ALSN and ALSU read it)
    line: Line
    stock: RollingStock = field(repr=False)
    category: str               # the ATO's train category (its ATP reads the codes for it)
    receiver_category: str      # the receiver's train_category (ALSN, ALSU and digital readings)
    receiver_v_max_mps: float   # the receiver's ceiling cap (its v_max; 0: the system's for the category)
    atp: Atp                    # built as fmus/ato_controller/core.py builds it (decelerations, latency)
    coding: object = field(repr=False)   # the coder's rule: the system's block_coding, a DigitalSystem, None (ALSN)
    reader: object = field(default=None, repr=False)   # the system object the receiver reads with (None: ALSN)

    @property
    def cab(self) -> cab_systems.CabSystem:
        return cab_systems.lookup(self.system)

    @functools.cached_property
    def free_line_codes(self) -> np.ndarray:
        """What each track circuit carries with the whole line free (_carried's ids)."""
        return _carried(self, np.zeros(len(self.line.sections), dtype=bool))


@dataclass(frozen=True)
class BlockIndication:
    """What the follower's cab shows in one block behind the occupied one."""

    block: int
    label: str                  # in the system's terms: "КЖ"; "code 4"; "free 3, 160 km/h"; "270→230"
    free_line: bool             # the same as with the whole line free: no restriction from the occupancy
    code: int                   # the coder's code_tx on the block's circuits (ALSN aspect code, ALSU code,
                                # digital KLUB / command code (ALS-EN: 15 for five and six free), TVM word)
    aspect: int                 # the receiver's outputs the ATP reads (fmus/signalling/aspects.py enumeration)
    v_permitted_mps: float
    v_target_mps: float
    free_blocks: int
    target_distance_m: float = 0.0     # TVM-430: from the block's entry to the target point
    gradient_permille: float = 0.0     # TVM-430: most falling gradient to the target, + uphill


def _resolve(path, default: Path) -> Path:
    """A data file as the FMUs name it: empty for the bundled default, a bundled file by name, or a path."""
    if not path:
        return default
    path = Path(path)
    return path if path.is_file() else DATA / path


def cab_setup(system: str, block_aspects: int = 3, line_file=None, rolling_stock_file=None,
              ato_parameters: Optional[Mapping[str, object]] = None,
              receiver_parameters: Optional[Mapping[str, object]] = None) -> CabSetup:
    """The setup of ``system`` on a line for a train. ``ato_parameters`` and
    ``receiver_parameters`` by FMU port name; one not given takes the FMU's default, except the
    ATO's ``cab_signal``, which follows the system (orchestrator/systems/chain.py
    ``cab_settings``, whose ATO parameters give the shipped systems' decoding latency). Read: the
    ATO's ``train_category`` (empty: the stock's), ``atp_decel`` (0: 0.7 × the stock's service
    deceleration), ``decoding_latency``; the receiver's ``train_category`` and ``v_max``."""
    try:
        cab_systems.check_name(system)
    except FmuInputError as error:
        raise UserError(str(error)) from None
    if block_aspects not in (3, 4):
        raise UserError(f"parameter block_aspects: {block_aspects} (3 or 4)")
    ato = dict(ato_parameters or {})
    mode = cab_settings(system)[3]["cab_signal"]
    if ato.get("cab_signal", mode) != mode:
        raise UserError(f"parameter cab_signal: {ato['cab_signal']!r}, but a {system} coder needs the ATO's "
                        f"cab_signal {mode!r}")
    try:
        line = load_line(_resolve(line_file, DEFAULT_LINE))
        stock = load_rolling_stock(_resolve(rolling_stock_file, DEFAULT_ROLLING_STOCK))
    except FmuInputError as error:
        raise UserError(str(error)) from None
    category = str(ato.get("train_category") or stock.category)
    if category not in TRAIN_CATEGORIES:
        raise UserError(f"parameter train_category: {category!r} is not one of {', '.join(TRAIN_CATEGORIES)}")
    # as fmus/ato_controller/core.py AtoCore builds its ATP (its facade has no brake_lead port:
    # the stock's brake lead always)
    defaults = AtoSettings()
    atp_decel = float(ato.get("atp_decel", defaults.atp_decel_mps2))
    try:
        atp = Atp(line, category, stock.length_m, mode, atp_decel if atp_decel > 0 else default_atp_decel_mps2(stock),
                  float(ato.get("decoding_latency", defaults.decoding_latency_s)),
                  emergency_decel_mps2=stock.emergency_decel, brake_lead_s=brake_lead_s(stock))
        coding, reader = _coding(cab_systems.lookup(system), line, block_aspects)
        rx = receiver_settings(system, dict(receiver_parameters or {}))
    except FmuInputError as error:
        raise UserError(str(error)) from None
    rx_category = getattr(rx, "train_category", category)
    if rx_category not in TRAIN_CATEGORIES:
        raise UserError(f"parameter train_category (receiver): {rx_category!r} is not one of "
                        f"{', '.join(TRAIN_CATEGORIES)}")
    return CabSetup(system, block_aspects, line, stock, category, rx_category, float(getattr(rx, "v_max_mps", 0.0)),
                    atp, coding, reader)


def _coding(cab: cab_systems.CabSystem, line: Line, block_aspects: int):
    """(the coder's per-system rule object, the system object the receiver reads with)."""
    system = cab.system()
    if cab.family == cab_systems.TABLE:
        return system.block_coding(line, block_aspects), system
    return system, system


def _occupancy(setup: CabSetup, occupied_block: int) -> np.ndarray:
    blocks = len(setup.line.block_bounds)
    if not isinstance(occupied_block, (int, np.integer)) or not 0 <= occupied_block < blocks:
        raise UserError(f"occupied block {occupied_block!r}: {setup.line.path} has blocks 0…{blocks - 1}")
    return np.asarray(setup.line.block_of_section) == occupied_block


def _carried(setup: CabSetup, occupied: np.ndarray) -> np.ndarray:
    """What each track circuit's coder sends for this occupancy, in the system's own ids: ALSN
    code (an aspect), ALSU code, digital command (NO_OUTPUT where cut), TVM word."""
    rules = block_codes(occupied, setup.line.block_of_section, setup.block_aspects)
    family = setup.cab.family
    if family == cab_systems.NUMERIC:
        return rules.alsn_code
    if family == cab_systems.TABLE:
        return setup.coding.codes(rules)
    free = np.minimum(np.maximum(rules.free_blocks, 0), FREE_BLOCKS_OPEN)
    commands = np.array([setup.coding.command_for(int(n)) for n in free.tolist()], dtype=np.int64)
    return np.where(rules.coded, commands, NO_OUTPUT)


def _received(setup: CabSetup, sent: int, circuit: int) -> dict:
    """The receiver's outputs for a valid code (the keyword arguments of Atp.indication_constraints),
    as each receiver publishes them (fmus/loco_receiver/)."""
    return setup.cab.receiver_outputs(setup.reader, int(sent), setup.receiver_category, setup.receiver_v_max_mps,
                                      setup.line.sections[circuit].carrier_hz)


def _code_tx(setup: CabSetup, sent: int) -> int:
    """The coder's ``code_tx`` for what it sends: the id itself, a digital command's passenger
    code (digital_generator.py)."""
    if setup.cab.family != cab_systems.DIGITAL_FAMILY:
        return int(sent)
    return 0 if sent == NO_OUTPUT else setup.coding.indication(int(sent), "passenger").code


def _label(setup: CabSetup, received: dict) -> str:
    return setup.cab.label(received)


def indications_behind(setup: CabSetup, occupied_block: int) -> List[BlockIndication]:
    """For every block b < ``occupied_block``, with only that block occupied: what the cab shows
    in block b (from its first track circuit: every circuit of a block behind the occupied one
    carries the same code, the block rules being per block)."""
    line = setup.line
    sent = _carried(setup, _occupancy(setup, occupied_block))
    first = {}
    for circuit, block in enumerate(line.block_of_section):
        first.setdefault(block, circuit)
    out = []
    for block in range(occupied_block):
        circuit = first[block]
        received = _received(setup, sent[circuit], circuit)
        out.append(BlockIndication(
            block, _label(setup, received), bool(sent[circuit] == setup.free_line_codes[circuit]),
            _code_tx(setup, sent[circuit]), received["aspect"], received["v_permitted"], received["v_target"],
            received["free_blocks"], received.get("target_distance_m", 0.0), received.get("gradient_permille", 0.0)))
    return out


def approach_blocks(setup: CabSetup) -> int:
    """The most blocks behind an occupied block whose indication is not the free-line one, over
    every block of the line occupied in turn (ALSN 3-aspect: 2, КЖ and Ж)."""
    return max((sum(not ind.free_line for ind in indications_behind(setup, k))
                for k in range(len(setup.line.block_bounds))), default=0)


def permitted_speed_mps(setup: CabSetup, occupied_block: int, head_m, speed_mps=None) -> np.ndarray:
    """The ATP's permitted speed (m/s) at each head position ``head_m`` with only block
    ``occupied_block`` occupied, under the indication of the circuit holding the head (module
    docstring): +inf where that is the free-line indication, NaN in or beyond the occupied block
    and off the line. ``speed_mps`` (the train's speed at each position) is read by TVM-430's stop
    curve only, which stays 2·dV_sbi(v) under the trip curve; None: the permitted speed itself
    (a train running on its curve)."""
    x = np.asarray(head_m, dtype=float)
    v = None if speed_mps is None else np.broadcast_to(np.asarray(speed_mps, dtype=float), x.shape)
    sent = _carried(setup, _occupancy(setup, occupied_block))
    out = np.full(x.shape, np.nan)
    line = setup.line
    for circuit, (section, block) in enumerate(zip(line.sections, line.block_of_section)):
        if block >= occupied_block:
            break
        here = (x >= section.start_m) & (x < section.end_m)
        if not here.any():
            continue
        if sent[circuit] == setup.free_line_codes[circuit]:
            out[here] = np.inf
            continue
        constraints = setup.atp.indication_constraints(section.start_m, **_received(setup, sent[circuit], circuit))
        out[here] = _permitted(setup.atp, constraints, x[here], None if v is None else v[here])
    return out


def _dv_sbi_mps(v_mps: np.ndarray) -> np.ndarray:
    return np.interp(v_mps * KMH_PER_MPS, *_DV_SBI_KMH) * MPS_PER_KMH


def _permitted(atp: Atp, c: Constraints, x: np.ndarray, v: Optional[np.ndarray]) -> np.ndarray:
    """atp.py's permitted speed for constraints ``c`` at heads ``x`` (Atp.supervise, Tvm430Supervision.levels)."""
    permitted = np.full(x.shape, c.ceiling_mps)
    for target in c.targets:
        distance = target.position_m - x
        curve = np.sqrt(target.speed_mps ** 2 + 2.0 * atp.decel * target.braking_share * np.maximum(distance, 0.0))
        permitted = np.minimum(permitted, np.where(distance >= 0.0, curve, target.speed_mps))
    stops, service = [], permitted
    if atp.mode == cab_systems.AtoMode.TVM430:
        for target in c.targets:
            if target.trip_speed_mps is None:
                continue
            distance = target.position_m - x
            decel = tvm_decel(atp.decel, target.gradient_permille)
            curve = np.sqrt(target.speed_mps ** 2 + 2.0 * decel * np.maximum(distance, 0.0))
            if target.trip_speed_mps == 0.0:
                stops.append((distance, curve, _trip_curve(atp, target, x)))
            else:
                service = np.where(distance >= 0.0, np.minimum(service, np.maximum(curve, 0.0)), service)
    if not stops:
        return service

    def with_stops(speed: np.ndarray) -> np.ndarray:
        result = service
        for distance, curve, trip in stops:
            held = np.maximum(np.minimum(curve, trip - 2.0 * _dv_sbi_mps(speed)), 0.0)
            result = np.where(distance >= 0.0, np.minimum(result, held), result)
        return result
    if v is not None:
        return with_stops(v)
    speed = service
    for _ in range(_FIXED_POINT_ROUNDS):
        speed = with_stops(np.where(np.isfinite(speed), speed, 0.0))
    return speed


def _trip_curve(atp: Atp, target, x: np.ndarray) -> np.ndarray:
    """Tvm430Supervision.trip_curve at heads ``x``."""
    v_t = target.trip_speed_mps
    end = target.position_m if target.trip_position_m is None else target.trip_position_m
    distance = end - x
    a = tvm_decel(atp.tvm.emergency_decel, target.gradient_permille)
    lead = atp.tvm.brake_lead_s if v_t == 0.0 else 0.0
    curve = -a * lead + np.sqrt(a * a * lead * lead + v_t * v_t + 2.0 * a * np.maximum(distance, 0.0))
    return np.where(distance > 0.0, curve, v_t)

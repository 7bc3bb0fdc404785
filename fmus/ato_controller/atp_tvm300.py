"""The ATP's TVM-300 supervision (docs/ato.md#tvm-300): fixed speed steps, no continuous curve.

TVM-300's code (the receiver's outputs, TVM-430's ports less the distance and the gradient):
``v_permitted`` the step in force until the end of the word's block, ``v_target`` the step to
reach at the block's exit (the next block's step), ``word_carrier`` the carrier the code came
from, which finds the word's block as TVM-430's does (atp_tvm430.TvmBlocks.word_block). Behind
an occupied block the cascade of steps 300–270–220–160–80–0 km/h runs block by block:
… (220, 160), (160, 80), (80, 0) — a stop at the block's exit, the entry of the buffer section
(the last free block) — and (0, 0) in the buffer section.

What is supervised (``Tvm300Supervision``):

* the trip: the step's control level, step + 15 km/h (TVM-430's margin taken over,
  ``TVM_CONTROL_MARGIN_MPS``) until the block's exit, and from the exit the next step's,
  next step + 15 km/h — a step function of the position, no trip curve;
* the service (permitted) curve the ATO keeps under: the next step reached by the block's exit
  at the supervision deceleration (the ATP's service intervention ``dV_sbi`` above it, as in the
  other modes), the step itself before;
* a stop at the exit of a block whose word is (80, 0) or (0, 0): passing it with such a word in
  force is a signal passed at danger (counted, the emergency brake), as TVM-430 counts a stop
  point at a block marker;
* a lost or invalid code: step 0, its control level 15 km/h trips a moving train at once (as
  TVM-430); the last valid word's targets stay where they were.
"""
from __future__ import annotations

import math
from typing import Tuple

import numpy as np

from fmus.ato_controller.atp_tvm430 import TVM_CONTROL_MARGIN_MPS, TvmBlocks, TvmMode
from fmus.ato_controller.supervision import Constraints, Target
from fmus.signalling import tvm300
from fmus.units import MPS_PER_KMH


class Tvm300Supervision(TvmBlocks):
    """TVM-300's steps on one line: the words' blocks (TvmBlocks), a word's constraints and its
    trip level at the head."""

    def constraints(self, v_step: float, v_next: float, block: int) -> Constraints:
        """The constraints of a TVM-300 word from track circuit ``block``: the step from now on,
        and — when the next step is lower, or the step is 0 — the next step at the block's exit
        (a stop there when it is 0), whose control level is the trip from the exit on."""
        v_step, v_next = max(v_step, 0.0), max(v_next, 0.0)
        c = Constraints(v_step)
        if v_next < v_step or v_step == 0.0:
            c.targets.append(Target(self.circuit_ends[block], v_next, signal=v_next == 0.0,
                                    trip_speed_mps=v_next + TVM_CONTROL_MARGIN_MPS))
        return c

    def levels(self, c: Constraints, x: float, permitted: float, cab_ceiling_mps: float) -> Tuple[float, float]:
        """(trip level, permitted speed) at the head: the control level of the step shown
        (``cab_ceiling_mps``, not of a higher one held while a fall is braked for) and of the
        line's ceiling, and the control level of each next step whose block exit the head has
        passed (a step function: no trip curve ahead of the exit). The permitted speed is the
        ATP's (the ceiling and the curves towards the targets at the supervision deceleration)."""
        trip = min(c.ceiling_mps, cab_ceiling_mps) + TVM_CONTROL_MARGIN_MPS
        for target in c.targets:
            if target.trip_speed_mps is not None and x >= target.position_m:
                trip = min(trip, target.trip_speed_mps)
        return trip, permitted


class Tvm300Mode(TvmMode):
    """TVM300: the ATP's reading of the TVM-300 code (this module's docstring)."""

    inputs = ("aspect", "v_permitted", "v_target", "word_carrier")

    def __init__(self, atp):
        super().__init__(atp)
        self.tvm = Tvm300Supervision(atp.line)

    def constraints(self, x, k, shown):
        block = self.tvm.word_block(x, shown.word_carrier_hz)
        if block is None:
            return self.no_code()
        return self.tvm.constraints(shown.v_permitted_mps, shown.v_target_mps, block)

    def levels(self, c, x, v, permitted, cab_ceiling_mps):
        return self.tvm.levels(c, x, permitted, cab_ceiling_mps)

    def planned_limits(self):
        """The steps the block rules send with the whole line free (tvm300.BlockCoding): they
        count the blocks to the line's last station stop as to an occupied block, so the last
        five blocks before it show the cascade even on a free line. Each track circuit's step
        while the head is in it, and — where its next step is lower — that next step from its
        exit until the next circuit's exit (the ATP wants it reached at the exit; on the free
        line it is the next circuit's own step), so the planner's braking for the drop ends at
        the exit. The shipped code table's steps: the ATO reads steps, not the table."""
        line = self.atp.line
        coding = tvm300.system().block_coding(line)
        circuits = len(line.sections)
        free = coding.codes_of(np.full(circuits, coding.open_blocks), np.ones(circuits, dtype=bool))
        limits = []
        for k, code in enumerate(free):
            reading = coding.tvm.reading(int(code))
            section = line.sections[k]
            limits.append((section.start_m, section.end_m, reading.step_kmh * MPS_PER_KMH))
            if reading.next_kmh < reading.step_kmh:
                until_m = line.sections[k + 1].end_m if k + 1 < circuits else math.inf
                limits.append((section.end_m, until_m, reading.next_kmh * MPS_PER_KMH))
        return tuple(dict.fromkeys(limits))       # a drop that is the next circuit's step once

    def fault(self, shown):
        fault = super().fault(shown)
        if fault is not None:
            return fault
        for name, value in (("v_permitted", shown.v_permitted_mps), ("v_target", shown.v_target_mps),
                            ("word_carrier", shown.word_carrier_hz)):
            if not (math.isfinite(value) and value >= 0.0):
                return name, f"TVM-300 {name} = {value:g} is impossible"
        return None

"""The track relays (no FMI here; docs/rail_line.md, plant): each circuit's relay-end level (its
network model's, relative to the calibrated reference) against the pick-up and drop-out levels,
with the pick-up and drop-out delays → up (free) or down (occupied).
"""
from __future__ import annotations

import numpy as np

from fmus.reductions import any_true


class TrackRelays:
    """``levels[k]``: relay k's level now (set by the bank when a section's model changes, with
    ``settled`` cleared); ``up``: the relays' states, a new array whenever a relay moves (never
    changed in place, so a reader can tell a change by identity)."""

    def __init__(self, count: int, settings):
        self.settings = settings
        self.levels = np.ones(count)
        self.settled = False                 # True: no relay moves until a level changes
        self.up = np.ones(count, dtype=bool)
        self.timer = np.zeros(count)

    def stand(self) -> None:
        """The state at t = 0: up only at or above pick-up, with no delay (the restrictive
        reading of a relay whose history is unknown)."""
        self.up = self.levels >= self.settings.relay_pick_up
        self.timer[:] = 0.0
        self.settled = False

    def would_move(self, k: int, level: float) -> bool:
        """Would relay k start to pick up or drop out at ``level`` (its state and the levels)?"""
        s = self.settings
        up = bool(self.up[k])
        return (level > s.relay_drop_out) != up if up else (level >= s.relay_pick_up) != up

    def update(self, step_s: float) -> None:
        """The relays after ``step_s`` seconds at the current levels."""
        s = self.settings
        levels = self.levels
        wants_up = np.where(self.up, levels > s.relay_drop_out, levels >= s.relay_pick_up)
        changing = wants_up != self.up
        if not any_true(changing):
            self.timer[:] = 0.0
            self.settled = True              # nothing to do until a level changes
            return
        self.timer = np.where(changing, self.timer + step_s, 0.0)
        delay = np.where(wants_up, s.relay_pick_up_delay_s, s.relay_drop_out_delay_s)
        done = changing & (self.timer >= delay - 1e-12)
        if any_true(done):
            self.up = np.where(done, wants_up, self.up)
            self.timer[done] = 0.0

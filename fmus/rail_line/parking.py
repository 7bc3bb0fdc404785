"""Parking of sections (no FMI here; docs/rail_line.md, performance): a section no train shunts
and no coil can reach before the next configuration change is not advanced; its code input is
kept in a history, and when a train or a coil needs it again (or a fault changes) its states are
caught up by stepping them through the frames since, or only through the last frames its
network's slowest mode needs to fall below ``SETTLED_SHARE`` of where it started (what is left
of the truncated start is far below rounding).
"""
from __future__ import annotations

import math
from typing import Callable, List, Optional

import numpy as np

from fmus.rail_line.network_models import NetworkModel

# a parked section is caught up over as many frames as its network's slowest mode takes to fall
# below this share (a few units in the last place of the states), the history at most this many
# floats; a section that would need more is never parked
SETTLED_SHARE = 2.0 ** -64
HISTORY_FLOATS = 2 ** 20


def settle_frames(model: NetworkModel) -> int:
    """Frames after which whatever a section's states held has decayed below SETTLED_SHARE (its
    network's slowest mode over a frame); kept on the model."""
    if not model.settle_frames:
        radius = float(np.abs(np.linalg.eigvals(model.phi_n)).max())
        model.settle_frames = 1 if radius < 1e-300 else 1 << 62 if radius >= 1.0 \
            else math.ceil(math.log(SETTLED_SHARE) / math.log(radius))
    return model.settle_frames


class Parking:
    """Which sections advance (``live``), which are wanted live (``wanted``), the parked ones'
    states and the frame they were parked at (``parked_at[k]``, None: live), and the code
    input's history (``history[frame index % its length]``, written by the bank while a section
    is parked). ``step`` is the bank's [Φᴺ | Ψ] per section, shared (it changes in place)."""

    def __init__(self, count: int, frame: int, size: int, step: np.ndarray, history_frames: int):
        self.size, self.frame, self.step = size, frame, step
        self.parked_at: List[Optional[int]] = [None] * count
        self.live = list(range(count))
        self.wanted = set(range(count))
        self.review = False                  # the wanted set changed: park what is no longer wanted
        self.parked = np.zeros((count, size))
        self.history = np.zeros((min(history_frames, HISTORY_FLOATS // (count * frame)), count, frame))

    def park(self, end: np.ndarray, frame_index: int, settle_frames_of: Callable[[int], int]) -> None:
        """Stop advancing the live sections no train or coil needs (``end``: the states after
        this frame's step, padded rows; ``frame_index``: the frame that follows), when their
        history would be long enough to catch them up (``settle_frames_of(k)``)."""
        self.review = False
        keep = []
        for k in self.live:
            if k in self.wanted or settle_frames_of(k) >= len(self.history):
                keep.append(k)
            else:
                self.parked[k] = end[k, :self.size]
                self.parked_at[k] = frame_index
        self.live = keep

    def caught_up(self, k: int, until: int, settle: int) -> np.ndarray:
        """Parked section k's states at the start of frame ``until``, live from then on: its
        parked states stepped through the code input of the frames since, or only of the last
        ``settle`` frames, which its slowest mode needs to forget where it started (the
        difference is below rounding)."""
        size, history = self.size, self.history
        first = max(self.parked_at[k], until - settle)
        row, following = np.empty(size + self.frame), np.empty(size)
        row[:size] = self.parked[k]
        step = self.step[k]
        for index in range(first, until):
            row[size:] = history[index % len(history), k]
            np.matmul(step, row, out=following)
            row[:size] = following
        self.parked_at[k] = None
        self.wanted.add(k)
        self.live = sorted(self.live + [k])
        return row[:size]

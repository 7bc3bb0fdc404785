"""Blocking-time theory (no FMI here; docs/capacity.md#blocking-time).

The formulation is Pachl's (docs/sources.md#headway-and-capacity): a block section is blocked
for a train from the moment its indication must have cleared for the train not to be braked to
the moment the section is free for the next one. For block section k the blocking time is,
in the order the train meets them,

* **reaction and decoding** — the cab system's stated latency: an indication changed by the
  wayside reaches the ATP that much later;
* **approach** — from the approach point (where, were block k still occupied, the ATP's
  braking curve under the indication the follower would be shown would first lie below the
  unhindered speed; docs/capacity.md#approach) to the entry of block k;
* **running** — the head from the entry of block k to its exit signal;
* **clearing** — the head from the exit signal on over the train's length, until the tail has
  cleared the section;
* **release** — the track relay's release and the coder's change to the next code.

A train's blocking times over the line form its **stairway**; a train standing at its first
stop needs its first blocks' indications before it departs (its approach begins at departure).
Two trains' minimum headway is the least shift of the follower's stairway that makes no section
overlap the leader's; for identical trains it is the longest blocking time, and that section is
the critical one.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np

#: the parts of a blocking time, in the order the train meets them (the output's ``parts_s``)
PARTS = ("latency", "approach", "running", "clearing", "release")


@dataclass(frozen=True)
class Trajectory:
    """A train's run: head position (m) and speed (m/s) against time (s), samples in time order."""

    time_s: np.ndarray
    head_m: np.ndarray
    speed_mps: np.ndarray

    def __post_init__(self):
        t, x, v = (np.asarray(a, dtype=float) for a in (self.time_s, self.head_m, self.speed_mps))
        if not t.size or t.shape != x.shape or t.shape != v.shape:
            raise ValueError("a trajectory needs equal, non-empty arrays of time, position and speed")
        if np.any(np.diff(t) <= 0):
            raise ValueError("a trajectory's times must increase")
        object.__setattr__(self, "time_s", t)
        object.__setattr__(self, "head_m", x)
        object.__setattr__(self, "speed_mps", v)
        # the first time the head reaches each new furthest position: a train standing adds no
        # point, so a position passed after a stop gets a time after the departure
        furthest = np.maximum.accumulate(x)
        first = np.flatnonzero(np.concatenate(([True], furthest[1:] > furthest[:-1])))
        moved = np.flatnonzero(x > x[0])
        # the last instant at the starting position: the departure of a train standing there
        departure = t[moved[0] - 1] if moved.size else t[-1]
        reach_s = t[first].copy()
        reach_s[0] = departure
        object.__setattr__(self, "departure_s", float(departure))
        object.__setattr__(self, "_first", first)
        object.__setattr__(self, "_reach_m", furthest[first])
        object.__setattr__(self, "_reach_s", reach_s)

    @property
    def start_m(self) -> float:
        return float(self.head_m[0])

    @property
    def furthest_m(self) -> float:
        return float(self._reach_m[-1])

    def time_at(self, position_m) -> np.ndarray:
        """The time the head first reaches each position (m): the departure for the starting
        position and anything behind it, NaN beyond the furthest position reached."""
        x = np.asarray(position_m, dtype=float)
        times = np.interp(x, self._reach_m, self._reach_s)
        # the start: the train leaves it at its departure, not at t = 0
        times = np.where(x <= self._reach_m[0], self.departure_s, times)
        return np.where(x > self._reach_m[-1], np.nan, times)

    def speed_at(self, position_m) -> np.ndarray:
        """The speed when the head first reaches each position (m/s)."""
        return np.interp(np.asarray(position_m, dtype=float), self._reach_m, self.speed_mps[self._first])


@dataclass(frozen=True)
class BlockingTime:
    """One block section's blocking time for one train (times in s from the run's start)."""

    section: int                 # block index along the line, from 0
    name: str                    # the block's name (its entry signal)
    entry_m: float
    exit_m: float
    approach_m: float            # the approach point
    start_s: float
    end_s: float
    parts_s: Dict[str, float]

    @property
    def duration_s(self) -> float:
        return self.end_s - self.start_s

    def as_dict(self) -> dict:
        out = asdict(self)
        out["duration_s"] = self.duration_s
        return out


def stairway(trajectory: Trajectory, blocks: Sequence[Tuple[float, float]], names: Sequence[str],
             approach_m: Sequence[Optional[float]], train_length_m: float, latency_s: float,
             release_s: float, offset_s: float = 0.0) -> List[BlockingTime]:
    """The blocking times of every block (entry, exit in m) the train runs through and clears
    (module docstring). ``approach_m[k]``: block k's approach point (None: its entry);
    one behind the train's start is its start (it needs the indication before departing);
    ``offset_s`` shifts every time (the train's departure in a timetable)."""
    out: List[BlockingTime] = []
    start = trajectory.start_m
    for k, ((entry, exit_m), name) in enumerate(zip(blocks, names)):
        if exit_m <= start or exit_m + train_length_m > trajectory.furthest_m:
            continue                       # behind the train, or never cleared in this run
        approach = entry if approach_m[k] is None else min(float(approach_m[k]), entry)
        approach = max(approach, start)
        t_approach, t_entry, t_exit, t_clear = trajectory.time_at(
            [approach, max(entry, start), exit_m, exit_m + train_length_m])
        parts = {"latency": float(latency_s), "approach": float(t_entry - t_approach),
                 "running": float(t_exit - t_entry), "clearing": float(t_clear - t_exit),
                 "release": float(release_s)}
        out.append(BlockingTime(k, name, float(entry), float(exit_m), float(approach),
                                float(t_approach - latency_s + offset_s), float(t_clear + release_s + offset_s),
                                parts))
    return out


def minimum_headway_s(leader: Sequence[BlockingTime], follower: Sequence[BlockingTime]) -> Tuple[float, Optional[int]]:
    """The least interval by which the follower's stairway (as computed, unshifted) must be shifted
    so that on no section its blocking time begins before the leader's ends, and that section
    (None when the two share no section)."""
    ends = {b.section: b.end_s for b in leader}
    best, critical = -np.inf, None
    for b in follower:
        if b.section in ends and ends[b.section] - b.start_s > best:
            best, critical = ends[b.section] - b.start_s, b.section
    return (float(best), critical) if critical is not None else (float("nan"), None)


def critical_section(steps: Sequence[BlockingTime]) -> BlockingTime:
    """The section with the longest blocking time (identical trains' headway)."""
    if not steps:
        raise ValueError("the train clears no block section in its run")
    return max(steps, key=lambda b: b.duration_s)

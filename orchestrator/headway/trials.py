"""Judging a headway trial (docs/capacity.md#co-simulated-headway): the trains of a system of
queued trains (orchestrator/systems/queued.py) against their references.

Each train's **reference** is the same train alone on the same line, with the same timetable
— the trial's own, shifted as in the trial: one single-train system (the base system's chain)
whose train is placed and timed by ``--set``. A follower is *unhindered* when at every timing
point (each block signal and each stop of the base line, up to the end of judging) it is at
most ``LATE_TOLERANCE_S`` behind its reference, and nowhere on that stretch slower than its
reference at the same position by more than ``SPEED_TOLERANCE_KMH``.

Why the same shift: the ATO's discrete choices (where to coast) can turn on a micrometre, and a
timetable shifted by whole seconds rounds its floating-point sums differently, so a train alone
at another shift may run a few seconds apart from itself with no indication to blame (measured
on free_run: 6–8 s at C and 10 km/h at 12.4 km, docs/capacity.md#judging-a-trial). At the same
shift a follower whom no indication binds runs as its reference does.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Dict, Sequence

import numpy as np

from fmus.units import MPS_PER_KMH
from orchestrator.systems.queued import (  # noqa: F401 — the plan and the systems, for the search
    QUEUE_GAP_M, BaseSystem, TrainSlot, TrialPlan, read_base, write_system, write_timetable)
from orchestrator.headway.blocking import Trajectory

#: the hindrance criteria (the issue's acceptance: 2 s, 5 km/h)
LATE_TOLERANCE_S = 2.0
SPEED_TOLERANCE_KMH = 5.0


# ---- judging a trial ---------------------------------------------------------------------------
def read_trajectories(run_dir: Path, trains: Sequence[str], offset_m: float = 0.0) -> Dict[str, Trajectory]:
    """Each train's trajectory from a run's results.csv (columns TRAIN.x, TRAIN.v), its
    positions less ``offset_m`` (a trial's line against the base line's: ``TrialPlan.offset_m``)."""
    import csv

    path = Path(run_dir) / "results.csv"
    with path.open(newline="") as handle:
        reader = csv.reader(handle)
        header = next(reader)
        wanted = {name: (header.index(f"{name}.x"), header.index(f"{name}.v")) for name in trains}
        rows = np.array([[float(row[0])] + [float(row[i]) for name in trains for i in wanted[name]]
                         for row in reader])
    out = {}
    for n, name in enumerate(trains):
        out[name] = Trajectory(rows[:, 0], rows[:, 1 + 2 * n] - offset_m, rows[:, 2 + 2 * n])
    return out


@dataclass(frozen=True)
class Hindrance:
    """How much a follower lost against its reference over the judged stretch."""

    train: str
    late_s: float                 # the most it was behind its reference at a timing point
    late_at_m: float
    speed_deficit_kmh: float      # the most it was slower than its reference at one position
    deficit_at_m: float

    @property
    def hindered(self) -> bool:
        return self.late_s > LATE_TOLERANCE_S or self.speed_deficit_kmh > SPEED_TOLERANCE_KMH


def judge(train: str, run: Trajectory, reference: Trajectory, shift_s: float,
          points_m: np.ndarray, end_m: float) -> Hindrance:
    """The follower ``run`` against its ``reference`` run shifted by ``shift_s`` (module
    docstring); points behind the train's start are left out."""
    points = points_m[(points_m > run.start_m) & (points_m <= end_m)]
    late = run.time_at(points) - (reference.time_at(points) + shift_s)
    late = np.where(np.isnan(late), np.inf, late)        # never reached: as late as can be
    k = int(np.argmax(late)) if late.size else 0
    grid = np.arange(run.start_m, end_m, 10.0)
    deficit = (reference.speed_at(grid) - run.speed_at(grid)) / MPS_PER_KMH
    if grid.size:
        reached = grid <= run.furthest_m
        deficit = np.where(reached, deficit, np.inf)
    d = int(np.argmax(deficit)) if grid.size else 0
    return Hindrance(train, float(late[k]) if late.size else 0.0, float(points[k]) if late.size else run.start_m,
                     float(deficit[d]) if grid.size else 0.0, float(grid[d]) if grid.size else run.start_m)

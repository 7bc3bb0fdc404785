"""Offline running-time calculation per stage (station to station), OSRD-style pipeline:

1. **Static speed profile** (MRSP) on a distance grid: the line's limit for the train's
   category, applied from the head reaching a lower limit until the *tail* has cleared it
   (re-acceleration only after the last car, docs/sources.md#running-time-calculation-osrd-mareco), less the ATO speed margin, capped by
   the vehicle's maximum speed; and the cab signal's own limits on a free line where its mode
   has some (``head_limits``: TVM-300's steps before the terminus), in force while the head is
   in their block.
2. **Speed ceiling**: braking curves at the planned deceleration integrated backwards from
   every limit drop and from the stop point (closed form: a reverse cumulative minimum of
   v² + 2·a·s).
3. **Family of driving programmes** parametrised by a cruise speed V1, with the structure of
   the optimal control (Strobel/Horn, Howlett; docs/sources.md#ato-energy-efficient-control): maximum traction up to V1,
   cruise at V1 (partial traction; above V1 on down-grades the train coasts up to the
   ceiling instead of braking), MARECO coasting before each braking phase, braking at the
   planned deceleration. Coasting ends at the MARECO speed Vf = w·V1/(w + R(V1)·V1) with
   w = V1²·R'(V1) (docs/sources.md#running-time-calculation-osrd-mareco). V1 = ∞ is the **minimum-time** (flat-out) profile.
   All candidates are integrated together (numpy over candidates, RK2 in distance).
4. **Energy-efficient programme**: the V1 whose running time equals the scheduled time,
   found by interpolation on the family's time–V1 curve and refined twice by a bracket of
   candidates (no per-iteration scalar loop).

The coasting curves run backwards through down-grades too, so the programme coasts before a
crest and lets the down-grade bring the speed back (the ATO book's Fig. 15, docs/sources.md#ato-energy-efficient-control; MARECO's "accelerating
slopes"), never below Vf. Simplification (docs/ato.md): above V1 on a down-grade the
train coasts up to the ceiling instead of MARECO's explicit accelerating-slope search.

The family is the ATO's whole start-up cost (its integration is a Python loop over the grid).
When the environment names a folder in ``RAILCOSIM_PLAN_CACHE`` (a study's worker does,
docs/studies.md), each stage's family is kept there under a hash of everything it is computed
from (the grid, the speed profiles, the path retardation, the train's force tables, the
scheduled time, this module's code and numpy's version), so the runs of a study that share
a line, timetable, rolling stock and ATO settings plan once: a kept family is the computed
one's bytes. Within one process the families are also kept in memory (the last
``PLAN_MEMORY_ENTRIES``, read-only): the ATOs of identical trains on one line and timetable
(N trains of a headway study, each its own FMU instance in the one interpreter) plan it once.
"""
from __future__ import annotations

import hashlib
import os
import tempfile
from collections import OrderedDict
from dataclasses import dataclass
from pathlib import Path
from typing import Optional, Sequence, Tuple

import numpy as np

from fmus.ato_controller import train_model
from fmus.data.loader import Line
from fmus.ato_controller.train_model import NominalTrain

PLAN_STEP_M = 10.0            # distance grid of the programmes
REGIME_TRACTION, REGIME_COAST, REGIME_BRAKE = 1, 0, -1
_FAMILY_SIZE = 24
_REFINE_SIZE = 8
PLAN_CACHE_ENV = "RAILCOSIM_PLAN_CACHE"
#: families a cache folder keeps (about 1 MB each for a 10 km stage); the least recently used go
PLAN_CACHE_ENTRIES = 64
_FAMILY_FIELDS = ("cruise_mps", "coast_end_mps", "v", "t", "regime", "energy_j")
#: families this process keeps in memory (about 1 MB each for a 10 km stage), the least recently used go
PLAN_MEMORY_ENTRIES = 32


class InfeasibleStage(ValueError):
    def __init__(self, minimum_time_s: float):
        super().__init__(f"minimum running time {minimum_time_s:.1f} s")
        self.minimum_time_s = minimum_time_s


@dataclass
class Programmes:
    """Driving programmes of one stage over the grid ``s`` (head position, m)."""

    cruise_mps: np.ndarray        # (C,) V1 of each programme; inf = minimum time
    coast_end_mps: np.ndarray     # (C,) MARECO Vf
    v: np.ndarray                 # (C, n) speed
    t: np.ndarray                 # (C, n) time since departure
    regime: np.ndarray            # (C, n-1) int8 per grid step: 1 traction, 0 coast, -1 brake
    energy_j: np.ndarray          # (C,) net energy from the line (η and auxiliaries included)

    @property
    def time_s(self) -> np.ndarray:
        return self.t[:, -1]

    def take(self, index) -> "Programmes":
        index = np.atleast_1d(index)
        return Programmes(self.cruise_mps[index], self.coast_end_mps[index], self.v[index],
                          self.t[index], self.regime[index], self.energy_j[index])


@dataclass
class StagePlan:
    start_m: float
    end_m: float
    s: np.ndarray                 # (n,) grid
    static_mps: np.ndarray        # (n,) MRSP less the margin
    ceiling_mps: np.ndarray       # (n,) MRSP with braking curves
    family: Programmes            # sorted by running time, longest first; includes the fitted one
    chosen: int                   # index of the energy-efficient programme in the family
    minimum: int                  # index of the minimum-time programme
    scheduled_time_s: Optional[float]

    @property
    def minimum_time_s(self) -> float:
        return float(self.family.time_s[self.minimum])


class StagePlanner:
    def __init__(self, train: NominalTrain, line: Line, category: str, braking_decel_mps2: float,
                 speed_margin_mps: float, step_m: float = PLAN_STEP_M,
                 head_limits: Sequence[Tuple[float, float, float]] = ()):
        """``head_limits``: (start m, end m, speed m/s) in force while the head is in [start,
        end), no tail rule — a cab signal's steps on a free line (CabSignalMode.planned_limits):
        a block's code changes when the head enters the next block."""
        self.train, self.line, self.category = train, line, category
        self.head_limits = tuple(head_limits)
        self.braking_decel = braking_decel_mps2
        self.margin = speed_margin_mps
        self.step_m = step_m

    # ---- speed profiles -----------------------------------------------------------------------
    def static_profile(self, s: np.ndarray) -> np.ndarray:
        line, length = self.line, self.train.length_m
        starts = line.limit_starts + [np.inf]
        limits = line.limits_mps[self.category]
        static = np.full(s.shape, self.train.max_speed_mps)
        for k, limit in enumerate(limits):
            # a limit holds from its start (head) until the tail has left it
            inside = (s >= starts[k]) & (s < starts[k + 1] + length)
            static[inside] = np.minimum(static[inside], limit)
        for restriction in line.restrictions_for(self.category):
            # the line file's temporary restrictions are planned like limits (same tail rule)
            inside = (s >= restriction.start_m) & (s < restriction.end_m + length)
            static[inside] = np.minimum(static[inside], restriction.speed_mps)
        for start_m, end_m, speed_mps in self.head_limits:
            inside = (s >= start_m) & (s < end_m)
            static[inside] = np.minimum(static[inside], speed_mps)
        return np.maximum(static - self.margin, 0.5)

    def ceiling(self, s: np.ndarray, static: np.ndarray) -> np.ndarray:
        """min over targets j ≥ i of sqrt(v_j² + 2a(s_j − s_i)), with a stop at the last point."""
        a = self.braking_decel
        targets = static ** 2
        targets[-1] = 0.0
        key = targets + 2.0 * a * s
        reverse_min = np.minimum.accumulate(key[::-1])[::-1]
        return np.sqrt(np.maximum(reverse_min - 2.0 * a * s, 0.0))

    def coast_end_speed(self, cruise_mps: np.ndarray) -> np.ndarray:
        """MARECO Vf for each V1 (level-track equal marginal cost), clamped to [1 m/s, V1]."""
        tr = self.train
        out = np.full(cruise_mps.shape, np.inf)
        for k, v1 in enumerate(cruise_mps):
            if np.isfinite(v1):
                w = v1 * v1 * tr.resistance_slope(v1)
                r = float(tr.resistance(v1))
                out[k] = min(max(w * v1 / (w + r * v1), 1.0), v1)
        return out

    # ---- programmes ---------------------------------------------------------------------------
    def _coast_brake_envelope(self, ds: float, ceiling, path, coast_end) -> np.ndarray:
        """Speed (C, n) of each programme's coasting/braking envelope on the grid, integrated
        backwards from the stop: MARECO coasting down to Vf, then braking at the planned
        deceleration, never above the ceiling."""
        tr = self.train
        a_brake = self.braking_decel
        n, c = ceiling.size, coast_end.size
        envelope = np.empty((c, n))
        envelope[:, -1] = 0.0
        g = np.zeros(c)
        switch_energy = 0.5 * np.where(np.isfinite(coast_end), coast_end, 1e9) ** 2
        for i in range(n - 2, -1, -1):
            energy = 0.5 * g * g
            braked = energy + a_brake * ds
            # the step where braking (backwards) reaches Vf is split: brake up to Vf, coast the
            # rest; otherwise the coasting curve would jump by a grid cell and the running time
            # would be discontinuous in V1 (cf. OSRD issue #1401)
            braking_part = np.clip((switch_energy - energy) / (a_brake * ds), 0.0, 1.0)
            start = np.minimum(braked, np.maximum(energy, switch_energy))
            rest = (1.0 - braking_part) * ds
            half = np.sqrt(2.0 * (start + 0.5 * rest * (tr.coasting_resistance(np.sqrt(2.0 * start)) + path[i])).clip(0.0))
            # on a down-grade coasting speeds the train up, so going backwards the curve falls,
            # never below Vf (there the train would have to brake while coasting downhill)
            coasted = np.maximum(start + rest * (tr.coasting_resistance(half) + path[i]), switch_energy)
            g = np.sqrt(2.0 * np.where(braked > switch_energy, coasted, braked))
            g = np.minimum(g, ceiling[i])
            envelope[:, i] = g
        return envelope

    def path_on_grid(self, s: np.ndarray) -> np.ndarray:
        """Path retardation [m/s²] at the middle of each grid step."""
        return self.train.path_accel(s[:-1] + 0.5 * (s[1] - s[0]))

    def programmes(self, s, ceiling, cruise_mps: np.ndarray, path: Optional[np.ndarray] = None) -> Programmes:
        """One programme per cruise speed V1, integrated forwards from standstill over the
        grid ``s`` under its envelope (numpy over the candidates); ``path`` is
        :meth:`path_on_grid` of ``s`` (computed when not given)."""
        tr = self.train
        ds = s[1] - s[0]
        n, c = s.size, cruise_mps.size
        if path is None:
            path = self.path_on_grid(s)
        coast_end = self.coast_end_speed(cruise_mps)
        envelope = self._coast_brake_envelope(ds, ceiling, path, coast_end)

        v = np.empty((c, n))
        t = np.zeros((c, n))
        regime = np.zeros((c, n - 1), dtype=np.int8)
        traction_work = np.zeros(c)
        returned_work = np.zeros(c)
        v[:, 0] = 0.0
        speed = np.zeros(c)
        for i in range(n - 1):
            p = path[i]
            e = 0.5 * speed * speed
            a_t = tr.max_traction(speed) - tr.resistance(speed) - p
            a_c = -tr.coasting_resistance(speed) - p
            v_half_t = np.sqrt(2.0 * (e + 0.5 * ds * a_t).clip(0.0))
            v_half_c = np.sqrt(2.0 * (e + 0.5 * ds * a_c).clip(0.0))
            v_trac = np.sqrt(2.0 * (e + ds * (tr.max_traction(v_half_t) - tr.resistance(v_half_t) - p)).clip(0.0))
            v_coast = np.sqrt(2.0 * (e + ds * (-tr.coasting_resistance(v_half_c) - p)).clip(0.0))
            below = speed < cruise_mps - 1e-9
            nxt = np.where(below | (v_coast < cruise_mps), np.minimum(v_trac, cruise_mps), v_coast)
            nxt = np.minimum(nxt, envelope[:, i + 1])
            mean = 0.5 * (speed + nxt)
            required = (nxt * nxt - speed * speed) / (2.0 * ds) + tr.resistance(mean) + p
            regime[:, i] = np.where(required > 1e-4, REGIME_TRACTION, np.where(required < -1e-4, REGIME_BRAKE, REGIME_COAST))
            traction_work += np.minimum(required.clip(0.0), tr.max_traction(mean))
            returned_work += np.minimum((-required).clip(0.0), tr.electric_brake(mean))
            with np.errstate(divide="ignore"):
                t[:, i + 1] = t[:, i] + np.where(mean > 0, ds / np.where(mean > 0, mean, 1.0), np.inf)
            speed = nxt
            v[:, i + 1] = nxt
        stock = tr.stock
        energy = traction_work * ds * tr.m_eff / stock.efficiency + stock.auxiliary_w * t[:, -1]
        if stock.ebrake_kind == "regenerative":
            energy -= returned_work * ds * tr.m_eff * stock.ebrake_efficiency
        return Programmes(cruise_mps, coast_end, v, t, regime, energy)

    def plan(self, start_m: float, end_m: float, scheduled_time_s: Optional[float]) -> StagePlan:
        n = max(int(np.ceil((end_m - start_m) / self.step_m)), 2) + 1
        s = np.linspace(start_m, end_m, n)
        static = self.static_profile(s)
        ceiling = self.ceiling(s, static)
        path = self.path_on_grid(s)
        cache = _PlanCache.from_environment()
        key = self._key(s, static, ceiling, path, scheduled_time_s, on_disk=cache is not None)
        kept = cache.load(key) if cache is not None else None
        if kept is None:
            kept = _IN_MEMORY.load(key) or self._family(s, static, ceiling, path, scheduled_time_s)
            if cache is not None:
                cache.store(key, *kept)
        _IN_MEMORY.store(key, *kept)
        family, chosen, minimum = kept
        return StagePlan(start_m, end_m, s, static, ceiling, family, chosen, minimum, scheduled_time_s)

    def _family(self, s, static, ceiling, path, scheduled_time_s: Optional[float]):
        """(family sorted longest first, chosen index, minimum-time index); InfeasibleStage when
        the schedule is shorter than the minimum running time."""
        top = float(static.max())
        cruise = np.concatenate([np.linspace(min(8.0, 0.5 * top), top, _FAMILY_SIZE - 1), [np.inf]])
        family = self.programmes(s, ceiling, cruise, path)
        if not np.isfinite(family.time_s[-1]):
            raise InfeasibleStage(np.inf)    # the train cannot even start on this stage
        minimum_time = float(family.time_s[-1])
        if scheduled_time_s is not None and scheduled_time_s < minimum_time:
            raise InfeasibleStage(minimum_time)
        if scheduled_time_s is not None:
            fitted = self._fit(s, ceiling, family, scheduled_time_s, path, top)
            family = _merge(family, fitted)
        order = np.argsort(-family.time_s, kind="stable")
        family = family.take(order)
        times = family.time_s
        minimum = int(np.argmin(times))
        if scheduled_time_s is None:
            chosen = minimum
        else:
            chosen = int(np.argmin(np.abs(times - scheduled_time_s) + 1e-9 * np.isinf(family.cruise_mps)))
        return family, chosen, minimum

    def _key(self, s, static, ceiling, path, scheduled_time_s: Optional[float], on_disk: bool = True) -> str:
        """A hash of everything :meth:`_family` reads: the arrays, the train's force tables and
        constants, the braking deceleration, the schedule and, for a key kept on disk, this code
        and numpy's version (in memory the process's own code is the code: its source is not
        read, since the folder a host extracted it to may be gone by then)."""
        tr, stock = self.train, self.train.stock
        digest = hashlib.sha256(_code_fingerprint() if on_disk else b"in memory")
        for array in (s, static, ceiling, path, tr.speeds, tr.traction_accel, tr.resistance_accel,
                      tr.coasting_resistance_accel, tr.electric_brake_accel):
            array = np.ascontiguousarray(array)
            digest.update(f"{array.dtype.str}{array.shape}".encode())
            digest.update(array.tobytes())
        scalars = (tr.m_eff, stock.efficiency, stock.auxiliary_w, stock.ebrake_efficiency,
                   self.braking_decel, -1.0 if scheduled_time_s is None else scheduled_time_s)
        digest.update(" ".join(float(x).hex() for x in scalars).encode())
        digest.update(f" {stock.ebrake_kind} {scheduled_time_s is None}".encode())
        return digest.hexdigest()

    def _fit(self, s, ceiling, family: Programmes, target_s: float, path: np.ndarray, top: float) -> Programmes:
        """Cruise speed whose programme runs in the scheduled time (time falls as V1 rises)."""
        cruise, times = family.cruise_mps[:-1], family.time_s[:-1]
        best = None
        for _ in range(2):
            slower = np.nonzero(times >= target_s)[0]
            faster = np.nonzero(times < target_s)[0]
            if not slower.size:          # even the slowest candidate is early: keep it
                return family.take([0])
            lo = cruise[slower.max()]
            hi = cruise[faster.min()] if faster.size else top
            trial = np.linspace(lo, hi, _REFINE_SIZE + 2)[1:-1]
            best = self.programmes(s, ceiling, trial, path)
            cruise = np.concatenate([[lo], trial, [hi]])
            times = np.concatenate([[times[slower.max()]], best.time_s,
                                    [times[faster.min()] if faster.size else -np.inf]])
        k = int(np.argmin(np.abs(best.time_s - target_s)))
        return best.take([k])


def _merge(a: Programmes, b: Programmes) -> Programmes:
    return Programmes(*(np.concatenate([getattr(a, f), getattr(b, f)]) for f in _FAMILY_FIELDS))


_CODE_FINGERPRINT: Optional[bytes] = None


def _code_fingerprint() -> bytes:
    """The planner's and the nominal train's source and numpy's version: a change to any of
    them makes every kept family a stranger."""
    global _CODE_FINGERPRINT
    if _CODE_FINGERPRINT is None:
        digest = hashlib.sha256(np.__version__.encode())
        for source in (__file__, train_model.__file__):
            digest.update(Path(source).read_bytes())
        _CODE_FINGERPRINT = digest.digest()
    return _CODE_FINGERPRINT


class _MemoryCache:
    """The last PLAN_MEMORY_ENTRIES families of this process by key, their arrays read-only
    (every ATO given one shares the arrays)."""

    def __init__(self, entries: int):
        self.entries = entries
        self._kept: "OrderedDict[str, tuple]" = OrderedDict()

    def load(self, key: str):
        kept = self._kept.get(key)
        if kept is not None:
            self._kept.move_to_end(key)
        return kept

    def store(self, key: str, family: "Programmes", chosen: int, minimum: int) -> None:
        for name in _FAMILY_FIELDS:
            getattr(family, name).setflags(write=False)
        self._kept[key] = (family, chosen, minimum)
        self._kept.move_to_end(key)
        while len(self._kept) > self.entries:
            self._kept.popitem(last=False)


_IN_MEMORY = _MemoryCache(PLAN_MEMORY_ENTRIES)


class _PlanCache:
    """Stage families in a folder, one ``<key>.npz`` each, written whole (a temporary file
    renamed into place, so concurrent runs never read half a file). A cache that cannot be
    read or written is only a cache: the family is computed as without one."""

    def __init__(self, folder: Path):
        self.folder = folder

    @classmethod
    def from_environment(cls) -> Optional["_PlanCache"]:
        folder = os.environ.get(PLAN_CACHE_ENV)
        return cls(Path(folder)) if folder else None

    def load(self, key: str):
        path = self.folder / f"{key}.npz"
        try:
            with np.load(path, allow_pickle=False) as data:
                family = Programmes(*(data[name] for name in _FAMILY_FIELDS))
                chosen, minimum = int(data["chosen"]), int(data["minimum"])
            os.utime(path)                                  # recently used
        except Exception:        # noqa: BLE001 — missing, cut short or damaged: planned afresh
            return None
        return family, chosen, minimum

    def store(self, key: str, family: Programmes, chosen: int, minimum: int) -> None:
        temporary = None
        try:
            self.folder.mkdir(parents=True, exist_ok=True)
            handle, temporary = tempfile.mkstemp(dir=self.folder, suffix=".part")
            with os.fdopen(handle, "wb") as f:
                np.savez(f, chosen=chosen, minimum=minimum,
                         **{name: getattr(family, name) for name in _FAMILY_FIELDS})
            os.replace(temporary, self.folder / f"{key}.npz")
            temporary = None
            kept = sorted(self.folder.glob("*.npz"), key=lambda p: p.stat().st_mtime_ns)
            for stale in kept[:-PLAN_CACHE_ENTRIES]:
                stale.unlink(missing_ok=True)
        except OSError:
            pass
        finally:
            if temporary is not None:
                Path(temporary).unlink(missing_ok=True)

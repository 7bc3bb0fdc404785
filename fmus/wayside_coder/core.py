"""Wayside ALSN coder: automatic-block aspect logic and KPT-5/KPT-7 code transmitters keying the
carrier into each block section (no FMI here).

Per block section k (line data: transmitter type and carrier per section):

* **Block logic** — the code fed into section k (from its exit end) follows the aspect of the
  signal at its exit, which depends on the occupancy of the sections ahead. 3-aspect block:
  next section occupied → red → КЖ; the one after occupied → yellow → Ж; else green → З.
  4-aspect block adds yellow-green (three sections ahead occupied), sent as З [U]. Beyond the
  last modelled section the line is taken as free. Coding is either always on or switched on
  when the section is occupied, after a switch-on delay.
* **Transmitter** — the cam turns continuously with the transmitter's cycle (KPT-5 1.6 s,
  KPT-7 1.86 s, scaled by ``timing_scale`` to model drift); a code change selects another cam
  contact at the current cam phase (no resynchronisation). Each section starts at a random cam
  phase (seeded): transmitters are not synchronised.
* **Output** — u_tx[k, n] = amplitude · key[k, n] · sin(2π·f_k·t_n), t_n = t + n/fs; the key
  is ideal or, with ``relay_time_constant`` > 0, smoothed by a first-order transmitter-relay
  transient (scipy.signal.lfilter with carried state).

Faults: main transmitter failed → reserve takes over (status 1, same codes); main and reserve
failed → no code anywhere (status 2).

Everything is a pure function of the sample index and the carried filter state, so frames of
any length N give the same samples (DESIGN §3).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Optional

import numpy as np
from scipy.signal import lfilter

from ..common import alsn
from ..common import signalling as sig
from ..common.data import Line
from ..common.slave import FmuInputError

SIGNAL_DARK, SIGNAL_RED, SIGNAL_YELLOW, SIGNAL_YELLOW_GREEN, SIGNAL_GREEN = 0, 1, 2, 3, 4
STATUS_OK, STATUS_PARTIAL, STATUS_FAILED = 0, 1, 2
_CODE_OF_SIGNAL = np.array([alsn.NO_CODE, sig.RED_YELLOW, sig.YELLOW, sig.GREEN, sig.GREEN])


@dataclass
class CoderSettings:
    fs_hz: float = 4000.0
    carrier_hz: float = 0.0             # 0: each section's carrier from the line file
    amplitude_v: float = 4.0            # peak transmitter voltage while a pulse is on
    block_aspects: int = 3
    coding: str = "always"              # always | on_occupation
    switch_on_delay_s: float = 0.0
    timing_scale: float = 1.0           # all code timings × this (transmitter drift)
    relay_time_constant_s: float = 0.0  # 0: ideal keying
    seed: int = 1


@dataclass
class CoderOutputs:
    u_tx: np.ndarray          # (K, N) V
    code_tx: np.ndarray       # (K,) aspect code sent, 0 none
    signal: np.ndarray        # (K,) wayside signal at each section's exit
    status: int = STATUS_OK


class WaysideCoderCore:
    def __init__(self, line: Line, sections: int, frame: int, settings: CoderSettings,
                 transmitters: Optional[dict] = None):
        s = settings
        if len(line.sections) > sections:
            raise FmuInputError(f"{line.path}: field block_sections: {len(line.sections)} sections, but this "
                                f"build models {sections}; rebuild with `railcosim build --sections "
                                f"{len(line.sections)}`")
        if s.block_aspects not in (3, 4):
            raise FmuInputError(f"parameter block_aspects: {s.block_aspects} (3 or 4)")
        if s.coding not in ("always", "on_occupation"):
            raise FmuInputError(f"parameter coding: {s.coding!r} is not always or on_occupation")
        for name, value in (("fs", s.fs_hz), ("amplitude", s.amplitude_v), ("timing_scale", s.timing_scale)):
            if not value > 0:
                raise FmuInputError(f"parameter {name}: must be positive, got {value}")
        for name, value in (("switch_on_delay", s.switch_on_delay_s), ("relay_time_constant", s.relay_time_constant_s)):
            if value < 0:
                raise FmuInputError(f"parameter {name}: must not be negative, got {value}")
        transmitters = transmitters or alsn.load_transmitters()
        self.settings = s
        self.count = len(line.sections)           # modelled sections; ports beyond stay silent
        self.sections, self.frame = sections, frame
        k = self.count
        carriers = np.array([sec.carrier_hz for sec in line.sections], dtype=float)
        if s.carrier_hz > 0:
            carriers[:] = s.carrier_hz
        for index, carrier in enumerate(carriers):
            where = "parameter " if s.carrier_hz > 0 else f"{line.path}: field block_sections[{index}]."
            alsn.check_carrier_and_rate(float(carrier), s.fs_hz, where)
        types = []
        for index, sec in enumerate(line.sections):
            if sec.transmitter not in transmitters:
                raise FmuInputError(f"{line.path}: field block_sections[{index}].transmitter: "
                                    f"{sec.transmitter!r} is not one of {', '.join(transmitters)}")
            types.append(transmitters[sec.transmitter])
        self.cycle_s = np.array([tx.cycle_s for tx in types]) * s.timing_scale
        # pulse table (K, code, P, 2) padded with empty pulses; code axis indexed by aspect code 0..4
        width = max(p.shape[0] for tx in types for p in tx.pulses.values())
        self.pulses = np.zeros((k, 5, width, 2))
        for index, tx in enumerate(types):
            for code, pulses in tx.pulses.items():
                self.pulses[index, code, :pulses.shape[0]] = pulses * s.timing_scale
        rng = np.random.default_rng(s.seed)
        self.cam_offset_s = rng.uniform(0.0, 1.0, k) * self.cycle_s
        self.omega = 2.0 * np.pi * carriers
        self.codes = np.zeros(k, dtype=np.int64)
        self.signals = np.zeros(k, dtype=np.int64)
        self.occupied_since = np.full(k, np.inf)
        if s.relay_time_constant_s > 0:
            a = np.exp(-1.0 / (s.fs_hz * s.relay_time_constant_s))
            self._relay = (np.array([1.0 - a]), np.array([1.0, -a]))
        else:
            self._relay = None
        self._relay_state = np.zeros((k, 1))
        self._index = np.arange(frame)
        self.out = CoderOutputs(np.zeros((sections, frame)), np.zeros(sections, dtype=np.int64),
                                np.zeros(sections, dtype=np.int64))

    # ---- block logic --------------------------------------------------------------------------
    def block_signals(self, occupied: np.ndarray) -> np.ndarray:
        """Aspect of the signal at each section's exit from the occupancy ahead (line beyond: free)."""
        k = self.count
        occ = np.concatenate([np.asarray(occupied[:k], dtype=bool), [False]])
        # distance (in sections) from each section to the first occupied section ahead of it
        index = np.where(occ, np.arange(k + 1), k + 10)
        next_occupied = np.minimum.accumulate(index[::-1])[::-1]
        ahead = next_occupied[1:] - np.arange(k)
        signals = np.full(k, SIGNAL_GREEN)
        signals[ahead == 1] = SIGNAL_RED
        signals[ahead == 2] = SIGNAL_YELLOW
        if self.settings.block_aspects == 4:
            signals[ahead == 3] = SIGNAL_YELLOW_GREEN
        return signals

    def step(self, t: float, occupied: np.ndarray, fault_main: bool = False, fault_reserve: bool = False) -> CoderOutputs:
        s = self.settings
        k, out = self.count, self.out
        signals = self.block_signals(occupied)
        codes = _CODE_OF_SIGNAL[signals]
        occ = np.asarray(occupied[:k], dtype=bool)
        self.occupied_since = np.where(occ, np.minimum(self.occupied_since, t), np.inf)
        if s.coding == "on_occupation":
            codes = np.where(t - self.occupied_since >= s.switch_on_delay_s - 1e-12, codes, alsn.NO_CODE)
        out.status = STATUS_FAILED if (fault_main and fault_reserve) else (STATUS_PARTIAL if fault_main or fault_reserve else STATUS_OK)
        if out.status == STATUS_FAILED:
            codes = np.zeros(k, dtype=np.int64)
        self.codes, self.signals = codes, signals
        # sample times from the integer sample index: no drift over long runs
        first = round(t * s.fs_hz)
        times = (first + self._index) / s.fs_hz
        phase = np.mod(times[None, :] + self.cam_offset_s[:, None], self.cycle_s[:, None])
        pulses = self.pulses[np.arange(k), codes]                       # (K, P, 2)
        key = ((phase[:, :, None] >= pulses[:, None, :, 0]) & (phase[:, :, None] < pulses[:, None, :, 1])).any(-1)
        envelope = key.astype(float)
        if self._relay is not None:
            envelope, self._relay_state = lfilter(*self._relay, envelope, axis=1, zi=self._relay_state)
        out.u_tx[:k] = s.amplitude_v * envelope * np.sin(self.omega[:, None] * times[None, :])
        out.code_tx[:k] = codes
        out.signal[:k] = signals
        return out

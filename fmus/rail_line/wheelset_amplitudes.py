"""The trains' code-current amplitudes in the track-circuit bank (circuit_bank.py's module
docstring): each section's wheelset chain (axle_chain.py) solved at a configuration tick with
every wheelset at its axle, and what it gives between solutions — the factor a train's current
from the network model is scaled by (:meth:`WheelsetAmplitudes.scale`, per frame), the entry-end
current's factor and the relay-end level. The bank decides which sections are solved when."""
from __future__ import annotations

import bisect
import math
from typing import Dict, List, Optional

import numpy as np

from fmus.library_shortcuts import interp
from fmus.rail_line.axle_chain import SectionChain


def _interp_one(x: float, xp: List[float], fp: List[float]) -> float:
    """np.interp at one point in floats (xp ascending; clipped at the ends as np.interp is)."""
    i = bisect.bisect_right(xp, x) - 1
    if i < 0:
        return fp[0]
    if i >= len(xp) - 1:
        return fp[-1]
    slope = (fp[i + 1] - fp[i]) / (xp[i + 1] - xp[i])
    return slope * (x - xp[i]) + fp[i]


class WheelsetAmplitudes:
    """Per section: its wheelset chain per frequency under its faults, each train's amplitude
    factor and the entry-end current's factor at the last solution; ``tick_s`` the configuration
    tick over which a new solution's factors take over from the last one's."""

    def __init__(self, geometry, calibration, settings, tick_s: float):
        s = settings
        self.geometry, self.calibration, self.settings = geometry, calibration, s
        count = geometry.count
        # per train its wheelsets, ascending from its last one (0) to its first (the head, ``span``)
        self._wheelsets = [np.asarray(offsets[-1] - offsets[::-1], dtype=float) for offsets in s.wheelset_offsets_m]
        self._offset_lists = [np.asarray(offsets, dtype=float).tolist() for offsets in s.wheelset_offsets_m]
        self.spans = [float(positions[-1]) for positions in self._wheelsets]
        self._carriers = [float(f) for f in geometry.carriers]
        self._track_frequencies = [float(f) for f in geometry.track_frequencies]
        self._nodes_lists = [nodes.tolist() for nodes in geometry.nodes_m]
        # per section: each head's amplitude (scale: e before and now, the tick, |r|, the head at
        # the tick, the standing value), the entry-end current's factor, the one-shunt table
        self.entry_factor = [1.0] * count
        self._log_amplitude: List[Optional[np.ndarray]] = [None] * count
        self._log_amplitude_lists: List[Optional[List[float]]] = [None] * count
        self._per_tick = 1.0 / tick_s            # the factors pass from one tick's solution to the next over a tick
        self.reset([])

    def reset(self, faults) -> None:
        """Every section's chains and factors dropped (``faults``: each section's faults now); taken
        at once: the network's own transient shows a fault change, not a passing factor."""
        count = self.geometry.count
        self._faults = faults
        self._chains: List[Dict[float, SectionChain]] = [{} for _ in range(count)]
        self._factors: List[Dict[int, tuple]] = [{} for _ in range(count)]
        self.passing: Dict[int, float] = {}      # sections whose factors pass to a new solution: its tick

    def one_shunt(self, k: int, log_amplitude: np.ndarray) -> None:
        """Section k's one-shunt amplitude table along its nodes (log), under its faults now."""
        self._log_amplitude[k] = log_amplitude
        self._log_amplitude_lists[k] = log_amplitude.tolist()

    def scale(self, k: int, head: np.ndarray, j: int, times: np.ndarray, standing_at: Optional[float] = None):
        """What the network model's current arriving at train j's head node in section k is
        multiplied by, at the sample ``times`` with the head at ``head``: the chain's amplitude
        over the model's, e·A₁(x)/|r|. A₁ is the one-shunt amplitude table along the track (its
        shape between ticks: the current varies continuously as the train moves), r the model's
        response at the head, e the chain's amplitude over A₁ at the tick positions, passing
        linearly over one tick from the last tick's to this one's (so it never steps: one tick,
        < 0.5 m, late). A train standing where the factor was last solved gets it as a float."""
        entry = self._factors[k].get(j)
        if entry is None:
            return 1.0
        before, now, tick, response, standing_head, standing_value = entry
        if standing_at is not None and standing_at == standing_head and before == now:
            return standing_value
        weight = np.minimum(np.maximum((times - tick) * self._per_tick, 0.0), 1.0)
        return (before + (now - before) * weight) * np.exp(interp(head, self.geometry.nodes_m[k],
                                                                    self._log_amplitude[k])) / response

    def settle(self, tick_s: float, solving) -> None:
        """A tick after its solution a section's factors have passed to it (the weight is 1
        from then on): they are taken as they are, so a standing train's is a float again (the
        sections ``solving`` now are left to their new solution)."""
        for k, solved in list(self.passing.items()):
            if tick_s > solved and k not in solving:
                del self.passing[k]
                factors = self._factors[k]
                for j, (_, now, tick, response, head, standing) in list(factors.items()):
                    factors[j] = (now, now, tick, response, head, standing)

    def chain(self, k: int, frequency_hz: float) -> SectionChain:
        """Section k's wheelset chain at a frequency under its faults, per unit code input."""
        chain = self._chains[k].get(frequency_hz)
        if chain is None:
            chain = self._chains[k][frequency_hz] = SectionChain(self.geometry.circuits[k], self._faults[k],
                                                                 frequency_hz, self.settings.transformer_ratio)
        return chain

    def wheelset_runs(self, k: int, chain: SectionChain, heads: List[float]) -> List[tuple]:
        """Section k's wheelsets as runs for the chain: per train the axles between the joints,
        split at the feed leads (beyond them they stand on the overhang up to the exit joint). The
        axles are found by their distance behind the head (a head exactly on a joint is on it)."""
        geometry = self.geometry
        start, feed, end = geometry.starts_list[k], geometry.feed_list[k], geometry.ends_list[k]
        runs = []
        for j, head in enumerate(heads):
            offsets = self._offset_lists[j]             # behind the head, ascending from 0
            if head < start or head - offsets[-1] > end:
                continue
            last = len(offsets) - 1
            # offsets within [head − end, head − start]: the overhang's (before head − feed), the rails'
            first = bisect.bisect_left(offsets, head - end)
            to_feed = bisect.bisect_left(offsets, head - feed)
            behind = bisect.bisect_right(offsets, head - start) - 1
            table = chain.table(j, self._wheelsets[j])
            for near, far in ((to_feed, behind), (first, to_feed - 1)):      # rails, then the overhang
                if near <= far:          # offsets near…far → table indices (ascending positions)
                    runs.append((head - offsets[far], head - offsets[near], table, last - far, last - near))
        runs.sort(key=lambda run: run[0])
        return runs

    def solve(self, k: int, heads: List[float], tick_s: float, rows: Dict[int, int], model) -> float:
        """Section k's wheelset chain at the tick (``rows``: the row of each train whose head is
        in it, ``model`` its network model): each head's amplitude factor and the entry-end
        current's factor (at the carrier); returned, the relay level (at the track circuit's
        frequency, per unit feed, against the relay's reference)."""
        carrier, track = self._carriers[k], self._track_frequencies[k]
        chain = self.chain(k, carrier)
        runs = self.wheelset_runs(k, chain, heads)
        trains = sorted(rows)
        currents, entry, relay = chain.solve(runs, [heads[j] for j in trains])
        nodes, log_amplitude = self._nodes_lists[k], self._log_amplitude_lists[k]
        factors, previous = {}, self._factors[k]
        for j, current in zip(trains, currents):
            response = abs(model.head_responses[rows[j]])
            one_shunt = math.exp(_interp_one(heads[j], nodes, log_amplitude))
            now = current / one_shunt if response > 0.0 else 0.0
            before = previous[j][1] if j in previous else now
            response = response if response > 0.0 else 1.0
            factors[j] = (before, now, tick_s, response, heads[j], now * one_shunt / response)
        self._factors[k] = factors
        self.passing[k] = tick_s
        response = abs(model.entry_response)
        self.entry_factor[k] = entry / response if response > 0.0 else 1.0
        if track != carrier:               # the relay reads the track circuit's own frequency
            relay_chain = self.chain(k, track)
            relay = relay_chain.solve(self.wheelset_runs(k, relay_chain, heads))[2]
        # per unit feed (the chain's is per unit code input, × the transformer ratio)
        return relay / self.settings.transformer_ratio / self.calibration.reference[k]

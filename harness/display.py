"""What every receiver of a running system displays, against what is sent under its coils: an
observer sampling each judged receiver at its own step (orchestrator.verdicts.verdict's
receivers, the same pairing of receiver, rail line slot and coder), and the measures of
docs/loco_receiver.md taken from those samples: display dropouts at joints, how long each
restrictive change of the code sent took to show, and how long the display stayed more
permissive than the code. Used by benchmarks/study_receiver_display.py and the acceptance
tests (tests/test_loco_receiver_display.py)."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Dict, List

import numpy as np

from fmus.signalling import aspects as sig
from orchestrator.verdicts.verdict import _OutputJudge, receivers_of, transmitted_indication, railway_verdicts

SENT_NONE = -1          # the coil outside every section


@dataclass
class Samples:
    receiver: str
    train: str
    system: str
    t: List[float] = field(default_factory=list)
    aspect: List[int] = field(default_factory=list)       # shown by the receiver
    valid: List[bool] = field(default_factory=list)
    sent: List[int] = field(default_factory=list)         # aspect meant by the code under the coil (0 none)
    section: List[int] = field(default_factory=list)      # track circuit under the coil (1-based, 0 none)
    x: List[float] = field(default_factory=list)          # the train's head

    def arrays(self):
        return (np.array(self.t), np.array(self.aspect, dtype=int), np.array(self.valid, dtype=bool),
                np.array(self.sent, dtype=int), np.array(self.section, dtype=int), np.array(self.x))


class DisplayProbe(_OutputJudge):
    """Observer: samples aspect, code_valid, the code sent under the coil and the head position
    of every judged receiver after each of its steps (summary section: none)."""

    def __init__(self, graph):
        self.graph = graph
        self.receivers = receivers_of(graph)
        self.samples: Dict[str, Samples] = {
            r.name: Samples(r.name, r.train, r.cab.name) for r in self.receivers}

    def outputs_needed(self):
        needed: Dict[str, List[str]] = {}
        for r in self.receivers:
            needed.setdefault(r.name, []).extend(["aspect", "code_valid"])
            needed.setdefault(r.rail, []).append(f"coil_section[{r.slot}]")
            needed.setdefault(r.train, []).append("x")
            needed.setdefault(r.coder, []).extend(
                v for v in self.graph.nodes[r.coder].interface.variables if v.startswith("code_tx["))
        return needed

    def started(self, master, step) -> None:
        self._bind_slots(master)
        self._sample(master, step, everyone=True)

    def after_tick(self, master, step) -> None:
        self._sample(master, step, everyone=False)

    def _sample(self, master, step, everyone: bool) -> None:
        for r in self.receivers:
            if not everyone and r.name not in step.stepped:
                continue
            for component in (r.name, r.rail, r.coder, r.train):
                master.fresh(component)
            section = int(self._value(r.rail, f"coil_section[{r.slot}]"))
            if section <= 0:
                meant = SENT_NONE
            else:
                code = int(self._value(r.coder, f"code_tx[{section}]"))
                if r.system is None:
                    meant = code
                else:
                    indication = transmitted_indication(r.system, code, r.category)
                    meant = sig.WHITE if indication is None else indication.aspect
            s = self.samples[r.name]
            s.t.append(step.time_s)
            s.aspect.append(int(self._value(r.name, "aspect")))
            s.valid.append(bool(self._value(r.name, "code_valid")))
            s.sent.append(meant)
            s.section.append(section)
            s.x.append(float(self._value(r.train, "x")))

    def summary_section(self):
        return {}


def with_probe(probes: list):
    """RunOptions.summaries for a railway run that also keeps a DisplayProbe in ``probes``."""
    def make(graph):
        probe = DisplayProbe(graph)
        probes.append(probe)
        return railway_verdicts(graph) + [probe]
    return make


def _runs(mask: np.ndarray):
    """(start index, end index exclusive) of each run of True."""
    edges = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    return list(zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)))


#: sig.restrictiveness of aspects 0..4, as a lookup table over whole arrays
_RANK_OF_ASPECT = np.array([sig.restrictiveness(a) for a in range(sig.GREEN + 1)])


def rank(aspects: np.ndarray) -> np.ndarray:
    """sig.restrictiveness of every aspect in ``aspects`` (higher is more permissive)."""
    return _RANK_OF_ASPECT[np.asarray(aspects, dtype=int)]


@dataclass
class DisplayReport:
    receiver: str
    dropouts: List[dict]          # no-code display (white/red) while a code was sent, after the first code shown
    restrictive: List[dict]       # changes of the code sent to one more restrictive than shown: time to show
    permissive: List[dict]        # episodes shown more permissive than sent: length

    @property
    def worst_restrictive_s(self) -> float:
        return max((e["latency_s"] for e in self.restrictive), default=0.0)

    @property
    def worst_permissive_s(self) -> float:
        return max((e["length_s"] for e in self.permissive), default=0.0)


def analyse(samples: Samples, settle_s: float = 0.0) -> DisplayReport:
    """The measures of one receiver's samples; ``settle_s``: ignore the start (acquisition)."""
    t, aspect, valid, sent, section, x = samples.arrays()
    shown_rank, sent_rank = rank(aspect), rank(np.where(sent == SENT_NONE, sig.WHITE, sent))
    judged = (sent != SENT_NONE) & (t >= settle_s)
    coded = judged & (sent != sig.WHITE)
    acquired = np.cumsum(np.isin(aspect, (sig.GREEN, sig.YELLOW, sig.RED_YELLOW))) > 0
    no_code = np.isin(aspect, (sig.WHITE, sig.RED)) & coded & acquired
    dropouts = [{"t": float(t[a]), "x": float(x[a]), "length_s": float(t[b - 1] - t[a]) if b - 1 > a else 0.0,
                 "shown": int(aspect[a]), "sent": int(sent[a])} for a, b in _runs(no_code)]
    too_permissive = judged & (shown_rank > sent_rank)
    permissive = [{"t": float(t[a]), "x": float(x[a]), "length_s": float(t[min(b, t.size - 1)] - t[a]),
                   "shown": int(aspect[a]), "sent": int(sent[a])} for a, b in _runs(too_permissive)]
    # each change of the code sent to one below what is shown: until the display is at or below it
    restrictive = []
    change = np.flatnonzero((np.diff(sent_rank) != 0) | (np.diff(section) != 0)) + 1
    for i in change:
        if not judged[i] or sent_rank[i] >= shown_rank[i]:
            continue
        later = np.flatnonzero(shown_rank[i:] <= sent_rank[i])
        done = later[0] + i if later.size else None
        restrictive.append({"t": float(t[i]), "x": float(x[i]), "from": int(aspect[i]), "to": int(sent[i]),
                            "latency_s": float(t[done] - t[i]) if done is not None else float("inf")})
    return DisplayReport(samples.receiver, dropouts, restrictive, permissive)

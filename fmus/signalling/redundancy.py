"""Redundancy of the digital cab-signal systems (docs/sources.md#digital-generator-receiver-and-redundancy): the wayside's
duplicated generator compared 2-out-of-2, the receiver's three channels voted 2-out-of-3.
Commands are compared by a restrictiveness rank supplied by the system (lower = more
restrictive); ``None`` means no output (loss of code), the most restrictive state of all.
"""
from __future__ import annotations

from collections import Counter
from typing import Callable, Optional, Sequence, Tuple

STATUS_OK, STATUS_PARTIAL, STATUS_FAILED = 0, 1, 2
Rank = Callable[[int], float]


def wayside_2oo2(main: Optional[int], reserve: Optional[int], main_ok: bool, reserve_ok: bool,
                 rank: Rank) -> Tuple[Optional[int], int]:
    """(command to send, status). Both healthy and equal: that command; both healthy and
    different: the more restrictive; one failed: the other, status partial; both failed: no
    output, status failed."""
    if main_ok and reserve_ok:
        if main == reserve:
            return main, STATUS_OK
        candidates = [c for c in (main, reserve) if c is not None]
        if len(candidates) < 2:
            return None, STATUS_OK               # one generator silent: nothing it could vouch for
        return min(candidates, key=rank), STATUS_OK
    if main_ok:
        return main, STATUS_PARTIAL
    if reserve_ok:
        return reserve, STATUS_PARTIAL
    return None, STATUS_FAILED


def vote_2oo3(channels: Sequence[Optional[int]], healthy: Sequence[bool] = (True, True, True)) -> Optional[int]:
    """A command at least two healthy channels agree on; otherwise no output (restrictive)."""
    counts = Counter(c for c, ok in zip(channels, healthy) if ok and c is not None)
    if not counts:
        return None
    command, votes = counts.most_common(1)[0]
    return command if votes >= 2 else None

"""Cab-signal aspects and the ALSN speed table shared by the receiver and the ATP.

Aspect enumeration (docs/interfaces.md#locoreceiver-locoreceiverfmu): 0 white/none (Б), 1 red (К), 2 red-yellow (КЖ), 3 yellow (Ж),
4 green (З). Lower numbers are more restrictive, except white, which is ranked between red
and red-yellow by :func:`restrictiveness` (no code: 40 km/h, no stop target).

Speeds per aspect and train category (km/h). ``ceiling``: highest speed while the aspect is
shown (None: the line's limit). ``at_signal``: speed to be reached at the next (exit) signal
(0: stop before it). Sources (tags as in docs/sources.md#how-to-read-this-page):

* yellow, passenger: reduce to 60 km/h by the end of the block section — ATO book, МИИТ
  reactions (docs/sources.md#cab-signal-speeds-per-aspect) [S];
* yellow, freight 50 / high-speed 80: the thesis' 4-aspect ALSU values for passing a wayside
  yellow (docs/sources.md#cab-signal-speeds-per-aspect) [S], applied to ALSN by analogy [U];
* red-yellow: traction–coast band 60…42 km/h (МИИТ) → ceiling 60 km/h passenger [S], freight
  50 [U]; stop before the red signal (docs/sources.md#alsn-carriers-and-aspects) [S];
* red: 20 km/h — ДКСВ vigilance rule "red and v < 20 km/h" (docs/sources.md#cab-signal-speeds-per-aspect) [S];
* white (no code): 40 km/h — KLUB ``no_code_limit`` 41 km/h (docs/sources.md#cab-signal-speeds-per-aspect) [S].

Everything is a parameter of the data, not of the code: replace this table for another
railway's rules.
"""
from __future__ import annotations

from typing import Dict, Optional, Tuple

WHITE, RED, RED_YELLOW, YELLOW, GREEN = 0, 1, 2, 3, 4

#: The train categories the speed tables know (the ``train_category`` parameters).
TRAIN_CATEGORIES = ("passenger", "freight", "high_speed")
#: Maximum speed of each category (km/h): what green permits unless ``v_max`` says otherwise.
CATEGORY_MAX_KMH = {"passenger": 160.0, "freight": 90.0, "high_speed": 200.0}

ASPECT_NAMES = {WHITE: "white", RED: "red", RED_YELLOW: "red-yellow", YELLOW: "yellow", GREEN: "green"}

# category → aspect → (ceiling km/h or None for the line limit, speed at the exit signal km/h or None)
ALSN_SPEEDS_KMH: Dict[str, Dict[int, Tuple[Optional[float], Optional[float]]]] = {
    "passenger": {GREEN: (None, None), YELLOW: (None, 60.0), RED_YELLOW: (60.0, 0.0),
                  RED: (20.0, None), WHITE: (40.0, None)},
    "freight": {GREEN: (None, None), YELLOW: (None, 50.0), RED_YELLOW: (50.0, 0.0),
                RED: (20.0, None), WHITE: (40.0, None)},
    "high_speed": {GREEN: (None, None), YELLOW: (None, 80.0), RED_YELLOW: (60.0, 0.0),
                   RED: (20.0, None), WHITE: (40.0, None)},
}

_RANK = {RED: 0, WHITE: 1, RED_YELLOW: 2, YELLOW: 3, GREEN: 4}


def restrictiveness(aspect: int) -> int:
    """Rank for 'more permissive than' comparisons: higher is more permissive."""
    return _RANK.get(int(aspect), 0)


def alsn_speeds_mps(category: str, aspect: int) -> Tuple[Optional[float], Optional[float]]:
    ceiling, at_signal = ALSN_SPEEDS_KMH[category].get(int(aspect), ALSN_SPEEDS_KMH[category][RED])
    return (None if ceiling is None else ceiling / 3.6, None if at_signal is None else at_signal / 3.6)

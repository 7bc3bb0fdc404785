"""Cab-signal aspects and the ALSN speed table shared by the receiver and the ATP.

Aspect enumeration (docs/interfaces.md#locoreceiver-locoreceiverfmu): 0 white/none (Б), 1 red (К), 2 red-yellow (КЖ), 3 yellow (Ж),
4 green (З). Lower numbers are more restrictive, except white, which is ranked between red
and red-yellow by :func:`restrictiveness` (no code: 40 km/h, no stop target).

Two tables per aspect and train category (km/h), because the sources give two kinds of speed:

* ``ALSN_SPEEDS_KMH`` — what the **ATP supervises** (and what the receiver reports as
  ``v_permitted``/``v_target``): ``ceiling``, the highest speed while the aspect is shown (None:
  the line's limit), and ``at_signal``, the speed to be reached at the next (exit) signal
  (0: stop before it);
* ``ALSN_DRIVING_KMH`` — how the **ATO drives** under the aspect (the ATO book's МИИТ
  reactions): ``band_top``, the top of its traction–coast band, and ``at_signal``, its own
  target at the exit signal. The ATO keeps under both tables.

Sources (tags as in docs/sources.md#how-to-read-this-page; ``SOURCES`` below names each entry's):

* yellow, supervised at the exit signal: passenger 80, freight 50 km/h — the thesis' speeds for
  passing a wayside yellow with 4-aspect ALSU (docs/sources.md#cab-signal-speeds-per-aspect,
  row 4) [S], read for ALSN's yellow by analogy [U]; high-speed trains are passenger trains:
  80 [U];
* red-yellow, supervised: a stop before the exit signal (docs/sources.md#alsn-carriers-and-aspects)
  [S]; the ceiling V_КЖ is supervised by ALSN equipment, its value is not in the sources
  (docs/sources.md#alsn-decoder-rules, row 10): we take the speed permitted past the yellow signal
  the train has just passed (80 / 50 / 80) [U];
* red: 20 km/h — the thesis' Table 2.1 (its red, КЖ and flashing-white commands permit 20 km/h,
  docs/sources.md#cab-signal-speeds-per-aspect, row 6) [S], applied to ALSN [U]; the ДКСВ's
  vigilance rule "red and v < 20 km/h" agrees;
* white (no code): 40 km/h — KLUB ``no_code_limit`` 41 km/h (docs/sources.md#cab-signal-speeds-per-aspect,
  row 7) [S];
* ATO, yellow: reduce to 60 km/h by the end of the block section; red-yellow: a traction–coast
  band 60…42 km/h, then a stop — МИИТ's ATO for a passenger locomotive
  (docs/sources.md#cab-signal-speeds-per-aspect, rows 1–2) [S]; freight 50 km/h [U] (the
  supervised yellow speed); high-speed as passenger [U].

Everything is a parameter of the data, not of the code: replace these tables for another
railway's rules.
"""
from __future__ import annotations

from typing import Dict, Optional, Tuple

from fmus.train_categories import TRAIN_CATEGORIES   # the categories the speed tables know

WHITE, RED, RED_YELLOW, YELLOW, GREEN = 0, 1, 2, 3, 4

#: Maximum speed of each category (km/h): what green permits unless ``v_max`` says otherwise.
CATEGORY_MAX_KMH = {"passenger": 160.0, "freight": 90.0, "high_speed": 200.0}

ASPECT_NAMES = {WHITE: "white", RED: "red", RED_YELLOW: "red-yellow", YELLOW: "yellow", GREEN: "green"}

# category → aspect → (ceiling km/h or None for the line limit, speed at the exit signal km/h or None)
ALSN_SPEEDS_KMH: Dict[str, Dict[int, Tuple[Optional[float], Optional[float]]]] = {
    "passenger": {GREEN: (None, None), YELLOW: (None, 80.0), RED_YELLOW: (80.0, 0.0),
                  RED: (20.0, None), WHITE: (40.0, None)},
    "freight": {GREEN: (None, None), YELLOW: (None, 50.0), RED_YELLOW: (50.0, 0.0),
                RED: (20.0, None), WHITE: (40.0, None)},
    "high_speed": {GREEN: (None, None), YELLOW: (None, 80.0), RED_YELLOW: (80.0, 0.0),
                   RED: (20.0, None), WHITE: (40.0, None)},
}

# category → aspect → (top of the ATO's traction–coast band km/h or None, ATO target at the exit
# signal km/h or None); aspects not listed: the ATO drives under the supervised table alone
ALSN_DRIVING_KMH: Dict[str, Dict[int, Tuple[Optional[float], Optional[float]]]] = {
    "passenger": {YELLOW: (None, 60.0), RED_YELLOW: (60.0, 0.0)},
    "freight": {YELLOW: (None, 50.0), RED_YELLOW: (50.0, 0.0)},
    "high_speed": {YELLOW: (None, 60.0), RED_YELLOW: (60.0, 0.0)},
}

# category → aspect → bottom of the ATO's traction–coast band (km/h): МИИТ's КЖ band 60…42 km/h
# ("42" as printed, reading uncertain) [S]; freight and high-speed the same 18 km/h depth [U]
ALSN_BAND_BOTTOM_KMH: Dict[str, Dict[int, float]] = {
    "passenger": {RED_YELLOW: 42.0}, "freight": {RED_YELLOW: 32.0}, "high_speed": {RED_YELLOW: 42.0},
}

#: (table, category, aspect) → where each speed comes from (docs/ato.md shows it beside the value)
SOURCES: Dict[Tuple[str, str, int], str] = {
    **{("supervised", c, GREEN): "line limit (docs/sources.md#alsn-carriers-and-aspects) [S]" for c in TRAIN_CATEGORIES},
    ("supervised", "passenger", YELLOW): "thesis §1.3: passing a wayside yellow ≤ 80 km/h, passenger [S]; for ALSN [U]",
    ("supervised", "freight", YELLOW): "thesis §1.3: passing a wayside yellow ≤ 50 km/h, freight [S]; for ALSN [U]",
    ("supervised", "high_speed", YELLOW): "the passenger 80 km/h [U]",
    **{("supervised", c, RED_YELLOW): "stop at the exit signal [S]; V_КЖ = the yellow passing speed [U]"
       for c in TRAIN_CATEGORIES},
    **{("supervised", c, RED): "thesis Table 2.1: red 20 km/h [S]; for ALSN [U]" for c in TRAIN_CATEGORIES},
    **{("supervised", c, WHITE): "KLUB no_code_limit 41 km/h [S]" for c in TRAIN_CATEGORIES},
    ("driving", "passenger", YELLOW): "ATO book §9, МИИТ: 60 km/h by the end of the block [S]",
    ("driving", "passenger", RED_YELLOW): "ATO book §9, МИИТ: band 60…42 km/h, then stop [S]",
    ("driving", "freight", YELLOW): "the supervised 50 km/h [U]",
    ("driving", "freight", RED_YELLOW): "band 50…32 km/h (the passenger depth) [U], then stop [S]",
    ("driving", "high_speed", YELLOW): "as passenger [U]",
    ("driving", "high_speed", RED_YELLOW): "as passenger [U]",
}

#: aspects under which the driver's vigilance is checked periodically (ALSN: yellow, red-yellow, red
#: and white, docs/sources.md#alsn-decoder-rules; none on green)
VIGILANCE_ASPECTS = (YELLOW, RED_YELLOW, RED, WHITE)

_RANK = {RED: 0, WHITE: 1, RED_YELLOW: 2, YELLOW: 3, GREEN: 4}


def restrictiveness(aspect: int) -> int:
    """Rank for 'more permissive than' comparisons: higher is more permissive."""
    return _RANK.get(int(aspect), 0)


def alsn_speeds_mps(category: str, aspect: int) -> Tuple[Optional[float], Optional[float]]:
    ceiling, at_signal = ALSN_SPEEDS_KMH[category].get(int(aspect), ALSN_SPEEDS_KMH[category][RED])
    return (None if ceiling is None else ceiling / 3.6, None if at_signal is None else at_signal / 3.6)


def alsn_driving_mps(category: str, aspect: int) -> Tuple[Optional[float], Optional[float]]:
    """(top of the ATO's band, ATO target at the exit signal) in m/s; None where the aspect
    asks nothing of the ATO beyond the supervised speeds."""
    band, at_signal = ALSN_DRIVING_KMH[category].get(int(aspect), (None, None))
    return (None if band is None else band / 3.6, None if at_signal is None else at_signal / 3.6)


def alsn_band_bottom_mps(category: str, aspect: int) -> Optional[float]:
    """Bottom of the ATO's traction–coast band under the aspect (m/s), None: no band."""
    bottom = ALSN_BAND_BOTTOM_KMH[category].get(int(aspect))
    return None if bottom is None else bottom / 3.6


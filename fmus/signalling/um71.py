"""The UM71 track circuits both TVM systems send on (docs/sources.md#tvm-430, rows 3–4;
docs/sources.md#tvm-300): the audio-frequency carriers of each track, alternating block by
block, which a low frequency modulates, and the one figure of the receivers' shared front end
(fmus/loco_receiver/um71.py) that the systems' decoder rules state their decode times with.
No FMI, no filtering here.
"""
from __future__ import annotations

#: carriers per track, alternating block by block [S]
TRACK_CARRIERS_HZ = {1: (1700.0, 2300.0), 2: (2000.0, 2600.0)}
CARRIERS_HZ = (1700.0, 2000.0, 2300.0, 2600.0)
#: the receivers' baseband low-pass rise (s): its step response reaches the squelch / the
#: weakest carrier (0.03 / 0.1 V) after 7.2 ms (a third after 7.5 ms), so a carrier that starts
#: is above the squelch that much later (tests/test_tvm430_receiver.py checks it against the
#: low-pass of fmus/loco_receiver/um71.py at 8 and 12 kHz); a decode time counts it
BASEBAND_RISE_S = 0.0076


def decoder_times(window_s: float, hop_s: float):
    """(hold, stated latency, stated decode time) in s of a UM71 receiver that decides every
    ``hop_s`` on a sliding window of ``window_s`` (the rule both TVM receivers follow, ours [U];
    docs/loco_receiver.md#tvm-430):

    * **hold** (``inertia`` 0), 2·window + 3·hop: how long the code shown outlives its last
      support. It bridges a block boundary at the worst moment: the code of the block being left
      changes just before it (the windows straddling the change read nothing, up to a window and
      a hop), then the new block's carrier needs a window and two hops of its own;
    * **stated latency**, window + hold + hop: from the instant the code at the coils is lost (no
      carrier, a code not read) to the restrictive display — a window that still holds part of
      the old code may read it (a whole window at most), then the hold, then the next decision;
    * **stated decode time**, window + 2·hop + BASEBAND_RISE_S: a code is shown within this of
      the instant it starts at the coils (from cold, on a new carrier, a permissive change): the
      carrier's rise through the baseband low-pass, the window filled, a decision boundary and
      one more to confirm (a restrictive change needs no confirmation: a hop less)."""
    hold_s = 2 * window_s + 3 * hop_s
    return hold_s, window_s + hold_s + hop_s, window_s + 2 * hop_s + BASEBAND_RISE_S


def read_steps_and_margin(doc: dict, fail) -> tuple:
    """A TVM code table's ``steps_kmh`` (falling from the fastest step to 0) and
    ``control_margin_kmh`` (above 0), as given; ``fail(field, message)`` raises the table's error."""
    steps = doc.get("steps_kmh")
    if not isinstance(steps, list) or len(steps) < 2 or any(not is_number(s) or s < 0 for s in steps) \
            or any(b >= a for a, b in zip(steps, steps[1:])) or steps[-1] != 0:
        fail("steps_kmh", "expected speeds in km/h falling from the fastest step to 0")
    margin = doc.get("control_margin_kmh")
    if not is_number(margin) or margin <= 0:
        fail("control_margin_kmh", "must be a speed in km/h above 0")
    return steps, margin


def is_number(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)

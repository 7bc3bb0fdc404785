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

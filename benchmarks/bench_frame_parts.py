"""Where a 10 ms frame of free_run goes, in process: wall-clock timers around the signal units'
steps and the rail line's parts, over a window of the timetable.

    python benchmarks/bench_frame_parts.py [--from 150] [--to 190]

Steps free_run to ``--from`` seconds untimed (the train is running at about 22 m/s from
150 s; it stands at its first station until about 65 s), then times every call of the parts
below up to ``--to`` and prints µs per frame. The timers add about 0.3 µs per timed call, so
the parts are read against each other, not added up to the frame's total (printed first).
"""
import argparse
import collections
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))   # `python benchmarks/X.py` from anywhere

from benchmarks._runs import scratch_run  # noqa: E402
from fmus.fmi.slave import FacadeSlave  # noqa: E402
from fmus.loco_receiver.facade import LocoReceiver  # noqa: E402
from fmus.rail_line.circuit_bank import TrackCircuitBank  # noqa: E402
from fmus.rail_line.coil_pickup import CoilPickup  # noqa: E402
from fmus.rail_line.core import RailLineCore  # noqa: E402
from fmus.rail_line.facade import RailLine  # noqa: E402
from fmus.rail_line.traction_interference import TractionInterference  # noqa: E402
from fmus.wayside_coder.facade import WaysideCoder  # noqa: E402
from orchestrator import master  # noqa: E402
from orchestrator.cli import SSP_ROOT, _build_dir  # noqa: E402
from orchestrator.graph import TICKS_PER_SECOND  # noqa: E402

PARTS = (   # (class, method, label): indentation shows what is inside what
    (FacadeSlave, "do_step", "every unit's doStep (coder, rail line, receiver; train, ATO)"),
    (FacadeSlave, "_step_refusal", "  the facades' per-step checks"),
    (WaysideCoder, "step_core", "  coder"),
    (RailLine, "step_core", "  rail line"),
    (TrackCircuitBank, "set_faults", "    fault inputs"),
    (RailLineCore, "step", "    rail line core"),
    (RailLineCore, "_update_anchor", "      trains' position updates"),
    (RailLineCore, "_head_into", "      positions over the frame"),
    (TractionInterference, "new_frame", "      traction current"),
    (TrackCircuitBank, "follow_shunts", "      shunts (and new network models)"),
    (TrackCircuitBank, "advance", "      sections' states"),
    (CoilPickup, "sense", "      coil pickup"),
    (LocoReceiver, "step_core", "  receiver"),
)


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--from", dest="start", type=float, default=150.0)
    parser.add_argument("--to", dest="stop", type=float, default=190.0)
    args = parser.parse_args()
    spent = collections.Counter()
    timing = [False]

    def timed(function, label):
        def wrapper(*positional, **named):
            if not timing[0]:
                return function(*positional, **named)
            began = time.perf_counter()
            try:
                return function(*positional, **named)
            finally:
                spent[label] += time.perf_counter() - began
        return wrapper

    for cls, name, label in PARTS:
        setattr(cls, name, timed(getattr(cls, name), label))
    run_until = master.Master.run_until

    def windowed(self, stop_ticks):
        run_until(self, round(args.start * TICKS_PER_SECOND))
        timing[0] = True
        began = time.perf_counter()
        run_until(self, stop_ticks)
        spent["frame"] = time.perf_counter() - began
        timing[0] = False

    master.Master.run_until = windowed
    scratch_run(SSP_ROOT / "free_run", True, [_build_dir()], args.stop)
    frames = (args.stop - args.start) / 0.01
    print(f"free_run in process, {args.start:g}–{args.stop:g} s, µs per 10 ms frame:")
    print(f"{1e6 * spent['frame'] / frames:8.1f}  the whole frame (master, observers and all)")
    for _, _, label in PARTS:
        print(f"{1e6 * spent[label] / frames:8.1f}  {label}")


if __name__ == "__main__":
    main()

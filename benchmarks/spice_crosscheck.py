"""The rail line's track circuits against ngspice over every shipped line: the tables of
docs/rail_line.md#checked-against-ngspice (accuracy, not speed).

    python benchmarks/spice_crosscheck.py [--lines default_line ...] [--places 3] [--quick]

For every line file a shipped system runs on, at the carriers the systems use there (the line
file's, and 174.38 / 175 Hz on the lines the digital systems run on) and 1 / 50 / 200 Ω·km:

* .ac: the rail line's network (one shunt per node a 400 m train covers) against ngspice on the
  same netlist, every section design;
* .tran: section 1 of each line, 1 s with a code change and a train entering;
* the wheelsets: every documented train (the shipped rolling stock and the light engine of two
  bogies) leading, the passenger train following 30 and 100 m behind, at ``--places`` head
  positions per section design: the lumped network and the wheelset chain against every axle
  in ngspice (rails in 1 m pieces).

Needs ngspice on PATH (apt-get install ngspice). ``--quick``: 1 Ω·km and one place only. A few
minutes per line on one core.
"""
import argparse
import math
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))   # `python benchmarks/X.py` from anywhere

from fmus.data.loader import DATA, load_line  # noqa: E402
from orchestrator.circuits.crosscheck import (BALLASTS_OHM_KM, TRAN_BOUND, AC_BOUND, WHEELSET_BOUND, ac_rows,  # noqa: E402
                                              ac_table, documented_trains, shipped_train, tran_check, tran_table,
                                              wheelset_rows)

REPO = Path(__file__).resolve().parent.parent
DIGITAL_CARRIERS_HZ = (174.38, 175.0)
# the line files of the shipped systems, and whether a digital system runs on it
LINES = {
    "default_line": (DATA / "default_line.json", True),
    "default_line_ac": (DATA / "default_line_ac.json", False),
    "following_line": (REPO / "ssp" / "following" / "resources" / "following_line.json", True),
    "throat_line": (REPO / "ssp" / "joints_at_speed" / "resources" / "throat_line.json", False),
    "same_block_line": (REPO / "ssp" / "same_block" / "resources" / "same_block_line.json", False),
}


def worst(low: float, high: float) -> float:
    return low if abs(low) > abs(high) else high


def show(error: float) -> str:
    """A relative error: per cent, or × the reference when far above it."""
    if math.isinf(error):
        return "∞"
    if error >= 9.0:
        return f"×{1.0 + error:.2g}"
    if abs(error) < 1e-4:
        return f"{error:+.0e}"
    return f"{100.0 * error:+.2f} %"


def summary_table(rows) -> list:
    """One row per line, ballast and leading train: the worst error (signed) of the lumping and
    of the wheelset chain per quantity."""
    out = ["| line | ballast Ω·km | leading train | first axle: lumped / chain | 30–100 m behind: lumped / chain "
           "| relay under it: lumped / chain |", "|---|---|---|---|---|---|"]
    for row in rows:
        cells = []
        for key in ("current at the first axle", "behind", "relay voltage under the train"):
            picked = [v for q, v in row.errors.items() if key in q]
            if not picked:
                cells.append("—")
                continue
            lumped = max((worst(v[0], v[1]) for v in picked), key=abs)
            chain = max((worst(v[2], v[3]) for v in picked), key=abs)
            cells.append(f"{show(lumped)} / {show(chain)}")
        out.append(f"| {row.line} | {row.ballast_ohm_km:g} | {row.train} | " + " | ".join(cells) + " |")
    return out


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--lines", nargs="*", default=list(LINES))
    parser.add_argument("--places", type=int, default=3)
    parser.add_argument("--quick", action="store_true")
    args = parser.parse_args()
    ballasts = (1.0,) if args.quick else BALLASTS_OHM_KM
    places = 1 if args.quick else args.places
    trains = documented_trains()
    follower = shipped_train("passenger_chs7.json")
    began = time.perf_counter()
    ac, tran, wheelsets = [], [], []
    for name in args.lines:
        path, digital = LINES[name]
        line = load_line(path)
        carriers = sorted({float(s.carrier_hz) for s in line.sections} | (set(DIGITAL_CARRIERS_HZ) if digital else set()))
        ac += ac_rows(line, name, carriers, ballasts)
        tran.append(tran_check(line, name, 0))
        wheelsets += wheelset_rows(line, name, trains, follower, ballasts, places=places)
        print(f"{name}: done ({time.perf_counter() - began:.0f} s)", file=sys.stderr)
    print(f"## .ac (largest relative difference; bound {AC_BOUND:g})\n")
    print("\n".join(ac_table(ac)) + "\n")
    print(f"## .tran (of the local amplitude; bound {TRAN_BOUND:g})\n")
    print("\n".join(tran_table(tran)) + "\n")
    print(f"## wheelsets against every axle in ngspice (worst signed error; the chain's bound ±{WHEELSET_BOUND:g})\n")
    print("\n".join(summary_table(wheelsets)) + "\n")
    failed = [r for r in ac if not r.passed()] + [r for r in tran if not r.passed()] + \
        [r for r in wheelsets if not r.chain_passed()]
    print("every comparison within its bound" if not failed else f"{len(failed)} comparisons OUTSIDE their bound")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())

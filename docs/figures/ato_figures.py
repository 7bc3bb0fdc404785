"""Figures of docs/ato.md: python docs/figures/ato_figures.py (writes the PNGs beside it).

1. ato_speed_distance.png — the default timetable with an 8 % running-time supplement:
   flat-out (minimum time) and energy-efficient (programme strategy) runs of the closed loop,
   the line limit, and the energy of both.
2. ato_red_yellow.png — yellow then red-yellow ahead of signal 9 (15 200 m), cleared at 900 s.
"""
import json
import sys
import tempfile
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from fmus.ato_controller.core import AtoSettings  # noqa: E402
sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository: harness
from harness.closed_loop import red_signal_ahead, run_closed_loop  # noqa: E402
from fmus.ato_controller.planner import StagePlanner  # noqa: E402
from fmus.ato_controller.train_model import NominalTrain  # noqa: E402
from fmus.data.loader import load_line, load_rolling_stock  # noqa: E402

HERE = Path(__file__).resolve().parent
KMH = 1 / 3.6


def timetable_with_supplement(folder: Path, supplement: float) -> Path:
    line, stock = load_line(), load_rolling_stock()
    planner = StagePlanner(NominalTrain(stock, line), line, "passenger", 0.5, 2 * KMH)
    t_ab = round(planner.plan(400, 10300, None).minimum_time_s * (1 + supplement))
    t_bc = round(planner.plan(10300, 19600, None).minimum_time_s * (1 + supplement))
    stops = [{"station": "A", "departure_s": 60}, {"station": "B", "arrival_s": 60 + t_ab, "departure_s": 120 + t_ab},
             {"station": "C", "arrival_s": 120 + t_ab + t_bc}]
    path = folder / "timetable_8pct.json"
    path.write_text(json.dumps({"train": "8 % supplement", "stops": stops}))
    return path


def limit_profile(line, xs):
    return np.array([line.speed_limit_mps(x, "passenger") for x in xs]) * 3.6


def speed_distance(folder: Path) -> dict:
    timetable = timetable_with_supplement(folder, 0.08)
    runs = {s: run_closed_loop(1100.0, timetable_file=timetable, settings=AtoSettings(strategy=s, cab_signal="off"))
            for s in ("flat_out", "programme", "predictive")}
    line = load_line()
    xs = np.linspace(0, line.length_m, 4001)
    fig, ax = plt.subplots(figsize=(11, 4.8))
    ax.step(xs / 1000, limit_profile(line, xs), where="post", color="0.6", lw=1, label="line limit (passenger)")
    for name, style in (("flat_out", "C3"), ("programme", "C0"), ("predictive", "C2")):
        r = runs[name]
        ax.plot(r.column("x") / 1000, r.column("v") * 3.6, style, lw=1.2,
                label=f"{name}: {r.energy_kwh:.0f} kWh, arrivals "
                      + ", ".join(f"{a['station']} {a['arrival_deviation_s']:+.1f} s" for a in r.ato.arrivals))
    ax.set_xlabel("distance [km]")
    ax.set_ylabel("speed [km/h]")
    ax.set_title("Default line A–B–C, timetable with 8 % running-time supplement (ЧС7 + 14 coaches)")
    ax.legend(loc="lower center", fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(HERE / "ato_speed_distance.png", dpi=110)
    return {name: {"energy_kwh": r.energy_kwh, "arrivals": r.ato.arrivals, "mode_changes": r.ato.out.mode_changes}
            for name, r in runs.items()}


def red_yellow() -> None:
    cab = red_signal_ahead(load_line(), 15200.0, 900.0)
    r = run_closed_loop(1300.0, cab_signal=cab)
    fig, ax = plt.subplots(figsize=(11, 4.5))
    x = r.column("x") / 1000
    ax.plot(x, r.column("v") * 3.6, "C0", lw=1.3, label="speed")
    ax.plot(x, np.minimum(r.column("v_atp"), 60) * 3.6, "C3", lw=0.8, label="ATP permitted speed (clipped at 216 km/h)")
    for pos in (10.4, 12.8, 15.2):
        ax.axvline(pos, color="0.5", ls=":", lw=0.8)
    ax.text(15.2, 5, " signal 9 (red until 900 s)", fontsize=8)
    ax.set_xlim(9.5, 19.8)
    ax.set_xlabel("distance [km]")
    ax.set_ylabel("speed [km/h]")
    ax.set_title("Stage B–C: З → Ж (10.4–12.8 km) → КЖ (12.8–15.2 km), stop before the red signal, recovery")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(HERE / "ato_red_yellow.png", dpi=110)


if __name__ == "__main__":
    with tempfile.TemporaryDirectory() as folder:
        figures = speed_distance(Path(folder))
    red_yellow()
    json.dump(figures, sys.stdout, indent=1, default=float)
    print()

"""Figures and tables of docs/rail_line.md: python docs/figures/rail_line_figures.py

1. rail_code_current.png — code current under the first wheelset along section 4
   (7800–10400 m): the network (time-domain core, steady 50 Hz carrier) against the two-port
   cascade; and the relay-end voltage (free / shunted).
2. rail_joint_80_160.png — coil EMF while the coils pass the joint at 2600 m at 80 and
   160 km/h with a keyed code and 600 A DC traction.
Prints the ALS-mode table (minimum code current per section against ballast resistance).
"""
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "tests"))
from test_rail_line import _analytic_shunt_current, _run  # noqa: E402

from fmus.data.loader import load_line  # noqa: E402
from fmus.rail_line.core import RailLineCore, RailSettings  # noqa: E402
from fmus.rail_line.track_circuit import CircuitParameters  # noqa: E402

HERE = Path(__file__).resolve().parent
FS, N = 4000.0, 40


def code_current() -> None:
    params = CircuitParameters()
    positions = np.linspace(7810.0, 10390.0, 44)
    network, analytic = [], []
    for x in positions:
        core = RailLineCore(load_line(), 8, 2, N, RailSettings(transformer_ratio=1.0))
        _, _, axle = _run(core, 0.3, lambda t, x=x: x, 0.0, sections=[3])
        network.append(axle[-10:].mean() * np.sqrt(2.0))
        analytic.append(_analytic_shunt_current(core.circuits[3], x, core.circuits[3].params))
    network, analytic = np.array(network), np.array(analytic)
    print(f"code current, network vs two-port: max deviation {np.max(np.abs(network / analytic - 1)) * 100:.2f} %")
    fig, ax = plt.subplots(figsize=(9, 4))
    ax.plot(positions / 1000, analytic, "k-", lw=1, label="two-port cascade (exact line)")
    ax.plot(positions / 1000, network, "C0o", ms=3, label="network (π sections ≤ 50 m, ZOH at 4 kHz)")
    ax.set_xlabel("first wheelset [km] (feed at 10.399 km, relay end at 7.8 km)")
    ax.set_ylabel("code current amplitude per volt of feed [A/V]")
    ax.set_title("Section 4, 50 Hz, ballast 1 Ω·km, 0.06 Ω shunt")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(HERE / "rail_code_current.png", dpi=110)


def joint_crossing() -> None:
    fig, axes = plt.subplots(2, 1, figsize=(10, 6), sharey=True)
    joint = 2600.0
    for ax, speed in zip(axes, (80.0, 160.0)):
        v = speed / 3.6
        core = RailLineCore(load_line(), 8, 2, N, RailSettings())
        start = joint - 1.5 - 12.0
        emf = []
        for k in range(int(round(24.0 / v * FS / N))):
            t = k * N / FS
            times = t + np.arange(N) / FS
            u = np.tile(4.0 * np.sin(2 * np.pi * 50 * times), (8, 1))
            emf.append(core.step(t, u, np.array([start + v * t, -1000.0]), np.array([v, 0.0]),
                                 np.array([600.0, 0.0])).e_coil[0].copy())
        emf = np.concatenate(emf)
        coil = start + v * np.arange(emf.size) / FS + 1.5
        ax.plot(coil - joint, emf, lw=0.6)
        ax.axvspan(-1.0, 0.0, color="0.85", label="null zone (bond leads → joint)")
        ax.axvspan(0.0, 1.5, color="0.93", label="weak zone (next section, not shunted yet)")
        ax.set_title(f"{speed:g} km/h: coil EMF through the joint at 2.6 km (continuous 50 Hz code, 600 A DC)")
        ax.set_ylabel("EMF [V]")
        ax.grid(alpha=0.3)
    axes[1].set_xlabel("coil position relative to the joint [m]")
    axes[0].legend(fontsize=8, loc="upper right")
    fig.tight_layout()
    fig.savefig(HERE / "rail_joint_80_160.png", dpi=110)


def als_table() -> None:
    core = RailLineCore(load_line(), 8, 2, N, RailSettings())
    ballasts = (1.0, 1.5, 2.5, 5.0, 20.0, 50.0)
    print("| section | length m | " + " | ".join(f"{b:g} Ω·km" for b in ballasts) + " |")
    print("|---" * (len(ballasts) + 2) + "|")
    for k, sec in enumerate(load_line().sections):
        values = [core.minimum_code_current(k, b) for b in ballasts]
        print(f"| {sec.name} | {sec.end_m - sec.start_m:.0f} | " + " | ".join(f"{v:.2f}" for v in values) + " |")


if __name__ == "__main__":
    code_current()
    joint_crossing()
    als_table()

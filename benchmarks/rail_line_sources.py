"""The rail line against its sources: python benchmarks/rail_line_sources.py (≈ 2 min)

Prints the tables of docs/rail_line.md that compare the model with the sources — the rail
impedance per carrier, the ALS-mode code current per carrier, the relay calibration per shipped
line, the joint interference beside the joints paper's table — and draws
docs/figures/rail_joint_paper.png (the DC pulse pair at 40/80/160 km/h and its spectrum at
80 km/h; the AC 50 Hz burst at 40/80/160 km/h).
"""
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from scipy.signal import butter, hilbert, sosfiltfilt  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from harness.joints import FS, JOINT_M, burst_envelope, cross_joint, pulse_lobes  # noqa: E402
from fmus.data.loader import DEFAULT_LINE, load_line  # noqa: E402
from fmus.rail_line.core import RailLineCore, RailSettings  # noqa: E402
from fmus.rail_line.track_circuit import CircuitParameters, rail_impedance  # noqa: E402

AC_LINE = DEFAULT_LINE.parent / "default_line_ac.json"
THROAT_LINE = ROOT / "ssp" / "joints_at_speed" / "resources" / "throat_line.json"


def impedance_table() -> None:
    params = CircuitParameters()
    print("| carrier Hz | R Ω/km | L mH/km | z Ω/km |")
    print("|---|---|---|---|")
    for f in (25.0, 50.0, 75.0, params.rail_reference_hz, 174.38, 175.0):
        r, l = rail_impedance(params, f)
        x = 2 * np.pi * f * l
        print(f"| {f:g} | {r:.3f} | {l * 1e3:.3f} | {r:.3f} + j{x:.3f} |")


def als_table() -> None:
    ballasts = (1.0, 1.5, 2.5, 5.0, 20.0, 50.0)
    print("| carrier, line | " + " | ".join(f"{b:g} Ω·km" for b in ballasts) + " |")
    print("|---" * (len(ballasts) + 1) + "|")
    for path, carrier in ((AC_LINE, 25.0), (DEFAULT_LINE, 50.0), (DEFAULT_LINE, 75.0), (DEFAULT_LINE, 174.38)):
        core = RailLineCore(load_line(path), 8, 2, 40, RailSettings(carrier_hz=carrier))
        values = [min(core.minimum_code_current(k, b) for k in range(8)) for b in ballasts]
        print(f"| {carrier:g} Hz, {path.stem} | " + " | ".join(f"{v:.2f}" for v in values) + " |")


def calibration_table() -> None:
    for path, name in ((DEFAULT_LINE, "default_line"), (AC_LINE, "default_line_ac (25 Hz)"), (THROAT_LINE, "throat line")):
        core = RailLineCore(load_line(path), 8, 2, 40, RailSettings())
        bank = core.bank
        groups = {}
        for k, c in enumerate(bank.calibration.table):
            groups.setdefault((round(c.length_m), round(c.shunt_level, 6)), []).append(k)
        for (_, _), ks in groups.items():
            c = bank.calibration.table[ks[0]]
            where = "feed end" if c.shunt_node == core.circuits[ks[0]].segments else f"node {c.shunt_node}"
            sections = f"{ks[0] + 1}" if len(ks) == 1 else f"{ks[0] + 1}–{ks[-1] + 1}"
            print(f"| {name} | {sections} | {c.length_m:.0f} | {c.ballast_min_ohm_km:g}–{c.ballast_max_ohm_km:g} | "
                  f"{c.normal_level:.3f} | {c.shunt_level:.3f} ({where}) | {c.control_level:.1e} | "
                  f"{100 * c.shunt_margin:.1f} % | {bank.calibration.longest_calibratable_m(ks[0]):.0f} |")


def joints() -> None:
    fig, axes = plt.subplots(1, 3, figsize=(14, 4))
    print("| quantity (DC, 80 km/h, 1000 A, matched coils) | joints paper | model |")
    print("|---|---|---|")
    for speed in (40.0, 80.0, 160.0):
        coil, t, emf = cross_joint(speed, asymmetry=0.03, before_m=6.0, after_m=6.0)
        centre = t[np.argmin(np.abs(coil - JOINT_M))]
        axes[0].plot((t - centre) * 1000, emf, label=f"{speed:g} km/h")
        (up, w_up, _), (down, w_down, _) = pulse_lobes(t, emf)
        if speed == 80.0:
            spectrum = np.abs(np.fft.rfft(emf, 1 << 16))
            f = np.fft.rfftfreq(1 << 16, 1 / FS)
            energy = spectrum ** 2
            axes[1].plot(f, spectrum / spectrum.max(), "C1")
            axes[1].axvline(5.0, color="k", ls=":", lw=0.8)
            axes[1].set_xlim(0, 40)
            print(f"| half-amplitude width of each pulse | 0.059 s | {w_up:.4f} / {w_down:.4f} s |")
            print(f"| spectrum envelope maximum | 5 Hz | {f[np.argmax(spectrum)]:.2f} Hz |")
            print(f"| energy below 20 Hz | main part | {100 * energy[f <= 20].sum() / energy.sum():.1f} % |")
            print(f"| largest EMF | 0.925 V | {max(up, down):.3f} V (+{up:.3f} / −{down:.3f}) |")
        else:
            print(f"| at {speed:g} km/h: largest EMF, width | depends on speed | {max(up, down):.3f} V, {w_up:.4f} s |")
    _, _, mismatched = cross_joint(80.0, asymmetry=0.03, coil_mismatch=0.05, before_m=6.0, after_m=6.0)
    print(f"| coil-pair asymmetry 5 % | 5 V | {np.abs(mismatched).max():.2f} V |")
    axes[0].set_xlabel("time from the coil's passing the joint [ms]")
    axes[0].set_ylabel("coil EMF [V]")
    axes[0].set_title("DC 1000 A: pulse pair\n(paper: 0.059 s, 0.925 V at 80 km/h)", fontsize=10)
    axes[0].set_xlim(-250, 250)
    axes[0].legend(fontsize=8)
    axes[1].set_xlabel("frequency [Hz]")
    axes[1].set_ylabel("|spectrum| (relative)")
    axes[1].set_title("DC, 80 km/h: spectrum\n(paper: maximum at 5 Hz, energy below 20 Hz)", fontsize=10)
    line = load_line(AC_LINE)
    for speed in (40.0, 80.0, 160.0):
        coil, t, emf = cross_joint(speed, line=line, i_traction=300.0, asymmetry=0.03, before_m=6.0, after_m=6.0)
        envelope, peak = burst_envelope(emf)
        fifty = np.abs(hilbert(sosfiltfilt(butter(4, (30.0, 70.0), btype="band", fs=FS, output="sos"), emf)))
        inner = np.abs(coil - JOINT_M) < 5.0
        axes[2].plot((coil - JOINT_M)[inner], fifty[inner], label=f"{speed:g} km/h (50 Hz peak {fifty[inner].max():.2f} V)")
        print(f"| AC 300 A, {speed:g} km/h: 50 Hz burst peak | independent of speed | {peak:.2f} V, "
              f"{(envelope > 0.5 * peak).sum() / FS * 1000:.0f} ms above half |")
    axes[2].set_xlabel("coil position from the joint [m]")
    axes[2].set_ylabel("50 Hz envelope of the EMF [V]")
    axes[2].set_title("AC 300 A: 50 Hz envelope (band 30–70 Hz)\n(paper: amplitude independent of speed)", fontsize=10)
    axes[2].legend(fontsize=8)
    for ax in axes:
        ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(ROOT / "docs" / "figures" / "rail_joint_paper.png", dpi=100)


if __name__ == "__main__":
    impedance_table()
    print()
    als_table()
    print()
    calibration_table()
    print()
    joints()

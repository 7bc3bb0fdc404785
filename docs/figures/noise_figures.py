"""Figures of docs/noise_immunity.md from the study's results:

    python benchmarks/study_noise_immunity.py      # writes docs/figures/noise_immunity.json
    python docs/figures/noise_figures.py           # the PNGs below and the markdown tables

1. noise_ber.png — bit error rate of both modems against Eb/N0 and the theory of
   differentially detected 4-phase DPSK; the generator's spectrum beside it.
2. noise_message_errors.png — message error rate against wideband SNR, and
   against the rate of impulse noise, for ALSN, ALSU, ALS-EN and FIRE_DQPSK.
"""
import json
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from scipy import signal  # noqa: E402

from fmus.signalling import cab_systems, dqpsk  # noqa: E402
from fmus.data.loader import load_line  # noqa: E402
from fmus.wayside_coder.core import CoderSettings  # noqa: E402
from fmus.wayside_coder.digital_generator import DigitalCoderCore  # noqa: E402

HERE = Path(__file__).resolve().parent
SYSTEMS = (cab_systems.ALSN.name, cab_systems.ALSU.name, cab_systems.ALS_EN.name, cab_systems.FIRE_DQPSK.name)
STYLE = {cab_systems.ALSN.name: "s-", cab_systems.ALSU.name: "d-", cab_systems.ALS_EN.name: "o-", cab_systems.FIRE_DQPSK.name: "^-"}


def ber_and_spectrum(results) -> None:
    fig, (ax, ax_psd) = plt.subplots(1, 2, figsize=(11, 4.2))
    ebn0 = np.linspace(0, 11, 100)
    ax.semilogy(ebn0, dqpsk.theory_ber(ebn0), "k-", label="theory, differential 4-DPSK")
    for name, marker in ((cab_systems.FIRE_DQPSK.name, "^"), (cab_systems.ALS_EN.name, "o")):
        points = results["ber"][name]
        ax.semilogy([float(e) for e in points], list(points.values()), marker, label=f"{name} (simulated)")
    ax.set_xlabel("Eb/N0 (dB)")
    ax.set_ylabel("bit error rate")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend()
    ax.set_title("Modem BER, ideal timing")
    for name in (cab_systems.FIRE_DQPSK.name, cab_systems.ALS_EN.name):
        coder = DigitalCoderCore(cab_systems.DIGITAL[name], load_line(), 8, 4000, CoderSettings(amplitude_v=1.0))
        occupied = np.zeros(8, dtype=bool)
        u = np.concatenate([coder.step(k * 1.0, occupied).u_tx[0].copy() for k in range(60)])
        f, p = signal.welch(u, 4000.0, nperseg=8000)
        ax_psd.semilogy(f, p / p.max(), label=name)
    ax_psd.set_xlim(0, 700)
    ax_psd.set_ylim(1e-8, 2)
    ax_psd.set_xlabel("frequency (Hz)")
    ax_psd.set_ylabel("PSD / peak")
    ax_psd.grid(True, which="both", alpha=0.3)
    ax_psd.legend()
    ax_psd.set_title("Generator output (square wave + Chebyshev band-pass)")
    fig.tight_layout()
    fig.savefig(HERE / "noise_ber.png", dpi=110)


def message_errors(results) -> None:
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
    # each system at its own levels: the file also holds TVM430's (docs/loco_receiver.md#tvm-430),
    # whose SNR is over another band and which these plots leave out
    for name in SYSTEMS:
        snrs = sorted((s for s in results["white"] if name in results["white"][s]), key=float, reverse=True)
        rates = sorted((r for r in results["impulse"] if name in results["impulse"][r]), key=float)
        if not snrs:
            continue
        mer = [max(results["white"][s][name]["mer"], 1e-5) for s in snrs]
        axes[0].semilogy([float(s) for s in snrs], mer, STYLE[name], label=name)
        mer = [max(results["impulse"][r][name]["mer"], 1e-5) for r in rates]
        axes[1].semilogy([float(r) for r in rates], mer, STYLE[name], label=name)
    axes[0].set_xlabel("SNR over the whole 0–2 kHz band (dB)")
    axes[0].invert_xaxis()
    axes[1].set_xlabel("impulses per second (5–40 V against a 0.2 V signal)")
    for ax in axes:
        ax.set_ylabel("message error rate (floor 1e-5)")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend()
    axes[0].set_title("White noise")
    axes[1].set_title("Impulse noise")
    fig.tight_layout()
    fig.savefig(HERE / "noise_message_errors.png", dpi=110)


def tables(results) -> str:
    lines = []
    for kind, label in (("white", "SNR (dB)"), ("impulse", "impulses / s"), ("joint", "joint pulses at km/h")):
        if not results.get(kind):
            continue
        lines.append(f"\n| {label} | system | messages | MER | undetected | wrong-side events (time) | availability |")
        lines.append("|---|---|---|---|---|---|---|")
        for key in sorted(results[kind], key=float, reverse=kind == "white"):
            for name in SYSTEMS:
                r = results[kind][key].get(name)
                if r is None:
                    continue
                lines.append(f"| {key} | {name} | {r['messages']} | {r['mer']:.4f} | {r['undetected']} | "
                             f"{r['wrong_side_events']} ({r['wrong_side_s']:.2f} s) | {r['availability']:.3f} |")
    lines.append("\n| signal alone | system | message durations | messages accepted | other-track messages discarded |")
    lines.append("|---|---|---|---|---|")
    for kind, label in (("tone", "steady tone at the carrier"), ("adjacent", "adjacent track (other parity)")):
        for name, r in results[kind].items():
            lines.append(f"| {label} | {name} | {r['messages']} | {r['accepted']} | {r['foreign']} |")
    return "\n".join(lines)


def main():
    results = json.loads((HERE / "noise_immunity.json").read_text())
    ber_and_spectrum(results)
    message_errors(results)
    print(tables(results))


if __name__ == "__main__":
    main()

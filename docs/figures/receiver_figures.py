"""Figures and tables of docs/loco_receiver.md: python docs/figures/receiver_figures.py

1. receiver_bode.png — the band-pass filters (25, 50, 75 Hz carriers; python-control Bode data
   of the discretised filters) and their group delay.
2. receiver_code_z.png — code З at the filter output while the coils pass an insulated joint:
   the feed end of one section (3.5 V at the coil), a 1 m null zone, then the entry end of the
   next section (0.28 V, another cam phase), as in the joints paper's Fig. 2 and its table row 3 (docs/sources.md#interference-at-insulated-joints).
Prints the overload-recovery table.
"""
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from scipy.signal import sosfilt  # noqa: E402

from fmus.data.loader import load_line  # noqa: E402
from fmus.loco_receiver import filters  # noqa: E402
from fmus.loco_receiver.core import LocoReceiverCore, ReceiverSettings  # noqa: E402
from fmus.wayside_coder.core import CoderSettings, WaysideCoderCore  # noqa: E402

HERE = Path(__file__).resolve().parent
FS, N = 4000.0, 40


def bode() -> None:
    fig, (ax_mag, ax_gd) = plt.subplots(2, 1, figsize=(9, 6.5), sharex=True)
    freqs = np.linspace(5, 400, 2000)
    for carrier in (25.0, 50.0, 75.0):
        f = filters.band_pass(carrier, filters.default_bandwidth(carrier), 3, FS)
        response = f.response(freqs)
        ax_mag.plot(freqs, 20 * np.log10(np.abs(response)), label=f"{carrier:g} Hz, B = {0.4 * carrier:g} Hz")
        # group delay −dφ/dω from the unwrapped phase of the same response
        delay = -np.gradient(np.unwrap(np.angle(response)), 2 * np.pi * freqs)
        ax_gd.plot(freqs, delay * 1000, label=f"{carrier:g} Hz")
        at = np.interp(carrier, freqs, delay)
        print(f"{carrier:g} Hz: group delay at the carrier {at * 1000:.1f} ms; "
              + ", ".join(f"{h} Hz {20 * np.log10(abs(np.interp(h, freqs, np.abs(response)))):.1f} dB"
                          for h in (25, 50, 75, 100, 150, 300) if h != carrier))
    for harmonic in (100, 150, 300):
        ax_mag.axvline(harmonic, color="0.6", ls=":", lw=0.8)
    ax_mag.set_ylim(-90, 5)
    ax_mag.set_ylabel("magnitude [dB]")
    ax_mag.set_title("Receiver band-pass: Butterworth prototype order 3, Tustin pre-warped at the carrier, fs 4 kHz")
    ax_mag.legend(fontsize=8)
    ax_mag.grid(alpha=0.3)
    ax_gd.set_ylim(0, 150)
    ax_gd.set_ylabel("group delay [ms]")
    ax_gd.set_xlabel("frequency [Hz] (dotted: 100, 150, 300 Hz traction harmonics)")
    ax_gd.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(HERE / "receiver_bode.png", dpi=110)


def joint_waveform() -> None:
    line = load_line()
    coder = WaysideCoderCore(line, 8, N, CoderSettings(seed=3))
    receiver = LocoReceiverCore(N, ReceiverSettings())
    speed = 80 / 3.6
    t_joint = 6.0
    null_s = 1.0 / speed
    free = np.zeros(8, dtype=bool)
    emf, filtered, relay, aspect, times = [], [], [], [], []
    bp_state = receiver.band_pass.initial_state()
    for k in range(int(12.0 * FS / N)):
        t = k * N / FS
        u = coder.step(t, free).u_tx
        tt = t + np.arange(N) / FS
        # before the joint: the feed end of section 1 (strong); after: entry end of section 2
        e = np.where(tt < t_joint, u[0] / 4.0 * 3.5, np.where(tt < t_joint + null_s, 0.0, u[1] / 4.0 * 0.28))
        out = receiver.step(t, e)
        band, bp_state = sosfilt(receiver.band_pass.sos, e, zi=bp_state)
        emf.append(e)
        filtered.append(band)
        times.append(tt)
        relay.append(np.full(N, out.relay))
        aspect.append(np.full(N, out.aspect))
    t = np.concatenate(times)
    fig, axes = plt.subplots(3, 1, figsize=(10, 6.5), sharex=True,
                             gridspec_kw={"height_ratios": [3, 1, 1]})
    axes[0].plot(t, np.concatenate(filtered), lw=0.5)
    axes[0].set_ylabel("filter output [V]")
    axes[0].set_title("Code З at the band-pass output through an insulated joint at 80 km/h: 3.5 V feed end → "
                      "1 m null → 0.28 V entry end")
    axes[1].plot(t, np.concatenate(relay), lw=0.8, color="C1")
    axes[1].set_ylabel("relay")
    axes[2].plot(t, np.concatenate(aspect), lw=0.8, color="C2")
    axes[2].set_yticks([0, 2, 3, 4], ["Б", "КЖ", "Ж", "З"])
    axes[2].set_ylabel("aspect")
    axes[2].set_xlabel("time [s] (joint at 6 s)")
    for ax in axes:
        ax.axvline(t_joint, color="0.5", ls=":", lw=0.8)
        ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(HERE / "receiver_code_z.png", dpi=110)


def recovery_table() -> None:
    print("| coil EMF before the joint | ratio to 0.28 V | relay picks up again after |")
    print("|---|---|---|")
    for high in (1.0, 2.0, 3.5, 5.0):
        receiver = LocoReceiverCore(N, ReceiverSettings())
        t = np.arange(int(5 * FS)) / FS
        e = np.where(t < 2.0, high, 0.28) * np.sin(2 * np.pi * 50 * t)
        relay = np.array([receiver.step(k * N / FS, e[k * N:(k + 1) * N]).relay for k in range(t.size // N)])
        ends = (np.arange(relay.size) + 1) * N / FS
        dropped = np.flatnonzero((ends > 2.0) & ~relay)
        if dropped.size:
            back = ends[dropped[0] + np.argmax(relay[dropped[0]:])] - 2.0
            text = f"{back:.2f} s"
        else:
            text = "never drops"
        print(f"| {high:g} V | {high / 0.28:.1f} | {text} |")


if __name__ == "__main__":
    bode()
    joint_waveform()
    recovery_table()

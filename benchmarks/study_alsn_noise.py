"""ALSN code error rate against signal-to-noise ratio (target: "the code error rate vs SNR is
reported"). Not a speed benchmark: a study whose table is in docs/loco_receiver.md.

For each SNR (white noise over the whole 0–2 kHz band, carrier power A²/2 against σ²; the
in-band SNR of the 20 Hz receiver filter is 20 dB higher) with the DC-traction harmonics of the
tests (100 Hz 0.8 V, 150 Hz 0.8 V, 300 Hz 2 V against a 0.4 V code), each code (З, Ж, КЖ) from
each transmitter type (KPT-5 section 1, KPT-7 section 2) for ``--seconds`` of signal:

* cycle error rate = invalid cycles / all completed cycles;
* wrong cycles = valid cycles decoding another code than the one sent (more permissive ones
  counted apart);
* availability = share of time the shown aspect equals the code sent (after the first 4 s);
* wrong-side time = time shown more permissive than sent.

    python benchmarks/study_alsn_noise.py [--seconds 60]
"""
import argparse
import sys
from pathlib import Path

import numpy as np

from fmus.signalling import aspects as sig
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the repository: harness
from harness.channel import CodeChannel, white_noise_and_hum

HARMONICS = {100.0: 0.8, 150.0: 0.8, 300.0: 2.0}
CODES = {"З": (sig.GREEN, ()), "Ж": (sig.YELLOW, (2,)), "КЖ": (sig.RED_YELLOW, (1,))}


def occupancy(section, ahead):
    occ = np.zeros(8, dtype=bool)
    for a in ahead:
        occ[section + a] = True
    return occ


def measure(section, code_name, snr_db, seconds, seed):
    code, ahead = CODES[code_name]
    channel = CodeChannel(section, coupling=0.1)
    cycles = []
    original = channel.receiver.decoder._cycle

    def spy(short, length, time_s):
        original(short, length, time_s)
        cycles.append(channel.receiver.out.code)
    channel.receiver.decoder._cycle = spy
    rows = channel.run(seconds, occupancy(section, ahead), white_noise_and_hum(snr_db, 0.4, HARMONICS, seed))
    settled = rows[rows[:, 0] > 4.0]
    cycles = np.array(cycles)
    valid = cycles[cycles > 0]
    wrong = valid[valid != code]
    permissive = sum(sig.restrictiveness(int(c)) > sig.restrictiveness(code) for c in wrong)
    shown_permissive = [sig.restrictiveness(int(a)) > sig.restrictiveness(code) for a in settled[:, 1]]
    return {
        "cycles": cycles.size,
        "error_rate": float(np.mean(cycles == 0)) if cycles.size else 1.0,
        "wrong": int(wrong.size), "wrong_permissive": int(permissive),
        "availability": float(np.mean(settled[:, 1] == code)),
        "wrong_side_s": float(np.sum(shown_permissive) * 0.01),
    }


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--seconds", type=float, default=60.0)
    parser.add_argument("--snr", type=float, nargs="*", default=[20, 10, 5, 0, -3, -6, -9, -12])
    args = parser.parse_args()
    print("| SNR dB (in-band) | code | KPT | cycles | cycle error rate | wrong (more permissive) | availability | wrong-side s |")
    print("|---|---|---|---|---|---|---|---|")
    for snr in args.snr:
        for code_name in CODES:
            for section, kpt in ((0, "5"), (1, "7")):
                r = measure(section, code_name, snr, args.seconds, seed=int(snr * 10) + 1000 + section)
                print(f"| {snr:g} ({snr + 20:g}) | {code_name} | {kpt} | {r['cycles']} | {r['error_rate']:.3f} | "
                      f"{r['wrong']} ({r['wrong_permissive']}) | {r['availability']:.3f} | {r['wrong_side_s']:.2f} |")


if __name__ == "__main__":
    main()

"""The ALSN receiver's latencies per transmitter type over cam phases (the tables of
docs/loco_receiver.md, "Latencies"), measured on the receiver and coder cores.

    python benchmarks/receiver_latencies.py [PHASES] [--carrier HZ]   # default 16 cam phases, 50 Hz
"""
import argparse

import numpy as np

from harness.latency import table


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("phases", nargs="?", type=int, default=16, help="cam phases per case (default 16)")
    parser.add_argument("--carrier", type=float, default=50.0, help="carrier of coder and receiver, Hz (25, 50, 75)")
    args = parser.parse_args()
    print(f"carrier {args.carrier:g} Hz, {args.phases} cam phases")
    print("| what | KPT | least s | greatest s |\n|---|---|---|---|")
    for row in table(np.linspace(0.0, 1.0, args.phases, endpoint=False), carrier_hz=args.carrier):
        print(f"| {row['what']} | {row['kpt']} | {row['min_s']:.2f} | {row['max_s']:.2f} |", flush=True)


if __name__ == "__main__":
    main()

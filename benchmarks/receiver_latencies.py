"""The ALSN receiver's latencies per transmitter type over cam phases (the table of
docs/loco_receiver.md, "Latencies"), measured on the receiver and coder cores.

    python benchmarks/receiver_latencies.py [PHASES]      # default 8 cam phases
"""
import sys

import numpy as np

from harness.latency import table


def main():
    count = int(sys.argv[1]) if len(sys.argv) > 1 else 8
    print("| what | KPT | least s | greatest s |\n|---|---|---|---|")
    for row in table(np.linspace(0.0, 1.0, count, endpoint=False)):
        print(f"| {row['what']} | {row['kpt']} | {row['min_s']:.2f} | {row['max_s']:.2f} |", flush=True)


if __name__ == "__main__":
    main()

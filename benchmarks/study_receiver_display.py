"""What each receiver of a shipped system displays through a whole run (docs/loco_receiver.md,
"In the shipped systems"): display dropouts (white or red shown while a code is sent under the
coil), the time each restrictive change of the code sent took to show, and the longest time
the display was more permissive than the code sent, with the ATP's interventions and
emergency brakings.

    python benchmarks/study_receiver_display.py [NAME[:STOP_TIME] ...]   # default: free_run joints_at_speed following
"""
import sys
import tempfile
from pathlib import Path

from harness.display import analyse, with_probe
from fmus.signalling import aspects as sig
from orchestrator.cli import SSP_ROOT, _build_dir
from orchestrator.run import RunOptions, run_system

DEFAULT = ("free_run", "joints_at_speed", "following")
SETTLE_S = 10.0          # the first acquisition is not a dropout


def study(name: str, stop_time=None, fmu_dir=None):
    probes = []
    with tempfile.TemporaryDirectory() as folder:
        options = RunOptions(summaries=with_probe(probes), output_dir=Path(folder), in_process=True,
                             fmu_dirs=[fmu_dir or _build_dir()], stop_time=stop_time, record=[])
        summary = run_system(SSP_ROOT / name, options).summary
    return summary, {n: analyse(s, SETTLE_S) for n, s in probes[0].samples.items()}


def main():
    for item in sys.argv[1:] or DEFAULT:
        name, _, stop = item.partition(":")
        summary, reports = study(name, float(stop) if stop else None)
        trains = "; ".join(f"{t['name']}: interventions {t.get('atp_interventions')}, emergency "
                           f"{t.get('emergency_brakings')}" for t in summary["trains"])
        print(f"{name} ({summary['sim_time_s']:.0f} s): {trains}")
        for receiver, report in reports.items():
            print(f"  {receiver}: display dropouts {len(report.dropouts)}"
                  + "".join(f"\n    at {d['t']:.2f} s, x {d['x']:.0f} m: {sig.ASPECT_NAMES[d['shown']]} for "
                            f"{d['length_s']:.2f} s (sent {sig.ASPECT_NAMES.get(d['sent'], d['sent'])})"
                            for d in report.dropouts))
            print(f"    restrictive changes {len(report.restrictive)}, worst {report.worst_restrictive_s:.2f} s: "
                  + ", ".join(f"{sig.ASPECT_NAMES[e['from']]}→{sig.ASPECT_NAMES[e['to']]} {e['latency_s']:.2f} s"
                              for e in report.restrictive))
            print(f"    more permissive than sent: {len(report.permissive)} episodes, longest "
                  f"{report.worst_permissive_s:.2f} s", flush=True)


if __name__ == "__main__":
    main()

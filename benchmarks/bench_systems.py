"""Every shipped system in full (its own stop time and scenario), one run each, in process by
default; the verdict and the real-time factor of each (docs/performance.md, docs/scenarios.md).
The acceptance tests (tests/test_systems.py) run shortened versions of these.

    python benchmarks/bench_systems.py [NAME[:fmi] ...]     # default: every shipped system

``NAME:fmi`` runs that system through FMI instead of in process.
"""
import sys
from pathlib import Path

from orchestrator.cli import SSP_ROOT, _build_dir

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))   # `python benchmarks/X.py` from anywhere
from benchmarks._runs import scratch_run  # noqa: E402


def describe(train: dict) -> str:
    stops = ", ".join(f"{s['station']} {s['arrival_deviation_s']:+.1f} s / {s['stop_error_m']:+.2f} m"
                      for s in train.get("stops", []) if s.get("arrival_deviation_s") is not None)
    return (f"{train['name']}: {train.get('energy_kwh', 0):.1f} kWh, interventions {train.get('atp_interventions')}, "
            f"SPAD {train.get('signals_passed_at_danger')}" + (f", {stops}" if stops else "")
            + (f", min headway {train['min_headway_m']:.0f} m" if train.get("min_headway_m") is not None else "")
            + (f", departure held {train['departure_hold_s']:.1f} s" if train.get("departure_hold_s") else ""))


def main():
    names = sys.argv[1:] or sorted(p.name for p in SSP_ROOT.iterdir() if (p / "SystemStructure.ssd").is_file())
    for item in names:
        name, _, mode = item.partition(":")
        summary = scratch_run(SSP_ROOT / name, mode != "fmi", [_build_dir()], record=None).summary
        wrong_side = sum(r["wrong_side_failures"] for r in summary["receivers"])
        unsafe = sum(r.get("unsafe_indications", 0) for r in summary["receivers"])
        print(f"{name}{' through FMI' if mode == 'fmi' else ''}: {summary['sim_time_s']:.0f} s simulated in "
              f"{summary['wall_time_s']:.1f} s = {summary['realtime_factor']:.1f}x real time; wrong-side failures "
              f"{wrong_side}, unsafe indications {unsafe}; " + "; ".join(describe(t) for t in summary["trains"]),
              flush=True)


if __name__ == "__main__":
    main()

"""Robustness of the ATO to the train it drives: the plant's mass, main resistance and catenary
voltage differ from the ATO's nominal model (the ATO book's ±10 %, ±20 %, ±5 %).

The ATO and traction cores run in one closed loop (harness/closed_loop.py) on the
default line with the passenger train and a timetable of the minimum running times + 8 %; the
cab signal is green and the ATP's cab-signal supervision is off, so only the train differs.
Cases: the voltage alone at ±5 %, and the four corners (heavy + high resistance + low voltage,
…); each with both strategies and 0.1 / 0.5 / 1 s steps. Printed: arrival deviation and stop
error at B and C, energy, ATP interventions, and the worst figures (docs/traction.md).

    python benchmarks/bench_robustness.py [--steps 0.1 0.5 1.0]
"""
import argparse
import tempfile
from pathlib import Path

from harness.closed_loop import run_closed_loop, timetable_with_supplement
from fmus.ato_controller.core import AtoSettings
from fmus.traction.core import RATED_VOLTAGE_V

RATED_V = RATED_VOLTAGE_V["DC3000"]      # the default passenger train's system
RUN_S = 1100.0
#: (mass_scale, resistance_scale, voltage ratio)
CASES = [(1.0, 1.0, 1.0), (1.0, 1.0, 0.95), (1.0, 1.0, 1.05),
         (1.1, 1.2, 0.95), (1.1, 0.8, 1.05), (0.9, 1.2, 0.95), (0.9, 0.8, 1.05)]


def run_case(timetable: Path, strategy: str, step_s: float, mass: float, resistance: float, ratio: float) -> dict:
    result = run_closed_loop(RUN_S, step_s=step_s, timetable_file=timetable, mass_scale=mass,
                             resistance_scale=resistance, pantograph_voltage_v=ratio * RATED_V,
                             settings=AtoSettings(strategy=strategy, cab_signal="off"))
    arrivals = {a["station"]: a for a in result.ato.arrivals}
    return {"arrivals": arrivals, "energy_kwh": result.energy_kwh, "interventions": result.ato.atp.interventions}


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=float, nargs="+", default=[0.1, 0.5, 1.0])
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory() as folder:
        timetable = timetable_with_supplement(Path(folder))
        print("| mass | resistance | voltage | strategy | step s | B s / m | C s / m | energy kWh | interventions |")
        print("|---|---|---|---|---|---|---|---|---|")
        worst_s, worst_m, missing = (0.0, None), (0.0, None), []
        for mass, resistance, ratio in CASES:
            for strategy in ("programme", "predictive"):
                for step in args.steps:
                    case = run_case(timetable, strategy, step, mass, resistance, ratio)
                    cells = []
                    for station in ("B", "C"):
                        a = case["arrivals"].get(station)
                        if a is None:
                            missing.append((mass, resistance, ratio, strategy, step, station))
                            cells.append("not reached")
                            continue
                        label = (mass, resistance, ratio, strategy, step, station)
                        if abs(a["arrival_deviation_s"]) > abs(worst_s[0]):
                            worst_s = (a["arrival_deviation_s"], label)
                        if abs(a["stop_error_m"]) > abs(worst_m[0]):
                            worst_m = (a["stop_error_m"], label)
                        cells.append(f"{a['arrival_deviation_s']:+.1f} / {a['stop_error_m']:+.2f}")
                    print(f"| {mass:g} | {resistance:g} | {ratio * RATED_V:.0f} V | {strategy} | {step:g} | "
                          f"{cells[0]} | {cells[1]} | {case['energy_kwh']:.0f} | {case['interventions']} |", flush=True)
        print(f"\nworst arrival {worst_s[0]:+.1f} s at {worst_s[1]}; worst stop {worst_m[0]:+.2f} m at {worst_m[1]}"
              f"; stops not reached: {missing or 'none'}")


if __name__ == "__main__":
    main()

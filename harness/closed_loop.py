"""The ATO and traction cores in one closed loop, without FMI: for quick studies, the tests
and the benchmarks. The coupling is the shipped system's (ssp/free_run): Gauss-Seidel, the ATO
reads the train's position and speed at the start of each step, the train gets its command.
The cab signal comes from a function of (t, x) returning (aspect, code_valid), or for a digital
cab signal (aspect, code_valid, v_permitted_mps, v_target_mps, free_blocks), or a dict of
AtoCore.step's keyword arguments (TVM-430: target_distance, gradient, word_carrier too).
"""
from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Optional

import numpy as np

from fmus.signalling import aspects as sig
from fmus.data.loader import DEFAULT_LINE, DEFAULT_ROLLING_STOCK, DEFAULT_TIMETABLE, load_line, load_rolling_stock, load_timetable
from fmus.signalling import cab_systems
from fmus.traction.core import TractionCore
from fmus.ato_controller.core import AtoCore, AtoSettings
from fmus.ato_controller.planner import StagePlanner
from fmus.ato_controller.train_model import NominalTrain
from fmus.units import J_PER_KWH

CabSignal = Callable[[float, float], tuple]


@dataclass
class LoopResult:
    ato: AtoCore
    train: TractionCore
    # one row per step: t, x, v, command, mode, v_atp (ATP permitted), atp ceiling-equivalent, aspect
    trace: np.ndarray = field(repr=False)

    COLUMNS = ("t", "x", "v", "command", "mode", "v_atp", "aspect", "energy", "deviation")

    def column(self, name: str) -> np.ndarray:
        return self.trace[:, self.COLUMNS.index(name)]

    @property
    def energy_kwh(self) -> float:
        return self.train.out.energy_j / J_PER_KWH

    def energy_at_kwh(self, t: float) -> float:
        return float(np.interp(t, self.column("t"), self.column("energy"))) / J_PER_KWH


def run_closed_loop(stop_time_s: float, step_s: float = 0.5, settings: Optional[AtoSettings] = None,
                    line_file=DEFAULT_LINE, stock_file=DEFAULT_ROLLING_STOCK, timetable_file=DEFAULT_TIMETABLE,
                    category: Optional[str] = None, mass_scale: float = 1.0, resistance_scale: float = 1.0,
                    pantograph_voltage_v: float = 0.0, cab_signal: Optional[CabSignal] = None,
                    before_step: Optional[Callable[[float, AtoCore], None]] = None) -> LoopResult:
    """The ATO driving the traction core, one ATO step per ``step_s``; ``before_step(t, ato)``
    is called before each step (what a scenario event would set, e.g. a restriction)."""
    line = load_line(line_file)
    stock = load_rolling_stock(stock_file)
    timetable = load_timetable(timetable_file, line)
    settings = settings or AtoSettings(cab_signal=cab_systems.AtoMode.OFF if cab_signal is None else cab_systems.AtoMode.ALSN)
    ato = AtoCore(line, stock, timetable, timetable_file, category or stock.category, settings)
    train = TractionCore(stock, line, x0_m=timetable[0].stop_m, mass_scale=mass_scale,
                         resistance_scale=resistance_scale, pantograph_voltage_v=pantograph_voltage_v)
    steps = int(round(stop_time_s / step_s))
    trace = np.empty((steps, len(LoopResult.COLUMNS)))
    state = train.out
    for k in range(steps):
        t = k * step_s
        shown = cab_signal(t, state.x_m) if cab_signal else (sig.GREEN, True)
        if before_step is not None:
            before_step(t, ato)
        out = ato.step(t, step_s, state.x_m, state.v_mps, **shown) if isinstance(shown, dict) \
            else ato.step(t, step_s, state.x_m, state.v_mps, *shown)
        trace[k] = (t, state.x_m, state.v_mps, out.command, out.mode, out.v_permitted_mps, out.aspect, state.energy_j,
                    out.schedule_deviation_s)
        state = train.step(t, step_s, out.command, out.emergency_brake)
    return LoopResult(ato, train, trace)


def red_signal_ahead(line, red_signal_m: float, clear_s: float) -> CabSignal:
    """Scripted ALSN codes of a 3-aspect block with the section beyond the signal at
    ``red_signal_m`` occupied until ``clear_s``: red-yellow in the section before the signal,
    yellow in the one before that, green elsewhere and after the clear (no receiver latency;
    the ATP's own latency rules still apply)."""
    ends = [s.end_m for s in line.sections]
    k = ends.index(red_signal_m)
    ry = (line.sections[k].start_m, line.sections[k].end_m)
    y = (line.sections[k - 1].start_m, line.sections[k - 1].end_m) if k > 0 else (0.0, 0.0)

    def cab(t: float, x: float):
        if t >= clear_s:
            return sig.GREEN, True
        if ry[0] <= x < ry[1]:
            return sig.RED_YELLOW, True
        if y[0] <= x < y[1]:
            return sig.YELLOW, True
        return sig.GREEN, True
    return cab


def timetable_with_supplement(folder: Path, supplement: float = 0.08, name: str = "timetable_8pct.json") -> Path:
    """The default stops with scheduled running times = minimum time × (1 + supplement)."""
    line, stock = load_line(), load_rolling_stock()
    stop_m = {station.name: station.stop_m for station in line.stations}
    # the planning deceleration the ATO takes for this train (0.5 m/s², below 0.6 × its service
    # deceleration) and its speed margin below every limit
    planner = StagePlanner(NominalTrain(stock, line), line, "passenger", 0.5, AtoSettings().speed_margin_mps)
    t_ab = planner.plan(stop_m["A"], stop_m["B"], None).minimum_time_s * (1 + supplement)
    t_bc = planner.plan(stop_m["B"], stop_m["C"], None).minimum_time_s * (1 + supplement)
    stops = [{"station": "A", "departure_s": 60.0},
             {"station": "B", "arrival_s": round(60 + t_ab), "departure_s": round(60 + t_ab) + 60},
             {"station": "C", "arrival_s": round(60 + t_ab) + 60 + round(t_bc)}]
    path = Path(folder) / name
    path.write_text(json.dumps({"train": "supplemented", "stops": stops}))
    return path

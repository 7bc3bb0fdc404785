"""``railcosim report RUN_DIR``: pictures and a verdict table of a finished run (issue 8).

Reads what every run writes (results.csv, summary.json, metadata.json, capture_*.csv) and
the line and timetables the run's components used, and writes into RUN_DIR (or --output):

* ``speed_distance.png`` — per train: speed over distance with the ATP's permitted speed and
  the ATO's ceiling, the aspect the ATP acted on as a coloured band, block signals, stations,
  and the gradient profile below;
* ``time_distance.png`` — every train's path against its timetable (scheduled arrivals and
  departures as markers);
* ``coil_emf.png`` — the captured coil EMF around a chosen time (``--at``; default the
  middle of the capture) and the receiver band-pass output computed from it with the
  receiver's own filter design (needs a run with ``--capture rail.e_coil@T0:T1``);
* ``energy.png`` — each train's energy over time;

and prints the verdict as a short text table.
"""
from __future__ import annotations

import csv
import json
from pathlib import Path
from typing import Dict, List, Optional

import numpy as np

from orchestrator.errors import UserError

ASPECT_COLOURS = {"white": "#d0d0d0", "red": "#d62728", "red-yellow": "#ff7f0e", "yellow": "#ffd700", "green": "#2ca02c"}
ASPECT_BY_CODE = {0: "white", 1: "red", 2: "red-yellow", 3: "yellow", 4: "green"}


def read_results(run_dir: Path):
    path = run_dir / "results.csv"
    if not path.is_file():
        raise UserError(f"{run_dir}: no results.csv (not a railcosim run folder)")
    with path.open() as handle:
        reader = csv.reader(handle)
        header = next(reader, None)
        if not header:
            raise UserError(f"{path}: empty")
        rows = [[float(v) if v not in ("", "True", "False") else float(v == "True") for v in row] for row in reader]
    data = np.array(rows) if rows else np.zeros((0, len(header)))
    return {name: data[:, k] for k, name in enumerate(header)}


def _json(path: Path) -> dict:
    if not path.is_file():
        raise UserError(f"{path}: missing (not a complete railcosim run folder)")
    from orchestrator.scenario import read_json   # the one JSON reader of bad input (deep nesting included)

    return read_json(path)


def make_report(run_dir: Path, output: Optional[Path] = None, at_s: Optional[float] = None) -> List[Path]:
    import matplotlib

    matplotlib.use("Agg")
    run_dir = Path(run_dir)
    if not run_dir.is_dir():
        raise UserError(f"{run_dir}: no such run folder")
    output = Path(output) if output else run_dir
    output.mkdir(parents=True, exist_ok=True)
    results = read_results(run_dir)
    summary = _json(run_dir / "summary.json")
    metadata = _json(run_dir / "metadata.json")
    components = metadata.get("components", {})
    trains = [t for t in summary.get("trains", []) if f"{t['name']}.x" in results]
    written = []
    if trains:
        written.append(_speed_distance(output, results, trains, components,
                                       summary.get("scenario", {}).get("events_applied", [])))
        written.append(_time_distance(output, results, trains, components))
        written.append(_energy(output, results, trains))
    capture = _coil_capture(run_dir, output, components, at_s)
    if capture:
        written.append(capture)
    print(verdict_table(summary))
    return written


def _line_of(components: Dict[str, dict], ato: Optional[str]):
    from fmus.data.loader import DEFAULT_LINE, load_line

    params = components.get(ato, {}).get("parameters", {}) if ato else {}
    return load_line(params.get("line_file") or DEFAULT_LINE)


def _speed_distance(output: Path, results, trains, components, summary_events=()) -> Path:
    import matplotlib.pyplot as plt

    line = _line_of(components, trains[0].get("ato"))
    fig, axes = plt.subplots(len(trains) + 1, 1, figsize=(11, 3.2 * len(trains) + 2), sharex=True,
                             gridspec_kw={"height_ratios": [3] * len(trains) + [1]})
    axes = np.atleast_1d(axes)
    for ax, train in zip(axes, trains):
        name, ato = train["name"], train.get("ato")
        x = results[f"{name}.x"] / 1000.0
        ax.plot(x, results[f"{name}.v"] * 3.6, "k-", lw=1.2, label="speed")
        if ato and f"{ato}.v_atp" in results:
            ax.plot(x, np.minimum(results[f"{ato}.v_atp"] * 3.6, 400), "r--", lw=0.9, label="ATP permitted")
            ax.plot(x, np.minimum(results[f"{ato}.v_ceiling"] * 3.6, 400), "b:", lw=0.9, label="ATO ceiling")
            aspects = results[f"{ato}.atp_aspect"].astype(int)
            top = ax.get_ylim()[1] if ax.get_ylim()[1] > 10 else 170
            for code, colour in ((c, ASPECT_COLOURS[n]) for c, n in ASPECT_BY_CODE.items()):
                mask = aspects == code
                if mask.any():
                    ax.fill_between(x, top * 0.96, top, where=mask, color=colour, step="post", lw=0)
        for section in line.sections:
            ax.axvline(section.end_m / 1000.0, color="0.6", lw=0.6)
            ax.text(section.end_m / 1000.0, 2, section.signal, fontsize=7, ha="right", color="0.3")
        for station in line.stations:
            ax.axvline(station.stop_m / 1000.0, color="purple", lw=0.8, ls="-.")
            ax.text(station.stop_m / 1000.0, 10, station.name, color="purple")
        _draw_restrictions(ax, line, components, ato, summary_events)
        ax.set_ylabel(f"{name}: km/h")
        ax.legend(loc="lower right", fontsize=8)
        ax.grid(alpha=0.3)
    ax = axes[-1]
    starts = [g / 1000.0 for g in line.gradient_starts] + [line.length_m / 1000.0]
    grades = list(line.gradient_permille)
    ax.step(starts, grades + grades[-1:], where="post", color="brown")
    ax.set_ylabel("gradient ‰")
    ax.set_xlabel("distance (km)")
    ax.grid(alpha=0.3)
    fig.suptitle("Speed over distance: ATP permitted speed, aspect acted on (band), signals, stations, gradient")
    return _save(fig, output / "speed_distance.png")


def restrictions_drawn(line, components, ato: Optional[str], events) -> List[tuple]:
    """(start km, end km, speed km/h, label) of every temporary restriction the ATO ``ato`` was
    given: the line file's for its train category, and the scenario's ``restrict`` events (its
    ``tsr_*`` slots as set, ``t`` the time set)."""
    params = components.get(ato, {}).get("parameters", {}) if ato else {}
    category = params.get("train_category") or None
    drawn = [(r.start_m / 1000.0, r.end_m / 1000.0, r.speed_mps * 3.6, r.name or "restriction")
             for r in (line.restrictions_for(category) if category else line.restrictions)]
    slots: Dict[str, dict] = {}
    for event in events:
        variable = str(event.get("variable", ""))
        if event.get("model") != ato or not variable.startswith("tsr_") or "[" not in variable:
            continue
        name, slot = variable.split("[", 1)
        entry = slots.setdefault(slot, {"t": event.get("t", 0.0)})
        entry[name] = event.get("value") if event.get("action") == "set" else None
        if entry.get("tsr_start") is not None and entry.get("tsr_end") is not None and entry.get("tsr_speed"):
            drawn.append((entry["tsr_start"] / 1000.0, entry["tsr_end"] / 1000.0, entry["tsr_speed"] * 3.6,
                          f"set at {entry['t']:.0f} s"))
            slots.pop(slot)
    return drawn


def _draw_restrictions(ax, line, components, ato: Optional[str], events) -> None:
    """Temporary restrictions as hatched bars at their speed over their extent (head positions)."""
    for k, (start, end, speed, label) in enumerate(restrictions_drawn(line, components, ato, events)):
        ax.fill_between([start, end], 0.0, speed, color="tab:orange", alpha=0.12, hatch="//", lw=0,
                        label="temporary restriction" if k == 0 else None)
        ax.plot([start, end], [speed, speed], color="tab:orange", lw=1.4)
        ax.text(start, speed + 2.0, f"{speed:.0f} km/h {label}", fontsize=7, color="tab:orange")


def _time_distance(output: Path, results, trains, components) -> Path:
    import matplotlib.pyplot as plt
    from fmus.data.loader import DEFAULT_TIMETABLE, load_timetable

    fig, ax = plt.subplots(figsize=(11, 5))
    t = results["time"]
    for train in trains:
        name, ato = train["name"], train.get("ato")
        (handle,) = ax.plot(t, results[f"{name}.x"] / 1000.0, lw=1.2, label=name)
        if not ato:
            continue
        line = _line_of(components, ato)
        params = components.get(ato, {}).get("parameters", {})
        try:
            timetable = load_timetable(params.get("timetable_file") or DEFAULT_TIMETABLE, line)
        except Exception:
            continue
        stations = {s.name: s.stop_m for s in line.stations}
        for stop in timetable:
            for when in (stop.arrival_s, stop.departure_s):
                if when is not None:
                    ax.plot(when, stations[stop.station] / 1000.0, "o", mfc="none", color=handle.get_color())
    ax.set_xlabel("time (s)")
    ax.set_ylabel("distance (km)")
    ax.grid(alpha=0.3)
    ax.legend()
    ax.set_title("Time–distance: trains (lines) against their timetables (circles: scheduled arrival / departure)")
    return _save(fig, output / "time_distance.png")


def _energy(output: Path, results, trains) -> Path:
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(9, 4))
    for train in trains:
        ax.plot(results["time"], results[f"{train['name']}.energy"] / 3.6e6, label=train["name"])
    ax.set_xlabel("time (s)")
    ax.set_ylabel("energy (kWh)")
    ax.grid(alpha=0.3)
    ax.legend()
    return _save(fig, output / "energy.png")


def _coil_capture(run_dir: Path, output: Path, components, at_s: Optional[float]) -> Optional[Path]:
    import matplotlib.pyplot as plt
    from scipy.signal import lfilter

    captures = sorted(run_dir.glob("capture_*e_coil*.csv"))
    if not captures:
        return None
    capture = read_results_file(captures[0])
    t = capture["time"]
    columns = [name for name in capture if name != "time"]
    emf = capture[columns[0]]
    receiver = next((n for n, c in components.items() if c.get("model_identifier") == "LocoReceiver"), None)
    params = components.get(receiver, {}).get("parameters", {}) if receiver else {}
    band = _receiver_band_pass(params)
    filtered = lfilter(band.b, band.a, emf) if band is not None else None
    centre = at_s if at_s is not None else 0.5 * (t[0] + t[-1])
    window = (t >= centre - 1.0) & (t <= centre + 1.0)
    if not window.any():
        raise UserError(f"--at {at_s}: outside the capture ({t[0]:g}…{t[-1]:g} s)")
    fig, ax = plt.subplots(figsize=(11, 4))
    ax.plot(t[window], emf[window], lw=0.6, color="0.5", label=f"coil EMF ({columns[0]})")
    if filtered is not None:
        ax.plot(t[window], filtered[window], lw=0.9, color="C0", label="receiver band-pass output")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("V")
    ax.grid(alpha=0.3)
    ax.legend()
    ax.set_title(f"Coil EMF and filter output around t = {centre:.2f} s")
    return _save(fig, output / "coil_emf.png")


def _save(fig, path: Path) -> Path:
    import matplotlib.pyplot as plt

    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def read_results_file(path: Path):
    with path.open() as handle:
        reader = csv.reader(handle)
        header = next(reader)
        data = np.array([[float(v) for v in row] for row in reader])
    return {name: data[:, k] for k, name in enumerate(header)}


def _receiver_band_pass(params: dict):
    """The band-pass the receiver FMU designs from these parameters: its own settings mapping
    and filter design."""
    from fmus.loco_receiver.filters import receiver_band_pass
    from fmus.loco_receiver.parameters import receiver_settings
    from fmus.signalling import cab_systems

    system = cab_systems.DIGITAL.get(str(params.get("system", "ALSN")))
    return receiver_band_pass(receiver_settings(system, params), system)


def verdict_table(summary: dict) -> str:
    lines = [f"{summary.get('system')}: {summary.get('sim_time_s', 0):.1f} s simulated, "
             f"{summary.get('realtime_factor') or 0:.1f}× real time, completed: {summary.get('completed')}"]
    lines.append(f"{'train':12s} {'station':8s} {'sched. arr.':>11s} {'arrival':>9s} {'dev. s':>7s} {'stop err m':>10s}")
    for train in summary.get("trains", []):
        for stop in train.get("stops", []):
            sched = stop.get("scheduled_arrival_s")
            dev = stop.get("arrival_deviation_s")
            lines.append(f"{train['name']:12s} {str(stop.get('station')):8s} "
                         f"{'' if sched is None else f'{sched:.0f}':>11s} {stop.get('arrival_s', 0):9.1f} "
                         f"{'' if dev is None else f'{dev:+.1f}':>7s} {stop.get('stop_error_m', 0):+10.2f}")
        if "atp_interventions" in train:
            lines.append(f"{train['name']:12s} energy {train.get('energy_kwh', 0):.1f} kWh, max overspeed "
                         f"{train.get('max_overspeed_kmh', 0):.1f} km/h, ATP interventions {train['atp_interventions']}, "
                         f"emergency brakings {train['emergency_brakings']}, SPAD {train['signals_passed_at_danger']}")
        if train.get("min_headway_m") is not None:
            lines.append(f"{train['name']:12s} min. headway to the train ahead {train['min_headway_m']:.0f} m")
    for rx in summary.get("receivers", []):
        lines.append(f"receiver {rx['receiver']} ({rx['system']}, train {rx['train']}): decoded "
                     f"{rx.get('decoded_codes', '?')}, errors {rx.get('code_errors', '?')}, wrong-side failures "
                     f"{rx['wrong_side_failures']}, unsafe indications {rx.get('unsafe_indications', '?')}")
    if summary.get("receivers"):
        from orchestrator.analysis.verdict import safety_verdict

        lines.append(safety_verdict(summary)[1])
    if summary.get("scenario"):
        lines.append(f"scenario: {len(summary['scenario']['events_applied'])} events applied "
                     f"({summary['scenario']['file']})")
    return "\n".join(lines)

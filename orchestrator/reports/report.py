"""``railcosim report RUN_DIR``: pictures and a verdict table of a finished run.

Reads what every run writes (results.csv, summary.json, metadata.json, capture_*.csv) and
the line and timetables the run's components used, and writes into RUN_DIR (or --output):

* ``speed_distance.png`` — per train: speed over distance with the ATP's static permitted
  speed and braking curves (computed from the line file, :func:`static_speed_profile`), the
  recorded permitted speed where the cab signal holds it lower, the ATO's ceiling, the aspect
  the ATP acted on as a coloured band (keyed in the legend), block signals, stations, and the
  gradient profile below;
* ``time_distance.png`` — every train's path against its timetable (scheduled arrivals and
  departures as markers);
* ``coil_emf.png`` — the captured coil EMF around a chosen time (``--at``; default the
  middle of the capture) and the receiver band-pass output computed from it with the
  receiver's own filter design (needs a run with ``--capture rail.e_coil@T0:T1``);
* ``energy.png`` — each train's energy over time;
* ``report.html`` — one offline page for a browser: provenance, the verdict tables, the signal
  chain per train over time and the other interactive figures (orchestrator/reports/interactive.py),
  and these pictures;

and prints the verdict as a short text table.
"""
from __future__ import annotations

import csv
from pathlib import Path
from typing import Dict, Iterator, List, Optional, Sequence, Tuple

import numpy as np

from fmus.signalling.aspects import ASPECT_NAMES
from orchestrator.verdicts.verdict import RECEIVER_MODEL, safety_parts, safety_verdict, stop_cells
from orchestrator.errors import UserError, print_warning
from orchestrator.folders import create_file
from orchestrator.ports import split_element

#: the aspect enumeration's names (fmus/signalling/aspects.py), by value
ASPECT_BY_CODE = ASPECT_NAMES


def _cell(text: str) -> float:
    """A recorded value: a number, or a Boolean output as the recorder writes it (True, False)."""
    return float(text == "True") if text in ("True", "False") else float(text)


def results_rows(path: Path) -> Iterator[Tuple[int, List[float]]]:
    """The header of a results.csv or capture file the run wrote (as (1, names)), then each row
    as (its line number, its values): the one reader of those files (``report``, ``netlist
    --results``). Whatever else the file holds — text that is not a number, a row of another
    length, bytes that are not text, a line beyond the csv module's field limit — is one line
    naming ``file:line`` and the column, not a traceback."""
    try:
        with path.open(newline="", encoding="utf-8") as handle:
            reader = csv.reader(handle)
            header = next(reader, None)
            if not header or header[0] != "time":
                raise UserError(f"{path}: {'no header line' if not header else 'its first column is not time'} "
                                "(not a file a railcosim run wrote)")
            yield 1, header
            for row in reader:
                if len(row) != len(header):
                    raise UserError(f"{path}:{reader.line_num}: {len(row)} values in a row of "
                                    f"{len(header)} columns (not a file a railcosim run wrote)")
                try:
                    yield reader.line_num, [_cell(cell) for cell in row]
                except ValueError:
                    column = next(k for k, cell in enumerate(row) if not _is_cell(cell))
                    shown = row[column] if len(row[column]) <= 40 else row[column][:20] + "…"
                    raise UserError(f"{path}:{reader.line_num}: column {header[column]}: {shown!r} is not "
                                    "a number (not a file a railcosim run wrote)") from None
    except UnicodeDecodeError as error:
        raise UserError(f"{path}: not UTF-8 text (byte 0x{error.object[error.start]:02x}); "
                        "not a file a railcosim run wrote") from None
    except csv.Error as error:
        raise UserError(f"{path}: not a CSV file a railcosim run wrote ({error})") from None
    except OSError as error:
        raise UserError(f"{path}: cannot be read ({error.strerror or error})") from None


def _is_cell(text: str) -> bool:
    try:
        _cell(text)
    except ValueError:
        return False
    return True


def read_results_file(path: Path) -> Dict[str, np.ndarray]:
    """A results.csv or capture file: column name → its values (:func:`results_rows`)."""
    rows = results_rows(path)
    _, header = next(rows)
    values = [row for _, row in rows]
    data = np.array(values) if values else np.zeros((0, len(header)))
    return {name: data[:, k] for k, name in enumerate(header)}


def read_results(run_dir: Path) -> Dict[str, np.ndarray]:
    path = run_dir / "results.csv"
    if not path.is_file():
        raise UserError(f"{run_dir}: no results.csv (not a railcosim run folder)")
    return read_results_file(path)


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
    # a run recorded with --record may lack a train's speed or energy: that picture leaves it out
    moving = [t for t in trains if f"{t['name']}.v" in results]
    metered = [t for t in trains if f"{t['name']}.energy" in results]
    if moving:
        written.append(_speed_distance(output, results, moving, components,
                                       summary.get("scenario", {}).get("events_applied", [])))
    if trains:
        written.append(_time_distance(output, results, trains, components))
    if metered:
        written.append(_energy(output, results, metered))
    captured = _capture_data(run_dir)         # read once: the PNG and the page both draw it
    picture = _coil_capture(captured, output, components, at_s) if captured else None
    if picture:
        written.append(picture)
    elif at_s is not None:
        print_warning(f"--at {at_s:g}: {run_dir} has no coil-EMF capture, so there is no coil_emf.png to centre; "
                      f"run with --capture rail.e_coil@T0:T1 for one")
    print(verdict_table(summary))
    line = _line_of(components, trains[0].get("ato")) if trains else None
    written.append(write_html(output / "report.html", summary, written, metadata, results, line, captured))
    return written


def _capture_data(run_dir: Path) -> Optional[tuple]:
    """(the first coil-EMF capture's columns, its EMF column's name), or None for no capture; a
    capture without rows or without an EMF column is one line naming the file."""
    captures = sorted(run_dir.glob("capture_*e_coil*.csv"))
    if not captures:
        return None
    capture = read_results_file(captures[0])
    columns = [name for name in capture if name != "time"]
    if not columns or not len(capture["time"]):
        raise UserError(f"{captures[0]}: {'no rows' if columns else 'no EMF column'} (not a capture a railcosim "
                        "run wrote)")
    return capture, columns[0]


def _parameters_of(components: Dict[str, dict], name: Optional[str]) -> dict:
    """A component's parameters as metadata.json records them ({} for none or no component)."""
    return components.get(name, {}).get("parameters", {}) if name else {}


def _line_of(components: Dict[str, dict], ato: Optional[str]):
    from fmus.data.loader import DEFAULT_LINE, load_line

    params = _parameters_of(components, ato)
    return load_line(params.get("line_file") or DEFAULT_LINE)


#: how each aspect the ATP acted on is drawn in the band above the speed curves: (face, hatch
#: colour); red-yellow is the two lights, a yellow band hatched red
ASPECT_STYLES = {"white": ("#e8e8e8", None), "red": ("#d62728", None), "red-yellow": ("#ffd700", "#d62728"),
                 "yellow": ("#ffd700", None), "green": ("#2ca02c", None)}


def static_speed_profile(line, params: dict, x_m: np.ndarray):
    """The ATP's static permitted speed along ``x_m`` (m/s) from the line file: the line limit
    for the train's category, held until the tail has cleared a lower limit
    (fmus/ato_controller/atp.py, ``Atp.static_limit``), and beneath it the braking curves
    v = sqrt(v_t² + 2·a·(x_t − x)) down to each lower limit x_t, with the ATP's supervision
    deceleration a (parameter ``atp_decel``, default 0.7 × the stock's service deceleration,
    as the ATO controller sets it). Returns (static, with_curves, a)."""
    from fmus.ato_controller.atp import Atp
    from fmus.ato_controller.core import default_atp_decel_mps2
    from fmus.data.loader import DEFAULT_ROLLING_STOCK, load_rolling_stock

    stock = load_rolling_stock(params.get("rolling_stock_file") or DEFAULT_ROLLING_STOCK)
    category = params.get("train_category") or stock.category
    decel = float(params.get("atp_decel") or 0.0) or default_atp_decel_mps2(stock)
    # the ATP's own static limit at each point (no cab signal: the line's limits only)
    atp = Atp(line, category, stock.length_m, "off", decel, 0.0)
    static = np.fromiter(map(atp.static_limit, x_m), float, count=len(x_m))
    starts, limits = np.array(atp.limit_starts), np.array(atp.limits)
    curves = static.copy()
    for k in range(1, len(limits)):
        if limits[k] < limits[k - 1]:
            ahead = x_m < starts[k]
            reach = np.sqrt(limits[k] ** 2 + 2.0 * decel * np.clip(starts[k] - x_m, 0.0, None))
            curves = np.where(ahead, np.minimum(curves, reach), curves)
    return static, curves, decel


def _aspect_band(ax, x, aspects: np.ndarray, bottom: float, top: float) -> None:
    for code, name in ASPECT_BY_CODE.items():
        mask = aspects == code
        if mask.any():
            face, hatch = ASPECT_STYLES[name]
            ax.fill_between(x, bottom, top, where=mask, step="post", lw=0, facecolor=face,
                            edgecolor=hatch or face, hatch="////" if hatch else None)


def _aspect_key(ax, aspects: np.ndarray) -> list:
    from matplotlib.patches import Patch

    shown = [ASPECT_BY_CODE[c] for c in sorted(ASPECT_BY_CODE) if (aspects == c).any()]
    return [Patch(facecolor=ASPECT_STYLES[n][0], edgecolor=ASPECT_STYLES[n][1] or ASPECT_STYLES[n][0],
                  hatch="////" if ASPECT_STYLES[n][1] else None, label=f"aspect: {n}") for n in shown]


def _line_marks(ax, line) -> None:
    """Block signals (grey, named at the foot) and stations (purple, named above the panel),
    so that no name sits on another or under the legend."""
    from matplotlib.transforms import blended_transform_factory

    marks = blended_transform_factory(ax.transData, ax.transAxes)
    for section in line.sections:
        if section.signal:
            ax.axvline(section.end_m / 1000.0, color="0.6", lw=0.6)
            ax.text(section.end_m / 1000.0, 0.015, f" {section.signal}", fontsize=7, ha="left", va="bottom",
                    color="0.3", transform=marks)
    # a station name goes up a row when it would touch the one before (A and "A east" 500 m apart)
    km_per_char = 0.012 * line.length_m / 1000.0
    row_ends: List[float] = []
    for station in line.stations:
        at_km = station.stop_m / 1000.0
        half = 0.5 * km_per_char * (len(station.name) + 1)
        row = next((k for k, end in enumerate(row_ends) if at_km - half > end), len(row_ends))
        row_ends[row:row + 1] = [at_km + half]
        ax.axvline(at_km, color="purple", lw=0.8, ls="-.")
        ax.text(at_km, 1.01 + 0.07 * row, station.name, color="purple", ha="center", va="bottom",
                transform=marks, fontweight="bold")


def _speed_distance(output: Path, results, trains, components, summary_events=()) -> Path:
    import matplotlib.pyplot as plt

    line = _line_of(components, trains[0].get("ato"))
    height_in = 3.6 * len(trains) + 2
    fig, axes = plt.subplots(len(trains) + 1, 1, figsize=(12, height_in), sharex=True,
                             gridspec_kw={"height_ratios": [3] * len(trains) + [1]})
    axes = np.atleast_1d(axes)
    grid_m = np.arange(0.0, line.length_m + 1.0, 1.0)
    for ax, train in zip(axes, trains):
        name, ato = train["name"], train.get("ato")
        x = results[f"{name}.x"] / 1000.0
        speed = results[f"{name}.v"] * 3.6
        ax.plot(x, speed, "k-", lw=1.3, label="speed")
        top = max(float(np.nanmax(speed, initial=0.0)), 10.0)
        key = []
        if ato and all(f"{ato}.{port}" in results for port in ("v_atp", "v_ceiling", "atp_aspect")):
            static, curves, decel = static_speed_profile(line, _parameters_of(components, ato), grid_m)
            ax.plot(grid_m / 1000.0, static * 3.6, "r-", lw=1.0, label="static permitted speed (line limits)")
            ax.plot(grid_m / 1000.0, np.where(curves < static, curves, np.nan) * 3.6, "r--", lw=0.9,
                    label=f"braking curves to lower limits ({decel:.2f} m/s²)")
            # what the cab signal adds: the recorded permitted speed where it is below the line's
            permitted = results[f"{ato}.v_atp"] * 3.6
            line_curve = np.interp(results[f"{name}.x"], grid_m, curves) * 3.6
            below = permitted < line_curve - 1.0
            if below.any():
                ax.plot(x, np.where(below, permitted, np.nan), color="darkred", ls=":", lw=1.2,
                        label="ATP permitted speed below it (cab signal)")
            # ato.v_ceiling holds the line limit and the cab-signal ceiling, not the targets: under
            # a yellow aspect (no ceiling, a target at the next signal) it is the line limit, and
            # a red-yellow → yellow → red-yellow sequence would draw a spike to it. The ATO never
            # runs above the ATP's permitted speed, so that caps what is drawn.
            ax.plot(x, np.minimum(results[f"{ato}.v_ceiling"] * 3.6, permitted), color="tab:blue", ls=":",
                    lw=0.9, label="ATO ceiling (at most the ATP permitted speed)")
            top = max(top, float(np.nanmax(static[np.isfinite(static)], initial=0.0)) * 3.6)
            aspects = results[f"{ato}.atp_aspect"].astype(int)
            _aspect_band(ax, x, aspects, top * 1.08, top * 1.14)
            key = _aspect_key(ax, aspects)
        ax.set_ylim(0.0, top * 1.15)
        _line_marks(ax, line)
        _draw_restrictions(ax, line, components, ato, summary_events)
        ax.set_ylabel("speed (km/h)")
        handles, _ = ax.get_legend_handles_labels()
        ax.legend(handles=handles + key, loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8,
                  borderaxespad=0.0, title=name if "train" in name.lower() else f"train {name}", title_fontsize=9, alignment="left")
        ax.grid(alpha=0.3)
    ax = axes[-1]
    starts = [g / 1000.0 for g in line.gradient_starts] + [line.length_m / 1000.0]
    grades = list(line.gradient_permille)
    ax.step(starts, grades + grades[-1:], where="post", color="brown")
    ax.set_ylabel("gradient (‰)")
    ax.set_xlabel("distance (km)")
    ax.grid(alpha=0.3)
    # the title and the panels' layout in inches from the top: a fraction of a 16-train
    # figure's height would put the title over the first panel
    fig.suptitle("Speed over distance: static permitted speed and braking curves (ATP), ATO ceiling, "
                 "aspect acted on (band), signals, stations, gradient", fontsize=10, y=1.0 - 0.1 / height_in, va="top")
    return _save(fig, output / "speed_distance.png", top=1.0 - 0.4 / height_in)


def restrictions_drawn(line, components, ato: Optional[str], events) -> List[tuple]:
    """(start km, end km, speed km/h, label) of every temporary restriction the ATO ``ato`` was
    given: the line file's for its train category, and the scenario's ``restrict`` events (its
    ``tsr_*`` slots as set, ``t`` the time set)."""
    params = _parameters_of(components, ato)
    category = params.get("train_category") or None
    drawn = [(r.start_m / 1000.0, r.end_m / 1000.0, r.speed_mps * 3.6, r.name or "restriction")
             for r in (line.restrictions_for(category) if category else line.restrictions)]
    slots: Dict[Tuple[int, ...], dict] = {}
    for event in events:
        name, slot = split_element(str(event.get("variable", ""))) or ("", ())
        if event.get("model") != ato or not name.startswith("tsr_") or not slot:
            continue
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


def train_styles(names: Sequence[str]) -> Dict[str, dict]:
    """A colour and line style per train, distinct for any number of trains: the ten colours of
    matplotlib's cycle, then the same ten dashed, dotted, dash-dotted (16 trains would otherwise
    repeat six colours, and two trains' lines and legend entries would look alike)."""
    styles = ("-", "--", ":", "-.")
    return {name: {"color": f"C{k % 10}", "ls": styles[(k // 10) % len(styles)]} for k, name in enumerate(names)}


def _legend_outside(ax, entries: int) -> None:
    """The key beside the axes, in columns of at most 20 entries, so that it never hides a line."""
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0, fontsize=8 if entries > 10 else None,
              ncol=-(-entries // 20))


def _time_distance(output: Path, results, trains, components) -> Path:
    import matplotlib.pyplot as plt
    from fmus.data.loader import DEFAULT_TIMETABLE, load_timetable

    fig, ax = plt.subplots(figsize=(11, 5))
    t = results["time"]
    styles = train_styles([train["name"] for train in trains])
    lines: Dict[str, object] = {}     # each line file loaded once, however many trains run on it
    for train in trains:
        name, ato = train["name"], train.get("ato")
        ax.plot(t, results[f"{name}.x"] / 1000.0, lw=1.2, label=name, **styles[name])
        if not ato:
            continue
        params = _parameters_of(components, ato)
        line_file = params.get("line_file") or ""
        if line_file not in lines:
            lines[line_file] = _line_of(components, ato)
        line = lines[line_file]
        try:
            timetable = load_timetable(params.get("timetable_file") or DEFAULT_TIMETABLE, line)
        except Exception:
            continue
        stations = {s.name: s.stop_m for s in line.stations}
        for stop in timetable:
            for when in (stop.arrival_s, stop.departure_s):
                if when is not None:
                    ax.plot(when, stations[stop.station] / 1000.0, "o", mfc="none", color=styles[name]["color"])
    ax.set_xlabel("time (s)")
    ax.set_ylabel("distance (km)")
    ax.grid(alpha=0.3)
    _legend_outside(ax, len(trains))
    ax.set_title("Time–distance: trains (lines) against their timetables (circles: scheduled arrival / departure)")
    return _save(fig, output / "time_distance.png")


def _energy(output: Path, results, trains) -> Path:
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(9, 4))
    styles = train_styles([train["name"] for train in trains])
    for train in trains:
        name = train["name"]
        ax.plot(results["time"], results[f"{name}.energy"] / 3.6e6, label=name, **styles[name])
    ax.set_xlabel("time (s)")
    ax.set_ylabel("energy (kWh)")
    ax.grid(alpha=0.3)
    _legend_outside(ax, len(trains))
    ax.set_title("Energy from the line per train (drawn − returned by regenerative braking)")
    return _save(fig, output / "energy.png")


def _coil_capture(captured: tuple, output: Path, components, at_s: Optional[float]) -> Path:
    """coil_emf.png from a capture (:func:`_capture_data`)."""
    import matplotlib.pyplot as plt
    from scipy.signal import sosfilt

    capture, column = captured
    t = capture["time"]
    emf = capture[column]
    receiver = next((n for n, c in components.items() if c.get("model_identifier") == RECEIVER_MODEL), None)
    params = _parameters_of(components, receiver)
    band = _receiver_band_pass(params)
    filtered = sosfilt(band.sos, emf) if band is not None else None
    centre = at_s if at_s is not None else 0.5 * (t[0] + t[-1])
    window = (t >= centre - 1.0) & (t <= centre + 1.0)
    if not window.any():
        raise UserError(f"--at {at_s}: outside the capture ({t[0]:g}…{t[-1]:g} s)")
    fig, ax = plt.subplots(figsize=(11, 4))
    ax.plot(t[window], emf[window], lw=0.6, color="0.5", label=f"coil EMF ({column})")
    if filtered is not None:
        ax.plot(t[window], filtered[window], lw=0.9, color="C0", label="receiver band-pass output")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("V")
    ax.grid(alpha=0.3)
    ax.legend()
    ax.set_title(f"Coil EMF and filter output around t = {centre:.2f} s")
    return _save(fig, output / "coil_emf.png")


def _save(fig, path: Path, top: float = 1.0) -> Path:
    """Lay the figure out below ``top`` (a fraction of its height: room for a title) and write it."""
    import matplotlib.pyplot as plt

    fig.tight_layout(rect=(0.0, 0.0, 1.0, top))
    with create_file(path, binary=True) as handle:     # never through a link planted at its name
        fig.savefig(handle, format="png", dpi=100)
    plt.close(fig)
    return path


def _receiver_band_pass(params: dict):
    """The band-pass the receiver FMU designs from these parameters: its own settings mapping
    and filter design; None for a receiver of several carriers or tones (ALSU's six channels,
    TVM's track carriers: the EMF alone is drawn) or an unknown system."""
    from fmus.errors import FmuInputError
    from fmus.loco_receiver.filters import receiver_band_pass
    from fmus.loco_receiver.parameters import receiver_settings
    from fmus.signalling import cab_systems

    try:
        cab = cab_systems.of_parameters(params)
    except FmuInputError:
        return None
    if not cab.one_carrier:
        return None
    system = cab.system()
    return receiver_band_pass(receiver_settings(cab.name, params), system)


# ---- report.html ---------------------------------------------------------------------------------
CAPTIONS = {
    "speed_distance.png": "Speed over distance per train: the static permitted speed from the line file and "
                          "the ATP's braking curves to each lower limit, the ATP's permitted speed where the cab "
                          "signal holds it lower, the ATO's ceiling, the aspect acted on (band), block signals, "
                          "stations and the gradient.",
    "time_distance.png": "Time–distance: each train's path against its timetable (circles: scheduled arrivals "
                         "and departures).",
    "energy.png": "Energy from the line per train (drawn − returned).",
    "coil_emf.png": "Captured coil EMF and the receiver's band-pass output computed from it.",
}


def verdict_items(summary: dict) -> Tuple[List[List[str]], List[Tuple[str, str]]]:
    """The verdict as table rows: one per timetabled stop of each train (train, station,
    scheduled arrival, arrival, deviation, stop error, result), then one per further judgement
    (what, verdict): each train's supervision, headway, each receiver, the safety verdict."""
    stops, others = [], []
    for train in summary.get("trains", []):
        for stop in train.get("stops", []):
            *cells, reached = stop_cells(stop)
            stops.append([train["name"], *cells, "reached" if reached else "not reached"])
        if "atp_interventions" in train:
            others.append((f"train {train['name']}: supervision",
                           f"energy {train.get('energy_kwh', 0):.1f} kWh, max overspeed "
                           f"{train.get('max_overspeed_kmh', 0):.1f} km/h, ATP interventions "
                           f"{train['atp_interventions']}, emergency brakings {train['emergency_brakings']}, "
                           f"SPAD {train['signals_passed_at_danger']}"))
        if train.get("min_headway_m") is not None:
            others.append((f"train {train['name']}: headway",
                           f"min. headway to the train ahead {train['min_headway_m']:.0f} m"))
    for rx in summary.get("receivers", []):
        others.append((f"receiver {rx['receiver']} ({rx['system']}, train {rx['train']})",
                       f"decoded {rx.get('decoded_codes', '?')}, errors {rx.get('code_errors', '?')}, "
                       f"wrong-side failures {rx['wrong_side_failures']}, unsafe indications "
                       f"{rx.get('unsafe_indications', '?')}"))
    if summary.get("receivers"):
        others.append(("safety", safety_parts(summary)[1]))
    return stops, others


def write_html(path: Path, summary: dict, pictures: Sequence[Path], metadata: Optional[dict] = None,
               results: Optional[Dict[str, np.ndarray]] = None, line=None, capture: Optional[tuple] = None) -> Path:
    """report.html beside the pictures: provenance, the verdict tables, the interactive figures
    (orchestrator/reports/interactive.py) and every picture."""
    from html import escape

    from orchestrator.reports import interactive

    stops, others = verdict_items(summary)
    head = ("train", "station", "scheduled arrival (s)", "arrival (s)", "deviation (s)", "stop error (m)", "result")
    rows = "\n".join("<tr class=\"verdict{}\">{}</tr>".format(
        " missed" if row[-1] == "not reached" else "",
        "".join(f"<td>{escape(cell)}</td>" for cell in row)) for row in stops)
    more = "\n".join(f"<tr class=\"verdict\"><th scope=\"row\">{escape(what)}</th><td>{escape(text)}</td></tr>"
                      for what, text in others)
    figures = "\n".join(
        f"<figure><img src=\"{escape(p.name)}\" alt=\"{escape(p.stem)}\">"
        f"<figcaption>{escape(CAPTIONS.get(p.name, p.name))}</figcaption></figure>"
        for p in pictures if p.suffix == ".png")
    scenario = summary.get("scenario")
    lines = [f"{summary.get('sim_time_s', 0):.1f} s simulated, "
             f"{summary.get('realtime_factor') or 0:.1f}× real time, completed: {summary.get('completed')}"]
    if summary.get("error"):
        lines.append(f"stopped: {summary['error']}")
    if scenario:
        lines.append(f"scenario: {len(scenario['events_applied'])} events applied ({scenario['file']})")
    tables = f"""{"".join(f"<p>{escape(line)}</p>" for line in lines)}
<h2>Stops</h2>
<table id="stops"><thead><tr>{"".join(f"<th>{h}</th>" for h in head)}</tr></thead>
<tbody>
{rows}
</tbody></table>
<h2>Supervision and safety</h2>
<table id="judgements"><tbody>
{more}
</tbody></table>"""
    results = results if results is not None else {"time": np.zeros(0)}
    return interactive.write(path, interactive.page(summary, metadata or {}, results, line, tables, figures, capture))


def verdict_table(summary: dict) -> str:
    lines = [f"{summary.get('system')}: {summary.get('sim_time_s', 0):.1f} s simulated, "
             f"{summary.get('realtime_factor') or 0:.1f}× real time, completed: {summary.get('completed')}"]
    lines.append(f"{'train':12s} {'station':8s} {'sched. arr.':>11s} {'arrival':>9s} {'dev. s':>7s} {'stop err m':>10s}")
    for train in summary.get("trains", []):
        for stop in train.get("stops", []):
            station, sched, arrival, dev, error, reached = stop_cells(stop)
            figures = f"{arrival:>9s} {dev:>7s} {error:>10s}" if reached else f"{'not reached':>9s}"
            lines.append(f"{train['name']:12s} {station:8s} {sched:>11s} {figures}")
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
        lines.append(safety_verdict(summary)[1])
    if summary.get("scenario"):
        lines.append(f"scenario: {len(summary['scenario']['events_applied'])} events applied "
                     f"({summary['scenario']['file']})")
    return "\n".join(lines)

"""``report.html``: one self-contained page a browser opens offline — the run's provenance and
verdict tables, and interactive figures (zoom, pan, hover values, time axes linked across
figures) drawn with Bokeh, its JavaScript inlined (no CDN, no request to anywhere):

* per train, against time, the signal chain in its cab system's own terms (code sent under the
  coils → code decoded → indication shown, orchestrator/reports/chain_view.py), each receiver
  error marked with its cause, wrong-side and unsafe episodes and scenario events marked; below
  it the ATP's permitted speed and the train's speed;
* the time–distance diagram: every train's head, block signals, stations, and the track
  circuits' occupancy;
* the captured coil EMF, or how to capture it;
* the static PNGs (for papers) below.

Why Bokeh: docs/architecture.md#dependencies.
"""
from __future__ import annotations

from html import escape
from pathlib import Path
from typing import Dict, List, Mapping, Optional, Sequence

import numpy as np

from fmus.units import KMH_PER_MPS
from orchestrator.folders import create_file
from orchestrator.reports import chain_view
from orchestrator.reports.chain_view import TrainChain

#: at most this many points per drawn series: a run at a 1 ms output interval would otherwise
#: make a page of hundreds of MB (every k-th row is kept; the steps of the chain rows are exact)
MAX_POINTS = 20000
ROWS = ("indication shown", "code decoded", "code sent under the coils")
#: the BokehJS bundles inlined: the core draws every figure here; its widgets, tables and
#: MathJax bundles (2.7 MB more) are for models this page does not use
BOKEH_BUNDLES = ("bokeh",)
EPISODE_COLOURS = {"wrong-side": "#b00000", "unsafe": "#ff00ff", "event": "#1f77b4"}
CAUSE_MARKERS = {"section change": "triangle", "code change": "diamond", "no code": "square",
                 "acquisition": "circle", "steady code": "x"}


def _thin(*columns: np.ndarray):
    stride = max(1, -(-len(columns[0]) // MAX_POINTS))
    return [np.asarray(c)[::stride] for c in columns]


def chain_figure(chain: TrainChain, x_range):
    from bokeh.models import ColumnDataSource, HoverTool, LabelSet
    from bokeh.plotting import figure

    fig = figure(height=190, sizing_mode="stretch_width", x_range=x_range, y_range=list(ROWS),
                 tools="xpan,xwheel_zoom,box_zoom,reset,save", active_scroll="xwheel_zoom",
                 title=f"train {chain.train}: {chain.cab.title} chain (receiver {chain.receiver}) — "
                       f"sent under the coils → decoded → shown", toolbar_location="above")
    segments = {"row": [], "left": [], "right": [], "label": [], "colour": [], "detail": [], "hatch": []}
    for row, parts in zip(ROWS, (chain.shown, chain.decoded, chain.sent)):
        for seg in parts:
            hatch = "x" if seg.hatched else " "
            for key, value in zip(segments, (row, seg.t0_s, seg.t1_s, seg.label, seg.colour, seg.detail, hatch)):
                segments[key].append(value)
    source = ColumnDataSource(segments)
    bars = fig.hbar(y="row", left="left", right="right", height=0.8, fill_color="colour", line_color="#888888",
                    line_width=0.3, hatch_pattern="hatch", hatch_color="#555555", hatch_alpha=0.6, source=source)
    fig.add_tools(HoverTool(renderers=[bars], tooltips=[("", "@row: @label"), ("from", "@left{0.0} s"),
                                                         ("to", "@right{0.0} s"), ("", "@detail")]))
    # each run of one label named once, where its name fits (at ~1100 px for the whole run)
    span = max(max((s.t1_s for s in chain.sent), default=1.0) - min((s.t0_s for s in chain.sent), default=0.0), 1e-9)
    named = {"row": [], "middle": [], "label": []}
    for row, parts in zip(ROWS, (chain.shown, chain.decoded, chain.sent)):
        for label, left, right in merged_labels(parts):
            if (right - left) / span * 1100.0 > 7.0 * len(label) + 8.0:
                for key, value in zip(named, (row, 0.5 * (left + right), label)):
                    named[key].append(value)
    fig.add_layout(LabelSet(x="middle", y="row", text="label", text_align="center", text_baseline="middle",
                            text_font_size="9pt", source=ColumnDataSource(named)))
    if chain.errors:
        errors = ColumnDataSource({"t": [e.t_s for e in chain.errors], "row": [ROWS[1]] * len(chain.errors),
                                   "cause": [e.cause for e in chain.errors],
                                   "explanation": [e.explanation for e in chain.errors],
                                   "marker": [CAUSE_MARKERS.get(e.cause, "x") for e in chain.errors],
                                   "count": [e.count for e in chain.errors]})
        marks = fig.scatter(x="t", y="row", marker="marker", size=11, fill_color="white", line_color="black",
                            line_width=1.5, source=errors, legend_field="cause")
        fig.add_tools(HoverTool(renderers=[marks], tooltips=[("receiver error", "@count at @t{0.0} s"),
                                                              ("cause", "@cause"), ("", "@explanation")]))
        fig.legend.label_text_font_size = "8pt"
        fig.legend.title = "receiver errors"
        _legend_outside(fig)
    _episodes(fig, chain.episodes, ROWS[0])
    fig.xaxis.axis_label = "time (s)"
    return fig


def merged_labels(parts: Sequence[chain_view.Segment]) -> List[tuple]:
    """(label, t0, t1) of each run of consecutive segments with the same label."""
    merged: List[list] = []
    for seg in parts:
        if merged and merged[-1][0] == seg.label and merged[-1][2] == seg.t0_s:
            merged[-1][2] = seg.t1_s
        else:
            merged.append([seg.label, seg.t0_s, seg.t1_s])
    return [tuple(m) for m in merged]


def _episodes(fig, found: Sequence[chain_view.Episode], row=None) -> None:
    """Each episode a dashed line across ``fig``; with ``row``, a marker on it to hover."""
    from bokeh.models import ColumnDataSource, HoverTool, Span

    for episode in found:
        fig.add_layout(Span(location=episode.t_s, dimension="height", line_color=EPISODE_COLOURS[episode.kind],
                            line_dash="dashed", line_width=1.5 if row is not None else 1.0))
    if not found or row is None:
        return
    source = ColumnDataSource({"t": [e.t_s for e in found], "row": [row] * len(found),
                               "kind": [e.kind for e in found], "text": [e.text for e in found],
                               "colour": [EPISODE_COLOURS[e.kind] for e in found]})
    marks = fig.scatter(x="t", y="row", marker="inverted_triangle", size=12, color="colour", source=source)
    fig.add_tools(HoverTool(renderers=[marks], tooltips=[("", "@kind at @t{0.0} s"), ("", "@text")]))


def speed_figure(results: Mapping[str, np.ndarray], train: str, ato: Optional[str], receiver: Optional[str], x_range,
                 found: Sequence[chain_view.Episode] = ()):
    from bokeh.models import ColumnDataSource, HoverTool
    from bokeh.plotting import figure

    fig = figure(height=260, sizing_mode="stretch_width", x_range=x_range, tools="xpan,xwheel_zoom,box_zoom,reset,save",
                 active_scroll="xwheel_zoom", title=f"train {train}: speed and the ATP's permitted speed",
                 toolbar_location="above", y_axis_label="km/h", x_axis_label="time (s)")
    columns = {"time": results["time"], "speed": results[f"{train}.v"] * KMH_PER_MPS,
               "x_km": results[f"{train}.x"] / 1000.0}
    drawn = [("speed", "train speed", "black", "solid")]
    if ato and f"{ato}.v_atp" in results:
        columns["permitted"] = results[f"{ato}.v_atp"] * KMH_PER_MPS
        drawn.append(("permitted", "ATP permitted speed", "#d62728", "solid"))
    if ato and f"{ato}.v_ref" in results:
        columns["reference"] = results[f"{ato}.v_ref"] * KMH_PER_MPS
        drawn.append(("reference", "ATO reference speed", "#1f77b4", "dotted"))
    if receiver and f"{receiver}.v_target" in results:
        columns["target"] = results[f"{receiver}.v_target"] * KMH_PER_MPS
        drawn.append(("target", "cab-signal target speed", "#ff7f0e", "dashed"))
    names = list(columns)
    source = ColumnDataSource(dict(zip(names, _thin(*columns.values()))))
    renderers = [fig.line(x="time", y=key, legend_label=label, color=colour, line_dash=dash, line_width=1.6 if key == "speed" else 1.1,
                          source=source) for key, label, colour, dash in drawn]
    fig.add_tools(HoverTool(renderers=renderers[:1], mode="vline",
                            tooltips=[("t", "@time{0.0} s"), ("x", "@x_km{0.000} km")]
                            + [(label, f"@{key}{{0.0}} km/h") for key, label, _, _ in drawn]))
    fig.legend.click_policy = "hide"
    fig.legend.label_text_font_size = "8pt"
    _legend_outside(fig)
    _episodes(fig, found)
    return fig


def time_distance_figure(results: Mapping[str, np.ndarray], trains: Sequence[str], line, rails: Sequence[str], x_range):
    from bokeh.models import ColumnDataSource, HoverTool, Label, Span
    from bokeh.palettes import Category10_10
    from bokeh.plotting import figure

    fig = figure(height=420, sizing_mode="stretch_width", x_range=x_range, tools="pan,wheel_zoom,box_zoom,reset,save",
                 active_scroll="wheel_zoom", title="time–distance: trains, block signals, stations and occupied track "
                                                    "circuits (grey)", toolbar_location="above",
                 x_axis_label="time (s)", y_axis_label="distance (km)")
    if line is not None:
        for rail in rails:
            spans = chain_view.occupancy(results, rail)
            quads = {"left": [], "right": [], "bottom": [], "top": [], "circuit": []}
            for k, times in spans.items():
                if k > len(line.sections):
                    continue
                section = line.sections[k - 1]
                for t0, t1 in times:
                    for key, value in zip(quads, (t0, t1, section.start_m / 1000.0, section.end_m / 1000.0, k)):
                        quads[key].append(value)
            if quads["left"]:
                occupied = fig.quad(left="left", right="right", bottom="bottom", top="top", fill_color="#bbbbbb",
                                    fill_alpha=0.5, line_color=None, source=ColumnDataSource(quads),
                                    legend_label="circuit occupied")
                fig.add_tools(HoverTool(renderers=[occupied], tooltips=[("circuit", "@circuit"),
                                                                         ("occupied", "@left{0.0} – @right{0.0} s")]))
        for section in line.sections:
            if section.signal:
                fig.add_layout(Span(location=section.end_m / 1000.0, dimension="width", line_color="#999999",
                                    line_width=0.6, line_dash="dotted"))
                fig.add_layout(Label(x=0, y=section.end_m / 1000.0, x_units="screen", text=section.signal,
                                     text_font_size="7pt", text_color="#555555"))
        for station in line.stations:
            fig.add_layout(Span(location=station.stop_m / 1000.0, dimension="width", line_color="purple",
                                line_width=0.8, line_dash="dashdot"))
            fig.add_layout(Label(x=40, y=station.stop_m / 1000.0, x_units="screen", text=station.name,
                                 text_font_size="8pt", text_color="purple"))
    drawn = []
    for k, train in enumerate(trains):
        time, x = _thin(results["time"], results[f"{train}.x"] / 1000.0)
        speed = _thin(results[f"{train}.v"] * KMH_PER_MPS if f"{train}.v" in results
                      else np.full(len(results["time"]), np.nan))[0]
        source = ColumnDataSource({"time": time, "x_km": x, "speed": speed, "train": [train] * len(time)})
        drawn.append(fig.line(x="time", y="x_km", color=Category10_10[k % 10], line_width=1.6, legend_label=train,
                              line_dash=("solid", "dashed", "dotted", "dotdash")[(k // 10) % 4], source=source))
    fig.add_tools(HoverTool(renderers=drawn, tooltips=[("train", "@train"), ("t", "@time{0.0} s"),
                                                        ("x", "@x_km{0.000} km"), ("v", "@speed{0.0} km/h")]))
    if fig.legend:
        fig.legend.click_policy = "hide"
        fig.legend.label_text_font_size = "8pt"
        _legend_outside(fig)
    return fig


def _legend_outside(fig) -> None:
    """The key to the right of the plot, where it hides no data."""
    legend = fig.legend[0]
    fig.center.remove(legend)
    fig.add_layout(legend, "right")


def coil_figure(capture: Mapping[str, np.ndarray], column: str):
    """The captured EMF; a capture of more than :data:`MAX_POINTS` samples as its envelope (the
    minimum and maximum of each run of samples): keeping every k-th sample of a 12 kHz capture
    would alias a 2300 Hz carrier to 1700 Hz."""
    from bokeh.models import ColumnDataSource, HoverTool
    from bokeh.plotting import figure

    time, emf = np.asarray(capture["time"]), np.asarray(capture[column])
    fig = figure(height=260, sizing_mode="stretch_width", tools="xpan,xwheel_zoom,box_zoom,reset,save",
                 active_scroll="xwheel_zoom", toolbar_location="above", x_axis_label="time (s)", y_axis_label="V",
                 title=f"captured coil EMF ({column})")
    if len(time) > MAX_POINTS:
        per = -(-len(time) // (MAX_POINTS // 2))
        usable = len(time) // per * per
        buckets = emf[:usable].reshape(-1, per)
        source = ColumnDataSource({"time": time[:usable:per], "low": buckets.min(axis=1), "high": buckets.max(axis=1)})
        band = fig.varea(x="time", y1="low", y2="high", source=source, fill_alpha=0.6,
                         legend_label=f"envelope (min–max of every {per} samples)")
        fig.add_tools(HoverTool(renderers=[band], mode="vline",
                                tooltips=[("t", "@time{0.0000} s"), ("min", "@low{0.0000} V"), ("max", "@high{0.0000} V")]))
        return fig
    line = fig.line(x="time", y="emf", source=ColumnDataSource({"time": time, "emf": emf}), line_width=0.7)
    fig.add_tools(HoverTool(renderers=[line], mode="vline", tooltips=[("t", "@time{0.0000} s"), ("EMF", "@emf{0.0000} V")]))
    return fig


def capture_hint(system: str, chains: Sequence[TrainChain], stop_s: float) -> str:
    """The command that captures the coil EMF: around the first receiver error if there is one
    (of that train), else in the first minute."""
    erring = next((c for c in chains if c.errors), chains[0] if chains else None)
    first = erring.errors[0].t_s if erring is not None and erring.errors else min(stop_s, 60.0)
    t0 = max(0.0, first - 2.0)
    where = f"{erring.rail}.e_coil[{erring.slot}]" if erring is not None else "rail.e_coil[1]"
    return f"railcosim run {system} --capture {where}@{t0:g}:{t0 + 4.0:g}"


def provenance_rows(summary: Mapping[str, object], metadata: Mapping[str, object]) -> List[tuple]:
    """(what, value) rows: version, system and its hash, parameters set, date, how the run ended."""
    overrides = metadata.get("overrides") or {}
    version = str(metadata.get("railcosim_version", "not recorded (a run of an earlier version)"))
    if metadata.get("railcosim_source"):
        version += f" (checkout {metadata['railcosim_source']})"
    data_files = metadata.get("data_files_sha256") or {}
    rows = [("railcosim", version),
            ("system", f"{metadata.get('system', summary.get('system'))} ({metadata.get('ssd', '?')})"),
            ("system SHA-256", str(metadata.get("system_sha256", "not recorded"))),
            ("data files named (SHA-256)", "; ".join(f"{path}: {digest[:16]}…" for path, digest in data_files.items())
             or "none besides railcosim's bundled defaults"),
            ("parameters set (--set)", ", ".join(f"{k} = {v}" for k, v in overrides.items()) or "none"),
            ("parameter sets", ", ".join(metadata.get("param_sets") or []) or "none"),
            ("run written (UTC)", str(metadata.get("date_utc", "not recorded"))),
            ("stop time", f"{metadata.get('stop_time_s', '?')} s, output every {metadata.get('output_interval_s', '?')} s"),
            ("completed", completion(summary, metadata))]
    return rows


def completion(summary: Mapping[str, object], metadata: Mapping[str, object]) -> str:
    simulated = float(summary.get("sim_time_s") or 0.0)
    if summary.get("completed"):
        return f"yes: {simulated:.1f} s simulated"
    how = f"interrupted by {summary['interrupted']}" if summary.get("interrupted") else "no: stopped by an error"
    return (f"{how} at {simulated:.1f} s of {metadata.get('stop_time_s', '?')} s — every verdict on this page holds "
            f"over 0–{simulated:.1f} s only")


def top_speed_kmh(line) -> float:
    """The line's highest speed limit for any category (km/h): the top of TVM's step colours,
    the same for every train of a page; 0 without a line."""
    if line is None:
        return 0.0
    return max((max(limits, default=0.0) for limits in line.limits_mps.values()), default=0.0) * KMH_PER_MPS


def page(summary: Mapping[str, object], metadata: Mapping[str, object], results: Mapping[str, np.ndarray],
         line, tables_html: str, pictures_html: str, capture: Optional[tuple]) -> str:
    """The whole page as one string."""
    from bokeh.embed import components
    from bokeh.layouts import column
    from bokeh.models import Range1d
    from bokeh.resources import Resources

    component_info = metadata.get("components", {})
    chains, missing = chain_view.chains(results, summary, component_info, top_speed_kmh(line))
    by_train: Dict[str, TrainChain] = {c.train: c for c in chains}
    trains = [t for t in summary.get("trains", []) if f"{t['name']}.x" in results]
    time = results["time"]
    x_range = Range1d(float(time[0]) if len(time) else 0.0,
                      float(time[-1]) if len(time) > 1 else (float(time[0]) + 1.0 if len(time) else 1.0))
    figures, notes = [], [escape(reason) for reason in missing]
    for train in trains:
        chain = by_train.get(train["name"])
        if chain is not None:
            figures.append(chain_figure(chain, x_range))
        if f"{train['name']}.v" in results:
            figures.append(speed_figure(results, train["name"], train.get("ato"), chain.receiver if chain else None,
                                        x_range, chain.episodes if chain else ()))
        else:
            notes.append(f"train {escape(train['name'])}: the run did not record its speed ({escape(train['name'])}.v): "
                         "no speed figure")
    if not summary.get("receivers"):
        notes.append("This system has no cab-signal chain judged (no receiver fed by a rail line): the trains' "
                     "speeds alone are drawn.")
    rails = sorted({r["rail"] for r in summary.get("receivers", []) if r.get("rail")})
    if trains:
        figures.append(time_distance_figure(results, [t["name"] for t in trains], line, rails, x_range))
    if capture is not None:
        figures.append(coil_figure(*capture))
    elif chains:
        hint = capture_hint(str(summary.get("system")), chains, float(summary.get("sim_time_s") or 0.0))
        notes.append(f"No coil EMF was captured in this run. To see it (and the receiver's band-pass output in "
                     f"coil_emf.png), capture a window: <code>{escape(hint)}</code>, then "
                     f"<code>railcosim report</code> the new run.")
    script, div = components(column(*figures, sizing_mode="stretch_width")) if figures else ("", "")
    legend = "".join(f"<li><b>{escape(c.train)}</b> ({escape(c.cab.title)}): {_error_summary(c)}</li>" for c in chains)
    provenance = "".join(f"<tr><th scope=\"row\">{escape(k)}</th><td>{escape(v)}</td></tr>"
                         for k, v in provenance_rows(summary, metadata))
    system = escape(str(summary.get("system")))
    return f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8">
<title>railcosim report: {system}</title>
{Resources(mode="inline", components=list(BOKEH_BUNDLES)).render()}
<style>
body {{ font-family: sans-serif; margin: 2em; max-width: 1400px; }}
table {{ border-collapse: collapse; margin: 0.5em 0 1.5em; }}
th, td {{ border: 1px solid #bbb; padding: 0.25em 0.6em; text-align: left; }}
thead th {{ background: #eee; }}
tr.missed td {{ background: #fdd; }}
p.interrupted {{ background: #fff3cd; border: 1px solid #e0b000; padding: 0.5em; }}
figure {{ margin: 1.5em 0; }} img {{ max-width: 100%; }}
</style></head>
<body>
<h1>{system}</h1>
{"" if summary.get("completed") else f'<p class="interrupted">{escape(completion(summary, metadata))}</p>'}
<h2>Provenance</h2>
<table id="provenance"><tbody>{provenance}</tbody></table>
{tables_html}
<h2>The signal chain over time</h2>
<p>Drag to pan, scroll to zoom the time axis (linked across the figures), hover for values; click a
legend entry to hide its line. Receiver errors are marked on the decoded row by cause.</p>
<ul>{legend}</ul>
{"".join(f"<p>{n}</p>" for n in notes)}
{div}
{script}
<h2>Pictures (static, for papers)</h2>
{pictures_html}
</body></html>
"""


def _error_summary(chain: TrainChain) -> str:
    if not chain.errors:
        return "no receiver errors"
    counts: Dict[str, int] = {}
    for error in chain.errors:
        counts[error.cause] = counts.get(error.cause, 0) + error.count
    return "receiver errors " + ", ".join(f"{n} {escape(cause)}" for cause, n in counts.items())


def write(path: Path, text: str) -> Path:
    with create_file(path) as handle:     # never through a link planted at its name
        handle.write(text)
    return path

"""``railcosim study report DIR``: a finished study summed up per point (docs/studies.md,
"Reading the results").

From DIR/study.json and DIR/study.csv: per point the mean, min and max of every numeric
collected key over the point's successful runs (its seeds), for the safety keys the total and
the worst run, the values other keys took; PNG plots for one- and two-axis studies, of the
keys whose plot says more than the table (:func:`informative`); the worst runs by id. Written to
DIR/report.txt (Markdown), DIR/report.html (all of it on one offline page, the worst runs
linked to their folders) and DIR/study_<key>*.png.
"""
from __future__ import annotations

import csv
import json
import math
import re
from pathlib import Path
from typing import Dict, List, Optional, TextIO, Tuple

from orchestrator.errors import UserError
from orchestrator.folders import create_file

WORST_SHOWN = 5
#: more pictures per key than this: no plots (the table says it all)
MAX_FACETS = 12


def _number(text: str) -> Optional[float]:
    if text in ("", "True", "False"):
        return None
    try:
        value = float(text)
    except ValueError:
        return None
    return value if math.isfinite(value) else None


def _read(folder: Path) -> Tuple[dict, List[dict]]:
    try:
        study = json.loads((folder / "study.json").read_text())
        with open(folder / "study.csv", newline="") as f:
            rows = list(csv.DictReader(f))
    except FileNotFoundError as error:
        raise UserError(f"study report {folder}: no {Path(error.filename).name} (not a study's output "
                        "folder, or the study has not finished)") from None
    except (OSError, ValueError) as error:
        raise UserError(f"study report {folder}: cannot read the study's files ({error})") from None
    return study, rows


def aggregate(study: dict, rows: List[dict]) -> List[dict]:
    """One entry per point: its axis values, run and failure counts, and per collected key
    either numbers (mean, min, max, total, worst run) or the values seen with their counts."""
    points: Dict[str, List[dict]] = {}
    for row in rows:
        points.setdefault(row["point"], []).append(row)
    safety = set(study.get("safety", []))
    table = []
    for point, runs in sorted(points.items(), key=lambda item: int(item[0])):
        good = [r for r in runs if r["status"] == "ok"]
        entry = {"point": int(point), "axes": {a: runs[0][a] for a in study["axes"]},
                 "runs": len(runs), "failed": len(runs) - len(good), "keys": {}}
        for key in study["collect"]:
            numbers = [(v, r["id"]) for r in good if (v := _number(r[key])) is not None]
            if numbers and len(numbers) == sum(r[key] != "" for r in good):
                values = [v for v, _ in numbers]
                stats = {"mean": sum(values) / len(values), "min": min(values), "max": max(values),
                         "n": len(values)}
                if key in safety:
                    worst = max(numbers, key=lambda item: item[0])
                    stats.update(total=sum(values), worst=worst[1] if worst[0] > 0 else None)
                entry["keys"][key] = stats
            else:
                seen: Dict[str, int] = {}
                for r in good:
                    seen[r[key] or "—"] = seen.get(r[key] or "—", 0) + 1
                entry["keys"][key] = {"values": seen}
        table.append(entry)
    return table


def _format(stats: dict) -> str:
    if "values" in stats:
        return ", ".join(f"{v}×{n}" if n > 1 else v for v, n in stats["values"].items()) or "—"
    g = lambda x: f"{x:.4g}"                                        # noqa: E731
    if "total" in stats:
        return f"total {g(stats['total'])}" + (f" (worst {stats['worst']})" if stats["worst"] else "")
    if stats["min"] == stats["max"]:
        return g(stats["mean"])
    return f"{g(stats['mean'])} [{g(stats['min'])}, {g(stats['max'])}]"


def _uncollected_safety(study: dict) -> List[str]:
    """Safety keys of a study.json written before a study refused them uncollected: study.csv has
    no column for them, so nothing is known of them."""
    return [key for key in study.get("safety", []) if key not in study["collect"]]


def _no_worst_run(study: dict) -> str:
    """What the worst runs' list says when it has none."""
    collected = [key for key in study.get("safety", []) if key not in _uncollected_safety(study)]
    return (f"none: no collected safety key above zero ({', '.join(collected)})" if collected
            else "none: no safety key collected") + ", no failed run"


def _worst_runs(study: dict, rows: List[dict]) -> List[Tuple[str, str, str]]:
    """(run id, its point and seed, what is wrong with it): the runs with the most of each
    collected safety key, then every run that did not end ok."""
    found = []
    for key in (k for k in study.get("safety", []) if k not in _uncollected_safety(study)):
        hits = sorted(((v, r) for r in rows          # a failed run's figures are not its verdict
                       if r["status"] == "ok" and (v := _number(r.get(key, ""))) is not None and v > 0),
                      key=lambda item: -item[0])
        for value, r in hits[:WORST_SHOWN]:
            found.append((r["id"], f"{_axes_text(study, r)}, seed {r['seed'] or '—'}", f"{key} = {value:g}"))
    for r in rows:
        if r["status"] != "ok":
            found.append((r["id"], f"{_axes_text(study, r)}, seed {r['seed'] or '—'}", f"{r['status']}: {r['error']}"))
    return found


def _axes_text(study: dict, row: dict) -> str:
    return ", ".join(f"{a} {row[a]}" for a in study["axes"]) or "the point"


def _markdown(study: dict, table: List[dict], worst: List[Tuple[str, str, str]]) -> str:
    counts = study["counts"]
    head = ["point", *study["axes"], "runs", "failed", *study["collect"]]
    lines = [f"# Study {study['name']}", "",
             f"{counts['runs']} runs of {counts['points']} points: {counts['ok']} ok, {counts['failed']} failed, "
             f"{counts['timeout']} timed out, {counts['lost']} lost (study file {study['file']}, hash {study['hash']}). "
             "Numbers: mean [min, max] over the point's successful runs; safety keys: total over the runs "
             "and the run with the most.", "",
             "| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for entry in table:
        cells = [str(entry["point"]), *entry["axes"].values(), str(entry["runs"]), str(entry["failed"]),
                 *[_format(entry["keys"][k]) for k in study["collect"]]]
        lines.append("| " + " | ".join(cells) + " |")
    uncollected = _uncollected_safety(study)
    if uncollected:
        lines += ["", f"Safety keys not collected (no run reports them; not judged): {', '.join(uncollected)}."]
    lines += ["", "## Worst runs", ""] + ([f"- {run} ({where}): {what}" for run, where, what in worst]
                                          or [_no_worst_run(study)])
    return "\n".join(lines) + "\n"


def _slug(key: str) -> str:
    return re.sub(r"[^A-Za-z0-9]+", "_", key).strip("_")


def informative(table: List[dict], key: str, x_axis: str) -> bool:
    """Whether a key's plot says more than its row of the table: at least two values of the x
    axis have a figure, and the figures are not one value everywhere (all zeros, say)."""
    drawn = [e for e in table if "mean" in e["keys"][key]]
    xs = {e["axes"][x_axis] for e in drawn}
    figures = {round(v, 12) for e in drawn for v in (e["keys"][key]["min"], e["keys"][key]["max"])}
    return len(xs) >= 2 and len(figures) >= 2


def plot(study: dict, table: List[dict], folder: Path, left_out: Optional[Dict[str, str]] = None) -> List[Path]:
    """PNGs of every numeric key: its mean (min–max as error bars) against the axis with
    numeric values that has the most of them, one line per value of the last other axis; with
    more axes, one picture per combination of the rest (``study_<key>_<axis>-<value>.png``).
    ``left_out`` gets each key not plotted → why."""
    left_out = {} if left_out is None else left_out
    axes = study["axes"]

    def none_because(reason: str) -> List[Path]:
        left_out.update({key: reason for key in study["collect"]})
        return []

    if not axes or not table:
        return none_because("the study has no axis" if not axes else "no point has a run")
    numeric = [a for a in axes if all(_number(e["axes"][a]) is not None for e in table)]
    if not numeric:
        return none_because("no axis has numeric values to draw against")
    x_axis = max(numeric, key=lambda a: len({e["axes"][a] for e in table}))
    rest = [a for a in axes if a != x_axis]
    line_axis = rest[-1] if rest else None
    facet_axes = rest[:-1]
    facets: Dict[tuple, List[dict]] = {}
    for entry in table:
        facets.setdefault(tuple(entry["axes"][a] for a in facet_axes), []).append(entry)
    if len(facets) > MAX_FACETS:
        return none_because(f"more than {MAX_FACETS} pictures per key (the table says it all)")
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    written = []
    for key in study["collect"]:
        if not all("mean" in e["keys"][key] or e["runs"] == e["failed"] for e in table):
            left_out[key] = "not a number at every point"
            continue
        if not informative(table, key, x_axis):
            left_out[key] = f"one value over the sweep, or figures at a single {x_axis}"
            continue
        for facet, members in facets.items():
            figure, ax = plt.subplots(figsize=(6.4, 4.0))
            lines: Dict[str, List[dict]] = {}
            for entry in members:
                if "mean" in entry["keys"][key]:
                    lines.setdefault(entry["axes"][line_axis] if line_axis else "", []).append(entry)
            for label, entries in lines.items():
                entries.sort(key=lambda e: _number(e["axes"][x_axis]))
                x = [_number(e["axes"][x_axis]) for e in entries]
                mean = [e["keys"][key]["mean"] for e in entries]
                low = [m - e["keys"][key]["min"] for m, e in zip(mean, entries)]
                high = [e["keys"][key]["max"] - m for m, e in zip(mean, entries)]
                ax.errorbar(x, mean, yerr=[low, high], marker="o", capsize=3,
                            label=f"{line_axis} {label}" if line_axis else None)
            where = ", ".join(f"{a} {v}" for a, v in zip(facet_axes, facet))
            ax.set_xlabel(x_axis)
            ax.set_ylabel(key)
            ax.set_title(f"{study['name']}: {key}" + (f" ({where})" if where else ""))
            ax.grid(True, alpha=0.3)
            if line_axis:
                ax.legend(fontsize="small")
            figure.tight_layout()
            suffix = "".join(f"_{_slug(a)}-{_slug(str(v))}" for a, v in zip(facet_axes, facet))
            path = folder / f"study_{_slug(key)}{suffix}.png"
            figure.savefig(path, dpi=100)
            plt.close(figure)
            written.append(path)
    return written


def outcome_lines(name: str, result) -> List[str]:
    """What `railcosim study` prints once the runs are done: the counts of a study's runs
    (orchestrator/study/runner.py ``StudyResult``) and one line per run not ``ok``."""
    counts = result.counts
    lines = [f"study {name}: {counts['runs']} run(s) of {counts['points']} point(s): {counts['ok']} ok, "
             f"{counts['failed']} failed, {counts['timeout']} timed out, {counts['lost']} lost"
             + (f" ({result.skipped} done before)" if result.skipped else "") + f"; results in {result.output}"]
    lines += [f"  {record['id']} {record['status']}: {record['error']}"
              for record in result.records if record["status"] != "ok"]
    return lines


def make_study_report(folder: Path, stream: Optional[TextIO] = None) -> List[Path]:
    """report.txt (a Markdown table) and the plots in ``folder``; the table is also written to ``stream``."""
    study, rows = _read(folder)
    table = aggregate(study, rows)
    worst = _worst_runs(study, rows)
    text = _markdown(study, table, worst)
    if stream is not None:
        stream.write(text)
    report = folder / "report.txt"
    report.write_text(text)
    left_out: Dict[str, str] = {}
    pictures = plot(study, table, folder, left_out)
    return [report, write_html(folder / "report.html", study, table, worst, pictures, left_out), *pictures]


def write_html(path: Path, study: dict, table: List[dict], worst: List[Tuple[str, str, str]],
               pictures: List[Path], left_out: Dict[str, str]) -> Path:
    """report.html: the study on one page, offline — its counts, the table per point, the plots
    that carry information (inlined), the worst runs linked to their folders and reports."""
    import base64
    from html import escape

    counts = study["counts"]
    head = ["point", *study["axes"], "runs", "failed", *study["collect"]]
    rows = "\n".join("<tr class=\"point\">" + "".join(f"<td>{escape(str(c))}</td>" for c in (
        entry["point"], *entry["axes"].values(), entry["runs"], entry["failed"],
        *[_format(entry["keys"][k]) for k in study["collect"]])) + "</tr>" for entry in table)
    figures = "\n".join(
        f"<figure><img alt=\"{escape(p.stem)}\" src=\"data:image/png;base64,"
        f"{base64.b64encode(p.read_bytes()).decode()}\"><figcaption>{escape(p.name)}</figcaption></figure>"
        for p in pictures)

    def link(run: str) -> str:
        folder = path.parent / "runs" / run
        target = f"runs/{run}/report.html" if (folder / "report.html").is_file() else f"runs/{run}/"
        return f"<a href=\"{escape(target)}\">{escape(run)}</a>"

    worst_items = "\n".join(f"<li class=\"worst\">{link(run)} ({escape(where)}): {escape(what)}</li>"
                             for run, where, what in worst) or f"<li>{escape(_no_worst_run(study))}</li>"
    text = f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8">
<title>railcosim study: {escape(study['name'])}</title>
<style>
body {{ font-family: sans-serif; margin: 2em; max-width: 1300px; }}
table {{ border-collapse: collapse; margin: 0.5em 0 1.5em; }}
th, td {{ border: 1px solid #bbb; padding: 0.25em 0.6em; text-align: left; }}
thead th {{ background: #eee; }}
figure {{ display: inline-block; margin: 1em; }} img {{ max-width: 100%; }}
</style></head>
<body>
<h1>Study {escape(study['name'])}</h1>
<p>{counts['runs']} runs of {counts['points']} points: {counts['ok']} ok, {counts['failed']} failed,
{counts['timeout']} timed out, {counts['lost']} lost (study file {escape(str(study['file']))}, hash
{escape(str(study['hash']))}). Numbers: mean [min, max] over the point's successful runs; safety keys:
total over the runs and the run with the most.</p>
<h2>Per point</h2>
<table id="points"><thead><tr>{"".join(f"<th>{escape(h)}</th>" for h in head)}</tr></thead>
<tbody>
{rows}
</tbody></table>
<h2>Worst runs</h2>
<ul>{worst_items}</ul>
{f"<p>Safety keys not collected (no run reports them; not judged): {escape(', '.join(_uncollected_safety(study)))}.</p>"
 if _uncollected_safety(study) else ""}
<h2>Plots</h2>
{figures or "<p>No plot carries more than the table.</p>"}
{"<p>Not plotted:</p><ul>" + "".join(f'<li class="left-out">{escape(k)}: {escape(why)}</li>'
                                    for k, why in left_out.items()) + "</ul>" if left_out else ""}
</body></html>
"""
    with create_file(path) as handle:      # never through a link planted at its name
        handle.write(text)
    return path

"""The headway's pictures and page: the blocking-time stairway (time–distance, a box per block
section and train, the trains' paths) as PNG and in a self-contained report.html, and the text
the command prints (docs/capacity.md)."""
from __future__ import annotations

import base64
import html
import json
from pathlib import Path
from typing import Dict, List, Optional

from orchestrator.folders import replace_file, replacing


def stairway_picture(path: Path, result: dict, paths: Dict[str, tuple], headway_s: float, title: str) -> Path:
    """Time (down) against distance: each train's blocking times as boxes (the stairway of the
    first train shifted by ``headway_s`` per train) and, where given, the trains' paths
    (``paths``: name → (position array m, time array s))."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Rectangle

    steps = result["stairway"]
    trains = max(len(paths), 2)
    figure, axes = plt.subplots(figsize=(11, 7))
    colours = plt.get_cmap("tab10")
    for j in range(trains):
        shift = j * headway_s
        for step in steps:
            critical = result.get("critical_section") and step["section"] == result["critical_section"]["section"]
            axes.add_patch(Rectangle((step["entry_m"] / 1000.0, (step["start_s"] + shift) / 60.0),
                                     (step["exit_m"] - step["entry_m"]) / 1000.0, step["duration_s"] / 60.0,
                                     facecolor=colours(j % 10), alpha=0.25, edgecolor="black" if critical else colours(j % 10),
                                     linewidth=1.2 if critical else 0.5))
    for j, (name, (x_m, t_s)) in enumerate(paths.items()):
        axes.plot([x / 1000.0 for x in x_m], [t / 60.0 for t in t_s], color=colours(j % 10), linewidth=1.2, label=name)
    if steps:
        axes.set_xlim(min(s["entry_m"] for s in steps) / 1000.0 - 0.5, max(s["exit_m"] for s in steps) / 1000.0 + 0.5)
        top = min(s["start_s"] for s in steps) / 60.0 - 1.0
        bottom = (max(s["end_s"] for s in steps) + (trains - 1) * headway_s) / 60.0 + 1.0
        axes.set_ylim(bottom, top)
    axes.set_xlabel("position (km)")
    axes.set_ylabel("time (min)")
    axes.set_title(title)
    if paths:
        axes.legend(loc="upper right", fontsize=8)
    axes.grid(alpha=0.3)
    figure.tight_layout()
    path = Path(path)
    try:
        with replacing(path, binary=True) as handle:
            figure.savefig(handle, dpi=110, format="png")
    finally:
        plt.close(figure)
    return path


def text_lines(result: dict) -> List[str]:
    lines = [f"headway of {result['system']} ({result['cab_signal']}), {result['trains']} trains:"]
    critical = result.get("critical_section")
    if result.get("headway_blocking_s") is not None and critical:
        parts = ", ".join(f"{k} {v:.1f}" for k, v in result["parts_s"].items())
        lines.append(f"  blocking time: {result['headway_blocking_s']:.1f} s, critical section {critical['name']} "
                     f"({critical['entry_m']:g}-{critical['exit_m']:g} m; {parts} s)")
    if result.get("method") != "blocking":
        found = result.get("headway_cosim_s")
        lines.append(f"  co-simulation: {found:.0f} s" if found is not None else "  co-simulation: not found")
        for trial in result.get("trials", []):
            lines.append(f"    {trial['headway_s']:6.0f} s  {'hindered  ' if trial['hindered'] else 'unhindered'}  "
                         f"worst {trial['worst_follower']} {trial['late_s']:+.1f} s, "
                         f"{trial['speed_deficit_kmh']:.1f} km/h slower; {trial['verdict']}")
        if result.get("breakdown_s"):
            lines.append("  difference: " + ", ".join(f"{k} {v:+.1f} s" for k, v in result["breakdown_s"].items()))
    lines += [f"  note: {note}" for note in result.get("notes", [])]
    return lines


def write_page(folder: Path, result: dict, picture: Optional[Path]) -> Path:
    """report.html: one self-contained file (the picture inlined), no network."""
    rows = "".join(
        "<tr>" + "".join(f"<td>{html.escape(str(c))}</td>" for c in (
            s["name"], f"{s['entry_m']:g}", f"{s['exit_m']:g}", f"{s['approach_m']:g}",
            *(f"{s['parts_s'][k]:.1f}" for k in ("latency", "approach", "running", "clearing", "release")),
            f"{s['duration_s']:.1f}")) + "</tr>" for s in result["stairway"])
    trials = "".join(
        f"<tr><td>{t['headway_s']:g}</td><td>{'hindered' if t['hindered'] else 'unhindered'}</td>"
        f"<td>{html.escape(t['worst_follower'])}</td><td>{t['late_s']:+.1f}</td><td>{t['speed_deficit_kmh']:.1f}</td>"
        f"<td>{html.escape(str(t['verdict']))}</td><td>{html.escape(t['run_dir'])}</td></tr>"
        for t in result.get("trials", []))
    image = ""
    if picture is not None and Path(picture).is_file():
        data = base64.b64encode(Path(picture).read_bytes()).decode("ascii")
        image = f'<img alt="blocking-time stairway" src="data:image/png;base64,{data}">'
    summary = "<br>".join(html.escape(line) for line in text_lines(result))
    page = (f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>headway {html.escape(result['system'])}</title>"
            "<style>body{font-family:sans-serif;margin:2em}td,th{padding:2px 8px;border-bottom:1px solid #ddd}"
            "table{border-collapse:collapse}</style></head><body>"
            f"<h1>Headway: {html.escape(result['system'])}</h1><p>{summary}</p>{image}"
            "<h2>Blocking times (s)</h2><table><tr><th>block</th><th>entry m</th><th>exit m</th><th>approach m</th>"
            "<th>latency</th><th>approach</th><th>running</th><th>clearing</th><th>release</th><th>total</th></tr>"
            f"{rows}</table>"
            + (f"<h2>Trials</h2><table><tr><th>headway s</th><th>outcome</th><th>worst follower</th><th>late s</th>"
               f"<th>slower km/h</th><th>verdict</th><th>run folder</th></tr>{trials}</table>" if trials else "")
            + f"<h2>Data</h2><pre>{html.escape(json.dumps({k: v for k, v in result.items() if k != 'stairway'}, indent=1))}</pre>"
            "</body></html>\n")
    path = Path(folder) / "report.html"
    replace_file(path, page)
    return path

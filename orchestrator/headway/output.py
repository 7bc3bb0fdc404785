"""What ``railcosim headway`` leaves in its folder: headway.json (the command's JSON, the
stairway included), stairway.png and report.html (docs/capacity.md#what-the-command-writes)."""
from __future__ import annotations

import json
from pathlib import Path

from orchestrator.folders import replace_file
from orchestrator.headway import report
from orchestrator.headway.search import HeadwayResult


def _paths(document: dict) -> dict:
    """The trains' paths of the trial at the co-simulated headway, when there is one."""
    from orchestrator.headway.trials import read_trajectories

    found = document.get("headway_cosim_s")
    trial = next((t for t in document.get("trials", []) if t["headway_s"] == found), None)
    if trial is None:
        return {}
    run_dir = Path(trial["run_dir"])
    names = [f"train{j}" for j in range(1, document["trains"] + 1)]
    runs = read_trajectories(run_dir, names, float(document.get("trial_offset_m", 0.0)))
    return {name: (run.head_m, run.time_s) for name, run in runs.items()}


def write_outputs(result: HeadwayResult, folder: Path) -> dict:
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    document = result.as_dict()
    replace_file(folder / "headway.json", json.dumps(document, indent=1, ensure_ascii=False) + "\n")
    shown = document["headway_cosim_s"] or document["headway_blocking_s"]
    title = (f"{document['system']} ({document['cab_signal']}): blocking-time stairway at "
             f"{shown:g} s" + (" (co-simulated headway), the trains' paths" if document["headway_cosim_s"] else ""))
    picture = report.stairway_picture(folder / "stairway.png", document, _paths(document), shown, title)
    report.write_page(folder, document, picture)
    return document


def shown(document: dict, output_format: str, folder: Path) -> str:
    """What ``railcosim headway`` prints: the JSON without the stairway, or the text lines."""
    if output_format == "json":
        return json.dumps({k: v for k, v in document.items() if k != "stairway"}, indent=1, ensure_ascii=False)
    return "\n".join([*report.text_lines(document), f"results in {folder} (headway.json, stairway.png, report.html)"])

"""``railcosim plot RUN VAR [VAR …]``: recorded variables of a finished run against time, one
panel each, from its results.csv; the units in the axis labels and an enumeration's labels on
its ticks from the run's columns.json (docs/interfaces.md#results). A PNG or an SVG."""
from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Dict, List, Optional, Sequence

import numpy as np

from orchestrator.errors import UserError, did_you_mean
from orchestrator.folders import create_file
from orchestrator.reports.report import read_results_file, results_rows

#: the picture formats, by the suffix of -o
FORMATS = {".png": "png", ".svg": "svg"}
#: an enumeration with more labels than this gets ticks only at the values the run took
MAX_TICKS = 12
#: a panel's title, the column's description, cut to this many characters
MAX_TITLE = 130
_NAME_CHARACTERS = re.compile(r"[^\w.+-]+")


def default_name(variables: Sequence[str]) -> str:
    """``plot_train.v+rx.aspect.png``: the variables, in order, as a file name (brackets and
    other characters a shell or a file system minds made ``_``; many variables: the first and
    how many more)."""
    parts = [_NAME_CHARACTERS.sub("_", name).strip("_") for name in variables]
    joined = "+".join(parts)
    if len(joined) > 100:
        joined = f"{parts[0]}+{len(parts) - 1}_more"
    return f"plot_{joined}.png"


def _columns(run_dir: Path) -> Dict[str, dict]:
    """The run's columns.json by column name; {} for a run written before there was one."""
    path = run_dir / "columns.json"
    if not path.is_file():
        return {}
    try:
        document = json.loads(path.read_text(encoding="utf-8"))
        return {entry["name"]: entry for entry in document["columns"]}
    except (ValueError, UnicodeDecodeError, KeyError, TypeError):
        raise UserError(f"{path}: not a columns.json a railcosim run wrote") from None
    except OSError as error:
        raise UserError(f"{path}: cannot be read ({error.strerror or error})") from None


def plot_run(run_dir: Path, variables: Sequence[str], t0: Optional[float] = None, t1: Optional[float] = None,
             output: Optional[Path] = None) -> Path:
    """Draw ``variables`` of the run in ``run_dir`` from ``t0`` to ``t1`` (s; None: the run's
    start or end) into ``output`` (default ``RUN/plot_<variables>.png``); returns the file."""
    run_dir = Path(run_dir)
    path = run_dir / "results.csv"
    if not run_dir.is_dir():
        raise UserError(f"plot: {run_dir}: no such run folder")
    if not path.is_file():
        raise UserError(f"plot: {run_dir}: no results.csv (not a railcosim run folder)")
    output = Path(output) if output is not None else run_dir / default_name(variables)
    if output.suffix.lower() not in FORMATS:
        raise UserError(f"plot: -o {output}: give a .png or .svg file")
    if t0 is not None and t1 is not None and t1 <= t0:
        raise UserError(f"plot: --to {t1:g} must be after --from {t0:g}")
    _, header = next(results_rows(path))
    recorded = header[1:]
    for name in variables:
        if name not in recorded:
            raise UserError(f"plot: {name}: no such column in {path}{did_you_mean(name, recorded)}")
    data = read_results_file(path)
    time = data["time"]
    keep = np.ones(time.shape, dtype=bool)
    if t0 is not None:
        keep &= time >= t0
    if t1 is not None:
        keep &= time <= t1
    if not keep.any():
        span = f"{time[0]:g} … {time[-1]:g} s" if time.size else "no rows"
        raise UserError(f"plot: --from/--to: no row of {path} in that time (the run's: {span})")
    _draw(output, time[keep], [(name, data[name][keep]) for name in variables], _columns(run_dir))
    return output


def _draw(output: Path, time: np.ndarray, series: List[tuple], columns: Dict[str, dict]) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(len(series), 1, sharex=True, squeeze=False, figsize=(10.0, 0.8 + 2.1 * len(series)))
    for ax, (name, values) in zip(axes[:, 0], series):
        entry = columns.get(name, {})
        unit, labels = entry.get("unit", ""), entry.get("labels") or {}
        stepped = labels or entry.get("type") in ("Integer", "Boolean")
        if stepped:
            ax.step(time, values, where="post", linewidth=1.2)
        else:
            ax.plot(time, values, linewidth=1.2)
        ax.set_ylabel(f"{name} [{unit}]" if unit else name, fontsize=9)
        title = entry.get("description") or ""
        if title:
            ax.set_title(title if len(title) <= MAX_TITLE else title[:MAX_TITLE - 1] + "…", fontsize=8, loc="left")
        if labels:
            named = sorted(int(value) for value in labels)
            if len(named) > MAX_TICKS:
                taken = set(np.unique(values).astype(int).tolist())
                named = [value for value in named if value in taken]
            ax.set_yticks(named)
            ax.set_yticklabels([labels[str(value)] for value in named], fontsize=8)
            ax.set_ylim(min(named + [float(values.min())]) - 0.5, max(named + [float(values.max())]) + 0.5)
        ax.grid(True, alpha=0.3)
    axes[-1, 0].set_xlabel("time [s]")
    fig.tight_layout()
    try:
        # never through a link planted at its name; an SVG's text stays text (searchable, editable)
        with create_file(output, binary=True) as handle, matplotlib.rc_context({"svg.fonttype": "none"}):
            fig.savefig(handle, format=FORMATS[output.suffix.lower()], dpi=110)
    except OSError as error:
        raise UserError(f"plot: {output}: cannot be written ({error.strerror or error})") from None
    finally:
        plt.close(fig)

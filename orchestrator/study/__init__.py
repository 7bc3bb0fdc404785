"""Studies: many runs of a system (or of a function) over grids, random draws, scenarios and
seeds, on Dask distributed (docs/studies.md).

spec.py reads and expands a study file, runner.py runs it (worker.py on each worker), report.py
sums it up; the study files shipped with railcosim are in studies/ here, found by name
(:func:`shipped_studies`).
"""
from pathlib import Path
from typing import Dict

SHIPPED = Path(__file__).resolve().parent / "studies"


def shipped_studies() -> Dict[str, Path]:
    """Name → file of every shipped study (``railcosim study NAME``)."""
    return {p.stem: p for p in sorted(SHIPPED.glob("*.toml"))}

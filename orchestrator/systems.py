"""The shipped systems (ssp/<name>/), written from Python so they stay consistent with the
FMUs' ports. ``python -m orchestrator.systems`` rewrites them; the files are committed.

* ``free_run`` — one passenger train (Traction) driven by the ATO over the default line and
  timetable. Until the signal chain (wayside coder, rail line, receiver) is shipped the ATP
  supervises line limits only (``cab_signal = off``); the scenario issue adds the chain.
"""
from __future__ import annotations

from pathlib import Path
from typing import Dict, List, Tuple

from .sspgen import ComponentSpec, ConnectionSpec, write_ssd

SSP_ROOT = Path(__file__).resolve().parent.parent / "ssp"
TRAIN_STEP_S = 0.5
ATO_STEP_S = 0.5


def train_and_ato(train: str = "train", ato: str = "ato", train_parameters: Dict[str, object] = None,
                  ato_parameters: Dict[str, object] = None, fmu_folder: str = "resources",
                  step_s: Tuple[float, float] = (TRAIN_STEP_S, ATO_STEP_S)):
    """Components and connections of one train driven by its ATO (closed loop)."""
    components = [
        ComponentSpec(train, f"{fmu_folder}/Traction.fmu", step_s[0], dict(train_parameters or {})),
        ComponentSpec(ato, f"{fmu_folder}/AtoController.fmu", step_s[1], dict(ato_parameters or {})),
    ]
    connections: List[ConnectionSpec] = [
        ConnectionSpec(f"{train}.x", f"{ato}.x"),
        ConnectionSpec(f"{train}.v", f"{ato}.v"),
        ConnectionSpec(f"{ato}.command", f"{train}.command"),
        ConnectionSpec(f"{ato}.emergency_brake", f"{train}.emergency_brake"),
    ]
    return components, connections


def write_free_run(root: Path = SSP_ROOT) -> Path:
    components, connections = train_and_ato(ato_parameters={"cab_signal": "off"})
    return write_ssd(root / "free_run", "free_run", components, connections, stop_time=1100.0)


def write_shipped(root: Path = SSP_ROOT) -> List[Path]:
    return [write_free_run(root)]


if __name__ == "__main__":
    for path in write_shipped():
        print(f"wrote {path}")

"""The shipped systems (ssp/<name>/), written from Python so they stay consistent with the
FMUs' ports. ``python -m orchestrator.systems`` rewrites them; the files are committed.

* ``free_run`` — one passenger train (Traction) driven by the ATO over the default line and
  timetable, with the ALSN chain: wayside coder → rail line → locomotive receiver → ATP.
* ``ato_only`` — the same train and ATO without the signal chain (ATP on line limits): the
  fast system for timetable and energy studies.
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


SIGNAL_STEP_S = 0.01        # one 40-sample frame at 4 kHz


def alsn_chain(sections: int = 8, frame: int = 40, fmu_folder: str = "resources", train: str = "train",
               ato: str = "ato", train_slot: int = 1):
    """Coder → rail line → receiver → ATO of one train, and the train back into the rail line."""
    components = [
        ComponentSpec("coder", f"{fmu_folder}/WaysideCoder.fmu", SIGNAL_STEP_S),
        ComponentSpec("rail", f"{fmu_folder}/RailLine.fmu", SIGNAL_STEP_S),
        ComponentSpec("rx", f"{fmu_folder}/LocoReceiver.fmu", SIGNAL_STEP_S),
    ]
    j = train_slot
    connections = [ConnectionSpec(f"coder.u_tx[{k},{n}]", f"rail.u_tx[{k},{n}]")
                   for k in range(1, sections + 1) for n in range(1, frame + 1)]
    connections += [ConnectionSpec(f"rail.occupied[{k}]", f"coder.occupied[{k}]") for k in range(1, sections + 1)]
    connections += [ConnectionSpec(f"rail.e_coil[{j},{n}]", f"rx.e_coil[{n}]") for n in range(1, frame + 1)]
    # linear: the train publishes its state at the end of its 0.5 s step; the rail line needs
    # the position at each 10 ms frame, not half a second ahead (the master interpolates)
    connections += [ConnectionSpec(f"{train}.{a}", f"rail.{b}[{j}]", transition="linear")
                    for a, b in (("x", "x_head"), ("v", "v"), ("i_traction", "i_traction"))]
    connections += [ConnectionSpec(f"rx.{port}", f"{ato}.{port}")
                    for port in ("aspect", "code_valid", "v_permitted", "v_target", "free_blocks")]
    return components, connections


def write_free_run(root: Path = SSP_ROOT) -> Path:
    components, connections = train_and_ato(ato_parameters={"cab_signal": "ALSN"})
    chain, links = alsn_chain()
    return write_ssd(root / "free_run", "free_run", chain + components, connections + links, stop_time=1100.0)


def write_ato_only(root: Path = SSP_ROOT) -> Path:
    components, connections = train_and_ato(ato_parameters={"cab_signal": "off"})
    return write_ssd(root / "ato_only", "ato_only", components, connections, stop_time=1100.0)


def write_shipped(root: Path = SSP_ROOT) -> List[Path]:
    return [write_free_run(root), write_ato_only(root)]


if __name__ == "__main__":
    for path in write_shipped():
        print(f"wrote {path}")

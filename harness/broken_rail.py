"""A system with a broken rail ahead of its train, optionally with the coder deaf to the
occupancy, run in process with the railway verdicts (tests/test_track_verdict.py,
tests/test_tvm_systems.py: the verdict against the track catches a coder that sends a clear
line's codes while the rail line detects the break)."""
from __future__ import annotations

import json
from pathlib import Path

from orchestrator.verdicts.verdict import railway_verdicts
from orchestrator.run import RunOptions, run_system
from orchestrator.sspgen import write_ssd


def run_with_broken_rail(folder: Path, fmu_dir: Path, components, connections, broken_rail_m: float,
                         occupancy_sent: bool, stop_time: float):
    """(summary, the one receiver's verdict entry) of the system made of ``components`` and
    ``connections`` (the signal chain's among them), the rail broken at ``broken_rail_m`` from
    1 s; ``occupancy_sent`` False: the rail line's ``occupied`` never reaches the coder."""
    if not occupancy_sent:
        connections = [c for c in connections if not c.start.startswith("rail.occupied")]
    system = write_ssd(folder / "sys", "sys", components, connections, stop_time=stop_time)
    scenario = folder / "scenario.json"
    scenario.write_text(json.dumps({"description": "broken rail ahead", "events": [
        {"time": 1.0, "model": "rail", "variable": "broken_rail_at", "action": "set", "value": broken_rail_m}]}))
    result = run_system(system.parent if system.is_file() else system,
                        RunOptions(summaries=railway_verdicts, output_dir=folder / "out", in_process=True,
                                   fmu_dirs=[fmu_dir], scenario=scenario, record=[]))
    (receiver,) = result.summary["receivers"]
    return result.summary, receiver

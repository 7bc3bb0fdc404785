"""A whole system run into a throw-away folder, as the whole-system benchmarks make them
(with the railway verdicts in its summary)."""
from __future__ import annotations

import tempfile
from pathlib import Path
from typing import Optional, Sequence

from orchestrator.verdicts.verdict import railway_verdicts
from orchestrator.run import RunOptions, RunResult, run_system

#: what the free_run benchmarks record (the recorder's cost as a user's run has it)
FREE_RUN_RECORD = ("train.x", "train.v", "rx.aspect")


def scratch_run(system: Path, in_process: bool, fmu_dirs: Sequence[Path], stop_time: Optional[float] = None,
                record: Optional[Sequence[str]] = FREE_RUN_RECORD) -> RunResult:
    with tempfile.TemporaryDirectory() as folder:
        options = RunOptions(summaries=railway_verdicts, stop_time=stop_time, output_dir=Path(folder),
                             in_process=in_process, fmu_dirs=list(fmu_dirs),
                             record=None if record is None else list(record))
        return run_system(system, options)

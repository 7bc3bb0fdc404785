"""The garbage collector while the master steps (orchestrator/process_policy.py `ProcessPolicy.stepping`):
frozen and off during stepping, as it was afterwards, and stepping makes no cyclic garbage, so
that nothing can pile up while it is off (docs/performance.md#one-sample-per-frame-as-a-deadline)."""
import gc
from pathlib import Path

import pytest

from orchestrator.verdicts.verdict import railway_verdicts
from orchestrator.run import RunOptions, run_system

REPO = Path(__file__).resolve().parent.parent


class GarbageProbe:
    """A summary observer: at two ticks during stepping, whether the collector is on and how many
    unreachable objects a full collection finds among those made since stepping began (the
    frozen ones, made before, are left out of it)."""

    def __init__(self, at_ticks):
        self.at_ticks, self.seen = set(at_ticks), []
        self.ticks = 0

    def outputs_needed(self):
        return {}

    def started(self, master, step):
        pass

    def after_tick(self, master, step):
        self.ticks += 1
        if self.ticks in self.at_ticks:
            self.seen.append((gc.isenabled(), gc.get_freeze_count() > 0, gc.collect()))

    def close(self):
        pass

    def summary_section(self):
        return {}


@pytest.mark.parametrize("system, in_process, stop_s", [
    ("free_run", True, 3.0),          # the whole chain in process, 300 frames
    ("free_run", False, 2.0),         # the same through FMI (pythonfmu's Python shares this process)
    ("ato_only", True, 120.0),        # the train leaving, stopping and the ATO planning ahead
])
def test_stepping_runs_with_the_collector_off_and_leaves_no_cyclic_garbage(product_fmus, tmp_path, system,
                                                                           in_process, stop_s):
    probe = GarbageProbe(at_ticks=(20, 100, 150))
    assert gc.isenabled() and gc.get_freeze_count() == 0
    run_system(REPO / "ssp" / system, RunOptions(
        stop_time=stop_s, output_dir=tmp_path, in_process=in_process, fmu_dirs=[product_fmus],
        summaries=lambda graph: [*railway_verdicts(graph), probe]))
    assert probe.seen == [(False, True, 0)] * 3
    assert gc.isenabled() and gc.get_freeze_count() == 0      # as it was, once the run is over

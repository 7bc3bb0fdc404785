"""Acceptance in the shipped systems (docs/loco_receiver.md#in-the-shipped-systems): what the
receiver displays (its own `aspect`, not the ATP's) against the code sent under its coils, in
process, over windows that pass several insulated joints — no display dropout at any joint,
every restrictive change within the stated latency, never more permissive than the code
beyond it — and a loss of code at speed ends without an emergency brake (faults). The whole
runs: python benchmarks/study_receiver_display.py."""
import tempfile
from pathlib import Path

import pytest

from harness.display import analyse, with_probe
from fmus.signalling.alsn import EQUIPMENT_INERTIA_S
from fmus.signalling import aspects as sig
from fmus.signalling.alsn import STATED_LATENCY_S
from orchestrator.cli import SSP_ROOT
from orchestrator.run import RunOptions, run_system

SETTLE_S = 10.0


def _run(product_fmus, system, stop_time):
    probes = []
    with tempfile.TemporaryDirectory() as folder:
        options = RunOptions(summaries=with_probe(probes), stop_time=stop_time, output_dir=Path(folder),
                             in_process=True, fmu_dirs=[product_fmus], record=[])
        summary = run_system(SSP_ROOT / system, options).summary
    return summary, probes[0]


@pytest.mark.parametrize("system, stop_time, joints", [
    ("free_run", 400.0, 2),             # joints at 2.6 and 5.2 km (passed at about 150 and 280 s)
    ("joints_at_speed", 350.0, 5),      # 160 km/h through the station throat
    ("following", 520.0, 2),            # two trains, each past the first joints
])
def test_no_display_dropout_at_joints_and_every_restrictive_change_in_time(product_fmus, system, stop_time, joints):
    summary, probe = _run(product_fmus, system, stop_time)
    for name, samples in probe.samples.items():
        report = analyse(samples, SETTLE_S)
        sections = {s for s in samples.section if s > 0}
        assert len(sections) > joints or name == "rx2", (name, sections)   # the follower starts later
        assert report.dropouts == [], (name, report.dropouts)
        assert report.worst_restrictive_s <= STATED_LATENCY_S, (name, report.restrictive)
        assert report.worst_permissive_s <= STATED_LATENCY_S, (name, report.permissive)
    for train in summary["trains"]:
        assert train["emergency_brakings"] == 0 and train["signals_passed_at_danger"] == 0, train["name"]
    for receiver in summary["receivers"]:
        assert receiver["wrong_side_failures"] == 0 and receiver["unsafe_indications"] == 0, receiver


def test_code_loss_at_speed_ends_in_white_without_emergency_braking(product_fmus):
    """faults: the feed of section 1 fails under the train at 100 s (repaired at 130 s), both
    code transmitters at 170 s: the display holds for the inertia, then white; the ATP brakes
    to 40 km/h on its curve, no emergency brake, no wrong-side failure."""
    summary, probe = _run(product_fmus, "faults", 200.0)
    samples = probe.samples["rx"]
    for fault_s, until_s in ((100.0, 130.0), (170.0, 200.0)):
        after = [a for t, a in zip(samples.t, samples.aspect) if fault_s + EQUIPMENT_INERTIA_S + 0.2 <= t < until_s]
        assert after and set(after) == {sig.WHITE}, (fault_s, set(after))
        held = [a for t, a in zip(samples.t, samples.aspect) if fault_s < t < fault_s + EQUIPMENT_INERTIA_S - 2.0]
        assert set(held) == {sig.GREEN}, (fault_s, set(held))
    train = summary["trains"][0]
    assert train["emergency_brakings"] == 0 and train["signals_passed_at_danger"] == 0
    assert summary["receivers"][0]["wrong_side_failures"] == 0

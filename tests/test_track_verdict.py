"""The verdict against the track (docs/scenarios.md, "Results: summary.json"): a
receiver showing more than the real occupancy allows by the block rules is an unsafe
indication, even when it shows exactly what the coder sent (then it is no wrong-side failure)."""
import pytest

from harness.broken_rail import run_with_broken_rail
from orchestrator.systems.chain import signal_chain, train_and_ato
from orchestrator.verdicts.verdict import safety_verdict
from orchestrator.sspgen import write_ssd

BROKEN_RAIL_M = 3000.0          # in section 2 (2.6-5.2 km), ahead of the train standing at A (400 m)


def _run(tmp_path, product_fmus, occupancy_sent: bool, stop_time=14.0):
    folder = str(product_fmus)
    components, connections = train_and_ato(fmu_folder=folder, ato_parameters={"cab_signal": "ALSN"})
    chain, links = signal_chain(fmu_folder=folder)
    # occupancy not sent: the coder never learns it and sends З everywhere
    return run_with_broken_rail(tmp_path, product_fmus, chain + components, connections + links, BROKEN_RAIL_M,
                                occupancy_sent, stop_time)


def test_a_coder_that_never_hears_the_occupancy_is_caught_against_the_track_not_against_its_code(tmp_path, product_fmus):
    summary, rx = _run(tmp_path, product_fmus, occupancy_sent=False)
    assert rx["wrong_side_failures"] == 0, rx          # the receiver shows what was sent …
    assert rx["unsafe_indications"] == 1, rx           # … which the broken rail ahead forbids
    (event,) = rx["unsafe_events"]
    assert event["section"] == 1 and event["free_blocks_allowed"] == 0
    assert rx["unsafe_s"] > 0.0
    safe, line = safety_verdict(summary)
    assert not safe and "unsafe indications 1" in line


def test_the_same_fault_with_the_occupancy_sent_is_safe(tmp_path, product_fmus):
    summary, rx = _run(tmp_path, product_fmus, occupancy_sent=True)
    assert rx["wrong_side_failures"] == 0 and rx["unsafe_indications"] == 0, rx
    assert safety_verdict(summary)[0]


def test_the_verdict_judges_the_real_train_length_not_a_shorter_one_given_to_the_rail_line(tmp_path, product_fmus):
    """A 944 m freight train whose rail line keeps its 400 m default: the verdict's occupancy uses
    the rolling-stock file's length, so it does not share the rail line's blind spot."""
    from orchestrator.verdicts.verdict import train_lengths
    from orchestrator.graph import build_graph
    from orchestrator.ssp import open_system

    folder = str(product_fmus)
    from fmus.data.loader import DATA

    # the bundled file by its path: a bare "freight_vl80.json" is in neither the system nor the
    # FMU's resources/ (the FMU would not find it; the graph refuses it)
    stock = {"rolling_stock_file": str(DATA / "freight_vl80.json")}
    components, connections = train_and_ato(fmu_folder=folder, train_parameters=stock,
                                            ato_parameters={"cab_signal": "ALSN", **stock})
    chain, links = signal_chain(fmu_folder=folder)
    ssd = write_ssd(tmp_path / "sys", "sys", chain + components, connections + links, stop_time=1.0)
    system = open_system(ssd.parent if ssd.is_file() else ssd, [product_fmus])
    try:
        assert train_lengths(build_graph(system, {}, []))["train"] == pytest.approx(944.0)
    finally:
        system.close()


def test_a_receiver_the_verdict_cannot_judge_is_never_reported_safe():
    summary = {"trains": [{"signals_passed_at_danger": 0}],
               "receivers": [{"wrong_side_failures": 0, "unsafe_indications": 0}],
               "receivers_not_judged": ["rx2"]}
    safe, line = safety_verdict(summary)
    assert not safe and "not judged" in line and "rx2" in line
    del summary["receivers_not_judged"]
    assert safety_verdict(summary) == (True, "safety: safe (signals passed at danger 0, wrong-side failures 0, "
                                             "unsafe indications 0)")

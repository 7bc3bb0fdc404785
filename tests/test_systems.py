"""Acceptance of the shipped systems (docs/scenarios.md): no signal passed at danger,
no wrong-side failure, timetables kept, the following and fault scenarios end where they must.
The long runs are shortened where the behaviour under test is over, and run in process (the
same facades without FMI; the FMI path is exercised by the shorter runs in test_ato.py,
test_alsn.py and test_digital.py). The full runs: python benchmarks/bench_systems.py."""
import json

import numpy as np
import pytest

from fmus.signalling import aspects as sig
from fmus.signalling.alsn import STATED_LATENCY_S
from fmus.signalling.alsn import EQUIPMENT_INERTIA_S
from helpers import read_csv
from orchestrator.systems.chain import stock_length_m
from orchestrator.cli import SSP_ROOT
from orchestrator.verdicts.verdict import railway_verdicts
from orchestrator.run import RunOptions, run_system


LENGTH_M = stock_length_m()        # the passenger train of the shipped systems (its rolling-stock file)


def _run(tmp_path, product_fmus, system, stop_time, record=None):
    out = tmp_path / system
    result = run_system(SSP_ROOT / system, RunOptions(summaries=railway_verdicts, stop_time=stop_time, output_dir=out, in_process=True,
                                                      fmu_dirs=[product_fmus], record=record))
    header, data = read_csv(out / "results.csv")
    return result.summary, {name: data[:, i] for i, name in enumerate(header)}


def _no_danger(summary, emergency_allowed=False):
    for train in summary["trains"]:
        assert train["signals_passed_at_danger"] == 0, train["name"]
        assert emergency_allowed or train["emergency_brakings"] == 0, train["name"]
    assert summary["receivers"], "no receiver judged"
    for receiver in summary["receivers"]:
        assert receiver["wrong_side_failures"] == 0, receiver
        assert receiver["unsafe_indications"] == 0, receiver     # judged against the track


def _on_time(train, stations):
    stops = {s["station"]: s for s in train["stops"]}
    for station in stations:
        assert abs(stops[station]["arrival_deviation_s"]) <= 15.0, stops[station]
        assert abs(stops[station]["stop_error_m"]) <= 0.5, stops[station]


def test_free_run_keeps_the_timetable_to_15_s_and_stops_to_half_a_metre(tmp_path, product_fmus):
    summary, _ = _run(tmp_path, product_fmus, "free_run", 1100.0, ["train.x"])
    _no_danger(summary)
    _on_time(summary["trains"][0], ("B", "C"))
    assert summary["realtime_factor"] > 0


# the ALSN variant runs until the follower is at C; the digital ones until it has gone again
# (their full runs reach C too: docs/scenarios.md, verdict table, a benchmark-length run)
@pytest.mark.parametrize("system, stop_s", [("following", 1600.0), ("als_en_following", 1250.0),
                                            ("fire_dqpsk_following", 1250.0)])
def test_following_the_follower_stops_before_the_red_signal_and_reaches_c_once_the_line_clears(tmp_path, product_fmus,
                                                                                                system, stop_s):
    summary, col = _run(tmp_path, product_fmus, system, stop_s,
                        ["leader.x", "follower.x", "follower.v", "follower_ato.atp_aspect"])
    _no_danger(summary)
    assert [e["t"] for e in summary["scenario"]["events_applied"]] == [830.0, 1060.0]
    follower = next(t for t in summary["trains"] if t["name"] == "follower")
    approach = [a["aspect"] for a in follower["aspects"] if 8000.0 < a["x"] < 15200.0]
    # green, then yellow, then red-yellow, in that order; a digital receiver (no display hold)
    # shows no code (white, or red after a stop command) between them while it re-acquires
    # after a joint
    seen = iter(approach)
    assert all(aspect in seen for aspect in ("green", "yellow", "red-yellow")), approach
    # it stops before signal 9 (15.2 km) while the leader's tail is still in section 7 ...
    signal_m = 15200.0
    # (standing anywhere from 12.8 km up to C's approach: standing beyond the signal would be caught)
    standing = np.flatnonzero((col["follower.v"] < 0.01) & (col["follower.x"] > 12800.0)
                              & (col["follower.x"] < 18000.0))
    assert standing.size
    assert col["follower.x"][standing].max() < signal_m
    assert 15200.0 < col["leader.x"][standing[0]] - LENGTH_M < 17600.0
    # ... goes again only once the leader's tail has left section 7 (the signal cleared) ...
    assert col["follower.x"][-1] > signal_m
    assert col["leader.x"][standing[-1] + 1] - LENGTH_M > 17600.0
    if stop_s < 1600.0:
        return
    # ... and reaches C: the leader runs through C to the sidings beyond the last signal, off
    # every track circuit (docs/scenarios.md, following)
    stops = {s["station"]: s for s in follower["stops"]}
    assert stops["C"]["reached"] and abs(stops["C"]["stop_error_m"]) <= 0.5, stops
    leader = next(t for t in summary["trains"] if t["name"] == "leader")
    assert [(s["station"], s["reached"]) for s in leader["stops"]] == [("B", True), ("C sidings", True)]
    assert col["leader.x"][-1] - LENGTH_M > 20000.0


def test_faults_each_end_in_a_restrictive_state_within_the_latency(tmp_path, product_fmus):
    summary, col = _run(tmp_path, product_fmus, "faults", 650.0,
                        ["rx.aspect", "rx.code_valid", "train.x", "train.v", "coder.status", "rail.occupied[4]",
                         "rail.coil_section[1]"])
    # a code lost at speed: the receiver holds it for its inertia, then white; the ATP brakes
    # to the no-code ceiling (40 km/h) on a braking curve, never with the emergency brake
    _no_danger(summary)
    t = col["time"]

    def restrictive(fault_s, repaired_s, allowed):
        window = (t >= fault_s + max(STATED_LATENCY_S, EQUIPMENT_INERTIA_S + 0.2)) & (t < repaired_s)
        assert window.any() and np.isin(col["rx.aspect"][window], allowed).all(), \
            (fault_s, np.unique(col["rx.aspect"][window]))

    # the feed of section 1 fails under the train (100 s): code lost → white
    assert (col["rail.coil_section[1]"][(t > 100) & (t < 130)] == 1).all()
    restrictive(100.0, 130.0, [sig.WHITE, sig.RED])
    # the main transmitter fails (160 s): the reserve carries on; then the reserve (170 s): no code
    assert col["coder.status"][(t > 161) & (t < 169)].min() == 1 and col["coder.status"][(t > 171) & (t < 229)].min() == 2
    assert (col["rx.aspect"][(t > 161) & (t < 170)] == sig.GREEN).all()
    restrictive(170.0, 230.0, [sig.WHITE, sig.RED])
    # a broken rail in section 4 (300 s): its relay drops, signal 5 (7.8 km) turns red; the train
    # runs on yellow then red-yellow and stops before the signal until the rail is repaired
    assert col["rail.occupied[4]"][(t > 301.0) & (t < 600.0)].min() == 1
    restrictive(300.0 + 0.2, 600.0, [sig.YELLOW, sig.RED_YELLOW, sig.WHITE, sig.RED])
    stopped = (t > 300.0) & (t < 600.0) & (col["train.v"] < 0.01)
    assert stopped.any() and col["train.x"][stopped].max() < 7800.0
    assert col["train.x"][-1] > 7800.0                                  # on again after the repair
    assert len(summary["scenario"]["events_applied"]) == 8


def test_joints_at_speed_no_aspect_artefact_through_the_station_throat(tmp_path, product_fmus):
    summary, col = _run(tmp_path, product_fmus, "joints_at_speed", 350.0,
                        ["train.x", "train.v", "rx.aspect", "ato.atp_aspect"])
    _no_danger(summary)
    throat = (col["train.x"] > 7600.0) & (col["train.x"] < 9400.0)      # three track circuits, one block
    assert throat.any() and col["train.v"][throat].min() * 3.6 > 150.0  # through the throat at speed
    assert summary["trains"][0]["atp_interventions"] == 0
    # every section carries З: the ATP acts on green throughout, the receiver never shows
    # another code (at most a short white while it resynchronises after a joint)
    assert [a["aspect"] for a in summary["trains"][0]["aspects"]] == ["white", "green"]
    assert set(np.unique(col["rx.aspect"][col["time"] > 6.0])) <= {sig.GREEN, sig.WHITE}


@pytest.mark.parametrize("system", ["als_en", "fire_dqpsk"])
def test_digital_free_run_reaches_b_on_time_without_danger(tmp_path, product_fmus, system):
    summary, col = _run(tmp_path, product_fmus, system, 560.0, ["rx.aspect", "rx.code_valid", "ato.atp_aspect"])
    _no_danger(summary)
    _on_time(summary["trains"][0], ("B",))
    settled = col["time"] > 10.0
    # every section carries the most permissive command: the ATP acts on green, and on no code
    # for the moments the receiver re-acquires after a joint (no display hold by default,
    # docs/loco_receiver.md#display-hold-equipment-inertia), never on a restrictive one
    acted = col["ato.atp_aspect"][settled]
    assert set(np.unique(acted)) <= {sig.GREEN, sig.WHITE} and np.mean(acted == sig.GREEN) > 0.95
    assert summary["trains"][0]["atp_interventions"] == 0
    assert summary["receivers"][0]["system"] == {"als_en": "ALS-EN", "fire_dqpsk": "FIRE_DQPSK"}[system]


def test_freight_ac_reaches_b_on_time(tmp_path, product_fmus):
    summary, _ = _run(tmp_path, product_fmus, "freight_ac", 930.0, ["train.x"])
    _no_danger(summary)
    stops = {s["station"]: s for s in summary["trains"][0]["stops"]}
    assert abs(stops["B"]["arrival_deviation_s"]) <= 15.0 and abs(stops["B"]["stop_error_m"]) <= 10.0


def _headways_m(summary):
    """min_headway_m wherever the train verdict puts it (per train, or for the run)."""
    found = [t["min_headway_m"] for t in summary["trains"] if t.get("min_headway_m") is not None]
    return found + ([summary["min_headway_m"]] if summary.get("min_headway_m") is not None else [])


def test_same_block_the_follower_waits_for_a_code_while_the_leader_stands_in_its_circuit(tmp_path, product_fmus):
    """The follower at A (400 m) and the leader standing at 2 km, both in track circuit 1
    (0-2600 m), the leader until 180 s. The follower's receiver never shows a permissive code
    while the leader is in that circuit; its ATO, due at 60 s, holds the departure and runs once
    the code arrives (docs/scenarios.md, same_block)."""
    summary, col = _run(tmp_path, product_fmus, "same_block", 420.0,
                        ["leader.x", "follower.x", "follower.v", "rx2.aspect", "rx2.code_valid",
                         "follower_ato.departure_hold"])
    _no_danger(summary)
    for receiver in summary["receivers"]:
        assert receiver["unsafe_indications"] == 0, receiver
    leader_tail_m = col["leader.x"] - LENGTH_M
    in_circuit = leader_tail_m < 2600.0
    permissive = np.isin(col["rx2.aspect"], [sig.GREEN, sig.YELLOW, sig.RED_YELLOW]) & (col["rx2.code_valid"] > 0.5)
    assert in_circuit.any() and not permissive[in_circuit].any()
    # the follower stands (not a centimetre) until the leader has cleared, then goes
    assert np.ptp(col["follower.x"][in_circuit]) < 1e-6
    assert col["follower.x"][-1] > 400.0 + 500.0
    assert (leader_tail_m - col["follower.x"]).min() > 0.0                 # never closer than touching
    follower = next(t for t in summary["trains"] if t["name"] == "follower")
    assert follower["departure_hold_s"] >= 120.0                            # due at 60 s, leader away at 180 s
    leader = next(t for t in summary["trains"] if t["name"] == "leader")
    assert leader["departure_hold_s"] == 0.0
    headways = _headways_m(summary)
    assert headways and min(headways) > 0.0


def test_no_shipped_system_places_trains_overlapping_or_off_the_line():
    """Initial placements (docs/scenarios.md): every train's head (x0) and tail (its length: the
    rolling-stock file's or the rail line's train_length, the longer) on the line, no two overlapping."""
    from fmus.data.loader import DATA
    from orchestrator.ssp import read_ssd

    for folder in sorted(p for p in SSP_ROOT.iterdir() if (p / "SystemStructure.ssd").is_file()):
        system = read_ssd(folder / "SystemStructure.ssd", folder)

        def param(component, name, default):
            return next((v.value for v in system.components[component].parameters if v.name == name), default)

        def data(name, default):
            return json.loads(((folder / "resources" / name) if name else (DATA / default)).read_text())

        spans = []
        for name, component in system.components.items():
            if not component.source.endswith("Traction.fmu"):
                continue
            line = data(param(name, "line_file", ""), "default_line.json")
            length_m = data(param(name, "rolling_stock_file", ""), "passenger_chs7.json")["length_m"]
            slot = next((c.end_connector for c in system.connections
                         if c.start_element == name and c.start_connector == "x"
                         and c.end_connector.startswith("x_head[")), None)
            if slot is not None:
                length_m = max(length_m, param("rail", slot.replace("x_head", "train_length"), 400.0))
            head_m = param(name, "x0", 400.0)
            assert head_m - length_m >= 0.0 and head_m <= line["length_m"], (folder.name, name)
            spans.append((head_m - length_m, head_m, name))
        spans.sort()
        for (_, head_m, name), (tail_m, _, other) in zip(spans, spans[1:]):
            assert tail_m > head_m, (folder.name, name, other)


def test_every_shipped_system_is_written_and_packed(tmp_path, product_fmus):
    import zipfile

    from orchestrator.packaging.packing import pack_systems

    names = {p.name for p in SSP_ROOT.iterdir() if (p / "SystemStructure.ssd").is_file()}
    assert {"free_run", "ato_only", "following", "faults", "joints_at_speed", "freight_ac", "als_en", "fire_dqpsk",
            "als_en_following", "fire_dqpsk_following", "same_block"} <= names
    packed = {p.stem: p for p in pack_systems(SSP_ROOT, product_fmus, tmp_path)}
    assert set(packed) == names
    with zipfile.ZipFile(packed["following"]) as archive:      # the archive carries its scenario and data
        assert {"scenario.json", "resources/follower_timetable.json", "resources/RailLine.fmu"} <= set(archive.namelist())
    scenario = json.loads((SSP_ROOT / "faults" / "scenario.json").read_text())
    assert {e["variable"] for e in scenario["events"]} == {"feed_open[1]", "fault_main", "fault_reserve", "broken_rail_at"}


@pytest.mark.parametrize("system, trains, stop_s", [("suburban_peak", 10, 420.0), ("tvm430_headway", 5, 150.0)])
def test_systems_of_many_trains_start_in_order_and_safely(tmp_path, product_fmus, system, trains, stop_s):
    """The waiting trains of the many-train systems (docs/capacity.md): only the leader has left
    by its first minutes, the others stand where they wait (suburban_peak: on holding circuits
    of their own; tvm430_headway: queued in the circuits they share), one behind the other, and
    nothing is unsafe while they stand. The full runs: docs/scenarios.md#systems-of-many-trains."""
    if not (SSP_ROOT / system).is_dir():
        pytest.skip(f"{system} not written")
    summary, columns = _run(tmp_path, product_fmus, system, stop_s,
                            record=[f"train{j}.{v}" for j in range(1, trains + 1) for v in ("x", "v")])
    _no_danger(summary)
    assert len(summary["trains"]) == trains
    start = [columns[f"train{j}.x"][0] for j in range(1, trains + 1)]
    end = [columns[f"train{j}.x"][-1] for j in range(1, trains + 1)]
    assert all(a > b for a, b in zip(start, start[1:]))          # the leader ahead of the queue
    assert end[0] > start[0] + 300.0                             # it has left
    assert np.allclose(end[1:], start[1:])                       # the others wait their turn

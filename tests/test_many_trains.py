"""Many trains on one line (docs/performance.md#many-trains): 12 and 16 trains queued on the
default line, each with its own receiver, ATO and verdict; the report's pictures with 16 trains;
the suburban line (docs/rail_line.md#the-suburban-line) with one EMU. Short runs: the cost
against trains is benchmarks/bench_trains.py's."""
import json

import numpy as np
import pytest

from fmus.data.loader import DATA, load_line
from harness.queued_trains import Queue, origins, write_queued_trains
from harness.suburban import SUBURBAN_TIMETABLE, fastest_stage_times, write_suburban_emu
from helpers import read_csv
from orchestrator.reports.report import make_report, train_styles
from orchestrator.systems.chain import stock_length_m
from orchestrator.verdicts.verdict import railway_verdicts
from orchestrator.packaging.builder import build_sized_for
from orchestrator.run import RunOptions, run_system


def _run(folder, out, fmu_dir, in_process, record=None):
    build_sized_for(fmu_dir, [folder])
    result = run_system(folder, RunOptions(summaries=railway_verdicts, output_dir=out, in_process=in_process,
                                           fmu_dirs=[fmu_dir], record=record))
    header, data = read_csv(out / "results.csv")
    return result.summary, {name: data[:, i] for i, name in enumerate(header)}


def _safe(summary):
    for train in summary["trains"]:
        assert train["signals_passed_at_danger"] == 0, train["name"]
        assert train["emergency_brakings"] == 0, train["name"]
    for receiver in summary["receivers"]:
        assert receiver["wrong_side_failures"] == 0, receiver
        assert receiver["unsafe_indications"] == 0, receiver


def _behind_a_train_in_its_circuit(line, heads, length_m):
    """Per train (front first): whether the train ahead stands in the track circuit of its head,
    between it and the circuit's feed end, where the code comes from."""
    ends = [s.end_m for s in line.sections]
    behind = []
    for j, head in enumerate(heads):
        end = next(e for e in ends if e > head)
        behind.append(j > 0 and heads[j - 1] - length_m < end)
    return behind


@pytest.mark.parametrize("trains, in_process", [(12, False), (16, True)], ids=["12 through FMI", "16 in process"])
def test_trains_queued_on_the_default_line_get_their_own_code_and_verdict(tmp_path, product_fmus, trains, in_process):
    queue = Queue(trains=trains, first_departure_s=5.0, departure_interval_s=0.5, stop_time_s=20.0)
    folder = tmp_path / "queue"
    write_queued_trains(folder, queue)
    summary, results = _run(folder, tmp_path / "out", product_fmus, in_process)
    names = [f"train{j}" for j in range(1, trains + 1)]
    assert [t["name"] for t in summary["trains"]] == names
    assert [r["train"] for r in summary["receivers"]] == names
    _safe(summary)
    # every train's outputs are in results.csv, its own columns
    for j in range(1, trains + 1):
        assert {f"train{j}.x", f"rx{j}.aspect", f"ato{j}.v_atp", f"rail.coil_section[{j}]"} <= results.keys()
    length_m = stock_length_m()
    heads = [head for _, head in origins(queue)]
    line = load_line(folder / "resources" / "queued_line.json")
    behind = _behind_a_train_in_its_circuit(line, heads, length_m)
    assert any(behind) and not all(behind)
    for j, (train, held) in enumerate(zip(summary["trains"], behind), start=1):
        moved_m = float(np.ptp(results[f"train{j}.x"]))
        if held:     # the train ahead shunts the code away: no code, the departure is held
            assert moved_m < 1.0 and train["departure_hold_s"] > 0, train
            assert {a["aspect"] for a in train["aspects"]} == {"white"}, train
        else:        # a code (green, yellow or red-yellow) and away
            assert moved_m > 1.0, train
            assert {a["aspect"] for a in train["aspects"]} - {"white"}, train
        # the headway to the train ahead, the leader none
        if j == 1:
            assert train["min_headway_m"] is None
        else:
            assert 0.0 < train["min_headway_m"] <= queue.spacing_m - length_m + 1e-6, train
    # the cycles broken are named by their members: the chain's loops, then each train with its
    # ATO (once listing every component left, N² names)
    cycles = json.loads((tmp_path / "out" / "metadata.json").read_text())["cycles_broken"]
    assert [sorted(c) for c in cycles[2:]] == [sorted([f"train{j}", f"ato{j}"]) for j in range(1, trains + 1)]
    if trains == 16:
        written = make_report(tmp_path / "out", tmp_path / "report")
        assert {p.name for p in written} >= {"speed_distance.png", "time_distance.png", "energy.png", "report.html"}


def test_every_train_of_sixteen_is_drawn_in_a_style_of_its_own():
    styles = train_styles([f"train{j}" for j in range(1, 17)])
    assert len({(s["color"], s["ls"]) for s in styles.values()}) == 16


def test_one_emu_on_the_suburban_line_departs_on_green_and_runs_on_green(tmp_path, product_fmus):
    folder = tmp_path / "suburban"
    write_suburban_emu(folder, 100.0)     # the timetable departs at 60 s
    summary, results = _run(folder, tmp_path / "out", product_fmus, True, ["train.x", "rx.aspect", "rx.code_valid"])
    _safe(summary)
    train = summary["trains"][0]
    assert [a["aspect"] for a in train["aspects"]] == ["white", "green"]
    assert train["departure_hold_s"] == 0.0
    assert results["train.x"][-1] - results["train.x"][0] > 300.0     # away from Glavnaya
    assert summary["receivers"][0]["decoded_codes"] > 10


def test_the_suburban_timetable_runs_five_to_eight_percent_over_the_fastest_run(product_fmus):
    stops = json.loads((DATA / SUBURBAN_TIMETABLE).read_text())["stops"]
    for k, (origin, to, fastest_s) in enumerate(fastest_stage_times([product_fmus])):
        assert (origin, to) == (stops[k]["station"], stops[k + 1]["station"])
        scheduled_s = stops[k + 1]["arrival_s"] - stops[k]["departure_s"]
        assert 1.05 <= scheduled_s / fastest_s <= 1.08, (origin, to, scheduled_s, fastest_s)


def test_the_suburban_line_fits_a_build_of_32_sections_and_its_platforms_the_emu():
    line = load_line(DATA / "suburban_line.json")
    lengths = [s.end_m - s.start_m for s in line.sections]
    assert len(lengths) <= 32 and 1000.0 <= min(lengths) and max(lengths) <= 1500.0
    gaps = np.diff([s.stop_m for s in line.stations])
    assert len(line.stations) >= 10 and 2000.0 <= gaps.min() and gaps.max() <= 4000.0
    raw = json.loads((DATA / "suburban_line.json").read_text())
    assert min(s["platform_length_m"] for s in raw["stations"]) >= stock_length_m("emu_er2.json")

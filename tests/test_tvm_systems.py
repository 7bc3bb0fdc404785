"""TVM-430 and TVM-300 through the whole chain under the orchestrator (coder → rail line → receiver
→ ATP/ATO, docs/scenarios.md): the run's verdicts judge a TVM receiver against the codes sent and
against the block rules on the real occupancy; the shipped tvm430 and tvm300 systems run on their
own build sizes (32 sections, 10 ms frames at 12 kHz). The full tvm430, tvm430_following, tvm300
and tvm300_following runs are in docs/scenarios.md's table."""
import json

import pytest

from fmus.signalling import cab_systems
from harness.broken_rail import run_with_broken_rail
from orchestrator.systems.chain import signal_chain, train_and_ato
from orchestrator.verdicts.verdict import railway_verdicts, safety_verdict
from orchestrator.run import RunOptions, run_system

BLOCK_M, BLOCKS = 1500.0, 8
FS_HZ, FRAME = 16000.0, 40          # the default build's 40-sample frame: 2.5 ms at 16 kHz
BROKEN_RAIL_M = 3500.0              # in block 3, ahead of the train standing at 400 m in block 1


def _line(folder):
    blocks = [{"name": str(k + 1), "start_m": k * BLOCK_M, "end_m": (k + 1) * BLOCK_M, "signal": f"R{k + 1}",
               "transmitter": "UM71", "carrier_hz": (1700, 2300)[k % 2], "ballast_ohm_km": 2.0}
              for k in range(BLOCKS)]
    doc = {"name": "TVM test line", "length_m": BLOCKS * BLOCK_M, "max_ballast_ohm_km": 50,
           "electrification": {"system": "AC25000"}, "block_sections": blocks,
           "separation_zones": [{"position_m": k * BLOCK_M} for k in range(1, BLOCKS)],
           "stations": [{"name": "A", "stop_m": 400.0}, {"name": "Z", "stop_m": 11500.0}],
           "gradients": [{"start_m": 0.0, "permille": 0.0}], "curves": [],
           "speed_limits": [{"start_m": 0.0, "passenger_kmh": 160, "freight_kmh": 100, "high_speed_kmh": 300}]}
    path = folder / "tvm_line.json"
    path.write_text(json.dumps(doc))
    timetable = folder / "tvm_timetable.json"
    timetable.write_text(json.dumps({"train": "TGV", "stops": [{"station": "A", "departure_s": 5.0},
                                                               {"station": "Z", "arrival_s": 400.0}]}))
    return path, timetable


TVM_SYSTEMS = [cab.name for cab in cab_systems.REGISTRY.values() if cab.transmitter == cab_systems.UM71]


def _run(tmp_path, product_fmus, occupancy_sent: bool, system: str, stop_time: float = 16.0):
    cab = cab_systems.lookup(system)
    folder = str(product_fmus)
    line, timetable = _line(tmp_path)
    files = {"line_file": str(line)}
    from fmus.data.loader import DATA

    stock = {"rolling_stock_file": str(DATA / "high_speed_tgv.json")}
    components, connections = train_and_ato(
        fmu_folder=folder, train_parameters={**files, **stock},
        ato_parameters={**cab.ato_parameters(), "timetable_file": str(timetable), **files, **stock})
    chain, links = signal_chain(fmu_folder=folder, fs_hz=FS_HZ, frame=FRAME, coder={"system": system, **files},
                                rail=files, receiver={"system": system, "train_category": "high_speed"},
                                stocks=[stock["rolling_stock_file"]])
    # occupancy not sent: the coder never learns it and sends a clear line's words everywhere
    return run_with_broken_rail(tmp_path, product_fmus, chain + components, connections + links, BROKEN_RAIL_M,
                                occupancy_sent, stop_time)


@pytest.mark.parametrize("system", TVM_SYSTEMS)
def test_a_tvm_coder_that_never_hears_the_occupancy_is_caught_against_the_track(tmp_path, product_fmus, system):
    summary, rx = _run(tmp_path, product_fmus, False, system)
    assert rx["system"] == system and rx["decoded_codes"] > 0, rx
    assert rx["wrong_side_failures"] == 0, rx          # the receiver shows the word sent …
    assert rx["unsafe_indications"] == 1, rx           # … which the broken rail two blocks ahead forbids
    (event,) = rx["unsafe_events"]
    assert event["section"] == 1 and event["free_blocks_allowed"] == 1
    safe, line = safety_verdict(summary)
    assert not safe and "unsafe indications 1" in line


@pytest.mark.parametrize("system", TVM_SYSTEMS)
def test_the_same_fault_with_the_occupancy_sent_is_safe(tmp_path, product_fmus, system):
    summary, rx = _run(tmp_path, product_fmus, True, system)
    assert rx["decoded_codes"] > 0 and rx["wrong_side_failures"] == 0 and rx["unsafe_indications"] == 0, rx
    assert rx["latency_s"] == pytest.approx({"TVM430": 5.1875, "TVM300": 3.1273}[system], abs=1e-4)
    assert safety_verdict(summary)[0]
    (train,) = summary["trains"]
    assert train["signals_passed_at_danger"] == 0 and train["atp_interventions"] == 0


@pytest.mark.parametrize("system", TVM_SYSTEMS)
def test_the_shipped_tvm_system_runs_on_its_build_sizes_and_departs_under_its_codes(tmp_path, product_fmus, system):
    from orchestrator.systems.shipped import SSP_ROOT

    result = run_system(SSP_ROOT / system.lower(), RunOptions(summaries=railway_verdicts, output_dir=tmp_path / "out",
                                                        in_process=True, fmu_dirs=[product_fmus], stop_time=130.0,
                                                        record=["train.x", "train.v", "rx.v_permitted",
                                                                "rx.word_carrier"]))
    summary = result.summary
    (rx,) = summary["receivers"]
    assert rx["system"] == system and rx["wrong_side_failures"] == 0 and rx["unsafe_indications"] == 0, rx
    assert safety_verdict(summary)[0]
    header, *rows = (line.split(",") for line in (tmp_path / "out" / "results.csv").read_text().splitlines())
    column = {name: k for k, name in enumerate(header)}
    last = rows[-1]
    assert float(last[column["train.x"]]) > 2100.0          # out of the first block, on its 300 km/h code
    assert float(last[column["rx.v_permitted"]]) == pytest.approx(300 / 3.6)
    assert {float(r[column["rx.word_carrier"]]) for r in rows} >= {1700.0, 2300.0}

"""Initial placements and train lengths (docs/scenarios.md, "Trains on the line"): a train whose
tail starts before the line, or two trains overlapping on one rail line, are refused before the
run (one line, exit 2); a rail line given another length than the train's rolling-stock file is
a warning; every shipped system's rail line carries its trains' rolling-stock lengths."""
import json

import pytest

from fmus.data.loader import DATA
from helpers import railcosim
from orchestrator.systems.chain import signal_chain, stock_length_m, train_and_ato
from orchestrator.systems.shipped import SSP_ROOT
from orchestrator.sspgen import write_ssd

FREIGHT = {"rolling_stock_file": str(DATA / "freight_vl80.json")}


def _two_trains(tmp_path, product_fmus, leader_x0_m, rail=None, stocks=None):
    folder = str(product_fmus)
    leader, leader_links = train_and_ato("leader", "leader_ato", {"x0": leader_x0_m}, {"cab_signal": "ALSN"},
                                         fmu_folder=folder)
    follower, follower_links = train_and_ato("follower", "follower_ato", {}, {"cab_signal": "ALSN"},
                                             fmu_folder=folder)
    chain, links = signal_chain((("leader", "leader_ato"), ("follower", "follower_ato")), fmu_folder=folder,
                                rail=rail, stocks=stocks)
    ssd = write_ssd(tmp_path / "sys", "sys", chain + leader + follower, links + leader_links + follower_links,
                    stop_time=1.0)
    return ssd.parent


def test_overlapping_trains_are_refused_naming_both(tmp_path, product_fmus):
    code, _, stderr = railcosim("validate", _two_trains(tmp_path, product_fmus, leader_x0_m=600.0))
    assert code == 2 and "Traceback" not in stderr
    assert "trains 'follower' (head 400 m) and 'leader' (tail 212 m) overlap at t = 0" in stderr
    # validate also initialises the components, and the rail line refuses the same placement in
    # its own words: every line is about these two trains, the system check's comes first
    lines = stderr.strip().splitlines()
    assert "overlap at t = 0" in lines[0]
    assert all("overlap" in line for line in lines)


def test_trains_apart_are_valid_and_a_wrong_rail_train_length_is_a_warning(tmp_path, product_fmus):
    code, stdout, stderr = railcosim("validate", _two_trains(tmp_path, product_fmus, leader_x0_m=900.0,
                                                             rail={"train_length[2]": 400.0}))
    assert code == 0 and "valid" in stdout, stderr
    assert "warning: rail.train_length[2] = 400 m, but train 'follower' on that slot is 388 m long" in stderr


def test_a_rail_line_given_another_trains_wheelsets_is_a_warning(tmp_path, product_fmus):
    code, stdout, stderr = railcosim("validate", _two_trains(tmp_path, product_fmus, leader_x0_m=900.0,
                                                             rail={"rolling_stock_file[1]": str(DATA / "emu_er2.json"),
                                                                   "train_length[1]": 388.0}))
    assert code == 0 and "valid" in stdout, stderr
    assert ("warning: rail.rolling_stock_file[1] is emu_er2.json, but train 'leader' on that slot runs on the "
            "bundled default passenger_chs7.json") in stderr


def test_a_train_whose_tail_is_before_the_line_start_is_refused(tmp_path, product_fmus):
    folder = str(product_fmus)
    components, connections = train_and_ato(train_parameters=FREIGHT, ato_parameters={"cab_signal": "ALSN", **FREIGHT},
                                            fmu_folder=folder)
    chain, links = signal_chain(fmu_folder=folder, stocks=[FREIGHT["rolling_stock_file"]])
    ssd = write_ssd(tmp_path / "sys", "sys", chain + components, connections + links, stop_time=1.0)
    code, _, stderr = railcosim("run", ssd.parent, "--no-build", "--in-process", "--output", tmp_path / "out")
    assert code == 2 and "Traceback" not in stderr
    assert "train 'train' (head x0 = 400 m, 944 m long in freight_vl80.json) is not on its line" in stderr
    assert "its tail at -544 m is before the line start" in stderr


def test_signal_chain_gives_the_rail_line_the_rolling_stock_lengths():
    chain, _ = signal_chain((("a", "a_ato"), ("b", "b_ato")), stocks=[None, "freight_vl80.json"])
    rail = next(c for c in chain if c.name == "rail")
    assert rail.parameters["train_length[1]"] == pytest.approx(388.0) == stock_length_m()
    assert rail.parameters["train_length[2]"] == pytest.approx(944.0)


@pytest.mark.parametrize("system", ["following", "same_block", "freight_ac", "free_run"])
def test_every_shipped_rail_line_carries_its_trains_rolling_stock_lengths(system):
    from orchestrator.ssp import read_ssd

    folder = SSP_ROOT / system
    ssd = read_ssd(folder / "SystemStructure.ssd", folder)
    params = {c: {v.name: v.value for v in comp.parameters} for c, comp in ssd.components.items()}
    for connection in ssd.connections:
        if connection.end_element == "rail" and connection.end_connector.startswith("x_head["):
            stock = params[connection.start_element].get("rolling_stock_file")
            length_m = json.loads(((folder / "resources" / stock) if stock else DATA / "passenger_chs7.json")
                                  .read_text())["length_m"]
            slot = connection.end_connector.replace("x_head", "train_length")
            assert params["rail"][slot] == pytest.approx(length_m), (system, slot)

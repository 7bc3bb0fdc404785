"""`railcosim new`: a system folder of one's own (docs/your_own_system.md) that `railcosim run`
runs, with one line file shared by every component through one parameter set."""
import json
import os
import shutil

import pytest

from helpers import REPO, railcosim

EXAMPLES = REPO / "docs" / "examples"


def _new(tmp_path, *extra, name="branch"):
    return railcosim("new", name, "--line", EXAMPLES / "short_line.json", "--timetable",
                     EXAMPLES / "short_timetable.json", *extra, cwd=tmp_path)


def test_new_then_run_lists_the_custom_timetables_stops(tmp_path, product_fmus):
    code, stdout, stderr = _new(tmp_path)
    assert code == 0, stderr
    folder = tmp_path / "branch"
    assert {p.name for p in folder.iterdir()} == {"SystemStructure.ssd", "line.ssv", "resources"}
    assert {p.name for p in (folder / "resources").iterdir()} == {"short_line.json", "short_timetable.json",
                                                                  "passenger_chs7.json"}
    # the line file is named once, in the parameter set every line-reading component binds
    ssd = (folder / "SystemStructure.ssd").read_text()
    assert ssd.count('source="line.ssv"') == 4 and "short_line.json" not in ssd
    assert "short_line.json" in (folder / "line.ssv").read_text()
    code, stdout, stderr = railcosim("run", "branch", "--no-build", "--in-process", "--stop-time", "260",
                                     "--output", tmp_path / "out", cwd=tmp_path)
    assert code == 0, stderr
    assert "warning" not in stderr, stderr
    (train,) = json.loads((tmp_path / "out" / "summary.json").read_text())["trains"]
    stops = {s["station"]: s for s in train["stops"]}
    assert list(stops) == ["Halt", "South"]
    assert stops["Halt"]["reached"] and abs(stops["Halt"]["stop_error_m"]) < 1.0
    assert not stops["South"]["reached"] and stops["South"]["scheduled_arrival_s"] == 460.0
    assert train["signals_passed_at_danger"] == 0
    assert "South not reached (due 460 s)" in stdout


def test_a_component_on_another_line_is_refused(tmp_path, product_fmus):
    assert _new(tmp_path)[0] == 0
    other = tmp_path / "other_line.json"
    shutil.copyfile(REPO / "fmus" / "data" / "shipped" / "default_line.json", other)
    code, _, stderr = railcosim("run", "branch", "--no-build", "--in-process", "--stop-time", "1", "--set",
                                f"train.line_file={other}", "--output", tmp_path / "out", cwd=tmp_path)
    assert code == 2 and "Traceback" not in stderr
    assert "train.line_file" in stderr and "must run on one line file" in stderr


def test_new_refuses_bad_input_in_one_line(tmp_path):
    code, _, stderr = _new(tmp_path, "--traction", "ac")
    assert code == 2 and "--traction ac" in stderr and "electrification.system is 'DC3000'" in stderr
    code, _, stderr = _new(tmp_path, "--trains", "2")
    assert code == 2 and "give one --timetable per train" in stderr
    code, _, stderr = _new(tmp_path, "--system", "bogus")
    assert code == 2 and "--system bogus" in stderr
    (tmp_path / "taken").mkdir()
    (tmp_path / "taken" / "file").write_text("x")
    code, _, stderr = _new(tmp_path, name="taken")
    assert code == 2 and "already exists" in stderr
    assert "Traceback" not in stderr and len(stderr.strip().splitlines()) == 1


# ---- one `new` per folder ----------------------------------------------------------------------------
def _timetables(tmp_path, count):
    """``count`` copies of the example timetable under different names: which one a folder
    holds tells which `new` wrote it."""
    paths = []
    for k in range(count):
        path = tmp_path / f"timetable_{k}.json"
        shutil.copyfile(EXAMPLES / "short_timetable.json", path)
        paths.append(path)
    return paths


def test_two_concurrent_news_into_one_folder_give_one_system_and_one_refusal(tmp_path):
    """Two `railcosim new SAME` at once, three times: one writes the folder, the other is refused
    in one line, and the folder holds one system, never a mix of both."""
    import subprocess
    import sys

    from helpers import cli_environment

    for trial in range(3):
        name = f"same{trial}"
        (tmp_path / name).mkdir()
        timetables = _timetables(tmp_path / name, 2)
        procs = [subprocess.Popen([sys.executable, "-m", "orchestrator", "new", f"out/{name}", "--line",
                                   str(EXAMPLES / "short_line.json"), "--timetable", str(timetable)],
                                  cwd=tmp_path, env=cli_environment(), stdout=subprocess.PIPE,
                                  stderr=subprocess.PIPE, text=True) for timetable in timetables]
        outcomes = [(proc.wait(timeout=300), *proc.communicate()) for proc in procs]
        codes = sorted(code for code, _, _ in outcomes)
        assert codes == [0, 2], outcomes
        code, _, stderr = next(outcome for outcome in outcomes if outcome[0] == 2)
        assert stderr.count("\n") == 1 and "already exists" in stderr and "Traceback" not in stderr, stderr
        winner = timetables[[code for code, _, _ in outcomes].index(0)]
        folder = tmp_path / "out" / name
        assert sorted(p.name for p in (folder / "resources").iterdir()) == \
            sorted(["short_line.json", "passenger_chs7.json", winner.name])
        assert winner.name in (folder / "SystemStructure.ssd").read_text()
        assert sorted(os.listdir(tmp_path / "out")) == [f"same{k}" for k in range(trial + 1)]   # no staging left


def test_a_folder_made_while_new_writes_is_not_written_into(tmp_path, monkeypatch):
    """The folder appears (another `new`, a user) after the first check: this `new` is refused in
    one line, leaves the other's files as they are and no half-written folder of its own."""
    from orchestrator.systems import new_system as module
    from orchestrator.errors import UserError

    folder = tmp_path / "branch"
    write_ssd = module.write_ssd

    def someone_else_first(*args, **kwargs):
        folder.mkdir()
        (folder / "SystemStructure.ssd").write_text("the other's system")
        return write_ssd(*args, **kwargs)

    monkeypatch.setattr(module, "write_ssd", someone_else_first)
    with pytest.raises(UserError, match="branch: already exists"):
        module.new_system(folder, EXAMPLES / "short_line.json", [EXAMPLES / "short_timetable.json"])
    assert os.listdir(folder) == ["SystemStructure.ssd"]
    assert (folder / "SystemStructure.ssd").read_text() == "the other's system"
    assert os.listdir(tmp_path) == ["branch"]


def test_new_into_an_empty_folder_or_a_link_to_one(tmp_path):
    """An empty folder is taken (as before); a symbolic link, even to an empty folder, is a name
    that exists: refused, nothing written where it points."""
    (tmp_path / "empty").mkdir()
    code, _, stderr = _new(tmp_path, name="empty")
    assert code == 0, stderr
    assert (tmp_path / "empty" / "SystemStructure.ssd").is_file()
    (tmp_path / "target").mkdir()
    (tmp_path / "link").symlink_to(tmp_path / "target")
    code, _, stderr = _new(tmp_path, name="link")
    assert code == 2 and "already exists" in stderr and len(stderr.strip().splitlines()) == 1, stderr
    assert os.listdir(tmp_path / "target") == []


# ---- TVM-430: a line of UM71 track circuits -------------------------------------------------------
SHIPPED_DATA = REPO / "fmus" / "data" / "shipped"
TVM_LINE = SHIPPED_DATA / "hsl_tvm430_line.json"
TVM_TIMETABLE = EXAMPLES / "lgv_timetable.json"     # Origine at 10 s, Terminus at 760 s


def _sources(folder):
    from lxml import etree

    root = etree.parse(str(folder / "SystemStructure.ssd")).getroot()
    return {c.get("name"): c.get("source") for c in root.iter("{*}Component")}


def _um71_line(tmp_path, sections: int, block_m: float = 1000.0, alsn_after: int = 0):
    """A line of ``sections`` UM71 track circuits (track 1's carriers, a separation zone at every
    boundary), then ``alsn_after`` ALSN ones (KPT-5, 25 Hz under AC, insulated joints), with stations at
    both ends, and a timetable between them."""
    blocks = [{"name": str(k + 1), "start_m": k * block_m, "end_m": (k + 1) * block_m, "signal": f"R{k + 1}",
               "transmitter": "UM71", "carrier_hz": (1700, 2300)[k % 2], "ballast_ohm_km": 2.0}
              for k in range(sections)]
    blocks += [{"name": str(k + 1), "start_m": k * block_m, "end_m": (k + 1) * block_m, "signal": f"R{k + 1}",
                "transmitter": "KPT-5", "carrier_hz": 25, "ballast_ohm_km": 2.0}
               for k in range(sections, sections + alsn_after)]
    length_m = len(blocks) * block_m
    line = {"name": f"{sections} UM71 sections", "length_m": length_m, "max_ballast_ohm_km": 50,
            "electrification": {"system": "AC25000"}, "block_sections": blocks,
            "separation_zones": [{"position_m": k * block_m} for k in range(1, sections)],
            "insulated_joints": [{"position_m": k * block_m} for k in range(sections, len(blocks) + 1)
                                 if alsn_after],
            "stations": [{"name": "A", "stop_m": 400.0}, {"name": "Z", "stop_m": length_m - 500.0}],
            "gradients": [{"start_m": 0.0, "permille": 0.0}], "curves": [],
            "speed_limits": [{"start_m": 0.0, "passenger_kmh": 160, "freight_kmh": 100, "high_speed_kmh": 300}]}
    path, timetable = tmp_path / f"um71_{sections}.json", tmp_path / f"um71_{sections}_timetable.json"
    path.write_text(json.dumps(line))
    timetable.write_text(json.dumps({"train": "TGV", "stops": [{"station": "A", "departure_s": 10},
                                                               {"station": "Z", "arrival_s": 60 * sections}]}))
    return path, timetable


def test_a_tvm430_system_on_the_high_speed_line_runs_its_chain_at_12_khz_and_is_safe(tmp_path, product_fmus):
    code, stdout, stderr = railcosim("new", "lgv", "--line", TVM_LINE, "--timetable", TVM_TIMETABLE,
                                     "--system", "TVM430", cwd=tmp_path)
    assert code == 0, stderr
    folder = tmp_path / "lgv"
    # 28 sections: the standard build of 32, 10 ms frames of 120 samples, as the shipped tvm430's
    sources = _sources(folder)
    assert {sources[name] for name in ("coder", "rail", "rx")} == {
        f"resources/k32m2n120/{fmu}.fmu" for fmu in ("WaysideCoder", "RailLine", "LocoReceiver")}
    assert sources["train"] == "resources/Traction.fmu"
    assert {p.name for p in (folder / "resources").iterdir()} == {"hsl_tvm430_line.json", "lgv_timetable.json",
                                                                  "high_speed_tgv.json"}
    code, stdout, stderr = railcosim("run", "lgv", "--no-build", "--in-process", "--stop-time", "60",
                                     "--record", "train.x", "--record", "rx.v_permitted",
                                     "--output", tmp_path / "out", cwd=tmp_path)
    assert code == 0, stderr
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    (rx,) = summary["receivers"]
    assert rx["system"] == "TVM430" and rx["decoded_codes"] > 0, rx
    assert rx["wrong_side_failures"] == 0 and rx["unsafe_indications"] == 0, rx
    (train,) = summary["trains"]
    assert train["signals_passed_at_danger"] == 0
    assert "safety: safe" in stdout
    header, *rows = (line.split(",") for line in (tmp_path / "out" / "results.csv").read_text().splitlines())
    column = {name: k for k, name in enumerate(header)}
    # departed (10 s) on its words: over 500 m run, under block 1's word of 170 km/h (the line's limit there)
    assert float(rows[-1][column["train.x"]]) > 900.0
    assert float(rows[-1][column["rx.v_permitted"]]) == pytest.approx(170 / 3.6)


def test_a_tvm430_system_takes_the_smallest_standard_section_count_that_holds_the_line(tmp_path):
    line, timetable = _um71_line(tmp_path, 10)
    code, _, stderr = railcosim("new", "ten", "--line", line, "--timetable", timetable, "--system", "TVM430",
                                cwd=tmp_path)
    assert code == 0, stderr
    assert _sources(tmp_path / "ten")["rail"] == "resources/k16m2n120/RailLine.fmu"
    ssd = (tmp_path / "ten" / "SystemStructure.ssd").read_text()
    assert '"u_tx[16,120]"' in ssd and '"u_tx[17,1]"' not in ssd


def test_a_tvm430_system_from_railml_gets_the_high_speed_set_and_its_timetable(tmp_path):
    from orchestrator.railml.write import export_railml

    railml = tmp_path / "lgv.xml"
    railml.write_bytes(export_railml(json.loads(TVM_LINE.read_text())))
    code, _, stderr = railcosim("new", "lgv", "--railml", railml, "--system", "TVM430", cwd=tmp_path)
    assert code == 0, stderr
    resources = {p.name for p in (tmp_path / "lgv" / "resources").iterdir()}
    assert resources == {"lgv.json", "lgv_timetable.json", "high_speed_tgv.json"}
    assert _sources(tmp_path / "lgv")["rx"] == "resources/k32m2n120/LocoReceiver.fmu"


def test_tvm430_and_the_other_systems_are_refused_on_each_others_track_circuits(tmp_path):
    def refused(*args):
        code, _, stderr = railcosim("new", "x", *args, cwd=tmp_path)
        assert code == 2 and "Traceback" not in stderr and len(stderr.strip().splitlines()) == 1, stderr
        assert not (tmp_path / "x").exists()
        return stderr

    stderr = refused("--line", EXAMPLES / "short_line.json", "--timetable", EXAMPLES / "short_timetable.json",
                     "--system", "TVM430")
    assert "--system TVM430" in stderr and "short_line.json has no UM71 sections" in stderr
    for system in ("ALSN", "ALS-EN"):
        stderr = refused("--line", TVM_LINE, "--timetable", TVM_TIMETABLE, "--system", system)
        assert f"--system {system}" in stderr and "block_sections[0].transmitter is 'UM71'" in stderr
        assert "give --system TVM430" in stderr
    line, timetable = _um71_line(tmp_path, 3, alsn_after=2)         # UM71 then ALSN: TVM codes three
    stderr = refused("--line", line, "--timetable", timetable, "--system", "TVM430")
    assert "field block_sections[3].transmitter is 'KPT-5'" in stderr and "UM71 track circuits only" in stderr
    line, timetable = _um71_line(tmp_path, 65, block_m=500.0)
    stderr = refused("--line", line, "--timetable", timetable, "--system", "TVM430")
    assert "65 block sections" in stderr and "at most 64" in stderr

"""`railcosim new`: a system folder of one's own (docs/your_own_system.md) that `railcosim run`
runs, with one line file shared by every component through one parameter set."""
import json
import shutil

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

"""Bad systems, parameter sets and scenarios: each through the CLI as a user meets
it — exit code 2, one line on stderr naming the file the user gave and the field, no traceback
(docs/scenarios.md, "Systems, parameter sets and scenarios: bad input")."""
import json
import shutil
import zipfile
from pathlib import Path

import pytest

from helpers import REPO, ComponentSpec, ConnectionSpec, railcosim, write_ssd


def _expect_error(code, stderr, *fragments):
    assert code == 2, stderr
    lines = [line for line in stderr.splitlines() if line.strip()]
    assert len(lines) == 1, stderr
    assert "Traceback" not in stderr
    assert "railcosim_ssp_" not in lines[0], lines[0]          # never the extraction folder
    for fragment in fragments:
        assert fragment in lines[0], lines[0]
    return lines[0]


def _pair(folder: Path, fmus: Path, connections=(), gain_parameters=None, name="pair", components=None):
    write_ssd(folder, name, components or [
        ComponentSpec("clock", str(fmus / "TestCounter.fmu"), 0.5),
        ComponentSpec("gain", str(fmus / "TestGain.fmu"), 0.5, gain_parameters or {}),
    ], list(connections), stop_time=1.0, base_step_s=0.5)
    return folder


def _replace_in_ssd(folder: Path, old: str, new: str, count: int = 1) -> None:
    ssd = folder / "SystemStructure.ssd"
    text = ssd.read_text()
    assert text.count(old) >= count, old
    ssd.write_text(text.replace(old, new, count))


def _pack(folder: Path, archive: Path, compression=zipfile.ZIP_DEFLATED) -> Path:
    with zipfile.ZipFile(archive, "w", compression) as packed:
        for path in sorted(folder.rglob("*")):
            if path.is_file():
                packed.write(path, path.relative_to(folder).as_posix())
    return archive


def _run(system, tmp_path, *extra):
    return railcosim("run", system, "--no-build", "--output", tmp_path / "out", *extra)


# ---- scenarios ---------------------------------------------------------------------------------
def _scenario(tmp_path, text: str) -> Path:
    path = tmp_path / "events.json"
    path.write_text(text)
    return path


@pytest.mark.parametrize("time", ["NaN", "Infinity", "-Infinity"])
def test_scenario_event_time_not_finite(tmp_path, test_fmus, time):
    scenario = _scenario(tmp_path, '{"events": [{"time": %s, "model": "clock", "variable": "u", '
                                   '"action": "set", "value": 1.0}]}' % time)
    code, _, stderr = _run(_pair(tmp_path / "sys", test_fmus), tmp_path, "--scenario", scenario)
    _expect_error(code, stderr, "events.json", "events[0].time", "finite")


@pytest.mark.parametrize("end", ["NaN", "Infinity", "1e300"])
def test_scenario_end_not_finite_or_beyond_the_clock(tmp_path, test_fmus, end):
    scenario = _scenario(tmp_path, '{"events": [], "end": %s}' % end)
    code, _, stderr = _run(_pair(tmp_path / "sys", test_fmus), tmp_path, "--scenario", scenario)
    _expect_error(code, stderr, "events.json", "field end")


def test_scenario_integer_value_beyond_int32(tmp_path, test_fmus):
    scenario = _scenario(tmp_path, json.dumps({"events": [
        {"time": 0.5, "model": "clock", "variable": "steps", "action": "set", "value": 2 ** 40}]}))
    code, _, stderr = _run(_pair(tmp_path / "sys", test_fmus), tmp_path, "--scenario", scenario)
    _expect_error(code, stderr, "events.json", "events[0].value", str(2 ** 40), "Integer range")


def test_scenario_real_value_not_finite(tmp_path, test_fmus):
    scenario = _scenario(tmp_path, '{"events": [{"time": 0.5, "model": "gain", "variable": "u", '
                                   '"action": "bias", "value": NaN}]}')
    code, _, stderr = _run(_pair(tmp_path / "sys", test_fmus), tmp_path, "--scenario", scenario)
    _expect_error(code, stderr, "events.json", "events[0].value", "nan is not a finite number")


def test_scenario_setting_an_input_outside_its_declared_range_stops_the_run_keeping_its_results(
        tmp_path, product_fmus):
    """An event setting ato_only's ATO aspect to 99 (declared 0..4; with cab_signal = off the ATO
    does not read it): the step is refused, the run stops in one line naming the input, and the
    rows up to the event are written."""
    scenario = _scenario(tmp_path, json.dumps({"events": [
        {"time": 2.0, "model": "ato", "variable": "aspect", "action": "set", "value": 99}]}))
    code, _, stderr = _run("ato_only", tmp_path, "--scenario", scenario, "--stop-time", "5")
    _expect_error(code, stderr, "'ato'", "t = 2 s", "input aspect = 99 is above its maximum 4")
    rows = (tmp_path / "out" / "results.csv").read_text().splitlines()
    assert rows[-1].startswith("2.0,") and len(rows) == 1 + 5
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["completed"] is False and summary["sim_time_s"] == 2.0


def test_scenario_nested_too_deeply(tmp_path, test_fmus):
    scenario = _scenario(tmp_path, "[" * 100000 + "]" * 100000)
    code, _, stderr = _run(_pair(tmp_path / "sys", test_fmus), tmp_path, "--scenario", scenario)
    _expect_error(code, stderr, "events.json", "nested too deeply")


def test_validate_checks_the_systems_own_scenario(tmp_path, test_fmus):
    folder = _pair(tmp_path / "sys", test_fmus)
    (folder / "scenario.json").write_text('{"events": [{"time": Infinity, "model": "clock", '
                                          '"variable": "u", "action": "reset"}]}')
    _expect_error(*railcosim("validate", folder)[::2], "scenario.json", "events[0].time")


# ---- SSD annotations and numbers -----------------------------------------------------------------
@pytest.mark.parametrize("command", ["run", "validate"])
@pytest.mark.parametrize("annotation, value", [("StepSize", "fast"), ("StepSizeHint", "NaN"),
                                               ("BaseStep", "half"), ("BaseStep", "-0.5")])
def test_step_annotation_not_a_positive_number(tmp_path, test_fmus, command, annotation, value):
    folder = _pair(tmp_path / "sys", test_fmus)
    if annotation == "StepSizeHint":       # ours absent: the OSP hint is read
        _replace_in_ssd(folder, '<rcs:StepSize value="0.5"/>', "", count=2)
    _replace_in_ssd(folder, f'<{"osp" if annotation == "StepSizeHint" else "rcs"}:{annotation} value="0.5"/>',
                    f'<{"osp" if annotation == "StepSizeHint" else "rcs"}:{annotation} value="{value}"/>')
    args = (command, folder) if command == "validate" else ("run", folder, "--no-build", "--output", tmp_path / "o")
    _expect_error(*railcosim(*args)[::2], "SystemStructure.ssd:", annotation, repr(value))


@pytest.mark.parametrize("value", ["NaN", "INF", "-INF"])
def test_parameter_value_not_finite_in_the_ssd(tmp_path, test_fmus, value):
    folder = _pair(tmp_path / "sys", test_fmus, gain_parameters={"k": 2.0})
    _replace_in_ssd(folder, '<ssv:Real value="2.0"', f'<ssv:Real value="{value}"')
    _expect_error(*railcosim("validate", folder)[::2], "SystemStructure.ssd:", "'k'", "not a finite number")


def test_parameter_value_not_finite_in_an_ssv_parameter_set(tmp_path, test_fmus):
    folder = _pair(tmp_path / "sys", test_fmus)
    (folder / "bad.ssv").write_text(
        '<?xml version="1.0"?>\n<ssv:ParameterSet xmlns:ssv="http://ssp-standard.org/SSP1/'
        'SystemStructureParameterValues" version="1.0" name="bad">\n  <ssv:Parameters>\n'
        '    <ssv:Parameter name="gain.k"><ssv:Real value="INF"/></ssv:Parameter>\n'
        '  </ssv:Parameters>\n</ssv:ParameterSet>\n')
    _expect_error(*_run(folder, tmp_path, "--param-set", "bad")[::2], "bad.ssv:4", "'gain.k'", "not a finite number")


def test_set_not_finite(tmp_path, test_fmus):
    _expect_error(*_run(_pair(tmp_path / "sys", test_fmus), tmp_path, "--set", "gain.k=nan")[::2],
                  "--set gain.k", "not a valid Real")


def test_validate_reports_connection_and_parameter_problems(tmp_path, test_fmus):
    folder = _pair(tmp_path / "sys", test_fmus, [ConnectionSpec("clock.t_end", "gain.nothing")])
    _expect_error(*railcosim("validate", folder)[::2], "SystemStructure.ssd:", "gain.nothing", "does not exist")
    folder = _pair(tmp_path / "sys2", test_fmus, gain_parameters={"nope": 1.0})
    _expect_error(*railcosim("validate", folder)[::2], "SystemStructure.ssd:", "'nope'", "does not exist")


# ---- components and connections ---------------------------------------------------------------
def test_duplicate_component_name(tmp_path, test_fmus):
    folder = _pair(tmp_path / "sys", test_fmus, components=[
        ComponentSpec("gain", str(test_fmus / "TestGain.fmu"), 0.5),
        ComponentSpec("gain", str(test_fmus / "TestCounter.fmu"), 0.5)])
    _expect_error(*railcosim("validate", folder)[::2], "SystemStructure.ssd:", "'gain'", "used twice")


@pytest.mark.parametrize("suppress", [False, True])
def test_two_connections_into_one_input(tmp_path, test_fmus, suppress):
    """Refused the same way with or without suppressUnitConversion (before: accepted, last won)."""
    folder = _pair(tmp_path / "sys", test_fmus, [
        ConnectionSpec("a.y", "gain.u", suppress_unit_conversion=suppress),
        ConnectionSpec("clock.t_end", "gain.u", suppress_unit_conversion=suppress)], components=[
        ComponentSpec("clock", str(test_fmus / "TestCounter.fmu"), 0.5),
        ComponentSpec("a", str(test_fmus / "TestGain.fmu"), 0.5),
        ComponentSpec("gain", str(test_fmus / "TestGain.fmu"), 0.5)])
    if not suppress:        # same units, so that only the second driver is wrong
        _replace_in_ssd(folder, 'startConnector="t_end"', 'startConnector="y"')
        _replace_in_ssd(folder, 'startElement="clock"', 'startElement="gain"')
    for args in (("validate", folder), ("run", folder, "--no-build", "--output", tmp_path / "o")):
        _expect_error(*railcosim(*args)[::2], "SystemStructure.ssd:", "input gain.u already has a connection",
                      "from a.y")


# ---- archives ------------------------------------------------------------------------------------
def test_message_about_a_member_names_the_archive(tmp_path, test_fmus):
    folder = _pair(tmp_path / "sys", test_fmus, [ConnectionSpec("clock.t_end", "gain.nothing")])
    archive = _pack(folder, tmp_path / "pair.ssp")
    _expect_error(*railcosim("validate", archive)[::2], f"{archive}!SystemStructure.ssd:", "gain.nothing")


def test_corrupt_member_bad_crc(tmp_path, test_fmus):
    archive = _pack(_pair(tmp_path / "sys", test_fmus), tmp_path / "pair.ssp", zipfile.ZIP_STORED)
    data = bytearray(archive.read_bytes())
    at = data.index(b"<ssd:Component") + 5                   # inside the stored member's bytes
    data[at:at + 4] = b"XXXX"
    archive.write_bytes(bytes(data))
    _expect_error(*_run(archive, tmp_path)[::2], f"{archive}!SystemStructure.ssd", "corrupt")


def test_corrupt_member_deflated_stream(tmp_path, test_fmus):
    archive = _pack(_pair(tmp_path / "sys", test_fmus), tmp_path / "pair.ssp")
    with zipfile.ZipFile(archive) as packed:
        info = packed.getinfo("SystemStructure.ssd")
    data = bytearray(archive.read_bytes())
    start = info.header_offset + 30 + len(info.filename.encode()) + len(info.extra)
    middle = start + info.compress_size // 2
    for k in range(middle, middle + 16):
        data[k] ^= 0xFF
    archive.write_bytes(bytes(data))
    _expect_error(*_run(archive, tmp_path)[::2], f"{archive}!SystemStructure.ssd", "corrupt")


def test_member_in_a_compression_method_python_cannot_read(tmp_path, test_fmus):
    """A member packed with a method zipfile has no codec for (here 99, AES as WinZip writes it)
    is named with its method, not reported as a corrupt archive."""
    archive = _pack(_pair(tmp_path / "sys", test_fmus), tmp_path / "pair.ssp", zipfile.ZIP_STORED)
    with zipfile.ZipFile(archive) as packed:
        info = packed.getinfo("SystemStructure.ssd")
    data = bytearray(archive.read_bytes())
    data[info.header_offset + 8:info.header_offset + 10] = (99).to_bytes(2, "little")   # local header
    central = data.index(b"PK\x01\x02")                    # the member's central directory entry
    while data[central + 46:central + 46 + len(info.filename)] != info.filename.encode():
        central = data.index(b"PK\x01\x02", central + 4)
    data[central + 10:central + 12] = (99).to_bytes(2, "little")                       # central directory
    archive.write_bytes(bytes(data))
    _expect_error(*_run(archive, tmp_path)[::2], f"{archive}!SystemStructure.ssd", "zip method 99",
                  "repack it with deflate")


def test_truncated_archive(tmp_path, test_fmus):
    archive = _pack(_pair(tmp_path / "sys", test_fmus), tmp_path / "pair.ssp")
    archive.write_bytes(archive.read_bytes()[: archive.stat().st_size // 2])
    _expect_error(*_run(archive, tmp_path)[::2], str(archive), "not a zip archive")


# ---- data files of the product systems ---------------------------------------------------------------
def _line(tmp_path, name="line.json", **change) -> Path:
    line = json.loads((REPO / "fmus" / "data" / "shipped" / "default_line.json").read_text())
    for key, value in change.items():
        line[key] = value
    path = tmp_path / name
    path.write_text(json.dumps(line))
    return path


def test_missing_data_file_inside_an_ssp_names_the_archive(tmp_path, product_fmus):
    from orchestrator.packaging.packing import pack_system

    archive = pack_system(REPO / "ssp" / "ato_only", product_fmus, tmp_path)   # as `railcosim build` packs it
    code, _, stderr = _run(archive, tmp_path, "--set", "train.line_file=missing.json")
    _expect_error(code, stderr, f"{archive}!resources/missing.json: file not found", "train.line_file")


def test_data_file_nested_too_deeply(tmp_path, product_fmus):
    deep = tmp_path / "deep.json"
    deep.write_text("[" * 100000 + "]" * 100000)
    code, _, stderr = _run("ato_only", tmp_path, "--set", f"train.rolling_stock_file={deep}")
    _expect_error(code, stderr, "deep.json", "nested", "train.rolling_stock_file")


SHIPPED = REPO / "fmus" / "data" / "shipped"


def _with_literal(source: Path, path: list, literal: str, target: Path) -> Path:
    """``source`` with the field at ``path`` replaced by a JSON literal as written (``NaN``,
    ``Infinity``, ``1e400``: Python's json reads each as a float that is not finite)."""
    document = json.loads(source.read_text())
    holder = document
    for key in path[:-1]:
        holder = holder[key]
    holder[path[-1]] = "@@LITERAL@@"
    target.write_text(json.dumps(document).replace('"@@LITERAL@@"', literal))
    return target


@pytest.mark.parametrize("system, parameters, source, path, literal, field", [
    # the line file of both the train and the ATO (the error named the bundled timetable: "minimum
    # running time inf s")
    ("ato_only", ("train.line_file", "ato.line_file"), SHIPPED / "default_line.json",
     ["gradients", 1, "permille"], "NaN", "gradients[1].permille: nan"),
    ("ato_only", ("train.line_file", "ato.line_file"), SHIPPED / "default_line.json",
     ["stations", 1, "stop_m"], "1e400", "stations[1].stop_m: inf"),
    # a = NaN was accepted: the train never moved and the run ended "completed"
    ("ato_only", ("train.rolling_stock_file",), SHIPPED / "passenger_chs7.json",
     ["units", 0, "resistance", "a"], "NaN", "units[0].resistance.a: nan"),
    ("ato_only", ("ato.timetable_file",), SHIPPED / "default_timetable.json",
     ["stops", 1, "arrival_s"], "Infinity", "stops[1].arrival_s: inf"),
    ("free_run", ("coder.codes_file",), REPO / "fmus" / "signalling" / "alsn_codes.json",
     ["transmitters", "KPT-5", "codes", "Z", 0], "-Infinity", "transmitters.KPT-5.codes.Z[0]: -inf"),
], ids=["line-nan", "line-1e400", "rolling-stock-nan", "timetable-infinity", "code-table-minus-infinity"])
def test_data_file_number_not_finite(tmp_path, product_fmus, system, parameters, source, path, literal, field):
    """Every data file a component reads refuses a number that is not finite before the run, in
    one line naming the file, the field and the parameter that names the file."""
    bad = _with_literal(source, path, literal, tmp_path / f"bad_{source.name}")
    sets = [arg for name in parameters for arg in ("--set", f"{name}={bad}")]
    code, _, stderr = _run(system, tmp_path, *sets, "--stop-time", "1")
    line = _expect_error(code, stderr, str(bad), f"field {field} is not a finite number", parameters[0])
    assert "default_" not in line.replace(bad.name, "")          # never blames a bundled file
    assert not (tmp_path / "out").exists()


def test_validate_refuses_a_scenario_number_not_finite_at_load(tmp_path, test_fmus):
    """Any number of a scenario, not only the fields checked by meaning: here an Integer event's
    value, typed only against the FMU's variable before."""
    folder = _pair(tmp_path / "sys", test_fmus)
    (folder / "scenario.json").write_text('{"events": [{"time": 0.5, "model": "clock", "variable": "steps", '
                                          '"action": "set", "value": Infinity}]}')
    _expect_error(*railcosim("validate", folder)[::2], "scenario.json", "field events[0].value: inf is not a finite number")


def test_gap_between_block_sections(tmp_path, product_fmus):
    line = json.loads((REPO / "fmus" / "data" / "shipped" / "default_line.json").read_text())
    line["block_sections"][2]["start_m"] += 200.0                # 200 m of track with no circuit
    gapped = tmp_path / "gapped.json"
    gapped.write_text(json.dumps(line))
    code, _, stderr = _run("ato_only", tmp_path, "--set", f"train.line_file={gapped}",
                           "--set", f"ato.line_file={gapped}")
    _expect_error(code, stderr, "gapped.json", "block_sections[2].start_m", "200 m gap")


def test_train_and_ato_on_different_line_files(tmp_path, product_fmus):
    other = REPO / "ssp" / "following" / "resources" / "following_line.json"
    code, _, stderr = _run("ato_only", tmp_path, "--set", f"ato.line_file={other}")
    _expect_error(code, stderr, "ato.line_file", "following_line.json", "train.line_file",
                  "the bundled default", "one line file")


def test_same_line_in_two_files_of_identical_content_is_accepted(tmp_path, product_fmus):
    copy = tmp_path / "copy.json"
    shutil.copy(REPO / "fmus" / "data" / "shipped" / "default_line.json", copy)
    code, _, stderr = _run("ato_only", tmp_path, "--set", f"ato.line_file={copy}", "--stop-time", "1")
    assert code == 0, stderr


def test_report_of_a_run_folder_with_json_nested_too_deeply(tmp_path):
    run = tmp_path / "run"
    run.mkdir()
    (run / "results.csv").write_text("time\n0\n")
    (run / "summary.json").write_text("[" * 100000 + "]" * 100000)
    (run / "metadata.json").write_text("{}")
    _expect_error(*railcosim("report", run)[::2], "summary.json", "nested too deeply")

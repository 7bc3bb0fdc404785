"""Bad input: one clear line on stderr naming what and where, exit code 2, no traceback."""
import json
import zipfile

import pytest

from helpers import ComponentSpec, ConnectionSpec, railcosim, read_csv, write_ssd


def _expect_error(code, stderr, *fragments):
    assert code == 2, stderr
    lines = [l for l in stderr.splitlines() if l.strip()]
    assert len(lines) == 1, stderr
    assert "Traceback" not in stderr
    for fragment in fragments:
        assert fragment in lines[0], lines[0]
    return lines[0]


def _pair(tmp_path, fmus, connections, base_step=None, gain_step=0.5):
    folder = tmp_path / "sys"
    write_ssd(folder, "pair", [
        ComponentSpec("clock", str(fmus / "TestCounter.fmu"), 0.5),
        ComponentSpec("gain", str(fmus / "TestGain.fmu"), gain_step),
    ], connections, stop_time=1.0, base_step_s=base_step)
    return folder


def test_missing_system(tmp_path):
    _expect_error(*railcosim("run", tmp_path / "nope.ssp", "--no-build")[::2], "nope.ssp")


def test_corrupt_fmu_not_a_zip(tmp_path):
    bad = tmp_path / "bad.fmu"
    bad.write_bytes(b"this is not a zip")
    _expect_error(*railcosim("inspect", bad)[::2], "bad.fmu", "not a zip")


def test_fmu_without_model_description(tmp_path):
    bad = tmp_path / "empty.fmu"
    with zipfile.ZipFile(bad, "w") as archive:
        archive.writestr("resources/readme.txt", "nothing")
    _expect_error(*railcosim("validate", bad)[::2], "empty.fmu", "no modelDescription.xml")


def test_ssd_failing_the_schema(tmp_path):
    folder = tmp_path / "sys"
    folder.mkdir()
    (folder / "SystemStructure.ssd").write_text(
        '<?xml version="1.0"?>\n<ssd:SystemStructureDescription '
        'xmlns:ssd="http://ssp-standard.org/SSP1/SystemStructureDescription" version="1.0" name="x">\n'
        '  <ssd:Bogus/>\n</ssd:SystemStructureDescription>\n')
    _expect_error(*railcosim("run", folder, "--no-build")[::2], "SystemStructure.ssd:", "schema")


def test_connection_to_missing_connector(tmp_path, test_fmus):
    folder = _pair(tmp_path, test_fmus, [ConnectionSpec("clock.t_end", "gain.nothing")])
    _expect_error(*railcosim("run", folder, "--no-build")[::2], "SystemStructure.ssd:", "gain.nothing",
                  "does not exist")


def test_causality_mismatch(tmp_path, test_fmus):
    folder = _pair(tmp_path, test_fmus, [ConnectionSpec("gain.u", "clock.u")])
    _expect_error(*railcosim("run", folder, "--no-build")[::2], "gain.u", "not an output")


def test_type_mismatch(tmp_path, test_fmus):
    folder = _pair(tmp_path, test_fmus, [ConnectionSpec("clock.steps", "gain.u")])
    _expect_error(*railcosim("run", folder, "--no-build")[::2], "type mismatch", "Integer", "Real")


def test_step_not_multiple_of_base_step(tmp_path, test_fmus):
    folder = _pair(tmp_path, test_fmus, [], base_step=0.2, gain_step=0.5)
    _expect_error(*railcosim("run", folder, "--no-build")[::2], "not a multiple of the base step")


def test_unknown_set_variable(tmp_path, test_fmus):
    folder = _pair(tmp_path, test_fmus, [])
    _expect_error(*railcosim("run", folder, "--no-build", "--set", "gain.nope=1")[::2],
                  "--set gain.nope", "no such variable")


def test_bad_command_line_argument(tmp_path):
    _expect_error(*railcosim("run", "--algorithm", "newton")[::2], "invalid choice")


@pytest.mark.parametrize("window", ["nan:5", "0:inf", "-inf:1", "0:1e300", "0:2e6"])
def test_capture_window_not_finite_or_beyond_the_clock(tmp_path, test_fmus, window):
    """float() takes nan and inf: the window is refused naming the option (a ValueError and an
    OverflowError traceback came out of the recorder); so is one beyond a run's longest time,
    10⁶ s (orchestrator/graph.py MAX_TIME_S, the bound of --stop-time too)."""
    folder = _pair(tmp_path, test_fmus, [])
    _expect_error(*railcosim("run", folder, "--no-build", "--output", tmp_path / "out",
                             "--capture", f"clock.y@{window}")[::2],
                  f"--capture clock.y@{window}", "finite numbers of seconds")
    assert not (tmp_path / "out").exists()


def test_zip_slip_archive(tmp_path):
    evil = tmp_path / "evil.ssp"
    with zipfile.ZipFile(evil, "w") as archive:
        archive.writestr("SystemStructure.ssd", "<x/>")
        archive.writestr("../../escaped.txt", "gotcha")
    _expect_error(*railcosim("run", evil, "--no-build")[::2], "zip-slip", "../../escaped.txt")
    assert not (tmp_path.parent / "escaped.txt").exists()


def test_step_failure_mid_run_keeps_results(tmp_path, test_fmus):
    folder = tmp_path / "sys"
    write_ssd(folder, "failing", [
        ComponentSpec("clock", str(test_fmus / "TestCounter.fmu"), 0.1, {"fail_at": 1.0}),
    ], [], stop_time=5.0)
    out = tmp_path / "out"
    code, _, stderr = railcosim("run", folder, "--no-build", "--output", out)
    _expect_error(code, stderr, "'clock'", "t = 1 s")
    header, data = read_csv(out / "results.csv")
    assert data[-1, 0] == pytest.approx(1.0)  # every row up to the failure is there
    assert data[-1, header.index("clock.steps")] == 10
    summary = json.loads((out / "summary.json").read_text())
    assert summary["completed"] is False and "clock" in summary["error"]
    assert summary["sim_time_s"] == pytest.approx(1.0)


def test_parameter_outside_its_declared_range_names_the_port(tmp_path, product_fmus):
    """Through FMI: the facade's range check refuses it at exitInitializationMode, in the port's name."""
    code, _, stderr = railcosim("run", "ato_only", "--no-build", "--output", tmp_path / "out",
                                "--set", "train.mass_scale=0.05")
    _expect_error(code, stderr, "train", "mass_scale = 0.05 is below its minimum 0.1")


@pytest.mark.parametrize("system, setting", [("ato_only", "ato.aspect=99"), ("ato_only", "ato.v_target=-3")])
def test_an_input_outside_its_declared_range_names_the_port(tmp_path, product_fmus, system, setting):
    """ato_only's ATO runs with cab_signal = off and does not read its aspect or the digital
    speeds: a --set outside their declared range is refused like any input's (it was applied
    silently), before the first step."""
    name, value = setting.split("=")
    code, _, stderr = railcosim("run", system, "--no-build", "--output", tmp_path / "out", "--set", setting)
    words = "above its maximum 4" if value == "99" else "below its minimum 0"
    _expect_error(code, stderr, "ato", f"input {name.split('.')[1]} = {value} is {words}")


# ---- every numeric option of every command (orchestrator/cli.py, _Number) ---------------------------
def _numeric_options():
    """(command words, option, its _Number action) for every numeric option the parser has."""
    import argparse

    from orchestrator.cli import _Number, make_parser

    found = []

    def walk(parser, words):
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction):
                for name, sub in action.choices.items():
                    walk(sub, words + (name,))
            elif isinstance(action, _Number):
                found.append((words, action.option_strings[0], action))
            else:       # a number read any other way would miss the shared checks
                assert action.type not in (int, float), (words, action.option_strings)

    walk(make_parser(), ())
    return found


NUMERIC_OPTIONS = _numeric_options()
NOT_A_NUMBER = {float: ["nan", "inf", "-inf", "1e400", "-1e400", "NaN", "Infinity", "x"],
                int: ["nan", "inf", "1.5", "1e3", "9" * 5000, "x"]}


def _main_error(capsys, monkeypatch, tmp_path, *argv):
    """The CLI's main in this process (as `railcosim ARGV`): its exit code and its one stderr line."""
    from orchestrator.cli import main

    monkeypatch.chdir(tmp_path)           # nothing a command might write lands in the checkout
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    line = _expect_error(code, err)
    assert list(tmp_path.iterdir()) == []     # refused before the command did anything
    return line


def test_every_command_has_its_numeric_options_checked():
    commands = {words[0] for words, _, _ in NUMERIC_OPTIONS}
    assert commands >= {"build", "run", "validate", "report", "study", "netlist", "crosscheck", "dcp-slave", "new"}


@pytest.mark.parametrize("words, option, action", NUMERIC_OPTIONS,
                         ids=[f"{' '.join(w)} {o}" for w, o, _ in NUMERIC_OPTIONS])
def test_a_numeric_option_that_is_not_a_finite_number_is_one_line(capsys, monkeypatch, tmp_path, words, option,
                                                                   action):
    """nan, ±inf, a literal beyond the double range (float() reads 1e400 as inf), text, and for
    an integer option a fraction or 5000 digits (int() refuses more than 4300): one line naming
    the command, the option and the value, exit 2, before the command starts."""
    for value in NOT_A_NUMBER[action.kind]:
        line = _main_error(capsys, monkeypatch, tmp_path, *words, f"{option}={value}")
        shown = value if len(value) <= 40 else value[:20]
        assert f"{' '.join(words)}: {option} {shown}" in line
        assert ("not an integer" if action.kind is int else ("not a finite number" if value != "x" else
                                                              "not a number")) in line
    # a negative value as its own argument is the option's value, not an unknown option
    line = _main_error(capsys, monkeypatch, tmp_path, *words, option, "-inf")
    assert f"{option} -inf: not" in line


@pytest.mark.parametrize("words, option, action", [o for o in NUMERIC_OPTIONS if
                                                   {o[2].minimum, o[2].maximum, o[2].above} != {None}],
                         ids=[f"{' '.join(w)} {o}" for w, o, a in NUMERIC_OPTIONS if
                              {a.minimum, a.maximum, a.above} != {None}])
def test_a_numeric_option_outside_its_range_is_one_line(capsys, monkeypatch, tmp_path, words, option, action):
    step = 1 if action.kind is int else 0.5
    outside = ([action.minimum - step] if action.minimum is not None else []) + \
        ([action.maximum + step] if action.maximum is not None else []) + \
        ([action.above] if action.above is not None else [])
    for value in outside:
        text = str(action.kind(value))
        line = _main_error(capsys, monkeypatch, tmp_path, *words, f"{option}={text}")
        assert f"{option} {text}: must be" in line

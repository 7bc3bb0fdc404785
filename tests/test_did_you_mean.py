"""A mistyped name is one line naming what is wrong and the closest name there is (difflib),
exit 2: a system, a variable of --set, --record, --capture, a role, a study; a name close to
none is said with the names there are."""
import pytest

from helpers import railcosim
from orchestrator.errors import did_you_mean


def _one_line(argv, tmp_path):
    code, stdout, stderr = railcosim(*argv, cwd=tmp_path)
    lines = stderr.strip().splitlines()
    assert code == 2 and stdout == "" and len(lines) == 1 and "Traceback" not in stderr, stderr
    return lines[0]


@pytest.mark.parametrize("argv, line", [
    (["run", "free_rn"], "system 'free_rn': no such folder or .ssp file, and not a shipped system; "
                         "did you mean free_run?"),
    (["run", "TVM430"], "not a shipped system; did you mean tvm430?"),
    (["run", "free_run", "--set", "rx.filter_ordr=3"],
     "--set rx.filter_ordr: no such variable (component 'rx' exists); did you mean rx.filter_order?"),
    (["run", "free_run", "--set", "trian.v0=3"],
     "--set trian.v0: no such variable (component 'trian' does not exist); did you mean train.v0?"),
    (["run", "free_run", "--set", "train.vv=3"], "did you mean train.v0?"),            # a parameter, not the output v
    (["run", "free_run", "--record", "train.vv"], "--record train.vv: no such variable; did you mean train.v?"),
    (["validate", "free_run", "--record", "ato.atp_aspekt"], "did you mean ato.atp_aspect?"),
    (["run", "free_run", "--capture", "rail.e_col@1:2"], "--capture rail.e_col: no such frame output; "
                                                         "did you mean rail.e_coil?"),
    (["run", "free_run", "--capture", "rial.e_coil@1:2"], "--capture rial.e_coil@1:2: no component 'rial'; "
                                                          "did you mean rail?"),
    (["study", "ato_robustnes", "--no-build"], "study 'ato_robustnes': no such file, and not a shipped study; "
                                               "did you mean ato_robustness?"),
    (["conform", "X.fmu", "--role", "tracton"], "--role 'tracton': not a role; did you mean traction? (roles: "),
    (["contract", "check", "X.fmu", "--manifest", "rail_lin"], "--manifest rail_lin: neither a manifest file nor "
                                                               "a role; did you mean rail_line? (roles: "),
])
def test_a_mistyped_name_is_one_line_with_the_closest(argv, line, tmp_path, product_fmus):
    if argv[0] == "run":
        argv = [*argv, "--no-build", "--output", str(tmp_path / "out")]
    shown = _one_line(argv, tmp_path)
    assert shown.startswith("railcosim: error: ") and line in shown, shown
    assert not (tmp_path / "out").exists()            # refused before the run claimed its folder


def test_a_name_close_to_none_lists_the_names_there_are(tmp_path):
    shown = _one_line(["run", "nothing_like_any", "--no-build"], tmp_path)
    assert "did you mean" not in shown and "(shipped: als_en, " in shown and "free_run" in shown


def test_the_closest_ignores_case_and_gives_the_names_spelling():
    assert did_you_mean("Free_Rn", ["free_run", "following"]) == "; did you mean free_run?"
    assert did_you_mean("zzz", ["free_run"]) == ""

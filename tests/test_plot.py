"""``railcosim plot RUN VAR …``: a run's recorded variables against time, with the units of
columns.json in the axis labels and an enumeration's labels on its ticks; a mistyped variable is
one line with the closest column."""
import shutil

import pytest

from helpers import REPO
from orchestrator.cli import main
from orchestrator.run import RunOptions, run_system
from orchestrator.verdicts.labels import railway_labels


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory, product_fmus):
    out = tmp_path_factory.mktemp("plot") / "free_run"
    run_system(REPO / "ssp" / "free_run", RunOptions(stop_time=20.0, output_dir=out, fmu_dirs=[product_fmus],
                                                     in_process=True, labels=railway_labels))
    return out


def _plot(capsys, *argv):
    code = main(["plot", *map(str, argv)])
    out, err = capsys.readouterr()
    return code, out, err


def test_plot_writes_a_png_beside_the_results_by_default(capsys, run_dir):
    code, out, err = _plot(capsys, run_dir, "train.v", "rx.aspect", "rail.occupied[3]")
    expected = run_dir / "plot_train.v+rx.aspect+rail.occupied_3.png"
    assert code == 0 and err == "" and out == f"wrote {expected}\n"
    assert expected.read_bytes().startswith(b"\x89PNG\r\n\x1a\n")


def test_the_axes_say_the_units_and_the_enumeration_labels(capsys, run_dir, tmp_path):
    svg = tmp_path / "chain.svg"
    code, out, err = _plot(capsys, run_dir, "train.v", "rx.aspect", "ato.mode", "rx.code_valid", "-o", svg,
                           "--from", "1", "--to", "15")
    assert code == 0, err
    text = svg.read_text(encoding="utf-8")
    for shown in ("train.v [m/s]", "time [s]", "speed, never negative",       # unit and description
                  "white", "red-yellow", "green",                               # rx.aspect's ticks
                  "standstill", "ATP emergency", "false", "true"):             # ato.mode, a Boolean
        assert shown in text, shown
    assert "rx.aspect [" not in text                                           # an enumeration has no unit


def test_a_run_without_columns_json_still_plots_without_units(capsys, run_dir, tmp_path):
    older = tmp_path / "older"
    shutil.copytree(run_dir, older)
    (older / "columns.json").unlink()
    code, _, err = _plot(capsys, older, "train.v", "-o", older / "v.svg")
    assert code == 0, err
    text = (older / "v.svg").read_text()
    assert "train.v" in text and "[m/s]" not in text


@pytest.mark.parametrize("argv, says", [
    (["train.vv"], "plot: train.vv: no such column in {run}/results.csv; did you mean train.v?"),
    (["rx.aspekt"], "did you mean rx.aspect?"),
    (["nothing_like_it"], "plot: nothing_like_it: no such column in {run}/results.csv"),
    (["train.v", "--from", "10", "--to", "5"], "plot: --to 5 must be after --from 10"),
    (["train.v", "--from", "500"], "plot: --from/--to: no row of {run}/results.csv in that time (the run's: 0 … 20 s)"),
    (["train.v", "-o", "v.pdf"], "plot: -o v.pdf: give a .png or .svg file"),
])
def test_bad_plot_requests_are_one_line(capsys, run_dir, argv, says):
    code, out, err = _plot(capsys, run_dir, *argv)
    lines = err.strip().splitlines()
    assert code == 2 and out == "" and len(lines) == 1, err
    assert lines[0].startswith("railcosim: error: ") and says.format(run=run_dir) in lines[0], lines[0]
    assert "did you mean" not in lines[0] or "?" == lines[0][-1]


def test_a_folder_that_is_no_run_is_one_line(capsys, tmp_path):
    code, _, err = _plot(capsys, tmp_path, "train.v")
    assert code == 2 and err.strip() == f"railcosim: error: plot: {tmp_path}: no results.csv (not a railcosim run folder)"


def test_a_later_run_into_the_folder_removes_the_earlier_runs_plots(capsys, product_fmus, tmp_path):
    out = tmp_path / "run"
    options = RunOptions(stop_time=1.0, output_dir=out, fmu_dirs=[product_fmus], in_process=True)
    run_system(REPO / "ssp" / "ato_only", options)
    assert _plot(capsys, out, "train.v")[0] == 0 and _plot(capsys, out, "train.x", "-o", out / "plot_x.svg")[0] == 0
    (out / "mine.png").write_bytes(b"the user's own")
    run_system(REPO / "ssp" / "ato_only", options)
    assert sorted(p.name for p in out.glob("*.png")) + sorted(p.name for p in out.glob("*.svg")) == ["mine.png"]

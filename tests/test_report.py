"""railcosim report: pictures, the verdict table and report.html of a finished run; bad run
folders give one line."""
import json
import shutil
import subprocess
from html.parser import HTMLParser

import numpy as np
import pytest

from helpers import railcosim


def test_report_of_a_run_with_a_coil_capture(tmp_path, product_fmus):
    run = tmp_path / "run"
    code, _, stderr = railcosim("run", "free_run", "--output", run, "--no-build", "--in-process", "--stop-time", "70",
                                "--capture", "rail.e_coil[1]@62:66")
    assert code == 0, stderr
    code, stdout, stderr = railcosim("report", run, "--output", tmp_path / "pictures", "--at", "64")
    assert code == 0, stderr
    for name in ("speed_distance.png", "time_distance.png", "energy.png", "coil_emf.png"):
        assert (tmp_path / "pictures" / name).stat().st_size > 10_000, name
    assert "receiver rx (ALSN, train train)" in stdout and "wrong-side failures 0" in stdout
    assert "SPAD 0" in stdout
    _check_html(tmp_path / "pictures", json.loads((run / "summary.json").read_text()))
    # the interactive page draws the capture too, and then gives no line telling how to make one
    page = (tmp_path / "pictures" / "report.html").read_text(encoding="utf-8")
    assert "captured coil EMF (rail.e_coil[1])" in page and "No coil EMF was captured" not in page


class _Page(HTMLParser):
    def __init__(self):
        super().__init__()
        self.images, self.rows, self.table = [], {}, None

    def handle_starttag(self, tag, attrs):
        attrs = dict(attrs)
        if tag == "img":
            self.images.append(attrs["src"])
        elif tag == "table":
            self.table = attrs.get("id")
        elif tag == "tr" and "verdict" in (attrs.get("class") or "").split():
            self.rows[self.table] = self.rows.get(self.table, 0) + 1


def _check_html(folder, summary):
    """report.html names every picture written, each decodes, and the tables have one row per
    verdict item: each timetabled stop, each train's supervision, each receiver, the safety line."""
    import matplotlib.image

    page = _Page()
    page.feed((folder / "report.html").read_text(encoding="utf-8"))
    assert sorted(page.images) == sorted(p.name for p in folder.glob("*.png"))
    for name in page.images:
        assert matplotlib.image.imread(folder / name).shape[0] > 200, name
    trains = summary["trains"]
    assert page.rows.get("stops", 0) == sum(len(t.get("stops", [])) for t in trains)
    assert page.rows["judgements"] == (sum("atp_interventions" in t for t in trains)
                                       + sum(t.get("min_headway_m") is not None for t in trains)
                                       + len(summary.get("receivers", [])) + bool(summary.get("receivers")))
    browser = shutil.which("chromium") or shutil.which("chromium-browser")
    if browser:                       # where a browser is installed: it renders the page
        shot = folder / "screenshot.png"
        subprocess.run([browser, "--headless", "--no-sandbox", "--disable-gpu", f"--screenshot={shot}",
                        "--window-size=1280,2400", (folder / "report.html").as_uri()],
                       capture_output=True, timeout=120)
        image = matplotlib.image.imread(shot)
        assert image.shape[:2] == (2400, 1280) and np.ptp(image[..., :3]) > 0.5   # not a blank page


def test_report_html_lists_every_stop_missed_ones_included(tmp_path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from orchestrator.reports.report import write_html

    fig, ax = plt.subplots()
    ax.plot([0, 1], [1, 0])
    fig.savefig(tmp_path / "energy.png")
    plt.close(fig)
    stop = {"station": "B", "scheduled_arrival_s": 515.0, "arrival_s": 516.5, "arrival_deviation_s": 1.5,
            "stop_error_m": -0.2}
    summary = {"system": "s<1>", "sim_time_s": 900.0, "realtime_factor": 5.0, "completed": True, "trains": [
        {"name": "leader", "stops": [stop], "atp_interventions": 0, "emergency_brakings": 0,
         "signals_passed_at_danger": 0},
        {"name": "follower", "stops": [stop, {"station": "C", "scheduled_arrival_s": 1015.0, "reached": False}],
         "atp_interventions": 1, "emergency_brakings": 0, "signals_passed_at_danger": 0, "min_headway_m": 812.0}],
        "receivers": [{"receiver": "rx", "system": "ALSN", "train": "leader", "wrong_side_failures": 0}]}
    write_html(tmp_path / "report.html", summary, [tmp_path / "energy.png"])
    _check_html(tmp_path, summary)
    text = (tmp_path / "report.html").read_text()
    assert "<h1>s&lt;1&gt;</h1>" in text and text.count("not reached") == 1 and "+1.5" in text


def test_static_speed_profile_follows_the_line_file_with_tail_hold_and_braking_curves():
    from fmus.data.loader import DEFAULT_LINE, DEFAULT_ROLLING_STOCK, load_line, load_rolling_stock
    from orchestrator.reports.report import static_speed_profile

    line, stock = load_line(DEFAULT_LINE), load_rolling_stock(DEFAULT_ROLLING_STOCK)
    x = np.arange(0.0, line.length_m + 1.0, 1.0)
    static, curves, decel = static_speed_profile(line, {"atp_decel": 0.5}, x)
    assert decel == 0.5
    kmh = static * 3.6
    # 80 km/h to 1200 m, 140 once the tail has cleared it, 120 from 2900 m at the head
    assert kmh[1199] == pytest.approx(80) and kmh[int(1200 + stock.length_m) - 1] == pytest.approx(80)
    assert kmh[int(1200 + stock.length_m) + 1] == pytest.approx(140) and kmh[2900] == pytest.approx(120)
    # a braking curve at 0.5 m/s² down to each lower limit, never above the static profile
    d = 2900.0 - x[2700]
    assert curves[2700] == pytest.approx(np.sqrt((120 / 3.6) ** 2 + 2 * 0.5 * d))
    assert np.all(curves <= static) and np.all(np.diff(curves[2000:2900]) <= 1e-12)


def test_capturing_a_port_that_is_not_a_frame_is_one_clear_line(tmp_path, product_fmus):
    code, _, stderr = railcosim("run", "free_run", "--output", tmp_path / "run", "--no-build", "--in-process",
                                "--stop-time", "1", "--capture", "rx.level@0:1")
    assert code == 2 and "--capture rx.level: no such frame output" in stderr and "Traceback" not in stderr


def test_report_names_a_folder_that_is_not_a_run(tmp_path):
    code, _, stderr = railcosim("report", tmp_path / "nothing")
    assert code == 2 and "no such run folder" in stderr and "Traceback" not in stderr
    (tmp_path / "empty").mkdir()
    code, _, stderr = railcosim("report", tmp_path / "empty")
    assert code == 2 and "no results.csv" in stderr


@pytest.mark.parametrize("name, text, message", [
    ("results.csv", "time,train.x\n0,100\n0.1,abc\n", "results.csv:3: column train.x: 'abc' is not a number"),
    ("results.csv", "time,train.x\n0,100\n0.1,101,7\n", "results.csv:3: 3 values in a row of 2 columns"),
    ("results.csv", "train.x,time\n0,1\n", "results.csv: its first column is not time"),
    ("results.csv", "time,a\n0," + "9" * 200_000 + "\n", "results.csv: not a CSV file a railcosim run wrote"),
    ("capture_rail.e_coil_1.csv", "time,rail.e_coil[1]\n", "no rows"),
    ("capture_rail.e_coil_1.csv", "time,rail.e_coil[1]\n0.0,x\n", "column rail.e_coil[1]: 'x' is not a number"),
], ids=["text", "torn row", "no time column", "beyond the field limit", "capture without rows", "capture text"])
def test_report_of_a_results_file_no_run_wrote_is_one_line(tmp_path, name, text, message):
    """Text where a number belongs (a ValueError traceback), a torn row, a line beyond the csv
    module's field limit, a capture without rows: one line naming the file and line, exit 2."""
    run = tmp_path / "run"
    run.mkdir()
    (run / "results.csv").write_text("time,x\n0,1\n")
    (run / "summary.json").write_text(json.dumps({"system": "s", "trains": []}))
    (run / "metadata.json").write_text(json.dumps({"components": {}}))
    (run / name).write_text(text)
    code, _, stderr = railcosim("report", run)
    assert code == 2 and stderr.count("\n") == 1 and message in stderr and "Traceback" not in stderr, stderr

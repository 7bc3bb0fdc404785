"""railcosim report: pictures and the verdict table of a finished run; bad run folders give one line."""
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

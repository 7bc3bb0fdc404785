"""The command line as a user meets it: validate finds what run would refuse, --set on a
connected input, stop times between base steps (or closer to the start than 1 ns), report --at
without a capture, the bare command, build repacking only what changed, and capture files (exact
times, whole 2-D ports)."""
import csv
import shutil
import zipfile

from helpers import ComponentSpec, ConnectionSpec, REPO, railcosim, write_ssd


def _errors(stderr):
    return [line for line in stderr.splitlines() if line.startswith("railcosim: error:")]


def _broken_free_run(tmp_path):
    """free_run with a bad parameter value in its SSD and a malformed scenario.json."""
    folder = tmp_path / "broken"
    shutil.copytree(REPO / "ssp" / "free_run", folder)
    ssd = folder / "SystemStructure.ssd"
    text = ssd.read_text()
    assert text.count('<ssv:String value="ALSN"/>') == 1
    ssd.write_text(text.replace('<ssv:String value="ALSN"/>', '<ssv:String value="bogus"/>'))
    (folder / "scenario.json").write_text('{"events": [')
    return folder


def test_validate_reports_every_problem_run_would_meet(tmp_path, product_fmus):
    folder = _broken_free_run(tmp_path)
    code, stdout, stderr = railcosim("validate", folder, "--set", "rx.system=bogus")
    errors = _errors(stderr)
    assert code == 2 and "valid" not in stdout and "Traceback" not in stderr
    assert len(errors) == 3, stderr
    assert any("scenario.json: not valid JSON" in e for e in errors)
    assert any(e.startswith("railcosim: error: ato:") and "cab_signal: 'bogus'" in e for e in errors)
    assert any(e.startswith("railcosim: error: rx:") and "system: 'bogus'" in e for e in errors)
    # run refuses the same system (its first problem), and validate passes the shipped one
    code, _, stderr = railcosim("run", folder, "--no-build", "--in-process", "--output", tmp_path / "out")
    assert code == 2 and "scenario.json: not valid JSON" in stderr
    code, _, stderr = railcosim("run", folder, "--no-build", "--in-process", "--no-scenario",
                                "--output", tmp_path / "out")
    assert code == 2 and "cab_signal: 'bogus'" in stderr
    code, stdout, stderr = railcosim("validate", "free_run")
    assert code == 0 and stdout.strip() == "free_run: valid", stderr


def test_a_stop_time_less_than_a_nanosecond_after_the_start_runs_one_base_step_and_says_so(tmp_path, product_fmus):
    """1e-12 s is after the start but rounds to it on the master's nanosecond clock: the run
    takes one base step, as any stop time between base steps does, with the same warning (it
    simulated 0 s and said nothing)."""
    run = tmp_path / "run"
    code, _, stderr = railcosim("run", "ato_only", "--no-build", "--stop-time", "1e-12", "--output", run)
    assert code == 0, stderr
    assert stderr.strip() == ("railcosim: warning: stop time 1e-12 s is not a whole number of base steps "
                              "(0.5 s) after the start; the run ends at 0.5 s")
    assert '"sim_time_s": 0.5' in (run / "summary.json").read_text()


def test_set_on_an_input_fed_by_a_connection_is_refused(tmp_path, product_fmus):
    for command in (("run", "free_run", "--no-build", "--in-process", "--stop-time", "1",
                     "--output", tmp_path / "out"), ("validate", "free_run")):
        code, _, stderr = railcosim(*command, "--set", "train.command=0.5")
        assert code == 2 and len(stderr.strip().splitlines()) == 1, stderr
        assert "--set train.command: this input is fed by the connection from ato.command" in stderr
    assert not (tmp_path / "out" / "results.csv").exists()


def test_stop_time_between_base_steps_and_report_at_without_capture_are_said(tmp_path, product_fmus):
    run = tmp_path / "run"
    code, _, stderr = railcosim("run", "free_run", "--no-build", "--in-process", "--stop-time", "0.003",
                                "--output", run)
    assert code == 0, stderr
    assert ("railcosim: warning: stop time 0.003 s is not a whole number of base steps (0.01 s) after the "
            "start; the run ends at 0.01 s") in stderr
    assert '"sim_time_s": 0.01' in (run / "summary.json").read_text()
    code, _, stderr = railcosim("report", run, "--at", "500", "--output", tmp_path / "pictures")
    assert code == 0, stderr
    assert "railcosim: warning: --at 500:" in stderr and "no coil-EMF capture" in stderr
    assert not (tmp_path / "pictures" / "coil_emf.png").exists()
    code, _, stderr = railcosim("run", "free_run", "--no-build", "--in-process", "--stop-time", "0.02",
                                "--output", run)
    assert code == 0 and "warning" not in stderr, stderr


def test_the_bare_command_says_what_to_do_once():
    code, stdout, stderr = railcosim()
    assert code == 2 and stdout == ""
    assert stderr.count("railcosim") == 2 and stderr.startswith("railcosim: error: no command given")
    assert "validate" in stderr and len(stderr.splitlines()) == 1
    code, _, stderr = railcosim("run", "free_run", "--stop-time", "x")
    assert stderr.startswith("railcosim: error: run: --stop-time x: ") and stderr.count("railcosim") == 1


def test_packing_again_without_changes_leaves_the_archive_alone(tmp_path, test_fmus):
    from orchestrator.packaging.packing import pack_system, pack_systems

    folder = tmp_path / "systems" / "pair"
    write_ssd(folder, "pair", [ComponentSpec("a", str(test_fmus / "TestCounter.fmu"), 0.1),
                               ComponentSpec("b", str(test_fmus / "TestCounter.fmu"), 0.1)],
              [ConnectionSpec("a.t_end", "b.u")], stop_time=1.0)
    dest = tmp_path / "packed"
    target = pack_system(folder, test_fmus, dest)
    before = (target.stat().st_mtime_ns, target.read_bytes())
    repacked = []
    assert pack_systems(tmp_path / "systems", test_fmus, dest, repacked=repacked) == [target]
    assert repacked == [] and (target.stat().st_mtime_ns, target.read_bytes()) == before
    (folder / "resources").mkdir()
    (folder / "resources" / "note.csv").write_text("a,b\n")      # an input changed: packed again
    pack_systems(tmp_path / "systems", test_fmus, dest, repacked=repacked)
    assert repacked == [target]
    with zipfile.ZipFile(target) as archive:
        assert "resources/note.csv" in archive.namelist()


def test_build_twice_repacks_nothing_the_second_time(product_fmus):
    code, stdout, stderr = railcosim("build")
    assert code == 0, stderr
    archives = sorted((REPO / "build").glob("*.ssp"))
    assert len(archives) >= 10
    stamps = {p: (p.stat().st_mtime_ns, p.stat().st_size) for p in archives}
    code, stdout, stderr = railcosim("build")
    assert code == 0, stderr
    assert "packed" not in stdout and stdout.count("up to date") >= len(archives) + 5
    assert {p: (p.stat().st_mtime_ns, p.stat().st_size) for p in archives} == stamps


def _rows(path):
    with open(path, newline="") as handle:
        return list(csv.reader(handle))


def test_captures_write_exact_sample_times_and_take_a_whole_2d_port(tmp_path, product_fmus):
    run = tmp_path / "run"
    code, _, stderr = railcosim("run", "free_run", "--no-build", "--in-process", "--stop-time", "0.6",
                                "--output", run, "--capture", "rail.e_coil@0.5:0.6",
                                "--capture", "rail.e_coil[1]@0.5:0.6")
    assert code == 0, stderr
    whole, row = _rows(run / "capture_rail_e_coil.csv"), _rows(run / "capture_rail_e_coil_1.csv")
    assert whole[0] == ["time", "rail.e_coil[1]", "rail.e_coil[2]"] and row[0] == ["time", "rail.e_coil[1]"]
    assert len(whole) == len(row) == 1 + 400                  # 0.1 s at 4 kHz
    # sample k of the window is at 0.5 + k/4000 s, written as that decimal (0.50025, not 0.50024999999999997)
    expected = [f"{(500_000_000 + k * 250_000) / 1e9:.9f}".rstrip("0").rstrip(".") for k in range(400)]
    assert [r[0] for r in whole[1:]] == [r[0] for r in row[1:]] == expected
    assert expected[1] == "0.50025"
    assert [r[1] for r in whole[1:]] == [r[1] for r in row[1:]]
    assert any(float(r[1]) != 0.0 for r in row[1:])


def test_sample_times_are_decimals_of_the_integer_clock():
    from orchestrator.observers import sample_times

    assert sample_times(100_000_000_000, 10_000_000, 40)[:3] == ["100", "100.00025", "100.0005"]
    assert sample_times(-500_000_000, 10_000_000, 40)[:2] == ["-0.5", "-0.49975"]
    # a sample instant between two nanoseconds: the shortest decimal of the nearest float
    assert sample_times(0, 10_000_000, 3) == ["0.0", repr(0.01 / 3), repr(0.02 / 3)]

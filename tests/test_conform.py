"""`railcosim conform --role ROLE TARGET`: our five FMUs pass their role's vectors; broken
variants (a receiver whose display latches, a coder without its 2-out-of-2) fail with the
catching vectors named; bad input is one line, exit 2; the shipped vectors are what the
generator writes."""
import json
import shutil

import numpy as np
import pytest

from helpers import railcosim
from conftest import FIXTURE_PACKAGE, REPO

PRODUCT = {"loco_receiver": "LocoReceiver", "wayside_coder": "WaysideCoder", "rail_line": "RailLine",
           "traction": "Traction", "ato_controller": "AtoController"}
DATA = REPO / "orchestrator" / "conformance" / "data"


@pytest.fixture(scope="module")
def broken_fmus(tmp_path_factory):
    from orchestrator.packaging.builder import UnitSpec, build_unit

    dest = REPO / "build" / "test_fmus" / "broken"
    return {identifier: build_unit(UnitSpec(identifier.lower(), "rcs_testfmus.broken", identifier), dest,
                                   extra_packages=[FIXTURE_PACKAGE]).path
            for identifier in ("StuckReceiver", "UncheckedTvmReceiver", "NoFailoverCoder", "BlindAto")}


@pytest.mark.parametrize("role", sorted(PRODUCT))
def test_our_fmu_passes_its_role(product_fmus, role):
    code, out, err = railcosim("conform", "--role", role, product_fmus / f"{PRODUCT[role]}.fmu")
    assert code == 0, out + err
    vectors = len(json.loads((DATA / f"{role}.json").read_text())["vectors"])
    assert out.strip().splitlines()[-1].endswith(f"all {vectors} vectors pass")
    assert "FAIL" not in out


def test_json_report_lists_every_check_with_the_measured_figure(product_fmus):
    code, out, _ = railcosim("conform", "--role", "traction", product_fmus / "Traction.fmu", "--format", "json")
    report = json.loads(out)
    assert code == 0 and report["passed"] and report["failed_vectors"] == []
    braking = [c for c in report["checks"] if c["vector"] == "emergency_brake_100kmh"]
    assert {c["check"] for c in braking} >= {"stopping point (reference train model)", "speed never negative"}
    assert all(c["measured"] is not None and c["bound"] for c in braking)


def test_a_receiver_that_shows_the_last_code_forever_fails(broken_fmus):
    code, out, _ = railcosim("conform", "--role", "loco_receiver", broken_fmus["StuckReceiver"], "--format", "json")
    report = json.loads(out)
    assert code == 1 and not report["passed"]
    failed = set(report["failed_vectors"])
    # every loss of code and every restrictive change catches it; acquisition alone does not
    assert {"acquire_loss_Z_KPT-5_phase0.0", "acquire_loss_KZh_KPT-7_phase0.0", "restrictive_Z_to_KZh_KPT-5",
            "fire_dqpsk_clear_to_block1", "als_en_clear_to_block1", "tvm430_300_then_230_then_loss",
            "tvm300_300_then_160_then_loss", "tvm300_bare_carrier", "tvm300_unused_sub_frequency"} <= failed
    assert "acquire_Z_KPT-5_phase0.5" not in failed
    loss = [c for c in report["checks"] if c["vector"] == "acquire_loss_Z_KPT-5_phase0.0"
            and c["check"].startswith("loss")]
    assert loss[0]["measured"] is None and not loss[0]["passed"]          # never shows the no-code indication


def test_a_tvm430_receiver_that_ignores_the_check_bits_fails_the_corrupted_word(broken_fmus):
    """Two bits flipped in the speed field read 230/230 without the check: the receiver that
    skips the check shows it, and only that vector catches it."""
    code, out, _ = railcosim("conform", "--role", "loco_receiver", broken_fmus["UncheckedTvmReceiver"],
                             "--format", "json")
    report = json.loads(out)
    assert code == 1 and report["failed_vectors"] == ["tvm430_double_bit_error"]
    failed = {c["check"] for c in report["checks"] if not c["passed"]}
    assert "the corrupted word never shown: any word shown reads 230/170" in failed


def test_a_coder_without_its_two_out_of_two_fails_and_the_table_names_it(broken_fmus):
    code, out, _ = railcosim("conform", "--role", "wayside_coder", broken_fmus["NoFailoverCoder"])
    assert code == 1
    vectors = len(json.loads((DATA / "wayside_coder.json").read_text())["vectors"])
    assert out.strip().splitlines()[-1].endswith(f"1 of {vectors} vectors fail: two_out_of_two_faults")
    rows = [line for line in out.splitlines() if line.startswith("two_out_of_two_faults")]
    assert any("no output with both failed" in row and row.rstrip().endswith("FAIL") for row in rows)


def test_an_ato_that_reads_every_code_as_green_fails_the_signal_at_danger(broken_fmus):
    code, out, _ = railcosim("conform", "--role", "ato_controller", broken_fmus["BlindAto"], "--format", "json")
    report = json.loads(out)
    assert code == 1 and report["failed_vectors"] == ["red_signal_ahead"]
    failed = {c["check"] for c in report["checks"] if not c["passed"]}
    assert "stops before the signal at danger" in failed


@pytest.mark.parametrize("args, message", [
    (("--role", "signal_box", "X.fmu"), "--role 'signal_box': not a role"),
    (("--role", "traction", "dcp://127.0.0.1:8080"), "dcp:// targets are not supported yet"),
    (("--role", "traction", "no_such.fmu"), "no_such.fmu: no such FMU file"),
    (("--role", "traction", "README.md"), "README.md: not an FMU (not a zip archive)"),
])
def test_bad_input_is_one_line_exit_2(args, message):
    code, out, err = railcosim("conform", *args, cwd=REPO)
    assert code == 2 and out == ""
    assert len(err.strip().splitlines()) == 1 and message in err, err


def test_an_fmu_of_another_role_is_refused(product_fmus):
    code, _, err = railcosim("conform", "--role", "loco_receiver", product_fmus / "Traction.fmu")
    assert code == 2 and len(err.strip().splitlines()) == 1
    assert "does not have the ports of role loco_receiver (missing: system, fs, e_coil" in err


@pytest.mark.parametrize("damage, message", [
    (lambda d: (d / "traction.json").write_text("{not json"), "traction.json: not a valid JSON vector file"),
    (lambda d: (d / "traction.json").write_text(
        (d / "traction.json").read_text().replace('"kind": "when"', '"kind": "whenever"', 1)),
     "traction.json: field vectors[0].checks[0].kind: must be one of"),
    (lambda d: (d / "rail_line.npz").write_bytes(b"PK\x03\x04 damaged"), "rail_line.npz: not a readable .npz archive"),
    (lambda d: (d / "traction.json").write_text(json.dumps(
        {**json.loads((d / "traction.json").read_text()),
         "required_ports": [p for p in json.loads((d / "traction.json").read_text())["required_ports"]
                            if p != "stop_time"]})),
     "traction.json: field vectors[0]: uses ports not in required_ports: stop_time"),
])
def test_a_damaged_vector_file_is_one_line_exit_2(product_fmus, tmp_path, damage, message):
    vectors = tmp_path / "vectors"
    shutil.copytree(DATA, vectors)
    damage(vectors)
    role = "rail_line" if "npz" in message else "traction"
    code, out, err = railcosim("conform", "--role", role, product_fmus / f"{PRODUCT[role]}.fmu",
                               "--vectors", vectors)
    assert code == 2 and len(err.strip().splitlines()) == 1 and message in err, err


def _same_to_rounding(written, shipped, where):
    """JSON values: the same structure and text, numbers to 1e-9 relative (the cores' rounding
    differs between processors' BLAS kernels, and a model change at rounding level moves it)."""
    if isinstance(written, dict):
        assert isinstance(shipped, dict) and written.keys() == shipped.keys(), where
        for key in written:
            _same_to_rounding(written[key], shipped[key], f"{where}.{key}")
    elif isinstance(written, list):
        assert isinstance(shipped, list) and len(written) == len(shipped), where
        for index, (a, b) in enumerate(zip(written, shipped)):
            _same_to_rounding(a, b, f"{where}[{index}]")
    elif isinstance(written, float) and not isinstance(shipped, bool):
        assert shipped == pytest.approx(written, rel=1e-9, abs=1e-300), where
    else:
        assert written == shipped and type(written) is type(shipped), where


def test_the_shipped_vectors_are_what_the_generator_writes(tmp_path):
    """The shipped vectors are the generator's output: the same files, with the same numbers to
    rounding (int16 sample counts to one count)."""
    from orchestrator.conformance.generate import generate

    written = generate(directory=tmp_path)
    assert sorted(path.name for path in written) == sorted(path.name for path in DATA.iterdir()
                                                           if path.suffix in (".json", ".npz"))
    for path in written:
        if path.suffix == ".json":
            _same_to_rounding(json.loads(path.read_text(encoding="utf-8")),
                              json.loads((DATA / path.name).read_text(encoding="utf-8")), path.name)
        else:
            with np.load(path) as mine, np.load(DATA / path.name) as theirs:
                assert sorted(mine.files) == sorted(theirs.files), path.name
                for name in mine.files:
                    a, b = mine[name], theirs[name]
                    assert a.dtype == b.dtype and a.shape == b.shape, f"{path.name}: {name}"
                    if a.dtype.kind in "iu":
                        assert np.abs(a.astype(np.int64) - b.astype(np.int64)).max(initial=0) <= 1, f"{path.name}: {name}"
                    else:
                        assert np.allclose(a, b, rtol=1e-9, atol=0.0), f"{path.name}: {name}"


def test_a_target_built_with_another_frame_size_is_stepped_with_its_own_frames():
    """The runner steps N/fs with the target's N (here 16, the vectors were written with 40):
    the rail line's frame input and output and its per-frame rms give the same verdicts."""
    from orchestrator.packaging.builder import UnitSpec, build_unit
    from orchestrator.conformance.runner import conform
    from fmus.sizes import BuildConfig

    fmu = build_unit(UnitSpec("rail_line", "fmus.rail_line.facade", "RailLine"), REPO / "build" / "test_fmus" / "n16",
                     BuildConfig(frame=16)).path
    report = conform("rail_line", str(fmu))
    assert report.passed, [v for v in report.verdicts if not v.passed]
    current = [v for v in report.verdicts if v.vector == "code_current_first_axle"]
    assert current[0].measured < 1e-4          # the window's rms does not depend on the frame

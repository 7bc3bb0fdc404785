"""The master algorithm: multi-rate exactness, Gauss-Seidel/Jacobi latency, frame invariance."""
import numpy as np
import pytest

from helpers import ComponentSpec, ConnectionSpec, frame_connections, read_csv, write_ssd
from orchestrator.verdicts.verdict import railway_verdicts
from orchestrator.run import RunOptions, run_system


def test_multirate_exactness_over_one_hour(tmp_path, test_fmus):
    system = tmp_path / "rates"
    write_ssd(system, "rates", [
        ComponentSpec("fast", str(test_fmus / "TestCounter.fmu"), 0.01),
        ComponentSpec("slow", str(test_fmus / "TestCounter.fmu"), 1.0),
    ], [ConnectionSpec("slow.t_end", "fast.u")], stop_time=3600.0)
    result = run_system(system, RunOptions(summaries=railway_verdicts, output_dir=tmp_path / "out", output_interval=60.0))
    assert result.steps_taken == {"fast": 360_000, "slow": 3_600}
    assert result.end_time_s == 3600.0
    header, data = read_csv(tmp_path / "out" / "results.csv")
    last = dict(zip(header, data[-1]))
    assert last["time"] == 3600.0
    assert last["fast.t_end"] == 3600.0 and last["slow.t_end"] == 3600.0
    assert last["fast.steps"] == 360_000 and last["slow.steps"] == 3_600
    assert data.shape[0] == 61  # t = 0 and every minute


def _chain(tmp_path, fmus, frame, alpha=0.0, name="chain"):
    system = tmp_path / name
    step = frame / 4000.0
    connections = (frame_connections("source.y", "stage1.u", (frame,)) +
                   frame_connections("stage1.y", "stage2.u", (frame,)))
    write_ssd(system, name, [
        ComponentSpec("stage2", str(fmus / "TestFrameStage.fmu"), step, {"alpha": alpha}),
        ComponentSpec("source", str(fmus / "TestFrameSource.fmu"), step),
        ComponentSpec("stage1", str(fmus / "TestFrameStage.fmu"), step, {"alpha": alpha}),
    ], connections, stop_time=0.1)
    return system


def _capture(tmp_path, system, algorithm, tag):
    out = tmp_path / tag
    run_system(system, RunOptions(summaries=railway_verdicts, output_dir=out, algorithm=algorithm, record=[],
                                  captures=["source.y@0:0.1", "stage2.y@0:0.1"]))
    _, source = read_csv(out / "capture_source_y.csv")
    _, final = read_csv(out / "capture_stage2_y.csv")
    return source, final


def test_gauss_seidel_adds_no_latency_and_jacobi_one_frame_per_hop(tmp_path, test_fmus):
    frame = 4
    system = _chain(tmp_path, test_fmus, frame)
    source, final = _capture(tmp_path, system, "gauss-seidel", "gs")
    assert len(source) == 400  # 0.1 s at 4 kHz
    np.testing.assert_array_equal(source[:, 0], np.arange(400) / 4000.0)
    np.testing.assert_array_equal(final[:, 1], source[:, 1])  # declared out of order, run in data-flow order
    source_j, final_j = _capture(tmp_path, system, "jacobi", "jacobi")
    lag = 2 * frame  # two hops, one frame each
    np.testing.assert_array_equal(final_j[lag:, 1], source_j[:-lag, 1])
    assert np.all(final_j[:lag, 1] == 0.0)


def test_frame_size_invariance(tmp_path, test_fmus_by_frame):
    captures = {}
    for frame in (1, 40):
        system = _chain(tmp_path, test_fmus_by_frame(frame), frame, alpha=0.9, name=f"chain{frame}")
        captures[frame] = _capture(tmp_path, system, "gauss-seidel", f"n{frame}")[1]
    assert captures[1].shape == captures[40].shape == (400, 2)
    np.testing.assert_array_equal(captures[1][:, 0], captures[40][:, 0])
    np.testing.assert_allclose(captures[1][:, 1], captures[40][:, 1], rtol=1e-12, atol=1e-12)
    assert captures[40][-1, 1] > 300  # the filter really ran


@pytest.mark.parametrize("in_process", [False, True])
def test_in_process_reference_gives_the_same_results(tmp_path, test_fmus, in_process):
    system = _chain(tmp_path, test_fmus, 4, alpha=0.5)
    out = tmp_path / f"ip{in_process}"
    run_system(system, RunOptions(summaries=railway_verdicts, output_dir=out, in_process=in_process, record=[],
                                  captures=["stage2.y@0:0.1"]))
    _, final = read_csv(out / "capture_stage2_y.csv")
    expected = np.arange(400, dtype=float)
    from scipy.signal import lfilter
    expected = lfilter([0.5], [1, -0.5], lfilter([0.5], [1, -0.5], expected))
    np.testing.assert_allclose(final[:, 1], expected, rtol=1e-12)

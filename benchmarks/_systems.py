"""Small systems the benchmarks run (built from the test FMUs)."""
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO / "tests"))
sys.path.insert(0, str(REPO / "tests" / "fixture_fmus"))

from conftest import build_test_fmus  # noqa: E402
from orchestrator.sspgen import ComponentSpec, ConnectionSpec, write_ssd  # noqa: E402


def trivial_system(folder: Path, stop_time: float, step: float = 0.001) -> Path:
    fmus = build_test_fmus(4)
    write_ssd(folder, "trivial", [
        ComponentSpec("a", str(fmus / "TestCounter.fmu"), step),
        ComponentSpec("b", str(fmus / "TestCounter.fmu"), step),
    ], [ConnectionSpec("a.t_end", "b.u")], stop_time=stop_time)
    return folder

"""Shared fixtures: the test FMUs (built once per frame size, cached by content hash)."""
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent
FIXTURE_PACKAGE = Path(__file__).resolve().parent / "fixture_fmus" / "rcs_testfmus"
sys.path.insert(0, str(FIXTURE_PACKAGE.parent))
sys.path.insert(0, str(REPO))  # harness: the cores coupled without FMI

TEST_UNITS = ("TestCounter", "TestGain", "TestFrameSource", "TestFrameStage", "TestSchedule", "TestSine")


def build_test_fmus(frame: int) -> Path:
    from orchestrator.packaging.builder import UnitSpec, build_unit
    from fmus.sizes import BuildConfig

    dest = REPO / "build" / "test_fmus" / f"n{frame}"
    for identifier in TEST_UNITS:
        build_unit(UnitSpec(identifier.lower(), "rcs_testfmus.facade", identifier), dest,
                   BuildConfig(frame=frame), extra_packages=[FIXTURE_PACKAGE])
    return dest


@pytest.fixture(scope="session")
def test_fmus():
    """Folder with the test FMUs built with frame N = 4."""
    return build_test_fmus(4)


@pytest.fixture(scope="session")
def test_fmus_by_frame():
    return build_test_fmus


@pytest.fixture(scope="session")
def product_fmus():
    """The product FMUs, built (or found up to date) in build/fmus."""
    from orchestrator.packaging.builder import build_all, build_sized_for, default_build_dir

    dest = default_build_dir(REPO)
    build_all(dest)
    build_sized_for(dest, [p for p in (REPO / "ssp").iterdir() if p.is_dir()])     # TVM-430's 32 sections
    return dest


def pytest_terminal_summary(terminalreporter):
    """The doc blocks tests/test_docs_run.py does not run, each with its reason (recorded by
    test_block_not_run_says_why, which passes when the block says why and fails when not)."""
    reasons = sorted(value for report in terminalreporter.stats.get("passed", [])
                     for name, value in getattr(report, "user_properties", ()) if name == "doc block not run")
    if reasons:
        terminalreporter.section("doc blocks not run")
        for reason in reasons:
            terminalreporter.write_line(reason)

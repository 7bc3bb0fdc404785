"""The one-component system ``sine`` of docs/hil.md#tested-against, from a checkout: the test FMU
TestSine (DCPLib's example slave as an FMU, y = sin(k + a); tests/fixture_fmus/rcs_testfmus)
built into FOLDER/resources/TestSine.fmu, and FOLDER/SystemStructure.ssd with that FMU as
component ``ex`` (10 ms step).

    python tests/fixture_fmus/sine_system.py FOLDER

The test suite builds the same FMU (tests/conftest.py, ``build_test_fmus``); this script makes
it, and a system to swap it in, for a bench engineer repeating the DCPLib sessions.
"""
import argparse
import shutil
import sys
from pathlib import Path

FIXTURES = Path(__file__).resolve().parent
REPO = FIXTURES.parent.parent
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(FIXTURES))

#: the test suite's frame for its test FMUs (tests/conftest.py); TestSine has no frame ports
FRAME = 4


def make_sine_system(folder: Path) -> Path:
    """FOLDER/SystemStructure.ssd and FOLDER/resources/TestSine.fmu; the SSD's path."""
    from fmus.sizes import BuildConfig
    from orchestrator.errors import UserError
    from orchestrator.packaging.builder import UnitSpec, build_unit
    from orchestrator.sspgen import ComponentSpec, write_ssd

    if folder.exists() and (not folder.is_dir() or any(folder.iterdir())):
        raise UserError(f"{folder}: already exists; give a new folder")
    built = build_unit(UnitSpec("testsine", "rcs_testfmus.facade", "TestSine"), REPO / "build" / "test_fmus" / f"n{FRAME}",
                       BuildConfig(frame=FRAME), extra_packages=[FIXTURES / "rcs_testfmus"])
    (folder / "resources").mkdir(parents=True, exist_ok=True)
    shutil.copyfile(built.path, folder / "resources" / "TestSine.fmu")
    write_ssd(folder, folder.name, [ComponentSpec("ex", "resources/TestSine.fmu", 0.01)], [])
    return folder / "SystemStructure.ssd"


def main() -> int:
    from orchestrator.errors import UserError

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("folder", type=Path, help="the system folder to write (new, or empty)")
    args = parser.parse_args()
    try:
        ssd = make_sine_system(args.folder)
    except UserError as error:
        print(f"sine_system.py: error: {error}", file=sys.stderr)
        return 2
    print(f"wrote {ssd} (component ex: {args.folder / 'resources' / 'TestSine.fmu'})")
    return 0


if __name__ == "__main__":
    sys.exit(main())

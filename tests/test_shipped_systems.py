"""The committed ssp/ is exactly what orchestrator/systems/shipped.py writes: a change to a
shipped system is made in the generator (and ssp/ regenerated), never by hand, and an installed
package, which writes its systems from the generator, runs the same systems as a checkout."""
import subprocess
import sys
from pathlib import Path

from orchestrator.systems.shipped import SHIPPED, SSP_ROOT, refresh_shipped

REPO = Path(__file__).resolve().parent.parent


def _files(root: Path):
    return {p.relative_to(root).as_posix(): p.read_bytes() for p in sorted(root.rglob("*"))
            if p.is_file() and "__pycache__" not in p.parts}


def test_committed_systems_are_what_the_generator_writes(tmp_path):
    subprocess.run([sys.executable, "-m", "orchestrator.systems.shipped", str(tmp_path)],
                   check=True, cwd=REPO, capture_output=True)
    generated, committed = _files(tmp_path), _files(SSP_ROOT)
    assert sorted(generated) == sorted(committed), "regenerate: python -m orchestrator.systems.shipped"
    differing = [name for name in committed if committed[name] != generated[name]]
    assert not differing, f"differ from the generator (regenerate ssp/): {differing}"
    assert {name.split("/")[0] for name in committed} == set(SHIPPED)


def test_refresh_mirrors_a_shipped_system_exactly(tmp_path):
    refresh_shipped(tmp_path, ["following"])
    folder = tmp_path / "following"
    (folder / "resources" / "extra.json").write_text("{}")
    (folder / "scenario.json").write_text("{}")
    kept = (folder / "SystemStructure.ssd").stat().st_mtime_ns
    refresh_shipped(tmp_path, ["following"])
    assert _files(folder) == _files(SSP_ROOT / "following")
    assert (folder / "SystemStructure.ssd").stat().st_mtime_ns == kept   # unchanged files are not rewritten
    assert sorted(p.name for p in tmp_path.iterdir()) == ["following"]   # no scratch folder left

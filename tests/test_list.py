"""`railcosim list`: every shipped system, study and role by the name the other commands take,
each with a description, as text and as JSON; nothing is built or written."""
import json

from helpers import REPO, railcosim
from orchestrator.conformance import ROLES
from orchestrator.study import shipped_studies
from orchestrator.study.spec import load_study


def _shipped_systems():
    return sorted(p.name for p in (REPO / "ssp").iterdir() if (p / "SystemStructure.ssd").is_file())


def test_list_names_every_shipped_system_study_and_role_with_a_description(tmp_path):
    code, stdout, stderr = railcosim("list", cwd=tmp_path)
    assert code == 0 and stderr == "", stderr
    assert list(tmp_path.iterdir()) == []            # read-only: no build/, no results/
    headings = [line for line in stdout.splitlines() if line and not line.startswith(" ")]
    assert [h.split(" ")[0] for h in headings] == ["systems", "studies", "roles"]
    rows = {line.split()[0]: line for line in stdout.splitlines() if line.startswith("  ")}
    for name in [*_shipped_systems(), *shipped_studies(), *ROLES]:
        assert name in rows, f"{name} not listed:\n{stdout}"
        # a description after the name (and "(default)" for free_run)
        assert len(rows[name].split(None, 1)[1].replace("(default)", "").strip()) > 20, rows[name]
    assert "(default)" in rows["free_run"]

    code, stdout, _ = railcosim("list", "--format", "json", cwd=tmp_path)
    listing = json.loads(stdout)
    assert [s["name"] for s in listing["systems"]][0] == "free_run"
    assert sorted(s["name"] for s in listing["systems"]) == _shipped_systems()
    assert all(s["description"] for kind in listing.values() for s in kind)
    # a study's run count is the one `railcosim study NAME` runs
    assert {s["name"]: s["runs"] for s in listing["studies"]} == {
        name: len(load_study(path).runs) for name, path in shipped_studies().items()}
    # a role's FMU is the one its shipped manifest describes, its vectors those conform runs
    roles = {r["name"]: r for r in listing["roles"]}
    assert set(roles) == set(ROLES)
    assert roles["loco_receiver"]["fmu"] == "LocoReceiver.fmu"
    vectors = json.loads((REPO / "orchestrator" / "conformance" / "data" / "loco_receiver.json").read_text())
    assert roles["loco_receiver"]["vectors"] == len(vectors["vectors"])


def test_list_one_kind_and_a_bad_kind(tmp_path):
    code, stdout, _ = railcosim("list", "roles", cwd=tmp_path)
    assert code == 0 and stdout.startswith("roles ") and "systems" not in stdout
    code, stdout, _ = railcosim("list", "studies", "--format", "json", cwd=tmp_path)
    assert code == 0 and list(json.loads(stdout)) == ["studies"]
    code, stdout, stderr = railcosim("list", "trains", cwd=tmp_path)
    assert code == 2 and stdout == "" and len(stderr.strip().splitlines()) == 1 and "'trains'" in stderr

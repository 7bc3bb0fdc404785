"""`railcosim contract snapshot|check` (docs/contracts.md) and the completeness of the FMUs' model
descriptions: every difference between an FMU and a manifest found and classified, the exit codes a
CI relies on, bad input in one line; descriptions, units, declared step handling and ranges as a
user finds them with fmpy alone."""
import copy
import json
import re
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest
from lxml import etree

from helpers import cli_environment, railcosim
from orchestrator import contracts
from orchestrator.packaging.builder import discover_units
from orchestrator.conformance.roles import role_manifest_path
from orchestrator.cli import main

UNITS = [(spec.unit, spec.model_identifier) for spec in discover_units()]
SIGNAL_FMUS = {"WaysideCoder", "RailLine", "LocoReceiver"}


def _cli(capsys, *args):
    code = main([str(a) for a in args])
    out, err = capsys.readouterr()
    return code, out, err


def _write(path: Path, manifest: dict) -> Path:
    path.write_text(json.dumps(manifest))
    return path


# ---- snapshot → check ---------------------------------------------------------------------------
@pytest.mark.parametrize("unit, identifier", UNITS, ids=[u for u, _ in UNITS])
def test_snapshot_then_check_is_clean_and_the_shipped_manifest_matches(capsys, tmp_path, product_fmus, unit, identifier):
    fmu = product_fmus / f"{identifier}.fmu"
    manifest = tmp_path / "m.json"
    code, out, _ = _cli(capsys, "contract", "snapshot", fmu, "-o", manifest)
    assert code == 0 and f"wrote {manifest}" in out
    written = json.loads(manifest.read_text())
    assert written["model_identifier"] == identifier
    assert written["variable_step"] is (identifier not in SIGNAL_FMUS)
    assert written["frame"] == (40 if identifier in SIGNAL_FMUS else None)
    assert written["step_size_s"] == (0.01 if identifier in SIGNAL_FMUS else 0.5)
    assert all(port["description"] for port in written["ports"].values())
    code, out, _ = _cli(capsys, "contract", "check", fmu, "--manifest", manifest, "--strict")
    assert code == 0, out
    assert out.strip().endswith("0 breaking, 0 compatible difference(s) (--strict: any difference fails): passed")
    # the role's shipped manifest is this FMU's, field for field
    code, out, _ = _cli(capsys, "contract", "check", fmu, "--manifest", unit, "--strict")
    assert code == 0, out
    assert json.loads(role_manifest_path(unit).read_text()) == written


def test_snapshot_to_standard_output_is_the_manifest(capsys, product_fmus):
    code, out, _ = _cli(capsys, "contract", "snapshot", product_fmus / "Traction.fmu")
    assert code == 0
    assert json.loads(out) == contracts.snapshot(product_fmus / "Traction.fmu")


# ---- classification -----------------------------------------------------------------------------
@pytest.fixture(scope="module")
def receiver(product_fmus):
    return contracts.snapshot(product_fmus / "LocoReceiver.fmu")


@pytest.fixture(scope="module")
def ato(product_fmus):
    return contracts.snapshot(product_fmus / "AtoController.fmu")


def _found(manifest, current):
    return {(d.kind, d.port, d.field) for d in contracts.compare(manifest, current)}


def _edited(snapshot, edit):
    manifest = copy.deepcopy(snapshot)
    edit(manifest)
    return manifest


BREAKING, COMPATIBLE = contracts.BREAKING, contracts.COMPATIBLE


def _set(port, field, value):
    def edit(m):
        m["ports"][port][field] = value
    return edit


def _remove_from_fmu(m):          # the manifest has a port the FMU lacks
    m["ports"]["ghost_level"] = {**m["ports"]["level"], "description": "another output"}
    m["ports"]["ghost_level"]["unit"] = "A"


def _rename(m):                   # the manifest's name for `level` is `coil_level`
    m["ports"]["coil_level"] = m["ports"].pop("level")


def _add_to_fmu(m):               # the FMU has a port the manifest lacks
    del m["ports"]["foreign"]


# (edit of the receiver's manifest, the one difference expected)
RECEIVER_CASES = {
    "port removed": (_remove_from_fmu, (BREAKING, "ghost_level", None)),
    "port renamed": (_rename, (BREAKING, "coil_level", None)),
    "port added": (_add_to_fmu, (COMPATIBLE, "foreign", None)),
    "type changed": (_set("code", "type", "Real"), (BREAKING, "code", "type")),
    "causality changed": (_set("level", "causality", "input"), (BREAKING, "level", "causality")),
    "unit changed": (_set("agc_recovery", "unit", "1/s"), (BREAKING, "agc_recovery", "unit")),
    "shape changed": (_set("channel_code", "shape", [2]), (BREAKING, "channel_code", "shape")),
    "variability tunable to fixed": (_set("pick_up", "variability", "tunable"), (BREAKING, "pick_up", "variability")),
    "parameter start changed": (_set("pick_up", "start", "0.2"), (BREAKING, "pick_up", "start")),
    "output start changed": (_set("aspect", "start", "1"), (COMPATIBLE, "aspect", "start")),
    "parameter range narrowed": (_set("pick_up", "min", None), (BREAKING, "pick_up", "min")),
    "parameter range widened": (_set("filter_order", "max", "6"), (COMPATIBLE, "filter_order", "max")),
    "input range narrowed": (_set("channel_fault", "max", "4"), (BREAKING, "channel_fault", "max")),
    "description changed": (_set("level", "description", "old words"), (COMPATIBLE, "level", "description")),
    "model identifier": (lambda m: m.update(model_identifier="SupplierReceiver"), (COMPATIBLE, None, "model_identifier")),
    "frame": (lambda m: m.update(frame=20), (BREAKING, None, "frame")),
    "fixed step changed": (lambda m: m.update(step_size_s=0.005), (BREAKING, None, "step_size_s")),
    "variable step withdrawn": (lambda m: m.update(variable_step=True), (BREAKING, None, "variable_step")),
}


@pytest.mark.parametrize("case", RECEIVER_CASES)
def test_each_change_class_is_found_and_classified(receiver, case):
    edit, expected = RECEIVER_CASES[case]
    assert _found(_edited(receiver, edit), receiver) == {expected}


def test_output_ranges_classify_the_other_way(ato):
    # the ATO's `command` is declared −1…1: an FMU that may send more than the manifest allowed breaks
    # its consumers, one that sends less does not
    assert _found(_edited(ato, _set("command", "max", "0.5")), ato) == {(BREAKING, "command", "max")}
    assert _found(_edited(ato, _set("command", "max", "2")), ato) == {(COMPATIBLE, "command", "max")}


def test_a_variable_step_fmu_default_step_and_added_step_freedom_are_compatible(ato, receiver):
    assert _found(_edited(ato, lambda m: m.update(step_size_s=0.1)), ato) == {(COMPATIBLE, None, "step_size_s")}
    fixed = _edited(receiver, lambda m: m.update(variable_step=True))     # the manifest allows any step …
    assert _found(receiver, fixed) == {(COMPATIBLE, None, "variable_step")}    # … an FMU that does is fine


def test_check_exit_codes_strict_and_json(capsys, tmp_path, product_fmus, receiver):
    fmu = product_fmus / "LocoReceiver.fmu"
    compatible = _write(tmp_path / "c.json", _edited(receiver, _set("level", "description", "old words")))
    code, out, _ = _cli(capsys, "contract", "check", fmu, "--manifest", compatible)
    assert code == 0
    assert out.splitlines()[0].startswith("COMPATIBLE") and "level: description" in out
    code, out, _ = _cli(capsys, "contract", "check", fmu, "--manifest", compatible, "--strict")
    assert code == 1 and out.strip().endswith("FAILED")

    def both(m):
        _rename(m)
        m["ports"]["code"]["type"] = "Real"
    breaking = _write(tmp_path / "b.json", _edited(receiver, both))
    code, out, _ = _cli(capsys, "contract", "check", fmu, "--manifest", breaking, "--format", "json")
    assert code == 1
    report = json.loads(out)
    assert (report["passed"], report["breaking"], report["compatible"]) == (False, 2, 0)
    assert {(d["kind"], d["port"], d["field"]) for d in report["differences"]} == {
        (BREAKING, "coil_level", None), (BREAKING, "code", "type")}
    assert next(d for d in report["differences"] if d["field"] == "type")["fmu"] == "Integer"


def test_a_user_checks_a_receiver_against_its_role_from_the_shell(tmp_path, product_fmus):
    """As in docs/contracts.md: the shipped role manifest, JSON for the CI, the exit code."""
    code, out, err = railcosim("contract", "check", product_fmus / "LocoReceiver.fmu", "--manifest", "loco_receiver",
                               "--format", "json")
    assert (code, err) == (0, "")
    assert json.loads(out)["passed"] is True
    code, out, err = railcosim("contract", "check", product_fmus / "Traction.fmu", "--manifest", "loco_receiver")
    assert code == 1 and err == ""
    assert "BREAKING   e_coil: removed (input in the manifest, not in the FMU)" in out


# ---- bad input ----------------------------------------------------------------------------------
def _one_line_error(capsys, *args):
    code, out, err = _cli(capsys, *args)
    assert code == 2 and out == ""
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("railcosim: error: ") and "Traceback" not in err
    return lines[0]


def test_bad_manifests_fmus_and_roles_are_one_line_exit_2(capsys, tmp_path, product_fmus, receiver):
    fmu = product_fmus / "LocoReceiver.fmu"
    not_json = tmp_path / "not.json"
    not_json.write_text("{ports: none")
    assert f"manifest {not_json}: not JSON" in _one_line_error(capsys, "contract", "check", fmu, "--manifest", not_json)
    lacking = _write(tmp_path / "lacking.json", {"ports": receiver["ports"]})
    line = _one_line_error(capsys, "contract", "check", fmu, "--manifest", lacking)
    assert "lacks the field(s) model_identifier, step_size_s, variable_step, frame" in line
    port_lacking = _write(tmp_path / "port.json", _edited(receiver, lambda m: m["ports"]["level"].pop("unit")))
    assert "ports.level lacks the field(s) unit" in _one_line_error(
        capsys, "contract", "check", fmu, "--manifest", port_lacking)
    assert ("neither a manifest file nor a role; did you mean loco_receiver? (roles: wayside_coder, rail_line, "
            "loco_receiver") in _one_line_error(
        capsys, "contract", "check", fmu, "--manifest", "receiver")
    assert "--manifest missing.json: no such file" in _one_line_error(
        capsys, "contract", "check", fmu, "--manifest", "missing.json")
    text = tmp_path / "text.fmu"
    text.write_text("not a zip")
    assert f"{text}: not an FMU (not a zip archive)" in _one_line_error(
        capsys, "contract", "check", text, "--manifest", "loco_receiver")
    empty_zip = tmp_path / "empty.fmu"
    with zipfile.ZipFile(empty_zip, "w") as archive:
        archive.writestr("readme.txt", "hello")
    assert "not an FMU (no modelDescription.xml)" in _one_line_error(capsys, "contract", "snapshot", empty_zip)
    assert "FMU not found" in _one_line_error(capsys, "contract", "snapshot", tmp_path / "absent.fmu")
    assert "contract check: the following arguments are required: --manifest" in _one_line_error(
        capsys, "contract", "check", fmu)
    assert "cannot write the manifest" in _one_line_error(
        capsys, "contract", "snapshot", fmu, "-o", tmp_path / "no_such_folder" / "m.json")
    other_version = _write(tmp_path / "v2.json", {**receiver, "manifest_version": 2})
    assert "manifest_version 2; this railcosim reads version 1" in _one_line_error(
        capsys, "contract", "check", fmu, "--manifest", other_version)


# ---- model descriptions as a user finds them ----------------------------------------------------
def _model_description(fmu: Path):
    with zipfile.ZipFile(fmu) as archive:
        return etree.fromstring(archive.read("modelDescription.xml"))


@pytest.mark.parametrize("unit, identifier", UNITS, ids=[u for u, _ in UNITS])
def test_model_descriptions_are_complete_and_valid(product_fmus, unit, identifier):
    from fmpy.validation import validate_fmu

    fmu = product_fmus / f"{identifier}.fmu"
    assert validate_fmu(str(fmu)) == []
    root = _model_description(fmu)
    undescribed = [sv.get("name") for sv in root.find("ModelVariables") if not (sv.get("description") or "").strip()]
    assert undescribed == []
    variable = root.find("CoSimulation").get("canHandleVariableCommunicationStepSize")
    assert variable == ("false" if identifier in SIGNAL_FMUS else "true")


def test_agc_recovery_is_declared_in_db_per_second(product_fmus):
    root = _model_description(product_fmus / "LocoReceiver.fmu")
    real = root.find("ModelVariables/ScalarVariable[@name='agc_recovery']/Real")
    assert real.get("unit") == "dB/s"
    unit = root.find("UnitDefinitions/Unit[@name='dB/s']")
    assert unit is not None and unit.find("BaseUnit").get("s") == "-1"


_FMPY_SCRIPT = r"""
import json, sys
from fmpy import simulate_fmu
messages = []
def logger(env, instance, status, category, message):
    messages.append(message.decode(errors="replace"))
fmu, values, step = sys.argv[1], json.loads(sys.argv[2]), float(sys.argv[3])
try:
    simulate_fmu(fmu, stop_time=2 * step, step_size=step, output_interval=step, start_values=values, logger=logger,
                 debug_logging=True)
    print(json.dumps({"ok": True, "messages": messages}))
except Exception as error:
    print(json.dumps({"ok": False, "error": str(error), "messages": messages}))
"""


def _fmpy(fmu: Path, values: dict, step: float) -> dict:
    proc = subprocess.run([sys.executable, "-c", _FMPY_SCRIPT, str(fmu), json.dumps(values), str(step)],
                          capture_output=True, text=True, timeout=300, env=cli_environment())
    return json.loads(proc.stdout.strip().splitlines()[-1])


# a message naming a parameter: `parameter NAME` (NAME, or each of NAME / NAME, a literal word)
_NAMED = re.compile(r"parameter ((?:[a-z_][a-z0-9_]*)(?: / [a-z_][a-z0-9_]*)*)[:\s]")


def test_error_messages_name_the_fmus_own_variables():
    """Every message of a unit's model that names a parameter names one of its FMU's variables
    (not a core's keyword such as ``pantograph_voltage_v``)."""
    import importlib

    from fmus.sizes import BuildConfig

    ports = set()
    for spec in discover_units():
        facade = getattr(importlib.import_module(spec.facade_module), spec.model_identifier)
        ports |= {port.name for port in facade.declare_ports(BuildConfig())}
    root = Path(__file__).resolve().parent.parent / "fmus"
    strangers = []
    for path in sorted(root.rglob("*.py")):
        for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
            text = line.strip()
            if text.startswith(("class ", '"""')) or ("Error(" not in text and not text.startswith(('f"', '"'))):
                continue
            for match in _NAMED.finditer(line):
                strangers += [f"{path.relative_to(root)}:{number}: {name}"
                              for name in match.group(1).split(" / ") if name not in ports]
    assert strangers == []


@pytest.mark.parametrize("values, message", [
    ({"mass_scale": 0.05}, "mass_scale = 0.05 is below its minimum 0.1"),
    ({"max_substep": 50.0}, "max_substep = 50 is above its maximum 10"),
])
def test_a_parameter_outside_its_declared_range_fails_initialisation_naming_it(product_fmus, values, message):
    result = _fmpy(product_fmus / "Traction.fmu", values, 0.5)
    assert result["ok"] is False and "fmi2ExitInitializationMode" in result["error"]
    assert any(message in line for line in result["messages"]), result["messages"]


def test_the_declared_step_handling_is_what_the_fmus_do(product_fmus):
    # Traction declares a variable step: fmpy steps it at 0.2 s instead of its 0.5 s default
    assert _fmpy(product_fmus / "Traction.fmu", {}, 0.2) == {"ok": True, "messages": []}
    # the rail line declares a fixed step: another one is refused (fmi2Discard, which fmpy does
    # not raise), naming the one it needs
    refused = _fmpy(product_fmus / "RailLine.fmu", {}, 0.02)
    assert refused["messages"] == ["RailLine: communication step 0.02 s refused; this build needs exactly 0.01 s (frame/fs)"]


_IMPORTS_SCRIPT = r"""
import importlib, json, sys
module, name = sys.argv[1], sys.argv[2]
facade = getattr(importlib.import_module(module), name)
slave = facade(instance_name="imports", resources=None)
slave.setup_experiment(0.0, None, None)
slave.enter_initialization_mode()
slave.exit_initialization_mode()
assert slave.do_step(0.0, slave.required_step_s or 0.5)
print(json.dumps(sorted({m.split(".")[0] for m in sys.modules})))
"""
_PACKAGES = ("numpy", "scipy", "control", "matplotlib", "jsonschema", "pythonfmu")


def test_the_python_packages_each_fmu_needs_are_the_ones_documented():
    """docs/interfaces.md lists, per FMU, the packages its Python must have: the ones its model
    imports through initialisation and a step (pythonfmu for every FMU)."""
    page = (Path(__file__).resolve().parent.parent / "docs" / "interfaces.md").read_text(encoding="utf-8")
    documented = {}
    for line in page.splitlines():
        cells = [cell.strip() for cell in line.strip().strip("|").split("|")]
        if len(cells) == 2 and cells[0] in {identifier for _, identifier in UNITS}:
            documented[cells[0]] = {p for p in _PACKAGES if re.search(rf"\b{p}\b", cells[1])} | {"pythonfmu"}
    assert set(documented) == {identifier for _, identifier in UNITS}
    for spec in discover_units():
        proc = subprocess.run([sys.executable, "-c", _IMPORTS_SCRIPT, spec.facade_module, spec.model_identifier],
                              capture_output=True, text=True, timeout=300, env=cli_environment())
        imported = set(json.loads(proc.stdout.strip().splitlines()[-1])) & set(_PACKAGES)
        assert imported == documented[spec.model_identifier], spec.model_identifier


def test_build_dest_writes_the_fmus_there_and_nothing_beside_them(tmp_path):
    """docs/contracts.md's `railcosim build --frame 20 --dest supplier/fmus`: the FMUs in
    supplier/fmus and nothing else; the shipped systems' .ssp archives (packed with these
    20-sample FMUs they would not even run) were written into supplier/ too."""
    code, stdout, stderr = railcosim("build", "--frame", "20", "--dest", "supplier/fmus", cwd=tmp_path)
    assert code == 0, stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["supplier"]
    assert sorted(p.name for p in (tmp_path / "supplier").iterdir()) == ["fmus"]
    assert sorted(p.name for p in (tmp_path / "supplier" / "fmus").iterdir() if p.suffix == ".fmu") == sorted(
        f"{identifier}.fmu" for _, identifier in UNITS)
    assert "packed" not in stdout

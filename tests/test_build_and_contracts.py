"""Built FMUs validate cleanly, match their committed contract manifests, rebuild only on change,
and many instances of one FMU live in one process; every declared parameter bound is enforced."""
import importlib
import math
import subprocess
import sys
from pathlib import Path

import pytest

from conftest import FIXTURE_PACKAGE, TEST_UNITS
from orchestrator.packaging.builder import UnitSpec, build_unit, discover_units, validate_built
from orchestrator.conformance.roles import diff, manifest_of, read_manifest
from fmus.errors import FmuInputError
from fmus.sizes import BuildConfig

REPO = Path(__file__).resolve().parent.parent
CONTRACTS = Path(__file__).resolve().parent / "fixture_fmus" / "contracts"


@pytest.mark.parametrize("identifier", TEST_UNITS)
def test_fixture_fmus_validate_and_match_contract(test_fmus, identifier):
    fmu = test_fmus / f"{identifier}.fmu"
    assert validate_built(fmu) == []
    assert diff(read_manifest(CONTRACTS / f"{identifier}.json"), manifest_of(fmu)) == []


def test_contract_diff_lists_every_difference(test_fmus):
    manifest = read_manifest(CONTRACTS / "TestGain.json")
    manifest["y"]["unit"] = "km/h"
    manifest["ghost"] = dict(manifest["u"])
    del manifest["bias"]
    problems = diff(manifest, manifest_of(test_fmus / "TestGain.fmu"))
    assert problems == ["bias: in the FMU, not in the manifest",
                        "ghost: in the manifest, missing from the FMU",
                        "y.unit: manifest 'km/h', FMU 'm/s'"]


@pytest.mark.parametrize("spec", discover_units(), ids=lambda s: s.unit)
def test_product_fmus_validate_and_match_contract(tmp_path_factory, spec):
    built = build_unit(spec, REPO / "build" / "fmus")
    assert validate_built(built.path) == []
    manifest = REPO / "fmus" / spec.unit / "contract.json"
    assert diff(read_manifest(manifest), manifest_of(built.path)) == []


def test_rebuild_only_when_content_changes(tmp_path):
    spec = UnitSpec("testgain", "rcs_testfmus.facade", "TestGain")
    first = build_unit(spec, tmp_path, BuildConfig(frame=4), extra_packages=[FIXTURE_PACKAGE])
    again = build_unit(spec, tmp_path, BuildConfig(frame=4), extra_packages=[FIXTURE_PACKAGE])
    other = build_unit(spec, tmp_path, BuildConfig(frame=8), extra_packages=[FIXTURE_PACKAGE])
    assert (first.rebuilt, again.rebuilt, other.rebuilt) == (True, False, True)


def test_many_instances_of_one_fmu_in_one_process(test_fmus):
    """pythonfmu 0.7.0 releases a borrowed module reference per instance; our scripts compensate."""
    script = f"""
import gc
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave
path = {str(test_fmus / 'TestCounter.fmu')!r}
md = read_model_description(path); folder = extract(path)
slaves = []
for k in range(25):
    s = FMU2Slave(guid=md.guid, unzipDirectory=folder, modelIdentifier='TestCounter', instanceName=f'c{{k}}')
    s.instantiate(); s.setupExperiment(startTime=0); s.enterInitializationMode(); s.exitInitializationMode()
    s.doStep(0.0, 0.1); gc.collect(); slaves.append(s)
print('ok', len(slaves))
for s in slaves:
    s.terminate(); s.fmi2FreeInstance(s.component)
"""
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0 and "ok 25" in proc.stdout, proc.stderr[-500:]


# ---- parameter bounds: one check in fmus/fmi, generated from the ports --------------------------
def _facades():
    return [(spec.unit, getattr(importlib.import_module(spec.facade_module), spec.model_identifier))
            for spec in discover_units()]


def _bound_violations():
    """For every numeric parameter of every product facade: a value past each declared bound,
    and for a Real one a value that is not finite, with the error it must give."""
    cases = []
    for unit, facade in _facades():
        for port in facade.declare_ports(BuildConfig()):
            if port.causality != "parameter" or port.type not in ("Real", "Integer"):
                continue
            element = port.element_names()[-1]          # of an array, its last element
            for bound, side, sign in ((port.min, "below its minimum", -1), (port.max, "above its maximum", 1)):
                if bound is None:
                    continue
                value = bound + sign * (1 if port.type == "Integer" else 0.5 * max(abs(bound), 1.0))
                cases.append(pytest.param(facade, port, element, value, f"{element} = {value:g} is {side} {bound:g}",
                                          id=f"{unit}.{element}-{side.split()[0]}"))
            if port.type == "Real":
                for value in (math.nan, math.inf):
                    cases.append(pytest.param(facade, port, element, value, f"{element} = {value:g} is not a finite number",
                                              id=f"{unit}.{element}-{value}"))
    return cases


@pytest.mark.parametrize("unit, facade", _facades(), ids=[unit for unit, _ in _facades()])
def test_every_parameter_start_is_within_its_declared_bounds(unit, facade):
    facade(instance_name=unit, resources=None).check_parameter_ranges()


@pytest.mark.parametrize("facade, port, element, value, message", _bound_violations())
def test_every_declared_parameter_bound_is_enforced_in_the_ports_name(facade, port, element, value, message):
    """In process, through the facade's FMI setter and exitInitializationMode, as a host does."""
    slave = facade(instance_name="bounds", resources=None)
    vr = next(vr for vr, variable in slave.vars.items() if variable.name == element)
    getattr(slave, f"set_{port.type.lower()}")([vr], [value])
    slave.enter_initialization_mode()
    with pytest.raises(FmuInputError) as error:
        slave.exit_initialization_mode()
    assert str(error.value) == message
    assert slave.core is None                          # refused before the core is made
    assert any(message in entry.msg for entry in slave.log_queue)


def _fixture_modules():
    return [n for n in sys.modules if n == "rcs_testfmus" or n.startswith("rcs_testfmus.")]


def test_an_extra_package_imported_earlier_from_a_removed_folder_does_not_shadow_the_build(tmp_path, monkeypatch):
    """A run in process imports a test package from an unpacked FMU, whose folder is then
    removed; a later build in that process must import the package's modules from its own
    staged copy (the copy imported first lacks the module the build needs)."""
    import shutil

    unpacked = tmp_path / "unpacked"
    shutil.copytree(FIXTURE_PACKAGE, unpacked / "rcs_testfmus", ignore=shutil.ignore_patterns("broken.py", "__pycache__"))
    for name in _fixture_modules():
        monkeypatch.delitem(sys.modules, name)         # put back after the test
    monkeypatch.syspath_prepend(str(unpacked))
    try:
        importlib.import_module("rcs_testfmus.facade")
        shutil.rmtree(unpacked)
        built = build_unit(UnitSpec("stuckreceiver", "rcs_testfmus.broken", "StuckReceiver"), tmp_path / "fmus",
                           extra_packages=[FIXTURE_PACKAGE])
        assert built.path.is_file()
    finally:
        for name in _fixture_modules():               # the unpacked copies, gone with their folder
            del sys.modules[name]

"""The forwarding binary at build time (orchestrator/packaging/forwarder/) and the FMUs without it:
the fallback without a C compiler, a Python without a shared libpython, foreign (plain
pythonfmu) FMUs in our orchestrator, an FMU without a binary for this platform."""
import dataclasses
import zipfile

import pytest

from conftest import FIXTURE_PACKAGE
from fmus.sizes import BuildConfig
from helpers import ComponentSpec, ConnectionSpec, railcosim, write_ssd
from orchestrator import hostenv
from orchestrator.packaging import forwarder as fwd
from orchestrator.packaging.builder import UnitSpec, build_unit, content_hash
from orchestrator.errors import UserError

COUNTER = UnitSpec("testcounter", "rcs_testfmus.facade", "TestCounter")


def test_without_a_c_compiler_the_build_says_so_once_and_builds_plain_fmus(monkeypatch):
    monkeypatch.setattr(fwd, "find_compiler", lambda: None)
    plan = fwd.plan()
    assert isinstance(plan, fwd.NoForwarder) and "no C compiler" in plan.reason


def test_a_python_without_shared_libpython_is_one_clear_error(monkeypatch, tmp_path):
    missing = tmp_path / "libpython9.9.so"
    monkeypatch.setattr(hostenv, "libpython_candidates", lambda: [missing])
    with pytest.raises(UserError) as error:
        fwd.plan()
    message = str(error.value)
    assert str(missing) in message and "\n" not in message and "--enable-shared" in message


def test_the_content_hash_follows_the_forwarder_source_and_python_settings(monkeypatch, tmp_path):
    plan = fwd.plan()
    assert isinstance(plan, fwd.Forwarder)
    before = content_hash(COUNTER, BuildConfig(), [FIXTURE_PACKAGE], plan)
    other_settings = content_hash(COUNTER, BuildConfig(), [FIXTURE_PACKAGE],
                                  dataclasses.replace(plan, settings=plan.settings + "X=1\n"))
    source = tmp_path / "fmi2_direct.c"
    source.write_text(fwd.SOURCES[1].read_text() + "/* changed */\n")
    monkeypatch.setattr(fwd, "SOURCES", (fwd.SOURCES[0], source))
    after = content_hash(COUNTER, BuildConfig(), [FIXTURE_PACKAGE], plan)
    plain = content_hash(COUNTER, BuildConfig(), [FIXTURE_PACKAGE], fwd.NoForwarder("test"))
    assert len({before, other_settings, after, plain}) == 4


@pytest.fixture(scope="module")
def plain_fmus(tmp_path_factory):
    """A foreign FMU: TestCounter as a plain pythonfmu 0.7.0 FMU (no forwarder)."""
    dest = tmp_path_factory.mktemp("plain")
    build_unit(COUNTER, dest, BuildConfig(frame=4), extra_packages=[FIXTURE_PACKAGE],
               forwarder=fwd.NoForwarder("test: plain pythonfmu FMU"))
    return dest


def test_the_plain_build_keeps_pythonfmus_binary(plain_fmus):
    with zipfile.ZipFile(plain_fmus / "TestCounter.fmu") as archive:
        names = set(archive.namelist())
    assert "binaries/linux64/TestCounter.so" in names and "binaries/linux64/TestCounter_pythonfmu.so" not in names
    assert fwd.SETTINGS_MEMBER not in names and fwd.VALUE_REFERENCES_MEMBER not in names


def _two_counters(folder, fmu):
    write_ssd(folder, "two", [ComponentSpec("a", str(fmu), 0.001), ComponentSpec("b", str(fmu), 0.001)],
              [ConnectionSpec("a.t_end", "b.u")], stop_time=0.05)
    return folder


def test_a_foreign_pythonfmu_fmu_runs_and_its_library_is_released(plain_fmus, tmp_path, monkeypatch):
    """Foreign plain pythonfmu binaries keep the orchestrator's release (FmuSlave.free)."""
    from orchestrator import fmu
    from orchestrator.run import RunOptions, run_system

    monkeypatch.setattr(fmu, "_LIVE_LIBRARIES", {})
    folder = _two_counters(tmp_path / "sys", plain_fmus / "TestCounter.fmu")
    run_system(folder, RunOptions(output_dir=tmp_path / "o", output_interval=0.01))
    assert len(fmu._LIVE_LIBRARIES) == 1 and set(fmu._LIVE_LIBRARIES.values()) == {0}
    code, _, stderr = railcosim("run", folder, "--no-build", "--output", tmp_path / "o2")
    assert code == 0, stderr[-800:]


def test_our_fmus_need_no_release_by_the_orchestrator(test_fmus, tmp_path, monkeypatch):
    from orchestrator import fmu
    from orchestrator.run import RunOptions, run_system

    monkeypatch.setattr(fmu, "_LIVE_LIBRARIES", {})
    folder = _two_counters(tmp_path / "sys", test_fmus / "TestCounter.fmu")
    run_system(folder, RunOptions(output_dir=tmp_path / "o", output_interval=0.01))
    assert fmu._LIVE_LIBRARIES == {}


def test_an_fmu_without_a_binary_for_this_platform_is_one_line(test_fmus, tmp_path):
    stripped = tmp_path / "TestCounter.fmu"
    with zipfile.ZipFile(test_fmus / "TestCounter.fmu") as source, zipfile.ZipFile(stripped, "w") as target:
        for info in source.infolist():
            if not info.filename.startswith("binaries/linux64/"):
                target.writestr(info, source.read(info))
    folder = _two_counters(tmp_path / "sys", stripped)
    code, _, stderr = railcosim("run", folder, "--no-build", "--output", tmp_path / "o")
    assert code == 2 and len(stderr.strip().splitlines()) == 1 and "Traceback" not in stderr
    assert "TestCounter.fmu: no binary for linux64" in stderr and "win64" in stderr


# ---- the value-reference table the forwarder checks get/set against --------------------------------
def _table(text: str) -> dict:
    lines = [line.split() for line in text.splitlines() if not line.startswith("#")]
    return {words[0]: [int(w) for w in words[1:]] for words in lines}


def test_the_value_reference_table_rules():
    """Every variable under its FMI type (an Enumeration is Integer); settable: inputs,
    parameters, initial exact/approx; never a constant, the independent variable or a
    calculated output."""
    xml = b"""<fmiModelDescription><ModelVariables>
      <ScalarVariable name="p" valueReference="7" causality="parameter" variability="fixed"><Real start="1"/></ScalarVariable>
      <ScalarVariable name="u" valueReference="3" causality="input"><Boolean start="false"/></ScalarVariable>
      <ScalarVariable name="y" valueReference="1" causality="output" initial="calculated"><Real/></ScalarVariable>
      <ScalarVariable name="y0" valueReference="2" causality="output" initial="exact"><Real start="0"/></ScalarVariable>
      <ScalarVariable name="e" valueReference="4" causality="input"><Enumeration declaredType="E" start="1"/></ScalarVariable>
      <ScalarVariable name="k" valueReference="5" variability="constant"><Integer start="2"/></ScalarVariable>
      <ScalarVariable name="t" valueReference="0" causality="independent"><Real/></ScalarVariable>
      <ScalarVariable name="s" valueReference="6" causality="local"><String start=""/></ScalarVariable>
    </ModelVariables></fmiModelDescription>"""
    assert _table(fwd.value_reference_text(xml)) == {
        "Real": [0, 1, 2, 7], "Real:set": [2, 7], "Integer": [4, 5], "Integer:set": [4],
        "Boolean": [3], "Boolean:set": [3], "String": [6], "String:set": []}


def test_the_built_table_is_the_facades_value_reference_table(product_fmus):
    """What the forwarder reads is what FacadeSlave.value_reference_table() gives: every reference
    per type; settable exactly the parameters and inputs."""
    from fmus.loco_receiver.facade import LocoReceiver
    from fmus.traction.facade import Traction

    for facade in (Traction, LocoReceiver):
        with zipfile.ZipFile(product_fmus / f"{facade.__name__}.fmu") as archive:
            built = _table(archive.read(fwd.VALUE_REFERENCES_MEMBER).decode())
        table = facade(instance_name="f", resources=None).value_reference_table()
        for fmi_type, by_causality in table.items():
            assert built[fmi_type] == sorted(vr for vrs in by_causality.values() for vr in vrs), (facade, fmi_type)
            assert built[f"{fmi_type}:set"] == sorted(by_causality.get("parameter", []) + by_causality.get("input", []))


def test_the_description_copy_holds_the_guid_and_the_capabilities():
    """resources/railcosim_description.txt: what fmi2Instantiate and the optional calls are checked
    against (a host need not extract modelDescription.xml)."""
    xml = (b'<fmiModelDescription fmiVersion="2.0" guid="{abc}"><CoSimulation modelIdentifier="m"'
           b' canGetAndSetFMUstate="true" maxOutputDerivativeOrder="2"/></fmiModelDescription>')
    assert fwd.description_text(xml).splitlines()[1:] == [
        "guid={abc}", "CoSimulation=1", "canGetAndSetFMUstate=1", "canSerializeFMUstate=0",
        "providesDirectionalDerivative=0", "canInterpolateInputs=0", "maxOutputDerivativeOrder=2"]
    model_exchange = b'<fmiModelDescription guid="g"><ModelExchange modelIdentifier="m"/></fmiModelDescription>'
    assert "CoSimulation=0" in fwd.description_text(model_exchange)

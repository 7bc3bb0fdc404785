"""SSP loading: parameter bindings (external, inline, prefix), SSM mappings, LinearTransformation,
connector units, named parameter sets and command-line overrides — values checked after a run."""
import os

import pytest
from lxml import etree

from helpers import ComponentSpec, ConnectionSpec, railcosim, read_csv, write_ssd
from orchestrator.verdicts.verdict import railway_verdicts
from orchestrator.run import RunOptions, run_system
from orchestrator.sspgen import write_ssv

SSM = """<?xml version="1.0" encoding="UTF-8"?>
<ssm:ParameterMapping xmlns:ssm="http://ssp-standard.org/SSP1/SystemStructureParameterMapping"
    xmlns:ssc="http://ssp-standard.org/SSP1/SystemStructureCommon" version="1.0">
  <ssm:MappingEntry source="gain_percent" target="k">
    <ssc:LinearTransformation factor="0.01" offset="0.0"/>
  </ssm:MappingEntry>
  <ssm:MappingEntry source="switch" target="mode">
    <ssc:IntegerMappingTransformation>
      <ssc:MapEntry source="1" target="7"/>
    </ssc:IntegerMappingTransformation>
  </ssm:MappingEntry>
</ssm:ParameterMapping>
"""


def _system(tmp_path, fmus, gain_params, connection_factor=1.0, connection_offset=0.0):
    folder = tmp_path / "sys"
    (folder / "resources").mkdir(parents=True, exist_ok=True)
    write_ssd(folder, "bindings", [
        ComponentSpec("clock", str(fmus / "TestCounter.fmu"), 0.5),
        ComponentSpec("gain", str(fmus / "TestGain.fmu"), 0.5, **gain_params),
    ], [ConnectionSpec("clock.t_end", "gain.u", connection_factor, connection_offset,
                       suppress_unit_conversion=True)], stop_time=2.0)  # s → m/s on purpose
    return folder


def _last(out):
    header, data = read_csv(out / "results.csv")
    return dict(zip(header, data[-1]))


def test_bindings_mapping_and_linear_transformation(tmp_path, test_fmus):
    folder = tmp_path / "sys"
    write_ssv(folder / "resources" / "gain.ssv", "gain", {"gain_percent": 250.0, "switch": 1,
                                                          "enabled": True, "label": "external"})
    (folder / "resources" / "gain.ssm").write_text(SSM)
    _system(tmp_path, test_fmus, {"parameter_file": "resources/gain.ssv",
                                  "parameter_mapping": "resources/gain.ssm",
                                  "parameters": {"bias": 0.5}},
            connection_factor=3.0, connection_offset=1.0)
    out = tmp_path / "out"
    result = run_system(folder, RunOptions(summaries=railway_verdicts, output_dir=out, output_interval=0.5))
    params = result.graph.nodes["gain"].parameters
    assert params["k"] == 2.5 and params["mode"] == 7 and params["bias"] == 0.5
    assert params["label"] == "external" and params["enabled"] is True
    last = _last(out)
    # u = 3·t_end + 1 with t_end = 2.0 → 7; y = 2.5·7 + 0.5
    assert last["gain.y"] == 2.5 * 7.0 + 0.5
    assert last["gain.mode_out"] == 7


def test_connector_units_are_converted(tmp_path, test_fmus):
    """A km/h parameter value bound to an m/s parameter is divided by 3.6 (SSD unit definitions)."""
    folder = _system(tmp_path, test_fmus, {"parameters": {"k": 1.0}})
    ssd = folder / "SystemStructure.ssd"
    ns_ssd = "http://ssp-standard.org/SSP1/SystemStructureDescription"
    ns_ssc = "http://ssp-standard.org/SSP1/SystemStructureCommon"
    tree = etree.parse(str(ssd))
    root = tree.getroot()
    units = etree.Element(f"{{{ns_ssd}}}Units")
    for name, factor in (("km/h", 1 / 3.6), ("m/s", 1.0)):
        unit = etree.SubElement(units, f"{{{ns_ssc}}}Unit", name=name)
        etree.SubElement(unit, f"{{{ns_ssc}}}BaseUnit", m="1", s="-1", factor=repr(factor))
    root.insert(list(root).index(root.find(f"{{{ns_ssd}}}DefaultExperiment")), units)
    tree.write(str(ssd))
    write_ssv(folder / "speeds.ssv", "speeds", {"gain.bias": 36.0}, units={"gain.bias": "km/h"})
    out = tmp_path / "out"
    result = run_system(folder, RunOptions(summaries=railway_verdicts, output_dir=out, param_sets=["speeds"],
                                           overrides={"gain.k": "0"}, output_interval=0.5))
    # 36 km/h → 10 m/s
    assert abs(result.graph.nodes["gain"].parameters["bias"] - 10.0) < 1e-12
    assert abs(_last(out)["gain.y"] - 10.0) < 1e-12


# ---- connectors and the OSP algorithm annotation (docs/interfaces.md#ssp-conventions) ------------
SSD_NS = {"ssd": "http://ssp-standard.org/SSP1/SystemStructureDescription",
          "ssc": "http://ssp-standard.org/SSP1/SystemStructureCommon",
          "osp": "http://opensimulationplatform.com/SSP/OSPAnnotations",
          "rcs": "http://railcosim.org/SSP/1"}


def _edit_ssd(folder, edit):
    ssd = folder / "SystemStructure.ssd"
    tree = etree.parse(str(ssd))
    edit(tree.getroot())
    tree.write(str(ssd))
    return ssd


def _connector(root, component, name):
    return root.find(f".//ssd:Component[@name='{component}']/ssd:Connectors/ssd:Connector[@name='{name}']", SSD_NS)


def test_written_ssd_declares_connectors_and_the_osp_base_step(tmp_path, test_fmus):
    """write_ssd declares each component's outputs, parameters and connected inputs (types and
    units from the FMU) and the base step as osp:FixedStepAlgorithm; the loader reads it back."""
    from orchestrator.ssp import open_system

    folder = _system(tmp_path, test_fmus, {"parameters": {"k": 2.0}})
    system = open_system(folder)
    assert system.components["gain"].connectors == {
        "bias": ("parameter", "Real", "m/s"), "enabled": ("parameter", "Boolean", None),
        "enabled_out": ("output", "Boolean", None), "k": ("parameter", "Real", "1"),
        "label": ("parameter", "String", None), "mode": ("parameter", "Integer", None),
        "mode_out": ("output", "Integer", None), "u": ("input", "Real", "m/s"), "y": ("output", "Real", "m/s")}
    assert "u" not in system.components["clock"].connectors      # an unconnected input is not declared
    root = etree.parse(str(folder / "SystemStructure.ssd")).getroot()
    fixed = root.find("ssd:DefaultExperiment/ssd:Annotations/ssc:Annotation[@type='com.opensimulationplatform']"
                      "/osp:Algorithm/osp:FixedStepAlgorithm", SSD_NS)
    assert fixed.get("baseStepSize") == "0.5" and system.base_step_s == 0.5
    assert root.find(".//rcs:BaseStep", SSD_NS) is None

    # steps 0.5 and 0.2 → base 0.1 (gcd); a given base step is written both ways, ours wins when they differ
    write_ssd(folder, "rates", [ComponentSpec("clock", str(test_fmus / "TestCounter.fmu"), 0.5),
                                ComponentSpec("gain", str(test_fmus / "TestGain.fmu"), 0.2)], [])
    assert open_system(folder).base_step_s == 0.1
    write_ssd(folder, "rates", [ComponentSpec("clock", str(test_fmus / "TestCounter.fmu"), 0.5)], [],
              base_step_s=0.25)
    _edit_ssd(folder, lambda root: root.find(".//osp:FixedStepAlgorithm", SSD_NS).set("baseStepSize", "0.05"))
    assert open_system(folder).base_step_s == 0.25


def test_ssd_without_connectors_or_osp_annotations_runs_the_same(tmp_path, test_fmus):
    """Users' own SSDs need not declare connectors: the same system without them (and without any
    osp annotation) gives the same results."""
    runs = {}
    for variant in ("declared", "bare"):
        folder = _system(tmp_path / variant, test_fmus, {"parameters": {"k": 2.0, "bias": 0.25}})
        if variant == "bare":
            def strip(root):
                for node in root.findall(".//ssd:Connectors", SSD_NS) + root.findall(
                        ".//ssc:Annotation[@type='com.opensimulationplatform']", SSD_NS):
                    node.getparent().remove(node)
                for empty in root.findall(".//ssd:Annotations", SSD_NS):
                    if not len(empty):
                        empty.getparent().remove(empty)
            text = _edit_ssd(folder, strip).read_text()
            assert "<ssd:Connector" not in text and "<osp:" not in text
        out = tmp_path / variant / "out"
        run_system(folder, RunOptions(summaries=railway_verdicts, output_dir=out, output_interval=0.5))
        runs[variant] = read_csv(out / "results.csv")
    assert runs["declared"][0] == runs["bare"][0]
    assert (runs["declared"][1] == runs["bare"][1]).all() and len(runs["bare"][1]) == 5


def _bad_kind(root):
    _connector(root, "gain", "y").set("kind", "input")


def _bad_type(root):
    typed = _connector(root, "gain", "mode")[0]
    typed.tag = typed.tag.replace("Integer", "Real")


def _bad_unit(root):
    _connector(root, "gain", "u")[0].set("unit", "km/h")


def _missing(root):
    _connector(root, "gain", "k").set("name", "gain_k")


@pytest.mark.parametrize("edit, expected", [
    (_missing, "connector 'gain_k' does not exist in"),
    (_bad_kind, "connector 'y' is declared kind='input' but the FMU has causality 'output'"),
    (_bad_type, "connector 'mode' is declared Real but the FMU has Integer"),
    (_bad_unit, "connector 'u' is declared in 'km/h' but the FMU's unit is 'm/s'"),
])
def test_declared_connectors_are_checked_against_the_fmu(tmp_path, test_fmus, edit, expected):
    from orchestrator.errors import UserError
    from orchestrator.graph import build_graph
    from orchestrator.ssp import open_system

    folder = _system(tmp_path, test_fmus, {"parameters": {"k": 2.0}})
    ssd = _edit_ssd(folder, edit)
    line = next(n for n, text in enumerate(ssd.read_text().splitlines(), 1) if 'name="gain"' in text)
    with pytest.raises(UserError) as error:
        build_graph(open_system(folder))
    message = str(error.value)
    assert "\n" not in message and expected in message
    assert message.startswith(f"{ssd}:{line}: component 'gain': ")


def test_cli_names_ssd_and_component_of_a_bad_connector(tmp_path, test_fmus):
    folder = _system(tmp_path, test_fmus, {"parameters": {"k": 2.0}})
    ssd = _edit_ssd(folder, _bad_kind)
    code, _, err = railcosim("validate", folder)
    assert code == 2 and len(err.strip().splitlines()) == 1, err
    assert str(ssd) in err and "component 'gain'" in err and "kind='input'" in err


def test_shipped_systems_declare_what_libcosim_and_fmpy_need():
    """Every shipped SSD: each connection's ends are declared connectors of the right kind, no
    unconnected input is declared, and the DefaultExperiment carries osp:FixedStepAlgorithm with
    the greatest common divisor of the component steps (libcosim needs both; FMPy the first)."""
    import math
    from pathlib import Path

    from orchestrator.ssp import parse_validated

    for ssd in sorted((Path(__file__).resolve().parent.parent / "ssp").glob("*/SystemStructure.ssd")):
        root = parse_validated(ssd, "SystemStructureDescription.xsd")
        declared = {(c.getparent().getparent().get("name"), c.get("name")): c.get("kind")
                    for c in root.iterfind(".//ssd:Connector", SSD_NS)}
        connected = set()
        for link in root.iterfind(".//ssd:Connection", SSD_NS):
            start = (link.get("startElement"), link.get("startConnector"))
            end = (link.get("endElement"), link.get("endConnector"))
            assert declared.get(start) == "output" and declared.get(end) == "input", (ssd, start, end)
            connected.add(end)
        assert {key for key, kind in declared.items() if kind == "input"} == connected, ssd
        steps = [round(float(h.get("value")) * 1e9) for h in root.iterfind(".//osp:StepSizeHint", SSD_NS)]
        fixed = root.findall("ssd:DefaultExperiment//osp:Algorithm/osp:FixedStepAlgorithm", SSD_NS)
        assert len(fixed) == 1 and round(float(fixed[0].get("baseStepSize")) * 1e9) == math.gcd(*steps), ssd


# ---- archives: bounded, and every error naming <archive>!<member> -------------------------------------
def _private_tmp(tmp_path, monkeypatch):
    import tempfile

    folder = tmp_path / "tmp"
    folder.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(folder))
    return folder


def _one_line(code, stderr, *fragments):
    lines = [line for line in stderr.splitlines() if line.strip()]
    assert code == 2 and len(lines) == 1 and "Traceback" not in stderr, stderr
    for fragment in fragments:
        assert fragment in lines[0], lines[0]
    return lines[0]


def _zip_of_zeros(path, member, size_bytes, declared_bytes=None):
    """A .ssp whose ``member`` unpacks to ``size_bytes`` zeros (deflate: a thousandth of that),
    its headers declaring ``declared_bytes`` instead when given (a crafted archive)."""
    import struct
    import zipfile

    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as archive:
        archive.writestr("SystemStructure.ssd", "<not read/>")
        with archive.open(member, "w", force_zip64=False) as sink:
            for _ in range(size_bytes >> 20):
                sink.write(bytes(1 << 20))
    if declared_bytes is not None:
        data = bytearray(path.read_bytes())
        name = member.encode()
        for signature, offset in ((b"PK\x03\x04", 22), (b"PK\x01\x02", 24)):   # uncompressed size fields
            at = 0
            while (at := data.find(signature, at)) >= 0:
                header_name_at = 30 if signature == b"PK\x03\x04" else 46
                if data[at + header_name_at: at + header_name_at + len(name)] == name:
                    struct.pack_into("<I", data, at + offset, declared_bytes)
                at += 4
        path.write_bytes(bytes(data))
    return path


def test_an_archive_over_the_bound_is_refused_before_anything_is_extracted(tmp_path, monkeypatch):
    """A zip bomb (40 MB of zeros in 40 kB) under a 10 MB bound, and a member declaring 4 GB under
    the default bound: one line naming the archive, its largest member and the variable that
    raises the bound, and nothing written to the temp folder."""
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    bomb = _zip_of_zeros(tmp_path / "bomb.ssp", "resources/zeros.bin", 40 << 20)
    assert bomb.stat().st_size < 200_000
    code, _, stderr = railcosim("run", bomb, "--no-build", "--output", tmp_path / "out",
                                env={"TMPDIR": tmp, "RAILCOSIM_MAX_UNPACKED_MB": "10"})
    _one_line(code, stderr, f"{bomb}: unpacks to 41.9 MB", f"{bomb}!resources/zeros.bin", "10.0 MB allowed",
              "RAILCOSIM_MAX_UNPACKED_MB")
    crafted = _zip_of_zeros(tmp_path / "crafted.ssp", "resources/zeros.bin", 1 << 20, declared_bytes=4_000_000_000)
    code, _, stderr = railcosim("run", crafted, "--no-build", "--output", tmp_path / "out", env={"TMPDIR": tmp})
    _one_line(code, stderr, f"{crafted}: unpacks to 4000.0 MB", "512.0 MB allowed")
    assert os.listdir(tmp) == [] and not (tmp_path / "out").exists()


def test_the_bound_can_be_raised_and_a_bad_bound_is_one_line(tmp_path, test_fmus, monkeypatch):
    from orchestrator.archives import max_unpacked_bytes, safe_extract
    from orchestrator.errors import UserError

    archive = _zip_of_zeros(tmp_path / "three.ssp", "resources/zeros.bin", 3 << 20)
    monkeypatch.setenv("RAILCOSIM_MAX_UNPACKED_MB", "2")
    with pytest.raises(UserError, match="more than the 2.0 MB allowed"):
        safe_extract(archive, tmp_path / "a")
    monkeypatch.setenv("RAILCOSIM_MAX_UNPACKED_MB", "4")
    safe_extract(archive, tmp_path / "b")
    assert (tmp_path / "b" / "resources" / "zeros.bin").stat().st_size == 3 << 20
    for bad in ("nan", "-1", "0", "lots"):
        monkeypatch.setenv("RAILCOSIM_MAX_UNPACKED_MB", bad)
        with pytest.raises(UserError, match=f"RAILCOSIM_MAX_UNPACKED_MB='{bad}': must be a positive number"):
            max_unpacked_bytes()
    monkeypatch.delenv("RAILCOSIM_MAX_UNPACKED_MB")
    assert max_unpacked_bytes() == 512_000_000
    # an FMU is held to the same bound: its extraction and its modelDescription, read whole
    monkeypatch.setenv("RAILCOSIM_MAX_UNPACKED_MB", "0.001")
    code, _, stderr = railcosim("inspect", test_fmus / "TestCounter.fmu", env={"RAILCOSIM_MAX_UNPACKED_MB": "0.001"})
    _one_line(code, stderr, f"{test_fmus / 'TestCounter.fmu'}!modelDescription.xml", "2292 bytes, more than the 1000 bytes allowed")
    with pytest.raises(UserError, match=r"TestCounter.fmu: unpacks to [0-9.]+ MB .* more than the 1000 bytes allowed"):
        safe_extract(test_fmus / "TestCounter.fmu", tmp_path / "c")


def test_a_member_larger_than_it_declares_stops_at_its_declared_size(tmp_path, monkeypatch):
    """A member whose headers declare 1000 bytes but that holds 8 MB: the extraction stops at
    1000 bytes, one line naming <archive>!<member>, and the extraction folder goes."""
    tmp = _private_tmp(tmp_path, monkeypatch)
    from orchestrator.errors import UserError
    from orchestrator.ssp import open_system

    liar = _zip_of_zeros(tmp_path / "liar.ssp", "resources/zeros.bin", 8 << 20, declared_bytes=1000)
    with pytest.raises(UserError) as refused:
        open_system(liar)
    assert str(refused.value).startswith(f"{liar}!resources/zeros.bin: ")
    assert os.listdir(tmp) == []


def test_extraction_errors_name_the_archive_member(tmp_path, test_fmus):
    """A member the temp folder cannot take (a file-size limit: the same path as a full disk) and
    a member with a 300-character name: named <archive>!<member>, never by a temporary path."""
    import resource
    import zipfile

    tmp = tmp_path / "tmp"
    tmp.mkdir()
    archive = tmp_path / "pair.ssp"
    long_name = "resources/" + "n" * 300 + ".json"
    with zipfile.ZipFile(archive, "w", zipfile.ZIP_STORED) as handle:
        handle.writestr("SystemStructure.ssd", "<not read/>")
        handle.write(test_fmus / "TestCounter.fmu", "resources/TestCounter.fmu")
    code, _, stderr = railcosim("run", archive, "--no-build", "--output", tmp_path / "out", env={"TMPDIR": tmp},
                                preexec_fn=lambda: resource.setrlimit(resource.RLIMIT_FSIZE, (500_000, 500_000)))
    line = _one_line(code, stderr, f"{archive}!resources/TestCounter.fmu: cannot be extracted", "File too large")
    assert "railcosim_ssp_" not in line and os.listdir(tmp) == []
    with zipfile.ZipFile(archive, "w") as handle:
        handle.writestr("SystemStructure.ssd", "<not read/>")
        handle.writestr(long_name, "{}")
    code, _, stderr = railcosim("run", archive, "--no-build", "--output", tmp_path / "out", env={"TMPDIR": tmp})
    line = _one_line(code, stderr, f"{archive}!{long_name}: cannot be extracted", "File name too long")
    assert "railcosim_ssp_" not in line and os.listdir(tmp) == []


def test_no_room_for_an_archive_is_one_line_before_extraction(tmp_path, monkeypatch):
    import shutil as shutil_module
    from collections import namedtuple

    from orchestrator.archives import safe_extract
    from orchestrator.errors import UserError

    archive = _zip_of_zeros(tmp_path / "three.ssp", "resources/zeros.bin", 3 << 20)
    usage = namedtuple("usage", "total used free")
    monkeypatch.setattr(shutil_module, "disk_usage", lambda path: usage(10**9, 10**9 - 1_000_000, 1_000_000))
    with pytest.raises(UserError, match=r"three.ssp: unpacks to 3.1 MB, but .* has 1.0 MB free"):
        safe_extract(archive, tmp_path / "dest")
    assert not (tmp_path / "dest").exists() or os.listdir(tmp_path / "dest") == []


def test_a_name_held_twice_in_an_archive_is_refused(tmp_path):
    import warnings
    import zipfile

    from orchestrator.archives import safe_extract
    from orchestrator.errors import UserError

    archive = tmp_path / "twice.ssp"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")          # zipfile warns of the duplicate name
        with zipfile.ZipFile(archive, "w") as handle:
            handle.writestr("resources/line.json", "{}")
            handle.writestr("resources/line.json", "[]")
    with pytest.raises(UserError, match=r"twice.ssp!resources/line.json: its path is taken by another member"):
        safe_extract(archive, tmp_path / "dest")

"""railML 3 lines in and out (docs/railml.md): every shipped line through railML and back
unchanged, our railML 3.1 and 3.2 fixtures (a double-track stage with a branch) imported to the
same line, the branch chosen by --line-id or the sidecar, an imported line run as a system with a
clean verdict, and every bad input refused in one line naming the railML element."""
import json
import os
from pathlib import Path

import pytest

from helpers import REPO, railcosim
from orchestrator.railml.read import import_railml
from orchestrator.railml.validate import validate_railml
from orchestrator.railml.write import export_railml
from orchestrator.errors import UserError

DATA = REPO / "tests" / "data" / "railml"
FIXTURE_31, FIXTURE_32 = DATA / "double_track_3.1.xml", DATA / "double_track_3.2.xml"
SHIPPED_LINES = [REPO / "fmus" / "data" / "shipped" / "default_line.json",
                 REPO / "fmus" / "data" / "shipped" / "default_line_ac.json",
                 REPO / "fmus" / "data" / "shipped" / "suburban_line.json",
                 *sorted({p.name: p for p in REPO.glob("ssp/*/resources/*line*.json")}.values()),
                 REPO / "docs" / "examples" / "short_line.json"]


@pytest.mark.parametrize("line", SHIPPED_LINES, ids=lambda p: p.name)
@pytest.mark.parametrize("version", ["3.2", "3.1"])
def test_every_shipped_line_goes_through_railml_and_back_unchanged(tmp_path, line, version):
    document = json.loads(line.read_text())
    railml = tmp_path / "line.xml"
    railml.write_bytes(export_railml(document, version))
    back = import_railml(railml)
    assert back.version == version
    # the same line file: every field, numbers of the same JSON type (2600 stays 2600, 1.0 stays 1.0)
    assert json.dumps(back.document, sort_keys=True, ensure_ascii=False) == json.dumps(document, sort_keys=True,
                                                                                      ensure_ascii=False)


def test_our_31_and_32_fixtures_read_as_the_same_double_track_line():
    line_32, line_31 = import_railml(FIXTURE_32), import_railml(FIXTURE_31)
    assert line_31.document == line_32.document
    line = line_32.document
    # the main track, run in its normal direction, not track 2 (reverse) nor the branch
    assert line_32.path_ids == ["ne_t1a", "ne_t1b"] and line["length_m"] == 6000
    assert line["name"] == "North - South"
    assert [(s["name"], s["start_m"], s["end_m"], s["signal"]) for s in line["block_sections"]] == [
        ("1П", 0, 1800, "1"), ("2П", 1800, 3000, "Ч"), ("3П", 3000, 4500, "5"), ("4П", 4500, 6000, "Н")]
    first = line["block_sections"][0]
    assert (first["transmitter"], first["carrier_hz"], first["ballast_ohm_km"]) == ("KPT-7", 50, 1.2)
    # defaults where the file says nothing: transmitters alternating, 1 Ω·km
    assert [s["transmitter"] for s in line["block_sections"]] == ["KPT-7", "KPT-5", "KPT-7", "KPT-5"]
    assert line["insulated_joints"][0] == {"position_m": 0, "impedance_bond": True, "bond_lead_offset_m": 1.5}
    assert [j["position_m"] for j in line["insulated_joints"]] == [0, 1800, 3000, 4500, 6000]
    assert line["stations"] == [{"name": "North", "stop_m": 400, "platform_length_m": 400},
                                {"name": "South", "stop_m": 5600}]
    assert line["gradients"] == [{"start_m": 0, "permille": 0}, {"start_m": 1500, "permille": 5},
                                 {"start_m": 3000, "permille": -3}]
    assert line["curves"] == [{"start_m": 3500, "end_m": 3900, "radius_m": 800}]
    assert line["speed_limits"] == [{"start_m": 0, "passenger_kmh": 120, "freight_kmh": 80},
                                    {"start_m": 2800, "passenger_kmh": 60, "freight_kmh": 60},
                                    {"start_m": 3200, "passenger_kmh": 120, "freight_kmh": 80}]
    assert line["temporary_restrictions"] == [{"name": "track works", "start_m": 4000, "end_m": 4400,
                                               "speed_kmh": 40}]
    assert line["electrification"] == {"system": "DC3000", "nominal_voltage_v": 3000}
    notes = "\n".join(line_32.notes)
    # what was not read is said: the distant signal, the speed board, the reverse-only limit
    assert "1 distant" in notes and "other running direction" in notes and "off the running path" in notes


@pytest.mark.parametrize("fixture", [FIXTURE_31, FIXTURE_32], ids=["3.1", "3.2"])
def test_the_branch_is_chosen_through_the_switch(tmp_path, fixture):
    by_line = import_railml(fixture, line_id="line_depot")
    sidecar = tmp_path / "sidecar.json"
    sidecar.write_text(json.dumps({"via": ["ne_br"]}))
    by_via = import_railml(fixture, sidecar=sidecar)
    for branch in (by_line, by_via):
        assert branch.path_ids == ["ne_t1a", "ne_br"]
        line = branch.document
        assert line["length_m"] == 4500 and [s["name"] for s in line["stations"]] == ["North", "Depot"]
        # the depot track ends at a buffer stop, which closes its TVD section
        assert line["block_sections"][-1]["name"] == "Depot track" and line["block_sections"][-1]["end_m"] == 4500
        assert line["gradients"][-1] == {"start_m": 3000, "permille": 8}
        assert line["speed_limits"][-1]["passenger_kmh"] == 40


def test_the_sidecar_overrides_what_the_file_lacks(tmp_path):
    sidecar = tmp_path / "sidecar.json"
    sidecar.write_text(json.dumps({"defaults": {"ballast_ohm_km": 2.0, "transmitter": "KPT-5"},
                                   "sections": {"tvd_4": {"carrier_hz": 75}}, "max_ballast_ohm_km": 40}))
    line = import_railml(FIXTURE_32, sidecar=sidecar).document
    assert [s["ballast_ohm_km"] for s in line["block_sections"]] == [1.2, 2.0, 2.0, 2.0]
    assert [s["transmitter"] for s in line["block_sections"]] == ["KPT-7", "KPT-5", "KPT-5", "KPT-5"]
    assert line["block_sections"][3]["carrier_hz"] == 75 and line["max_ballast_ohm_km"] == 40


def test_an_imported_line_runs_as_a_system_with_a_clean_verdict(tmp_path, product_fmus):
    code, stdout, stderr = railcosim("new", "stage", "--railml", FIXTURE_32, cwd=tmp_path)
    assert code == 0, stderr
    # one warning block: a header line, then one line per thing ignored or assumed
    assert stderr.count("railcosim: warning:") == 1 and "1 distant" in stderr
    resources = tmp_path / "stage" / "resources"
    assert json.loads((resources / "double_track_3.2.json").read_text()) == import_railml(FIXTURE_32).document
    timetable = json.loads((resources / "double_track_3.2_timetable.json").read_text())
    assert [s["station"] for s in timetable["stops"]] == ["North", "South"]
    code, stdout, stderr = railcosim("run", "stage", "--no-build", "--in-process", "--output", tmp_path / "out",
                                     cwd=tmp_path)
    assert code == 0, stderr
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    (train,) = summary["trains"]
    (south,) = train["stops"]
    assert south["station"] == "South" and south["reached"] and abs(south["stop_error_m"]) < 1.0
    assert train["signals_passed_at_danger"] == 0
    assert "safety: safe (signals passed at danger 0, wrong-side failures 0, unsafe indications 0)" in stdout


def test_export_writes_a_systems_line_that_imports_back(tmp_path):
    code, stdout, stderr = railcosim("export", "railml", "freight_ac", "-o", tmp_path / "ac.xml", cwd=tmp_path)
    assert code == 0, stderr
    original = json.loads((REPO / "ssp" / "freight_ac" / "resources" / "default_line_ac.json").read_text())
    assert import_railml(tmp_path / "ac.xml").document == original
    assert b"https://www.railml.org/schemas/3.2" in (tmp_path / "ac.xml").read_bytes()


TVM_LINE = REPO / "ssp" / "tvm430" / "resources" / "hsl_tvm430_line.json"


def test_the_tvm430_system_exports_its_um71_sections_and_zones_and_imports_back(tmp_path):
    code, stdout, stderr = railcosim("export", "railml", "tvm430", "-o", tmp_path / "hsl.xml", cwd=tmp_path)
    assert code == 0, stderr
    original = json.loads(TVM_LINE.read_text())
    assert import_railml(tmp_path / "hsl.xml").document == original
    # jointless: every inner border a trackCircuit detector marked as the zone, no insulated joint
    text = (tmp_path / "hsl.xml").read_text()
    assert 'type="insulatedRailJoint"' not in text
    assert text.count('rcs:separationZone="true"') == len(original["separation_zones"]) == 27
    assert 'frequency="1700"' in text and 'rcs:transmitter="UM71"' in text


def _without_zones(tmp_path) -> Path:
    """The high-speed line as a file from elsewhere might give it: the sections' carriers, but
    neither our zones nor our transmitter."""
    text = export_railml(json.loads(TVM_LINE.read_text())).decode()
    for attribute in (' rcs:separationZone="true"', ' rcs:separationZoneLengthM="26"', ' rcs:transmitter="UM71"'):
        assert attribute in text
        text = text.replace(attribute, "")
    path = tmp_path / "lgv.xml"
    path.write_text(text)
    return path


def test_a_tvm_file_without_its_separation_zones_is_refused_naming_the_border(tmp_path):
    stderr = _refused(tmp_path, _without_zones(tmp_path))
    assert "trainDetectionElement 'tde_border_2'" in stderr and "1500 m" in stderr
    assert "'tvd_1' and 'tvd_2'" in stderr and "missing the tuned separation zone" in stderr


def test_the_sidecar_gives_the_zones_a_file_lacks(tmp_path):
    original = json.loads(TVM_LINE.read_text())
    sidecar = tmp_path / "zones.json"
    # the border detectors between sections: tde_border_2 … tde_border_28 (1500 … 40500 m)
    sidecar.write_text(json.dumps({"zones": {f"tde_border_{k}": {"length_m": 26} for k in range(2, 29)}}))
    line = import_railml(_without_zones(tmp_path), sidecar=sidecar).document
    assert line["separation_zones"] == original["separation_zones"]
    # a TVM carrier is a UM71 circuit's
    assert [(s["transmitter"], s["carrier_hz"]) for s in line["block_sections"]] == [
        (s["transmitter"], s["carrier_hz"]) for s in original["block_sections"]]


def test_a_separation_zone_between_tvm_and_alsn_sections_is_refused(tmp_path):
    text = export_railml(json.loads(TVM_LINE.read_text())).decode()
    old = '<tvdSection id="tvd_28" residualRouteCancellationDelay="PT0S" partialRouteReleaseDelay="PT0S" ' \
          'technology="trackCircuit" frequency="2300" rcs:transmitter="UM71"'
    assert old in text
    path = tmp_path / "mixed.xml"
    path.write_text(text.replace(old, old.replace('"2300"', '"50"').replace('"UM71"', '"KPT-5"')))
    with pytest.raises(UserError, match=r"trainDetectionElement 'tde_border_28' .*a separation zone at 40500 m, "
                                        r"where no two TVM \(UM71\) sections meet"):
        import_railml(path)


def _variant(tmp_path, source: Path, old: str, new: str) -> Path:
    text = source.read_text()
    assert old in text
    path = tmp_path / source.name
    path.write_text(text.replace(old, new, 1))
    return path


def _refused(tmp_path, railml, *extra):
    code, stdout, stderr = railcosim("new", "bad", "--railml", railml, *extra, cwd=tmp_path)
    assert code == 2, stderr
    assert "Traceback" not in stderr and len(stderr.strip().splitlines()) == 1, stderr
    assert not (tmp_path / "bad").exists()
    return stderr


def test_a_file_that_is_not_railml_3_is_refused(tmp_path):
    railml2 = tmp_path / "old.xml"
    railml2.write_text('<railml xmlns="http://www.railml.org/schemas/2013" version="2.2"><infrastructure/></railml>')
    assert "not railML 3" in _refused(tmp_path, railml2) and "railML 2" in _refused(tmp_path, railml2)
    garbage = tmp_path / "line.json"
    garbage.write_text("{}")
    assert "not railML 3: not an XML document" in _refused(tmp_path, garbage)


def test_a_path_that_does_not_connect_is_refused(tmp_path):
    sidecar = tmp_path / "via.json"
    sidecar.write_text(json.dumps({"via": ["ne_t1b", "ne_br"]}))      # a switch's two branches
    stderr = _refused(tmp_path, FIXTURE_32, "--sidecar", sidecar)
    assert "ne_t1b, ne_br" in stderr and "no path through the topology" in stderr
    dangling = _variant(tmp_path, FIXTURE_32, '<elementB ref="ne_t1b"/>', '<elementB ref="ne_gone"/>')
    stderr = _refused(tmp_path, dangling)
    assert "netRelation 'nr_t1a_t1b'" in stderr and "ne_gone" in stderr


def test_a_block_without_detection_at_its_end_is_refused(tmp_path):
    open_block = _variant(tmp_path, FIXTURE_32, '<hasDemarcatingTraindetector ref="ij_6000"/>', "")
    stderr = _refused(tmp_path, open_block)
    assert "tvdSection 'tvd_4'" in stderr and "no train detection at its end" in stderr


def test_a_length_disagreeing_with_the_positions_is_refused(tmp_path):
    wrong = _variant(tmp_path, FIXTURE_31, '<netElement id="ne_t1b">', '<netElement id="ne_t1b" length="2900">')
    stderr = _refused(tmp_path, wrong)
    assert "netElement 'ne_t1b'" in stderr and "length 2900 m disagrees with its positioning" in stderr
    assert "3000 m" in stderr


def test_bad_options_and_sidecars_are_refused(tmp_path):
    assert "--line-id nowhere" in _refused(tmp_path, FIXTURE_32, "--line-id", "nowhere")
    sidecar = tmp_path / "bad.json"
    sidecar.write_text(json.dumps({"defaults": {"carrier_hz": 60}}))
    assert "--sidecar" in _refused(tmp_path, FIXTURE_32, "--sidecar", sidecar)
    code, _, stderr = railcosim("new", "both", "--railml", FIXTURE_32, "--line", "x.json", cwd=tmp_path)
    assert code == 2 and "one of them" in stderr
    code, _, stderr = railcosim("export", "railml", "free_run", "-o", tmp_path, cwd=tmp_path)
    assert code == 2 and "is a folder" in stderr and "Traceback" not in stderr


@pytest.mark.parametrize("extras, named", [
    # docs/railml.md's sidecar once chose track 2 and gave tvd_1 and ij_0 of track 1: ignored in silence
    ({"via": ["ne_t2"], "sections": {"tvd_1": {"name": "1П"}}, "joints": {"ij_0": {"impedance_bond": False}}},
     "sections.tvd_1: no block section 'tvd_1' on the running path (ne_t2) (and 1 more: joints.ij_0)"),
    ({"joints": {"ij_00": {"impedance_bond": False}}}, "joints.ij_00: no insulated joint 'ij_00' on the running path"),
    ({"zones": {"tde_nowhere": {}}}, "zones.tde_nowhere: no trainDetectionElement 'tde_nowhere' on the running path"),
])
def test_a_sidecar_key_the_import_would_not_use_is_refused_naming_it_and_the_sidecar(tmp_path, extras, named):
    sidecar = tmp_path / "mine.json"
    sidecar.write_text(json.dumps(extras))
    stderr = _refused(tmp_path, FIXTURE_32, "--sidecar", sidecar)
    assert f"--sidecar: {sidecar}: {named}" in stderr, stderr


def test_stock_that_cannot_run_on_the_imported_line_is_named_with_the_railml_file(tmp_path):
    """The line imported is the user's railML file to the user: a message names it, never the
    temporary file the import wrote (the DC stock on an AC line named /tmp/railcosim_railml_…)."""
    sidecar = tmp_path / "ac.json"
    sidecar.write_text(json.dumps({"via": ["ne_t2"], "electrification": {"system": "AC25000", "nominal_voltage_v": 25000}}))
    stock = REPO / "fmus" / "data" / "shipped" / "emu_er2.json"
    for timetable in ([], ["--timetable", REPO / "docs" / "examples" / "short_timetable.json"]):
        stderr = _refused(tmp_path, FIXTURE_32, "--sidecar", sidecar, "--rolling-stock", stock, *timetable)
        assert f"cannot run on {FIXTURE_32} (the line imported from it)" in stderr, stderr
        assert "railcosim_railml_" not in stderr


LONG = "9" * 4001       # int() reads it, float() of it overflows: an OverflowError came out of the import
BAD_ATTRIBUTES = [      # (old text, new text, what the one line says) in the 3.2 fixture
    # an id missing where the import names and links the element, or given twice
    ('<netElement id="ne_t2" length="6000">', '<netElement length="6000">',
     "netElement (line 30): attribute id missing"),
    ('<signalIS id="sig_5"', '<signalIS', "signalIS (line 154): attribute id missing"),
    ('<trainDetectionElement id="ij_1800"', '<trainDetectionElement id=""', "trainDetectionElement (line 237): "
                                                                            "attribute id empty"),
    ('<tvdSection id="tvd_2"', '<tvdSection', "tvdSection (line 271): attribute id missing"),
    ('<netElement id="ne_br" length="1500">', '<netElement id="ne_t1b" length="1500">',     # replaced a track
     "netElement 'ne_t1b' (line 27): id 'ne_t1b' is also the id of the netElement at line 24"),
    ('<signalIS id="sig_5"', '<signalIS id="sig_1"',                                       # dropped a signal
     "signalIS 'sig_1' (line 154): id 'sig_1' is also the id of the signalIS at line 144"),
    ('<speedSection id="ss_works"', '<speedSection id="tvd_1"', "tvdSection 'tvd_1' (line 265): id 'tvd_1' is "
                                                                "also the id of the speedSection at line 205"),
    # a reference naming nothing in the file
    ('<spotLocation id="op_south_t1" netElementRef="ne_t1b"', '<spotLocation id="op_south_t1" netElementRef="ne_x"',
     "spotLocation 'op_south_t1' (line 116): attribute netElementRef='ne_x' names no element of the file"),
    ('<validForSpeedProfile ref="sp_pass"/>', '<validForSpeedProfile ref="sp_x"/>',
     "speedSection 'ss_t1_pass' (line 180): <validForSpeedProfile ref='sp_x'> at line 185 names no element"),
    # numbers: not one, not finite, beyond any railway quantity, outside what the attribute means
    ('<netElement id="ne_t1b" length="3000">', f'<netElement id="ne_t1b" length="{LONG}">',
     "netElement 'ne_t1b' (line 24): attribute length='99999999999999999999'… (4001 characters) is beyond ±1e+12"),
    ('<netElement id="ne_t1b" length="3000">', '<netElement id="ne_t1b" length="1e400">',
     "netElement 'ne_t1b' (line 24): attribute length='1e400' is beyond ±1e+12"),
    ('<netElement id="ne_t1b" length="3000">', '<netElement id="ne_t1b" length="NaN">',
     "netElement 'ne_t1b' (line 24): attribute length='NaN' is not a finite number"),
    ('<netElement id="ne_t1b" length="3000">', '<netElement id="ne_t1b" length="3_000">',
     "netElement 'ne_t1b' (line 24): attribute length='3_000' is not a number"),
    ('<netElement id="ne_t1b" length="3000">', '<netElement id="ne_t1b" length="3e6">',
     "netElement 'ne_t1b' (line 24): length 3e+06 m: longer than the longest line railcosim runs (1000 km)"),
    ('<intrinsicCoordinate id="ne_t1b_1" intrinsicCoord="1"/>', '<intrinsicCoordinate id="ne_t1b_1" '
                                                                'intrinsicCoord="5"/>',
     "intrinsicCoordinate 'ne_t1b_1' (line 25): attribute intrinsicCoord='5': must be from 0 to 1"),
    ('netElementRef="ne_t1b" applicationDirection="both" pos="2600"/>',
     'netElementRef="ne_t1b" applicationDirection="both" pos="5000"/>',
     "spotLocation 'op_south_t1' (line 116): attribute pos=5000 m is off netElement 'ne_t1b', which is 3000 m long"),
    ('netElementRef="ne_t1b" applicationDirection="both" pos="2600"/>',
     f'netElementRef="ne_t1b" applicationDirection="both" pos="-{LONG}"/>',
     "spotLocation 'op_south_t1' (line 116): attribute pos='-9999999999999999999'… (4002 characters) is beyond"),
    ('frequency="50" rcs:transmitter="KPT-7"', f'frequency="{LONG}" rcs:transmitter="KPT-7"',
     "tvdSection 'tvd_1' (line 265): attribute frequency="),
    ('rcs:ballastOhmKm="1.2"', 'rcs:ballastOhmKm="wet"',            # a ValueError came out of the import
     "tvdSection 'tvd_1' (line 265): attribute rcs:ballastOhmKm='wet' is not a number"),
    ('rcs:ballastOhmKm="1.2"', 'rcs:ballastOhmKm="INF"', "attribute rcs:ballastOhmKm='INF' is not a finite number"),
    ('rcs:bondLeadOffsetM="1.5"', 'rcs:bondLeadOffsetM="x"',
     "trainDetectionElement 'ij_0' (line 234): attribute rcs:bondLeadOffsetM='x' is not a number"),
    ('<speedSection id="ss_t1_pass" maxSpeed="120"', '<speedSection id="ss_t1_pass" maxSpeed="fast"',
     "speedSection 'ss_t1_pass' (line 180): attribute maxSpeed='fast' is not a number"),   # was: left out
    ('<speedSection id="ss_t1_pass" maxSpeed="120"', '<speedSection id="ss_t1_pass" maxSpeed="NaN"',
     "speedSection 'ss_t1_pass' (line 180): attribute maxSpeed='NaN' is not a finite number"),
    ('<linePerformance maxSpeed="120"/>', '<linePerformance maxSpeed="1e308"/>',
     "linePerformance (line 96): attribute maxSpeed='1e308' is beyond ±1e+12"),
    ('gradient="5"', 'gradient="-INF"', "gradientCurve 'gc_2' (line 60): attribute gradient='-INF' is not a finite"),
    ('<netRelation id="nr_t1a_t1b" positionOnA="1"', '<netRelation id="nr_t1a_t1b" positionOnA="2"',   # was: no path
     "netRelation 'nr_t1a_t1b' (line 35): attribute positionOnA='2': must be 0 or 1"),
    ('<line id="line_main" lineType="mainLine">', '<line id="line_main" lineType="mainLine" rcs:divergingRoutes="'
                                                  + "[" * 100000 + "]" * 100000 + '">',    # a RecursionError
     "line 'line_main' (line 89): rcs:divergingRoutes nested more than 64 deep"),
    ('<netElement id="ne_t1a" length="3000">', '<netElement id="ne_t1a" length="999000">',
     "the running path ne_t1a → ne_t1b is 1.002e+06 m long: longer than the longest line railcosim runs"),
]


@pytest.mark.parametrize("old, new, message", BAD_ATTRIBUTES, ids=[m[:60] for _, _, m in BAD_ATTRIBUTES])
def test_an_id_a_reference_or_a_number_the_import_cannot_use_is_one_line_naming_the_element(tmp_path, old, new,
                                                                                            message):
    stderr = _refused(tmp_path, _variant(tmp_path, FIXTURE_32, old, new))
    assert message in stderr, stderr


def test_a_schema_folder_whose_xsd_does_not_parse_is_one_line_naming_the_file(tmp_path):
    """An undefined entity in the user's railml3.xsd (an lxml XMLSyntaxError came out), or in a
    file it includes; a schema that loads validates the fixture (our extension schema with it)."""
    head = '<?xml version="1.0"?>\n<xs:schema xmlns:xs="http://www.w3.org/2001/XMLSchema" ' \
           'targetNamespace="https://www.railml.org/schemas/3.2" elementFormDefault="qualified">\n'
    broken, including, lax = tmp_path / "broken", tmp_path / "including", tmp_path / "lax"
    for folder in (broken, including, lax):
        folder.mkdir()
    (broken / "railml3.xsd").write_text(head + "<xs:annotation><xs:documentation>&undefined;</xs:documentation>"
                                               "</xs:annotation>\n</xs:schema>\n")
    (including / "railml3.xsd").write_text(head + '<xs:include schemaLocation="part.xsd"/>\n</xs:schema>\n')
    (including / "part.xsd").write_text((broken / "railml3.xsd").read_text())
    stderr = _refused(tmp_path, FIXTURE_32, "--schema", broken)
    assert f"{broken / 'railml3.xsd'}:3: not an XML document (Entity 'undefined' not defined" in stderr, stderr
    stderr = _refused(tmp_path, FIXTURE_32, "--schema", including)
    assert f"{including / 'part.xsd'}:3: the schema does not load (Entity 'undefined' not defined)" in stderr, stderr
    (lax / "railml3.xsd").write_text(head + '<xs:element name="railML"><xs:complexType><xs:sequence>'
                                            '<xs:any processContents="lax" minOccurs="0" maxOccurs="unbounded"/>'
                                            '</xs:sequence><xs:attribute name="version"/></xs:complexType>'
                                            '</xs:element>\n</xs:schema>\n')
    assert validate_railml(FIXTURE_32, lax) == (True, [])


@pytest.mark.skipif(not os.environ.get("RAILCOSIM_RAILML_SCHEMA_31"),
                    reason="the railML 3.1 XSD is not redistributable: set RAILCOSIM_RAILML_SCHEMA_31 to its folder")
def test_exports_and_the_31_fixture_validate_against_the_railml_31_schema(tmp_path):
    schema = Path(os.environ["RAILCOSIM_RAILML_SCHEMA_31"])
    assert validate_railml(FIXTURE_31, schema) == (True, [])
    for line in SHIPPED_LINES:
        (tmp_path / "line.xml").write_bytes(export_railml(json.loads(line.read_text()), "3.1"))
        assert validate_railml(tmp_path / "line.xml", schema) == (True, []), line
    invalid = _variant(tmp_path, FIXTURE_31, 'type="insulatedRailJoint"', 'type="glue"')
    valid, errors = validate_railml(invalid, schema)
    assert not valid and "glue" in errors[0]

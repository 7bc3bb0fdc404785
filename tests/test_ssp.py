"""SSP loading: parameter bindings (external, inline, prefix), SSM mappings, LinearTransformation,
connector units, named parameter sets and command-line overrides — values checked after a run."""
from lxml import etree

from helpers import ComponentSpec, ConnectionSpec, read_csv, write_ssd
from orchestrator.analysis.verdict import railway_verdicts
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

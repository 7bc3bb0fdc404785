"""Each port is declared once, in its facade (fmus/fmi/ports.py ``Port``); what is stated
elsewhere is derived from it and compared here: the facades' output copies (each output's core
field) and the fail-safe values a DCP master shows (through the modelDescription and the .dcpx)."""
import dataclasses
import importlib
from pathlib import Path

import pytest

from fmus.ato_controller.core import AtoOutputs
from fmus.fmi.ports import Port, fail_safe_values, output_fields
from fmus.loco_receiver.core import ReceiverOutputs
from fmus.rail_line.core import RailOutputs
from fmus.sizes import BuildConfig
from fmus.traction.core import TractionOutputs
from fmus.wayside_coder.core import CoderOutputs
from orchestrator.dcp import dcpx
from orchestrator.dcp.master import dcpx_interface
from orchestrator.errors import UserError
from orchestrator.fmu import read_interface
from orchestrator.packaging.builder import discover_units

REPO = Path(__file__).resolve().parent.parent
#: the record each unit's core gives its outputs in
OUTPUT_RECORDS = {"traction": TractionOutputs, "ato_controller": AtoOutputs, "loco_receiver": ReceiverOutputs,
                  "rail_line": RailOutputs, "wayside_coder": CoderOutputs}


def _facade(spec):
    return getattr(importlib.import_module(spec.facade_module), spec.model_identifier)


@pytest.mark.parametrize("spec", discover_units(), ids=lambda s: s.unit)
def test_every_output_is_copied_from_a_field_of_its_cores_output_record(spec):
    fields = {f.name for f in dataclasses.fields(OUTPUT_RECORDS[spec.unit])}
    copied = output_fields(_facade(spec).declare_ports(BuildConfig()))
    assert copied and [port for port, field in copied if field not in fields] == []


def test_a_fail_safe_value_or_core_field_belongs_to_an_output_and_fits_it():
    with pytest.raises(TypeError, match="only an output"):
        Port("aspect", "input", "Integer", fail_safe=0)
    with pytest.raises(TypeError, match="only an output"):
        Port("x0", "parameter", core_field="x0_m")
    with pytest.raises(TypeError, match="not a value"):
        Port("aspect", "output", "Integer", max=4, fail_safe=5)
    with pytest.raises(TypeError, match="not a value"):
        Port("system", "output", "String", start="", fail_safe="ALSN")


@pytest.mark.parametrize("unit", ["loco_receiver", "ato_controller"])
def test_fail_safe_values_reach_the_dcp_master_from_the_facade(tmp_path, product_fmus, unit):
    """Facade → the FMU's modelDescription → the interface a swapped component's master reads,
    and → the .dcpx `railcosim dcp-slave` writes → the interface of a component declared by it."""
    spec = next(s for s in discover_units() if s.unit == unit)
    declared = fail_safe_values(_facade(spec).declare_ports(BuildConfig()))
    interface = read_interface(product_fmus / f"{spec.model_identifier}.fmu")
    assert declared and interface.fail_safe == declared
    path = tmp_path / f"{spec.model_identifier}.dcpx"
    dcpx.write_dcpx(dcpx.description_from_fmu(interface), path)       # checked against the schema
    assert dcpx_interface(path).fail_safe == declared


def test_a_fail_safe_value_that_is_no_number_is_one_line_naming_the_variable(tmp_path, product_fmus):
    interface = read_interface(product_fmus / "LocoReceiver.fmu")
    path = tmp_path / "rx.dcpx"
    dcpx.write_dcpx(dcpx.description_from_fmu(interface), path)
    path.write_text(path.read_text().replace('<FailSafe value="0"/>', '<FailSafe value="low"/>', 1))
    with pytest.raises(UserError, match="variable 'aspect': fail-safe value 'low' is not a number"):
        dcpx.read_dcpx(path)

"""The registry of cab systems (docs/cab_systems.md): every system declared once and found by
every part that treats systems differently; `railcosim new --system S` for every registered S on
a line of the track circuits it codes, and a one-line refusal on the other kind."""
import ast
import json
from pathlib import Path

import pytest

from fmus.loco_receiver.cores import RECEIVERS
from fmus.signalling import cab_systems
from fmus.wayside_coder.cores import CODERS
from fmus.ato_controller.atp import CAB_SIGNAL_MODES
from helpers import REPO, railcosim

EXAMPLES = REPO / "docs" / "examples"
SHIPPED = REPO / "fmus" / "data" / "shipped"
#: a line of each kind of track circuit, with a timetable of a train on it
LINES = {cab_systems.KPT: (EXAMPLES / "short_line.json", EXAMPLES / "short_timetable.json"),
         cab_systems.UM71: (SHIPPED / "hsl_tvm430_line.json", EXAMPLES / "lgv_timetable.json")}


def test_every_registered_system_has_a_coder_a_receiver_and_an_ato_mode():
    assert set(CODERS) == set(RECEIVERS) == set(cab_systems.NAMES)
    for cab in cab_systems.REGISTRY.values():
        assert cab.ato_mode in CAB_SIGNAL_MODES, cab.name
        assert cab.family in (cab_systems.NUMERIC, cab_systems.TABLE, cab_systems.DIGITAL_FAMILY)
        assert cab.transmitter in LINES
        if cab.codes_file is not None:
            cab.load_codes(cab.codes_file)                    # the bundled table reads
        system = cab.system()
        assert (system is None) == (cab.family == cab_systems.NUMERIC)
        if system is not None:
            assert system.name == cab.name
        assert cab.latency_s({}) > 0
        assert cab.ato_parameters()["cab_signal"] == cab.ato_mode


def test_the_system_port_lists_the_registry():
    for unit in ("wayside_coder", "loco_receiver"):
        system = json.loads((REPO / "fmus" / unit / "contract.json").read_text())["ports"]["system"]
        assert system["description"] == " | ".join(cab_systems.NAMES)


def test_unknown_names_and_spellings():
    with pytest.raises(Exception, match="'TVM999' is not one of ALSN, ALSU"):
        cab_systems.lookup("TVM999")
    assert cab_systems.spelled("als_en") == "ALS-EN" and cab_systems.spelled("tvm300") == "TVM300"
    assert cab_systems.spelled("nonsense") == "nonsense"


def test_system_names_are_literal_only_in_the_signalling_library():
    """Outside fmus/signalling/ the product names a system through the registry, never by a
    string constant of its name (docstrings, data, tests and docs may name it)."""
    found = []
    for folder in ("fmus", "orchestrator", "harness"):
        for path in sorted((REPO / folder).rglob("*.py")):
            if path.is_relative_to(REPO / "fmus" / "signalling"):
                continue
            tree = ast.parse(path.read_text(encoding="utf-8"))
            docstrings = {id(node.body[0].value) for node in ast.walk(tree)
                          if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef))
                          and node.body and isinstance(node.body[0], ast.Expr)
                          and isinstance(node.body[0].value, ast.Constant)}
            found += [f"{path.relative_to(REPO)}:{node.lineno}: {node.value!r}" for node in ast.walk(tree)
                      if isinstance(node, ast.Constant) and node.value in cab_systems.NAMES
                      and id(node) not in docstrings]
    assert not found, "\n".join(found)


@pytest.mark.parametrize("name", cab_systems.NAMES)
def test_new_writes_and_runs_every_system_on_a_line_that_suits_it(tmp_path, product_fmus, name):
    cab = cab_systems.REGISTRY[name]
    line, timetable = LINES[cab.transmitter]
    code, _, stderr = railcosim("new", "mine", "--line", line, "--timetable", timetable, "--system",
                                name.lower().replace("-", "_"), cwd=tmp_path)          # as typed
    assert code == 0, stderr
    code, stdout, stderr = railcosim("run", "mine", "--no-build", "--in-process", "--stop-time", "40",
                                     "--output", tmp_path / "out", cwd=tmp_path)
    assert code == 0, stderr
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    (rx,) = summary["receivers"]
    assert rx["system"] == name and rx["decoded_codes"] > 0, rx
    assert rx["wrong_side_failures"] == 0 and rx["unsafe_indications"] == 0, rx
    assert "safety: safe" in stdout


@pytest.mark.parametrize("name", cab_systems.NAMES)
def test_new_refuses_a_line_of_the_other_track_circuits_in_one_line(tmp_path, name):
    cab = cab_systems.REGISTRY[name]
    other = cab_systems.UM71 if cab.transmitter == cab_systems.KPT else cab_systems.KPT
    line, timetable = LINES[other]
    code, _, stderr = railcosim("new", "mine", "--line", line, "--timetable", timetable, "--system", name,
                                cwd=tmp_path)
    assert code == 2 and "Traceback" not in stderr and len(stderr.strip().splitlines()) == 1, stderr
    assert f"--system {name}" in stderr and Path(line).name in stderr
    assert not (tmp_path / "mine").exists()

"""columns.json, beside every run's results.csv: each column's name in the file's order, its unit,
FMI type and description from the modelDescription, and the labels of an enumeration's values
from where they are stated (the registry of cab systems, the cores), for every shipped system."""
import csv
import json

import pytest

from helpers import REPO
from fmus.ato_controller.core import MODE_NAMES
from fmus.signalling import cab_systems
from fmus.signalling.aspects import ASPECT_NAMES
from fmus.signalling.block_rules import SIGNAL_NAMES
from orchestrator.plan import RunOptions, plan_run
from orchestrator.ports import base_of
from orchestrator.results import columns
from orchestrator.run import run_system
from orchestrator.ssp import open_system
from orchestrator.verdicts.labels import railway_labels

SHIPPED = sorted(p.name for p in (REPO / "ssp").iterdir() if (p / "SystemStructure.ssd").is_file())
#: port → the labels it must carry wherever it is recorded
FIXED = {"aspect": ASPECT_NAMES, "atp_aspect": ASPECT_NAMES, "signal": SIGNAL_NAMES, "mode": MODE_NAMES}


def _labels(names):
    return {str(value): text for value, text in names.items()}


def _check(document, plan):
    entries = document["columns"]
    assert document["file"] == "results.csv"
    assert [e["name"] for e in entries] == ["time"] + [f"{c}.{v}" for c, v in plan.recorded]
    for entry in entries[1:]:
        component, _, variable = entry["name"].partition(".")
        port, node = base_of(variable), plan.graph.nodes[component]
        assert entry["description"], entry           # every output of ours says what it is
        if entry["type"] == "Real":
            assert entry["unit"] == node.interface.variables[variable].unit and entry["unit"], entry
        elif entry["type"] == "Boolean":
            assert entry["unit"] == "" and entry["labels"] == {"0": "false", "1": "true"}, entry
        if port in FIXED:
            assert entry["unit"] == "" and entry["labels"] == _labels(FIXED[port]), entry
        if port in ("code", "code_tx"):
            cab = cab_systems.lookup(node.parameters.get("system") or cab_systems.DEFAULT.name)
            if cab.code_values is None:                      # TVM-430's words: not named
                assert "labels" not in entry and entry["unit"] == "1", entry
            else:
                assert entry["labels"]["0"] == "none" and len(entry["labels"]) > 2, entry


@pytest.mark.parametrize("name", SHIPPED)
def test_columns_name_every_column_a_shipped_system_records(name, product_fmus):
    system = open_system(REPO / "ssp" / name, [product_fmus])
    try:
        plan = plan_run(system, RunOptions(fmu_dirs=[product_fmus], labels=railway_labels))
        _check(columns(plan), plan)
    finally:
        system.close()


@pytest.mark.parametrize("name", ["free_run", "als_en", "tvm300"])
def test_a_run_writes_columns_json_whose_names_are_the_results_header(name, product_fmus, tmp_path):
    """What a run writes: the header of results.csv is columns.json's names, and every value an
    enumerated column took has its label."""
    out = tmp_path / name
    run_system(REPO / "ssp" / name, RunOptions(stop_time=1.0, output_dir=out, fmu_dirs=[product_fmus],
                                               in_process=True, labels=railway_labels))
    document = json.loads((out / "columns.json").read_text(encoding="utf-8"))
    with (out / "results.csv").open() as handle:
        rows = list(csv.reader(handle))
    assert rows[0] == [e["name"] for e in document["columns"]]
    assert len(rows) > 2
    codes = [e for e in document["columns"] if base_of(e["name"].partition(".")[2]) == "code"]
    assert codes and all(e.get("labels") for e in codes)
    for k, entry in enumerate(document["columns"]):
        if "labels" in entry:
            assert {row[k] for row in rows[1:]} <= set(entry["labels"]), entry["name"]


def test_a_later_run_into_the_folder_replaces_columns_json(product_fmus, tmp_path):
    out = tmp_path / "run"
    for record in (["train.v", "rx.aspect"], ["train.x"]):
        run_system(REPO / "ssp" / "free_run", RunOptions(stop_time=0.5, output_dir=out, fmu_dirs=[product_fmus],
                                                         in_process=True, record=record))
        document = json.loads((out / "columns.json").read_text(encoding="utf-8"))
        assert [e["name"] for e in document["columns"]] == ["time", *record]
    # without the railway's labels (RunOptions.labels None) only a Boolean's are given
    assert document["columns"][1] == {"name": "train.x", "unit": "m", "type": "Real",
                                      "description": "head position along the line"}

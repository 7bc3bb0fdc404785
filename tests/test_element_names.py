"""Array-element names (``u_tx[2,7]``) have one reader and one writer, orchestrator/ports.py,
which the recorder, the DCP layer, the graph, the verdicts and the CLI all use."""
import re
from pathlib import Path

import pytest

from orchestrator.ports import base_of, element_name, element_names, split_element

REPO = Path(__file__).resolve().parent.parent


@pytest.mark.parametrize("name, parsed", [
    ("x", ("x", ())), ("e_coil[3]", ("e_coil", (3,))), ("u_tx[2,7]", ("u_tx", (2, 7))),
    ("u_tx[2, 7]", ("u_tx", (2, 7))), ("a.b", ("a.b", ())),
    ("u_tx[]", None), ("u_tx[2,]", None), ("u_tx[a]", None), ("u_tx[1]x", None), ("[1]", None)])
def test_an_element_name_is_split_into_its_port_and_indices(name, parsed):
    assert split_element(name) == parsed


def test_names_are_written_as_they_are_read():
    assert element_names("u_tx", (2, 3)) == ["u_tx[1,1]", "u_tx[1,2]", "u_tx[1,3]",
                                             "u_tx[2,1]", "u_tx[2,2]", "u_tx[2,3]"]
    assert element_names("x", ()) == ["x"] and element_name("x", ()) == "x"
    assert all(element_name(*split_element(name)) == name for name in element_names("e_coil", (2, 4)))
    assert base_of("rolling_stock_file[2]") == "rolling_stock_file" and base_of("u_tx[") == "u_tx["


def test_no_product_module_parses_element_names_itself():
    """A second reader would drift from the first (three regexes and several splits did)."""
    ad_hoc = re.compile(r"""(split|partition)\(\s*["']\[["']|re\.compile\(.*\\\[.*[0-9]""")
    found = [f"{path.relative_to(REPO)}:{number}" for folder in ("orchestrator", "fmus", "harness")
             for path in sorted((REPO / folder).rglob("*.py")) if path != REPO / "orchestrator" / "ports.py"
             for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), start=1)
             if ad_hoc.search(line)]
    assert found == []

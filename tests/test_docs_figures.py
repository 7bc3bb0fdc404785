"""Facts a page states about the product that no command block prints, compared with what the
code derives: where a page lists an FMU's variables or sizes its PDUs, the list and the sizes
are the built FMU's (tests/test_docs_run.py checks what the commands print)."""
from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
HIL = ROOT / "docs" / "hil.md"
PERFORMANCE = ROOT / "docs" / "performance.md"


def _paragraph(page: Path, start: str) -> str:
    text = page.read_text(encoding="utf-8")
    assert start in text, f"{page.name}: no paragraph starting {start!r}"
    return text[text.index(start):].split("\n\n")[0]


@pytest.fixture(scope="module")
def receiver_dcpx(product_fmus):
    """The description `railcosim dcp-slave build/fmus/LocoReceiver.fmu --dcpx-out` writes."""
    from orchestrator.dcp import dcpx
    from orchestrator.fmu import read_interface

    return dcpx.description_from_fmu(read_interface(product_fmus / "LocoReceiver.fmu"))


def _listed(part: str) -> list:
    """(name, count, type) of each "`name[count]` (Type)" in a page's list."""
    return [(name, int(count or 1), kind.lower())
            for name, count, kind in re.findall(r"`(\w+)(?:\[(\d+)\])?`\s+\((\w+)\)", part)]


def test_the_served_receivers_variables_are_the_dcpx_ones(receiver_dcpx):
    """docs/hil.md lists the served receiver's inputs and outputs, each with its DCP type: every
    one of the `.dcpx`, in its order, and nothing else; the parameters it names exist with the
    type given."""
    text = _paragraph(HIL, "The served receiver, for example")
    inputs, rest = text.split("; outputs ", 1)
    outputs, parameters = rest.split("; parameters ", 1)

    def actual(causality):
        return [(v.name, v.count, v.data_type.name) for v in receiver_dcpx.of_causality(causality)]

    assert _listed(inputs) == actual("input")
    assert _listed(outputs) == actual("output")
    named = _listed(parameters)
    assert named and set(named) <= set(actual("parameter")), sorted(set(named) - set(actual("parameter")))


def test_the_dat_pdu_sizes_on_the_pages_are_the_receivers(receiver_dcpx):
    """The sizes docs/hil.md gives for the receiver's DAT PDUs and payloads (all its inputs, all
    its outputs) are those of its variables; every "N-byte DAT" on hil.md and performance.md is
    one of the two."""
    from orchestrator.dcp.pdu import PayloadCodec, Pdu, PduType

    def sizes(causality):
        payload = PayloadCodec([(v.data_type, v.count) for v in receiver_dcpx.of_causality(causality)]).size
        return len(Pdu(PduType.DAT_input_output, pdu_seq_id=0, data_id=0, payload=bytes(payload)).encode()), payload

    (in_pdu, in_payload), (out_pdu, out_payload) = sizes("input"), sizes("output")
    sentence = re.search(r"travels in a (\d+)-byte\s+DAT PDU \(all the receiver's inputs: a (\d+)-byte payload\), its"
                         r"\s+outputs in a (\d+)-byte DAT PDU \(a\s+(\d+)-byte payload\)", HIL.read_text(encoding="utf-8"))
    assert sentence, "docs/hil.md: the sentence giving the receiver's DAT sizes is gone"
    assert [int(g) for g in sentence.groups()] == [in_pdu, in_payload, out_pdu, out_payload]
    for page in (HIL, PERFORMANCE):
        stated = {int(n) for n in re.findall(r"(\d+)-byte DAT", page.read_text(encoding="utf-8"))}
        assert stated and stated <= {in_pdu, out_pdu}, f"{page.name}: {sorted(stated)}, the receiver's {in_pdu}, {out_pdu}"


INTERFACES = ROOT / "docs" / "interfaces.md"


def _table_rows(lines, first: int) -> list:
    rows = []
    for line in lines[first:]:
        if not line.startswith("|"):
            break
        rows.append([cell.strip() for cell in line.strip().strip("|").split("|")])
    return rows


def test_every_receiver_output_is_defined_for_every_system_it_takes():
    """docs/interfaces.md's table of the receiver's outputs per system: a row for each output of
    the port table, a column for each system of fmus/loco_receiver/cores.py (ALSU's `errors` and
    `decoded_codes` were defined nowhere), no cell empty."""
    from fmus.loco_receiver.cores import RECEIVERS

    lines = INTERFACES.read_text(encoding="utf-8").splitlines()
    start = next(k for k, line in enumerate(lines) if line.startswith("<!-- ports of LocoReceiver"))
    ports = _table_rows(lines, next(k for k in range(start, len(lines)) if lines[k].startswith("|")))
    outputs = [row[0] for row in ports[2:] if row[1] == "output"]
    assert outputs
    header = next((k for k, line in enumerate(lines) if line.startswith("| output | ")), None)
    assert header is not None, "docs/interfaces.md: no table of the receiver's outputs per system"
    rows = _table_rows(lines, header)
    columns = [system.strip() for cell in rows[0][1:] for system in cell.split(",")]
    assert sorted(columns) == sorted(RECEIVERS), columns
    named = [row[0].strip("`") for row in rows[2:]]
    assert named == outputs
    empty = [(row[0], rows[0][k]) for row in rows[2:] for k, cell in enumerate(row) if not cell]
    assert not empty and all(len(row) == len(rows[0]) for row in rows[2:]), empty

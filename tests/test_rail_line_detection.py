"""Issue 22, the rail line: trains shunt as trains, relay calibration (normal, shunt and control
modes) per track circuit, initial occupancy, bad input. In process (cores, no FMI)."""
import json
from pathlib import Path

import numpy as np
import pytest

from fmus.data.loader import DEFAULT_LINE, load_line
from fmus.errors import FmuInputError
from fmus.loco_receiver.core import LocoReceiverCore, ReceiverSettings
from fmus.rail_line.core import RailLineCore, RailSettings
from fmus.rail_line.track_circuit import Faults
from fmus.signalling.aspects import GREEN, YELLOW
from fmus.wayside_coder.core import CoderSettings, WaysideCoderCore

FS, N = 4000.0, 40
ROOT = Path(__file__).resolve().parents[1]
SHIPPED_LINES = [DEFAULT_LINE, DEFAULT_LINE.parent / "default_line_ac.json",
                 ROOT / "ssp" / "joints_at_speed" / "resources" / "throat_line.json",
                 DEFAULT_LINE.parent / "suburban_line.json"]
OFF = -1000.0


def _core(line=None, **settings):
    line = line or load_line()
    return RailLineCore(line, len(line.sections), 2, N, RailSettings(**settings))


# ---- finding 1: a train behind another one in the same track circuit -----------------------
def _chain(heads, seconds=20.0):
    """Coder → rail line → one receiver per train, both trains standing; the coder sees section 4
    (index 3) occupied and the sections ahead free, so it sends З into it. Returns per train
    the aspects shown per frame and the mean code current under the first axle (A rms)."""
    line = load_line()
    coder = WaysideCoderCore(line, 8, N, CoderSettings())
    rail = _core(line)
    receivers = [LocoReceiverCore(N, ReceiverSettings()) for _ in heads]
    occupancy = np.zeros(8, dtype=bool)
    occupancy[3] = True
    aspects, axle = [[] for _ in heads], [[] for _ in heads]
    x = np.array(heads, dtype=float)
    for frame in range(int(round(seconds * FS / N))):
        t = frame * N / FS
        sent = coder.step(t, occupancy)
        out = rail.step(t, sent.u_tx, x, np.zeros(2), np.zeros(2))
        for j, receiver in enumerate(receivers):
            aspects[j].append(receiver.step(t, out.e_coil[j]).aspect)
            axle[j].append(out.i_axle[j])
    return np.array(aspects), np.array(axle).mean(axis=1)


def test_rear_train_in_the_same_circuit_gets_no_permissive_code():
    """Train 2 stands at 9000 m in block section 4 (7800–10400 m); train 1 stands 100 m behind
    its tail (head 8500 m). The front train's axles shunt the code fed from the exit end: the
    rear train's coils see < 2 % of the front train's current and its receiver never shows a
    permissive code (Ж or З) in 20 s; alone at 8500 m it shows З (the same code)."""
    aspects, axle = _chain([8500.0, 9000.0])
    assert axle[0] < 0.02 * axle[1]
    assert not np.isin(aspects[0], (GREEN, YELLOW)).any()
    assert aspects[1][-1] == GREEN                       # the front train receives the code
    alone, _ = _chain([8500.0, OFF], seconds=12.0)
    assert alone[0][-1] == GREEN                         # the rear train's receiver works


LIGHT_ENGINE = np.array([0.0, 2.0, 4.0, 8.66, 10.66, 12.66])     # ЧМЭ3: two three-axle bogies


def _steady(core, seconds, heads, section=3):
    """A steady 1 V 50 Hz carrier into one section, the trains standing: i_axle per train (A rms)."""
    for frame in range(int(round(seconds * FS / N))):
        t = frame * N / FS
        u = np.zeros((8, N))
        u[section] = np.sin(2 * np.pi * 50.0 * (t + np.arange(N) / FS))
        out = core.step(t, u, np.array(heads), np.zeros(2), np.zeros(2))
    return out.i_axle.copy()


def test_the_code_left_behind_a_light_engine_is_what_its_wheelsets_leave():
    """A light engine of two bogies (six wheelsets over 12.7 m) at 9000 m, a 388 m train 100 m
    behind it in the same circuit: the rear train's coils get the current the wheelset chain
    leaves past the engine's six axles (docs/rail_line.md, wheelsets at their axles), not the
    far larger one that passed the single shunt the engine made when it was lumped onto one
    node; the relay-end level is the chain's too."""
    passenger = RailSettings().train_length_m[0]
    core = _core(train_length_m=(17.22, passenger),
                 wheelset_offsets_m=(LIGHT_ENGINE, load_stock_wheelsets()))
    heads = [9000.0, 9000.0 - 12.66 - 100.0]
    axle = _steady(core, 0.6, heads) * np.sqrt(2.0)                 # amplitudes per volt of code
    chain, _, relay = core.bank.wheelset_solution(3, heads)
    assert axle == pytest.approx([chain[0], chain[1]], rel=2e-3)
    # the lumped network: the engine one 0.06 Ω shunt at one node
    assert core.bank.geometry.node_at(3, 9000.0 - 17.22) == core.bank.geometry.node_at(3, 9000.0)
    lumped = _lumped_current(core, heads)
    assert chain[1] < 0.5 * lumped                  # what the engine's wheelsets leave: less than half
    assert core.bank.relays.levels[3] == pytest.approx(relay / core.settings.transformer_ratio
                                                        / core.bank.calibration.reference[3])


def load_stock_wheelsets():
    from fmus.data.loader import load_rolling_stock
    return load_rolling_stock(DEFAULT_LINE.parent / "passenger_chs7.json").wheelset_offsets_m


def _lumped_current(core, heads):
    """The rear train's current as the lumped network alone gives it (one shunt per node)."""
    from fmus.rail_line.network import PhasorFamily
    configs, rows = core.bank.configuration(heads)
    shunts, head_nodes = configs[3]
    circuit = core.circuits[3]
    net = circuit.network(None, Faults(), core.settings.transformer_ratio, 50.0)
    family = PhasorFamily(net, 2 * np.pi * 50.0, [1.0])
    nodes = [net.node_index[f"n{n}"] for n in shunts]
    volts = family.with_shunts(nodes, 1.0 / 0.06)
    node = head_nodes[rows[3][1]]
    a, b = net.node_index[f"n{node}"], net.node_index[f"n{node + 1}"]
    return abs((volts[a] - volts[b]) / family.z_branch[node])


def test_every_train_shunts_its_whole_length():
    """A 400 m train with its head 10 m before the feed end of section 4: every node it covers
    holds a shunt; the old single front-most shunt is gone."""
    core = _core()
    bank = core.bank
    circuit = core.circuits[3]
    head = circuit.feed_m - 10.0
    configs, _ = bank.configuration([head, OFF])
    shunts, heads = configs[3]
    assert heads == (circuit.segments,)
    assert shunts == tuple(range(bank.geometry.node_at(3, head - 400.0), circuit.segments + 1))
    assert len(shunts) >= 8


# ---- finding 3: detection margins, calibration ---------------------------------------------
def test_old_example_reads_occupied_at_200_ohm_km():
    """The example: ballast_override 200 Ω·km, a 400 m train standing with its head 10 m
    before the feed end read free; with every wheelset shunting it reads occupied."""
    core = _core()
    override = np.zeros(8)
    override[3] = 200.0
    core.set_faults(-1.0, override, np.zeros(8, dtype=bool))
    head = core.circuits[3].feed_m - 10.0
    for frame in range(int(0.5 * FS / N)):
        out = core.step(frame * N / FS, np.zeros((8, N)), np.array([head, OFF]), np.zeros(2), np.zeros(2))
    assert out.occupied[3]


@pytest.mark.parametrize("path", SHIPPED_LINES, ids=lambda p: p.stem)
def test_standing_train_is_detected_anywhere_at_maximum_ballast_and_supply(path):
    """A standing 400 m train, its head at every node of every circuit of the shipped line (and
    1 m inside either joint): every circuit it touches has its relay below drop-out at the line's
    maximum ballast and +10 % supply."""
    line = load_line(path)
    core = _core(line)
    bank, s = core.bank, core.settings
    for k, circuit in enumerate(core.circuits):
        positions = np.concatenate([circuit.nodes_m, [circuit.start_m + 1.0, circuit.end_m - 1.0]])
        for head in positions:
            configs, _ = bank.configuration([float(head), OFF])
            for section, (shunts, _) in enumerate(configs):
                if shunts:
                    level = bank.relay_level(section, shunts, Faults(bank.calibration.ballast_max_ohm_km),
                                             1.0 + s.supply_tolerance)
                    assert level < s.relay_drop_out, (k, head, section, level)


@pytest.mark.parametrize("path", SHIPPED_LINES, ids=lambda p: p.stem)
def test_calibration_modes_per_shipped_line(path):
    """Normal mode: the free circuit at minimum ballast and −10 % supply picks up. Shunt mode:
    one 0.06 Ω shunt at any node (relay end … feed end) at maximum ballast and +10 % supply is
    below drop-out by the stated margin. Control mode: a broken rail anywhere drops it."""
    line = load_line(path)
    core = _core(line)
    bank, s = core.bank, core.settings
    for k, circuit in enumerate(core.circuits):
        minimum = circuit.params.ballast_ohm_km
        assert minimum == line.sections[k].ballast_ohm_km        # the line file's, per section
        assert bank.relay_level(k, (), Faults(minimum), 1.0 - s.supply_tolerance) >= s.relay_pick_up
        for node in range(circuit.segments + 1):
            level = bank.relay_level(k, (node,), Faults(bank.calibration.ballast_max_ohm_km), 1.0 + s.supply_tolerance)
            assert level * (1.0 + s.shunt_margin) <= s.relay_drop_out, (k, node)
        for ballast in (minimum, bank.calibration.ballast_max_ohm_km):
            for broken in np.linspace(circuit.start_m + 5.0, circuit.feed_m - 5.0, 7):
                level = bank.relay_level(k, (), Faults(ballast, float(broken)), 1.0 + s.supply_tolerance)
                assert level < s.relay_drop_out, (k, ballast, broken)
        calibration = bank.calibration.table[k]
        assert calibration.normal_level == pytest.approx(s.relay_pick_up)
        assert calibration.shunt_margin >= s.shunt_margin


def _line_file(tmp_path, **changes):
    document = json.loads(DEFAULT_LINE.read_text())
    for key, value in changes.items():
        if key == "sections":
            value(document["block_sections"])
        else:
            document[key] = value
    path = tmp_path / "line.json"
    path.write_text(json.dumps(document))
    return path


def test_uncalibratable_circuit_is_refused_naming_it_and_its_limit(tmp_path):
    def lengthen(sections):                              # section 1 3.4 km long, section 2 shorter
        sections[0]["end_m"] = sections[1]["start_m"] = 3400.0
    path = _line_file(tmp_path, sections=lengthen,
                      insulated_joints=[{"position_m": 3400.0, "impedance_bond": True, "bond_lead_offset_m": 1.0}])
    with pytest.raises(FmuInputError) as error:
        _core(load_line(path))
    message = str(error.value)
    assert "\n" not in message
    assert "field block_sections[0]" in message and "cannot be calibrated" in message
    longest = float(message.rsplit("calibrates is ", 1)[1].split(" m")[0])
    assert 2650.0 < longest < 2800.0                     # ≈ 2.7 km at 50 Hz (docs/rail_line.md, relay calibration)


def test_ballast_outside_the_schema_range_is_refused_naming_the_field(tmp_path):
    with pytest.raises(FmuInputError, match=r"field max_ballast_ohm_km: .*"):
        load_line(_line_file(tmp_path, max_ballast_ohm_km=5000.0))

    def wet(sections):
        sections[2]["ballast_ohm_km"] = 0.01
    with pytest.raises(FmuInputError, match=r"field block_sections\[2\]\.ballast_ohm_km"):
        load_line(_line_file(tmp_path, sections=wet))

    def dry(sections):
        sections[2]["ballast_ohm_km"] = 80.0
    with pytest.raises(FmuInputError, match=r"field block_sections\[2\]\.ballast_ohm_km: 80 is above the line's max"):
        load_line(_line_file(tmp_path, sections=dry))


def test_per_section_ballast_and_line_maximum_are_used(tmp_path):
    def drier(sections):
        sections[5]["ballast_ohm_km"] = 2.0
    core = _core(load_line(_line_file(tmp_path, sections=drier, max_ballast_ohm_km=20.0)))
    assert core.circuits[5].params.ballast_ohm_km == 2.0 and core.circuits[4].params.ballast_ohm_km == 1.0
    assert core.bank.calibration.table[5].ballast_max_ohm_km == 20.0


def test_a_circuit_whose_minimum_ballast_is_the_lines_maximum_calibrates_and_detects(tmp_path):
    """A section with one ballast only (its minimum the line's maximum): the two design regimes
    are read at the same ballast (an exception escaped the calibration before)."""
    def one_ballast(sections):
        sections[5]["ballast_ohm_km"] = 20.0
    core = _core(load_line(_line_file(tmp_path, sections=one_ballast, max_ballast_ohm_km=20.0)))
    row = core.bank.calibration.table[5]
    assert row.ballast_min_ohm_km == row.ballast_max_ohm_km == 20.0 and row.shunt_margin > 0.0


# ---- initial state and overlapping trains ----------------------------------------------------
def test_trains_on_the_line_occupy_their_circuits_at_t_0():
    core = _core()
    out = core.start(np.array([9000.0, 5300.0]))       # 8600–9000 m and 4900–5300 m
    assert out.occupied.tolist() == [False, True, True, True, False, False, False, False]
    out = core.step(0.0, np.zeros((8, N)), np.array([9000.0, 5300.0]), np.zeros(2), np.zeros(2))
    assert out.occupied.tolist() == [False, True, True, True, False, False, False, False]
    assert _core().start(np.array([OFF, OFF])).occupied.sum() == 0


def test_overlapping_trains_at_initialisation_are_refused():
    with pytest.raises(FmuInputError, match=r"^input x_head\[2\]: train 2 .* overlaps train 1"):
        _core().start(np.array([9000.0, 8800.0]))
    _core().start(np.array([9000.0, 8600.0]))          # nose to tail: allowed


def test_traction_publishes_its_initial_position_in_initialisation_mode():
    from fmus.traction.facade import Traction

    slave = Traction(instance_name="t", resources=None)
    slave.io["x0"][...] = 1234.0
    slave.io["v0"][...] = 5.0
    slave.enter_initialization_mode()
    assert float(slave.io["x"]) == 1234.0 and float(slave.io["v"]) == 5.0


def test_calibration_table_in_docs_matches_the_model():
    """docs/rail_line.md, relay calibration: the levels per shipped line are the model's."""
    text = (ROOT / "docs" / "rail_line.md").read_text()
    rows = [line.split("|")[1:-1] for line in text.splitlines()
            if line.startswith(("| default_line", "| throat line", "| suburban_line"))]
    assert len(rows) == 10
    cores = {}
    for cells in rows:
        name = cells[0].strip()
        path = SHIPPED_LINES[0 if name == "default_line" else 1 if name.startswith("default_line_ac")
                             else 3 if name.startswith("suburban_line") else 2]
        core = cores.setdefault(path, _core(load_line(path)))
        first = int(cells[1].strip().split("–")[0]) - 1
        calibration = core.bank.calibration.table[first]
        assert float(cells[2]) == pytest.approx(calibration.length_m, abs=1)
        assert float(cells[4]) == pytest.approx(calibration.normal_level, abs=5e-4)
        assert float(cells[5].split("(")[0]) == pytest.approx(calibration.shunt_level, abs=5e-4)
        assert float(cells[7].strip(" %")) == pytest.approx(100 * calibration.shunt_margin, abs=0.05)

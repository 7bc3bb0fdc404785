"""The shipped TVM-300 line, fmus/data/shipped/hsl_tvm300_line.json (docs/rail_line.md#tvm-430-track-circuits):
it loads, its blocks are as documented, its carriers alternate with a separation zone at every
boundary, its limits are TVM-300 steps, and every drop of the cascade is braked within one block
at the ATP's supervision deceleration after the receiver's latency and the brake's lead."""
from __future__ import annotations

import json

import pytest

from fmus.ato_controller.core import ATP_DECEL_SHARE
from fmus.data.loader import DATA, load_line, load_rolling_stock
from fmus.loco_receiver.tvm430 import STATED_LATENCY_S
from fmus.traction.brake_pipeline import brake_lead_s
from fmus.units import MPS_PER_KMH

LINE = DATA / "hsl_tvm300_line.json"
TGV = DATA / "high_speed_tgv.json"
BLOCK_M = 2000.0
BLOCKS = 21
# the cascade behind an occupied block (docs/ato.md#tvm-300), km/h
STEPS_KMH = (300, 270, 220, 160, 80, 0)


def test_it_loads_with_21_blocks_of_2000_m_on_42_km():
    line = load_line(LINE)
    assert line.length_m == BLOCKS * BLOCK_M == 42000.0
    assert len(line.sections) == BLOCKS
    for k, section in enumerate(line.sections):
        assert (section.start_m, section.end_m) == (k * BLOCK_M, (k + 1) * BLOCK_M)
    assert [s.name for s in line.stations] == ["Origine", "Terminus"]


def test_its_um71_carriers_alternate_with_a_separation_zone_at_every_boundary():
    document = json.loads(LINE.read_text(encoding="utf-8"))
    sections = document["block_sections"]
    assert {s["transmitter"] for s in sections} == {"UM71"}
    assert [s["carrier_hz"] for s in sections] == [1700 if k % 2 == 0 else 2300 for k in range(BLOCKS)]
    assert [z["position_m"] for z in document["separation_zones"]] == [k * BLOCK_M for k in range(1, BLOCKS)]
    assert document["electrification"]["system"] == "AC25000"


def test_its_high_speed_limits_are_tvm_300_steps_lower_only_near_the_stations():
    line = load_line(LINE)
    limits_kmh = [round(v / MPS_PER_KMH, 6) for v in line.limits_mps["high_speed"]]
    assert set(limits_kmh) <= set(STEPS_KMH)
    assert limits_kmh == [160, 300, 220, 160]
    starts = list(line.limit_starts)
    origine, terminus = (s.stop_m for s in line.stations)
    assert starts[1] - origine <= BLOCK_M and terminus - starts[2] <= 3 * BLOCK_M   # only near the stations


def test_every_cascade_drop_is_braked_within_one_block_at_the_documented_deceleration():
    """v²-drop / (2·a_atp) after the receiver's latency and the brake's lead at the higher step
    fits the block: 270 → 220 km/h, the largest, needs 945 m²/s² / 0.7 m/s² = 1350 m + 520 m."""
    stock = load_rolling_stock(TGV)
    a_atp = ATP_DECEL_SHARE * stock.service_decel
    reaction_s = STATED_LATENCY_S + brake_lead_s(stock)
    needs = {}
    for high, low in zip(STEPS_KMH, STEPS_KMH[1:]):
        v1, v2 = high * MPS_PER_KMH, low * MPS_PER_KMH
        needs[(high, low)] = (v1 * v1 - v2 * v2) / (2.0 * a_atp) + v1 * reaction_s
    largest = max(needs, key=needs.get)
    assert largest == (270, 220)
    assert ((270 * MPS_PER_KMH) ** 2 - (220 * MPS_PER_KMH) ** 2) / 2.0 == pytest.approx(945.2, abs=0.1)
    assert needs[largest] == pytest.approx(1870.6, abs=1.0)
    assert all(need <= BLOCK_M for need in needs.values())
    # a TVM-430 block (1500 m) would not hold it
    assert needs[largest] > 1500.0

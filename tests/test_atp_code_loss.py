"""The ATP's own rules around a loss of code and after passing a signal (fmus/ato_controller/atp.py,
docs/ato.md, ATP): a loss of code at speed is supervised on a braking curve to the no-code
speed (service brake, no emergency brake), and a steady green at line speed on short blocks is
not capped by what the ATP assumes after each signal."""
import json

import pytest

from fmus.ato_controller.atp import EMERGENCY_INTERVENTION, NO_INTERVENTION, SERVICE_INTERVENTION, Atp
from fmus.ato_controller.supervision import dv_ebi_mps
from fmus.data.loader import DATA, load_line
from fmus.signalling import aspects as sig
from fmus.units import MPS_PER_KMH

DECEL = 0.63             # supervision deceleration, m/s² (ЧС7 + 14 coaches)
SERVICE = 0.9            # the train's full-service deceleration, m/s²
DT = 0.1


def _atp(line=None, mode="ALSN"):
    return Atp(line or load_line(), "passenger", 400.0, mode, DECEL, 4.22)


def _drive(atp, x, v, t, seconds, aspect_at, driver_brakes=False):
    """A train that keeps its speed unless the ATP intervenes (the worst driver), or that
    brakes like the ATO when the permitted speed is below it (``driver_brakes``). Per step:
    (t, x, v, result)."""
    rows = []
    for _ in range(int(seconds / DT)):
        aspect, valid = aspect_at(t)
        r = atp.supervise(t, x, v, aspect, valid, 0.0, 0.0, 0)
        if r.intervention == EMERGENCY_INTERVENTION:
            a = -1.2
        elif r.intervention == SERVICE_INTERVENTION or (driver_brakes and v > r.permitted_mps - 0.3):
            a = -SERVICE
        else:
            a = 0.0
        v = max(v + a * DT, 0.0)
        x += v * DT
        t += DT
        rows.append((t, x, v, r))
    return rows


@pytest.mark.parametrize("driver_brakes", [False, True], ids=["worst-driver", "ato-brakes"])
def test_code_loss_at_80_kmh_is_supervised_on_a_braking_curve_without_emergency_braking(driver_brakes):
    atp = _atp()
    lost_s = 20.0
    shown = lambda t: (sig.GREEN, True) if t < lost_s else (sig.WHITE, False)
    rows = _drive(atp, 3000.0, 80.0 * MPS_PER_KMH, 0.0, 120.0, shown, driver_brakes)
    interventions = [r.intervention for _, _, _, r in rows]
    assert EMERGENCY_INTERVENTION not in interventions and atp.emergency_brakings == 0
    # the no-code ceiling (40 km/h) is reached: by the ATO alone, or by the ATP's service brake
    v_end = rows[-1][2]
    assert v_end <= 40.0 * MPS_PER_KMH + 1e-6
    if not driver_brakes:
        assert SERVICE_INTERVENTION in interventions
    else:
        assert atp.interventions == 0
    # never above the curve by the emergency margin, and the curve starts at the speed of the loss
    for t, x, v, r in rows:
        assert v <= r.permitted_mps + dv_ebi_mps(v)
    first = next(r for t, _, _, r in rows if t > lost_s + DT)
    assert first.permitted_mps >= 80.0 * MPS_PER_KMH and first.ceiling_mps >= 80.0 * MPS_PER_KMH


def test_code_loss_after_red_yellow_keeps_the_stop_at_that_signal():
    atp = _atp()
    # on red-yellow in section 2 (2600-5200 m) at 60 km/h, then the code is lost
    shown = lambda t: (sig.RED_YELLOW, True) if t < 5.0 else (sig.RED, False)
    rows = _drive(atp, 3000.0, 60.0 * MPS_PER_KMH, 0.0, 600.0, shown, driver_brakes=True)
    assert max(x for _, x, _, _ in rows) < 5200.0
    assert rows[-1][2] < 0.5 and atp.signals_passed_at_danger == 0 and atp.emergency_brakings == 0


def _short_block_line(tmp_path, block_m=1000.0, sections=12):
    doc = json.loads((DATA / "default_line.json").read_text())
    template = doc["block_sections"][0]
    doc["length_m"] = block_m * sections
    doc["block_sections"] = [dict(template, name=str(k + 1), start_m=k * block_m, end_m=(k + 1) * block_m,
                                  signal=f"S{k + 1}", transmitter="KPT-5" if k % 2 == 0 else "KPT-7")
                             for k in range(sections)]
    doc["insulated_joints"] = [{"position_m": k * block_m, "impedance_bond": True, "bond_lead_offset_m": 1.0}
                               for k in range(sections + 1)]
    doc["stations"] = [s for s in doc["stations"] if s["stop_m"] < doc["length_m"]]
    doc["speed_limits"] = [{"start_m": 0, "passenger_kmh": 160, "freight_kmh": 90}]
    doc["gradients"] = [g for g in doc["gradients"] if g["start_m"] < doc["length_m"]]
    doc["curves"] = []
    path = tmp_path / "short_blocks.json"
    path.write_text(json.dumps(doc))
    return load_line(path)


def test_steady_green_at_160_kmh_on_1000_m_blocks_is_not_capped_after_the_signals(tmp_path):
    line = _short_block_line(tmp_path)
    atp = _atp(line)
    rows = _drive(atp, 500.0, 160.0 * MPS_PER_KMH, 0.0, 150.0, lambda t: (sig.GREEN, True))
    passed = [x for _, x, _, _ in rows if 1000.0 < x < 9000.0]
    assert len(passed) > 100                                       # several signals passed
    assert atp.interventions == 0
    least = min(r.permitted_mps for _, x, _, r in rows if 1000.0 < x < 9000.0)
    assert least >= 160.0 * MPS_PER_KMH - 1e-9


def test_after_a_green_signal_the_assumed_worst_case_is_a_stop_two_signals_ahead(tmp_path):
    line = _short_block_line(tmp_path)
    atp = _atp(line)
    atp.supervise(0.0, 1900.0, 40.0, sig.GREEN, True, 0.0, 0.0, 0)
    r = atp.supervise(0.5, 2010.0, 40.0, sig.GREEN, True, 0.0, 0.0, 0)    # signal at 2000 m passed
    stops = [tg.position_m for tg in r.constraints.targets if tg.signal and tg.speed_mps == 0.0]
    assert stops == [4000.0]
    # and the train could still stop there from 160 km/h (the red it protects against)
    assert (160.0 * MPS_PER_KMH) ** 2 / (2 * DECEL) < 4000.0 - 2010.0
    later = atp.supervise(8.0, 2300.0, 40.0, sig.GREEN, True, 0.0, 0.0, 0)
    assert not [tg for tg in later.constraints.targets if tg.signal]


def test_after_a_yellow_signal_red_yellow_is_assumed_for_the_receiver_hold(tmp_path):
    line = _short_block_line(tmp_path)
    atp = _atp(line)
    atp.supervise(0.0, 1900.0, 16.0, sig.YELLOW, True, 0.0, 0.0, 0)
    r = atp.supervise(0.5, 2010.0, 16.0, sig.YELLOW, True, 0.0, 0.0, 0)
    assert 3000.0 in [tg.position_m for tg in r.constraints.targets if tg.signal and tg.speed_mps == 0.0]
    # still there after the decoding latency (4.22 s), while the display may still hold the old code
    held = atp.supervise(5.0, 2080.0, 16.0, sig.YELLOW, True, 0.0, 0.0, 0)
    assert 3000.0 in [tg.position_m for tg in held.constraints.targets if tg.signal and tg.speed_mps == 0.0]


def test_no_bridging_of_its_own_the_no_code_display_acts_at_once():
    atp = _atp()
    atp.supervise(0.0, 3000.0, 10.0, sig.GREEN, True, 0.0, 0.0, 0)
    r = atp.supervise(0.5, 3005.0, 10.0, sig.WHITE, False, 0.0, 0.0, 0)
    assert r.aspect == sig.WHITE and r.ceiling_mps == pytest.approx(40.0 * MPS_PER_KMH)
    assert r.intervention == NO_INTERVENTION


def test_passing_the_last_block_signal_of_the_line_under_green_needs_no_brake():
    """Beyond the line's last block signal (sidings, a terminus) there is no next section whose
    code the ATP could assume, so no stop target is put behind the train: a train running on
    at 40 km/h (the no-code speed) past it is not braked."""
    atp = _atp()
    last_signal_m = atp.section_ends[-1]
    shown = lambda t: (sig.GREEN, True) if t < 10.0 else (sig.WHITE, False)
    rows = _drive(atp, last_signal_m - 100.0, 36.0 * MPS_PER_KMH, 0.0, 40.0, shown)
    assert rows[-1][1] > last_signal_m + 200.0
    assert atp.emergency_brakings == 0 and atp.interventions == 0


# ---- the ATO through a loss of a digital code (fmus/ato_controller/core.py, docs/ato.md) ----------

def _digital_loop(lost):
    """free_run's train under a clear digital code (green, line speed, every block free) that
    is lost while ``lost(t)``."""
    from harness.closed_loop import run_closed_loop
    from fmus.ato_controller.core import AtoSettings
    from fmus.signalling.digital_messages import FREE_BLOCKS_OPEN

    clear = 200.0 * MPS_PER_KMH       # the line's own limits bind: the code never does

    def shown(t, x):
        if lost(t):
            return sig.WHITE, False, 0.0, 0.0, 0
        return sig.GREEN, True, clear, clear, FREE_BLOCKS_OPEN
    return run_closed_loop(400.0, step_s=0.1, settings=AtoSettings(cab_signal="digital"), cab_signal=shown)


def test_a_digital_code_lost_for_the_re_acquisition_after_a_joint_only_cuts_traction():
    # 2.7 s, the longest re-acquisition gap the shipped digital systems show, every 40 s at speed
    starts = [180.0 + 40.0 * k for k in range(4)]
    result = _digital_loop(lambda t: any(s <= t < s + 2.7 for s in starts))
    t, v, command = result.column("t"), result.column("v"), result.column("command")
    for s in starts:
        window = (t >= s) & (t < s + 2.7)
        assert v[window].min() > 80.0 * MPS_PER_KMH              # at speed when the code goes
        assert command[window].min() >= 0.0, f"the ATO braked for the loss at {s} s"
        assert command[window].max() == 0.0                       # and drew no traction
    assert result.ato.atp.interventions == 0


def test_a_digital_code_lost_for_good_is_braked_for_by_the_ato_before_the_atp_intervenes():
    result = _digital_loop(lambda t: t >= 200.0)
    t, v, command = result.column("t"), result.column("v"), result.column("command")
    during = (t >= 200.0) & (t < 200.0 + 3.0 - 1e-9)
    assert command[during].min() >= 0.0 and v[t >= 200.0][0] > 80.0 * MPS_PER_KMH
    assert command[(t > 203.0) & (t < 215.0)].min() < 0.0        # braking after the grace
    assert v[t > 320.0].max() <= 40.0 * MPS_PER_KMH               # down to the no-code speed
    assert result.ato.atp.interventions == 0 and result.ato.atp.emergency_brakings == 0

"""The ATP's periodic vigilance check (atp.VigilanceDevice): unanswered → emergency brake after
the period plus the answer window; the ATO answers while it drives."""
import numpy as np
import pytest

from harness.closed_loop import red_signal_ahead, run_closed_loop
from fmus.ato_controller.atp import EMERGENCY_INTERVENTION, Atp
from fmus.ato_controller.core import AtoSettings
from fmus.data.loader import load_line
from fmus.errors import FmuInputError
from fmus.signalling import aspects as sig

PERIOD_S, ANSWER_S = 30.0, 7.0


def _atp():
    atp = Atp(load_line(), "passenger", 388.0, "ALSN", 0.63, 4.22)
    atp.attach_vigilance(PERIOD_S, ANSWER_S)
    return atp


def _run(atp, times, aspect, pressed=lambda t: False, ato=False, x=3000.0, v=10.0):
    """Time of the first emergency intervention, or None."""
    for t in times:
        atp.check_vigilance(t, aspect, True, pressed(t), ato)
        if atp.supervise(t, x, v, aspect, True, 0, 0, 0).intervention == EMERGENCY_INTERVENTION:
            return t
    return None


@pytest.mark.parametrize("aspect", [sig.YELLOW, sig.RED_YELLOW, sig.RED, sig.WHITE])
def test_withheld_acknowledgement_brakes_after_the_period_and_the_answer_window(aspect):
    atp = _atp()
    times = np.arange(0.0, 60.0, 0.5)
    braked = _run(atp, times, aspect, v=3.0 if aspect == sig.RED else 10.0)
    assert braked == pytest.approx(PERIOD_S + ANSWER_S)
    assert atp.vigilance.brakings == 1 and atp.emergency_brakings == 1


def test_no_check_on_green():
    assert _run(_atp(), np.arange(0.0, 300.0, 0.5), sig.GREEN) is None


def test_a_press_answers_the_warning_and_restarts_the_period():
    atp = _atp()
    # pressed 3 s into the warning (rising edge at 33 s), then never again
    braked = _run(atp, np.arange(0.0, 100.0, 0.5), sig.YELLOW, pressed=lambda t: 33.0 <= t < 34.0)
    assert braked == pytest.approx(33.0 + PERIOD_S + ANSWER_S)


def test_a_held_handle_answers_only_once():
    atp = _atp()
    braked = _run(atp, np.arange(0.0, 120.0, 0.5), sig.YELLOW, pressed=lambda t: t >= 33.0)
    assert braked == pytest.approx(33.0 + PERIOD_S + ANSWER_S)


def test_the_ato_answers_while_it_drives():
    assert _run(_atp(), np.arange(0.0, 600.0, 0.5), sig.YELLOW, ato=True) is None


def test_bad_vigilance_parameters_name_the_parameter():
    with pytest.raises(FmuInputError, match="parameter vigilance_answer"):
        Atp(load_line(), "passenger", 388.0, "ALSN", 0.63, 4.22).attach_vigilance(30.0, 0.0)


def test_closed_loop_without_acknowledgement_ends_in_an_emergency_brake_under_yellow():
    """ATO + train under a restrictive aspect: with the ATO answering there is no vigilance
    braking; with the ATO's answers withheld, the emergency brake comes period + window after
    the first checked aspect."""
    cab = red_signal_ahead(load_line(), 15200.0, 900.0)
    answered = run_closed_loop(1300.0, cab_signal=cab)
    assert answered.ato.out.vigilance_brakings == 0 and answered.ato.atp.interventions == 0
    withheld = run_closed_loop(1300.0, cab_signal=cab, settings=AtoSettings(cab_signal="ALSN", ato_acknowledges=False))
    t, aspect, mode = withheld.column("t"), withheld.column("aspect"), withheld.column("mode")
    first_checked = t[np.argmax((aspect != sig.GREEN) & (t > 10.0))]
    first_emergency = t[np.argmax(mode == 5)]
    assert withheld.ato.out.vigilance_brakings >= 1
    assert first_emergency == pytest.approx(first_checked + PERIOD_S + ANSWER_S, abs=1.0)


@pytest.mark.parametrize("press_at_s, brakings", [(None, 1), (33.0, 0)])
def test_the_fmus_acknowledgement_input_answers_the_check(tmp_path, product_fmus, press_at_s, brakings):
    """ato_only with an ALSN cab signal and no receiver: white (no code) from the start, so the
    check runs; the ATO does not answer. Unanswered: the emergency brake at 37 s; a press
    (vigilance_ack false → true at 33 s) answers it and the next warning comes at 63 s."""
    import json

    from helpers import railcosim

    events = [] if press_at_s is None else [{"time": press_at_s, "model": "ato", "variable": "vigilance_ack",
                                             "action": "set", "value": True}]
    scenario = tmp_path / "press.json"
    scenario.write_text(json.dumps({"events": events}))
    out = tmp_path / "run"
    code, _, stderr = railcosim("run", "ato_only", "--output", out, "--no-build", "--stop-time", "65",
                                "--scenario", scenario, "--set", "ato.cab_signal=ALSN",
                                "--set", "ato.ato_acknowledges=false")
    assert code == 0, stderr
    (train,) = json.loads((out / "summary.json").read_text())["trains"]
    assert train["emergency_brakings"] == brakings and train["vigilance_brakings"] == brakings

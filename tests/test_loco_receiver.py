"""The receiver's display hold (the locomotive equipment's inertia, docs/loco_receiver.md) and its
latencies, on the receiver and coder cores: a loss of code shorter than the inertia is bridged
(the indication and code_valid stay), a longer one ends in white (red after red-yellow) at the
inertia, restrictive news is shown at once even during a hold, and every latency is within
its stated bound over cam phases."""
import numpy as np
import pytest

from harness import latency as lat
from harness.display import rank
from fmus.errors import FmuInputError
from fmus.loco_receiver.core import LocoReceiverCore, ReceiverSettings
from fmus.signalling.alsn import EQUIPMENT_INERTIA_S
from fmus.loco_receiver.digital_receiver import DigitalReceiverCore, DigitalReceiverSettings
from fmus.signalling.digital_messages import JOINT_BRIDGE_MIN_S, TIMEOUT_MARGIN_S, TIMEOUT_MESSAGES
from fmus.data.loader import DEFAULT_LINE, load_line
from fmus.signalling import aspects as sig
from fmus.signalling import cab_systems
from fmus.signalling.alsn import STATED_LATENCY_S
from fmus.wayside_coder.core import CoderSettings
from fmus.wayside_coder.digital_generator import DigitalCoderCore

CYCLE_S = {"KPT-5": 1.60, "KPT-7": 1.86}
PHASES = (0.0, 0.3, 0.55, 0.8)


@pytest.mark.parametrize("kpt", ["KPT-5", "KPT-7"])
@pytest.mark.parametrize("code", [sig.GREEN, sig.YELLOW, sig.RED_YELLOW], ids=["Z", "Zh", "KZh"])
def test_a_loss_shorter_than_the_inertia_is_bridged(kpt, code):
    # 1.5 s without any code EMF (the longest sensitivity recovery after a joint in the joints
    # paper) at any cam phase: with the cycle lost before it and the one begun mid-pattern after
    # it, three cycles pass without a valid one, and the decoder's 2 s timeout used to show
    # white (red after red-yellow) meanwhile
    for phase in PHASES:
        no_code_s, held = lat.loss_s(kpt, code, phase, gap_s=1.5)
        assert no_code_s == np.inf and held, (phase, no_code_s)


@pytest.mark.parametrize("carrier_hz", [25.0, 50.0])
@pytest.mark.parametrize("kpt", ["KPT-5", "KPT-7"])
@pytest.mark.parametrize("code", [sig.GREEN, sig.YELLOW, sig.RED_YELLOW], ids=["Z", "Zh", "KZh"])
def test_a_cold_start_anywhere_in_the_cycle_shows_the_code_within_two_cycles_and_half_a_second(carrier_hz, kpt, code):
    # every 10 ms of the cam's cycle: at 25 Hz a start in the last 25 ms of З's second pulse
    # (too short to raise the relay) once read the third pulse as a cycle's start, showed КЖ
    # and З only after two more cycles (4.3 s KPT-5, 5.0 s KPT-7), while the cold-start rule's
    # threshold was 50 Hz's 0.2 s
    bound = 2 * CYCLE_S[kpt] + 0.5
    starts, shown_s, most = lat.cold_starts(kpt, code, carrier_hz, step_s=0.01, seconds=bound + 0.2)
    assert shown_s.max() <= bound, (starts[np.argmax(shown_s)], shown_s.max())
    assert (most <= sig.restrictiveness(code)).all(), starts[most > sig.restrictiveness(code)]


@pytest.mark.parametrize("kpt", ["KPT-5", "KPT-7"])
def test_a_longer_loss_gives_the_no_code_indication_at_the_inertia(kpt):
    for code in (sig.GREEN, sig.RED_YELLOW):
        for phase in PHASES:
            no_code_s, _ = lat.loss_s(kpt, code, phase)
            # counted from the last cycle supporting the code: ended at most one cycle before the cut
            assert EQUIPMENT_INERTIA_S - CYCLE_S[kpt] <= no_code_s <= EQUIPMENT_INERTIA_S + 0.3, (code, phase)


def test_the_inertia_is_a_parameter():
    no_code_s, _ = lat.loss_s("KPT-5", sig.GREEN, 0.0, receiver=ReceiverSettings(inertia_s=3.0))
    assert 3.0 - 1.6 <= no_code_s <= 3.3
    with pytest.raises(FmuInputError, match="inertia"):
        LocoReceiverCore(40, ReceiverSettings(inertia_s=-1.0))


@pytest.mark.parametrize("kpt", ["KPT-5", "KPT-7"])
def test_restrictive_changes_within_the_stated_latency_permissive_within_three_cycles(kpt):
    # a permissive change needs two identical cycles after the one that straddles the change
    for changes, bound in ((lat.RESTRICTIVE, STATED_LATENCY_S), (lat.PERMISSIVE, 3 * CYCLE_S[kpt] + 0.5)):
        for before, after in changes:
            for phase in PHASES:
                took = lat.change_s(kpt, before, after, phase)
                assert took <= bound, (sig.ASPECT_NAMES[before], sig.ASPECT_NAMES[after], phase, took)


# З → Ж met at an insulated joint (a train standing two circuits ahead of the one past it): the
# cam phases past and behind the joint where it takes longest (benchmarks/receiver_change_latency.py:
# 3.62 s, 4.21 s),
# and where it took 4.6 s and 5.2 s while the receiver waited for a second cycle after every joint
JOINT_WORST = {"KPT-7 → KPT-5": ((0.823, 0.5), (0.667, 0.333), (0.167, 0.333)),
               "KPT-5 → KPT-7": ((0.791, 0.5), (0.719, 0.375), (0.25, 0.667))}


@pytest.mark.parametrize("case", sorted(JOINT_WORST))
def test_a_restrictive_change_at_a_joint_within_the_stated_latency_over_noise_seeds(case):
    took = {(phase, old_phase, seed): lat.joint_change_s(case, phase, old_phase, seed)
            for phase, old_phase in JOINT_WORST[case] for seed in range(1, 7)}
    assert max(took.values()) <= STATED_LATENCY_S, took


@pytest.mark.parametrize("case", sorted(lat.JOINT_CASES))
@pytest.mark.parametrize("standing", [None, 2, 1], ids=["Z-Z", "Z-Zh", "Zh-KZh"])
def test_crossing_a_joint_shows_no_white_between_the_old_code_and_the_new(case, standing):
    # 12 cam phases past the joint × 2 behind it: the display goes from the code behind the joint
    # to the code past it, never through the no-code indication, never above the code behind it,
    # and above the code past it no longer than the stated latency. Two of these crossings
    # showed white for 50 ms: two restrictive cycles ended the old code's hold while the second
    # one waited for the level of the pulse after it
    for old_phase in (0.0, 0.5):
        for phase in np.linspace(0.0, 1.0, 12, endpoint=False):
            t_end, shown, sent = lat.joint_crossing(case, phase, old_phase, 1, standing=standing)
            past = t_end > lat.CROSS_S
            behind, ahead = sent[~past][-1], sent[past][0]
            where = (round(phase, 3), old_phase)
            assert shown[~past][-1] == behind, where
            after = shown[past]
            assert not np.isin(after, lat.NO_CODE).any(), (where, t_end[past][np.isin(after, lat.NO_CODE)][:3])
            assert (rank(after) <= sig.restrictiveness(behind)).all(), where
            late = t_end[past] > lat.CROSS_S + STATED_LATENCY_S
            assert (rank(after[late]) <= sig.restrictiveness(ahead)).all(), where


def test_red_yellow_to_yellow_does_not_pass_through_red():
    """The code sent turns from КЖ to Ж mid-block (the train ahead left): the receiver needs two
    Ж cycles, and the decoder's 2 s without a valid cycle used to show red meanwhile."""
    channel = lat._channel("KPT-7", 0.4)
    schedule = lambda t: lat.occupancy(sig.RED_YELLOW if t < lat.SETTLE_S else sig.YELLOW, 1)
    rows = channel.run(lat.SETTLE_S + lat.AFTER_S, schedule)
    late = rows[rows[:, 0] > lat.SETTLE_S - 1.0]
    shown = [int(a) for i, a in enumerate(late[:, 1]) if i == 0 or a != late[i - 1, 1]]
    assert shown == [sig.RED_YELLOW, sig.YELLOW] and late[:, 2].all()


def test_restrictive_news_during_a_hold_is_shown_at_once():
    """З, then the EMF is lost for 2.5 s while the code sent turns КЖ: КЖ is shown on its first
    clean cycle after the loss, never white or red in between."""
    channel = lat._channel("KPT-5", 0.2)
    loss = (lat.SETTLE_S, lat.SETTLE_S + 2.5)
    schedule = lambda t: lat.occupancy(sig.GREEN if t < lat.SETTLE_S else sig.RED_YELLOW, 0)
    cut = lambda t, e: e * ((t < loss[0]) | (t >= loss[1]))
    rows = channel.run(lat.SETTLE_S + lat.AFTER_S, schedule, disturb=cut)
    late = rows[rows[:, 0] > lat.SETTLE_S - 1.0]
    shown = [int(a) for i, a in enumerate(late[:, 1]) if i == 0 or a != late[i - 1, 1]]
    assert shown == [sig.GREEN, sig.RED_YELLOW]
    first = late[late[:, 1] == sig.RED_YELLOW][0, 0]
    assert first - loss[1] <= 2 * 0.8 + 0.5                        # КЖ's half-period cycles


def bridging_hold_s(message_s: float) -> float:
    """A display hold that bridges FIRE_DQPSK's re-acquisition at joints (1.3–2.3 s after the
    acceptance timeout at 100 km/h): the timeout + 3 s, never longer than the ALSN equipment's
    inertia; a user may set it as a digital receiver's ``inertia``."""
    return min(TIMEOUT_MESSAGES * message_s + TIMEOUT_MARGIN_S + JOINT_BRIDGE_MIN_S, EQUIPMENT_INERTIA_S)


def _digital_run(name, gap, seconds=14.0, start_gap=8.0, inertia_s=0.0):
    system = cab_systems.digital_system(name)
    line = load_line(str(DEFAULT_LINE))
    fs, frame = 4000.0, 40
    coder = DigitalCoderCore(system, line, 8, frame, CoderSettings(fs_hz=fs, amplitude_v=1.0, seed=1))
    receiver = DigitalReceiverCore(system, frame, DigitalReceiverSettings(fs_hz=fs, inertia_s=inertia_s))
    occupied = np.zeros(8, dtype=bool)
    rows = []
    for k in range(int(seconds * fs / frame)):
        t = k * frame / fs
        e = 0.2 * coder.step(t, occupied).u_tx[0]
        if start_gap <= t < start_gap + gap:
            e = 0.0 * e
        out = receiver.step(t, e)
        rows.append((t + frame / fs, out.aspect, out.code_valid))
    return np.array(rows), receiver


def test_a_digital_receiver_holds_nothing_by_default():
    """No display hold unless one is set: a 1.5 s loss on FIRE_DQPSK outlasts its acceptance
    timeout (1.03 s), and the display shows no code until the command is back."""
    rows, receiver = _digital_run("FIRE_DQPSK", gap=1.5, seconds=14.0)
    assert receiver.inertia_s == 0.0
    after = rows[(rows[:, 0] > 8.0) & (rows[:, 0] < 11.0)]
    assert (after[:, 1] == sig.WHITE).any() and not after[after[:, 1] == sig.WHITE, 2].any()


@pytest.mark.parametrize("name", ["FIRE_DQPSK", "ALS-EN"])
def test_digital_receivers_hold_through_a_short_loss_and_give_up_after_a_set_hold(name):
    system = cab_systems.digital_system(name)
    hold = bridging_hold_s(system.message_s(system.carrier_hz))
    assert hold <= EQUIPMENT_INERTIA_S
    # a 1.5 s loss (a joint's): FIRE_DQPSK's acceptance times out after 1.03 s, and the
    # display holds until two identical messages bring the command back
    rows, receiver = _digital_run(name, gap=1.5, seconds=22.0, inertia_s=hold)
    shown = rows[rows[:, 0] > 7.0, 1]
    assert receiver.inertia_s == pytest.approx(hold)
    assert (shown == shown[0]).all() and shown[0] != sig.WHITE and rows[rows[:, 0] > 7.0, 2].all()
    rows, _ = _digital_run(name, gap=30.0, seconds=22.0, inertia_s=hold)
    lost = rows[(rows[:, 0] > 8.0) & (rows[:, 1] == sig.WHITE) & (rows[:, 2] == 0)]
    assert lost.size and lost[0, 0] - 8.0 <= hold + 0.1

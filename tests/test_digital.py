"""The digital systems through the whole chain — coder core → (coupling, noise) → receiver
core — and through the FMUs: decoding, latency, never more permissive than sent, 2-out-of-2
and 2-out-of-3 redundancy, parity protection, impulse noise, spectrum, bad input."""
import numpy as np
import pytest
from scipy import signal

from fmus.signalling import cab_systems, aspects as sig
from fmus.data.loader import DEFAULT_LINE, load_line
from fmus.signalling.digital_messages import Acceptor, Message, stated_latency_s
from fmus.errors import FmuInputError
from fmus.loco_receiver import digital_receiver as rxd
from fmus.loco_receiver.digital_receiver import DigitalReceiverCore, DigitalReceiverSettings
from fmus.wayside_coder.core import CoderSettings
from fmus.wayside_coder.digital_generator import DigitalCoderCore
from helpers import read_csv, railcosim
from orchestrator.sspgen import ComponentSpec, ConnectionSpec, write_ssd

FS, N = 4000.0, 40
SYSTEMS = ("ALS-EN", "FIRE_DQPSK")
LINE = load_line(str(DEFAULT_LINE))
COUPLING = 0.2


def _occupied(free_blocks):
    """Occupancy giving section 0 this many free sections ahead (6: the whole line free)."""
    occ = np.zeros(8, dtype=bool)
    if free_blocks < 6:
        occ[free_blocks + 1] = True
    return occ


class Chain:
    def __init__(self, name, frame=N, seed=1, coder=None, receiver=None):
        self.system = cab_systems.digital_system(name)
        self.frame = frame
        self.coder = DigitalCoderCore(self.system, LINE, 8, frame, CoderSettings(fs_hz=FS, amplitude_v=1.0, seed=seed,
                                                                                   **(coder or {})))
        self.receiver = DigitalReceiverCore(self.system, frame, DigitalReceiverSettings(fs_hz=FS, **(receiver or {})))
        self.message_s = self.system.message_s(self.system.carrier_hz)
        self.t = 0.0
        self.step_count = 0

    def run(self, seconds, occupied, section=0, noise=None, faults=(0, 0, 0), coder_inputs=(), extra=None):
        """Rows of (t, code sent, command shown or None, aspect, free_blocks, valid)."""
        rows = []
        for _ in range(int(round(seconds * FS / self.frame))):
            t = self.step_count * self.frame / FS
            out = self.coder.step(t, occupied, *coder_inputs)
            e = COUPLING * out.u_tx[section]
            if extra is not None:
                e = e + extra(t, self.frame)
            if noise is not None:
                e = e + noise(self.frame)
            rx = self.receiver.step(t, e, faults)
            sent = self.coder.current[section].command if self.coder.live[section] else None
            shown = self.receiver.acceptor.command if rx.code_valid else None
            rows.append((t, sent, shown, rx.aspect, rx.free_blocks, rx.code_valid))
            self.step_count += 1
        return rows


def _rank(system, command):
    return (-1,) if command is None else system.rank(command)


@pytest.mark.parametrize("name", SYSTEMS)
@pytest.mark.parametrize("free_blocks", [0, 1, 3, 6])
def test_each_free_block_count_is_decoded_through_the_chain(name, free_blocks):
    chain = Chain(name)
    rows = chain.run(5 * chain.message_s, _occupied(free_blocks))
    command = chain.system.command_for(free_blocks)
    ind = chain.system.indication(command, "passenger")
    first = next(r[0] for r in rows if r[2] is not None)
    assert first <= 4 * chain.message_s + 0.5                   # symbol timing, lock, two messages
    assert all(r[2] == command for r in rows if r[0] >= first)
    last = rows[-1]
    assert last[3] == ind.aspect and last[4] == free_blocks and last[5]
    rx = chain.receiver.out
    assert rx.v_target_mps == pytest.approx(ind.target_kmh / 3.6) and rx.code == ind.code
    assert rx.level_v == pytest.approx(COUPLING, rel=0.15)


@pytest.mark.parametrize("name", SYSTEMS)
@pytest.mark.parametrize("seed", [1, 2, 3])
def test_a_restrictive_change_is_shown_within_the_latency_and_nothing_more_permissive_is(name, seed):
    chain = Chain(name, seed=seed)
    chain.run(5 * chain.message_s, _occupied(6))
    change_s = chain.t = chain.step_count * N / FS
    rows = chain.run(4 * chain.message_s, _occupied(0))
    kzh = chain.system.command_for(0)
    shown_at = next(r[0] for r in rows if r[2] == kzh)
    latency = stated_latency_s(chain.message_s)                  # docs/scenarios.md#results-summaryjson, digital systems
    assert shown_at - change_s <= latency
    # from the moment the modulated message changed: one message and the filters' delay
    sent_at = next(r[0] for r in rows if r[1] == kzh)
    assert shown_at - sent_at <= chain.message_s + 0.2
    for t, *_ in rows:
        shown = next(r[2] for r in rows if r[0] == t)
        if t - change_s > latency:
            assert _rank(chain.system, shown) <= chain.system.rank(kzh)


@pytest.mark.parametrize("name", SYSTEMS)
def test_frame_length_does_not_change_what_is_sent_or_shown(name):
    seconds = 3 * Chain(name).message_s
    long_frames, one_sample = Chain(name, frame=N), Chain(name, frame=1)
    a = long_frames.run(seconds, _occupied(2))
    b = one_sample.run(seconds, _occupied(2))
    shown_long = [r[2] for r in a]
    shown_one = [r[2] for r in b][N - 1::N]
    assert shown_long == shown_one
    one_second = Chain(name, frame=4000)                       # what the noise study uses
    c = one_second.run(round(seconds), _occupied(2))
    assert [r[2] for r in c] == shown_long[99::100][:len(c)]


@pytest.mark.parametrize("name", SYSTEMS)
def test_the_generator_samples_do_not_depend_on_the_frame_length(name):
    settings = CoderSettings(fs_hz=FS, amplitude_v=1.0)
    system = cab_systems.digital_system(name)
    long_frames = DigitalCoderCore(system, LINE, 8, N, settings)
    one_sample = DigitalCoderCore(system, LINE, 8, 1, settings)
    occ = _occupied(1)
    joined = np.concatenate([long_frames.step(k * N / FS, occ).u_tx.copy() for k in range(60)], axis=1)
    single = np.concatenate([one_sample.step(k / FS, occ).u_tx.copy() for k in range(60 * N)], axis=1)
    np.testing.assert_allclose(joined, single, atol=1e-12)


# ---- redundancy ---------------------------------------------------------------------------------
@pytest.mark.parametrize("name", SYSTEMS)
def test_wayside_2oo2_sends_the_more_restrictive_command_and_falls_back_to_the_reserve(name):
    chain = Chain(name)
    system = chain.system
    occ = _occupied(3)
    right = system.command_for(3)
    permissive = max(system.commands(), key=system.rank)
    restrictive = min(system.commands(), key=system.rank)
    chain.run(0.05, occ, coder_inputs=(False, False, permissive, 0))
    assert chain.coder.pending[0].command == right and chain.coder.out.status == 0
    chain.run(0.05, occ, coder_inputs=(False, False, 0, restrictive))
    assert chain.coder.pending[0].command == restrictive
    chain.run(0.05, occ, coder_inputs=(True, False, permissive, 0))     # the faulty main is out
    assert chain.coder.pending[0].command == right and chain.coder.out.status == 1
    rows = chain.run(5 * chain.message_s, occ, coder_inputs=(True, True))
    assert chain.coder.out.status == 2 and chain.coder.out.code_tx[0] == 0
    assert np.abs(chain.coder.out.u_tx).max() < 1e-3                    # the filter has rung down
    lost = next(r[0] for r in rows if not r[5])
    assert lost - rows[0][0] <= stated_latency_s(chain.message_s) + 0.1      # the filter rings down, then the timeout
    assert rows[-1][3] in (sig.WHITE, sig.RED)


@pytest.mark.parametrize("name", SYSTEMS)
def test_receiver_2oo3_outvotes_one_faulty_channel_and_never_follows_a_minority(name):
    chain = Chain(name)
    occ = _occupied(1)
    command = chain.system.command_for(1)
    chain.run(5 * chain.message_s, occ)
    code = chain.system.indication(command, "passenger").code
    for faults, expected in (((rxd.CHANNEL_STUCK_PERMISSIVE, 0, 0), command),
                             ((rxd.CHANNEL_FAILED, 0, 0), command),
                             ((0, rxd.CHANNEL_SILENT, 0), command),
                             ((rxd.CHANNEL_FAILED, rxd.CHANNEL_SILENT, 0), None),
                             ((rxd.CHANNEL_FAILED, rxd.CHANNEL_STUCK_PERMISSIVE, 0), None)):
        rows = chain.run(0.02, occ, faults=faults)
        assert rows[-1][2] == expected, faults
        assert chain.receiver.channel_codes[2] == code
    assert chain.receiver.out.aspect == sig.RED_YELLOW or not chain.receiver.out.code_valid


# ---- protection ---------------------------------------------------------------------------------
@pytest.mark.parametrize("name", SYSTEMS)
def test_the_adjacent_tracks_code_never_gives_a_command(name):
    chain = Chain(name, coder={"track_parity": 0}, receiver={"track_parity": 1})
    rows = chain.run(10 * chain.message_s, _occupied(6))
    assert not any(r[5] for r in rows) and chain.receiver.acceptor.foreign >= 3


def test_a_leaking_code_of_the_other_block_parity_cannot_show_more_than_the_own():
    system = cab_systems.digital_system("FIRE_DQPSK")
    acceptor = Acceptor(system, 1, 0.5)
    own, leak = Message(system.command_for(0), 1, 0), Message(system.command_for(6), 1, 1)
    acceptor.push(0.0, own)
    acceptor.push(0.5, own)
    t = 0.5
    for message in [leak, leak, own] * 6:                         # the leak interleaved with the own code
        t += 0.5
        acceptor.push(t, message)
        assert acceptor.command == own.command
    for message in [leak] * 8:                                    # the own code has stopped: a joint
        t += 0.5
        acceptor.push(t, message)
        acceptor.expire(t)
    assert acceptor.command == leak.command
    # an equal or more restrictive code of the new section is taken at once
    acceptor.push(t + 0.5, Message(system.command_for(1), 1, 0))
    assert acceptor.command == system.command_for(1) and acceptor.block == 0


@pytest.mark.parametrize("name", SYSTEMS)
def test_after_a_loss_of_code_one_message_is_not_enough(name):
    # the code sent may have turned more restrictive while messages were lost: a lone word "no
    # more permissive than the last command" (noise passes the code check now and then) must
    # not be shown at once — the impulse-noise study found exactly that wrong-side
    system = cab_systems.digital_system(name)
    acceptor = Acceptor(system, 1, 0.5)
    open_line, one_free = Message(system.command_for(6), 1, 0), Message(system.command_for(1), 1, 0)
    acceptor.push(0.0, open_line)
    acceptor.push(0.5, open_line)
    assert acceptor.command == open_line.command
    acceptor.expire(0.5 + acceptor.timeout_s + 0.01)             # messages lost: no code
    assert acceptor.command is None
    acceptor.push(2.0, one_free)
    assert acceptor.command is None                               # one word is not enough ...
    acceptor.push(2.5, one_free)
    assert acceptor.command == one_free.command                   # ... two identical ones are
    # while a command is in force, a more restrictive word is taken at once, whatever its quality
    # — but an unclear one (possibly noise) does not restart the timeout: it expires when the
    # command it replaced would have
    acceptor.push(3.0, Message(system.command_for(0), 1, 0), quality=0.05)
    assert acceptor.command == system.command_for(0)
    acceptor.expire(2.5 + acceptor.timeout_s + 0.01)
    assert acceptor.command is None


@pytest.mark.parametrize("name", SYSTEMS)
@pytest.mark.parametrize("level", [0.25, 0.5])
def test_a_superposed_signal_of_the_next_section_never_shows_more_than_the_own_code(name, level):
    leak_coder = DigitalCoderCore(cab_systems.digital_system(name), LINE, 8, N,
                                  CoderSettings(fs_hz=FS, amplitude_v=1.0, seed=9))
    leak_occ = _occupied(6)

    def leak(t, frame):                                        # section 2's green, other block parity
        return level * COUPLING * leak_coder.step(t, leak_occ).u_tx[1]

    chain = Chain(name)
    rows = chain.run(10 * chain.message_s, _occupied(0), extra=leak)
    own = chain.system.command_for(0)
    assert all(_rank(chain.system, r[2]) <= chain.system.rank(own) for r in rows)


@pytest.mark.parametrize("name", SYSTEMS)
def test_impulse_noise_makes_words_fail_but_never_a_wrong_command(name):
    rng = np.random.default_rng(5)
    chain = Chain(name)
    frames = int(20.0 * FS / N)
    spikes = {int(k) for k in rng.choice(frames, int(frames * N / FS), replace=False)}     # one a second
    counter = iter(range(10 ** 9))

    def impulses(frame):
        # traction switching transients: damped oscillations of 5–40 V, ringing 100–400 Hz,
        # 2–10 ms decay, starting within one frame (their tails beyond it are dropped)
        e = np.zeros(frame)
        if next(counter) in spikes:
            t = np.arange(frame) / FS
            e += rng.choice([-1, 1]) * rng.uniform(5.0, 40.0) * np.exp(-t / rng.uniform(0.002, 0.01)) \
                * np.sin(2 * np.pi * rng.uniform(100, 400) * t + rng.uniform(0, 2 * np.pi))
        return e

    rows = chain.run(20.0, _occupied(1), noise=impulses)
    right = chain.system.command_for(1)
    assert {r[2] for r in rows} <= {None, right}
    assert chain.receiver.acceptor.rejected > 0                 # the impulses did hit words
    assert sum(r[2] == right for r in rows) > 0.25 * len(rows)  # and the code still got through


def test_fire_generator_spectrum_stays_in_its_band():
    coder = DigitalCoderCore(cab_systems.digital_system("FIRE_DQPSK"), LINE, 8, N, CoderSettings(fs_hz=FS))
    u = np.concatenate([coder.step(k * N / FS, _occupied(3)).u_tx[0].copy() for k in range(2000)])
    f, p = signal.welch(u[4000:], FS, nperseg=4000)
    in_band = p[(f >= 160) & (f <= 190)].sum() / p.sum()
    carrier = p[np.argmin(np.abs(f - 175))]
    assert in_band > 0.85
    assert p[np.argmin(np.abs(f - 525))] < carrier * 1e-4            # 3rd harmonic of the square wave, > 40 dB down
    assert max(p[np.argmin(np.abs(f - 50))], p[np.argmin(np.abs(f - 25))]) < carrier * 1e-4


def test_receiver_anti_alias_filter_is_the_thesis_6th_order_chebyshev_at_500_hz():
    rx = DigitalReceiverCore(cab_systems.digital_system("FIRE_DQPSK"), N, DigitalReceiverSettings())
    lp = rx.anti_alias
    _, h = signal.sosfreqz(lp.sos, worN=[175.0, 500.0, 1500.0], fs=FS)
    gain_db = 20 * np.log10(np.abs(h))
    assert lp.order == 6 and lp.sos.shape == (3, 6)          # three biquads, as the thesis' circuit
    assert -1.05 <= gain_db[0] <= 0.05 and gain_db[1] == pytest.approx(-1.0, abs=0.05)
    assert gain_db[2] < -50


# ---- bad input ----------------------------------------------------------------------------------
@pytest.mark.parametrize("make, message", [
    (lambda: cab_systems.digital_system("TVM"), "parameter system: 'TVM'"),
    (lambda: DigitalReceiverCore(cab_systems.digital_system("FIRE_DQPSK"), N, DigitalReceiverSettings(fs_hz=500.0)),
     "parameter fs: 500 Hz cannot carry"),
    (lambda: DigitalCoderCore(cab_systems.digital_system("ALS-EN"), LINE, 8, N,
                              CoderSettings(fs_hz=FS, carrier_hz=50.0)), "parameter carrier: 50 Hz"),
    (lambda: DigitalCoderCore(cab_systems.digital_system("FIRE_DQPSK"), LINE, 8, N,
                              CoderSettings(fs_hz=FS)).step(0.0, _occupied(1), False, False, 17, 0),
     "input wrong_command_main: command 17"),
    (lambda: DigitalReceiverCore(cab_systems.digital_system("ALS-EN"), N, DigitalReceiverSettings(track_parity=2)),
     "parameter track_parity"),
])
def test_bad_parameters_name_what_is_wrong(make, message):
    with pytest.raises(FmuInputError, match=message.replace("(", r"\(")):
        make()


# ---- through the FMUs ----------------------------------------------------------------------------
@pytest.mark.parametrize("name", SYSTEMS)
def test_coder_and_receiver_fmus_run_the_digital_system_through_the_orchestrator(tmp_path, product_fmus, name):
    components = [
        ComponentSpec("coder", str(product_fmus / "WaysideCoder.fmu"), 0.01, {"system": name}),
        ComponentSpec("rx", str(product_fmus / "LocoReceiver.fmu"), 0.01,
                      {"system": name, "train_category": "freight"}),
    ]
    connections = [ConnectionSpec(f"coder.u_tx[1,{n}]", f"rx.e_coil[{n}]", factor=COUPLING) for n in range(1, N + 1)]
    write_ssd(tmp_path / "sys", "digital_pair", components, connections, stop_time=7.0)
    code, _, stderr = railcosim("run", tmp_path / "sys", "--output", tmp_path / "out", "--no-build",
                                "--record", "rx.aspect", "--record", "rx.code_valid", "--record", "rx.v_target",
                                "--record", "coder.code_tx[1]", "--record", "rx.channel_code[2]")
    assert code == 0, stderr
    header, data = read_csv(tmp_path / "out" / "results.csv")
    last = dict(zip(header, data[-1]))
    system = cab_systems.digital_system(name)
    ind = system.indication(system.command_for(6), "freight")
    assert last["coder.code_tx[1]"] == ind.code and last["rx.channel_code[2]"] == ind.code
    assert last["rx.aspect"] == sig.GREEN and last["rx.code_valid"] == 1
    assert last["rx.v_target"] == pytest.approx(ind.target_kmh / 3.6)


def test_receiver_fmu_names_an_unknown_system(tmp_path, product_fmus):
    components = [ComponentSpec("rx", str(product_fmus / "LocoReceiver.fmu"), 0.01, {"system": "TVM"})]
    write_ssd(tmp_path / "sys", "bad", components, [], stop_time=0.1)
    code, _, stderr = railcosim("run", tmp_path / "sys", "--output", tmp_path / "out", "--no-build")
    assert code == 2 and "parameter system: 'TVM'" in stderr and "Traceback" not in stderr

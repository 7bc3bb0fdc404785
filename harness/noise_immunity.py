"""The noise-immunity study's channel (docs/noise_immunity.md): each cab-signalling system's
wayside generator and receiver core under white noise, impulse noise or (ALSU) DC joint pulses,
counted as message errors, undetected errors, wrong-side failures and availability; and the two
modems' bit error rate. ``condition`` is one run of the shipped studies noise_immunity and
noise_immunity_alsu (``railcosim study``); benchmarks/study_noise_immunity.py runs them all and
writes the docs' figures, and tests/test_study.py checks the study against it."""
from __future__ import annotations

import numpy as np
from scipy.ndimage import maximum_filter1d
from scipy.signal import lfilter


from fmus.signalling import als_en, cab_systems, dqpsk
from fmus.signalling import aspects as sig
from fmus.data.loader import load_line
from fmus.signalling.digital_messages import Message, stated_latency_s
from fmus.loco_receiver.digital_receiver import DigitalReceiverCore, DigitalReceiverSettings
from fmus.wayside_coder.core import CoderSettings
from fmus.wayside_coder.digital_generator import DigitalCoderCore

FS = 4000.0
AMPLITUDE_V = 0.2
# the squelch the study's figures were taken with: 20x below the coil level, as a receiver at a
# normal code level sees it (the receiver is scale-free apart from squelch and limiter)
SQUELCH_V = 0.01
CHUNK = 40000                       # 10 s of signal per receiver step (the core is frame-length invariant)
GRID_S = 0.01
HOLD = 6


# ---- 1. modem bit error rate -------------------------------------------------------------------
def ber(system_name: str, ebn0_db: float, symbols: int, seed: int) -> float:
    rng = np.random.default_rng(seed)
    dibits = rng.integers(0, 4, symbols)
    if system_name == "FIRE_DQPSK":
        carrier, baud = 175.0, 15.0
        increments = dqpsk.INCREMENT_OF_DIBIT[dibits]
    else:
        carrier = als_en.CARRIER_HZ
        baud = carrier / als_en.CYCLES_PER_SYMBOL
        increments = als_en.INCREMENT_OF_DIBIT[dibits]
    x = dqpsk.modulate_increments(increments, FS, carrier, baud, 1.0, 0.3)
    sigma = np.sqrt(FS / (8.0 * baud * 10 ** (ebn0_db / 10)))      # Eb/N0 = A²·fs / (8·σ²·baud)
    z = dqpsk.correlate(x + sigma * rng.standard_normal(x.size), FS, carrier, baud)
    decided = dqpsk.decide(z) if system_name == "FIRE_DQPSK" else als_en.dibits_of(z)
    errors = np.bitwise_xor(decided[:symbols], dibits)
    return float((np.unpackbits(errors.astype(np.uint8)[:, None], axis=1)[:, -2:].sum()) / (2 * symbols))


# ---- 2. the digital chain --------------------------------------------------------------------------
class Transmission:
    """A message sequence through the generator, sample by sample in chunks."""

    def __init__(self, system, messages, seed_phase: float = 0.4):
        self.system = system
        coder = DigitalCoderCore(system, load_line(), 8, 1, CoderSettings(fs_hz=FS, amplitude_v=AMPLITUDE_V))
        self.shaping, self.scale = coder.shaping, coder.scale
        self.state = np.zeros(self.shaping.a.size - 1)
        self.carrier = system.carrier_hz
        self.baud = system.baud(self.carrier)
        cache = {}
        increments = np.concatenate([cache.setdefault(m, system.increments(m)) for m in messages])
        self.phase = np.mod(seed_phase + np.concatenate([[0.0], np.cumsum(increments)]), 2 * np.pi)
        self.samples = int(np.ceil(self.phase.size * FS / self.baud))

    def chunk(self, first: int, count: int) -> np.ndarray:
        n = first + np.arange(count)
        symbol = np.minimum(np.floor(n * self.baud / FS + 1e-9).astype(np.int64), self.phase.size - 1)
        square = np.where(np.cos(2 * np.pi * self.carrier * n / FS + self.phase[symbol]) >= 0, 1.0, -1.0)
        shaped, self.state = lfilter(self.shaping.b, self.shaping.a, square, zi=self.state)
        return self.scale * shaped


def impulses(rate_per_s: float, rng):
    def add(first: int, count: int) -> np.ndarray:
        e = np.zeros(count)
        for start in np.flatnonzero(rng.random(count) < rate_per_s / FS):
            length = min(count - start, 400)
            t = np.arange(length) / FS
            e[start:start + length] += rng.choice([-1, 1]) * rng.uniform(5.0, 40.0) * \
                np.exp(-t / rng.uniform(0.002, 0.01)) * np.sin(2 * np.pi * rng.uniform(100, 400) * t + rng.uniform(0, 6.3))
        return e
    return add


def white(snr_db: float, rng):
    sigma = np.sqrt(AMPLITUDE_V ** 2 / 2 / 10 ** (snr_db / 10))
    return lambda first, count: sigma * rng.standard_normal(count)


def run_digital(name: str, count: int, noise, seed: int, track_parity: int = 1, tone: bool = False) -> dict:
    system = cab_systems.digital_system(name)
    rng = np.random.default_rng(seed)
    free = rng.integers(0, 7, (count + HOLD - 1) // HOLD)
    # track_parity 0: the adjacent track's signal, received by a train on track 1
    messages = [Message(system.command_for(int(n)), track_parity, 0) for n in free for _ in range(HOLD)][:count]
    tx = Transmission(system, messages)
    receiver = DigitalReceiverCore(system, CHUNK, DigitalReceiverSettings(fs_hz=FS, track_parity=1, min_level_v=SQUELCH_V))
    acceptor = receiver.acceptor
    events = []                                              # (time, decoded message or None, command in force)
    original = acceptor.push

    def spy(time_s, message, quality=1.0):
        original(time_s, message, quality)
        events.append((time_s, message, acceptor.command, acceptor.confirmed_s))
    acceptor.push = spy
    length = system.message_symbols
    message_s = length / tx.baud
    carrier = system.carrier_hz
    for first in range(0, tx.samples, CHUNK):
        count_now = min(CHUNK, tx.samples - first)
        if tone:
            e = AMPLITUDE_V * np.cos(2 * np.pi * carrier * (first + np.arange(count_now)) / FS + 0.4)
        else:
            e = tx.chunk(first, count_now)
        if noise is not None:
            e = e + noise(first, count_now)
        if count_now < CHUNK:
            e = np.concatenate([e, np.zeros(CHUNK - count_now)])
        receiver.step(first / FS, e)
    # message outcomes: a decoded message belongs to the one whose last symbol it just integrated
    commands = np.array([m.command for m in messages])
    correct = undetected = detected = 0
    for time_s, message, _, _ in events:
        if message is None:
            detected += 1
            continue
        symbol = int(np.floor(time_s * tx.baud - 0.5))           # the last symbol, filter delays included
        index = (symbol - 1 - system.decode_lag_symbols) // length
        if 0 <= index < count and message.command == commands[index] and message.track == 1:
            correct += 1
        elif message.track == 1:
            undetected += 1
    # what is shown, on a 10 ms grid, against what was sent within the latency before
    # dense ranks: commands that mean the same to the train (КЖ with any speed field) share one
    levels = sorted({system.rank(c) for c in system.commands()})
    ranks = {c: levels.index(system.rank(c)) for c in system.commands()}
    grid = int(tx.samples / FS / GRID_S)
    shown = np.full(grid, -1, dtype=np.int16)
    for k, (time_s, _, command, confirmed_s) in enumerate(events):
        if command is None:
            continue
        until = events[k + 1][0] if k + 1 < len(events) else grid * GRID_S
        until = min(until, confirmed_s + acceptor.timeout_s)
        shown[int(np.ceil(time_s / GRID_S)):int(np.ceil(until / GRID_S))] = ranks[command]
    sent = np.full(grid, -1, dtype=np.int16)
    starts = (1 + np.arange(count) * length) / tx.baud
    for k in range(count):
        sent[int(starts[k] / GRID_S):int((starts[k] + message_s) / GRID_S) + 1] = ranks[commands[k]] \
            if track_parity == 1 else -1
    window = int(np.ceil(stated_latency_s(message_s) / GRID_S))
    recent = maximum_filter1d(sent, size=window + 1, origin=window // 2)   # max over [t − latency, t]
    wrong = shown > recent
    settled = np.arange(grid) * GRID_S > 4 * message_s
    lowest = -maximum_filter1d(-sent, size=window + 1, origin=window // 2)
    available = (shown >= 0) & (shown <= recent) & (shown >= lowest)
    return {"messages": count, "seconds": tx.samples / FS, "correct": correct,
            "mer": 1.0 - correct / count, "undetected": undetected, "detected": detected,
            "wrong_side_events": int(np.sum(wrong[1:] & ~wrong[:-1]) + wrong[0]),
            "wrong_side_s": float(wrong.sum() * GRID_S),
            "availability": float(available[settled].mean()),
            "accepted": acceptor.accepted, "foreign": acceptor.foreign}


# ---- 2b. ALSN --------------------------------------------------------------------------------------
def alsn_chain(cycles: int, noise, seed: int) -> dict:
    """ALSN through coder → receiver in 10 ms frames (the coder keys per frame); a message is a
    code cycle."""
    from harness.channel import CodeChannel
    rng = np.random.default_rng(seed)
    codes = [sig.RED_YELLOW, sig.YELLOW, sig.GREEN]
    ahead = {sig.RED_YELLOW: [1], sig.YELLOW: [2], sig.GREEN: []}
    hold_s = HOLD * 1.6
    seconds = cycles * 1.6
    schedule = [codes[i] for i in rng.integers(0, 3, int(seconds / hold_s) + 2)]

    def occupancy(t):
        occ = np.zeros(8, dtype=bool)
        for a in ahead[schedule[int(t / hold_s)]]:
            occ[a] = True
        return occ

    channel = CodeChannel(0, coupling=AMPLITUDE_V / 4.0)       # the coder's 4 V → 0.2 V at the coil
    cycles_seen = []
    original = channel.receiver._cycle

    def spy(short, length, time_s):
        original(short, length, time_s)
        cycles_seen.append((time_s, channel.receiver.out.code))
    channel.receiver._cycle = spy
    def disturb(t, e):
        return e + noise(int(round(t[0] * FS)), t.size)
    rows = channel.run(seconds, occupancy, disturb if noise is not None else None)
    # a cycle ending at t carries the code sent during the cycle before t
    correct = undetected = detected = 0
    for t, code in cycles_seen:
        # the coder changes code mid-cycle (cam contacts), so a cycle may carry either code
        during = {schedule[int(max(t - 1.7, 0.0) / hold_s)], schedule[int(t / hold_s)]}
        if code == 0:
            detected += 1
        elif code in during:
            correct += 1
        else:
            undetected += 1
    # cycles sent: КЖ is keyed twice per cam period
    per_cycle = {sig.RED_YELLOW: 0.8, sig.YELLOW: 1.6, sig.GREEN: 1.6}
    sent_cycles = int(sum(min(hold_s, seconds - k * hold_s) / per_cycle[c]
                          for k, c in enumerate(schedule) if k * hold_s < seconds))
    latency = 2 * 1.6 + 0.5
    grid_t = rows[:, 0]
    sent_rank = np.array([sig.restrictiveness(c) for c in rows[:, 3].astype(int)])
    shown_rank = np.where(rows[:, 2] > 0, [sig.restrictiveness(int(a)) for a in rows[:, 1]], -1)
    window = int(latency / GRID_S)
    recent = maximum_filter1d(sent_rank, size=window + 1, origin=window // 2)
    wrong = shown_rank > recent
    lowest = -maximum_filter1d(-sent_rank, size=window + 1, origin=window // 2)
    settled = grid_t > 6.0
    return {"messages": sent_cycles, "seconds": seconds, "correct": correct, "mer": 1.0 - correct / sent_cycles,
            "undetected": undetected, "detected": detected,
            "wrong_side_events": int(np.sum(wrong[1:] & ~wrong[:-1]) + wrong[0]),
            "wrong_side_s": float(wrong.sum() * GRID_S),
            "availability": float(np.mean(((shown_rank >= lowest) & (shown_rank <= recent) & (shown_rank >= 0))[settled]))}


# ---- 2c. ALSU --------------------------------------------------------------------------------------
ALSU_TONE_V = 0.35             # each tone at the coil: the weakest place of a 2.6 km section at 1 Ω·km (the bench)
ALSU_FRAME = 400               # 0.1 s: the receiver's frame here (it is frame-length invariant)
JOINT_RATE_PER_S = 0.5         # joint pulse pairs per second: one joint every 2 s, far more than a train meets
_JOINT_PULSES = {}


def joint_pulse(speed_kmh: float) -> np.ndarray:
    """The coil EMF of a train crossing a joint at ``speed_kmh`` under DC traction, the rail
    line's own (harness/joints.py): 1000 A, the coil pair 5 % mismatched — the joints
    paper's 5 V at 80 km/h — the same asymmetry both sides, no code, no ripple."""
    if speed_kmh not in _JOINT_PULSES:
        from harness.joints import cross_joint

        _, _, emf = cross_joint(speed_kmh, coil_mismatch=0.05, asymmetry=0.03, before_m=3.0, after_m=6.0)
        _JOINT_PULSES[speed_kmh] = emf - emf[0]
    return _JOINT_PULSES[speed_kmh]


def joints(speed_kmh: float, rng):
    """DC joint pulse pairs at ``speed_kmh``, Poisson at JOINT_RATE_PER_S."""
    pulse = joint_pulse(speed_kmh)
    pending = np.zeros(0)

    def add(first: int, count: int) -> np.ndarray:
        nonlocal pending
        e = np.zeros(count + pulse.size)
        e[:pending.size] += pending
        for start in np.flatnonzero(rng.random(count) < JOINT_RATE_PER_S / FS):
            e[start:start + pulse.size] += pulse
        pending = e[count:].copy()
        return e[:count]
    return add


def alsu_chain(count: int, noise, seed: int) -> dict:
    """ALSU through its coder core (every tone ALSU_TONE_V at the coil) into its receiver core;
    a message is one minimum duration (0.5 s) of a code, each code held for HOLD messages
    (random codes of those a wayside sends). A message is decoded correctly when the receiver
    hears exactly the code's two tones at its end; undetected: another pair; wrong-side: a code
    shown more permissive than every code sent within the stated latency (2 s) before."""
    from fmus.loco_receiver.alsu import MIN_DURATION_S, AlsuReceiverCore, AlsuReceiverSettings
    from fmus.signalling import alsu
    from fmus.wayside_coder.alsu import AlsuCoderCore

    system = alsu.system()
    rng = np.random.default_rng(seed)
    codes = np.array(system.codes())
    schedule = codes[rng.integers(0, codes.size, (count + HOLD - 1) // HOLD)]
    per_message = int(round(MIN_DURATION_S * FS))
    frames = per_message // ALSU_FRAME
    coder = AlsuCoderCore(load_line(), 8, ALSU_FRAME, CoderSettings(fs_hz=FS, amplitude_v=ALSU_TONE_V, block_aspects=4))
    receiver = AlsuReceiverCore(ALSU_FRAME, AlsuReceiverSettings(fs_hz=FS))
    levels = sorted({system.rank(int(c)) for c in codes})
    rank = {int(c): levels.index(system.rank(int(c))) for c in codes}
    occupied = np.zeros(8, dtype=bool)
    grid_sent, grid_shown = np.empty(count * frames, dtype=np.int16), np.empty(count * frames, dtype=np.int16)
    correct = undetected = detected = 0
    row = 0
    for m in range(count):
        code = int(schedule[m // HOLD])
        if m % HOLD == 0:
            coder.send(np.tile(coder.tones_of(code), (coder.count, 1)), np.full(coder.count, code))
        for f in range(frames):
            first = m * per_message + f * ALSU_FRAME
            e = coder.step(first / FS, occupied).u_tx[0]
            if noise is not None:
                e = e + noise(first, ALSU_FRAME)
            out = receiver.step(first / FS, e)
            grid_sent[row] = rank[code]
            grid_shown[row] = rank[out.code] if out.code_valid else -1
            row += 1
        heard = receiver.pair_code
        if heard == code:
            correct += 1
        elif heard:
            undetected += 1
        else:
            detected += 1
    step_s = ALSU_FRAME / FS
    window = int(round(alsu.STATED_LATENCY_S / step_s))
    recent = maximum_filter1d(grid_sent, size=window + 1, origin=window // 2)
    lowest = -maximum_filter1d(-grid_sent, size=window + 1, origin=window // 2)
    wrong = grid_shown > recent
    settled = np.arange(row) * step_s > 4 * MIN_DURATION_S * HOLD
    available = (grid_shown >= 0) & (grid_shown <= recent) & (grid_shown >= lowest)
    return {"messages": count, "seconds": count * MIN_DURATION_S, "correct": correct, "mer": 1.0 - correct / count,
            "undetected": undetected, "detected": detected,
            "wrong_side_events": int(np.sum(wrong[1:] & ~wrong[:-1]) + wrong[0]),
            "wrong_side_s": float(wrong.sum() * step_s), "availability": float(available[settled].mean())}


# ---- one condition: a run of the study -------------------------------------------------------------
SNRS_DB = (0.0, -6.0, -10.0, -13.0, -16.0, -20.0)
IMPULSE_RATES = (0.5, 2.0, 5.0)
JOINT_SPEEDS_KMH = (40.0, 80.0, 160.0)
#: the random-number seeds of each (noise, system): (noise generator, messages); ALSN's message
#: schedule always from seed 5. Replication ``seed`` k adds 1000·k to both (0: the figures below).
SEEDS = {("white", "FIRE_DQPSK"): (100, 7), ("white", "ALS-EN"): (101, 8), ("white", "ALSN"): (99, 5),
         ("impulse", "FIRE_DQPSK"): (200, 17), ("impulse", "ALS-EN"): (201, 18), ("impulse", "ALSN"): (199, 5),
         ("white", "ALSU"): (98, 6), ("impulse", "ALSU"): (198, 16), ("joint", "ALSU"): (298, 26)}


def condition(system: str, noise: str, level: float, seed: int = 0, messages: int = 100000,
              alsn_cycles: int = 2000) -> dict:
    """One system under one noise condition (white: SNR in dB; impulse: impulses per second;
    joint, ALSU only: DC joint pulse pairs at this speed in km/h): a run of the study
    orchestrator/study/studies/noise_immunity.toml or noise_immunity_alsu.toml (``railcosim study``)."""
    if (noise, system) not in SEEDS:
        raise ValueError(f"noise {noise!r} / system {system!r}: choose white or impulse, and ALSN, ALSU, ALS-EN "
                         f"or FIRE_DQPSK; or joint and ALSU")
    noise_seed, message_seed = (s + 1000 * seed for s in SEEDS[(noise, system)])
    noise_of = {"white": white, "impulse": impulses, "joint": joints}[noise]
    if system == "ALSU" and noise == "white":
        # SNR of the code's power, both tones (A² against σ²), over the whole band
        source = white(level - 10 * np.log10(2 * ALSU_TONE_V ** 2 / AMPLITUDE_V ** 2), np.random.default_rng(noise_seed))
    else:
        source = noise_of(level, np.random.default_rng(noise_seed))
    if system == "ALSU":
        return alsu_chain(messages, source, message_seed)
    if system == "ALSN":
        return alsn_chain(alsn_cycles, source, message_seed)
    return run_digital(system, messages, source, message_seed)

"""The noise-immunity study's channel (docs/noise_immunity.md): each cab-signalling system's
wayside generator and receiver core under white noise, impulse noise, (ALSU) DC joint pulses or
(TVM430, TVM300) in-band interference and the neighbour's carrier leaking through a separation
zone, counted as message errors, undetected errors, wrong-side failures and availability; and
the two modems' bit error rate. ``condition`` is one run of the shipped studies noise_immunity,
noise_immunity_alsu, noise_immunity_tvm430 and noise_immunity_tvm300 (``railcosim study``), each
system's runner and seeds one entry of CHANNELS; benchmarks/study_noise_immunity.py runs them
all and writes the docs' figures, and tests/test_study.py checks the study against it."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Dict, Tuple

import numpy as np
from scipy.ndimage import maximum_filter1d
from scipy.signal import lfilter


from fmus.signalling import als_en, cab_systems, dqpsk
from fmus.signalling import aspects as sig
from fmus.data.loader import load_line
from fmus.signalling.digital_messages import Message, stated_latency_s
from fmus.sizes import DEFAULT_SAMPLE_RATE_HZ
from fmus.loco_receiver.digital_receiver import DigitalReceiverCore, DigitalReceiverSettings
from fmus.wayside_coder.core import CoderSettings
from fmus.wayside_coder.digital_generator import DigitalCoderCore

FS = DEFAULT_SAMPLE_RATE_HZ
AMPLITUDE_V = 0.2
# the squelch the study's figures were taken with: 20x below the coil level, as a receiver at a
# normal code level sees it (the receiver is scale-free apart from squelch and limiter)
SQUELCH_V = 0.01
CHUNK = int(10 * FS)                # 10 s of signal per receiver step (the core is frame-length invariant)
GRID_S = 0.01
HOLD = 6


# ---- 1. modem bit error rate -------------------------------------------------------------------
def ber(system_name: str, ebn0_db: float, symbols: int, seed: int) -> float:
    rng = np.random.default_rng(seed)
    dibits = rng.integers(0, 4, symbols)
    if system_name == cab_systems.FIRE_DQPSK.name:
        carrier, baud = 175.0, 15.0
        increments = dqpsk.INCREMENT_OF_DIBIT[dibits]
    else:
        carrier = als_en.CARRIER_HZ
        baud = carrier / als_en.CYCLES_PER_SYMBOL
        increments = als_en.INCREMENT_OF_DIBIT[dibits]
    x = dqpsk.modulate_increments(increments, FS, carrier, baud, 1.0, 0.3)
    sigma = np.sqrt(FS / (8.0 * baud * 10 ** (ebn0_db / 10)))      # Eb/N0 = A²·fs / (8·σ²·baud)
    z = dqpsk.correlate(x + sigma * rng.standard_normal(x.size), FS, carrier, baud)
    decided = dqpsk.decide(z) if system_name == cab_systems.FIRE_DQPSK.name else als_en.dibits_of(z)
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


def impulses(rate_per_s: float, rng, fs_hz: float = FS):
    """Damped oscillations (5–40 V, 100–400 Hz, 2–10 ms decay, each cut after 0.1 s) at random
    times, Poisson at ``rate_per_s``, sampled at ``fs_hz``."""
    cut = int(round(0.1 * fs_hz))

    def add(first: int, count: int) -> np.ndarray:
        e = np.zeros(count)
        for start in np.flatnonzero(rng.random(count) < rate_per_s / fs_hz):
            length = min(count - start, cut)
            t = np.arange(length) / fs_hz
            e[start:start + length] += rng.choice([-1, 1]) * rng.uniform(5.0, 40.0) * \
                np.exp(-t / rng.uniform(0.002, 0.01)) * np.sin(2 * np.pi * rng.uniform(100, 400) * t + rng.uniform(0, 6.3))
        return e
    return add


def white(snr_db: float, rng, amplitude_v: float = AMPLITUDE_V):
    """White noise at ``snr_db`` below a carrier of ``amplitude_v`` (peak): A²/2 against σ²."""
    sigma = np.sqrt(amplitude_v ** 2 / 2 / 10 ** (snr_db / 10))
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
    original = channel.receiver.decoder._cycle

    def spy(short, length, time_s):
        original(short, length, time_s)
        cycles_seen.append((time_s, channel.receiver.out.code))
    channel.receiver.decoder._cycle = spy
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


# ---- 2d. TVM-430 -----------------------------------------------------------------------------------
TVM_FS = 12000.0               # the TVM chain's sample rate (docs/rail_line.md#tvm-430-track-circuits)
#: the own carrier at the coil, peak: the weakest the rail line gives a train, 10 m into a circuit
#: at 1 Ω·km (0.025–0.034 V per volt of the coder's 4 V, docs/rail_line.md#tvm-430-track-circuits,
#: "Levels"; the line's own sections at their minimum ballast give 0.135–0.176 V); the
#: receiver's squelch (0.03 V) is a third of it
TVM_CARRIER_V = 0.1
TVM_OWN_HZ, TVM_NEIGHBOUR_HZ = 1700.0, 2300.0      # track 1: the line's first section and the next
#: a message: 13 decisions (1.625 s), the fewest whole decisions (0.125 s) that hold a whole
#: decision window (1.5625 s); the message's last decision reads a window lying wholly in it
#: (60 ms after its start: the baseband low-pass has settled), so the messages' decisions read
#: disjoint stretches of signal and noise. The 12 decisions between overlap it by 92 % and are
#: not counted as messages (counted apart: ``decisions_other_word``)
TVM_HOPS_PER_MESSAGE = 13
#: the in-band interferer: one traction-converter harmonic sweeping the own carrier ± SWEEP_HZ
#: (a triangle, SWEEP_S period: 2 Hz/s, as a harmonic moving with a converter's frequency while
#: the train accelerates), so that every offset from the carrier — the tones' 0.88–17.52 Hz
#: among them — is met
SWEEP_HZ = 50.0
SWEEP_S = 100.0
_TVM_LEAK = {}


def swept_harmonic(ratio_db: float, rng, carrier_hz: float = TVM_OWN_HZ, amplitude_v: float = TVM_CARRIER_V,
                   fs_hz: float = TVM_FS):
    """A sinusoid ``ratio_db`` against the carrier (peak to peak), its frequency a triangle
    between carrier − SWEEP_HZ and carrier + SWEEP_HZ (period SWEEP_S), its phase the
    frequency's closed-form integral (any chunking gives the same samples); a random start
    phase and a random point of the sweep."""
    amplitude = amplitude_v * 10 ** (ratio_db / 20)
    start_phase, sweep_start_s = rng.uniform(0.0, 2 * np.pi), rng.uniform(0.0, SWEEP_S)

    def add(first: int, count: int) -> np.ndarray:
        n = first + np.arange(count, dtype=float)
        u = np.mod(n / fs_hz + sweep_start_s, SWEEP_S) / SWEEP_S
        # ∫ of the triangle 1 − 4|u − ½| (−1 … +1 … −1) from the period's start, per period
        integral = np.where(u <= 0.5, 2 * u * u - u, 3 * u - 2 * u * u - 1.0)
        cycles = np.fmod(carrier_hz * n, fs_hz) / fs_hz + SWEEP_HZ * SWEEP_S * integral
        return amplitude * np.cos(2 * np.pi * cycles + start_phase)
    return add


def tvm_leak_ratio() -> float:
    """The neighbour carrier's coil EMF against the own one where it leaks most through a
    separation zone on the high-speed line: the line's first section (1700 Hz, at its minimum or
    the line's maximum ballast, whichever leaks more), the next (2300 Hz) at the line's maximum,
    the train's head 2.7 m before the zone (fmus/rail_line/separation_leak.py, its worst place;
    docs/rail_line.md#tvm-430-track-circuits)."""
    if "ratio" not in _TVM_LEAK:
        from fmus.rail_line.core import default_wheelsets
        from fmus.rail_line.separation_leak import NEAREST_HEAD_BEFORE_ZONE_M, leak_at
        from harness.tvm_line import HSL_LINE, TRAIN_M

        line = load_line(HSL_LINE)
        own, ahead = line.sections[0], line.sections[1]
        _TVM_LEAK["ratio"] = max(
            leak_at(NEAREST_HEAD_BEFORE_ZONE_M, float(own.carrier_hz), float(ahead.carrier_hz), ballast,
                    line.max_ballast_ohm_km, default_wheelsets(TRAIN_M), length_m=own.end_m - own.start_m,
                    neighbour_length_m=ahead.end_m - ahead.start_m).emf_ratio
            for ballast in (float(own.ballast_ohm_km), line.max_ballast_ohm_km))
    return _TVM_LEAK["ratio"]


def tvm_words(tvm):
    """The words a wayside of the high-speed line sends (every block, every number of free
    blocks ahead), less the most permissive word there is (300/300, no target, the least falling
    gradient), which is the leaking neighbour's: more permissive than every word sent."""
    from fmus.signalling import tvm430
    from harness.tvm_line import HSL_LINE

    table = tvm.table
    most = tvm430.assemble(table.addresses[0], table.speed_code(table.steps_kmh[0], table.steps_kmh[0]),
                           table.distance_codes - 1, len(table.gradient_permille) - 1)
    blocks = tvm430.BlockWords(load_line(HSL_LINE), tvm)
    words = sorted({blocks.word(b, free) for b in range(len(blocks.block_starts)) for free in range(8)} - {most})
    return np.array(words, dtype=np.int64), most


def tvm_first_sections(count: int = 2):
    """The high-speed line cut after its first ``count`` sections (its lists cut there too): the
    coder core computes every section's carrier each frame, and the chain needs two."""
    import json

    from fmus.data.loader import Line
    from harness.tvm_line import HSL_LINE

    document = json.loads(HSL_LINE.read_text())
    end = float(document["block_sections"][count - 1]["end_m"])
    document.update(block_sections=document["block_sections"][:count], length_m=end,
                    separation_zones=[z for z in document["separation_zones"] if z["position_m"] < end],
                    stations=[s for s in document["stations"] if s["stop_m"] < end])
    for key in ("gradients", "speed_limits", "curves"):
        document[key] = [dict(x, **({"end_m": min(x["end_m"], end)} if "end_m" in x else {}))
                         for x in document.get(key, []) if x["start_m"] < end]
    return Line(document, HSL_LINE)


@dataclass(frozen=True)
class Um71Bench:
    """What a TVM system brings to the UM71 chain (um71_chain): its coder and receiver cores,
    the codes the own carrier sends and the most permissive one (the leaking neighbour's), how
    many decisions make a message, the receiver's stated latency, its no-code value, and the
    fields a code is compared by (more permissive in one: wrong-side)."""

    coder_core: type
    receiver: Callable[[int], object]          # frame → a receiver core on track 1 at TVM_FS
    codes: np.ndarray
    most: int
    hops_per_message: int
    hop_s: float
    stated_latency_s: float
    no_code: int
    fields: Callable[[int], tuple]


def um71_chain(bench: Um71Bench, count: int, noise, seed: int, leak_ratio: float = 0.0) -> dict:
    """A TVM system through its coder core (``bench.codes`` sent on the high-speed line's first
    section, 1700 Hz, scaled to TVM_CARRIER_V at the coil) into its receiver core (track 1);
    ``leak_ratio`` > 0: the next section's 2300 Hz carrier added at that ratio of it (the study:
    tvm_leak_ratio()), sending the most permissive code. A message is ``hops_per_message``
    decisions, each code held for HOLD messages (random codes of ``bench.codes``). A message is
    correct when its last decision (the one whose window lies wholly in it) reads the code sent
    on the own carrier; detected: no code; undetected: another valid code (or the neighbour's
    carrier), ``undetected_permissive`` of them one more permissive than the code sent in a
    field. ``decisions_other``: every decision reading a valid code neither of the messages its
    window reaches into sent. Wrong-side: a code shown that is more permissive in any field
    (``bench.fields``: the run verdicts' rule) than every code sent within the receiver's stated
    latency before."""
    codes, hops = bench.codes, bench.hops_per_message
    rng = np.random.default_rng(seed)
    schedule = codes[rng.integers(0, codes.size, (count + HOLD - 1) // HOLD)]
    sent = np.repeat(schedule, HOLD)[:count]
    frame = int(round(bench.hop_s * TVM_FS))                # one decision per frame
    line = tvm_first_sections(2)
    coder = bench.coder_core(line, len(line.sections), frame, CoderSettings(fs_hz=TVM_FS, seed=seed))
    receiver = bench.receiver(frame)
    own_gain = TVM_CARRIER_V / coder.settings.amplitude_v
    leak_gain = own_gain * leak_ratio
    forced = np.zeros(coder.count, dtype=np.int64)
    forced[1] = bench.most
    occupied = np.zeros(coder.count, dtype=bool)
    frames = count * hops
    shown = np.zeros(frames, dtype=np.int64)               # the code shown after each frame (0: none)
    shown_carrier = np.zeros(frames)
    read = np.zeros(frames, dtype=np.int64)                # the code each frame's decision read
    read_carrier = np.zeros(frames)
    decided = np.zeros(frames, dtype=bool)
    for j in range(frames):
        m = j // hops
        if j % (hops * HOLD) == 0:
            forced[0] = sent[m]
            coder.send(forced)
        first = j * frame
        u = coder.step(first / TVM_FS, occupied).u_tx
        e = own_gain * u[0] + leak_gain * u[1] if leak_ratio else own_gain * u[0]
        if noise is not None:
            e = e + noise(first, frame)
        out = receiver.step(first / TVM_FS, e)
        shown[j], shown_carrier[j] = (out.code, out.word_carrier_hz) if out.code_valid else (0, 0.0)
        decision = receiver.last_decision
        if decision is not None:
            read[j], read_carrier[j], decided[j] = decision.word, decision.carrier_hz, True
    fields = {}
    for c in {int(x) for x in np.unique(np.concatenate([codes, sent, shown[shown != 0], read[read != bench.no_code]]))}:
        fields[c] = bench.fields(c)

    width = len(bench.fields(int(codes[0])))

    def table(cs):
        return np.array([fields[int(c)] for c in cs]).reshape(-1, width)
    last = np.arange(count) * hops + hops - 1
    on_own = read_carrier[last] == TVM_OWN_HZ
    correct = int(np.sum((read[last] == sent) & on_own))
    detected = int(np.sum(read[last] == bench.no_code))
    undetected = count - correct - detected
    wrong_read = (read[last] != bench.no_code) & ~((read[last] == sent) & on_own)
    tol = 1e-6
    permissive = np.zeros(count, dtype=bool)
    permissive[wrong_read] = (table(read[last][wrong_read]) > table(sent[wrong_read]) + tol).any(axis=1)
    # every decision: a valid code neither of the messages its window reaches into sent
    message_of = np.arange(frames) // hops
    valid = read != bench.no_code
    this, before = sent[message_of], sent[np.maximum(message_of - 1, 0)]
    other = valid & ((read_carrier != TVM_OWN_HZ) | ((read != this) & (read != before)))
    # the display against the codes sent within the stated latency before (at most two: a code
    # is held for HOLD messages, longer than the latency)
    t_end = (np.arange(frames) + 1) * bench.hop_s
    message_s = hops * bench.hop_s
    hi = np.minimum((t_end / message_s - 1e-9).astype(np.int64), count - 1)
    lo = np.maximum(np.floor((t_end - bench.stated_latency_s) / message_s).astype(np.int64), 0)
    is_shown = shown != 0
    shown_fields = np.zeros((frames, width))
    shown_fields[is_shown] = table(shown[is_shown])
    exceeds_lo = (shown_fields > table(sent[lo]) + tol).any(axis=1)
    exceeds_hi = (shown_fields > table(sent[hi]) + tol).any(axis=1)
    wrong = is_shown & ((shown_carrier != TVM_OWN_HZ) | (exceeds_lo & exceeds_hi))
    settled = t_end > min(4 * message_s * HOLD, t_end[-1] / 2)
    available = is_shown & (shown_carrier == TVM_OWN_HZ) & ((shown == sent[lo]) | (shown == sent[hi]))
    return {"messages": count, "seconds": count * message_s, "correct": correct, "mer": 1.0 - correct / count,
            "undetected": undetected, "undetected_permissive": int(permissive.sum()), "detected": detected,
            "decisions": int(decided.sum()), "decisions_other": int(other.sum()),
            "wrong_side_events": int(np.sum(wrong[1:] & ~wrong[:-1]) + wrong[0]),
            "wrong_side_s": float(wrong.sum() * bench.hop_s), "availability": float(available[settled].mean())}


def tvm430_bench() -> Um71Bench:
    """TVM-430 on the UM71 chain: the high-speed line's words (tvm_words), 13 decisions a
    message (TVM_HOPS_PER_MESSAGE), compared by step, next step, target distance and gradient."""
    from fmus.loco_receiver.tvm430 import HOP_S, STATED_LATENCY_S, Tvm430ReceiverCore, Tvm430ReceiverSettings
    from fmus.signalling import tvm430
    from fmus.wayside_coder.tvm430 import Tvm430CoderCore

    tvm = tvm430.system()
    words, most = tvm_words(tvm)

    def fields(w: int) -> tuple:
        r = tvm.reading(w)
        return (r.step_kmh, r.next_kmh, r.target_distance_m, r.gradient_permille)
    return Um71Bench(Tvm430CoderCore, lambda frame: Tvm430ReceiverCore(frame, Tvm430ReceiverSettings(fs_hz=TVM_FS, track=1)),
                     words, most, TVM_HOPS_PER_MESSAGE, HOP_S, STATED_LATENCY_S, tvm430.NO_WORD, fields)


def tvm430_chain(count: int, noise, seed: int, leak_ratio: float = 0.0) -> dict:
    """TVM-430 through um71_chain (tvm430_bench): a message is TVM_HOPS_PER_MESSAGE decisions
    (1.625 s); wrong-side: a word shown more permissive in any field (step, next step, target
    distance, gradient) than every word sent within the receiver's stated latency (5.19 s)
    before. ``decisions_other_word``: um71_chain's ``decisions_other``."""
    result = um71_chain(tvm430_bench(), count, noise, seed, leak_ratio)
    result["decisions_other_word"] = result.pop("decisions_other")
    return result


# ---- 2e. TVM-300 -----------------------------------------------------------------------------------
def tvm300_hops_per_message() -> int:
    """A TVM-300 message: the fewest whole decisions (0.1 s) that hold a whole decision window
    (1/1.1 s), 10 (1.0 s); its last decision reads a window lying wholly in it (91 ms after its
    start: the baseband low-pass has settled), so the messages' decisions read disjoint
    stretches of signal and noise."""
    from fmus.signalling.tvm300 import HOP_S, WINDOW_S

    return int(np.ceil(WINDOW_S / HOP_S - 1e-9))


def tvm300_codes(tvm):
    """The codes a TVM-300 wayside of the high-speed line sends (every block, every number of
    free blocks ahead), less the most permissive (300/300), which is the leaking neighbour's:
    more permissive than every code sent."""
    from fmus.signalling import tvm300
    from harness.tvm_line import HSL_LINE

    steps = tvm.table.steps_kmh
    most = tvm.table.code_of_pair(steps[0], steps[0])
    codes = sorted({int(c) for c in np.unique(tvm300.BlockCoding(load_line(HSL_LINE), tvm).code)} - {most})
    return np.array(codes, dtype=np.int64), most


def tvm300_bench() -> Um71Bench:
    """TVM-300 on the UM71 chain: the high-speed line's codes (tvm300_codes), a message
    tvm300_hops_per_message() decisions, compared by step and next step (tvm300.at_most)."""
    from fmus.loco_receiver.tvm300 import Tvm300ReceiverCore, Tvm300ReceiverSettings
    from fmus.signalling import tvm300
    from fmus.wayside_coder.tvm300 import Tvm300CoderCore

    tvm = tvm300.system()
    codes, most = tvm300_codes(tvm)

    def fields(code: int) -> tuple:
        r = tvm.reading(code)
        return (r.step_kmh, r.next_kmh)
    return Um71Bench(Tvm300CoderCore, lambda frame: Tvm300ReceiverCore(frame, Tvm300ReceiverSettings(fs_hz=TVM_FS, track=1)),
                     codes, most, tvm300_hops_per_message(), tvm300.HOP_S, tvm300.STATED_LATENCY_S, tvm300.NO_CODE,
                     fields)


def tvm300_chain(count: int, noise, seed: int, leak_ratio: float = 0.0) -> dict:
    """TVM-300 through um71_chain (tvm300_bench): the Tvm300 coder core's sub-frequency on the
    1700 Hz carrier at 0.1 V into Tvm300ReceiverCore at 12 kHz; a message is 10 decisions
    (1.0 s); wrong-side: a code shown with a higher step or next step than every code sent
    within the stated latency (3.13 s) before. ``decisions_other_code``: um71_chain's
    ``decisions_other``."""
    result = um71_chain(tvm300_bench(), count, noise, seed, leak_ratio)
    result["decisions_other_code"] = result.pop("decisions_other")
    return result


# ---- one condition: a run of the study -------------------------------------------------------------
SNRS_DB = (0.0, -6.0, -10.0, -13.0, -16.0, -20.0)
IMPULSE_RATES = (0.5, 2.0, 5.0)
JOINT_SPEEDS_KMH = (40.0, 80.0, 160.0)


def _digital(name: str):
    def run(noise: str, level: float, noise_seed: int, message_seed: int, messages: int, alsn_cycles: int) -> dict:
        source = {"white": white, "impulse": impulses}[noise](level, np.random.default_rng(noise_seed))
        return run_digital(name, messages, source, message_seed)
    return run


def _alsn(noise: str, level: float, noise_seed: int, message_seed: int, messages: int, alsn_cycles: int) -> dict:
    source = {"white": white, "impulse": impulses}[noise](level, np.random.default_rng(noise_seed))
    return alsn_chain(alsn_cycles, source, message_seed)


def _alsu(noise: str, level: float, noise_seed: int, message_seed: int, messages: int, alsn_cycles: int) -> dict:
    rng = np.random.default_rng(noise_seed)
    if noise == "white":
        # SNR of the code's power, both tones (A² against σ²), over the whole band
        source = white(level - 10 * np.log10(2 * ALSU_TONE_V ** 2 / AMPLITUDE_V ** 2), rng)
    else:
        source = {"impulse": impulses, "joint": joints}[noise](level, rng)
    return alsu_chain(messages, source, message_seed)


def _um71(chain):
    """A TVM system's runner: white noise (SNR against TVM_CARRIER_V), impulses at TVM_FS, the
    swept in-band harmonic, or the neighbour's carrier at its worst leak with white noise."""
    def run(noise: str, level: float, noise_seed: int, message_seed: int, messages: int, alsn_cycles: int) -> dict:
        rng = np.random.default_rng(noise_seed)
        source = {"white": lambda: white(level, rng, TVM_CARRIER_V), "leak": lambda: white(level, rng, TVM_CARRIER_V),
                  "impulse": lambda: impulses(level, rng, TVM_FS), "inband": lambda: swept_harmonic(level, rng)}[noise]()
        return chain(messages, source, message_seed, tvm_leak_ratio() if noise == "leak" else 0.0)
    return run


@dataclass(frozen=True)
class Channel:
    """One system's channel in the study: its runner ``run(noise, level, noise seed, message
    seed, messages, alsn_cycles)`` and, for each noise it is studied under, the random-number
    seeds (noise generator, messages)."""

    run: Callable[..., dict]
    seeds: Dict[str, Tuple[int, int]]


#: every system's channel. Replication ``seed`` k adds 1000·k to both seeds (0: the docs'
#: figures); ALSN's message schedule always from seed 5
CHANNELS: Dict[str, Channel] = {
    cab_systems.FIRE_DQPSK.name: Channel(_digital(cab_systems.FIRE_DQPSK.name), {"white": (100, 7), "impulse": (200, 17)}),
    cab_systems.ALS_EN.name: Channel(_digital(cab_systems.ALS_EN.name), {"white": (101, 8), "impulse": (201, 18)}),
    cab_systems.ALSN.name: Channel(_alsn, {"white": (99, 5), "impulse": (199, 5)}),
    cab_systems.ALSU.name: Channel(_alsu, {"white": (98, 6), "impulse": (198, 16), "joint": (298, 26)}),
    cab_systems.TVM430.name: Channel(_um71(tvm430_chain), {"white": (97, 9), "impulse": (197, 19),
                                                           "inband": (397, 29), "leak": (497, 39)}),
    cab_systems.TVM300.name: Channel(_um71(tvm300_chain), {"white": (96, 10), "impulse": (196, 20),
                                                           "inband": (396, 30), "leak": (496, 40)}),
}


def condition(system: str, noise: str, level: float, seed: int = 0, messages: int = 100000,
              alsn_cycles: int = 2000) -> dict:
    """One system under one noise condition (white: SNR in dB; impulse: impulses per second;
    joint, ALSU only: DC joint pulse pairs at this speed in km/h; TVM430 and TVM300 only:
    inband, a harmonic sweeping the carrier ± 50 Hz at this level against the carrier in dB,
    and leak, the neighbour's carrier at its worst leak with white noise at this SNR in dB): a
    run of the study orchestrator/study/studies/noise_immunity.toml, noise_immunity_alsu.toml,
    noise_immunity_tvm430.toml or noise_immunity_tvm300.toml (``railcosim study``)."""
    channel = CHANNELS.get(system)
    if channel is None or noise not in channel.seeds:
        studied = "; ".join(f"{name}: {', '.join(c.seeds)}" for name, c in CHANNELS.items())
        raise ValueError(f"noise {noise!r} / system {system!r}: the systems and their noises are {studied}")
    noise_seed, message_seed = (s + 1000 * seed for s in channel.seeds[noise])
    return channel.run(noise, level, noise_seed, message_seed, messages, alsn_cycles)

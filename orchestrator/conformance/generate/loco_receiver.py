"""The loco_receiver role's vectors (data/loco_receiver.json, .npz): the coil EMF of our coder
cores for each cab system, with the latencies, holds and readings the receiver's page states
(docs/loco_receiver.md, docs/digital_channels.md).
"""
from __future__ import annotations

from typing import List

import numpy as np

from fmus.data.loader import DEFAULT_LINE, load_line
from fmus.loco_receiver.digital_receiver import DigitalReceiverCore, DigitalReceiverSettings
from fmus.signalling import alsn, cab_systems
from fmus.signalling import aspects as sig
from fmus.signalling.alsn import BENCH_COIL_COUPLING
from fmus.signalling.digital_messages import stated_latency_s
from fmus.wayside_coder.core import CoderSettings
from fmus.wayside_coder.digital_generator import DigitalCoderCore
from orchestrator.conformance.generate.coder_signals import (CODE_NAME, CODE_TAG, CYCLE_S, SECTION, TVM_FS_HZ,
                                                             coder_emf, occupancy, tvm_line, tvm_line_loaded)
from orchestrator.conformance.generate.role_file import (FRAME, FS_HZ, RoleFile, cond, in_range,
                                                         not_more_permissive)


def _shows(code: int) -> list:
    return [cond("aspect", [code]), cond("code_valid", [1])]


def receiver_vectors() -> RoleFile:
    role = RoleFile("loco_receiver", ["system", "fs", "e_coil", "aspect", "code_valid", "free_blocks",
                                      # TVM430's reading of the word shown
                                      "v_permitted", "v_target", "target_distance", "gradient", "word_carrier"])
    alsn_params = {"system": cab_systems.ALSN.name, "fs": FS_HZ}
    for kpt in ("KPT-5", "KPT-7"):
        role.vectors.extend(_alsn_acquire_vectors(role, alsn_params, kpt))
        role.vectors.append(_alsn_restrictive_change_vector(role, alsn_params, kpt))
    role.vectors.extend(_alsn_noise_vectors(role, alsn_params))
    role.vectors.append(_alsn_joint_vector(role, alsn_params))
    for system_name in (cab_systems.FIRE_DQPSK.name, cab_systems.ALS_EN.name):
        role.vectors.extend(_digital_receiver_vectors(role, system_name))
    role.vectors.extend(_alsu_receiver_vectors(role))
    role.vectors.extend(_tvm430_receiver_vectors(role))
    role.vectors.extend(_tvm300_receiver_vectors(role))
    return role


def _alsn_acquire_vectors(role: RoleFile, alsn_params: dict, kpt: str) -> List[dict]:
    """Each ALSN code from a ``kpt`` transmitter acquired from cold within two cycles + 0.5 s at
    two cam phases, and (at phase 0) its loss shown within the display hold + 0.2 s."""
    vectors = []
    loss_at_s, loss_bound_s = 6.0, alsn.EQUIPMENT_INERTIA_S + 0.2
    acquire_s = 2 * CYCLE_S[kpt] + 0.5
    for code in (sig.GREEN, sig.YELLOW, sig.RED_YELLOW):
        tag, label = CODE_TAG[code], CODE_NAME[code]
        steady = lambda t, c=code, s=SECTION[kpt]: occupancy(c, s)
        for phase in (0.0, 0.5):
            with_loss = phase == 0.0
            seconds = loss_at_s + loss_bound_s + 0.8 if with_loss else acquire_s + 1.0
            emf = coder_emf(SECTION[kpt], seconds, steady, phase)
            if with_loss:
                emf[int(loss_at_s * FS_HZ):] = 0.0
            name = f"{'acquire_loss' if with_loss else 'acquire'}_{tag}_{kpt}_phase{phase}"
            checks = [
                {"kind": "latency", "label": f"shows {label} within two cycles + 0.5 s", "from_s": 0.0,
                 "until": _shows(code), "bound_s": acquire_s},
                {"kind": "holds", "label": f"never more permissive than {label}",
                 "conditions": [cond("aspect", not_more_permissive(code))], "bound_s": 0.0}]
            if with_loss:
                no_code = [sig.RED] if code == sig.RED_YELLOW else [sig.WHITE]
                checks.append({"kind": "latency", "label": "loss: no-code indication within the display hold + 0.2 s",
                               "from_s": loss_at_s, "until": [cond("aspect", no_code), cond("code_valid", [0])],
                               "bound_s": loss_bound_s})
            vectors.append({
                "name": name, "what": f"code {label} from a {kpt} transmitter at 0.4 V, cam phase {phase} of its cycle"
                + (f"; the code's EMF stops at {loss_at_s} s" if with_loss else ""),
                "parameters": alsn_params, "step": {"fs_hz": FS_HZ}, "duration_s": seconds,
                "inputs": {"e_coil": role.samples(name, "e_coil", emf)}, "checks": checks})
    return vectors


def _alsn_restrictive_change_vector(role: RoleFile, alsn_params: dict, kpt: str) -> dict:
    """A restrictive change of the code sent, З → КЖ: shown within the stated latency."""
    change_s = 8.0
    name = f"restrictive_Z_to_KZh_{kpt}"
    schedule = lambda t, s=SECTION[kpt]: occupancy(sig.GREEN if t < change_s else sig.RED_YELLOW, s)
    seconds = change_s + alsn.STATED_LATENCY_S + 2.0
    emf = coder_emf(SECTION[kpt], seconds, schedule, 0.3)
    return {
        "name": name, "what": f"{kpt}: З for {change_s} s, then КЖ (the block ahead became occupied)",
        "parameters": alsn_params, "step": {"fs_hz": FS_HZ}, "duration_s": seconds,
        "inputs": {"e_coil": role.samples(name, "e_coil", emf)},
        "checks": [
            {"kind": "latency", "label": "restrictive change shown within the stated latency", "from_s": change_s,
             "until": [cond("aspect", not_more_permissive(sig.RED_YELLOW))], "bound_s": alsn.STATED_LATENCY_S},
            {"kind": "holds", "label": "never more permissive than КЖ after the stated latency",
             "from_s": change_s + alsn.STATED_LATENCY_S,
             "conditions": [cond("aspect", not_more_permissive(sig.RED_YELLOW))], "bound_s": 0.0}]}


def _alsn_noise_vectors(role: RoleFile, alsn_params: dict) -> List[dict]:
    """Noise and impulses: never more permissive than the code sent (docs/loco_receiver.md,
    noise study)."""
    rng = np.random.default_rng(18)
    seconds = 10.0
    t = np.arange(int(seconds * FS_HZ)) / FS_HZ
    code = sig.YELLOW
    clean = coder_emf(SECTION["KPT-5"], seconds, lambda _t: occupancy(code, 0), 0.2)
    sigma = np.sqrt(0.4 ** 2 / 2.0)                       # 0 dB over the whole band
    hum = 0.8 * np.sin(2 * np.pi * 100 * t + 100) + 0.8 * np.sin(2 * np.pi * 150 * t + 150) \
        + 2.0 * np.sin(2 * np.pi * 300 * t + 300)
    noisy = clean + sigma * rng.standard_normal(t.size) + hum
    impulses = clean.copy()
    for start in rng.uniform(0.0, seconds - 0.01, 40):      # 2 ms spikes of ±3 V, 4 per second
        k = int(start * FS_HZ)
        impulses[k:k + 8] += 3.0 * rng.choice((-1.0, 1.0))
    return [{
        "name": name, "what": what, "parameters": alsn_params, "step": {"fs_hz": FS_HZ}, "duration_s": seconds,
        "inputs": {"e_coil": role.samples(name, "e_coil", emf)},
        "checks": [{"kind": "holds", "label": "never more permissive than Ж",
                    "conditions": [cond("aspect", not_more_permissive(code))], "bound_s": 0.0}]}
        for name, emf, what in (("noise_Zh_0dB", noisy, "Ж (KPT-5, 0.4 V) in white noise at 0 dB full band with "
                                 "100 Hz 0.8 V, 150 Hz 0.8 V and 300 Hz 2 V traction harmonics"),
                                ("impulses_Zh", impulses,
                                 "Ж (KPT-5, 0.4 V) with 40 impulses of ±3 V, 2 ms, at seeded instants"))]


def _alsn_joint_vector(role: RoleFile, alsn_params: dict) -> dict:
    """A joint: the strong feed end of one circuit (3.5 V), 1 s without code (null zone and the
    receiver's recovery, docs/sources.md#interference-at-insulated-joints), then the weak entry
    end of the next (0.28 V, the other transmitter type): З held throughout."""
    before_s, gap_s, after_s = 7.0, 1.0, 8.0
    strong = coder_emf(0, before_s, lambda _t: occupancy(sig.GREEN, 0), 0.0, level=3.5 / 4.0)
    weak = coder_emf(1, before_s + gap_s + after_s, lambda _t: occupancy(sig.GREEN, 1), 0.6, level=0.28 / 4.0)
    emf = weak.copy()
    emf[:strong.size] = strong
    emf[strong.size:strong.size + int(gap_s * FS_HZ)] = 0.0
    name = "joint_dropout_Z"
    return {
        "name": name, "what": "З at 3.5 V (KPT-5 feed end), 1 s without code at the joint, З at 0.28 V (KPT-7 entry end)",
        "parameters": alsn_params, "step": {"fs_hz": FS_HZ}, "duration_s": before_s + gap_s + after_s,
        "inputs": {"e_coil": role.samples(name, "e_coil", emf)},
        "checks": [
            {"kind": "latency", "label": "shows З within two cycles + 0.5 s", "from_s": 0.0, "until": _shows(sig.GREEN),
             "bound_s": 2 * CYCLE_S["KPT-5"] + 0.5},
            {"kind": "holds", "label": "З held through the joint (display hold)", "from_s": before_s - 0.5,
             "conditions": _shows(sig.GREEN), "bound_s": 0.0}]}


def _alsu_emf(seconds: float, plan: List[tuple], level: float = BENCH_COIL_COUPLING) -> np.ndarray:
    """Section 1 of the ALSU coder core × ``level``: ``plan`` is (from s, code or a set of tone
    numbers 0…5) in time order, sent through the core's test generator (its tones keep running)."""
    from fmus.wayside_coder.alsu import AlsuCoderCore

    coder = AlsuCoderCore(load_line(str(DEFAULT_LINE)), 8, FRAME, CoderSettings(fs_hz=FS_HZ, seed=1, block_aspects=4))
    frames, current = [], None
    for k in range(int(round(seconds * FS_HZ / FRAME))):
        t = k * FRAME / FS_HZ
        wanted = [what for start, what in plan if start <= t + 1e-9][-1]
        if wanted is not current:
            current = wanted
            flags = coder.tones_of(wanted) if isinstance(wanted, int) else np.isin(np.arange(6), list(wanted))
            coder.send(np.tile(flags, (8, 1)))
        frames.append(coder.step(t, np.zeros(8, dtype=bool)).u_tx[0] * level)
    return np.concatenate(frames)


def _alsu_receiver_vectors(role: RoleFile) -> List[dict]:
    """ALSU: codes acquired, changed and lost within the stated latency (2 s) and the hold;
    three tones never a code (docs/loco_receiver.md#alsu). Readings: the shipped code table."""
    from fmus.loco_receiver.alsu import DISPLAY_HOLD_S, MIN_DURATION_S
    from fmus.signalling import alsu

    system = alsu.system()
    latency = alsu.STATED_LATENCY_S
    params = {"system": cab_systems.ALSU.name, "fs": FS_HZ}

    def shows(code: int) -> list:
        ind = system.indication(code, "passenger")
        return [cond("aspect", [ind.aspect]), cond("free_blocks", [ind.free_blocks]), cond("code_valid", [1])]

    def at_most(code: int) -> list:
        ind = system.indication(code, "passenger")
        return [cond("aspect", not_more_permissive(ind.aspect)), in_range("free_blocks", None, float(ind.free_blocks))]
    vectors = []
    change_s, loss_s = 4.0, 8.0
    seconds = loss_s + DISPLAY_HOLD_S + 1.5
    name = "alsu_9_then_4_then_loss"
    vectors.append({
        "name": name, "what": f"ALSU code 9 (tones 225 and 275 Hz, 0.4 V each) from cold, code 4 (175 and 225 Hz) "
                              f"from {change_s:g} s, no tone from {loss_s:g} s",
        "parameters": params, "step": {"fs_hz": FS_HZ}, "duration_s": seconds,
        "inputs": {"e_coil": role.samples(name, "e_coil", _alsu_emf(seconds, [(0.0, 9), (change_s, 4), (loss_s, 0)]))},
        "checks": [
            {"kind": "latency", "label": "code 9 shown within the stated latency", "from_s": 0.0, "until": shows(9),
             "bound_s": latency},
            {"kind": "latency", "label": "restrictive change to code 4 within the stated latency", "from_s": change_s,
             "until": shows(4), "bound_s": latency},
            {"kind": "holds", "label": "never more permissive than code 4 after the stated latency",
             "from_s": change_s + latency, "conditions": at_most(4), "bound_s": 0.0},
            {"kind": "latency", "label": "loss: no code within the hold + 0.5 s", "from_s": loss_s,
             "until": [cond("aspect", [sig.WHITE]), cond("code_valid", [0])], "bound_s": DISPLAY_HOLD_S + 0.5}]})
    garbled_s = 3.0
    seconds = garbled_s + 3.0
    name = "alsu_three_tones"
    vectors.append({
        "name": name, "what": f"ALSU code 9, then from {garbled_s:g} s three tones (175, 225, 275 Hz)",
        "parameters": params, "step": {"fs_hz": FS_HZ}, "duration_s": seconds,
        "inputs": {"e_coil": role.samples(name, "e_coil", _alsu_emf(seconds, [(0.0, 9), (garbled_s, (1, 2, 3))]))},
        "checks": [
            {"kind": "latency", "label": "three tones: no code within the minimum duration + 0.3 s", "from_s": garbled_s,
             "until": [cond("code_valid", [0])], "bound_s": MIN_DURATION_S + 0.3},
            {"kind": "holds", "label": "no code after that", "from_s": garbled_s + MIN_DURATION_S + 0.3,
             "conditions": [cond("code_valid", [0])], "bound_s": 0.0}]})
    rng = np.random.default_rng(33)
    seconds = 8.0
    t = np.arange(int(seconds * FS_HZ)) / FS_HZ
    hum = 0.8 * np.sin(2 * np.pi * 100 * t) + 0.8 * np.sin(2 * np.pi * 150 * t) + 0.8 * np.sin(2 * np.pi * 200 * t) \
        + 0.8 * np.sin(2 * np.pi * 250 * t) + 2.0 * np.sin(2 * np.pi * 300 * t) + 0.8 * np.sin(2 * np.pi * 350 * t)
    emf = _alsu_emf(seconds, [(0.0, 1)]) + np.sqrt(2 * 0.4 ** 2) * rng.standard_normal(t.size) + hum
    name = "alsu_noise_code_1"
    vectors.append({
        "name": name, "what": "ALSU code 1 (125 and 175 Hz, 0.4 V each) in white noise at 0 dB full band with 0.8 V "
                              "at 100, 150, 200, 250, 350 Hz and 2 V at 300 Hz (the traction harmonics between the tones)",
        "parameters": params, "step": {"fs_hz": FS_HZ}, "duration_s": seconds,
        "inputs": {"e_coil": role.samples(name, "e_coil", emf)},
        "checks": [
            {"kind": "latency", "label": "code 1 shown within the stated latency", "from_s": 0.0, "until": shows(1),
             "bound_s": latency},
            {"kind": "holds", "label": "never more permissive than code 1", "conditions": at_most(1), "bound_s": 0.0}]})
    return vectors


def _tvm_emf(seconds: float, plan: List[tuple], noise_v: float = 0.0, seed: int = 0, coder_core=None) -> np.ndarray:
    """Coil EMF from a TVM coder core (``coder_core``, default TVM-430's) on the coder vectors'
    line (section 1: 1700 Hz, section 2: 2300 Hz) at TVM_FS_HZ: ``plan`` is (from s, {section
    index: (word or code, peak V)}) in time order, sent through the core's test generator (each
    change phase-continuous, as in service); a section not listed is silent; plus white noise
    of ``noise_v`` rms."""
    from fmus.wayside_coder.tvm430 import Tvm430CoderCore

    coder = (coder_core or Tvm430CoderCore)(tvm_line_loaded(), 8, FRAME, CoderSettings(fs_hz=TVM_FS_HZ, seed=1))
    amplitude = coder.settings.amplitude_v
    words = np.zeros(8, dtype=np.int64)
    frames, current = [], None
    for k in range(int(round(seconds * TVM_FS_HZ / FRAME))):
        t = k * FRAME / TVM_FS_HZ
        entry = [what for start, what in plan if start <= t + 1e-9][-1]
        if entry is not current:
            current = entry
            for section, (word, _) in entry.items():
                words[section] = word
            coder.send(words)
            gains = np.zeros(8)
            for section, (_, level_v) in entry.items():
                gains[section] = level_v / amplitude
        frames.append(gains @ coder.step(t, np.zeros(8, dtype=bool)).u_tx)
    emf = np.concatenate(frames)
    if noise_v:
        emf += noise_v * np.random.default_rng(seed).standard_normal(emf.size)
    return emf


def _tvm430_receiver_vectors(role: RoleFile) -> List[dict]:
    """TVM-430 (docs/loco_receiver.md#tvm-430): a word from cold and a restrictive change within
    the stated decode time (a window, two decisions and the baseband low-pass's rise, 1.82 s), a lost carrier → the
    restrictive display within the stated latency (5.19 s) and not before the hold less one
    decision; a neighbour's more permissive word 20 dB down and a word with two bits flipped
    never shown. The coil EMF is our coder core's output at 8 kHz; the readings are the shipped
    word tables'."""
    bench = _Tvm430Bench(role)
    return [_tvm430_change_and_loss(bench), _tvm430_neighbour(bench), _tvm430_double_bit_error(bench)]


def _near(port: str, value: float, tolerance: float) -> dict:
    return in_range(port, round(value - tolerance, 6), round(value + tolerance, 6))


class _Tvm430Bench:
    """What the TVM-430 receiver vectors share: the carrier of our section (1700 Hz; the
    neighbour's 2300 Hz) at 0.3 V peak, two words, the stated times, and what the receiver must
    show of a word (the shipped word tables' readings)."""
    OWN, NEIGHBOUR = 0, 1                                     # sections: 1700 Hz, 2300 Hz
    LEVEL_V = 0.3                                             # a carrier at the coils (peak)

    def __init__(self, role: RoleFile):
        from fmus.loco_receiver.tvm430 import STATED_DECODE_S, STATED_LATENCY_S
        from fmus.signalling import tvm430

        self.role = role
        self.tvm = tvm430.system()
        self.params = {"system": cab_systems.TVM430.name, "fs": TVM_FS_HZ}
        self.step = {"fs_hz": TVM_FS_HZ}
        self.decode_s, self.latency_s = round(STATED_DECODE_S, 4), round(STATED_LATENCY_S, 4)
        self.no_word = [cond("code_valid", [0]), in_range("v_permitted", None, 0.01),
                        cond("aspect", not_more_permissive(sig.RED))]
        self.own_hz = float(tvm_line()["block_sections"][self.OWN]["carrier_hz"])
        self.clear = self.word(300, 300, 7000.0, 0.0)             # no target in range
        self.yellow = self.word(230, 170, 2750.0, -6.0)           # two blocks before the target, falling 6 ‰

    def word(self, step_kmh: float, next_kmh: float, distance_m: float, gradient_permille: float) -> int:
        from fmus.signalling import tvm430

        table = self.tvm.table
        return tvm430.assemble(table.addresses[0], table.speed_code(step_kmh, next_kmh),
                               table.distance_code(distance_m), table.gradient_code(gradient_permille))

    def meaning(self, w: int, carrier_hz: float) -> list:
        """The outputs of word ``w`` shown from ``carrier_hz`` (speeds to 0.01 m/s, distance to
        0.5 m, gradient to 0.05 ‰, carrier to 0.5 Hz)."""
        read = self.tvm.reading(w)
        return [cond("aspect", [read.aspect]), _near("v_permitted", read.step_kmh / 3.6, 0.01),
                _near("v_target", read.next_kmh / 3.6, 0.01), _near("target_distance", read.target_distance_m, 0.5),
                _near("gradient", read.gradient_permille, 0.05), _near("word_carrier", carrier_hz, 0.5)]

    def shows(self, w: int, carrier_hz: float) -> list:
        return [*self.meaning(w, carrier_hz), cond("code_valid", [1])]

    def at_most(self, w: int) -> list:
        """Nothing more permissive than ``w``: its aspect or a more restrictive one, its step, next
        step and target distance or less (no word: all 0)."""
        read = self.tvm.reading(w)
        return [cond("aspect", not_more_permissive(read.aspect)),
                in_range("v_permitted", None, round(read.step_kmh / 3.6 + 0.01, 6)),
                in_range("v_target", None, round(read.next_kmh / 3.6 + 0.01, 6)),
                in_range("target_distance", None, read.target_distance_m + 0.5)]

    def vector(self, name: str, what: str, seconds: float, emf: np.ndarray, checks: list) -> dict:
        return {"name": name, "what": what, "parameters": self.params, "step": self.step, "duration_s": seconds,
                "inputs": {"e_coil": self.role.samples(name, "e_coil", emf)}, "checks": checks}


def _tvm430_change_and_loss(bench: _Tvm430Bench) -> dict:
    """300/300 from cold, a restrictive change to 230/170, then the carrier lost."""
    from fmus.loco_receiver.tvm430 import HOLD_S, HOP_S, STATED_LATENCY_S

    own, level_v, clear, yellow, own_hz = bench.OWN, bench.LEVEL_V, bench.clear, bench.yellow, bench.own_hz
    change_s, loss_s = 4.0, 7.5
    seconds = round(loss_s + STATED_LATENCY_S + 0.5, 1)
    hold_to_s = round(loss_s + HOLD_S - HOP_S, 4)
    return bench.vector(
        "tvm430_300_then_230_then_loss",
        f"TVM-430 on the {own_hz:g} Hz carrier at {level_v:g} V: 300/300 (no target) from "
        f"cold, 230/170 (target 2750 m, −6 ‰) from {change_s:g} s, no carrier from {loss_s:g} s",
        seconds, _tvm_emf(seconds, [(0.0, {own: (clear, level_v)}), (change_s, {own: (yellow, level_v)}), (loss_s, {})]),
        [{"kind": "latency", "label": "300/300 shown with its reading within the stated decode time",
          "from_s": 0.0, "until": bench.shows(clear, own_hz), "bound_s": bench.decode_s},
         {"kind": "latency", "label": "restrictive change to 230/170 within the stated decode time",
          "from_s": change_s, "until": bench.shows(yellow, own_hz), "bound_s": bench.decode_s},
         {"kind": "holds", "label": "never more permissive than 230/170 after the stated decode time",
          "from_s": round(change_s + bench.decode_s, 4), "conditions": bench.at_most(yellow), "bound_s": 0.0},
         {"kind": "holds", "label": "lost carrier: the word held for the hold less one decision (it bridges a "
                                    "separation zone)", "from_s": loss_s, "to_s": hold_to_s,
          "conditions": [cond("code_valid", [1])], "bound_s": 0.0},
         {"kind": "latency", "label": "lost carrier: no word (step 0, code_valid false) within the stated latency",
          "from_s": loss_s, "until": bench.no_word, "bound_s": bench.latency_s}])


def _tvm430_neighbour(bench: _Tvm430Bench) -> dict:
    """The next block's more permissive word 20 dB down in noise: never shown."""
    own, level_v, own_hz = bench.OWN, bench.LEVEL_V, bench.own_hz
    seconds, leak, noise_v = 5.0, 0.1, 0.03
    plan = [(0.0, {own: (bench.yellow, level_v), bench.NEIGHBOUR: (bench.clear, leak * level_v)})]
    return bench.vector(
        "tvm430_neighbour_20dB_permissive",
        f"230/170 on the {own_hz:g} Hz carrier at {level_v:g} V, the next block's 2300 Hz "
        f"carrier 20 dB down with 300/300, white noise {noise_v:g} V rms",
        seconds, _tvm_emf(seconds, plan, noise_v, seed=43),
        [{"kind": "latency", "label": "230/170 shown from its own carrier within the stated decode time",
          "from_s": 0.0, "until": bench.shows(bench.yellow, own_hz), "bound_s": bench.decode_s},
         {"kind": "holds", "label": "the neighbour's 300/300 never shown (nothing more permissive, never its carrier)",
          "conditions": [*bench.at_most(bench.yellow), in_range("word_carrier", None, own_hz + 0.5)],
          "bound_s": 0.0}])


def _tvm430_double_bit_error(bench: _Tvm430Bench) -> dict:
    """Two bits of the speed field flipped (without the check the word would read 230/230):
    the corrupted word never shown."""
    from fmus.loco_receiver.tvm430 import STATED_LATENCY_S
    from fmus.signalling import tvm430

    own, level_v, yellow, own_hz = bench.OWN, bench.LEVEL_V, bench.yellow, bench.own_hz
    speed_low = tvm430.FIELDS["speed"][0]
    flips = (1 << speed_low) | (1 << (speed_low + 4))
    corrupted = yellow ^ flips
    assert not tvm430.check_passes(corrupted)
    assert bench.tvm.table.speed_codes[tvm430.field(corrupted, "speed")] == (230.0, 230.0)
    corrupt_s = 3.0
    seconds = round(corrupt_s + STATED_LATENCY_S + 0.5, 1)
    return bench.vector(
        "tvm430_double_bit_error",
        f"230/170 on the {own_hz:g} Hz carrier at {level_v:g} V, from {corrupt_s:g} s with "
        f"word bits {speed_low} and {speed_low + 4} flipped (its speed field reads 230/230; "
        f"the check fails)",
        seconds, _tvm_emf(seconds, [(0.0, {own: (yellow, level_v)}), (corrupt_s, {own: (corrupted, level_v)})]),
        [{"kind": "latency", "label": "230/170 shown within the stated decode time", "from_s": 0.0,
          "until": bench.shows(yellow, own_hz), "bound_s": bench.decode_s},
         {"kind": "holds", "label": "the corrupted word never shown: any word shown reads 230/170",
          "where": [cond("code_valid", [1])], "conditions": bench.meaning(yellow, own_hz), "bound_s": 0.0},
         {"kind": "latency", "label": "corrupted word: no word (step 0, code_valid false) within the stated latency",
          "from_s": corrupt_s, "until": bench.no_word, "bound_s": bench.latency_s}])


def _tvm300_receiver_vectors(role: RoleFile) -> List[dict]:
    """TVM-300 (docs/loco_receiver.md#tvm-300): every used code shown within the stated decode
    time (a window, two decisions and the baseband low-pass's rise, 1.12 s), from cold and at
    each change; a restrictive change, then a lost carrier → no code within the stated latency
    (3.13 s) and not before the hold less one decision; a bare carrier, two sub-frequencies at
    once and an unused one → no code within the stated latency, never a code after; the
    neighbour's more permissive code 20 dB down never shown. Never more permissive than the
    code sent. The coil EMF is our coder core's output at 8 kHz (the two sub-frequencies: a
    coder whose second oscillator joins in, synthesised here); the readings are the shipped
    code table's."""
    bench = _Tvm300Bench(role)
    return [_tvm300_every_code(bench), _tvm300_change_and_loss(bench), _tvm300_neighbour(bench),
            *(_tvm300_no_code(bench, kind) for kind in ("bare_carrier", "two_sub_frequencies", "unused_sub_frequency"))]


class _Tvm300Bench:
    """What the TVM-300 receiver vectors share: the carriers of our sections (1700 Hz; the next
    one's 2300 Hz) at 0.3 V peak, the stated times, and what the receiver must show of a code
    (the shipped code table's readings)."""
    OWN, NEIGHBOUR = 0, 1                                     # sections: 1700 Hz, 2300 Hz
    LEVEL_V = 0.3                                             # a carrier at the coils (peak)

    def __init__(self, role: RoleFile):
        from fmus.signalling import tvm300

        self.role = role
        self.tvm = tvm300.system()
        self.params = {"system": cab_systems.TVM300.name, "fs": TVM_FS_HZ}
        self.step = {"fs_hz": TVM_FS_HZ}
        self.decode_s, self.latency_s = round(tvm300.STATED_DECODE_S, 4), round(tvm300.STATED_LATENCY_S, 4)
        self.no_code = [cond("code_valid", [0]), in_range("v_permitted", None, 0.01),
                        cond("aspect", not_more_permissive(sig.RED))]
        sections = tvm_line()["block_sections"]
        self.carriers_hz = [float(sections[k]["carrier_hz"]) for k in (self.OWN, self.NEIGHBOUR)]
        self.used = [c for c in range(1, tvm300.SUB_FREQUENCY_COUNT + 1) if self.tvm.reading(c) is not None]
        self.unused = [c for c in range(1, tvm300.SUB_FREQUENCY_COUNT + 1) if self.tvm.reading(c) is None]

    def code(self, step_kmh: float, next_kmh: float) -> int:
        return self.tvm.table.code_of_pair(float(step_kmh), float(next_kmh))

    def label(self, code: int) -> str:
        read = self.tvm.reading(code)
        return f"{read.step_kmh:g}/{read.next_kmh:g}"

    def shows(self, code: int, carrier_hz: float) -> list:
        """Code ``code`` shown from ``carrier_hz``: its aspect, steps (to 0.01 m/s), free blocks,
        carrier (to 0.5 Hz)."""
        read = self.tvm.reading(code)
        return [cond("aspect", [read.aspect]), _near("v_permitted", read.step_kmh / 3.6, 0.01),
                _near("v_target", read.next_kmh / 3.6, 0.01), cond("free_blocks", [read.free_blocks]),
                _near("word_carrier", carrier_hz, 0.5), cond("code_valid", [1])]

    def at_most(self, code: int) -> list:
        """Nothing more permissive than ``code``: its aspect or a more restrictive one, neither
        its step nor its next step exceeded (no code: both 0)."""
        read = self.tvm.reading(code)
        return [cond("aspect", not_more_permissive(read.aspect)),
                in_range("v_permitted", None, round(read.step_kmh / 3.6 + 0.01, 6)),
                in_range("v_target", None, round(read.next_kmh / 3.6 + 0.01, 6))]

    def emf(self, seconds: float, plan: List[tuple], noise_v: float = 0.0, seed: int = 0) -> np.ndarray:
        from fmus.wayside_coder.tvm300 import Tvm300CoderCore

        return _tvm_emf(seconds, plan, noise_v, seed, coder_core=Tvm300CoderCore)

    def vector(self, name: str, what: str, seconds: float, emf: np.ndarray, checks: list) -> dict:
        return {"name": name, "what": what, "parameters": self.params, "step": self.step, "duration_s": seconds,
                "inputs": {"e_coil": self.role.samples(name, "e_coil", emf)}, "checks": checks}


def _tvm300_every_code(bench: _Tvm300Bench) -> dict:
    """The 14 used codes in turn (sub-frequency order, 0/0 first from cold), each for 2 s."""
    own, level_v, own_hz = bench.OWN, bench.LEVEL_V, bench.carriers_hz[0]
    each_s = 2.0
    seconds = each_s * len(bench.used)
    plan = [(k * each_s, {own: (code, level_v)}) for k, code in enumerate(bench.used)]
    checks = []
    for k, code in enumerate(bench.used):
        start, end = k * each_s, (k + 1) * each_s
        checks.append({"kind": "latency", "label": f"{bench.label(code)} (code {code}) shown within the stated "
                                                   f"decode time", "from_s": start, "until": bench.shows(code, own_hz),
                       "bound_s": bench.decode_s})
        checks.append({"kind": "holds", "label": f"never more permissive than {bench.label(code)} after it",
                       "from_s": round(start + bench.decode_s, 4), "to_s": end, "conditions": bench.at_most(code),
                       "bound_s": 0.0})
    return bench.vector(
        "tvm300_every_code", f"TVM-300 on the {own_hz:g} Hz carrier at {level_v:g} V: the {len(bench.used)} used "
                             f"codes in sub-frequency order ({', '.join(bench.label(c) for c in bench.used)}), "
                             f"{each_s:g} s each, the first from cold",
        seconds, bench.emf(seconds, plan), checks)


def _tvm300_change_and_loss(bench: _Tvm300Bench) -> dict:
    """300/300 from cold on the other carrier, a restrictive change to 160/80, then the carrier lost."""
    from fmus.signalling.tvm300 import HOLD_S, HOP_S, STATED_LATENCY_S

    section, level_v, hz = bench.NEIGHBOUR, bench.LEVEL_V, bench.carriers_hz[1]
    clear, yellow = bench.code(300, 300), bench.code(160, 80)
    change_s, loss_s = 3.0, 6.0
    seconds = round(loss_s + STATED_LATENCY_S + 0.5, 1)
    hold_to_s = round(loss_s + HOLD_S - HOP_S, 4)
    return bench.vector(
        "tvm300_300_then_160_then_loss",
        f"TVM-300 on the {hz:g} Hz carrier at {level_v:g} V: 300/300 from cold, 160/80 from {change_s:g} s, "
        f"no carrier from {loss_s:g} s",
        seconds, bench.emf(seconds, [(0.0, {section: (clear, level_v)}), (change_s, {section: (yellow, level_v)}),
                                     (loss_s, {})]),
        [{"kind": "latency", "label": "300/300 shown with its reading within the stated decode time",
          "from_s": 0.0, "until": bench.shows(clear, hz), "bound_s": bench.decode_s},
         {"kind": "latency", "label": "restrictive change to 160/80 within the stated decode time",
          "from_s": change_s, "until": bench.shows(yellow, hz), "bound_s": bench.decode_s},
         {"kind": "holds", "label": "never more permissive than 160/80 after the stated decode time",
          "from_s": round(change_s + bench.decode_s, 4), "conditions": bench.at_most(yellow), "bound_s": 0.0},
         {"kind": "holds", "label": "lost carrier: the code held for the hold less one decision (it bridges a "
                                    "separation zone)", "from_s": loss_s, "to_s": hold_to_s,
          "conditions": [cond("code_valid", [1])], "bound_s": 0.0},
         {"kind": "latency", "label": "lost carrier: no code (step 0, code_valid false) within the stated latency",
          "from_s": loss_s, "until": bench.no_code, "bound_s": bench.latency_s}])


def _tvm300_neighbour(bench: _Tvm300Bench) -> dict:
    """The next block's more permissive code 20 dB down in noise: never shown."""
    own, level_v, own_hz = bench.OWN, bench.LEVEL_V, bench.carriers_hz[0]
    yellow, clear = bench.code(160, 80), bench.code(300, 300)
    seconds, leak, noise_v = 5.0, 0.1, 0.03
    plan = [(0.0, {own: (yellow, level_v), bench.NEIGHBOUR: (clear, leak * level_v)})]
    return bench.vector(
        "tvm300_neighbour_20dB_permissive",
        f"TVM-300: 160/80 on the {own_hz:g} Hz carrier at {level_v:g} V, the next block's "
        f"{bench.carriers_hz[1]:g} Hz carrier 20 dB down with 300/300, white noise {noise_v:g} V rms",
        seconds, bench.emf(seconds, plan, noise_v, seed=44),
        [{"kind": "latency", "label": "160/80 shown from its own carrier within the stated decode time",
          "from_s": 0.0, "until": bench.shows(yellow, own_hz), "bound_s": bench.decode_s},
         {"kind": "holds", "label": "the neighbour's 300/300 never shown (nothing more permissive, never its carrier)",
          "conditions": [*bench.at_most(yellow), in_range("word_carrier", None, own_hz + 0.5)], "bound_s": 0.0}])


#: the no-code vectors: the code sent first (a speed pair), and what follows it
_TVM300_NO_CODE = {"bare_carrier": ((160, 80), "the bare carrier (no sub-frequency)"),
                   "two_sub_frequencies": ((160, 80), "its sub-frequency and 300/300's at once, each at the full "
                                                      "deviation (a coder's second oscillator joining in)"),
                   "unused_sub_frequency": ((270, 220), "an unused sub-frequency")}


def _tvm300_no_code(bench: _Tvm300Bench, kind: str) -> dict:
    """A code, then no sub-frequency, two, or an unused one: no code within the stated latency,
    none after it, never anything more permissive than the code first sent."""
    from fmus.signalling import tvm300

    own, level_v, own_hz = bench.OWN, bench.LEVEL_V, bench.carriers_hz[0]
    (step_kmh, next_kmh), then = _TVM300_NO_CODE[kind]
    first = bench.code(step_kmh, next_kmh)
    change_s = 3.0
    seconds = round(change_s + bench.latency_s + 1.5, 1)
    if kind == "two_sub_frequencies":
        emf = _two_sub_frequencies_emf(seconds, own_hz, level_v, first, bench.code(300, 300), change_s)
    else:
        # the unused sub-frequency beside the one a confusion would gain most speed from (300/220)
        later = tvm300.NO_CODE if kind == "bare_carrier" else min(bench.unused, key=lambda c: abs(c - bench.code(300, 220)))
        then = then if kind == "bare_carrier" else f"{then} (code {later}, {tvm300.SUB_FREQUENCIES_HZ[later - 1]:.1f} Hz)"
        emf = bench.emf(seconds, [(0.0, {own: (first, level_v)}), (change_s, {own: (later, level_v)})])
    after_s = round(change_s + bench.latency_s, 4)
    return bench.vector(
        f"tvm300_{kind}", f"TVM-300: {bench.label(first)} on the {own_hz:g} Hz carrier at {level_v:g} V, from "
                          f"{change_s:g} s {then}",
        seconds, emf,
        [{"kind": "latency", "label": f"{bench.label(first)} shown within the stated decode time", "from_s": 0.0,
          "until": bench.shows(first, own_hz), "bound_s": bench.decode_s},
         {"kind": "holds", "label": f"never more permissive than {bench.label(first)}",
          "conditions": bench.at_most(first), "bound_s": 0.0},
         {"kind": "latency", "label": "no code (step 0, code_valid false) within the stated latency",
          "from_s": change_s, "until": bench.no_code, "bound_s": bench.latency_s},
         {"kind": "holds", "label": "no code after that", "from_s": after_s, "conditions": bench.no_code,
          "bound_s": 0.0}])


def _two_sub_frequencies_emf(seconds: float, carrier_hz: float, level_v: float, code: int, second: int,
                             from_s: float) -> np.ndarray:
    """A carrier frequency-modulated by ``code``'s sub-frequency throughout and, from
    ``from_s``, by ``second``'s as well, each at the full deviation (fmus/signalling/tvm300.py:
    the phase's term (Δ/f)·sin(2π f t); the second starts at 0, so the phase is continuous), at
    TVM_FS_HZ: what no coder in service sends."""
    from fmus.signalling import tvm300

    t = np.arange(int(round(seconds * TVM_FS_HZ))) / TVM_FS_HZ
    f1, f2 = (tvm300.SUB_FREQUENCIES_HZ[tvm300.index_of_code(c)] for c in (code, second))
    phase = 2.0 * np.pi * carrier_hz * t + tvm300.DEVIATION_HZ / f1 * np.sin(2.0 * np.pi * f1 * t)
    late = t >= from_s
    phase[late] += tvm300.DEVIATION_HZ / f2 * np.sin(2.0 * np.pi * f2 * (t[late] - from_s))
    return level_v * np.sin(phase)


def _digital_receiver_vectors(role: RoleFile, system_name: str) -> List[dict]:
    """The command the block sends into section 1 for a clear line and for the second section
    ahead occupied, each acquired from cold within four messages + 0.5 s, then the command for
    the next section occupied within the stated latency (docs/digital_channels.md, Latency).
    The indication expected for each command is the one our receiver core settles on."""
    system = cab_systems.digital_system(system_name)
    line = load_line(str(DEFAULT_LINE))
    message_s = system.message_s(system.carrier_hz)
    acquire_s = 4 * message_s + 0.5
    latency_s = stated_latency_s(message_s)
    vectors = []
    patterns = {"clear": np.zeros(8, dtype=bool), "block2": occupancy(sig.YELLOW, 0),
                "block1": occupancy(sig.RED_YELLOW, 0)}
    for before, after in (("clear", "block1"), ("block2", "block1")):
        change_s = round(acquire_s + 1.5, 2)
        seconds = round(change_s + latency_s + 1.5, 2)
        coder = DigitalCoderCore(system, line, 8, FRAME, CoderSettings(fs_hz=FS_HZ, amplitude_v=1.0, seed=1))
        receiver = DigitalReceiverCore(system, FRAME, DigitalReceiverSettings(fs_hz=FS_HZ))
        frames, shown = [], []
        for k in range(int(round(seconds * FS_HZ / FRAME))):
            t = k * FRAME / FS_HZ
            e = 0.2 * coder.step(t, patterns[before if t < change_s else after]).u_tx[0]
            frames.append(e)
            out = receiver.step(t, e)
            shown.append((t + FRAME / FS_HZ, out.aspect, out.free_blocks, out.code_valid))
        shown = np.array(shown)
        # what our receiver settles on for each command: the expected indication
        first = shown[(shown[:, 0] > change_s - 0.5) & (shown[:, 0] <= change_s)][-1]
        last = shown[-1]
        name = f"{system_name.lower().replace('-', '_')}_{before}_to_{after}"
        vectors.append({
            "name": name, "what": f"{system_name}: the command for '{before}' from cold, then '{after}' at {change_s} s",
            "parameters": {"system": system_name, "fs": FS_HZ}, "step": {"fs_hz": FS_HZ}, "duration_s": seconds,
            "inputs": {"e_coil": role.samples(name, "e_coil", np.concatenate(frames))},
            "checks": [
                {"kind": "latency", "label": "command acquired within four messages + 0.5 s", "from_s": 0.0,
                 "until": [cond("aspect", [first[1]]), cond("free_blocks", [first[2]]), cond("code_valid", [1])],
                 "bound_s": round(acquire_s, 4)},
                {"kind": "latency", "label": "restrictive change within the stated latency", "from_s": change_s,
                 "until": [cond("aspect", [last[1]]), cond("free_blocks", [last[2]]), cond("code_valid", [1])],
                 "bound_s": round(latency_s, 4)},
                {"kind": "holds", "label": "never more permissive after the stated latency",
                 "from_s": round(change_s + latency_s, 4),
                 "conditions": [cond("aspect", not_more_permissive(int(last[1]))),
                                in_range("free_blocks", None, float(last[2]))], "bound_s": 0.0}]})
    return vectors

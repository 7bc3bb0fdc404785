"""Write the conformance vectors (data/<role>.json and .npz) from our model cores and the
documented bounds: ``python -m orchestrator.conformance.generate [ROLE ...]``.

Every input is computed here (the coder core's transmitter output for the receiver, seeded
noise, the traction core for the expected motion), every bound is the one the unit's page
states (docs/loco_receiver.md, docs/digital_channels.md, docs/wayside_coder.md,
docs/rail_line.md, docs/traction.md, docs/ato.md); running this again writes the same files.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Callable, Dict, List, Optional

import numpy as np

from fmus.data.loader import DEFAULT_LINE, DEFAULT_ROLLING_STOCK, DEFAULT_TIMETABLE, load_line, load_rolling_stock, load_timetable
from fmus.signalling import aspects as sig
from fmus.signalling import alsn, cab_systems
from fmus.signalling.alsn import BENCH_COIL_COUPLING
from fmus.signalling.digital_messages import stated_latency_s
from fmus.wayside_coder.core import CoderSettings, WaysideCoderCore
from fmus.wayside_coder.digital_generator import DigitalCoderCore
from fmus.loco_receiver.digital_receiver import DigitalReceiverCore, DigitalReceiverSettings
from fmus.rail_line.track_circuit import cascade_shunt_current
from fmus.sizes import DEFAULT_SAMPLE_RATE_HZ
from orchestrator.conformance import ROLES
from orchestrator.conformance.vectors import DATA_DIR, FORMAT

FS_HZ = DEFAULT_SAMPLE_RATE_HZ   # the units' default rate: the vectors hold for a default build
FRAME = 40                  # the generator's own frame; the runner steps with the target's
GENERATOR = "python -m orchestrator.conformance.generate"


class RoleFile:
    """One role's vectors and arrays as they are being written."""

    def __init__(self, role: str, required_ports: List[str]):
        self.role, self.required_ports = role, required_ports
        self.vectors: List[dict] = []
        self.arrays: Dict[str, np.ndarray] = {}
        self.data_files: Dict[str, object] = {}        # file name → JSON document written beside

    def samples(self, vector: str, port: str, values: np.ndarray) -> dict:
        """An input stream stored as int16 counts × scale (the scale keeps 15 bits of its peak)."""
        peak = float(np.max(np.abs(values))) or 1.0
        scale = peak / 32000.0
        key = f"{vector}.{port}"
        self.arrays[key] = np.round(values / scale).astype(np.int16)
        return {"array": key, "scale": scale}

    def write(self, directory: Path) -> List[Path]:
        directory.mkdir(parents=True, exist_ok=True)
        data = {"format": FORMAT, "role": self.role, "generator": GENERATOR,
                "required_ports": self.required_ports,
                "arrays": f"{self.role}.npz" if self.arrays else None, "vectors": self.vectors}
        path = directory / f"{self.role}.json"
        path.write_text(json.dumps(data, indent=1, ensure_ascii=False) + "\n", encoding="utf-8")
        written = [path]
        for file_name, document in sorted(self.data_files.items()):
            data_path = directory / file_name
            data_path.write_text(json.dumps(document, indent=1, ensure_ascii=False) + "\n", encoding="utf-8")
            written.append(data_path)
        if self.arrays:
            npz = directory / f"{self.role}.npz"
            # fixed member timestamps: the same vectors give the same bytes
            _save_npz(npz, self.arrays)
            written.append(npz)
        return written


def _save_npz(path: Path, arrays: Dict[str, np.ndarray]) -> None:
    import io
    import zipfile

    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as archive:
        for key in sorted(arrays):
            buffer = io.BytesIO()
            np.lib.format.write_array(buffer, arrays[key], allow_pickle=False)
            info = zipfile.ZipInfo(f"{key}.npy", date_time=(2020, 1, 1, 0, 0, 0))
            info.compress_type = zipfile.ZIP_DEFLATED
            archive.writestr(info, buffer.getvalue())


def _cond(port: str, values) -> dict:
    return {"port": port, "in": [int(v) for v in values]}


def _rng(port: str, lo: Optional[float], hi: Optional[float]) -> dict:
    return {"port": port, "range": [lo, hi]}


def not_more_permissive(code: int) -> List[int]:
    """Aspects a receiver may show while ``code`` is sent: the code or anything more restrictive."""
    return [a for a in (sig.WHITE, sig.RED, sig.RED_YELLOW, sig.YELLOW, sig.GREEN)
            if sig.restrictiveness(a) <= sig.restrictiveness(code)]


# ---- loco_receiver ------------------------------------------------------------------------------
SECTION = {"KPT-5": 0, "KPT-7": 1}      # the bundled line's sections 1 and 2
#: cam cycle per transmitter type, from the code tables (docs/wayside_coder.md)
CYCLE_S = {kpt: table["cycle_s"] for kpt, table in
           json.loads(alsn.CODES_FILE.read_text(encoding="utf-8"))["transmitters"].items()}
CODE_TAG = {sig.GREEN: "Z", sig.YELLOW: "Zh", sig.RED_YELLOW: "KZh"}      # in vector names
CODE_NAME = {sig.GREEN: "З", sig.YELLOW: "Ж", sig.RED_YELLOW: "КЖ"}


def occupancy(code: int, section: int, sections: int = 8) -> np.ndarray:
    """Occupied sections that make the coder send ``code`` into ``section`` (3-aspect block)."""
    occupied = np.zeros(sections, dtype=bool)
    if code == sig.YELLOW:
        occupied[section + 2] = True
    elif code == sig.RED_YELLOW:
        occupied[section + 1] = True
    return occupied


def coder_emf(section: int, seconds: float, schedule: Callable[[float], np.ndarray], phase: float,
              level: float = BENCH_COIL_COUPLING) -> np.ndarray:
    """The coil EMF of one section's transmitter output × ``level``, frame by frame, every cam
    starting at ``phase`` of its cycle."""
    line = load_line(str(DEFAULT_LINE))
    coder = WaysideCoderCore(line, len(line.sections), FRAME, CoderSettings(fs_hz=FS_HZ, seed=1))
    coder.cam_offset_s[:] = phase * coder.cycle_s
    frames = []
    for k in range(int(round(seconds * FS_HZ / FRAME))):
        t = k * FRAME / FS_HZ
        frames.append(coder.step(t, schedule(t)).u_tx[section] * level)
    return np.concatenate(frames)


def _shows(code: int) -> list:
    return [_cond("aspect", [code]), _cond("code_valid", [1])]


def receiver_vectors() -> RoleFile:
    role = RoleFile("loco_receiver", ["system", "fs", "e_coil", "aspect", "code_valid", "free_blocks",
                                      # TVM430's reading of the word shown
                                      "v_permitted", "v_target", "target_distance", "gradient", "word_carrier"])
    alsn_params = {"system": "ALSN", "fs": FS_HZ}
    loss_at_s, loss_bound_s = 6.0, alsn.EQUIPMENT_INERTIA_S + 0.2
    for kpt in ("KPT-5", "KPT-7"):
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
                     "conditions": [_cond("aspect", not_more_permissive(code))], "bound_s": 0.0}]
                if with_loss:
                    no_code = [sig.RED] if code == sig.RED_YELLOW else [sig.WHITE]
                    checks.append({"kind": "latency", "label": "loss: no-code indication within the display hold + 0.2 s",
                                   "from_s": loss_at_s, "until": [_cond("aspect", no_code), _cond("code_valid", [0])],
                                   "bound_s": loss_bound_s})
                role.vectors.append({
                    "name": name, "what": f"code {label} from a {kpt} transmitter at 0.4 V, cam phase {phase} of its cycle"
                    + (f"; the code's EMF stops at {loss_at_s} s" if with_loss else ""),
                    "parameters": alsn_params, "step": {"fs_hz": FS_HZ}, "duration_s": seconds,
                    "inputs": {"e_coil": role.samples(name, "e_coil", emf)}, "checks": checks})
        # a restrictive change of the code sent, З → КЖ: within the stated latency
        change_s = 8.0
        name = f"restrictive_Z_to_KZh_{kpt}"
        schedule = lambda t, s=SECTION[kpt]: occupancy(sig.GREEN if t < change_s else sig.RED_YELLOW, s)
        seconds = change_s + alsn.STATED_LATENCY_S + 2.0
        emf = coder_emf(SECTION[kpt], seconds, schedule, 0.3)
        role.vectors.append({
            "name": name, "what": f"{kpt}: З for {change_s} s, then КЖ (the block ahead became occupied)",
            "parameters": alsn_params, "step": {"fs_hz": FS_HZ}, "duration_s": seconds,
            "inputs": {"e_coil": role.samples(name, "e_coil", emf)},
            "checks": [
                {"kind": "latency", "label": "restrictive change shown within the stated latency", "from_s": change_s,
                 "until": [_cond("aspect", not_more_permissive(sig.RED_YELLOW))], "bound_s": alsn.STATED_LATENCY_S},
                {"kind": "holds", "label": "never more permissive than КЖ after the stated latency",
                 "from_s": change_s + alsn.STATED_LATENCY_S,
                 "conditions": [_cond("aspect", not_more_permissive(sig.RED_YELLOW))], "bound_s": 0.0}]})

    # noise and impulses: never more permissive than the code sent (docs/loco_receiver.md, noise study)
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
    for name, emf, what in (("noise_Zh_0dB", noisy, "Ж (KPT-5, 0.4 V) in white noise at 0 dB full band with "
                             "100 Hz 0.8 V, 150 Hz 0.8 V and 300 Hz 2 V traction harmonics"),
                            ("impulses_Zh", impulses, "Ж (KPT-5, 0.4 V) with 40 impulses of ±3 V, 2 ms, at seeded instants")):
        role.vectors.append({
            "name": name, "what": what, "parameters": alsn_params, "step": {"fs_hz": FS_HZ}, "duration_s": seconds,
            "inputs": {"e_coil": role.samples(name, "e_coil", emf)},
            "checks": [{"kind": "holds", "label": "never more permissive than Ж",
                        "conditions": [_cond("aspect", not_more_permissive(code))], "bound_s": 0.0}]})

    # a joint: the strong feed end of one circuit (3.5 V), 1 s without code (null zone and the
    # receiver's recovery, docs/sources.md#interference-at-insulated-joints), then the weak entry
    # end of the next (0.28 V, the other transmitter type): З held throughout
    before_s, gap_s, after_s = 7.0, 1.0, 8.0
    strong = coder_emf(0, before_s, lambda _t: occupancy(sig.GREEN, 0), 0.0, level=3.5 / 4.0)
    weak = coder_emf(1, before_s + gap_s + after_s, lambda _t: occupancy(sig.GREEN, 1), 0.6, level=0.28 / 4.0)
    emf = weak.copy()
    emf[:strong.size] = strong
    emf[strong.size:strong.size + int(gap_s * FS_HZ)] = 0.0
    name = "joint_dropout_Z"
    role.vectors.append({
        "name": name, "what": "З at 3.5 V (KPT-5 feed end), 1 s without code at the joint, З at 0.28 V (KPT-7 entry end)",
        "parameters": alsn_params, "step": {"fs_hz": FS_HZ}, "duration_s": before_s + gap_s + after_s,
        "inputs": {"e_coil": role.samples(name, "e_coil", emf)},
        "checks": [
            {"kind": "latency", "label": "shows З within two cycles + 0.5 s", "from_s": 0.0, "until": _shows(sig.GREEN),
             "bound_s": 2 * CYCLE_S["KPT-5"] + 0.5},
            {"kind": "holds", "label": "З held through the joint (display hold)", "from_s": before_s - 0.5,
             "conditions": _shows(sig.GREEN), "bound_s": 0.0}]})

    for system_name in ("FIRE_DQPSK", "ALS-EN"):
        role.vectors.extend(_digital_receiver_vectors(role, system_name))
    role.vectors.extend(_alsu_receiver_vectors(role))
    role.vectors.extend(_tvm430_receiver_vectors(role))
    return role


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
    params = {"system": "ALSU", "fs": FS_HZ}

    def shows(code: int) -> list:
        ind = system.indication(code, "passenger")
        return [_cond("aspect", [ind.aspect]), _cond("free_blocks", [ind.free_blocks]), _cond("code_valid", [1])]

    def at_most(code: int) -> list:
        ind = system.indication(code, "passenger")
        return [_cond("aspect", not_more_permissive(ind.aspect)), _rng("free_blocks", None, float(ind.free_blocks))]
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
             "until": [_cond("aspect", [sig.WHITE]), _cond("code_valid", [0])], "bound_s": DISPLAY_HOLD_S + 0.5}]})
    garbled_s = 3.0
    seconds = garbled_s + 3.0
    name = "alsu_three_tones"
    vectors.append({
        "name": name, "what": f"ALSU code 9, then from {garbled_s:g} s three tones (175, 225, 275 Hz)",
        "parameters": params, "step": {"fs_hz": FS_HZ}, "duration_s": seconds,
        "inputs": {"e_coil": role.samples(name, "e_coil", _alsu_emf(seconds, [(0.0, 9), (garbled_s, (1, 2, 3))]))},
        "checks": [
            {"kind": "latency", "label": "three tones: no code within the minimum duration + 0.3 s", "from_s": garbled_s,
             "until": [_cond("code_valid", [0])], "bound_s": MIN_DURATION_S + 0.3},
            {"kind": "holds", "label": "no code after that", "from_s": garbled_s + MIN_DURATION_S + 0.3,
             "conditions": [_cond("code_valid", [0])], "bound_s": 0.0}]})
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


def _tvm_emf(seconds: float, plan: List[tuple], noise_v: float = 0.0, seed: int = 0) -> np.ndarray:
    """Coil EMF from the TVM-430 coder core on the coder vectors' line (section 1: 1700 Hz,
    section 2: 2300 Hz) at TVM_FS_HZ: ``plan`` is (from s, {section index: (word, peak V)}) in
    time order, sent through the core's test generator (each change phase-continuous, as in
    service); a section not listed is silent; plus white noise of ``noise_v`` rms."""
    from fmus.wayside_coder.tvm430 import Tvm430CoderCore

    coder = Tvm430CoderCore(_tvm_line_loaded(), 8, FRAME, CoderSettings(fs_hz=TVM_FS_HZ, seed=1))
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
    from fmus.loco_receiver.tvm430 import HOLD_S, HOP_S, STATED_DECODE_S, STATED_LATENCY_S
    from fmus.signalling import tvm430

    tvm = tvm430.system()
    table = tvm.table
    params = {"system": "TVM430", "fs": TVM_FS_HZ}
    step = {"fs_hz": TVM_FS_HZ}
    decode_s, latency_s = round(STATED_DECODE_S, 4), round(STATED_LATENCY_S, 4)

    def word(step_kmh: float, next_kmh: float, distance_m: float, gradient_permille: float) -> int:
        return tvm430.assemble(table.addresses[0], table.speed_code(step_kmh, next_kmh),
                               table.distance_code(distance_m), table.gradient_code(gradient_permille))

    def near(port: str, value: float, tolerance: float) -> dict:
        return _rng(port, round(value - tolerance, 6), round(value + tolerance, 6))

    def meaning(w: int, carrier_hz: float) -> list:
        """The outputs of word ``w`` shown from ``carrier_hz`` (speeds to 0.01 m/s, distance to
        0.5 m, gradient to 0.05 ‰, carrier to 0.5 Hz)."""
        read = tvm.reading(w)
        return [_cond("aspect", [read.aspect]), near("v_permitted", read.step_kmh / 3.6, 0.01),
                near("v_target", read.next_kmh / 3.6, 0.01), near("target_distance", read.target_distance_m, 0.5),
                near("gradient", read.gradient_permille, 0.05), near("word_carrier", carrier_hz, 0.5)]

    def shows(w: int, carrier_hz: float) -> list:
        return [*meaning(w, carrier_hz), _cond("code_valid", [1])]

    def at_most(w: int) -> list:
        """Nothing more permissive than ``w``: its aspect or a more restrictive one, its step, next
        step and target distance or less (no word: all 0)."""
        read = tvm.reading(w)
        return [_cond("aspect", not_more_permissive(read.aspect)),
                _rng("v_permitted", None, round(read.step_kmh / 3.6 + 0.01, 6)),
                _rng("v_target", None, round(read.next_kmh / 3.6 + 0.01, 6)),
                _rng("target_distance", None, read.target_distance_m + 0.5)]

    no_word = [_cond("code_valid", [0]), _rng("v_permitted", None, 0.01), _cond("aspect", not_more_permissive(sig.RED))]
    own, neighbour = 0, 1                                     # sections: 1700 Hz, 2300 Hz
    own_hz = float(_tvm_line()["block_sections"][own]["carrier_hz"])
    level_v = 0.3                                             # a carrier at the coils (peak)
    clear = word(300, 300, 7000.0, 0.0)                       # no target in range
    yellow = word(230, 170, 2750.0, -6.0)                     # two blocks before the target, falling 6 ‰
    vectors = []

    change_s, loss_s = 4.0, 7.5
    seconds = round(loss_s + STATED_LATENCY_S + 0.5, 1)
    hold_to_s = round(loss_s + HOLD_S - HOP_S, 4)
    name = "tvm430_300_then_230_then_loss"
    vectors.append({
        "name": name, "what": f"TVM-430 on the {own_hz:g} Hz carrier at {level_v:g} V: 300/300 (no target) from "
                              f"cold, 230/170 (target 2750 m, −6 ‰) from {change_s:g} s, no carrier from {loss_s:g} s",
        "parameters": params, "step": step, "duration_s": seconds,
        "inputs": {"e_coil": role.samples(name, "e_coil", _tvm_emf(
            seconds, [(0.0, {own: (clear, level_v)}), (change_s, {own: (yellow, level_v)}), (loss_s, {})]))},
        "checks": [
            {"kind": "latency", "label": "300/300 shown with its reading within the stated decode time",
             "from_s": 0.0, "until": shows(clear, own_hz), "bound_s": decode_s},
            {"kind": "latency", "label": "restrictive change to 230/170 within the stated decode time",
             "from_s": change_s, "until": shows(yellow, own_hz), "bound_s": decode_s},
            {"kind": "holds", "label": "never more permissive than 230/170 after the stated decode time",
             "from_s": round(change_s + decode_s, 4), "conditions": at_most(yellow), "bound_s": 0.0},
            {"kind": "holds", "label": "lost carrier: the word held for the hold less one decision (it bridges a "
                                       "separation zone)", "from_s": loss_s, "to_s": hold_to_s,
             "conditions": [_cond("code_valid", [1])], "bound_s": 0.0},
            {"kind": "latency", "label": "lost carrier: no word (step 0, code_valid false) within the stated latency",
             "from_s": loss_s, "until": no_word, "bound_s": latency_s}]})

    seconds, leak, noise_v = 5.0, 0.1, 0.03
    name = "tvm430_neighbour_20dB_permissive"
    vectors.append({
        "name": name, "what": f"230/170 on the {own_hz:g} Hz carrier at {level_v:g} V, the next block's 2300 Hz "
                              f"carrier 20 dB down with 300/300, white noise {noise_v:g} V rms",
        "parameters": params, "step": step, "duration_s": seconds,
        "inputs": {"e_coil": role.samples(name, "e_coil", _tvm_emf(
            seconds, [(0.0, {own: (yellow, level_v), neighbour: (clear, leak * level_v)})], noise_v, seed=43))},
        "checks": [
            {"kind": "latency", "label": "230/170 shown from its own carrier within the stated decode time",
             "from_s": 0.0, "until": shows(yellow, own_hz), "bound_s": decode_s},
            {"kind": "holds", "label": "the neighbour's 300/300 never shown (nothing more permissive, never its carrier)",
             "conditions": [*at_most(yellow), _rng("word_carrier", None, own_hz + 0.5)], "bound_s": 0.0}]})

    # two bits of the speed field flipped: without the check the word would read 230/230
    speed_low = tvm430.FIELDS["speed"][0]
    flips = (1 << speed_low) | (1 << (speed_low + 4))
    corrupted = yellow ^ flips
    assert not tvm430.check_passes(corrupted)
    assert table.speed_codes[tvm430.field(corrupted, "speed")] == (230.0, 230.0)
    corrupt_s = 3.0
    seconds = round(corrupt_s + STATED_LATENCY_S + 0.5, 1)
    name = "tvm430_double_bit_error"
    vectors.append({
        "name": name, "what": f"230/170 on the {own_hz:g} Hz carrier at {level_v:g} V, from {corrupt_s:g} s with "
                              f"word bits {speed_low} and {speed_low + 4} flipped (its speed field reads 230/230; "
                              f"the check fails)",
        "parameters": params, "step": step, "duration_s": seconds,
        "inputs": {"e_coil": role.samples(name, "e_coil", _tvm_emf(
            seconds, [(0.0, {own: (yellow, level_v)}), (corrupt_s, {own: (corrupted, level_v)})]))},
        "checks": [
            {"kind": "latency", "label": "230/170 shown within the stated decode time", "from_s": 0.0,
             "until": shows(yellow, own_hz), "bound_s": decode_s},
            {"kind": "holds", "label": "the corrupted word never shown: any word shown reads 230/170",
             "where": [_cond("code_valid", [1])], "conditions": meaning(yellow, own_hz), "bound_s": 0.0},
            {"kind": "latency", "label": "corrupted word: no word (step 0, code_valid false) within the stated latency",
             "from_s": corrupt_s, "until": no_word, "bound_s": latency_s}]})
    return vectors


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
                 "until": [_cond("aspect", [first[1]]), _cond("free_blocks", [first[2]]), _cond("code_valid", [1])],
                 "bound_s": round(acquire_s, 4)},
                {"kind": "latency", "label": "restrictive change within the stated latency", "from_s": change_s,
                 "until": [_cond("aspect", [last[1]]), _cond("free_blocks", [last[2]]), _cond("code_valid", [1])],
                 "bound_s": round(latency_s, 4)},
                {"kind": "holds", "label": "never more permissive after the stated latency",
                 "from_s": round(change_s + latency_s, 4),
                 "conditions": [_cond("aspect", not_more_permissive(int(last[1]))),
                                _rng("free_blocks", None, float(last[2]))], "bound_s": 0.0}]})
    return vectors


# ---- traction -----------------------------------------------------------------------------------
def _traction_core(**kwargs):
    from fmus.traction.core import TractionCore

    return TractionCore(load_rolling_stock(str(DEFAULT_ROLLING_STOCK)), load_line(str(DEFAULT_LINE)), **kwargs)


def _drive(core, seconds: float, step_s: float, schedule: Callable[[float], tuple]) -> np.ndarray:
    """Rows (t_end, x, v, a) of the traction core under a (command, emergency) schedule."""
    rows = []
    for k in range(int(round(seconds / step_s))):
        t = k * step_s
        command, emergency = schedule(t)
        out = core.step(t, step_s, command, emergency)
        rows.append((t + step_s, out.x_m, out.v_mps, out.a_mps2))
    return np.array(rows)


def _schedule_input(times: List[float], values: List) -> dict:
    return {"times_s": times, "values": values}


def _ideal_brake_stock(decel_mps2: float) -> dict:
    """The bundled EMU made an ideal brake: no resistance to speak of, no rotating mass, the
    full service brake at once and exactly ``decel_mps2`` (the ATO book's constant-deceleration
    examples, docs/traction.md#our-figures-beside-the-sources)."""
    stock = json.loads((DEFAULT_ROLLING_STOCK.parent / "emu_er2.json").read_text(encoding="utf-8"))
    stock["name"] = f"ideal brake {decel_mps2:g} m/s2 (conformance vectors)"
    stock["rotating_mass_factor"] = 0.0
    for unit in stock["units"]:
        unit["resistance"] = {"a": 1e-9, "b": 0.0, "c": 0.0, "per_axle_load": [0.0, 0.0, 0.0]}
    stock["traction"]["auxiliary_kw"] = 0
    stock["pneumatic_brake"].update(service_decel_mps2=decel_mps2, delay_s=0.0, time_constant_s=0.0)
    return stock


def _flat_line() -> dict:
    line = json.loads(DEFAULT_LINE.read_text(encoding="utf-8"))
    line["name"] = "the bundled line made level and straight (conformance vectors)"
    line["gradients"], line["curves"] = [{"start_m": 0, "permille": 0.0}], []
    return line


#: the ATO book's stops from 80 km/h at a constant deceleration: distance, time (docs/traction.md)
BOOK_STOPS = {0.3: (822.0, 74.0), 0.5: (493.0, 44.4)}


def traction_vectors() -> RoleFile:
    role = RoleFile("traction", ["rolling_stock_file", "line_file", "x0", "v0", "command", "emergency_brake",
                                 "x", "v", "a", "stop_time"])
    # the book's braking examples through the FMU's own data-file parameters, at 0.1 s and 1 s
    role.data_files["traction_flat_line.json"] = _flat_line()
    v0 = 80.0 / 3.6
    for decel, (book_m, book_s) in BOOK_STOPS.items():
        stock_file = f"traction_ideal_brake_{decel:g}.json"
        role.data_files[stock_file] = _ideal_brake_stock(decel)
        exact_m, exact_s = v0 ** 2 / (2 * decel), v0 / decel
        for step_s in (0.1, 1.0):
            stopped = [_rng("v", None, 0.0)]
            role.vectors.append({
                "name": f"book_stop_80kmh_{decel:g}mps2_step{step_s:g}s",
                "what": f"ideal brake of {decel:g} m/s² from 80 km/h on a level line, step {step_s:g} s "
                        f"(the ATO book: {book_m:g} m, {book_s:g} s)",
                "parameters": {"rolling_stock_file": stock_file, "line_file": "traction_flat_line.json",
                               "x0": 1000.0, "v0": v0},
                "step": {"step_s": step_s}, "duration_s": round(exact_s + 10.0),
                "inputs": {"command": _schedule_input([0.0], [-1.0])},
                "checks": [
                    {"kind": "when", "label": f"stopping distance (v²/2a = {exact_m:.2f} m; book {book_m:g} m)",
                     "trigger": stopped, "port": "x", "expected": round(1000.0 + exact_m, 4), "tolerance": 1.5,
                     "unit": "m"},
                    {"kind": "when", "label": f"stopping time (v/a = {exact_s:.2f} s; book {book_s:g} s)",
                     "trigger": stopped, "port": "stop_time", "expected": round(exact_s, 4), "tolerance": 0.25,
                     "unit": "s"},
                    {"kind": "extreme", "label": "speed never negative", "port": "v", "extreme": "min",
                     "at_least": 0.0, "unit": "m/s"}]})
    # braking: from 80 km/h (service, command −1) and 100 km/h (emergency) to a stop; stopping
    # distance and time against our core (the braking model of docs/traction.md), speed never negative
    for name, v0_kmh, command, emergency in (("service_brake_80kmh", 80.0, -1.0, False),
                                             ("emergency_brake_100kmh", 100.0, 0.0, True)):
        step_s, seconds = 0.5, 90.0
        rows = _drive(_traction_core(x0_m=2000.0, v0_mps=v0_kmh / 3.6), seconds, step_s,
                      lambda t, c=command, e=emergency: (c, e))
        stopped = rows[np.flatnonzero(rows[:, 2] <= 0.0)[0]]
        role.vectors.append({
            "name": name, "what": f"from {v0_kmh:g} km/h at 2000 m, {'emergency brake' if emergency else 'full service brake'} to a stop",
            "parameters": {"x0": 2000.0, "v0": v0_kmh / 3.6}, "step": {"step_s": step_s}, "duration_s": seconds,
            "inputs": {"command": _schedule_input([0.0], [command]),
                       "emergency_brake": _schedule_input([0.0], [emergency])},
            "checks": [
                {"kind": "when", "label": "stopping point (reference train model)", "trigger": [_rng("v", None, 0.0)],
                 "port": "x", "expected": float(stopped[1]), "tolerance": 2.0, "unit": "m"},
                {"kind": "latency", "label": "stopped within the reference time + one step", "from_s": 0.0,
                 "until": [_rng("v", None, 0.0)], "bound_s": float(stopped[0]) + step_s},
                {"kind": "extreme", "label": "speed never negative", "port": "v", "extreme": "min",
                 "at_least": 0.0, "unit": "m/s"}]})
    # balancing speed: the bundled freight train at full traction on a constant +6 ‰ of the AC
    # line, from 70 km/h; the speed it settles at against the book's balance of forces
    # F(v) = (P + Q)·(w0(v) + i) (docs/traction.md#our-figures-beside-the-sources), solved with
    # the train's own effort and resistance
    from scipy.optimize import brentq

    from fmus.traction.core import TractionCore

    grade = 6.0
    ac_line = json.loads((DEFAULT_LINE.parent / "default_line_ac.json").read_text(encoding="utf-8"))
    ac_line["name"] = f"the bundled AC line at a constant +{grade:g} permille (conformance vectors)"
    ac_line["gradients"], ac_line["curves"] = [{"start_m": 0, "permille": grade}], []
    role.data_files["traction_ac_line_6permille.json"] = ac_line
    freight = load_rolling_stock(str(DEFAULT_ROLLING_STOCK.parent / "freight_vl80.json"))
    probe = TractionCore(freight, load_line(str(DEFAULT_LINE.parent / "default_line_ac.json")))
    v_bal = brentq(lambda v: probe.max_traction_force(v) - (probe.main_resistance(v) + grade * probe.weight_kn),
                   20.0 / 3.6, freight.max_speed_mps)
    settled_s = 1000.0
    role.vectors.append({
        "name": "balancing_speed_freight_6permille",
        "what": f"ВЛ80 + 62 wagons at full traction on +{grade:g} ‰ from 70 km/h for {settled_s:g} s, step 1 s",
        "parameters": {"rolling_stock_file": "traction_freight_vl80.json",
                       "line_file": "traction_ac_line_6permille.json", "x0": 1000.0, "v0": 70.0 / 3.6},
        "step": {"step_s": 1.0}, "duration_s": settled_s,
        "inputs": {"command": _schedule_input([0.0], [1.0])},
        "checks": [
            {"kind": "near", "label": f"settled speed against F = (P + Q)(w0 + i): {v_bal * 3.6:.2f} km/h",
             "port": "v", "at_s": [settled_s], "expected": [round(v_bal, 6)], "tolerance": 0.005, "relative": True},
            {"kind": "extreme", "label": "settled: acceleration ≥ −2e-4 m/s²", "port": "a", "extreme": "min",
             "from_s": settled_s - 10.0, "at_least": -2e-4, "unit": "m/s2"},
            {"kind": "extreme", "label": "settled: acceleration ≤ 2e-4 m/s²", "port": "a", "extreme": "max",
             "from_s": settled_s - 10.0, "at_most": 2e-4, "unit": "m/s2"}]})
    role.data_files["traction_freight_vl80.json"] = json.loads(
        (DEFAULT_ROLLING_STOCK.parent / "freight_vl80.json").read_text(encoding="utf-8"))
    # step-size robustness: one command profile at 0.1, 0.5 and 1 s; position at 120 s against
    # the 0.1 s reference within 0.5 m (docs/ato.md: the stop point between 0.1 s and 1 s steps)
    profile_t = [0.0, 60.0, 90.0]
    profile_c = [1.0, 0.0, -0.6]
    profile = lambda t: (profile_c[int(np.searchsorted(profile_t, t, side="right")) - 1], False)
    reference = _drive(_traction_core(x0_m=400.0), 120.0, 0.1, profile)
    x_ref = float(reference[-1, 1])
    for step_s in (0.1, 0.5, 1.0):
        role.vectors.append({
            "name": f"step_size_{step_s:g}s", "what": f"traction 60 s, coast 30 s, brake 0.6 for 30 s, step {step_s:g} s",
            "parameters": {"x0": 400.0, "v0": 0.0}, "step": {"step_s": step_s}, "duration_s": 120.0,
            "inputs": {"command": _schedule_input(profile_t, profile_c)},
            "checks": [{"kind": "near", "label": "position at 120 s against the 0.1 s reference", "port": "x",
                        "at_s": [120.0], "expected": [x_ref], "tolerance": 0.5, "unit": "m"}]})
    return role


# ---- wayside_coder ------------------------------------------------------------------------------
def _coder_core(block_aspects: int = 3, system: Optional[str] = None):
    line = load_line(str(DEFAULT_LINE))
    settings = CoderSettings(fs_hz=FS_HZ, block_aspects=block_aspects, seed=1)
    if system is None:
        return WaysideCoderCore(line, 8, FRAME, settings)
    return DigitalCoderCore(cab_systems.digital_system(system), line, 8, FRAME, settings)


def coder_vectors() -> RoleFile:
    role = RoleFile("wayside_coder", ["system", "fs", "block_aspects", "line_file", "occupied", "fault_main",
                                      "fault_reserve",
                                      "wrong_command_main",
                                      "u_tx", "code_tx", "signal", "status"])
    line = load_line(str(DEFAULT_LINE))
    tables = json.loads(alsn.CODES_FILE.read_text(encoding="utf-8"))["transmitters"]
    step = {"fs_hz": FS_HZ, "frame_port": "u_tx"}
    # code timings: each code of each transmitter type, two cycles and more of the keyed carrier
    for kpt in ("KPT-5", "KPT-7"):
        section = SECTION[kpt]
        carrier = line.sections[section].carrier_hz
        cycle = tables[kpt]["cycle_s"]
        for code in (sig.GREEN, sig.YELLOW, sig.RED_YELLOW):
            occupied = occupancy(code, section)
            name = f"timing_{CODE_TAG[code]}_{kpt}"
            seconds = round(2.5 * cycle + 0.5, 2)
            sent = _coder_core().step(0.0, occupied).code_tx.tolist()
            role.vectors.append({
                "name": name, "what": f"{CODE_NAME[code]} into section {section + 1} ({kpt}) for {seconds} s",
                "parameters": {"system": "ALSN", "fs": FS_HZ}, "step": step, "duration_s": seconds,
                "inputs": {"occupied": _schedule_input([0.0], [occupied.tolist()])},
                "record_frames": [f"u_tx[{section + 1}]"],
                "checks": [
                    {"kind": "table", "label": f"code_tx: {CODE_NAME[code]} into section {section + 1}", "port": "code_tx",
                     "at_s": [seconds], "expected": [sent]},
                    {"kind": "code_timing", "label": f"pulses and intervals of {CODE_NAME[code]} ({kpt}) within ±5 %",
                     "port": f"u_tx[{section + 1}]", "pattern_s": tables[kpt]["codes"][CODE_TAG[code]],
                     "tolerance": 0.05, "fs_hz": FS_HZ, "carrier_hz": carrier, "cycle_s": cycle}]})
    # block logic: occupancy patterns → signals and codes of every section, from our block rules
    for aspects in (3, 4):
        core = _coder_core(aspects)
        patterns = [np.zeros(8, dtype=bool)] + [np.eye(8, dtype=bool)[k] for k in range(8)] \
            + [np.eye(8, dtype=bool)[2] | np.eye(8, dtype=bool)[6]]
        hold_s = 0.05
        times = [round(i * hold_s, 4) for i in range(len(patterns))]
        at = [round(t + hold_s, 4) for t in times]
        signals, codes = [], []
        for pattern in patterns:
            out = core.step(0.0, pattern)
            signals.append(out.signal.tolist())
            codes.append(out.code_tx.tolist())
        role.vectors.append({
            "name": f"block_logic_{aspects}_aspect", "what": f"{len(patterns)} occupancy patterns, {aspects}-aspect block",
            "parameters": {"system": "ALSN", "fs": FS_HZ, "block_aspects": aspects}, "step": step,
            "duration_s": round(len(patterns) * hold_s, 4),
            "inputs": {"occupied": _schedule_input(times, [p.tolist() for p in patterns])},
            "checks": [{"kind": "table", "label": "signal of every section (block rules)", "port": "signal",
                        "at_s": at, "expected": signals},
                       {"kind": "table", "label": "code_tx of every section (block rules)", "port": "code_tx",
                        "at_s": at, "expected": codes}]})
    # 2-out-of-2: main fails at 1 s (reserve alone, status 1, code kept), reserve too at 2 s
    # (status 2, no code, no output)
    core = _coder_core()
    clear = np.zeros(8, dtype=bool)
    sent = core.step(0.0, clear).code_tx.tolist()
    role.vectors.append({
        "name": "two_out_of_two_faults", "what": "main transmitter fails at 1 s, the reserve at 2 s",
        "parameters": {"system": "ALSN", "fs": FS_HZ}, "step": step, "duration_s": 3.0,
        "inputs": {"fault_main": _schedule_input([0.0, 1.0], [False, True]),
                   "fault_reserve": _schedule_input([0.0, 2.0], [False, True])},
        "record_frames": ["u_tx[1]"],
        "checks": [
            {"kind": "table", "label": "status 0, 1, 2", "port": "status", "at_s": [1.0, 2.0, 3.0],
             "expected": [[0], [1], [2]]},
            {"kind": "table", "label": "codes kept on the reserve, none when both failed", "port": "code_tx",
             "at_s": [1.0, 2.0, 3.0], "expected": [sent, sent, [0] * 8]},
            {"kind": "frame_peak", "label": "reserve transmits (section 1)", "port": "u_tx[1]", "from_s": 1.0,
             "to_s": 2.0, "at_least": 0.5 * CoderSettings().amplitude_v, "unit": "V"},
            {"kind": "frame_peak", "label": "no output with both failed (section 1)", "port": "u_tx[1]",
             "from_s": 2.0, "at_most": 0.0, "unit": "V"}]})
    role.vectors.extend(_alsu_coder_vectors())
    role.data_files[TVM_LINE_FILE] = _tvm_line()
    role.vectors.extend(_tvm430_coder_vectors())
    # digital 2-out-of-2 comparison: a controller computing a wrong command is outvoted by the
    # more restrictive of the two (fmus/signalling/redundancy.py); expected from our core
    for system_name in ("FIRE_DQPSK", "ALS-EN"):
        system = cab_systems.digital_system(system_name)
        wrong = max(system.commands(), key=system.rank)          # the most permissive command
        core = _coder_core(system=system_name)
        healthy = core.step(0.0, occupancy(sig.RED_YELLOW, 0)).code_tx.tolist()
        faulty = core.step(0.01, occupancy(sig.RED_YELLOW, 0), wrong_command_main=wrong).code_tx.tolist()
        role.vectors.append({
            "name": f"{system_name.lower().replace('-', '_')}_wrong_command", "what":
                f"{system_name}: section 2 occupied; from 0.5 s the main controller computes command {wrong} everywhere",
            "parameters": {"system": system_name, "fs": FS_HZ}, "step": step, "duration_s": 1.0,
            "inputs": {"occupied": _schedule_input([0.0], [occupancy(sig.RED_YELLOW, 0).tolist()]),
                       "wrong_command_main": _schedule_input([0.0, 0.5], [0, wrong])},
            "checks": [{"kind": "table", "label": "the 2-out-of-2 sends the more restrictive command",
                        "port": "code_tx", "at_s": [0.5, 1.0], "expected": [healthy, faulty]},
                       {"kind": "table", "label": "status stays 0", "port": "status", "at_s": [1.0],
                        "expected": [[0]]}]})
    return role


def _alsu_coder_vectors() -> List[dict]:
    """ALSU: the block's codes of every section (4-aspect, from our block rules) and the two
    tones a code sends (docs/wayside_coder.md#alsu)."""
    from fmus.signalling import alsu
    from fmus.wayside_coder.alsu import AlsuCoderCore

    line = load_line(str(DEFAULT_LINE))
    params = {"system": "ALSU", "fs": FS_HZ, "block_aspects": 4}
    step = {"fs_hz": FS_HZ, "frame_port": "u_tx"}
    core = AlsuCoderCore(line, 8, FRAME, CoderSettings(fs_hz=FS_HZ, block_aspects=4, seed=1))
    patterns = [np.zeros(8, dtype=bool)] + [np.eye(8, dtype=bool)[k] for k in range(1, 8)]
    hold_s = 0.05
    times = [round(i * hold_s, 4) for i in range(len(patterns))]
    at = [round(t + hold_s, 4) for t in times]
    codes = [core.step(0.0, pattern).code_tx.tolist() for pattern in patterns]
    vectors = [{
        "name": "alsu_block_logic_4_aspect", "what": f"{len(patterns)} occupancy patterns, ALSU on a 4-aspect block",
        "parameters": params, "step": step, "duration_s": round(len(patterns) * hold_s, 4),
        "inputs": {"occupied": _schedule_input(times, [p.tolist() for p in patterns])},
        "checks": [{"kind": "table", "label": "ALSU code of every section (block rules)", "port": "code_tx",
                    "at_s": at, "expected": codes}]}]
    tones = list(alsu.system().table.tones_hz)
    amplitude = CoderSettings().amplitude_v
    change_s, seconds = 1.0, 2.0
    first = core.tone_mask[int(_coder_codes(core, np.zeros(8, dtype=bool))[0])]
    occupied = np.eye(8, dtype=bool)[1]
    second = core.tone_mask[int(_coder_codes(core, occupied)[0])]
    checks = []
    for (start, end), flags in (((0.1, change_s), first), ((change_s + 0.1, seconds), second)):
        code = next(n for n in range(16) if (core.tone_mask[n] == flags).all())
        checks.append({"kind": "tones", "label": f"section 1 sends code {code}: its two tones, no other",
                       "port": "u_tx[1]", "from_s": start, "to_s": end, "fs_hz": FS_HZ, "frequencies_hz": tones,
                       "present": [f for f, on in zip(tones, flags) if on], "at_least": 0.98 * amplitude,
                       "at_most": 0.02 * amplitude, "unit": "V"})
    vectors.append({
        "name": "alsu_tones_section_1", "what": f"the line clear, then section 2 occupied from {change_s:g} s: "
                                                f"the tones into section 1",
        "parameters": params, "step": step, "duration_s": seconds,
        "inputs": {"occupied": _schedule_input([0.0, change_s], [np.zeros(8, dtype=bool).tolist(), occupied.tolist()])},
        "record_frames": ["u_tx[1]"], "checks": checks})
    return vectors


TVM_LINE_FILE = "wayside_coder_tvm430_line.json"
#: the 4 kHz of the other vectors cannot hold a 2300 Hz carrier. 8 kHz, not the TVM chain's 12
#: kHz: a sample is 125 µs, so a target's step N/fs is a whole number of nanoseconds for any
#: frame N (at 12 kHz only for N a multiple of 3, and the default N is 40); the receiver works
#: at any fs ≥ 5.1 kHz on track 1 (docs/loco_receiver.md#tvm-430)
TVM_FS_HZ = 8000.0


def _tvm_line() -> dict:
    """8 blocks of 1500 m on track 1 (UM71 circuits, carriers 1700 / 2300 Hz alternating, a
    separation zone at every boundary), a 10 ‰ fall from 4 km, the station stop near the end:
    every TVM-430 speed pair within 8 sections."""
    blocks = [{"name": f"B{b + 1}", "start_m": 1500.0 * b, "end_m": 1500.0 * (b + 1), "signal": f"M{b + 1}",
               "transmitter": "UM71", "carrier_hz": (1700, 2300)[b % 2], "ballast_ohm_km": 2.0} for b in range(8)]
    return {"name": "TVM-430 coder vectors", "length_m": 12000.0, "electrification": {"system": "AC25000"},
            "block_sections": blocks, "separation_zones": [{"position_m": 1500.0 * b} for b in range(1, 8)],
            "stations": [{"name": "end", "stop_m": 11800.0}],
            "gradients": [{"start_m": 0, "permille": 0.0}, {"start_m": 4000, "permille": -10.0}], "curves": [],
            "speed_limits": [{"start_m": 0, "passenger_kmh": 160, "freight_kmh": 90, "high_speed_kmh": 300}]}


def _tvm_line_loaded():
    """_tvm_line() as the loader reads it."""
    import tempfile

    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / TVM_LINE_FILE
        path.write_text(json.dumps(_tvm_line()), encoding="utf-8")
        return load_line(str(path))


def _tvm430_coder_vectors() -> List[dict]:
    """TVM-430: the block rules' word of every section for a train in each block, and the word's
    tones on section 1's carrier before and after a change, with no phase step at the change
    (docs/wayside_coder.md#tvm-430)."""
    from fmus.signalling import tvm430
    from fmus.wayside_coder.tvm430 import PEAK_DEVIATION_HZ, Tvm430CoderCore

    line = _tvm_line_loaded()
    params = {"system": "TVM430", "fs": TVM_FS_HZ, "line_file": TVM_LINE_FILE}
    step = {"fs_hz": TVM_FS_HZ, "frame_port": "u_tx"}
    core = Tvm430CoderCore(line, 8, FRAME, CoderSettings(fs_hz=TVM_FS_HZ, seed=1))
    patterns = [np.zeros(8, dtype=bool)] + [np.eye(8, dtype=bool)[k] for k in range(8)]
    hold_s = 0.05
    times = [round(i * hold_s, 4) for i in range(len(patterns))]
    at = [round(t + hold_s, 4) for t in times]
    words = [core.step(0.0, pattern).code_tx.tolist() for pattern in patterns]
    vectors = [{
        "name": "tvm430_block_words", "what": f"{len(patterns)} occupancy patterns (the line clear, a train in each "
                                              f"block) on an 8-block TVM-430 line",
        "parameters": params, "step": step, "duration_s": round(len(patterns) * hold_s, 4),
        "inputs": {"occupied": _schedule_input(times, [p.tolist() for p in patterns])},
        "checks": [{"kind": "table", "label": "TVM-430 word of every section (block rules)", "port": "code_tx",
                    "at_s": at, "expected": words}]}]
    change_s, seconds = 3.0, 6.0
    clear, occupied = np.zeros(8, dtype=bool), np.eye(8, dtype=bool)[2]
    first, second = (int(core.step(0.0, pattern).code_tx[0]) for pattern in (clear, occupied))
    carrier = float(line.sections[0].carrier_hz)
    tones = [round(float(f), 2) for f in tvm430.TONES_HZ]
    checks = []
    for (start, end), word in (((0.2, change_s - 0.2), first), ((change_s + 0.2, seconds - 0.2), second)):
        bits = tvm430.bits_of(word)
        checks.append({"kind": "fm_tones", "label": f"section 1 sends word {word}: its tones, no other",
                       "port": "u_tx[1]", "from_s": start, "to_s": end, "fs_hz": TVM_FS_HZ, "carrier_hz": carrier,
                       "frequencies_hz": tones, "present": [f for f, bit in zip(tones, bits) if bit],
                       "at_least": 0.9 * tvm430.DEVIATION_HZ_PER_TONE,
                       "at_most": 0.1 * tvm430.DEVIATION_HZ_PER_TONE, "unit": "Hz"})
    checks.append({"kind": "frequency_excursion", "label": "no phase step at the word change: the carrier stays "
                                                          f"within ±{PEAK_DEVIATION_HZ:g} Hz",
                   "port": "u_tx[1]", "from_s": 0.2, "to_s": seconds - 0.2, "fs_hz": TVM_FS_HZ,
                   "carrier_hz": carrier, "at_most": PEAK_DEVIATION_HZ, "unit": "Hz"})
    vectors.append({
        "name": "tvm430_word_section_1", "what": f"the line clear, then block 3 occupied from {change_s:g} s: "
                                                 f"the word's tones on section 1's {carrier:g} Hz carrier",
        "parameters": params, "step": step, "duration_s": seconds,
        "inputs": {"occupied": _schedule_input([0.0, change_s], [clear.tolist(), occupied.tolist()])},
        "record_frames": ["u_tx[1]"], "checks": checks})
    return vectors


def _coder_codes(core, occupied: np.ndarray) -> np.ndarray:
    return core.step(0.0, occupied).code_tx.copy()


# ---- rail_line ----------------------------------------------------------------------------------
OFF_LINE_M = -1000.0


def _coder_stream(seconds: float) -> np.ndarray:
    """The coder core's output for a free line (З into every section), K × samples."""
    coder = _coder_core()
    frames = [coder.step(k * FRAME / FS_HZ, np.zeros(8, dtype=bool)).u_tx.copy()
              for k in range(int(round(seconds * FS_HZ / FRAME)))]
    return np.concatenate(frames, axis=1)


def _rail_run(u_tx: np.ndarray, schedule: Callable[[float], tuple]):
    """Our rail-line core fed as the runner feeds a target: per frame (t_end, i_axle[1],
    occupied[1..8]) and train 1's coil EMF samples; ``schedule(t)`` → (x_head, v, broken_rail_at)."""
    from fmus.rail_line.core import RailLineCore, RailSettings

    core = RailLineCore(load_line(str(DEFAULT_LINE)), 8, 2, FRAME, RailSettings(fs_hz=FS_HZ))
    core.start(np.array([OFF_LINE_M, OFF_LINE_M]))
    rows, emf = [], []
    for k in range(u_tx.shape[1] // FRAME):
        t = k * FRAME / FS_HZ
        x_head, v, broken = schedule(t)
        core.set_faults(broken, np.zeros(8), np.zeros(8, dtype=bool))
        out = core.step(t, u_tx[:, k * FRAME:(k + 1) * FRAME], np.array([x_head, OFF_LINE_M]), np.array([v, 0.0]),
                        np.zeros(2))
        rows.append((t + FRAME / FS_HZ, out.i_axle[0], *out.occupied.astype(int)))
        emf.append(out.e_coil[0].copy())
    return np.array(rows), np.concatenate(emf)


def _check_worked_example() -> None:
    """two_port reproduces the sourced worked example (docs/sources.md#track-circuits-and-rail-impedance:
    z = 0.52 + j1.224 Ω/km, 1 Ω·km, 0.3 km → A 1.023 + j0.055, B 0.151 + j0.373 Ω, C 0.302 + j0.006 S)."""
    from fmus.rail_line.track_circuit import two_port

    abcd = two_port(0.52 + 1.224j, 1.0, 0.3)
    for got, want, tol in ((abcd[0, 0], 1.023 + 0.055j, 1e-3), (abcd[0, 1], 0.151 + 0.373j, 1.5e-3),
                           (abcd[1, 0], 0.302 + 0.006j, 1e-3)):
        if abs(got - want) > tol:
            raise RuntimeError(f"two_port no longer reproduces the worked example: {got} against {want}")


def rail_vectors() -> RoleFile:
    role = RoleFile("rail_line", ["fs", "transformer_ratio", "u_tx", "x_head", "v", "broken_rail_at", "e_coil",
                                  "occupied", "i_axle"])
    step = {"fs_hz": FS_HZ, "frame_port": "u_tx"}
    params = {"fs": FS_HZ}
    # the two-port cascade of the worked example's method: a steady 1 V 50 Hz carrier into
    # section 4 (transformer ratio 1), a standing 400 m train (the default rolling stock's
    # wheelsets at their axles) at five places; the rms of i_axle over each place against the
    # cascade's current (amplitude / √2), within 1 % (docs/rail_line.md#validation)
    from fmus.rail_line.core import RailLineCore, RailSettings

    _check_worked_example()
    line = load_line(str(DEFAULT_LINE))
    plant = RailLineCore(line, 8, 2, FRAME, RailSettings(fs_hz=FS_HZ, transformer_ratio=1.0))
    section, carrier = 3, line.sections[3].carrier_hz
    circuit = plant.circuits[section]
    places = [7850.0, 8600.0, 9137.0, 9900.0, 10350.0]
    place_s = 0.6
    seconds = place_s * len(places)
    u_tx = np.zeros((8, int(round(seconds * FS_HZ))))
    u_tx[section] = np.sin(2 * np.pi * carrier * np.arange(u_tx.shape[1]) / FS_HZ)
    expected = [cascade_shunt_current(circuit, x, carrier_hz=carrier, wheelsets_m=plant.settings.wheelset_offsets_m[0])
                / np.sqrt(2.0) for x in places]
    name = "two_port_first_axle"
    role.vectors.append({
        "name": name, "what": f"1 V {carrier:g} Hz steady into section {section + 1}, transformer ratio 1; a standing "
                              f"400 m train at {', '.join(f'{x:g}' for x in places)} m, {place_s:g} s each",
        "parameters": {**params, "transformer_ratio": 1.0}, "step": step, "duration_s": seconds,
        "inputs": {"u_tx": role.samples(name, "u_tx", u_tx),
                   "x_head": _schedule_input([round(i * place_s, 4) for i in range(len(places))], [[x] for x in places]),
                   "v": _schedule_input([0.0], [[0.0]])},
        "checks": [{"kind": "near", "label": "i_axle[1] (rms) against the two-port cascade", "port": "i_axle[1]",
                    "windows": [[round(i * place_s + 0.4, 4), round((i + 1) * place_s, 4)] for i in range(len(places))],
                    "statistic": "rms", "expected": [round(e, 9) for e in expected], "tolerance": 0.01,
                    "relative": True}]})
    # the keyed code current under the first axle of a standing train at three places in
    # section 1: its rms over whole code cycles against our plant (which follows the two-port
    # cascade within 0.5 %, above); bound 1 %. The port is
    # an rms over each frame, so the rms of the frames' values is the window's at any frame size
    hold_s, heads = 2 * CYCLE_S["KPT-5"] + 0.4, [900.0, 1800.0, 2500.0]
    seconds = hold_s * len(heads)
    u_tx = _coder_stream(seconds)
    place = lambda t: (heads[min(int(t // hold_s), len(heads) - 1)], 0.0, -1.0)
    rows, _ = _rail_run(u_tx, place)
    windows = [[round(i * hold_s + 0.4, 4), round((i + 1) * hold_s, 4)] for i in range(len(heads))]
    rms = [float(np.sqrt(np.mean(rows[(rows[:, 0] > lo + 1e-9) & (rows[:, 0] <= hi + 1e-9), 1] ** 2)))
           for lo, hi in windows]
    name = "code_current_first_axle"
    role.vectors.append({
        "name": name, "what": f"З (4 V) into every section; a standing train's head at {', '.join(f'{h:g}' for h in heads)} m, {hold_s:g} s each",
        "parameters": params, "step": step, "duration_s": seconds,
        "inputs": {"u_tx": role.samples(name, "u_tx", u_tx),
                   "x_head": _schedule_input([i * hold_s for i in range(len(heads))], [[h] for h in heads]),
                   "v": _schedule_input([0.0], [[0.0]])},
        "checks": [{"kind": "near", "label": "i_axle[1], rms over two code cycles at each place (our plant)",
                    "port": "i_axle[1]", "windows": windows, "statistic": "rms", "expected": rms,
                    "tolerance": 0.01, "relative": True}]})
    # the track relays: normal (free), shunt (a train in section 3), control (a broken rail in
    # section 4) modes, 2 s each
    mode_s = 2.0
    phases = [(OFF_LINE_M, -1.0), (6000.0, -1.0), (OFF_LINE_M, 9000.0)]
    seconds = mode_s * len(phases)
    u_tx = _coder_stream(seconds)
    rows, _ = _rail_run(u_tx, lambda t: (*phases[min(int(t // mode_s), 2)][:1], 0.0, phases[min(int(t // mode_s), 2)][1]))
    at = [mode_s * (i + 1) for i in range(len(phases))]
    expected = [rows[int(round(a * FS_HZ / FRAME)) - 1, 2:].astype(int).tolist() for a in at]
    assert expected == [[0] * 8, [0, 0, 1, 0, 0, 0, 0, 0], [0, 0, 0, 1, 0, 0, 0, 0]], expected
    name = "track_circuit_modes"
    role.vectors.append({
        "name": name, "what": "free line (normal mode), a train with its head at 6000 m (shunt mode), "
                              "a broken rail at 9000 m (control mode), 2 s each",
        "parameters": params, "step": step, "duration_s": seconds,
        "inputs": {"u_tx": role.samples(name, "u_tx", u_tx),
                   "x_head": _schedule_input([i * mode_s for i in range(3)], [[p[0]] for p in phases]),
                   "v": _schedule_input([0.0], [[0.0]]),
                   "broken_rail_at": _schedule_input([i * mode_s for i in range(3)], [p[1] for p in phases])},
        "checks": [{"kind": "table", "label": "occupied: none; section 3; section 4", "port": "occupied",
                    "at_s": at, "expected": expected}]})
    # the joint between sections 1 and 2 (2600 m) passed at 20 m/s: the coil EMF vanishes in
    # the null zone between the feed leads and the joint (docs/rail_line.md)
    seconds, speed, start = 4.0, 20.0, 2540.0
    u_tx = _coder_stream(seconds)
    rows, emf = _rail_run(u_tx, lambda t: (start + speed * t, speed, -1.0))
    frame_peak = np.abs(emf).reshape(-1, FRAME).max(axis=1)
    t_end = rows[:, 0]
    near_joint = np.abs(t_end - (2600.0 - 1.5 - start) / speed) < 0.1
    null = np.flatnonzero(near_joint & (frame_peak == 0.0))
    null_window = [round(float(t_end[null[0]] - FRAME / FS_HZ), 4), round(float(t_end[null[-1]]), 4)]
    entry_level = float(frame_peak[t_end > 3.2].max())
    name = "joint_null_zone"
    role.vectors.append({
        "name": name, "what": f"З into every section; a train from {start:g} m at {speed:g} m/s across the joint at 2600 m",
        "parameters": params, "step": step, "duration_s": seconds,
        "inputs": {"u_tx": role.samples(name, "u_tx", u_tx),
                   "x_head": _schedule_input([0.0], [[start]]), "v": _schedule_input([0.0], [[speed]])},
        "record_frames": ["e_coil[1]"],
        "checks": [
            {"kind": "frame_peak", "label": "code before the joint (≥ half our core's level)", "port": "e_coil[1]",
             "from_s": 1.0, "to_s": 2.5, "at_least": 0.5 * float(frame_peak[(t_end > 1.0) & (t_end <= 2.5)].max()),
             "unit": "V"},
            {"kind": "frame_peak", "label": "null zone: EMF ≤ 5 % of the next section's entry level",
             "port": "e_coil[1]", "from_s": null_window[0], "to_s": null_window[1],
             "at_most": round(0.05 * entry_level, 6), "unit": "V"},
            {"kind": "frame_peak", "label": "next section's code after the joint (≥ half our core's level)",
             "port": "e_coil[1]", "from_s": 3.2, "at_least": 0.5 * entry_level, "unit": "V"}]})
    return role


# ---- ato_controller -----------------------------------------------------------------------------
ARRIVAL_TOLERANCE_S, STOP_TOLERANCE_M = 15.0, 0.5        # docs/ato.md, Tests


def ato_vectors() -> RoleFile:
    """Closed loops with the reference train (our traction core, the runner's plant): the
    default timetable, and a signal at danger ahead (ALSN codes by position)."""
    role = RoleFile("ato_controller", ["cab_signal", "x", "v", "aspect", "code_valid", "command", "emergency_brake",
                                       "atp_interventions", "emergency_brakings", "signals_passed_at_danger",
                                       "stop_index", "arrival_time", "stop_error"])
    line = load_line(str(DEFAULT_LINE))
    timetable = load_timetable(str(DEFAULT_TIMETABLE), line)
    step = {"step_s": 0.5}
    never = [{"kind": "extreme", "label": f"no {what}", "port": port, "extreme": "max", "at_most": 0.0}
             for what, port in (("ATP intervention", "atp_interventions"), ("emergency braking", "emergency_brakings"),
                                ("signal passed at danger", "signals_passed_at_danger"))]
    checks = []
    for index, stop in enumerate(timetable[1:], start=2):
        reached = [_cond("stop_index", [index])]
        checks += [
            {"kind": "when", "label": f"arrival at {stop.station} (timetable {stop.arrival_s:g} s)", "trigger": reached,
             "port": "arrival_time", "expected": float(stop.arrival_s), "tolerance": ARRIVAL_TOLERANCE_S, "unit": "s"},
            {"kind": "when", "label": f"stop error at {stop.station}", "trigger": reached, "port": "stop_error",
             "expected": 0.0, "tolerance": STOP_TOLERANCE_M, "unit": "m"}]
    role.vectors.append({
        "name": "timetable_closed_loop", "what": "the bundled timetable A → B → C (19.2 km) with green codes throughout; "
                                                "the reference train from A",
        "parameters": {"cab_signal": "ALSN"}, "step": step, "duration_s": float(timetable[-1].arrival_s) + 60.0,
        "plant": {"x0_m": timetable[0].stop_m},
        "checks": checks + never + [{"kind": "extreme", "label": "speed never negative", "port": "plant.v",
                                     "extreme": "min", "at_least": 0.0, "unit": "m/s"}]})
    # a signal at danger at the end of section 2 until 300 s: yellow in section 1, red-yellow in
    # section 2 (3-aspect block), green after the clear
    red_m = line.sections[1].end_m
    ry = (line.sections[1].start_m, red_m)
    y = (line.sections[0].start_m, line.sections[0].end_m)
    clear_s = 300.0
    ceiling_kmh, _ = sig.ALSN_SPEEDS_KMH["passenger"][sig.RED_YELLOW]
    _, yellow_at_signal_kmh = sig.ALSN_SPEEDS_KMH["passenger"][sig.YELLOW]
    role.vectors.append({
        "name": "red_signal_ahead", "what": f"signal at {red_m:g} m at danger until {clear_s:g} s: Ж from {y[0]:g} m, "
                                            f"КЖ from {ry[0]:g} m; green after",
        "parameters": {"cab_signal": "ALSN"}, "step": step, "duration_s": clear_s + 150.0,
        "plant": {"x0_m": timetable[0].stop_m, "cab_zones": [[*y, sig.YELLOW], [*ry, sig.RED_YELLOW]],
                  "cab_clear_s": clear_s},
        "checks": never + [
            {"kind": "extreme", "label": "stops before the signal at danger", "port": "plant.x", "extreme": "max",
             "to_s": clear_s, "offset": red_m, "at_most": 0.0, "unit": "m"},
            {"kind": "extreme", "label": f"at most {yellow_at_signal_kmh:g} km/h passing the yellow's exit signal",
             "port": "plant.v", "extreme": "max", "where": [_rng("plant.x", ry[0], ry[0] + 50.0)],
             "to_s": clear_s, "at_most": round(yellow_at_signal_kmh / 3.6, 4), "unit": "m/s"},
            {"kind": "extreme", "label": f"within the red-yellow ceiling ({ceiling_kmh:g} km/h)", "port": "plant.v",
             "extreme": "max", "where": [_rng("plant.x", *ry)], "to_s": clear_s,
             "at_most": round(ceiling_kmh / 3.6, 4), "unit": "m/s"},
            {"kind": "extreme", "label": "drives on after the clear", "port": "plant.x", "extreme": "max",
             "offset": red_m, "at_least": 0.0, "unit": "m"}]})
    return role


GENERATORS = {"loco_receiver": receiver_vectors, "wayside_coder": coder_vectors, "rail_line": rail_vectors,
              "traction": traction_vectors, "ato_controller": ato_vectors}


def generate(roles=ROLES, directory: Path = DATA_DIR) -> List[Path]:
    written = []
    for role in roles:
        written += GENERATORS[role]().write(directory)
    return written


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog=GENERATOR, description=__doc__.splitlines()[0])
    parser.add_argument("roles", nargs="*", help=f"roles (default all: {', '.join(GENERATORS)})")
    parser.add_argument("--dest", type=Path, default=DATA_DIR, help="folder (default: the package's data/)")
    args = parser.parse_args(argv)
    unknown = [r for r in args.roles if r not in GENERATORS]
    if unknown:
        print(f"{GENERATOR}: error: unknown role {', '.join(unknown)} (roles: {', '.join(GENERATORS)})", file=sys.stderr)
        return 2
    for path in generate(args.roles or list(GENERATORS), args.dest):
        print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""The wayside_coder role's vectors (data/wayside_coder.json): code timings, the block logic,
the 2-out-of-2 transmitters and comparison, ALSU's tones, TVM-430's words and TVM-300's
sub-frequencies (docs/wayside_coder.md).
"""
from __future__ import annotations

import json
from typing import List

import numpy as np

from fmus.data.loader import DEFAULT_LINE, load_line
from fmus.signalling import alsn, cab_systems
from fmus.signalling import aspects as sig
from fmus.wayside_coder.core import CoderSettings
from orchestrator.conformance.generate.coder_signals import (CODE_NAME, CODE_TAG, SECTION, TVM_FS_HZ, TVM_LINE_FILE,
                                                             coder_core, occupancy, tvm_line, tvm_line_loaded)
from orchestrator.conformance.generate.role_file import FRAME, FS_HZ, RoleFile, schedule_input

#: TVM-300's deviation is always its peak, so the judge's instantaneous frequency (from the
#: analytic signal) overshoots it by its own ripple: 11.12 Hz for our coder's 11 Hz at 8 kHz. A
#: phase step shows as far more (0.1 rad in one sample at 8 kHz: 127 Hz)
FREQUENCY_EXCURSION_MARGIN_HZ = 1.0


def coder_vectors() -> RoleFile:
    role = RoleFile("wayside_coder", ["system", "fs", "block_aspects", "line_file", "occupied", "fault_main",
                                      "fault_reserve",
                                      "wrong_command_main",
                                      "u_tx", "code_tx", "signal", "status"])
    step = {"fs_hz": FS_HZ, "frame_port": "u_tx"}
    _code_timings(role, step)
    _block_logic(role, step)
    _two_out_of_two_faults(role, step)
    role.vectors.extend(_alsu_coder_vectors())
    role.data_files[TVM_LINE_FILE] = tvm_line()
    role.vectors.extend(_tvm430_coder_vectors())
    role.vectors.extend(_tvm300_coder_vectors())
    _wrong_command(role, step)
    return role


def _alsu_coder_vectors() -> List[dict]:
    """ALSU: the block's codes of every section (4-aspect, from our block rules) and the two
    tones a code sends (docs/wayside_coder.md#alsu)."""
    from fmus.signalling import alsu
    from fmus.wayside_coder.alsu import AlsuCoderCore

    line = load_line(str(DEFAULT_LINE))
    params = {"system": cab_systems.ALSU.name, "fs": FS_HZ, "block_aspects": 4}
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
        "inputs": {"occupied": schedule_input(times, [p.tolist() for p in patterns])},
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
        "inputs": {"occupied": schedule_input([0.0, change_s], [np.zeros(8, dtype=bool).tolist(), occupied.tolist()])},
        "record_frames": ["u_tx[1]"], "checks": checks})
    return vectors

def _tvm430_coder_vectors() -> List[dict]:
    """TVM-430: the block rules' word of every section for a train in each block, and the word's
    tones on section 1's carrier before and after a change, with no phase step at the change
    (docs/wayside_coder.md#tvm-430)."""
    from fmus.signalling import tvm430
    from fmus.wayside_coder.tvm430 import PEAK_DEVIATION_HZ, Tvm430CoderCore

    line = tvm_line_loaded()
    params = {"system": cab_systems.TVM430.name, "fs": TVM_FS_HZ, "line_file": TVM_LINE_FILE}
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
        "inputs": {"occupied": schedule_input(times, [p.tolist() for p in patterns])},
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
        "inputs": {"occupied": schedule_input([0.0, change_s], [clear.tolist(), occupied.tolist()])},
        "record_frames": ["u_tx[1]"], "checks": checks})
    return vectors


def _tvm300_coder_vectors() -> List[dict]:
    """TVM-300 on the TVM-430 vectors' line (its block rules accept it): the block rules' code
    of every section for a train in each block, and the code's one sub-frequency on section
    1's carrier before and after a change, with no phase step at the change
    (docs/wayside_coder.md#tvm-300)."""
    from fmus.signalling import tvm300
    from fmus.wayside_coder.tvm300 import PEAK_DEVIATION_HZ, Tvm300CoderCore

    line = tvm_line_loaded()
    params = {"system": cab_systems.TVM300.name, "fs": TVM_FS_HZ, "line_file": TVM_LINE_FILE}
    step = {"fs_hz": TVM_FS_HZ, "frame_port": "u_tx"}
    core = Tvm300CoderCore(line, 8, FRAME, CoderSettings(fs_hz=TVM_FS_HZ, seed=1))
    patterns = [np.zeros(8, dtype=bool)] + [np.eye(8, dtype=bool)[k] for k in range(8)]
    hold_s = 0.05
    times = [round(i * hold_s, 4) for i in range(len(patterns))]
    at = [round(t + hold_s, 4) for t in times]
    codes = [core.step(0.0, pattern).code_tx.tolist() for pattern in patterns]
    vectors = [{
        "name": "tvm300_block_codes", "what": f"{len(patterns)} occupancy patterns (the line clear, a train in each "
                                              f"block) on an 8-block line of UM71 circuits, TVM-300",
        "parameters": params, "step": step, "duration_s": round(len(patterns) * hold_s, 4),
        "inputs": {"occupied": schedule_input(times, [p.tolist() for p in patterns])},
        "checks": [{"kind": "table", "label": "TVM-300 code (sub-frequency index + 1) of every section (block rules)",
                    "port": "code_tx", "at_s": at, "expected": codes}]}]
    change_s, seconds = 3.0, 6.0
    clear, occupied = np.zeros(8, dtype=bool), np.eye(8, dtype=bool)[2]
    first, second = (int(core.step(0.0, pattern).code_tx[0]) for pattern in (clear, occupied))
    carrier = float(line.sections[0].carrier_hz)
    sub_hz = [round(float(f), 2) for f in tvm300.SUB_FREQUENCIES_HZ]
    checks = []
    for (start, end), code in (((0.2, change_s - 0.2), first), ((change_s + 0.2, seconds - 0.2), second)):
        read = tvm300.system().reading(code)
        checks.append({"kind": "fm_tones", "label": f"section 1 sends code {code} ({read.step_kmh:g}/{read.next_kmh:g} "
                                                    f"km/h): its sub-frequency, no other",
                       "port": "u_tx[1]", "from_s": start, "to_s": end, "fs_hz": TVM_FS_HZ, "carrier_hz": carrier,
                       "frequencies_hz": sub_hz, "present": [sub_hz[tvm300.index_of_code(code)]],
                       "at_least": 0.9 * tvm300.DEVIATION_HZ, "at_most": 0.1 * tvm300.DEVIATION_HZ, "unit": "Hz"})
    bound_hz = PEAK_DEVIATION_HZ + FREQUENCY_EXCURSION_MARGIN_HZ
    checks.append({"kind": "frequency_excursion", "label": "no phase step at the code change: the carrier stays "
                                                          f"within ±{bound_hz:g} Hz",
                   "port": "u_tx[1]", "from_s": 0.2, "to_s": seconds - 0.2, "fs_hz": TVM_FS_HZ,
                   "carrier_hz": carrier, "at_most": bound_hz, "unit": "Hz"})
    vectors.append({
        "name": "tvm300_sub_frequency_section_1", "what": f"TVM-300: the line clear, then block 3 occupied from "
                                                          f"{change_s:g} s: the code's sub-frequency on section 1's "
                                                          f"{carrier:g} Hz carrier",
        "parameters": params, "step": step, "duration_s": seconds,
        "inputs": {"occupied": schedule_input([0.0, change_s], [clear.tolist(), occupied.tolist()])},
        "record_frames": ["u_tx[1]"], "checks": checks})
    return vectors


def _coder_codes(core, occupied: np.ndarray) -> np.ndarray:
    return core.step(0.0, occupied).code_tx.copy()


def _code_timings(role: RoleFile, step: dict) -> None:
    """Code timings: each code of each transmitter type, two cycles and more of the keyed carrier."""
    line = load_line(str(DEFAULT_LINE))
    tables = json.loads(alsn.CODES_FILE.read_text(encoding="utf-8"))["transmitters"]
    for kpt in ("KPT-5", "KPT-7"):
        section = SECTION[kpt]
        carrier = line.sections[section].carrier_hz
        cycle = tables[kpt]["cycle_s"]
        for code in (sig.GREEN, sig.YELLOW, sig.RED_YELLOW):
            occupied = occupancy(code, section)
            name = f"timing_{CODE_TAG[code]}_{kpt}"
            seconds = round(2.5 * cycle + 0.5, 2)
            sent = coder_core().step(0.0, occupied).code_tx.tolist()
            role.vectors.append({
                "name": name, "what": f"{CODE_NAME[code]} into section {section + 1} ({kpt}) for {seconds} s",
                "parameters": {"system": cab_systems.ALSN.name, "fs": FS_HZ}, "step": step, "duration_s": seconds,
                "inputs": {"occupied": schedule_input([0.0], [occupied.tolist()])},
                "record_frames": [f"u_tx[{section + 1}]"],
                "checks": [
                    {"kind": "table", "label": f"code_tx: {CODE_NAME[code]} into section {section + 1}", "port": "code_tx",
                     "at_s": [seconds], "expected": [sent]},
                    {"kind": "code_timing", "label": f"pulses and intervals of {CODE_NAME[code]} ({kpt}) within ±5 %",
                     "port": f"u_tx[{section + 1}]", "pattern_s": tables[kpt]["codes"][CODE_TAG[code]],
                     "tolerance": 0.05, "fs_hz": FS_HZ, "carrier_hz": carrier, "cycle_s": cycle}]})


def _block_logic(role: RoleFile, step: dict) -> None:
    """Block logic: occupancy patterns → signals and codes of every section, from our block rules."""
    for aspects in (3, 4):
        core = coder_core(aspects)
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
            "parameters": {"system": cab_systems.ALSN.name, "fs": FS_HZ, "block_aspects": aspects}, "step": step,
            "duration_s": round(len(patterns) * hold_s, 4),
            "inputs": {"occupied": schedule_input(times, [p.tolist() for p in patterns])},
            "checks": [{"kind": "table", "label": "signal of every section (block rules)", "port": "signal",
                        "at_s": at, "expected": signals},
                       {"kind": "table", "label": "code_tx of every section (block rules)", "port": "code_tx",
                        "at_s": at, "expected": codes}]})


def _two_out_of_two_faults(role: RoleFile, step: dict) -> None:
    """2-out-of-2: main fails at 1 s (reserve alone, status 1, code kept), reserve too at 2 s
    (status 2, no code, no output)."""
    core = coder_core()
    clear = np.zeros(8, dtype=bool)
    sent = core.step(0.0, clear).code_tx.tolist()
    role.vectors.append({
        "name": "two_out_of_two_faults", "what": "main transmitter fails at 1 s, the reserve at 2 s",
        "parameters": {"system": cab_systems.ALSN.name, "fs": FS_HZ}, "step": step, "duration_s": 3.0,
        "inputs": {"fault_main": schedule_input([0.0, 1.0], [False, True]),
                   "fault_reserve": schedule_input([0.0, 2.0], [False, True])},
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


def _wrong_command(role: RoleFile, step: dict) -> None:
    """Digital 2-out-of-2 comparison: a controller computing a wrong command is outvoted by the more
    restrictive of the two (fmus/signalling/redundancy.py); expected from our core."""
    for system_name in (cab_systems.FIRE_DQPSK.name, cab_systems.ALS_EN.name):
        system = cab_systems.digital_system(system_name)
        wrong = max(system.commands(), key=system.rank)          # the most permissive command
        core = coder_core(system=system_name)
        healthy = core.step(0.0, occupancy(sig.RED_YELLOW, 0)).code_tx.tolist()
        faulty = core.step(0.01, occupancy(sig.RED_YELLOW, 0), wrong_command_main=wrong).code_tx.tolist()
        role.vectors.append({
            "name": f"{system_name.lower().replace('-', '_')}_wrong_command", "what":
                f"{system_name}: section 2 occupied; from 0.5 s the main controller computes command {wrong} everywhere",
            "parameters": {"system": system_name, "fs": FS_HZ}, "step": step, "duration_s": 1.0,
            "inputs": {"occupied": schedule_input([0.0], [occupancy(sig.RED_YELLOW, 0).tolist()]),
                       "wrong_command_main": schedule_input([0.0, 0.5], [0, wrong])},
            "checks": [{"kind": "table", "label": "the 2-out-of-2 sends the more restrictive command",
                        "port": "code_tx", "at_s": [0.5, 1.0], "expected": [healthy, faulty]},
                       {"kind": "table", "label": "status stays 0", "port": "status", "at_s": [1.0],
                        "expected": [[0]]}]})

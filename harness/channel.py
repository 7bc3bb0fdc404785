"""A wayside coder section coupled straight into a receiver (coupling factor, optional
disturbance), frame by frame, without FMI or a rail line: for receiver studies, the tests, the
benchmarks and the figures of docs/loco_receiver.md."""
from __future__ import annotations

from typing import Callable, Optional

import numpy as np

from fmus.data.loader import Line, load_line
from fmus.wayside_coder.core import CoderSettings, WaysideCoderCore
from fmus.loco_receiver.core import LocoReceiverCore, ReceiverSettings

Disturbance = Callable[[np.ndarray, np.ndarray], np.ndarray]   # (sample times, clean EMF) → EMF
COLUMNS = ("t_end", "aspect", "code_valid", "code_sent")


class CodeChannel:
    def __init__(self, section: int = 0, frame: int = 40, coupling: float = 0.1, line: Optional[Line] = None,
                 coder: Optional[CoderSettings] = None, receiver: Optional[ReceiverSettings] = None,
                 cam_phase: Optional[float] = None):
        line = line or load_line()
        self.section, self.frame, self.coupling = section, frame, coupling
        self.coder = WaysideCoderCore(line, len(line.sections), frame, coder or CoderSettings())
        if cam_phase is not None:
            self.coder.cam_offset_s[:] = cam_phase * self.coder.cycle_s
        self.receiver = LocoReceiverCore(frame, receiver or ReceiverSettings())
        self.fs = self.coder.settings.fs_hz
        self.frames_done = 0

    def run(self, seconds: float, occupancy, disturb: Optional[Disturbance] = None,
            keep_emf: bool = False):
        """Rows (t_end, aspect shown, code_valid, code sent) per frame; with ``keep_emf`` also
        the coil EMF samples fed to the receiver."""
        rows, emf = [], []
        offsets = np.arange(self.frame) / self.fs
        for _ in range(int(round(seconds * self.fs / self.frame))):
            t = self.frames_done * self.frame / self.fs
            sent = self.coder.step(t, occupancy(t) if callable(occupancy) else occupancy)
            e = sent.u_tx[self.section] * self.coupling
            if disturb is not None:
                e = disturb(t + offsets, e)
            if keep_emf:
                emf.append(e)
            out = self.receiver.step(t, e)
            rows.append((t + self.frame / self.fs, out.aspect, out.code_valid, int(sent.code_tx[self.section])))
            self.frames_done += 1
        rows = np.array(rows)
        return (rows, np.concatenate(emf)) if keep_emf else rows


def white_noise_and_hum(snr_db: float, carrier_amplitude_v: float, harmonics_v: dict, seed: int) -> Disturbance:
    """White noise at ``snr_db`` over the whole band (carrier power A²/2 against σ²) plus
    sinusoids {frequency Hz: amplitude V}."""
    rng = np.random.default_rng(seed)
    sigma = np.sqrt(carrier_amplitude_v ** 2 / 2.0 / 10 ** (snr_db / 10.0))

    def add(t: np.ndarray, e: np.ndarray) -> np.ndarray:
        hum = sum(a * np.sin(2 * np.pi * f * t + f) for f, a in harmonics_v.items())
        return e + sigma * rng.standard_normal(t.size) + hum
    return add

"""What both TVM coders share (fmus/wayside_coder/tvm430.py, tvm300.py;
docs/wayside_coder.md#tvm-430, #tvm-300): each section sends on its line-file UM71 carrier
(fmus/signalling/um71.py), never stops (the carrier is the circuit's detection signal), at a
sample rate that holds the highest carrier with its deviation; the faults as ALSN's (main
failed: the reserve carries on, status 1; both: no carrier anywhere, status 2); and the
frame's sample times and carrier phase from the integer sample index, so that frames of any
length give the same samples. No FMI here.
"""
from __future__ import annotations

import numpy as np

from fmus.data.loader import Line
from fmus.errors import FmuInputError
from fmus.signalling import um71
from fmus.wayside_coder.core import STATUS_FAILED, STATUS_OK, STATUS_PARTIAL, CoderSettings, check_settings

#: the modulated carrier's highest frequency must stay below this share of fs (Nyquist 0.5, with
#: room for the rail line's and the receiver's filters)
MAX_FREQUENCY_PER_FS = 0.4


def check_carriers_and_rate(line: Line, fs_hz: float, peak_deviation_hz: float, system_label: str) -> np.ndarray:
    """Each section's carrier (Hz) from the line file; a carrier not of UM71 or a sample rate
    that cannot hold the highest one with ``peak_deviation_hz`` is an input error."""
    carriers = np.array([sec.carrier_hz for sec in line.sections], dtype=float)
    for index, carrier in enumerate(carriers):
        if not any(abs(carrier - c) < 1e-9 for c in um71.CARRIERS_HZ):
            raise FmuInputError(f"{line.path}: field block_sections[{index}].carrier_hz: {carrier:g} Hz is not a "
                                f"{system_label} carrier ({', '.join(f'{c:g}' for c in um71.CARRIERS_HZ)} Hz)")
    top = float(carriers.max()) + peak_deviation_hz
    if top > MAX_FREQUENCY_PER_FS * fs_hz:
        raise FmuInputError(f"parameter fs: {fs_hz:g} Hz cannot hold the carrier {carriers.max():g} Hz "
                            f"+ {peak_deviation_hz:g} Hz deviation: {system_label} needs fs ≥ "
                            f"{top / MAX_FREQUENCY_PER_FS:g} Hz")
    return carriers


def check_um71_settings(line: Line, sections: int, s: CoderSettings, system_label: str) -> None:
    """Every coder's checks, and a TVM coder's own: the carrier is the line file's, coding always."""
    check_settings(line, sections, s)
    if s.carrier_hz:
        raise FmuInputError(f"parameter carrier: {s.carrier_hz:g} Hz, but {system_label} sends on each section's "
                            f"line-file carrier (leave carrier 0)")
    if s.coding != "always":
        raise FmuInputError(f"parameter coding: {s.coding}, but a {system_label} carrier is its track circuit's "
                            f"detection signal and never stops (use always)")


def fault_status(fault_main: bool, fault_reserve: bool) -> int:
    return STATUS_FAILED if (fault_main and fault_reserve) else (
        STATUS_PARTIAL if fault_main or fault_reserve else STATUS_OK)


class SampleClock:
    """A frame's sample indices and times, and every section's carrier phase, from the integer
    sample index: work buffers preallocated for frames up to ``frame`` samples."""

    def __init__(self, carriers_hz: np.ndarray, frame: int, fs_hz: float):
        self.carriers_hz, self.fs_hz = carriers_hz, fs_hz
        self._index = np.arange(frame, dtype=float)
        self._samples = np.empty(frame)
        self._times = np.empty(frame)
        self._cycles = np.empty((carriers_hz.size, frame))

    def samples(self, t: float, n: int):
        """(sample indices, times s) of the ``n`` samples from ``t``: whole numbers, exact below 2⁵³."""
        index = np.add(self._index[:n], round(t * self.fs_hz), out=self._samples[:n])
        return index, np.divide(index, self.fs_hz, out=self._times[:n])

    def carrier_phase(self, index: np.ndarray) -> np.ndarray:
        """(sections, n) 2π f_c n / fs (rad), the carrier cycles f_c·n/fs reduced mod 1 before the
        2π: exact whatever the run's length (a view of a work buffer, overwritten next frame)."""
        cycles = np.multiply.outer(self.carriers_hz, index, out=self._cycles[:, :index.size])
        np.fmod(cycles, self.fs_hz, out=cycles)
        cycles *= 2.0 * np.pi / self.fs_hz
        return cycles

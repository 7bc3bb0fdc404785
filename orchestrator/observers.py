"""Observers: what a run records (the Observer protocol, orchestrator/protocols.py). They read
the master's output buffers after each tick (``master.fresh(component)`` first: outputs are
read from the slaves on demand).

* Recorder: chosen scalar outputs at a fixed output interval → results.csv (rows are written
  and flushed as the run goes, so a failed run keeps everything computed before it failed).
* WaveformCapture: every sample of a frame output port inside a time window → capture CSV.
  Sample n of the frame from doStep(t, h) is the value at t + (n-1)·h/N (docs/interfaces.md,
  "Time and frames"), written as an exact decimal from the integer clock. A whole 2-D port
  (``rail.e_coil``) gives one column per row.
* Progress: the run's progress on stderr, a bar on a terminal or a line every few seconds
  into a log (``--progress``).

A results file that cannot be written (no space left, no permission, a read-only file system,
a name too long, a folder in its place) stops the run with :class:`ResultsWriteError`: one line
naming the file and the reason (docs/reliability.md, "Full disks and write errors"). A symbolic
link at its name is never followed: one line naming the link (orchestrator/folders.py).
"""
from __future__ import annotations

import csv
import math
import re
import sys
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Dict, List, Sequence, Tuple

import numpy as np

from orchestrator.errors import UserError
from orchestrator.folders import create_file
from orchestrator.graph import MAX_TIME_S, TICKS_PER_SECOND
from orchestrator.ports import split_element
from orchestrator.protocols import MasterView, Observer, StepRecord

class ResultsWriteError(UserError):
    """A results file could not be written; the run stops, what could be written is kept."""


def cannot_write(path: Path, error: OSError) -> ResultsWriteError:
    reason = error.strerror or str(error) or type(error).__name__
    return ResultsWriteError(f"{path}: cannot write ({reason})")


def open_for_writing(path: Path):
    """From empty, never through a symbolic link at ``path`` (orchestrator/folders.py: one line
    naming the link)."""
    try:
        return create_file(path)
    except OSError as error:
        raise cannot_write(path, error) from None


def close_file(path: Path, handle) -> None:
    """Flush and close; a failed flush still closes the descriptor (and is reported)."""
    try:
        handle.close()
    except OSError as error:
        raise cannot_write(path, error) from None


def scalar_outputs(interface) -> List[str]:
    """Outputs a run records by default: scalars and per-section/per-train arrays, not frames."""
    names = []
    for name, var in interface.variables.items():
        if var.causality != "output" or var.type == "String":
            continue
        base, index = split_element(name) or (name, ())
        if len(index) == 0 or (len(index) == 1 and base not in interface.frame_ports):
            names.append(name)
    return names


class Recorder(Observer):
    """Chosen outputs at every output interval, streamed to CSV."""

    def __init__(self, path: Path, variables: Sequence[Tuple[str, str]], interval_ticks: int):
        self.path = Path(path)
        self.variables = list(variables)
        self.interval_ticks = interval_ticks
        self.rows_written = 0
        self._file = None

    def outputs_needed(self) -> Dict[str, List[str]]:
        needed: Dict[str, List[str]] = {}
        for component, variable in self.variables:
            needed.setdefault(component, []).append(variable)
        return needed

    def started(self, master: MasterView, step: StepRecord) -> None:
        slots = [master.output_slot(c, v) for c, v in self.variables]
        # one gather per output buffer per row: (buffer, its indices, their columns, Real)
        groups: Dict[int, tuple] = {}
        for column, (buffer, index) in enumerate(slots):
            group = groups.setdefault(id(buffer), (buffer, [], []))
            group[1].append(index)
            group[2].append(column + 1)
        self._groups = [(buffer, list(zip(columns, indices)), buffer.type == "Real")
                        for buffer, indices, columns in groups.values()]
        self._components = sorted({c for c, _ in self.variables})
        self._file = open_for_writing(self.path)
        self._writer = csv.writer(self._file)
        try:
            self._writer.writerow(["time"] + [f"{c}.{v}" for c, v in self.variables])
        except OSError as error:
            raise cannot_write(self.path, error) from None
        self._write(master, step.tick)

    def after_tick(self, master: MasterView, step: StepRecord) -> None:
        if step.tick % self.interval_ticks == 0:
            self._write(master, step.tick)

    def _write(self, master: MasterView, tick: int) -> None:
        for component in self._components:
            master.fresh(component)
        row = [repr(tick / TICKS_PER_SECOND)] * (len(self.variables) + 1)
        # value by value with ndarray.item (a Python number): a row is written every 0.1 s
        # between many signal ticks, where numpy's take and tolist cost more, cold, than these
        for buffer, places, real in self._groups:
            item = buffer.values.item
            for column, index in places:
                row[column] = repr(item(index)) if real else str(int(item(index)))
        try:    # whole rows only reach the file: a row is written, the buffer flushed per 100 rows
            self._writer.writerow(row)
            self.rows_written += 1
            if self.rows_written % 100 == 0:
                self._file.flush()
        except OSError as error:
            raise cannot_write(self.path, error) from None

    def close(self) -> None:
        handle, self._file = self._file, None
        if handle is not None:
            close_file(self.path, handle)


@dataclass
class CaptureRequest:
    component: str
    port: str          # e.g. "e_coil[1]" (row 1 of e_coil[j,n]) or "u" for u[n]
    t0: float
    t1: float

    @classmethod
    def parse(cls, text: str) -> "CaptureRequest":
        match = re.match(r"^(?P<comp>[A-Za-z_]\w*)\.(?P<port>[^@]+)@(?P<t0>[^:]+):(?P<t1>.+)$", text)
        if not match:
            raise UserError(f"--capture {text}: expected COMPONENT.PORT@T0:T1 (seconds)")
        try:
            t0, t1 = float(match.group("t0")), float(match.group("t1"))
        except ValueError:
            raise UserError(f"--capture {text}: T0 and T1 must be numbers of seconds") from None
        # (float() takes nan and inf; a run's times are bounded: orchestrator/graph.py)
        if not all(math.isfinite(t) and abs(t) <= MAX_TIME_S for t in (t0, t1)):
            raise UserError(f"--capture {text}: T0 and T1 must be finite numbers of seconds "
                            f"within ±{MAX_TIME_S:g} s, a run's longest time")
        if t1 <= t0:
            raise UserError(f"--capture {text}: T1 must be after T0")
        return cls(match.group("comp"), match.group("port"), t0, t1)

    def elements(self, interface) -> List[List[str]]:
        """Element names of the frame, one list per captured row in sample order: one row for a
        1-D port or a named row (``e_coil[1]``), every row for a whole 2-D port (``e_coil``)."""
        base, named_row = split_element(self.port) or (self.port, ())
        names, indices = [], []
        for name, variable in interface.variables.items():
            element = split_element(name)
            if element is not None and element[0] == base and len(element[1]) > len(named_row) \
                    and element[1][:len(named_row)] == named_row and variable.causality == "output":
                names.append(name)
                indices.append(element[1][len(named_row):])
        if not names:
            raise UserError(f"--capture {self.component}.{self.port}: no such frame output")
        if len({len(i) for i in indices}) != 1 or len(indices[0]) > 2:
            raise UserError(f"--capture {self.component}.{self.port}: not a frame port or one row of one")
        by_row: Dict[int, List[Tuple[int, str]]] = {}
        for index, name in zip(indices, names):
            row, sample = index if len(index) == 2 else (0, index[0])
            by_row.setdefault(row, []).append((sample, name))
        return [[name for _, name in sorted(samples)] for _, samples in sorted(by_row.items())]

    def columns(self, elements: List[List[str]]) -> List[str]:
        """The CSV's value columns: the port (or the row named), or ``port[j]`` per row of a
        whole 2-D port."""
        named_row = (split_element(self.port) or (self.port, ()))[1]
        if named_row or len(split_element(elements[0][0])[1]) < 2:
            return [f"{self.component}.{self.port}"]
        return [f"{self.component}.{self.port}[{j}]" for j in range(1, len(elements) + 1)]


def sample_times(start_ticks: int, step_ticks: int, n: int) -> List[str]:
    """The N sample instants of the frame from doStep(start, step), as decimal seconds written
    from the integer clock: start + k·step/N ticks, exact (no float rounding) when a whole
    number of nanoseconds, else the shortest decimal of the nearest float."""
    numerators = start_ticks * n + np.arange(n, dtype=np.int64) * step_ticks
    return _instants(numerators, n, step_ticks % n == 0)


def _instants(numerators: np.ndarray, n: int, whole: bool) -> List[str]:
    """Sample instants numerator/N ticks as text (:func:`sample_times`); ``whole``: every
    instant of the frame is a whole number of ticks (step·k/N is for every k when N divides
    the step), written exactly."""
    if whole:
        ticks = numerators // n
        whole_s, nanos = np.divmod(np.abs(ticks), TICKS_PER_SECOND)
        text = np.char.add(np.char.mod("%d.", whole_s), np.char.zfill(np.char.mod("%d", nanos), 9))
        text = np.char.rstrip(np.char.rstrip(text, "0"), ".")
        return list(np.char.add(np.where(ticks < 0, "-", ""), text))
    return [repr(float(t)) for t in numerators / (n * TICKS_PER_SECOND)]


class WaveformCapture(Observer):
    """Every sample of one frame output (one row, or every row of a 2-D port) inside a time
    window; times are exact sample instants (:func:`sample_times`)."""

    def __init__(self, path: Path, request: CaptureRequest, elements: List[List[str]]):
        self.path = Path(path)
        self.request = request
        self.elements = elements
        self._file = None

    def outputs_needed(self) -> Dict[str, List[str]]:
        return {self.request.component: [e for row in self.elements for e in row]}

    def started(self, master: MasterView, step: StepRecord) -> None:
        slots = [[master.output_slot(self.request.component, e) for e in row] for row in self.elements]
        self._buffer = slots[0][0][0]
        self._index = np.array([[i for _, i in row] for row in slots])      # (rows, N)
        n = self._index.shape[1]
        step_ticks = master.graph.nodes[self.request.component].step_ticks
        # sample k of the step from ``start`` is at (start·N + k·h) / N ticks: the window and
        # the samples are compared (and written) in integers
        self._step_ticks, self._offsets = step_ticks, np.arange(n, dtype=np.int64) * step_ticks
        self._t0_ticks = round(self.request.t0 * TICKS_PER_SECOND)
        self._t1_ticks = round(self.request.t1 * TICKS_PER_SECOND)
        self._whole = step_ticks % n == 0
        self._file = open_for_writing(self.path)
        try:
            self._file.write(",".join(["time"] + self.request.columns(self.elements)) + "\n")
        except OSError as error:
            raise cannot_write(self.path, error) from None

    def after_tick(self, master: MasterView, step: StepRecord) -> None:
        if self.request.component not in step.stepped:
            return
        start_ticks = step.tick - master.graph.base_ticks      # the step began one base step ago
        if start_ticks + self._step_ticks <= self._t0_ticks or start_ticks >= self._t1_ticks:
            return
        master.fresh(self.request.component)
        n = self._index.shape[1]
        numerators = start_ticks * n + self._offsets
        keep = (numerators >= self._t0_ticks * n) & (numerators < self._t1_ticks * n)
        if not keep.any():
            return
        times = _instants(numerators[keep], n, self._whole)
        values = np.char.mod("%.17g", np.asarray(self._buffer.values[self._index[:, keep]], dtype=float))
        text = "".join(",".join(sample) + "\n" for sample in zip(times, *values))
        try:
            self._file.write(text)
        except OSError as error:
            raise cannot_write(self.path, error) from None

    def close(self) -> None:
        handle, self._file = self._file, None
        if handle is not None:
            close_file(self.path, handle)


#: how a run shows its progress on stderr (``--progress``): a bar redrawn in place on a terminal,
#: a line every few seconds of wall time into a log, or nothing
PROGRESS_MODES = ("bar", "lines", "none")
DEFAULT_PROGRESS_INTERVAL_S = 5.0


def duration_text(seconds: float) -> str:
    """``12 s``, ``1 m 30 s``, ``2 h 5 m``: a wall-clock duration as a person reads it."""
    seconds = max(0.0, seconds)
    if seconds < 59.5:
        return f"{seconds:.0f} s"
    whole = round(seconds)
    if whole < 3600:
        return f"{whole // 60} m {whole % 60} s"
    return f"{whole // 3600} h {whole % 3600 // 60} m"


class Progress(Observer):
    """A run's progress on ``stream`` (stderr): while the components are initialised
    (``initialising N components…`` and how long it took), then the simulated time against the
    stop time, the wall time elapsed (initialisation included), the real-time factor of the
    stepping so far and the time still to go at that rate.

    ``bar`` (a terminal): the initialisation line at once, the bar from ``bar_after_s`` of
    stepping on, redrawn in place twice a second. ``lines`` (a log): nothing for the first
    ``interval_s`` of wall time — a short run prints no progress at all — then one line every
    ``interval_s`` (``t=123.4/1100 s  11%  elapsed 12 s  ETA 1 m 30 s  RTF 9.8×``); an
    initialisation still going on at ``interval_s`` is said then, and how long it took when done.
    """

    def __init__(self, mode: str, start_s: float, stop_s: float, components: int,
                 interval_s: float = DEFAULT_PROGRESS_INTERVAL_S, stream=None, clock=time.monotonic,
                 bar_after_s: float = 2.0):
        if mode not in ("bar", "lines"):
            raise ValueError(f"progress mode {mode!r}")
        self.mode, self.start_s, self.stop_s, self.components = mode, start_s, stop_s, components
        self.interval_s, self.bar_after_s = interval_s, bar_after_s
        self.stream = stream if stream is not None else sys.stderr
        self.clock = clock
        self._lock = threading.Lock()
        self._timer = None
        self._began = self._stepping = self._next = None
        self._open_line = False          # a bar or an initialisation line not ended yet
        self._init_said = False          # ``initialising …`` was written

    # ---- initialisation ------------------------------------------------------------------------
    def initialising(self) -> None:
        """Before the components are made: the clock starts."""
        self._began = self.clock()
        if self.mode == "bar":
            self._write(self._init_text(), end="")
            self._open_line = self._init_said = True
        else:
            self._timer = threading.Timer(self.interval_s, self._still_initialising)
            self._timer.daemon = True
            self._timer.start()

    def _init_text(self) -> str:
        return f"initialising {self.components} component{'s' if self.components != 1 else ''}…"

    def _still_initialising(self) -> None:
        with self._lock:
            if self._stepping is None and not self._init_said:
                self._init_said = True
                self._write_locked(self._init_text(), end="\n")

    def started(self, master: MasterView, step: StepRecord) -> None:
        now = self.clock()
        self._cancel_timer()
        if self._began is None:
            self._began = now
        with self._lock:
            self._stepping = now
            took = f"initialised {self.components} component{'s' if self.components != 1 else ''} in {now - self._began:.1f} s"
            if self.mode == "bar":
                self._write_locked("\r" + took + "\x1b[K", end="\n")
                self._open_line = False
            elif self._init_said:
                self._write_locked(took, end="\n")
        # lines: the first after interval_s of the run, and after some stepping to rate it
        self._next = max(self._began + self.interval_s, now + min(self.interval_s, 1.0))
        if self.mode == "bar":
            self._next = now + self.bar_after_s

    # ---- stepping ------------------------------------------------------------------------------
    def after_tick(self, master: MasterView, step: StepRecord) -> None:
        now = self.clock()
        if now < self._next:
            return
        text = self.status(step.time_s, now)
        if self.mode == "bar":
            self._next = now + 0.5
            share = self._share(step.time_s)
            self._write(f"\r[{'#' * int(share * 30):<30}] {text}\x1b[K", end="")
            self._open_line = True
        else:
            self._next = now + self.interval_s
            self._write(text, end="\n")

    def _share(self, time_s: float) -> float:
        span = self.stop_s - self.start_s
        return min(max((time_s - self.start_s) / span, 0.0), 1.0) if span > 0 else 1.0

    def status(self, time_s: float, now: float) -> str:
        """``t=123.4/1100 s  11%  elapsed 12 s  ETA 1 m 30 s  RTF 9.8×`` at the master's time."""
        simulated = time_s - self.start_s
        stepping = now - self._stepping
        rate = simulated / stepping if stepping > 0 else 0.0
        left = self.stop_s - time_s
        eta = duration_text(left / rate) if rate > 0 else "?"
        return (f"t={time_s:.1f}/{self.stop_s:g} s  {self._share(time_s) * 100:.0f}%  "
                f"elapsed {duration_text(now - self._began)}  ETA {eta}  RTF {rate:.1f}×")

    def close(self) -> None:
        self._cancel_timer()
        with self._lock:
            if self._open_line:           # a bar ends its line; an initialisation that failed is erased
                self._write_locked("\n" if self._stepping is not None else "\r\x1b[K", end="")
                self._open_line = False

    # ---- output --------------------------------------------------------------------------------
    def _cancel_timer(self) -> None:
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None

    def _write(self, text: str, end: str) -> None:
        with self._lock:
            self._write_locked(text, end)

    def _write_locked(self, text: str, end: str) -> None:
        try:
            self.stream.write(text + end)
            self.stream.flush()
        except (OSError, ValueError):     # a closed or full stderr: progress is not worth failing for
            pass

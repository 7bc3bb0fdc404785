"""ngspice as a subprocess: a netlist run in batch mode (``ngspice -b``) and its output read back
(docs/rail_line.md#checked-against-ngspice).

The results come from the raw file ngspice writes with ``-r`` in its ASCII form
(``SPICE_ASCIIRAWFILE=1``): every vector of the analysis by name, real (.tran) or complex (.ac),
printed to 16 digits. The netlist itself stays plain SPICE (no control block).
"""
from __future__ import annotations

import os
import shutil
import subprocess
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np

from orchestrator.errors import UserError

INSTALL_HINT = "ngspice is not installed (Debian/Ubuntu: apt-get install ngspice; https://ngspice.sourceforge.io)"


def ngspice_path() -> Optional[str]:
    """The ngspice on PATH, or None."""
    return shutil.which("ngspice")


@dataclass
class RawFile:
    """One analysis (plot) of a raw file: its name and every vector by lower-case name."""
    plot: str
    vectors: Dict[str, np.ndarray]

    def value(self, probe: Sequence[Tuple[float, str]]) -> np.ndarray:
        """A probe (a sum of coefficient × vector) over the analysis' points."""
        first = next(iter(self.vectors.values()))
        total = np.zeros(first.shape, dtype=first.dtype)
        for coefficient, name in probe:
            if name not in self.vectors:
                raise KeyError(f"no vector {name!r} in ngspice's output (it has {', '.join(sorted(self.vectors))[:200]})")
            total = total + coefficient * self.vectors[name]
        return total


def read_raw(text: str) -> List[RawFile]:
    """Every plot of an ASCII raw file (``Title:`` … ``Variables:`` … ``Values:``)."""
    plots: List[RawFile] = []
    lines = text.splitlines()
    at = 0
    while at < len(lines):
        header: Dict[str, str] = {}
        while at < len(lines) and not lines[at].startswith("Variables:"):
            key, _, value = lines[at].partition(":")
            if value:
                header[key.strip().lower()] = value.strip()
            at += 1
        if at >= len(lines):
            break
        count = int(header["no. variables"])
        points = int(header["no. points"])
        complex_values = "complex" in header.get("flags", "")
        names = [lines[at + 1 + k].split()[1].lower() for k in range(count)]
        at += 1 + count
        if not lines[at].startswith("Values:"):
            raise ValueError(f"raw file: 'Values:' expected, got {lines[at][:60]!r}")
        at += 1
        tokens: List[str] = []
        need = points * (count + 1)              # each point: its index, then one token per vector
        while len(tokens) < need and at < len(lines):
            tokens += lines[at].split()
            at += 1
        if len(tokens) < need:
            raise ValueError(f"raw file: {points} points of {count} vectors expected, the values end early")
        table = np.array(tokens[:need], dtype=object).reshape(points, count + 1)[:, 1:]
        if complex_values:
            def parse(token: str) -> complex:
                real, _, imaginary = token.partition(",")
                return complex(float(real), float(imaginary or 0.0))
            values = np.vectorize(parse, otypes=[complex])(table)
        else:
            values = table.astype(float)
        plots.append(RawFile(header.get("plotname", ""), {name: values[:, k] for k, name in enumerate(names)}))
    return plots


def run(netlist_text: str, folder: Optional[Path] = None, timeout_s: float = 600.0) -> RawFile:
    """Run one netlist with ``ngspice -b`` and read its analysis back. Raises UserError naming
    the problem when ngspice is missing, fails, or writes no results."""
    program = ngspice_path()
    if program is None:
        raise UserError(INSTALL_HINT)
    with tempfile.TemporaryDirectory(dir=folder) as work:
        circuit, raw = Path(work) / "circuit.cir", Path(work) / "circuit.raw"
        circuit.write_text(netlist_text)
        env = dict(os.environ, SPICE_ASCIIRAWFILE="1")
        done = subprocess.run([program, "-b", "-r", str(raw), str(circuit)], cwd=work, env=env,
                              capture_output=True, text=True, timeout=timeout_s)
        errors = [line for line in (done.stdout + done.stderr).splitlines()
                  if line.lower().startswith(("error", "fatal")) or "error:" in line.lower()]
        if done.returncode != 0 or not raw.is_file() or errors:
            detail = errors[0] if errors else (done.stderr.strip().splitlines() or ["no raw file written"])[-1]
            raise UserError(f"ngspice failed on {netlist_text.splitlines()[0]!r}: {detail}")
        plots = read_raw(raw.read_text())
    if not plots:
        raise UserError(f"ngspice wrote no analysis for {netlist_text.splitlines()[0]!r}")
    return plots[-1]

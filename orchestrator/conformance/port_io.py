"""A target's named ports through one slave's preallocated buffers, for the runner: each port's
elements found once, written and read as arrays; an input a vector leaves alone keeps its
start value."""
from __future__ import annotations

from typing import Dict, List, Sequence, Tuple

import numpy as np

from orchestrator.conformance.target import Target


class PortIO:
    """Named inputs and outputs of one slave through its preallocated buffers."""

    def __init__(self, target: Target, slave, inputs: Sequence[str], outputs: Sequence[str]):
        variables = target.interface.variables
        self.slave = slave
        tables: Tuple[Dict[str, List[int]], Dict[str, List[int]]] = ({}, {})
        self.slot: Dict[str, Tuple[bool, str, int]] = {}
        self._positions: Dict[tuple, Tuple[str, np.ndarray]] = {}
        for is_input, names in ((True, inputs), (False, outputs)):
            table = tables[0 if is_input else 1]
            for name in dict.fromkeys(names):
                var = variables[name]
                vrs = table.setdefault(var.type, [])
                self.slot[name] = (is_input, var.type, len(vrs))
                vrs.append(var.vr)
        slave.bind(*tables)
        # an element a vector leaves alone keeps its start value (it is written with the rest)
        for name in dict.fromkeys(inputs):
            start = variables[name].start
            if start is not None:
                self.set([name], [_start_value(variables[name].type, start)])

    def set(self, names: Sequence[str], values) -> None:
        buffers = self.slave.inputs
        type_name, positions = self._where(names)
        buffers[type_name].values[positions] = np.ravel(values)

    def get(self, names: Sequence[str]) -> np.ndarray:
        type_name, positions = self._where(names)
        return np.asarray(self.slave.outputs[type_name].values[positions], dtype=float)

    def _where(self, names: Sequence[str]):
        """(FMI type, buffer positions) of a port's elements (all of one type), found once."""
        key = tuple(names)
        found = self._positions.get(key)
        if found is None:
            slots = [self.slot[n] for n in names]
            found = self._positions[key] = (slots[0][1], np.array([slot[2] for slot in slots], dtype=np.intp))
        return found


def _start_value(type_name: str, start) -> float:
    if type_name == "Boolean":
        return float(str(start).lower() in ("true", "1"))
    return float(start)

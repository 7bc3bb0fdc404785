"""The values of an FMU's ports: one flat numpy array per FMI type and a value-reference → slot
table, so a get or set of many values is one fancy-indexing operation (docs/architecture.md,
"Build pipeline"); the ports' views into it (``io``); the checks of the numeric inputs before
each step; a core's output record written into it. No FMI library here: the facade registers
each element with pythonfmu through the ``register`` callback it gives.
"""
from __future__ import annotations

import math
import operator
from dataclasses import dataclass, field
from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple

import numpy as np

from fmus.errors import FmuCallError
from fmus.fmi.ports import Port
from fmus.reductions import all_true

FMI_TYPES = ("Real", "Integer", "Boolean", "String")
_NUMPY_DTYPES = {"Real": np.float64, "Integer": np.int64, "Boolean": np.bool_}
#: what a get of an unknown value reference returns (the call is refused and logged)
FALLBACK = {"Real": math.nan, "Integer": 0, "Boolean": False, "String": ""}
#: at most this many range-checked inputs of a type are tested in plain Python
_FEW_BOUNDED = 8


@dataclass
class _InputCheck:
    """The inputs of one numeric type checked before each step: a view of them in the value
    store (their slots when not contiguous); whether they must be finite (Reals), with a scratch
    buffer; those with a declared range (a few: (position, min, max) tested in plain Python,
    cheaper than numpy for a handful; many: positions and bound arrays); (port, element) of each
    value, for the message."""

    view: Optional[np.ndarray]
    index: Any
    finite: bool
    scratch: np.ndarray
    few: Optional[List[Tuple[int, float, float]]]
    bounded: Optional[np.ndarray]
    low: np.ndarray
    high: np.ndarray
    elements: List[Tuple[Port, str]]


def slot_index(slots: List[int]):
    """Store slots as an index: a slice when they are consecutive (numpy then copies a block,
    and a slice of a store is a view of it), else an index array."""
    if slots == list(range(slots[0], slots[0] + len(slots))):
        return slice(slots[0], slots[0] + len(slots))
    return np.array(slots, dtype=np.int64)


@dataclass
class TypeStore:
    """Flat value store of one FMI type plus the value-reference → slot table."""

    values: Any
    slot_of_vr: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))



class ValueStore:
    """Every port's values: ``types`` (a :class:`TypeStore` per FMI type), ``io`` (each port's
    view, scalar ports as 0-d arrays, a String port its str), and the slots of each port.

    ``register(port, element, getter) -> value reference`` is called for every element in port
    order (the facade makes the pythonfmu variable there); ``getter`` reads the element's value."""

    def __init__(self, ports: Sequence[Port], register: Callable[[Port, str, Callable[[], Any]], int]):
        counts = {t: sum(p.size for p in ports if p.type == t) for t in FMI_TYPES}
        self.types: Dict[str, TypeStore] = {
            t: TypeStore(np.zeros(n, dtype=_NUMPY_DTYPES[t]) if t in _NUMPY_DTYPES else [""] * n)
            for t, n in counts.items()}
        total_vrs = sum(p.size for p in ports)
        for store in self.types.values():
            store.slot_of_vr = np.full(total_vrs, -1, dtype=np.int64)
        self.io: Dict[str, Any] = {}
        self.string_ports: Dict[str, Tuple[int, int]] = {}    # String port → (first slot, elements; 0: scalar)
        self.port_slots: Dict[str, Tuple[str, int]] = {}       # numeric port → (type, its first slot)
        self._slot_cache: Dict[tuple, Tuple[list, np.ndarray]] = {}
        self._output_plans: Dict[tuple, tuple] = {}            # write_outputs: the ports of each field list
        next_slot = {t: 0 for t in FMI_TYPES}
        for port in ports:
            store = self.types[port.type]
            first = next_slot[port.type]
            if port.type == "String":
                store.values[first:first + port.size] = [str(port.start)] * port.size
                self.string_ports[port.name] = (first, port.size if port.shape else 0)
                self.io[port.name] = self.string_value(port.name)
            else:
                self.port_slots[port.name] = (port.type, first)
                view = store.values[first:first + port.size]
                view[:] = port.start
                self.io[port.name] = view.reshape(port.shape) if port.shape else view.reshape(())
            values = store.values
            for k, element in enumerate(port.element_names()):
                slot = first + k
                vr = register(port, element, lambda slot=slot: values[slot])
                store.slot_of_vr[vr] = slot
            next_slot[port.type] += port.size

    # ---- value references ------------------------------------------------------------------
    def slots(self, type_name: str, vrs) -> np.ndarray:
        """The slots of ``vrs`` in the type's store; FmuCallError for an unknown reference or one
        of another type. An FMI host (pythonfmu's C layer passes lists) sends the same lists
        every step: each list is resolved once."""
        if not isinstance(vrs, list) or not vrs:
            return self._resolve(type_name, vrs)
        key = (type_name, len(vrs), vrs[0], vrs[-1])
        cached = self._slot_cache.get(key)
        if cached is not None and cached[0] == vrs:
            return cached[1]
        slots = self._resolve(type_name, vrs)
        self._slot_cache[key] = (list(vrs), slots)
        return slots

    def _resolve(self, type_name: str, vrs) -> np.ndarray:
        store = self.types[type_name]
        vr_array = np.asarray(vrs, dtype=np.int64)
        if vr_array.size and (vr_array.max() >= store.slot_of_vr.size or vr_array.min() < 0):
            unknown = [int(vr) for vr in vr_array if not 0 <= vr < store.slot_of_vr.size]
            raise FmuCallError(f"unknown value reference(s) {unknown[:10]}")
        slots = store.slot_of_vr[vr_array]
        if (slots < 0).any():
            raise FmuCallError(f"value reference(s) {vr_array[slots < 0].tolist()[:10]} are not {type_name}")
        return slots

    # ---- get and set (numeric: one fancy-indexing operation) ----------------------------------
    def get(self, type_name: str, vrs) -> list:
        return self.types[type_name].values[self.slots(type_name, vrs)].tolist()

    def set(self, type_name: str, vrs, values) -> None:
        self.types[type_name].values[self.slots(type_name, vrs)] = values

    def get_strings(self, vrs) -> list:
        strings = self.types["String"].values
        return [strings[s] for s in self.slots("String", vrs)]

    def set_strings(self, vrs, values) -> None:
        strings = self.types["String"].values
        for slot, value in zip(self.slots("String", list(vrs)), values):
            strings[slot] = str(value)
        for name in self.string_ports:
            self.io[name] = self.string_value(name)

    def string_value(self, name: str):
        """A String port's value: a str, or a tuple of them for an array port."""
        first, size = self.string_ports[name]
        strings = self.types["String"].values
        return strings[first] if size == 0 else tuple(strings[first:first + size])

    def view(self, type_name: str, vrs) -> Tuple[np.ndarray, np.ndarray]:
        """(store, slots): the flat store of a numeric type and the slots of ``vrs`` in it."""
        return self.types[type_name].values, self.slots(type_name, vrs)

    # ---- a core's outputs --------------------------------------------------------------------
    def write_outputs(self, out, fields) -> None:
        """Copy a core's output record to the ports: ``fields`` is ((port, attribute), ...).
        The scalar ports of each type are written together, one assignment of all their values
        into the type's store (a receiver has a dozen, read every frame); array ports are
        copied one by one."""
        plan = self._output_plans.get(fields)
        if plan is None:
            plan = self._output_plans[fields] = self._output_plan(fields)
        arrays, scalars = plan
        for port, attribute in arrays:
            port[...] = getattr(out, attribute)
        for values, slots, read in scalars:
            values[slots] = read(out)

    def _output_plan(self, fields):
        """(array ports and their attributes; per type of scalar port: the type's store, the
        ports' slots in it, a getter of their attributes' values in that order)."""
        arrays = tuple((self.io[port], attribute) for port, attribute in fields if self.io[port].ndim)
        by_type: Dict[str, List[Tuple[int, str]]] = {}
        for port, attribute in fields:
            if not self.io[port].ndim:
                type_name, slot = self.port_slots[port]
                by_type.setdefault(type_name, []).append((slot, attribute))
        scalars = []
        for type_name, entries in by_type.items():
            slots = [slot for slot, _ in entries]
            read = operator.attrgetter(*(attribute for _, attribute in entries))
            scalars.append((self.types[type_name].values, slot_index(slots) if len(slots) > 1 else slots[0], read))
        return arrays, tuple(scalars)


class InputChecks:
    """The numeric inputs checked before each step: finite (Reals) and within a declared range.
    A ``bad_input="unit"`` port is left to the unit when ``unit_handled`` is None or names it."""

    def __init__(self, ports: Sequence[Port], store: ValueStore, unit_handled: Optional[Sequence[str]] = None):
        self.store = store
        self.checks: List[Tuple[str, _InputCheck]] = []
        for type_name in ("Real", "Integer"):
            slots, bounded, low, high, elements = [], [], [], [], []
            first = 0
            for port in ports:
                if port.type != type_name:
                    continue
                left_to_unit = port.bad_input == "unit" and (unit_handled is None or port.name in unit_handled)
                if port.causality == "input" and not left_to_unit:
                    if port.bad_input != "clamp" and (port.min is not None or port.max is not None):
                        bounded.extend(range(len(slots), len(slots) + port.size))
                        low.extend([-math.inf if port.min is None else port.min] * port.size)
                        high.extend([math.inf if port.max is None else port.max] * port.size)
                    slots.extend(range(first, first + port.size))
                    elements.extend((port, element) for element in port.element_names())
                first += port.size
            if not slots or (type_name == "Integer" and not bounded):
                continue                  # an integer without a declared range cannot be wrong
            index = slot_index(slots)
            # the stores are allocated once and written in place, so a slice stays their view
            view = store.types[type_name].values[index] if isinstance(index, slice) else None
            few = list(zip(bounded, low, high)) if 0 < len(bounded) <= _FEW_BOUNDED else None
            self.checks.append((type_name, _InputCheck(
                view, index, type_name == "Real", np.zeros(len(slots), dtype=bool), few,
                np.array(bounded, dtype=np.int64) if bounded and few is None else None,
                np.array(low, dtype=np.float64), np.array(high, dtype=np.float64), elements)))

    def error(self) -> Optional[str]:
        """The first input that is not finite or outside its declared range, or None: per numeric
        type one vectorised finiteness test over all its inputs (no warnings, unlike a sum or dot
        product of ±inf) and one test of the few with a declared range."""
        for type_name, check in self.checks:
            values = check.view if check.view is not None else self.store.types[type_name].values[check.index]
            if check.finite:
                finite = np.isfinite(values, out=check.scratch)
                if not all_true(finite):
                    return self._message(check, int(np.argmin(finite)), values)
            if check.few is not None:
                item = values.item
                for k, low, high in check.few:
                    if not low <= item(k) <= high:
                        return self._message(check, k, values)
            elif check.bounded is not None:
                inside = values[check.bounded]
                good = (inside >= check.low) & (inside <= check.high)
                if not all_true(good):
                    return self._message(check, int(check.bounded[int(np.argmin(good))]), values)
        return None

    @staticmethod
    def _message(check: _InputCheck, k: int, values: np.ndarray) -> str:
        port, element = check.elements[k]
        return "input " + port.range_error(element, values[k].item())

"""Bulk access to a slave's Real values for our FMUs' forwarding binary (docs/performance.md,
"Frames across the FMI boundary").

pythonfmu's C wrapper answers fmi2GetReal/fmi2SetReal by building a Python list of value
references and one of values element by element: about 0.1 µs per value, 30 µs for a
320-sample frame. Our forwarding binary (orchestrator/build/forwarder/fmi2_forward.c) checks the
value references itself and then hands the host's two C arrays to the accessors made here as
memoryviews, which numpy reads or fills in place: one Python call per get or set whatever its
length. The host still calls plain fmi2GetReal/fmi2SetReal and gets the same values.

The generated slave script registers each instance pythonfmu's C wrapper creates
(``created``); the forwarder claims its instance's accessors right after fmi2Instantiate
(``take``). The registry holds the slaves weakly, so a plain pythonfmu FMU (built without the
forwarder) leaves nothing behind. Setting RAILCOSIM_NO_BULK=1 in the environment makes the
forwarder leave every call to pythonfmu (a comparison of the two routes).
"""
from __future__ import annotations

import weakref
from typing import Callable, Tuple

import numpy as np

_created: "weakref.WeakValueDictionary[str, object]" = weakref.WeakValueDictionary()
#: instance names whose accessors a forwarder claimed (tests read it)
claimed = []


def created(slave) -> None:
    """Record an instance pythonfmu's C wrapper just created, by its instance name."""
    _created[slave.instance_name] = slave


def take(instance_name: str) -> Tuple[Callable, Callable, Callable]:
    """(resolve, get, set) for the Real values of the instance just created under
    ``instance_name`` (KeyError if none was registered: the forwarder then forwards every call)."""
    slave = _created.pop(instance_name)
    accessors = real_accessors(slave)
    claimed.append(instance_name)
    return accessors


def real_accessors(slave) -> Tuple[Callable, Callable, Callable]:
    """resolve(refs) → the number of that list of value references, get(number, values) fills
    ``values``, set(number, values) stores them; the buffers as the host passed them
    (fmi2ValueReference = uint32, fmi2Real = float64). The forwarder checked the references and
    keeps the lists it resolved (a host sends the same lists every step), so a get or set costs
    one slot lookup here; a run of consecutive slots is a slice."""
    store = slave._stores["Real"]
    values, slot_of_vr = store.values, store.slot_of_vr
    lists = []

    def resolve(ref_buffer) -> int:
        where = slot_of_vr[np.frombuffer(ref_buffer, dtype=np.uint32)]
        first = int(where[0])
        if where.size > 1 and np.array_equal(where, np.arange(first, first + where.size)):
            where = slice(first, first + where.size)
        lists.append(where)
        return len(lists) - 1

    def get(number: int, value_buffer) -> None:
        np.frombuffer(value_buffer, dtype=np.float64)[:] = values[lists[number]]

    def put(number: int, value_buffer) -> None:
        values[lists[number]] = np.frombuffer(value_buffer, dtype=np.float64)

    return resolve, get, put

"""Direct access to a slave's Real, Integer and Boolean values for our FMUs' forwarding binary
(docs/performance.md, "Frames across the FMI boundary").

pythonfmu's C wrapper answers every fmi2Get/fmi2Set of a number type by taking the GIL,
building a Python list of value references and one of values element by element and calling
the slave: about 0.1 µs per value, 30 µs for a 320-sample frame. Our forwarding binary
(orchestrator/packaging/forwarder/fmi2_forward.c) checks the value references itself; for each list
of references a host sends (the same lists every step) it asks the resolvers made here, once,
where those values live in the slave's value store (fmus/fmi/value_store.py): the store's address
and either the first of a run of consecutive slots or the address of an array of slots. From
then on a get or set of that list is a copy in C between the host's array and the store, with
no Python call. The host still calls plain fmi2Get/fmi2Set and gets the values pythonfmu's
route gives (tests/test_bulk_values.py).

The generated slave script registers each instance pythonfmu's C wrapper creates
(``created``); the forwarder claims its instance's resolvers right after fmi2Instantiate
(``take``, with references to what pythonfmu holds of the slave: see the forwarder's "After
fmi2Fatal") and keeps them (and with them the store and the slot arrays) until
fmi2FreeInstance. The registry holds the slaves weakly, so a plain pythonfmu FMU (built
without the forwarder) leaves nothing behind. Setting RAILCOSIM_NO_BULK=1 in the environment
makes the forwarder leave every call to pythonfmu (a comparison of the two routes).
"""
from __future__ import annotations

import weakref
from typing import Callable, Tuple

import numpy as np

from fmus.fmi.value_store import slot_index

_created: "weakref.WeakValueDictionary[str, object]" = weakref.WeakValueDictionary()
#: instance names whose resolvers a forwarder claimed (tests read it)
claimed = []

#: the store's element type per FMI type, as the forwarder copies it (fmi2Real ↔ float64,
#: fmi2Integer ↔ int64, fmi2Boolean ↔ one byte 0 or 1)
STORE_TYPES = (("Real", np.float64), ("Integer", np.int64), ("Boolean", np.bool_))


def created(slave) -> None:
    """Record an instance pythonfmu's C wrapper just created, by its instance name."""
    _created[slave.instance_name] = slave


def take(instance_name: str, resolvers: bool = True) -> tuple:
    """What pythonfmu's C wrapper holds of the instance just created under ``instance_name`` —
    the slave, its class and its log queue, of which the forwarder keeps a reference each so
    that pythonfmu's double release after fmi2Fatal frees nothing in use — followed, when
    ``resolvers``, by its Real, Integer and Boolean resolvers (KeyError if no instance was
    registered under that name: the forwarder then forwards every call)."""
    slave = _created.pop(instance_name)
    held = (slave, type(slave), slave._get_log_queue())
    if not resolvers:
        return held
    claimed.append(instance_name)
    return held + tuple(store_resolver(slave, type_name, dtype) for type_name, dtype in STORE_TYPES)


def store_resolver(slave, type_name: str, dtype) -> Callable:
    """resolve(refs) → (the store's address, first slot, 0) for a list of value references
    (uint32, as the host passed them) whose slots are consecutive, else (address, 0, the
    address of an int64 array of their slots, kept here while the forwarder holds this
    resolver). The forwarder checked the references first."""
    store = slave.store.types[type_name]
    values, slot_of_vr = store.values, store.slot_of_vr
    if values.dtype != dtype or not values.flags.c_contiguous:
        raise TypeError(f"{type_name} store: {values.dtype}, not a contiguous {np.dtype(dtype)}")
    address = values.ctypes.data
    kept = []

    def resolve(ref_buffer) -> Tuple[int, int, int]:
        slots = slot_of_vr[np.frombuffer(ref_buffer, dtype=np.uint32)].tolist()
        if min(slots) < 0:
            raise KeyError(f"{type_name} value references without a slot")
        where = slot_index(slots)
        if isinstance(where, slice):
            return address, where.start, 0
        kept.append(where)
        return address, 0, where.ctypes.data

    return resolve

"""Slaves the master steps: an FMU through fmpy, or a facade in-process without FMI.

Both implement the slave protocol (orchestrator/protocols.py: preallocated value buffers per
FMI type, step, read, write), so the master does not know which it drives. The in-process
slave is the performance reference (docs/performance.md) and a debugging aid.
"""
from __future__ import annotations

import ctypes
import hashlib
import importlib
import os
import shutil
import sys
import tempfile
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Dict, List, Mapping, Optional, Sequence

import numpy as np

from orchestrator.archives import MAX_UNPACKED_VARIABLE, max_unpacked_bytes, safe_extract, shown_size
from orchestrator.errors import SimulationError, UserError
from orchestrator.library_shortcuts import count_nonzero, library_function, raw_function
from orchestrator.protocols import Causality, Slave, UnitDef

FMI_TYPES = ("Real", "Integer", "Boolean", "String")
_CTYPES = {"Real": ctypes.c_double, "Integer": ctypes.c_int, "Boolean": ctypes.c_int}


@dataclass(frozen=True)
class Variable:
    name: str
    vr: int
    type: str
    causality: Causality
    variability: str
    unit: Optional[str]
    start: object
    min: Optional[float] = None
    max: Optional[float] = None
    description: str = ""
    #: the unit of the variable's declaredType (FMI 2.0: where the variable names none itself)
    declared_unit: Optional[str] = None


@dataclass
class Interface:
    """What the master needs to know of a component: variables, units, its own step."""

    model_identifier: str
    variables: Dict[str, Variable]
    units: Dict[str, UnitDef]
    default_step_s: Optional[float]
    guid: str
    generation_tool: str
    version: Optional[str]
    frame_ports: frozenset = frozenset()   # waveform arrays (railcosim vendor annotation)
    #: outputs' fail-safe values by name, what a DCP master shows while they are lost (railcosim
    #: variable annotations; docs/hil.md)
    fail_safe: Mapping[str, float] = field(default_factory=dict)


def read_interface(fmu_path: Path) -> Interface:
    """Read and check a .fmu's modelDescription; any defect is one clear UserError. In a process
    that keeps extractions (keep_extractions: a study's worker and the runs forked from it) the
    interface read is kept too, per FMU file as it is (path, size, modification time)."""
    fmu_path = Path(fmu_path)
    if not fmu_path.is_file():
        raise UserError(f"{fmu_path}: FMU not found (run `railcosim build`?)")
    if _KEPT_EXTRACTIONS is None:
        return _read_interface(fmu_path)
    stat = fmu_path.stat()
    key = (str(fmu_path.resolve()), stat.st_size, stat.st_mtime_ns)
    interface = _KEPT_INTERFACES.get(key)
    if interface is None:
        interface = _KEPT_INTERFACES[key] = _read_interface(fmu_path)
    return interface


#: interfaces read in a process that keeps extractions, by (resolved path, size, mtime_ns)
_KEPT_INTERFACES: Dict[tuple, Interface] = {}


def _read_interface(fmu_path: Path) -> Interface:
    from fmpy import read_model_description

    try:
        with zipfile.ZipFile(fmu_path) as archive:
            if "modelDescription.xml" not in archive.namelist():
                raise UserError(f"{fmu_path}: not an FMU (no modelDescription.xml)")
            # read whole into memory by fmpy and lxml: held to the bound an extraction is held to
            size, bound = archive.getinfo("modelDescription.xml").file_size, max_unpacked_bytes()
            if size > bound:
                raise UserError(f"{fmu_path}!modelDescription.xml: {shown_size(size)}, more than the "
                                f"{shown_size(bound)} allowed (set {MAX_UNPACKED_VARIABLE} to raise the bound)")
    except zipfile.BadZipFile:
        raise UserError(f"{fmu_path}: not an FMU (not a zip archive)") from None
    try:
        md = read_model_description(str(fmu_path), validate=True)
    except Exception as error:  # fmpy raises plain exceptions with the schema message
        first = str(error).strip().splitlines()[0] if str(error).strip() else type(error).__name__
        raise UserError(f"{fmu_path}: invalid modelDescription.xml: {first}") from None
    if md.fmiVersion != "2.0" or md.coSimulation is None:
        raise UserError(f"{fmu_path}: not an FMI 2.0 co-simulation FMU")
    units = {}
    for unit in md.unitDefinitions:
        base = unit.baseUnit
        if base is None:
            units[unit.name] = UnitDef(unit.name)
            continue
        exps = tuple(int(getattr(base, k) or 0) for k in ("kg", "m", "s", "A", "K", "mol", "cd", "rad"))
        units[unit.name] = UnitDef(unit.name, exps, float(base.factor or 1.0), float(base.offset or 0.0))
    variables = {}
    for v in md.modelVariables:
        variables[v.name] = Variable(v.name, int(v.valueReference), v.type, v.causality,
                                     v.variability, v.unit, v.start,
                                     None if v.min is None else float(v.min),
                                     None if v.max is None else float(v.max), v.description or "",
                                     getattr(v.declaredType, "unit", None))
    step = md.defaultExperiment.stepSize if md.defaultExperiment is not None else None
    from lxml import etree

    with zipfile.ZipFile(fmu_path) as archive:
        root = etree.fromstring(archive.read("modelDescription.xml"))
    return Interface(md.coSimulation.modelIdentifier, variables, units,
                     float(step) if step else None, md.guid, md.generationTool or "", md.version,
                     frame_ports_of(root), fail_safe_of(root, f"{fmu_path}!modelDescription.xml"))


def frame_ports_of(root) -> frozenset:
    """Frame ports named in our VendorAnnotations of a modelDescription (absent in foreign FMUs)."""
    node = root.find("VendorAnnotations/Tool[@name='railcosim']/FramePorts")
    return frozenset((node.text or "").split()) if node is not None else frozenset()


def fail_safe_of(root, where: str = "modelDescription.xml") -> Dict[str, float]:
    """Each output's fail-safe value from our variable annotations of a modelDescription
    (``<Annotations><Tool name="railcosim"><FailSafe value="…"/>``; a Boolean as 0 or 1)."""
    values = {}
    for variable in root.iterfind("ModelVariables/ScalarVariable"):
        node = variable.find("Annotations/Tool[@name='railcosim']/FailSafe")
        if node is None:
            continue
        name, text = variable.get("name"), node.get("value", "")
        try:
            values[name] = 1.0 if text == "true" else 0.0 if text == "false" else float(text)
        except ValueError:
            raise UserError(f"{where}: variable {name}: fail-safe value {text!r} is not a number") from None
    return values


class ValueBuffer:
    """Preallocated value references and values of one FMI type (numpy view on ctypes memory)."""

    def __init__(self, type_name: str, vrs: Sequence[int]):
        self.type = type_name
        self.count = len(vrs)
        self.vr = (ctypes.c_uint * max(self.count, 1))(*vrs)
        self.vr_array = np.asarray(vrs, dtype=np.int64)
        if type_name == "String":
            self.raw = (ctypes.c_char_p * max(self.count, 1))()
            self.values = [""] * self.count
        else:
            self.raw = (_CTYPES[type_name] * max(self.count, 1))()
            self.values = np.ctypeslib.as_array(self.raw)[:self.count]


def contiguous(index: np.ndarray):
    """``index`` as a slice when it is a run of consecutive positions (numpy then copies a block
    instead of gathering element by element), else as it is."""
    if index.size and index[0] >= 0 and np.array_equal(index, np.arange(index[0], index[0] + index.size)):
        return slice(int(index[0]), int(index[0]) + index.size)
    return index


def _coerce(type_name: str, value):
    if type_name == "Real":
        return float(value)
    if type_name == "Integer":
        return int(value)
    if type_name == "Boolean":
        return bool(value) if not isinstance(value, str) else value.lower() in ("1", "true")
    return str(value)


#: where keep_extractions() keeps FMUs extracted across runs (None: once per run, in its workdir)
_KEPT_EXTRACTIONS: Optional[Path] = None
#: each FMU file's content digest, by (resolved path, size, mtime_ns): hashed once per file
_CONTENT_DIGESTS: Dict[tuple, str] = {}


def keep_extractions(folder: Optional[Path]) -> None:
    """From now on, in this process and the processes forked from it, extract each FMU once
    into ``folder`` and let every later run use that extraction (a study's worker does this,
    docs/studies.md); None: back to one extraction per run in the run's work folder. An
    extraction belongs to the FMU's content (sha256): an FMU rebuilt in place is extracted
    anew, the same FMU unpacked from a .ssp for each run is extracted once."""
    global _KEPT_EXTRACTIONS
    _KEPT_EXTRACTIONS = Path(folder) if folder is not None else None


def extractions_kept() -> bool:
    """Whether this process keeps extractions (keep_extractions): a run then needs no work
    folder of its own."""
    return _KEPT_EXTRACTIONS is not None


def _extract_once(fmu_path: Path, workdir: Optional[Path]) -> Path:
    """One extraction (and so one loaded library) per FMU file, shared by its instances."""
    if _KEPT_EXTRACTIONS is not None:
        return _kept_extraction(Path(fmu_path), _KEPT_EXTRACTIONS)
    folder = Path(workdir) / f"{Path(fmu_path).stem}_{abs(hash(str(Path(fmu_path).resolve()))):x}"
    if not folder.is_dir():
        safe_extract(Path(fmu_path), folder)
    return folder


def import_python_module(fmu_path: Path) -> bool:
    """Import a Python (pythonfmu) FMU's module into this process from its kept extraction, as
    its instances would at instantiation, so that processes forked from this one find it (and
    what it imports) already imported: a study's worker does this once per system. Only with
    keep_extractions on (the module's folder must outlive the runs); False when the FMU has no
    Python module or extractions are not kept."""
    if _KEPT_EXTRACTIONS is None:
        return False
    resources = _kept_extraction(Path(fmu_path), _KEPT_EXTRACTIONS) / "resources"
    if not (resources / "slavemodule.txt").is_file():
        return False
    if str(resources) not in sys.path:
        sys.path.insert(0, str(resources))
    importlib.import_module((resources / "slavemodule.txt").read_text().strip())
    return True


def _kept_extraction(fmu_path: Path, kept: Path) -> Path:
    """The FMU's extraction in ``kept``, made whole in a staging folder and renamed into place
    (a run stopped mid-extraction leaves no half folder for the next run to load)."""
    resolved = fmu_path.resolve()
    try:
        stat = resolved.stat()
        key = (str(resolved), stat.st_size, stat.st_mtime_ns)
        digest = _CONTENT_DIGESTS.get(key)
        if digest is None:
            digest = _CONTENT_DIGESTS[key] = hashlib.sha256(resolved.read_bytes()).hexdigest()[:24]
    except OSError as error:
        raise UserError(f"{fmu_path}: cannot read ({error.strerror or error})") from None
    folder = kept / f"{resolved.stem}_{digest}"
    if not folder.is_dir():
        kept.mkdir(parents=True, exist_ok=True)
        staging = Path(tempfile.mkdtemp(prefix=".extracting_", dir=kept))
        try:
            safe_extract(resolved, staging)
            os.rename(staging, folder)
        except OSError:
            if not folder.is_dir():          # not another process's extraction that came first
                raise
        finally:
            shutil.rmtree(staging, ignore_errors=True)
    return folder


def make_buffers(table: Dict[str, List[int]]) -> Dict[str, ValueBuffer]:
    return {t: ValueBuffer(t, vrs) for t, vrs in table.items() if vrs}


class _ExtractedComponent(Slave):
    """A component whose FMU archive is extracted (once per run) into the work folder."""

    def __init__(self, name: str, fmu_path: Path, interface: Interface, workdir: Path):
        self.name = name
        self.interface = interface
        self.unzip_dir = _extract_once(fmu_path, workdir)


class FmuSlave(_ExtractedComponent):
    """One FMU instance driven through fmpy's ctypes functions with preallocated buffers."""

    in_process = False

    def __init__(self, name: str, fmu_path: Path, interface: Interface, workdir: Path):
        from fmpy import platform, sharedLibraryExtension
        from fmpy.fmi2 import FMU2Slave

        super().__init__(name, fmu_path, interface, workdir)
        binary = f"binaries/{platform}/{interface.model_identifier}{sharedLibraryExtension}"
        if not (self.unzip_dir / binary).is_file():
            present = sorted(p.name for p in (self.unzip_dir / "binaries").glob("*") if p.is_dir())
            raise UserError(f"{fmu_path}: no binary for {platform} ({binary} is missing; "
                            f"binaries for: {', '.join(present) or 'none'})")
        self._fmu = FMU2Slave(guid=interface.guid, unzipDirectory=str(self.unzip_dir),
                              modelIdentifier=interface.model_identifier, instanceName=name)
        self._component = None
        self._fatal = False
        # a plain pythonfmu binary (a foreign FMU, or ours built without a C compiler) exports
        # this; our forwarding binary does not need it (see free)
        self._finalize = library_function(self._fmu, "finalizePythonInterpreter")
        if self._finalize is not None:
            _claim_library(self.unzip_dir)
        self.messages: List[str] = []
        self.inputs: Dict[str, ValueBuffer] = {}
        self.outputs: Dict[str, ValueBuffer] = {}

    # ---- lifecycle --------------------------------------------------------------------------
    def instantiate(self) -> None:
        _LOG_SINKS[self.name.encode()] = self.messages
        try:
            self._fmu.instantiate(callbacks=_shared_callbacks(), loggingOn=True)
        except Exception:
            raise UserError(f"{self.name}: instantiation failed{self._last_message()}") from None
        self._component = self._fmu.component
        self._component_arg = ctypes.c_void_p(self._component)

    def _call(self, what: str, function, *args):
        try:
            return function(self._component, *args)
        except Exception as error:
            status = getattr(error, "status", None)
            if status is not None and status >= 4:
                self._fatal = True
            raise SimulationError(f"{self.name}: {what} failed{self._last_message()}") from None

    def _last_message(self) -> str:
        # prefer the FMU's own message over pythonfmu's generic "Fatal py exception" wrapper
        own = [m for m in self.messages if m and not m.startswith("Fatal py exception")]
        chosen = own or self.messages
        return f": {chosen[-1]}" if chosen else ""

    def setup_experiment(self, start_time: float, stop_time: Optional[float]) -> None:
        self._call("setupExperiment", self._fmu.fmi2SetupExperiment, 0, 0.0, start_time,
                   1 if stop_time is not None else 0, stop_time or 0.0)

    def enter_initialization(self) -> None:
        self._call("enterInitializationMode", self._fmu.fmi2EnterInitializationMode)

    def exit_initialization(self) -> None:
        self._call("exitInitializationMode (parameters or data files rejected)",
                   self._fmu.fmi2ExitInitializationMode)

    def set_values(self, values: Dict[str, object]) -> None:
        """Set parameters/inputs by name (initialisation only; not on the hot path)."""
        by_type: Dict[str, list] = {}
        for name, value in values.items():
            var = self.interface.variables[name]
            by_type.setdefault(var.type, []).append((var.vr, _coerce(var.type, value)))
        for type_name, pairs in by_type.items():
            buffer = ValueBuffer(type_name, [vr for vr, _ in pairs])
            if type_name == "String":
                for k, (_, value) in enumerate(pairs):
                    buffer.raw[k] = value.encode()
            else:
                buffer.values[:] = [value for _, value in pairs]
            self._call(f"set {type_name} values", getattr(self._fmu, f"fmi2Set{type_name}"),
                       buffer.vr, buffer.count, buffer.raw)

    def bind(self, inputs: Dict[str, List[int]], outputs: Dict[str, List[int]]) -> None:
        self.inputs, self.outputs = make_buffers(inputs), make_buffers(outputs)
        # last written values (NaN: nothing written yet); strings are always written
        # the hot path calls the library's functions directly with arguments converted once
        # (fmpy's wrappers convert every argument and add two Python calls per call), and
        # raises fmpy's exception on an error status as they do
        self._setters = [(self._raw(f"fmi2Set{b.type}"), b, ctypes.c_size_t(b.count),
                          None if b.type == "String" else np.full(b.count, np.nan)) for b in self.inputs.values()]
        self._getters = [(self._raw(f"fmi2Get{b.type}"), b, ctypes.c_size_t(b.count)) for b in self.outputs.values()]
        self._do_step = self._raw("fmi2DoStep")[1]
        self._unchanged = {id(b): np.zeros(b.count, dtype=bool) for b in self.inputs.values()}

    def _raw(self, name: str):
        return name, raw_function(self._fmu, name)

    def write_inputs(self) -> None:
        component = self._component_arg
        for (name, setter), buffer, count, last in self._setters:
            # an FMU keeps its inputs until they are set again (FMI 2.0 §4.2.1): an unchanged
            # buffer (occupancy, faults, commands between events) costs no call
            if last is not None:
                # a ufunc and a count of the equal values (np.array_equal's Python layer costs
                # more than the test); NaN never equals, as there
                unchanged = np.equal(last, buffer.values, out=self._unchanged[id(buffer)])
                if count_nonzero(unchanged) == unchanged.size:
                    continue
                last[:] = buffer.values
            status = setter(component, buffer.vr, count, buffer.raw)
            if status > _FMI2_WARNING:
                raise _call_exception(name, status)

    def read_outputs(self, types=None) -> None:
        """Read the output buffers (all, or only those of the given FMI types)."""
        component = self._component_arg
        for (name, getter), buffer, count in self._getters:
            if types is not None and buffer.type not in types:
                continue
            status = getter(component, buffer.vr, count, buffer.raw)
            if status > _FMI2_WARNING:
                raise _call_exception(name, status)
            if buffer.type == "String":
                buffer.values[:] = [s.decode() if s else "" for s in buffer.raw[:buffer.count]]

    def do_step(self, time_s: float, step_s: float) -> None:
        # the library's function directly, as for the gets and sets (fmpy's wrapper converts the
        # arguments and checks the status in two more Python calls)
        status = self._do_step(self._component_arg, ctypes.c_double(time_s), ctypes.c_double(step_s), 1)
        if status > _FMI2_WARNING:
            if status >= _FMI2_FATAL:
                self._fatal = True
            raise SimulationError(f"component {self.name!r} failed its step at t = {time_s:.6g} s"
                                  f"{self._last_message()}") from None

    def terminate(self) -> None:
        if self._component is not None and not self._fatal:
            self._call("terminate", self._fmu.fmi2Terminate)

    def free(self) -> None:
        """Free the instance and unload its library; after fmi2Fatal neither (FMI 2.0 §2.1.3:
        nothing more may be called on the instance, and pythonfmu would release its Python
        references twice).

        Our FMUs' forwarding binary releases pythonfmu 0.7.0's interpreter state itself when it
        is unloaded or the process exits (docs/architecture.md, "Forwarding binary"), so the
        host does nothing pythonfmu-specific. A plain pythonfmu binary (a foreign pythonfmu
        FMU, or ours built without a C compiler) does not: it keeps a global
        ``std::shared_ptr<PyState>`` that its own library destructor resets at process exit
        *after* the C++ runtime destroyed it, reading and writing freed heap memory (an abort
        now and then at exit). For such a library this method calls its exported
        ``finalizePythonInterpreter`` once no instance of it is alive, including after a failed
        fmi2Instantiate (pythonfmu creates the state before the instance) and after fmi2Fatal
        (instance not freed, library not unloaded, but its global emptied all the same).
        """
        component, self._component = self._component, None
        if component is not None and not self._fatal:
            self._fmu.fmi2FreeInstance(component)
        if self._fmu is None:
            return
        fmu, self._fmu = self._fmu, None
        if self._finalize is not None and _release_library(self.unzip_dir):
            self._finalize()
        if component is not None and self._fatal:
            return
        try:
            fmu.freeLibrary()
        except Exception:
            pass


_FMI2_WARNING, _FMI2_FATAL = 1, 4


def _call_exception(function: str, status: int) -> Exception:
    """The exception fmpy's wrapper raises for an FMI call that returned ``status``."""
    from fmpy.fmi1 import FMICallException

    return FMICallException(function=function, status=status)


_LIVE_LIBRARIES: Dict[str, int] = {}
_LOG_SINKS: Dict[bytes, List[str]] = {}
_CALLBACKS = []


def _shared_callbacks():
    """One callback structure for every instance in this process.

    fmpy's logger proxy (which formats the variadic message) keeps a single global target,
    so a second structure would redirect or break the first; messages are routed to the
    instance's own list by instance name instead.
    """
    if not _CALLBACKS:
        from fmpy import calloc, free
        from fmpy.fmi2 import (fmi2CallbackAllocateMemoryTYPE, fmi2CallbackFreeMemoryTYPE,
                               fmi2CallbackFunctions, fmi2CallbackLoggerTYPE)
        from fmpy.logging import addLoggerProxy

        def log(env, instance, status, category, message):
            sink = _LOG_SINKS.get(instance)
            if sink is not None:
                sink.append((message or b"").decode(errors="replace").strip())

        callbacks = fmi2CallbackFunctions()
        callbacks.logger = fmi2CallbackLoggerTYPE(log)
        callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
        callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
        addLoggerProxy(ctypes.byref(callbacks))
        _CALLBACKS.append((callbacks, log))
    return _CALLBACKS[0][0]


# instances alive per plain pythonfmu library (extraction folder), see FmuSlave.free
def _claim_library(unzip_dir: Path) -> None:
    key = str(unzip_dir)
    _LIVE_LIBRARIES[key] = _LIVE_LIBRARIES.get(key, 0) + 1


def _release_library(unzip_dir: Path) -> bool:
    key = str(unzip_dir)
    _LIVE_LIBRARIES[key] = _LIVE_LIBRARIES.get(key, 1) - 1
    return _LIVE_LIBRARIES[key] <= 0


class InProcessSlave(_ExtractedComponent):
    """The same facade class, driven directly in this interpreter (no FMI, no ctypes)."""

    in_process = True

    def __init__(self, name: str, fmu_path: Path, interface: Interface, workdir: Path):
        super().__init__(name, fmu_path, interface, workdir)
        resources = self.unzip_dir / "resources"
        module_name = (resources / "slavemodule.txt").read_text().strip()
        if str(resources) not in sys.path:
            sys.path.insert(0, str(resources))
        module = importlib.import_module(module_name)
        self._class = getattr(module, interface.model_identifier)
        self._resources = str(resources)
        self.messages: List[str] = []
        self._slave = None
        self.inputs: Dict[str, ValueBuffer] = {}
        self.outputs: Dict[str, ValueBuffer] = {}

    def instantiate(self) -> None:
        self._slave = self._class(instance_name=self.name, resources=self._resources)

    def _flush_log(self) -> None:
        queue = self._slave.log_queue
        self.messages.extend(m.msg for m in queue)
        queue.clear()

    def setup_experiment(self, start_time: float, stop_time: Optional[float]) -> None:
        self._slave.setup_experiment(start_time, stop_time, None)

    def enter_initialization(self) -> None:
        self._slave.enter_initialization_mode()

    def exit_initialization(self) -> None:
        try:
            self._slave.exit_initialization_mode()
        except Exception as error:
            self._flush_log()
            raise SimulationError(f"{self.name}: exitInitializationMode (parameters or data files "
                                  f"rejected): {error}") from None

    def set_values(self, values: Dict[str, object]) -> None:
        for name, value in values.items():
            var = self.interface.variables[name]
            getattr(self._slave, f"set_{var.type.lower()}")([var.vr], [_coerce(var.type, value)])

    def bind(self, inputs, outputs) -> None:
        self.inputs, self.outputs = make_buffers(inputs), make_buffers(outputs)
        slave = self._slave
        # numeric ports move straight between the master's buffers and the facade's value
        # store (slots resolved once); strings keep the facade's setters and getters
        # (a run of consecutive slots, as frame ports are, is a slice: no index array, no temporary)
        self._writes = [(store, contiguous(slots), b.values) for b in self.inputs.values() if b.type != "String"
                        for store, slots in (slave.value_view(b.type, b.vr_array),)]
        self._reads = [(b.type, store, contiguous(slots), b.values) for b in self.outputs.values()
                       if b.type != "String" for store, slots in (slave.value_view(b.type, b.vr_array),)]
        self._string_inputs = [b for b in self.inputs.values() if b.type == "String"]
        self._string_outputs = [b for b in self.outputs.values() if b.type == "String"]

    def write_inputs(self) -> None:
        for store, slots, values in self._writes:
            store[slots] = values
        for buffer in self._string_inputs:
            self._slave.set_string(buffer.vr_array, buffer.values)

    def read_outputs(self, types=None) -> None:
        """Read the output buffers (all, or only those of the given FMI types)."""
        for type_name, store, slots, values in self._reads:
            if types is None or type_name in types:
                values[:] = store[slots]
        if types is None or "String" in types:
            for buffer in self._string_outputs:
                buffer.values[:] = self._slave.get_string(buffer.vr_array)

    def do_step(self, time_s: float, step_s: float) -> None:
        ok = self._slave.do_step(time_s, step_s)
        if not ok:
            self._flush_log()
            raise SimulationError(f"component {self.name!r} failed its step at t = {time_s:.6g} s: "
                                  f"{self.messages[-1] if self.messages else 'no message'}")

    def terminate(self) -> None:
        if self._slave is not None:
            self._slave.terminate()

    def free(self) -> None:
        self._slave = None


def make_slave(name: str, fmu_path: Path, interface: Interface, workdir: Path, in_process: bool) -> Slave:
    if in_process:
        return InProcessSlave(name, fmu_path, interface, workdir)
    return FmuSlave(name, fmu_path, interface, workdir)


def new_workdir() -> Path:
    return Path(tempfile.mkdtemp(prefix="railcosim_run_"))


def remove_workdir(path: Path) -> None:
    shutil.rmtree(path, ignore_errors=True)

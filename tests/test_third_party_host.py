"""Our FMUs in hosts that are not our orchestrator (docs/third_party.md).

A non-Python host (tests/host/fmi2_host.c, compiled here: what fmusim or an S-function does)
runs every product FMU with nothing set in its environment (no LD_PRELOAD, PYTHONHOME or
PYTHONPATH) and exits 0 every time, thanks to the forwarding binary of every built FMU
(orchestrator/packaging/forwarder/); fmpy.simulate_fmu runs each FMU three times in one process.
fmpy, libcosim and the C host load, free and load again in one process with the first
extraction removed, and a host calling on after fmi2Fatal gets fmi2Error, not a crash.
"""
import ctypes
import json
import os
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest
from fmpy import read_model_description

from orchestrator.library_shortcuts import fmi_headers
from orchestrator.packaging.forwarder import DESCRIPTION_MEMBER, MARKER_SYMBOL, SETTINGS_MEMBER

HOST_SOURCE = Path(__file__).resolve().parent / "host" / "fmi2_host.c"
PRODUCT = ("Traction", "AtoController", "WaysideCoder", "RailLine", "LocoReceiver")
PYTHON_VARIABLES = ("LD_PRELOAD", "PYTHONHOME", "PYTHONPATH", "RAILCOSIM_LIBPYTHON")
# every function of FMI 2.0 for co-simulation (FMI 2.0 §2.1, §4.2)
FMI2_CS_FUNCTIONS = (
    "fmi2GetTypesPlatform", "fmi2GetVersion", "fmi2SetDebugLogging", "fmi2Instantiate",
    "fmi2FreeInstance", "fmi2SetupExperiment", "fmi2EnterInitializationMode",
    "fmi2ExitInitializationMode", "fmi2Terminate", "fmi2Reset", "fmi2GetReal", "fmi2GetInteger",
    "fmi2GetBoolean", "fmi2GetString", "fmi2SetReal", "fmi2SetInteger", "fmi2SetBoolean",
    "fmi2SetString", "fmi2GetFMUstate", "fmi2SetFMUstate", "fmi2FreeFMUstate",
    "fmi2SerializedFMUstateSize", "fmi2SerializeFMUstate", "fmi2DeSerializeFMUstate",
    "fmi2GetDirectionalDerivative", "fmi2SetRealInputDerivatives", "fmi2GetRealOutputDerivatives",
    "fmi2DoStep", "fmi2CancelStep", "fmi2GetStatus", "fmi2GetRealStatus", "fmi2GetIntegerStatus",
    "fmi2GetBooleanStatus", "fmi2GetStringStatus")


def compile_host(dest: Path) -> Path:
    compiler = shutil.which("gcc") or shutil.which("cc")
    assert compiler, "a C compiler is part of this machine kind (docs/third_party.md)"
    binary = dest / "fmi2_host"
    headers = fmi_headers()
    subprocess.run([compiler, "-O1", f"-I{headers}", "-o", str(binary), str(HOST_SOURCE), "-ldl"], check=True)
    return binary


@pytest.fixture(scope="module")
def host_binary(tmp_path_factory):
    return compile_host(tmp_path_factory.mktemp("host"))


def clean_environment(**extra):
    env = {k: v for k, v in os.environ.items() if k not in PYTHON_VARIABLES}
    env.update(extra)
    return env


def host_arguments(fmu: Path, folder: Path, cycles: str = "1", steps: int = 4):
    """Extract ``fmu`` into ``folder`` and give the host's arguments: a few steps at the FMU's
    DefaultExperiment step (signal-chain FMUs refuse any other), full traction for Traction."""
    if not folder.is_dir():
        with zipfile.ZipFile(fmu) as archive:
            archive.extractall(folder)
    md = read_model_description(str(fmu))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    step = float(md.defaultExperiment.stepSize)
    identifier = md.coSimulation.modelIdentifier
    binary = folder / "binaries" / "linux64" / f"{identifier}.so"
    if identifier == "Traction":
        io = [f"{vr['command']}=1.0", str(vr["x"]), str(vr["v"])]
        steps = 120   # one minute of full traction
    else:
        io = [str(v.valueReference) for v in md.modelVariables
              if v.causality == "output" and v.type == "Real"][:3]
    return [str(binary), (folder / "resources").as_uri(), md.guid, repr(steps * step), repr(step), cycles, *io]


def run_host(host_binary, arguments, env=None, timeout=180):
    return subprocess.run([str(host_binary), *arguments], capture_output=True, text=True,
                          env=env if env is not None else clean_environment(), timeout=timeout)


# ---- (b) every built FMU carries the forwarding binary --------------------------------------------
@pytest.mark.parametrize("name", PRODUCT)
def test_every_product_fmu_has_the_forwarding_binary(name, product_fmus, tmp_path):
    fmu = product_fmus / f"{name}.fmu"
    with zipfile.ZipFile(fmu) as archive:
        members = set(archive.namelist())
        archive.extractall(tmp_path)
    assert {f"binaries/linux64/{name}.so", f"binaries/linux64/{name}_pythonfmu.so", SETTINGS_MEMBER,
            DESCRIPTION_MEMBER} <= members
    assert f"guid={read_model_description(str(fmu)).guid}\n" in (tmp_path / DESCRIPTION_MEMBER).read_text()
    settings = dict(line.split("=", 1) for line in (tmp_path / SETTINGS_MEMBER).read_text().splitlines())
    assert set(settings) == {"LIBPYTHON", "PYTHONHOME", "PYTHONPATH"} and Path(settings["LIBPYTHON"]).is_file()
    # loading runs nothing: the forwarder loads Python and pythonfmu at the first fmi2Instantiate
    library = ctypes.CDLL(str(tmp_path / "binaries" / "linux64" / f"{name}.so"))
    assert ctypes.c_char_p(ctypes.addressof(ctypes.c_char.in_dll(library, MARKER_SYMBOL))).value.startswith(
        b"railcosim fmi2 forwarder")
    assert [f for f in FMI2_CS_FUNCTIONS if not hasattr(library, f)] == []
    assert not hasattr(library, "finalizePythonInterpreter")   # the host has nothing to call
    assert b"finalizePythonInterpreter" in (tmp_path / "binaries" / "linux64" / f"{name}_pythonfmu.so").read_bytes()
    assert read_model_description(str(fmu)).coSimulation.modelIdentifier == name


# ---- (c) a C host without any Python environment ----------------------------------------------------
def test_the_c_host_calls_nothing_pythonfmu_specific(host_binary):
    assert b"finalizePythonInterpreter" not in host_binary.read_bytes()


@pytest.mark.parametrize("name", PRODUCT)
def test_c_host_runs_each_fmu_20_times_without_python_environment(name, product_fmus, host_binary, tmp_path):
    from concurrent.futures import ThreadPoolExecutor

    arguments = host_arguments(product_fmus / f"{name}.fmu", tmp_path / "fmu")
    outputs = set()
    with ThreadPoolExecutor(2) as pool:       # two host processes at a time: one per core
        for run, proc in enumerate(pool.map(lambda _: run_host(host_binary, arguments), range(20))):
            assert proc.returncode == 0, f"run {run}: exit {proc.returncode}: {proc.stderr[-800:]}"
            outputs.add(proc.stdout)
    assert len(outputs) == 1 and outputs.pop().strip()
    if name == "Traction":
        x, v = (float(line.split()[1]) for line in proc.stdout.splitlines())
        assert x > 900.0 and 15.0 < v < 25.0    # a minute of full traction from station A


@pytest.mark.parametrize("cycles", ["2", "2r"])
def test_c_host_instantiates_and_frees_twice_in_one_process(cycles, product_fmus, host_binary, tmp_path):
    """"2": two instances one after the other; "2r": the library closed and opened between them
    (the interpreter started by the first stays: CPython with numpy cannot start twice)."""
    proc = run_host(host_binary, host_arguments(product_fmus / "Traction.fmu", tmp_path / "fmu", cycles))
    assert proc.returncode == 0, proc.stderr[-800:]
    lines = proc.stdout.splitlines()
    assert len(lines) == 4 and lines[:2] == lines[2:]


def test_c_host_with_the_fmu_env_overrides(product_fmus, host_binary, tmp_path):
    from orchestrator.hostenv import host_environment

    proc = run_host(host_binary, host_arguments(product_fmus / "Traction.fmu", tmp_path / "fmu"),
                    clean_environment(**host_environment()))
    assert proc.returncode == 0, proc.stderr[-800:]


def test_c_host_gets_fmi2error_for_a_bad_value_reference(product_fmus, host_binary, tmp_path):
    """The forwarder's check in a non-Python host (its own variadic logger), with the table found
    through a percent-encoded resource URI: every fmi2SetReal of an unknown reference is fmi2Error
    with the logged message, nothing is set (the train stays at x0), and the run goes on to exit 0."""
    arguments = host_arguments(product_fmus / "Traction.fmu", tmp_path / "fmu folder")
    assert "%20" in arguments[1]
    command, x, v = arguments[6:]
    proc = run_host(host_binary, [*arguments[:6], "999999=1.0", x])
    assert proc.returncode == 0, proc.stderr[-800:]
    refused = [line for line in proc.stderr.splitlines() if "999999" in line]
    assert len(refused) == 120 and set(refused) == {"[host 3] host: value reference 999999 is not a Real variable"}
    assert proc.stdout.split() == [x, "400"]


# ---- (d) a Python that cannot start, or cannot import the slave: a logged failure -----------------
@pytest.mark.parametrize("env, expected", [
    ({"PYTHONHOME": "/nonexistent/python"}, "Python could not start (PYTHONHOME /nonexistent/python)"),
    ({"RAILCOSIM_LIBPYTHON": "/nonexistent/libpython3.so"}, "cannot load libpython"),
    ({"PYTHONPATH": "{hidden}"}, "numpy hidden by this test"),
], ids=["pythonhome", "libpython", "slave-import"])
def test_a_python_that_cannot_run_the_fmu_is_a_logged_instantiation_failure(env, expected, product_fmus,
                                                                            host_binary, tmp_path):
    # "slave-import": a PYTHONPATH whose numpy cannot be imported, so the FMU's slave cannot be
    hidden = tmp_path / "hidden"
    (hidden / "numpy").mkdir(parents=True)
    (hidden / "numpy" / "__init__.py").write_text("raise ImportError('numpy hidden by this test')\n")
    env = {key: value.replace("{hidden}", str(hidden)) for key, value in env.items()}
    proc = run_host(host_binary, host_arguments(product_fmus / "Traction.fmu", tmp_path / "fmu"),
                    clean_environment(**env))
    assert proc.returncode == 4, (proc.returncode, proc.stderr[-800:])   # fmi2Instantiate returned NULL
    assert "[host 4]" in proc.stderr and expected in proc.stderr, proc.stderr[-800:]


# ---- (a) fmpy.simulate_fmu three times in one process ------------------------------------------------
SIMULATE_THRICE = """
import sys
import fmpy
from fmpy import read_model_description
results = []
for path in sys.argv[1:]:
    md = read_model_description(path)
    step = float(md.defaultExperiment.stepSize)
    # fmpy's default: a fresh extraction per call, removed after it
    result = fmpy.simulate_fmu(path, stop_time=3 * step, step_size=step, output_interval=step)
    results.append(repr(result.tolist()))
    print(path, len(result))
print('distinct', len(set(results)))
"""


@pytest.mark.parametrize("name", PRODUCT)
def test_simulate_fmu_three_times_in_one_process(name, product_fmus):
    path = str(product_fmus / f"{name}.fmu")
    proc = subprocess.run([sys.executable, "-c", SIMULATE_THRICE, path, path, path],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-1500:]
    assert "distinct 1" in proc.stdout


def test_simulate_fmu_of_two_fmus_in_turn(product_fmus):
    """The second FMU imports modules the first did not, after the first's folder is gone."""
    traction, ato = (str(product_fmus / f"{n}.fmu") for n in ("Traction", "AtoController"))
    proc = subprocess.run([sys.executable, "-c", SIMULATE_THRICE, traction, ato, traction],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-1500:]
    assert "distinct 2" in proc.stdout


# ---- (e) load → free → load in one process, the first extraction removed -------------------------
RELOAD_RUNNER = Path(__file__).resolve().parent / "host" / "reload_run.py"


@pytest.fixture(scope="module")
def packed(product_fmus, tmp_path_factory):
    """The shipped systems packed as .ssp archives (what `railcosim build` writes to build/)."""
    from orchestrator.systems.shipped import SSP_ROOT
    from orchestrator.packaging.packing import pack_systems

    dest = tmp_path_factory.mktemp("ssp")
    pack_systems(SSP_ROOT, product_fmus, dest)
    return dest


def component_names(ssp: Path):
    """The instance names a host gives a packed system's components (their SSD names)."""
    from lxml import etree

    with zipfile.ZipFile(ssp) as archive:
        root = etree.fromstring(archive.read("SystemStructure.ssd"))
    return sorted(c.get("name") for c in root.iter("{*}Component"))


def reload_run(host, tasks, cwd):
    """tests/host/reload_run.py in a process of its own, from an empty folder (fmpy and libcosim
    extract into temporary folders and remove them)."""
    proc = subprocess.run([sys.executable, str(RELOAD_RUNNER), host, *tasks], capture_output=True, text=True,
                          timeout=600, cwd=cwd)
    assert proc.returncode == 0, (proc.returncode, proc.stdout[-1000:], proc.stderr[-3000:])
    *reached, claimed = proc.stdout.strip().splitlines()
    return [float(line.rsplit("reached ", 1)[1].split()[0]) for line in reached], json.loads(claimed)


@pytest.mark.parametrize("first, second", [
    ("ssp,free_run,1,0.01", "ssp,ato_only,3,0.5"),      # two systems sharing the train and the ATO
    ("ssp,ato_only,3,0.5", "ssp,ato_only,3,0.5"),       # the same one twice
    ("ssp,ato_only,3,0.5", "ssp,als_en,1,0.01"),        # a signal-chain system second
    ("drop,AtoController", "ssp,ato_only,3,0.5"),       # loaded and dropped before it ran
], ids=["free_run-ato_only", "ato_only-twice", "ato_only-als_en", "dropped-ato_only"])
def test_fmpy_loads_frees_and_loads_again(first, second, packed, product_fmus, tmp_path):
    """fmpy extracts every FMU into a temporary folder and removes it after freeing the instance:
    the second system runs to its stop time, and the forwarding binary of each of its instances
    still claims the direct value route (from the registry of the package imported for it)."""
    def task(text):
        kind, name, *rest = text.split(",")
        path = packed / f"{name}.ssp" if kind == "ssp" else product_fmus / f"{name}.fmu"
        return ",".join([kind, str(path), *rest])

    reached, claimed = reload_run("fmpy", [task(first), task(second)], tmp_path)
    assert reached[1] == pytest.approx(float(second.split(",")[2]))
    assert sorted(claimed[-len(component_names(packed / f"{second.split(',')[1]}.ssp")):]) == \
        component_names(packed / f"{second.split(',')[1]}.ssp")


def test_fmpy_frees_an_fmu_while_another_uses_the_package_it_imported(product_fmus, tmp_path):
    """The ATO loaded while Traction lives shares the ``fmus`` package imported from Traction's
    extraction; Traction is freed and its folder removed before the ATO initialises (it then reads
    the line, rolling-stock and timetable files and their schemas) and runs 3 s."""
    task = f"overlap,{product_fmus / 'Traction.fmu'},{product_fmus / 'AtoController.fmu'},3"
    reached, claimed = reload_run("fmpy", [task], tmp_path)
    assert reached == [pytest.approx(3.0)] and claimed == ["first", "second"]


@pytest.mark.parametrize("first, second", [
    ("drop,free_run", "run,ato_only,3"),
    ("drop,ato_only", "run,ato_only,3"),
    ("run,ato_only,3", "run,ato_only,3"),
    ("run,ato_only,3", "run,free_run,1"),
], ids=["free_run-ato_only", "ato_only-twice-dropped", "ato_only-twice", "ato_only-free_run"])
def test_libcosim_loads_frees_and_loads_again(first, second, packed, tmp_path):
    """libcosim (libcosimpy) unpacks an .ssp into a temporary folder and removes it when the
    execution is dropped; the next execution, of another system or the same one, runs to its stop
    time and the process exits 0 (it aborted with "line.schema.json: No such file")."""
    pytest.importorskip("libcosimpy")

    def task(text):
        kind, name, *rest = text.split(",")
        return ",".join([kind, str(packed / f"{name}.ssp"), *rest])

    reached, claimed = reload_run("libcosim", [task(first), task(second)], tmp_path)
    assert reached[1] == float(second.split(",")[2])
    names = component_names(packed / f"{second.split(',')[1]}.ssp")
    assert sorted(claimed[-len(names):]) == names


@pytest.mark.parametrize("first, cycles, second", [
    ("AtoController", "1nd", "AtoController"),    # dropped before it ran, then loaded again
    ("AtoController", "1d", "AtoController"),     # the same FMU twice
    ("Traction", "1d", "AtoController"),
    ("AtoController", "1d", "RailLine"),          # a signal-chain FMU second
])
def test_c_host_loads_frees_and_loads_another_fmu(first, cycles, second, product_fmus, host_binary, tmp_path):
    """The C host runs the first FMU, frees it, closes its library and deletes its extraction
    ("d"), then runs the second from its own extraction in the same process: both print their
    outputs, every step of the second is accepted (the host exits 6 otherwise) and it exits 0."""
    arguments = host_arguments(product_fmus / f"{first}.fmu", tmp_path / "first")
    arguments[5] = cycles
    proc = run_host(host_binary, [*arguments, "--", *host_arguments(product_fmus / f"{second}.fmu",
                                                                      tmp_path / "second")])
    assert proc.returncode == 0, proc.stderr[-1500:]
    assert not (tmp_path / "first").exists()
    outputs = proc.stdout.splitlines()
    assert len(outputs) == (3 if "n" in cycles else 6) - (first == "Traction") - (second == "Traction")
    if first == "Traction":
        assert float(outputs[0].split()[1]) > 900.0          # a minute of full traction


def test_c_host_calls_after_fmi2fatal_are_refused_not_crashed(product_fmus, host_binary, tmp_path):
    """A host that ignores fmi2Fatal (traction v0 = 1e9, above its maximum 150: exitInitializationMode
    fails) and calls doStep, fmi2GetReal and fmi2Terminate on the instance gets fmi2Error for each
    with a logged message, frees it, and the process goes on: a second such instance, then a good
    one that runs a minute of full traction, and exit 0 (doStep after the fatal crashed the host)."""
    fmu = product_fmus / "Traction.fmu"
    v0 = {v.name: v.valueReference for v in read_model_description(str(fmu)).modelVariables}["v0"]
    failing = host_arguments(fmu, tmp_path / "fmu")
    failing[5] = "2f"
    failing.insert(6, f"{v0}:=1e9")
    proc = run_host(host_binary, [*failing, "--", *host_arguments(fmu, tmp_path / "fmu")])
    assert proc.returncode == 0, (proc.returncode, proc.stderr[-1500:])
    lines = proc.stdout.splitlines()
    assert lines[:10] == 2 * ["exitInitializationMode: 4", "after doStep: 3", "after fmi2GetReal: 3",
                              "after fmi2Terminate: 3", "freed"]
    assert float(lines[10].split()[1]) > 900.0
    refused = [line for line in proc.stderr.splitlines() if "refused: the instance returned fmi2Fatal" in line]
    assert len(refused) == 6 and "[host 3] host: fmi2DoStep refused" in refused[0]
    assert proc.stderr.count("v0 = 1e+09 is above its maximum 150") == 2


# ---- (f) an FMU extracted where the path needs encoding: the forwarder decodes the URI -----------
AWKWARD_FOLDERS = {"cyrillic": "врем", "hash": "a#b", "percent": "100%", "percent_hex": "%41", "space": "a b",
                   "long": "/".join(["l" * 60] * 12)}


@pytest.mark.parametrize("uri", ["encoded", "as-is"])
@pytest.mark.parametrize("kind", AWKWARD_FOLDERS)
def test_c_host_runs_an_fmu_extracted_under_a_folder_the_uri_must_encode(kind, uri, product_fmus, host_binary,
                                                                         tmp_path):
    """The host's resource URI is percent-encoded (file:///…/%D0%B2…, %23, %25, %20) as FMI 2.0
    asks; some hosts write the path as it is after "file://". Both name the folder: the run gives
    the outputs of the same FMU in a plain folder (pythonfmu, handed the URI undecoded, crashed at
    fmi2Instantiate). "%41" is a folder of that name, not "A": encoded it is %2541."""
    fmu = product_fmus / "Traction.fmu"
    plain = run_host(host_binary, host_arguments(fmu, tmp_path / "plain"))
    folder = tmp_path / AWKWARD_FOLDERS[kind] / "fmu"
    arguments = host_arguments(fmu, folder)
    if uri == "as-is":
        arguments[1] = f"file://{folder / 'resources'}"
    else:
        assert arguments[1] == (folder / "resources").as_uri() and (kind == "long" or "%" in arguments[1])
    proc = run_host(host_binary, arguments)
    assert proc.returncode == 0, (proc.returncode, proc.stderr[-800:])
    assert proc.stdout == plain.stdout and plain.stdout.strip()


@pytest.mark.parametrize("name", PRODUCT)
def test_every_fmu_runs_extracted_under_cyrillic_hash_percent_and_space(name, product_fmus, host_binary, tmp_path):
    proc = run_host(host_binary, host_arguments(product_fmus / f"{name}.fmu", tmp_path / "врем #1 100% x" / "fmu"))
    assert proc.returncode == 0, (proc.returncode, proc.stderr[-800:])
    assert proc.stdout.strip()


def test_simulate_fmu_with_a_temporary_folder_of_cyrillic_hash_percent_and_space(product_fmus, tmp_path):
    """fmpy extracts into TMPDIR and hands the FMU the percent-encoded URI of that folder."""
    tmp = tmp_path / "врем #1 100% x"
    tmp.mkdir()
    path = str(product_fmus / "AtoController.fmu")
    proc = subprocess.run([sys.executable, "-c", SIMULATE_THRICE, path], capture_output=True, text=True,
                          timeout=300, env=dict(os.environ, TMPDIR=str(tmp)))
    assert proc.returncode == 0, (proc.returncode, proc.stderr[-1500:])
    assert "distinct 1" in proc.stdout and list(tmp.iterdir()) == []


# ---- (g) every fmi2 function with bad arguments: an error status, never a crash ------------------
BAD_CALLS_SOURCE = HOST_SOURCE.with_name("fmi2_bad_calls.c")
DISCARD, ERROR = 2, 3
BAD_INSTANTIATIONS = ("null_name", "empty_name", "model_exchange", "unknown_type", "wrong_guid", "null_guid",
                      "null_location", "missing_location", "http_location", "other_host", "relative_location",
                      "nul_escape", "overlong_location", "null_callbacks")


@pytest.fixture(scope="module")
def bad_calls_binary(tmp_path_factory):
    compiler = shutil.which("gcc") or shutil.which("cc")
    binary = tmp_path_factory.mktemp("bad_calls") / "fmi2_bad_calls"
    headers = fmi_headers()
    subprocess.run([compiler, "-O1", f"-I{headers}", "-o", str(binary), str(BAD_CALLS_SOURCE), "-ldl", "-lm"],
                   check=True)
    return binary


@pytest.mark.parametrize("name", PRODUCT)
def test_every_fmi2_function_with_bad_arguments_is_refused_never_a_crash(name, product_fmus, bad_calls_binary,
                                                                          tmp_path):
    """tests/host/fmi2_bad_calls.c: fmi2Instantiate with each bad argument returns NULL with the
    reason logged (a wrong GUID and ModelExchange among them, issue of co-simulation-only FMUs); every
    other function with a NULL or foreign component, NULL arrays, unknown references, n = SIZE_MAX,
    or a call the modelDescription does not offer answers fmi2Error (a step the slave refuses:
    fmi2Discard); the instance then still runs, and freeing twice is harmless."""
    fmu = product_fmus / f"{name}.fmu"
    md = read_model_description(str(fmu))
    arguments = host_arguments(fmu, tmp_path / "fmu")
    real_output = next(v.valueReference for v in md.modelVariables if v.causality == "output" and v.type == "Real")
    string_parameter = next((v.valueReference for v in md.modelVariables
                             if v.causality == "parameter" and v.type == "String"), 0)
    proc = subprocess.run([str(bad_calls_binary), *arguments[:3], arguments[4], str(real_output), str(string_parameter)],
                          capture_output=True, text=True, env=clean_environment(), timeout=300)
    assert proc.returncode == 0, (proc.returncode, proc.stdout[-600:], proc.stderr[-1500:])
    answers = dict(line.split(" ", 1) for line in proc.stdout.splitlines())
    assert list(answers)[-1] == "getReal_after_free" and len(answers) == len(proc.stdout.splitlines()) > 130
    assert {answers[f"instantiate_{case}"] for case in BAD_INSTANTIATIONS} == {"NULL"}
    assert answers.pop("instantiate_without_memory_functions") == "instance" and answers.pop("life") == "0"
    assert answers.pop("instantiate_without_logger") == "instance"

    def expected(label):
        if label.startswith("freeInstance"):
            return {"0"}                     # (void: printed once it returned)
        if label.startswith("doStep_"):
            return {str(DISCARD), str(ERROR)}  # the slave refuses a step with fmi2Discard
        return {str(ERROR)}

    unexpected = {label: status for label, status in answers.items()
                  if not label.startswith("instantiate_") and status not in expected(label)}
    assert unexpected == {}
    for reason in ("ModelExchange requested; this FMU is for co-simulation only",
                   f'GUID "{{not-this-fmu}}" is not this FMU\'s {md.guid}',
                   "the instance name is NULL", "no resource location (NULL)",
                   "/nonexistent/railcosim/resources/slavemodule.txt cannot be read",
                   "fmi2SetString: the value for reference", "canGetAndSetFMUstate=\"false\"",
                   "fmi2GetReal of 18446744073709551615 values refused",
                   "fmi2SetupExperiment refused: the start time is not finite",
                   "fmi2DoStep refused: the component is NULL"):
        assert reason in proc.stderr, reason

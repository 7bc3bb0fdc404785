"""The FMUs never hang, never poison their state, never accept nonsense (docs/interfaces.md,
"Bad parameters, inputs and calls"): declared parameter ranges, non-finite inputs, FMI calls out
of order or with unknown value references, over-long traction steps, ATO measurement faults and
bad data files.

Through FMI: each built FMU is driven by fmpy in a subprocess (this file run as a script, see
``_drive``), so a crash of the FMU fails one test instead of the session, and the statuses are the
ones pythonfmu's C layer returns. The cases of the parameter test are generated from the built
FMUs' modelDescription.xml, not listed by hand.
"""
import json
import math
import subprocess
import sys
from pathlib import Path

import pytest

OK, WARNING, DISCARD, ERROR, FATAL = range(5)
HERE = Path(__file__).resolve()


# ---- the driver: one FMU through fmpy, a list of sessions (one instance each) -------------------
def _driver(plan: dict) -> dict:
    """Run ``plan`` ({"fmu", "sessions": [[op, ...], ...]}) and return each op's status, value
    and the messages logged during it (``log``; ``logged``: [status, category] of each). Ops: ["setup", t0], ["enter"], ["exit"], ["step", t, h],
    ["terminate"], ["set", name, value], ["get", name], ["set_vr", type, vr, value],
    ["get_vr", type, vr]. A session stops at its first fmi2Fatal (nothing may be called after it)."""
    import ctypes

    from fmpy import calloc, extract, free, read_model_description
    from fmpy.fmi1 import FMICallException
    from fmpy.fmi2 import (FMU2Slave, fmi2CallbackAllocateMemoryTYPE, fmi2CallbackFreeMemoryTYPE,
                           fmi2CallbackFunctions, fmi2CallbackLoggerTYPE)
    from fmpy.logging import addLoggerProxy

    description = read_model_description(plan["fmu"])
    variables = {v.name: v for v in description.modelVariables}
    unzipped = extract(plan["fmu"])
    sink, kinds = [], []

    def log(env, instance, status, category, message):
        sink.append((message or b"").decode(errors="replace").strip())
        kinds.append([status, (category or b"").decode(errors="replace")])

    callbacks = fmi2CallbackFunctions()
    callbacks.logger = fmi2CallbackLoggerTYPE(log)
    callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
    callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
    addLoggerProxy(ctypes.byref(callbacks))

    results, slaves, live = [], [], []
    for number, ops in enumerate(plan["sessions"]):
        slave = FMU2Slave(guid=description.guid, unzipDirectory=unzipped,
                          modelIdentifier=description.coSimulation.modelIdentifier, instanceName=f"s{number}")
        slaves.append(slave)
        slave.instantiate(callbacks=callbacks, loggingOn=True)
        session, fatal = [], False
        for op in ops:
            sink.clear()
            kinds.clear()
            kind, args, value, status = op[0], op[1:], None, OK
            try:
                if kind == "setup":
                    slave.setupExperiment(startTime=args[0])
                elif kind == "enter":
                    slave.enterInitializationMode()
                elif kind == "exit":
                    slave.exitInitializationMode()
                elif kind == "step":
                    slave.doStep(args[0], args[1])
                elif kind == "terminate":
                    slave.terminate()
                elif kind in ("set", "get"):
                    var = variables[args[0]]
                    if kind == "set":
                        getattr(slave, f"set{var.type}")([var.valueReference], [args[1]])
                    else:
                        value = getattr(slave, f"get{var.type}")([var.valueReference])[0]
                elif kind == "set_vr":
                    getattr(slave, f"set{args[0]}")([args[1]], [args[2]])
                elif kind == "get_vr":
                    value = getattr(slave, f"get{args[0]}")([args[1]])[0]
            except FMICallException as error:
                status = error.status
            session.append({"op": op, "status": status, "value": value, "log": list(sink), "logged": list(kinds)})
            if status == FATAL:
                fatal = True
                break
        if not fatal:
            live.append(slave)
        results.append(session)
    for slave in live:
        slave.fmi2FreeInstance(slave.component)
    # pythonfmu 0.7.0's exit-time defect (docs/architecture.md): our forwarder releases it; a
    # plain pythonfmu binary exports the release for the host to call
    if hasattr(slaves[0].dll, "finalizePythonInterpreter"):
        slaves[0].dll.finalizePythonInterpreter()
    return {"sessions": results}


def _drive(fmu: Path, sessions, timeout=300) -> list:
    """The driver in a subprocess; fails with its stderr if it crashes."""
    proc = subprocess.run([sys.executable, str(HERE), json.dumps({"fmu": str(fmu), "sessions": sessions})],
                          capture_output=True, text=True, timeout=timeout)
    assert proc.returncode == 0, f"exit {proc.returncode}: {proc.stderr[-2000:]}"
    return json.loads(proc.stdout.splitlines()[-1])["sessions"]


def _fmu(product_fmus, name):
    return product_fmus / f"{name}.fmu"


START = [["setup", 0.0], ["enter"], ["exit"]]
UNITS = ("WaysideCoder", "RailLine", "LocoReceiver", "Traction", "AtoController")


# ---- 1. every declared parameter range, from the modelDescription --------------------------------
def _parameter_cases(fmu: Path):
    """(variable, value, words the message must contain) for every numeric parameter: past each
    declared bound, and NaN / inf for a Real one."""
    from fmpy import read_model_description

    cases = []
    for var in read_model_description(str(fmu)).modelVariables:
        if var.causality != "parameter" or var.type not in ("Real", "Integer"):
            continue
        integer = var.type == "Integer"
        for bound, sign, words in ((var.min, -1, "below its minimum"), (var.max, 1, "above its maximum")):
            if bound is None:
                continue
            bound = float(bound)
            value = int(bound) + sign if integer else bound + sign * 0.5 * max(abs(bound), 1.0)
            cases.append((var.name, value, words))
        if not integer:
            cases += [(var.name, math.nan, "not a finite number"), (var.name, math.inf, "not a finite number")]
    return cases


@pytest.mark.parametrize("unit", UNITS)
def test_every_parameter_outside_its_declared_range_fails_initialisation_naming_it(product_fmus, unit):
    fmu = _fmu(product_fmus, unit)
    cases = _parameter_cases(fmu)
    assert len(cases) >= 10
    sessions = _drive(fmu, [[["setup", 0.0], ["enter"], ["set", name, value], ["exit"]] for name, value, _ in cases])
    for (name, value, words), session in zip(cases, sessions):
        exit_ = session[-1]
        assert exit_["op"][0] == "exit" and exit_["status"] == FATAL, (name, value, session)
        text = " ".join(exit_["log"])
        assert f"{name} = " in text and words in text, (name, value, text)


def test_the_declared_starts_pass_and_a_real_parameter_without_declared_range_is_still_checked(product_fmus):
    """Every FMU initialises with its declared starts; rail line coil_offset (no declared range)
    refuses NaN all the same."""
    for unit in UNITS:
        [session] = _drive(_fmu(product_fmus, unit), [START])
        assert [op["status"] for op in session] == [OK] * 3, (unit, session)
    [session] = _drive(_fmu(product_fmus, "RailLine"), [[["setup", 0.0], ["enter"], ["set", "coil_offset", math.nan], ["exit"]]])
    assert session[-1]["status"] == FATAL and "coil_offset = nan is not a finite number" in " ".join(session[-1]["log"])


# ---- 2. a traction step that would never end ------------------------------------------------------
def test_traction_refuses_a_step_needing_too_many_substeps_and_goes_on(product_fmus):
    [session] = _drive(_fmu(product_fmus, "Traction"), [START + [
        ["set", "command", 0.5], ["step", 0.0, 1e9], ["step", 0.0, 0.5], ["get", "x"]]], timeout=120)
    long, normal, x = session[4:]
    assert long["status"] == DISCARD and "sub-steps" in " ".join(long["log"])
    assert normal["status"] == OK and x["value"] > 400.0


# ---- 3. unknown value references ------------------------------------------------------------------
# Our FMUs' forwarding binary answers them (fmi2Error); the facade's own handling is the backstop
# for a binary without the table (docs/interfaces.md, "Bad parameters, inputs and calls").
def _vr(fmu: Path, name: str) -> int:
    from fmpy import read_model_description

    return next(v.valueReference for v in read_model_description(str(fmu)).modelVariables if v.name == name)


def test_a_bad_value_reference_is_fmi2error_and_the_instance_keeps_working(product_fmus):
    """An unknown Real get, a Real set of a String reference, a set of an output, an unknown
    Integer set: each fmi2Error with a message naming the reference through the host's logger,
    nothing forwarded; the instance steps and reads as if they never happened, then terminates
    and is freed (the driver's exit code 0)."""
    fmu = _fmu(product_fmus, "Traction")
    x, command = _vr(fmu, "x"), _vr(fmu, "command")
    [session] = _drive(fmu, [START + [
        ["set", "command", 0.5], ["step", 0.0, 0.5],
        ["get_vr", "Real", 999999], ["step", 0.5, 0.5], ["get", "x"],
        ["set_vr", "Real", 0, 1.0],                      # vr 0 is the String rolling_stock_file
        ["set_vr", "Real", x, -1.0],                     # an output
        ["set_vr", "Integer", 999999, 3],
        ["step", 1.0, 0.5], ["get_vr", "Real", x], ["get_vr", "Real", command], ["terminate"]]])
    ops = session[3:]
    assert [op["status"] for op in ops] == [OK, OK, ERROR, OK, OK, ERROR, ERROR, ERROR, OK, OK, OK, OK]
    messages = [ops[k]["log"] for k in (2, 5, 6, 7)]
    assert messages == [["s0: value reference 999999 is not a Real variable"],
                        ["s0: value reference 0 is not a Real variable"],
                        [f"s0: value reference {x} is a Real variable that cannot be set (not an input or parameter)"],
                        ["s0: value reference 999999 is not an Integer variable"]]
    assert all(ops[k]["logged"] == [[ERROR, "logStatusError"]] for k in (2, 5, 6, 7))
    assert ops[4]["value"] > 400.0 and ops[9]["value"] > ops[4]["value"]  # moving: the output was not overwritten
    assert ops[10]["value"] == 0.5


def test_a_bad_reference_during_initialisation_does_not_fail_it(product_fmus):
    [session] = _drive(_fmu(product_fmus, "WaysideCoder"), [[["setup", 0.0], ["enter"], ["set_vr", "Real", 999999, 1.0],
                                                              ["get_vr", "String", 999999], ["exit"], ["step", 0.0, 0.01]]])
    assert [op["status"] for op in session] == [OK, OK, ERROR, ERROR, OK, OK]
    assert session[3]["log"] == ["s0: value reference 999999 is not a String variable"]


def test_without_the_table_the_facade_answers_ok_and_refuses_the_next_step(product_fmus, tmp_path):
    """The forwarder without resources/railcosim_value_references.txt forwards unchecked: the
    facade's backstop answers (what a plain pythonfmu build of our FMUs does): OK with an error
    message, nothing read, the next doStep refused once, then the instance goes on."""
    import zipfile

    from orchestrator.packaging.forwarder import VALUE_REFERENCES_MEMBER

    stripped = tmp_path / "Traction.fmu"
    with zipfile.ZipFile(_fmu(product_fmus, "Traction")) as source, zipfile.ZipFile(stripped, "w") as target:
        assert VALUE_REFERENCES_MEMBER in source.namelist()
        for info in source.infolist():
            if info.filename != VALUE_REFERENCES_MEMBER:
                target.writestr(info, source.read(info))
    [session] = _drive(stripped, [START + [["get_vr", "Real", 999999], ["step", 0.0, 0.5], ["step", 0.0, 0.5],
                                           ["terminate"]]])
    get, refused, stepped, _ = session[3:]
    assert get["status"] == OK and math.isnan(get["value"])
    assert "unknown value reference(s) [999999]" in " ".join(get["log"])
    assert refused["status"] == DISCARD and "fmi2GetReal refused" in " ".join(refused["log"])
    assert stepped["status"] == OK


def test_the_facade_backstop_refuses_the_next_step_once():
    """The Python side alone (a plain pythonfmu build): a bad reference writes or reads nothing,
    logs an error and refuses the next doStep once; before initialisation it fails
    exitInitializationMode."""
    from fmus.fmi.slave import FmuCallError
    from fmus.traction.facade import Traction

    slave = Traction(instance_name="t", resources=None)
    slave.setup_experiment(0.0, None, None)
    slave.enter_initialization_mode()
    slave.exit_initialization_mode()
    assert math.isnan(slave.get_real([999999])[0])
    assert "unknown value reference(s) [999999]" in slave.log_queue[-1].msg
    assert not slave.do_step(0.0, 0.5) and "fmi2GetReal refused" in slave.log_queue[-1].msg
    assert slave.do_step(0.0, 0.5)
    slave.set_real([0], [1.0])                        # vr 0 is the String rolling_stock_file
    assert "are not Real" in slave.log_queue[-1].msg and slave.get_string([0]) == [""]
    assert not slave.do_step(0.5, 0.5) and slave.do_step(0.5, 0.5)

    early = Traction(instance_name="t", resources=None)
    early.setup_experiment(0.0, None, None)
    early.enter_initialization_mode()
    early.set_integer([999999], [3])
    with pytest.raises(FmuCallError):
        early.exit_initialization_mode()


# ---- 4. non-finite inputs: refused, state unchanged -----------------------------------------------
# (FMU, bad input, value, good value, how long one step is)
BAD_INPUTS = [
    ("Traction", "command", math.nan, 0.8, 0.5),
    ("RailLine", "u_tx[1,1]", math.nan, 0.0, 0.01),
    ("RailLine", "x_head[1]", math.inf, -1000.0, 0.01),
    ("LocoReceiver", "e_coil[7]", math.inf, 0.5, 0.01),
    ("WaysideCoder", "wrong_command_main", -1, 0, 0.01),      # Integer below its declared minimum 0
]


@pytest.mark.parametrize("unit, port, bad, good, h", BAD_INPUTS, ids=[f"{u}.{p}" for u, p, *_ in BAD_INPUTS])
def test_a_bad_input_refuses_the_step_without_touching_the_state(product_fmus, unit, port, bad, good, h):
    """The step with the bad input is refused (fmi2Discard, a message naming the port); the same
    step retried with the good value gives exactly what an instance never given it gives."""
    from fmpy import read_model_description

    fmu = _fmu(product_fmus, unit)
    outputs = [v.name for v in read_model_description(str(fmu)).modelVariables
               if v.causality == "output" and v.type in ("Real", "Integer", "Boolean")]
    reads = [["get", name] for name in outputs]
    begin = START + [["set", port, good], ["step", 0.0, h]]
    reference = begin + [["step", h, h], ["step", 2 * h, h]] + reads
    trial = begin + [["set", port, bad], ["step", h, h], ["set", port, good], ["step", h, h], ["step", 2 * h, h]] + reads
    ref, got = _drive(fmu, [reference, trial])
    statuses = [op["status"] for op in got]
    refused = got[len(begin) + 1]
    assert refused["op"][0] == "step" and refused["status"] == DISCARD
    assert statuses.count(DISCARD) == 1 and set(statuses) == {OK, DISCARD}
    text = " ".join(refused["log"])
    assert f"input {port} = " in text and "state unchanged" in text, text
    assert all(op["status"] == OK for op in ref)
    values_ref = [op["value"] for op in ref[-len(reads):]]
    values_got = [op["value"] for op in got[-len(reads):]]
    assert values_got == values_ref and any(v not in (0, False) for v in values_ref)


def test_traction_still_clamps_a_finite_command_outside_its_range():
    """The declared −1…1 of traction's command is clamped and counted, not refused (docs/traction.md)."""
    from fmus.traction.facade import Traction

    slave = Traction(instance_name="t", resources=None)
    slave.setup_experiment(0.0, None, None)
    slave.enter_initialization_mode()
    slave.exit_initialization_mode()
    slave.io["command"][...] = 7.0
    assert slave.do_step(0.0, 0.5) and int(slave.io["commands_clamped"]) == 1
    slave.io["command"][...] = -math.inf
    assert not slave.do_step(0.5, 0.5) and "input command = -inf is not a finite number" in slave.log_queue[-1].msg


# ---- 5. the ATO fails safe on impossible measurements ---------------------------------------------
def _ato(**parameters):
    from fmus.ato_controller.facade import AtoController

    slave = AtoController(instance_name="ato", resources=None)
    slave.setup_experiment(0.0, None, None)
    slave.enter_initialization_mode()
    slave.exit_initialization_mode()
    slave.io["x"][...] = 400.0                       # at station A, green, valid code
    slave.io["aspect"][...] = 4
    slave.io["code_valid"][...] = True
    return slave


def _run_until_traction(slave):
    t = 0.0
    while float(slave.io["command"]) <= 0.0:
        assert slave.do_step(t, 0.5)
        t += 0.5
        assert t < 300.0
    return t


@pytest.mark.parametrize("port, value", [("v", math.nan), ("v", -5.0), ("x", math.nan), ("x", math.inf),
                                         ("aspect", 9)])
def test_ato_answers_an_impossible_measurement_with_the_emergency_brake(port, value):
    slave = _ato()
    t = _run_until_traction(slave)                   # departed: it commands traction now
    slave.io["v"][...] = 2.0
    assert slave.do_step(t, 0.5) and float(slave.io["command"]) > 0.0
    slave.log_queue.clear()
    slave.io[port][...] = value
    assert slave.do_step(t + 0.5, 0.5)                # not an FMI error: the controller fails safe
    io = slave.io
    assert float(io["command"]) == -1.0 and bool(io["emergency_brake"])
    assert int(io["mode"]) == 5 and int(io["atp_intervention"]) == 2 and int(io["emergency_brakings"]) == 1
    assert all(math.isfinite(float(io[name])) for name in ("command", "v_ref", "v_ceiling", "v_atp"))
    [message] = [m.msg for m in slave.log_queue]
    assert f"{port} = " in message and "emergency brake" in message


def test_ato_refuses_an_input_it_does_not_read_outside_its_declared_range(product_fmus):
    """The ATP judges the aspect only with a cab signal, the digital speeds only with a digital
    one (the test above): an input the ATO does not read in its mode is checked as any other.
    cab_signal = off: aspect 99 (declared 0..4) refuses the step, which then goes on with a good
    aspect (it was accepted unread); set before initialisation it fails exitInitializationMode;
    ALSN: v_permitted = -5 m/s (declared ≥ 0) refuses the step."""
    fmu = _fmu(product_fmus, "AtoController")
    off = [["set", "cab_signal", "off"]] + START + [["set", "x", 400.0], ["step", 0.0, 0.5],
                                                    ["set", "aspect", 99], ["step", 0.5, 0.5],
                                                    ["set", "aspect", 4], ["step", 0.5, 0.5]]
    at_init = [["set", "cab_signal", "off"], ["set", "aspect", 99]] + START
    digital_under_alsn = START + [["set", "x", 400.0], ["set", "v_permitted", -5.0], ["step", 0.0, 0.5]]
    off_session, init_session, alsn_session = _drive(fmu, [off, at_init, digital_under_alsn])
    assert [op["status"] for op in off_session if op["op"][0] == "step"] == [OK, DISCARD, OK]
    refused = [op for op in off_session if op["status"] == DISCARD][0]
    assert "input aspect = 99 is above its maximum 4" in " ".join(refused["log"])
    assert init_session[-1]["op"] == ["exit"] and init_session[-1]["status"] == FATAL
    assert "input aspect = 99 is above its maximum 4" in " ".join(init_session[-1]["log"])
    assert alsn_session[-1]["status"] == DISCARD
    assert "input v_permitted = -5 is below its minimum 0" in " ".join(alsn_session[-1]["log"])


def test_ato_holds_the_emergency_brake_until_standstill_after_a_fault():
    slave = _ato()
    t = _run_until_traction(slave)
    slave.io["v"][...] = -5.0
    assert slave.do_step(t, 0.5)
    slave.io["v"][...] = 3.0                          # valid again, still moving
    assert slave.do_step(t + 0.5, 0.5)
    assert bool(slave.io["emergency_brake"]) and float(slave.io["command"]) == -1.0
    assert "valid again" in slave.log_queue[-1].msg
    slave.io["v"][...] = 0.0                          # standing: released, counted once
    assert slave.do_step(t + 1.0, 0.5)
    assert not bool(slave.io["emergency_brake"]) and int(slave.io["emergency_brakings"]) == 1


def test_ato_tolerates_a_small_negative_speed_at_standstill():
    slave = _ato()
    slave.io["v"][...] = -0.1
    assert slave.do_step(0.0, 0.5) and not bool(slave.io["emergency_brake"])


def test_ato_fails_safe_through_fmi(product_fmus):
    [session] = _drive(_fmu(product_fmus, "AtoController"), [START + [
        ["set", "v", math.nan], ["step", 0.0, 0.5], ["get", "command"], ["get", "emergency_brake"], ["get", "mode"]]])
    step, command, brake, mode = session[4:]
    assert step["status"] == OK and "emergency brake" in " ".join(step["log"])
    assert (command["value"], brake["value"], mode["value"]) == (-1.0, True, 5)


# ---- 6. calls out of order --------------------------------------------------------------------------
def test_calls_out_of_order_are_refused(product_fmus):
    fmu = _fmu(product_fmus, "Traction")
    no_enter, backwards, after_terminate, before_init, twice = _drive(fmu, [
        [["setup", 0.0], ["exit"]],
        START + [["step", 0.0, 0.5], ["step", 0.0, 0.5], ["step", 1.0, 0.5], ["step", 0.5, -0.5],
                 ["step", 0.5, math.nan], ["step", 0.5, 0.5]],
        START + [["step", 0.0, 0.5], ["terminate"], ["step", 0.5, 0.5]],
        [["setup", 0.0], ["step", 0.0, 0.5], ["enter"], ["exit"], ["step", 0.0, 0.5]],
        [["setup", 0.0], ["enter"], ["enter"]],
    ])
    assert no_enter[-1]["status"] == FATAL and "fmi2ExitInitializationMode refused" in " ".join(no_enter[-1]["log"])
    steps = [op["status"] for op in backwards[3:]]
    assert steps == [OK, DISCARD, DISCARD, DISCARD, DISCARD, OK]
    assert "time must continue" in " ".join(backwards[4]["log"]) + " ".join(backwards[5]["log"])
    assert "step positive" in " ".join(backwards[6]["log"])
    assert after_terminate[-1]["status"] == DISCARD and "after fmi2Terminate" in " ".join(after_terminate[-1]["log"])
    assert [op["status"] for op in before_init] == [OK, DISCARD, OK, OK, OK]
    assert twice[-1]["status"] == FATAL and "fmi2EnterInitializationMode refused" in " ".join(twice[-1]["log"])


def test_signal_fmus_still_refuse_a_wrong_step(product_fmus):
    [session] = _drive(_fmu(product_fmus, "LocoReceiver"), [START + [["step", 0.0, 0.02], ["step", 0.0, 0.01]]])
    assert session[3]["status"] == DISCARD and "needs exactly 0.01 s" in " ".join(session[3]["log"])
    assert session[4]["status"] == OK


# ---- 7. data files: one message naming the file -----------------------------------------------------
def _bad_files(tmp_path):
    """(what the message says, path): a Cyrillic file saved as cp1251, a nesting that overflows
    the parser, and one it parses but no data file has."""
    latin1 = tmp_path / "cp1251.json"
    latin1.write_bytes('{"name": "Гора"}'.encode("cp1251"))
    deep = tmp_path / "deep.json"
    deep.write_text("[" * 100_000 + "]" * 100_000)
    deep_parsable = tmp_path / "deep_parsable.json"
    deep_parsable.write_text('{"a": ' + "[" * 500 + "]" * 500 + "}")
    return [("not UTF-8", latin1), ("nested", deep), ("nested", deep_parsable)]


def test_loader_names_a_non_utf8_or_deeply_nested_file(tmp_path):
    from fmus.data.loader import load_line, load_rolling_stock, load_timetable
    from fmus.errors import FmuInputError
    from fmus.signalling.alsn import load_transmitters

    line = load_line()
    for words, path in _bad_files(tmp_path):
        for load in (load_line, load_rolling_stock, lambda p: load_timetable(p, line), load_transmitters):
            with pytest.raises(FmuInputError) as error:
                load(path)
            assert str(error.value).startswith(f"{path}: "), str(error.value)
            if load is not load_transmitters:
                assert words in str(error.value)


def test_a_data_file_found_valid_is_checked_again_once_it_changes(tmp_path):
    """The loader checks a document against its schema once per process (a run reads its line
    and rolling stock several times): a file edited since is checked again."""
    from fmus.data.loader import DEFAULT_ROLLING_STOCK, load_rolling_stock
    from fmus.errors import FmuInputError

    path = tmp_path / "stock.json"
    document = json.loads(Path(DEFAULT_ROLLING_STOCK).read_text())
    path.write_text(json.dumps(document))
    assert load_rolling_stock(path).mass_kg == load_rolling_stock(path).mass_kg > 0
    del document["units"]
    path.write_text(json.dumps(document))
    with pytest.raises(FmuInputError, match="field units: missing"):
        load_rolling_stock(path)


def test_the_verdict_skips_a_bad_data_file_like_any_other(tmp_path):
    """orchestrator/verdicts/verdict.py catches FmuInputError (the FMU reports the file itself)."""
    from orchestrator.verdicts import verdict

    _, path = _bad_files(tmp_path)[0]

    class Node:
        parameters = {"line_file": str(path), "timetable_file": str(path)}

    class Graph:
        nodes = {"ato": Node()}

    assert verdict._timetable(Graph(), "ato") == []


def test_a_bad_rolling_stock_file_given_to_the_train_is_named(product_fmus, tmp_path):
    paths = [path for _, path in _bad_files(tmp_path)]
    sessions = _drive(_fmu(product_fmus, "Traction"),
                      [[["setup", 0.0], ["enter"], ["set", "rolling_stock_file", str(path)], ["exit"]] for path in paths])
    for path, session in zip(paths, sessions):
        assert session[-1]["status"] == FATAL
        assert any(message.startswith(f"Traction: {path}: ") for message in session[-1]["log"]), session[-1]["log"]


# ---- the value-reference table (the forwarder's table is written from the modelDescription) ---------
def test_value_reference_table_matches_the_model_description(product_fmus):
    from fmpy import read_model_description

    from fmus.loco_receiver.facade import LocoReceiver

    table = LocoReceiver(instance_name="r", resources=None).value_reference_table()
    described = {}
    for var in read_model_description(str(_fmu(product_fmus, "LocoReceiver"))).modelVariables:
        described.setdefault(var.type, {}).setdefault(var.causality, []).append(var.valueReference)
    assert {t: c for t, c in table.items() if c} == described


if __name__ == "__main__":
    print(json.dumps(_driver(json.loads(sys.argv[1]))))


# ---- where the FMU is extracted: a folder whose URI must be percent-encoded -----------------------
AWKWARD_TMP = "врем #1 100% x"   # Cyrillic, '#', '%' and a space: each is encoded in a file: URI


def test_the_slave_decodes_a_file_uri_and_keeps_a_path():
    from fmus.errors import FmuInputError
    from fmus.fmi.slave import resources_folder

    assert resources_folder("file:///tmp/%D0%B2%D1%80%D0%B5%D0%BC%20%231%20100%25/resources") == \
        "/tmp/врем #1 100%/resources"
    assert resources_folder("FILE://localhost/a%2Fb") == "/a/b"
    assert resources_folder("file:/a#b?c%zz") == "/a#b?c%zz"          # a host that does not encode
    assert resources_folder("/tmp/%41/resources") == "/tmp/%41/resources"   # a path is not decoded
    assert resources_folder(None) is None
    with pytest.raises(FmuInputError, match="names another host"):
        resources_folder("file://server/share/resources")


@pytest.mark.parametrize("command", [
    ["run", "ato_only", "--stop-time", "5", "--output", "{out}"],
    ["validate", "ato_only"],
    ["validate", "{fmus}/Traction.fmu"],
    ["conform", "--role", "traction", "{fmus}/Traction.fmu"],
], ids=["run", "validate-system", "validate-fmu", "conform"])
def test_commands_run_with_a_temporary_folder_the_uri_must_encode(command, product_fmus, tmp_path):
    """TMPDIR with Cyrillic, '#', '%' and a space: every FMU extracted there got its resources as
    file:///…/%D0%B2… and pythonfmu, reading that undecoded, crashed the command (exit 139)."""
    from helpers import railcosim

    tmp = tmp_path / AWKWARD_TMP
    tmp.mkdir()
    arguments = [part.format(out=tmp_path / "out", fmus=product_fmus) for part in command]
    code, out, err = railcosim(*arguments, env={"TMPDIR": tmp})
    assert code == 0, (code, out[-800:], err[-1500:])
    assert list(tmp.iterdir()) == []   # and nothing left behind


def test_dcp_slave_serves_an_fmu_extracted_under_such_a_temporary_folder(product_fmus, tmp_path, monkeypatch):
    """The slave instantiates its FMU before it says LISTENING."""
    from dcp_test_master import start_slave

    tmp = tmp_path / AWKWARD_TMP
    tmp.mkdir()
    monkeypatch.setenv("TMPDIR", str(tmp))
    proc, _ = start_slave(product_fmus / "Traction.fmu")
    try:
        assert proc.poll() is None
    finally:
        proc.terminate()
        proc.wait(timeout=60)
    assert proc.returncode in (0, -15, 143), proc.stderr.read()[-1500:]

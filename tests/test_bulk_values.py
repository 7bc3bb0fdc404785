"""Our FMUs' forwarding binary moves Real, Integer and Boolean values straight between the host's
arrays and the slave's store (fmus/fmi/bulk.py): a host calling plain fmi2Get/fmi2Set gets exactly
the values pythonfmu's own route gives, and the checks of the value references still come first."""
import json
import os
import subprocess
import sys
import textwrap

import pytest

from orchestrator.packaging import forwarder as fwd

pytestmark = pytest.mark.skipif(isinstance(fwd.plan(), fwd.NoForwarder), reason="no forwarding binary here")

# a host's first steps: the FMU (argv[1]) instantiated under the name argv[2], its value references
OPEN = textwrap.dedent("""
    import ctypes, json, sys
    from fmpy import read_model_description, extract
    from fmpy.fmi2 import FMU2Slave

    path = sys.argv[1]
    md = read_model_description(path)
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=extract(path), modelIdentifier=md.coSimulation.modelIdentifier,
                    instanceName=sys.argv[2])
    fmu.instantiate()
    vr = {v.name: v.valueReference for v in md.modelVariables}
""")

HOST = OPEN + textwrap.dedent("""
    u = [vr[f"u[{i}]"] for i in range(1, 5)]
    y = [vr[f"y[{i}]"] for i in range(1, 5)]

    def array(kind, values):
        return (kind * len(values))(*values)

    lib = fmu.dll
    status = {"set_alpha": lib.fmi2SetReal(fmu.component, array(ctypes.c_uint, [vr["alpha"]]), 1,
                                           array(ctypes.c_double, [0.5]))}
    fmu.setupExperiment(startTime=0.0)
    fmu.enterInitializationMode()
    fmu.exitInitializationMode()
    frames, t = [], 0.0
    for k in range(3):
        values = [0.1 * k + 0.25 * i - 0.3 for i in range(4)]
        lib.fmi2SetReal(fmu.component, array(ctypes.c_uint, u), 4, array(ctypes.c_double, values))
        fmu.doStep(currentCommunicationPoint=t, communicationStepSize=1e-3)
        t += 1e-3
        out = (ctypes.c_double * 6)()
        # out of order, with a repeat and an input among the outputs
        order = [y[3], y[0], y[1], y[2], y[0], u[1]]
        status[f"get{k}"] = lib.fmi2GetReal(fmu.component, array(ctypes.c_uint, order), 6, out)
        frames.append([values, list(out)])
    status["set_output"] = lib.fmi2SetReal(fmu.component, array(ctypes.c_uint, [y[0]]), 1,
                                           array(ctypes.c_double, [9.0]))
    after = (ctypes.c_double * 1)()
    lib.fmi2GetReal(fmu.component, array(ctypes.c_uint, [y[0]]), 1, after)
    # a reset gives a new slave (pythonfmu makes one): the same lists reach the new one's values
    status["reset"] = lib.fmi2Reset(fmu.component)
    lib.fmi2SetReal(fmu.component, array(ctypes.c_uint, [vr["alpha"]]), 1, array(ctypes.c_double, [0.0]))
    fmu.setupExperiment(startTime=0.0)
    fmu.enterInitializationMode()
    fmu.exitInitializationMode()
    lib.fmi2SetReal(fmu.component, array(ctypes.c_uint, u), 4, array(ctypes.c_double, [1.5, -2.0, 0.75, 3.25]))
    fmu.doStep(currentCommunicationPoint=0.0, communicationStepSize=1e-3)
    out = (ctypes.c_double * 6)()
    lib.fmi2GetReal(fmu.component, array(ctypes.c_uint, order), 6, out)
    bulk = sys.modules.get("fmus.fmi.bulk")
    print(json.dumps({"frames": frames, "status": status, "y1_after": after[0], "after_reset": list(out),
                      "claimed": list(bulk.claimed) if bulk else []}))
    fmu.terminate()
    fmu.freeInstance()
""")


INTEGERS_AND_BOOLEANS = OPEN + textwrap.dedent("""
    lib, c = fmu.dll, fmu.component

    def refs(*names):
        return (ctypes.c_uint * len(names))(*[vr[name] for name in names])

    def integers(*values):
        return (ctypes.c_int * len(values))(*values)

    status, seen = {}, {}
    status["set_mode"] = lib.fmi2SetInteger(c, refs("mode"), 1, integers(-123456))
    status["set_enabled"] = lib.fmi2SetBoolean(c, refs("enabled"), 1, integers(2))    # any non-zero is true
    fmu.setupExperiment(startTime=0.0)
    fmu.enterInitializationMode()
    fmu.exitInitializationMode()
    for k, (mode, enabled) in enumerate([(7, 0), (-1, 1)]):
        status[f"set{k}"] = (lib.fmi2SetInteger(c, refs("mode"), 1, integers(mode)),
                             lib.fmi2SetBoolean(c, refs("enabled"), 1, integers(enabled)))
        out_i, out_b = integers(0, 0, 0), integers(5, 5, 5)
        # out of order, with a repeat and a parameter among the outputs
        status[f"get{k}"] = (lib.fmi2GetInteger(c, refs("mode", "mode_out", "mode"), 3, out_i),
                             lib.fmi2GetBoolean(c, refs("enabled_out", "enabled", "enabled_out"), 3, out_b))
        seen[k] = [list(out_i), list(out_b)]
    status["set_output"] = lib.fmi2SetInteger(c, refs("mode_out"), 1, integers(3))
    status["wrong_type"] = lib.fmi2GetBoolean(c, refs("mode"), 1, integers(0))
    after = integers(0)
    lib.fmi2GetInteger(c, refs("mode_out"), 1, after)
    bulk = sys.modules.get("fmus.fmi.bulk")
    print(json.dumps({"seen": seen, "status": status, "mode_out_after": after[0],
                      "claimed": list(bulk.claimed) if bulk else []}))
    fmu.terminate()
    fmu.freeInstance()
""")


def host_run(fmu, bulk: bool, script: str = HOST, instance: str = "stage"):
    env = dict(os.environ)
    env.pop("RAILCOSIM_NO_BULK", None)
    if not bulk:
        env["RAILCOSIM_NO_BULK"] = "1"
    done = subprocess.run([sys.executable, "-c", script, str(fmu), instance], env=env, capture_output=True, text=True,
                          timeout=120)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout.strip().splitlines()[-1])


def test_bulk_values_equal_pythonfmus_route_and_checks_still_come_first(test_fmus):
    fmu = test_fmus / "TestFrameStage.fmu"
    bulk, plain = host_run(fmu, True), host_run(fmu, False)
    assert bulk["claimed"] == ["stage", "stage"] and plain["claimed"] == []       # again after the reset
    assert bulk["frames"] == plain["frames"]
    # after fmi2Reset (alpha 0: y = u, a fresh filter) the values reach the new slave
    assert bulk["after_reset"] == plain["after_reset"] == [3.25, 1.5, -2.0, 0.75, 1.5, -2.0]
    # the slave's own answer: y = 0.5·u + 0.5·y[-1] per sample, read back in the order asked
    y_prev = 0.0
    for values, out in bulk["frames"]:
        y = []
        for value in values:
            y_prev = 0.5 * value + 0.5 * y_prev
            y.append(y_prev)
        assert out == [y[3], y[0], y[1], y[2], y[0], values[1]]
    assert bulk["status"] == plain["status"]
    assert bulk["status"]["set_alpha"] == 0 and bulk["status"]["get0"] == 0
    assert bulk["status"]["set_output"] == 3          # fmi2Error: an output cannot be set
    assert bulk["y1_after"] == bulk["frames"][-1][1][1]  # and it was not written


def test_integers_and_booleans_go_straight_to_the_store_with_the_same_answers(test_fmus):
    fmu = test_fmus / "TestGain.fmu"
    direct, plain = (host_run(fmu, bulk, INTEGERS_AND_BOOLEANS, "gain") for bulk in (True, False))
    assert direct["claimed"] == ["gain"] and plain["claimed"] == []
    assert direct == dict(plain, claimed=["gain"])
    # the parameters as set (a Boolean reads back 1 for any non-zero set), the outputs as
    # published at initialisation (mode −123456, enabled true)
    assert direct["seen"] == {"0": [[7, -123456, 7], [1, 0, 1]], "1": [[-1, -123456, -1], [1, 1, 1]]}
    assert direct["status"]["set_output"] == 3 and direct["status"]["wrong_type"] == 3     # fmi2Error
    assert direct["mode_out_after"] == -123456                                            # not written

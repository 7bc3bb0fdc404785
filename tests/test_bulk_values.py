"""Our FMUs' forwarding binary moves Real values to and from the slave in bulk (fmus/fmi/bulk.py):
a host calling plain fmi2GetReal/fmi2SetReal gets exactly the values pythonfmu's own route gives,
and the checks of the value references still come first."""
import json
import os
import subprocess
import sys
import textwrap

import pytest

from orchestrator.build import forwarder as fwd

pytestmark = pytest.mark.skipif(isinstance(fwd.plan(), fwd.NoForwarder), reason="no forwarding binary here")

HOST = textwrap.dedent("""
    import ctypes, json, sys
    import numpy as np
    from fmpy import read_model_description, extract
    from fmpy.fmi2 import FMU2Slave

    path = sys.argv[1]
    md = read_model_description(path)
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=extract(path), modelIdentifier=md.coSimulation.modelIdentifier,
                    instanceName="stage")
    fmu.instantiate()
    vr = {v.name: v.valueReference for v in md.modelVariables}
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
    bulk = sys.modules.get("fmus.fmi.bulk")
    print(json.dumps({"frames": frames, "status": status, "y1_after": after[0],
                      "claimed": list(bulk.claimed) if bulk else []}))
    fmu.terminate()
    fmu.freeInstance()
""")


def host_run(fmu, bulk: bool):
    env = dict(os.environ)
    env.pop("RAILCOSIM_NO_BULK", None)
    if not bulk:
        env["RAILCOSIM_NO_BULK"] = "1"
    done = subprocess.run([sys.executable, "-c", HOST, str(fmu)], env=env, capture_output=True, text=True,
                          timeout=120)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout.strip().splitlines()[-1])


def test_bulk_values_equal_pythonfmus_route_and_checks_still_come_first(test_fmus):
    fmu = test_fmus / "TestFrameStage.fmu"
    bulk, plain = host_run(fmu, True), host_run(fmu, False)
    assert bulk["claimed"] == ["stage"] and plain["claimed"] == []
    assert bulk["frames"] == plain["frames"]
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

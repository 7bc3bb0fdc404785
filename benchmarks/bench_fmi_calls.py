"""What one fmi2SetReal / fmi2GetReal costs a host, with our forwarding binary's bulk route and
through pythonfmu's own (RAILCOSIM_NO_BULK=1): the rail line's 320 u_tx values, its 80 e_coil
values and one v value, called as the orchestrator calls them (raw ctypes, preallocated arrays).

    python benchmarks/bench_fmi_calls.py [--calls 3000] [--rounds 3]

Needs `railcosim build`. Each route runs in its own process (the binary reads the switch when
it loads), the two alternating; prints per round the best of five batches, µs per call, CPU time.
"""
import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent

MEASURE = """
import ctypes, json, sys, time
from fmpy import read_model_description, extract
from fmpy.fmi2 import FMU2Slave

path, calls = sys.argv[1], int(sys.argv[2])
md = read_model_description(path)
fmu = FMU2Slave(guid=md.guid, unzipDirectory=extract(path), modelIdentifier=md.coSimulation.modelIdentifier,
                instanceName="rail")
fmu.instantiate()
fmu.setupExperiment(startTime=0.0)
fmu.enterInitializationMode()
fmu.exitInitializationMode()

def refs(prefix, count=None):
    found = [v.valueReference for v in md.modelVariables if v.name.startswith(prefix)][:count]
    return (ctypes.c_uint * len(found))(*found), (ctypes.c_double * len(found))(*([0.5] * len(found))), len(found)

lib, result = fmu.dll, {}
for name, function, (vr, values, n) in (("set u_tx (320)", lib.fmi2SetReal, refs("u_tx[")),
                                        ("get e_coil (80)", lib.fmi2GetReal, refs("e_coil[")),
                                        ("set v (1)", lib.fmi2SetReal, refs("v[", 1))):
    batches = []
    for _ in range(5):
        began = time.process_time()
        for _ in range(calls):
            function(fmu.component, vr, n, values)
        batches.append((time.process_time() - began) / calls * 1e6)
    result[name] = min(batches)
print(json.dumps(result))
"""


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--calls", type=int, default=3000)
    parser.add_argument("--rounds", type=int, default=3)
    args = parser.parse_args()
    fmu = REPO / "build" / "fmus" / "RailLine.fmu"
    for round_ in range(1, args.rounds + 1):
        for route, off in (("bulk", ""), ("pythonfmu", "1")):
            env = dict(os.environ, RAILCOSIM_NO_BULK=off)
            done = subprocess.run([sys.executable, "-c", MEASURE, str(fmu), str(args.calls)], env=env,
                                  capture_output=True, text=True, check=True)
            figures = json.loads(done.stdout.strip().splitlines()[-1])
            print(f"round {round_}, {route:9s}: " + ", ".join(f"{name} {us:.1f}" for name, us in figures.items())
                  + " µs per call", flush=True)


if __name__ == "__main__":
    main()

"""What each library shortcut saves a call against its public fallback (fmus/library_shortcuts.py
for the cores, orchestrator/library_shortcuts.py for the engine), on a frame's inputs: 40
flags, 40 points on a 200-node table, one 40-sample frame through an order-4 band-pass
(lfilter) and through three second-order sections (sosfilt), and one fmi2GetReal of the
traction FMU's outputs through its binary's own function and through fmpy's wrapper.

    python benchmarks/bench_library_shortcuts.py [--calls 20000] [--repeats 5]

Prints per shortcut the best of ``--repeats`` batches of ``--calls`` calls (the shortcut's and
its fallback's alternating), µs per call. The fmi2GetReal line needs `railcosim build` (it is left out
without build/fmus/Traction.fmu).
"""
import argparse
import ctypes
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))   # `python benchmarks/X.py` from anywhere

import numpy as np  # noqa: E402
from scipy.signal import butter, lfilter  # noqa: E402

from fmus import library_shortcuts as shortcuts  # noqa: E402
from orchestrator import library_shortcuts as engine_shortcuts  # noqa: E402


def per_call_us(functions, calls: int, repeats: int):
    """The best batch of each function, µs per call; the batches alternate, so a load that
    comes and goes weighs on both alike."""
    best = [float("inf")] * len(functions)
    for _ in range(repeats):
        for i, function in enumerate(functions):
            began = time.perf_counter()
            for _ in range(calls):
                function()
            best[i] = min(best[i], (time.perf_counter() - began) / calls * 1e6)
    return best


def frame_cases():
    rng = np.random.default_rng(1)
    flags = rng.random(40) < 0.3
    xp = np.cumsum(rng.uniform(1.0, 50.0, 200))
    fp = rng.standard_normal(200)
    x = rng.uniform(xp[0], xp[-1], 40)
    b, a = butter(2, [0.04, 0.06], btype="band")
    zi = np.zeros(a.size - 1)
    sos = butter(3, [0.04, 0.06], btype="band", output="sos")
    sos_zi = np.zeros((sos.shape[0], 2))
    samples = rng.standard_normal(40)
    return [
        ("count_nonzero (40 flags)", lambda: shortcuts.count_nonzero(flags), lambda: np.count_nonzero(flags)),
        ("interp (40 points)", lambda: shortcuts.interp(x, xp, fp), lambda: np.interp(x, xp, fp)),
        ("linear_filter (40 samples)", lambda: shortcuts.linear_filter(b, a, samples, -1, zi),
         lambda: lfilter(b, a, samples, axis=-1, zi=zi)),
        ("sections_filter (40 samples)", lambda: shortcuts.sections_filter(sos, samples, sos_zi),
         lambda: shortcuts.public_sections_filter(sos, samples, sos_zi)),
        ("engine count_nonzero (40 flags)", lambda: engine_shortcuts.count_nonzero(flags),
         lambda: np.count_nonzero(flags)),
    ]


def fmi_case(folder: str):
    """(the instance, the case): fmi2GetReal of the traction FMU's Real outputs, raw and through
    fmpy's wrapper; None without the built FMU."""
    path = REPO / "build" / "fmus" / "Traction.fmu"
    if not path.is_file():
        return None
    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Slave

    description = read_model_description(str(path))
    fmu = FMU2Slave(guid=description.guid, unzipDirectory=extract(str(path), folder),
                    modelIdentifier=description.coSimulation.modelIdentifier, instanceName="traction")
    fmu.instantiate()
    fmu.setupExperiment(startTime=0.0)
    fmu.enterInitializationMode()
    fmu.exitInitializationMode()
    refs = [v.valueReference for v in description.modelVariables if v.type == "Real" and v.causality == "output"]
    vr, values = (ctypes.c_uint * len(refs))(*refs), (ctypes.c_double * len(refs))()
    component, count = ctypes.c_void_p(fmu.component), ctypes.c_size_t(len(refs))
    raw = engine_shortcuts.raw_function(fmu, "fmi2GetReal")
    return fmu, (f"raw_function fmi2GetReal ({len(refs)} values)", lambda: raw(component, vr, count, values),
                 lambda: fmu.fmi2GetReal(component, vr, count, values))


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--calls", type=int, default=20000)
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as folder:
        cases, fmi = frame_cases(), fmi_case(folder)
        if fmi is not None:
            cases.append(fmi[1])
        for name, shortcut, fallback in cases:
            fast, slow = per_call_us((shortcut, fallback), args.calls, args.repeats)
            print(f"{name:36s} shortcut {fast:6.2f} µs, public fallback {slow:6.2f} µs a call "
                  f"({slow - fast:+.2f} µs)", flush=True)
        if fmi is not None:
            fmi[0].terminate()
            fmi[0].freeInstance()


if __name__ == "__main__":
    main()

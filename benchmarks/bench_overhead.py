"""Orchestrator overhead per component step for a trivial pythonfmu FMU.

Runs the same two-counter system (one connection each way per step) three ways in one
process and reports medians over repeats:
  fmi       : full co-simulation through fmpy (what users run)
  inprocess : the same facades stepped without FMI (the reference, docs/architecture.md#master-algorithm-orchestratormasterpy)
  raw       : bare fmpy calls set+doStep+get on the same FMU, no master (FMI cost alone)
  null      : the master driving slaves that do nothing: the orchestrator's own overhead
              per component step (scheduling, links, buffers, observers)

    python benchmarks/bench_overhead.py [--steps 20000] [--repeats 5]
"""
import argparse
import ctypes
import statistics
import tempfile
import time
from pathlib import Path

from _systems import build_test_fmus, trivial_system
import orchestrator.components
from orchestrator.fmu import make_buffers
from orchestrator.verdicts.verdict import railway_verdicts
from orchestrator.run import RunOptions, run_system


class NullSlave:
    """Does nothing but own the preallocated buffers the master moves values through."""

    def __init__(self, name, *args):
        self.name, self.messages = name, []

    def bind(self, inputs, outputs):
        self.inputs, self.outputs = make_buffers(inputs), make_buffers(outputs)

    def instantiate(self): pass
    def setup_experiment(self, *a): pass
    def set_values(self, values): pass
    def enter_initialization(self): pass
    def exit_initialization(self): pass
    def write_inputs(self): pass
    def read_outputs(self, types=None): pass
    def do_step(self, t, h): pass
    def terminate(self): pass
    def free(self): pass


def run_null(folder: Path) -> float:
    real = orchestrator.components.make_slave
    orchestrator.components.make_slave = lambda name, *a: NullSlave(name)
    try:
        return run_master(folder, in_process=False)
    finally:
        orchestrator.components.make_slave = real


def run_master(folder: Path, in_process: bool) -> float:
    with tempfile.TemporaryDirectory() as out:
        began = time.perf_counter()
        result = run_system(folder, RunOptions(summaries=railway_verdicts, output_dir=Path(out), in_process=in_process,
                                               record=[], output_interval=1.0))
        return (time.perf_counter() - began), sum(result.steps_taken.values())


def raw_fmpy(steps: int) -> float:
    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Slave

    path = build_test_fmus(4) / "TestCounter.fmu"
    md = read_model_description(str(path))
    slave = FMU2Slave(guid=md.guid, unzipDirectory=extract(str(path)), modelIdentifier="TestCounter",
                      instanceName="raw")
    slave.instantiate(); slave.setupExperiment(startTime=0.0)
    slave.enterInitializationMode(); slave.exitInitializationMode()
    vr_in = (ctypes.c_uint * 1)(0); val_in = (ctypes.c_double * 1)(1.0)
    vr_out = (ctypes.c_uint * 1)(2); val_out = (ctypes.c_double * 1)()
    c = slave.component
    began = time.perf_counter()
    for k in range(steps):
        slave.fmi2SetReal(c, vr_in, 1, val_in)
        slave.fmi2DoStep(c, k * 0.001, 0.001, 1)
        slave.fmi2GetReal(c, vr_out, 1, val_out)
    elapsed = time.perf_counter() - began
    slave.terminate(); slave.fmi2FreeInstance(c)   # the FMU's forwarder releases pythonfmu's state at unload
    return elapsed / steps


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--steps", type=int, default=20000, help="steps per component")
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        folder = trivial_system(Path(tmp) / "sys", stop_time=args.steps * 0.001)
        fmi, inproc, raw, null = [], [], [], []
        for _ in range(args.repeats):
            wall, n = run_master(folder, in_process=False); fmi.append(wall / n)
            wall, n = run_master(folder, in_process=True); inproc.append(wall / n)
            raw.append(raw_fmpy(args.steps))
            wall, n = run_null(folder); null.append(wall / n)
    med = {k: statistics.median(v) * 1e6 for k, v in
           (("fmi", fmi), ("inprocess", inproc), ("raw", raw), ("null", null))}
    print(f"per component step, median of {args.repeats} (µs): co-simulation {med['fmi']:.1f}, "
          f"in-process {med['inprocess']:.1f}, raw fmpy set+doStep+get {med['raw']:.1f}")
    print(f"orchestrator overhead per component step (null slaves): {med['null']:.2f} µs; "
          f"co-simulation / in-process = {med['fmi'] / med['inprocess']:.2f}")


if __name__ == "__main__":
    main()

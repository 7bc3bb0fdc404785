"""Load, free and load again in one process, as GUI hosts, notebooks and study tools do: each task
loads a system or an FMU from a fresh temporary extraction, which the host removes when it is done
with it (docs/third_party.md, "Loading again in one process").

    python reload_run.py fmpy TASK [TASK ...]
    python reload_run.py libcosim TASK [TASK ...]

fmpy tasks:
  ssp,SSP,STOP_S,STEP_S   fmpy.ssp.simulation.simulate_ssp (extracts every FMU, frees and removes it)
  drop,FMU                extracted, instantiated, freed and removed without running
  overlap,FMU_A,FMU_B,STOP_S
                          A initialised and stepped; B loaded while A lives; A freed and its
                          extraction removed; then B initialised and run to STOP_S at its own step
libcosim tasks (libcosimpy):
  drop,SSP                an execution loaded and dropped before it ran
  run,SSP,STOP_S          an execution loaded, run to STOP_S and dropped

Each task prints "<task>: reached <time> s"; the last line is the JSON list of the instance names
whose forwarding binary claimed the direct value route from the ``fmus.fmi.bulk`` registry the
interpreter holds at the end (one per instance our forwarder made). Used by
tests/test_third_party_host.py, in a process of its own: a crash or an abort fails that test only.
"""
import gc
import json
import shutil
import sys

NS = 1_000_000_000


def _opened(path: str, name: str):
    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Slave

    unzipdir = extract(path)
    md = read_model_description(path)
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=unzipdir, modelIdentifier=md.coSimulation.modelIdentifier,
                    instanceName=name)
    fmu.instantiate()
    return fmu, unzipdir, float(md.defaultExperiment.stepSize)


def _closed(fmu, unzipdir: str, initialised: bool) -> None:
    if initialised:
        fmu.terminate()
    fmu.freeInstance()              # fmpy: fmi2FreeInstance, then the library unloaded
    shutil.rmtree(unzipdir)


def _started(fmu) -> None:
    fmu.setupExperiment(startTime=0.0)
    fmu.enterInitializationMode()
    fmu.exitInitializationMode()


def fmpy_task(kind: str, args) -> float:
    if kind == "ssp":
        from fmpy.ssp.simulation import simulate_ssp

        path, stop_s, step_s = args[0], float(args[1]), float(args[2])
        result = simulate_ssp(path, stop_time=stop_s, step_size=step_s)
        return float(result["time"][-1]) + step_s      # rows are labelled with their step's start
    if kind == "drop":
        fmu, unzipdir, _ = _opened(args[0], "dropped")
        _closed(fmu, unzipdir, initialised=False)
        return 0.0
    if kind == "overlap":
        first, first_dir, first_step = _opened(args[0], "first")
        _started(first)
        first.doStep(currentCommunicationPoint=0.0, communicationStepSize=first_step)
        second, second_dir, step_s = _opened(args[1], "second")
        _closed(first, first_dir, initialised=True)
        _started(second)
        steps = round(float(args[2]) / step_s)
        for k in range(steps):
            second.doStep(currentCommunicationPoint=k * step_s, communicationStepSize=step_s)
        _closed(second, second_dir, initialised=True)
        return steps * step_s
    raise SystemExit(f"unknown fmpy task {kind!r}")


def libcosim_task(kind: str, args) -> float:
    from libcosimpy.CosimExecution import CosimExecution
    from libcosimpy.CosimLogging import CosimLogLevel, log_output_level

    log_output_level(CosimLogLevel.ERROR)
    execution = CosimExecution.from_ssp_file(args[0])
    reached = 0.0
    if kind == "run":
        if not execution.simulate_until(round(float(args[1]) * NS)):
            raise SystemExit(f"{args[0]}: libcosim failed before {args[1]} s")
        reached = execution.status().current_time / NS
    elif kind != "drop":
        raise SystemExit(f"unknown libcosim task {kind!r}")
    del execution                    # libcosim frees the instances and removes its extraction
    gc.collect()
    return reached


if __name__ == "__main__":
    host, *tasks = sys.argv[1:]
    run_task = {"fmpy": fmpy_task, "libcosim": libcosim_task}[host]
    for task in tasks:
        kind, *args = task.split(",")
        print(f"{task}: reached {run_task(kind, args):g} s", flush=True)
    bulk = sys.modules.get("fmus.fmi.bulk")
    print(json.dumps(list(bulk.claimed) if bulk else []))

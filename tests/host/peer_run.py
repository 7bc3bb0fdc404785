"""Run a packed system (.ssp) as written in another engine and record it like railcosim's
results.csv: a CSV with time first and one column per "component.variable".

    python peer_run.py libcosim SSP STOP_S INTERVAL_S OUT.csv [component.variable ...]
    python peer_run.py fmpy SSP STOP_S STEP_S OUT.csv

libcosim (libcosimpy): the SSP's own step sizes and base step, no option; the named variables
are read every INTERVAL_S through a last-value observer. FMPy (fmpy.ssp.simulate_ssp): one step
size for every component; every declared connector is written, each row labelled, as FMPy
does, with the start time of the step whose results it holds. Used by
tests/test_peer_engines.py, in a process of its own: an FMU crash at exit must not take the
test runner with it.
"""
import csv
import sys
import time

NS = 1_000_000_000


def run_libcosim(ssp: str, stop_s: float, interval_s: float, out: str, names) -> None:
    from libcosimpy.CosimEnums import CosimVariableType
    from libcosimpy.CosimExecution import CosimExecution
    from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
    from libcosimpy.CosimObserver import CosimObserver

    log_output_level(CosimLogLevel.ERROR)
    started = time.perf_counter()
    execution = CosimExecution.from_ssp_file(ssp)
    observer = CosimObserver.create_last_value()
    execution.add_observer(observer)
    slaves = {info.name.decode(): info.index for info in execution.slave_infos()}
    readers = []                     # (column, slave index, reference, type)
    for name in names:
        component, _, variable = name.partition(".")
        if component not in slaves:
            raise SystemExit(f"{ssp}: libcosim has no component {component!r}")
        found = [v for v in execution.slave_variables(slaves[component]) if v.name.decode() == variable]
        if not found:
            raise SystemExit(f"{ssp}: libcosim has no variable {name!r}")
        readers.append((name, slaves[component], found[0].reference, CosimVariableType(found[0].type)))
    read = {CosimVariableType.REAL: observer.last_real_values, CosimVariableType.INTEGER: observer.last_integer_values,
            CosimVariableType.BOOLEAN: observer.last_boolean_values}
    with open(out, "w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(["time"] + [r[0] for r in readers])
        for k in range(1, round(stop_s / interval_s) + 1):
            if not execution.simulate_until(round(k * interval_s * NS)):
                raise SystemExit(f"{ssp}: libcosim failed before {k * interval_s:g} s")
            row = [repr(k * interval_s)]
            for _, index, reference, kind in readers:
                value = read[kind](index, [reference])[0]
                row.append(repr(float(value)) if kind is CosimVariableType.REAL else str(int(value)))
            writer.writerow(row)
    print(f"libcosim: {len(slaves)} components, {execution.status().current_time / NS:g} s simulated "
          f"in {time.perf_counter() - started:.2f} s", flush=True)


def run_fmpy(ssp: str, stop_s: float, step_s: float, out: str) -> None:
    from fmpy.ssp.simulation import simulate_ssp

    started = time.perf_counter()
    result = simulate_ssp(ssp, stop_time=stop_s, step_size=step_s)
    with open(out, "w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(result.dtype.names)
        writer.writerows([repr(float(value)) for value in row] for row in result)
    print(f"fmpy: {len(result.dtype.names) - 1} connectors, {stop_s:g} s in "
          f"{time.perf_counter() - started:.2f} s", flush=True)


if __name__ == "__main__":
    engine, ssp, stop, interval, out, *names = sys.argv[1:]
    if engine == "libcosim":
        run_libcosim(ssp, float(stop), float(interval), out, names)
    else:
        run_fmpy(ssp, float(stop), float(interval), out)

"""One sample per frame as a deadline: every 0.25 ms tick of the N = 1 ALSN chain against the
4 kHz sample period (docs/performance.md#one-sample-per-frame-as-a-deadline).

    python benchmarks/bench_deadline.py [--stop-time 30] [--fmi] [--gc-frozen-off] [--real-time 60]
                                        [--floor 60]

free_run built with one sample per frame (`railcosim build --frame 1`, into build/fmus_n1, as
benchmarks/bench_sample_by_sample.py builds it): coder, rail line and receiver step every tick,
the train and the ATO every 0.5 s. A manipulator stamps the wall clock (perf_counter_ns) at the
start of every tick; a tick's time is the stamp of the next one less its own (all components
due, the exchange, the observers). Printed per mode (in process, with --fmi also through FMI):
the median, 99th and 99.9th percentile and the maximum against the deadline of 250 µs, and
the ticks over the deadline per simulated minute (each a missed sample when the run is paced
and has no slack to catch up with).

The worst 0.1 % of ticks are then put down to what happened in them: a garbage collection
(gc.callbacks), the rail line activating a section's network for a new shunt configuration (a
train's wheelsets reaching the next node), a new network model generated, a section's
wheelset chain solved again, a parked section woken (caught up), sections parked, a relay
picking up or dropping out, the train and ATO stepping (every 0.5 s), a row of results.csv
(every 0.1 s). The rail line's events are seen by wrapping its methods in this process, which
pythonfmu FMUs share (so they are seen through FMI too). Each component's step and each
observer's work are timed per tick, and their medians printed for the ticks of the two
periodic causes (the slow components' step; a results row with the verdicts' checks) and for
the rest.

--gc-frozen-off runs without what `railcosim run` does around stepping (orchestrator/process_policy.py:
the garbage collector frozen and off while the master steps), to compare. --real-time S
also runs S simulated seconds paced at real time (`railcosim run --real-time`) in process and
prints the pacer's count of late ticks per minute and the worst lateness. --floor S paces S
seconds of ticks that do nothing but a fixed busy wait as long as the median tick (no
simulation): the late ticks of that loop are the machine's own, a floor under any paced run's
figure.
"""
from __future__ import annotations

import argparse
import gc
import os
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path
from types import SimpleNamespace
from typing import Dict, List

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))   # `python benchmarks/X.py` from anywhere

from benchmarks.bench_sample_by_sample import sample_by_sample_system  # noqa: E402
from fmus.rail_line import circuit_bank, network_models, relays, wheelset_amplitudes  # noqa: E402
from fmus.rail_line import parking as parking_module  # noqa: E402
from fmus.sizes import BuildConfig  # noqa: E402
from orchestrator import master as master_module  # noqa: E402
from orchestrator.verdicts.verdict import railway_verdicts  # noqa: E402
from orchestrator.graph import TICKS_PER_SECOND  # noqa: E402
from orchestrator.pacing import Pacer  # noqa: E402
from orchestrator.packaging.builder import build_all  # noqa: E402
from orchestrator.process_policy import ProcessPolicy  # noqa: E402
from orchestrator.run import RunOptions, run_system  # noqa: E402

REPO = Path(__file__).resolve().parent.parent
DEADLINE_US = 250.0
SLOW_STEP_S, OUTPUT_INTERVAL_S, TICK_S = 0.5, 0.1, 0.00025


def slow_step_tick(index):
    """Whether tick ``index`` (an int or an array of them) steps the train and the ATO."""
    return index % round(SLOW_STEP_S / TICK_S) == 0


def results_row_tick(index):
    """Whether tick ``index`` ends with a row of results.csv (and the verdicts' checks)."""
    return (index + 1) % round(OUTPUT_INTERVAL_S / TICK_S) == 0


class TickClock:
    """A manipulator that changes nothing: the wall clock at the start of every tick."""

    def __init__(self, ticks: int):
        self.stamps = np.zeros(ticks + 2, dtype=np.int64)
        self.cpu = np.zeros(ticks + 2, dtype=np.int64)       # this thread's CPU time
        self.index = 0

    def outputs_needed(self):
        return {}

    def inputs_needed(self):
        return {}

    def adjusted_components(self):
        return (), ()

    def bound(self, master) -> None:
        pass

    def before_tick(self, master, tick: int) -> None:
        self.stamps[self.index] = time.perf_counter_ns()
        self.cpu[self.index] = time.thread_time_ns()
        self.index += 1

    def adjust_inputs(self, component: str) -> None:
        pass

    def adjust_outputs(self, component: str) -> None:
        pass


class Events:
    """What happened in which tick: the rail line's methods wrapped, the collector watched."""

    def __init__(self, clock: TickClock):
        self.clock = clock
        self.by_tick: Dict[int, set] = {}
        self.gc_starts: List[int] = []
        self.gc_ns: List[int] = []
        self.gc_collected: List[int] = []
        self._undo = []
        self._gc_began = 0

    def _note(self, cause: str) -> None:
        self.by_tick.setdefault(self.clock.index - 1, set()).add(cause)

    def _wrap(self, owner, name: str, cause: str, when=None) -> None:
        original = getattr(owner, name)
        events = self

        def wrapped(*args, **kwargs):
            before = when(args) if when is not None else None
            result = original(*args, **kwargs)
            if when is None or before != when(args):
                events._note(cause)
            return result
        setattr(owner, name, wrapped)
        self._undo.append((owner, name, original))

    def _gc(self, phase: str, info: dict) -> None:
        now = time.perf_counter_ns()
        if phase == "start":
            self._gc_began = now
        elif self.clock.index > 0:                   # while stepping
            self.gc_starts.append(self._gc_began)
            self.gc_ns.append(now - self._gc_began)
            self.gc_collected.append(info.get("collected", 0))

    def _time_steps(self) -> None:
        """Master.step wrapped: each component's step (write inputs, do_step) per tick."""
        original = master_module.Master.step
        clock, spent = self.clock, self.component_ns

        def step(master, component, time_s):
            began = time.perf_counter_ns()
            original(master, component, time_s)
            row = spent.get(component.name)
            if row is None:
                row = spent[component.name] = np.zeros(clock.stamps.size, dtype=np.int64)
            row[clock.index - 1] += time.perf_counter_ns() - began
        master_module.Master.step = step
        self._undo.append((master_module.Master, "step", original))
        run_until = master_module.Master.run_until

        def observed_run_until(master, stop_ticks):
            for observer in master.observers:           # each observer's after_tick per tick
                self._time_observer(observer)
            return run_until(master, stop_ticks)
        master_module.Master.run_until = observed_run_until
        self._undo.append((master_module.Master, "run_until", run_until))

    def _time_observer(self, observer) -> None:
        original, clock = observer.after_tick, self.clock
        row = self.component_ns.setdefault(f"observer {type(observer).__name__}",
                                           np.zeros(clock.stamps.size, dtype=np.int64))

        def after_tick(master, step):
            began = time.perf_counter_ns()
            original(master, step)
            row[clock.index - 1] += time.perf_counter_ns() - began
        observer.after_tick = after_tick

    def __enter__(self) -> "Events":
        self.component_ns: Dict[str, np.ndarray] = {}
        self._time_steps()
        bank = circuit_bank.TrackCircuitBank
        self._wrap(bank, "_activate", "network of a new shunt configuration")
        self._wrap(wheelset_amplitudes.WheelsetAmplitudes, "solve", "wheelset chain solved again")
        self._wrap(bank, "_wake", "parked section woken")
        self._wrap(bank, "_wake_in_frame", "parked section woken")
        self._wrap(parking_module.Parking, "park", "sections parked")
        self._wrap(network_models, "discretise", "network model generated")
        self._wrap(relays.TrackRelays, "update", "relay picked up or dropped",
                   when=lambda args: args[0].up.tobytes())
        gc.callbacks.append(self._gc)
        return self

    def __exit__(self, *exc) -> None:
        gc.callbacks.remove(self._gc)
        for owner, name, original in reversed(self._undo):
            setattr(owner, name, original)

    def causes(self, ticks: np.ndarray, stamps: np.ndarray, waited_us: np.ndarray) -> List[set]:
        """The causes seen in each of ``ticks`` (indices), the collections by their start time;
        a tick whose wall time exceeds its CPU time by more than the deadline waited for the
        core (another process ran: preempted)."""
        starts = np.asarray(self.gc_starts, dtype=np.int64)
        gc_ticks = Counter((np.searchsorted(stamps, starts, side="right") - 1).tolist()) if starts.size else {}
        found = []
        for i in ticks.tolist():
            causes = set(self.by_tick.get(i, ()))
            if i in gc_ticks:
                causes.add("garbage collection")
            if slow_step_tick(i):
                causes.add("train and ATO step")
            if results_row_tick(i):
                causes.add("results.csv row")
            if waited_us[i] > DEADLINE_US:
                causes.add("preempted (wall exceeds CPU time by > 250 us)")
            found.append(causes or {"none of these"})
        return found


def measure(system: Path, fmus: Path, stop_time: float, in_process: bool, collector_off: bool = True) -> dict:
    """``collector_off`` False: without the run's freezing of the collector around stepping
    (for comparison)."""
    ticks = round(stop_time / TICK_S)
    clock = TickClock(ticks)
    with tempfile.TemporaryDirectory() as folder, Events(clock) as events:
        options = RunOptions(summaries=railway_verdicts, stop_time=stop_time, output_dir=Path(folder),
                             in_process=in_process, fmu_dirs=[fmus], record=["train.x", "train.v", "rx.aspect"],
                             manipulators=[clock], process=ProcessPolicy(collector_off=collector_off))
        summary = run_system(system, options).summary
        stamps = clock.stamps[:clock.index].copy()
        cpu_us = np.diff(clock.cpu[:clock.index]) / 1e3
    durations_us = np.diff(stamps) / 1e3
    waited_us = durations_us - cpu_us
    inside = [(start, ns, n) for start, ns, n in zip(events.gc_starts, events.gc_ns, events.gc_collected)
              if stamps[0] <= start < stamps[-1]]                 # while stepping
    worst_count = max(1, durations_us.size // 1000)
    worst = np.argsort(durations_us)[-worst_count:]
    every = np.arange(durations_us.size)
    worst_cpu = np.argsort(cpu_us)[-worst_count:]
    components = {name: row[:durations_us.size] / 1e3 for name, row in events.component_ns.items()}
    return {"durations_us": durations_us, "cpu_us": cpu_us, "worst": worst, "worst_cpu": worst_cpu,
            "worst_causes": events.causes(worst, stamps, waited_us),
            "worst_cpu_causes": events.causes(worst_cpu, stamps, np.zeros_like(waited_us)),
            "all_causes": Counter(c for causes in events.causes(every, stamps, waited_us) for c in causes),
            "gc_count": len(inside), "gc_max_us": max((ns for _, ns, _ in inside), default=0) / 1e3,
            "gc_collected": sum(n for _, _, n in inside), "summary": summary,
            "components_us": components,
            "cpu_by_cause": _median_by_cause(cpu_us, events.causes(every, stamps, np.zeros_like(waited_us))),
            "parts_of_periodic": _parts_of_periodic(durations_us, components)}


def _parts_of_periodic(durations_us: np.ndarray, components: Dict[str, np.ndarray]) -> Dict[str, Dict[str, float]]:
    """The median wall time of each component's step and observer in the ticks of the two
    periodic causes: the slow components' step, and a results row without it."""
    index = np.arange(durations_us.size)
    slow = slow_step_tick(index)
    row = results_row_tick(index) & ~slow
    parts = {}
    for label, mask in (("train and ATO step", slow), ("results.csv row", row), ("neither", ~slow & ~row)):
        medians = {name: float(np.median(values[mask])) for name, values in components.items()}
        medians["tick"] = float(np.median(durations_us[mask]))
        parts[label] = medians
    return parts


def _median_by_cause(cpu_us: np.ndarray, causes: List[set]) -> Dict[str, float]:
    ticks: Dict[str, List[float]] = {}
    for value, found in zip(cpu_us.tolist(), causes):
        for cause in found:
            ticks.setdefault(cause, []).append(value)
    return {cause: float(np.median(values)) for cause, values in ticks.items()}


def report(label: str, result: dict, stop_time: float) -> None:
    d = result["durations_us"]
    p50, p99, p999 = np.percentile(d, [50, 99, 99.9])
    minutes = stop_time / 60.0
    over = int((d > DEADLINE_US).sum())
    print(f"{label}: {d.size} ticks; median {p50:.1f} us, p99 {p99:.1f} us, p99.9 {p999:.1f} us "
          f"({100 * p999 / DEADLINE_US:.0f} % of the deadline), max {d.max():.0f} us; "
          f"{over} ticks over {DEADLINE_US:g} us = {over / minutes:.0f} per simulated minute; "
          f"{result['gc_count']} collections while stepping, the longest {result['gc_max_us']:.0f} us, "
          f"{result['gc_collected']} objects collected", flush=True)
    c = result["cpu_us"]
    c50, c99, c999 = np.percentile(c, [50, 99, 99.9])
    print(f"  CPU time per tick: median {c50:.1f} us, p99 {c99:.1f} us, p99.9 {c999:.1f} us "
          f"({100 * c999 / DEADLINE_US:.0f} % of the deadline), max {c.max():.0f} us; "
          f"{int((c > DEADLINE_US).sum())} ticks over {DEADLINE_US:g} us")
    for what, times, key in (("wall", d, "worst"), ("CPU", c, "worst_cpu")):
        worst = result[key]
        counted = Counter(cause for causes in result[key + "_causes"] for cause in causes)
        print(f"  the worst {worst.size} ticks by {what} time (0.1 %, from {times[worst].min():.0f} us): "
              + "; ".join(f"{cause} {n} (of {result['all_causes'][cause]} ticks with it)"
                          for cause, n in counted.most_common()))
    worst = result["worst_cpu"]
    parts = {name: row[worst] for name, row in result["components_us"].items()}
    rest = result["durations_us"][worst] - sum(parts.values())
    print(f"  in the worst {worst.size} by CPU time, median wall time of each component's step and observer: " + "; ".join(
        f"{name} {np.median(values):.0f} us (max {values.max():.0f})" for name, values in
        sorted(parts.items(), key=lambda kv: -np.median(kv[1])))
        + f"; the master, exchange and observers {np.median(rest):.0f} us")
    for label, medians in result["parts_of_periodic"].items():
        tick = medians.pop("tick")
        print(f"  ticks of {label}: median {tick:.0f} us; of it (medians) " + "; ".join(
            f"{name} {value:.1f} us" for name, value in sorted(medians.items(), key=lambda kv: -kv[1])))
    print("  median CPU time of the ticks with each: " + "; ".join(
        f"{cause} {value:.0f} us" for cause, value in sorted(result["cpu_by_cause"].items(), key=lambda kv: -kv[1])))


def paced(system: Path, fmus: Path, stop_time: float) -> None:
    with tempfile.TemporaryDirectory() as folder:
        options = RunOptions(summaries=railway_verdicts, stop_time=stop_time, output_dir=Path(folder),
                             in_process=True, fmu_dirs=[fmus], record=["train.x", "train.v", "rx.aspect"],
                             real_time=1.0, warn=lambda line: None)
        pace = run_system(system, options).summary["real_time"]
    print(f"paced at real time, in process, {stop_time:g} s: {pace['overruns']} of {pace['steps']} ticks late "
          f"= {pace['overruns'] / (stop_time / 60):.0f} per minute, worst by {pace['worst_lateness_ms'] * 1e3:.0f} us, "
          f"mean {pace['mean_lateness_ms'] * 1e3:.0f} us; kept pace: {pace['kept_pace']}", flush=True)


def floor(seconds: float, work_us: float) -> None:
    """The pacer of `railcosim run --real-time` over ticks of a fixed busy wait of ``work_us``
    and nothing else, the collector off as in a run: what the machine alone makes late."""
    pacer = Pacer(1.0)
    step_ticks = round(TICK_S * TICKS_PER_SECOND)
    pacer.bound(SimpleNamespace(graph=SimpleNamespace(base_ticks=step_ticks)))
    clock, work_s = time.perf_counter, work_us * 1e-6
    gc.disable()
    try:
        for tick in range(0, round(seconds / TICK_S) * step_ticks, step_ticks):
            pacer.before_tick(None, tick)
            done = clock() + work_s
            while clock() < done:
                pass
    finally:
        gc.enable()
    print(f"the machine's floor: {seconds:g} s of ticks of a {work_us:.0f} us busy wait, paced at real time: "
          f"{pacer.overruns} of {pacer.steps} ticks late = {pacer.overruns / (seconds / 60):.0f} per minute, "
          f"worst by {pacer.worst_lateness_s * 1e6:.0f} us; kept pace: {pacer.kept_pace}", flush=True)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--stop-time", type=float, default=30.0, help="simulated seconds per measured run")
    parser.add_argument("--fmi", action="store_true", help="also through FMI")
    parser.add_argument("--gc-frozen-off", action="store_true",
                        help="also without the collector frozen and off while stepping, alternating")
    parser.add_argument("--real-time", type=float, default=0.0, metavar="S",
                        help="also S simulated seconds paced at real time, in process")
    parser.add_argument("--floor", type=float, default=0.0, metavar="S",
                        help="also S seconds of paced ticks of a fixed busy wait as long as the median tick (no simulation)")
    args = parser.parse_args(argv)
    fmus = REPO / "build" / "fmus_n1"
    build_all(fmus, BuildConfig(frame=1))
    print(f"load average {' '.join(f'{x:.2f}' for x in os.getloadavg())} on {os.cpu_count()} cores", flush=True)
    variants = [True, False] if args.gc_frozen_off else [True]
    median_tick_us = None
    with tempfile.TemporaryDirectory() as folder:
        system = sample_by_sample_system(Path(folder), fmus)
        for in_process in ([True, False] if args.fmi else [True]):
            for frozen in variants:
                result = measure(system, fmus, args.stop_time, in_process, collector_off=frozen)
                where = "in process" if in_process else "through FMI"
                report(f"{where}{'' if frozen else ', collector not frozen'}", result, args.stop_time)
                if median_tick_us is None:
                    median_tick_us = float(np.median(result["durations_us"]))
        if args.real_time:
            paced(system, fmus, args.real_time)
    if args.floor:
        floor(args.floor, median_tick_us)
    print(f"load average {' '.join(f'{x:.2f}' for x in os.getloadavg())}")


if __name__ == "__main__":
    main()

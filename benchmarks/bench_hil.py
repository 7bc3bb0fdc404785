"""Hardware-in-the-loop exchange on loopback (docs/performance.md#hardware-in-the-loop-dcp):

* ``free_run`` (default): free_run with its receiver ``rx`` swapped for ``railcosim dcp-slave
  LocoReceiver.fmu`` (non-real-time, a process of its own) against the same run with the FMU:
  real-time factors, whether results.csv is byte-identical, and the per-frame round trip
  (median, p99, max) against the 10 ms frame;
* ``ato``: the whole free_run with its ATO ``ato`` swapped for ``railcosim dcp-slave
  AtoController.fmu``: the same stops and safety verdict as with the FMU;
* ``free_run_srt``: the same swap with the emulator in soft real time (its own clock; the run is
  paced to the wall clock): lost outputs, fail-safe steps and the age of the outputs used;
* ``counter``: the exchange alone, with the test suite's counter slave (tests/test_hil.py, a
  foreign .dcpx) stepping every 10 ms beside a test FMU;
* ``sine_srt``: the test suite's sine slave in soft real time (tests/test_hil.py, the run paced
  to the wall clock): whether over a minute any output is lost or late, any step falls back to
  the fail-safe values, and the outputs' age against the deadline (the test asserts only what
  the wall clock does not decide).

    PYTHONPATH=. python benchmarks/bench_hil.py [free_run|free_run_srt|ato|counter|sine_srt] [SIM_SECONDS]

Needs `railcosim build` first. Record the machine's load with the figures: on a shared machine
the exchange (eight datagrams per step, two processes) waits for the scheduler.
"""
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path[:0] = [str(REPO / "tests"), str(REPO)]

from helpers import ComponentSpec, ConnectionSpec, cli_environment, write_ssd   # noqa: E402
from orchestrator.dcp.master import parse_swap                     # noqa: E402
from orchestrator.run import RunOptions, run_system         # noqa: E402

FMUS = REPO / "build" / "fmus"
_KEYS = ("exchanges", "rtt_median_ms", "rtt_p99_ms", "rtt_max_ms", "overruns", "lost", "fail_safe_steps")


def _emulator(fmu: Path, dcpx: Path, *options: str) -> tuple:
    process = subprocess.Popen([sys.executable, "-m", "orchestrator", "dcp-slave", str(fmu), "--port", "0",
                                "--dcpx-out", str(dcpx), "--quiet", *options], cwd=REPO, env=cli_environment(),
                               stdout=subprocess.PIPE, text=True)
    return process, process.stdout.readline().split()[1]


def free_run_srt(sim_s: float) -> dict:
    """The receiver's emulator in soft real time: what the run counts lost, and the outputs' age."""
    from orchestrator.verdicts.verdict import railway_verdicts, safety_verdict

    with tempfile.TemporaryDirectory() as folder:
        folder = Path(folder)
        process, address = _emulator(FMUS / "LocoReceiver.fmu", folder / "rx.dcpx", "--real-time")
        try:
            swap = parse_swap(f"rx=dcp://{address}?dcpx={folder / 'rx.dcpx'}")
            swapped = run_system(REPO / "ssp" / "free_run",
                                 RunOptions(output_dir=folder / "dcp", swaps={"rx": swap}, stop_time=sim_s,
                                            fmu_dirs=[FMUS], summaries=railway_verdicts))
        finally:
            process.wait(timeout=30)
    return {"sim_time_s": swapped.summary["sim_time_s"], "load_average": os.getloadavg(),
            "real_time": swapped.summary["real_time"], "verdict": safety_verdict(swapped.summary)[1],
            **{k: swapped.summary["hil"]["rx"][k] for k in _KEYS}}


def free_run(sim_s: float, component: str = "rx", unit: str = "LocoReceiver") -> dict:
    from orchestrator.verdicts.verdict import railway_verdicts, safety_verdict

    with tempfile.TemporaryDirectory() as folder:
        folder = Path(folder)
        options = dict(stop_time=sim_s, fmu_dirs=[FMUS], summaries=railway_verdicts)
        reference = run_system(REPO / "ssp" / "free_run", RunOptions(output_dir=folder / "fmu", **options))
        process, address = _emulator(FMUS / f"{unit}.fmu", folder / f"{component}.dcpx")
        try:
            swap = parse_swap(f"{component}=dcp://{address}?dcpx={folder / f'{component}.dcpx'}")
            swapped = run_system(REPO / "ssp" / "free_run",
                                 RunOptions(output_dir=folder / "dcp", swaps={component: swap}, **options))
        finally:
            process.kill()
            process.wait()
        identical = (folder / "fmu" / "results.csv").read_bytes() == (folder / "dcp" / "results.csv").read_bytes()
    stops = [[s.get("station"), s.get("arrival_s")] for t in swapped.summary["trains"] for s in t.get("stops", [])]
    return {"swapped": component, "sim_time_s": swapped.summary["sim_time_s"], "load_average": os.getloadavg(),
            "realtime_factor_fmu": reference.summary["realtime_factor"],
            "realtime_factor_swapped": swapped.summary["realtime_factor"], "results_identical": identical,
            "same_stops": swapped.summary["trains"] == reference.summary["trains"], "stops": stops,
            "verdict": safety_verdict(swapped.summary)[1],
            "same_verdict": safety_verdict(swapped.summary) == safety_verdict(reference.summary),
            **{k: swapped.summary["hil"][component][k] for k in _KEYS}}


def counter(sim_s: float) -> dict:
    from conftest import build_test_fmus
    from test_hil import DCPX

    fmus = build_test_fmus(4)
    with tempfile.TemporaryDirectory() as folder:
        folder = Path(folder)
        system = folder / "pair"
        write_ssd(system, "pair", [ComponentSpec("src", str(fmus / "TestCounter.fmu"), 0.01),
                                   ComponentSpec("dut", str(fmus / "TestCounter.fmu"), 0.01)],
                  [ConnectionSpec("src.t_end", "dut.u")], stop_time=sim_s)
        server = subprocess.Popen([sys.executable, __file__, "--serve"], stdout=subprocess.PIPE, text=True)
        try:
            port = int(server.stdout.readline())
            dcpx = folder / "counter.dcpx"
            dcpx.write_text(DCPX.format(port=port))
            swap = parse_swap(f"dut=dcp://127.0.0.1:{port}?dcpx={dcpx}")
            result = run_system(system, RunOptions(output_dir=folder / "out", swaps={"dut": swap}))
        finally:
            server.kill()
            server.wait()
    return {"sim_time_s": sim_s, "load_average": os.getloadavg(),
            "realtime_factor": result.summary["realtime_factor"],
            **{k: result.summary["hil"]["dut"][k] for k in _KEYS}}


def sine_srt(sim_s: float) -> dict:
    from conftest import build_test_fmus
    from test_hil import soft_real_time_run

    with tempfile.TemporaryDirectory() as folder:
        hil, counts = soft_real_time_run(Path(folder), build_test_fmus(4), sim_s)
    return {"sim_time_s": sim_s, "load_average": os.getloadavg(), "slave_sent": counts["sent"],
            "slave_dropped": counts["dropped"], "late": hil["late"], "deadline_ms": hil["deadline_ms"],
            **{k: hil[k] for k in _KEYS}}


def serve() -> None:
    """The counter slave's process: say the port, then answer until killed."""
    from test_hil import CounterSlave

    slave = CounterSlave()
    print(slave.port, flush=True)
    slave.run()


if __name__ == "__main__":
    if sys.argv[1:] == ["--serve"]:
        serve()
    else:
        kind = sys.argv[1] if len(sys.argv) > 1 else "free_run"
        seconds = float(sys.argv[2]) if len(sys.argv) > 2 else None    # ato: the whole run
        runs = {"free_run": lambda: free_run(seconds or 120.0), "counter": lambda: counter(seconds or 60.0),
                "free_run_srt": lambda: free_run_srt(seconds or 60.0), "sine_srt": lambda: sine_srt(seconds or 60.0),
                "ato": lambda: free_run(seconds, "ato", "AtoController")}
        print(json.dumps(runs[kind](), indent=2))

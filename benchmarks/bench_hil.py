"""Per-step DCP exchange of a swapped component on loopback: round trip median / p99 / max
against a 10 ms frame, and the real-time factor of the run (docs/performance.md).

The slave is the test suite's non-real-time counter slave (tests/test_hil.py, a foreign .dcpx)
in a process of its own (as a bench's would be); the swapped component steps every 10 ms.

    PYTHONPATH=. python benchmarks/bench_hil.py [SIM_SECONDS]
"""
import json
import subprocess
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path[:0] = [str(REPO / "tests"), str(REPO)]

from conftest import build_test_fmus                       # noqa: E402
from helpers import ComponentSpec, ConnectionSpec, write_ssd   # noqa: E402
from test_hil import DCPX, CounterSlave                     # noqa: E402
from orchestrator.hil import parse_swap                     # noqa: E402
from orchestrator.run import RunOptions, run_system         # noqa: E402


def main(sim_s: float = 60.0) -> dict:
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
    figures = {"sim_time_s": result.summary["sim_time_s"], "realtime_factor": result.summary["realtime_factor"],
               **{k: result.summary["hil"]["dut"][k] for k in ("exchanges", "rtt_median_ms", "rtt_p99_ms",
                                                              "rtt_max_ms", "overruns", "lost")}}
    print(json.dumps(figures, indent=2))
    return figures


def serve() -> None:
    """The slave process: say the port, then answer until killed."""
    slave = CounterSlave()
    print(slave.port, flush=True)
    slave.run()


if __name__ == "__main__":
    if sys.argv[1:] == ["--serve"]:
        serve()
    else:
        main(float(sys.argv[1]) if len(sys.argv) > 1 else 60.0)

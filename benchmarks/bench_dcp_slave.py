"""The per-frame exchange with `railcosim dcp-slave` on loopback, non-real-time: the receiver
(LocoReceiver.fmu, every input and output configured, the coil EMF as one 40-sample array)
stepped frame by frame by a minimal master, as a DCP master does it:

    DAT_input_output (inputs) → STC_do_step → … NTF COMPUTED → STC_send_outputs → … DAT (outputs)
    … NTF RUNNING

The round trip of one frame is timed from the inputs' send to the outputs' arrival (the
master's cost of encoding and decoding included), against the 10 ms frame a soft real-time bench
has. Needs `railcosim build` first.

    python benchmarks/bench_dcp_slave.py [--frames 3000] [--fmu build/fmus/LocoReceiver.fmu]

Prints the sizes of the DAT PDUs (inputs, outputs) and their payloads, median, p99 and max of
the round trip, and the share of the 10 ms frame the p99 takes.
"""
import argparse
import statistics
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO / "tests"))

from dcp_test_master import TestMaster, start_slave  # noqa: E402
from orchestrator.dcp import dcpx  # noqa: E402
from orchestrator.dcp.pdu import PayloadCodec, Pdu, PduType, State  # noqa: E402
from orchestrator.fmu import read_interface  # noqa: E402

FRAME_NS = 10_000_000


def dat_size(payload_bytes: int) -> int:
    """The bytes of a DAT_input_output PDU carrying a payload of this size (docs/hil.md#pdus)."""
    return len(Pdu(PduType.DAT_input_output, pdu_seq_id=0, data_id=0, payload=bytes(payload_bytes)).encode())


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--frames", type=int, default=3000)
    parser.add_argument("--fmu", default=str(REPO / "build" / "fmus" / "LocoReceiver.fmu"))
    args = parser.parse_args()
    fmu = Path(args.fmu)
    desc = dcpx.description_from_fmu(read_interface(fmu))
    inputs = desc.of_causality("input")
    outputs = desc.of_causality("output")
    proc, address = start_slave(fmu)
    master = TestMaster(address)
    try:
        master.register(desc.uuid)
        master.configure([(v.vr, v.data_type) for v in inputs], [(v.vr, v.data_type) for v in outputs], FRAME_NS)
        codec_in = PayloadCodec([(v.data_type, v.count) for v in inputs])
        codec_out = PayloadCodec([(v.data_type, v.count) for v in outputs])
        values = [np.asarray(v.start * (v.count // len(v.start))) for v in inputs]
        coil = next(k for k, v in enumerate(inputs) if v.name == "e_coil")
        master.request(lambda s: Pdu(PduType.STC_run, pdu_seq_id=s, receiver=1, state_id=State.CONFIGURED, start_time=0))
        master.wait_state(State.SYNCHRONIZED)
        master.request(lambda s: Pdu(PduType.STC_run, pdu_seq_id=s, receiver=1, state_id=State.SYNCHRONIZED, start_time=0))
        master.wait_state(State.RUNNING)
        rng = np.random.default_rng(1)
        round_trips = []
        for k in range(args.frames):
            values[coil] = rng.normal(0.0, 0.1, inputs[coil].count)
            master.data.clear()
            began = time.perf_counter()
            master.send_inputs(k, codec_in.encode(values))
            master.request(lambda s: Pdu(PduType.STC_do_step, pdu_seq_id=s, receiver=1, state_id=State.RUNNING, steps=FRAME_NS))
            master.wait_state(State.COMPUTED)
            master.stc(PduType.STC_send_outputs, State.COMPUTED, None)
            master.wait_data(1)
            codec_out.decode(master.data[-1].payload)
            round_trips.append(time.perf_counter() - began)
            master.wait_state(State.RUNNING)
        master.stc(PduType.STC_stop, State.RUNNING, State.STOPPED)
        master.stc(PduType.STC_deregister, State.STOPPED, State.ALIVE)
        proc.wait(timeout=60)
    finally:
        master.close()
        if proc.poll() is None:
            proc.kill()
    ms = np.array(round_trips) * 1e3
    p99 = float(np.percentile(ms, 99))
    print(f"{fmu.name}: {len(ms)} frames, DAT PDUs in {dat_size(codec_in.size)} B / out {dat_size(codec_out.size)} B "
          f"(payloads {codec_in.size} B / {codec_out.size} B)")
    print(f"round trip per frame: median {statistics.median(ms):.3f} ms, p99 {p99:.3f} ms, max {ms.max():.3f} ms")
    print(f"p99 against the 10 ms frame: {p99 / 10 * 100:.1f} %")


if __name__ == "__main__":
    main()

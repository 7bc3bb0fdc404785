"""`railcosim dcp-slave` in a subprocess on loopback, driven by a test master written from the
DCP 1.0 standard (tests/dcp_test_master.py)."""
import os
import signal
import socket
import struct
import subprocess
import sys

import numpy as np
import pytest

from dcp_test_master import REPO, TestMaster, start_slave
from orchestrator.dcp import dcpx
from orchestrator.dcp.pdu import (DataType, ErrorCode, OpMode, PayloadCodec, PduType, State, Pdu)

STEP_NS = 1_000_000          # the test frame FMUs' step: 4 samples at 4 kHz


def _end(proc, master):
    master.close()
    if proc.poll() is None:
        proc.kill()
    proc.wait(timeout=30)
    proc.stdout.close()
    proc.stderr.close()


@pytest.fixture
def frame_stage(test_fmus, tmp_path):
    """The slave serving TestFrameStage (frame input u[4], frame output y[4], parameter alpha),
    its description as the slave wrote it, and a master."""
    dcpx_path = tmp_path / "stage.dcpx"
    proc, address = start_slave(test_fmus / "TestFrameStage.fmu", "--dcpx-out", str(dcpx_path))
    master = TestMaster(address)
    yield proc, dcpx.read_dcpx(dcpx_path), master
    _end(proc, master)


def _reference_outputs(fmu_path, alpha, frames):
    """TestFrameStage stepped directly through FMI, frame by frame."""
    from orchestrator.fmu import make_slave, new_workdir, read_interface, remove_workdir

    interface = read_interface(fmu_path)
    workdir = new_workdir()
    slave = make_slave("reference", fmu_path, interface, workdir, in_process=False)
    try:
        slave.instantiate()
        u = [interface.variables[f"u[{k}]"].vr for k in range(1, 5)]
        y = [interface.variables[f"y[{k}]"].vr for k in range(1, 5)]
        slave.bind({"Real": u}, {"Real": y})
        slave.setup_experiment(0.0, None)
        slave.set_values({"alpha": alpha})
        slave.enter_initialization()
        slave.inputs["Real"].values[:] = frames[0]
        slave.write_inputs()
        slave.exit_initialization()
        out = []
        for k, frame in enumerate(frames):
            slave.inputs["Real"].values[:] = frame
            slave.write_inputs()
            slave.do_step(k * STEP_NS / 1e9, STEP_NS / 1e9)
            slave.read_outputs()
            out.append(slave.outputs["Real"].values.copy())
        slave.terminate()
        return np.array(out)
    finally:
        slave.free()
        remove_workdir(workdir)


# the 1 ms frame in any resolution that divides it: 1 ns (the recommended one), 1 µs, 1 ms
@pytest.mark.parametrize("resolution,steps", [((1, 1_000_000_000), STEP_NS), ((1, 1_000_000), 1000),
                                              ((1, 1000), 1)])
def test_state_sequence_and_dat_round_trip_match_the_fmu(frame_stage, test_fmus, resolution, steps):
    proc, desc, master = frame_stage
    u, y, alpha = desc.by_name("u"), desc.by_name("y"), desc.by_name("alpha")
    assert u.dims == (4,) and y.dims == (4,) and alpha.causality == "parameter"
    master.register(desc.uuid)
    master.configure([(u.vr, DataType.float64)], [(y.vr, DataType.float64)], steps, resolution=resolution,
                     parameters=[(alpha.vr, DataType.float64, struct.pack("<d", 0.5))])
    codec_in = PayloadCodec([(DataType.float64, 4)])
    codec_out = PayloadCodec([(DataType.float64, 4)])
    frames = np.random.default_rng(3).normal(size=(12, 4))

    master.send_inputs(0, codec_in.encode([frames[0]]))
    master.stc(PduType.STC_initialize, State.CONFIGURED, State.INITIALIZED)
    master.stc(PduType.STC_send_outputs, State.INITIALIZED, State.CONFIGURED)
    master.wait_data(1)
    master.request(lambda s: Pdu(PduType.STC_run, pdu_seq_id=s, receiver=1, state_id=State.CONFIGURED, start_time=0))
    master.wait_state(State.SYNCHRONIZED)
    master.request(lambda s: Pdu(PduType.STC_run, pdu_seq_id=s, receiver=1, state_id=State.SYNCHRONIZED, start_time=0))
    master.wait_state(State.RUNNING)
    got = []
    for k, frame in enumerate(frames):
        master.send_inputs(k + 1, codec_in.encode([frame]))
        master.request(lambda s: Pdu(PduType.STC_do_step, pdu_seq_id=s, receiver=1, state_id=State.RUNNING,
                                     steps=steps))
        master.wait_state(State.COMPUTED)
        master.stc(PduType.STC_send_outputs, State.COMPUTED, State.RUNNING)
        master.wait_data(k + 2)
        got.append(codec_out.decode(master.data[-1].payload)[0].copy())
    assert [d.pdu_seq_id for d in master.data] == list(range(len(frames) + 1))
    assert master.inf_state() == State.RUNNING
    master.stc(PduType.STC_stop, State.RUNNING, State.STOPPED)
    master.stc(PduType.STC_deregister, State.STOPPED, State.ALIVE)
    assert proc.wait(timeout=30) == 0                 # a deregistered slave ends cleanly
    expected = _reference_outputs(test_fmus / "TestFrameStage.fmu", 0.5, frames)
    np.testing.assert_array_equal(np.array(got), expected)          # bit for bit
    assert not np.allclose(expected, frames)                        # the filter did act


def test_requests_out_of_turn_are_refused_with_the_standards_codes(frame_stage):
    proc, desc, master = frame_stage
    u = desc.by_name("u")
    wrong_uuid = dcpx.slave_uuid("not-this-slave")
    rsp = master.request(lambda s: Pdu(PduType.STC_register, pdu_seq_id=s, receiver=1, state_id=State.ALIVE, slave_uuid=wrong_uuid, op_mode=OpMode.NRT), expect_ack=False)
    assert rsp.type_id == PduType.RSP_nack and rsp.error_code == ErrorCode.INVALID_UUID
    rsp = master.request(lambda s: Pdu(PduType.STC_register, pdu_seq_id=s, receiver=1, state_id=State.ALIVE, slave_uuid=desc.uuid, op_mode=OpMode.SRT), expect_ack=False)
    assert rsp.error_code == ErrorCode.INVALID_OP_MODE            # this slave offers NRT only
    master.register(desc.uuid)
    sid = master.slave_id
    # a request of another state, and a state_id that is not the slave's
    rsp = master.request(lambda s: Pdu(PduType.STC_do_step, pdu_seq_id=s, receiver=sid, state_id=State.CONFIGURATION, steps=1), expect_ack=False)
    assert rsp.error_code == ErrorCode.PROTOCOL_ERROR_PDU_NOT_ALLOWED_IN_THIS_STATE
    rsp = master.request(lambda s: Pdu(PduType.STC_prepare, pdu_seq_id=s, receiver=sid, state_id=State.RUNNING), expect_ack=False)
    assert rsp.error_code == ErrorCode.INVALID_STATE_ID
    # configuration the description does not allow: a resolution of which the 1 ms step is no
    # whole number (0.3 ms)
    rsp = master.request(lambda s: Pdu(PduType.CFG_time_res, pdu_seq_id=s, receiver=sid, numerator=3,
                                       denominator=10000), expect_ack=False)
    assert rsp.error_code == ErrorCode.INVALID_TIME_RESOLUTION
    rsp = master.request(lambda s: Pdu(PduType.CFG_input, pdu_seq_id=s, receiver=sid, data_id=1, pos=0, target_vr=987654, source_data_type=DataType.float64), expect_ack=False)
    assert rsp.error_code == ErrorCode.INVALID_VALUE_REFERENCE
    rsp = master.request(lambda s: Pdu(PduType.CFG_input, pdu_seq_id=s, receiver=sid, data_id=1, pos=0, target_vr=u.vr, source_data_type=DataType.string), expect_ack=False)
    assert rsp.error_code == ErrorCode.INVALID_SOURCE_DATA_TYPE
    rsp = master.request(lambda s: Pdu(PduType.STC_prepare, pdu_seq_id=s, receiver=sid, state_id=State.CONFIGURATION), expect_ack=False)
    assert rsp.error_code == ErrorCode.INCOMPLETE_CONFIG_TIME_RESOLUTION
    # truncated and oversized requests: RSP_nack INVALID_LENGTH for their sequence id
    seq = master.seq
    master.send_raw(Pdu(PduType.CFG_time_res, pdu_seq_id=seq, receiver=sid, numerator=1, denominator=1_000_000_000).encode()[:-2])
    assert master.response(seq).error_code == ErrorCode.INVALID_LENGTH
    seq = master.seq = seq + 1
    master.send_raw(Pdu(PduType.INF_state, pdu_seq_id=seq, receiver=sid).encode() + b"\x00" * 60000)
    assert master.response(seq).error_code == ErrorCode.INVALID_LENGTH
    master.seq = seq + 1
    # out of sequence: refused, the expected id named
    seq = master.seq + 5
    master.send_raw(Pdu(PduType.INF_state, pdu_seq_id=seq, receiver=sid).encode())
    rsp = master.response(seq)
    assert rsp.error_code == ErrorCode.INVALID_SEQUENCE_ID and rsp.exp_seq_id == master.seq
    # a PDU of the standard we do not offer (CFG_logging)
    rsp = master.request(lambda s: _raw_header(0x2A, s, sid, b"\x01\x01\x00"), expect_ack=False)
    assert rsp.error_code == ErrorCode.NOT_SUPPORTED_PDU
    # garbage, an unknown type id, a DAT of an unknown data_id, a malformed DAT: no answer, no crash
    for junk in (b"", b"\x07", b"\x99\x00\x00\x01", bytes(range(256)) * 3,
                 b"\xf0\x00\x00\x07\x00" + b"\x00" * 8, b"\xf0\x00"):
        master.send_raw(junk)
    assert master.request(lambda s: Pdu(PduType.INF_state, pdu_seq_id=s, receiver=sid),
                          expect_ack=False).type_id == PduType.RSP_state_ack
    assert master.inf_state() == State.CONFIGURATION
    assert proc.poll() is None


class _raw_header:
    """A request of any type id: header (type, seq, receiver) and a body."""

    def __init__(self, type_id, seq, receiver, body):
        self.data = struct.pack("<BHB", type_id, seq, receiver) + body

    def encode(self):
        return self.data


def test_wrong_length_dat_is_dropped_and_later_data_still_apply(frame_stage):
    proc, desc, master = frame_stage
    u, y = desc.by_name("u"), desc.by_name("y")
    master.register(desc.uuid)
    master.configure([(u.vr, DataType.float64)], [(y.vr, DataType.float64)], STEP_NS)
    codec = PayloadCodec([(DataType.float64, 4)])
    master.send_inputs(0, codec.encode([[1.0, 2.0, 3.0, 4.0]])[:-1])       # one byte short
    master.send_inputs(1, codec.encode([[1.0, 2.0, 3.0, 4.0]]) + b"\x00")  # one byte long
    master.send_inputs(2, codec.encode([[5.0, 6.0, 7.0, 8.0]]))
    master.send_inputs(1, codec.encode([[9.0, 9.0, 9.0, 9.0]]))            # older than seq 2: stale
    master.request(lambda s: Pdu(PduType.STC_run, pdu_seq_id=s, receiver=1, state_id=State.CONFIGURED, start_time=0))
    master.wait_state(State.SYNCHRONIZED)
    master.request(lambda s: Pdu(PduType.STC_do_step, pdu_seq_id=s, receiver=1, state_id=State.SYNCHRONIZED, steps=STEP_NS))
    master.wait_state(State.COMPUTED)
    master.stc(PduType.STC_send_outputs, State.COMPUTED, State.SYNCHRONIZED)
    master.wait_data(1)
    # alpha = 0: the stage is a wire, so its outputs are the inputs that applied
    assert codec.decode(master.data[-1].payload)[0].tolist() == [5.0, 6.0, 7.0, 8.0]


def test_soft_real_time_slave_runs_on_its_own_clock(test_fmus):
    proc, address = start_slave(test_fmus / "TestFrameSource.fmu", "--real-time")
    master = TestMaster(address)
    try:
        from orchestrator.fmu import read_interface

        desc = dcpx.description_from_fmu(read_interface(test_fmus / "TestFrameSource.fmu"))
        y = desc.by_name("y")
        rsp = master.request(lambda s: Pdu(PduType.STC_register, pdu_seq_id=s, receiver=1, state_id=State.ALIVE, slave_uuid=desc.uuid, op_mode=OpMode.NRT), expect_ack=False)
        assert rsp.error_code == ErrorCode.INVALID_OP_MODE           # a real-time-only slave
        master.register(desc.uuid, OpMode.SRT)
        master.configure([], [(y.vr, DataType.float64)], 2 * STEP_NS)    # outputs every 2 ms
        master.request(lambda s: Pdu(PduType.STC_run, pdu_seq_id=s, receiver=1, state_id=State.CONFIGURED, start_time=0))
        master.wait_state(State.SYNCHRONIZED)
        rsp = master.request(lambda s: Pdu(PduType.STC_do_step, pdu_seq_id=s, receiver=1, state_id=State.SYNCHRONIZED, steps=1), expect_ack=False)
        assert rsp.error_code == ErrorCode.NOT_SUPPORTED_PDU              # no master steps in SRT
        master.wait_data(3)                  # the slave's clock runs from the first STC_run on
        master.request(lambda s: Pdu(PduType.STC_run, pdu_seq_id=s, receiver=1, state_id=State.SYNCHRONIZED, start_time=0))
        master.wait_state(State.RUNNING)
        master.wait_data(len(master.data) + 3)
        codec = PayloadCodec([(DataType.float64, 4)])
        firsts = [codec.decode(d.payload)[0][0] for d in master.data]
        # the source (1 ms steps of 4 samples, numbered from the step's start time) stepped on
        # the slave's clock without a gap across the change to RUNNING, its outputs sent after
        # every second step
        assert firsts == [4.0 + 8.0 * k for k in range(len(firsts))]
        master.stc(PduType.STC_stop, State.RUNNING, State.STOPPED)
        master.stc(PduType.STC_deregister, State.STOPPED, State.ALIVE)
        assert proc.wait(timeout=30) == 0
    finally:
        _end(proc, master)


def test_drop_data_leaves_a_fraction_of_outputs_unsent(test_fmus):
    proc, address = start_slave(test_fmus / "TestFrameSource.fmu", "--drop-data", "0.3", "--seed", "7")
    master = TestMaster(address, timeout_s=2.0)
    try:
        from orchestrator.fmu import read_interface

        desc = dcpx.description_from_fmu(read_interface(test_fmus / "TestFrameSource.fmu"))
        master.register(desc.uuid)
        master.configure([], [(desc.by_name("y").vr, DataType.float64)], STEP_NS)
        master.request(lambda s: Pdu(PduType.STC_run, pdu_seq_id=s, receiver=1, state_id=State.CONFIGURED, start_time=0))
        master.wait_state(State.SYNCHRONIZED)
        for _ in range(60):
            master.request(lambda s: Pdu(PduType.STC_do_step, pdu_seq_id=s, receiver=1, state_id=State.SYNCHRONIZED, steps=STEP_NS))
            master.wait_state(State.COMPUTED)
            master.stc(PduType.STC_send_outputs, State.COMPUTED, State.SYNCHRONIZED)
        master.inf_state()        # every DAT sent has arrived before this answer on loopback
        seqs = [d.pdu_seq_id for d in master.data]
        assert 25 < len(seqs) < 58                        # about 70 % of 60
        assert seqs == sorted(seqs) and seqs[-1] <= 59    # gaps the master can count
    finally:
        _end(proc, master)


def _cli(*args, timeout=120):
    env = dict(os.environ, PYTHONPATH=str(REPO))
    return subprocess.run([sys.executable, "-m", "orchestrator", "dcp-slave", *args], capture_output=True,
                          text=True, env=env, cwd=str(REPO), timeout=timeout)


def test_bad_command_lines_are_one_line_and_exit_2(tmp_path, test_fmus):
    missing = _cli(str(tmp_path / "nothing.fmu"))
    assert missing.returncode == 2 and missing.stderr.count("\n") == 1 and "FMU not found" in missing.stderr
    busy = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    busy.bind(("127.0.0.1", 0))
    try:
        taken = _cli(str(test_fmus / "TestGain.fmu"), "--port", str(busy.getsockname()[1]))
    finally:
        busy.close()
    assert taken.returncode == 2 and "cannot listen on 127.0.0.1:" in taken.stderr
    assert taken.stderr.count("\n") == 1
    drop = _cli(str(test_fmus / "TestGain.fmu"), "--drop-data", "1.5")
    assert drop.returncode == 2 and "--drop-data" in drop.stderr


def test_sigterm_ends_the_slave_cleanly(test_fmus):
    proc, address = start_slave(test_fmus / "TestGain.fmu")
    try:
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=30) == 128 + signal.SIGTERM
        assert "Traceback" not in proc.stderr.read()
    finally:
        if proc.poll() is None:
            proc.kill()
        proc.stdout.close()
        proc.stderr.close()


def _serve(fmu):
    proc, address = start_slave(fmu)
    return proc, TestMaster(address)


def _run_to_running(master):
    master.request(lambda s: Pdu(PduType.STC_run, pdu_seq_id=s, receiver=master.slave_id, state_id=State.CONFIGURED, start_time=0))
    master.wait_state(State.SYNCHRONIZED)
    master.request(lambda s: Pdu(PduType.STC_run, pdu_seq_id=s, receiver=master.slave_id, state_id=State.SYNCHRONIZED, start_time=0))
    master.wait_state(State.RUNNING)


def _step(master, steps):
    master.request(lambda s: Pdu(PduType.STC_do_step, pdu_seq_id=s, receiver=master.slave_id, state_id=State.RUNNING, steps=steps))
    master.wait_state(State.COMPUTED)
    master.stc(PduType.STC_send_outputs, State.COMPUTED, State.RUNNING)


def test_parameters_and_every_fmi_type_travel(test_fmus):
    """Real, Integer, Boolean (as uint8) and String parameters by CFG_parameter; Integer and
    Boolean outputs back in DAT."""
    from orchestrator.fmu import read_interface

    desc = dcpx.description_from_fmu(read_interface(test_fmus / "TestGain.fmu"))
    v = {name: desc.by_name(name) for name in ("u", "y", "k", "bias", "enabled", "mode", "label",
                                                "mode_out", "enabled_out")}
    assert v["enabled"].data_type == DataType.uint8 and v["mode"].data_type == DataType.int32
    proc, master = _serve(test_fmus / "TestGain.fmu")
    try:
        master.register(desc.uuid)
        label = PayloadCodec([(DataType.string, 1)]).encode(["по-русски"])
        master.configure([(v["u"].vr, DataType.float32)],            # a float32 source widened
                         [(v[n].vr, None) for n in ("y", "mode_out", "enabled_out")], 10_000_000,
                         parameters=[(v["k"].vr, DataType.float64, struct.pack("<d", 2.5)),
                                     (v["bias"].vr, DataType.int16, struct.pack("<h", -3)),
                                     (v["mode"].vr, DataType.int32, struct.pack("<i", 7)),
                                     (v["enabled"].vr, DataType.uint8, b"\x01"),
                                     (v["label"].vr, DataType.string, label)])
        _run_to_running(master)
        master.send_inputs(0, PayloadCodec([(DataType.float32, 1)]).encode([4.0]))
        _step(master, 10_000_000)
        master.wait_data(1)
        out = PayloadCodec([(DataType.float64, 1), (DataType.int32, 1), (DataType.uint8, 1)])
        y, mode, enabled = out.decode(master.data[-1].payload)
        assert (y[0], mode[0], enabled[0]) == (2.5 * 4.0 - 3, 7, 1)
    finally:
        _end(proc, master)


def test_a_failing_fmu_puts_the_slave_in_error_and_reset_starts_afresh(test_fmus):
    from orchestrator.fmu import read_interface

    desc = dcpx.description_from_fmu(read_interface(test_fmus / "TestCounter.fmu"))
    steps_vr, fail_vr = desc.by_name("steps").vr, desc.by_name("fail_at").vr
    proc, master = _serve(test_fmus / "TestCounter.fmu")
    try:
        master.register(desc.uuid)
        master.configure([], [(steps_vr, None)], 10_000_000,
                         parameters=[(fail_vr, DataType.float64, struct.pack("<d", 0.02))])
        _run_to_running(master)
        _step(master, 10_000_000)
        _step(master, 10_000_000)
        master.request(lambda s: Pdu(PduType.STC_do_step, pdu_seq_id=s, receiver=master.slave_id, state_id=State.RUNNING, steps=10_000_000))
        master.wait_state(State.ERROR_HANDLING)
        master.wait_state(State.ERROR_RESOLVED)
        rsp = master.request(lambda s: Pdu(PduType.INF_error, pdu_seq_id=s, receiver=master.slave_id), expect_ack=False)
        assert rsp.error_code == ErrorCode.PROTOCOL_ERROR_GENERIC
        master.stc(PduType.STC_reset, State.ERROR_RESOLVED, State.CONFIGURATION)
        master.data.clear()
        master.configure([], [(steps_vr, None)], 10_000_000)     # fail_at back to its start value
        _run_to_running(master)
        for _ in range(4):
            _step(master, 10_000_000)
        master.wait_data(4)
        counts = [PayloadCodec([(DataType.int32, 1)]).decode(d.payload)[0][0] for d in master.data]
        assert counts == [1, 2, 3, 4]                               # a fresh instance counts from 1
        master.stc(PduType.STC_stop, State.RUNNING, State.STOPPED)
        master.stc(PduType.STC_deregister, State.STOPPED, State.ALIVE)
        assert proc.wait(timeout=30) == 0
    finally:
        _end(proc, master)

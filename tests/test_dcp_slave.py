"""`railcosim dcp-slave` in a subprocess on loopback, driven by a test master written from the
DCP 1.0 standard (tests/dcp_test_master.py)."""
import os
import signal
import socket
import struct
import subprocess
import sys
import time

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


# the 1 ms frame in any resolution that divides it: 1 ns, 1 µs, 1 ms (the FMU step, the recommended one)
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


# ---- a session bound to the master that registered it ----------------------------------------

def _intruder():
    """A third socket on loopback: neither the slave nor its master."""
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    sock.settimeout(0.3)
    return sock


def _silent(sock) -> bool:
    """Nothing arrives on ``sock`` within its timeout."""
    try:
        sock.recvfrom(65536)
    except socket.timeout:
        return True
    return False


def _traction_session(product_fmus, quiet=False):
    from orchestrator.fmu import read_interface

    fmu = product_fmus / "Traction.fmu"
    desc = dcpx.description_from_fmu(read_interface(fmu))
    proc, address = start_slave(fmu, quiet=quiet)
    master = TestMaster(address)
    master.register(desc.uuid)
    names = ("command", "emergency_brake", "v", "force_brake")
    command, brake, v, force_brake = (desc.by_name(n) for n in names)
    # the FMU's own step (1/2 s) is the description's first resolution: one tick per step
    master.configure([(command.vr, DataType.float64), (brake.vr, DataType.uint8)],
                     [(v.vr, None), (force_brake.vr, None)], 1, resolution=(1, 2))
    _run_to_running(master)
    return proc, master


def _traction_reference(product_fmus, inputs):
    """Traction stepped directly through FMI by its own step: (v, force_brake) after each step."""
    from orchestrator.fmu import make_slave, new_workdir, read_interface, remove_workdir

    fmu = product_fmus / "Traction.fmu"
    interface = read_interface(fmu)
    workdir = new_workdir()
    slave = make_slave("reference", fmu, interface, workdir, in_process=False)
    vr = {n: interface.variables[n].vr for n in ("command", "emergency_brake", "v", "force_brake")}
    try:
        slave.instantiate()
        slave.bind({"Real": [vr["command"]], "Boolean": [vr["emergency_brake"]]},
                   {"Real": [vr["v"], vr["force_brake"]]})
        slave.setup_experiment(0.0, None)
        slave.enter_initialization()
        slave.write_inputs()
        slave.exit_initialization()
        trace = []
        for k, (command, brake) in enumerate(inputs):
            slave.inputs["Real"].values[:] = [command]
            slave.inputs["Boolean"].values[:] = [brake]
            slave.write_inputs()
            slave.do_step(k * 0.5, 0.5)
            slave.read_outputs()
            trace.append(tuple(float(x) for x in slave.outputs["Real"].values))
        slave.terminate()
        return trace
    finally:
        slave.free()
        remove_workdir(workdir)


def test_an_intruders_datagrams_are_ignored_and_counted_and_the_masters_brake_applies(product_fmus):
    """A spoofed DAT far ahead in sequence, and control requests with the right sequence id,
    from a third socket: none answered or applied, each counted, and the master's emergency
    brake acts on the very next step."""
    proc, master = _traction_session(product_fmus)
    intruder = _intruder()
    inputs = PayloadCodec([(DataType.float64, 1), (DataType.uint8, 1)])
    outputs = PayloadCodec([(DataType.float64, 1), (DataType.float64, 1)])
    seq, trace = 0, []

    def step(command, brake):
        nonlocal seq
        master.send_inputs(seq, inputs.encode([[command], [brake]]))
        seq += 1
        _step(master, 1)
        master.wait_data(seq)
        v, force_brake = outputs.decode(master.data[-1].payload)
        trace.append((float(v[0]), float(force_brake[0])))

    try:
        for _ in range(4):
            step(1.0, 0)
        assert all(b > a for (a, _), (b, _) in zip(trace, trace[1:])) and trace[-1][1] == 0.0
        spoofed = Pdu(PduType.DAT_input_output, pdu_seq_id=(seq - 1 + 0x7FFF) & 0xFFFF, data_id=1,
                      payload=inputs.encode([[1.0], [0]]))
        intruder.sendto(spoofed.encode(), master.slave)
        for kind, state in ((PduType.INF_state, None), (PduType.STC_stop, State.RUNNING),
                            (PduType.STC_deregister, State.STOPPED)):
            fields = {} if state is None else {"state_id": state}
            intruder.sendto(Pdu(kind, pdu_seq_id=master.seq, receiver=master.slave_id, **fields).encode(),
                            master.slave)
            assert _silent(intruder), kind.name           # no answer, not even a NACK naming the next id
        braking_from = len(trace)
        for _ in range(4):
            step(-1.0, 1)
        # the master's inputs apply on the very next step: traction off at once, so the train
        # slows from that step on (the pneumatic brake's force follows with its own delay)
        assert all(b[0] < a[0] for a, b in zip(trace[braking_from - 1:], trace[braking_from:]))
        assert master.inf_state() == State.RUNNING          # the intruder's STC_stop did nothing
        master.stc(PduType.STC_stop, State.RUNNING, State.STOPPED)
        master.stc(PduType.STC_deregister, State.STOPPED, State.ALIVE)
        assert proc.wait(timeout=30) == 0
        err = proc.stderr.read()
    finally:
        intruder.close()
        _end(proc, master)
    # exactly the FMU given the master's inputs alone
    assert trace == _traction_reference(product_fmus, [(1.0, False)] * 4 + [(-1.0, True)] * 4)
    assert "ignored from other addresses 4 (1 addresses)" in err
    assert "stale 0, outside the window 0" in err
    assert err.count("ignored a datagram from 127.0.0.1:") == 1 and "obeys no one else" in err


def _wire(test_fmus, quiet=True, *extra):
    """The slave serving TestFrameStage (alpha 0: its output frame is the input frame applied)."""
    from orchestrator.fmu import read_interface

    fmu = test_fmus / "TestFrameStage.fmu"
    desc = dcpx.description_from_fmu(read_interface(fmu))
    proc, address = start_slave(fmu, *extra, quiet=quiet)
    return proc, TestMaster(address), desc


def test_a_second_master_can_neither_query_nor_stop_nor_deregister_the_session(test_fmus):
    proc, master, desc = _wire(test_fmus)
    second = TestMaster(master.slave, timeout_s=0.3)
    try:
        master.register(desc.uuid)
        for seq in (0, 1, master.seq, 0xFFFF):       # any id, the right one included: no NACK naming it
            second.send_raw(Pdu(PduType.INF_state, pdu_seq_id=seq, receiver=1).encode())
            assert _silent(second.sock)
        second.send_raw(Pdu(PduType.STC_register, pdu_seq_id=0, receiver=1, state_id=State.ALIVE,
                            slave_uuid=desc.uuid, op_mode=OpMode.NRT).encode())
        second.send_raw(Pdu(PduType.STC_deregister, pdu_seq_id=master.seq, receiver=1,
                            state_id=State.CONFIGURATION).encode())
        assert _silent(second.sock)
        assert master.inf_state() == State.CONFIGURATION   # its own id, unused by the second master
        assert proc.poll() is None
    finally:
        second.close()
        _end(proc, master)


def test_inputs_are_received_and_outputs_sent_only_where_the_slave_and_its_master_are(test_fmus):
    proc, master, desc = _wire(test_fmus)
    slave_host, slave_port = master.slave

    def network(kind, ip, port):
        return master.request(lambda s: Pdu(kind, pdu_seq_id=s, receiver=1, data_id=1, port=port, ip_address=ip),
                              expect_ack=False)

    try:
        master.register(desc.uuid)
        source, target = PduType.CFG_source_network_information, PduType.CFG_target_network_information
        for kind, ip in ((source, "127.0.0.2"), (source, "10.1.2.3"), (target, "127.0.0.2"), (target, "10.1.2.3"),
                         (target, "0.0.0.0")):
            rsp = network(kind, ip, 40000)
            assert rsp.type_id == PduType.RSP_nack and rsp.error_code == ErrorCode.INVALID_NETWORK_INFORMATION, ip
        for kind, ip, port in ((source, "0.0.0.0", slave_port), (source, slave_host, slave_port),
                               (target, "127.0.0.1", 40000), (target, slave_host, slave_port)):
            assert network(kind, ip, port).type_id == PduType.RSP_ack, (kind.name, ip)
    finally:
        _end(proc, master)


def test_dat_sequence_ids_are_judged_modulo_2_16_within_a_window(test_fmus):
    """1 … 1024 ahead: applied; 0 … 16 behind: stale; farther: applied only when the next
    datagram follows it (the stream really jumped), so a single far one changes nothing, and
    one injected ahead within the window costs the real stream one datagram, not 1024."""
    proc, master, desc = _wire(test_fmus, quiet=False)
    codec = PayloadCodec([(DataType.float64, 4)])
    seen = []

    def exchange(seq, value):
        master.send_inputs(seq, codec.encode([[value] * 4]))
        _step(master, 1)
        master.wait_data(len(seen) + 1)
        seen.append(float(codec.decode(master.data[-1].payload)[0][0]))

    try:
        master.register(desc.uuid)
        master.configure([(desc.by_name("u").vr, DataType.float64)], [(desc.by_name("y").vr, None)], 1,
                         resolution=(1, 1000))
        _run_to_running(master)
        for seq, value in ((0xFFF0, 1.0),          # any first id
                           (0xFFF0 + 0x7FFF, 2.0),  # one datagram half the id space ahead: not taken
                           (0xFFF1, 3.0),           # the stream goes on, not stale
                           (0xFFF1 + 1025, 4.0),    # beyond the window: held
                           (0xFFF1 + 1026, 5.0),    # the next follows it: the stream jumped
                           (0xFFF1 + 1026 + 1024, 6.0),    # the window's edge, across the wrap
                           (0xFFF1 + 1026, 7.0),    # 1024 behind: held as a jump, not taken
                           (0xFFF1 + 1026 + 1021, 7.5),    # 3 behind: stale
                           (0xFFF1 + 1026 + 2048, 8.0),    # injected 1024 ahead: taken …
                           (0xFFF1 + 1026 + 1025, 9.0),    # … the real stream's next is held …
                           (0xFFF1 + 1026 + 1026, 10.0)):  # … and the one after it taken again
            exchange(seq & 0xFFFF, value)
        master.stc(PduType.STC_stop, State.RUNNING, State.STOPPED)
        master.stc(PduType.STC_deregister, State.STOPPED, State.ALIVE)
        assert proc.wait(timeout=30) == 0
        err = proc.stderr.read()
    finally:
        _end(proc, master)
    assert seen == [1.0, 1.0, 3.0, 3.0, 5.0, 6.0, 6.0, 6.0, 8.0, 8.0, 10.0]
    assert "DAT in 6 (missing 3070, stale 1, outside the window 4, rejected 0)" in err


def test_steps_times_and_resolutions_are_bounded_or_refused_with_the_standards_codes(test_fmus):
    """Non-real-time: one STC_do_step of at most 1000 FMU steps (2³²−1 ticks refused at once).
    Soft real time: output periods of whole FMU steps, a start time at most an hour ahead."""
    proc, master, desc = _wire(test_fmus)
    try:
        master.register(desc.uuid)
        master.configure([], [(desc.by_name("y").vr, None)], STEP_NS)        # 1 ns resolution
        _run_to_running(master)
        for steps in (2 ** 32 - 1, 1001 * STEP_NS):
            rsp = master.request(lambda s: Pdu(PduType.STC_do_step, pdu_seq_id=s, receiver=1,
                                               state_id=State.RUNNING, steps=steps), expect_ack=False)
            assert rsp.error_code == ErrorCode.INVALID_STEPS, steps
        _step(master, 1000 * STEP_NS)                  # 1000 FMU steps: taken
        assert master.inf_state() == State.RUNNING
    finally:
        _end(proc, master)

    from orchestrator.fmu import read_interface

    source = test_fmus / "TestFrameSource.fmu"
    desc = dcpx.description_from_fmu(read_interface(source))
    y = desc.by_name("y").vr
    proc, address = start_slave(source, "--real-time")
    master = TestMaster(address)

    def time_res(num, den):
        return lambda s: Pdu(PduType.CFG_time_res, pdu_seq_id=s, receiver=1, numerator=num, denominator=den)

    def steps_of(steps):
        return lambda s: Pdu(PduType.CFG_steps, pdu_seq_id=s, receiver=1, data_id=2, steps=steps)

    try:
        master.register(desc.uuid, OpMode.SRT)
        master.request(lambda s: Pdu(PduType.CFG_output, pdu_seq_id=s, receiver=1, data_id=2, pos=0, source_vr=y))
        master.request(steps_of(1))                     # DCPLib's example master: steps before the resolution
        rsp = master.request(time_res(1, 1_000_000_000), expect_ack=False)
        assert rsp.error_code == ErrorCode.INVALID_TIME_RESOLUTION     # an output every 1 ns in real time
        master.request(time_res(1, 1000))               # the FMU's own step: one tick per step
        master.request(steps_of(1000))                  # 1000 FMU steps
        master.request(time_res(1, 1_000_000))          # the same 1 s: 1000 FMU steps
        for steps in (1, 1500):                         # 1 µs, 1.5 ms: no whole number of FMU steps
            assert master.request(steps_of(steps), expect_ack=False).error_code == ErrorCode.INVALID_STEPS
        master.configure([], [(y, None)], 2000, resolution=(1, 1_000_000))
        now = int(time.time())
        for start_time in (2 ** 63 - 1, now + 3600 + 120, now - 120):
            rsp = master.request(lambda s: Pdu(PduType.STC_run, pdu_seq_id=s, receiver=1, state_id=State.CONFIGURED,
                                               start_time=start_time), expect_ack=False)
            assert rsp.error_code == ErrorCode.INVALID_START_TIME, start_time
        assert master.inf_state() == State.CONFIGURED and proc.poll() is None
        master.request(lambda s: Pdu(PduType.STC_run, pdu_seq_id=s, receiver=1, state_id=State.CONFIGURED,
                                     start_time=0))
        master.wait_state(State.SYNCHRONIZED)
        master.wait_data(3)
    finally:
        _end(proc, master)


def test_an_empty_host_is_refused_and_a_non_loopback_one_warned(test_fmus):
    empty = _cli(str(test_fmus / "TestGain.fmu"), "--host", "")
    assert empty.returncode == 2 and empty.stderr.count("\n") == 1 and "--host ''" in empty.stderr
    from orchestrator.dcp.slave import exposure_warning

    # the warning's text (the tests bind loopback only: 0.0.0.0 itself is not bound here)
    for host in ("0.0.0.0", "192.168.1.20"):
        line = exposure_warning(host, 5000)
        assert line.startswith(f"warning: the control port {host}:5000 is open") and "\n" not in line
    assert exposure_warning("127.0.0.1", 5000) is None and exposure_warning("127.0.0.2", 5000) is None


def _stderr_lines(proc):
    """The slave's stderr lines as they come, read in a thread."""
    import queue
    import threading

    lines = queue.Queue()
    threading.Thread(target=lambda: [lines.put(line) for line in proc.stderr], daemon=True).start()
    return lines


def _next_line(lines, containing, timeout_s=10.0):
    import queue

    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        try:
            line = lines.get(timeout=max(0.01, end - time.monotonic()))
        except queue.Empty:
            break
        if containing in line:
            return line
    raise AssertionError(f"no stderr line with {containing!r} within {timeout_s} s")


def test_overruns_are_reported_as_they_happen_and_a_session_that_cannot_keep_up_stops(test_fmus):
    """TestSine (10 ms step) in soft real time; the slave's process is held (SIGSTOP) once for
    0.3 s: overruns reported at once, the session goes on; then held 150 ms of every 152 ms: every
    step late or nearly every one (the host decides how soon a held process catches up), and
    within a 2 s window of 90 % overruns the session stops in ERROR with one line saying why."""
    from orchestrator.fmu import read_interface

    fmu = test_fmus / "TestSine.fmu"
    desc = dcpx.description_from_fmu(read_interface(fmu))
    proc, address = start_slave(fmu, "--real-time")       # --quiet: warnings are printed all the same
    master = TestMaster(address)
    sink = _intruder()                                    # where the outputs go: never read
    lines = _stderr_lines(proc)
    try:
        master.register(desc.uuid, OpMode.SRT)
        master.configure([], [(desc.by_name("y").vr, None)], 1, resolution=(1, 100), target=sink.getsockname())
        master.request(lambda s: Pdu(PduType.STC_run, pdu_seq_id=s, receiver=1, state_id=State.CONFIGURED,
                                     start_time=0))
        master.wait_state(State.SYNCHRONIZED)
        time.sleep(0.2)
        proc.send_signal(signal.SIGSTOP)
        time.sleep(0.3)
        proc.send_signal(signal.SIGCONT)
        assert "ms late (period 10 ms)" in _next_line(lines, "overrun: real-time step")
        assert master.inf_state() == State.SYNCHRONIZED        # a stall caught up: the session goes on
        said, end = [], time.monotonic() + 20.0      # a loaded machine gives the slave fewer steps per cycle
        while time.monotonic() < end and not any("real time not kept" in line for line in said):
            proc.send_signal(signal.SIGSTOP)            # 15 steps due in each cycle, a few taken
            time.sleep(0.15)
            proc.send_signal(signal.SIGCONT)
            time.sleep(0.002)
            while not lines.empty():
                said.append(lines.get())
        line = next((line for line in said if "real time not kept" in line), f"no stop line in {said}")
        assert "the FMU cannot be stepped at this period in real time" in line and "10 ms" in line
        master.wait_state(State.ERROR_RESOLVED)
        rsp = master.request(lambda s: Pdu(PduType.INF_error, pdu_seq_id=s, receiver=1), expect_ack=False)
        assert rsp.error_code == ErrorCode.PROTOCOL_ERROR_GENERIC
    finally:
        if proc.poll() is None:
            proc.send_signal(signal.SIGCONT)
        sink.close()
        _end(proc, master)


def test_dcplib_example_masters_choices_step_the_fmu_by_its_own_step(product_fmus):
    """What DCPLib's example master does (docs/hil.md#tested-against), against the slave serving
    Traction: soft real time, the FIRST time resolution the description offers, CFG_steps 1,
    its output sent to the slave's own control port and taken there as its input, STC_run a
    second ahead. The first resolution is the FMU's own 0.5 s step, so the FMU is stepped every
    0.5 s with no overrun."""
    from orchestrator.fmu import read_interface

    fmu = product_fmus / "Traction.fmu"
    desc = dcpx.description_from_fmu(read_interface(fmu), real_time=False)
    assert desc.resolutions[0] == (1, 2, False, True)              # the FMU's step, recommended
    assert [r for r in desc.resolutions if r[3]] == [desc.resolutions[0]]
    proc, address = start_slave(fmu, "--real-time", quiet=False)
    master = TestMaster(address)
    try:
        master.register(desc.uuid, OpMode.SRT)
        num, den = desc.resolutions[0][:2]
        v, command = desc.by_name("v").vr, desc.by_name("command").vr
        sid = 1
        for make in (lambda s: Pdu(PduType.CFG_scope, pdu_seq_id=s, receiver=sid, data_id=1, scope=0),
                     lambda s: Pdu(PduType.CFG_input, pdu_seq_id=s, receiver=sid, data_id=1, pos=0, target_vr=command,
                                   source_data_type=DataType.float64),
                     lambda s: Pdu(PduType.CFG_output, pdu_seq_id=s, receiver=sid, data_id=1, pos=0, source_vr=v),
                     lambda s: Pdu(PduType.CFG_steps, pdu_seq_id=s, receiver=sid, data_id=1, steps=1),
                     lambda s: Pdu(PduType.CFG_time_res, pdu_seq_id=s, receiver=sid, numerator=num, denominator=den),
                     lambda s: Pdu(PduType.CFG_source_network_information, pdu_seq_id=s, receiver=sid, data_id=1,
                                   port=address[1], ip_address=address[0]),
                     lambda s: Pdu(PduType.CFG_target_network_information, pdu_seq_id=s, receiver=sid, data_id=1,
                                   port=address[1], ip_address=address[0])):
            master.request(make)
        master.stc(PduType.STC_prepare, State.CONFIGURATION, State.PREPARED)
        master.stc(PduType.STC_configure, State.PREPARED, State.CONFIGURED)
        master.request(lambda s: Pdu(PduType.STC_run, pdu_seq_id=s, receiver=sid, state_id=State.CONFIGURED,
                                     start_time=int(time.time()) + 1))
        master.wait_state(State.SYNCHRONIZED)
        master.request(lambda s: Pdu(PduType.STC_run, pdu_seq_id=s, receiver=sid, state_id=State.SYNCHRONIZED,
                                     start_time=0))
        master.wait_state(State.RUNNING)
        running_at = time.monotonic()
        time.sleep(2.2)
        master.stc(PduType.STC_stop, State.RUNNING, State.STOPPED)
        stopped_at = time.monotonic()
        master.stc(PduType.STC_deregister, State.STOPPED, State.ALIVE)
        assert proc.wait(timeout=30) == 0
        err = proc.stderr.read()
    finally:
        _end(proc, master)
    summary = err.strip().splitlines()[-1]
    steps = int(summary.split("railcosim dcp-slave: ")[1].split(" steps")[0])
    # 0.5 s steps, not 1 ns ones: at least those of the 2.2 s running, at most those of the time
    # since synchronising began (up to 1 s before RUNNING) and the stop's round trip on a loaded host
    assert 4 <= steps <= (stopped_at - running_at + 1.0) / 0.5 + 2
    assert f"DAT in {steps - 1} " in summary or f"DAT in {steps} " in summary      # its own outputs, looped back
    assert "ignored from other addresses 0" in summary and "overruns 0 " in summary


def test_a_slave_serving_every_interface_takes_as_its_own_only_senders_of_this_machine():
    """Its outputs looped back to its inputs come from one of its ports on an address of this
    machine; another host sending from the same port number is foreign, not the slave."""
    import types

    from orchestrator.dcp.slave_data import DataExchange

    data_socket = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    data_socket.bind(("127.0.0.1", 0))
    try:
        port = data_socket.getsockname()[1]
        for host in ("0.0.0.0", "127.0.0.1"):
            slave = types.SimpleNamespace(port=port + 1, data_sockets={1: data_socket}, host=host,
                                          _local_addresses={})
            assert DataExchange.is_own(slave, ("127.0.0.1", port))
            assert not DataExchange.is_own(slave, ("203.0.113.9", port))     # a remote host, same port
            assert not DataExchange.is_own(slave, ("127.0.0.1", port + 2))   # not one of its ports
    finally:
        data_socket.close()

"""DCP 1.0 protocol layer: PDU layouts and sizes as the standard gives them, round trips,
malformed datagrams, payloads, the slave state machine, and .dcpx descriptions."""
import struct
import uuid

import numpy as np
import pytest

from orchestrator.dcp import dcpx, states
from orchestrator.dcp.pdu import (DataType, ErrorCode, OpMode, PayloadCodec, PduError, PduType, Scope, State, decode, next_seq, Pdu)
from orchestrator.errors import UserError

UID = uuid.UUID("b5279485-720d-4542-9f29-bee4d9a75ef9")

# (pdu, its length in bytes per the standard)
SAMPLES = [
    (Pdu(PduType.STC_register, pdu_seq_id=7, receiver=3, state_id=State.ALIVE, slave_uuid=UID, op_mode=OpMode.NRT, major_version=1, minor_version=0), 24),
    (Pdu(PduType.STC_prepare, pdu_seq_id=8, receiver=3, state_id=State.CONFIGURATION), 5),
    (Pdu(PduType.STC_deregister, pdu_seq_id=9, receiver=3, state_id=State.STOPPED), 5),
    (Pdu(PduType.STC_run, pdu_seq_id=10, receiver=3, state_id=State.CONFIGURED, start_time=1_700_000_000), 13),
    (Pdu(PduType.STC_do_step, pdu_seq_id=11, receiver=3, state_id=State.RUNNING, steps=10_000_000), 9),
    (Pdu(PduType.CFG_time_res, pdu_seq_id=12, receiver=3, numerator=1, denominator=1_000_000_000), 12),
    (Pdu(PduType.CFG_steps, pdu_seq_id=13, receiver=3, steps=10_000_000, data_id=2), 10),
    (Pdu(PduType.CFG_input, pdu_seq_id=14, receiver=3, data_id=1, pos=0, target_vr=2**40 + 5, source_data_type=DataType.float64), 17),
    (Pdu(PduType.CFG_output, pdu_seq_id=15, receiver=3, data_id=2, pos=4, source_vr=99), 16),
    (Pdu(PduType.CFG_clear, pdu_seq_id=16, receiver=3), 4),
    (Pdu(PduType.INF_state, pdu_seq_id=17, receiver=3), 4),
    (Pdu(PduType.INF_error, pdu_seq_id=18, receiver=3), 4),
    (Pdu(PduType.CFG_source_network_information, pdu_seq_id=19, receiver=3, data_id=1, port=5001, ip_address="127.0.0.1"), 13),
    (Pdu(PduType.CFG_target_network_information, pdu_seq_id=20, receiver=3, data_id=2, port=6001, ip_address="192.168.1.20"), 13),
    (Pdu(PduType.CFG_parameter, pdu_seq_id=21, receiver=3, parameter_vr=4, source_data_type=DataType.float64, configuration=struct.pack("<d", 2.5)), 21),
    (Pdu(PduType.CFG_scope, pdu_seq_id=22, receiver=3, data_id=1, scope=Scope.Run_NonRealTime), 7),
    (Pdu(PduType.RSP_ack, sender=3, resp_seq_id=7), 4),
    (Pdu(PduType.RSP_nack, sender=3, resp_seq_id=7, exp_seq_id=8, error_code=ErrorCode.INVALID_SEQUENCE_ID), 8),
    (Pdu(PduType.RSP_state_ack, sender=3, resp_seq_id=17, state_id=State.RUNNING), 5),
    (Pdu(PduType.RSP_error_ack, sender=3, resp_seq_id=18, error_code=ErrorCode.INVALID_LENGTH), 6),
    (Pdu(PduType.NTF_state_changed, sender=3, state_id=State.COMPUTED), 3),
    (Pdu(PduType.DAT_input_output, pdu_seq_id=5, data_id=1, payload=b"\x01\x02\x03"), 8),
]


@pytest.mark.parametrize("pdu,size", SAMPLES, ids=[type(p).__name__ + "_" + p.type_id.name for p, _ in SAMPLES])
def test_round_trip_and_standard_length(pdu, size):
    data = pdu.encode()
    assert len(data) == size
    assert data[0] == pdu.type_id
    assert decode(data) == pdu


def test_register_layout_is_little_endian_field_by_field():
    data = Pdu(PduType.STC_register, pdu_seq_id=0x0102, receiver=3, state_id=State.ALIVE, slave_uuid=UID, op_mode=OpMode.SRT, major_version=1, minor_version=0).encode()
    assert data[:5] == bytes([0x01, 0x02, 0x01, 3, 0x00])        # type, seq LE, receiver, state
    assert data[5:21] == UID.bytes                                # uuid in written byte order
    assert data[21:] == bytes([1, 1, 0])                          # op_mode SRT, version 1.0


def test_network_information_ip_is_uint32_of_the_address():
    data = Pdu(PduType.CFG_target_network_information, pdu_seq_id=1, receiver=2, data_id=3, port=0x1389, ip_address="127.0.0.1").encode()
    assert data[6] == 0                                           # UDP_IPv4
    assert data[7:9] == b"\x89\x13"
    assert data[9:13] == bytes([1, 0, 0, 127])                    # 0x7F000001 little-endian


def test_responses_mirror_the_request_header_and_dat_layout():
    """RSP_: type_id, resp_seq_id (uint16) where the request had its pdu_seq_id, sender where
    it had its receiver (DCPLib's layout since its 2019 fix of the RSP offsets)."""
    assert Pdu(PduType.RSP_nack, sender=4, resp_seq_id=0x0A0B, exp_seq_id=0x0A0C,
               error_code=ErrorCode.INVALID_LENGTH).encode() == bytes([0xB1, 0x0B, 0x0A, 4, 0x0C, 0x0A, 0x01, 0x20])
    assert Pdu(PduType.RSP_ack, sender=1, resp_seq_id=0).encode() == bytes([0xB0, 0, 0, 1])
    assert Pdu(PduType.RSP_state_ack, sender=1, resp_seq_id=9, state_id=State.ALIVE).encode() == bytes(
        [0xB2, 9, 0, 1, 0])
    assert Pdu(PduType.RSP_error_ack, sender=2, resp_seq_id=0x0102, error_code=ErrorCode.INVALID_STEPS).encode() == \
        bytes([0xB3, 0x02, 0x01, 2, 0x0E, 0x20])
    assert Pdu(PduType.DAT_input_output, pdu_seq_id=0x0201, data_id=0x0403, payload=b"xy").encode() == bytes([0xF0, 1, 2, 3, 4]) + b"xy"


def test_truncated_oversized_and_unknown_pdus_raise_with_header():
    good = Pdu(PduType.STC_do_step, pdu_seq_id=300, receiver=5, state_id=State.RUNNING, steps=1).encode()
    with pytest.raises(PduError) as info:
        decode(good[:-1])
    assert info.value.error_code == ErrorCode.INVALID_LENGTH
    assert (info.value.type_id, info.value.pdu_seq_id, info.value.receiver) == (PduType.STC_do_step, 300, 5)
    with pytest.raises(PduError) as info:
        decode(good + b"\x00")
    assert info.value.error_code == ErrorCode.INVALID_LENGTH
    with pytest.raises(PduError) as info:
        decode(b"\x55\x00\x00\x00")
    assert info.value.error_code == ErrorCode.NOT_SUPPORTED_PDU
    with pytest.raises(PduError):
        decode(b"")
    with pytest.raises(PduError) as info:
        decode(b"\x07\x01")                                       # header cut short
    assert info.value.pdu_seq_id is None
    with pytest.raises(PduError) as info:                         # op_mode 9 is not defined
        decode(good[:0] + Pdu(PduType.STC_register, pdu_seq_id=1, receiver=1, state_id=State.ALIVE, slave_uuid=UID, op_mode=OpMode.NRT).encode()[:21] + b"\x09\x01\x00")
    assert info.value.error_code == ErrorCode.INVALID_OP_MODE


def test_sequence_ids_wrap():
    assert next_seq(5) == 6 and next_seq(0xFFFF) == 0


def test_payload_codec_numeric_and_strings():
    codec = PayloadCodec([(DataType.float64, 3), (DataType.uint8, 1), (DataType.int32, 2)])
    payload = codec.encode([[1.5, -2.0, 3.25], 1, [-7, 9]])
    assert len(payload) == 3 * 8 + 1 + 2 * 4 == codec.size
    a, b, c = codec.decode(payload)
    assert a.tolist() == [1.5, -2.0, 3.25] and b.tolist() == [1] and c.tolist() == [-7, 9]
    with pytest.raises(PduError):
        codec.decode(payload[:-1])
    mixed = PayloadCodec([(DataType.string, 1), (DataType.float64, 1), (DataType.binary, 1)])
    payload = mixed.encode(["ALS-EN", 4.0, b"\x00\xff"])
    assert payload[:4] == struct.pack("<I", 6)
    assert mixed.decode(payload)[0] == "ALS-EN" and mixed.decode(payload)[2] == b"\x00\xff"
    with pytest.raises(PduError):
        mixed.decode(payload + b"\x00")
    nan = PayloadCodec([(DataType.float64, 1)]).decode(struct.pack("<d", float("nan")))[0]
    assert np.isnan(nan[0])


def test_state_machine_follows_the_standard():
    assert states.enters(State.ALIVE, PduType.STC_register) == State.CONFIGURATION
    assert states.enters(State.CONFIGURED, PduType.STC_run) == State.SYNCHRONIZING
    assert states.enters(State.SYNCHRONIZED, PduType.STC_run) == State.RUNNING
    assert states.enters(State.RUNNING, PduType.STC_do_step) == State.COMPUTING
    assert states.enters(State.COMPUTED, PduType.STC_send_outputs) == State.SENDING_D
    assert states.enters(State.STOPPED, PduType.STC_deregister) == State.ALIVE
    assert not states.allowed(State.ALIVE, PduType.STC_do_step)
    assert not states.allowed(State.RUNNING, PduType.CFG_input)      # configuration is over
    assert not states.allowed(State.CONFIGURATION, PduType.DAT_input_output)
    assert states.allowed(State.ERROR_RESOLVED, PduType.INF_error)
    for state in State:                                               # every state has its row
        assert states.allowed(state, PduType.INF_state)


# the standard's example description (as in its reference implementation's example), by hand
EXAMPLE = """<?xml version="1.0" encoding="UTF-8"?>
<dcpSlaveDescription dcpMajorVersion="1" dcpMinorVersion="0" dcpSlaveName="dcpslave"
    uuid="b5279485-720d-4542-9f29-bee4d9a75ef9">
  <OpMode><SoftRealTime/><NonRealTime defaultSteps="1" fixedSteps="true"/></OpMode>
  <TimeRes><Resolution numerator="1" denominator="100" fixed="true" recommended="true"/></TimeRes>
  <TransportProtocols>
    <UDP_IPv4>
      <Control host="127.0.0.1" port="8080"/>
      <DAT_input_output host="127.0.0.1"><AvailablePortRange from="2048" to="65535"/></DAT_input_output>
    </UDP_IPv4>
  </TransportProtocols>
  <CapabilityFlags canAcceptConfigPdus="true" canHandleReset="true" canHandleVariableSteps="true"/>
  <Variables>
    <Variable name="y" valueReference="1"><Output><Float64 start="10.0"/></Output></Variable>
    <Variable name="a" valueReference="2"><Input><Float64 start="0"/></Input></Variable>
  </Variables>
</dcpSlaveDescription>
"""


def test_reads_the_standards_example(tmp_path):
    path = tmp_path / "example.dcpx"
    path.write_text(EXAMPLE)
    desc = dcpx.read_dcpx(path)
    assert desc.uuid == UID and desc.op_modes == (OpMode.SRT, OpMode.NRT)
    assert desc.supports_time_resolution(1, 100) and not desc.supports_time_resolution(1, 1000)
    assert desc.supports_dat_port(5000) and not desc.supports_dat_port(80)
    assert [(v.name, v.vr, v.causality, v.data_type) for v in desc.variables] == [
        ("y", 1, "output", DataType.float64), ("a", 2, "input", DataType.float64)]
    again = tmp_path / "again.dcpx"
    dcpx.write_dcpx(desc, again)
    assert dcpx.read_dcpx(again) == desc


def test_invalid_description_is_one_line_naming_the_file(tmp_path):
    path = tmp_path / "bad.dcpx"
    path.write_text(EXAMPLE.replace('valueReference="2"', 'valueReference="x"'))
    with pytest.raises(UserError, match=r"bad\.dcpx: not a valid DCP 1\.0 slave description \(line"):
        dcpx.read_dcpx(path)
    path.write_text("<dcpSlaveDescription")
    with pytest.raises(UserError, match="not an XML file"):
        dcpx.read_dcpx(path)
    with pytest.raises(UserError, match="not found"):
        dcpx.read_dcpx(tmp_path / "missing.dcpx")


def test_description_from_fmu_groups_arrays(test_fmus, tmp_path):
    from orchestrator.fmu import read_interface

    interface = read_interface(test_fmus / "TestFrameSource.fmu")
    desc = dcpx.description_from_fmu(interface, "127.0.0.1", 5000)
    frames = [v for v in desc.variables if v.dims]
    assert frames, "a frame port becomes a DCP array"
    for var in frames:
        assert len(var.fmi_names) == var.count
        assert var.vr == interface.variables[var.fmi_names[0]].vr
    path = tmp_path / "source.dcpx"
    dcpx.write_dcpx(desc, path)
    back = dcpx.read_dcpx(path)
    assert [(v.name, v.dims, v.data_type) for v in back.variables] == [
        (v.name, v.dims, v.data_type) for v in desc.variables]
    assert back.uuid == dcpx.slave_uuid(interface.guid)


def test_slave_engine_survives_mutated_requests(test_fmus):
    """Thousands of mutated PDUs with the right receiver and sequence id (so that they reach
    the checks behind those) at a running slave: every one handled without an exception."""
    from orchestrator.dcp.slave import DcpSlaveServer
    from orchestrator.fmu import make_slave, new_workdir, read_interface, remove_workdir

    fmu = test_fmus / "TestFrameStage.fmu"
    interface = read_interface(fmu)
    desc = dcpx.description_from_fmu(interface, "127.0.0.1", 1)

    class Socket:
        sent = []

        def getsockname(self):
            return ("127.0.0.1", 1)

        def sendto(self, data, address):
            self.sent.append(decode(data))      # whatever the slave sends is a valid PDU

    workdir = new_workdir()
    logged = []
    slave = DcpSlaveServer(desc, lambda: make_slave("s", fmu, interface, workdir, False), Socket(), log=logged.append)
    slave.load_fmu()
    master = ("127.0.0.1", 2)
    seq = [0]

    def send(pdu):
        slave.handle(pdu.encode(), master)
        seq[0] = slave.expected_seq

    u, y = desc.by_name("u"), desc.by_name("y")
    send(Pdu(PduType.STC_register, pdu_seq_id=0, receiver=1, state_id=State.ALIVE, slave_uuid=desc.uuid, op_mode=OpMode.NRT))
    for make in (lambda s: Pdu(PduType.CFG_time_res, pdu_seq_id=s, receiver=1, numerator=1, denominator=10**9), lambda s: Pdu(PduType.CFG_input, pdu_seq_id=s, receiver=1, data_id=1, pos=0, target_vr=u.vr, source_data_type=DataType.float64),
                 lambda s: Pdu(PduType.CFG_output, pdu_seq_id=s, receiver=1, data_id=2, pos=0, source_vr=y.vr), lambda s: Pdu(PduType.CFG_steps, pdu_seq_id=s, receiver=1, steps=10**6, data_id=2),
                 lambda s: Pdu(PduType.CFG_source_network_information, pdu_seq_id=s, receiver=1, data_id=1, port=1, ip_address="127.0.0.1"),
                 lambda s: Pdu(PduType.CFG_target_network_information, pdu_seq_id=s, receiver=1, data_id=2, port=2, ip_address="127.0.0.1"),
                 lambda s: Pdu(PduType.STC_prepare, pdu_seq_id=s, receiver=1, state_id=State.CONFIGURATION),
                 lambda s: Pdu(PduType.STC_configure, pdu_seq_id=s, receiver=1, state_id=State.PREPARED),
                 lambda s: Pdu(PduType.STC_run, pdu_seq_id=s, receiver=1, state_id=State.CONFIGURED, start_time=0), lambda s: Pdu(PduType.STC_run, pdu_seq_id=s, receiver=1, state_id=State.SYNCHRONIZED, start_time=0)):
        send(make(seq[0]))
    assert slave.state == State.RUNNING and slave.counters.nacks == 0
    rng = np.random.default_rng(11)
    templates = [p for p, _ in SAMPLES if p.type_id != PduType.STC_deregister] + [
        Pdu(PduType.DAT_input_output, pdu_seq_id=0, data_id=1, payload=bytes(32)), Pdu(PduType.STC_do_step, pdu_seq_id=0, receiver=1, state_id=State.RUNNING, steps=10**6)]
    try:
        for _ in range(4000):
            data = bytearray(rng.choice(templates).encode())
            if len(data) >= 4 and data[0] < 0xB0 and data[0] != 0xF0:
                data[1:4] = struct.pack("<HB", seq[0], 1)
            cut = rng.integers(4)
            if cut == 0 and len(data) > 1:
                data = data[:rng.integers(1, len(data))]
            elif cut == 1:
                data += rng.bytes(int(rng.integers(1, 40)))
            for _ in range(int(rng.integers(0, 3))):
                k = int(rng.integers(4 if len(data) > 4 else 0, len(data)))
                data[k] = int(rng.integers(256))
            slave.handle(bytes(data), master)      # must not raise
            seq[0] = slave.expected_seq
        assert not [m for m in logged if m.startswith("internal error")], logged[:3]
        assert slave.counters.nacks > 100             # the mutations reached the checks
    finally:
        slave.shutdown()
        remove_workdir(workdir)

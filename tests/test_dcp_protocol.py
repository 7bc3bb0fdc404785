"""DCP 1.0 protocol layer: PDU layouts and sizes as the standard gives them, round trips,
malformed datagrams, payloads, the slave state machine, and .dcpx descriptions."""
import struct
import uuid

import numpy as np
import pytest

from orchestrator.dcp import dcpx, states
from orchestrator.dcp.pdu import (Basic, CfgInput, CfgNetworkInformation, CfgOutput, CfgParameter, CfgScope,
                                  CfgSteps, CfgTimeRes, DataType, DatInputOutput, ErrorCode, NtfStateChanged,
                                  OpMode, PayloadCodec, PduError, PduType, RspAck, RspErrorAck, RspNack,
                                  RspStateAck, Scope, State, Stc, StcDoStep, StcRegister, StcRun, decode,
                                  next_seq)
from orchestrator.errors import UserError

UID = uuid.UUID("b5279485-720d-4542-9f29-bee4d9a75ef9")

# (pdu, its length in bytes per the standard)
SAMPLES = [
    (StcRegister(7, 3, State.ALIVE, UID, OpMode.NRT, 1, 0), 24),
    (Stc(PduType.STC_prepare, 8, 3, State.CONFIGURATION), 5),
    (Stc(PduType.STC_deregister, 9, 3, State.STOPPED), 5),
    (StcRun(10, 3, State.CONFIGURED, 1_700_000_000), 13),
    (StcDoStep(11, 3, State.RUNNING, 10_000_000), 9),
    (CfgTimeRes(12, 3, 1, 1_000_000_000), 12),
    (CfgSteps(13, 3, 10_000_000, 2), 10),
    (CfgInput(14, 3, 1, 0, 2**40 + 5, DataType.float64), 17),
    (CfgOutput(15, 3, 2, 4, 99), 16),
    (Basic(PduType.CFG_clear, 16, 3), 4),
    (Basic(PduType.INF_state, 17, 3), 4),
    (Basic(PduType.INF_error, 18, 3), 4),
    (CfgNetworkInformation(PduType.CFG_source_network_information, 19, 3, 1, 5001, "127.0.0.1"), 13),
    (CfgNetworkInformation(PduType.CFG_target_network_information, 20, 3, 2, 6001, "192.168.1.20"), 13),
    (CfgParameter(21, 3, 4, DataType.float64, struct.pack("<d", 2.5)), 21),
    (CfgScope(22, 3, 1, Scope.Run_NonRealTime), 7),
    (RspAck(3, 7), 4),
    (RspNack(3, 7, 8, ErrorCode.INVALID_SEQUENCE_ID), 8),
    (RspStateAck(3, 17, State.RUNNING), 5),
    (RspErrorAck(3, 18, ErrorCode.INVALID_LENGTH), 6),
    (NtfStateChanged(3, State.COMPUTED), 3),
    (DatInputOutput(5, 1, b"\x01\x02\x03"), 8),
]


@pytest.mark.parametrize("pdu,size", SAMPLES, ids=[type(p).__name__ + "_" + p.type_id.name for p, _ in SAMPLES])
def test_round_trip_and_standard_length(pdu, size):
    data = pdu.encode()
    assert len(data) == size
    assert data[0] == pdu.type_id
    assert decode(data) == pdu


def test_register_layout_is_little_endian_field_by_field():
    data = StcRegister(0x0102, 3, State.ALIVE, UID, OpMode.SRT, 1, 0).encode()
    assert data[:5] == bytes([0x01, 0x02, 0x01, 3, 0x00])        # type, seq LE, receiver, state
    assert data[5:21] == UID.bytes                                # uuid in written byte order
    assert data[21:] == bytes([1, 1, 0])                          # op_mode SRT, version 1.0


def test_network_information_ip_is_uint32_of_the_address():
    data = CfgNetworkInformation(PduType.CFG_target_network_information, 1, 2, 3, 0x1389, "127.0.0.1").encode()
    assert data[6] == 0                                           # UDP_IPv4
    assert data[7:9] == b"\x89\x13"
    assert data[9:13] == bytes([1, 0, 0, 127])                    # 0x7F000001 little-endian


def test_nack_and_dat_layouts():
    assert RspNack(4, 0x0A0B, 0x0A0C, ErrorCode.INVALID_LENGTH).encode() == bytes(
        [0xB1, 4, 0x0B, 0x0A, 0x0C, 0x0A, 0x01, 0x20])
    assert DatInputOutput(0x0201, 0x0403, b"xy").encode() == bytes([0xF0, 1, 2, 3, 4]) + b"xy"


def test_truncated_oversized_and_unknown_pdus_raise_with_header():
    good = StcDoStep(300, 5, State.RUNNING, 1).encode()
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
        decode(good[:0] + StcRegister(1, 1, State.ALIVE, UID, OpMode.NRT).encode()[:21] + b"\x09\x01\x00")
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

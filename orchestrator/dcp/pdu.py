"""DCP 1.0 protocol data units: type ids, states, error codes, and every PDU we use as bytes.

Layouts are those of the DCP 1.0 standard (docs/hil.md#pdus): all fields little-endian, no
padding, one PDU per UDP datagram (the 4-byte length indicator exists only on stream
transports). Each PDU class has ``encode() -> bytes``; :func:`decode` parses a datagram and
raises :class:`PduError` with the standard's error code (``INVALID_LENGTH``,
``NOT_SUPPORTED_PDU``) and whatever of the header it could read, so a slave can answer with
RSP_nack instead of failing.

Payloads of DAT_input_output (and the configuration of CFG_parameter) are encoded by
:class:`PayloadCodec` from the variables' DCP data types and element counts.
"""
from __future__ import annotations

import ipaddress
import struct
import uuid as uuidlib
from dataclasses import dataclass, field
from enum import IntEnum
from typing import Dict, List, Optional, Sequence, Tuple, Type, Union

import numpy as np

DCP_MAJOR_VERSION, DCP_MINOR_VERSION = 1, 0
#: a UDP_IPv4 datagram's largest payload, the standard's default maxPduSize for UDP_IPv4
UDP_MAX_PDU_SIZE = 65507


class PduType(IntEnum):
    STC_register = 0x01
    STC_deregister = 0x02
    STC_prepare = 0x03
    STC_configure = 0x04
    STC_initialize = 0x05
    STC_run = 0x06
    STC_do_step = 0x07
    STC_send_outputs = 0x08
    STC_stop = 0x09
    STC_reset = 0x0A
    CFG_time_res = 0x20
    CFG_steps = 0x21
    CFG_input = 0x22
    CFG_output = 0x23
    CFG_clear = 0x24
    CFG_target_network_information = 0x25
    CFG_source_network_information = 0x26
    CFG_parameter = 0x27
    CFG_tunable_parameter = 0x28
    CFG_param_network_information = 0x29
    CFG_logging = 0x2A
    CFG_scope = 0x2B
    INF_state = 0x80
    INF_error = 0x81
    INF_log = 0x82
    RSP_ack = 0xB0
    RSP_nack = 0xB1
    RSP_state_ack = 0xB2
    RSP_error_ack = 0xB3
    RSP_log_ack = 0xB4
    NTF_state_changed = 0xE0
    NTF_log = 0xE1
    DAT_input_output = 0xF0
    DAT_parameter = 0xF1


class State(IntEnum):
    ALIVE = 0x00
    CONFIGURATION = 0x01
    PREPARING = 0x02
    PREPARED = 0x03
    CONFIGURING = 0x04
    CONFIGURED = 0x05
    INITIALIZING = 0x06
    INITIALIZED = 0x07
    SENDING_I = 0x08
    SYNCHRONIZING = 0x09
    SYNCHRONIZED = 0x0A
    RUNNING = 0x0B
    COMPUTING = 0x0C
    COMPUTED = 0x0D
    SENDING_D = 0x0E
    STOPPING = 0x0F
    STOPPED = 0x10
    ERROR_HANDLING = 0x11
    ERROR_RESOLVED = 0x12


class ErrorCode(IntEnum):
    NONE = 0x0000
    PROTOCOL_ERROR_GENERIC = 0x1001
    PROTOCOL_ERROR_HEARTBEAT_MISSED = 0x1002
    PROTOCOL_ERROR_PDU_NOT_ALLOWED_IN_THIS_STATE = 0x1003
    PROTOCOL_ERROR_PROPERTY_VIOLATED = 0x1004
    PROTOCOL_ERROR_STATE_TRANSITION_IN_PROGRESS = 0x1005
    INVALID_LENGTH = 0x2001
    INVALID_LOG_CATEGORY = 0x2002
    INVALID_LOG_LEVEL = 0x2003
    INVALID_LOG_MODE = 0x2004
    INVALID_MAJOR_VERSION = 0x2005
    INVALID_MINOR_VERSION = 0x2006
    INVALID_NETWORK_INFORMATION = 0x2007
    INVALID_OP_MODE = 0x2008
    INVALID_PAYLOAD = 0x2009
    INVALID_SCOPE = 0x200A
    INVALID_SOURCE_DATA_TYPE = 0x200B
    INVALID_START_TIME = 0x200C
    INVALID_STATE_ID = 0x200D
    INVALID_STEPS = 0x200E
    INVALID_TIME_RESOLUTION = 0x200F
    INVALID_TRANSPORT_PROTOCOL = 0x2010
    INVALID_UUID = 0x2011
    INVALID_VALUE_REFERENCE = 0x2012
    INVALID_SEQUENCE_ID = 0x2013
    INCOMPLETE_CONFIG_GAP_INPUT_POS = 0x3001
    INCOMPLETE_CONFIG_GAP_OUTPUT_POS = 0x3002
    INCOMPLETE_CONFIG_GAP_TUNABLE_POS = 0x3003
    INCOMPLETE_CONFIG_NW_INFO_INPUT = 0x3004
    INCOMPLETE_CONFIG_NW_INFO_OUTPUT = 0x3005
    INCOMPLETE_CONFIG_NW_INFO_TUNABLE = 0x3006
    INCOMPLETE_CONFIG_SCOPE = 0x3007
    INCOMPLETE_CONFIG_STEPS = 0x3008
    INCOMPLETE_CONFIG_TIME_RESOLUTION = 0x3009
    INCOMPLETE_CONFIGURATION = 0x300A
    NOT_SUPPORTED_LOG_ON_NOTIFICATION = 0x4001
    NOT_SUPPORTED_LOG_ON_REQUEST = 0x4002
    NOT_SUPPORTED_VARIABLE_STEPS = 0x4003
    NOT_SUPPORTED_PDU = 0x4005
    NOT_SUPPORTED_PDU_SIZE = 0x4006


class OpMode(IntEnum):
    HRT = 0   # hard real time
    SRT = 1   # soft real time
    NRT = 2   # non real time: the master sends STC_do_step


class DataType(IntEnum):
    uint8 = 0
    uint16 = 1
    uint32 = 2
    uint64 = 3
    int8 = 4
    int16 = 5
    int32 = 6
    int64 = 7
    float32 = 8
    float64 = 9
    string = 10
    binary = 11


class TransportProtocol(IntEnum):
    UDP_IPv4 = 0
    rfcomm_Bluetooth = 1
    CAN_BASED = 2
    USB = 3
    TCP_IPv4 = 4


class Scope(IntEnum):
    Initialization_Run_NonRealTime = 0
    Initialization = 1
    Run_NonRealTime = 2


#: numpy dtype (little-endian) of each fixed-size DCP data type
NUMPY_DTYPES: Dict[DataType, np.dtype] = {
    DataType.uint8: np.dtype("<u1"), DataType.uint16: np.dtype("<u2"),
    DataType.uint32: np.dtype("<u4"), DataType.uint64: np.dtype("<u8"),
    DataType.int8: np.dtype("<i1"), DataType.int16: np.dtype("<i2"),
    DataType.int32: np.dtype("<i4"), DataType.int64: np.dtype("<i8"),
    DataType.float32: np.dtype("<f4"), DataType.float64: np.dtype("<f8"),
}
VARIABLE_LENGTH = frozenset({DataType.string, DataType.binary})


class PduError(ValueError):
    """A datagram that is not a valid PDU of the standard. ``type_id``, ``pdu_seq_id`` and
    ``receiver`` are what could be read of its header (None where it is too short)."""

    def __init__(self, error_code: ErrorCode, message: str, type_id: Optional[int] = None,
                 pdu_seq_id: Optional[int] = None, receiver: Optional[int] = None):
        super().__init__(message)
        self.error_code = error_code
        self.type_id = type_id
        self.pdu_seq_id = pdu_seq_id
        self.receiver = receiver


# ---- the PDUs ---------------------------------------------------------------------------------
# Each class lists its fields after type_id in wire order with a struct format; SIZE is the
# standard's fixed length (None for a PDU with a variable tail).

class Pdu:
    TYPES: Tuple[PduType, ...] = ()
    FORMAT = ""            # struct format of the fields after type_id
    FIELDS: Tuple[str, ...] = ()
    TAIL: Optional[str] = None   # name of a variable-length bytes field at the end
    type_id: PduType

    @classmethod
    def size(cls) -> int:
        return 1 + struct.calcsize("<" + cls.FORMAT)

    def _values(self) -> tuple:
        return tuple(_wire(getattr(self, name)) for name in self.FIELDS)

    def encode(self) -> bytes:
        head = struct.pack("<B" + self.FORMAT, int(self.type_id), *self._values())
        return head + bytes(getattr(self, self.TAIL)) if self.TAIL else head

    @classmethod
    def _decode(cls, data: bytes) -> "Pdu":
        fixed = cls.size()
        values = struct.unpack_from("<" + cls.FORMAT, data, 1)
        kwargs = {name: _unwire(cls, name, value) for name, value in zip(cls.FIELDS, values)}
        if cls.TAIL:
            kwargs[cls.TAIL] = bytes(data[fixed:])
        if len(cls.TYPES) > 1:
            kwargs["type_id"] = PduType(data[0])
        return cls(**kwargs)


def _wire(value):
    if isinstance(value, uuidlib.UUID):
        return value.bytes            # the uuid's 16 bytes in the order it is written
    if isinstance(value, IntEnum):
        return int(value)
    return value


_ENUM_FIELDS = {"state_id": State, "op_mode": OpMode, "error_code": ErrorCode,
                "source_data_type": DataType, "transport_protocol": TransportProtocol,
                "scope": Scope}


def _unwire(cls, name, value):
    if name == "slave_uuid":
        return uuidlib.UUID(bytes=value)
    if name == "ip_address":
        return str(ipaddress.IPv4Address(value))
    enum = _ENUM_FIELDS.get(name)
    if enum is not None:
        try:
            return enum(value)
        except ValueError:
            # a value outside the standard's table: the slave answers INVALID_* for it
            raise PduError(_INVALID_ENUM.get(name, ErrorCode.PROTOCOL_ERROR_GENERIC),
                           f"{name} {value} is not defined by DCP 1.0") from None
    return value


_INVALID_ENUM = {"state_id": ErrorCode.INVALID_STATE_ID, "op_mode": ErrorCode.INVALID_OP_MODE,
                 "source_data_type": ErrorCode.INVALID_SOURCE_DATA_TYPE,
                 "transport_protocol": ErrorCode.INVALID_TRANSPORT_PROTOCOL,
                 "scope": ErrorCode.INVALID_SCOPE}


@dataclass(frozen=True)
class StcRegister(Pdu):
    pdu_seq_id: int
    receiver: int
    state_id: State
    slave_uuid: uuidlib.UUID
    op_mode: OpMode
    major_version: int = DCP_MAJOR_VERSION
    minor_version: int = DCP_MINOR_VERSION
    type_id: PduType = field(default=PduType.STC_register, init=False)
    TYPES = (PduType.STC_register,)
    FORMAT = "HBB16sBBB"
    FIELDS = ("pdu_seq_id", "receiver", "state_id", "slave_uuid", "op_mode", "major_version", "minor_version")


@dataclass(frozen=True)
class Stc(Pdu):
    """STC_deregister, _prepare, _configure, _initialize, _send_outputs, _stop, _reset."""
    type_id: PduType
    pdu_seq_id: int
    receiver: int
    state_id: State
    TYPES = (PduType.STC_deregister, PduType.STC_prepare, PduType.STC_configure,
             PduType.STC_initialize, PduType.STC_send_outputs, PduType.STC_stop, PduType.STC_reset)
    FORMAT = "HBB"
    FIELDS = ("pdu_seq_id", "receiver", "state_id")


@dataclass(frozen=True)
class StcRun(Pdu):
    pdu_seq_id: int
    receiver: int
    state_id: State
    start_time: int = 0      # seconds since the epoch (0: at once)
    type_id: PduType = field(default=PduType.STC_run, init=False)
    TYPES = (PduType.STC_run,)
    FORMAT = "HBBq"
    FIELDS = ("pdu_seq_id", "receiver", "state_id", "start_time")


@dataclass(frozen=True)
class StcDoStep(Pdu):
    pdu_seq_id: int
    receiver: int
    state_id: State
    steps: int
    type_id: PduType = field(default=PduType.STC_do_step, init=False)
    TYPES = (PduType.STC_do_step,)
    FORMAT = "HBBI"
    FIELDS = ("pdu_seq_id", "receiver", "state_id", "steps")


@dataclass(frozen=True)
class CfgTimeRes(Pdu):
    pdu_seq_id: int
    receiver: int
    numerator: int
    denominator: int
    type_id: PduType = field(default=PduType.CFG_time_res, init=False)
    TYPES = (PduType.CFG_time_res,)
    FORMAT = "HBII"
    FIELDS = ("pdu_seq_id", "receiver", "numerator", "denominator")


@dataclass(frozen=True)
class CfgSteps(Pdu):
    pdu_seq_id: int
    receiver: int
    steps: int
    data_id: int
    type_id: PduType = field(default=PduType.CFG_steps, init=False)
    TYPES = (PduType.CFG_steps,)
    FORMAT = "HBIH"
    FIELDS = ("pdu_seq_id", "receiver", "steps", "data_id")


@dataclass(frozen=True)
class CfgInput(Pdu):
    pdu_seq_id: int
    receiver: int
    data_id: int
    pos: int
    target_vr: int
    source_data_type: DataType
    type_id: PduType = field(default=PduType.CFG_input, init=False)
    TYPES = (PduType.CFG_input,)
    FORMAT = "HBHHQB"
    FIELDS = ("pdu_seq_id", "receiver", "data_id", "pos", "target_vr", "source_data_type")


@dataclass(frozen=True)
class CfgOutput(Pdu):
    pdu_seq_id: int
    receiver: int
    data_id: int
    pos: int
    source_vr: int
    type_id: PduType = field(default=PduType.CFG_output, init=False)
    TYPES = (PduType.CFG_output,)
    FORMAT = "HBHHQ"
    FIELDS = ("pdu_seq_id", "receiver", "data_id", "pos", "source_vr")


@dataclass(frozen=True)
class Basic(Pdu):
    """A PDU of header only: CFG_clear, INF_state, INF_error."""
    type_id: PduType
    pdu_seq_id: int
    receiver: int
    TYPES = (PduType.CFG_clear, PduType.INF_state, PduType.INF_error)
    FORMAT = "HB"
    FIELDS = ("pdu_seq_id", "receiver")


@dataclass(frozen=True)
class CfgNetworkInformation(Pdu):
    """CFG_source_/CFG_target_network_information for UDP_IPv4: port, then the IPv4 address
    as a little-endian uint32 of its numeric value (127.0.0.1 is 0x7F000001)."""
    type_id: PduType
    pdu_seq_id: int
    receiver: int
    data_id: int
    port: int
    ip_address: str
    transport_protocol: TransportProtocol = TransportProtocol.UDP_IPv4
    TYPES = (PduType.CFG_source_network_information, PduType.CFG_target_network_information)
    FORMAT = "HBHBHI"
    FIELDS = ("pdu_seq_id", "receiver", "data_id", "transport_protocol", "port", "ip_address")

    def _values(self) -> tuple:
        return (self.pdu_seq_id, self.receiver, self.data_id, int(self.transport_protocol),
                self.port, int(ipaddress.IPv4Address(self.ip_address)))


@dataclass(frozen=True)
class CfgParameter(Pdu):
    pdu_seq_id: int
    receiver: int
    parameter_vr: int
    source_data_type: DataType
    configuration: bytes
    type_id: PduType = field(default=PduType.CFG_parameter, init=False)
    TYPES = (PduType.CFG_parameter,)
    FORMAT = "HBQB"
    FIELDS = ("pdu_seq_id", "receiver", "parameter_vr", "source_data_type")
    TAIL = "configuration"


@dataclass(frozen=True)
class CfgScope(Pdu):
    pdu_seq_id: int
    receiver: int
    data_id: int
    scope: Scope
    type_id: PduType = field(default=PduType.CFG_scope, init=False)
    TYPES = (PduType.CFG_scope,)
    FORMAT = "HBHB"
    FIELDS = ("pdu_seq_id", "receiver", "data_id", "scope")


@dataclass(frozen=True)
class RspAck(Pdu):
    sender: int
    resp_seq_id: int
    type_id: PduType = field(default=PduType.RSP_ack, init=False)
    TYPES = (PduType.RSP_ack,)
    FORMAT = "BH"
    FIELDS = ("sender", "resp_seq_id")


@dataclass(frozen=True)
class RspNack(Pdu):
    sender: int
    resp_seq_id: int
    exp_seq_id: int
    error_code: ErrorCode
    type_id: PduType = field(default=PduType.RSP_nack, init=False)
    TYPES = (PduType.RSP_nack,)
    FORMAT = "BHHH"
    FIELDS = ("sender", "resp_seq_id", "exp_seq_id", "error_code")


@dataclass(frozen=True)
class RspStateAck(Pdu):
    sender: int
    resp_seq_id: int
    state_id: State
    type_id: PduType = field(default=PduType.RSP_state_ack, init=False)
    TYPES = (PduType.RSP_state_ack,)
    FORMAT = "BHB"
    FIELDS = ("sender", "resp_seq_id", "state_id")


@dataclass(frozen=True)
class RspErrorAck(Pdu):
    sender: int
    resp_seq_id: int
    error_code: ErrorCode
    type_id: PduType = field(default=PduType.RSP_error_ack, init=False)
    TYPES = (PduType.RSP_error_ack,)
    FORMAT = "BHH"
    FIELDS = ("sender", "resp_seq_id", "error_code")


@dataclass(frozen=True)
class NtfStateChanged(Pdu):
    sender: int
    state_id: State
    type_id: PduType = field(default=PduType.NTF_state_changed, init=False)
    TYPES = (PduType.NTF_state_changed,)
    FORMAT = "BB"
    FIELDS = ("sender", "state_id")


@dataclass(frozen=True)
class DatInputOutput(Pdu):
    pdu_seq_id: int
    data_id: int
    payload: bytes
    type_id: PduType = field(default=PduType.DAT_input_output, init=False)
    TYPES = (PduType.DAT_input_output,)
    FORMAT = "HH"
    FIELDS = ("pdu_seq_id", "data_id")
    TAIL = "payload"


@dataclass(frozen=True)
class Unsupported(Pdu):
    """A PDU the standard defines that we do not implement (logging, tunable parameters,
    DAT_parameter): only its header is read, so that a slave can refuse it."""
    type_id: PduType
    pdu_seq_id: int
    receiver: int
    body: bytes = b""
    TYPES = (PduType.CFG_tunable_parameter, PduType.CFG_param_network_information,
             PduType.CFG_logging, PduType.INF_log, PduType.RSP_log_ack, PduType.NTF_log,
             PduType.DAT_parameter)
    FORMAT = "HB"
    FIELDS = ("pdu_seq_id", "receiver")
    TAIL = "body"


PDU_CLASSES: Dict[PduType, Type[Pdu]] = {t: cls for cls in (
    StcRegister, Stc, StcRun, StcDoStep, CfgTimeRes, CfgSteps, CfgInput, CfgOutput, Basic,
    CfgNetworkInformation, CfgParameter, CfgScope, RspAck, RspNack, RspStateAck, RspErrorAck,
    NtfStateChanged, DatInputOutput, Unsupported) for t in cls.TYPES}

#: the request families a master sends: their header is type_id, pdu_seq_id (uint16), receiver
REQUEST_TYPES = frozenset(t for t in PduType if t < 0xB0)


def decode(data: bytes) -> Pdu:
    """The PDU in one datagram; a wrong length or unknown type id raises :class:`PduError`."""
    if not data:
        raise PduError(ErrorCode.INVALID_LENGTH, "empty datagram")
    try:
        type_id = PduType(data[0])
    except ValueError:
        raise PduError(ErrorCode.NOT_SUPPORTED_PDU, f"type_id 0x{data[0]:02X} is not defined by DCP 1.0",
                       type_id=data[0]) from None
    seq = receiver = None
    if type_id in REQUEST_TYPES and type_id != PduType.DAT_input_output and len(data) >= 4:
        seq, receiver = struct.unpack_from("<HB", data, 1)
    elif type_id == PduType.DAT_input_output and len(data) >= 3:
        seq = struct.unpack_from("<H", data, 1)[0]
    cls = PDU_CLASSES[type_id]
    fixed = cls.size()
    if len(data) < fixed or (cls.TAIL is None and len(data) != fixed):
        raise PduError(ErrorCode.INVALID_LENGTH,
                       f"{type_id.name}: {len(data)} bytes, the standard's length is "
                       f"{fixed}{' or more' if cls.TAIL else ''}", type_id, seq, receiver)
    try:
        return cls._decode(data)
    except PduError as error:
        error.type_id, error.pdu_seq_id, error.receiver = type_id, seq, receiver
        raise


# ---- payloads ---------------------------------------------------------------------------------

class PayloadCodec:
    """Encodes/decodes the concatenated values of a DAT_input_output payload (or a
    CFG_parameter configuration): one entry per position, each a DCP data type and an element
    count (1 for a scalar, the product of the dimensions for an array, row-major).

    Numeric entries are laid out back to back little-endian; a string or binary value is a
    uint32 byte length followed by its bytes (UTF-8 for strings). Numeric-only payloads are
    decoded with one numpy structured view.
    """

    def __init__(self, entries: Sequence[Tuple[DataType, int]]):
        self.entries = [(DataType(t), int(n)) for t, n in entries]
        self.fixed = all(t not in VARIABLE_LENGTH for t, _ in self.entries)
        if self.fixed:
            self.dtype = np.dtype([(f"f{k}", NUMPY_DTYPES[t], (n,)) for k, (t, n) in enumerate(self.entries)])
            self.size = self.dtype.itemsize
        else:
            self.dtype, self.size = None, None

    def decode(self, payload: bytes) -> List[Union[np.ndarray, str, bytes]]:
        """One numpy array (count elements) per numeric entry, a str/bytes per variable-length
        entry; a payload of the wrong length raises PduError(INVALID_LENGTH)."""
        if self.fixed:
            if len(payload) != self.size:
                raise PduError(ErrorCode.INVALID_LENGTH,
                               f"payload of {len(payload)} bytes, expected {self.size}")
            record = np.frombuffer(payload, dtype=self.dtype, count=1)[0]
            return [record[k] for k in range(len(self.entries))]
        values, offset = [], 0
        for data_type, count in self.entries:
            if data_type in VARIABLE_LENGTH:
                if offset + 4 > len(payload):
                    raise PduError(ErrorCode.INVALID_LENGTH, "payload ends inside a length field")
                length = struct.unpack_from("<I", payload, offset)[0]
                offset += 4
                if offset + length > len(payload):
                    raise PduError(ErrorCode.INVALID_LENGTH, "payload ends inside a string/binary value")
                raw = bytes(payload[offset:offset + length])
                offset += length
                if data_type == DataType.string:
                    try:
                        values.append(raw.decode("utf-8"))
                    except UnicodeDecodeError:
                        raise PduError(ErrorCode.INVALID_PAYLOAD, "string value is not UTF-8") from None
                else:
                    values.append(raw)
            else:
                dtype = NUMPY_DTYPES[data_type]
                end = offset + dtype.itemsize * count
                if end > len(payload):
                    raise PduError(ErrorCode.INVALID_LENGTH, "payload shorter than its variables")
                values.append(np.frombuffer(payload, dtype=dtype, count=count, offset=offset))
                offset = end
        if offset != len(payload):
            raise PduError(ErrorCode.INVALID_LENGTH, f"payload of {len(payload)} bytes, its variables use {offset}")
        return values

    def encode(self, values: Sequence) -> bytes:
        """The payload of ``values`` (one per entry: a number, a sequence/array, a str or bytes)."""
        if self.fixed:
            record = np.zeros(1, dtype=self.dtype)
            for k, value in enumerate(values):
                record[f"f{k}"][0] = value
            return record.tobytes()
        parts = []
        for (data_type, count), value in zip(self.entries, values):
            if data_type in VARIABLE_LENGTH:
                raw = value.encode("utf-8") if isinstance(value, str) else bytes(value)
                parts.append(struct.pack("<I", len(raw)) + raw)
            else:
                parts.append(np.asarray(value, dtype=NUMPY_DTYPES[data_type]).reshape(count).tobytes())
        return b"".join(parts)


def next_seq(seq_id: int) -> int:
    """The sequence id after ``seq_id`` (uint16, wraps to 0)."""
    return (seq_id + 1) & 0xFFFF

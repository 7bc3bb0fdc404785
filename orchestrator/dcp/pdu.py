"""DCP 1.0 protocol data units: the ids of the standard, and every PDU as one row of a table.

The wire layout of each PDU type is one :class:`Layout` in :data:`LAYOUTS`: its fields after
``type_id`` in wire order, each a name and a :mod:`struct` code, all little-endian without
padding, one PDU per UDP datagram (the 4-byte length indicator exists only on stream
transports). The layouts were checked field by field against the DCP reference implementation
(DCPLib: its PDU classes, its Wireshark dissector where the two agree) and against datagrams
it sent and received (tests/data/dcp/, docs/hil.md#pdus says which source each row comes from).

A :class:`Pdu` is a type id and its fields by name::

    Pdu(PduType.RSP_ack, resp_seq_id=7, sender=1).encode()     # b'\\xb0\\x07\\x00\\x01'
    decode(datagram).resp_seq_id

:func:`decode` parses a datagram and raises :class:`PduError` with the standard's error code
(``INVALID_LENGTH``, ``NOT_SUPPORTED_PDU``, ``INVALID_*`` for an enumeration value the standard
does not define) and whatever of the header it could read, so a slave can answer with
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
from typing import Dict, List, Mapping, Optional, Sequence, Tuple, Union

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
    NOT_SUPPORTED_TRANSPORT_PROTOCOL = 0x4004
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


# ---- the layouts ------------------------------------------------------------------------------

@dataclass(frozen=True)
class Layout:
    """One PDU type on the wire: ``fields`` after type_id in order, each (name, struct code);
    ``tail`` names a variable-length bytes field at the end (None: the PDU has a fixed length);
    ``defaults`` are values a constructor may leave out."""

    fields: Tuple[Tuple[str, str], ...]
    tail: Optional[str] = None
    defaults: Mapping[str, object] = field(default_factory=dict)

    def __post_init__(self):
        object.__setattr__(self, "struct", struct.Struct("<B" + "".join(code for _, code in self.fields)))

    @property
    def names(self) -> Tuple[str, ...]:
        return tuple(name for name, _ in self.fields) + ((self.tail,) if self.tail else ())

    @property
    def size(self) -> int:
        """The length of the fixed part, type_id included (the PDU's length without a tail)."""
        return self.struct.size


P = PduType
_REQUEST = (("pdu_seq_id", "H"), ("receiver", "B"))                 # STC_, CFG_, INF_
_STC = _REQUEST + (("state_id", "B"),)
_RESPONSE = (("resp_seq_id", "H"), ("sender", "B"))                 # RSP_ (mirrors the request)
_NETWORK = (("transport_protocol", "B"), ("port", "H"), ("ip_address", "I"))   # UDP_IPv4 / TCP_IPv4
_UDP = {"transport_protocol": TransportProtocol.UDP_IPv4}

#: every PDU of DCP 1.0, fields after type_id in wire order (docs/hil.md#pdus has the same table)
LAYOUTS: Dict[PduType, Layout] = {
    P.STC_register: Layout(_STC + (("slave_uuid", "16s"), ("op_mode", "B"), ("major_version", "B"),
                                   ("minor_version", "B")),
                           defaults={"major_version": DCP_MAJOR_VERSION, "minor_version": DCP_MINOR_VERSION}),
    **{t: Layout(_STC) for t in (P.STC_deregister, P.STC_prepare, P.STC_configure, P.STC_initialize,
                                 P.STC_send_outputs, P.STC_stop, P.STC_reset)},
    P.STC_run: Layout(_STC + (("start_time", "q"),), defaults={"start_time": 0}),   # Unix seconds, 0: at once
    P.STC_do_step: Layout(_STC + (("steps", "I"),)),
    P.CFG_time_res: Layout(_REQUEST + (("numerator", "I"), ("denominator", "I"))),
    P.CFG_steps: Layout(_REQUEST + (("steps", "I"), ("data_id", "H"))),
    P.CFG_input: Layout(_REQUEST + (("data_id", "H"), ("pos", "H"), ("target_vr", "Q"), ("source_data_type", "B"))),
    P.CFG_output: Layout(_REQUEST + (("data_id", "H"), ("pos", "H"), ("source_vr", "Q"))),
    P.CFG_clear: Layout(_REQUEST),
    P.CFG_target_network_information: Layout(_REQUEST + (("data_id", "H"),) + _NETWORK, defaults=_UDP),
    P.CFG_source_network_information: Layout(_REQUEST + (("data_id", "H"),) + _NETWORK, defaults=_UDP),
    P.CFG_parameter: Layout(_REQUEST + (("parameter_vr", "Q"), ("source_data_type", "B")), tail="configuration"),
    P.CFG_tunable_parameter: Layout(_REQUEST + (("param_id", "H"), ("pos", "H"), ("parameter_vr", "Q"),
                                                ("source_data_type", "B"))),
    P.CFG_param_network_information: Layout(_REQUEST + (("param_id", "H"),) + _NETWORK, defaults=_UDP),
    P.CFG_logging: Layout(_REQUEST + (("log_category", "B"), ("log_level", "B"), ("log_mode", "B"))),
    P.CFG_scope: Layout(_REQUEST + (("data_id", "H"), ("scope", "B"))),
    P.INF_state: Layout(_REQUEST),
    P.INF_error: Layout(_REQUEST),
    P.INF_log: Layout(_REQUEST + (("log_category", "B"), ("log_max_num", "B"))),
    P.RSP_ack: Layout(_RESPONSE),
    P.RSP_nack: Layout(_RESPONSE + (("exp_seq_id", "H"), ("error_code", "H"))),
    P.RSP_state_ack: Layout(_RESPONSE + (("state_id", "B"),)),
    P.RSP_error_ack: Layout(_RESPONSE + (("error_code", "H"),)),
    P.RSP_log_ack: Layout(_RESPONSE, tail="log_entries"),
    P.NTF_state_changed: Layout((("sender", "B"), ("state_id", "B"))),
    P.NTF_log: Layout((("sender", "B"), ("time", "q"), ("template_id", "B")), tail="log_arguments"),
    P.DAT_input_output: Layout((("pdu_seq_id", "H"), ("data_id", "H")), tail="payload"),
    P.DAT_parameter: Layout((("pdu_seq_id", "H"), ("param_id", "H")), tail="configuration"),
}
del P

#: the request families a master sends: their header is type_id, pdu_seq_id (uint16), receiver
REQUEST_TYPES = frozenset(t for t in PduType if t < PduType.RSP_ack)
#: the PDUs a slave answers with RSP_ (all but data)
ANSWERED_TYPES = REQUEST_TYPES - {PduType.DAT_input_output, PduType.DAT_parameter}

#: enumerated fields: (their enumeration, the error a slave answers for an undefined value;
#: None: a value outside the table is kept as a plain int, since a response or notification is
#: never refused)
_ENUM_FIELDS: Dict[str, Tuple[type, Optional[ErrorCode]]] = {
    "state_id": (State, ErrorCode.INVALID_STATE_ID),
    "op_mode": (OpMode, ErrorCode.INVALID_OP_MODE),
    "source_data_type": (DataType, ErrorCode.INVALID_SOURCE_DATA_TYPE),
    "transport_protocol": (TransportProtocol, ErrorCode.INVALID_TRANSPORT_PROTOCOL),
    "scope": (Scope, ErrorCode.INVALID_SCOPE),
    "error_code": (ErrorCode, None),
}


def _to_wire(name: str, value):
    if name == "slave_uuid":
        return value.bytes            # the uuid's 16 bytes in the order it is written (RFC 4122)
    if name == "ip_address":
        return int(ipaddress.IPv4Address(value))     # the address's number, as a little-endian uint32
    return int(value) if isinstance(value, IntEnum) else value


def _from_wire(name: str, value, responding: bool):
    if name == "slave_uuid":
        return uuidlib.UUID(bytes=value)
    if name == "ip_address":
        return str(ipaddress.IPv4Address(value))
    enum = _ENUM_FIELDS.get(name)
    if enum is None:
        return value
    kind, refusal = enum
    try:
        return kind(value)
    except ValueError:
        if refusal is None or responding:
            return value
        raise PduError(refusal, f"{name} {value} is not defined by DCP 1.0") from None


class Pdu:
    """One PDU: ``type_id`` and its fields as attributes, named as in :data:`LAYOUTS`.
    Immutable; equal when type and fields are equal."""

    __slots__ = ("type_id", "_fields")

    def __init__(self, type_id: PduType, **fields):
        type_id = PduType(type_id)
        layout = LAYOUTS[type_id]
        values = {**layout.defaults, **fields}
        missing = [name for name in layout.names if name not in values]
        unknown = sorted(set(values) - set(layout.names))
        if missing or unknown:
            raise TypeError(f"{type_id.name}: " + "; ".join(
                part for part in (f"missing {', '.join(missing)}" if missing else "",
                                  f"no field {', '.join(unknown)}" if unknown else "") if part))
        object.__setattr__(self, "type_id", type_id)
        object.__setattr__(self, "_fields", {name: values[name] for name in layout.names})

    def __getattr__(self, name):
        try:
            return object.__getattribute__(self, "_fields")[name]
        except KeyError:
            raise AttributeError(f"{self.type_id.name} has no field {name!r}") from None

    def __setattr__(self, name, value):
        raise AttributeError("a PDU is immutable")

    def __eq__(self, other):
        return isinstance(other, Pdu) and self.type_id == other.type_id and self._fields == other._fields

    def __hash__(self):
        return hash((self.type_id, tuple(self._fields.items())))

    def __repr__(self):
        fields = ", ".join(f"{k}={v!r}" for k, v in self._fields.items())
        return f"Pdu({self.type_id.name}, {fields})"

    @property
    def fields(self) -> Dict[str, object]:
        return dict(self._fields)

    def encode(self) -> bytes:
        layout = LAYOUTS[self.type_id]
        head = layout.struct.pack(int(self.type_id), *(_to_wire(name, self._fields[name]) for name, _ in layout.fields))
        return head + bytes(self._fields[layout.tail]) if layout.tail else head


def decode(data: bytes) -> Pdu:
    """The PDU in one datagram; a wrong length, an unknown type id or an enumeration value the
    standard does not define raises :class:`PduError`."""
    if not data:
        raise PduError(ErrorCode.INVALID_LENGTH, "empty datagram")
    try:
        type_id = PduType(data[0])
    except ValueError:
        raise PduError(ErrorCode.NOT_SUPPORTED_PDU, f"type_id 0x{data[0]:02X} is not defined by DCP 1.0",
                       type_id=data[0]) from None
    seq = receiver = None
    if type_id in ANSWERED_TYPES and len(data) >= 4:
        seq, receiver = struct.unpack_from("<HB", data, 1)
    elif type_id in (PduType.DAT_input_output, PduType.DAT_parameter) and len(data) >= 3:
        seq = struct.unpack_from("<H", data, 1)[0]
    layout = LAYOUTS[type_id]
    if len(data) < layout.size or (layout.tail is None and len(data) != layout.size):
        raise PduError(ErrorCode.INVALID_LENGTH,
                       f"{type_id.name}: {len(data)} bytes, the standard's length is "
                       f"{layout.size}{' or more' if layout.tail else ''}", type_id, seq, receiver)
    responding = type_id not in REQUEST_TYPES
    values = layout.struct.unpack_from(data)
    try:
        fields = {name: _from_wire(name, value, responding) for (name, _), value in zip(layout.fields, values[1:])}
    except PduError as error:
        error.type_id, error.pdu_seq_id, error.receiver = type_id, seq, receiver
        raise
    if layout.tail:
        fields[layout.tail] = bytes(data[layout.size:])
    return Pdu(type_id, **fields)


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

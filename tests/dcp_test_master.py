"""A small DCP master for the tests, written from the standard: numbered requests, waits for
the RSP with the request's sequence id, collects NTF_state_changed and DAT_input_output."""
from __future__ import annotations

import os
import socket
import subprocess
import sys
import time
from pathlib import Path
from typing import List, Optional

from orchestrator.dcp.pdu import (OpMode, PduType, State, decode, next_seq, Pdu)

REPO = Path(__file__).resolve().parent.parent


def start_slave(fmu: Path, *extra: str, timeout_s: float = 60.0, quiet: bool = True):
    """``railcosim dcp-slave FMU --port 0`` in a subprocess; returns (process, (host, port))."""
    env = dict(os.environ, PYTHONPATH=str(REPO))
    proc = subprocess.Popen([sys.executable, "-m", "orchestrator", "dcp-slave", str(fmu), "--port", "0",
                             *(["--quiet"] if quiet else []), *extra], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, env=env, cwd=str(REPO))
    line = proc.stdout.readline()
    if not line.startswith("LISTENING "):
        proc.kill()
        raise RuntimeError(f"slave did not start: {line!r} {proc.stderr.read()}")
    host, port = line.split()[1].rsplit(":", 1)
    return proc, (host, int(port))


class TestMaster:
    __test__ = False

    def __init__(self, slave_address, slave_id: int = 1, timeout_s: float = 10.0):
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.settimeout(timeout_s)
        self.slave = slave_address
        self.slave_id = slave_id
        self.seq = 0
        self.states: List[State] = []
        self.data: List[Pdu] = []
        self.others: list = []

    @property
    def address(self):
        return self.sock.getsockname()

    def close(self):
        self.sock.close()

    def send_raw(self, data: bytes) -> None:
        self.sock.sendto(data, self.slave)

    def _receive(self):
        data, _ = self.sock.recvfrom(65536)
        pdu = decode(data)
        if pdu.type_id == PduType.NTF_state_changed:
            self.states.append(pdu.state_id)
        elif pdu.type_id == PduType.DAT_input_output:
            self.data.append(pdu)
        return pdu

    def response(self, seq: int):
        """The RSP answering sequence id ``seq`` (NTF and DAT met meanwhile are collected)."""
        while True:
            pdu = self._receive()
            if pdu.type_id in (PduType.RSP_ack, PduType.RSP_nack, PduType.RSP_state_ack,
                               PduType.RSP_error_ack) and pdu.resp_seq_id == seq:
                return pdu
            if pdu.type_id >= PduType.RSP_ack and pdu.type_id < PduType.NTF_state_changed:
                self.others.append(pdu)

    def request(self, make, expect_ack: bool = True):
        """Send ``make(seq)`` with the next sequence id and return the slave's response."""
        seq = self.seq
        self.send_raw(make(seq).encode())
        self.seq = next_seq(seq)
        rsp = self.response(seq)
        if expect_ack:
            assert rsp.type_id == PduType.RSP_ack, f"expected RSP_ack, got {rsp}"
        return rsp

    def wait_state(self, state: State, timeout_s: float = 10.0) -> None:
        end = time.monotonic() + timeout_s
        while state not in self.states:
            assert time.monotonic() < end, f"no NTF_state_changed to {state.name}; saw {self.states}"
            self._receive()
        del self.states[:self.states.index(state) + 1]

    def wait_data(self, count: int, timeout_s: float = 10.0) -> None:
        end = time.monotonic() + timeout_s
        while len(self.data) < count:
            assert time.monotonic() < end, f"{len(self.data)} of {count} DAT PDUs"
            self._receive()

    # ---- the standard's sequence ------------------------------------------------------------
    def register(self, uuid, op_mode=OpMode.NRT):
        rsp = self.request(lambda s: Pdu(PduType.STC_register, pdu_seq_id=s, receiver=self.slave_id, state_id=State.ALIVE, slave_uuid=uuid, op_mode=op_mode))
        self.wait_state(State.CONFIGURATION)
        return rsp

    def stc(self, type_id, state, then: Optional[State] = None):
        self.request(lambda s: Pdu(type_id, pdu_seq_id=s, receiver=self.slave_id, state_id=state))
        if then is not None:
            self.wait_state(then)

    def configure(self, inputs, outputs, steps: int, resolution=(1, 1_000_000_000), parameters=(), target=None):
        """inputs/outputs: lists of (vr, DataType) on data_id 1 (in) and 2 (out); the slave
        receives on its control port and sends to this master (or to ``target``, (host, port))."""
        target = target or self.address
        sid = self.slave_id
        self.request(lambda s: Pdu(PduType.CFG_time_res, pdu_seq_id=s, receiver=sid, numerator=resolution[0], denominator=resolution[1]))
        for pos, (vr, data_type) in enumerate(inputs):
            self.request(lambda s: Pdu(PduType.CFG_input, pdu_seq_id=s, receiver=sid, data_id=1, pos=pos, target_vr=vr, source_data_type=data_type))
        for pos, (vr, _) in enumerate(outputs):
            self.request(lambda s: Pdu(PduType.CFG_output, pdu_seq_id=s, receiver=sid, data_id=2, pos=pos, source_vr=vr))
        self.request(lambda s: Pdu(PduType.CFG_steps, pdu_seq_id=s, receiver=sid, steps=steps, data_id=2))
        if inputs:
            self.request(lambda s: Pdu(PduType.CFG_source_network_information, pdu_seq_id=s, receiver=sid, data_id=1, port=self.slave[1], ip_address=self.slave[0]))
        self.request(lambda s: Pdu(PduType.CFG_target_network_information, pdu_seq_id=s, receiver=sid, data_id=2, port=target[1], ip_address=target[0]))
        for vr, data_type, configuration in parameters:
            self.request(lambda s: Pdu(PduType.CFG_parameter, pdu_seq_id=s, receiver=sid, parameter_vr=vr, source_data_type=data_type, configuration=configuration))
        self.stc(PduType.STC_prepare, State.CONFIGURATION, State.PREPARED)
        self.stc(PduType.STC_configure, State.PREPARED, State.CONFIGURED)

    def send_inputs(self, seq: int, payload: bytes, data_id: int = 1) -> None:
        self.send_raw(Pdu(PduType.DAT_input_output, pdu_seq_id=seq, data_id=data_id, payload=payload).encode())

    def inf_state(self) -> State:
        return self.request(lambda s: Pdu(PduType.INF_state, pdu_seq_id=s, receiver=self.slave_id), expect_ack=False).state_id

"""DCP interoperability against the reference implementation, DCPLib, from datagrams it sent and
received (tests/data/dcp/, README.md there says how each file was made): nothing here depends
on our encoder agreeing with our own decoder.

* every captured PDU decodes, with fields consistent with the session, and re-encodes to the
  same bytes;
* DCPLib's example master, replayed against ``railcosim dcp-slave`` serving an FMU under the
  example slave's own description, gets the answers DCPLib's example slave gave, field for
  field, sequence ids and state changes included, and the same data values;
* refused requests get DCPLib's refusals (codes, sequence ids, senders);
* our master, answered with what DCPLib's slave answered, sends what it sent then and gets
  the values DCPLib's slave computed (y = sin(k + a) for the a it was sent).
"""
import json
import math
import socket
import struct
import threading
import time
from pathlib import Path

import pytest

from dcp_test_master import start_slave
from orchestrator.dcp.pdu import DataType, PayloadCodec, Pdu, PduType, State, decode

DATA = Path(__file__).resolve().parent / "data" / "dcp"
EXAMPLE_DCPX = DATA / "dcplib_example_slave.dcpx"
SESSIONS = sorted(p.name for p in DATA.glob("*.json"))
FLOAT = PayloadCodec([(DataType.float64, 1)])


def load(name):
    return json.loads((DATA / name).read_text())


def datagrams(name):
    return [(d["from"], d["to"], bytes.fromhex(d["hex"])) for d in load(name)["datagrams"]]


def value(pdu) -> float:
    return float(FLOAT.decode(pdu.payload)[0][0])


# ---- decode, check, re-encode ------------------------------------------------------------------

@pytest.mark.parametrize("name", SESSIONS)
def test_every_captured_pdu_decodes_and_reencodes_byte_for_byte(name):
    requests = {}
    seen_types = set()
    for sender, _, data in datagrams(name):
        if len(data) == 11 and data[0] == PduType.CFG_time_res:
            # the one deliberately truncated request of the refusal capture: only its header counts
            requests[struct.unpack_from("<H", data, 1)[0]] = None
            continue
        pdu = decode(data)
        assert pdu.encode() == data
        seen_types.add(pdu.type_id)
        if sender == "master" and pdu.type_id not in (PduType.DAT_input_output,):
            requests[pdu.pdu_seq_id] = pdu
            assert pdu.receiver in (1, 7)            # the example's slave id (7: a wrong-receiver probe)
        elif pdu.type_id in (PduType.RSP_ack, PduType.RSP_nack, PduType.RSP_state_ack):
            # a response answers a request sent before it, and names the slave (0 before registration)
            assert pdu.resp_seq_id in requests, pdu
            assert pdu.sender in (0, 1)
        elif pdu.type_id == PduType.NTF_state_changed:
            assert pdu.sender == 1 and isinstance(pdu.state_id, State)
    assert PduType.RSP_ack in seen_types or PduType.RSP_nack in seen_types


def test_the_captures_hold_the_layouts_docs_hil_md_states():
    """Field offsets read straight off DCPLib's bytes: RSP_ack type, resp_seq_id (2), sender;
    RSP_nack then exp_seq_id and error_code; NTF_state_changed sender, state_id."""
    nack = bytes.fromhex(next(s for s in load("dcplib_slave_nacks.json")["steps"]
                              if s["note"].startswith("C1 "))["received"][0])
    assert nack == bytes([0xB1, 105, 0, 1, 101, 0, 0x13, 0x20])
    assert decode(nack).fields == {"resp_seq_id": 105, "sender": 1, "exp_seq_id": 101,
                                   "error_code": 0x2013}
    first = datagrams("dcplib_master_dcplib_slave_srt.json")
    assert first[1][2] == bytes([0xB0, 0, 0, 1])                 # RSP_ack of STC_register seq 0
    assert first[2][2] == bytes([0xE0, 1, State.CONFIGURATION])


# ---- DCPLib's master against our slave ---------------------------------------------------------

def _description_with_nrt(tmp_path) -> Path:
    """The example slave's description with the non-real-time mode the NRT capture's slave
    offered (one step at a time)."""
    text = EXAMPLE_DCPX.read_text().replace(
        "<SoftRealTime/>", '<SoftRealTime/>\n\t\t<NonRealTime defaultSteps="1" fixedSteps="true" minSteps="1" '
                           'maxSteps="1"/>')
    path = tmp_path / "example_nrt.dcpx"
    path.write_text(text)
    return path


class Replayer:
    """The master side of a capture, sent to our slave: each request as captured (its network
    information pointed at this replayer, start times moved to now), the slave's answers
    collected; data the slave sends to itself in the capture is received here and forwarded to
    it, so the loop of the example (y fed back as a) closes through the replayer."""

    def __init__(self, slave_address):
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.settimeout(10.0)
        self.slave = slave_address
        self.answers, self.data = [], []

    def close(self):
        self.sock.close()

    def rewrite(self, pdu: Pdu) -> Pdu:
        fields = pdu.fields
        if pdu.type_id == PduType.CFG_source_network_information:
            fields["port"] = self.slave[1]                 # the slave's own port, as in the capture
        elif pdu.type_id == PduType.CFG_target_network_information:
            fields["port"] = self.sock.getsockname()[1]    # through us, to see and forward the data
        elif pdu.type_id == PduType.STC_run and fields["start_time"]:
            fields["start_time"] = int(time.time()) + 1
        return Pdu(pdu.type_id, **fields)

    def receive(self):
        data, _ = self.sock.recvfrom(65536)
        pdu = decode(data)
        if pdu.type_id == PduType.DAT_input_output:
            self.data.append(pdu)
            self.sock.sendto(data, self.slave)             # the example's loop: y → a
        else:
            self.answers.append(pdu)

    def run(self, name, data_wanted: int):
        """Replay ``name``'s master datagrams in order; after each, wait for as many answers as
        the capture's slave gave before the master's next datagram; before STC_stop, for
        ``data_wanted`` data PDUs."""
        captured = datagrams(name)
        expected_answers, expected_data = [], []
        waiting = 0
        for k, (sender, _, data) in enumerate(captured):
            if sender != "master":
                pdu = decode(data)
                (expected_data if pdu.type_id == PduType.DAT_input_output else expected_answers).append(pdu)
                continue
            pdu = self.rewrite(decode(data))
            if pdu.type_id == PduType.STC_stop:
                while len(self.data) < data_wanted:
                    self.receive()
            self.sock.sendto(pdu.encode(), self.slave)
            waiting = sum(1 for s, _, d in captured[:self._next_master(captured, k)]
                          if s == "slave" and d[0] != PduType.DAT_input_output)
            while len(self.answers) < waiting:
                self.receive()
        return expected_answers, expected_data

    @staticmethod
    def _next_master(captured, k):
        return next((j for j in range(k + 1, len(captured)) if captured[j][0] == "master"), len(captured))


@pytest.mark.parametrize("name,mode", [("dcplib_master_dcplib_slave_srt.json", "SRT"),
                                       ("dcplib_master_dcplib_slave_nrt.json", "NRT")])
def test_dcplib_master_gets_from_our_slave_what_dcplib_slave_answered(name, mode, test_fmus, tmp_path):
    description = EXAMPLE_DCPX if mode == "SRT" else _description_with_nrt(tmp_path)
    extra = ("--real-time",) if mode == "SRT" else ()
    proc, address = start_slave(test_fmus / "TestSine.fmu", "--dcpx", str(description), *extra)
    replayer = Replayer(address)
    try:
        expected_answers, expected_data = replayer.run(name, data_wanted=100 if mode == "SRT" else 0)
        proc.wait(timeout=30)                      # deregistered: the slave ends by itself
        assert proc.returncode == 0
    finally:
        replayer.close()
        if proc.poll() is None:
            proc.kill()
        proc.communicate()
    assert [p.fields | {"type": p.type_id} for p in replayer.answers] == \
           [p.fields | {"type": p.type_id} for p in expected_answers]
    n = min(len(replayer.data), len(expected_data))
    assert n >= (100 if mode == "SRT" else 5)
    ours, theirs = [(p.pdu_seq_id, value(p)) for p in replayer.data[:n]], [(p.pdu_seq_id, value(p)) for p in
                                                                           expected_data[:n]]
    if mode == "NRT":
        # stepped by the master: y_k = sin(k + y_(k-1)) from a = 10, DCPLib's example and the FMU alike
        assert ours == theirs
    else:
        # on its own clock the slave applies whichever fed-back output has arrived by its step
        # (here through the replayer, on a loaded machine maybe a period late): every output is
        # sin(k + a) for a = 10 or an earlier output, the first one DCPLib's to the bit
        assert ours[0] == theirs[0] == (0, math.sin(10.0))
        fed = [10.0]
        for k, (seq, y) in enumerate(ours):
            assert seq == k and any(y == math.sin(k + a) for a in fed), (k, y)
            fed.append(y)


def test_refusals_are_dcplibs(test_fmus):
    """Each request DCPLib's example slave refused (or answered) in the refusal capture, sent to
    our slave under the same description: the same answer, byte for byte."""
    proc, address = start_slave(test_fmus / "TestSine.fmu", "--dcpx", str(EXAMPLE_DCPX), "--real-time")
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    try:
        for step in load("dcplib_slave_nacks.json")["steps"]:
            sock.sendto(bytes.fromhex(step["sent"]), address)
            got = []
            sock.settimeout(10.0 if step["received"] else 0.3)
            while len(got) < max(1, len(step["received"])):
                try:
                    got.append(sock.recvfrom(65536)[0].hex())
                except socket.timeout:
                    break
            assert got == step["received"], step["note"]
        proc.wait(timeout=30)                      # the last step deregisters it
    finally:
        sock.close()
        if proc.poll() is None:
            proc.kill()
        proc.communicate()


def test_dcplib_master_ran_a_whole_session_against_our_slave():
    """The recorded session (DCPLib's master, unchanged, against railcosim dcp-slave): every
    request acknowledged, the states of a soft-real-time run in order, y = sin(k + a) all along."""
    acked, states, values = set(), [], []
    for sender, to, data in datagrams("dcplib_master_railcosim_slave_srt.json"):
        pdu = decode(data)
        if pdu.type_id == PduType.RSP_ack:
            acked.add(pdu.resp_seq_id)
        assert pdu.type_id != PduType.RSP_nack
        if pdu.type_id == PduType.NTF_state_changed:
            states.append(pdu.state_id)
        if pdu.type_id == PduType.DAT_input_output:
            values.append((pdu.pdu_seq_id, value(pdu)))
    assert acked == set(range(14))                 # register … deregister
    assert states == [State.CONFIGURATION, State.PREPARING, State.PREPARED, State.CONFIGURING, State.CONFIGURED,
                      State.SYNCHRONIZING, State.SYNCHRONIZED, State.RUNNING, State.STOPPING, State.STOPPED,
                      State.ALIVE]
    a = 10.0
    for k, (seq, y) in enumerate(values):
        assert seq == k and y == math.sin(k + a)
        a = y


# ---- our master against DCPLib's slave ----------------------------------------------------------

def test_our_master_drove_dcplibs_slave_with_the_input_it_set():
    """The recorded runs (`railcosim run … --swap ex=dcp://… --set ex.a=0.25`, DCPLib's example
    slave unchanged in soft real time, with its NRT option non-real-time): a = 0.25 in every
    input, and every output DCPLib computed is sin(k + 0.25), k its step."""
    for name, first_run_seq in (("railcosim_master_dcplib_slave_srt.json", 1),
                                ("railcosim_master_dcplib_slave_nrt.json", 1)):
        inputs, outputs = [], []
        for sender, _, data in datagrams(name):
            pdu = decode(data)
            assert pdu.type_id != PduType.RSP_nack
            if pdu.type_id == PduType.DAT_input_output:
                (inputs if sender == "master" else outputs).append(pdu)
        assert inputs and all(value(p) == 0.25 for p in inputs)
        assert [p.pdu_seq_id for p in inputs] == list(range(len(inputs)))
        assert value(outputs[0]) == math.sin(0.25)                     # initialisation
        run = outputs[first_run_seq:]
        assert len(run) >= (500 if "srt" in name else 100)
        assert all(value(p) == math.sin(k + 0.25) for k, p in enumerate(run))


class CapturedSlave(threading.Thread):
    """DCPLib's slave as recorded: each request our master sends must be the request our master
    sent in the recorded run (its own port aside), and is answered with what DCPLib's slave
    answered to it."""

    def __init__(self, name):
        super().__init__(daemon=True)
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.port = self.sock.getsockname()[1]
        self.script = datagrams(name)
        self.mismatches = []

    def run(self):
        k = 0
        while k < len(self.script):
            try:
                data, master = self.sock.recvfrom(65536)
            except OSError:
                return
            sender, _, expected = self.script[k]
            got, want = decode(data), decode(expected)
            if want.type_id == PduType.CFG_target_network_information:
                want = Pdu(want.type_id, **(want.fields | {"port": got.port}))
            elif want.type_id == PduType.CFG_source_network_information:
                want = Pdu(want.type_id, **(want.fields | {"port": self.port}))
            if got != want:
                self.mismatches.append((k, got, want))
            k += 1
            while k < len(self.script) and self.script[k][0] == "slave":
                self.sock.sendto(self.script[k][2], master)
                k += 1

    def close(self):
        self.sock.close()


def test_our_master_answered_as_dcplib_answered_runs_as_it_did(test_fmus, tmp_path):
    from helpers import ComponentSpec, read_csv, write_ssd
    from orchestrator.dcp.master import parse_swap
    from orchestrator.run import RunOptions, run_system

    slave = CapturedSlave("railcosim_master_dcplib_slave_nrt.json")
    description = tmp_path / "dcplib_nrt.dcpx"
    description.write_text(_description_with_nrt(tmp_path).read_text().replace('port="8080"', f'port="{slave.port}"'))
    system = tmp_path / "sine"
    write_ssd(system, "sine", [ComponentSpec("ex", str(test_fmus / "TestSine.fmu"), 0.01)], [], stop_time=1.0)
    slave.start()
    try:
        result = run_system(system, RunOptions(
            output_dir=tmp_path / "out", overrides={"ex.a": "0.25"}, stop_time=1.0,
            swaps={"ex": parse_swap(f"ex=dcp://127.0.0.1:{slave.port}?dcpx={description}")}))
    finally:
        slave.close()
    assert slave.mismatches == []
    assert result.summary["completed"] and result.summary["hil"]["ex"]["lost"] == 0
    header, rows = read_csv(tmp_path / "out" / "results.csv")
    assert list(rows[:, header.index("ex.y")]) == [math.sin(0.25)] + [math.sin(10 * k - 1 + 0.25) for k in range(1, 11)]


def test_dcplib_master_stepped_the_traction_fmu_by_its_own_step():
    """The recorded session (DCPLib's example master, unchanged, against `railcosim dcp-slave
    Traction.fmu --real-time`): the master took the first resolution offered, which is the FMU's
    own 0.5 s step, and the slave stepped and sent its output (to itself, the example's loop)
    every 0.5 s: no 1 ns steps, no request refused."""
    captured = datagrams("dcplib_master_railcosim_traction_srt.json")
    times = [d["t"] for d in load("dcplib_master_railcosim_traction_srt.json")["datagrams"]]
    pdus = [(sender, to, decode(data)) for sender, to, data in captured]
    assert not any(p.type_id == PduType.RSP_nack for _, _, p in pdus)
    res = next(p for _, _, p in pdus if p.type_id == PduType.CFG_time_res)
    steps = next(p for _, _, p in pdus if p.type_id == PduType.CFG_steps)
    assert (res.numerator, res.denominator, steps.steps) == (1, 2, 1)
    looped = [(t, p) for t, (sender, to, p) in zip(times, pdus) if p.type_id == PduType.DAT_input_output]
    assert all(sender == to == "slave" for sender, to, p in pdus if p.type_id == PduType.DAT_input_output)
    assert [p.pdu_seq_id for _, p in looped] == list(range(len(looped))) and len(looped) >= 14
    gaps = [b - a for (a, _), (b, _) in zip(looped[1:], looped[2:])]     # the first is the synchronisation's
    assert all(0.45 < g < 0.55 for g in gaps), gaps

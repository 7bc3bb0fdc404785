"""The orchestrator as DCP master (orchestrator/dcp/master.py): a component swapped for a remote DCP
slave gives the run it gives with its FMU; losses are counted and put the outputs at their
fail-safe values; a slave that is not there ends the run in one line, exit 2.

The slave here is written in the test from a hand-built .dcpx in the standard's example
layout with its own variables (not one of ours): a step counter that echoes its input, served
in a thread over UDP on loopback with the PDUs of orchestrator/dcp/pdu.py.
"""
import random
import socket
import subprocess
import sys
import threading

import numpy as np
import pytest

from helpers import REPO, ComponentSpec, ConnectionSpec, cli_environment, railcosim, read_csv, write_ssd
from orchestrator.verdicts.verdict import railway_verdicts
from orchestrator.dcp import pdu as P
from orchestrator.errors import UserError
from orchestrator.dcp.master import DEFAULT_DEADLINE_MS, parse_swap
from orchestrator.run import RunOptions, run_system
from orchestrator.validation import problems_of

DCPX = """<?xml version="1.0" encoding="UTF-8"?>
<dcpSlaveDescription dcpMajorVersion="1" dcpMinorVersion="0" dcpSlaveName="counter"
    uuid="2f1c1d7e-5a7b-4c1e-9f0e-3b8f5d1a6c42">
  <OpMode><NonRealTime defaultSteps="10" fixedSteps="false" minSteps="1" maxSteps="1000"/></OpMode>
  <TimeRes><Resolution numerator="1" denominator="1000" fixed="true" recommended="true"/></TimeRes>
  <TransportProtocols><UDP_IPv4>
    <Control host="127.0.0.1" port="{port}"/>
    <DAT_input_output host="127.0.0.1"><AvailablePortRange from="2048" to="65535"/></DAT_input_output>
  </UDP_IPv4></TransportProtocols>
  <CapabilityFlags canAcceptConfigPdus="true" canHandleReset="false" canHandleVariableSteps="false"
      canMonitorHeartbeat="false" canProvideLogOnRequest="false" canProvideLogOnNotification="false"/>
  <Variables>
    <Variable name="u" valueReference="10"><Input><Float64 start="0"/></Input></Variable>
    <Variable name="steps" valueReference="11"><Output><Int32 start="0"/></Output></Variable>
    <Variable name="t_end" valueReference="12"><Output><Float64 start="0"/></Output></Variable>
    <Variable name="u_seen" valueReference="13"><Output><Float64 start="0"/></Output></Variable>
    <Variable name="fail_at" valueReference="14"><Parameter><Float64 start="-1"/></Parameter></Variable>
  </Variables>
</dcpSlaveDescription>
"""


class CounterSlave(threading.Thread):
    """A DCP slave (non-real-time) of a step counter: steps += 1, t_end = time after the step,
    u_seen = u. ``drop`` is the share of its output DAT PDUs it does not send."""

    def __init__(self, drop=0.0, answer=True, noise=False, intruder=False):
        super().__init__(daemon=True)
        self.noise = noise          # before each outputs PDU: malformed, truncated, oversized, stale ones
        # before each outputs PDU, the same PDU with other values from a third socket
        self.intruder = socket.socket(socket.AF_INET, socket.SOCK_DGRAM) if intruder else None
        self.spoofed = 0
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.port = self.sock.getsockname()[1]
        self.drop, self.answer = drop, answer
        self.random = random.Random(7)
        self.state = P.State.ALIVE
        self.inputs, self.outputs = {}, {}
        self.values = {10: 0.0, 11: 0, 12: 0.0, 13: 0.0}
        self.types = {10: P.DataType.float64, 11: P.DataType.int32, 12: P.DataType.float64, 13: P.DataType.float64}
        self.resolution = 0.001
        self.elapsed = 0                # steps of the time resolution done
        self.dropped = 0
        self.states_seen = []
        self.target = None
        self.seq = 0

    def run(self):
        while True:
            try:
                data, master = self.sock.recvfrom(65535)
            except OSError:
                return
            if not self.answer:
                continue
            message = P.decode(data)
            kind = message.type_id
            if kind == P.PduType.DAT_input_output:
                values = P.PayloadCodec([(self.types[vr], 1) for _, vr in sorted(self.inputs.items())]).decode(message.payload)
                for (_, vr), value in zip(sorted(self.inputs.items()), values):
                    self.values[vr] = float(value[0])
                continue
            self.sock.sendto(P.Pdu(P.PduType.RSP_ack, resp_seq_id=message.pdu_seq_id, sender=1).encode(), master)
            if kind == P.PduType.CFG_time_res:
                self.resolution = message.numerator / message.denominator
            elif kind == P.PduType.CFG_input:
                self.inputs[message.pos] = message.target_vr
            elif kind == P.PduType.CFG_output:
                self.outputs[message.pos] = message.source_vr
            elif kind == P.PduType.CFG_target_network_information:
                self.target = (message.ip_address, message.port)
            elif kind == P.PduType.STC_register:
                self._go(master, P.State.CONFIGURATION)
            elif kind == P.PduType.STC_prepare:
                self._go(master, P.State.PREPARING, P.State.PREPARED)
            elif kind == P.PduType.STC_configure:
                self._go(master, P.State.CONFIGURING, P.State.CONFIGURED)
            elif kind == P.PduType.STC_initialize:
                self._go(master, P.State.INITIALIZING, P.State.INITIALIZED)
            elif kind == P.PduType.STC_send_outputs:
                back = P.State.CONFIGURED if self.state == P.State.INITIALIZED else P.State.RUNNING
                self._go(master, P.State.SENDING_I if back == P.State.CONFIGURED else P.State.SENDING_D)
                self._send_outputs()
                self._go(master, back)
            elif kind == P.PduType.STC_run:
                self._go(master, P.State.SYNCHRONIZING, P.State.SYNCHRONIZED) if self.state == P.State.CONFIGURED \
                    else self._go(master, P.State.RUNNING)
            elif kind == P.PduType.STC_do_step:
                # t + h as a master on integer nanoseconds computes them (1 ms resolution)
                t_s, h_s = self.elapsed * 1_000_000 / 1e9, message.steps * 1_000_000 / 1e9
                self.elapsed += message.steps
                self.values[11] += 1
                self.values[12] = t_s + h_s
                self.values[13] = self.values[10]
                self._go(master, P.State.COMPUTING, P.State.COMPUTED)
            elif kind == P.PduType.STC_stop:
                self._go(master, P.State.STOPPING, P.State.STOPPED)
            elif kind == P.PduType.STC_deregister:
                self._go(master, P.State.ALIVE)

    def _go(self, master, *states):
        for state in states:
            self.state = state
            self.states_seen.append(state)
            self.sock.sendto(P.Pdu(P.PduType.NTF_state_changed, sender=1, state_id=state).encode(), master)

    def _send_outputs(self):
        if self.state == P.State.SENDING_D and self.random.random() < self.drop:
            self.dropped += 1
            return
        order = [vr for _, vr in sorted(self.outputs.items())]
        payload = P.PayloadCodec([(self.types[vr], 1) for vr in order]).encode([self.values[vr] for vr in order])
        if self.noise and self.seq > 2:
            stale = P.Pdu(P.PduType.DAT_input_output, pdu_seq_id=self.seq - 2, data_id=2, payload=payload).encode()    # out of sequence: older
            for junk in (b"\xff\x00", stale[:5], bytes([0xF0]) + bytes(60000), stale, b"", bytes([0xB0, 1])):
                self.sock.sendto(junk, self.target)
        self.seq = P.next_seq(self.seq)
        if self.intruder is not None and self.state == P.State.SENDING_D:
            forged = P.PayloadCodec([(self.types[vr], 1) for vr in order]).encode([999 for _ in order])
            self.intruder.sendto(P.Pdu(P.PduType.DAT_input_output, pdu_seq_id=self.seq, data_id=2,
                                       payload=forged).encode(), self.target)
            self.spoofed += 1
        self.sock.sendto(P.Pdu(P.PduType.DAT_input_output, pdu_seq_id=self.seq, data_id=2, payload=payload).encode(), self.target)


@pytest.fixture
def counter_slave(tmp_path):
    def start(**options):
        slave = CounterSlave(**options)
        dcpx = tmp_path / f"counter_{slave.port}.dcpx"
        dcpx.write_text(DCPX.format(port=slave.port))
        slave.start()
        return slave, dcpx
    return start


def _system(tmp_path, test_fmus, stop_time=2.0):
    system = tmp_path / "pair"
    write_ssd(system, "pair", [
        ComponentSpec("src", str(test_fmus / "TestCounter.fmu"), 0.01),
        ComponentSpec("dut", str(test_fmus / "TestCounter.fmu"), 0.02),
    ], [ConnectionSpec("src.t_end", "dut.u")], stop_time=stop_time)
    return system


def test_a_foreign_dcp_slave_stands_in_for_a_component_with_the_same_results(tmp_path, test_fmus, counter_slave):
    slave, dcpx = counter_slave()
    system = _system(tmp_path, test_fmus)
    run_system(system, RunOptions(output_dir=tmp_path / "fmu"))
    swap = parse_swap(f"dut=dcp://127.0.0.1:{slave.port}?dcpx={dcpx}")
    result = run_system(system, RunOptions(output_dir=tmp_path / "dcp", swaps={"dut": swap}))
    header, reference = read_csv(tmp_path / "fmu" / "results.csv")
    header_dcp, swapped = read_csv(tmp_path / "dcp" / "results.csv")
    assert header == header_dcp
    np.testing.assert_array_equal(swapped, reference)      # every column, every row
    hil = result.summary["hil"]["dut"]
    assert hil["mode"] == "NRT" and hil["lost"] == 0 and hil["late"] == 0
    assert hil["exchanges"] == 100                          # 2 s in 20 ms steps
    assert hil["rtt_median_ms"] <= hil["rtt_p99_ms"] <= hil["rtt_max_ms"]
    assert hil["pdus_sent"] > 3 * 100 and hil["pdus_received"] > 3 * 100
    # the standard's sequence from register to deregister
    seen = [s for s in slave.states_seen if s not in (P.State.COMPUTING, P.State.COMPUTED, P.State.SENDING_D,
                                                       P.State.RUNNING)]
    assert seen[:5] == [P.State.CONFIGURATION, P.State.PREPARING, P.State.PREPARED, P.State.CONFIGURING,
                        P.State.CONFIGURED]
    assert seen[-3:] == [P.State.STOPPING, P.State.STOPPED, P.State.ALIVE]


def _swapped_run_equals_the_fmus(tmp_path, test_fmus, slave, dcpx) -> dict:
    """The system run with its FMU and with the slave swapped in: results.csv byte-identical;
    the swapped component's summary.json `hil` entry."""
    system = _system(tmp_path, test_fmus, stop_time=0.5)
    run_system(system, RunOptions(output_dir=tmp_path / "fmu"))
    swap = parse_swap(f"dut=dcp://127.0.0.1:{slave.port}?dcpx={dcpx}")
    result = run_system(system, RunOptions(output_dir=tmp_path / "dcp", swaps={"dut": swap}))
    assert (tmp_path / "dcp" / "results.csv").read_bytes() == (tmp_path / "fmu" / "results.csv").read_bytes()
    return result.summary["hil"]["dut"]


def test_malformed_truncated_oversized_and_stale_pdus_never_disturb_the_master(tmp_path, test_fmus, counter_slave):
    slave, dcpx = counter_slave(noise=True)
    hil = _swapped_run_equals_the_fmus(tmp_path, test_fmus, slave, dcpx)
    assert hil["lost"] == 0 and hil["late"] >= 20           # each stale PDU counted and dropped


def test_outputs_from_any_other_address_than_the_slaves_are_ignored_and_counted(tmp_path, test_fmus, counter_slave):
    """A third socket sends the master each of the slave's outputs PDUs first, with the same
    sequence id and other values: none is taken, each is counted, the run is the FMU's run."""
    slave, dcpx = counter_slave(intruder=True)
    hil = _swapped_run_equals_the_fmus(tmp_path, test_fmus, slave, dcpx)
    assert slave.spoofed == 25 and hil["ignored"] == 25 and hil["late"] == 0 and hil["lost"] == 0


def test_lost_outputs_are_counted_and_the_run_goes_on(tmp_path, test_fmus, counter_slave):
    slave, dcpx = counter_slave(drop=0.05)
    system = _system(tmp_path, test_fmus)
    swap = parse_swap(f"dut=dcp://127.0.0.1:{slave.port}?dcpx={dcpx}&deadline_ms=20")
    result = run_system(system, RunOptions(output_dir=tmp_path / "out", swaps={"dut": swap}))
    hil = result.summary["hil"]["dut"]
    assert slave.dropped > 0
    assert hil["lost"] == slave.dropped == hil["fail_safe_steps"]
    assert hil["exchanges"] + hil["lost"] == 100


def test_an_unreachable_slave_ends_the_run_in_one_line_with_exit_2(tmp_path, test_fmus, counter_slave):
    slave, dcpx = counter_slave(answer=False)
    system = _system(tmp_path, test_fmus, stop_time=0.2)
    code, _, err = railcosim("run", system, "--no-build", "--output", tmp_path / "out",
                             "--swap", f"dut=dcp://127.0.0.1:{slave.port}?dcpx={dcpx}&timeout_s=0.5")
    assert code == 2
    assert err.count("\n") == 1 and "dut" in err and f"dcp://127.0.0.1:{slave.port}" in err and "answer" in err
    # paced, the same failure says nothing of a pace it never had to keep
    code, _, err = railcosim("run", system, "--no-build", "--output", tmp_path / "paced", "--real-time",
                             "--swap", f"dut=dcp://127.0.0.1:{slave.port}?dcpx={dcpx}&timeout_s=0.5")
    assert code == 2 and err.count("\n") == 1 and "pace" not in err


@pytest.mark.parametrize("text, complaint", [
    ("dut", "expected NAME=dcp://"),
    ("dut=http://127.0.0.1:5000", "only dcp://"),
    ("dut=dcp://127.0.0.1", "HOST:PORT"),
    ("dut=dcp://127.0.0.1:5000?deadline_ms=0", "deadline_ms"),
    ("dut=dcp://127.0.0.1:5000?speed=1", "unknown option"),
])
def test_a_malformed_swap_is_one_clear_error(text, complaint):
    with pytest.raises(UserError, match=complaint):
        parse_swap(text)


def test_a_swap_of_a_missing_component_or_dcpx_is_refused_before_the_run(tmp_path, test_fmus, counter_slave):
    slave, dcpx = counter_slave()
    system = _system(tmp_path, test_fmus, stop_time=0.1)
    with pytest.raises(UserError, match="no component 'rx'"):
        run_system(system, RunOptions(output_dir=tmp_path / "a",
                                      swaps={"rx": parse_swap(f"rx=dcp://127.0.0.1:{slave.port}?dcpx={dcpx}")}))
    with pytest.raises(UserError, match="give the slave's description with"):
        run_system(system, RunOptions(output_dir=tmp_path / "b",
                                      swaps={"dut": parse_swap(f"dut=dcp://127.0.0.1:{slave.port}")}))


# ---- our emulator (railcosim dcp-slave) in a process of its own ---------------------------------
@pytest.fixture
def emulator(tmp_path, product_fmus):
    """Start ``railcosim dcp-slave UNIT.fmu`` on a free port; returns the --swap address."""
    processes = []

    def start(unit, *options):
        dcpx = tmp_path / f"{unit}_{len(processes)}.dcpx"
        process = subprocess.Popen(
            [sys.executable, "-m", "orchestrator", "dcp-slave", str(product_fmus / f"{unit}.fmu"), "--port", "0",
             "--dcpx-out", str(dcpx), "--quiet", *options],
            cwd=REPO, env=cli_environment(), stdout=subprocess.PIPE, text=True)
        processes.append(process)
        line = process.stdout.readline()          # LISTENING HOST:PORT once it serves
        assert line.startswith("LISTENING"), line
        return f"dcp://{line.split()[1]}?dcpx={dcpx}"

    yield start
    for process in processes:
        process.kill()
        process.wait()


def _free_run(tmp_path, product_fmus, tag, stop_time, swaps=()):
    options = RunOptions(output_dir=tmp_path / tag, stop_time=stop_time, fmu_dirs=[product_fmus],
                         summaries=railway_verdicts, swaps={s.component: s for s in swaps})
    return run_system(REPO / "ssp" / "free_run", options)


#: simulated seconds of the swapped free_run in a test: the receiver over 120 s (the train
#: departs, passes joints and signals); the ATO over its first 30 s (the whole run, with its
#: stops and verdict, is benchmarks/bench_hil.py's)
RECEIVER_SWAP_S = 120.0
SWAP_TEST_S = 30.0


def _free_run_swapped(tmp_path, product_fmus, seconds, swap):
    """free_run with its FMUs ("fmu") and with one component swapped for a DCP slave ("dcp");
    the two results.csv are the same bytes. → (reference, swapped)"""
    reference = _free_run(tmp_path, product_fmus, "fmu", seconds)
    swapped = _free_run(tmp_path, product_fmus, "dcp", seconds, [parse_swap(swap)])
    assert (tmp_path / "dcp" / "results.csv").read_bytes() == (tmp_path / "fmu" / "results.csv").read_bytes()
    return reference, swapped


def test_the_receiver_swapped_for_its_dcp_emulator_gives_identical_results(tmp_path, product_fmus, emulator):
    address = emulator("LocoReceiver")
    reference, swapped = _free_run_swapped(tmp_path, product_fmus, RECEIVER_SWAP_S, f"rx={address}")
    assert swapped.summary["receivers"] == reference.summary["receivers"]
    hil = swapped.summary["hil"]["rx"]
    assert hil["lost"] == 0 and hil["exchanges"] == swapped.steps_taken["rx"]


def test_lost_receiver_outputs_show_restrictive_and_nothing_unsafe(tmp_path, product_fmus, emulator):
    address = emulator("LocoReceiver", "--drop-data", "0.05", "--seed", "3")
    result = _free_run(tmp_path, product_fmus, "loss", 20.0, [parse_swap(f"rx={address}&deadline_ms=200")])
    hil = result.summary["hil"]["rx"]
    steps = result.steps_taken["rx"]
    assert 0.02 * steps < hil["lost"] < 0.10 * steps          # about 5 % of the frames
    assert hil["fail_safe_steps"] == hil["lost"] and hil["exchanges"] + hil["lost"] == steps
    receiver = result.summary["receivers"][0]
    assert receiver["wrong_side_failures"] == 0 and receiver["unsafe_indications"] == 0
    # a lost frame shows the no-code indication at once (never the last permissive one held):
    # the samples taken at lost frames (about 5 % of them, after the first code) are restrictive
    header, data = read_csv(tmp_path / "loss" / "results.csv")
    valid, aspect, v_permitted = (data[:, header.index(f"rx.{name}")] for name in ("code_valid", "aspect", "v_permitted"))
    running = np.arange(len(valid)) >= np.argmax(valid == 1)
    lost_samples = running & (valid == 0)
    assert lost_samples.any()
    assert np.all(aspect[lost_samples] <= 1) and np.all(v_permitted[lost_samples] == 0)


def test_the_ato_swapped_for_its_dcp_emulator_drives_the_same_train(tmp_path, product_fmus, emulator):
    # the first SWAP_TEST_S of free_run (the whole run, with its stops and verdict:
    # benchmarks/bench_hil.py ato)
    address = emulator("AtoController")
    reference, swapped = _free_run_swapped(tmp_path, product_fmus, SWAP_TEST_S, f"ato={address}")
    assert swapped.summary["trains"] == reference.summary["trains"]
    assert swapped.summary["hil"]["ato"]["lost"] == 0


def _declared_system(tmp_path, test_fmus, dcpx, port: int):
    """The pair with ``dut`` declared in the SSD as a DCP slave (its .dcpx, host and port)."""
    from lxml import etree

    system = tmp_path / "declared"
    write_ssd(system, "declared", [
        ComponentSpec("src", str(test_fmus / "TestCounter.fmu"), 0.01),
        ComponentSpec("dut", str(test_fmus / "TestCounter.fmu"), 0.02),
    ], [ConnectionSpec("src.t_end", "dut.u")], stop_time=2.0)
    ssd = system / "SystemStructure.ssd"
    tree = etree.parse(str(ssd))
    rcs = "http://railcosim.org/SSP/1"
    for component in tree.iter("{*}Component"):
        if component.get("name") == "dut":
            component.set("type", "application/x-dcp-slave")
            component.set("source", str(dcpx))
            annotation = etree.SubElement(component.find("{*}Annotations"),
                                          "{http://ssp-standard.org/SSP1/SystemStructureCommon}Annotation",
                                          type="org.railcosim")
            etree.SubElement(annotation, f"{{{rcs}}}DcpSlave", host="127.0.0.1", port=str(port))
    tree.write(str(ssd))
    return system


def test_a_dcp_slave_declared_in_the_ssd_is_a_component(tmp_path, test_fmus, counter_slave):
    slave, dcpx = counter_slave()
    reference = _system(tmp_path, test_fmus)
    run_system(reference, RunOptions(output_dir=tmp_path / "fmu"))
    system = _declared_system(tmp_path, test_fmus, dcpx, slave.port)
    result = run_system(system, RunOptions(output_dir=tmp_path / "dcp"))
    assert (tmp_path / "dcp" / "results.csv").read_bytes() == (tmp_path / "fmu" / "results.csv").read_bytes()
    assert result.summary["hil"]["dut"]["exchanges"] == 100


def test_validate_checks_a_declared_dcp_slave_without_contacting_it(tmp_path, test_fmus):
    """`railcosim validate` reads and checks the .dcpx (its ports against the connections) but
    registers with no slave: validating a hardware-in-the-loop system must not start the rig
    (our emulator would even end after the deregistration)."""
    listener = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    listener.bind(("127.0.0.1", 0))
    listener.settimeout(0.2)
    port = listener.getsockname()[1]
    dcpx = tmp_path / "counter.dcpx"
    dcpx.write_text(DCPX.format(port=port))
    try:
        system = _declared_system(tmp_path, test_fmus, dcpx, port)
        assert problems_of(system, RunOptions()) == []
        with pytest.raises(socket.timeout):
            listener.recvfrom(2048)                   # nothing was sent to the slave
        dcpx.write_text(DCPX.format(port=port).replace('name="u"', 'name="w"'))
        problems = problems_of(system, RunOptions())
        assert len(problems) == 1 and "u" in problems[0] and "dut" in problems[0], problems
    finally:
        listener.close()


# ---- inputs set on a slave, and soft real time --------------------------------------------------
def _sine_emulator(tmp_path, test_fmus, *options):
    """``railcosim dcp-slave TestSine.fmu`` (y = sin(k + a)) in its own process; → (process, --swap text)."""
    dcpx = tmp_path / f"sine_{len(list(tmp_path.glob('sine_*.dcpx')))}.dcpx"
    process = subprocess.Popen(
        [sys.executable, "-m", "orchestrator", "dcp-slave", str(test_fmus / "TestSine.fmu"), "--port", "0",
         "--dcpx-out", str(dcpx), *options],
        cwd=REPO, env=cli_environment(), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    line = process.stdout.readline()
    assert line.startswith("LISTENING"), line
    return process, f"ex=dcp://{line.split()[1]}?dcpx={dcpx}"


def _sine_system(tmp_path, test_fmus):
    system = tmp_path / "sine"
    write_ssd(system, "sine", [ComponentSpec("ex", str(test_fmus / "TestSine.fmu"), 0.01)], [])
    return system


def _finish(process):
    try:
        process.wait(timeout=30)
    finally:
        if process.poll() is None:
            process.kill()
    return process.communicate()[1]


def test_an_input_set_on_a_dcp_slave_travels_as_data(tmp_path, test_fmus):
    """`--set ex.a=0.25` on an input no connection feeds: sent in every inputs PDU (DCP's
    CFG_parameter is for parameters only, and a reference slave refuses it for an input), so
    the swapped run is the FMU's own run, bit for bit."""
    system = _sine_system(tmp_path, test_fmus)
    run_system(system, RunOptions(output_dir=tmp_path / "fmu", stop_time=1.0, overrides={"ex.a": "0.25"}))
    process, swap = _sine_emulator(tmp_path, test_fmus, "--quiet")
    result = run_system(system, RunOptions(output_dir=tmp_path / "dcp", stop_time=1.0, overrides={"ex.a": "0.25"},
                                           swaps={"ex": parse_swap(swap)}))
    _finish(process)
    assert (tmp_path / "dcp" / "results.csv").read_bytes() == (tmp_path / "fmu" / "results.csv").read_bytes()
    header, data = read_csv(tmp_path / "dcp" / "results.csv")
    assert data[1, header.index("ex.y")] == np.sin(9 + 0.25)          # the 10th step, a = 0.25
    assert result.summary["hil"]["ex"]["lost"] == 0


def _slave_counts(stderr: str) -> dict:
    """The counts of the emulator's last line (``… DAT out N (dropped D) …``)."""
    line = stderr.strip().splitlines()[-1]
    words = line.replace(",", "").replace("(", "").replace(")", "").split()
    return {"sent": int(words[words.index("out") + 1]), "dropped": int(words[words.index("dropped") + 1])}


def soft_real_time_run(tmp_path, test_fmus, stop_time_s: float):
    """A soft-real-time sine slave on loopback, the master paced to the wall clock for
    ``stop_time_s``: (summary.json's ``hil`` section, the slave's own counts)."""
    process, swap = _sine_emulator(tmp_path, test_fmus, "--real-time")
    result = run_system(_sine_system(tmp_path, test_fmus),
                        RunOptions(output_dir=tmp_path / "srt", stop_time=stop_time_s, overrides={"ex.a": "0.25"},
                                   swaps={"ex": parse_swap(swap)}))
    return result.summary["hil"]["ex"], _slave_counts(_finish(process))


def test_soft_real_time_on_loopback_accounts_for_every_step(tmp_path, test_fmus):
    """A soft-real-time slave on loopback, the master paced to the wall clock: every step either
    uses outputs that arrived within the deadline (an exchange, its age recorded) or falls back
    to the fail-safe values, and the ages are reported in order, never negative. Whether nothing
    is lost over a minute depends on the machine's load, so it is measured, not asserted:
    benchmarks/bench_hil.py sine_srt (docs/performance.md#hardware-in-the-loop-dcp)."""
    hil, counts = soft_real_time_run(tmp_path, test_fmus, 2.0)
    assert hil["mode"] == "SRT"
    assert hil["exchanges"] + hil["fail_safe_steps"] == 200          # 2 s in 10 ms steps
    assert hil["deadline_ms"] == DEFAULT_DEADLINE_MS
    assert hil["exchanges"] == 0 or 0.0 <= hil["rtt_median_ms"] <= hil["rtt_p99_ms"] <= hil["rtt_max_ms"]
    assert counts["sent"] > 0 and 0 <= counts["dropped"] <= counts["sent"]


def test_soft_real_time_counts_every_output_the_slave_did_not_send(tmp_path, test_fmus):
    """Outputs the slave leaves unsent (--drop-data) are all counted lost, from the gaps in their
    sequence ids; a single missing period leaves outputs younger than the deadline, so no step
    needs the fail-safe values."""
    process, swap = _sine_emulator(tmp_path, test_fmus, "--real-time", "--drop-data", "0.02", "--seed", "5")
    result = run_system(_sine_system(tmp_path, test_fmus),
                        RunOptions(output_dir=tmp_path / "drop", stop_time=10.0, overrides={"ex.a": "0.25"},
                                   swaps={"ex": parse_swap(swap)}))
    counts = _slave_counts(_finish(process))
    hil = result.summary["hil"]["ex"]
    assert counts["dropped"] >= 5
    # every drop is seen as a gap, but one in the last period before STC_stop has no later
    # output to show it
    assert counts["dropped"] - 1 <= hil["lost"] <= counts["dropped"]
    assert hil["fail_safe_steps"] == 0

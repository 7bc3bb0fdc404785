"""Issue 34: the track circuits as SPICE netlists and checked by ngspice (docs/rail_line.md,
checked against ngspice). The netlist writer and the raw-file reader run without ngspice; the
numerical cross-checks run the real ngspice and are skipped, saying how to install it, where it
is not on PATH (CI installs it: .ci/run)."""
import re
import shutil

import numpy as np
import pytest

from fmus.data.loader import load_line
from fmus.rail_line.track_circuit import CircuitParameters, Faults, TrackCircuit, rail_impedance
from orchestrator.circuits.netlist import (axle_netlist, lumped_netlist, staircase_points,
                                           tran_source)
from orchestrator.circuits.ngspice import read_raw
from helpers import REPO, railcosim

NGSPICE = shutil.which("ngspice")
needs_ngspice = pytest.mark.skipif(NGSPICE is None, reason="ngspice not on PATH: install it to run the SPICE "
                                                           "cross-checks (Debian/Ubuntu: apt-get install ngspice)")
THROAT_LINE = REPO / "ssp" / "joints_at_speed" / "resources" / "throat_line.json"
LIGHT_ENGINE = np.array([0.0, 2.0, 4.0, 8.66, 10.66, 12.66])


def _cards(netlist):
    """Element name → its fields, from the netlist text (continuation and comment lines left out)."""
    cards = {}
    for line in netlist.text().splitlines()[1:]:
        if line and line[0] not in "*.+":
            fields = line.split()
            cards[fields[0].lower()] = fields[1:]
    return cards


def _circuit(ballast=1.0):
    return TrackCircuit(7800.0, 10400.0, 1.0, CircuitParameters(ballast_ohm_km=ballast))


# ---- the netlist writer ---------------------------------------------------------------------------
def test_the_lumped_netlist_is_the_rail_lines_network_element_for_element():
    circuit = _circuit()
    faults = Faults(0.0, 9010.0, False)
    netlist = lumped_netlist(circuit, [10, 11, 12], [12], faults, 50.0, 2.5)
    cards = _cards(netlist)
    segment_km = (circuit.feed_m - circuit.start_m) / circuit.segments / 1000.0
    r, l = rail_impedance(circuit.params, 50.0)
    for k in range(circuit.segments):
        a, m = cards[f"r{k}"][:2]
        assert (a, cards[f"l{k}"][1]) == (f"n{k}", f"n{k + 1}") and m == cards[f"l{k}"][0]
        broken = circuit.nodes_m[k] <= 9010.0 < circuit.nodes_m[k + 1]
        assert float(cards[f"r{k}"][2]) == pytest.approx(1e9 if broken else r * segment_km)
        assert float(cards[f"l{k}"][2]) == pytest.approx(l * segment_km)
    ballast_conductance = sum(1.0 / float(fields[2]) for name, fields in cards.items() if name.startswith("rg"))
    assert ballast_conductance == pytest.approx((circuit.feed_m - circuit.start_m) / 1000.0 / 1.0)
    assert [name for name in cards if name.startswith("rsh")] == ["rsh10", "rsh11", "rsh12"]
    assert cards["etx"] == ["src", "0", "u", "0", "2.5"] and cards["rfeed"][1:] == [f"n{circuit.segments}", "0.5"]
    assert cards["rrelay"] == ["n0", "0", "4"] and cards["lbondr"] == ["br", "0", "0.02"]
    assert netlist.probes["head0"] == [(-1.0, "i(l12)")] and netlist.probes["relay"] == [(1.0, "v(n0)")]
    opened = _cards(lumped_netlist(circuit, [], [], Faults(feed_open=True)))
    assert "etx" not in opened and opened["ropen"][:2] == [f"n{circuit.segments}", "0"]


def test_the_axle_netlist_puts_every_wheelset_at_its_axle():
    circuit = _circuit()
    head = circuit.feed_m + 0.5                     # the first axle beyond the feed leads
    axles = [head - o for o in LIGHT_ENGINE]
    netlist = axle_netlist(circuit, axles, [head], Faults(), 50.0, 2.5, segment_m=2.0)
    cards = _cards(netlist)
    # node positions: the pieces' lengths summed from the relay end, then the overhang's
    position = {"p0": circuit.start_m}
    for name in sorted((n for n in cards if re.fullmatch(r"l[pq]\d+", n)), key=lambda n: (n[1], int(n[2:]))):
        a, b = cards["r" + name[1:]][0], cards[name][1]
        length_m = float(cards[name][2]) / (rail_impedance(circuit.params, 50.0)[1] / 1000.0)
        assert length_m <= 2.0 + 1e-9
        position[b] = position[a] + length_m
    at = sorted(position[cards[n][0]] for n in cards if n.startswith("rax"))
    assert at == pytest.approx(sorted(axles), abs=1e-6)
    assert max(position.values()) == pytest.approx(circuit.end_m)     # the overhang up to the exit joint
    assert netlist.probes["head0"][0] == (1.0, "i(lq0)")               # the current into the overhang


def test_the_staircase_holds_each_sample_from_its_instant():
    times = np.arange(5) * 0.25e-3
    points = staircase_points(times, np.array([0.0, 1.0, 1.0, -2.0, -2.0]), 1e-8)
    assert points == [(0.0, 0.0), (0.25e-3 - 1e-8, 0.0), (0.25e-3, 1.0), (0.75e-3 - 1e-8, 1.0), (0.75e-3, -2.0)]
    netlist = tran_source(lumped_netlist(_circuit(), [], []), times, np.array([0.0, 1.0, 1.0, -2.0, -2.0]),
                          1e-3, 0.25e-3)
    assert netlist.source[1] == "Vu u 0 PWL(" and netlist.analysis[-1].startswith(".tran 0.00025 0.001")


def test_the_raw_reader_reads_complex_and_real_analyses():
    text = ("Title: t\nDate: today\nPlotname: AC Analysis\nFlags: complex\nNo. Variables: 3\nNo. Points: 1\n"
            "Variables:\n\t0\tfrequency\tfrequency\n\t1\tv(n0)\tvoltage\n\t2\ti(l3)\tcurrent\nValues:\n"
            "0\t5.0e+01,0.0e+00\n\t1.5e+00,-2.0e-01\n\t-3.0e-02,4.0e-02\n\n"
            "Title: t\nDate: today\nPlotname: Transient Analysis\nFlags: real\nNo. Variables: 2\nNo. Points: 2\n"
            "Variables:\n\t0\ttime\ttime\n\t1\tv(n0)\tvoltage\nValues:\n0\t0.0\n\t1.0\n1\t2.5e-04\n\t-1.0\n")
    ac, tran = read_raw(text)
    assert ac.plot == "AC Analysis" and ac.vectors["v(n0)"][0] == 1.5 - 0.2j
    assert ac.value([(-1.0, "i(l3)"), (2.0, "v(n0)")])[0] == pytest.approx(3.03 - 0.44j)
    assert tran.vectors["time"].tolist() == [0.0, 2.5e-4] and tran.vectors["v(n0)"].tolist() == [1.0, -1.0]
    with pytest.raises(ValueError, match="points of 2 vectors"):
        read_raw(text.replace("\t-1.0\n", ""))


def test_netlist_command_writes_a_section_and_refuses_bad_input_in_one_line(tmp_path):
    out = tmp_path / "s4.cir"
    code, stdout, stderr = railcosim("netlist", "free_run", "--section", "4", "--train",
                                     "passenger_chs7.json@9000", "-o", out)
    assert code == 0, stderr
    text = out.read_text()
    assert text.startswith("railcosim: default_line.json section 4") and "Rsh24 n24 0 0.06" in text
    assert ".ac lin 1 50 50" in text and ".print ac vm(n0)" in text
    for args, message in ((["--section", "9"], "--section 9: the line default_line.json has sections 1–8"),
                          (["--section", "1", "--train", "passenger_chs7.json"], "FILE@HEAD expected"),
                          (["--section", "1", "--time", "30"], "add --results RUN_DIR")):
        code, _, stderr = railcosim("netlist", "free_run", *args)
        assert code == 2 and stderr.count("\n") == 1 and message in stderr, stderr


@pytest.mark.parametrize("args, message", [
    (["--ballast", "nan"], "netlist: --ballast nan: not a finite number"),      # was: the section's own
    (["--ballast", "inf"], "netlist: --ballast inf: not a finite number"),      # was: a netlist ngspice rejects
    (["--ballast", "5000"], "--ballast 5000: a ballast resistance from 0.1 to 1000 Ω·km"),
    (["--frequency", "-50"], "netlist: --frequency -50: must be more than 0"),
    (["--frequency", "nan"], "netlist: --frequency nan: not a finite number"),
    (["--frequency", "inf"], "netlist: --frequency inf: not a finite number"),
    (["--train", "passenger_chs7.json@nan"], "the head position 'nan' is not a finite number"),   # was: left out
    (["--train", "passenger_chs7.json@-inf"], "the head position '-inf' is not a finite number"),
    (["--time", "nan", "--results", "."], "netlist: --time nan: not a finite number"),          # was: the first row
    (["--tran", "inf"], "netlist: --tran inf: not a finite number"),
    (["--wheelsets", "axles", "--segment", "1e-9"], "--segment 1e-09: section 1's 2600 m of rails would be 2.6e+12 "
                                                    "pieces; at most 100000"),        # was: an 18.9 TiB allocation
    (["--wheelsets", "axles", "--segment", "0"], "netlist: --segment 0: must be more than 0"),
    (["-o", "/nonexistent/s1.cir"], "-o /nonexistent/s1.cir: cannot be written"),
])
def test_netlist_options_not_finite_or_out_of_range_are_one_line(tmp_path, args, message):
    code, stdout, stderr = railcosim("netlist", "free_run", "--section", "1", *args, cwd=tmp_path)
    assert code == 2 and stderr.count("\n") == 1 and message in stderr and "Traceback" not in stderr, stderr
    assert stdout == "" and list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("args, message", [
    (["--section", "99"], "--section 99: the line default_line.json has sections 1–8"),      # was: IndexError
    (["--section", "0"], "crosscheck: --section 0: must be at least 1"),
    (["--section", "1", "--train", "passenger_chs7.json@nan"], "is not a finite number"),   # was: passed without it
    (["--time", "inf"], "crosscheck: --time inf: not a finite number"),
])
def test_crosscheck_options_out_of_range_are_one_line(args, message):
    code, _, stderr = railcosim("crosscheck", "spice", "free_run", *args)
    assert code == 2 and stderr.count("\n") == 1 and message in stderr and "Traceback" not in stderr, stderr


@pytest.mark.parametrize("results, args, message", [
    ("time,train.x\n0,100\n0.1,abc\n", [], "results.csv:3: column train.x: 'abc' is not a number"),
    ("time,train.x\n0,100\n0.1\n", [], "results.csv:3: 1 values in a row of 2 columns"),
    ("time,train.x\n0,nan\n", [], "results.csv:2: train.x = nan is not a position"),
    ("time,train.x\n0,100\n0.1,101\n", ["--time", "900"], "--time 900: "),
    ("", [], "results.csv: no header line"),
])
def test_netlist_from_a_results_folder_that_no_run_wrote_is_one_line(tmp_path, results, args, message):
    (tmp_path / "results.csv").write_text(results)
    code, _, stderr = railcosim("netlist", "free_run", "--section", "1", "--results", tmp_path, *args)
    assert code == 2 and stderr.count("\n") == 1 and message in stderr and "Traceback" not in stderr, stderr


# ---- against the real ngspice -------------------------------------------------------------------------
@needs_ngspice
def test_ngspice_solves_the_rail_lines_network_as_we_do():
    from orchestrator.circuits.crosscheck import ac_rows
    rows = ac_rows(load_line(THROAT_LINE), "throat_line", [50.0], [1.0, 200.0], only=3)
    assert rows and all(row.passed() for row in rows), rows
    assert max(max(row.worst.values()) for row in rows) < 1e-9          # the same network: solver precision


@needs_ngspice
def test_ngspice_transient_agrees_with_our_discretised_model():
    from orchestrator.circuits.crosscheck import TRAN_BOUND, tran_check
    result = tran_check(load_line(THROAT_LINE), "throat_line", 3, seconds=0.3, change_s=0.05, enter_s=0.15)
    assert result.samples == 1200 and result.passed(), result
    assert max(result.worst.values()) < TRAN_BOUND / 10


@needs_ngspice
def test_the_wheelset_chain_is_every_axle_in_ngspice_and_the_lumping_is_not():
    from orchestrator.circuits.crosscheck import Train, shipped_train, wheelset_rows
    follower = shipped_train("passenger_chs7.json")
    rows = wheelset_rows(load_line(THROAT_LINE), "throat_line", [Train("light engine", 17.22, LIGHT_ENGINE)],
                         follower, ballasts=[1.0], places=1, only=3)
    (row,) = rows
    assert row.chain_passed(), row.errors
    lumped_low, lumped_high, chain_low, chain_high = row.errors["current 100 m behind"]
    assert lumped_low > 1.0                      # the lumped engine leaves more than twice the code
    assert max(abs(chain_low), abs(chain_high)) < 1e-5


@needs_ngspice
def test_a_written_netlist_runs_in_ngspice_unchanged(tmp_path):
    import subprocess
    out = tmp_path / "s4.cir"
    code, _, stderr = railcosim("netlist", "free_run", "--section", "4", "--wheelsets", "axles",
                                "--train", "passenger_chs7.json@9000", "-o", out)
    assert code == 0, stderr
    done = subprocess.run([NGSPICE, "-b", str(out)], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0 and "vm(p0)" in done.stdout and "Error" not in done.stdout + done.stderr


def test_crosscheck_without_ngspice_says_how_to_install_it():
    code, _, stderr = railcosim("crosscheck", "spice", "free_run", "--section", "1", env={"PATH": "/nonexistent"})
    assert code == 2 and stderr.count("\n") == 1 and "apt-get install ngspice" in stderr, stderr


@needs_ngspice
def test_crosscheck_command_tables_a_section_and_passes():
    code, out, err = railcosim("crosscheck", "spice", "--line", THROAT_LINE, "--section", "4")
    assert code == 0, err + out[-2000:]
    assert "## .ac" in out and "## .tran" in out and "## wheelsets" in out
    assert "| throat_line | 4–6 | 50 | 200 |" in out and "light engine ЧМЭ3" in out
    assert out.rstrip().endswith("every comparison within its bound")

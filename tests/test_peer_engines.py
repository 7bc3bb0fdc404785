"""The shipped systems as written in other engines (docs/interfaces.md#ssp-conventions, "Other
engines"): libcosim (libcosimpy 0.0.6) loads the packed .ssp, steps it at the SSD's own step sizes
and base step and reproduces ``railcosim run --algorithm jacobi``; FMPy's ``simulate_ssp`` makes
every connection. Each engine runs in a process of its own (tests/host/peer_run.py)."""
import csv
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from helpers import railcosim
from orchestrator.systems.shipped import SSP_ROOT

pytest.importorskip("libcosimpy")

RUNNER = Path(__file__).resolve().parent / "host" / "peer_run.py"
# systems whose parameters name data files of their own (resources/ of the system): libcosim passes a
# String parameter as written; the FMU finds the file in its own resources, where packing copies it
OWN_DATA_FILES = ("following", "same_block", "joints_at_speed", "freight_ac", "als_en_following",
                  "fire_dqpsk_following", "alsu", "alsu_following", "tvm430", "tvm430_following", "tvm300", "tvm300_following",
                  "suburban", "suburban_peak", "tvm430_headway")
#: systems of several trains: their receivers are rx1, rx2 …
SEVERAL_TRAINS = ("same_block", "suburban_peak", "tvm430_headway")


@pytest.fixture(scope="module")
def packed(product_fmus, tmp_path_factory):
    """The shipped systems packed as .ssp archives (what `railcosim build` writes to build/)."""
    from orchestrator.packaging.packing import pack_systems

    dest = tmp_path_factory.mktemp("ssp")
    pack_systems(SSP_ROOT, product_fmus, dest)
    return dest


def _peer(engine, ssp, stop_s, interval_s, out, names=()):
    proc = subprocess.run([sys.executable, str(RUNNER), engine, str(ssp), repr(stop_s), repr(interval_s), str(out),
                           *names], capture_output=True, text=True, timeout=600)
    return proc.returncode, proc.stdout, proc.stderr[-3000:]


def _csv(path):
    with open(path) as handle:
        rows = list(csv.reader(handle))
    return rows[0], np.array(rows[1:], dtype=float)


def _ours(tmp_path, system, stop_s, interval_s, *options):
    out = tmp_path / f"ours_{system}"
    code, _, err = railcosim("run", system, "--algorithm", "jacobi", "--no-build", "--stop-time", stop_s,
                             "--output-interval", interval_s, "--output", out, *options)
    assert code == 0, err
    header, data = _csv(out / "results.csv")
    rows = {round(t, 9): i for i, t in enumerate(data[:, 0])}       # the last row of each instant
    return header, data, rows


def _worst(ours, peer, columns, shift_s=0.0):
    """{column: max |ours − peer|} over the peer's rows, ours taken at the peer's time + shift."""
    header, data, rows = ours
    peer_header, peer_data = peer
    index = [rows[round(t + shift_s, 9)] for t in peer_data[:, 0]]
    return {name: float(np.max(np.abs(data[index, header.index(name)] - peer_data[:, peer_header.index(name)])))
            for name in columns}


@pytest.mark.parametrize("system, stop_s", [("ato_only", None), ("free_run", 60.0)])
def test_libcosim_reproduces_railcosim_jacobi(tmp_path, packed, system, stop_s):
    """Every recorded output of the whole run (ato_only: 1100 s) or its first minute (free_run, the
    ALSN chain at 10 ms and the train at 0.5 s) is what `railcosim run --algorithm jacobi` records,
    at every 0.5 s (the train's and ATO's step: between two of their steps libcosim's observer shows
    the values of the step in progress, ours those of the last step completed)."""
    stop_s = stop_s or 1100.0
    ours = _ours(tmp_path, system, stop_s, 0.5)
    columns = ours[0][1:]
    code, out, err = _peer("libcosim", packed / f"{system}.ssp", stop_s, 0.5, tmp_path / "libcosim.csv", columns)
    assert f"{stop_s:g} s simulated" in out, err
    peer = _csv(tmp_path / "libcosim.csv")
    assert len(peer[1]) == round(stop_s / 0.5) and len(columns) > 20
    worst = _worst(ours, peer, columns)
    assert all(value <= 1e-9 for value in worst.values()), {k: v for k, v in worst.items() if v > 1e-9}
    # the run did something: the ATO drove the train from A (ato_only) / the chain sent a code (free_run)
    header, data, _ = ours
    moved = "train.x" if system == "ato_only" else "rx.code"
    assert np.ptp(data[:, header.index(moved)]) > 0
    assert code == 0, f"libcosim exited {code} after writing its results: {err}"


@pytest.mark.parametrize("system", ["als_en", "fire_dqpsk", "faults", *OWN_DATA_FILES])
def test_libcosim_loads_and_steps_the_other_shipped_systems(tmp_path, packed, system):
    """Every other shipped system loads and steps in libcosim as written (ato_only and free_run run
    in full above), those with data files of their own too: the packed FMUs carry the system's
    data files in their resources (orchestrator/packaging/packing.py)."""
    receiver = "rx1" if "following" in system or system in SEVERAL_TRAINS else "rx"
    code, out, err = _peer("libcosim", packed / f"{system}.ssp", 1.0, 0.5, tmp_path / "libcosim.csv",
                           [f"{receiver}.level"])
    assert "file not found" not in err
    assert "components, 1 s simulated" in out, err
    assert code == 0, f"libcosim exited {code} after stepping: {err}"


def test_own_data_files_are_what_the_list_above_says():
    """OWN_DATA_FILES are exactly the shipped systems with a resources/ folder (their data files)."""
    assert sorted(p.parent.name for p in SSP_ROOT.glob("*/resources")) == sorted(OWN_DATA_FILES)


def test_fmpy_simulate_ssp_makes_every_connection(tmp_path, packed):
    """FMPy 0.3.32 makes all four connections of ato_only, and every output it records is what our
    Jacobi run gives with the parameters FMPy applies: the FMUs' defaults, because simulate_ssp
    applies none of the SSD's parameter bindings (and could not apply a String one). With the
    ATO's default cab_signal (ALSN) and no code, the train is held at A by the ATO's brake command."""
    code, out, err = _peer("fmpy", packed / "ato_only.ssp", 1100.0, 0.5, tmp_path / "fmpy.csv")
    assert code == 0 and "fmpy:" in out, err
    header, data = _csv(tmp_path / "fmpy.csv")
    column = {name: data[:, header.index(name)] for name in header}
    for start, end in (("train.x", "ato.x"), ("train.v", "ato.v"), ("ato.command", "train.command"),
                       ("ato.emergency_brake", "train.emergency_brake")):
        assert (column[start] == column[end]).all(), (start, end)
    assert (column["ato.x"] == 400.0).all()                        # the train's x (the ATO's own start: 0)
    assert (column["train.command"] == -0.3).all() and column["train.brake_step"].max() == 3  # the ATO's brake arrived
    # FMPy labels each row with the start of the step whose results it holds: ours at t + 0.5 s
    ours = _ours(tmp_path, "ato_only", 1100.0, 0.5, "--set", "ato.cab_signal=ALSN")
    columns = [name for name in ours[0][1:] if name in header]
    assert len(columns) > 20
    worst = _worst(ours, (header, data), columns, shift_s=0.5)
    assert all(value <= 1e-9 for value in worst.values()), {k: v for k, v in worst.items() if v > 1e-9}

"""TVM-430's sample rate: accuracy and cost of the rail line at 8, 10.4, 12 and 16 kHz on the
high-speed line (fmus/data/shipped/hsl_tvm430_line.json; docs/rail_line.md#tvm-430-track-circuits, "Sample rate",
docs/performance.md).

Accuracy, per sample rate, for a 1700 Hz and a 2300 Hz circuit with a train standing near the
entry, in the middle and near the feed (plain sine at the carrier, 1 V):

* the network model's steady state at the carrier (the discrete model's response, a
  zero-order hold on u_tx) against the same network's continuous phasor: amplitude and phase;
  and its spread over the carrier ± 50 Hz (an FM word's band);
* the coil EMF's backward difference against M·di/dt at the carrier: amplitude and phase;
* the whole chain: the coil EMF's amplitude fitted over 0.1 s of a run against M·ω·|I| with I
  the wheelset chain's current at the first axle (two-port solution, no sampling).

(8 kHz is below the fs/4 rule for 2300 Hz: measured with the rule relaxed for that core.)

Cost: the rail line core's time per simulated second (in process, 10 ms frames, core.step only)
on the whole line with 1 and with 2 trains at 300 km/h (3 min apart).

Also: the rails' √f law against plain R and L at the carriers (the far-end level), and the
selectivity of the separation zone across the FM band (what a complex-envelope model at the
carrier's phasor would flatten).

    python benchmarks/tvm_sample_rate.py [--rates 8000 10400 12000 16000] [--seconds 10] [--repeats 3]
    python benchmarks/tvm_sample_rate.py --uniform-ballast 1     # the cost alone, one ballast everywhere
"""
from __future__ import annotations

import argparse
import json
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from fmus.data.loader import DATA, load_line
from fmus.rail_line import core as rail_core
from fmus.rail_line.axle_chain import SectionChain
from fmus.rail_line.core import RailLineCore, RailSettings, default_wheelsets
from fmus.rail_line.track_circuit import Faults, TrackCircuit, end_admittance

LINE = DATA / "hsl_tvm430_line.json"
TRAIN_M = 200.0
SPEED_MPS = 300.0 / 3.6
FRAME_S = 0.01


def core_for(line, fs: float, trains: int) -> RailLineCore:
    """The rail line core at ``fs``; a rate below the carrier rule (8 kHz for 2300 Hz) is measured
    with the rule relaxed for this core alone."""
    wheels = default_wheelsets(TRAIN_M)
    settings = RailSettings(fs_hz=fs, train_length_m=(TRAIN_M,) * trains, wheelset_offsets_m=(wheels,) * trains)
    rule = rail_core.MAX_CARRIER_SHARE_OF_FS
    rail_core.MAX_CARRIER_SHARE_OF_FS = max(rule, max(s.carrier_hz for s in line.sections) / fs)
    try:
        return RailLineCore(line, len(line.sections), trains, int(round(fs * FRAME_S)), settings)
    finally:
        rail_core.MAX_CARRIER_SHARE_OF_FS = rule


def carrier_frame(carriers: np.ndarray, times: np.ndarray) -> np.ndarray:
    return np.sin(2 * np.pi * carriers[:, None] * times[None, :])


def accuracy(line, fs: float, k: int, head_m: float) -> dict:
    """Section k, one train standing with its first wheelset at ``head_m``."""
    core = core_for(line, fs, 1)
    n = core.frame
    carriers = np.array([s.carrier_hz for s in line.sections])
    carrier = float(carriers[k])
    core.start(np.array([head_m]))
    emf, t = [], 0.0
    for _ in range(int(round(0.4 / FRAME_S))):
        times = t + np.arange(n) / fs
        out = core.step(t, carrier_frame(carriers, times), np.array([head_m]), np.zeros(1), np.zeros(1))
        emf.append(out.e_coil[0].copy())
        t += n / fs
    emf = np.concatenate(emf)[-int(0.1 * fs):]
    times = (np.arange(emf.size) + int(round(0.4 * fs)) - emf.size) / fs
    basis = np.stack([np.cos(2 * np.pi * carrier * times), np.sin(2 * np.pi * carrier * times)], 1)
    (c, s), *_ = np.linalg.lstsq(basis, emf, rcond=None)
    emf_amplitude = float(np.hypot(c, s))
    bank = core.bank
    currents, _, _ = bank.wheelset_solution(k, [head_m])
    omega = 2 * np.pi * carrier
    expected = core.settings.coil_gain_h * omega * currents[0]
    # the active network model against its continuous phasor
    family, node_index, _ = bank.models._families[(k, bank._effective_faults[k])]
    shunts, heads = bank._configs[k]
    system = family.state_space([node_index[f"n{node}"] for node in shunts])
    model = bank._active[k][1]
    nx = system.a.shape[0]

    def ratio(f_hz: float) -> complex:
        w = 2 * np.pi * f_hz
        continuous = np.linalg.solve(1j * w * np.eye(nx) - system.a, system.b[:, 0])[heads[0]]
        discrete = np.linalg.solve(np.exp(1j * w / fs) * np.eye(nx) - model.phi, model.psi[:, -1])[heads[0]]
        return complex(discrete / continuous)
    at_carrier = ratio(carrier)
    spread = [abs(ratio(carrier + d) / at_carrier) for d in (-50.0, 50.0)]
    difference = (1 - np.exp(-1j * omega / fs)) / (1j * omega / fs)
    return {"zoh_amplitude": abs(at_carrier), "zoh_phase_deg": np.degrees(np.angle(at_carrier)),
            "zoh_band_spread": max(abs(1 - x) for x in spread),
            "difference_amplitude": abs(difference), "difference_phase_deg": np.degrees(np.angle(difference)),
            "emf_vs_continuous": emf_amplitude / expected, "emf_v": emf_amplitude}


def cost(line, fs: float, trains: int, seconds: float) -> float:
    """Seconds of the core's step per simulated second, whole line, trains at 300 km/h."""
    core = core_for(line, fs, trains)
    n = core.frame
    carriers = np.array([s.carrier_hz for s in line.sections])
    starts = np.array([TRAIN_M + 1000.0 + 180.0 * SPEED_MPS * j for j in range(trains)][::-1])
    speeds = np.full(trains, SPEED_MPS)
    core.start(starts)
    spent, t = 0.0, 0.0
    warm = 2.0
    for frame in range(int(round((seconds + warm) / FRAME_S))):
        times = t + np.arange(n) / fs
        u = carrier_frame(carriers, times)
        x = starts + SPEED_MPS * t
        began = time.perf_counter()
        core.step(t, u, x, speeds, np.full(trains, 300.0))
        if t >= warm:
            spent += time.perf_counter() - began
        t += n / fs
    return spent / seconds


def law_against_plain_rl(line) -> list:
    """Relay-end level (free circuit, the section's minimum ballast) and the current at a first
    axle 10 m into the section, per volt of u_tx: the √f law against R and L held at 165 Hz."""
    core = core_for(line, 12000.0, 1)
    rows = []
    for k in (0, 1):
        circuit = core.circuits[k]
        plain = TrackCircuit(circuit.start_m, circuit.end_m, circuit.end_m - circuit.feed_m,
                             replace(circuit.params, rail_internal_l_h_per_km=0.0))
        f = float(line.sections[k].carrier_hz)
        values = []
        for c in (circuit, plain):
            chain = SectionChain(c, Faults(), f, core.settings.transformer_ratio)
            relay = chain.solve(())[2]
            table = chain.table(0, np.zeros(1))
            head = circuit.start_m + 10.0
            current = chain.solve([(head, head, table, 0, 0)], [head])[0][0]
            values.append((relay, current))
        rows.append((f, circuit.params.ballast_ohm_km, values))
    return rows


def zone_band(line) -> list:
    """|Z| of a circuit's end (its zone with the receiver) at the carrier ± 20 / 50 / 100 Hz over the
    value at the carrier, and at the neighbour's carrier."""
    core = core_for(line, 12000.0, 1)
    rows = []
    for k in (0, 1):
        p = core.circuits[k].params
        f = float(line.sections[k].carrier_hz)

        def z(x):
            return abs(1.0 / (end_admittance(p, p.ballast_ohm_km, x) + 1.0 / p.relay_r_ohm))
        rows.append((f, [z(f + d) / z(f) for d in (-100.0, -50.0, -20.0, 20.0, 50.0, 100.0)], z(f), z(p.zone.other_hz)))
    return rows


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--rates", type=float, nargs="+", default=[8000.0, 10400.0, 12000.0, 16000.0])
    parser.add_argument("--seconds", type=float, default=10.0)
    parser.add_argument("--repeats", type=int, default=3, help="cost runs per rate, the rates alternating")
    parser.add_argument("--uniform-ballast", type=float, default=0.0,
                        help="cost only, every section at this minimum ballast (Ω·km): sections of one carrier "
                             "then share their network models")
    args = parser.parse_args()
    line = load_line(LINE)
    if args.uniform_ballast:
        document = json.loads(LINE.read_text(encoding="utf-8"))
        for section in document["block_sections"]:
            section["ballast_ohm_km"] = args.uniform_ballast
        path = Path(tempfile.mkdtemp()) / "uniform_ballast_line.json"
        path.write_text(json.dumps(document), encoding="utf-8")
        line = load_line(path)
        print_costs(line, args)
        return
    print("accuracy at the carrier (train standing; entry +10 m / middle / feed −5 m):")
    print("  fs Hz   carrier  ZOH |r|/|r_c|  ZOH phase°  ±50 Hz spread  d/dt |·|  d/dt phase°  EMF/continuous")
    for fs in args.rates:
        for k in (0, 1):
            circuit_start, feed = line.sections[k].start_m, line.sections[k].end_m - 1.0
            results = [accuracy(line, fs, k, x) for x in (circuit_start + 10.0, 0.5 * (circuit_start + feed), feed - 5.0)]
            r = results[0]
            print(f"  {fs:6.0f}  {line.sections[k].carrier_hz:5.0f}   {r['zoh_amplitude']:.4f}       "
                  f"{r['zoh_phase_deg']:7.2f}      {max(x['zoh_band_spread'] for x in results):.1e}      "
                  f"{r['difference_amplitude']:.4f}    {r['difference_phase_deg']:7.2f}     "
                  + " / ".join(f"{x['emf_vs_continuous']:.4f}" for x in results))
    print_costs(line, args)
    print("rails: √f law against R, L held at 165 Hz (relay end free, current 10 m into the section), per V:")
    for f, ballast, ((relay_law, head_law), (relay_plain, head_plain)) in law_against_plain_rl(line):
        print(f"  {f:.0f} Hz, {ballast:g} Ω·km: relay {relay_law:.4g} V vs {relay_plain:.4g} V "
              f"({20 * np.log10(relay_law / relay_plain):+.1f} dB); head {head_law:.4g} A vs {head_plain:.4g} A "
              f"({20 * np.log10(head_law / head_plain):+.1f} dB)")
    print("separation zone with the receiver, |Z| over the FM band (carrier −100/−50/−20/+20/+50/+100 Hz, relative):")
    for f, relative, own, other in zone_band(line):
        print(f"  {f:.0f} Hz: " + " ".join(f"{x:.3f}" for x in relative)
              + f"; |Z| {own:.3f} Ω at the carrier, {other:.4f} Ω at the neighbour's")


def print_costs(line, args):
    print(f"cost, rail line core, {line.path.name} ({len(line.sections)} sections), 10 ms frames, s per simulated s "
          f"(median of {args.repeats}, the rates alternating):")
    runs = {(fs, trains): [] for fs in args.rates for trains in (1, 2)}
    for _ in range(args.repeats):
        for fs in args.rates:
            for trains in (1, 2):
                runs[(fs, trains)].append(cost(line, fs, trains, args.seconds))
    for fs in args.rates:
        print(f"  {fs:6.0f} Hz: 1 train {np.median(runs[(fs, 1)]):.4f}   2 trains {np.median(runs[(fs, 2)]):.4f}")


if __name__ == "__main__":
    main()

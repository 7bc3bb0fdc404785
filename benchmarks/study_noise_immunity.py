"""Noise immunity of ALSN, ALSU, ALS-EN, FIRE_DQPSK, TVM-430 and TVM-300 side by side. A study, not a speed
benchmark: its tables and plots are in docs/noise_immunity.md.

1. **Bit error rate vs Eb/N0** of the two modems (ideal symbol timing, integrate-and-dump,
   differential decision) against the theory of differentially detected 4-phase DPSK.
2. **Message error rate, undetected-error rate and wrong-side failures** of the whole chain —
   the wayside generator (square wave + Chebyshev band-pass), white noise or impulse noise at
   the coil, the receiver core exactly as in the FMU (limiter, anti-alias, band-pass, symbol
   timing recovery, framing, code check, acceptance) — Monte Carlo with fixed seeds:

   * message error rate (MER) = 1 − messages decoded correctly / messages sent;
   * undetected errors = messages that passed the code check but differ from the one sent;
   * wrong-side failure = the receiver shows a command more permissive than every command sent
     within the stated latency before (docs/scenarios.md#results-summaryjson: two messages + 0.2 s; ALSN two cycles + 0.5 s),
     counted as events and as time;
   * availability = share of time a command is shown that was sent within the latency before
     (after the first four messages).

   Messages: random plain-line commands (free blocks 0…6), each held for six messages, so
   the acceptance rules meet changes in both directions. SNR is taken over the whole 0–2 kHz
   band (carrier power A²/2 against σ²), as in study_alsn_noise.py; the receivers' in-band
   SNR is 20–25 dB higher. Impulse noise: damped oscillations (5–40 V against a 0.2 V signal,
   100–400 Hz, 2–10 ms decay) at random times, Poisson at a given rate.
   ALSN: a message is one code cycle (КЖ/Ж/З from a KPT-5 section), decoded by the ALSN
   receiver core.
   ALSU: a message is one minimum duration (0.5 s) of a code (two tones), decoded by the ALSU
   receiver core; besides white and impulse noise, DC joint pulse pairs (the rail line's own
   at 40, 80 and 160 km/h with the coil pair 5 % mismatched: the joints paper's 5 V at
   80 km/h) at 0.5 per second.
   TVM430: a message is 13 decisions (1.625 s) of a 27-bit word on the 1700 Hz carrier at 0.1 V,
   decoded by the TVM-430 receiver core; white and impulse noise, a traction harmonic sweeping
   the carrier ±50 Hz (inband: its level against the carrier in dB), and the neighbour's
   2300 Hz carrier at its worst separation-zone leak with white noise (leak: the SNR in dB).
   TVM300: a message is 10 decisions (1.0 s) of one sub-frequency on the 1700 Hz carrier at
   0.1 V, decoded by the TVM-300 receiver core; the same four kinds of noise as TVM430's.
3. **A steady unmodulated tone at the carrier and the adjacent track's signal alone** (the other
   track parity) must never give a command.

    python benchmarks/study_noise_immunity.py [--messages 100000] [--alsn-cycles 2000] [--tvm430-messages 2000] [--tvm300-messages 10000]
        [--systems ALSN,ALSU,ALS-EN,FIRE_DQPSK,TVM430,TVM300]

Part 2 is the studies orchestrator/study/studies/noise_immunity.toml, noise_immunity_alsu.toml,
noise_immunity_tvm430.toml and noise_immunity_tvm300.toml run on Dask (a local cluster, or
--scheduler): ``railcosim study noise_immunity`` (and ``noise_immunity_alsu``,
``noise_immunity_tvm430``, ``noise_immunity_tvm300``) run the same conditions on their own.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the repository: harness

from fmus.signalling import cab_systems  # noqa: E402
from fmus.signalling import dqpsk  # noqa: E402
from harness.noise_immunity import ber, run_digital  # noqa: E402

DOCS = Path(__file__).resolve().parents[1] / "docs"
STUDIES = Path(__file__).resolve().parents[1] / "orchestrator" / "study" / "studies"
STUDY = STUDIES / "noise_immunity.toml"
ALSU_STUDY = STUDIES / "noise_immunity_alsu.toml"
TVM430_STUDY = STUDIES / "noise_immunity_tvm430.toml"
TVM300_STUDY = STUDIES / "noise_immunity_tvm300.toml"
SYSTEMS = (cab_systems.ALSN.name, cab_systems.ALSU.name, cab_systems.ALS_EN.name, cab_systems.FIRE_DQPSK.name,
           cab_systems.TVM430.name, cab_systems.TVM300.name)
NOISE_KINDS = ("white", "impulse", "joint", "inband", "leak")


# ---- main ------------------------------------------------------------------------------------------
def run_conditions(messages: int, alsn_cycles: int, systems, output: Path, workers=None, scheduler=None,
                   tvm430_messages: int = 2000, tvm300_messages: int = 10000) -> dict:
    """The white- and impulse-noise tables through ``railcosim study`` (the study file with
    these message counts and systems): {"white": {snr: {system: result}}, "impulse": …} for
    every kind of NOISE_KINDS."""
    from orchestrator.study.runner import run_study
    from orchestrator.study.spec import load_study

    tables = {kind: {} for kind in NOISE_KINDS}
    # each study: its folder beside ``output`` and its messages per condition
    studies = ((STUDY, "", messages), (ALSU_STUDY, "_alsu", messages), (TVM430_STUDY, "_tvm430", tvm430_messages),
               (TVM300_STUDY, "_tvm300", tvm300_messages))
    for study, suffix, study_messages in studies:
        folder = output.with_name(output.name + suffix)
        spec = load_study(study)
        spec.data["arguments"].update(messages=study_messages,
                                      **({"alsn_cycles": alsn_cycles} if study == STUDY else {}))
        spec.runs = [r for r in spec.runs if r.values["system"] in systems]
        if not spec.runs:
            continue
        result = run_study(spec, folder, None, [], workers=workers, scheduler=scheduler, resume=True,
                           progress=sys.stderr, python_path=[str(Path(__file__).resolve().parents[1])])
        for record in result.records:
            if record["status"] != "ok":
                raise SystemExit(f"{record['id']} {record['values']}: {record['status']}: {record['error']}")
            summary = json.loads((result.output / "runs" / record["id"] / "summary.json").read_text())
            summary.pop("wall_time_s", None)
            values = record["values"]
            tables[values["noise"]].setdefault(str(float(values["level"])), {})[values["system"]] = summary
    return tables


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--messages", type=int, default=100000, help="digital messages per condition")
    parser.add_argument("--alsn-cycles", type=int, default=2000, help="ALSN code cycles per condition")
    parser.add_argument("--tvm430-messages", type=int, default=2000,
                        help="TVM-430 messages (1.625 s, 13 decisions each) per condition")
    parser.add_argument("--tvm300-messages", type=int, default=10000,
                        help="TVM-300 messages (1.0 s, 10 decisions each) per condition")
    parser.add_argument("--ber-symbols", type=int, default=200000)
    parser.add_argument("--systems", default=",".join(SYSTEMS),
                        help="which systems to (re)compute; the others are kept from an existing --output")
    parser.add_argument("--output", default=str(DOCS / "figures" / "noise_immunity.json"))
    parser.add_argument("--runs", default="results/noise_immunity",
                        help="the study's folder (one run folder per condition; an interrupted study resumes)")
    parser.add_argument("--workers", type=int, help="local Dask workers (default: one per core)")
    parser.add_argument("--scheduler", help="an existing Dask scheduler instead of a local cluster")
    args = parser.parse_args()
    chosen = set(args.systems.split(","))
    unknown = sorted(chosen - set(SYSTEMS))
    if unknown:
        parser.exit(2, f"--systems: unknown {', '.join(unknown)}; choose among {','.join(SYSTEMS)}\n")
    digital = [name for name in (cab_systems.FIRE_DQPSK.name, cab_systems.ALS_EN.name) if name in chosen]
    output = Path(args.output)
    results = json.loads(output.read_text()) if output.is_file() else {}
    for key in ("ber", "tone", "adjacent", *NOISE_KINDS):
        results.setdefault(key, {})
    began = time.perf_counter()
    for name in digital:
        results["ber"][name] = {str(e): ber(name, e, args.ber_symbols, 11 + int(e)) for e in (2, 4, 6, 8, 10)}
    results["ber"]["theory"] = {str(e): float(dqpsk.theory_ber(e)) for e in (2, 4, 6, 8, 10)}
    print("BER", json.dumps(results["ber"]), f"{time.perf_counter() - began:.0f} s", flush=True)
    tables = run_conditions(args.messages, args.alsn_cycles, chosen, Path(args.runs), args.workers, args.scheduler,
                            args.tvm430_messages, args.tvm300_messages)
    for kind in NOISE_KINDS:
        for level, row in tables[kind].items():
            results[kind].setdefault(level, {}).update(row)
    print(f"white and impulse noise: {time.perf_counter() - began:.0f} s", flush=True)
    output.write_text(json.dumps(results, indent=1) + "\n")
    for name in digital:
        results["tone"][name] = run_digital(name, max(args.messages // 10, 100), None, 3, tone=True)
        results["adjacent"][name] = run_digital(name, args.messages, None, 4, track_parity=0)
        print("tone/adjacent", name, json.dumps(results["tone"][name]), json.dumps(results["adjacent"][name]),
              f"{time.perf_counter() - began:.0f} s", flush=True)
    output.write_text(json.dumps(results, indent=1) + "\n")
    print(f"written {output} in {time.perf_counter() - began:.0f} s")


if __name__ == "__main__":
    main()

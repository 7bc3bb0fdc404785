"""The shipped systems (ssp/<name>/), written from Python so they stay consistent with the
FMUs' ports. ``python -m orchestrator.systems.shipped [FOLDER]`` rewrites them (default: the
checkout's ssp/); the files are committed, and tests/test_shipped_systems.py checks that they are
what this module writes. An installed package has no ssp/: ``railcosim`` writes the systems it
needs with :func:`refresh_shipped` (docs/architecture.md, "Installed package").

* ``free_run`` — one passenger train (Traction) driven by the ATO over the default line and
  timetable, with the ALSN chain: wayside coder → rail line → locomotive receiver → ATP.
* ``ato_only`` — the same train and ATO without the signal chain (ATP on line limits): the
  fast system for timetable and energy studies.
* ``following`` — two trains six minutes apart (the follower does not stop at B); the leader stops in block section 7 for
  three minutes (its scenario.json), then runs through C to sidings beyond the last block
  signal; the follower runs on green, yellow, red-yellow, stops before the red signal, resumes
  and arrives at C.
* ``faults`` — the free run with a transmitter failure, a broken rail and an open feed
  injected and repaired by its scenario.json; the late train still reaches C.
* ``joints_at_speed`` — 160 km/h through a station throat: three short track circuits inside one
  block (joints without signals).
* ``freight_ac`` — a heavy freight train, AC 25 kV, ALSN 25 Hz.
* ``same_block`` — the follower starts in the track circuit in which, ahead of it, the leader
  stands for three minutes: its receiver gets no code and its ATO holds the departure until the
  leader has cleared the circuit and a permissive code arrives.
* ``als_en``, ``fire_dqpsk``, ``als_en_following``, ``fire_dqpsk_following`` — ``free_run``
  and ``following`` with the digital systems.
* ``alsu`` — ``free_run`` with ALSU on a 4-aspect block: the route into station B set onto a
  diverging track (frog 1/18, 80 km/h, code 5) and the permanent restriction to 140 km/h at
  12.8 km announced by code 10; ``alsu_following`` — ``following`` with ALSU, 4-aspect.

Every train's initial placement is checked here (:func:`check_placements`): on the line, tail
included, and no two trains overlapping (checked again before every run:
orchestrator/verdicts/system_checks.py). Train lengths come from the rolling-stock files
(:func:`stock_length_m`).
"""
from __future__ import annotations

import json
from dataclasses import dataclass
import tempfile
from functools import partial
from pathlib import Path
from typing import Callable, Dict, Iterable, List, Optional, Sequence, Tuple

from fmus.signalling import cab_systems
from fmus.sizes import BuildConfig
from orchestrator.folders import replace_file
from orchestrator.systems.chain import (sized_build, _shipped_json, _stop_m, _with_station, cab_settings, check_placements,
                                        signal_chain, stock_length_m, train_and_ato, write_ssd)

SSP_ROOT = Path(__file__).resolve().parents[2] / "ssp"   # the checkout's committed systems
# ALSU: 4-aspect block (code 4 before a yellow), the route into B onto a diverging track
ALSU_ROUTE = {"signal": "5", "frog": "1/18"}          # signal 5 (7.8 km): B's entry, 80 km/h
ALSU_TURNOUT_LIMIT = (7800.0, 8400.0, 80.0)           # the turnouts of the diverging route (passenger km/h)


def alsu_line(line: dict) -> dict:
    """A copy of a line for ALSU: the route into B set onto a diverging track (its signal sends
    code 5 into the approach, code 6 into the section before) and 80 km/h over its turnouts."""
    copy = json.loads(json.dumps(line))
    copy["description"] = (f"{line.get('description', line['name'])}; ALSU: the route at signal {ALSU_ROUTE['signal']} "
                           f"set onto a diverging track (frog {ALSU_ROUTE['frog']}), 80 km/h over its turnouts")
    copy["diverging_routes"] = [dict(ALSU_ROUTE)]
    start, end, speed = ALSU_TURNOUT_LIMIT
    limits = sorted(copy["speed_limits"], key=lambda item: item["start_m"])
    before = next(item for item in reversed(limits) if item["start_m"] <= start)     # in force at the turnouts
    after = next(dict(item) for item in reversed(limits) if item["start_m"] <= end)  # what holds beyond them
    kept = [item for item in limits if not start <= item["start_m"] <= end]
    kept += [{"start_m": int(start), "passenger_kmh": min(speed, before["passenger_kmh"]),
              "freight_kmh": min(speed, before["freight_kmh"])}, {**after, "start_m": int(end)}]
    copy["speed_limits"] = sorted(kept, key=lambda item: item["start_m"])
    return copy


def write_alsu(root: Path = SSP_ROOT, name: str = "alsu") -> Path:
    files = {"line_file": "alsu_line.json"}
    coder, rail, receiver, ato = cab_settings(cab_systems.ALSU.name)
    components, connections = train_and_ato(train_parameters=files, ato_parameters={**ato, **files})
    chain, links = signal_chain(coder={**coder, **files}, rail={**rail, **files}, receiver=receiver)
    folder = root / name
    path = write_ssd(folder, name, chain + components, connections + links, stop_time=1100.0)
    _write_json(folder / "resources" / "alsu_line.json", alsu_line(_shipped_json("default_line.json")))
    return path


@dataclass(frozen=True)
class HighSpeedLine:
    """A TVM system on its high-speed line, single and following (the shipped tvm430 /
    tvm430_following and tvm300 / tvm300_following pairs): the chain at the system's sample rate
    on a sized build (chain.sized_build), high-speed sets of the system's stock."""

    cab: cab_systems.CabSystem
    line_file: str
    sections: int                          # the line's track circuits (the build holds them)
    timetable: dict                        # the single train's
    stop_time_s: float
    leader_origin: Tuple[str, float]       # following: where the leader stands, ahead of the follower
    middle: Tuple[str, float]              # following: the follower's stop
    leader_timetable: dict
    follower_timetable: dict
    leader_halt_s: Tuple[float, float]     # following: the leader's full service brake, from … until
    following_stop_time_s: float
    following_story: str                   # following: its scenario's description

    @property
    def build(self) -> BuildConfig:
        return sized_build(self.cab, self.sections, 2)

    @property
    def stock_file(self) -> str:
        return self.cab.default_stock

    @property
    def prefix(self) -> str:
        return self.cab.name.lower()


def sized_chain(cab: cab_systems.CabSystem, build: BuildConfig, trains: Sequence[Tuple[str, str]],
                files: Dict[str, str]):
    """The signal chain of a system with build sizes of its own (the TVM systems) for high-speed
    trains of its default stock: (components, connections, the ATO's parameters)."""
    coder, rail, receiver, ato = cab_settings(cab.name)
    chain, links = signal_chain(trains, sections=build.sections, frame=build.frame,
                                fmu_folder=f"resources/{build.folder_name}", fs_hz=cab.sample_rate_hz,
                                coder={**coder, **files}, rail={**rail, **files},
                                receiver={**receiver, "train_category": "high_speed"},
                                stocks=[cab.default_stock] * len(trains))
    return chain, links, ato


def write_high_speed(spec: HighSpeedLine, root: Path = SSP_ROOT, name: Optional[str] = None) -> Path:
    """One high-speed set from Origine to Terminus under the system's cab signal."""
    name = name or spec.prefix
    line = _shipped_json(spec.line_file)
    check_placements(line, [("train", _stop_m(line, "Origine"), stock_length_m(spec.stock_file))])
    files = {"line_file": spec.line_file}
    stock = {"rolling_stock_file": spec.stock_file}
    timetable_file = f"{spec.prefix}_timetable.json"
    chain, links, ato = sized_chain(spec.cab, spec.build, (("train", "ato"),), files)
    components, connections = train_and_ato(
        train_parameters={**files, **stock, "x0": _stop_m(line, "Origine")},
        ato_parameters={**ato, **files, **stock, "timetable_file": timetable_file})
    folder = root / name
    path = write_ssd(folder, name, chain + components, connections + links, stop_time=spec.stop_time_s)
    _write_json(folder / "resources" / spec.line_file, line)
    _write_json(folder / "resources" / spec.stock_file, _shipped_json(spec.stock_file))
    _write_json(folder / "resources" / timetable_file, spec.timetable)
    return path


def write_high_speed_following(spec: HighSpeedLine, root: Path = SSP_ROOT, name: Optional[str] = None) -> Path:
    """Two high-speed sets: the leader ahead, held by a full service brake; the follower closes in
    under the cab signal's steps, stands, follows and stops at the middle station."""
    name = name or f"{spec.prefix}_following"
    line = _with_station(_shipped_json(spec.line_file), *spec.leader_origin,
                         f"{spec.leader_origin[0]}: where the leader of {name} stands, ahead of the follower")
    line = _with_station(line, *spec.middle, f"{spec.middle[0]}: the follower's stop in {name}")
    length_m = stock_length_m(spec.stock_file)
    check_placements(line, [("leader", spec.leader_origin[1], length_m), ("follower", _stop_m(line, "Origine"), length_m)])
    line_file = f"{name}_line.json"
    files = {"line_file": line_file}
    stock = {"rolling_stock_file": spec.stock_file}
    trains = (("leader", "leader_ato"), ("follower", "follower_ato"))
    chain, links, ato = sized_chain(spec.cab, spec.build, trains, files)
    leader, leader_links = train_and_ato(
        "leader", "leader_ato", train_parameters={**files, **stock, "x0": spec.leader_origin[1]},
        ato_parameters={**ato, **files, **stock, "timetable_file": "leader_timetable.json"})
    follower, follower_links = train_and_ato(
        "follower", "follower_ato", train_parameters={**files, **stock, "x0": _stop_m(line, "Origine")},
        ato_parameters={**ato, **files, **stock, "timetable_file": "follower_timetable.json"})
    folder = root / name
    path = write_ssd(folder, name, chain + leader + follower, links + leader_links + follower_links,
                     stop_time=spec.following_stop_time_s)
    resources = folder / "resources"
    _write_json(resources / line_file, line)
    _write_json(resources / spec.stock_file, _shipped_json(spec.stock_file))
    _write_json(resources / "leader_timetable.json", spec.leader_timetable)
    _write_json(resources / "follower_timetable.json", spec.follower_timetable)
    _write_json(folder / "scenario.json", leader_halt_scenario(spec.following_story, *spec.leader_halt_s))
    return path


# TVM-430 on the high-speed line: 28 block sections of 1500 m at its 12 kHz (docs/rail_line.md,
# sample rate of the TVM chain), so the signal FMUs are a build of 32 sections and 10 ms frames
# of 120 samples (docs/architecture.md#build-sizes). tvm430_following: the leader, standing at
# "Origine est" ahead of the follower, departs at 30 s; the follower departs 3 min later
# (TVM-430's headway on LGV Nord, docs/sources.md#tvm-430). The leader is held by a full service
# brake from 445 s (≈ 25.5 km, 250 km/h) until 685 s: it stands at 27.7 km (block 19); the
# follower, at 300 km/h, closes in under the steps 300 → 270 → 230 → 170 → 0, stands before the
# buffer section (block 18, from 25.5 km), then follows it on to its stop at "Milieu" (33.75 km)
# while the leader runs to Terminus
TVM430_SPEC = HighSpeedLine(
    cab_systems.TVM430, "hsl_tvm430_line.json", 28,
    {"train": "TGV 9001", "stops": [{"station": "Origine", "departure_s": 30},
                                    {"station": "Terminus", "arrival_s": 735.0}]}, 860.0,
    ("Origine est", 1200.0), ("Milieu", 33750.0),
    {"train": "TGV 9003 (leader)", "stops": [{"station": "Origine est", "departure_s": 30},
                                             {"station": "Terminus", "arrival_s": 740}]},
    {"train": "TGV 9005 (3 min behind)", "stops": [{"station": "Origine", "departure_s": 210},
                                                   {"station": "Milieu", "arrival_s": 830}]},
    (445.0, 685.0), 1100.0,
    "TVM-430 at 3 min headway: the leader, held by a full service brake from 445 s at about 25.5 km until "
    "685 s, stands in block 19 (27.7 km); the follower, 3 min behind at 300 km/h, closes in under the steps "
    "300, 270, 230, 170 and 0 km/h, stands before the buffer section (25.5 km), follows when the blocks clear "
    "and stops at Milieu (33.75 km) while the leader runs to Terminus.")
TVM430_FS_HZ, TVM430_BUILD = cab_systems.TVM430.sample_rate_hz, TVM430_SPEC.build
TVM430_LINE, TVM430_STOCK = TVM430_SPEC.line_file, TVM430_SPEC.stock_file

# TVM-300 on its own high-speed line (fmus/data/shipped/hsl_tvm300_line.json,
# docs/rail_line.md#tvm-430-track-circuits): 21 UM71 circuits of 2000 m, the same 12 kHz chain and sized
# build. tvm300_following: the follower departs 4 min after the leader (TVM-300's headway on LGV
# Atlantique, docs/sources.md#tvm-430 row 2); the leader is held from 445 s until 745 s; the
# follower steps down the cascade 300 → 270 → 220 → 160 → 80 → 0 block by block, stands before the
# buffer section, then follows it on to its stop at "Milieu". tvm300 is due at 766 s: the
# planner, planning the free line's cascade before Terminus, runs Origine → Terminus in 734.7 s
# at the least (earliest arrival 764.7 s; docs/ato.md#tvm-300)
TVM300_SPEC = HighSpeedLine(
    cab_systems.TVM300, "hsl_tvm300_line.json", 21,
    {"train": "TGV 8501", "stops": [{"station": "Origine", "departure_s": 30},
                                    {"station": "Terminus", "arrival_s": 766.0}]}, 880.0,
    ("Origine est", 1200.0), ("Milieu", 33750.0),
    {"train": "TGV 8503 (leader)", "stops": [{"station": "Origine est", "departure_s": 30},
                                             {"station": "Terminus", "arrival_s": 800}]},
    {"train": "TGV 8505 (4 min behind)", "stops": [{"station": "Origine", "departure_s": 270},
                                                   {"station": "Milieu", "arrival_s": 900}]},
    (445.0, 745.0), 1200.0,
    "TVM-300 at 4 min headway: the leader, held by a full service brake from 445 s until 745 s, stands on "
    "the line; the follower, 4 min behind at 300 km/h, steps down the cascade 300, 270, 220, 160, 80 and "
    "0 km/h block by block, stands before the buffer section, follows when the blocks clear and stops at "
    "Milieu (33.75 km) while the leader runs to Terminus.")


def write_tvm430(root: Path = SSP_ROOT, name: str = "tvm430") -> Path:
    return write_high_speed(TVM430_SPEC, root, name)


def write_ato_only(root: Path = SSP_ROOT) -> Path:
    components, connections = train_and_ato(ato_parameters={"cab_signal": "off"})
    return write_ssd(root / "ato_only", "ato_only", components, connections, stop_time=1100.0)


# following: the leader stops in block section 7 (15.2-17.6 km) for three minutes (the system's
# scenario.json); the follower, six minutes behind and not stopping at B, runs up to it, waits
# before the red signal and goes on to C once the leader has cleared the line: the leader runs
# through C to the sidings beyond the last block signal (Н3, 20.0 km), off every track circuit
FOLLOWER_TIMETABLE = {"train": "passenger 103 (following)",
                      "stops": [{"station": "A", "departure_s": 430},
                                {"station": "C", "arrival_s": 1380}]}
LEADER_HALT_S = (830.0, 830.0 + 50.0 + 180.0)   # full service brake from (≈15.7 km, 100 km/h): stands ≈50 s + 180 s
# the two trains cannot both stand at A (400 m) at t = 0: the leader starts ahead at "A east",
# its head 500 m further on, clear of the follower by 112 m (check_placements)
LEADER_ORIGIN = ("A east", 900.0)
# where the leader ends: sidings 500 m beyond the last block signal (its tail 112 m past it), on
# 600 m of track added to this system's copy of the line without track circuits (no code: the
# cab shows white, 40 km/h), entered at 40 km/h from just beyond C's stopping point
SIDINGS = ("C sidings", 20500.0)
SIDINGS_TRACK_END_M = 20600.0
SIDINGS_LIMIT = {"start_m": 19800, "passenger_kmh": 40, "freight_kmh": 40}
LEADER_TIMETABLE = {"train": "passenger 101 (leader)", "stops": [
    {"station": LEADER_ORIGIN[0], "departure_s": 60}, {"station": "B", "arrival_s": 515, "departure_s": 575},
    {"station": SIDINGS[0], "arrival_s": 1100}]}
FOLLOWING_STOP_TIME_S = 1700.0


def following_line() -> dict:
    """The default line with the leader's origin ("A east") and the sidings beyond Н3."""
    line = _with_station(_shipped_json("default_line.json"), *LEADER_ORIGIN,
                         "A east: where the leader of the following systems starts, ahead of the follower at A")
    line = _with_station(line, *SIDINGS, f"{SIDINGS[0]}: sidings beyond the last block signal "
                         f"(track without track circuits from 20.0 to {SIDINGS_TRACK_END_M / 1000:g} km, 40 km/h)")
    line["length_m"] = SIDINGS_TRACK_END_M
    line["speed_limits"] = line["speed_limits"] + [SIDINGS_LIMIT]
    return line


def write_following(root: Path = SSP_ROOT, system: str = cab_systems.DEFAULT.name, name: str = "following") -> Path:
    line = following_line()
    length_m = stock_length_m()
    check_placements(line, [("leader", LEADER_ORIGIN[1], length_m), ("follower", _stop_m(line, "A"), length_m)])
    files = {"line_file": "following_line.json"}
    coder, rail, receiver, ato = cab_settings(system)
    leader, leader_links = train_and_ato("leader", "leader_ato", train_parameters={**files, "x0": LEADER_ORIGIN[1]},
                                         ato_parameters={**ato, **files, "timetable_file": "leader_timetable.json"})
    follower, follower_links = train_and_ato("follower", "follower_ato", train_parameters=files,
                                             ato_parameters={**ato, **files, "timetable_file": "follower_timetable.json"})
    chain, links = signal_chain((("leader", "leader_ato"), ("follower", "follower_ato")),
                                coder={**coder, **files}, rail={**rail, **files}, receiver=receiver)
    folder = root / name
    path = write_ssd(folder, name, chain + leader + follower, links + leader_links + follower_links,
                     stop_time=FOLLOWING_STOP_TIME_S)
    resources = folder / "resources"
    resources.mkdir(exist_ok=True)
    _write_json(resources / "following_line.json", line)
    _write_json(resources / "leader_timetable.json", LEADER_TIMETABLE)
    _write_json(resources / "follower_timetable.json", FOLLOWER_TIMETABLE)
    _write_json(folder / "scenario.json", leader_halt_scenario(
        "The leader stops in block section 7 (15.2-17.6 km) for three minutes: its ATO's command is overridden by "
        "a full service brake, then released; it then runs through C to the sidings beyond the last block signal "
        "(20.5 km), clearing the line. The follower, six minutes behind and not stopping at B, receives green, "
        "yellow, red-yellow, stops before the red signal at 15.2 km, resumes when the line clears and arrives at C.",
        *LEADER_HALT_S))
    return path


def leader_halt_scenario(description: str, halt_s: float, release_s: float) -> dict:
    """A following system's scenario: the leader's ATO command overridden by a full service brake
    from ``halt_s`` and given back at ``release_s``."""
    return {"description": description, "events": [
        {"time": halt_s, "model": "leader", "variable": "command", "action": "set", "value": -1.0},
        {"time": release_s, "model": "leader", "variable": "command", "action": "reset"},
    ]}


def _write_json(path: Path, document: dict) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(document, indent=1, ensure_ascii=False) + "\n")


# faults: three faults on the free run, each followed by its recovery
FAULT_EVENTS = [
    (100.0, "rail", "feed_open[1]", "set", True),       # the feed of section 1 fails under the train: code lost
    (130.0, "rail", "feed_open[1]", "reset", None),
    (160.0, "coder", "fault_main", "set", True),        # main transmitter fails: the reserve takes over
    (170.0, "coder", "fault_reserve", "set", True),     # the reserve fails too: no code anywhere
    (230.0, "coder", "fault_reserve", "reset", None),
    (230.0, "coder", "fault_main", "reset", None),
    (300.0, "rail", "broken_rail_at", "set", 9000.0),  # broken rail in section 4: signal 5 (7.8 km) red
    (600.0, "rail", "broken_rail_at", "reset", None),
]


# the faults delay the train by about 280 s: it reaches C at about 1300 s
FAULTS_STOP_TIME_S = 1500.0


def write_free_run(root: Path = SSP_ROOT, system: str = cab_systems.DEFAULT.name, name: str = "free_run",
                   stop_time: float = 1100.0) -> Path:
    coder, rail, receiver, ato = cab_settings(system)
    components, connections = train_and_ato(ato_parameters=ato)
    chain, links = signal_chain(coder=coder, rail=rail, receiver=receiver)
    return write_ssd(root / name, name, chain + components, connections + links, stop_time=stop_time)


def write_faults(root: Path = SSP_ROOT) -> Path:
    path = write_free_run(root, name="faults", stop_time=FAULTS_STOP_TIME_S)
    scenario = {
        "description": "Faults on the free run, each followed by its repair: the feed of section 1 fails under "
                       "the train (code lost, 100-130 s); the main then the reserve code transmitter fail (no code "
                       "anywhere, 170-230 s); a broken rail in section 4 turns signal 5 red ahead of the train, which "
                       "stops before it (300-600 s). Each must end in a restrictive state within the decoding "
                       "latency, never a wrong-side failure.",
        "events": [{"time": t, "model": m, "variable": v, "action": a, **({} if value is None else {"value": value})}
                   for t, m, v, a, value in FAULT_EVENTS]}
    _write_json(path.parent / "scenario.json", scenario)
    return path


# joints_at_speed: 160 km/h through a station throat of three short track circuits in one block
THROAT_LINE = {
    "name": "station throat at speed",
    "description": "14 km, DC 3 kV, ALSN 50 Hz, 160 km/h: a station throat of three 600 m track circuits "
                   "between 7.6 and 9.4 km inside one block (no signals at the joints within it); railcosim's "
                   "joints_at_speed system",
    "length_m": 14000,
    "electrification": {"system": "DC3000", "nominal_voltage_v": 3000},
    "block_sections": [
        {"name": str(k + 1), "start_m": a, "end_m": b, "signal": sig, "transmitter": tx, "carrier_hz": 50,
         "ballast_ohm_km": 1.0}
        for k, (a, b, sig, tx) in enumerate([
            (0, 2600, "Ч1", "KPT-5"), (2600, 5200, "3", "KPT-7"), (5200, 7600, "НМ", "KPT-5"),
            (7600, 8200, "", "KPT-7"), (8200, 8800, "", "KPT-5"), (8800, 9400, "ЧМ", "KPT-7"),
            (9400, 11700, "5", "KPT-5"), (11700, 14000, "Н3", "KPT-7")])],
    "insulated_joints": [{"position_m": x, "impedance_bond": True, "bond_lead_offset_m": 1.0}
                         for x in (0, 2600, 5200, 7600, 8200, 8800, 9400, 11700, 14000)],
    "stations": [{"name": "A", "stop_m": 400, "platform_length_m": 400},
                 {"name": "B", "stop_m": 13600, "platform_length_m": 400}],
    "gradients": [{"start_m": 0, "permille": 0.0}],
    "curves": [],
    "speed_limits": [{"start_m": 0, "passenger_kmh": 160, "freight_kmh": 90}],
}
THROAT_TIMETABLE = {"train": "passenger 105 (through the throat)",
                    "stops": [{"station": "A", "departure_s": 30}, {"station": "B", "arrival_s": 465}]}


def write_joints_at_speed(root: Path = SSP_ROOT) -> Path:
    files = {"line_file": "throat_line.json"}
    coder, rail, receiver, ato = cab_settings(cab_systems.ALSN.name)
    components, connections = train_and_ato(
        train_parameters=files, ato_parameters={**ato, **files, "timetable_file": "throat_timetable.json",
                                                "strategy": "flat_out"})
    chain, links = signal_chain(coder={**coder, **files}, rail={**rail, **files}, receiver=receiver)
    folder = root / "joints_at_speed"
    path = write_ssd(folder, "joints_at_speed", chain + components, connections + links, stop_time=520.0)
    _write_json(folder / "resources" / "throat_line.json", THROAT_LINE)
    _write_json(folder / "resources" / "throat_timetable.json", THROAT_TIMETABLE)
    return path


# freight_ac: a heavy freight train on the AC 25 kV variant of the default line, ALSN 25 Hz
FREIGHT_TIMETABLE = {"train": "freight 2001", "stops": [
    {"station": "A", "departure_s": 60}, {"station": "B", "arrival_s": 900, "departure_s": 960},
    {"station": "C", "arrival_s": 1800}]}
# the 944 m train (its rolling-stock file) does not fit behind A's stop point at 400 m: in this
# system's copy of the line, A's stop point is at 1000 m (tail at 56 m)
FREIGHT_ORIGIN_M = 1000.0


def write_freight_ac(root: Path = SSP_ROOT) -> Path:
    folder = root / "freight_ac"
    files = {"line_file": "default_line_ac.json"}
    stock = {"rolling_stock_file": "freight_vl80.json"}
    length_m = stock_length_m(stock["rolling_stock_file"])
    line = _shipped_json("default_line_ac.json")
    next(s for s in line["stations"] if s["name"] == "A")["stop_m"] = FREIGHT_ORIGIN_M
    check_placements(line, [("train", FREIGHT_ORIGIN_M, length_m)])
    coder, rail, receiver, ato = cab_settings(cab_systems.ALSN.name)
    components, connections = train_and_ato(
        train_parameters={**files, **stock, "x0": FREIGHT_ORIGIN_M},
        ato_parameters={**ato, **files, **stock, "timetable_file": "freight_timetable.json"})
    chain, links = signal_chain(coder={**coder, **files}, rail={**rail, **files},
                                receiver={**receiver, "train_category": "freight", "carrier": 25.0},
                                stocks=[stock["rolling_stock_file"]])
    path = write_ssd(folder, "freight_ac", chain + components, connections + links, stop_time=1900.0)
    _write_json(folder / "resources" / "default_line_ac.json", line)
    _write_json(folder / "resources" / "freight_vl80.json", _shipped_json("freight_vl80.json"))
    _write_json(folder / "resources" / "freight_timetable.json", FREIGHT_TIMETABLE)
    return path


# same_block: the follower at A (400 m) and, ahead of it in the same track circuit (block section
# 1, 0-2600 m), the leader standing for three minutes at "2 km" (the state after a permissive
# restart past a red signal). The leader departs at 180 s and runs to C; the follower, due at
# 60 s, waits for a permissive code (docs/ato.md, departure hold) and runs to B.
SAME_BLOCK_LEADER_ORIGIN = ("2 km", 2000.0)
SAME_BLOCK_LEADER_TIMETABLE = {"train": "passenger 111 (standing ahead)", "stops": [
    {"station": SAME_BLOCK_LEADER_ORIGIN[0], "departure_s": 180}, {"station": "C", "arrival_s": 1060}]}
SAME_BLOCK_FOLLOWER_TIMETABLE = {"train": "passenger 113 (behind it)", "stops": [
    {"station": "A", "departure_s": 60}, {"station": "B", "arrival_s": 515}]}


def write_same_block(root: Path = SSP_ROOT) -> Path:
    line = _with_station(_shipped_json("default_line.json"), *SAME_BLOCK_LEADER_ORIGIN,
                         "2 km: where the leader of the same_block system stands, in the follower's track circuit")
    check_placements(line, [("leader", SAME_BLOCK_LEADER_ORIGIN[1], stock_length_m()),
                            ("follower", _stop_m(line, "A"), stock_length_m())])
    files = {"line_file": "same_block_line.json"}
    coder, rail, receiver, ato = cab_settings(cab_systems.ALSN.name)
    leader, leader_links = train_and_ato(
        "leader", "leader_ato", train_parameters={**files, "x0": SAME_BLOCK_LEADER_ORIGIN[1]},
        ato_parameters={**ato, **files, "timetable_file": "leader_timetable.json"})
    follower, follower_links = train_and_ato("follower", "follower_ato", train_parameters=files,
                                             ato_parameters={**ato, **files, "timetable_file": "follower_timetable.json"})
    chain, links = signal_chain((("leader", "leader_ato"), ("follower", "follower_ato")),
                                coder={**coder, **files}, rail={**rail, **files}, receiver=receiver)
    folder = root / "same_block"
    path = write_ssd(folder, "same_block", chain + leader + follower, links + leader_links + follower_links,
                     stop_time=1100.0)
    _write_json(folder / "resources" / "same_block_line.json", line)
    _write_json(folder / "resources" / "leader_timetable.json", SAME_BLOCK_LEADER_TIMETABLE)
    _write_json(folder / "resources" / "follower_timetable.json", SAME_BLOCK_FOLLOWER_TIMETABLE)
    return path


# name → writer(root) of every shipped system
# suburban: one ЭР2 EMU stopping at all 13 stations of the 36 km suburban line (31 sections of
# 1.0-1.4 km, 4-aspect ALSN block, DC 3 kV): the base of suburban_peak and of its headway; the
# chain on a build of 32 sections (resources/k32m2n40/)
SUBURBAN_LINE, SUBURBAN_STOCK, SUBURBAN_TIMETABLE = "suburban_line.json", "emu_er2.json", "suburban_timetable.json"
SUBURBAN_BUILD = BuildConfig(sections=32, trains=2, frame=40)
SUBURBAN_BLOCK_ASPECTS = 4


def write_suburban(root: Path = SSP_ROOT, name: str = "suburban") -> Path:
    line, timetable = _shipped_json(SUBURBAN_LINE), _shipped_json(SUBURBAN_TIMETABLE)
    origin_m = _stop_m(line, timetable["stops"][0]["station"])
    check_placements(line, [("train", origin_m, stock_length_m(SUBURBAN_STOCK))])
    files = {"line_file": SUBURBAN_LINE}
    stock = {"rolling_stock_file": SUBURBAN_STOCK}
    coder, rail, receiver, ato = cab_settings(cab_systems.ALSN.name)
    chain, links = signal_chain(sections=SUBURBAN_BUILD.sections, frame=SUBURBAN_BUILD.frame,
                                fmu_folder=f"resources/{SUBURBAN_BUILD.folder_name}",
                                coder={**coder, **files, "block_aspects": SUBURBAN_BLOCK_ASPECTS},
                                rail={**rail, **files}, receiver=receiver, stocks=[SUBURBAN_STOCK])
    components, connections = train_and_ato(
        train_parameters={**files, **stock, "x0": origin_m},
        ato_parameters={**ato, **files, **stock, "timetable_file": SUBURBAN_TIMETABLE})
    folder = root / name
    last = timetable["stops"][-1]["arrival_s"]
    path = write_ssd(folder, name, chain + components, connections + links, stop_time=float(last + 120))
    for document, file in ((line, SUBURBAN_LINE), (_shipped_json(SUBURBAN_STOCK), SUBURBAN_STOCK),
                           (timetable, SUBURBAN_TIMETABLE)):
        _write_json(folder / "resources" / file, document)
    return path


# ---- many trains: a single-train system's train queued N times at a headway ----------------------
def write_queued(root: Path, name: str, base: Callable[[Path], Path], trains: int, headway_s: float,
                 stop_time_s: Optional[float] = None) -> Path:
    """``trains`` copies of the train of the single-train system ``base`` writes, queued at its
    start and departing ``headway_s`` apart (orchestrator/systems/queued.py: the headway
    trials' layout, with sidings beyond the line where the cab system allows them)."""
    from orchestrator.systems import queued

    with tempfile.TemporaryDirectory() as scratch:
        plan = queued.TrialPlan(queued.read_base(base(Path(scratch)).parent), trains)
        folder = root / name
        timetables = {slot.index: queued.write_timetable(folder, plan, slot, (slot.index - 1) * headway_s, name)
                      for slot in plan.slots}
        return queued.write_system(folder, plan, plan.slots, name, timetables,
                                   stop_time_s or plan.stop_time_s(headway_s))


SHIPPED: Dict[str, Callable[[Path], Path]] = {
    "free_run": write_free_run, "ato_only": write_ato_only, "following": write_following,
    "faults": write_faults, "joints_at_speed": write_joints_at_speed, "freight_ac": write_freight_ac,
    "same_block": write_same_block,
}
for _system, _prefix in ((cab_systems.ALS_EN.name, "als_en"), (cab_systems.FIRE_DQPSK.name, "fire_dqpsk")):
    SHIPPED[_prefix] = partial(write_free_run, system=_system, name=_prefix)
    SHIPPED[f"{_prefix}_following"] = partial(write_following, system=_system, name=f"{_prefix}_following")
SHIPPED["alsu"] = write_alsu
SHIPPED["tvm430"] = write_tvm430
SHIPPED["tvm430_following"] = partial(write_high_speed_following, TVM430_SPEC)
SHIPPED["tvm300"] = partial(write_high_speed, TVM300_SPEC)
SHIPPED["tvm300_following"] = partial(write_high_speed_following, TVM300_SPEC)
SHIPPED["alsu_following"] = partial(write_following, system=cab_systems.ALSU.name, name="alsu_following")
SHIPPED["suburban"] = write_suburban
# the suburban peak: ten EMUs at the suburban line's blocking-time headway (railcosim headway
# suburban --method blocking: 292.4 s, critical the terminal block) plus a margin of 10 % [U]
SUBURBAN_PEAK_TRAINS, SUBURBAN_PEAK_HEADWAY_S = 10, 322.0
# five TGV sets at TVM-430's co-simulated headway on the high-speed line (railcosim headway tvm430:
# 140 s, the blocking-time figure 142.5 s; docs/capacity.md)
TVM430_HEADWAY_TRAINS, TVM430_HEADWAY_S = 5, 140.0
SHIPPED["tvm430_headway"] = partial(write_queued, name="tvm430_headway", base=write_tvm430,
                                    trains=TVM430_HEADWAY_TRAINS, headway_s=TVM430_HEADWAY_S)
SHIPPED["suburban_peak"] = partial(write_queued, name="suburban_peak", base=write_suburban,
                                   trains=SUBURBAN_PEAK_TRAINS, headway_s=SUBURBAN_PEAK_HEADWAY_S)


def write_shipped(root: Path = SSP_ROOT, names: Optional[Iterable[str]] = None) -> List[Path]:
    """Write the named shipped systems (default: all) under ``root``; their SSD paths."""
    return [SHIPPED[name](root) for name in (SHIPPED if names is None else names)]


def refresh_shipped(root: Path, names: Optional[Iterable[str]] = None) -> List[Path]:
    """Make ``root/<name>`` exactly what :func:`write_shipped` writes, for an installed package.

    The systems are written into a scratch folder first and only files whose bytes differ are
    replaced, each written beside and renamed (orchestrator/folders.py ``replacing``), so runs
    started at once in one folder never read a half-written file. Files in a shipped system's
    folder that it does not write are removed: ``railcosim run free_run`` always runs the
    shipped free_run (copy a folder to change it).
    """
    names = list(SHIPPED if names is None else names)
    root.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(dir=root, prefix=".writing_") as scratch:
        write_shipped(Path(scratch), names)
        for name in names:
            fresh, folder = Path(scratch) / name, root / name
            wanted = {p.relative_to(fresh) for p in fresh.rglob("*") if p.is_file()}
            stale = [p for p in folder.rglob("*") if p.is_file() and p.relative_to(folder) not in wanted] \
                if folder.is_dir() else []
            for path in stale:
                path.unlink()
            for relative in sorted(wanted):
                target = folder / relative
                data = (fresh / relative).read_bytes()
                if not target.is_file() or target.read_bytes() != data:
                    target.parent.mkdir(parents=True, exist_ok=True)
                    replace_file(target, data, concurrent=True)
    return [root / name / "SystemStructure.ssd" for name in names]


if __name__ == "__main__":
    import sys

    for path in write_shipped(Path(sys.argv[1]) if len(sys.argv) > 1 else SSP_ROOT):
        print(f"wrote {path}")

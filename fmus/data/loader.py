"""Line, rolling-stock and timetable files: JSON validated against the schemas in
fmus/data/schemas, then checked for what a schema cannot say (order, overlaps, ranges
along the line). Every error is an FmuInputError naming the file and the field.

Everything is converted to SI on loading; the cores never see km/h or kN.
"""
from __future__ import annotations

import bisect
import hashlib
import json
import re
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import List, Optional, Tuple

import numpy as np

from fmus.errors import FmuInputError, non_finite_number
from fmus.train_categories import TRAIN_CATEGORIES
from fmus.units import MPS_PER_KMH

HERE = Path(__file__).resolve().parent
SCHEMAS = HERE / "schemas"
DATA = HERE / "shipped"
DEFAULT_LINE = DATA / "default_line.json"
DEFAULT_ROLLING_STOCK = DATA / "passenger_chs7.json"
DEFAULT_TIMETABLE = DATA / "default_timetable.json"
# read now: inside an FMU this folder is the extraction the interpreter first imported the package
# from, which a host may remove while an instance of another FMU still uses the package
# (docs/third_party.md); the shipped defaults are each instance's own (FacadeSlave.resource_path)
_SCHEMA_TEXTS = {path.name: path.read_text(encoding="utf-8") for path in SCHEMAS.glob("*.json")}


@lru_cache(maxsize=None)
def _validator(name: str):
    import jsonschema

    return jsonschema.Draft202012Validator(json.loads(_SCHEMA_TEXTS[name]))


def _field(path) -> str:
    text = ""
    for part in path:
        text += f"[{part}]" if isinstance(part, int) else (f".{part}" if text else part)
    return text or "(top level)"


#: deepest nesting of arrays and objects a data file may have (the schemas need 4); deeper
#: files are refused before parsing, so neither the parser nor the schema check can recurse
#: past Python's limit
MAX_JSON_DEPTH = 64


def read_json_file(path) -> object:
    """A JSON data file's document; every failure an FmuInputError naming the file: missing or
    unreadable, not UTF-8 text, nested deeper than MAX_JSON_DEPTH, not valid JSON, a number that
    is not finite (NaN, Infinity, 1e400: Python's json reads them; named by its field)."""
    path = Path(path)
    return _parse_json(path, _read_bytes(path))


def _read_bytes(path: Path) -> bytes:
    if not path.is_file():
        raise FmuInputError(f"{path}: file not found")
    try:
        return path.read_bytes()
    except OSError as error:
        raise FmuInputError(f"{path}: cannot be read ({error.strerror or error})") from None


def _parse_json(path: Path, raw: bytes) -> object:
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as error:
        raise FmuInputError(f"{path}: not UTF-8 text (byte 0x{raw[error.start]:02x} at offset {error.start}); "
                            f"save the file as UTF-8") from None
    depth = json_nesting_depth(text)
    if depth > MAX_JSON_DEPTH:
        raise FmuInputError(f"{path}: not a data file: arrays and objects nested {depth} deep "
                            f"(at most {MAX_JSON_DEPTH})")
    try:
        document = json.loads(text)
    except json.JSONDecodeError as error:
        raise FmuInputError(f"{path}: not valid JSON (line {error.lineno}: {error.msg})") from None
    except RecursionError:           # (not reached below MAX_JSON_DEPTH; a last guard)
        raise FmuInputError(f"{path}: not a data file: nested too deeply") from None
    # before the schema, whose minimum and maximum let NaN through (every comparison is false)
    bad = non_finite_number(document)
    if bad is not None:
        raise FmuInputError(f"{path}: field {bad[0]}: {bad[1]} is not a finite number")
    return document


_BRACKETS = re.compile(r'"(?:[^"\\]|\\.)*"|[\[\]{}]')


def json_nesting_depth(text: str) -> int:
    """The deepest nesting of brackets outside strings (a malformed text may give any count;
    the parser reports it)."""
    depth = deepest = 0
    for token in _BRACKETS.findall(text):
        if token in "[{":
            depth += 1
            deepest = max(deepest, depth)
        elif token in "]}":
            depth -= 1
    return deepest


#: (schema, digest of a file's bytes) found valid in this process: a run reads its line and
#: rolling stock once per component and once for the verdicts, and checking a file (its nesting,
#: its numbers, the schema) costs more than parsing it; bytes checked once are only parsed again,
#: whatever file they come from
_VALID_DOCUMENTS: set = set()
_VALID_DOCUMENTS_KEPT = 1024


def load_json(path, schema: str) -> dict:
    path = Path(path)
    raw = _read_bytes(path)
    known = (schema, hashlib.sha256(raw).digest())
    if known in _VALID_DOCUMENTS:
        return json.loads(raw.decode("utf-8-sig"))
    document = _parse_json(path, raw)
    errors = sorted(_validator(schema).iter_errors(document), key=lambda e: list(e.absolute_path))
    if not errors:
        if len(_VALID_DOCUMENTS) >= _VALID_DOCUMENTS_KEPT:
            _VALID_DOCUMENTS.clear()
        _VALID_DOCUMENTS.add(known)
    if errors:
        error = errors[0]
        where_ = list(error.absolute_path)
        if error.validator == "required" and isinstance(error.instance, dict):
            missing = [name for name in error.validator_value if name not in error.instance]
            raise FmuInputError(f"{path}: field {_field(where_ + missing[:1])}: missing (required)")
        raise FmuInputError(f"{path}: field {_field(where_)}: {error.message}")
    return document


def _fail(path, field: str, message: str):
    raise FmuInputError(f"{path}: field {field}: {message}")


# ---- line ---------------------------------------------------------------------------------------
DEFAULT_MAX_BALLAST_OHM_KM = 50.0
#: the transmitter of an audio-frequency TVM track circuit, and the carriers per track: a track's
#: sections alternate its two carriers block by block (docs/interfaces.md#line-file-tvm-430-sections)
TVM_TRANSMITTER = "UM71"
TVM_TRACK_CARRIERS_HZ = ((1700.0, 2300.0), (2000.0, 2600.0))
ALSN_CARRIERS_HZ = (25.0, 50.0, 75.0)
DEFAULT_ZONE_LENGTH_M = 26.0


@dataclass(frozen=True)
class BlockSection:
    name: str
    start_m: float
    end_m: float
    signal: str
    transmitter: str
    carrier_hz: float
    ballast_ohm_km: float


@dataclass(frozen=True)
class TemporaryRestriction:
    """A temporary speed restriction (warning): from the head reaching ``start_m`` until the tail
    has cleared ``end_m``, at most ``speed_mps``, for the listed train categories."""

    start_m: float
    end_m: float
    speed_mps: float
    categories: Tuple[str, ...] = TRAIN_CATEGORIES
    name: str = ""


@dataclass(frozen=True)
class Station:
    name: str
    stop_m: float


#: nominal voltage of each electrification system (V); a line file may give its own, and a rolling
#: stock's effort table holds at its system's (docs/traction.md#effort-and-catenary-voltage)
NOMINAL_VOLTAGE_V = {"DC3000": 3000.0, "AC25000": 25000.0, "none": 0.0}


class Line:
    """A line in SI units with fast piecewise look-ups along the track."""

    def __init__(self, document: dict, path: Path):
        self.path = path
        self.name = document["name"]
        self.length_m = float(document["length_m"])
        self.electrification = document["electrification"]["system"]
        self.nominal_voltage_v = float(document["electrification"].get(
            "nominal_voltage_v", NOMINAL_VOLTAGE_V[self.electrification]))
        self.sections = [BlockSection(**s) for s in document["block_sections"]]
        self.stations = [Station(s["name"], float(s["stop_m"])) for s in document["stations"]]
        self.joints = document.get("insulated_joints", [])
        # position → length of every tuned separation zone (between two TVM sections)
        self.separation_zones = {float(z["position_m"]): float(z.get("length_m", DEFAULT_ZONE_LENGTH_M))
                                 for z in document.get("separation_zones", [])}
        # the track circuits' ballast range: each section's minimum, one maximum for the line (a
        # dry or frozen bed, docs/rail_line.md: above it the shunt-mode level hardly changes)
        self.max_ballast_ohm_km = float(document.get("max_ballast_ohm_km", DEFAULT_MAX_BALLAST_OHM_KM))
        self._check(document)
        self.restrictions = self._restrictions(document.get("temporary_restrictions", []))
        # (signal, frog) of every route set onto a diverging track (ALSU codes its approach)
        self.diverging_routes = self._routes(document.get("diverging_routes", []))
        # blocks: a block ends at a section with a signal at its exit; a section with no signal
        # ("signal": "") is a track circuit inside a block (a station throat) — the line end
        # always closes the last block
        self.has_signal = [bool(sec.signal) or k == len(self.sections) - 1 for k, sec in enumerate(self.sections)]
        self.block_of_section = []
        block = 0
        for has_signal in self.has_signal:
            self.block_of_section.append(block)
            block += has_signal
        self.block_bounds = [(min(s.start_m for s, b in zip(self.sections, self.block_of_section) if b == k),
                              max(s.end_m for s, b in zip(self.sections, self.block_of_section) if b == k))
                             for k in range(block)]
        grads = sorted(document["gradients"], key=lambda g: g["start_m"])
        self.gradient_starts = [float(g["start_m"]) for g in grads]
        self.gradient_permille = [float(g["permille"]) for g in grads]
        self.curves = [(float(c["start_m"]), float(c["end_m"]), float(c["radius_m"])) for c in document["curves"]]
        limits = sorted(document["speed_limits"], key=lambda s: s["start_m"])
        self.limit_starts = [float(s["start_m"]) for s in limits]
        self.limits_mps = {
            "passenger": [s["passenger_kmh"] * MPS_PER_KMH for s in limits],
            "freight": [s["freight_kmh"] * MPS_PER_KMH for s in limits],
            "high_speed": [s.get("high_speed_kmh", s["passenger_kmh"]) * MPS_PER_KMH for s in limits],
        }
        self._build_profile()

    def _check(self, document: dict) -> None:
        p = self.path
        previous_end = None
        for k, s in enumerate(self.sections):
            if s.end_m <= s.start_m:
                _fail(p, f"block_sections[{k}].end_m", f"{s.end_m} is not after start_m {s.start_m}")
            if s.end_m > self.length_m:
                _fail(p, f"block_sections[{k}].end_m", f"{s.end_m} is beyond the line end {self.length_m}")
            if previous_end is not None and s.start_m < previous_end - 1e-9:
                _fail(p, f"block_sections[{k}].start_m", f"{s.start_m} overlaps the previous section (ends {previous_end})")
            previous_end = s.end_m
            if s.ballast_ohm_km > self.max_ballast_ohm_km:
                _fail(p, f"block_sections[{k}].ballast_ohm_km",
                      f"{s.ballast_ohm_km:g} is above the line's max_ballast_ohm_km {self.max_ballast_ohm_km:g}")
        for k, j in enumerate(self.joints):
            if j["position_m"] > self.length_m:
                _fail(p, f"insulated_joints[{k}].position_m", f"{j['position_m']} is outside the line (0..{self.length_m})")
        self._check_tvm(document)
        for k, st in enumerate(self.stations):
            if st.stop_m > self.length_m:
                _fail(p, f"stations[{k}].stop_m", f"{st.stop_m} is outside the line")
            if k and st.stop_m <= self.stations[k - 1].stop_m:
                _fail(p, f"stations[{k}].stop_m", "stations must be in running order")
        for key in ("gradients", "speed_limits"):
            starts = [item["start_m"] for item in document[key]]
            if starts[0] != 0:
                _fail(p, f"{key}[0].start_m", "the first entry must start at 0")
            for k in range(1, len(starts)):
                if starts[k] <= starts[k - 1]:
                    _fail(p, f"{key}[{k}].start_m", "entries must be in increasing order")
        for k, c in enumerate(document["curves"]):
            if c["end_m"] <= c["start_m"] or c["end_m"] > self.length_m:
                _fail(p, f"curves[{k}].end_m", "must be after start_m and within the line")

    def _check_tvm(self, document: dict) -> None:
        """Audio-frequency (UM71) sections: a TVM carrier on a UM71 transmitter and an ALSN one on a
        KPT; one track's pair of carriers on the whole line, alternating from section to section;
        a separation zone at every boundary between two UM71 sections and nowhere else; an
        insulated joint where a UM71 section meets an ALSN one (the zone cannot stop 25–75 Hz)."""
        p, sections = self.path, self.sections
        tvm = [s.transmitter == TVM_TRANSMITTER for s in sections]
        pair = None
        for k, (s, is_tvm) in enumerate(zip(sections, tvm)):
            if is_tvm != (float(s.carrier_hz) not in ALSN_CARRIERS_HZ):
                _fail(p, f"block_sections[{k}].carrier_hz",
                      f"{s.carrier_hz:g} Hz does not go with transmitter {s.transmitter} "
                      f"({TVM_TRANSMITTER}: 1700/2000/2300/2600 Hz; KPT-5/KPT-7: 25/50/75 Hz)")
            if is_tvm:
                own = next(track for track in TVM_TRACK_CARRIERS_HZ if float(s.carrier_hz) in track)
                if pair is not None and own != pair:
                    _fail(p, f"block_sections[{k}].carrier_hz",
                          f"{s.carrier_hz:g} Hz is track {TVM_TRACK_CARRIERS_HZ.index(own) + 1}'s carrier, but the "
                          f"line's TVM sections use track {TVM_TRACK_CARRIERS_HZ.index(pair) + 1}'s "
                          f"{pair[0]:g}/{pair[1]:g} Hz")
                pair = own
        joints = {round(float(j["position_m"]), 6) for j in self.joints}
        zones = {round(position, 6): k for k, position in enumerate(self.separation_zones)}
        boundaries = set()
        for k in range(1, len(sections)):
            before, after = sections[k - 1], sections[k]
            if abs(after.start_m - before.end_m) > 1e-6:
                continue                               # a gap: the sections do not touch
            at = round(after.start_m, 6)
            boundaries.add(at)
            if tvm[k - 1] and tvm[k]:
                if before.carrier_hz == after.carrier_hz:
                    _fail(p, f"block_sections[{k}].carrier_hz",
                          f"{after.carrier_hz:g} Hz again after section '{before.name}': adjacent TVM sections "
                          f"alternate their track's two carriers")
                if at not in zones:
                    _fail(p, "separation_zones", f"no separation zone at {after.start_m:g} m between the TVM "
                                                 f"sections '{before.name}' and '{after.name}'")
                if at in joints:
                    _fail(p, "insulated_joints", f"an insulated joint at {after.start_m:g} m between the TVM "
                                                 f"sections '{before.name}' and '{after.name}' (a separation zone goes there)")
            elif tvm[k - 1] != tvm[k]:
                if at not in joints:
                    _fail(p, "insulated_joints",
                          f"the TVM and ALSN sections '{before.name}' and '{after.name}' meet at {after.start_m:g} m "
                          f"without an insulated joint (a separation zone cannot stop a 25–75 Hz carrier)")
                if at in zones:
                    _fail(p, f"separation_zones[{zones[at]}].position_m",
                          f"{after.start_m:g} m is where TVM and ALSN sections meet (an insulated joint goes there)")
        for position, k in zones.items():
            if position not in boundaries or not any(tvm[i] and round(s.start_m, 6) == position
                                                     for i, s in enumerate(sections)):
                _fail(p, f"separation_zones[{k}].position_m",
                      f"{position:g} m is not a boundary between two TVM (UM71) sections")

    def _restrictions(self, items) -> List[TemporaryRestriction]:
        restrictions = []
        for k, item in enumerate(items):
            start, end = float(item["start_m"]), float(item["end_m"])
            if end <= start:
                _fail(self.path, f"temporary_restrictions[{k}].end_m", f"{end:g} is not after start_m {start:g}")
            if end > self.length_m:
                _fail(self.path, f"temporary_restrictions[{k}].end_m", f"{end:g} is beyond the line end {self.length_m:g}")
            categories = tuple(item.get("categories", TemporaryRestriction.categories))
            restrictions.append(TemporaryRestriction(start, end, item["speed_kmh"] * MPS_PER_KMH, categories,
                                                     item.get("name", "")))
        return restrictions

    def _routes(self, items) -> List[Tuple[str, str]]:
        signals = [section.signal for section in self.sections if section.signal]
        routes = []
        for k, item in enumerate(items):
            if item["signal"] not in signals:
                _fail(self.path, f"diverging_routes[{k}].signal",
                      f"{item['signal']!r} is not the signal of a block section")
            if any(item["signal"] == name for name, _ in routes):
                _fail(self.path, f"diverging_routes[{k}].signal", f"{item['signal']!r} already has a route")
            routes.append((item["signal"], item["frog"]))
        return routes

    def restrictions_for(self, category: str) -> List[TemporaryRestriction]:
        """The temporary restrictions a train of ``category`` must keep."""
        return [r for r in self.restrictions if category in r.categories]

    def _build_profile(self) -> None:
        """Cumulative integrals of gradient (‰) and curve resistance (N/kN) at breakpoints, so
        the average over any train length is two look-ups each (DESIGN: averaged over the train)."""
        points = {0.0, self.length_m, *self.gradient_starts}
        for start, end, _ in self.curves:
            points.update((start, end))
        xs = sorted(p for p in points if 0.0 <= p <= self.length_m)
        self._px = xs
        self._grade_slope, self._curve_slope = [], []
        self._grade_cum, self._curve_cum = [0.0], [0.0]
        for a, b in zip(xs[:-1], xs[1:]):
            mid = 0.5 * (a + b)
            for slopes, cum, value in ((self._grade_slope, self._grade_cum, self.gradient_at(mid)),
                                       (self._curve_slope, self._curve_cum, self.curve_resistance_at(mid))):
                slopes.append(value)
                cum.append(cum[-1] + value * (b - a))

    def gradient_at(self, x: float) -> float:
        k = bisect.bisect_right(self.gradient_starts, x) - 1
        return self.gradient_permille[max(k, 0)]

    def curve_resistance_at(self, x: float) -> float:
        for start, end, radius in self.curves:
            if start <= x < end:
                return 700.0 / radius   # ПТР: w_r = 700/R N/kN (docs/sources.md#train-resistance-and-adhesion)
        return 0.0

    def _integral(self, slopes, cumulative, x: float) -> float:
        """∫0^x of a piecewise-constant profile; held flat (last/first value) beyond the line."""
        if x <= 0.0:
            return slopes[0] * x
        if x >= self.length_m:
            return cumulative[-1] + slopes[-1] * (x - self.length_m)
        k = bisect.bisect_right(self._px, x) - 1
        return cumulative[k] + slopes[k] * (x - self._px[k])

    def mean_gradient(self, head_m: float, length_m: float) -> float:
        """Gradient [‰] averaged over the train (tail..head); positive uphill."""
        g, c = self._grade_slope, self._grade_cum
        return (self._integral(g, c, head_m) - self._integral(g, c, head_m - length_m)) / length_m

    def mean_curve_resistance(self, head_m: float, length_m: float) -> float:
        g, c = self._curve_slope, self._curve_cum
        return (self._integral(g, c, head_m) - self._integral(g, c, head_m - length_m)) / length_m

    def mean_path_resistance(self, head_m: float, length_m: float) -> float:
        """Gradient + curve specific resistance [N/kN] averaged over the train."""
        return self.mean_gradient(head_m, length_m) + self.mean_curve_resistance(head_m, length_m)

    def speed_limit_mps(self, x: float, category: str) -> float:
        k = bisect.bisect_right(self.limit_starts, x) - 1
        return self.limits_mps[category][max(k, 0)]

    def station(self, name: str) -> Optional[Station]:
        return next((s for s in self.stations if s.name == name), None)


def check_carrier_under_traction(carrier_hz: float, electrification: str, where: str) -> None:
    """A 50 Hz ALSN carrier cannot be told from the traction current's own 50 Hz fundamental on
    an AC line, so such a pairing is refused (docs/sources.md#alsn-carriers-and-aspects, row 1);
    ``where`` names the field that set the carrier, in the message."""
    if electrification == "AC25000" and carrier_hz == 50:
        raise FmuInputError(f"{where}: a 50 Hz ALSN carrier cannot be used under 50 Hz AC traction "
                            "(electrification.system AC25000); use 25 or 75 Hz")


def load_line(path=DEFAULT_LINE) -> Line:
    path = Path(path)
    document = load_json(path, "line.schema.json")
    for k, section in enumerate(document["block_sections"]):
        check_carrier_under_traction(section["carrier_hz"], document["electrification"]["system"],
                                     f"{path}: field block_sections[{k}].carrier_hz")
    return Line(document, path)


# ---- rolling stock -----------------------------------------------------------------------------
def _curve(points, path, field: str, monotonic: bool = True) -> Tuple[List[float], List[float]]:
    speeds = [p[0] * MPS_PER_KMH for p in points]
    forces = [p[1] * 1000.0 for p in points]
    for k in range(1, len(speeds)):
        if speeds[k] <= speeds[k - 1]:
            _fail(path, f"{field}[{k}]", "speeds must increase")
    for k, f in enumerate(forces):
        if f < 0:
            _fail(path, f"{field}[{k}]", "effort must not be negative")
    for k in range(1, len(forces) if monotonic else 0):
        if forces[k] > forces[k - 1] + 1e-9:
            _fail(path, f"{field}[{k}]", "effort must not increase with speed (non-monotonic table)")
    return speeds, forces


@dataclass
class RollingStock:
    name: str
    category: str
    length_m: float
    max_speed_mps: float
    gamma: float
    mass_kg: float
    powered_mass_kg: float
    resistance_terms: List[Tuple[float, float, float, float]]  # (weight share, a, b, c) per V km/h
    effort_speeds: List[float]
    effort_forces: List[float]
    notches: int
    efficiency: float
    auxiliary_w: float
    adhesion: Tuple[float, ...]
    ebrake_kind: Optional[str]
    ebrake_speeds: List[float]
    ebrake_forces: List[float]
    ebrake_efficiency: float
    brake_kind: str
    service_decel: float
    emergency_decel: float
    brake_delay_s: float
    brake_time_constant_s: float
    brake_steps: int
    electrical_system: str
    power_factor: float
    starting_resistance: float   # N/kN near standstill (roller bearings, ПТР 28/(q0+7))
    path: Path
    # (weight share, a, b, c) with no tractive effort (coasting, braking): a unit's
    # resistance_idle where given, else its resistance
    idle_resistance_terms: Optional[List[Tuple[float, float, float, float]]] = None
    # every wheelset's distance behind the first one, m, ascending (0 first): the axle layout
    # the rail line shunts the track circuits with (wheelset_offsets)
    wheelset_offsets_m: Optional[np.ndarray] = None


DEFAULT_WHEELBASE_PER_GAP_M = 2.4      # a bogie's outer axles apart per gap between axles [U]
DEFAULT_BOGIE_CENTRES_SHARE = 0.7      # bogie pivots apart / body length [U]


def _unit_length(u: dict) -> float:
    """A unit's given length over its bodies (m): bodies × vehicle_length_m, an articulated set's
    two end bodies at end_body_length_m."""
    bodies, body = u.get("bodies", 1), u["vehicle_length_m"]
    if u.get("articulated", False):
        return u["count"] * ((bodies - 2) * body + 2 * u.get("end_body_length_m", body))
    return u["count"] * bodies * body


def _articulated_pivots(u: dict, k: int, path) -> List[float]:
    """Bogie pivots of one articulated vehicle from its front (m): a Jacobs bogie at each joint
    between two bodies, the end bogies ``bogie_centres_m`` ahead of the first joint and behind the
    last (docs/traction.md)."""
    bodies = u.get("bodies", 1)
    if bodies < 2:
        _fail(path, f"units[{k}].bodies", "an articulated vehicle needs at least 2 bodies")
    body = float(u["vehicle_length_m"])
    end = float(u.get("end_body_length_m", body))
    centres = float(u.get("bogie_centres_m", body))
    joints = [end + j * body for j in range(bodies - 1)]
    if centres > end:
        _fail(path, f"units[{k}].bogie_centres_m", f"an end bogie {centres:g} m from the joint lies outside "
                                                   f"the {end:g} m end body")
    return [joints[0] - centres] + joints + [joints[-1] + centres]


def wheelset_offsets(document: dict, path) -> np.ndarray:
    """The train's wheelsets as distances behind its first one (m, ascending, 0 first), from its
    units' bodies placed nose to tail from the front (docs/interfaces.md#rolling-stock-file): a
    body of length L on two bogies whose pivots are ``bogie_centres_m`` apart, centred in it, each
    bogie's axles spread evenly over ``bogie_wheelbase_m``; an articulated vehicle's bodies share a
    bogie at each joint. Bodies without a length share what the train's length_m leaves equally."""
    units = document["units"]
    length = float(document["length_m"])
    for k, u in enumerate(units):
        if u.get("articulated", False) and "vehicle_length_m" not in u:
            _fail(path, f"units[{k}].vehicle_length_m", "an articulated vehicle needs its bodies' length")
    given = sum(_unit_length(u) for u in units if "vehicle_length_m" in u)
    sharing = sum(u["count"] * u.get("bodies", 1) for u in units if "vehicle_length_m" not in u)
    if given > length + 1e-6:
        _fail(path, "units", f"the bodies' vehicle_length_m add up to {given:g} m, more than the train's "
                             f"length_m {length:g} m")
    shared = (length - given) / sharing if sharing else 0.0
    if sharing and shared <= 0.0:
        _fail(path, "units", f"no length left for the {sharing} bodies without vehicle_length_m "
                             f"(length_m {length:g} m, the others take {given:g} m)")
    positions: List[float] = []
    front = 0.0
    for k, u in enumerate(units):
        bodies = u.get("bodies", 1)
        articulated = u.get("articulated", False)
        bogies = bodies + 1 if articulated else 2 * bodies
        if u["axles"] % bogies:
            _fail(path, f"units[{k}].axles", f"{u['axles']} axles do not divide onto {bogies} bogies "
                                             f"of {bodies} {'articulated ' if articulated else ''}bodies")
        per_bogie = u["axles"] // bogies
        body = float(u.get("vehicle_length_m", shared))
        # absent values are defaults that always fit: a bogie at most 0.3 of the body, its pivots
        # at most 0.9 of the rest apart (the outer axles stay inside the body)
        wheelbase = float(u.get("bogie_wheelbase_m",
                                min(DEFAULT_WHEELBASE_PER_GAP_M * (per_bogie - 1), 0.3 * body)))
        axles = (np.linspace(-0.5, 0.5, per_bogie) * wheelbase) if per_bogie > 1 else np.zeros(1)
        if articulated:
            pivots = _articulated_pivots(u, k, path)
            vehicle = _unit_length(u) / u["count"]
            if pivots[0] < 0.5 * wheelbase:
                _fail(path, f"units[{k}].bogie_wheelbase_m", f"an end bogie's {wheelbase:g} m wheelbase "
                                                             f"reaches beyond the end body")
            for _ in range(u["count"]):
                for pivot in pivots:
                    positions += (front + pivot + axles).tolist()
                front += vehicle
            continue
        centres = float(u.get("bogie_centres_m", min(DEFAULT_BOGIE_CENTRES_SHARE * body, 0.9 * (body - wheelbase))))
        if centres + wheelbase > body + 1e-9:
            _fail(path, f"units[{k}].bogie_centres_m", f"bogies {centres:g} m apart with a {wheelbase:g} m "
                                                       f"wheelbase do not fit in a {body:g} m body")
        for _ in range(u["count"] * bodies):
            overhang = 0.5 * (body - centres)
            for pivot in (overhang, overhang + centres):
                positions += (front + pivot + axles).tolist()
            front += body
    offsets = np.array(positions) - positions[0]
    return offsets


def load_rolling_stock(path=DEFAULT_ROLLING_STOCK) -> RollingStock:
    path = Path(path)
    doc = load_json(path, "rolling_stock.schema.json")
    total = sum(u["count"] * u["mass_t"] for u in doc["units"]) * 1000.0
    powered = sum(u["count"] * u["mass_t"] for u in doc["units"] if u["powered"]) * 1000.0
    if powered <= 0:
        _fail(path, "units", "no powered vehicle")
    terms, idle_terms, start_res = [], [], 0.0
    for k, u in enumerate(doc["units"]):
        share = u["count"] * u["mass_t"] * 1000.0 / total
        q0 = u["mass_t"] / u["axles"]
        for key, into in (("resistance", terms), ("resistance_idle" if "resistance_idle" in u else "resistance", idle_terms)):
            r = u[key]
            a, b, c = r["a"], r["b"], r["c"]
            if "per_axle_load" in r:
                p0, p1, p2 = r["per_axle_load"]
                a, b, c = a + p0 / q0, b + p1 / q0, c + p2 / q0
            if a <= 0:
                _fail(path, f"units[{k}].{key}.a", "main resistance must be positive")
            into.append((share, a, b, c))
        start_res += share * 28.0 / (q0 + 7.0)
    speeds, forces = _curve(doc["traction"]["effort_kn"], path, "traction.effort_kn")
    eb = doc.get("electric_brake")
    eb_speeds, eb_forces = _curve(eb["effort_kn"], path, "electric_brake.effort_kn", monotonic=False) if eb else ([0.0, 1.0], [0.0, 0.0])
    pb = doc["pneumatic_brake"]
    if pb["emergency_decel_mps2"] < pb["service_decel_mps2"]:
        _fail(path, "pneumatic_brake.emergency_decel_mps2", "must be at least the service deceleration")
    electrical = doc["electrical"]
    return RollingStock(
        name=doc["name"], category=doc["category"], length_m=float(doc["length_m"]),
        max_speed_mps=doc["max_speed_kmh"] * MPS_PER_KMH, gamma=float(doc["rotating_mass_factor"]),
        mass_kg=total, powered_mass_kg=powered, resistance_terms=terms,
        effort_speeds=speeds, effort_forces=forces, notches=int(doc["traction"].get("notches", 1)),
        efficiency=float(doc["traction"]["efficiency"]), auxiliary_w=doc["traction"]["auxiliary_kw"] * 1000.0,
        adhesion=tuple(doc["traction"]["adhesion"]),
        ebrake_kind=eb["kind"] if eb else None, ebrake_speeds=eb_speeds, ebrake_forces=eb_forces,
        ebrake_efficiency=float(eb.get("efficiency", 0.8)) if eb else 0.0,
        brake_kind=pb["kind"], service_decel=float(pb["service_decel_mps2"]),
        emergency_decel=float(pb["emergency_decel_mps2"]), brake_delay_s=float(pb["delay_s"]),
        brake_time_constant_s=float(pb["time_constant_s"]), brake_steps=int(pb.get("steps", 7)),
        electrical_system=electrical["system"], power_factor=float(electrical.get("power_factor", 1.0)),
        starting_resistance=start_res, path=path, idle_resistance_terms=idle_terms,
        wheelset_offsets_m=wheelset_offsets(doc, path))


# ---- timetable ---------------------------------------------------------------------------------
@dataclass(frozen=True)
class TimetableStop:
    station: str
    stop_m: float
    arrival_s: Optional[float]
    departure_s: Optional[float]


def load_timetable(path, line: Line) -> List[TimetableStop]:
    path = Path(path)
    doc = load_json(path, "timetable.schema.json")
    stops, last_time, last_x = [], None, None
    for k, item in enumerate(doc["stops"]):
        station = line.station(item["station"])
        if station is None:
            _fail(path, f"stops[{k}].station", f"{item['station']!r} is not a station of line {line.name!r}")
        arrival, departure = item.get("arrival_s"), item.get("departure_s")
        dwell = item.get("dwell_s")
        if dwell is not None:
            if dwell < 0:
                _fail(path, f"stops[{k}].dwell_s", f"negative dwell {dwell}")
            if arrival is not None and departure is None:
                departure = arrival + dwell
        if arrival is not None and departure is not None and departure < arrival:
            _fail(path, f"stops[{k}].departure_s", "departure before arrival (negative dwell)")
        if k == 0 and departure is None:
            _fail(path, "stops[0].departure_s", "the first stop needs a departure time")
        if k > 0 and arrival is None:
            _fail(path, f"stops[{k}].arrival_s", "every stop after the first needs an arrival time")
        for value, name in ((arrival, "arrival_s"), (departure, "departure_s")):
            if value is not None:
                if last_time is not None and value < last_time:
                    _fail(path, f"stops[{k}].{name}", f"{value} s is earlier than the previous time {last_time} s")
                last_time = value
        if last_x is not None and station.stop_m <= last_x:
            _fail(path, f"stops[{k}].station", "stations must follow the running direction")
        last_x = station.stop_m
        stops.append(TimetableStop(station.name, station.stop_m, arrival, departure))
    return stops

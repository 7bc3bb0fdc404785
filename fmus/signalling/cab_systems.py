"""The cab-signal systems railcosim runs, declared once: one :class:`CabSystem` descriptor per
system in :data:`REGISTRY`, by its ``system`` parameter (docs/cab_systems.md). Every place that
treats systems differently reads the descriptor — its code table, its chain's sample rate and
build, the receiver's stated latency, the ATO's ``cab_signal`` mode, the receiver outputs the
ATO and the verdicts read, the track circuits it needs, what ``railcosim new`` offers, the
legend of its indications. Below the signalling wall the coder and the receiver keep a map of
name → core (fmus/wayside_coder/cores.py, fmus/loco_receiver/cores.py).

Adding a system: its signalling module here (the code table, the system object with
``reading``/``indication``/``command_of_code``/``at_most``, the block rules' coding with
``codes(rules)``), its coder and receiver cores with their map entries, its ATP mode
(fmus/ato_controller/) and one descriptor below.

Families (how a coder's ``code_tx`` is read, one rule per family, not per system):

* ``NUMERIC``: ALSN, whose ``code_tx`` is in the aspect enumeration (no system object);
* ``TABLE``: ALSU, TVM-430, TVM-300 — the block rules' coding (``system.block_coding``) gives
  each circuit's code, the system object reads it;
* ``DIGITAL``: ALS-EN, FIRE_DQPSK — a command per number of free blocks (``command_for``).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Dict, Mapping, Optional, Tuple

from fmus.errors import FmuInputError
from fmus.signalling import als_en, alsn, alsu, fire_dqpsk, tvm300, tvm430
from fmus.signalling import aspects as sig
from fmus.signalling import digital_messages as digital
from fmus.signalling.ato_modes import AtoMode
from fmus.signalling.digital_messages import DigitalSystem
from fmus.sizes import DEFAULT_SAMPLE_RATE_HZ
from fmus.units import KMH_PER_MPS, MPS_PER_KMH

NUMERIC, TABLE, DIGITAL_FAMILY = "numeric", "table", "digital"
#: the track circuits a system's coder feeds (the line file's ``transmitter``): KPT coded track
#: circuits with insulated joints, UM71 jointless audio-frequency circuits
KPT, UM71 = "KPT", "UM71"


@dataclass(frozen=True)
class CabSystem:
    """One cab-signal system, as every part of railcosim needs to know it."""

    name: str                                   # the `system` parameter
    title: str                                  # as engineers write it
    summary: str                                # one line: what it is
    family: str                                 # NUMERIC, TABLE or DIGITAL_FAMILY
    ato_mode: str                               # AtoMode
    transmitter: str                            # KPT or UM71: the track circuits it needs
    codes_file: Optional[Path]                  # the bundled code table (a `codes_file` replaces it)
    load_codes: Optional[Callable[[Path], object]]
    #: the system object read from a code table (None: the bundled one); None for NUMERIC
    make_system: Callable[[Optional[str]], object]
    #: the receiver's stated latency (s) from its parameters: a loss or restrictive change of
    #: code to the restrictive display (the verdicts' allowance)
    latency_s: Callable[[Mapping[str, object]], float]
    #: the ATO's ``decoding_latency`` for this system's chain (s); None: the ATO's default
    atp_latency_s: Callable[[], Optional[float]]
    #: the (coder, rail line, receiver) parameters of its chain beyond the common ones
    chain_parameters: Callable[[], Tuple[dict, dict, dict]]
    #: receiver output → ATO input, besides the common chain ports (aspect, code_valid, …)
    ato_links: Tuple[Tuple[str, str], ...] = ()
    #: receiver outputs the verdicts compare besides the common ones (system.shows_beyond)
    judged_outputs: Tuple[str, ...] = ()
    #: the chain's sample rate (Hz) and the block sections its signal FMUs are built for (None:
    #: the build's); shipped lines of its own
    sample_rate_hz: float = DEFAULT_SAMPLE_RATE_HZ
    build_sections: Tuple[int, ...] = ()
    default_stock: Optional[str] = None         # bundled rolling-stock file its systems run
    #: the receiver tunes one carrier for the whole line (its band-pass, drawn by the report)
    one_carrier: bool = False
    #: that carrier is the line file's (``carrier_hz``, one for all sections), not the system's own
    line_carrier: bool = False
    #: a receiver's outputs for a valid code as the ATO reads them (the headway's approach)
    receiver_outputs: Callable[..., dict] = field(default=None, repr=False)
    #: the indication in the system's own terms: "КЖ", "code 4", "270→220", …
    label: Callable[[Mapping[str, float]], str] = field(default=None, repr=False)
    #: the values a coder's ``code_tx`` and a receiver's ``code`` take besides 0 (no code), from
    #: the system object; None where they are too many to name (TVM-430's 27-bit words)
    code_values: Optional[Callable[[object], Tuple[int, ...]]] = field(default=None, repr=False)
    #: its indications are speed steps (TVM), drawn by step rather than in the aspect colours
    speed_steps: bool = False

    def system(self, codes_file: Optional[str] = None):
        """The system object (None for ALSN: its codes are aspects)."""
        return self.make_system(codes_file)

    def code_labels(self, system=None, category: str = "passenger") -> Dict[int, str]:
        """What each value of a coder's ``code_tx`` and a receiver's ``code`` stands for, in the
        system's own terms (:attr:`label` of the indication a receiver of ``category`` shows for
        it, and its aspect; 0: none), for the legends of a run's results (columns.json); empty
        where the values are not named (:attr:`code_values` None). ``system``: the system object (None: the
        bundled table's)."""
        if self.code_values is None:
            return {}
        system = system if system is not None or self.family == NUMERIC else self.system()
        labels = {0: "none"}
        for value in self.code_values(system):
            command = value if self.family == NUMERIC else system.command_of_code(value)
            if command is None:
                continue
            received = self.receiver_outputs(system, command, category, 0.0, 0.0)
            shown = self.label(received)
            # a numeric code is its aspect's letter; another's label is told apart by its aspect
            labels[int(value)] = shown if self.family == NUMERIC else f"{shown} ({ASPECT_LABELS[received['aspect']]})"
        return labels

    def ato_parameters(self) -> dict:
        latency = self.atp_latency_s()
        return {"cab_signal": self.ato_mode, **({} if latency is None else {"decoding_latency": round(latency, 3)})}


# ---- each system's own rules, as the descriptors name them ---------------------------------------------
ALSN_LETTERS = {sig.GREEN: "З", sig.YELLOW: "Ж", sig.RED_YELLOW: "КЖ", sig.WHITE: "Б", sig.RED: "К"}


def _alsn_outputs(system, code: int, category: str, v_max_mps: float, carrier_hz: float) -> dict:
    v_max = v_max_mps or sig.CATEGORY_MAX_KMH[category] * MPS_PER_KMH
    permitted, target, free = alsn.speeds_for(category, code, v_max)
    return dict(aspect=int(code), code=int(code), v_permitted=permitted, v_target=target, free_blocks=free)


def _alsu_outputs(system, code: int, category: str, v_max_mps: float, carrier_hz: float) -> dict:
    ind = system.indication(int(code), category)
    ceiling_kmh = min(ind.permitted_kmh, v_max_mps * KMH_PER_MPS or alsu.CATEGORY_MAX_KMH[category])
    return dict(aspect=ind.aspect, code=ind.code, v_permitted=ceiling_kmh * MPS_PER_KMH,
                v_target=min(ind.target_kmh, ceiling_kmh) * MPS_PER_KMH, free_blocks=ind.free_blocks)


def _tvm430_outputs(system, code: int, category: str, v_max_mps: float, carrier_hz: float) -> dict:
    read = system.reading(int(code))
    return dict(aspect=read.aspect, code=int(code), v_permitted=read.step_kmh * MPS_PER_KMH,
                v_target=read.next_kmh * MPS_PER_KMH, free_blocks=read.free_blocks,
                target_distance_m=read.target_distance_m, gradient_permille=read.gradient_permille,
                word_carrier_hz=carrier_hz)


def _tvm300_outputs(system, code: int, category: str, v_max_mps: float, carrier_hz: float) -> dict:
    read = system.reading(int(code))
    return dict(aspect=read.aspect, code=int(code), v_permitted=read.step_kmh * MPS_PER_KMH,
                v_target=read.next_kmh * MPS_PER_KMH, free_blocks=read.free_blocks, word_carrier_hz=carrier_hz)


def _digital_outputs(system, code: int, category: str, v_max_mps: float, carrier_hz: float) -> dict:
    ind = system.indication(int(code), category)
    ceiling = ind.permitted_kmh * MPS_PER_KMH
    if v_max_mps > 0:
        ceiling = min(ceiling, v_max_mps)
    return dict(aspect=ind.aspect, code=ind.code, v_permitted=ceiling,
                v_target=min(ind.target_kmh * MPS_PER_KMH, ceiling), free_blocks=ind.free_blocks)


def _steps_label(received: Mapping[str, float]) -> str:
    return f"{received['v_permitted'] * KMH_PER_MPS:.0f}→{received['v_target'] * KMH_PER_MPS:.0f}"


def _digital_label(received: Mapping[str, float]) -> str:
    return f"free {received['free_blocks']}, {received['v_target'] * KMH_PER_MPS:.0f} km/h"


def _digital_latency(system: DigitalSystem) -> Callable[[Mapping[str, object]], float]:
    def latency(parameters: Mapping[str, object]) -> float:
        carrier = float(parameters.get("carrier", 0.0) or system.carrier_hz)
        return digital.stated_latency_s(system.message_s(carrier))
    return latency


def _digital_codes(system: DigitalSystem) -> Tuple[int, ...]:
    """The ids a digital coder's ``code_tx`` and receiver's ``code`` show (ALS-EN: the KLUB
    registers; FIRE_DQPSK: the commands)."""
    return tuple(sorted({system.indication(command, "passenger").code for command in system.commands()}))


def _digital_descriptor(system: DigitalSystem, title: str, summary: str) -> CabSystem:
    return CabSystem(
        name=system.name, title=title, summary=summary, family=DIGITAL_FAMILY, ato_mode=AtoMode.DIGITAL,
        transmitter=KPT, codes_file=None, load_codes=None, make_system=lambda _codes_file=None: system,
        latency_s=_digital_latency(system),
        atp_latency_s=lambda: digital.atp_allowance_s(system.message_s(system.carrier_hz)),
        chain_parameters=lambda: ({"system": system.name}, {"carrier": system.carrier_hz}, {"system": system.name}),
        one_carrier=True, receiver_outputs=_digital_outputs, label=_digital_label, code_values=_digital_codes)


#: ALSU's coder keys the 4-aspect block (its codes are read against the signal after next)
ALSU_BLOCK_ASPECTS = 4


def _alsu_chain() -> Tuple[dict, dict, dict]:
    tones = alsu.system().table.tones_hz
    return ({"system": alsu.NAME, "block_aspects": ALSU_BLOCK_ASPECTS},
            {"tone_band_min": min(tones), "tone_band_max": max(tones)}, {"system": alsu.NAME})


ALSN = CabSystem(
    name="ALSN", title="ALSN", summary="numeric codes З/Ж/КЖ on one carrier (25/50/75 Hz), KPT transmitters",
    family=NUMERIC, ato_mode=AtoMode.ALSN, transmitter=KPT, codes_file=alsn.CODES_FILE,
    load_codes=alsn.load_transmitters, make_system=lambda _codes_file=None: None,
    latency_s=lambda _parameters: alsn.STATED_LATENCY_S, atp_latency_s=lambda: None,
    chain_parameters=lambda: ({}, {}, {}), one_carrier=True, line_carrier=True, receiver_outputs=_alsn_outputs,
    label=lambda received: ALSN_LETTERS[int(received["aspect"])],
    code_values=lambda _system: tuple(sorted(alsn.CODE_NAMES.values())))
ALSU = CabSystem(
    name=alsu.NAME, title="ALSU", summary="two of six tones per code, 13 codes (alsu_codes.json)",
    family=TABLE, ato_mode=AtoMode.ALSU, transmitter=KPT, codes_file=alsu.CODES_FILE, load_codes=alsu.load_codes,
    make_system=lambda codes_file=None: alsu.system(codes_file), latency_s=lambda _parameters: alsu.STATED_LATENCY_S,
    atp_latency_s=lambda: alsu.STATED_LATENCY_S, chain_parameters=_alsu_chain, ato_links=(("code", "cab_code"),),
    receiver_outputs=_alsu_outputs, label=lambda received: f"code {int(received['code'])}",
    code_values=lambda system: system.codes())
ALS_EN = _digital_descriptor(als_en.SYSTEM, "ALS-EN", "double relative phase modulation at 175 Hz, Bauer-coded words")
FIRE_DQPSK = _digital_descriptor(fire_dqpsk.SYSTEM, "Fire/π/4-DQPSK",
                                 "16 commands with a Fire code over π/4-DQPSK (the thesis' proposal)")
TVM430 = CabSystem(
    name=tvm430.NAME, title="TVM-430", summary="27-bit word of very-low tones on UM71 carriers, continuous curves",
    family=TABLE, ato_mode=AtoMode.TVM430, transmitter=UM71, codes_file=tvm430.CODES_FILE,
    load_codes=tvm430.load_codes, make_system=lambda codes_file=None: tvm430.system(codes_file),
    latency_s=lambda _parameters: tvm430.STATED_LATENCY_S, atp_latency_s=lambda: tvm430.STATED_LATENCY_S,
    chain_parameters=lambda: ({"system": tvm430.NAME}, {}, {"system": tvm430.NAME}),
    ato_links=(("target_distance", "target_distance"), ("gradient", "gradient"), ("word_carrier", "word_carrier")),
    judged_outputs=("target_distance", "gradient"), sample_rate_hz=12000.0, build_sections=(8, 16, 32, 64),
    default_stock="high_speed_tgv.json", receiver_outputs=_tvm430_outputs, label=_steps_label, speed_steps=True)
TVM300 = CabSystem(
    name=tvm300.NAME, title="TVM-300", summary="one of 18 sub-frequencies on UM71 carriers, a cascade of fixed steps",
    family=TABLE, ato_mode=AtoMode.TVM300, transmitter=UM71, codes_file=tvm300.CODES_FILE,
    load_codes=tvm300.load_codes, make_system=lambda codes_file=None: tvm300.system(codes_file),
    latency_s=lambda _parameters: tvm300.STATED_LATENCY_S, atp_latency_s=lambda: tvm300.STATED_LATENCY_S,
    chain_parameters=lambda: ({"system": tvm300.NAME}, {}, {"system": tvm300.NAME}),
    ato_links=(("word_carrier", "word_carrier"),), sample_rate_hz=12000.0, build_sections=(8, 16, 32, 64),
    default_stock="high_speed_tgv.json", receiver_outputs=_tvm300_outputs, label=_steps_label, speed_steps=True,
    code_values=lambda system: tuple(c for c in range(1, tvm300.SUB_FREQUENCY_COUNT + 1) if system.reading(c)))

#: the aspect enumeration every system's receiver shows (its ``aspect``, the ATO's ``atp_aspect``)
ASPECT_LABELS: Mapping[int, str] = sig.ASPECT_NAMES

REGISTRY: Dict[str, CabSystem] = {s.name: s for s in (ALSN, ALSU, ALS_EN, FIRE_DQPSK, TVM430, TVM300)}
NAMES = tuple(REGISTRY)
DEFAULT = ALSN
DIGITAL = {name: s.system() for name, s in REGISTRY.items() if s.family == DIGITAL_FAMILY}
#: a signal FMU steps one frame of this length (s) at every system's sample rate (4 kHz: 40
#: samples, 12 kHz: 120)
FRAME_S = 0.01


def lookup(name: str, where: str = "parameter system") -> CabSystem:
    """The descriptor of that name; an unknown name is an input error naming ``where``."""
    found = REGISTRY.get(str(name))
    if found is None:
        raise FmuInputError(f"{where}: {name!r} is not one of {', '.join(NAMES)}")
    return found


def spelled(name: str) -> str:
    """A name as a person may type it on a command line, in the registry's spelling: case and
    ``-``/``_`` ignored (``als_en`` → ``ALS-EN``, ``tvm300`` → ``TVM300``); unknown: unchanged."""
    key = str(name).upper().replace("_", "-")
    return next((n for n in NAMES if n.upper().replace("_", "-") == key), str(name))


def of_parameters(parameters: Mapping[str, object]) -> CabSystem:
    """The descriptor a component's parameters name (``system``; none given: the default)."""
    return lookup(str(parameters.get("system") or DEFAULT.name))


def check_name(name: str) -> str:
    """The name itself; an unknown name is an input error."""
    return lookup(name).name


def digital_system(name: str) -> Optional[DigitalSystem]:
    """The digital system of that name, None for the others; an unknown name is an input error."""
    cab = lookup(name)
    return cab.system() if cab.family == DIGITAL_FAMILY else None

"""A study file (JSON or TOML, docs/studies.md): read, checked against schema.json, and expanded
into its runs — every combination of the axes (cases × grid × random draws × scenarios),
each repeated for every seed.

Everything here is decided on the machine that submits the study; the runs themselves
(orchestrator/study/worker.py) only receive plain dictionaries.
"""
from __future__ import annotations

import gc
import hashlib
import itertools
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Dict, List, Optional, Sequence

from orchestrator.errors import UserError, non_finite_number

SCHEMA = Path(__file__).with_name("schema.json")
#: the keys every run reports unless the study names its own (derived from summary.json:
#: orchestrator/study/collect.py)
DEFAULT_COLLECT = ("verdict", "signals_passed_at_danger", "wrong_side_failures", "unsafe_indications")
DEFAULT_TIMEOUT_S = 3600.0
#: names an axis may not use: they are columns of study.csv already
RESERVED = ("id", "point", "seed", "status", "error", "wall_time_s", "scenario")
#: the runs a study may have without being asked for more (`railcosim study --yes`): each run
#: writes a folder of its own (a system run's results.csv is tens of kB to MBs), and 10 000 runs
#: are 7-10 minutes on two workers at the fastest rate measured (docs/studies.md#throughput),
#: hours for runs of a few seconds
MAX_RUNS = 10_000
#: the runs a study may have at all, --yes or not: the submitting side holds every run and its
#: record (about 2 kB each: 2 GB at this bound); a larger campaign is several studies. The
#: schema bounds random.count by the same number, before any draw is made
HARD_MAX_RUNS = 1_000_000
#: how deeply a study file's tables and lists may nest (the deepest field a study has is
#: random.variables.NAME.values[k]: 4); deeper is refused before the schema walks it
MAX_DEPTH = 32


@dataclass(slots=True)    # a million of them in a large study
class Run:
    id: str                      # r0000 … : the folder DIR/runs/<id>/
    point: int                   # index of the point (all axes but the seed)
    values: Dict[str, object]    # axis name → value (COMP.VAR, or keyword of a function)
    seed: Optional[int] = None
    scenario: Optional[str] = None   # absolute path of the point's scenario file


@dataclass
class StudySpec:
    path: Path
    name: str
    data: dict                          # the file's content, as validated
    runs: List[Run] = field(default_factory=list)
    axes: List[str] = field(default_factory=list)   # axis names in order (+ "scenario" when an axis)

    @property
    def is_function(self) -> bool:
        return "function" in self.data

    @property
    def collect(self) -> List[str]:
        return list(self.data.get("collect", DEFAULT_COLLECT))

    @property
    def safety(self) -> List[str]:
        given = self.data.get("safety")
        if given is not None:
            return list(given)
        return [k for k in self.collect if k in DEFAULT_COLLECT[1:]]

    @property
    def timeout_s(self) -> float:
        return float(self.data.get("timeout_s", DEFAULT_TIMEOUT_S))

    @property
    def hash(self) -> str:
        """Hash of what decides the runs' results: the file's content as read (key order
        aside) and the scenario files' bytes. A run folder from another hash is not reused."""
        digest = hashlib.sha256(json.dumps(self.data, sort_keys=True).encode())
        for scenario in sorted({r.scenario for r in self.runs if r.scenario}):
            digest.update(Path(scenario).read_bytes())
        return digest.hexdigest()[:16]


def set_text(value) -> str:
    """A value as --set takes it."""
    if isinstance(value, bool):
        return "true" if value else "false"
    return repr(value) if isinstance(value, float) else str(value)


def _read(path: Path) -> dict:
    data = _parse(path)
    bad = non_finite_number(data)          # TOML's nan and inf, JSON's NaN and Infinity
    if bad is not None:
        raise UserError(f"study {path}: field {bad[0]}: {bad[1]} is not a finite number")
    return data


def _parse(path: Path) -> dict:
    if not path.is_file():
        raise UserError(f"study {path}: no such file")
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as error:
        raise UserError(f"study {path}: cannot read ({error})") from None
    too_deep = UserError(f"study {path}: tables or lists nested more than {MAX_DEPTH} deep; a study file "
                         "nests a few levels")
    if path.suffix.lower() == ".toml":
        import tomllib

        try:
            data = tomllib.loads(text)
        except tomllib.TOMLDecodeError as error:
            raise UserError(f"study {path}: not valid TOML ({error})") from None
        except RecursionError:             # the readers recurse once per level of nesting
            raise too_deep from None
    elif path.suffix.lower() == ".json":
        try:
            data = json.loads(text)
        except json.JSONDecodeError as error:
            raise UserError(f"study {path}:{error.lineno}: not valid JSON ({error.msg})") from None
        except RecursionError:
            raise too_deep from None
    else:
        raise UserError(f"study {path}: a study file is .toml or .json")
    if _depth(data) > MAX_DEPTH:
        raise too_deep
    return data


def _depth(document) -> int:
    """How deeply ``document``'s dictionaries and lists nest (a walk without recursion)."""
    deepest, pending = 0, [(document, 1)]
    while pending:
        value, level = pending.pop()
        if isinstance(value, (dict, list)):
            deepest = max(deepest, level)
            pending.extend((item, level + 1) for item in (value.values() if isinstance(value, dict) else value))
    return deepest


def run_count(data: dict) -> tuple:
    """(runs, points) of a validated study file's content, from its lengths alone (before any
    point is made or drawn)."""
    points = len(data.get("cases", [{}])) * len(data.get("scenarios", [None]))
    for values in data.get("grid", {}).values():
        points *= len(values)
    points *= data["random"]["count"] if "random" in data else 1
    return points * len(data.get("seeds", [None])), points


def _field(error) -> str:
    parts = [str(p) if isinstance(p, int) else p for p in error.absolute_path]
    return ".".join(parts) or "(top level)"


def _validate(path: Path, data: dict) -> None:
    import jsonschema

    schema = json.loads(SCHEMA.read_text())
    error = jsonschema.exceptions.best_match(jsonschema.Draft202012Validator(schema).iter_errors(data))
    if error is not None:
        raise UserError(f"study {path}: field {_field(error)}: {error.message}")
    if ("system" in data) == ("function" in data):
        raise UserError(f"study {path}: give either 'system' (a run of a system) or 'function' "
                        "(module:callable), not both or neither")
    for name, dist in data.get("random", {}).get("variables", {}).items():
        where = f"study {path}: field random.variables.{name}"
        needs = {"uniform": ("low", "high"), "normal": ("mean", "std"), "choice": ("values",)}[dist["distribution"]]
        missing = [k for k in needs if k not in dist]
        extra = [k for k in dist if k not in needs and k != "distribution"]
        if missing or extra:
            raise UserError(f"{where}: a {dist['distribution']} distribution takes {' and '.join(needs)}"
                            + (f" (missing {', '.join(missing)})" if missing else "")
                            + (f" (not {', '.join(extra)})" if extra else ""))
        if dist["distribution"] == "uniform" and not dist["low"] < dist["high"]:
            raise UserError(f"{where}: low {dist['low']} must be below high {dist['high']}")
    names = [k for case in data.get("cases", []) for k in case] + list(data.get("grid", {})) \
        + list(data.get("random", {}).get("variables", {}))
    for name in names:
        if name in RESERVED:
            raise UserError(f"study {path}: axis {name!r} is a column of study.csv; name it otherwise")
    keys_of = [set(c) for c in data.get("cases", [])]
    grid, drawn = set(data.get("grid", {})), set(data.get("random", {}).get("variables", {}))
    cased = set().union(*keys_of) if keys_of else set()
    for left, right, label in ((grid, drawn, "grid and random"), (cased, grid, "cases and grid"),
                               (cased, drawn, "cases and random")):
        if left & right:
            raise UserError(f"study {path}: {', '.join(sorted(left & right))} is an axis of both {label}")
    if "function" in data and "collect" not in data:
        raise UserError(f"study {path}: field collect: a function study names the keys of its "
                        "function's result to collect")
    collected = data.get("collect", DEFAULT_COLLECT)
    for k, key in enumerate(data.get("safety", [])):
        if key not in collected:      # the report would sum a column study.csv does not have
            raise UserError(f"study {path}: field safety.{k}: {key!r} is not collected; the report sums "
                            f"and searches only collected keys: add it to collect ({', '.join(collected)})")
    if "seed_variables" in data and "function" in data:
        raise UserError(f"study {path}: field seed_variables: a function study receives its seed as "
                        "the keyword 'seed'")


def _draws(random: dict) -> List[Dict[str, object]]:
    """``count`` draws of every variable, from one generator seeded by ``seed`` (variables in
    name order, so a file's key order does not change the values)."""
    import numpy as np

    rng = np.random.default_rng(random["seed"])
    names = sorted(random["variables"])
    columns = {}
    for name in names:
        dist = random["variables"][name]
        count = random["count"]
        if dist["distribution"] == "uniform":
            columns[name] = [float(v) for v in rng.uniform(dist["low"], dist["high"], count)]
        elif dist["distribution"] == "normal":
            columns[name] = [float(v) for v in rng.normal(dist["mean"], dist["std"], count)]
        else:
            columns[name] = [dist["values"][i] for i in rng.integers(0, len(dist["values"]), count)]
    return [{name: columns[name][k] for name in names} for k in range(random["count"])]


def load_study(path, max_runs: int = HARD_MAX_RUNS) -> StudySpec:
    """The study file at ``path``, validated and expanded into its runs; a UserError stating
    its size when it has more than ``max_runs`` runs (at most :data:`HARD_MAX_RUNS`), before
    any point is made."""
    path = Path(path)
    data = _read(path)
    _validate(path, data)
    runs, points = run_count(data)
    if runs > min(max_runs, HARD_MAX_RUNS):
        size = f"study {path}: {runs} runs ({points} points × {len(data.get('seeds', [None]))} seed(s))"
        if runs > HARD_MAX_RUNS:
            raise UserError(f"{size}: more than the {HARD_MAX_RUNS} a study can hold; split it into several studies")
        raise UserError(f"{size}: more than {max_runs} runs, each writing a folder; give --yes to run a study "
                        "this size")
    name = data.get("name", path.stem)
    cases = data.get("cases", [{}])
    grid = data.get("grid", {})
    grid_points = [dict(zip(grid, values)) for values in itertools.product(*grid.values())] or [{}]
    draws = _draws(data["random"]) if "random" in data else [{}]
    scenarios: Sequence[Optional[str]] = [None]
    if "scenarios" in data:
        scenarios = []
        for text in data["scenarios"]:
            file = (path.parent / text).resolve()
            if not file.is_file():
                raise UserError(f"study {path}: field scenarios: {text}: no such file "
                                f"(looked for {file})")
            scenarios.append(str(file))
    seeds: Sequence[Optional[int]] = data.get("seeds", [None])
    spec = StudySpec(path, name, data)
    spec.axes = list(dict.fromkeys([k for c in cases for k in c] + list(grid) + sorted(
        data.get("random", {}).get("variables", {}))))
    if "scenarios" in data:
        spec.axes.append("scenario")
    point = 0
    collecting = gc.isenabled()
    gc.disable()        # nothing made here is garbage: the collector's passes over the growing
    try:                # list would take most of the time of a large study's expansion
        for case, values, drawn, scenario in itertools.product(cases, grid_points, draws, scenarios):
            merged = {**case, **values, **drawn}
            for seed in seeds:
                spec.runs.append(Run(f"r{len(spec.runs):04d}", point, merged, seed, scenario))
            point += 1
    finally:
        if collecting:
            gc.enable()
    return spec


def point_label(run: Run) -> Dict[str, object]:
    """The axis values of a run's point as study.csv shows them (a scenario by its file name)."""
    label = dict(run.values)
    if run.scenario is not None:
        label["scenario"] = Path(run.scenario).name
    return label


def check_against_system(spec: StudySpec, system_path: Path, fmu_dirs: Sequence[Path]) -> None:
    """Every COMP.VAR the study sets (options.set, the axes, seed_variables) names a parameter
    or an unconnected input of the system, and every value of it is one the variable takes;
    the first problem is a UserError naming the field. Nothing is submitted before this."""
    from orchestrator.graph import _parse_value, build_graph
    from orchestrator.ssp import open_system

    data = spec.data
    fields: Dict[str, str] = {}
    for key in data.get("options", {}).get("set", {}):
        fields[key] = f"options.set.{key}"
    for k, case in enumerate(data.get("cases", [])):
        for key in case:
            fields.setdefault(key, f"cases.{k}.{key}")
    for key in data.get("grid", {}):
        fields[key] = f"grid.{key}"
    for key in data.get("random", {}).get("variables", {}):
        fields[key] = f"random.variables.{key}"
    for key in data.get("seed_variables", []):
        fields[key] = "seed_variables"
    system = open_system(Path(system_path), list(fmu_dirs))
    try:
        graph = build_graph(system)
        fed = {(edge.target, edge.target_var.name): edge for edge in graph.edges}
        for key, where in fields.items():
            comp, _, var = key.partition(".")
            node = graph.nodes.get(comp)
            if node is None or not var:
                raise UserError(f"study {spec.path}: field {where}: {key!r} is not COMPONENT.VARIABLE of "
                                f"{system.name} (components: {', '.join(graph.nodes)})")
            variable = node.interface.variables.get(var)
            if variable is None:
                raise UserError(f"study {spec.path}: field {where}: component {comp!r} of {system.name} "
                                f"has no variable {var!r}")
            if variable.causality not in ("parameter", "input") or (comp, var) in fed:
                raise UserError(f"study {spec.path}: field {where}: {key} is "
                                + (f"an input fed by {fed[(comp, var)].source}" if (comp, var) in fed
                                   else f"an {variable.causality}") + "; a study sets parameters")
        values: Dict[str, set] = {}
        for run in spec.runs:
            for key, value in run.values.items():
                values.setdefault(key, set()).add(value)
            for key in data.get("seed_variables", []):
                values.setdefault(key, set()).add(run.seed if run.seed is not None else 0)
        for key, value in data.get("options", {}).get("set", {}).items():
            values.setdefault(key, set()).add(value)
        for key, seen in values.items():
            comp, _, var = key.partition(".")
            variable = graph.nodes[comp].interface.variables[var]
            for value in seen:
                text = set_text(value)
                _parse_value(variable, text, f"study {spec.path}: field {fields[key]}: {key}={text}")
    finally:
        system.close()

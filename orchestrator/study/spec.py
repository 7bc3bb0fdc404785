"""A study file (JSON or TOML, docs/studies.md): read, checked against schema.json, and expanded
into its runs — every combination of the axes (cases × grid × random draws × scenarios),
each repeated for every seed.

Everything here is decided on the machine that submits the study; the runs themselves
(orchestrator/study/runner.py) only receive plain dictionaries.
"""
from __future__ import annotations

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


@dataclass
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
    if path.suffix.lower() == ".toml":
        import tomllib

        try:
            return tomllib.loads(text)
        except tomllib.TOMLDecodeError as error:
            raise UserError(f"study {path}: not valid TOML ({error})") from None
    if path.suffix.lower() == ".json":
        try:
            return json.loads(text)
        except json.JSONDecodeError as error:
            raise UserError(f"study {path}:{error.lineno}: not valid JSON ({error.msg})") from None
    raise UserError(f"study {path}: a study file is .toml or .json")


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


def load_study(path) -> StudySpec:
    """The study file at ``path``, validated and expanded into its runs."""
    path = Path(path)
    data = _read(path)
    _validate(path, data)
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
    for case, values, drawn, scenario in itertools.product(cases, grid_points, draws, scenarios):
        merged = {**case, **values, **drawn}
        for seed in seeds:
            spec.runs.append(Run(f"r{len(spec.runs):04d}", point, merged, seed, scenario))
        point += 1
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

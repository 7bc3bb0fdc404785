"""`railcosim` command line: build, run, report, inspect, validate, new, export, list, contract, conform,
study, dcp-slave, fmu-env, netlist, crosscheck.

Bad input → one line on stderr, exit code 2, no traceback. An interrupted run (SIGINT,
SIGTERM, SIGHUP) writes its results so far and exits with 128 + the signal number: 130, 143,
129 (docs/reliability.md). The process exits with its own status every time (the pythonfmu
exit-time abort is avoided at its cause, see orchestrator/fmu.py FmuSlave.free).
"""
from __future__ import annotations

import argparse
import json
import math
import re
import sys
from pathlib import Path
from typing import List, Optional

from orchestrator.errors import UserError, did_you_mean, print_warning
from orchestrator.interrupts import Interrupted

# A checkout (the README's editable install) runs its committed ssp/ and builds into its own
# build/ wherever the command is started; an installed wheel has no checkout, so it builds into
# ./build and writes the shipped systems there when they are asked for (docs/architecture.md).
PACKAGE_PARENT = Path(__file__).resolve().parent.parent
IN_CHECKOUT = (PACKAGE_PARENT / "pyproject.toml").is_file() and (PACKAGE_PARENT / "ssp").is_dir()
WORK_ROOT = PACKAGE_PARENT if IN_CHECKOUT else Path.cwd()
SSP_ROOT = PACKAGE_PARENT / "ssp" if IN_CHECKOUT else WORK_ROOT / "build" / "ssp"
DEFAULT_SYSTEM = "free_run"
#: build sizes the CLI accepts (fmus/sizes.py has no limit of its own): a frame of 4096 samples
#: is 1 s at 4 kHz, and every FMU holds K×M×N-sized arrays, so larger sizes only build for ages
MAX_SECTIONS, MAX_TRAINS, MAX_FRAME = 64, 16, 4096
#: the largest local Dask cluster `study --workers` makes: each worker is a Python process of its
#: own with its FMUs loaded (about 0.1 GB), and runs are CPU-bound, so beyond this on one machine
#: a study only thrashes; a larger cluster is a --scheduler of its own
MAX_LOCAL_WORKERS = 128


class _Parser(argparse.ArgumentParser):
    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        # argparse reads "-inf", "-nan" and "-1e400" as option names ("expected one argument"):
        # taken as values, so _Number names what is wrong with them
        self._negative_number_matcher = re.compile(r"^-(\d|\.\d|inf|nan)", re.IGNORECASE)

    def error(self, message):  # one line, exit 2 (argparse prints usage on two)
        # main() says "railcosim: error:" once; a subcommand's parser names the subcommand
        where = self.prog.partition(" ")[2]
        raise UserError(f"{where}: {message}" if where else message)


class _Number(argparse.Action):
    """Every numeric option of every command (tests/test_bad_input.py walks the parser for them):
    the text read as ``kind`` (int or float), finite, and within the option's own range —
    ``minimum``/``maximum`` inclusive, ``above`` exclusive — else one line naming the option and
    the value, exit 2, before the command starts. Ranges that depend on data or on the engine
    (the line's sections, a capture's span, the master's clock, the pacing factors) are checked
    where those live."""

    def __init__(self, option_strings, dest, kind=float, minimum=None, maximum=None, above=None, of="", **kwargs):
        super().__init__(option_strings, dest, **kwargs)
        self.kind, self.minimum, self.maximum, self.above = kind, minimum, maximum, above
        self.of = f" of {of}" if of else ""          # the quantity: "of seconds", "of metres"

    def __call__(self, parser, namespace, values, option_string=None):
        command = parser.prog.partition(" ")[2]        # named as _Parser.error names it
        option = option_string or self.option_strings[0]
        setattr(namespace, self.dest, self.parse(values, f"{command}: {option}" if command else option))

    def parse(self, text, option: str):
        shown = str(text) if len(str(text)) <= 40 else f"{str(text)[:20]}… ({len(str(text))} characters)"
        try:
            value = self.kind(text)
        except (TypeError, ValueError):   # int() also refuses digits beyond Python's 4300
            wanted = "an integer" if self.kind is int else "a number"
            raise UserError(f"{option} {shown}: not {wanted}{self.of}") from None
        if not math.isfinite(value):      # float() reads nan, inf and 1e400 (as inf)
            raise UserError(f"{option} {shown}: not a finite number{self.of}")
        low, high = self.minimum, self.maximum
        if (low is not None and value < low) or (high is not None and value > high) or \
                (self.above is not None and value <= self.above):
            if low is not None and high is not None:
                wanted = f"from {low:g} to {high:g}"
            elif self.above is not None:
                wanted = f"more than {self.above:g}" + (f" and at most {high:g}" if high is not None else "")
            else:
                wanted = f"at least {low:g}" if low is not None else f"at most {high:g}"
            raise UserError(f"{option} {shown}: must be {wanted}")
        return value


def _build_dir() -> Path:
    from orchestrator.packaging.builder import default_build_dir

    return default_build_dir(WORK_ROOT)


def _write_shipped_systems(names: Optional[List[str]] = None) -> None:
    """Installed package only: (re)write the shipped systems under SSP_ROOT."""
    if not IN_CHECKOUT:
        from orchestrator.systems.shipped import refresh_shipped

        refresh_shipped(SSP_ROOT, names)


def _shipped_names() -> List[str]:
    if IN_CHECKOUT:
        return sorted(p.name for p in SSP_ROOT.iterdir() if (p / "SystemStructure.ssd").is_file())
    from orchestrator.systems.shipped import SHIPPED

    return sorted(SHIPPED)


def _system_path(name: Optional[str]) -> Path:
    if name is None:
        name = DEFAULT_SYSTEM
    path = Path(name)
    if path.exists():
        return path
    available = _shipped_names()
    if name in available:
        _write_shipped_systems([name])
    shipped = SSP_ROOT / name
    if shipped.is_dir():
        return shipped
    close = did_you_mean(name, available)
    raise UserError(f"system {name!r}: no such folder or .ssp file, and not a shipped system"
                    + (close if close else f" (shipped: {', '.join(available) or 'none yet'})"))


def cmd_build(args) -> int:
    from orchestrator.packaging.builder import build_all, build_sized_for
    from fmus.sizes import BuildConfig
    from orchestrator.packaging.packing import pack_systems

    config = BuildConfig(args.sections, args.trains, args.frame)
    dest = Path(args.dest) if args.dest else _build_dir()
    results = build_all(dest, config, force=args.force)
    _write_shipped_systems()
    if config == BuildConfig():        # and the other sizes a shipped system names (TVM-430's 32 sections)
        results += build_sized_for(dest, [p for p in SSP_ROOT.iterdir() if p.is_dir()], force=args.force)
    for result in results:
        print(f"{'built ' if result.rebuilt else 'up to date'} {result.path}")
    if not results:
        print("no unit under fmus/ has a model yet; nothing to build")
    if args.dest:                      # --dest: the FMUs there and nothing else (docs/contracts.md)
        return 0
    repacked: List[Path] = []
    for archive in pack_systems(SSP_ROOT, dest, dest.parent, force=args.force, repacked=repacked):
        print(f"{'packed    ' if archive in repacked else 'up to date'} {archive}")
    return 0


def cmd_run(args) -> int:
    """A signal from here on (imports and the build included) stops the run in order; the
    handlers stay until the process has exited (orchestrator/interrupts.py hold_until_exit)."""
    from orchestrator import interrupts

    if _ENDS_WITH_PROCESS:
        flag = interrupts.hold_until_exit()
        status = _run_command(args)
    else:                                   # main() called from Python: its handlers come back
        with interrupts.deferred() as flag:
            status = _run_command(args)
    if flag is not None and flag.signum:   # after the run's files were complete
        print(f"railcosim: {interrupts.signal_name(flag.signum)} after the run completed; "
              f"its results are complete in {args.output}", file=sys.stderr)
        return 128 + flag.signum
    return status


def _overrides(args) -> dict:
    overrides = {}
    for item in args.set or []:
        key, sep, value = item.partition("=")
        if not sep or "." not in key:
            raise UserError(f"--set {item}: expected COMPONENT.VARIABLE=VALUE")
        overrides[key.strip()] = value.strip()
    return overrides


def _run_options(args, overrides: dict, **more):
    """The options `run` and `validate` share (validate checks what run would meet), with the
    --set overrides parsed (:func:`_overrides`)."""
    from functools import partial

    from orchestrator.verdicts.labels import railway_labels
    from orchestrator.verdicts.verdict import railway_verdicts
    from orchestrator.run import RunOptions

    # the railway checks' warnings (a rail line's train length) go where the run's own go: stderr
    return RunOptions(
        stop_time=args.stop_time, overrides=overrides, param_sets=args.param_set or [],
        output_interval=args.output_interval, captures=args.capture or [], record=args.record,
        algorithm=args.algorithm, in_process=args.in_process, fmu_dirs=[_build_dir()],
        scenario=args.scenario, default_scenario=not args.no_scenario,
        summaries=partial(railway_verdicts, warn=print_warning), labels=railway_labels, **more)


def _run_command(args) -> int:
    from orchestrator.run import run_system

    system = _system_path(args.system)
    overrides = _overrides(args)    # a malformed --set is refused before the build
    if not args.no_build:
        from orchestrator.packaging.builder import build_all, build_sized_for

        build_all(_build_dir())
        build_sized_for(_build_dir(), [system.parent if system.is_file() else system])
    from orchestrator.dcp.master import parse_swap

    swaps = {}
    for text in args.swap or []:
        target = parse_swap(text)
        swaps[target.component] = target
    progress = args.progress if args.progress != "auto" else "bar" if sys.stderr.isatty() else "lines"
    options = _run_options(args, overrides, output_dir=Path(args.output), progress=progress,
                           progress_interval=args.progress_interval, real_time=args.real_time, swaps=swaps)
    result = run_system(system, options)
    summary = result.summary
    print(f"{summary['system']}: {summary['sim_time_s']:.3f} s simulated in {summary['wall_time_s']:.3f} s "
          f"({_timing(summary)}); results in {result.output_dir}")
    from orchestrator.verdicts.verdict import verdict_lines

    for line in verdict_lines(summary):
        print(f"  {line}")
    import shlex

    print(f"  draw it: railcosim report {shlex.quote(str(result.output_dir))}")
    return 0


def _timing(summary: dict) -> str:
    """``initialisation 2.105 s, then 37.8x real time``: the run's wall time parted, the factor
    the stepping's (summary.json ``stepping_realtime_factor``; the whole run's is
    ``realtime_factor``)."""
    init_s, factor = summary.get("init_wall_time_s") or 0.0, summary.get("stepping_realtime_factor")
    return f"initialisation {init_s:.3f} s, then " + (f"{factor:.1f}x real time" if factor else "no stepping")


def _collapse(names: List[str]) -> List[str]:
    """u_tx[1,1] … u_tx[8,40] → u_tx[8,40]."""
    from orchestrator.ports import element_name, split_element

    seen, shown = {}, []
    for name in names:
        base, index = split_element(name) or (name, ())
        if not index:
            shown.append(name)
            continue
        if base not in seen:
            shown.append(base)
        seen[base] = tuple(max(a, b) for a, b in zip(seen.get(base, index), index))
    return [element_name(n, seen[n]) if n in seen else n for n in shown]


def cmd_report(args) -> int:
    from orchestrator.reports.report import make_report

    for path in make_report(Path(args.run_dir), Path(args.output) if args.output else None, args.at):
        print(f"wrote {path}")
    return 0


def cmd_plot(args) -> int:
    from orchestrator.reports.plot import plot_run

    path = plot_run(Path(args.run_dir), args.variables, args.t0, args.t1,
                    Path(args.output) if args.output else None)
    print(f"wrote {path}")
    return 0


def cmd_inspect(args) -> int:
    from orchestrator.fmu import read_interface
    from orchestrator.ports import base_of

    path = Path(args.target)
    if path.suffix == ".fmu":
        interface = read_interface(path)
        print(f"{path}: {interface.model_identifier} ({interface.generation_tool}), "
              f"step {interface.default_step_s if interface.default_step_s else 'any'} s")
        by_base = {}
        for var in interface.variables.values():
            by_base.setdefault(base_of(var.name), []).append(var)
        for label in _collapse(list(interface.variables)):
            var = by_base[base_of(label)][0]
            print(f"  {label:28s} {var.causality:9s} {var.type:8s} {var.unit or '':6s} start={var.start}")
        return 0
    from orchestrator.components import interface_of
    from orchestrator.graph import TICKS_PER_SECOND, build_graph
    from orchestrator.ssp import open_system

    system = open_system(_system_path(args.target), [_build_dir()])
    try:
        graph = build_graph(system, interface_of=interface_of)
        print(f"{system.name}: base step {graph.base_ticks / TICKS_PER_SECOND:g} s, "
              f"order {' → '.join(graph.order)}")
        for name, node in graph.nodes.items():
            print(f"  {name:16s} {node.interface.model_identifier:16s} step "
                  f"{node.step_ticks / TICKS_PER_SECOND:g} s  params {len(node.parameters)}")
        pairs = {}
        for edge in graph.edges:
            pairs.setdefault((edge.source, edge.target, edge.transition), []).append(edge)
        for (source, target, transition), edges in pairs.items():
            print(f"  {source} → {target}: {len(edges)} connection(s), {transition}")
        for cycle in graph.cycles:
            print(f"  cycle broken by declared order among: {', '.join(cycle)}")
    finally:
        system.close()
    return 0


def cmd_validate(args) -> int:
    path = Path(args.target)
    if path.suffix == ".fmu":
        from fmpy.validation import validate_fmu
        from orchestrator.fmu import read_interface

        read_interface(path)
        problems = validate_fmu(str(path))
        if problems:
            raise UserError(f"{path}: " + "; ".join(problems))
        print(f"{path}: valid")
        return 0
    from orchestrator.validation import problems_of

    # everything a run with these options would refuse before its first step: the SSD and its
    # parameter sets, the FMUs' ports, connections, units, steps, the data files, the scenario,
    # and each component instantiated and initialised with its parameters (as run does)
    problems = problems_of(_system_path(args.target), _run_options(args, _overrides(args)))
    for problem in problems:
        print(f"railcosim: error: {problem}", file=sys.stderr)
    if problems:
        return 2
    print(f"{args.target}: valid")
    return 0


def _study_path(name: str) -> Path:
    """A study file, or the name of a shipped one (studies/NAME.toml)."""
    path = Path(name)
    if path.is_file():
        return path
    from orchestrator.study import shipped_studies

    shipped = shipped_studies()
    if name in shipped:
        return shipped[name]
    close = did_you_mean(name, shipped)
    raise UserError(f"study {name!r}: no such file, and not a shipped study"
                    + (close if close else f" (shipped: {', '.join(sorted(shipped)) or 'none'})"))


def cmd_study(args) -> int:
    """``railcosim study STUDY`` runs a study on Dask; ``railcosim study report DIR`` sums it up
    (docs/studies.md)."""
    if args.study == "report" and args.run_dir is not None:
        from orchestrator.study.report import make_study_report

        for path in make_study_report(Path(args.run_dir), sys.stdout):
            print(f"wrote {path}")
        return 0
    if args.run_dir is not None:
        raise UserError(f"study: unexpected argument {args.run_dir!r} (railcosim study STUDY, or "
                        "railcosim study report DIR)")
    if args.workers is not None and args.scheduler:
        raise UserError("--workers sizes the local cluster; with --scheduler the cluster's own workers run")
    from orchestrator.study.spec import HARD_MAX_RUNS, MAX_RUNS, check_against_system, load_study
    from orchestrator.study.runner import run_study

    spec = load_study(_study_path(args.study), max_runs=HARD_MAX_RUNS if args.yes else MAX_RUNS)
    system = None
    if not spec.is_function:
        given = spec.data["system"]
        beside = spec.path.parent / given
        system = beside if beside.exists() else _system_path(given)
        system = system.resolve()
        if not args.no_build:
            from orchestrator.packaging.builder import build_all, build_sized_for

            build_all(_build_dir())
            build_sized_for(_build_dir(), [system.parent if system.is_file() else system])
        check_against_system(spec, system, [_build_dir()])
    if spec.data.get("build_sizes") and not args.no_build:     # what a function study's runs name
        from orchestrator.packaging.builder import build_sizes

        build_sizes(_build_dir(), spec.data["build_sizes"])
    python_path = [str(PACKAGE_PARENT)] if IN_CHECKOUT else []
    if spec.is_function:
        from orchestrator.study.worker import import_function

        import_function(spec.data["function"], [str(spec.path.parent.resolve()), *python_path],
                        f"study {spec.path}: field function")
    output = Path(args.output) if args.output else Path("results") / spec.name
    if _ENDS_WITH_PROCESS:   # a signal while Dask's threads end with the process: recorded, ignored
        from orchestrator import interrupts

        interrupts.hold_until_exit()
    result = run_study(spec, output, system, [_build_dir().resolve()], workers=args.workers,
                       scheduler=args.scheduler, resume=args.resume, progress=sys.stderr,
                       python_path=python_path)
    from orchestrator.study.report import outcome_lines

    print("\n".join(outcome_lines(spec.name, result)))
    return 0 if result.counts["ok"] == result.counts["runs"] else 1


def cmd_headway(args) -> int:
    """``railcosim headway SYSTEM``: the minimum headway by blocking-time theory and by
    co-simulation of N trains (docs/capacity.md)."""
    from orchestrator.headway import search
    from orchestrator.headway.output import shown, write_outputs

    system = _system_path(args.system).resolve()
    if args.method != "blocking" and args.trains < 2:
        raise UserError(f"--trains {args.trains}: the co-simulated headway needs at least 2 trains")
    build_dir = _build_dir().resolve()
    build = None
    if not args.no_build:
        from orchestrator.packaging.builder import build_all, build_sized_for

        build_all(build_dir)
        build = lambda folders: build_sized_for(build_dir, folders)  # noqa: E731 — the trials' sizes
    if _ENDS_WITH_PROCESS:
        from orchestrator import interrupts

        interrupts.hold_until_exit()
    output = Path(args.output) if args.output else Path("results") / f"headway_{system.name}"
    result = search.headway(system, args.method, args.trains, output, [build_dir], build, args.workers,
                            progress=sys.stderr, resume=args.resume)
    print(shown(write_outputs(result, output), args.format, output))
    return 0


def cmd_capacity(args) -> int:
    """``railcosim capacity SYSTEM``: UIC 406 capacity consumption of a multi-train system by
    compressing its trains' blocking-time stairways (docs/capacity.md#compression)."""
    from orchestrator.headway.capacity import capacity, text_lines

    system = _system_path(args.system).resolve()
    output = Path(args.output) if args.output else Path("results") / f"capacity_{system.name}"
    if not args.no_build:
        from orchestrator.packaging.builder import build_all

        build_all(_build_dir())
    result = capacity(system, [_build_dir().resolve()], output)
    if args.format == "json":
        print(json.dumps({k: v for k, v in result.items() if k != "stairways"}, indent=1, ensure_ascii=False))
    else:
        print("\n".join([*text_lines(result), f"results in {output} (capacity.json)"]))
    return 0


def cmd_new(args) -> int:
    """``railcosim new NAME``: a system folder of one's own (docs/your_own_system.md), from a line
    file or from a railML 3 file (docs/railml.md)."""
    from orchestrator.systems.new_system import new_system, new_system_from_railml

    if (args.line is None) == (args.railml is None):
        raise UserError("new: give the line as --line FILE (JSON) or as --railml FILE (railML 3), one of them")
    if args.line is not None:
        for option, value in (("--line-id", args.line_id), ("--sidecar", args.sidecar), ("--schema", args.schema)):
            if value is not None:
                raise UserError(f"new: {option} goes with --railml, not with --line")
        if not args.timetable:
            raise UserError("new: --timetable is required with --line (give one per train)")
        path = new_system(Path(args.name), Path(args.line), args.timetable, args.rolling_stock, args.system,
                          args.trains, args.traction, _build_dir())
    else:
        path, notes = new_system_from_railml(Path(args.name), Path(args.railml), args.timetable or [], args.line_id,
                                             args.sidecar, args.schema, args.rolling_stock, args.system, args.trains,
                                             args.traction, _build_dir())
        if notes:
            print(f"railcosim: warning: {args.railml}: what the railML import ignored or assumed "
                  "(docs/railml.md):", file=sys.stderr)
            for note in notes:
                print(f"  - {' '.join(note.split())}", file=sys.stderr)
    print(f"wrote {path.parent} (SystemStructure.ssd, line.ssv, resources/); run it with: railcosim run {args.name}")
    return 0


def cmd_list(args) -> int:
    """``railcosim list``: the shipped systems, studies and roles, one line each (read-only)."""
    from orchestrator.catalogue import catalogue, format_text

    listing = catalogue(_shipped_names(), DEFAULT_SYSTEM)
    if args.kind != "all":
        listing = {args.kind: listing[args.kind]}
    if args.format == "json":
        print(json.dumps(listing, indent=1, ensure_ascii=False))
    else:
        print(format_text(listing))
    return 0


def add_new_command(sub) -> None:
    from fmus.signalling import cab_systems      # the systems `new` offers: their registry

    new = sub.add_parser("new", help="write a system folder from your line, timetable(s) and rolling stock")
    new.add_argument("name", help="folder to write (must not exist yet)")
    new.add_argument("--line", metavar="FILE", help="line file (JSON, docs/interfaces.md)")
    new.add_argument("--railml", metavar="FILE", help="the line from a railML 3.1 or 3.2 infrastructure file "
                                                      "instead of --line (docs/railml.md)")
    new.add_argument("--line-id", metavar="ID", help="with --railml: the railML line to import")
    new.add_argument("--sidecar", metavar="FILE", help="with --railml: what the railML file has no place for (JSON)")
    new.add_argument("--schema", metavar="DIR", help="with --railml: validate the file against the railML XSD in DIR")
    new.add_argument("--timetable", action="append", metavar="FILE",
                     help="timetable file; give one per train (train j starts at its first station); with "
                          "--railml optional (one is made)")
    new.add_argument("--rolling-stock", metavar="FILE",
                     help="rolling-stock file for every train (default: the bundled passenger train; "
                          "freight_vl80 for --traction ac; the system's own for a system that names one: "
                          + ", ".join(f"{c.default_stock.removesuffix('.json')} for {c.name}"
                                      for c in cab_systems.REGISTRY.values() if c.default_stock) + ")")
    new.add_argument("--system", default=cab_systems.DEFAULT.name,
                     help="cab signalling, on a line of the track circuits it codes: " + "; ".join(
                         f"{c.name} ({c.transmitter})" for c in cab_systems.REGISTRY.values())
                     + f" (default {cab_systems.DEFAULT.name})")
    new.add_argument("--trains", action=_Number, kind=int, minimum=1, help="number of trains (default: one per --timetable)")
    new.add_argument("--traction", help="dc, ac or none (default: the line's electrification; must agree)")
    new.set_defaults(func=cmd_new)


def cmd_export(args) -> int:
    """``railcosim export railml SYSTEM -o FILE``: a system's line as railML (docs/railml.md)."""
    import json

    from orchestrator.railml.validate import validate_railml
    from orchestrator.railml.write import export_railml, system_line_file
    from fmus.data.loader import load_line
    from fmus.errors import FmuInputError

    line_file = system_line_file(_system_path(args.system))
    try:
        load_line(line_file)
    except FmuInputError as error:
        raise UserError(str(error)) from None
    output = Path(args.output)
    if output.is_dir():
        raise UserError(f"-o {output}: is a folder; give the railML file to write")
    try:
        output.write_bytes(export_railml(json.loads(line_file.read_text("utf-8")), args.railml_version))
    except OSError as error:
        raise UserError(f"-o {output}: cannot be written ({error.strerror or error})") from None
    print(f"wrote {output} (railML {args.railml_version}) from {line_file}")
    if args.schema:
        valid, errors = validate_railml(output, args.schema)
        if not valid:
            more = f" (and {len(errors) - 1} more)" if len(errors) > 1 else ""
            raise UserError(f"{output}: not valid against the railML schema in {args.schema}: {errors[0]}{more}")
        print(f"{output}: valid against {args.schema}")
    return 0


def add_export_command(sub) -> None:
    export = sub.add_parser("export", help="write a system's line in another format: railml")
    formats = export.add_subparsers(dest="format", required=True, parser_class=_Parser)
    railml = formats.add_parser("railml", help="the system's line as railML 3.2 infrastructure (docs/railml.md)")
    railml.add_argument("system", metavar="SYSTEM", help="folder, .ssp archive or shipped system name")
    railml.add_argument("-o", "--output", required=True, metavar="FILE", help="railML file to write")
    railml.add_argument("--railml-version", choices=["3.2", "3.1"], default="3.2", help="default 3.2")
    railml.add_argument("--schema", metavar="DIR", help="validate the file written against the railML XSD in DIR")
    export.set_defaults(func=cmd_export)


def cmd_conform(args) -> int:
    from orchestrator.conformance.report import format_json, format_table
    from orchestrator.conformance.runner import conform

    report = conform(args.role, args.target, args.vectors)
    print(format_json(report) if args.format == "json" else format_table(report))
    return 0 if report.passed else 1


def cmd_contract(args) -> int:
    """``railcosim contract snapshot|check``: an FMU's interface manifest, or the FMU against a
    manifest or a role's shipped one (docs/contracts.md); exit 1 when the check fails."""
    from orchestrator import contracts
    from orchestrator.conformance.roles import resolve_manifest

    if args.action == "snapshot":
        if args.output:
            manifest = contracts.write_snapshot(Path(args.fmu), Path(args.output))
            print(f"wrote {args.output}: {manifest['model_identifier']}, {len(manifest['ports'])} ports")
        else:
            print(json.dumps(contracts.snapshot(Path(args.fmu)), indent=1, sort_keys=True))
        return 0
    manifest, shown = resolve_manifest(args.manifest)
    result = contracts.check(Path(args.fmu), manifest, strict=args.strict, shown=shown)
    print(json.dumps(result.as_json(), indent=1) if args.format == "json" else result.text())
    return 0 if result.passed else 1


def add_contract_command(sub) -> None:
    from orchestrator.conformance.roles import ROLES

    contract = sub.add_parser("contract", help="an FMU's interface manifest, or the FMU checked against one")
    actions = contract.add_subparsers(dest="action", required=True, parser_class=_Parser)
    snapshot = actions.add_parser("snapshot", help="write an FMU's interface manifest (JSON)")
    snapshot.add_argument("fmu", help="an .fmu")
    snapshot.add_argument("-o", "--output", metavar="FILE", help="manifest file to write (default: standard output)")
    check = actions.add_parser("check", help="every difference between an FMU and a manifest, breaking or "
                                             "compatible; exit 1 on a breaking one")
    check.add_argument("fmu", help="an .fmu")
    check.add_argument("--manifest", required=True, metavar="M",
                       help=f"a manifest file, or a role meaning its shipped manifest: {', '.join(ROLES)}")
    check.add_argument("--strict", action="store_true", help="any difference fails, compatible ones too")
    check.add_argument("--format", choices=["text", "json"], default="text", help="text (default) or json")
    contract.set_defaults(func=cmd_contract)


def cmd_fmu_env(args) -> int:
    from orchestrator.hostenv import host_environment

    for key, value in host_environment().items():
        print(f'export {key}="{value}"')
    return 0


def _add_run_setup_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of `run` that decide what is made before the first step (`validate` takes
    them too, to check a run with them)."""
    parser.add_argument("--stop-time", action=_Number, of="seconds",
                        help="seconds (default: the scenario's end, else the SSD's stopTime); a time "
                             "between two base steps ends the run at the next one, with a warning")
    parser.add_argument("--set", action="append", metavar="COMP.VAR=VALUE",
                        help="override a parameter (or an input no connection feeds)")
    parser.add_argument("--param-set", action="append", metavar="NAME", help="apply NAME.ssv")
    parser.add_argument("--output-interval", action=_Number, above=0.0, of="seconds", default=None,
                        help="seconds (default 0.1, rounded up to a multiple of the base step)")
    parser.add_argument("--capture", action="append", metavar="COMP.PORT@T0:T1",
                        help="full-rate capture of a frame output: a row (rail.e_coil[1]) or a whole port "
                             "(rail.e_coil: one column per row)")
    parser.add_argument("--record", action="append", metavar="COMP.VAR",
                        help="record only these outputs (default: all scalar outputs)")
    parser.add_argument("--algorithm", default="gauss-seidel", choices=["gauss-seidel", "jacobi"])
    parser.add_argument("--in-process", action="store_true",
                        help="run the facades in this interpreter without FMI (reference, debugging)")
    parser.add_argument("--scenario", metavar="FILE",
                        help="timed events (JSON, OSP-like; docs/scenarios.md); default: the system's scenario.json")
    parser.add_argument("--no-scenario", action="store_true", help="ignore the system's own scenario.json")


def cmd_dcp_slave(args) -> int:
    from orchestrator.dcp.slave import serve

    return serve(Path(args.fmu), args.host, args.port, args.real_time,
                 Path(args.dcpx_out) if args.dcpx_out else None, args.drop_data, args.seed, args.quiet,
                 dcpx_in=Path(args.dcpx) if args.dcpx else None)


def _rail_setup(args):
    """The rail line of ``args.system`` (or ``--line``) with ``--train``s added: (setup, system)."""
    from orchestrator.circuits.rail_setup import add_train, line_setup, rail_setup
    from orchestrator.ssp import open_system

    system = None
    if args.line:
        if args.system:
            raise UserError(f"give a system or --line, not both ({args.system}, --line {args.line})")
        setup = line_setup(args.line)
    else:
        system = open_system(_system_path(args.system))
        setup = rail_setup(system, args.time, Path(args.results) if args.results else None)
    for spec in args.train or []:
        add_train(setup, spec)
    return setup, system


def cmd_netlist(args) -> int:
    """``railcosim netlist``: a section as a SPICE netlist (docs/rail_line.md#checked-against-ngspice)."""
    from orchestrator.circuits.rail_setup import section_netlist

    if args.time and not args.results:
        raise UserError(f"--time {args.time:g}: the trains' positions then come from a run: add --results RUN_DIR")
    setup, system = _rail_setup(args)
    try:
        netlist = section_netlist(setup, setup.section(args.section), args.wheelsets, args.segment, args.frequency,
                                  args.tran, args.time, args.ballast)
    finally:
        if system is not None:
            system.close()
    if args.output:
        try:
            Path(args.output).write_text(netlist.text())
        except OSError as error:
            raise UserError(f"netlist: -o {args.output}: cannot be written ({error.strerror or error})") from None
        print(f"wrote {args.output} ({len(netlist.cards)} elements); run it with: ngspice -b {args.output}")
    else:
        sys.stdout.write(netlist.text())
    return 0


def cmd_crosscheck(args) -> int:
    """``railcosim crosscheck spice``: the system's track circuits against ngspice; exit 1 when a
    comparison is outside its bound."""
    from orchestrator.circuits.crosscheck import crosscheck_system

    if args.tool != "spice":
        raise UserError(f"crosscheck {args.tool}: the one cross-check is `spice` (ngspice)")
    setup, system = _rail_setup(args)
    try:
        passed = crosscheck_system(setup, args.section, sys.stdout)
    finally:
        if system is not None:
            system.close()
    return 0 if passed else 1


def _add_section_arguments(parser, required: bool = True) -> None:
    parser.add_argument("--line", metavar="FILE", help="a line file instead of a system")
    parser.add_argument("--section", action=_Number, kind=int, minimum=1, required=required, metavar="K",
                        help="the block section, 1-based" + ("" if required else " (default: every design)"))
    parser.add_argument("--train", action="append", metavar="FILE@HEAD",
                        help="a train: its rolling-stock file and its first wheelset's position, m (repeatable)")
    parser.add_argument("--time", action=_Number, minimum=0.0, of="seconds", default=0.0, metavar="T",
                        help="the instant: the trains where a run's results put them at T s (with --results)")
    parser.add_argument("--results", metavar="RUN_DIR", help="a finished run's folder (its results.csv)")


def make_parser() -> argparse.ArgumentParser:
    from orchestrator.provenance import railcosim_version

    parser = _Parser(prog="railcosim", description="Railway cab-signalling and ATO co-simulation")
    parser.add_argument("--version", action="version", version=f"railcosim {railcosim_version()}",
                        help="print railcosim's version and exit")
    # not required: a missing command is said by main, naming the commands, in one line
    sub = parser.add_subparsers(dest="command", parser_class=_Parser)

    build = sub.add_parser("build", help="build the FMUs into build/fmus and pack the shipped systems")
    build.add_argument("--sections", action=_Number, kind=int, minimum=1, maximum=MAX_SECTIONS, default=8,
                       help=f"block sections K (default 8, at most {MAX_SECTIONS})")
    build.add_argument("--trains", action=_Number, kind=int, minimum=1, maximum=MAX_TRAINS, default=2,
                       help=f"trains M (default 2, at most {MAX_TRAINS})")
    build.add_argument("--frame", action=_Number, kind=int, minimum=1, maximum=MAX_FRAME, default=40,
                       help=f"samples per frame N (default 40, at most {MAX_FRAME})")
    build.add_argument("--dest", help="write the FMUs into this folder and nothing else (default build/fmus, "
                                      "with the shipped systems' .ssp archives packed beside it in build/)")
    build.add_argument("--force", action="store_true", help="rebuild even when up to date")
    build.set_defaults(func=cmd_build)

    run = sub.add_parser("run", help="run a system (folder or .ssp); default: free_run")
    run.add_argument("system", nargs="?", help="folder, .ssp archive or shipped system name")
    run.add_argument("--output", default="results",
                     help="results folder (default results/); locked while the run uses it, and an "
                          "earlier run's files in it are replaced")
    _add_run_setup_arguments(run)
    run.add_argument("--no-build", action="store_true", help="do not (re)build FMUs first")
    run.add_argument("--real-time", action=_Number, nargs="?", const=1.0, default=None, metavar="FACTOR",
                     help="pace the run to the wall clock, FACTOR simulated seconds per second (default 1: "
                          "real time); late steps are counted in summary.json real_time")
    run.add_argument("--progress", choices=["auto", "bar", "lines", "none"], default="auto",
                     help="the run's progress on stderr: a bar redrawn in place, a line every --progress-interval "
                          "seconds (none for a shorter run), or none (default auto: the bar on a terminal, "
                          "else lines)")
    run.add_argument("--progress-interval", action=_Number, above=0.0, of="seconds", default=5.0, metavar="S",
                     help="with lines: seconds of wall time between two progress lines (default 5)")
    run.add_argument("--swap", action="append", metavar="NAME=dcp://HOST:PORT[?dcpx=FILE]",
                     help="drive component NAME as a remote DCP slave (hardware in the loop); its .dcpx "
                          "beside the component's FMU unless given; options deadline_ms, timeout_s")
    run.set_defaults(func=cmd_run)

    report = sub.add_parser("report", help="pictures and the verdict table of a finished run")
    report.add_argument("run_dir", help="a run's output folder (results.csv, summary.json, metadata.json)")
    report.add_argument("--output", help="folder for the PNGs (default: the run folder)")
    report.add_argument("--at", action=_Number, of="seconds", help="time (s) to centre the coil-EMF picture on")
    report.set_defaults(func=cmd_report)

    plot = sub.add_parser("plot", help="variables of a finished run against time, with their units and labels "
                                       "(a PNG or SVG)")
    plot.add_argument("run_dir", metavar="RUN", help="a run's output folder (results.csv, columns.json)")
    plot.add_argument("variables", nargs="+", metavar="VAR", help="a results.csv column: train.v, rx.aspect, "
                                                                 "rail.occupied[3]; one panel each")
    plot.add_argument("--from", dest="t0", action=_Number, of="seconds", metavar="T0",
                      help="from this time (s; default the run's start)")
    plot.add_argument("--to", dest="t1", action=_Number, of="seconds", metavar="T1",
                      help="to this time (s; default the run's end)")
    plot.add_argument("-o", "--output", metavar="FILE", help="a .png or .svg (default RUN/plot_VARS.png)")
    plot.set_defaults(func=cmd_plot)

    inspect = sub.add_parser("inspect", help="ports of an FMU, or components and connections of a system")
    inspect.add_argument("target")
    inspect.set_defaults(func=cmd_inspect)

    validate = sub.add_parser("validate", help="check an FMU, or a system as run would before its first step "
                                               "(every problem, one line each)")
    validate.add_argument("target", help="an .fmu, or a system (folder, .ssp archive or shipped system name)")
    _add_run_setup_arguments(validate)
    validate.set_defaults(func=cmd_validate)

    study = sub.add_parser("study", help="run a study (sweeps, Monte Carlo) on Dask, or `study report DIR`")
    study.add_argument("study", metavar="STUDY", help="study file (.toml or .json) or shipped study name; "
                                                      "or `report` followed by a study's output folder")
    study.add_argument("run_dir", nargs="?", metavar="DIR", help=argparse.SUPPRESS)
    study.add_argument("--workers", action=_Number, kind=int, minimum=1, maximum=MAX_LOCAL_WORKERS,
                       help=f"local cluster size (default: one per core; at most {MAX_LOCAL_WORKERS})")
    study.add_argument("--scheduler", metavar="ADDRESS", help="an existing Dask scheduler, e.g. tcp://host:8786")
    study.add_argument("--output", help="study folder (default results/NAME)")
    study.add_argument("--resume", action="store_true",
                       help="skip runs finished by an earlier start of the same study file")
    study.add_argument("--no-build", action="store_true", help="do not (re)build FMUs first")
    from orchestrator.study.spec import HARD_MAX_RUNS, MAX_RUNS

    study.add_argument("--yes", action="store_true",
                       help=f"run a study of more than {MAX_RUNS} runs (up to {HARD_MAX_RUNS}; docs/studies.md)")
    study.set_defaults(func=cmd_study)

    headway = sub.add_parser("headway", help="a system's minimum headway: blocking-time theory and N trains "
                                             "co-simulated through the signal chain (docs/capacity.md)")
    headway.add_argument("system", help="a single-train system with a signal chain (folder, .ssp or shipped name)")
    headway.add_argument("--method", choices=["blocking", "cosim", "both"], default="both")
    headway.add_argument("--trains", action=_Number, kind=int, minimum=1, maximum=MAX_TRAINS, default=3,
                         help=f"trains in each co-simulated trial (default 3, at least 2, at most {MAX_TRAINS})")
    headway.add_argument("--format", choices=["text", "json"], default="text")
    headway.add_argument("-o", "--output", help="folder (default results/headway_SYSTEM)")
    headway.add_argument("--workers", action=_Number, kind=int, minimum=1, maximum=MAX_LOCAL_WORKERS,
                         help="trials run side by side (a local Dask cluster; default one per core)")
    headway.add_argument("--no-build", action="store_true", help="do not (re)build FMUs first")
    headway.add_argument("--resume", action="store_true",
                         help="keep the runs an earlier search into the same folder finished (same trials)")
    headway.set_defaults(func=cmd_headway)

    capacity = sub.add_parser("capacity", help="capacity consumption of a system of several trains: their "
                                               "stairways compressed (UIC 406, docs/capacity.md)")
    capacity.add_argument("system", help="a system of two or more trains (folder, .ssp or shipped name)")
    capacity.add_argument("--format", choices=["text", "json"], default="text")
    capacity.add_argument("-o", "--output", help="folder (default results/capacity_SYSTEM)")
    capacity.add_argument("--no-build", action="store_true", help="do not (re)build FMUs first")
    capacity.set_defaults(func=cmd_capacity)

    add_new_command(sub)
    add_export_command(sub)
    add_contract_command(sub)

    listing = sub.add_parser("list", help="the shipped systems, studies and roles, one line each")
    listing.add_argument("kind", nargs="?", default="all", choices=["all", "systems", "studies", "roles"],
                         help="list one kind only (default: all three)")
    listing.add_argument("--format", choices=["text", "json"], default="text")
    listing.set_defaults(func=cmd_list)

    netlist = sub.add_parser("netlist", help="a section of a system (or line file) as a SPICE netlist at an instant")
    netlist.add_argument("system", nargs="?", help="folder, .ssp archive or shipped system name (default free_run)")
    _add_section_arguments(netlist)
    netlist.add_argument("--wheelsets", choices=["nodes", "axles"], default="nodes",
                         help="nodes: one shunt per network node a train covers, as the rail line's network; "
                              "axles: every wheelset at its axle (default nodes)")
    netlist.add_argument("--segment", action=_Number, above=0.0, of="metres", default=1.0, metavar="M",
                         help="with --wheelsets axles: the rails' pieces, at most M metres (default 1)")
    netlist.add_argument("--frequency", action=_Number, above=0.0, of="hertz", metavar="HZ", help=".ac frequency (default the section's carrier)")
    netlist.add_argument("--tran", action=_Number, above=0.0, of="seconds", metavar="SECONDS",
                         help=".tran of the coder's code for the section over SECONDS instead of .ac")
    netlist.add_argument("--ballast", action=_Number, minimum=0.0, of="Ω·km", default=0.0, metavar="OHM_KM",
                         help="the section's ballast resistance (default: the line file's)")
    netlist.add_argument("--output", "-o", metavar="FILE", help="write the netlist here (default: standard output)")
    netlist.set_defaults(func=cmd_netlist)

    crosscheck = sub.add_parser("crosscheck", help="check a system's track circuits against a circuit "
                                                   "simulator (`crosscheck spice`: ngspice)")
    crosscheck.add_argument("tool", help="spice")
    crosscheck.add_argument("system", nargs="?", help="folder, .ssp archive or shipped system name (default free_run)")
    _add_section_arguments(crosscheck, required=False)
    crosscheck.set_defaults(func=cmd_crosscheck)

    conform = sub.add_parser("conform", help="run a role's behavioural test vectors against an FMU "
                                             "(pass/fail table; exit 1 when a vector fails)")
    conform.add_argument("target", help="an FMI 2.0 co-simulation .fmu claiming the role")
    conform.add_argument("--role", required=True,
                         help="loco_receiver, wayside_coder, rail_line, traction or ato_controller")
    conform.add_argument("--format", choices=["table", "json"], default="table")
    conform.add_argument("--vectors", metavar="DIR",
                         help="a folder of vector files (default: the ones shipped in the package)")
    conform.set_defaults(func=cmd_conform)

    dcp = sub.add_parser("dcp-slave", help="serve an FMI 2.0 co-simulation FMU as a DCP 1.0 slave over UDP "
                                            "(docs/hil.md)")
    dcp.add_argument("fmu", help="the .fmu to serve")
    dcp.add_argument("--host", default="127.0.0.1",
                     help="IPv4 address to listen on (default 127.0.0.1; another than loopback is warned about)")
    dcp.add_argument("--port", action=_Number, kind=int, minimum=0, maximum=65535, default=0,
                     help="UDP port for control and data PDUs (default 0: a free port, printed at start)")
    dcp.add_argument("--real-time", action="store_true",
                     help="offer soft real-time mode only (the slave's own clock) instead of non-real-time")
    dcp.add_argument("--dcpx-out", metavar="FILE", help="write the slave's DCP description (.dcpx) here")
    dcp.add_argument("--dcpx", metavar="FILE",
                     help="serve this description (a bench device's .dcpx: its uuid, modes, time resolutions and "
                          "variables, matched to the FMU's by name) instead of the FMU's own")
    dcp.add_argument("--drop-data", action=_Number, default=0.0, metavar="FRACTION",
                     help="test option: leave this fraction of the DAT PDUs it should send unsent")
    dcp.add_argument("--seed", action=_Number, kind=int, minimum=0, default=None, help="seed of --drop-data's random choice")
    dcp.add_argument("--quiet", action="store_true", help="no progress lines on stderr")
    dcp.set_defaults(func=cmd_dcp_slave)

    env = sub.add_parser("fmu-env", help="optional overrides of the Python our FMUs start in a non-Python FMI host")
    env.set_defaults(func=cmd_fmu_env)
    parser.set_defaults(commands=tuple(sub.choices))
    return parser


def main(argv: Optional[List[str]] = None) -> int:
    try:
        args = make_parser().parse_args(argv)
        if args.command is None:
            raise UserError(f"no command given; choose one of {', '.join(args.commands)} "
                            "(railcosim COMMAND -h for help)")
        return args.func(args)
    except UserError as error:
        message = " ".join(str(error).split())
        print(f"railcosim: error: {message}", file=sys.stderr)
        return 2
    except Interrupted as stop:
        try:     # after SIGHUP the terminal may be gone: the exit code still tells
            print(f"railcosim: {' '.join(str(stop).split())}", file=sys.stderr)
        except OSError:
            pass
        return stop.exit_code
    except KeyboardInterrupt:   # outside a run (build, report, inspect): nothing half-written to keep
        print("railcosim: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:   # e.g. `railcosim inspect X | head`: the reader left, nothing to report
        import os

        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0


#: the command line's process ends with the command (entry_point), so the run's signal handlers
#: may stay until it has exited
_ENDS_WITH_PROCESS = False


def entry_point() -> None:
    global _ENDS_WITH_PROCESS
    _ENDS_WITH_PROCESS = True
    status = main()
    from orchestrator.interrupts import ignore_until_exit

    ignore_until_exit()
    sys.stdout.flush()
    sys.stderr.flush()
    sys.exit(status)

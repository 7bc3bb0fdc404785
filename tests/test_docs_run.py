"""Everything a reader copies from README.md and docs/*.md runs as written, and every figure a
page quotes from a run is the run's (docs/architecture.md, "Docs that run"; tests/docs_blocks.py
reads the pages).

* Each page's command blocks run in order, with bash, in a folder of their own that looks like
  the checkout (its top-level entries linked), as a reader runs them from the repository root;
  `railcosim` and `python` there are the interpreter under test and this checkout's code. A
  block fails on any non-zero exit; a transcript's command only where it shows `echo $?`.
  What the page leaves at the top of that folder must be something .gitignore ignores: a reader
  who follows it from the root of a checkout finds `git status` as it was.
* An output block, a transcript's lines and the shipped systems' verdict table are compared
  with what the runs printed or wrote: every line in order, every figure as printed or within
  the tolerance its annotation states.
* Example files (a study, a scenario, a line-file fragment, an SSD fragment, a CI job) are read
  by what reads them; synopses are checked against the CLI's parser and the scripts' --help.
* Blocks not run must say why; the end of a run lists them with their reasons (tests/conftest.py).

One test per page runs the page's blocks, so one page's runs are shared by its blocks and pages
run in parallel on the xdist workers; a failure lists every failing block by file:line.
"""
from __future__ import annotations

import json
import os
import re
import shlex
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Dict, List

import pytest

import docs_blocks as docs
from docs_blocks import ROOT, Block

BLOCKS = docs.all_blocks()
RUN_KINDS = ("shell", "python", "transcript", "output", "verdict table")
CHECK_KINDS = ("synopsis", *docs.DATA_KINDS)
SKIPPED_KINDS = docs.SKIP_KINDS
#: the property test_block_not_run_says_why records its block's reason under (tests/conftest.py lists them)
NOT_RUN_PROPERTY = "doc block not run"
#: top-level entries of the checkout a page's folder does not link (a reader's own, or VCS)
NOT_LINKED = {".git", "results", "out", "dist", "__pycache__", ".pytest_cache"}


def _skipped_reason(block: Block) -> str:
    d = block.directives
    for kind, label in (("needs dcp-slave", "needs a DCP slave"), ("needs hardware", "needs hardware"),
                        ("skip", "not run"), ("text", "not a command")):
        if kind in d:
            return f"{block.where}: {label}: {d[kind] or '(no reason given)'}"
    raise AssertionError(block.where)


# ---- the folder a page runs in -----------------------------------------------------------------

def _workspace(base: Path) -> Dict[str, str]:
    """Link the checkout's top-level entries into ``base``; the environment its commands get."""
    for entry in ROOT.iterdir():
        if entry.name in NOT_LINKED or entry.name.startswith(".venv") or entry.name.endswith(".egg-info"):
            continue
        (base / entry.name).symlink_to(entry)
    shims = base / ".docs-test-bin"
    shims.mkdir()
    for name, command in (("railcosim", f'"{sys.executable}" -m orchestrator'), ("python", f'"{sys.executable}"'),
                          ("python3", f'"{sys.executable}"')):
        (shims / name).write_text(f'#!/bin/sh\nexec {command} "$@"\n')
        (shims / name).chmod(0o755)
    env = {key: value for key, value in os.environ.items() if key not in ("PYTHONHOME",)}
    env["PATH"] = f"{shims}{os.pathsep}{env.get('PATH', '')}"
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT)] + [p for p in env.get("PYTHONPATH", "").split(os.pathsep) if p])
    return env


def _shell(command: str, cwd: Path, env: Dict[str, str], timeout_s: float) -> dict:
    """Run ``command`` with bash (errexit, pipefail) in its own process group; whatever it left
    running in the background (a DCP slave) is ended with it."""
    started = time.perf_counter()
    process = subprocess.Popen(["bash", "-e", "-o", "pipefail", "-c", command], cwd=cwd, env=env, text=True,
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, start_new_session=True)
    try:
        stdout, stderr = process.communicate(timeout=timeout_s)
        code = process.returncode
    except subprocess.TimeoutExpired:
        os.killpg(process.pid, signal.SIGKILL)
        stdout, stderr = process.communicate()
        code, stderr = -1, stderr + f"\n(timed out after {timeout_s:g} s)"
    finally:
        try:
            os.killpg(process.pid, signal.SIGTERM)
        except ProcessLookupError:
            pass
    return {"code": code, "stdout": stdout, "stderr": stderr, "seconds": time.perf_counter() - started}


# ---- synopses ------------------------------------------------------------------------------------

def _parser_options(parser) -> Dict[str, object]:
    """Subcommand (``contract check`` for nested ones) → its argparse parser."""
    import argparse

    found = {}

    def walk(p, prefix):
        for action in p._actions:
            if isinstance(action, argparse._SubParsersAction):
                for name, sub in action.choices.items():
                    found[f"{prefix}{name}".strip()] = sub
                    walk(sub, f"{prefix}{name} ")
    walk(parser, "")
    return found


def _options_of(parser) -> set:
    import argparse

    return {option for action in parser._actions if action.help != argparse.SUPPRESS
            for option in action.option_strings if option not in ("-h", "--help")}


def _option_spellings(parser) -> List[tuple]:
    import argparse

    return [tuple(o for o in action.option_strings if o not in ("-h", "--help")) for action in parser._actions
            if action.help != argparse.SUPPRESS and set(action.option_strings) - {"-h", "--help"}]


def _railcosim_synopsis_problems(block: Block) -> List[str]:
    from orchestrator.cli import make_parser

    subparsers = _parser_options(make_parser())
    commands: List[str] = []
    for line in block.lines:
        text, _ = docs.split_comment(line)
        if not text.strip():
            continue
        if text.startswith("railcosim "):
            commands.append(text)
        elif text.startswith(" ") and commands:          # a usage line continued
            commands[-1] += " " + text.strip()
    problems: List[str] = []
    named: Dict[str, set] = {}
    for command in commands:
        words = command.split()[1:]
        name = words[0]
        if f"{name} {words[1] if len(words) > 1 else ''}" in subparsers:
            name = f"{name} {words[1]}"
        if name not in subparsers:
            problems.append(f"{block.where}: railcosim {name}: no such command")
            continue
        options = set(docs.re.findall(r"(?<![\w-])(--?[a-zA-Z][\w-]*)", command))
        named.setdefault(name, set()).update(options)
        if "the run options above" in command:          # validate takes run's options
            named[name] |= named.get("run", set())
        unknown = sorted(options - _options_of(subparsers[name]))
        if unknown:
            problems.append(f"{block.where}: railcosim {name}: no option {', '.join(unknown)}")
    for name in sorted(named):
        # an option counts as named under any of its spellings (-o, --output)
        missing = sorted(max(spellings, key=len) for spellings in _option_spellings(subparsers[name])
                         if not set(spellings) & named[name])
        if missing:
            problems.append(f"{block.where}: railcosim {name}: {', '.join(missing)} not in the synopsis")
    return problems


def _script_synopsis_problems(block: Block, line: str, cwd: Path, env) -> List[str]:
    """A script's [--options] against its --help (the options a reader may add must exist)."""
    options = sorted({option for part in docs.optional_parts(line)
                      for option in docs.re.findall(r"(?<![\w-])(--[a-zA-Z][\w-]*)", part)})
    if not options:
        return []
    command = docs.split_comment(line)[0].split("[")[0].strip()
    helped = _shell(f"{command} --help", cwd, env, 120)
    return [f"{block.where}: {command}: no option {option} in its --help" for option in options
            if option not in helped["stdout"]]


# ---- example files -------------------------------------------------------------------------------

def _check_data(block: Block, folder: Path, env) -> List[str]:
    d = block.directives
    if "study file" in d:
        from orchestrator import cli
        from orchestrator.study.spec import check_against_system, load_study

        path = folder / "example_study.toml"
        path.write_text(block.text, encoding="utf-8")
        spec = load_study(path)
        given = spec.data["system"]
        system = path.parent / given if (path.parent / given).exists() else cli._system_path(given)
        check_against_system(spec, system.resolve(), [cli._build_dir()])
        return [] if spec.runs else [f"{block.where}: the study has no run"]
    if "scenario for" in d or "scenario event for" in d:
        document = json.loads(block.text) if "scenario for" in d else {"events": [json.loads(block.text)]}
        system = d.get("scenario for") or d.get("scenario event for")
        path = folder / "example_scenario.json"
        path.write_text(json.dumps(document), encoding="utf-8")
        done = _shell(f"railcosim validate {system} --scenario {path}", folder, env, 300)
        return [] if done["code"] == 0 else [f"{block.where}: railcosim validate {system} --scenario: "
                                             f"{done['stderr'].strip()}"]
    if "line file fragment" in d:
        from fmus.data.loader import DEFAULT_LINE, load_line

        line = json.loads(Path(DEFAULT_LINE).read_text(encoding="utf-8"))
        line.update(json.loads("{" + block.text + "}"))
        path = folder / "example_line.json"
        path.write_text(json.dumps(line), encoding="utf-8")
        load_line(path)
        return []
    if "railml sidecar" in d:
        from orchestrator.railml.read import load_sidecar

        path = folder / "example_sidecar.json"
        path.write_text(block.text, encoding="utf-8")
        load_sidecar(path)                   # checked against its schema; a UserError says why not
        shipped = d["railml sidecar"]        # the file the block shows, which the page's commands use
        if shipped and json.loads((ROOT / shipped).read_text(encoding="utf-8")) != json.loads(block.text):
            return [f"{block.where}: the block is not {shipped} (the file the commands read)"]
        return []
    if "ssd fragment" in d:
        from lxml import etree

        from orchestrator.ssp import NS, RCS_NS

        declarations = " ".join(f'xmlns:{prefix}="{uri}"' for prefix, uri in {**NS, "rcs": RCS_NS}.items())
        element = etree.fromstring(f"<fragment {declarations}>{block.text}</fragment>")[0]
        expected = f"{{{NS['ssd']}}}Component"
        return [] if element.tag == expected else [f"{block.where}: not an ssd:Component but {element.tag}"]
    if "ci job" in d:
        import yaml
        from orchestrator.cli import make_parser

        problems = []
        for step in yaml.safe_load(block.text):
            for command in step["run"].split("&&"):
                words = shlex.split(command.split(">")[0])
                if words and words[0] == "railcosim":
                    try:
                        make_parser().parse_args(words[1:])
                    except Exception as error:     # the CLI's parser says what is wrong in one line
                        problems.append(f"{block.where}: {command.strip()}: {error}")
        return problems
    raise AssertionError(f"{block.where}: {d}")


# ---- a page ---------------------------------------------------------------------------------------

def _run_page(page: Path, folder: Path) -> List[str]:
    """Run the page's blocks in order; the problems found (empty: the page runs as written)."""
    env = _workspace(folder)
    problems: List[str] = []
    last_output: List[str] = []
    timings = []
    unchecked = False      # after a ``full`` block not run: its output and verdict table too
    for block in (b for b in BLOCKS if b.page == page):
        d = block.directives
        timeout_s = float(d.get("timeout", docs.DEFAULT_TIMEOUT_S))
        if block.kind in ("shell", "python", "transcript"):
            unchecked = "full" in d and not docs.FULL_RUNS
            if unchecked:
                timings.append(f"{block.where}: not run (RAILCOSIM_DOCS_FULL=1 runs it): {d['full']}")
                continue
        elif unchecked and block.kind in ("output", "verdict table"):
            continue
        if "setup" in d and block.kind in RUN_KINDS + CHECK_KINDS:
            done = _shell(d["setup"], folder, env, timeout_s)
            if done["code"] != 0:
                problems.append(f"{block.where}: setup {d['setup']!r} exited {done['code']}: {done['stderr'][-2000:]}")
        started = time.perf_counter()
        if block.kind == "shell":
            for line in docs._logical_lines(block.text):
                if docs.optional_parts(line):
                    problems += _script_synopsis_problems(block, line, folder, env)
            script = docs.script_of(block)
            done = _shell(script, folder, env, timeout_s)
            last_output = (done["stdout"] + done["stderr"]).splitlines()
            if done["code"] != 0:
                problems.append(f"{block.where}: exited {done['code']}:\n{script}\n{done['stdout'][-3000:]}"
                                f"{done['stderr'][-3000:]}")
        elif block.kind == "python":
            path = folder / f"docs_block_{block.line}.py"
            path.write_text(block.text, encoding="utf-8")
            done = _shell(f"python {path.name}", folder, env, timeout_s)
            last_output = (done["stdout"] + done["stderr"]).splitlines()
            if done["code"] != 0:
                problems.append(f"{block.where}: exited {done['code']}: {done['stderr'][-3000:]}")
        elif block.kind == "transcript":
            problems += _run_transcript(block, folder, env, timeout_s)
        elif block.kind == "output":
            tolerances = docs.parse_tolerances(d.get("tolerance", ""))
            problems += [f"{block.where}: {p}" for p in docs.compare_output(block.lines, last_output, tolerances)]
        elif block.kind == "verdict table":
            problems += _check_verdict_table(block, folder) + _printed_verdict_problems(block, last_output)
        elif block.kind in CHECK_KINDS:
            continue                       # their own tests, which need no run of the page
        timings.append(f"{block.where} {block.kind}: {time.perf_counter() - started:.1f} s")
    print("\n".join(timings))
    return problems


def _run_transcript(block: Block, folder: Path, env, timeout_s: float) -> List[str]:
    problems = []
    tolerances = docs.parse_tolerances(block.directives.get("tolerance", ""))
    steps = docs.transcript_steps(block)
    code = 0
    for index, (command, shown) in enumerate(steps):
        if command.strip() == "echo $?":
            actual = [str(code)]
        else:
            done = _shell(docs.runnable(command, block.directives), folder, env, timeout_s)
            code = done["code"]
            actual = (done["stdout"] + done["stderr"]).splitlines()
            checked = index + 1 < len(steps) and steps[index + 1][0].strip() == "echo $?"
            if code != 0 and not checked:
                problems.append(f"{block.where}: $ {command}: exited {code}: {done['stderr'][-3000:]}")
        problems += [f"{block.where}: $ {command}: {p}" for p in docs.compare_output(shown, actual, tolerances)]
    return problems


def _check_verdict_table(block: Block, folder: Path) -> List[str]:
    tolerances = docs.parse_tolerances(block.directives.get("tolerance", ""))
    pattern = block.directives["verdict table"]
    problems = []

    def near(shown, produced, unit, what):
        tolerance = tolerances.get(unit, 0.0)
        if produced is None or abs(shown - produced) > tolerance + 1e-9:
            problems.append(f"{what}: {shown:g} {unit} on the page, {produced if produced is None else round(produced, 3)} "
                            f"{unit} from the run (within {tolerance:g} {unit})")

    for row in docs.verdict_rows(block):
        where = f"{block.where}: {row['system']}"
        path = folder / pattern.replace("SYSTEM", row["system"]) / "summary.json"
        if not path.is_file():
            problems.append(f"{where}: no {path.relative_to(folder)} (the command block above writes it)")
            continue
        summary = json.loads(path.read_text())
        trains = {t["name"]: t for t in summary["trains"]}
        if sorted(trains) != sorted(t["name"] for t in row["trains"]):
            problems.append(f"{where}: trains {sorted(t['name'] for t in row['trains'])} on the page, "
                            f"{sorted(trains)} in the run")
            continue
        for shown, atp in zip(row["trains"], row["atp_interventions"]):
            train = trains[shown["name"]]
            what = f"{where}: {shown['name']}"
            stops = [s for s in train["stops"]]
            if [s[0] for s in shown["stops"]] != [s["station"] for s in stops]:
                problems.append(f"{what}: stops {[s[0] for s in shown['stops']]} on the page, "
                                f"{[s['station'] for s in stops]} in the run")
                continue
            for (station, deviation, error), stop in zip(shown["stops"], stops):
                near(deviation, stop.get("arrival_deviation_s"), "s", f"{what} {station} arrival")
                near(error, stop.get("stop_error_m"), "m", f"{what} {station} stop error")
            near(shown["energy_kwh"], train["energy_kwh"], "kWh", f"{what} energy")
            if shown["departure_hold_s"] is not None:
                near(shown["departure_hold_s"], train["departure_hold_s"], "s", f"{what} held at departure")
            if atp != train["atp_interventions"]:
                problems.append(f"{what}: {atp} ATP interventions on the page, {train['atp_interventions']} in the run")
        if row["emergency_brakings"] is not None:
            braked = sum(t["emergency_brakings"] for t in summary["trains"])
            if braked != row["emergency_brakings"]:
                problems.append(f"{where}: {row['emergency_brakings']} emergency brakings on the page, {braked} in the run")
        receivers = summary.get("receivers", [])
        unsafe = sum(t["signals_passed_at_danger"] for t in summary["trains"]) + sum(
            r["wrong_side_failures"] + r["unsafe_indications"] for r in receivers)
        verdict = "no signal chain" if not receivers else ("safe" if unsafe == 0 else "UNSAFE")
        if not row["safety"].startswith(verdict):
            problems.append(f"{where}: safety {row['safety']!r} on the page, {verdict!r} from the run")
    return problems


_SIMULATED = re.compile(r"^(?P<system>\S+): \d+(?:\.\d+)? s simulated")
_PRINTED_HOLD = re.compile(r"held at departure (?P<hold>\d+(?:\.\d+)?) s")
_PRINTED_EMERGENCY = re.compile(r"emergency brakings (?P<count>\d+)")


def _printed_verdict_problems(block: Block, printed: List[str]) -> List[str]:
    """What the table quotes as the CLI's verdict lines (``held at departure``, emergency
    brakings, the safety verdict) against the lines the runs above printed: each system's lines
    follow its ``SYSTEM: … s simulated`` line."""
    tolerance = docs.parse_tolerances(block.directives.get("tolerance", "")).get("s", 0.0)
    sections: Dict[str, List[str]] = {}
    current = None
    for line in printed:
        match = _SIMULATED.match(line)
        if match:
            current = sections.setdefault(match.group("system"), [])
        elif current is not None and line.startswith("  "):
            current.append(line.strip())
    problems = []
    for row in docs.verdict_rows(block):
        where = f"{block.where}: {row['system']}"
        lines = sections.get(row["system"])
        if lines is None:
            problems.append(f"{where}: no verdict lines printed (the command block above prints them)")
            continue
        trains = {line.split(":", 1)[0]: line for line in lines if not line.startswith("safety:")}
        for train in row["trains"]:
            line = trains.get(train["name"])
            if line is None:
                problems.append(f"{where}: no line printed for train {train['name']}")
                continue
            hold = _PRINTED_HOLD.search(line)
            if train["departure_hold_s"] is not None and (
                    hold is None or abs(float(hold.group("hold")) - train["departure_hold_s"]) > tolerance + 1e-9):
                problems.append(f"{where}: {train['name']} held at departure {train['departure_hold_s']:g} s on the "
                                f"page; printed: {line!r}")
        if row["emergency_brakings"] is not None:
            printed_count = sum(int(m.group("count")) for line in trains.values()
                                for m in [_PRINTED_EMERGENCY.search(line)] if m)
            if printed_count != row["emergency_brakings"]:
                problems.append(f"{where}: {row['emergency_brakings']} emergency brakings on the page, "
                                f"{printed_count} printed")
        safety = next((line for line in lines if line.startswith("safety:")), None)
        if safety is None or not safety.startswith(f"safety: {row['safety']}"):
            problems.append(f"{where}: safety {row['safety']!r} on the page; printed: {safety!r}")
    return problems


# ---- the tests -----------------------------------------------------------------------------------

def _ids(block):
    return block.where


@pytest.mark.parametrize("block", [b for b in BLOCKS if b.kind in SKIPPED_KINDS and set(b.directives) & set(SKIPPED_KINDS)],
                         ids=_ids)
def test_block_not_run_says_why(block, record_property):
    """A block the test does not run says why in its annotation; the reasons are listed at the end
    of the run (tests/conftest.py, "doc blocks not run")."""
    reason = _skipped_reason(block)
    assert "(no reason given)" not in reason, f"{block.where}: a block not run must say why"
    record_property(NOT_RUN_PROPERTY, reason)


@pytest.mark.parametrize("block", [b for b in BLOCKS if b.kind == "text" and "text" not in b.directives], ids=_ids)
def test_text_block_is_no_command(block):
    """A fence with no command line needs no annotation; one is text (diagrams, messages)."""
    assert not any(docs.is_command(line) for line in block.lines)


def test_every_block_is_run_checked_or_skipped_with_a_reason():
    """A fence the test cannot tell what to do with (commands mixed with other lines, a data file
    without the annotation naming what reads it) is an error, not a silent pass."""
    unclear = [f"{b.where}: a {b.kind} block: annotate it (<!-- docs-test: … -->, tests/docs_blocks.py)"
               for b in BLOCKS if b.kind in ("mixed", "unannotated data")]
    assert not unclear, "\n".join(unclear)
    assert {b.kind for b in BLOCKS} <= {*RUN_KINDS, *CHECK_KINDS, *SKIPPED_KINDS}


@pytest.mark.parametrize("block", [b for b in BLOCKS if b.kind == "synopsis"], ids=_ids)
def test_synopsis_matches_the_commands(block):
    problems = _railcosim_synopsis_problems(block)
    assert not problems, "\n".join(problems)


@pytest.mark.parametrize("block", [b for b in BLOCKS if b.kind in docs.DATA_KINDS], ids=_ids)
def test_example_file_is_read_by_what_reads_it(block, tmp_path, product_fmus):
    env = _workspace(tmp_path)
    problems = _check_data(block, tmp_path, env)
    assert not problems, "\n".join(problems)


RUN_PAGES = sorted({b.page for b in BLOCKS if b.kind in RUN_KINDS}, key=lambda p: docs.pages().index(p))


@pytest.mark.parametrize("page", RUN_PAGES, ids=[p.relative_to(ROOT).as_posix() for p in RUN_PAGES])
def test_page_runs_as_written_and_quotes_its_runs(page, tmp_path, product_fmus):
    if shutil.which("ngspice") is None and any(
            b.page == page and b.kind == "shell" and re.search(r"^\s*ngspice\b", b.text, re.M) for b in BLOCKS):
        pytest.skip(f"{page.name} runs ngspice, which is not on PATH (apt-get install ngspice; .ci/run does)")
    problems = _run_page(page, tmp_path)
    problems += _not_ignored(page, tmp_path)
    assert not problems, "\n\n".join(problems)


# ---- what a page leaves behind ---------------------------------------------------------------------

#: what the test itself writes into a page's folder (the shims, the python blocks' files)
OWN_ENTRIES = re.compile(r"\.docs-test-bin|docs_block_\d+\.py")


def _git(*args) -> subprocess.CompletedProcess:
    return subprocess.run(["git", "-C", str(ROOT), *args], capture_output=True, text=True)


def _not_ignored(page: Path, folder: Path) -> List[str]:
    """Everything a page's commands make at the top of the folder they run in is what a reader
    running them from the repository root finds there: each must be something git ignores
    (.gitignore), so that following the docs leaves `git status` as it was. (What they write
    through the links, into build/, is ignored there already.)"""
    if _git("rev-parse", "--is-inside-work-tree").returncode != 0:
        return []                      # not a git checkout: nothing to compare with
    made = sorted(entry.name + ("/" if entry.is_dir() else "") for entry in folder.iterdir()
                  if not entry.is_symlink() and not OWN_ENTRIES.fullmatch(entry.name))
    shown = [name for name in made if _git("check-ignore", "-q", "--no-index", "--", name).returncode != 0]
    return [f"{page.relative_to(ROOT)}: its commands leave {', '.join(shown)} in the folder they run from, which "
            ".gitignore does not ignore: a reader following the page from the repository root finds them in "
            "git status"] if shown else []


# ---- the checks themselves: they fail where a page and a run differ ---------------------------

RUN_OUTPUT = ["wrote branch (SystemStructure.ssd, line.ssv, resources/)",
              "branch: 580.000 s simulated in 27.261 s (21.3x real time); results in results/branch",
              "  train: 102.9 kWh; arrivals Halt -3.0 s / -0.14 m, South -7.0 s / -0.05 m; ATP interventions 0, SPAD 0"]


def test_a_figure_off_the_run_a_missing_line_and_a_wrong_count_are_caught():
    page = ["branch: 520.000 s simulated …", "  train: 150.2 kWh; arrivals Halt -3.0 s / -0.14 m, South -7.5 s / "
            "-0.05 m; ATP interventions 0, SPAD 1", "safety: safe"]
    problems = docs.compare_output(page, RUN_OUTPUT, docs.parse_tolerances("0.5 s, 0.01 m, 0.1 kWh"))
    assert any(p.startswith("520.000 s on the page, 580.000 s from the run (within 0.5 s)") for p in problems)
    assert any(p.startswith("150.2 kWh on the page, 102.9 kWh") for p in problems)
    assert any(p.startswith("1 on the page, 0 from the run (as printed)") for p in problems)    # SPAD
    assert any("not in the output: 'safety: safe'" in p for p in problems)
    assert not any(p.startswith("-7.5") for p in problems)         # within its 0.5 s
    assert len(problems) == 4, problems


def test_figures_are_compared_as_printed_without_a_tolerance_and_ellipses_stand_for_text():
    page = ["branch: 580.000 s simulated …", "…", "  train: 102.9 kWh; arrivals Halt -3.0 s / -0.14 m, South …"]
    assert docs.compare_output(page, RUN_OUTPUT, {}) == []
    assert docs.compare_output(["branch: 580.0 s simulated …"], RUN_OUTPUT, {}) != []     # 580.0 ≠ 580.000 as printed
    # names with digits are text, not figures: KPT-5 does not match KPT-7, phase0.0 not phase1.0
    assert docs.compare_output(["acquire_Z_KPT-5_phase0.0  3.3 s"], ["acquire_Z_KPT-7_phase0.0  3.3 s"], {}) != []
    assert docs.compare_output(["acquire_Z_KPT-5_phase0.0  3.3 s"], ["acquire_Z_KPT-5_phase0.0  3.4 s"],
                               {"s": 0.1}) == []


def test_the_verdict_table_rows_are_read_figure_by_figure():
    block = Block(ROOT / "docs" / "scenarios.md", 1, "", "\n".join([
        "| system | trains | ATP | safety |", "|---|---|---|---|",
        "| following | leader: B +0.0 s / −0.14 m, C sidings +254.0 s / −0.12 m; 600.9 kWh · follower: C +110.0 s / "
        "−0.03 m; 705.2 kWh | 0 · 0 | safe |",
        "| same_block | leader: C −1.5 s / −0.04 m; 299.1 kWh · follower: B +317.0 s / −0.05 m; 513.0 kWh (held at "
        "departure 208.5 s) | 0 · 0 | safe |",
        "| faults | train: B +279.0 s / −0.07 m; 872.7 kWh | 0 (0 emergency brakings) | safe |"]))
    following, same_block, faults = docs.verdict_rows(block)
    assert following["trains"][0] == {"name": "leader", "stops": [("B", 0.0, -0.14), ("C sidings", 254.0, -0.12)],
                                      "energy_kwh": 600.9, "departure_hold_s": None}
    assert following["atp_interventions"] == [0, 0] and following["safety"] == "safe"
    assert same_block["trains"][1]["departure_hold_s"] == 208.5
    assert faults["emergency_brakings"] == 0 and faults["atp_interventions"] == [0]


def test_the_verdict_lines_a_table_quotes_are_the_ones_the_runs_print(tmp_path, product_fmus):
    """A departure hold, emergency brakings and the safety verdict the table quotes as the CLI's
    are the lines `railcosim run` prints (the CLI once printed none of the three): real runs,
    short ones, against a table of their figures, right and wrong."""
    env = _workspace(tmp_path)
    done = _shell("railcosim run same_block --stop-time 120 --in-process --no-build --output results/same_block\n"
                  "railcosim run ato_only --stop-time 20 --in-process --no-build --output results/ato_only",
                  tmp_path, env, 300)
    assert done["code"] == 0, done["stderr"]
    printed = done["stdout"].splitlines()

    def table(hold: str, emergency: str, safety: str) -> Block:
        return Block(ROOT / "docs" / "scenarios.md", 1, "", "\n".join([
            "| system | trains | ATP | safety |", "|---|---|---|---|",
            f"| same_block | leader: C −1.5 s / −0.04 m; 5.0 kWh · follower: B +0.0 s / −0.00 m; 5.0 kWh "
            f"(held at departure {hold} s) | 0 · 0 | safe |",
            f"| ato_only | train: B +0.5 s / −0.12 m; 0.8 kWh | 0 ({emergency} emergency brakings) | {safety} |"]),
            {"tolerance": "0.5 s"})

    assert _printed_verdict_problems(table("60.0", "0", "no signal chain"), printed) == []
    wrong = _printed_verdict_problems(table("70.0", "1", "safe"), printed)
    assert len(wrong) == 3, wrong
    assert "follower held at departure 70 s on the page" in wrong[0]
    assert "1 emergency brakings on the page, 0 printed" in wrong[1]
    assert "safety 'safe' on the page; printed: 'safety: no signal chain" in wrong[2]


def test_an_annotation_changes_only_what_it_declares():
    directives = docs.parse_directives("stop-time 20; add to bench_x.py: --repeats 1")
    assert directives == {"stop-time": "20", "add to bench_x.py": "--repeats 1"}
    assert docs.runnable('railcosim dcp-slave rx.fmu --port 5000 &', directives) == "railcosim dcp-slave rx.fmu --port 5000 &"
    assert docs.runnable('railcosim run free_run --swap "rx=dcp://h:1?a=b#c"   # swapped', directives) == \
        'railcosim run free_run --swap "rx=dcp://h:1?a=b#c" --stop-time 20'
    assert docs.runnable("python bench_x.py [--frames 3000]", directives) == "python bench_x.py --repeats 1"
    assert docs.runnable("python bench_y.py --frames 10", directives) == "python bench_y.py --frames 10"
    assert docs.runnable("python benchmarks/bench_x.py", directives) == "python benchmarks/bench_x.py --repeats 1"
    mixed = Block(ROOT / "README.md", 1, "", "railcosim run\nthis is not a command")
    assert docs.classify(mixed) == "mixed"

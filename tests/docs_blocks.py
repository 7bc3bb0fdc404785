"""The command and example blocks of README.md and docs/*.md, as tests/test_docs_run.py runs and
checks them; the convention is in docs/architecture.md ("Docs that run").

A block is a ``` fence. What the test does with it follows from its content, or from one
annotation line right above it, an HTML comment a reader sees in the page's source only:

    <!-- docs-test: DIRECTIVE; DIRECTIVE ... -->

Directives (each ``name`` or ``name: value``):

* ``skip: REASON`` — not run; listed with REASON at the end of the run;
* ``needs dcp-slave: REASON``, ``needs hardware: REASON`` — not run: it needs a DCP slave or a
  bench device the test does not have; listed with REASON;
* ``text: REASON`` — not a command though it looks like one (an illustration);
* ``synopsis`` — usage lines: every option they name must exist, every option of each railcosim
  command they show must be named (checked with the CLI's own parser, or a script's ``--help``);
* ``stop-time S`` — the test adds ``--stop-time S`` to every ``run`` command of the block;
* ``add: OPTIONS`` — the test appends OPTIONS to every command of the block; ``add to NAME:
  OPTIONS`` to the commands whose program or script is NAME (``add to bench_ato.py: --repeats 1``);
* ``setup: COMMAND`` — a shell command run before the block (what a reader has already made);
* ``timeout: S`` — seconds the block may take (default 600);
* ``full: REASON`` — a long block (whole systems in full): run, with the output or verdict
  table that checks it, only when ``RAILCOSIM_DOCS_FULL=1`` is set (``FULL_RUNS``); the default
  suite skips both and prints REASON, so that it stays within its time (the command that runs
  them: docs/architecture.md#docs-that-run-teststest_docs_runpy);
* ``output`` — the block is what the command block above it prints: compared line by line;
* ``tolerance: 0.5 s, 0.01 m`` — a figure with that unit may differ from the run's by that
  much (figures of other units: as printed);
* ``study file``, ``scenario for SYSTEM``, ``scenario event for SYSTEM``, ``line file fragment``,
  ``ssd fragment``, ``ci job``, ``railml sidecar`` — an example file read by what reads it (not run;
  ``railml sidecar: FILE``: also the content of FILE, which the page's commands use);
* ``verdict table: results/SYSTEM`` — above a Markdown table (not a fence): the table of the
  shipped systems' verdicts, compared with each run's summary.json in that folder.

Without an annotation: a fence whose lines start with ``$ `` is a transcript (each command run,
the lines after it compared with what it prints; a command may exit non-zero only where the
transcript shows ``echo $?``); ```python is run with the Python under test; a fence whose
every line is a command (``railcosim``, ``python``, ``pip``, ``cmp``, ``cd`` …) is run with
bash; a fence with no command line is text; anything else (a mixed fence, an unlabelled data
file) is an error asking for an annotation. A command line with ``[optional parts]`` is
checked as a synopsis and run without them.
"""
from __future__ import annotations

import os
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Dict, Iterator, List, Optional, Sequence, Tuple

ROOT = Path(__file__).resolve().parent.parent
#: whether the blocks annotated ``full`` run (and the checks of their results)
FULL_RUNS = os.environ.get("RAILCOSIM_DOCS_FULL", "") == "1"
ANNOTATION = re.compile(r"^\s*<!--\s*docs-test:\s*(?P<body>.*?)\s*-->\s*$")
COMMAND_WORDS = ("railcosim", "python", "python3", "pip", "cmp", "cd", "mkdir", "cp", "ls", "for", "do", "done",
                 "dask", "export", "echo", "ngspice", "PYTHONPATH=")
DATA_KINDS = ("study file", "scenario for", "scenario event for", "line file fragment", "ssd fragment", "ci job",
              "railml sidecar")
SKIP_KINDS = ("skip", "needs dcp-slave", "needs hardware", "text")
DEFAULT_TIMEOUT_S = 600.0


def pages() -> List[Path]:
    """The pages a reader follows: README.md and docs/*.md (the changelog's blocks are history)."""
    docs = sorted(p for p in (ROOT / "docs").glob("*.md") if p.name != "changelog.md" and not p.name.startswith("_"))
    return [ROOT / "README.md", *docs]


@dataclass
class Block:
    page: Path
    line: int                      # 1-based line of the opening fence (or of the table's first row)
    info: str                      # the fence's info string (``toml``, ``python`` …)
    text: str                      # the block's content
    directives: Dict[str, str] = field(default_factory=dict)
    kind: str = ""

    @property
    def where(self) -> str:
        return f"{self.page.relative_to(ROOT)}:{self.line}"

    @property
    def lines(self) -> List[str]:
        return self.text.splitlines()


def parse_directives(body: str) -> Dict[str, str]:
    directives = {}
    for part in filter(None, (p.strip() for p in body.split(";"))):
        name, _, value = part.partition(":")
        name, value = name.strip(), value.strip()
        for prefix in ("stop-time", "scenario for", "scenario event for"):   # "stop-time 20", "scenario for free_run"
            if name.startswith(prefix + " ") and not value:
                name, value = prefix, name[len(prefix):].strip()
        directives[name] = value
    return directives


def _logical_lines(text: str) -> List[str]:
    """Shell lines with their backslash continuations joined."""
    joined, current = [], ""
    for line in text.splitlines():
        if line.rstrip().endswith("\\"):
            current += line.rstrip()[:-1] + " "
            continue
        joined.append(current + line)
        current = ""
    if current:
        joined.append(current)
    return joined


def is_command(line: str) -> bool:
    word = line.strip().split(" ", 1)[0]
    return word in COMMAND_WORDS or word.startswith("PYTHONPATH=")


def classify(block: Block) -> str:
    d = block.directives
    for kind in (*SKIP_KINDS, *DATA_KINDS, "synopsis", "output", "verdict table"):
        if kind in d:
            return kind
    if block.info == "python":
        return "python"
    if block.info:
        return "unannotated data"
    lines = [line for line in _logical_lines(block.text) if line.strip() and not line.strip().startswith("#")]
    if lines and lines[0].startswith("$ "):
        return "transcript"
    commands = [is_command(line) for line in lines]
    if lines and all(commands):
        return "shell"
    if not any(commands):
        return "text"
    return "mixed"


def blocks_of(page: Path) -> Iterator[Block]:
    """Every fence of a page, and every annotated Markdown table, with its directives and kind."""
    lines = page.read_text(encoding="utf-8").splitlines()
    i = 0
    while i < len(lines):
        line = lines[i]
        stripped = line.strip()
        annotation = _annotation_above(lines, i)
        if stripped.startswith("```"):
            indent = len(line) - len(line.lstrip())
            end = i + 1
            while end < len(lines) and not lines[end].strip().startswith("```"):
                end += 1
            body = "\n".join(text[indent:] if not text[:indent].strip() else text.lstrip() for text in lines[i + 1:end])
            block = Block(page, i + 1, stripped[3:].strip(), body, parse_directives(annotation or ""))
            block.kind = classify(block)
            yield block
            i = end + 1
            continue
        if stripped.startswith("|") and annotation is not None and "verdict table" in annotation:
            end = i
            while end < len(lines) and lines[end].strip().startswith("|"):
                end += 1
            block = Block(page, i + 1, "", "\n".join(lines[i:end]), parse_directives(annotation))
            block.kind = "verdict table"
            yield block
            i = end
            continue
        i += 1


def _annotation_above(lines: Sequence[str], index: int) -> Optional[str]:
    """The docs-test annotation on the line above ``index`` (blank lines between allowed)."""
    k = index - 1
    while k >= 0 and not lines[k].strip():
        k -= 1
    match = ANNOTATION.match(lines[k]) if k >= 0 else None
    return match.group("body") if match else None


def all_blocks() -> List[Block]:
    return [block for page in pages() for block in blocks_of(page)]


# ---- commands as the test runs them ------------------------------------------------------------

_OPTIONAL = re.compile(r"\s*\[[^\[\]]*\]")


def split_comment(line: str) -> Tuple[str, str]:
    """(command, comment) of a shell line: the comment starts at a '#' after a blank, outside quotes."""
    quote = None
    for k, char in enumerate(line):
        if quote:
            quote = None if char == quote else quote
        elif char in "'\"":
            quote = char
        elif char == "#" and (k == 0 or line[k - 1].isspace()):
            return line[:k].rstrip(), line[k:]
    return line.rstrip(), ""


def optional_parts(line: str) -> List[str]:
    return [part.strip()[1:-1] for part in _OPTIONAL.findall(split_comment(line)[0])]


def runnable(line: str, directives: Dict[str, str]) -> str:
    """The line as the test runs it: [optional parts] dropped, the annotation's additions made
    (before a trailing '&', the comment kept out)."""
    command, _ = split_comment(line)
    command = _OPTIONAL.sub("", command).rstrip()
    background = command.endswith("&")
    if background:
        command = command[:-1].rstrip()
    words = command.split()
    extra = []
    is_run = len(words) > 1 and (words[:2] == ["railcosim", "run"] or "orchestrator run" in command)
    if "stop-time" in directives and is_run:
        extra.append(f"--stop-time {directives['stop-time']}")
    if "add" in directives and words and words[0] not in ("cd", "cmp", "for", "do", "done", "echo", "mkdir", "cp"):
        extra.append(directives["add"])
    for name, options in directives.items():      # "add to count_instructions.py: --warm 2"
        target = name[len("add to "):].strip() if name.startswith("add to ") else None
        if target and any(word == target or word.endswith("/" + target) for word in words[:3]):
            extra.append(options)
    command = " ".join([command, *extra])
    return command + (" &" if background else "")


def script_of(block: Block) -> str:
    """A bash script of a shell block as the test runs it."""
    return "\n".join(runnable(line, block.directives) for line in _logical_lines(block.text)
                     if line.strip() and not line.strip().startswith("#"))


def transcript_steps(block: Block) -> List[Tuple[str, List[str]]]:
    """(command, the lines shown after it) of a ``$`` transcript."""
    steps: List[Tuple[str, List[str]]] = []
    for line in block.lines:
        if line.startswith("$ "):
            steps.append((line[2:], []))
        elif steps:
            steps[-1][1].append(line)
    return steps


# ---- figures: a page's output beside the run's -------------------------------------------------

# a figure: a number standing alone (not the 5 of KPT-5, the 0.0 of phase0.0 or the 0000 of r0000)
NUMBER = re.compile(r"(?<![\w.\-−+/])[-+−]?\d+(?:\.\d+)?(?![\w.])|(?<=/)\d+(?:\.\d+)?(?![\w.])")
UNIT = re.compile(r"\s*([A-Za-zА-Яа-яµ%°²]+)")
ELLIPSIS = "…"


def parse_tolerances(text: str) -> Dict[str, float]:
    """``0.5 s, 0.01 m`` → {"s": 0.5, "m": 0.01}."""
    tolerances = {}
    for part in filter(None, (p.strip() for p in text.split(","))):
        value, _, unit = part.partition(" ")
        tolerances[unit.strip()] = float(value)
    return tolerances


def _number(text: str) -> float:
    return float(text.replace("−", "-"))


def line_pattern(expected: str) -> Tuple[re.Pattern, List[Tuple[str, str]]]:
    """A regex for one expected line (figures and … as wildcards, blanks as any blanks) and the
    (figure, unit) it captures, in order."""
    pattern, figures, pos = [], [], 0
    tokens = [(m.start(), m.end(), "number") for m in NUMBER.finditer(expected)]
    tokens += [(m.start(), m.end(), "ellipsis") for m in re.finditer(ELLIPSIS, expected)]
    for start, end, what in sorted(tokens):
        if start < pos:
            continue
        pattern.append(_literal(expected[pos:start]))
        if what == "number":
            pattern.append(r"([-+−]?\d+(?:\.\d+)?)")
            unit = UNIT.match(expected, end)
            figures.append((expected[start:end], unit.group(1) if unit else ""))
        else:
            pattern.append(r".*?")
        pos = end
    pattern.append(_literal(expected[pos:]))
    return re.compile("".join(pattern).strip()), figures


def _literal(text: str) -> str:
    return "".join(r"\s+" if part.isspace() else re.escape(part) for part in re.split(r"(\s+)", text) if part)


def compare_output(expected_lines: Sequence[str], actual_lines: Sequence[str],
                   tolerances: Dict[str, float]) -> List[str]:
    """Problems (empty: none) of a page's output against the run's: every expected line (a line
    of … alone skips any lines) must match an actual line, in order, and every figure in it must
    equal the run's as printed, or be within the tolerance of its unit."""
    problems = []
    position = 0
    actual = [line.strip() for line in actual_lines]
    for expected in (line.strip() for line in expected_lines):
        if not expected or expected == ELLIPSIS:
            continue
        pattern, figures = line_pattern(expected)
        for k in range(position, len(actual)):
            match = pattern.fullmatch(actual[k])
            if match:
                break
        else:
            problems.append(f"not in the output: {expected!r}")
            continue
        position = k + 1
        for (shown, unit), produced in zip(figures, match.groups()):
            tolerance = tolerances.get(unit)
            if tolerance is None:
                same = _number(shown) == _number(produced) and (
                    shown.lstrip("+−-") == produced.lstrip("+−-"))
            else:
                same = abs(_number(shown) - _number(produced)) <= tolerance + 1e-12
            if not same:
                bound = f"within {tolerance:g} {unit}" if tolerance is not None else "as printed"
                unit_text = f" {unit}" if unit else ""
                problems.append(f"{shown}{unit_text} on the page, {produced}{unit_text} from the run ({bound}): "
                                f"{expected!r}")
    return problems


# ---- the verdict table of the shipped systems --------------------------------------------------

_STOP = re.compile(r"(?P<station>[^,;:]+?)\s+(?P<dev>[-+−]?\d+(?:\.\d+)?) s / (?P<err>[-+−]?\d+(?:\.\d+)?) m")
_ENERGY = re.compile(r";\s*(?P<kwh>\d+(?:\.\d+)?) kWh")
_HOLD = re.compile(r"held at departure (?P<hold>\d+(?:\.\d+)?) s")


def verdict_rows(block: Block) -> List[dict]:
    """The table's rows: system, trains (name, stops, energy, departure hold), ATP interventions
    per train, emergency brakings if given, safety."""
    rows = []
    for line in block.lines[2:]:                      # header and its rule
        cells = [cell.strip() for cell in line.strip().strip("|").split("|")]
        system, trains_text, atp_text, safety = cells
        trains = []
        for part in trains_text.split(" · "):
            name, _, rest = part.partition(":")
            stops = [(m.group("station").strip(), _number(m.group("dev")), _number(m.group("err")))
                     for m in _STOP.finditer(rest.split(";")[0])]
            energy = _ENERGY.search(rest)
            hold = _HOLD.search(rest)
            trains.append({"name": name.strip(), "stops": stops, "energy_kwh": float(energy.group("kwh")),
                           "departure_hold_s": float(hold.group("hold")) if hold else None})
        atp = [int(text.strip().split(" ")[0]) for text in atp_text.split(" · ")]
        emergency = re.search(r"\((\d+) emergency brakings?\)", atp_text)
        rows.append({"system": system, "trains": trains, "atp_interventions": atp,
                     "emergency_brakings": int(emergency.group(1)) if emergency else None, "safety": safety})
    return rows

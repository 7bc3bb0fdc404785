"""The package walls of docs/architecture.md, checked on the source: who may import what,
and that the model cores, the data layer, the signalling library and the railway rooms
import with pythonfmu unavailable (a core runs in process without any FMI library)."""
import ast
import re
import subprocess
import sys
import textwrap
from dataclasses import dataclass
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent
UNITS = ("wayside_coder", "rail_line", "loco_receiver", "traction", "ato_controller")


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(REPO).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def _imports(path: Path):
    """Every module a file imports (relative imports resolved), with its line."""
    module = _module_name(path)
    package = module.split(".") if path.name == "__init__.py" else module.split(".")[:-1]
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield alias.name, node.lineno
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package[: len(package) - node.level + 1]
                name = ".".join(base + ([node.module] if node.module else []))
            else:
                name = node.module
            yield name, node.lineno
            for alias in node.names:          # "from fmus import fmi" imports fmus.fmi
                yield f"{name}.{alias.name}", node.lineno


#: the rooms of railway knowledge applied to runs (docs/architecture.md): on the engine, beneath the front ends
RAILWAY_ROOMS = ("verdicts", "reports", "railml", "circuits", "systems")


def _within(name: str, prefixes) -> bool:
    return any(name == p or name.startswith(p + ".") for p in prefixes)


# --- The may-import table of docs/architecture.md ("Layout"), as data -----------------------
#
# One Row per row of the table: ``cell`` is the row's first column as written there (its
# backticked paths say which files the row holds: a ``.py`` file, a folder and all below it, or
# with "(top level)" the folder's own files; the most specific path holds a file), ``may`` what
# the row's modules may import besides the standard library and each other: another Row (its
# modules, and the libraries that row may import), a product module or package by name, or a
# library by its import name. ``never`` is refused even where ``may`` is ANYTHING. To add a row,
# add it to the page and here, in the page's order (test_the_table_rows_are_the_pages_rows).

ANYTHING = ("*",)


@dataclass(frozen=True)
class Row:
    cell: str
    may: tuple = ()
    never: tuple = ()


LEAVES = Row("`fmus/errors.py`, `fmus/sizes.py`, `fmus/units.py`, `fmus/train_categories.py`")
FAST_PATHS = Row("`fmus/reductions.py`, `fmus/library_shortcuts.py`", ("numpy", "scipy"))
DATA = Row("`fmus/data/`", ("numpy", "jsonschema", "fmus.errors", "fmus.units", "fmus.train_categories"))
SIGNALLING = Row("`fmus/signalling/`", ("numpy", "scipy", "fmus.errors", "fmus.units", "fmus.train_categories",
                                        "fmus.sizes", "fmus.dsp", "fmus.data"))
DSP = Row("`fmus/dsp/`", ("numpy", "scipy", "control", "fmus.library_shortcuts"))
FMUS_LIBRARIES = (LEAVES, FAST_PATHS, DATA, SIGNALLING, DSP)
FMI = Row("`fmus/fmi/`", ("pythonfmu", *FMUS_LIBRARIES))
CORES = Row("`fmus/<unit>/`", FMUS_LIBRARIES)                  # their own row: other units' cores
FACADES = Row("`fmus/<unit>/facade.py`", (CORES, FMI, *FMUS_LIBRARIES))
ENGINE = Row("`orchestrator/` (top level)", ("fmpy", "lxml", "numpy"))
RUN = Row("`orchestrator/plan.py`, `orchestrator/run.py`, `orchestrator/components.py`, `orchestrator/results.py`, "
          "`orchestrator/process_policy.py`, `orchestrator/validation.py`", (ENGINE, "orchestrator.dcp", "threadpoolctl"))
VERDICTS = Row("`orchestrator/verdicts/`", (ENGINE, *FMUS_LIBRARIES, CORES))
REPORTS = Row("`orchestrator/reports/`", (ENGINE, VERDICTS, *FMUS_LIBRARIES, CORES, "matplotlib", "bokeh"))
RAILML = Row("`orchestrator/railml/` (+ `schema/`)",
             ("lxml", "jsonschema", "fmus.data", "fmus.errors", "orchestrator.errors", "orchestrator.ssp",
              "orchestrator.graph", "orchestrator.verdicts.system_checks"))
CIRCUITS = Row("`orchestrator/circuits/`", (ENGINE, REPORTS, *FMUS_LIBRARIES, CORES))
SYSTEM_WRITERS = Row("`orchestrator/systems/`", (ENGINE, VERDICTS, RAILML, *FMUS_LIBRARIES, CORES))
DCP = Row("`orchestrator/dcp/`", (ENGINE, "lxml", "numpy"))
CONFORMANCE = Row("`orchestrator/conformance/`", (ENGINE, *FMUS_LIBRARIES, CORES))
STUDY = Row("`orchestrator/study/`", (ENGINE, RUN, VERDICTS, "dask", "distributed", "jsonschema", "matplotlib"))
HEADWAY = Row("`orchestrator/headway/`", (ENGINE, RUN, VERDICTS, SYSTEM_WRITERS, STUDY, *FMUS_LIBRARIES, CORES,
                                           "matplotlib"))
PACKAGING = Row("`orchestrator/packaging/`", ANYTHING)
CLI = Row("`orchestrator/cli.py`, `orchestrator/__main__.py`", ANYTHING)
CATALOGUE = Row("`orchestrator/catalogue.py`", ANYTHING, never=("benchmarks",))
SYSTEMS = Row("`ssp/<name>/`")
HARNESS = Row("`harness/`", ("fmus", "orchestrator", "numpy", "scipy"), never=("benchmarks", "tests", "conftest"))
BENCHMARKS = Row("`benchmarks/`", ANYTHING)
TESTS = Row("`tests/`", ANYTHING, never=("benchmarks",))

TABLE = (LEAVES, FAST_PATHS, DATA, SIGNALLING, DSP, FMI, CORES, FACADES, ENGINE, RUN, VERDICTS, REPORTS, RAILML,
         CIRCUITS, SYSTEM_WRITERS, DCP, CONFORMANCE, STUDY, HEADWAY, PACKAGING, CLI, CATALOGUE, SYSTEMS, HARNESS,
         BENCHMARKS, TESTS)
#: the folders whose Python files the table places
CHECKED = ("fmus", "orchestrator", "harness", "benchmarks", "tests")
#: package roots: a docstring, no imports of their own; importing one is importing into it
ROOTS = ("fmus", "orchestrator")


def _page_rows():
    """The first column of every row of the Layout table in docs/architecture.md."""
    text = (REPO / "docs" / "architecture.md").read_text()
    section = text.split("\n## Layout\n", 1)[1].split("\n## ", 1)[0]
    cells = [line.split(" | ", 1)[0][2:] for line in section.splitlines() if line.startswith("| ")]
    return [cell for cell in cells if cell not in ("package",)]


def _placements(row: Row):
    """(path, kind) for each path the row's cell names: kind 'file', 'tree' or 'top'."""
    top_level = "(top level)" in row.cell
    for path in re.findall(r"`([^`]+)`", row.cell):
        for unit_path in ([path.replace("<unit>", unit) for unit in UNITS] if "<unit>" in path else [path]):
            kind = "file" if unit_path.endswith(".py") else "top" if top_level else "tree"
            yield unit_path, kind


def _row_of(relative: str) -> Row:
    """The row that holds a file (its path relative to the repository): the most specific."""
    best = []
    for row in TABLE:
        for path, kind in _placements(row):
            if kind == "file" and relative == path:
                best.append(((2, len(path)), row))
            elif kind == "tree" and relative.startswith(path):
                best.append(((1, len(path)), row))
            elif kind == "top" and relative.startswith(path) and "/" not in relative[len(path):]:
                best.append(((1, len(path)), row))
    if not best:
        return None
    best.sort(key=lambda found: found[0])
    assert len(best) < 2 or best[-1][0] != best[-2][0], f"{relative}: two rows hold it equally"
    return best[-1][1]


def _product_files():
    for package in ROOTS:
        yield from sorted((REPO / package).rglob("*.py"))


def _checked_files():
    for folder in CHECKED:
        yield from sorted((REPO / folder).rglob("*.py"))


def _is_root(path: Path) -> bool:
    return path.relative_to(REPO).as_posix() in (f"{root}/__init__.py" for root in ROOTS)


def _allowed(name: str, target: Row, row: Row) -> bool:
    """May a module of ``row`` import ``name`` (a product module of row ``target``, or None)?"""
    if _within(name, row.never):
        return False
    if row.may == ANYTHING or target is row:
        return True
    for entry in row.may:
        if isinstance(entry, Row):
            if target is entry or (target is None and _within(name, _libraries(entry))):
                return True
        elif _within(name, (entry,)):
            return True
    if name in ROOTS:      # ``import fmus`` (its folder): allowed wherever something inside it is
        return any(path.startswith(name + "/") for entry in row.may if isinstance(entry, Row)
                   for path, _ in _placements(entry)) \
            or any(isinstance(entry, str) and _within(entry, (name,)) for entry in row.may)
    return False


def _libraries(row: Row):
    """The libraries a row may import (what another row that may import it may use too)."""
    return tuple(e for e in row.may if isinstance(e, str) and e.split(".")[0] not in (*ROOTS, *CHECKED))


def test_the_table_rows_are_the_pages_rows():
    """Each row of docs/architecture.md's table is a Row here, in its order, and back."""
    assert _page_rows() == [row.cell for row in TABLE]


def test_every_module_imports_only_what_its_row_may():
    """The may-import table, checked exactly, at the level of its rows: every import of every
    module (at the top, inside functions, under TYPE_CHECKING) must be the standard library,
    its own row, a package above it, or what its row's "may import" names."""
    modules = {_module_name(path): path for path in _checked_files()}
    row_of_module = {}
    for module, path in modules.items():
        if not _is_root(path):
            row = _row_of(path.relative_to(REPO).as_posix())
            assert row is not None, f"{path.relative_to(REPO)}: no row of docs/architecture.md holds it"
            row_of_module[module] = row
    broken = []
    for module, path in modules.items():
        row = row_of_module.get(module)
        for name, line in _imports(path):
            top = name.split(".")[0]
            if name == module or top in sys.stdlib_module_names or top == "__future__":
                continue
            if module.startswith(name + "."):         # a package above it: imported by Python anyway
                continue
            if name not in modules and top in CHECKED and name.rpartition(".")[0] in modules:
                continue                              # ``from module import name``: the module counts
            where = f"{path.relative_to(REPO)}:{line} imports {name}"
            if row is None:                           # a package root imports nothing of its own
                broken.append(where + " (a package root)")
            elif not _allowed(name, row_of_module.get(name), row):
                broken.append(f"{where}, which the row {row.cell} may not")
    assert not broken, "the may-import table of docs/architecture.md is broken:\n" + "\n".join(broken)


def test_the_bundled_package_holds_no_build_tooling_or_harness():
    names = {p.stem for p in (REPO / "fmus").rglob("*.py")}
    assert not names & {"build", "builder", "packaging", "packing", "contract", "loop", "closed_loop", "channel"}


def test_cores_data_signalling_and_railway_rooms_import_without_any_fmi_library():
    modules = [f"fmus.{unit}.core" for unit in UNITS]
    modules += [_module_name(p) for p in _product_files()
                if _module_name(p).startswith(("fmus.data", "fmus.signalling", "fmus.dsp",
                                               *(f"orchestrator.{room}" for room in RAILWAY_ROOMS)))
                or (p.parent.name in UNITS and p.name not in ("facade.py",))]
    script = textwrap.dedent(f"""
        import importlib, importlib.abc, sys
        class Block(importlib.abc.MetaPathFinder):
            def find_spec(self, name, path=None, target=None):
                if name.split('.')[0] == 'pythonfmu':
                    raise ImportError('pythonfmu is blocked in this test')
        sys.meta_path.insert(0, Block())
        for module in {sorted(set(modules))!r}:
            importlib.import_module(module)
        loaded = sorted(m for m in sys.modules if m.split('.')[0] == 'pythonfmu')
        assert not loaded, loaded
        print(len({sorted(set(modules))!r}))
    """)
    done = subprocess.run([sys.executable, "-c", script], cwd=REPO, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr[-3000:]
    assert int(done.stdout.strip()) > 20


@pytest.mark.parametrize("unit", UNITS)
def test_a_core_runs_its_unit_without_fmi(unit):
    # the facade is the only module of a unit that may need pythonfmu
    facades = [p for p in (REPO / "fmus" / unit).glob("*.py")
               if any(_within(n, ("pythonfmu", "fmus.fmi")) for n, _ in _imports(p))]
    assert [p.name for p in facades] == ["facade.py"]


def _import_graph():
    """Module → the product modules it imports (every import: at the top, inside functions,
    under TYPE_CHECKING; ``from package import name`` counts as importing the package and, where
    ``name`` is a module, that module)."""
    modules = {_module_name(path): path for path in _product_files()}
    graph = {}
    for module, path in modules.items():
        graph[module] = {name for name, _ in _imports(path) if name in modules and name != module}
    return graph


def _cycles(graph):
    """The strongly connected components of more than one module (Tarjan)."""
    index, low, on_stack, stack, found = {}, {}, set(), [], []

    def visit(node):
        index[node] = low[node] = len(index)
        stack.append(node)
        on_stack.add(node)
        for target in graph[node]:
            if target not in index:
                visit(target)
                low[node] = min(low[node], low[target])
            elif target in on_stack:
                low[node] = min(low[node], index[target])
        if low[node] == index[node]:
            component = []
            while True:
                member = stack.pop()
                on_stack.discard(member)
                component.append(member)
                if member == node:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for node in sorted(graph):
        if node not in index:
            visit(node)
    return found


def test_no_import_circle_in_the_product():
    """An import circle makes a module's meaning depend on import order and hides which layer
    is below which (docs/architecture.md, 'Layout'); none may come back."""
    assert _cycles(_import_graph()) == []


def test_a_run_without_filters_imports_no_filter_design_library():
    """python-control (with matplotlib) and scipy.signal/scipy.stats take about a second to
    import: a run whose components design no filter (ato_only) and the verdicts it is judged
    by load them not at all (fmus/dsp/filter_design.py; docs/performance.md#start-up-of-a-run)."""
    script = textwrap.dedent("""
        import sys, tempfile
        from pathlib import Path
        from orchestrator.verdicts.verdict import railway_verdicts
        from orchestrator.packaging.builder import default_build_dir
        from orchestrator.run import RunOptions, run_system
        with tempfile.TemporaryDirectory() as folder:
            summary = run_system(Path('ssp/ato_only'), RunOptions(
                summaries=railway_verdicts, stop_time=2.0, output_dir=Path(folder), in_process=True,
                fmu_dirs=[default_build_dir()])).summary
        assert summary['completed'] and summary['sim_time_s'] == 2.0, summary
        heavy = ('control', 'matplotlib', 'scipy.signal', 'scipy.stats')
        print(sorted(m for m in heavy if m in sys.modules))
    """)
    done = subprocess.run([sys.executable, "-c", script], cwd=REPO, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr[-3000:]
    assert done.stdout.strip().splitlines()[-1] == "[]"

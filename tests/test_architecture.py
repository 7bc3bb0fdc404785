"""The package walls of docs/architecture.md, checked on the source: who may import what,
and that the model cores, the data layer, the signalling library and the railway rooms
import with pythonfmu unavailable (a core runs in process without any FMI library)."""
import ast
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent
UNITS = ("wayside_coder", "rail_line", "loco_receiver", "traction", "ato_controller")
FMI_LIBRARIES = ("pythonfmu", "fmpy")


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


def _forbidden_for(module: str):
    """What a module may not import, by where it lives (docs/architecture.md, 'Import rules')."""
    parts = module.split(".")
    if module in ("fmus.errors", "fmus.sizes", "fmus.units"):
        return ("fmus", "orchestrator", "benchmarks", "numpy", "scipy", "control", *FMI_LIBRARIES), \
            {"fmus.errors", "fmus.sizes", "fmus.units"}
    if parts[0] == "fmus":
        if len(parts) > 1 and parts[1] == "fmi":
            return ("orchestrator", "benchmarks", "fmpy", *(f"fmus.{u}" for u in UNITS)), set()
        if len(parts) > 2 and parts[1] in UNITS and parts[2] == "facade":
            return ("orchestrator", "benchmarks", "fmpy"), set()
        if len(parts) > 1 and parts[1] in ("data", "signalling", "dsp"):
            return ("orchestrator", "benchmarks", "fmus.fmi", *FMI_LIBRARIES,
                    *(f"fmus.{u}" for u in UNITS)), set()
        # a unit's core and its parts, the package roots
        return ("orchestrator", "benchmarks", "fmus.fmi", *FMI_LIBRARIES,
                *(f"fmus.{u}.facade" for u in UNITS)), set()
    if parts[0] == "orchestrator":
        if len(parts) > 1 and parts[1] in (*RAILWAY_ROOMS, "conformance", "study", "headway"):   # railway knowledge on the engine
            return ("fmus.fmi", "pythonfmu", "benchmarks", "orchestrator.packaging", "orchestrator.cli"), set()
        if len(parts) > 1 and parts[1] in ("packaging", "cli", "__main__", "catalogue"):   # the front ends
            return ("benchmarks",), set()
        # the engine: FMU-agnostic, knows no railway
        return ("fmus", "pythonfmu", "benchmarks", *(f"orchestrator.{room}" for room in RAILWAY_ROOMS),
                "orchestrator.packaging", "orchestrator.cli"), set()
    return (), set()


def _product_files():
    for package in ("fmus", "orchestrator"):
        yield from sorted((REPO / package).rglob("*.py"))


def test_every_product_module_keeps_its_import_rules():
    broken = []
    for path in _product_files():
        module = _module_name(path)
        forbidden, allowed = _forbidden_for(module)
        for name, line in _imports(path):
            if name in allowed or name == module:
                continue
            if _within(name, forbidden):
                broken.append(f"{path.relative_to(REPO)}:{line} imports {name}")
    assert not broken, "import rules (docs/architecture.md) broken:\n" + "\n".join(broken)


def test_tests_and_the_harness_import_no_benchmark():
    """Tests rely on the product and on harness/, never on a benchmark; the harness serves both
    and imports neither (docs/architecture.md)."""
    broken = []
    for folder, forbidden in (("tests", ("benchmarks",)), ("harness", ("benchmarks", "tests", "conftest"))):
        for path in sorted((REPO / folder).rglob("*.py")):
            for name, line in _imports(path):
                if _within(name, forbidden):
                    broken.append(f"{path.relative_to(REPO)}:{line} imports {name}")
    assert not broken, "\n".join(broken)


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
    is below which (docs/architecture.md, 'Import rules'); none may come back."""
    assert _cycles(_import_graph()) == []


#: the engine: loading, graph, master, slaves, observers and what they share; it knows neither
#: the railway, nor DCP, nor studies or conformance
ENGINE = ("orchestrator.ssp", "orchestrator.graph", "orchestrator.master", "orchestrator.algorithms",
          "orchestrator.fmu", "orchestrator.observers", "orchestrator.protocols", "orchestrator.archives",
          "orchestrator.errors", "orchestrator.interrupts", "orchestrator.scenario", "orchestrator.pacing",
          "orchestrator.ports")


def test_the_engine_imports_no_dcp_railway_study_or_conformance():
    graph = _import_graph()
    above = ("orchestrator.dcp", *(f"orchestrator.{room}" for room in RAILWAY_ROOMS), "orchestrator.study",
             "orchestrator.conformance")
    offending = {module: sorted(name for name in graph[module] if _within(name, above)) for module in ENGINE}
    assert {m: names for m, names in offending.items() if names} == {}


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

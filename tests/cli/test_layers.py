"""The library's shape, checked from its source (issue 32): layers that point one way, no cycle, small modules and functions.

Layers, lowest first (``docs/layout.md``). A module may import only from its own layer or a lower one:

0. types: the run-log model, its time base and the errors every layer speaks (``runlog``, ``timebase``, ``errors``, ``parallel``,
   ``jit``, numba's loader every compiled loop goes through, and ``prefault``, memory for fresh arrays beside the loop filling them);
1. io: the readers and writers (``io/``), which fill a run log;
2. preparation: repairs and the usable rows (``quality``, ``prepare``);
3. vocabulary: parameters, effects, regressor, least squares, filtering, the LM solver, the rigid-body model;
4. estimators: IDIM-LS, IDIM-ILIC, IV, DIDIM, OE and the n-joint estimators. The closed-loop ones are handed the loop
   simulation as a function, so they import no plant;
5. simulation: the plant, its controllers, the replay of a log and the loop timing (``plant/``, ``ilic_cli/simulation/``),
   and the composition that binds estimators to the loop (``identify``, the method registry);
6. diagnosis: propose, decide, refit (``diagnosis/``);
7. reports: typed results rendered as Markdown, CSV, JSON and plots, and the fleet's tables and trends;
8. commands: the command line, the only place that speaks of flags.

``plant/`` imports no estimator and no I/O: the online ILIC update is handed to the loop as a function.

Each ``*_PENDING`` set lists what is still to mend; it may only shrink (a listed entry that no longer occurs fails too).
"""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
PACKAGES = ("ilic_cli", "plant")

LAYERS: tuple[tuple[str, tuple[str, ...]], ...] = (
    (
        "types",
        (
            "ilic_cli",
            "ilic_cli.errors",
            "ilic_cli.method_names",
            "ilic_cli.runlog",
            "ilic_cli.jointlog",
            "ilic_cli.timebase",
            "ilic_cli.parallel",
            "ilic_cli.jit",
            "ilic_cli.prefault",
        ),
    ),
    ("io", ("ilic_cli.io",)),
    ("preparation", ("ilic_cli.quality", "ilic_cli.prepare")),
    (
        "vocabulary",
        (
            "ilic_cli.parameters",
            "ilic_cli.plausible",
            "ilic_cli.effects",
            "ilic_cli.regressor",
            "ilic_cli.lsq",
            "ilic_cli.filtering",
            "ilic_cli.row_spans",
            "ilic_cli.derivatives",
            "ilic_cli.spectra",
            "ilic_cli.filter_design",
            "ilic_cli.lm",
            "ilic_cli.robot.model",
            "ilic_cli.robot.base",
            "ilic_cli.robot.kernel",
            "ilic_cli.robot.dynamics",
        ),
    ),
    (
        "estimators",
        (
            "ilic_cli.estimators",
            "ilic_cli.idim_ls",
            "ilic_cli.drive_lag",
            "ilic_cli.friction_shape",
            "ilic_cli.usable",
            "ilic_cli.idim_ilic",
            "ilic_cli.closed_loop_id",
            "ilic_cli.output_error",
            "ilic_cli.modelfile",
            "ilic_cli.robot.idim",
            "ilic_cli.robot.consistency",
            "ilic_cli.robot.ilic",
            "ilic_cli.robot.closed_loop",
        ),
    ),
    (
        "simulation",
        (
            "plant",
            "ilic_cli.simulation",
            "ilic_cli.identify",
            "ilic_cli.methods",
            "ilic_cli.robot.simulate",
            "ilic_cli.robot.loop",
            "ilic_cli.robot.plant",
            "ilic_cli.robot.scenario",
            "ilic_cli.robot.record",
            "ilic_cli.robot.replay",
        ),
    ),
    ("diagnosis", ("ilic_cli.diagnosis",)),
    (
        "reports",
        ("ilic_cli.reports", "ilic_cli.identify_report", "ilic_cli.diagnosis.report", "ilic_cli.diagnosis.plots", "ilic_cli.plotting", "ilic_cli.fleet"),
    ),
    ("commands", ("ilic_cli.commands", "ilic_cli.cli", "ilic_cli.__main__")),
)

MAX_MODULE_LINES = 500
MAX_FUNCTION_LINES = 100

# (importer, imported) pairs that point upward, or out of plant/ into an estimator or io
LAYER_PENDING: set[tuple[str, str]] = set()

CYCLE_PENDING: set[frozenset[str]] = set()

MODULE_PENDING: set[str] = set()

FUNCTION_PENDING: set[str] = set()

# in-function imports (file:module) without a comment, on the line or above it in its run of imports, that gives the reason for deferring
DEFERRED_PENDING: set[str] = set()


def _sources() -> dict[str, Path]:
    out: dict[str, Path] = {}
    for pkg in PACKAGES:
        for p in sorted((ROOT / pkg).rglob("*.py")):
            parts = list(p.relative_to(ROOT).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts = parts[:-1]
            out[".".join(parts)] = p
    return out


SOURCES = _sources()


def _layer(module: str) -> int:
    best = (-1, -1)
    for rank, (_, prefixes) in enumerate(LAYERS):
        for prefix in prefixes:
            covers = module == prefix or (prefix != "ilic_cli" and module.startswith(prefix + "."))  # the package's own __init__ only
            if covers and len(prefix) > best[1]:
                best = (rank, len(prefix))
    assert best[0] >= 0, f"{module} is in no layer: add it to LAYERS"
    return best[0]


def _resolve(name: str) -> str | None:
    parts = name.split(".")
    while parts and ".".join(parts) not in SOURCES:
        parts.pop()
    return ".".join(parts) if parts else None


def _imports(module: str) -> list[tuple[str, ast.stmt, bool]]:
    """(imported internal module, statement, inside a function) for every import of ``module``."""
    path = SOURCES[module]
    tree = ast.parse(path.read_text())
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    found: list[tuple[str, ast.stmt, bool]] = []

    def visit(node: ast.AST, nested: bool) -> None:
        for child in ast.iter_child_nodes(node):
            inner = nested or isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda))
            names: list[str] = []
            if isinstance(child, ast.Import):
                names = [a.name for a in child.names]
            elif isinstance(child, ast.ImportFrom):
                if child.level:
                    base = package.split(".")[: len(package.split(".")) - child.level + 1]
                    stem = ".".join([*base, *([child.module] if child.module else [])])
                else:
                    stem = child.module or ""
                names = [stem, *(f"{stem}.{a.name}" for a in child.names)]
            for name in names:
                target = _resolve(name) if name.split(".")[0] in PACKAGES else name
                if target is not None and target != module:
                    found.append((target, child, nested))  # type: ignore[arg-type]
            visit(child, inner)

    visit(tree, False)
    return found


def _internal_edges() -> set[tuple[str, str]]:
    return {(m, t) for m in SOURCES for t, _, _ in _imports(m) if t in SOURCES}


def test_layers_point_one_way() -> None:
    bad = set()
    for a, b in _internal_edges():
        upward = _layer(b) > _layer(a)
        plant_out = a.split(".")[0] == "plant" and (b.startswith("ilic_cli.io") or _layer(b) == 4)
        if upward or plant_out:
            bad.add((a, b))
    assert bad - LAYER_PENDING == set(), sorted(bad - LAYER_PENDING)
    assert LAYER_PENDING - bad == set(), f"mended, remove from LAYER_PENDING: {sorted(LAYER_PENDING - bad)}"


def test_no_import_cycle() -> None:
    edges = _internal_edges()
    graph: dict[str, set[str]] = {m: set() for m in SOURCES}
    for a, b in edges:
        graph[a].add(b)
    # strongly connected components (Tarjan), iterative enough for this tree's depth
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    comps: list[frozenset[str]] = []

    def strong(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                strong(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = set()
            while True:
                w = stack.pop()
                on.discard(w)
                comp.add(w)
                if w == v:
                    break
            if len(comp) > 1:
                comps.append(frozenset(comp))

    for v in sorted(graph):
        if v not in index:
            strong(v)
    found = set(comps)
    assert found - CYCLE_PENDING == set(), [sorted(c) for c in found - CYCLE_PENDING]
    assert CYCLE_PENDING - found == set(), "mended, remove from CYCLE_PENDING"


def test_modules_are_small() -> None:
    big = {str(p.relative_to(ROOT)) for p in SOURCES.values() if len(p.read_text().splitlines()) > MAX_MODULE_LINES}
    assert big - MODULE_PENDING == set(), sorted(big - MODULE_PENDING)
    assert MODULE_PENDING - big == set(), f"mended, remove from MODULE_PENDING: {sorted(MODULE_PENDING - big)}"


def test_functions_are_short() -> None:
    long = set()
    for p in SOURCES.values():
        for node in ast.walk(ast.parse(p.read_text())):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) and node.end_lineno is not None:
                if node.end_lineno - node.lineno + 1 > MAX_FUNCTION_LINES:
                    long.add(f"{p.relative_to(ROOT)}:{node.name}")
    assert long - FUNCTION_PENDING == set(), sorted(long - FUNCTION_PENDING)
    assert FUNCTION_PENDING - long == set(), f"mended, remove from FUNCTION_PENDING: {sorted(FUNCTION_PENDING - long)}"


def _stem(stmt: ast.stmt) -> str:
    """The module an import statement names (its first for ``import a, b``)."""
    if isinstance(stmt, ast.ImportFrom):
        return "." * stmt.level + (stmt.module or "")
    return stmt.names[0].name if isinstance(stmt, ast.Import) else ""


def _commented(lines: list[str], i: int) -> bool:
    """A comment on line ``i``, or above it within the run of import and comment lines it belongs to."""
    if "#" in lines[i]:
        return True
    j = i - 1
    while j >= 0:
        text = lines[j].strip()
        if text.startswith("#"):
            return True
        if not (text.startswith(("import ", "from ")) or text.endswith((",", "(")) or text == ")"):
            return False
        j -= 1
    return False


def test_deferred_imports_say_why() -> None:
    """An import inside a function defers a heavy library for start-up; a comment on its line or the line above says which and why."""
    silent = set()
    for module, path in SOURCES.items():
        lines = path.read_text().splitlines()
        for target, stmt, nested in _imports(module):
            if nested and not _commented(lines, stmt.lineno - 1):
                silent.add(f"{path.relative_to(ROOT)}:{_stem(stmt) or target}")
    assert silent - DEFERRED_PENDING == set(), sorted(silent - DEFERRED_PENDING)
    assert DEFERRED_PENDING - silent == set(), "mended, remove from DEFERRED_PENDING"

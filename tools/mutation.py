"""Mutation testing of the numerics (``make mutation``).

The mutants are mutmut's (2.x mutation operators: numbers, operators,
comparisons, keywords, strings, arguments, assignments, lambdas), less those
that only change a type annotation or a docstring (equivalent: neither runs
in these modules, which all use ``from __future__ import annotations``); the tests
are run here, not by ``mutmut run``, for two reasons:

- speed: ``mutmut run`` starts a fresh interpreter per mutant, which pays
  about 1 s of NumPy/SciPy/pytest imports each time (1300+ mutants on the
  numerics would not fit in 30 min on 2 cores). This driver imports the
  third-party libraries once, then forks one child per mutant; the child
  imports the project fresh (the mutated module served from memory by an
  import hook) and runs the module's targeted tests with ``pytest.main``.
- safety: no file of the work tree is ever rewritten, so an interrupted
  run leaves nothing mutated behind and other work can go on beside it.

Which tests cover which module, and the share of mutants sampled, are in
``[tool.ilic-mutation]`` of ``pyproject.toml``; so are the *planted* bugs
(``[[tool.ilic-mutation.planted]]``: hand-written mutants that mutmut's
operators do not produce, such as the bugs of issue 14), run after the
modules and scored on their own line. A mutant is *killed* when the
tests fail (or error, or exceed the time limit: ``timeouts`` counted apart),
*survived* when they pass. Survivors are written with their diff to
``out/mutation/<module>.txt``.

Usage::

    python tools/mutation.py                     # every configured module
    python tools/mutation.py ilic_cli/lsq.py     # one module
    python tools/mutation.py --sample 0.3        # a deterministic 30 % sample per module
    python tools/mutation.py --tests tests/identify/test_identify_sim.py ilic_cli/idim_ls.py   # other tests
    python tools/mutation.py --planted-only          # the hand-planted bugs only
"""

from __future__ import annotations

import os

# one BLAS thread per child: the machine is shared, and forked children must not oversubscribe it
for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import ast  # noqa: E402
import atexit  # noqa: E402
import difflib  # noqa: E402
import importlib.abc  # noqa: E402
import importlib.util  # noqa: E402
import random  # noqa: E402
import re  # noqa: E402
import shutil  # noqa: E402
import signal  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
import tomllib  # noqa: E402
from dataclasses import dataclass, field  # noqa: E402
from functools import cache  # noqa: E402
from pathlib import Path  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]

WARM_IMPORTS = ("numpy", "scipy.signal", "scipy.stats", "scipy.optimize", "scipy.ndimage", "scipy.io", "pandas", "pytest", "hypothesis")
"""Third-party modules imported once by the parent, so each forked child starts warm.

The project's own modules are never imported by the parent: each child
imports them afresh, with the mutant in place.
"""


@dataclass
class ModuleScore:
    """Outcome of the mutants of one module.

    Attributes
    ----------
    path : str
        Module path relative to the repository root.
    total : int
        Mutants run (after sampling).
    killed, timeouts : int
        Mutants whose tests failed, and those stopped at the time limit (counted as killed).
    survivors : list of str
        Diffs of the mutants the tests did not detect.
    seconds : float
        Wall time of the module.
    """

    path: str
    total: int = 0
    killed: int = 0
    timeouts: int = 0
    survivors: list[str] = field(default_factory=list)
    seconds: float = 0.0

    def record(self, outcome: str, survivor: str) -> None:
        """Count one mutant's ``outcome`` ("failed", "timeout" or "passed"); ``survivor`` describes it if it passed."""
        self.total += 1
        if outcome == "failed":
            self.killed += 1
        elif outcome == "timeout":
            self.timeouts += 1
        else:
            self.survivors.append(survivor)

    @property
    def score_pct(self) -> float:
        return 100.0 * (self.killed + self.timeouts) / self.total if self.total else float("nan")


class _MutantLoader(importlib.abc.SourceLoader):
    """Loads one module from a source string instead of its file (no bytecode cache)."""

    def __init__(self, path: str, source: str) -> None:
        self.path = path
        self.source = source

    def get_filename(self, fullname: str) -> str:
        return self.path

    def get_data(self, path: str) -> bytes:
        return self.source.encode()


class _MutantFinder(importlib.abc.MetaPathFinder):
    """Serves the mutated source for exactly one module name."""

    def __init__(self, name: str, path: str, source: str) -> None:
        self.name, self.path, self.source = name, path, source

    def find_spec(self, fullname, path=None, target=None):  # noqa: ANN001, ANN201
        if fullname != self.name:
            return None
        return importlib.util.spec_from_file_location(fullname, self.path, loader=_MutantLoader(self.path, self.source))


def module_name(path: str) -> str:
    """Dotted module name of a repository-relative ``.py`` path."""
    return path[:-3].replace("/", ".").removesuffix(".__init__")


def mutants(path: str) -> tuple[str, list[tuple[int, str]]]:
    """The original source and every mutant of ``path`` as ``(line number, mutated source)``.

    Parameters
    ----------
    path : str
        Module path relative to the repository root.
    """
    from mutmut import ALL, Context, mutate

    source = (ROOT / path).read_text()
    ctx = Context(source=source, filename=path, mutation_id=ALL)
    ids = list(dict.fromkeys(_list(ctx)))
    out = []
    plain = _behaviour(source)
    for mid in ids:
        mutated, n = mutate(Context(source=source, filename=path, mutation_id=mid))
        if n and _behaviour(mutated) != plain:  # a mutant of a type annotation or a docstring only is equivalent: left out
            out.append((mid.line_number + 1, mutated))
    return source, out


def _behaviour(source: str) -> str:
    """The module's AST without its type annotations and docstrings (neither runs: ``from __future__ import annotations``)."""
    import ast

    try:
        tree = ast.parse(source)
    except SyntaxError as exc:  # a mutant that does not parse is kept (the tests' import kills it)
        return f"syntax error: {exc}"
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            node.returns = None
        if isinstance(node, ast.arg):
            node.annotation = None
        if isinstance(node, ast.AnnAssign):
            node.annotation = ast.Constant(None)
        body = getattr(node, "body", None)
        if (
            isinstance(body, list)
            and body
            and isinstance(body[0], ast.Expr)
            and isinstance(body[0].value, ast.Constant)
            and isinstance(body[0].value.value, str)
        ):
            body[0] = ast.Pass()
    return ast.dump(tree)


def _list(ctx):  # noqa: ANN001, ANN202
    from mutmut import list_mutations

    return list_mutations(ctx)


@cache
def _frozen_names() -> dict[str, set[str]]:
    """Module name -> the names that modules numba compiles import from it: numba freezes their values into the machine code."""
    out: dict[str, set[str]] = {}
    for path in sorted([*ROOT.glob("ilic_cli/**/*.py"), *ROOT.glob("plant/**/*.py")]):
        text = path.read_text()
        if "@njit" in text:
            for node in ast.walk(ast.parse(text)):
                if isinstance(node, ast.ImportFrom) and node.module:
                    out.setdefault(node.module, set()).update(a.name for a in node.names)
    return out


def _reaches_compiled_code(name: str, path: str, source: str) -> bool:
    """Whether a mutant changes what numba compiles: a module with compiled functions, or a line that sets a name such a
    module imports. Such a mutant is run with a numba cache of its own: numba keys a cached function on its file and its
    own bytecode (not its callees', nor the globals it froze), so the run's cache would give the original machine code."""
    if "@njit" in source:
        return True
    names = _frozen_names().get(name)
    if not names:
        return False
    changed = [line[1:] for line in diff(path, (ROOT / path).read_text(), source).splitlines() if line.startswith("+") and not line.startswith("+++")]
    return any(names & set(re.findall(r"\w+", line.split("=", 1)[0])) for line in changed if "=" in line)  # an assignment's targets


def run_child(tests: list[str], timeout_s: float, mutant: tuple[str, str, str] | None) -> str:
    """Run ``tests`` in a forked child, with ``mutant`` ``(module name, path, source)`` imported instead of the file.

    Returns
    -------
    str
        ``"passed"``, ``"failed"`` or ``"timeout"``.
    """
    own_cache = tempfile.mkdtemp(prefix="ilic-mutant-numba-") if mutant is not None and _reaches_compiled_code(*mutant) else None
    pid = os.fork()
    if pid == 0:  # child
        try:
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, 1)
            os.dup2(devnull, 2)
            signal.signal(signal.SIGALRM, signal.SIG_DFL)
            signal.setitimer(signal.ITIMER_REAL, timeout_s)
            if own_cache is not None:
                os.environ["NUMBA_CACHE_DIR"] = own_cache  # read when the child first imports numba
            if mutant is not None:
                name, path, source = mutant
                sys.meta_path.insert(0, _MutantFinder(name, str(ROOT / path), source))
            import pytest

            code = pytest.main(["-x", "-q", "-p", "no:cacheprovider", "--no-header", "-o", "addopts=", *tests])
            os._exit(0 if code == 0 else 1)
        except BaseException:  # noqa: BLE001 - anything the mutant breaks is a detection
            os._exit(1)
    _, status = os.waitpid(pid, 0)
    if own_cache is not None:
        shutil.rmtree(own_cache, ignore_errors=True)
    if os.WIFSIGNALED(status) and os.WTERMSIG(status) == signal.SIGALRM:
        return "timeout"
    return "passed" if os.WIFEXITED(status) and os.WEXITSTATUS(status) == 0 else "failed"


def diff(path: str, original: str, mutated: str) -> str:
    """The changed lines of a mutant as a unified diff."""
    return "".join(difflib.unified_diff(original.splitlines(True), mutated.splitlines(True), f"a/{path}", f"b/{path}", n=0))


def run_module(path: str, tests: list[str], sample: float, seed: int, out_dir: Path | None, verbose: bool) -> ModuleScore:
    """Mutation score of one module against its targeted tests.

    Parameters
    ----------
    path : str
        Module path relative to the repository root.
    tests : list of str
        Test files (or node ids) run for every mutant.
    sample : float
        Share of the mutants run (deterministic for a ``seed``); 1 runs all.
    seed : int
        Seed of the sample.
    out_dir : Path or None
        Where to write the survivors' diffs.
    verbose : bool
        Print every mutant's outcome.
    """
    score = ModuleScore(path)
    start = time.perf_counter()
    t0 = time.perf_counter()
    if run_child(tests, 600.0, None) != "passed":
        raise SystemExit(f"mutation: the tests of {path} fail without any mutant: {' '.join(tests)}")
    baseline = time.perf_counter() - t0
    timeout_s = max(10.0, 5.0 * baseline)
    original, muts = mutants(path)
    if sample < 1.0:
        rng = random.Random(f"{seed}:{path}")
        muts = sorted(rng.sample(muts, max(1, round(sample * len(muts)))), key=lambda m: m[0])
    name = module_name(path)
    for line, mutated in muts:
        outcome = run_child(tests, timeout_s, (name, path, mutated))
        score.record(outcome, f"line {line}\n{diff(path, original, mutated)}" if outcome == "passed" else "")
        if verbose:
            print(f"  {path}:{line} {outcome}", flush=True)
    score.seconds = time.perf_counter() - start
    if out_dir is not None:
        out_dir.mkdir(parents=True, exist_ok=True)
        report = out_dir / (path.replace("/", "_") + ".txt")
        report.write_text(f"{path}: {len(score.survivors)} surviving of {score.total} (tests: {' '.join(tests)})\n\n" + "\n".join(score.survivors))
    return score


def run_planted(planted: list[dict], paths: list[str] | None) -> ModuleScore:
    """Run the hand-planted bugs (``old`` replaced by ``new`` in ``path``) against their ``tests``.

    Parameters
    ----------
    planted : list of dict
        Entries with ``path``, ``old``, ``new``, ``tests`` and ``why``.
    paths : list of str or None
        Only the entries on these modules (``None``: all).
    """
    score = ModuleScore("planted bugs")
    start = time.perf_counter()
    for bug in planted:
        if paths is not None and bug["path"] not in paths:
            continue
        module = ROOT / bug["path"]
        source = module.read_text() if module.is_file() else ""
        if source.count(bug["old"]) != 1:
            raise SystemExit(
                f"mutation: planted bug '{bug['why']}' no longer applies to {bug['path']} (its original text is gone); update [tool.ilic-mutation.planted]"
            )
        outcome = run_child(bug["tests"], 60.0, (module_name(bug["path"]), bug["path"], source.replace(bug["old"], bug["new"])))
        score.record(outcome, f"{bug['path']}: {bug['why']}")
        print(f"  planted: {bug['why']}: {'killed' if outcome != 'passed' else 'SURVIVED'}", flush=True)
    score.seconds = time.perf_counter() - start
    return score


def main(argv: list[str] | None = None) -> int:
    config = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["ilic-mutation"]
    modules: dict[str, dict] = config["modules"]
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("paths", nargs="*", help="modules to mutate (default: every module of [tool.ilic-mutation.modules])")
    ap.add_argument("--sample", type=float, help="share of each module's mutants to run (default: the module's configured share)")
    ap.add_argument("--seed", type=int, default=int(config.get("seed", 0)), help="seed of the sample")
    ap.add_argument("--tests", nargs="+", help="run these tests instead of the configured ones")
    ap.add_argument("--out", default=config.get("out", "out/mutation"), help="folder for the survivors' diffs")
    ap.add_argument("--show-survivors", action="store_true", help="print the surviving mutants")
    ap.add_argument("-v", "--verbose", action="store_true", help="print every mutant's outcome")
    ap.add_argument("--planted-only", action="store_true", help="run only the planted bugs (of the given modules)")
    args = ap.parse_args(argv)
    os.chdir(ROOT)
    # numba's machine code of this run in a folder of its own, not the tree's: a mutant may make numba compile a kernel
    # for other argument types, which the tree's cache index would keep (tests/unit/test_compiled_once.py reads it)
    run_cache = tempfile.mkdtemp(prefix="ilic-mutation-numba-")
    os.environ["NUMBA_CACHE_DIR"] = run_cache
    atexit.register(shutil.rmtree, run_cache, True)
    sys.path.insert(0, str(ROOT))
    for mod in WARM_IMPORTS:
        __import__(mod)
    paths = args.paths or list(modules)
    scores = []
    t_all = time.perf_counter()
    for path in [] if args.planted_only else paths:
        if path not in modules and not args.tests:
            raise SystemExit(f"mutation: {path} is not configured in [tool.ilic-mutation.modules]; pass --tests")
        cfg = modules.get(path, {})
        tests = args.tests or cfg["tests"]
        sample = args.sample if args.sample is not None else float(cfg.get("sample", 1.0))
        s = run_module(path, tests, sample, args.seed, Path(args.out), args.verbose)
        scores.append(s)
        sampled = "" if sample >= 1.0 else f", {sample:.0%} sample"
        print(f"{path}: killed {s.killed + s.timeouts} / {s.total} ({s.score_pct:.1f} %; {s.timeouts} by timeout{sampled}), {s.seconds:.0f} s", flush=True)
        if args.show_survivors:
            print("\n".join(s.survivors))
    planted = run_planted(config.get("planted", []), None if not args.paths else paths) if not args.tests else None
    if planted is not None and planted.total:
        print(f"planted bugs: killed {planted.killed + planted.timeouts} / {planted.total} ({planted.score_pct:.1f} %), {planted.seconds:.0f} s", flush=True)
    killed = sum(s.killed + s.timeouts for s in scores)
    total = sum(s.total for s in scores)
    print(f"total: killed {killed} / {total} ({100.0 * killed / max(total, 1):.1f} %), {time.perf_counter() - t_all:.0f} s; survivors in {args.out}/")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

# make demo: simulate the paper's scenario, identify it, write a report and plots under out/demo/
# make test: run the test suite (the command CI runs)
# make test-fast: the unit, vocabulary and I/O tiers (the inner loop)
# make bench: print speed ratios (benchmarks/)
# make mutation: mutation score of the numerics, per module, and the planted bugs of issue 14 (not part of make test; about 16 min on 2 cores)
PYTHON ?= $(shell command -v python3.11 || command -v python3)
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: demo test test-fast bench bench-large corpus mutation clean

# pip itself first brought to a current release (best effort: the one venv bundles is kept when none can be had): the
# packages install in 17-23 s with pip 26 against 30-37 s with Python 3.11's bundled pip 23.2 (the same versions resolved);
# the packages' bytecode compiled on every core, their own test suites left out: pip compiles one file at a time
# (a fresh venv 46 s -> 34 s on 2 cores); the bytecode is needed, a PYTHONDONTWRITEBYTECODE=1 process compiles its imports anew.
# Not compiled: the installers and mypy's compiler, which no command or test imports (pip, setuptools, mypyc: 720 of 4,600
# modules; 12.3 s -> 11.2 s on 2 cores); fontTools and pygments are imported (matplotlib's PNGs, pytest's report).
# Measured, not kept: no compileall, the tests writing the bytecode of what they import (2,600 of the 4,470 files): the
# compile saves 9.3 s, and the suite then took 272 s against 248 s (8 min 40 s of CPU against 8 min 6 s; both workers
# compile the same imports at their start), 2026-12-07
$(STAMP): pyproject.toml
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade 'pip>=25' || echo "make: pip not upgraded; installing with $$($(BIN)/python -m pip --version)"
	$(BIN)/python -m pip install --quiet --no-compile -e '.[test]'
	$(BIN)/python -m compileall -q -j 0 -x '/tests?/|site-packages/(pip|setuptools|mypyc)/' $(VENV)/lib
	touch $(STAMP)

demo: $(STAMP)
	mkdir -p out/demo
	$(BIN)/ilic simulate --scenario paper-sim --duration 31 --seed 1 -o out/demo/paper-sim.mcap
	$(BIN)/ilic info out/demo/paper-sim.mcap
	$(BIN)/ilic identify out/demo/paper-sim.mcap --out out/demo
	@echo "demo: report and plots in out/demo/"

# the suite in TEST_WORKERS processes (pytest-xdist; CI has 2 cores): a clean clone 231 s in two with one BLAS thread each (2-core machine, 2026-12-06), BLAS threads on top oversubscribed the cores (332 s against 268 s then)
TEST_WORKERS ?= 2

# --dist worksteal: a worker that runs out takes half of the other's queue. Measured and not kept, --dist loadfile (each module
# whole in one worker): worksteal already computes all but 6 of the 58 module and session fixtures once (0.5 s of CPU twice),
# and paired clean clones took 289 s both ways (2026-12-07; unpaired runs of either ranged 240-290 s in one afternoon)
TEST_DIST := --dist worksteal

# one BLAS thread a worker: the TEST_WORKERS processes already share the cores (BLAS's own threads on top oversubscribed them).
# ilic's own threads (ILIC_THREADS, the folds' replays) are left as a user has them: measured, one a worker saved nothing
# (218 s and 7 min 0 s of CPU against 221 s and 7 min 3 s, back to back, 2026-12-07).
# Bytecode written (PYTHONDONTWRITEBYTECODE emptied where the environment sets it): the `ilic` processes the tests start load
# the tree's modules compiled once, not each anew, and pytest keeps its assertion-rewritten test modules
TEST_ENV := OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1 MKL_NUM_THREADS=1 PYTHONDONTWRITEBYTECODE=

# the tests' CPU time, steadier than wall time under other load (yet 10 % apart between hours here): make test PYTEST_ARGS="-p tests.cpu_durations --cpu-durations=30"
PYTEST_ARGS ?=

test: $(STAMP)
	$(TEST_ENV) $(BIN)/python -m pytest -q -n $(TEST_WORKERS) $(TEST_DIST) $(PYTEST_ARGS)

# the tiers without closed-loop diagnoses or long simulations
FAST_TESTS := tests/unit tests/vocabulary tests/io

test-fast: $(STAMP)
	$(TEST_ENV) $(BIN)/python -m pytest -q -n $(TEST_WORKERS) $(TEST_DIST) $(FAST_TESTS)

bench: $(STAMP)
	$(BIN)/python benchmarks/run_all.py

bench-large: $(STAMP)
	$(BIN)/python benchmarks/run_all.py --large

# the robot corpus of issue 29 (not part of make test; docs/diagnosis.md): every case measured, exit 1 when a rate of its "Done when" fails
corpus: $(STAMP)
	$(TEST_ENV) $(BIN)/python benchmarks/corpus_robot.py --jobs $(TEST_WORKERS) --check

# Mutation testing (issue 14). Tool: mutmut 2.x, for its mutation operators only.
# mutmut 3 (3.8.1 installable here; not adopted) copies the tree into mutants/,
# mutates only function bodies and chooses the tests itself: no per-module test
# command. cosmic-ray (8.7.0) needs a session database and a config per module
# for the same kind of operators. tools/mutation.py takes mutmut's mutants and
# runs each module's targeted unit tests ([tool.ilic-mutation] in pyproject.toml)
# in forked children of one warm interpreter: no file of the tree is rewritten,
# and a mutant costs ~0.3 s instead of ~1.5 s of interpreter start and imports.
# Prints killed / total (%) per module; survivors' diffs in out/mutation/.
MUTATION_ARGS ?=
mutation: $(STAMP)
	$(BIN)/python -m pip install --quiet -e '.[mutation]'
	$(BIN)/python tools/mutation.py $(MUTATION_ARGS)

clean:
	rm -rf $(VENV) out build *.egg-info

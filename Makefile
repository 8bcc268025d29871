# make demo: simulate the paper's scenario, identify it, write a report and plots under out/demo/
# make test: run the test suite (the command CI runs)
# make bench: print speed ratios (benchmarks/)
PYTHON ?= $(shell command -v python3.11 || command -v python3)
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: demo test bench bench-large clean

$(STAMP): pyproject.toml
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet -e '.[test]'
	touch $(STAMP)

demo: $(STAMP)
	mkdir -p out/demo
	$(BIN)/ilic simulate --scenario paper-sim --duration 31 --seed 1 -o out/demo/paper-sim.mcap
	$(BIN)/ilic info out/demo/paper-sim.mcap
	$(BIN)/ilic identify out/demo/paper-sim.mcap --out out/demo
	@echo "demo: report and plots in out/demo/"

test: $(STAMP)
	$(BIN)/python -m pytest -q

bench: $(STAMP)
	$(BIN)/python benchmarks/run_all.py

bench-large: $(STAMP)
	$(BIN)/python benchmarks/run_all.py --large

clean:
	rm -rf $(VENV) out build *.egg-info

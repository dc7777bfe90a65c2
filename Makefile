# Two commands on a fresh machine: `make demo` and `make test`. Each creates .venv itself.
# The demo installs surge without torch (the predictor and RL extras); the tests install everything.
PYTHON ?= python3
VENV ?= .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
DEMO_STAMP := $(VENV)/.installed-demo

.PHONY: demo test bench clean

$(DEMO_STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q -e .
	touch $(DEMO_STAMP)

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q torch==2.13.0
	$(PY) -m pip install -q -e '.[test,rl,cluster,predictor,watch]'
	touch $(STAMP) $(DEMO_STAMP)

demo: $(DEMO_STAMP)
	$(VENV)/bin/surge demo

test: $(STAMP)
	$(PY) -m pytest -q

bench: $(STAMP)
	mkdir -p bench-results
	$(VENV)/bin/surge bench city --data ../shared/data --json bench-results/city.json
	$(VENV)/bin/surge bench sim --json bench-results/sim.json
	$(VENV)/bin/surge bench plan --scenario nyc --data ../shared/data --taxis 100 --steps 5 --policies surge surge:base=greedy,scope=local,horizon=10,samples=1000,cap=24,adaptive=2 garces2023 --forecast true-rate --json bench-results/plan.json

clean:
	rm -rf $(VENV) bench-results

# Two commands on a fresh machine: `make demo` and `make test`. Each creates .venv itself.
PYTHON ?= python3
VENV ?= .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed

.PHONY: demo test bench clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q torch==2.13.0
	$(PY) -m pip install -q -e '.[test,rl,cluster,watch]'
	touch $(STAMP)

demo: $(STAMP)
	$(VENV)/bin/surge demo

test: $(STAMP)
	$(PY) -m pytest -q

bench: $(STAMP)
	mkdir -p bench-results
	$(VENV)/bin/surge bench city --data ../shared/data --json bench-results/city.json
	$(VENV)/bin/surge bench sim --json bench-results/sim.json
	$(VENV)/bin/surge bench plan --scenario nyc --data ../shared/data --taxis 100 --horizon 10 --samples 1000 --steps 5 --policies surge surge:adaptive=none,cap=none garces2023 --forecast true-rate --json bench-results/plan.json

clean:
	rm -rf $(VENV) bench-results

# Every target works on a fresh clone: it creates .venv and installs into it if needed.
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed

.PHONY: setup test bench discover-bench lint demo

$(STAMP): pyproject.toml
	python3 -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	# torch first, pinned: this spec resolves to the CPU wheel on these machines.
	$(PY) -m pip install --quiet torch==2.13.0
	$(PY) -m pip install --quiet -e ".[dev]"
	touch $(STAMP)

setup: $(STAMP)

test: $(STAMP)
	# one worker a core, a test file a worker (its module fixtures are built once), files in the order
	# tests/conftest.py collects them (the heaviest first)
	$(PY) -m pytest -q -n auto --dist loadfile --no-loadscope-reorder

bench: $(STAMP)
	$(PY) -m bench.train_bench
	$(PY) -m bench.map_bench
	$(PY) bench/pgd_bench.py
	$(PY) -m bench.device_bench
	$(PY) -m bench.suite_bench

discover-bench: $(STAMP)
	$(PY) -m bench.discover_bench
	$(PY) -m bench.contact_bench
	$(PY) -m bench.levels_bench

lint: $(STAMP)
	$(VENV)/bin/ruff check ptwin tests bench train.py
	$(VENV)/bin/ruff format --check ptwin tests bench train.py

demo: $(STAMP)
	$(PY) train.py

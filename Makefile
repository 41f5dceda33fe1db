# Two commands on a fresh machine: `make run` (the main job on the built-in default) and `make test`.
# Both build the environment first when it is missing.
PYTHON ?= python3.11
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed

.PHONY: run test env bench clean

$(STAMP): pyproject.toml
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q -e '.[test]'
	touch $(STAMP)

env: $(STAMP)

run: env
	$(VENV)/bin/farm trees --out out/trees

test: env
	$(PY) -m pytest -q

bench: env
	$(PY) benchmarks/bench_weber_penn.py

clean:
	rm -rf $(VENV) out

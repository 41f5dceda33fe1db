# Two commands on a fresh machine: `make run` (the main job on the built-in default) and `make test`.
# Both build the environment first when it is missing.
PYTHON ?= python3.11
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed

.PHONY: run test env blender-env node-env browser-env bench golden models clean

$(STAMP): pyproject.toml
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q -e '.[test]'
	touch $(STAMP)

# Blender (bpy) pins numpy<2, so its worker runs in a venv of its own (renderers/blender_worker/).
BLENDER_VENV := .venv-blender
BLENDER_STAMP := $(BLENDER_VENV)/.installed

$(BLENDER_STAMP): renderers/blender_worker/requirements.txt
	test -x $(BLENDER_VENV)/bin/python || $(PYTHON) -m venv $(BLENDER_VENV)
	$(BLENDER_VENV)/bin/python -m pip install -q -r renderers/blender_worker/requirements.txt
	touch $(BLENDER_STAMP)

blender-env: $(BLENDER_STAMP)

# The Khronos glTF validator (npm gltf-validator, pinned by package-lock.json) checks the GLBs tests write;
# without npm the env still builds and those tests skip.
NODE_STAMP := node_modules/.installed

$(NODE_STAMP): package.json package-lock.json
	if command -v npm >/dev/null; then npm ci --no-audit --no-fund && touch $(NODE_STAMP); \
	else echo "npm not found: glTF validator tests will be skipped (apt-get install nodejs npm)"; fi

node-env: $(NODE_STAMP)

# Debian's Chromium drives the review client's browser tests (playwright's own browser download cannot run here).
browser-env:
	command -v chromium >/dev/null || (apt-get update -q && apt-get install -y -q chromium)

env: $(STAMP) blender-env node-env browser-env

run: env
	$(VENV)/bin/farm generate --out out/dataset

# Two pytest workers, a test file each at a time: the suite waits on Ray start-ups, Blender and subprocesses
# for much of its time, and one core sat idle then (docs/performance.md, "Measurements behind choices").
test: env
	$(PY) -m pytest -q -n 2 --dist loadfile

# Rewrites tests/golden/*.json from the current code; a commit that changes outputs on purpose runs this.
golden: env
	$(PY) tests/golden/goldens.py

# The headline benchmarks on short settings (a few minutes on 2 cores), then docs/performance.md from their results.
bench: env
	$(PY) -m benchmarks.headline

# The default models shipped in models/: the shipped data specs generated (once) into out/train-full, each
# network trained on benchmarks.bench_train's budget recipe (each task's `recipe` in trainers/tasks.py: fixed
# epochs, seed 0; no time limit, so the same steps on any machine), exported as model folders. The tasks are read from the
# registry when the target runs (`=`, not `:=`: other targets do not start Python for it).
TRAIN_TASKS = $(shell $(PY) -c 'from trainers.tasks import TASKS; print(*TASKS)')
models: env
	mkdir -p out/train-full
	for task in $(TRAIN_TASKS); do test -f out/train-full/$$task/manifest.json || { \
		$(VENV)/bin/farm train $$task --print-data-spec > out/train-full/$$task.yaml && \
		$(VENV)/bin/farm generate out/train-full/$$task.yaml --out out/train-full/$$task --quiet; } || exit 1; done
	$(PY) -m benchmarks.bench_train --data-root out/train-full --skip-throughput --budget 0 --export-models models

clean:
	rm -rf $(VENV) $(BLENDER_VENV) node_modules out

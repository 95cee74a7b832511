# Two commands do all the set-up on a fresh machine (Python 3.11 with venv):
#   make demo   - create .venv if needed, install what the demo needs, run the paper scenario, say where the outputs are
#   make test   - same set-up plus the test extras (pytest, hypothesis, ray), the gpu extra (mujoco-warp,
#                 warp-lang: the batch engine's tests run on Warp's CPU device), the docs extra (MkDocs) and the
#                 ros extra (rosbags: the --rosbag tests),
#                 run the test suite (the tests marked slow excepted) and build the documentation with warnings as errors
#   make test-slow - the tests marked slow (CI runs them after make test)
#   make test-train - the train extra (torch, SB3, SuperSuit) and the tests that train with it (CI runs them too)
#   make docs   - build the documentation site into site/ (needs the docs extra)
#   make docs-commands - run every shell block of README.md and docs/ as written, each page in a fresh copy of
#                 the repository (tests/test_docs_commands.py; tens of minutes, not part of make test)
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
TEST_STAMP := $(VENV)/.installed-test
TRAIN_STAMP := $(VENV)/.installed-train

.PHONY: demo test test-slow test-train lint bench install clean docs docs-commands

$(PY):
	$(PYTHON) -m venv $(VENV)

# the package and its runtime dependencies only (no pytest, ray, pyarrow: the demo needs none); --no-compile:
# Python byte-compiles a module when it is first imported, so pip need not compile every module of every
# dependency ahead (42 -> 22 s of CPU for this install; the demo's first run then costs no measurable more)
$(STAMP): pyproject.toml | $(PY)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet --no-compile -e .
	touch $(STAMP)

# the test extras on top, the gpu extra (the batch engine's tests run on Warp's CPU device, no GPU needed)
# and the docs extra (make test builds the documentation strictly)
$(TEST_STAMP): $(STAMP) pyproject.toml
	$(PY) -m pip install --quiet -e '.[test,gpu,rl,urdf,docs,ros]'
	touch $(TEST_STAMP)

install: $(STAMP)

demo: $(STAMP)
	MUJOCO_GL=$${MUJOCO_GL:-egl} $(VENV)/bin/bioform run paper --plant mujoco --out runs/demo --overwrite --video --rrd --figures
	@echo "demo outputs: runs/demo/ (summary.json, log.npz, scene.xml, video.mp4, run.rrd, figures/)"

# numpy's AVX-512 paths, where this CPU has them: the equivalence tests run again without them,
# so both numpy code paths are compared with the compiled equations wherever the suite runs
NPY_AVX512 = $(PY) -c "from numpy._core._multiarray_umath import __cpu_features__ as f; \
	print(' '.join(k for k in ('AVX512F','AVX512CD','AVX512_SKX','AVX512_CLX','AVX512_CNL','AVX512_ICL','AVX512_SPR','X86_V4') if f.get(k)))"

# the suite in TEST_WORKERS processes (pytest-xdist; 2 = this project's 2-core reference machine; 0: one
# process); Ray's tests stay on one worker (tests/conftest.py)
TEST_WORKERS ?= 2
XDIST = $(if $(filter 0,$(TEST_WORKERS)),,-n $(TEST_WORKERS) --dist loadgroup)

test: $(TEST_STAMP)
	$(PY) -c "import warp, mujoco_warp" || { echo "error: the gpu extra is missing from $(VENV): rm $(TEST_STAMP) and run make test again" >&2; exit 2; }
	$(PY) -c "import pettingzoo, gymnasium" || { echo "error: the rl extra is missing from $(VENV): rm $(TEST_STAMP) and run make test again" >&2; exit 2; }
	$(VENV)/bin/ruff check src tests scripts examples docs/tutorials
	$(VENV)/bin/ruff format --check src tests scripts examples docs/tutorials
	$(PY) -m pytest -q -m "not slow and not train" $(XDIST)
	NPY_DISABLE_CPU_FEATURES="$$($(NPY_AVX512))" $(PY) -m pytest -q -m equivalence -p no:cacheprovider $(XDIST)
	$(MKDOCS) build --strict

# MkDocs' notice about its own future is not a warning about these docs
MKDOCS := NO_MKDOCS_2_WARNING=1 DISABLE_MKDOCS_2_WARNING=true $(VENV)/bin/mkdocs

# the site into site/ (offline: no plugin fetches anything); strict: a broken link or stale reference fails
docs: $(STAMP)
	@$(PY) -c "import mkdocs, material, mkdocstrings, mkdocstrings_handlers.python, mkdocs_gen_files" 2>/dev/null || \
		{ echo "error: the docs extra is missing from $(VENV): install it with $(PY) -m pip install -e '.[docs]'" >&2; exit 2; }
	$(MKDOCS) build --strict
	@echo "documentation: site/index.html (open it from disk; without a network for search: python -m http.server -d site)"

docs-commands: $(TEST_STAMP)
	BIOFORM_DOCS_COMMANDS=1 $(PY) -m pytest -q -p no:cacheprovider tests/test_docs_commands.py -k "run_as_written or reading_order"

lint: $(TEST_STAMP)
	$(VENV)/bin/ruff check --fix src tests scripts examples docs/tutorials
	$(VENV)/bin/ruff format src tests scripts examples docs/tutorials

# the checks marked slow (long closed-loop runs, 60 s recordings fitted, a Ray head killed mid-sweep): CI runs
# them after make test (.ci/run); make test keeps to the fast set (under 10 minutes on the 2-core reference machine)
test-slow: $(TEST_STAMP)
	$(PY) -m pytest -q -m slow -p no:cacheprovider $(XDIST)

# the train and marl extras on top (torch 2.13.0, Stable-Baselines3, SuperSuit; TorchRL 0.11.1, tensordict 0.11.0,
# BenchMARL 1.5.2: one set that installs together; about 2 minutes to install from a wheel on disk, much longer
# where torch is downloaded), then the tests that train (SuperSuit + SB3 SubprocVecEnv on the MuJoCo plant, TorchRL's
# wrapper, the BenchMARL example); CI runs them after make test-slow (.ci/run)
$(TRAIN_STAMP): $(TEST_STAMP) pyproject.toml
	$(PY) -m pip install --quiet -e '.[test,gpu,rl,urdf,docs,ros,train,marl]'
	touch $(TRAIN_STAMP)

test-train: $(TRAIN_STAMP)
	$(PY) -m pytest -q -m train -p no:cacheprovider -n 0

bench: $(STAMP)
	$(PY) scripts/bench_control_step.py
	$(VENV)/bin/bioform bench --json runs/bench.json

clean:
	rm -rf $(VENV) runs .pytest_cache site

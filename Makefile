# Two commands do all the set-up on a fresh machine (Python 3.11 with venv):
#   make demo   - create .venv if needed, install, run the paper scenario, say where the outputs are
#   make test   - same set-up, run the test suite
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed

.PHONY: demo test test-fast bench install clean

$(PY):
	$(PYTHON) -m venv $(VENV)

$(STAMP): pyproject.toml | $(PY)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[test]'
	touch $(STAMP)

install: $(STAMP)

demo: $(STAMP)
	MUJOCO_GL=$${MUJOCO_GL:-egl} $(VENV)/bin/bioform run paper --plant mujoco --out runs/demo --video --rrd --figures
	@echo "demo outputs: runs/demo/ (summary.json, log.npz, scene.xml, video.mp4, run.rrd, figures/)"

# numpy's AVX-512 paths, where this CPU has them: the equivalence tests run again without them,
# so both numpy code paths are compared with the compiled equations wherever the suite runs
NPY_AVX512 = $(PY) -c "from numpy._core._multiarray_umath import __cpu_features__ as f; \
	print(' '.join(k for k in ('AVX512F','AVX512CD','AVX512_SKX','AVX512_CLX','AVX512_CNL','AVX512_ICL','AVX512_SPR','X86_V4') if f.get(k)))"

test: $(STAMP)
	$(PY) -m pytest -q
	NPY_DISABLE_CPU_FEATURES="$$($(NPY_AVX512))" $(PY) -m pytest -q -m equivalence -p no:cacheprovider

test-fast: $(STAMP)
	$(PY) -m pytest -q -m "not slow"

bench: $(STAMP)
	$(PY) scripts/bench_control_step.py
	$(VENV)/bin/bioform bench --json runs/bench.json

clean:
	rm -rf $(VENV) runs .pytest_cache

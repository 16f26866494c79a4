# scan2morph: `make run` and `make test` set everything up first (idempotent), then do their job.
SHELL := /bin/bash
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
CORES ?= 2
# Debian packages: libusb for open3d, EGL/OSMesa for headless rendering, chromium for the report test,
# the X client libraries Blender's bpy module links (tests/unit/test_blender.py).
DEB_PACKAGES := libusb-1.0-0 libegl1 libosmesa6 libgl1 libglib2.0-0 libgomp1 chromium slurm-wlm munge \
  libx11-6 libxext6 libxfixes3 libxi6 libxrender1 libxkbcommon0 libsm6
STAMP := $(VENV)/.setup-stamp
# The Khronos glTF validator (npm; tests/unit/test_gltf_viewer.py), installed with `npm ci` from the
# committed lock. node and npm come from Debian (nodejs npm) only when npm is absent: a NodeSource
# nodejs bundles npm and conflicts with Debian's npm package.
NODE_DEB_PACKAGES := nodejs npm
VALIDATOR := tools/gltf-validator
VALIDATOR_STAMP := $(VALIDATOR)/node_modules/.ci-stamp
DEB_STAMP := $(VENV)/.deb-stamp
# Blender as a Python module (tests/unit/test_blender.py imports the outputs with Blender's own
# importers): bpy pins Python 3.11 and numpy < 2, so it has a virtualenv of its own. The stamp
# names the version, so that changing BPY_VERSION reinstalls. The pipeline does not need it: on a
# machine without BLENDER_PYTHON (Debian 13, Ubuntu 24.04) setup goes on without it, saying so,
# and that test skips; under CI (CI set) setup stops, as the test would fail.
BLENDER_PYTHON ?= python3.11
BLENDER_VENV := .venv-blender
BPY_VERSION := 5.0.1
BLENDER_STAMP := $(BLENDER_VENV)/.bpy-$(BPY_VERSION)-stamp
export PYOPENGL_PLATFORM ?= osmesa
# Python caches compiled modules, and pytest its rewritten test modules, in __pycache__: an
# environment that turns this off (PYTHONDONTWRITEBYTECODE=1, as some containers do) would
# compile every module again in every pipeline job and every test worker (test-fast: about
# 2.5 s a worker).
unexport PYTHONDONTWRITEBYTECODE

.PHONY: setup run test test-fast bench lint dry-run clean detector

setup: $(STAMP) $(BLENDER_STAMP)
setup: $(VALIDATOR_STAMP)
	@[ tools/viewer/node_modules/.package-lock.json -nt tools/viewer/package-lock.json ] || (cd tools/viewer && npm ci --no-audit --no-fund --loglevel=error)
	@[ tools/viewer/dist/viewer.js -nt src/scan2morph/report/viewer/viewer.js ] && [ tools/viewer/dist/viewer.js -nt tools/viewer/node_modules/.package-lock.json ] || (cd tools/viewer && npm run --silent build)

$(DEB_STAMP):
	@missing=""; for p in $(DEB_PACKAGES); do dpkg -s $$p >/dev/null 2>&1 || missing="$$missing $$p"; done; \
	if [ -n "$$missing" ]; then \
	  echo "installing Debian packages:$$missing"; \
	  if [ "$$(id -u)" = 0 ]; then SUDO=""; else SUDO="sudo"; fi; \
	  $$SUDO apt-get update -qq && DEBIAN_FRONTEND=noninteractive $$SUDO apt-get install -y -qq $$missing; \
	fi
	@mkdir -p $(VENV) && touch $@

# The lock is the complete resolved set, installed with --no-deps so that its PyOpenGL 3.1.10
# overrides pyrender's stale PyOpenGL==3.1.0 pin (3.1.0 cannot open a headless context).
$(STAMP): requirements.lock pyproject.toml | $(DEB_STAMP)
	@test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install -q --upgrade pip
	$(BIN)/python -m pip install -q --no-deps -r requirements.lock
	$(BIN)/python -m pip install -q --no-deps --no-build-isolation -e .
	$(BIN)/python -m compileall -q src
	@# pytest's rewritten test modules, cached once here: else the first test run rewrites
	@# and compiles every one in every worker (about 2.2 s a worker)
	$(BIN)/python -m pytest --collect-only -q -p no:cacheprovider > /dev/null
	@touch $@

$(BLENDER_STAMP): | $(DEB_STAMP)
	@if [ -z "$$CI" ] && [ ! -x $(BLENDER_VENV)/bin/python ] && ! command -v $(BLENDER_PYTHON) >/dev/null; then \
	  echo "$(BLENDER_PYTHON) not found: Blender's bpy not installed (tests/unit/test_blender.py skips; BLENDER_PYTHON=... names another Python 3.11)"; \
	else \
	  (test -x $(BLENDER_VENV)/bin/python || $(BLENDER_PYTHON) -m venv $(BLENDER_VENV)) && \
	  $(BLENDER_VENV)/bin/python -m pip install -q --upgrade pip && \
	  $(BLENDER_VENV)/bin/python -m pip install -q "bpy==$(BPY_VERSION)" && touch $@; \
	fi

$(VALIDATOR_STAMP): $(VALIDATOR)/package.json $(VALIDATOR)/package-lock.json | $(DEB_STAMP)
	@command -v npm >/dev/null 2>&1 || { \
	  echo "installing Debian packages: $(NODE_DEB_PACKAGES)"; \
	  if [ "$$(id -u)" = 0 ]; then SUDO=""; else SUDO="sudo"; fi; \
	  $$SUDO apt-get update -qq && DEBIAN_FRONTEND=noninteractive $$SUDO apt-get install -y -qq $(NODE_DEB_PACKAGES); }
	cd $(VALIDATOR) && npm ci --no-audit --no-fund --loglevel=error
	@touch $@

# `make run CONFIG=my.yaml`: your own config file on top of config/config.yaml (its keys win).
# a CONFIG that is missing, not YAML or gives a key twice: one line naming it (tools/check_config.py;
# Snakemake meets the first two before the workflow loads, the workflow checks the third again)
run: setup
	$(if $(CONFIG),@$(BIN)/python tools/check_config.py $(CONFIG))
	$(BIN)/snakemake --cores $(CORES) --keep-going --rerun-incomplete $(if $(CONFIG),--configfile $(CONFIG))

dry-run: setup
	$(if $(CONFIG),@$(BIN)/python tools/check_config.py $(CONFIG))
	$(BIN)/snakemake -n $(if $(CONFIG),--configfile $(CONFIG))

test: setup
	$(BIN)/python -m pytest -q --durations=15

# every test that runs no workflow (no Snakemake DAG, no SLURM): for quick checks while working;
# one pytest-xdist worker per core, each with one BLAS/OpenMP/OpenCV thread; glibc's malloc keeps
# freed blocks of up to 512 MB for reuse instead of unmapping them (a worker's large temporary
# arrays were mapped and zeroed anew each time: about 2% of the run, in system time)
test-fast: setup
	OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 OPENCV_FOR_THREADS_NUM=1 \
	MALLOC_MMAP_THRESHOLD_=536870912 MALLOC_TRIM_THRESHOLD_=1073741824 $(BIN)/python -m pytest -q -m "not slow" -n $(CORES) --dist loadscope --durations=10

# The landmark detector's weights (src/scan2morph/landmarks/model.npz, committed package data, so
# setup downloads nothing): retrained from the project's own synthetic heads, identical for the
# same seed (docs/landmarks.md), on one BLAS thread (more threads change the fit's last bits).
DETECTOR_SEED ?= 1
detector: setup
	OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 $(BIN)/python -m scan2morph.landmarks.train --seed $(DETECTOR_SEED) --out src/scan2morph/landmarks/model.npz

# Every benchmark's cheapest documented run, on the finished default run in results/ (make run
# first): a smoke run that none of them has rotted (none is run by the tests), about 5 minutes on
# two cores. The measurements themselves take each script's own options (its docstring); left
# out here as too long or not self-contained: bench_landmarks.py (4 minutes), bench_motion_noise.py
# without --stage (7), bench_noise_estimators.py without --paired (minutes a realisation),
# bench_subject_jobs.py (two source trees) and bench_facemesh.py (a model to download by hand).
BENCH_QUICK = \
	"bench_align.py --subjects 1" \
	"bench_align_still.py --run . synth04" \
	"bench_consensus.py . synth02" \
	"bench_depth_fusion.py --frames 1 2 --takes neutral" \
	"bench_error_regions.py" \
	"bench_fit.py" \
	"bench_lighting.py --exposures dark_smile" \
	"bench_mesh_camera.py" \
	"bench_modal.py --dofs 6000 --ks 10 --methods block arpack" \
	"bench_modal.py --reconstruction . synth01 --config config/config.yaml" \
	"bench_modal_span.py . --tune synth01 --configs skin" \
	"bench_motion_noise.py --stage . --repeat 1 synth04" \
	"bench_noise_estimators.py --paired --run . --draws 2 synth04" \
	"bench_profile.py --width 160 --height 120 --dag-subjects 2" \
	"bench_real_user.py" \
	"bench_refine.py --workdir . --subject synth04" \
	"bench_refine_skin.py --draws 1" \
	"bench_repair.py" \
	"bench_scaling.py --subjects 1 --width 160 --height 120" \
	"bench_stage_cpu.py . --src src --stages align --repeat 1 --subject synth01" \
	"bench_stereo.py --width 320 --height 240 --repeats 1" \
	"bench_stereo_rigs.py --quick --only 0" \
	"bench_stereo_takes.py --subjects 1 --labels neutral" \
	"bench_turned_takes.py --yaw 0" \
	"bench_zero_click.py . ."
bench: setup
	@test -f results/synth04/synth04.h5 || { echo "make bench reads the default run's results: run make run first"; exit 1; }
	@for b in $(BENCH_QUICK); do echo "== benchmarks/$$b"; $(BIN)/python benchmarks/$$b || exit 1; done

# snakemake --lint asks every rule for a conda environment or container; the project installs its
# own environment (make setup), so that one lint is expected and any other fails.
lint: setup
	$(BIN)/ruff check .
	$(BIN)/snakefmt --check .
	$(BIN)/python tools/check_shape.py
	$(BIN)/snakemake --lint >/dev/null 2>&1 || ! $(BIN)/snakemake --lint 2>&1 | grep '^    \* ' | grep -v 'Specify a conda environment or container'

clean:
	rm -rf results logs .snakemake benchmarks/rules

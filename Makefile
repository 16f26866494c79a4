# scan2morph: `make run` and `make test` set everything up first (idempotent), then do their job.
SHELL := /bin/bash
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
CORES ?= 2
# Debian packages: libusb for open3d, EGL/OSMesa for headless rendering, chromium for the report test.
DEB_PACKAGES := libusb-1.0-0 libegl1 libosmesa6 libgl1 libglib2.0-0 libgomp1 chromium
STAMP := $(VENV)/.setup-stamp
DEB_STAMP := $(VENV)/.deb-stamp
export PYOPENGL_PLATFORM ?= osmesa

.PHONY: setup run test bench lint dry-run clean

setup: $(STAMP)

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
	@touch $@

# `make run CONFIG=my.yaml`: your own config file on top of config/config.yaml (its keys win).
run: setup
	$(BIN)/snakemake --cores $(CORES) --keep-going --rerun-incomplete $(if $(CONFIG),--configfile $(CONFIG))

dry-run: setup
	$(BIN)/snakemake -n $(if $(CONFIG),--configfile $(CONFIG))

test: setup
	$(BIN)/python -m pytest -q

bench: setup
	@for b in benchmarks/bench_*.py; do echo "== $$b"; $(BIN)/python $$b || exit 1; done

lint: setup
	$(BIN)/ruff check .
	$(BIN)/snakefmt --check .
	$(BIN)/snakemake --lint

clean:
	rm -rf results logs .snakemake benchmarks/rules

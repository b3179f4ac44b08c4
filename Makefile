# photonloom: `make demo` renders the built-in ROOM animation, `make test` runs the test suite.
# Both start with `setup`, which is idempotent and makes a fresh Debian machine ready.

PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
LOOM   := $(VENV)/bin/loom
STAMP  := $(VENV)/.installed
DEMO   := out/demo

.PHONY: setup opencl test test-all demo render bench clean

setup: opencl $(STAMP)

# Debian's PoCL (the pip wheel fails on these CPUs); installed only when no OpenCL CPU device exists.
opencl:
	@bash docker/ensure_opencl.sh

$(STAMP): pyproject.toml
	@$(PYTHON) -c 'import sys; sys.exit(0 if sys.version_info >= (3, 11) else "photonloom needs Python >= 3.11")'
	@test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[test]'
	@touch $(STAMP)

test: setup
	$(PY) -m ruff check .
	$(PY) -m pytest

test-all: setup
	$(PY) -m pytest -m ''

# The whole ROOM animation (135 frames) at 320x240, 8 spp (docs/10-sampling.md); N_frame and F_max chosen per segment (§5.2).
demo: setup
	@mkdir -p $(DEMO)
	$(LOOM) scene room -o $(DEMO)/room.glb
	$(LOOM) info $(DEMO)/room.glb
	$(LOOM) render $(DEMO)/room.glb --out $(DEMO)/room --resolution 320x240 --spp 8
	$(LOOM) segments $(DEMO)/room
	@echo "frames: $(DEMO)/room/beauty.####.exr and .png; video: $(DEMO)/room/preview.mp4"
	@echo "report: $(DEMO)/room/report.html (one file: open it in a browser)"

# A make-driven farm render: make render SCENE=room.glb FRAMES=1-135 OUT=out/room [JOBS=2] [OPTS="--spp 4"]
# (`loom plan` writes OUT/Makefile, whose targets make then runs; a rerun does only what is missing).
# SCENE may also name a built-in scene (room, atrium, cornell, static) where no such file exists:
# it is written to OUT/NAME.glb first, as `loom scene NAME` writes it.
JOBS ?= $(shell nproc)
render: setup
	@test -n "$(SCENE)" -a -n "$(OUT)" || { echo "usage: make render SCENE=scene.glb|room|cornell|... OUT=dir [FRAMES=1-100] [JOBS=N] [OPTS=...]"; exit 2; }
	@scene='$(SCENE)'; \
	if [ ! -e "$$scene" ]; then $(LOOM) scene "$$scene" -o '$(OUT)'/"$$scene".glb || exit 2; scene='$(OUT)'/"$$scene".glb; fi; \
	echo "$(LOOM) plan $$scene --out $(OUT) $(if $(FRAMES),--frames $(FRAMES)) $(OPTS)"; \
	$(LOOM) plan "$$scene" --out '$(OUT)' $(if $(FRAMES),--frames $(FRAMES)) $(OPTS)
	$(MAKE) -C $(OUT) -j$(JOBS)

# Speed is measured here, never in tests: ratios measured in one run (figures: README "Headline figures"; docs/13-cluster.md §7).
bench: setup
	$(LOOM) bench photons
	$(LOOM) bench frame
	$(LOOM) bench temporal
	$(LOOM) bench aqm
	$(LOOM) bench render
	$(LOOM) bench error room --quick --out out/bench-error-room

clean:
	rm -rf out .pytest_cache

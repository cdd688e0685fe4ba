# Two commands on a fresh machine: `make demo` and `make test`. Both create .venv here.
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
# One cache folder for handshadow and Anny (Anny builds its cache once, about 90 s).
export HANDSHADOW_CACHE_DIR ?= $(CURDIR)/.cache
export ANNY_CACHE_DIR ?= $(HANDSHADOW_CACHE_DIR)/anny
export PIP_DISABLE_PIP_VERSION_CHECK := 1

.PHONY: demo test bench clean

$(VENV)/.installed: pyproject.toml
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	# torch first, pinned to the local CPU wheel: an unpinned torch would pull a multi-GB CUDA build.
	$(PY) -c "import torch" 2>/dev/null || $(PY) -m pip install -q torch==2.13.0
	$(PY) -m pip install -q -e '.[app,test]'
	touch $@

demo: $(VENV)/.installed
	$(VENV)/bin/handshadow fit bird --out out/demo --force
	@echo "Results in out/demo/: guide.png (how to hold your hands), overlay.png, shadow.png, scene.png, hands.glb, progress.gif"

# The browser tests drive Debian's Chromium (never `playwright install`, which downloads a browser).
CHROMIUM := /usr/bin/chromium
SUDO := $(shell [ "$$(id -u)" = 0 ] || echo sudo)

$(CHROMIUM):
	$(SUDO) apt-get update -qq && DEBIAN_FRONTEND=noninteractive $(SUDO) apt-get install -y -qq chromium

test: $(VENV)/.installed $(CHROMIUM)
	$(PY) -m pytest -q

bench: $(VENV)/.installed
	$(PY) bench/render.py

clean:
	rm -rf out .pytest_cache

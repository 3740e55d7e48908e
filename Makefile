# finepos: set-up, demo and tests. Every target creates/uses .venv and installs what it needs.
PY ?= python3
VENV ?= .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: setup system-deps demo test test-fast lint bench clean

# torch is pinned to the CPU build first, so the project's own range is already satisfied
# and pip never pulls the CUDA wheels.
$(STAMP): pyproject.toml
	$(PY) -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip
	$(BIN)/pip install --quiet torch==2.13.0
	$(BIN)/pip install --quiet -e '.[test]'
	touch $(STAMP)

setup: $(STAMP)

# The 3D-mouse teach-in test drives the real spacenavd daemon (Debian package). Installed when
# running as root (CI); otherwise that one test is skipped with its reason.
system-deps:
	@command -v spacenavd >/dev/null 2>&1 || { \
	  if [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then \
	    (apt-get update -qq || true) && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq spacenavd; \
	  else echo "note: spacenavd not installed (sudo apt-get install spacenavd); its test will be skipped"; fi; }

demo: $(STAMP)
	$(BIN)/finepos demo --out out/demo

test: $(STAMP) system-deps
	$(BIN)/ruff check .
	$(BIN)/python -m pytest -q

test-fast: $(STAMP)
	$(BIN)/python -m pytest -q -m "not slow"

lint: $(STAMP)
	$(BIN)/ruff check .

bench: $(STAMP)
	$(BIN)/finepos bench sim --json out/bench-sim.json
	$(BIN)/finepos bench perception --json out/bench-perception.json

clean:
	rm -rf $(VENV) out .pytest_cache

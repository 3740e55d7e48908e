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

# Two tests drive real system programs from Debian: spacenavd (3D-mouse teach-in) and
# systemd-analyze (the unit file check). Installed when running as root (CI); otherwise those
# tests are skipped with their reason.
SYSTEM_PACKAGES := spacenavd:spacenavd systemd-analyze:systemd
system-deps:
	@missing=""; for pair in $(SYSTEM_PACKAGES); do \
	  command -v $${pair%%:*} >/dev/null 2>&1 || missing="$$missing $${pair##*:}"; done; \
	if [ -n "$$missing" ]; then \
	  if [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then \
	    (apt-get update -qq || true) && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq $$missing; \
	  else echo "note: not installed:$$missing (sudo apt-get install$$missing); their tests will be skipped"; fi; fi

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

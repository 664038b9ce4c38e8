# `make test` and `make run` work on a fresh machine: they create .venv and install the project
# with every extra ([dev]).  `make check-core`: the core alone installs and allocates in a clean venv.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed

.PHONY: install test test-all run bench check-core clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip
	$(BIN)/pip install --quiet -e '.[dev]'
	touch $(STAMP)

# an editable install builds no wheel, so nothing compiled the numba kernels: do it once here
# (about 2-3 min of CPU; afterwards it only loads them, a few seconds)
install: $(STAMP)
	$(BIN)/python -m alloc._jit_cache warm --quiet

# after `install`: the kernels a first call would compile are compiled once, not inside timed tests
test: install
	$(BIN)/pytest -q --durations=25

test-all: $(STAMP)
	$(BIN)/pytest -q -m ''

# The README's curl story uses this key; override with `ALLOC_API_KEY=... make run`.
ALLOC_API_KEY ?= s3cret
WORKERS ?= 1
run: $(STAMP)
	ALLOC_API_KEY='$(ALLOC_API_KEY)' $(BIN)/python -m service.main --host 127.0.0.1 --port 8000 --workers $(WORKERS)

bench: $(STAMP)
	$(BIN)/python -m benchmarks.bench_alloc

check-core:
	PYTHON=$(PYTHON) .ci/check-core-install

clean:
	rm -rf $(VENV) .pytest_cache build *.egg-info

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

install: $(STAMP)

test: $(STAMP)
	$(BIN)/pytest -q

test-all: $(STAMP)
	$(BIN)/pytest -q -m ''

run: $(STAMP)
	$(BIN)/alloc serve --host 127.0.0.1 --port 8000

bench: $(STAMP)
	$(BIN)/python -m benchmarks.bench_alloc

check-core:
	PYTHON=$(PYTHON) .ci/check-core-install

clean:
	rm -rf $(VENV) .pytest_cache build *.egg-info

# `make test` and `make run` work on a fresh machine: they create .venv and install the project
# with every extra ([dev]).  `make check-core`: the core alone installs and allocates in a clean venv.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed

.PHONY: install lint test test-all run bench check-core clean

# `make install QUIET=1`, or `make -s install` (--quiet): nothing is printed unless something fails.
# Otherwise one line per step.
ifneq ($(findstring s,$(firstword -$(MAKEFLAGS))),)
QUIET := 1
endif
WARM_OUTPUT := $(if $(QUIET),--quiet,--summary)
PIP_OUTPUT  := $(if $(QUIET),--quiet --quiet,--quiet)

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install $(PIP_OUTPUT) --disable-pip-version-check --upgrade pip
	$(BIN)/pip install $(PIP_OUTPUT) --disable-pip-version-check -e '.[dev]'
	touch $(STAMP)

# an editable install builds no wheel, so nothing compiled the numba kernels: do it once here
# (about 2-3 min of CPU; afterwards it only loads them, a few seconds).  The library's kernels,
# then the simulator's (the library knows nothing of it): a first `alloc sim` compiles nothing.
install: $(STAMP)
	$(BIN)/python -m alloc._engine._jit_warm warm $(WARM_OUTPUT)
	$(BIN)/python -m sim.warm $(if $(QUIET),--quiet)

# ruff (about a second) and mypy (its cache in .mypy_cache: a few seconds warm, a minute or two
# cold), configured in pyproject.toml
lint: $(STAMP)
	$(BIN)/ruff check $(if $(QUIET),--quiet) .
	$(BIN)/mypy $(if $(QUIET),--no-error-summary)

# after `install`: the kernels a first call would compile are compiled once, not inside timed tests
test: install lint
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

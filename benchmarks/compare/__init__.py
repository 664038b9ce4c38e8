"""Allocator comparison: open loop and closed loop side by side (issue 6, seed section 1.3.4.9).

Open-loop measures (AMS coverage, moment error, effort, latency) do not predict
closed-loop tracking, so ``alloc bench`` measures both on the same methods:

* :mod:`.sweep` -- a sweep is a list of run specs (plain, JSON-able dicts with an ``id``);
  ``quick`` and ``full`` are defined there.
* :mod:`.openloop`, :mod:`.closedloop` -- one run is a pure, seeded function of its spec
  returning one CSV row (plus its timings, kept apart because they differ run to run).
* :mod:`.runner` -- local process pool or Dask cluster, resumable CSVs sorted by spec id.
* :mod:`.report` -- ranked Markdown tables, PNG plots, the headline.
* :mod:`.cli` -- the typer app mounted as ``alloc bench``.
"""

from .runner import run_spec, run_sweep
from .sweep import full_sweep, quick_sweep

__all__ = ["run_spec", "run_sweep", "quick_sweep", "full_sweep"]

"""Allocator comparison: open loop and closed loop side by side (issues 6 and 14, seed section 1.3.4.9).

Open-loop measures (AMS coverage, moment error, effort) do not by themselves predict
closed-loop tracking, so ``alloc bench`` measures both on the same methods:

* :mod:`.sweep` -- a sweep is a list of run specs (plain, JSON-able dicts with an ``id``);
  ``smoke``, ``quick`` and ``full`` are defined there, with the pass-through simulator settings.
* :mod:`.failures` -- the effector failure catalogue and how it reaches a scenario.
* :mod:`.openloop`, :mod:`.closedloop` -- one run is a pure, seeded function of its spec
  returning one CSV row (plus its wall time, kept apart; closed-loop runs may keep a history).
* :mod:`.runner` -- local process pool or Dask cluster by address, resumable CSVs sorted by spec id.
* :mod:`.cluster`, :mod:`.throughput` -- a loopback Dask cluster of separate processes; scaling.
* :mod:`.timing` -- per-call latency in a dedicated single-process pass after the sweep.
* :mod:`.stats`, :mod:`.report` -- bootstrap intervals, rankings with ties, told/blind ratios,
  Spearman; Markdown tables and figures (each with its data as CSV).
* :mod:`.cli` -- the typer app mounted as ``alloc bench``.
"""

from .runner import run_spec, run_sweep
from .sweep import full_sweep, quick_sweep

__all__ = ["run_spec", "run_sweep", "quick_sweep", "full_sweep"]

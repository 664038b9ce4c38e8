"""Run a sweep on a local process pool or a Dask cluster; resumable CSV output.

Each finished run appends its row to ``<table>.csv`` and its timings to
``<table>_timings.csv`` at once (flushed), so an interrupted sweep keeps what it did;
re-running skips the spec ids already present.  At the end every table is rewritten
sorted by spec id, so the result CSVs are byte-identical whichever engine ran them and
in whatever order runs finished (the timings CSVs naturally are not).

Tables: ``open`` (open loop), ``closed_<scenario>`` (closed loop; one per scenario
because the channels differ).  Runs whose spec asks for it (``history``) also leave their
time history in ``histories/<id>.npz`` (written by the client as the run finishes, so it
works the same on a remote cluster).
"""

from __future__ import annotations

import concurrent.futures as cf
import csv
import multiprocessing
import os
import time
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from .sweep import Spec

__all__ = ["run_spec", "run_sweep", "table_of", "read_table", "history_path", "SweepOutcome", "BLAS_ENV"]

#: One BLAS/OpenMP thread per worker process: a process per core already uses every
#: core, and Dask's nanny sets the same variables, so both engines compute alike.
BLAS_ENV = {v: "1" for v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS",
                             "NUMBA_NUM_THREADS")}

Row = dict[str, Any]


def table_of(spec: Spec) -> str:
    """Name of the CSV table a spec's row goes to."""
    return "open" if spec["kind"] == "open" else f"closed_{spec['scenario']}"


def history_path(out: Path | str, spec_id: str) -> Path:
    """Where the time history of run ``spec_id`` is stored."""
    return Path(out) / "histories" / (spec_id.replace("/", "__") + ".npz")


Result = tuple[str, Row, Row, "dict[str, Any] | None"]


def run_spec(spec: Spec) -> Result:
    """Run one spec (in a worker): ``(table, row, timings, history or None)``."""
    history = None
    if spec["kind"] == "open":
        from .openloop import run_open

        row, timings = run_open(spec)
    elif spec["kind"] == "closed":
        from .closedloop import run_closed

        row, timings, history = run_closed(spec)
    else:
        raise ValueError(f"spec {spec.get('id')!r}: unknown kind {spec['kind']!r}; 'open' or 'closed'")
    return table_of(spec), row, timings, history


# ----------------------------------------------------------------------------- CSV store
def _complete_rows(path: Path) -> tuple[list[str], list[Row]]:
    """Header and complete rows of a CSV (a line cut short by an interruption is dropped)."""
    if not path.exists() or path.stat().st_size == 0:
        return [], []
    with path.open(newline="") as fh:
        reader = csv.DictReader(fh)
        header = list(reader.fieldnames or [])
        rows = [r for r in reader if None not in r.values() and None not in r and r.get("id")]
    return header, rows


def read_table(path: Path) -> list[Row]:
    """Rows of a result CSV as strings (see :mod:`.report` for typed access)."""
    return _complete_rows(Path(path))[1]


def _write(path: Path, header: list[str], rows: Iterable[Row]) -> None:
    tmp = path.with_suffix(".csv.tmp")
    with tmp.open("w", newline="") as fh:
        writer = csv.DictWriter(fh, header, lineterminator="\n")
        writer.writeheader()
        writer.writerows(rows)
    tmp.replace(path)


class _Table:
    """An append-only CSV with a fixed header, opened lazily on the first row."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.header, rows = _complete_rows(path)
        self.ids = {r["id"] for r in rows}
        if rows or self.header:
            _write(path, self.header, rows)  # drop a half-written last line before appending
        self._fh: Any = None
        self._writer: csv.DictWriter | None = None

    def append(self, row: Row) -> None:
        if self._writer is None:
            new = not self.header
            if new:
                self.header = list(row)
            elif list(row) != self.header:
                raise ValueError(f"{self.path}: columns changed since it was written; write to a new folder")
            self._fh = self.path.open("a", newline="")
            self._writer = csv.DictWriter(self._fh, self.header, lineterminator="\n")
            if new:
                self._writer.writeheader()
        self._writer.writerow(row)
        self._fh.flush()
        self.ids.add(row["id"])

    def close(self, *, sort: bool) -> None:
        if self._fh is not None:
            self._fh.close()
            self._fh = self._writer = None
        if sort and self.path.exists():
            header, rows = _complete_rows(self.path)
            unique = {r["id"]: r for r in reversed(rows)}  # first occurrence wins
            _write(self.path, header, [unique[i] for i in sorted(unique)])


# ----------------------------------------------------------------------------- engines
@contextmanager
def _blas_env() -> Iterator[None]:
    saved = {k: os.environ.get(k) for k in BLAS_ENV}
    os.environ.update(BLAS_ENV)
    try:
        yield
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


def _local_results(specs: list[Spec], workers: int | None) -> Iterator[Result]:
    # spawn: fresh interpreters that see BLAS_ENV before numpy is imported
    with _blas_env(), cf.ProcessPoolExecutor(workers or os.cpu_count(),
                                             mp_context=multiprocessing.get_context("spawn")) as pool:
        futures = [pool.submit(run_spec, s) for s in specs]
        try:
            for fut in cf.as_completed(futures):
                yield fut.result()
        finally:
            for fut in futures:
                fut.cancel()


def _dask_results(specs: list[Spec], client: Any) -> Iterator[Result]:
    from distributed import as_completed

    futures = client.map(run_spec, specs, pure=False)
    try:
        for fut in as_completed(futures):
            yield fut.result()
    finally:
        client.cancel(futures)


@dataclass
class SweepOutcome:
    """What a sweep did: runs executed now, runs skipped (already in the CSVs), wall time."""

    ran: int
    skipped: int
    wall_s: float
    engine: str
    files: list[Path] = field(default_factory=list)


def run_sweep(specs: list[Spec], out: Path | str, *, workers: int | None = None, scheduler: Any = None,
              resume: bool = False, progress: bool = True, desc: str = "sweep") -> SweepOutcome:
    """Run ``specs``, writing rows to ``out/<table>.csv`` as they finish.

    Parameters
    ----------
    workers : int, optional
        Local process-pool size (default: all cores).  Ignored with ``scheduler``.
    scheduler : str or distributed.Client, optional
        Dask scheduler address (or a connected client): the same specs go to the cluster
        with ``client.map``.  The workers must be able to import ``alloc``, ``sim`` and
        ``benchmarks`` (install the repo on them).
    resume : bool
        Skip spec ids already written.  ``False`` (default): the sweep must start afresh, and
        ``FileExistsError`` is raised if ``out`` already holds one of its tables (nothing is
        deleted or overwritten).
    """
    ids = [s["id"] for s in specs]
    if len(set(ids)) != len(ids):
        raise ValueError("specs: duplicate ids")
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    names = sorted({table_of(s) for s in specs})
    if not resume:
        found = [f"{n}{suffix}.csv" for n in names for suffix in ("", "_timings") if (out / f"{n}{suffix}.csv").exists()]
        if found:
            raise FileExistsError(f"out: {out} already holds {', '.join(found)} from an earlier sweep; "
                                  "resume it explicitly (--resume) or write to a new folder")
    tables = {n: _Table(out / f"{n}.csv") for n in names}
    timings = {n: _Table(out / f"{n}_timings.csv") for n in names}
    todo = [s for s in specs if s["id"] not in tables[table_of(s)].ids]

    engine, client, own_client = "local", None, False
    if scheduler is not None:
        from distributed import Client

        engine = "dask"
        client = scheduler if isinstance(scheduler, Client) else Client(scheduler)
        own_client = client is not scheduler
    t0 = time.perf_counter()
    try:
        if todo:
            results = _dask_results(todo, client) if client is not None else _local_results(todo, workers)
            with tqdm(total=len(todo), desc=desc, unit="run", disable=not progress) as bar:
                for table, row, timing, history in results:
                    if history is not None:
                        path = history_path(out, row["id"])
                        path.parent.mkdir(exist_ok=True)
                        np.savez_compressed(path, **history)
                    tables[table].append(row)
                    timings[table].append(timing)
                    bar.update()
    finally:
        for t in (*tables.values(), *timings.values()):
            t.close(sort=True)
        if own_client:
            client.close()
    files = [t.path for t in (*tables.values(), *timings.values()) if t.path.exists()]
    return SweepOutcome(len(todo), len(specs) - len(todo), time.perf_counter() - t0, engine, files)

"""The comparison sweep gives the same CSVs on a local process pool and on a Dask cluster,
and a re-run resumes from what an interrupted run wrote."""

from __future__ import annotations

import csv
from pathlib import Path

import pytest

from benchmarks.compare.runner import run_sweep
from benchmarks.compare.sweep import tiny_sweep

RESULT_TABLES = ("open.csv", "closed_ice.csv")


@pytest.fixture(scope="module")
def specs() -> list[dict]:
    return tiny_sweep()


@pytest.fixture(scope="module")
def local_dir(tmp_path_factory: pytest.TempPathFactory, specs: list[dict]) -> Path:
    out = tmp_path_factory.mktemp("local")
    outcome = run_sweep(specs, out, workers=2, progress=False)
    assert (outcome.ran, outcome.skipped, outcome.engine) == (len(specs), 0, "local")
    return out


def test_dask_and_local_give_identical_csvs(tmp_path: Path, specs: list[dict], local_dir: Path) -> None:
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(n_workers=2, processes=True, threads_per_worker=1,
                                  dashboard_address=None) as cluster, distributed.Client(cluster) as client:
        outcome = run_sweep(specs, tmp_path, scheduler=client, progress=False)
    assert (outcome.ran, outcome.engine) == (len(specs), "dask")
    for name in RESULT_TABLES:
        local, dask = (local_dir / name).read_bytes(), (tmp_path / name).read_bytes()
        assert local == dask, name
    rows = list(csv.DictReader((local_dir / "open.csv").open()))
    assert [r["id"] for r in rows] == sorted(s["id"] for s in specs if s["kind"] == "open")
    # timings are kept apart from the compared tables
    assert "latency_median_us" not in rows[0]
    assert (tmp_path / "open_timings.csv").exists()


def test_rerun_skips_finished_runs(tmp_path: Path, specs: list[dict], local_dir: Path) -> None:
    for name in RESULT_TABLES:
        (tmp_path / name).write_bytes((local_dir / name).read_bytes())
    outcome = run_sweep(specs, tmp_path, workers=2, progress=False, resume=True)
    assert (outcome.ran, outcome.skipped) == (0, len(specs))


def test_interrupted_sweep_resumes(tmp_path: Path, specs: list[dict], local_dir: Path) -> None:
    # an interrupted run: two complete open-loop rows, a third cut mid-line, no closed loop yet
    lines = (local_dir / "open.csv").read_text().splitlines(keepends=True)
    (tmp_path / "open.csv").write_text("".join(lines[:3]) + lines[3][: len(lines[3]) // 2])
    outcome = run_sweep(specs, tmp_path, workers=2, progress=False, resume=True)
    assert (outcome.ran, outcome.skipped) == (len(specs) - 2, 2)
    for name in RESULT_TABLES:
        assert (tmp_path / name).read_bytes() == (local_dir / name).read_bytes(), name

"""The comparison sweep gives the same CSVs on a local process pool and on a real Dask cluster
(scheduler and workers as separate processes), a re-run resumes from what an interrupted run
wrote, and the report's time histories are the stored runs of its table."""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np
import pytest

from benchmarks.compare.report import HISTORY_DECIMATE, make_report, parse_markdown_table
from benchmarks.compare.runner import history_path, run_sweep
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


def _histories(out: Path) -> dict[str, dict[str, np.ndarray]]:
    return {p.name: dict(np.load(p)) for p in sorted((out / "histories").glob("*.npz"))}


# cluster start-up, the tiny sweep's runs, graceful teardown; the local reference is the module's
def test_dask_cluster_by_address_gives_byte_identical_csvs(tmp_path: Path, specs: list[dict], local_dir: Path) -> None:
    """``dask scheduler`` and two ``dask worker`` processes on loopback (torn down however the test ends)."""
    pytest.importorskip("distributed")
    from benchmarks.compare.cluster import loopback_cluster

    with loopback_cluster(2, timeout_s=120, log_dir=tmp_path) as address:
        assert address.startswith("tcp://127.0.0.1:")
        outcome = run_sweep(specs, tmp_path / "dask", scheduler=address, progress=False)
    assert (outcome.ran, outcome.engine) == (len(specs), "dask")
    for name in RESULT_TABLES:
        assert (local_dir / name).read_bytes() == (tmp_path / "dask" / name).read_bytes(), name
    local, dask = _histories(local_dir), _histories(tmp_path / "dask")
    assert sorted(local) == sorted(dask) and len(local) == sum(bool(s.get("history")) for s in specs) == 2
    for name in local:
        for key in local[name]:
            np.testing.assert_array_equal(local[name][key], dask[name][key], err_msg=f"{name}:{key}")
    rows = list(csv.DictReader((local_dir / "open.csv").open()))
    assert "wall_s" not in rows[0]  # timings are kept apart from the compared tables


def test_local_tables_are_sorted_by_id(specs: list[dict], local_dir: Path) -> None:
    rows = list(csv.DictReader((local_dir / "open.csv").open()))
    assert [r["id"] for r in rows] == sorted(s["id"] for s in specs if s["kind"] == "open")


def test_a_fresh_sweep_refuses_a_folder_with_results(tmp_path: Path, specs: list[dict], local_dir: Path) -> None:
    (tmp_path / "open.csv").write_bytes((local_dir / "open.csv").read_bytes())
    with pytest.raises(FileExistsError, match="resume"):
        run_sweep(specs, tmp_path, workers=2, progress=False)
    assert (tmp_path / "open.csv").read_bytes() == (local_dir / "open.csv").read_bytes()


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


def test_time_history_figure_is_drawn_from_the_runs_in_its_table(local_dir: Path, specs: list[dict]) -> None:
    text = make_report(local_dir, specs, {}).read_text()
    table = parse_markdown_table(text, "run id")
    assert [r["method"] for r in table] == ["static", "qp"]
    rows = {r["id"]: r for r in csv.DictReader((local_dir / "closed_ice.csv").open())}
    drawn = list(csv.DictReader((local_dir / "history_ice_pilot_gain_1_seed.csv").open()))
    for entry in table:
        row, run = rows[entry["run id"]], np.load(history_path(local_dir, entry["run id"]))
        after = run["t"] >= float(row["failure_time"])
        for j, c in enumerate(run["channels"]):
            err = run["reference"][after, j].astype(float) - run["output"][after, j]
            rms = math.sqrt(float(np.mean(err**2)))
            # the stored run reproduces its CSV row (float32 storage) and the table shows that row
            assert rms == pytest.approx(float(row[f"{c}_rms_after"]), rel=1e-4)
            assert entry[f"{c} RMS after"] == f"{float(row[f'{c}_rms_after']):.3g}"
            label = f"{entry['method']} ({entry['allocator']})"
            plotted = np.array([float(d[f"{label}:{c}:output"]) for d in drawn])
            np.testing.assert_array_equal(plotted, run["output"][::HISTORY_DECIMATE, j].astype(float))

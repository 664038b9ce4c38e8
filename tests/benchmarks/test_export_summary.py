"""benchmarks/bench_export.py --summarise: the peer ratios over several runs' JSON files."""

from __future__ import annotations

from benchmarks import bench_export as be


def _run(date: str, load: float, qp: float, daqp: float) -> dict:
    rows = [{"problem": "ICE 3x11", "sequence": "random", "kernel": k, "median_ns": t}
            for k, t in (("qp", qp), ("daqp cold", daqp))]
    return {"machine": {"date": date, "load_1min": load}, "rows": rows}


def test_the_summary_gives_median_range_and_runs_above_the_goal():
    runs = [_run("d1", 0.5, 1200.0, 1000.0), _run("d2", 0.7, 2000.0, 1000.0), _run("d3", 0.9, 800.0, 1000.0)]
    text = be.repeat_summary(runs)
    assert "| 2 | d2 | 0.70 |" in text
    assert "| ICE 3x11 | random | qp / daqp cold | 3 | 1.20x | 0.80x | 2.00x | 1 |" in text
    assert "daqp warm" not in text  # a pair no run has is left out

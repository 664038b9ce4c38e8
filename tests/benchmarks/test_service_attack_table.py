"""The attack suite's markdown table (benchmarks/service_attack_table.py): the committed table is
what its committed report renders to, the ``--attack-table`` command writes it, and every row's
cells and verdict follow from the report's numbers."""

from __future__ import annotations

import json
import re
import sys
from pathlib import Path

import numpy as np
import pytest

from benchmarks import bench_service
from benchmarks.service_attack_table import render_attack_table

REFERENCE = Path(__file__).resolve().parents[2] / "benchmarks" / "reference"
REPORT = REFERENCE / "service_attacks-2026-12-02-tmpfs.json"
TABLE = REFERENCE / "service_attacks.md"
CLASSES = ("event", "allocation", "health")


def test_the_committed_table_is_rendered_from_the_committed_report():
    """Byte for byte; the load before the run is the one figure the JSON does not hold (the
    command measures it before starting the suite), so it is read back from the table."""
    table = TABLE.read_text()
    before = re.search(r"load average \(1 / 5 / 15 min\) (\S+) / (\S+) / (\S+) before", table)
    assert before is not None
    load_before = tuple(float(x) for x in before.groups())
    assert render_attack_table(json.loads(REPORT.read_text()), load_before) == table


def test_the_attack_table_command_prints_and_writes_the_table(tmp_path, monkeypatch, capsys):
    out = tmp_path / "attacks.md"
    monkeypatch.setattr(sys, "argv", ["bench_service", "--attack-table", str(REPORT), "--markdown", str(out)])
    bench_service.main()
    expected = render_attack_table(json.loads(REPORT.read_text()))
    assert out.read_text() == expected
    assert capsys.readouterr().out == expected + "\n"
    assert "| no attack (floor) | 5 / 9 | 2 / 7 | 1 / 4 | 120 | yes | 0 / 464 | 0.7 |" in expected
    assert "on tmpfs: the event times leave out the disk" in expected


def random_report(rng: np.random.Generator) -> dict:
    """A report with p99s below, at and above their targets (a p99 equal to its target misses:
    the targets are strict), with and without targets and memory figures."""
    targets = {"event": 50.0, "allocation": 100.0, "health": 100.0} if rng.random() < 0.8 else {}
    attacks = {}
    for a in range(int(rng.integers(1, 6))):
        row: dict = {"loadavg": float(rng.uniform(0, 8))}
        for name in CLASSES:
            limit = targets.get(name, 100.0)
            p99 = float(rng.choice([limit, rng.uniform(0, 2 * limit), np.nextafter(limit, 0)]))
            row[name] = {"n": int(rng.integers(1, 60)), "p50_ms": float(rng.uniform(0, p99)), "p99_ms": p99}
        if rng.random() < 0.5:
            row["rss_growth_mib"], row["bound_mib"] = float(rng.uniform(-10, 500)), 464.0
        attacks[f"class {a}"] = row
    return {"loadavg": [1.0, 1.0, 1.0], "cpus": 2, "targets_ms": targets, "attacks": attacks}


@pytest.mark.parametrize("seed", range(4))
def test_each_row_states_its_figures_and_its_verdict(seed):
    rng = np.random.default_rng(seed)
    for _ in range(25):
        report = random_report(rng)
        rows = [line for line in render_attack_table(report).splitlines() if line.startswith("| class ")]
        assert len(rows) == len(report["attacks"])
        for line, (name, row) in zip(rows, report["attacks"].items()):
            cells = [c.strip() for c in line.strip("|").split("|")]
            assert cells[0] == name
            assert cells[1:4] == [f"{row[c]['p50_ms']:.0f} / {row[c]['p99_ms']:.0f}" for c in CLASSES]
            assert cells[4] == str(row["event"]["n"])
            if report["targets_ms"]:
                met = all(row[c]["p99_ms"] < report["targets_ms"][c] for c in CLASSES)
                assert cells[5] == ("yes" if met else "no")
            else:
                assert cells[5] == "-"
            assert cells[6] == (f"{row['rss_growth_mib']:.0f} / 464" if "rss_growth_mib" in row else "-")
            assert cells[7] == f"{row['loadavg']:.1f}"

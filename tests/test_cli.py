"""The command line: help texts, JSON output, clear errors."""

from __future__ import annotations

import json

import numpy as np
from typer.testing import CliRunner

import alloc
from alloc.cli import app
from alloc.vehicles import ice

runner = CliRunner()


def test_help_lists_every_command():
    out = runner.invoke(app, ["--help"]).output
    for cmd in ("methods", "allocate", "sim", "ams", "bench", "serve"):
        assert cmd in out


def test_methods_json_matches_registry():
    out = runner.invoke(app, ["methods", "--json"])
    assert out.exit_code == 0
    assert [m["name"] for m in json.loads(out.output)] == alloc.methods()


def test_allocate_json_equals_library():
    out = runner.invoke(app, ["allocate", "--vehicle", "ice", "--v", "2,30,0.5", "--method", "qp", "--json"])
    assert out.exit_code == 0, out.output
    data = json.loads(out.output)
    lib = alloc.allocate(ice(), [2, 30, 0.5], "qp")
    np.testing.assert_array_equal(data["u"], lib.u)
    assert data["status"] == "exact"


def test_allocate_bad_demand_is_a_clear_error():
    out = runner.invoke(app, ["allocate", "--vehicle", "ice", "--v", "2,30"])
    assert out.exit_code == 2
    assert "v: expected shape (3,)" in out.output


def test_allocate_problem_file_and_options(tmp_path):
    f = tmp_path / "p.json"
    f.write_text(json.dumps({"B": [[1, 1, 0], [0, 1, 1]], "umin": [-1, -1, -1], "umax": [1, 1, 1]}))
    out = runner.invoke(app, ["allocate", "--problem", str(f), "--v", "3,0", "--method", "qp",
                              "--option", "priorities=[2,1]", "--json"])
    assert out.exit_code == 0, out.output
    data = json.loads(out.output)
    assert data["status"] == "unattainable"
    # axis 0 first: at most 2 of its 3 (u0 = u1 = 1); then axis 1 met exactly with u2 = -1
    np.testing.assert_allclose(data["unallocated"], [1.0, 0.0], atol=1e-8)
    np.testing.assert_allclose(data["u"], [1.0, 1.0, -1.0], atol=1e-8)

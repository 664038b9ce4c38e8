"""The command line: help texts, JSON output, clear errors."""

from __future__ import annotations

import json

import numpy as np
import typer
import typer.core
import typer.main
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


def test_allocate_vehicle_daisy_uses_the_vehicles_groups():
    """ICE's [methods.daisy] groups reach daisy (without them it answered pinv_scale's u = 0 here)."""
    from alloc.vehicles import daisy_groups

    out = runner.invoke(app, ["allocate", "--vehicle", "ice", "--v", "0.5,1,0.2", "--method", "daisy", "--json"])
    assert out.exit_code == 0, out.output
    data = json.loads(out.output)
    lib = alloc.allocate(ice(), [0.5, 1, 0.2], "daisy", groups=daisy_groups("ice"))
    assert data["u"] == lib.u.tolist() and data["status"] == "exact"
    assert not np.array_equal(lib.u, alloc.allocate(ice(), [0.5, 1, 0.2], "pinv_scale").u)


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


def test_allocate_reports_build_first_call_and_solve_times_separately():
    # issue 22: solve_time was the first call's 138-355 ms (kernel loading) for a microsecond solve
    out = runner.invoke(app, ["allocate", "--vehicle", "ice", "--v", "2,30,0.5", "--json", "--repeat", "50"])
    assert out.exit_code == 0, out.output
    data = json.loads(out.stdout)
    assert data["timed_calls"] == 50
    assert 0.0 < data["solve_time"] < 5e-3  # the warm median: microseconds, 5 ms even on a loaded machine
    assert data["build_time"] > 0.0 and data["first_call_time"] > 0.0
    text = runner.invoke(app, ["allocate", "--vehicle", "ice", "--v", "2,30,0.5", "--repeat", "5"]).stdout
    assert "solve " in text and "(median of 5 calls), first call " in text and ", build " in text


def test_the_cli_default_method_is_the_registry_constant():
    from alloc.ams.cli import app as ams_app
    from alloc.registry import DEFAULT_METHOD

    out = runner.invoke(app, ["allocate", "--vehicle", "ice", "--v", "2,30,0.5", "--json", "--repeat", "1"])
    assert json.loads(out.stdout)["method"] == DEFAULT_METHOD
    assert f"[default: ({DEFAULT_METHOD})]" in runner.invoke(app, ["allocate", "--help"]).stdout
    plot = next(c for c in typer.main.get_command(ams_app).commands.values() if c.name == "plot")
    assert next(p for p in plot.params if p.name == "method").default == DEFAULT_METHOD


def test_one_default_method_everywhere():
    import inspect

    from alloc.registry import DEFAULT_METHOD
    from service.schemas import AllocateRequest, BatchAllocateRequest

    for fn in (alloc.make_allocator, alloc.allocate, alloc.allocate_batch):
        assert inspect.signature(fn).parameters["method"].default == DEFAULT_METHOD, fn.__name__
    for schema in (AllocateRequest, BatchAllocateRequest):
        assert schema.model_fields["method"].default == DEFAULT_METHOD, schema.__name__


def _commands() -> list[tuple[str, typer.core.TyperCommand]]:
    from alloc.cli import _load_command, command_entry_points

    root = typer.main.get_command(app)
    ctx = typer.Context(root, info_name="alloc")
    found = []

    def walk(cmd, path: str) -> None:
        found.append((path, cmd))
        for name in getattr(cmd, "list_commands", lambda ctx: [])(ctx):
            entry = command_entry_points().get(name) if path == "alloc" else None
            walk(_load_command(entry) if entry is not None else cmd.get_command(ctx, name), f"{path} {name}")

    walk(root, "alloc")
    return found


def test_every_command_and_option_explains_itself():
    commands = _commands()
    assert {p for p, _ in commands} >= {"alloc allocate", "alloc ams plot", "alloc ams coverage", "alloc sim",
                                         "alloc bench quick", "alloc bench full", "alloc bench report",
                                         "alloc bench scaling", "alloc serve"}
    for path, cmd in commands:
        assert (cmd.help or "").strip(), path
        undocumented = [p.name for p in cmd.params if p.name != "help" and not (getattr(p, "help", "") or "").strip()]
        assert undocumented == [], (path, undocumented)
        res = runner.invoke(app, [*path.split()[1:], "--help"], prog_name="alloc")
        assert res.exit_code == 0 and "Usage: alloc" in res.stdout, (path, res.output)

"""Every tool reads a vehicle: ``--vehicle NAME|FILE`` in allocate, ams, sim and bench, the
catalogue extended by ``ALLOC_VEHICLE_PATH`` and the ``alloc.vehicles`` entry points, and the
vehicle's ``[methods.<method>]`` defaults applied under the user's options (issues 24, 25).

The user's files here are written by the tests (a quad X by rotor geometry), not bundled.
"""

from __future__ import annotations

import json
import random
import sys
from importlib.metadata import EntryPoint
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from typer.testing import CliRunner

import alloc
from alloc import vehicles
from alloc.cli import app
from alloc.vehicle_file import load_vehicle

runner = CliRunner()
SEED = 20261201

QUAD = """format = "alloc-vehicle/1"
name = "my-quad"
description = "a user's quad X, 1 kg"

[[axes]]
name = "roll"
unit = "N m"

[[axes]]
name = "pitch"
unit = "N m"

[[axes]]
name = "yaw"
unit = "N m"

[[axes]]
name = "thrust"
unit = "N"
wrench = "fz"
trim = -9.81
{effectors}
[methods.daisy]
groups = [["m1", "m2"], ["m3", "m4"]]
"""
ROTOR = """
[[effectors]]
name = "m{i}"
kind = "rotor"
min = 0.0
max = 1.0
rate_max = 8.0
preferred = 0.5
rotor = {{ position = [{x}, {y}, 0.0], ct = 4.0, km = {km} }}
"""
_ROTORS = ((0.15, 0.15, 0.05), (-0.15, -0.15, 0.05), (0.15, -0.15, -0.05), (-0.15, 0.15, -0.05))


def quad_text(*, groups: bool = True, name: str = "my-quad") -> str:
    rotors = "".join(ROTOR.format(i=i + 1, x=x, y=y, km=km) for i, (x, y, km) in enumerate(_ROTORS))
    text = QUAD.format(effectors=rotors).replace('name = "my-quad"', f'name = "{name}"')
    return text if groups else text[:text.index("[methods.daisy]")]


def write_quad(folder: Path, file: str = "my-quad.toml", **kw: Any) -> Path:
    path = folder / file
    path.write_text(quad_text(**kw), encoding="utf-8")
    return path


def invoke(args: list[str], env: dict[str, str] | None = None) -> Any:
    res = runner.invoke(app, args, prog_name="alloc", env=env)
    res.cli_args = args
    return res


def ok_json(args: list[str], env: dict[str, str] | None = None) -> Any:
    res = invoke(args, env)
    assert res.exit_code == 0, (args, res.stdout, res.stderr)
    return json.loads(res.stdout)


def assert_one_line_error(res: Any, *tokens: str) -> str:
    where = f"args {res.cli_args}: stdout {res.stdout[:400]!r} stderr {res.stderr!r}"
    assert res.exit_code == 2, where
    assert res.exception is None or isinstance(res.exception, SystemExit), where
    lines = [line for line in res.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and "Traceback" not in res.stdout + res.stderr, where
    for token in tokens:
        assert token in lines[0], where
    return lines[0]


def csv(values: Any) -> str:
    return ",".join(repr(float(x)) for x in values)


# ------------------------------------------------------------------ allocate
HEXA_DEMAND = [2.0, 0.0, 3.0, -19.62]  # roll, pitch, yaw beyond the AMS at hover thrust


def test_allocate_vehicle_name_is_the_library_with_the_vehicles_defaults():
    v = vehicles.get_vehicle("hexa-x")
    out = ok_json(["allocate", "--vehicle", "hexa-x", "--v", csv(HEXA_DEMAND), "--method", "qp", "--json",
                   "--repeat", "2"])
    lib = alloc.allocate(v.problem(), HEXA_DEMAND, "qp", **v.method_options("qp"))
    assert out["u"] == lib.u.tolist() and out["status"] == lib.status.value == "unattainable"
    # the file's priorities [2, 2, 1, 3]: thrust kept, yaw gives way (without them roll gives way too)
    plain = alloc.allocate(v.problem(), HEXA_DEMAND, "qp")
    assert out["v_achieved"][3] == pytest.approx(-19.62, abs=1e-6) and abs(plain.v_achieved[0] - 2.0) > 0.3
    # the user's option overrides the vehicle's: equal priorities are the plain answer's
    flat = ok_json(["allocate", "--vehicle", "hexa-x", "--v", csv(HEXA_DEMAND), "--method", "qp", "--json",
                    "--repeat", "2", "--option", "priorities=[1, 1, 1, 1]"])
    assert flat["u"] == alloc.allocate(v.problem(), HEXA_DEMAND, "qp", priorities=[1, 1, 1, 1]).u.tolist()


def test_allocate_user_file_is_the_library(tmp_path):
    path = write_quad(tmp_path)
    v = load_vehicle(path)
    p = v.problem()
    rng = np.random.default_rng(SEED)
    for _ in range(3):
        u = rng.uniform(0.2, 0.8, 4)
        d = p.B @ u + rng.normal(size=4) * [0.2, 0.2, 0.05, 1.0]
        out = ok_json(["allocate", "--vehicle", str(path), "--v", csv(d), "--method", "daisy", "--json",
                       "--repeat", "2"])
        lib = alloc.allocate(p, d, "daisy", groups=[["m1", "m2"], ["m3", "m4"]])
        assert out["u"] == lib.u.tolist() and out["status"] == lib.status.value
        assert out["names"] == ["m1", "m2", "m3", "m4"] and out["axes"] == ["roll", "pitch", "yaw", "thrust"]
    one = ok_json(["allocate", "--vehicle", str(path), "--v", csv(d), "--method", "daisy", "--json", "--repeat", "2",
                   "--option", 'groups=[["m1", "m2", "m3", "m4"]]'])
    assert one["u"] == alloc.allocate(p, d, "pinv_scale").u.tolist()  # one group asked for: pinv_scale's answer
    assert one["u"] != out["u"]


# ------------------------------------------------------------------ ams
def test_ams_summary_and_coverage_read_a_file(tmp_path):
    from alloc.ams import AttainableSet, coverage

    path = write_quad(tmp_path)
    p = load_vehicle(path).problem()
    summary = ok_json(["ams", "summary", "--vehicle", str(path), "--json"])
    assert summary == json.loads(json.dumps(AttainableSet(p).summary()))
    assert summary["k"] == 4 and summary["m"] == 4 and summary["volume"] > 0
    rows = ok_json(["ams", "coverage", "--vehicle", str(path), "--method", "pinv", "--method", "daisy",
                    "--samples", "400", "--json"])
    lib = [coverage(p, "pinv", samples=400, seed=0).to_dict(),
           coverage(p, "daisy", samples=400, seed=0, groups=[["m1", "m2"], ["m3", "m4"]]).to_dict()]
    untimed = [{k: x for k, x in r.items() if k != "seconds"} for r in json.loads(json.dumps(lib))]
    assert [{k: x for k, x in r.items() if k != "seconds"} for r in rows] == untimed
    # B is square and invertible: pinv reaches the whole AMS (exact polytope); daisy's 2-rotor groups
    # cannot meet four axes one group at a time
    assert rows[0]["fraction"] == 1.0 and rows[1]["estimator"] == "monte-carlo" and rows[1]["samples"] == 400
    # the former spelling: the same answer and a one-line notice
    old = invoke(["ams", "summary", "--problem", str(path), "--json"])
    assert old.exit_code == 0 and json.loads(old.stdout) == summary
    assert old.stderr.strip() == "alloc ams: note: --problem is deprecated; use --vehicle NAME|FILE"


def test_ams_coverage_of_every_method_skips_what_the_vehicle_cannot_run(monkeypatch):
    import alloc.ams.cli as ams_cli

    monkeypatch.setattr(ams_cli, "registered_methods", lambda: ["pinv", "daisy"])
    res = invoke(["ams", "coverage", "--vehicle", "hexa-x", "--json"])
    assert res.exit_code == 0, res.stderr
    assert [r["method"] for r in json.loads(res.stdout)] == ["pinv"]
    assert res.stderr.startswith("alloc ams coverage: note: daisy skipped on hexa-x: groups:")
    assert_one_line_error(invoke(["ams", "coverage", "--vehicle", "hexa-x", "--method", "daisy"]), "groups", "hexa-x")


# ------------------------------------------------------------------ the catalogue, extended
def test_vehicle_path_adds_a_name_every_command_reads(tmp_path):
    folder = tmp_path / "fleet"
    folder.mkdir()
    path = write_quad(folder)
    (folder / "notes.txt").write_text("not a vehicle")
    env = {vehicles.VEHICLE_PATH_ENV: f"{tmp_path / 'absent'}{__import__('os').pathsep}{folder}"}
    listed = ok_json(["vehicles", "--json"], env)
    row = next(r for r in listed if r["name"] == "my-quad")
    assert row["origin"] == str(path) and row["k"] == 4 and row["daisy_groups"] == [["m1", "m2"], ["m3", "m4"]]
    assert [r["name"] for r in listed][:6] == ["ice", "ice-design", "ice-mid", "harv", "hexa-x", "tailless"]
    d = csv([0.1, -0.1, 0.01, -9.81])
    by_name = ok_json(["allocate", "--vehicle", "my-quad", "--v", d, "--method", "daisy", "--json", "--repeat", "2"],
                      env)
    by_path = ok_json(["allocate", "--vehicle", str(path), "--v", d, "--method", "daisy", "--json", "--repeat", "2"])
    assert by_name["u"] == by_path["u"]
    assert ok_json(["ams", "summary", "--vehicle", "my-quad", "--json"], env)["k"] == 4
    unknown = assert_one_line_error(invoke(["allocate", "--vehicle", "my-quad", "--v", d]), "unknown 'my-quad'")
    assert "known: ice, ice-design, ice-mid, harv, hexa-x, tailless" in unknown


def test_a_name_defined_twice_is_refused_naming_both(tmp_path):
    write_quad(tmp_path, "ice.toml", name="ice")
    env = {vehicles.VEHICLE_PATH_ENV: str(tmp_path)}
    line = assert_one_line_error(invoke(["allocate", "--vehicle", "ice", "--v", "0,0,0"], env),
                                 "'ice' is defined 2 times", "bundled ice.toml", str(tmp_path / "ice.toml"))
    assert "rename" in line
    assert ok_json(["allocate", "--vehicle", "harv", "--v", "0,0,0", "--json", "--repeat", "2"], env)["u"]


def test_entry_points_add_vehicles(tmp_path, monkeypatch):
    module = "alloc_test_fleet_plugin"
    quad = write_quad(tmp_path)
    (tmp_path / f"{module}.py").write_text(
        "import tomllib\n"
        f"PATH = {str(quad)!r}\n"
        "NUMBER = 3\n"
        "def make():\n"
        "    with open(PATH, 'rb') as fh:\n"
        "        doc = tomllib.load(fh)\n"
        "    return {**doc, 'name': 'ep-quad'}\n"
        "def broken():\n"
        "    return ['not', 'a', 'document']\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    group = vehicles.ENTRY_POINT_GROUP
    eps = tuple(EntryPoint(n, f"{module}:{attr}", group)
                for n, attr in (("ep-quad", "make"), ("ep-file", "PATH"), ("ep-number", "NUMBER"),
                                ("ep-broken", "broken"), ("ep-missing", "absent")))
    monkeypatch.setattr(vehicles, "_entry_points", lambda: eps)
    assert vehicles.names()[-5:] == ["ep-quad", "ep-file", "ep-number", "ep-broken", "ep-missing"]
    expected = load_vehicle(quad).problem()
    for name in ("ep-quad", "ep-file"):
        p = vehicles.problem(name)
        assert p.B.tobytes() == expected.B.tobytes() and p.names == expected.names
        assert vehicles.daisy_groups(name) == [["m1", "m2"], ["m3", "m4"]]
    assert vehicles.get_vehicle("ep-quad").name == "ep-quad"
    for name, reason in (("ep-number", "is a int; expected a path or a callable"),
                         ("ep-broken", "returned a list; expected a vehicle document"),
                         ("ep-missing", "cannot be loaded")):
        with pytest.raises(alloc.ProblemError, match=reason) as info:
            vehicles.problem(name)
        assert info.value.field == "vehicle" and name in str(info.value)
    sys.modules.pop(module, None)


# ------------------------------------------------------------------ the simulator
def test_daisy_flies_its_groups_in_the_loop(tmp_path):
    """``alloc sim ice --method daisy`` flew pinv_scale bit for bit (no groups reached it)."""
    from sim.scenarios import get_scenario

    run = get_scenario("ice")
    kw = dict(duration=0.25, noise=False, failure="seed", failure_time=0.1)
    out = tmp_path / "daisy.csv"
    res = invoke(["sim", "ice", "--method", "daisy", "--duration", "0.25", "--no-noise", "--failure", "seed",
                  "--failure-time", "0.1", "--csv", str(out)])
    assert res.exit_code == 0, res.stderr
    grouped = run(method="daisy", method_options={"groups": vehicles.daisy_groups("ice")}, **kw)
    grouped.to_csv(tmp_path / "grouped.csv")
    assert out.read_text() == (tmp_path / "grouped.csv").read_text()
    one_group = run(method="pinv_scale", **kw)
    assert np.abs(grouped.effectors - one_group.effectors).max() > 1.0  # deg: a different allocator flew


# ------------------------------------------------------------------ the comparison
def test_bench_openloop_reads_a_users_file_with_its_defaults(tmp_path):
    from benchmarks.compare.openloop import run_open
    from benchmarks.compare.sweep import open_spec

    path = write_quad(tmp_path)
    sizes = ["--samples", "100", "--demands", "10", "--steps", "10"]
    rows = ok_json(["bench", "openloop", "--vehicle", str(path), "--method", "pinv", "--method", "daisy", "--json",
                    *sizes])
    for row, method in zip(rows, ["pinv", "daisy"], strict=True):
        spec = {**open_spec("my-quad", method, samples=100, demands=10, steps=10), "vehicle": str(path)}
        assert row == run_open(spec)[0]
    assert rows[1]["problem"] == "my-quad"
    # B is square and invertible: pinv (and daisy as one group) reach the whole AMS; the file's groups do not
    assert rows[0]["coverage"] == 1.0 and rows[1]["coverage"] < 1.0


# ------------------------------------------------------------------ errors: one line, exit 2
def test_error_cases_are_one_line_exit_2(tmp_path):
    quad = write_quad(tmp_path)
    bare = write_quad(tmp_path, "bare.toml", groups=False, name="bare")
    bad = tmp_path / "bad.toml"
    bad.write_text(quad_text().replace("rate_max = 8.0", "rate_max = -1.0", 1))
    problem = tmp_path / "p.json"
    problem.write_text(json.dumps({"B": [[1.0]], "umin": [-1.0], "umax": [1.0]}))
    hover = csv([0.0, 0.0, 0.0, -19.62])
    cases = [
        (["allocate", "--vehicle", "hexa-x", "--method", "daisy", "--v", hover], ("groups", "hexa-x")),
        (["allocate", "--vehicle", str(bare), "--method", "daisy", "--v", hover], ("groups", "'bare'")),
        (["allocate", "--vehicle", str(tmp_path / "absent.toml"), "--v", "0"], ("absent.toml",)),
        (["allocate", "--vehicle", "f22", "--v", "0"], ("unknown 'f22'",)),
        (["allocate", "--vehicle", str(bad), "--v", hover], ("effectors[0].rate_max", "bad.toml")),
        (["allocate", "--vehicle", "ice", "--problem", str(problem), "--v", "0"], ("exactly one",)),
        (["ams", "summary", "--vehicle", "ice", "--problem", "ice"], ("--vehicle only",)),
        (["ams", "plot", "--vehicle", "hexa-x", "--method", "daisy", "--out", str(tmp_path / "a.png")], ("groups",)),
        (["sim", "--vehicle", str(quad)], ("vehicle my-quad: no [model] section", "linear model")),
        (["sim", "--vehicle", "hexa-x", "--failure", "float:motor9"], ("float:motor9", "hexa-x")),
        (["sim", "ice", "--vehicle", "ice"], ("one of them",)),
        (["sim", "harv_lon", "--method", "daisy", "--duration", "0.1"], ("groups",)),
        (["bench", "openloop", "--vehicle", "hexa-x", "--method", "daisy"], ("groups",)),
        (["bench", "openloop", "--vehicle", "nope"], ("unknown 'nope'",)),
    ]
    for args, tokens in cases:
        assert_one_line_error(invoke(args), *tokens)
    assert not (tmp_path / "a.png").exists()


def _hostile_vehicle_arguments(tmp_path: Path, n: int) -> list[str]:
    """Seeded: names that are no vehicle, paths that are no vehicle file, and malformed files."""
    rng = random.Random(SEED)
    valid = quad_text()
    mutations = [
        lambda t: t.replace("min = 0.0", "min = 2.0", 1),                       # max below min
        lambda t: t.replace('format = "alloc-vehicle/1"', 'format = "alloc-vehicle/9"'),
        lambda t: t.replace("ct = 4.0", "ct = -4.0", 1),
        lambda t: t.replace('["m1", "m2"]', '["m1", "m9"]'),                     # a group naming no effector
        lambda t: t.replace('name = "thrust"', 'name = "roll"'),                 # duplicate axis
        lambda t: t.replace("rate_max = 8.0", 'rate_max = "fast"', 1),
        lambda t: t[: rng.randrange(20, len(t) - 20)],                           # truncated
        lambda t: t.replace("[[axes]]", "[[axis]]", 1),
        lambda t: t.replace("trim = -9.81", "trim = nan"),
        lambda t: "\x00\xff" + t,
    ]
    out: list[str] = []
    for i in range(n):
        kind = rng.randrange(4)
        if kind == 0:
            out.append("".join(rng.choice("abcXYZ_-.é 9") for _ in range(rng.randrange(1, 12))))
        elif kind == 1:
            out.append(str(tmp_path / f"missing{i}{rng.choice(['.toml', '.json', '.params'])}"))
        elif kind == 2:
            out.append(str(tmp_path))  # a folder
        else:
            path = tmp_path / f"hostile{i}{rng.choice(['.toml', '.json'])}"
            text = rng.choice(mutations)(valid)
            if path.suffix == ".json":
                text = text if rng.random() < 0.5 else json.dumps({"format": "alloc-vehicle/1", "name": "x"})
            path.write_bytes(text.encode("utf-8", "surrogatepass"))
            out.append(str(path))
    return out


def test_hostile_vehicle_arguments_are_refused_in_one_line(tmp_path):
    args = _hostile_vehicle_arguments(tmp_path, 40)
    for i, source in enumerate(args):
        with pytest.raises(alloc.ProblemError):
            vehicles.get_vehicle(source)
        command = ["allocate", "--vehicle", source, "--v", "0,0,0,0"] if i % 2 else ["ams", "summary", "--vehicle",
                                                                                      source]
        assert_one_line_error(invoke(command), "--vehicle")


def test_user_options_override_vehicle_defaults_one_by_one():
    """Seeded: method_options(v, m, user) == {**defaults, **user} for every vehicle and method."""
    rng = random.Random(SEED)
    for _ in range(60):
        name = rng.choice(vehicles.names())
        v = vehicles.get_vehicle(name)
        method = rng.choice(["daisy", "qp", "cgi", "lp", "pinv"])
        user: dict[str, Any] = {}
        if rng.random() < 0.5:
            user["priorities"] = [rng.randint(1, 3) for _ in range(v.k)]
        if rng.random() < 0.5:
            user["groups"] = [list(v.effector_names)]
        defaults = v.method_options(method)
        if method == "daisy" and "groups" not in defaults and "groups" not in user:
            with pytest.raises(alloc.OptionError, match="groups") as info:
                vehicles.method_options(v, method, user)
            assert info.value.field == "groups"
            continue
        merged = vehicles.method_options(name, method, user)
        assert merged == {**defaults, **user}
        assert v.method_options(method) == defaults  # the vehicle's defaults are never changed

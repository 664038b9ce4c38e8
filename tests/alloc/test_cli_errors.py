"""Every invalid input of every ``alloc`` command: one line on stderr naming the field, exit 2.

Seeded generators build invalid problem files (``alloc allocate --problem``) and invalid
option values for ``alloc allocate``, ``alloc ams ...``, ``alloc sim``, ``alloc bench ...``
and the arguments of ``alloc serve`` (no server is started: the service's ``serve`` and the
sweep runner are replaced by stubs that fail the test if reached).  Most cases run in
process through typer's ``CliRunner``; a few run the installed command in a subprocess.
"""

from __future__ import annotations

import json
import os
import random
import subprocess
import sys
from pathlib import Path
from typing import Any
from collections.abc import Callable

import pytest
from typer.testing import CliRunner

from alloc.cli import app

ULOG = Path(__file__).resolve().parent / "data" / "px4_sitl_quad.ulg"  # tests/alloc/test_import_ulog.py
REPO = Path(__file__).resolve().parents[2]
runner = CliRunner()
SEED = 20261201
BIG_INT = "1" + "0" * 400  # beyond float64 (issue 22: -o gamma=10**400 exited 0)


def invoke(args: list[str]) -> Any:
    res = runner.invoke(app, args, prog_name="alloc")
    res.cli_args = args
    return res


def assert_one_line_error(res: Any, *tokens: str) -> str:
    """Exit 2, exactly one non-empty stderr line holding every token (``a|b``: either), no traceback."""
    where = f"args {getattr(res, 'cli_args', '?')}: stdout {res.stdout[:500]!r} stderr {res.stderr!r}"
    assert res.exit_code == 2, where
    assert res.exception is None or isinstance(res.exception, SystemExit), where
    lines = [line for line in res.stderr.splitlines() if line.strip()]
    assert len(lines) == 1, where
    assert "Traceback" not in res.stdout + res.stderr, where
    for token in tokens:
        assert any(t in lines[0] for t in token.split("|")), where
    return lines[0]


@pytest.fixture(scope="module", autouse=True)
def no_server_no_sweep() -> Any:
    """A case that passed validation by mistake must not start a server or a sweep."""
    import benchmarks.compare.runner as bench_runner
    import benchmarks.compare.throughput as throughput
    import service.main

    def refuse(*args: Any, **kwargs: Any) -> None:
        raise AssertionError("an invalid input reached the work it should have stopped")

    saved = service.main.serve, bench_runner.run_sweep, throughput.measure_scaling
    service.main.serve = bench_runner.run_sweep = throughput.measure_scaling = refuse
    yield
    service.main.serve, bench_runner.run_sweep, throughput.measure_scaling = saved


@pytest.fixture(scope="module", autouse=True)
def warm_default_method() -> None:
    """Load the default method's kernels once, so that no case prints their one-off progress line."""
    import alloc
    from alloc.registry import DEFAULT_METHOD
    from alloc.vehicles import ice

    alloc.make_allocator(ice(), DEFAULT_METHOD)([0.0, 0.0, 0.0])


# ------------------------------------------------------------------ problem files
def _valid_problem(rng: random.Random) -> dict[str, Any]:
    k, m = rng.randint(1, 3), rng.randint(3, 6)
    return {"B": [[round(rng.uniform(-2, 2), 3) for _ in range(m)] for _ in range(k)],
            "umin": [-1.0] * m, "umax": [1.0] * m, "names": [f"u{j}" for j in range(m)]}


def _text(problem: dict[str, Any]) -> str:
    return json.dumps(problem)


# each mutation: (name, function of (problem, rng) -> file bytes, a token the message must hold)
def _umin_above_umax(p: dict, rng: random.Random) -> bytes:
    j = rng.randrange(len(p["umin"]))
    p["umin"][j], p["umax"][j] = 1.0, -1.0
    return _text(p).encode()


def _literal(word: str) -> Callable[[dict, random.Random], bytes]:
    def mutate(p: dict, rng: random.Random) -> bytes:
        p["B"][0][rng.randrange(len(p["B"][0]))] = "@@"
        return _text(p).replace('"@@"', word).encode()
    return mutate


def _ragged(p: dict, rng: random.Random) -> bytes:
    p["B"].append(p["B"][0][:-1])
    return _text(p).encode()


def _duplicate_names(p: dict, rng: random.Random) -> bytes:
    p["names"][1] = p["names"][0]
    return _text(p).encode()


def _duplicate_key(p: dict, rng: random.Random) -> bytes:
    text = _text(p)
    return (text[:-1] + ', "umax": ' + json.dumps(p["umax"]) + "}").encode()


def _non_utf8(p: dict, rng: random.Random) -> bytes:
    p["names"][0] = "@@"
    return _text(p).encode().replace(b"@@", bytes([rng.choice([0xFF, 0xC3, 0x80, 0xFE])]))


def _deep(p: dict, rng: random.Random) -> bytes:
    depth = rng.choice([5_000, 100_000])
    return (_text(p)[:-1] + ', "up": ' + "[" * depth + "]" * depth + "}").encode()


def _wrong_length(field: str) -> Callable[[dict, random.Random], bytes]:
    def mutate(p: dict, rng: random.Random) -> bytes:
        p[field] = p[field] + [0.0]
        return _text(p).encode()
    return mutate


def _set(field: str, value: Any) -> Callable[[dict, random.Random], bytes]:
    def mutate(p: dict, rng: random.Random) -> bytes:
        p[field] = value
        return _text(p).encode()
    return mutate


def _drop(field: str) -> Callable[[dict, random.Random], bytes]:
    def mutate(p: dict, rng: random.Random) -> bytes:
        del p[field]
        return _text(p).encode()
    return mutate


def _whole(text: bytes) -> Callable[[dict, random.Random], bytes]:
    return lambda p, rng: text


def _truncated(p: dict, rng: random.Random) -> bytes:
    text = _text(p).encode()
    return text[: rng.randrange(1, len(text) - 1)]


PROBLEM_MUTATIONS: list[tuple[str, Callable[[dict, random.Random], bytes], str]] = [
    ("umin > umax", _umin_above_umax, "umin"),
    ("NaN literal", _literal("NaN"), "NaN"),
    ("Infinity literal", _literal("Infinity"), "Infinity"),
    ("-Infinity literal", _literal("-Infinity"), "Infinity"),
    ("1e400", _literal("1e400"), "float64"),
    ("big integer", _literal(BIG_INT), "float64"),
    ("text in B", _literal('"x"'), "B"),
    ("null in B", _literal("null"), "B"),
    ("true in B", _literal("true"), "B"),
    ("nested list in B", _literal("[1]"), "B"),
    ("ragged B", _ragged, "B"),
    ("duplicate names", _duplicate_names, "names"),
    ("duplicate JSON key", _duplicate_key, "duplicate key"),
    ("non-UTF-8", _non_utf8, "UTF-8"),
    ("deep nesting", _deep, "--problem"),
    ("umin too long", _wrong_length("umin"), "umin"),
    ("names too long", _wrong_length("names"), "names"),
    ("up outside limits", _set("up", None), "--problem"),
    ("Wu wrong shape", _set("Wu", [[1.0]]), "Wu"),
    ("rate_max negative", _set("rate_max", [-1.0] * 7), "rate_max"),
    ("unknown field", _set("Bee", 1), "Bee"),
    ("missing B", _drop("B"), "B"),
    ("missing umax", _drop("umax"), "umax"),
    ("a list", _whole(b"[1, 2, 3]"), "JSON object"),
    ("a number", _whole(b"3"), "JSON object"),
    ("empty file", _whole(b""), "--problem"),
    ("only a BOM", _whole(b"\xef\xbb\xbf{}"), "--problem"),
    ("truncated", _truncated, "--problem"),
    ("file v wrong length", _set("v", [1.0] * 9), "v"),
    ("file method unknown", _set("method", "nope"), "nope"),
    ("file options not an object", _set("options", [1]), "options"),
    ("file dt negative", _set("dt", -1.0), "dt"),
]


def _problem_cases(n: int) -> list[tuple[str, int]]:
    rng = random.Random(SEED)
    cases = [(name, i) for i, (name, _, _) in enumerate(PROBLEM_MUTATIONS)]  # every kind once
    cases += [(PROBLEM_MUTATIONS[j][0], j) for j in (rng.randrange(len(PROBLEM_MUTATIONS)) for _ in range(n))]
    return [(name, 1000 * s + j) for s, (name, j) in enumerate(cases)]


@pytest.mark.parametrize("name,case", _problem_cases(24))
def test_invalid_problem_file_is_one_line_exit_2(tmp_path: Path, name: str, case: int) -> None:
    rng = random.Random(case)
    kind, mutate, token = PROBLEM_MUTATIONS[case % 1000]
    problem = _valid_problem(rng)
    k = len(problem["B"])
    data = mutate(problem, rng)
    path = tmp_path / "p.json"
    path.write_bytes(data)
    args = ["allocate", "--problem", str(path)]
    if kind == "up outside limits":  # up = 2 on [-1, 1]: a value check, not a syntax one
        path.write_text(_text({**problem, "up": [2.0] * len(problem["umin"])}))
    if kind == "rate_max negative":
        path.write_text(_text({**problem, "rate_max": [-1.0] * len(problem["umin"])}))
    if not kind.startswith("file v") and not kind.startswith("file dt"):
        args += ["--v", ",".join(["0.1"] * k)]
    if kind == "file dt negative":
        path.write_text(_text({**problem, "dt": -1.0, "v": [0.1] * k, "u_prev": [0.0] * len(problem["umin"])}))
    line = assert_one_line_error(invoke(args), token)
    assert line.startswith("alloc allocate: error: "), line


def test_problem_file_paths_that_are_not_files(tmp_path: Path) -> None:
    assert_one_line_error(invoke(["allocate", "--problem", str(tmp_path / "absent.json"), "--v", "1"]),
                          "--problem", "absent.json")
    assert_one_line_error(invoke(["allocate", "--problem", str(tmp_path), "--v", "1"]), "--problem")


def test_problem_file_demand_and_flag_conflict(tmp_path: Path) -> None:
    path = tmp_path / "p.json"
    path.write_text(json.dumps({"B": [[1.0, 1.0]], "umin": [-1, -1], "umax": [1, 1], "v": [0.5]}))
    assert_one_line_error(invoke(["allocate", "--problem", str(path), "--v", "0.5"]), "--v", "both")
    ok = invoke(["allocate", "--problem", str(path), "--json", "--repeat", "3"])  # the file's own v
    assert ok.exit_code == 0, ok.output
    data = json.loads(ok.stdout)
    assert data["v"] == [0.5] and data["status"] == "exact" and data["method"] == "qp"  # DEFAULT_METHOD
    assert data["v_achieved"] == pytest.approx([0.5], abs=1e-12) and data["timed_calls"] == 3


# ------------------------------------------------------------------ option values
NAN_INF = ["nan", "NaN", "inf", "-inf", "Infinity"]
NOT_NUMBERS = ["abc", "", " ", "1,2", "0x10", "--"]


def _option_cases(tmp: Path) -> list[tuple[list[str], list[str], tuple[str, ...]]]:
    """(command, candidate bad values for the last flag, tokens the message must hold)."""
    existing = tmp / "exists.png"
    existing.write_bytes(b"png")
    sweep = tmp / "sweep"
    sweep.mkdir()
    (sweep / "specs.json").write_text('[{"id": "a", "kind": "closed", "scenario": "ice"}]')
    (sweep / "run.json").write_text("{}")
    bad_specs = tmp / "bad_specs"
    bad_specs.mkdir()
    (bad_specs / "specs.json").write_text('{"id": 1}')
    (bad_specs / "run.json").write_text("{}")
    not_json = tmp / "not_json"
    not_json.mkdir()
    (not_json / "specs.json").write_text("[NaN]")
    (not_json / "run.json").write_text("{}")
    full = tmp / "full"
    full.mkdir()
    (full / "report.md").write_text("x")
    ice = ["allocate", "--vehicle", "ice", "--v", "2,30,0.5"]
    sim = ["sim", "ice", "--duration", "0.01"]
    return [
        (["allocate", "--vehicle", "ice", "--v"], ["nan,1,2", "1,2", "a,b,c", "1e400,0,0", ",,", "1,2,3,4"], ("v",)),
        (ice + ["--dt"], ["0", "-1", "1e400", *NAN_INF, *NOT_NUMBERS[:2]], ("--dt",)),
        (ice + ["--repeat"], ["0", "-5", "1e3", "x", BIG_INT, "1000001"], ("--repeat",)),
        (ice + ["--option"], ["gamma", "=1", f"gamma={BIG_INT}", "gamma=1e400", "gamma=NaN", "gamma=Infinity",
                              "x=1"], ("--option|x",)),
        (ice + ["-m", "wls", "--option"], ["gamma=-1", "gamma=[1]", "gamma=true", "gamma=1e300", "gamma=abc"],
         ("gamma",)),
        (ice + ["--method"], ["nope", "", "QP", "pinv "], ("method",)),
        (["allocate", "--v", "1", "--vehicle"], ["nope", "", "ICE!"], ("--vehicle",)),
        (ice + ["--dt", "0.01", "--u-prev"], ["0,0", "nan," * 10 + "0", "x"], ("u_prev|--u-prev",)),
        (["ams", "coverage", "--method", "pinv", "--samples"], ["-5", "0", "abc", "1000001", BIG_INT],
         ("--samples",)),
        (["ams", "coverage", "--method", "pinv", "--seed"], ["-1", "x", "1.5"], ("--seed",)),
        (["ams", "coverage", "--method"], ["nope", ""], ("method",)),
        (["ams", "summary", "--problem"], ["nope", ""], ("--problem",)),
        (["ams", "plot", "--problem", "harv", "--out"], [str(existing), str(tmp / "no" / "x.png"), str(tmp)],
         ("--out",)),
        (["ams", "plot", "--problem", "harv", "--out", str(tmp / "new.png"), "--samples"], ["-1", "0", "x"],
         ("--samples",)),
        (["ams", "plot", "--out", str(tmp / "new.png"), "--problem"], ["nope"], ("--problem",)),
        (["sim"], ["nope", "ICE", ""], ("SCENARIO",)),
        (sim + ["--failure"], ["nope", "", "failure2"], ("--failure",)),
        (["sim", "ice", "--duration"], ["0", "-1", "1e9", *NAN_INF, "x"], ("--duration",)),
        (sim + ["--failure", "seed", "--failure-time"], ["-1", "0.01", "5", *NAN_INF], ("--failure-time",)),
        (sim + ["--failure-time"], ["0.001"], ("--failure-time",)),
        (sim + ["--seed"], ["-1", "x", str(2**32)], ("--seed",)),
        (sim + ["--frame-rate"], ["0", "-1", *NAN_INF, "x", "300"], ("frame",)),
        (sim + ["--pilot-gain"], ["-1", *NAN_INF], ("--pilot-gain",)),
        (sim + ["--pilot-delay"], ["-1", "100", *NAN_INF], ("--pilot-delay",)),
        (sim + ["--json"], [str(existing), str(tmp / "no" / "x.json"), str(tmp)], ("--json",)),
        (sim + ["--json", str(tmp / "a.json"), "--csv"], [str(tmp / "a.json")], ("--csv",)),
        (sim + ["--controller"], ["nope", ""], ("controller",)),
        (sim + ["--pilot"], ["nope"], ("pilot",)),
        (sim + ["--rate-window"], ["nope"], ("rate_window",)),
        (sim + ["--anti-windup"], ["nope"], ("anti_windup",)),
        (sim + ["--boundary-layer"], ["nope"], ("boundary_layer",)),
        (sim + ["--u-prev"], ["nope"], ("u_prev",)),
        (sim + ["--preferred"], ["nope"], ("preferred",)),
        (sim + ["--method"], ["nope"], ("method",)),
        (["sim", "harv_latdir_failure2", "--failure", "none", "--failure-time"], ["1"], ("--failure-time",)),
        (["bench", "report"], [str(tmp / "absent"), str(existing), str(tmp), str(sweep), str(bad_specs),
                               str(not_json)], ("DIR",)),
        (["bench", "scaling", "--workers"], ["a", "0", "1,x", "-1", "257", ""], ("--workers",)),
        (["bench", "scaling", "--runs"], ["1", "x", "-3"], ("--runs",)),
        (["bench", "scaling", "--engine"], ["nope"], ("--engine",)),
        (["bench", "full", "--dry-run", "--seeds"], ["1", "x", "1001"], ("--seeds",)),
        (["bench", "full", "--dry-run", "--frame-rates"], ["nan", "0", "-5", "x", "100,100", "inf"],
         ("--frame-rates",)),
        (["bench", "quick", "--workers"], ["0", "x", "100000"], ("--workers",)),
        (["bench", "smoke", "--timing-calls"], ["5", "x"], ("--timing-calls",)),
        (["bench", "smoke", "--no-timing", "--out"], [str(full)], ("--out",)),
        (["serve", "--port"], ["0", "-1", "65536", "99999999", "x", "1e3", BIG_INT], ("--port",)),
        (["serve", "--host"], ["a b", "-x", "", "a..b", "x" * 300, "1.2.3.4.5:80"], ("--host",)),
        (["serve", "--workers"], ["0", "65", "x"], ("--workers",)),
        (["serve", "--api-key-file"], [str(tmp / "absent"), str(tmp)], ("--api-key-file",)),
        (["serve", "--data-dir"], [str(existing)], ("--data-dir",)),
        (["serve", "--api-key"], ["secret"], ("--api-key",)),
        (["replay", "--ulog"], [str(tmp / "absent.ulg"), str(tmp), str(existing)], ("--ulog",)),
        (["replay", "--ulog", str(ULOG), "--method"], ["nope"], ("method",)),
        (["replay", "--ulog", str(ULOG), "--vehicle"], ["nope", str(tmp / "absent.toml")], ("vehicle",)),
        (["replay", "--ulog", str(ULOG), "--csv"], [str(existing)], ("--csv",)),
    ]


def test_every_invalid_value_of_every_flag(tmp_path: Path) -> None:
    seen = set()
    for prefix, values, tokens in _option_cases(tmp_path):
        for value in values:
            line = assert_one_line_error(invoke([*prefix, value]), *tokens)
            assert ": error: " in line, line
        seen.add(prefix[0] if prefix[0] != "ams" else " ".join(prefix[:2]))
    assert {"allocate", "ams coverage", "ams plot", "ams summary", "sim", "bench", "serve", "replay"} <= seen
    assert not (tmp_path / "new.png").exists() and not (tmp_path / "a.json").exists()  # nothing written


#: flags that take a number, with a valid rest of the command line
NUMERIC_FLAGS = [
    (["allocate", "--vehicle", "ice", "--v", "2,30,0.5", "--dt"], "--dt"),
    (["allocate", "--vehicle", "ice", "--v", "2,30,0.5", "--repeat"], "--repeat"),
    (["ams", "coverage", "--method", "pinv", "--samples"], "--samples"),
    (["ams", "coverage", "--method", "pinv", "--seed"], "--seed"),
    (["sim", "ice", "--duration"], "--duration"),
    (["sim", "ice", "--duration", "0.01", "--pilot-gain"], "--pilot-gain"),
    (["sim", "ice", "--duration", "0.01", "--frame-rate"], "--frame-rate"),
    (["bench", "scaling", "--runs"], "--runs"),
    (["bench", "full", "--dry-run", "--seeds"], "--seeds"),
    (["serve", "--port"], "--port"),
    (["serve", "--workers"], "--workers"),
]


def _garbage(rng: random.Random) -> str:
    """Text that is no number: digits, signs and dots around at least one foreign character."""
    pool = "0123456789.-+e "
    foreign = rng.choice("xyz#@!?%$&,;/\\'\"()[]{}\u00e9\u03c0\u2212\u00bd\U0001f600\x00")  # no whitespace: int(" 5\t") is 5
    word = [rng.choice(pool) for _ in range(rng.randint(0, 6))]
    word.insert(rng.randint(0, len(word)), foreign)
    return "".join(word)


def test_seeded_garbage_for_numeric_flags_and_two_errors_at_once(tmp_path: Path) -> None:
    rng = random.Random(SEED)
    cases = _option_cases(tmp_path)
    for _ in range(60):
        prefix, token = rng.choice(NUMERIC_FLAGS)
        value = _garbage(rng)
        if value.startswith("-"):
            value = "=" + value  # so that the parser cannot read it as a flag: --port=-x
            line = assert_one_line_error(invoke([*prefix[:-1], prefix[-1] + value]), token)
        else:
            line = assert_one_line_error(invoke([*prefix, value]), token)
        assert line.count(": error: ") == 1
    for _ in range(30):  # two invalid flags of one command: still one line, naming one of them
        prefix, values, tokens = rng.choice([c for c in cases if c[0][0] == "serve" and c[0][1] != "--api-key"])
        other, other_values, other_tokens = rng.choice([c for c in cases if c[0][0] == "serve"
                                                       and c[0][1] not in (prefix[1], "--api-key")])
        res = invoke([*prefix, rng.choice(values), *other[1:], rng.choice(other_values)])
        assert_one_line_error(res, "|".join(tokens + other_tokens))


def test_usage_errors_are_one_line_too() -> None:
    for args in (["nope"], ["allocate", "--nope"], ["allocate", "--vehicle"], ["ams", "nope"], ["bench", "nope"],
                 ["allocate", "--v", "1"], ["sim", "ice", "extra-arg"]):
        assert_one_line_error(invoke(args))


def test_big_integer_option_no_longer_exits_0() -> None:
    # issue 22: -o gamma=<10**400> exited 0 with every call falling back
    line = assert_one_line_error(invoke(["allocate", "--vehicle", "ice", "--v", "2,30,0.5", "-m", "wls",
                                         "-o", f"gamma={BIG_INT}"]), "gamma")
    assert "float64" in line


# ------------------------------------------------------------------ real processes
def _alloc_command() -> list[str]:
    script = Path(sys.executable).parent / "alloc"
    return [str(script)] if script.exists() else [sys.executable, "-c", "from alloc.cli import main; main()"]


def _run(args: list[str], cwd: Path) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    return subprocess.run(args, cwd=cwd, env=env, capture_output=True, text=True, timeout=300)


def _assert_process_one_line(proc: subprocess.CompletedProcess, token: str) -> None:
    lines = [line for line in proc.stderr.splitlines() if line.strip()]
    assert proc.returncode == 2, (proc.stdout, proc.stderr)
    assert len(lines) == 1 and token in lines[0] and "Traceback" not in proc.stderr, proc.stderr


def test_real_processes(tmp_path: Path) -> None:
    bad = tmp_path / "p.json"
    bad.write_text('{"B": [[1, 1]], "umin": [1, 0], "umax": [0, 1]}')
    _assert_process_one_line(_run([*_alloc_command(), "allocate", "--problem", str(bad), "--v", "0.5"], tmp_path),
                             "umin")
    _assert_process_one_line(_run([*_alloc_command(), "serve", "--port", "99999999"], tmp_path), "--port")
    _assert_process_one_line(_run([sys.executable, "-m", "benchmarks.compare", "report", str(tmp_path / "x")],
                                  tmp_path), "DIR")

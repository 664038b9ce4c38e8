"""Run settings defined once (sim.settings.RunSettings): every field has its CLI option with the same
default, a bad value is refused naming the field (library: SettingError; CLI: exit 2, one line), and
the recorded ``result.settings`` round-trip to the same run bit for bit."""

from __future__ import annotations

import inspect
import json
import math
import shlex
from dataclasses import fields
from pathlib import Path

import numpy as np
import pytest
import typer
from typer.testing import CliRunner

from alloc.cli import app as alloc_app
from alloc.exceptions import AllocError
from alloc.result import Status
from sim.cli import command_line, sim_command
from sim.cli_settings import cli_default, flag_of, from_cli, setting_fields, settings_table
from sim.result import STATUS_NAMES
from sim.scenarios import get_scenario
from sim.scenarios.mimo import run_mimo
from sim.settings import LoopSettings, LoopSpec, RunSettings, SettingError, setting_of, value_types

ROOT = Path(__file__).resolve().parents[2]
runner = CliRunner()
FIELDS = fields(RunSettings)


def _command() -> typer.main.TyperCommand:
    app = typer.Typer()
    app.command()(sim_command)
    return typer.main.get_command(app)


def test_every_setting_is_one_cli_option_with_the_same_default():
    params = {p.name: p for p in _command().params}
    assert [f.name for f in setting_fields()] == [n for n in params if n in {f.name for f in FIELDS}]
    for f in FIELDS:
        spec, param = setting_of(f.name), params[f.name]
        on, _, off = spec.flag.partition("/")
        assert on in param.opts and all(a in param.opts for a in spec.aliases), f.name
        assert param.secondary_opts == ([off] if off else []), f.name
        assert from_cli(f.name, param.default) == f.default == getattr(RunSettings(), f.name), f.name
        assert param.default == cli_default(f) and spec.help in param.help, f.name
        assert all(c in param.help for c in spec.choices), f.name
    # and nothing else of the command is a setting: the flags are unique
    flags = [o for p in _command().params for o in p.opts + p.secondary_opts]
    assert len(flags) == len(set(flags))


def test_run_mimo_takes_every_setting_with_its_default():
    params = inspect.signature(run_mimo).parameters
    for f in FIELDS:
        assert params[f.name].default == f.default and params[f.name].kind is inspect.Parameter.KEYWORD_ONLY
    # LoopSpec is the loop settings (inherited, with their defaults) plus the engine's objects
    loop = {f.name: f.default for f in fields(LoopSettings)}
    assert {f.name: f.default for f in fields(LoopSpec) if f.name in loop} == loop


def _bad_values(name: str, rng: np.random.Generator) -> list[object]:
    """Values setting ``name`` must refuse, from its type, choices and range (seeded)."""
    kinds, optional = value_types(name)
    spec = setting_of(name)
    bad: list[object] = [] if optional else [None]
    if bool in kinds:
        return bad + [1, 0, "yes", 1.0, [True]]
    if float in kinds or int in kinds:
        bad += [math.nan, math.inf, -math.inf, True, "1", [1.0], complex(1, 1)]
        span = 10.0 ** rng.uniform(-6, 3)
        if spec.low is not None:
            bad += [spec.low - span] + ([spec.low] if spec.low_open else [])
        if spec.high is not None:
            bad += [spec.high + span * max(1.0, spec.high)] + ([spec.high] if spec.high_open else [])
        if int in kinds and float not in kinds:
            bad += [float(spec.low or 0) + 0.5, 2.0]
        return bad
    if spec.choices:
        word = "".join(rng.choice(list("abcdefxyz_-"), size=int(rng.integers(1, 9))))
        bad += [word, spec.choices[0].upper(), spec.choices[0] + " ", ""]
    return bad + [3, 2.5, True, ["smc"]] if str in kinds else bad + [3, "a=1", ["a"]]


def _wrong_type(name: str, value: object) -> bool:
    """Whether ``value`` is of a type setting ``name`` does not take (a SettingTypeError, also a TypeError)."""
    kinds, optional = value_types(name)
    if value is None:
        return not optional
    if bool in kinds:
        return not isinstance(value, bool)
    if float in kinds or int in kinds:
        number = isinstance(value, int) or (float in kinds and isinstance(value, float))
        return isinstance(value, bool) or not number
    return not any(isinstance(value, k) for k in kinds)


@pytest.mark.parametrize("seed", range(3))
def test_a_bad_value_of_any_setting_is_refused_naming_the_field(seed):
    rng = np.random.default_rng(seed)
    refused = 0
    for f in FIELDS:
        for value in _bad_values(f.name, rng):
            with pytest.raises(SettingError) as info:
                RunSettings(**{f.name: value})
            err = info.value
            assert isinstance(err, (AllocError, ValueError)) and err.field == f.name, (f.name, value)
            assert str(err).startswith(f"{f.name}: "), (f.name, value, str(err))
            assert isinstance(err, TypeError) == _wrong_type(f.name, value), (f.name, value)
            refused += 1
    assert refused > 4 * len(FIELDS)


def test_cross_field_rules_are_checked():
    with pytest.raises(SettingError, match="frame_period: .* is not a positive multiple of dt") as info:
        RunSettings(frame_period=0.0007)
    assert info.value.field == "frame_period"
    assert RunSettings(frame_period=0.002, dt=0.00025).frame_steps() == 8
    from sim.scenarios.ice import SCENARIO

    with pytest.raises(SettingError) as info:
        run_mimo(SCENARIO, rate_window="sometimes")
    assert info.value.field == "rate_window"
    # the engine's own spec checks the same fields (LoopSpec inherits them)
    with pytest.raises(SettingError) as info:
        LoopSpec(scenario="x", vehicle=None, references=(), controller=None, commands=np.zeros((1, 0)),
                 failure=None, method="pinv", duration=1.0, u_prev_source="measured")
    assert info.value.field == "u_prev_source"
    with pytest.raises(SettingError, match="duration: ") as info:
        LoopSpec(scenario="x", vehicle=None, references=(), controller=None, commands=np.zeros((1, 0)),
                 failure=None, method="pinv", duration=-1.0)


def _cli_bad_words(name: str, rng: np.random.Generator) -> list[str]:
    """Bad command-line values of setting ``name`` (a text outside its choices, a number outside its range)."""
    spec, (kinds, _) = setting_of(name), value_types(name)
    if spec.choices:
        return ["x" + "".join(rng.choice(list("abcxyz"), size=3)), spec.choices[0].upper()]
    if spec.per_second:
        return ["0", "-5", "nan", "300"]  # 300 Hz: 3.33 ms is not a multiple of 0.5 ms
    if (float in kinds or int in kinds) and (spec.low is not None or spec.high is not None):
        words = ["nan", "inf"] if float in kinds else ["1.5"]
        if spec.low is not None:
            words.append(f"{spec.low - 1.0:g}")
        if spec.high is not None:
            words.append(f"{spec.high * 2 + 1:g}")
        return words
    return []


def test_the_cli_refuses_a_bad_setting_in_one_line_naming_it():
    rng = np.random.default_rng(7)
    checked = 0
    for f in FIELDS:
        for word in _cli_bad_words(f.name, rng):
            short = [] if f.name == "duration" else ["--duration", "0.01"]
            res = runner.invoke(alloc_app, ["sim", "ice", flag_of(f.name), word, *short])
            lines = [line for line in res.stderr.splitlines() if line.strip()]
            assert res.exit_code == 2 and len(lines) == 1, (f.name, word, res.stderr)
            assert flag_of(f.name) in lines[0] or f"{f.name}:" in lines[0], (f.name, word, lines[0])
            checked += 1
    assert checked >= 30


def _random_settings(rng: np.random.Generator, scenario: str) -> dict[str, object]:
    """Valid, varied and short settings for ``scenario`` (every field drawn from its choices or range)."""
    run = get_scenario(scenario)
    dt = float(rng.choice([0.0005, 0.00025, 0.001]))
    duration = float(rng.uniform(0.05, 0.25))
    out: dict[str, object] = {"dt": dt, "duration": duration, "seed": int(rng.integers(0, 2**32)),
                              "record_every": int(rng.integers(1, 20)),
                              "frame_period": None if rng.random() < 0.3 else dt * int(rng.integers(1, 9)),
                              "pilot_gain": None if rng.random() < 0.5 else float(rng.uniform(0.0, 3.0)),
                              "pilot_delay": None if rng.random() < 0.5 else float(rng.uniform(0.0, 0.3)),
                              "method": str(rng.choice(["pinv", "qp", "wls", "static", "cgi"]))}
    if rng.random() < 0.6:
        out["failure"] = str(rng.choice(sorted(run.failures)))
        out["failure_time"] = float(rng.uniform(0.0, duration * 0.8))
    for f in FIELDS:
        spec = setting_of(f.name)
        if f.name in out:
            continue
        if spec.choices:
            out[f.name] = str(rng.choice(spec.choices))
        elif isinstance(f.default, bool):
            out[f.name] = bool(rng.random() < 0.5)
    out["allocator_knows_failure"] = out["health"] == "told"  # one choice, two names (--told is --health told)
    return out


def _arrays(result) -> dict[str, np.ndarray]:
    return {k: v for k, v in vars(result).items() if isinstance(v, np.ndarray)}


@pytest.mark.parametrize("case", range(12))
def test_recorded_settings_round_trip_to_the_same_run(case):
    rng = np.random.default_rng(1000 + case)
    scenario = ["ice", "harv_lon", "harv_latdir"][case % 3]
    given = _random_settings(rng, scenario)
    first = get_scenario(scenario)(**given)
    record = first.settings
    # the world's draws are recorded when a world setting is not its default (sim.world)
    worldly = given.get("turbulence", "none") != "none"
    assert set(record) == {f.name for f in FIELDS} | {"pilots"} | ({"world"} if worldly else set())
    for name, value in given.items():  # what was given is recorded as given ...
        if name != "frame_period" and not (name == "failure_time" and "failure" not in given):
            assert record[name] == value, name
    assert record["frame_period"] == (given["frame_period"] or given["dt"])  # ... the frame period as flown
    assert json.loads(json.dumps(record)) == record
    again = RunSettings.from_record(record)
    second = get_scenario(scenario)(**{f.name: getattr(again, f.name) for f in FIELDS})
    assert second.settings == record
    first_arrays, second_arrays = _arrays(first), _arrays(second)
    assert first_arrays.keys() == second_arrays.keys()
    for name, values in first_arrays.items():
        assert np.array_equal(values, second_arrays[name], equal_nan=True), name


@pytest.mark.parametrize("case", range(2))
def test_the_recorded_settings_command_line_flies_the_same_run(case):
    rng = np.random.default_rng(2000 + case)
    scenario = ["ice", "harv_latdir"][case]
    result = get_scenario(scenario)(**_random_settings(rng, scenario))
    options = {k: v for k, v in result.settings.items() if k not in ("pilots", "world")}  # world: draws, not settings
    line = command_line(scenario, **options)
    res = runner.invoke(alloc_app, shlex.split(line)[1:])
    assert res.exit_code in (0, 1), (line, res.stderr)  # 1: the run diverged, as the library's did
    summary = json.loads(res.stdout)
    assert summary == json.loads(json.dumps(result.summary())), line


def test_status_names_are_alloc_status():
    assert STATUS_NAMES == tuple(s.value for s in Status)
    assert all(STATUS_NAMES.index(s) == i for i, s in enumerate(Status))


def test_the_docs_settings_table_is_the_generated_one():
    page = (ROOT / "docs" / "simulator.md").read_text()
    assert settings_table() in page

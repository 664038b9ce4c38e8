"""The ``alloc sim`` options of the run settings, derived from :class:`sim.settings.RunSettings`.

One typer option per field: its flag, type, default and help come from the field and its
:class:`sim.settings.Setting`; a number's range becomes the option's parser (checked before the
run, exit 2 with one line); the choices of a text setting are listed in the help and checked
when the settings are built (:func:`sim.scenarios.mimo.run_mimo`, before anything is flown).
:func:`with_setting_options` adds the options to a command; :func:`setting_words` turns
settings back into the command line that gives them.
"""

from __future__ import annotations

import functools
import inspect
import json
from collections.abc import Callable, Mapping
from dataclasses import Field, fields
from typing import Any, Optional, get_type_hints

import typer

from alloc.cli import finite, parse_options
from sim.settings import LoopSettings, RunSettings, Setting, setting_of, value_types

__all__ = ["setting_fields", "flag_of", "cli_default", "from_cli", "with_setting_options", "setting_words"]


def setting_fields() -> list[Field]:
    """The :class:`RunSettings` fields in help order: the runner's own (method, failure, ...), then the loop's."""
    loop = {f.name for f in fields(LoopSettings)}
    every = fields(RunSettings)
    return [f for f in every if f.name not in loop] + [f for f in every if f.name in loop]


def flag_of(name: str) -> str:
    """The option of setting ``name`` as a user types it (``--told/--blind`` -> ``--told``)."""
    return setting_of(name).flag.partition("/")[0]


def _is_mapping(f: Field) -> bool:
    return Mapping in value_types(f.name)[0]


def _cli_type(f: Field) -> Any:
    """The option's Python type: the setting's first (bool, int, float or str; Optional when it may be None),
    a list of ``key=value`` words for a mapping."""
    if _is_mapping(f):
        return list[str]
    kinds, optional = value_types(f.name)
    return Optional[kinds[0]] if optional else kinds[0]


def cli_default(f: Field) -> Any:
    """The option's default: the field's (``[]`` for a mapping, no ``--option`` given)."""
    return [] if _is_mapping(f) else f.default


def from_cli(name: str, value: Any) -> Any:
    """The setting's value from the option's (a rate in Hz to a period, ``key=value`` pairs to a dict)."""
    spec = setting_of(name)
    if value is None:
        return None
    if spec.per_second:
        return 1.0 / value
    if isinstance(value, list):
        return parse_options(value) or None
    return value


def _help(f: Field) -> str:
    """The option's help: the setting's, its choices, its range (typer prints an int's), what None means."""
    spec: Setting = setting_of(f.name)
    parts = [spec.help]
    if spec.choices:
        parts.append(f"one of: {', '.join(spec.choices)}")
    if spec.per_second:
        parts.append(f"given as its rate in Hz (> 0), 1 / {f.name}")
    elif spec.range_text() and _cli_type(f) not in (int, Optional[int]):
        parts.append(spec.range_text())
    elif spec.unit and not spec.range_text():
        parts.append(f"in {spec.unit}")
    if f.default is None and spec.none_means:
        parts.append(f"default: {spec.none_means}")
    return "; ".join(parts)


def _option(f: Field) -> Any:
    """The typer option of field ``f``."""
    spec = setting_of(f.name)
    kind = _cli_type(f)
    extra: dict[str, Any] = {}
    if kind in (float, Optional[float]):
        if spec.per_second:  # a period in (0, inf) s is a rate in (0, inf) Hz
            extra["parser"] = finite(0.0, low_open=True, unit=" Hz")
        else:
            extra["parser"] = finite(spec.low, spec.high, low_open=spec.low_open, high_open=spec.high_open,
                                     unit=f" {spec.unit}" if spec.unit else "")
    elif kind in (int, Optional[int]):
        extra.update(min=spec.low, max=spec.high)
    return typer.Option(cli_default(f), spec.flag, *spec.aliases, help=_help(f), **extra)


def with_setting_options(command: Callable[..., None]) -> Callable[..., None]:
    """``command`` with one option per run setting, after its first two parameters.

    ``command`` takes ``settings``: a dict of the settings given on the command line (by field
    name, converted with :func:`from_cli`); a setting not given is not in it, so a scenario
    that does not take that setting is never handed it.
    """
    settings = setting_fields()
    names = [f.name for f in settings]

    @functools.wraps(command)
    def run(ctx: typer.Context, **kwargs: Any) -> None:
        given = {}
        for name in names:
            value = kwargs.pop(name)
            source = ctx.get_parameter_source(name)
            if source is not None and source.name == "COMMANDLINE":
                given[name] = from_cli(name, value)
        command(settings=given, **kwargs)

    hints = get_type_hints(command)
    own = [p.replace(annotation=hints[p.name]) for p in inspect.signature(command).parameters.values()
           if p.name != "settings"]
    added = [inspect.Parameter(f.name, inspect.Parameter.KEYWORD_ONLY, default=_option(f), annotation=_cli_type(f))
             for f in settings]
    context = inspect.Parameter("ctx", inspect.Parameter.KEYWORD_ONLY, annotation=typer.Context)
    params = [context] + [p.replace(kind=inspect.Parameter.KEYWORD_ONLY) for p in own[:2]] + added + \
             [p.replace(kind=inspect.Parameter.KEYWORD_ONLY) for p in own[2:]]
    run.__signature__ = inspect.Signature(params, return_annotation=None)  # type: ignore[attr-defined]
    run.__annotations__ = {p.name: p.annotation for p in params}
    return run


def setting_words(options: Mapping[str, Any]) -> list[str]:
    """The command-line words that give these settings (None values omitted).

    Raises ``TypeError`` for a key that is no setting.
    """
    words: list[str] = []
    for key, value in options.items():
        if value is None:
            continue
        try:
            spec = setting_of(key)
        except KeyError:
            raise TypeError(f"command_line: no flag for option {key!r}") from None
        on, _, off = spec.flag.partition("/")
        if off:
            words.append(on if value else off)
        elif spec.per_second:
            rate = 1.0 / value
            words += [spec.flag, f"{rate:g}" if float(f"{rate:g}") == rate else repr(rate)]
        elif isinstance(value, Mapping):
            for k, v in value.items():
                words += [spec.flag, f"{k}={v if isinstance(v, str) else json.dumps(v)}"]
        else:
            words += [spec.flag, str(value)]
    return words



def settings_table() -> str:
    """The run settings as a Markdown table (``docs/simulator.md`` holds it; a test keeps them equal)."""
    rows = ["| setting | option | default | allowed | verdict | meaning |", "|---|---|---|---|---|---|"]
    for f in setting_fields():
        spec = setting_of(f.name)
        options = " ".join(f"`{o}`" for o in (spec.flag, *spec.aliases))
        if f.default is None:
            default = spec.none_means or "none"
        elif isinstance(f.default, bool):
            default = spec.flag.partition("/")[0 if f.default else 2]
            default = f"`{default}`"
        else:
            default = f"`{f.default}`"
        if spec.choices:
            allowed = ", ".join(f"`{c}`" for c in spec.choices)
        elif spec.per_second:
            allowed = f"> 0 {spec.unit}, a multiple of dt (the option: its rate in Hz)"
        else:
            kind = value_types(f.name)[0][0]
            allowed = spec.range_text() or {bool: "true / false", str: "a name the scenario checks",
                                             Mapping: "key=value pairs"}[kind]
        rows.append(f"| `{f.name}` | {options} | {default} | {allowed} | {'yes' if spec.verdict else 'no'} | "
                    f"{spec.help} |")
    return "\n".join(rows) + "\n"

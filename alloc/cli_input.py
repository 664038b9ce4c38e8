"""Input helpers shared by ``alloc``'s commands and its plugins' commands: a finite-number
parser, strict JSON (no NaN, no numbers beyond float64, no duplicate keys), bounded JSON files,
and output paths refused before any work is done.  Each failure is a ``typer.BadParameter``,
which :class:`alloc.cli.OneLineErrors` prints as one line with exit status 2."""

from __future__ import annotations

import json
import math
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any, NoReturn

import typer

from alloc._files import read_user_file
from alloc.exceptions import ProblemError

#: largest JSON input file read (a 32 x 512 problem is about 0.4 MB of JSON)
MAX_JSON_BYTES = 64 * 1024 * 1024


def finite(low: float | None = None, high: float | None = None, *, low_open: bool = False,
           high_open: bool = False, unit: str = "") -> Callable[[str], float]:
    """A typer ``parser`` for a finite real number in ``[low, high]`` (open ends on request).

    Click's own ``FloatRange`` lets ``nan`` and ``inf`` through; this one does not.  It raises
    ``BadParameter`` (a ``ValueError`` would reach the user as "Value error, ...").
    """
    def parse(text: str) -> float:
        if isinstance(text, float):  # a default, already parsed
            return text
        try:
            value = float(text)
        except (TypeError, ValueError):
            raise typer.BadParameter(f"expected a number, got {text!r}") from None
        if not math.isfinite(value):
            raise typer.BadParameter(f"must be a finite number, got {text!r}")
        below = low is not None and (value <= low if low_open else value < low)
        above = high is not None and (value >= high if high_open else value > high)
        if below or above:
            lo = "" if low is None else f"{'>' if low_open else '>='} {low:g}"
            hi = "" if high is None else f"{'<' if high_open else '<='} {high:g}"
            raise typer.BadParameter(f"must be {' and '.join(filter(None, [lo, hi]))}{unit}, got {text}")
        return value

    return parse


def _no_duplicate_keys(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for key, value in pairs:
        if key in out:
            raise ValueError(f"duplicate key {key!r}")
        out[key] = value
    return out


def _json_int(text: str) -> int:
    value = int(text)
    try:
        float(value)
    except OverflowError:
        raise ValueError(f"integer with {len(text.lstrip('-'))} digits is beyond float64") from None
    return value


def json_float(text: str) -> float:
    """A finite float64 from a JSON number's text (the CLI's comma lists read numbers the same way)."""
    value = float(text)
    if not math.isfinite(value):
        raise ValueError(f"number {text} is beyond float64")
    return value


def _json_constant(name: str) -> NoReturn:
    raise ValueError(f"{name} is not a JSON number (JSON has no NaN or infinity)")


def strict_json(text: str) -> Any:
    """Parse standard JSON: no ``NaN``/``Infinity``, no numbers beyond float64, no duplicate keys.

    Raises ``ValueError`` (a ``json.JSONDecodeError`` with its position where the syntax is
    wrong) naming the reason; nesting deeper than the parser can follow is one too.
    """
    try:
        return json.loads(text, object_pairs_hook=_no_duplicate_keys, parse_int=_json_int,
                          parse_float=json_float, parse_constant=_json_constant)
    except RecursionError:
        raise ValueError("nested too deeply") from None


def read_json_file(path: Path, param_hint: str) -> Any:
    """The JSON value in ``path`` (UTF-8, at most :data:`MAX_JSON_BYTES`), or a ``BadParameter``.

    Read through :func:`alloc._files.read_user_file`: a FIFO, a device or a directory is refused
    before it is opened for a blocking read.
    """
    def bad(reason: str) -> NoReturn:
        raise typer.BadParameter(f"{path}: {reason}", param_hint=param_hint)

    try:
        raw = read_user_file(path, field=param_hint, max_bytes=MAX_JSON_BYTES)
    except ProblemError as exc:
        bad(str(exc).removeprefix(f"{param_hint}: "))
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        bad(f"not UTF-8 text (byte {exc.start})")
    try:
        return strict_json(text)
    except ValueError as exc:
        bad(f"not valid JSON: {exc}")


def output_file(path: Path | None, force: bool, param_hint: str, *, taken: dict[Path, str] | None = None) -> None:
    """Refuse an output path before any work is done: an existing file (unless ``force``), a
    directory, a folder that does not exist or cannot be written, or a path given twice."""
    if path is None:
        return
    if path.is_dir():
        raise typer.BadParameter(f"{path} is a directory; give a file name", param_hint=param_hint)
    if path.exists() and not force:
        raise typer.BadParameter(f"{path} exists; choose another name or pass --force to overwrite it",
                                 param_hint=param_hint)
    parent = path.parent if str(path.parent) else Path(".")
    if not parent.is_dir():
        raise typer.BadParameter(f"folder {parent} does not exist", param_hint=param_hint)
    if not os.access(parent, os.W_OK):
        raise typer.BadParameter(f"folder {parent} is not writable", param_hint=param_hint)
    if taken is not None:
        key = path.resolve()
        if key in taken:
            raise typer.BadParameter(f"{path} is also the {taken[key]} output", param_hint=param_hint)
        taken[key] = param_hint

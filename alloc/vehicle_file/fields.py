"""The vehicle format's constants and its field readers: each checks one value and raises
:class:`~alloc.exceptions.ProblemError` naming the field's path (``effectors[3].rate_max``)."""

from __future__ import annotations

import math
import re
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from ..exceptions import ProblemError
from ..problem import MAX_MAGNITUDE, short_repr

#: the format this module reads and writes (a later, incompatible format gets a new number)
FORMAT = "alloc-vehicle/1"
#: format 1 with the optional ``[simulation]`` section (:mod:`~alloc.vehicle_file.simulation`); a
#: document is written in the oldest format that carries it (1 without the section)
FORMAT_SIMULATION = "alloc-vehicle/1.1"
#: format 1.1 with the optional ``[schedule]`` section (:mod:`~alloc.vehicle_file.schedule`): the
#: effectiveness as a function of named scheduling variables; written only when the section is there
FORMAT_SCHEDULE = "alloc-vehicle/1.2"
#: the formats this library reads
FORMATS = (FORMAT, FORMAT_SIMULATION, FORMAT_SCHEDULE)
#: the published JSON Schema of the format
SCHEMA_PATH = Path(__file__).parents[1] / "schemas" / "vehicle-1.schema.json"
#: the bundled vehicle files (the seed's aircraft): ``load_vehicle("ice")`` reads ``ice.toml`` here
DATA_DIR = Path(__file__).parents[1] / "data" / "vehicles"
#: what an effector is; informative (plots, importers), no method branches on it
EFFECTOR_KINDS = ("surface", "rotor", "thrust-vector", "thruster", "other")
#: the body-axis wrench components a rotor's geometry yields, in PX4's order (moments, then forces)
WRENCH_COMPONENTS = ("roll", "pitch", "yaw", "fx", "fy", "fz")

#: the most states, and the most outputs, of a vehicle's ``[model]``: checked on the document
#: before any matrix is read (an unbounded output list made the default ``D``, outputs x
#: effectors, as large as memory); the seed's models have at most 12 of each
MAX_MODEL_SIZE = 256

_NAME = re.compile(r"^[^\x00-\x1f\x7f]{1,64}$")


#: a matrix as the file holds it: rows of floats
Matrix = tuple[tuple[float, ...], ...]

# --------------------------------------------------------------------------- errors and readers
def _fail(path: str, message: str) -> ProblemError:
    return ProblemError(f"{path}: {message}", field=path)


def _table(value: Any, path: str) -> Mapping[str, Any]:
    if not isinstance(value, Mapping):
        raise _fail(path, f"expected a table (object), got {_kind(value)}")
    return value


def _kind(value: Any) -> str:
    if value is None:
        return "null"
    if isinstance(value, bool):
        return f"boolean {value!r}"
    if isinstance(value, str):
        return f"text {short_repr(value)}"
    if isinstance(value, Mapping):
        return "a table"
    if isinstance(value, (list, tuple)):
        return f"a list of {len(value)}"
    return f"{type(value).__name__} {short_repr(value)}"


_PLAIN_KEY = re.compile(r"^[A-Za-z_][A-Za-z0-9_-]{0,63}$")


def _child(path: str, key: Any) -> str:
    """The path of ``key`` below ``path``: ``effectors[0].rate_max``; a key that is not a plain
    name (empty, long, with spaces or dots) in brackets, elided: ``vehicle['']``, ``methods['a b']``."""
    if isinstance(key, str) and _PLAIN_KEY.match(key):
        return f"{path}.{key}" if path else key
    return f"{path or 'vehicle'}[{short_repr(key, 40)}]"


def _keys(table: Mapping[str, Any], path: str, allowed: Sequence[str], required: Sequence[str] = ()) -> None:
    unknown = [k for k in table if k not in allowed]
    if unknown:
        raise _fail(_child(path, unknown[0]), f"unknown field; accepted: {', '.join(allowed)}")
    for k in required:
        if k not in table:
            where = f"{path}." if path else ""
            raise _fail(f"{where}{k}", "required")


def _text(value: Any, path: str, *, name: bool = False) -> str:
    if not isinstance(value, str):
        raise _fail(path, f"expected text, got {_kind(value)}")
    try:
        value.encode("utf-8")
    except UnicodeEncodeError:
        raise _fail(path, "not valid Unicode text (lone surrogate)") from None
    if name and not _NAME.match(value):
        raise _fail(path, f"a name must be 1-64 characters without control characters, got {short_repr(value)}")
    return value


def _real(value: Any, path: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise _fail(path, f"expected a number, got {_kind(value)}")
    try:
        x = float(value)
    except OverflowError:
        raise _fail(path, f"{short_repr(value)} is too large (|x| <= {MAX_MAGNITUDE:g})") from None
    if not abs(x) <= MAX_MAGNITUDE:
        what = "must be finite" if not math.isfinite(x) else f"|x| must be <= {MAX_MAGNITUDE:g}"
        raise _fail(path, f"{what}, got {short_repr(value)}")
    return x


def _positive(value: Any, path: str) -> float:
    x = _real(value, path)
    if not x > 0.0:
        raise _fail(path, f"must be > 0, got {x:g}")
    return x


def _weight(value: Any, path: str) -> float:
    """A diagonal weight entry: positive and inside the weight domain (>= 1 / MAX_MAGNITUDE)."""
    w = _positive(value, path)
    if w < 1.0 / MAX_MAGNITUDE:
        raise _fail(path, f"must be >= {1.0 / MAX_MAGNITUDE:g}, got {w:g}")
    return w


def _list(value: Any, path: str, n: int | None = None, *, low: int = 0, high: int | None = None) -> list[Any]:
    if not isinstance(value, (list, tuple)):
        raise _fail(path, f"expected a list, got {_kind(value)}")
    if n is not None and len(value) != n:
        raise _fail(path, f"expected {n} entries, got {len(value)}")
    if len(value) < low:
        raise _fail(path, f"expected at least {low} entries, got {len(value)}")
    if high is not None and len(value) > high:
        raise _fail(path, f"expected at most {high} entries, got {len(value)}")
    return list(value)


def _reals(value: Any, path: str, n: int | None = None) -> tuple[float, ...]:
    return tuple(_real(x, f"{path}[{i}]") for i, x in enumerate(_list(value, path, n)))


def _matrix(value: Any, path: str, rows: int | None, cols: int | None) -> tuple[tuple[float, ...], ...]:
    out = []
    for i, row in enumerate(_list(value, path, rows)):
        out.append(_reals(row, f"{path}[{i}]", cols))
        if cols is None:
            cols = len(out[0])
    return tuple(out)


def _names(value: Any, path: str, n: int | None = None, *, high: int | None = None) -> tuple[str, ...]:
    names = tuple(_text(x, f"{path}[{i}]", name=True) for i, x in enumerate(_list(value, path, n, high=high)))
    _unique(names, path)
    return names


def _unique(names: Sequence[str], path: str) -> None:
    seen: dict[str, int] = {}
    for i, s in enumerate(names):
        if s in seen:
            raise _fail(f"{path}[{i}]", f"duplicate name {s!r} (also at index {seen[s]})")
        seen[s] = i

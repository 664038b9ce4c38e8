"""A small TOML writer for vehicle documents (the standard library reads TOML, it does not write it)."""

from __future__ import annotations

import json
import math
import re
from collections.abc import Mapping
from typing import Any


# --------------------------------------------------------------------------- writing TOML
_BARE_KEY = re.compile(r"^[A-Za-z0-9_-]+$")


def _key(k: str) -> str:
    return k if _BARE_KEY.match(k) else _string(k)


def _string(s: str) -> str:
    return json.dumps(s, ensure_ascii=False).replace("\x7f", "\\u007f")


def _value(v: Any, indent: str = "") -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return repr(v)
    if isinstance(v, str):
        return _string(v)
    if isinstance(v, Mapping):
        return "{ " + ", ".join(f"{_key(k)} = {_value(x)}" for k, x in v.items()) + " }" if v else "{}"
    if isinstance(v, (list, tuple)):
        if v and all(isinstance(x, (list, tuple)) for x in v):  # a matrix: one row a line
            inner = indent + "  "
            return "[\n" + "".join(f"{inner}{_value(x, inner)},\n" for x in v) + indent + "]"
        return "[" + ", ".join(_value(x, indent) for x in v) + "]"
    raise TypeError(f"cannot write {type(v).__name__} as TOML")


def _is_table(v: Any) -> bool:
    return isinstance(v, Mapping)


def _is_table_array(v: Any) -> bool:
    return isinstance(v, (list, tuple)) and bool(v) and all(isinstance(x, Mapping) for x in v)


def to_toml(doc: Mapping[str, Any]) -> str:
    """A document of tables, arrays of tables, strings, numbers, booleans and lists as TOML.

    Floats are written with ``repr`` so they read back bit for bit; ``None`` values are left
    out (TOML has no null).
    """
    lines: list[str] = []
    _emit(lines, [], doc)
    return "\n".join(lines).strip("\n") + "\n"


def _emit(lines: list[str], path: list[str], table: Mapping[str, Any]) -> None:
    for k, v in table.items():
        if v is None or _is_table(v) or _is_table_array(v):
            continue
        lines.append(f"{_key(k)} = {_value(v)}")
    for k, v in table.items():
        if _is_table_array(v):
            for item in v:
                lines.append("")
                lines.append(f"[[{'.'.join(_key(p) for p in (*path, k))}]]")
                for ik, iv in item.items():
                    if iv is not None:
                        lines.append(f"{_key(ik)} = {_value(iv)}")
    for k, v in table.items():
        if _is_table(v):
            only_tables = bool(v) and all(_is_table(x) for x in v.values())
            if not only_tables:  # a header with nothing under it but sub-tables is implied by theirs
                lines.append("")
                lines.append(f"[{'.'.join(_key(p) for p in (*path, k))}]")
            _emit(lines, [*path, k], v)

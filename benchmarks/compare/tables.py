"""The report's cells: numbers and intervals as text, Markdown tables (written and read back),
and the CSV written beside every figure."""

from __future__ import annotations

import csv
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["Row", "parse_markdown_table"]

Row = dict[str, Any]


def _fmt(x: Any, digits: int = 3) -> str:
    if x is None:
        return "-"
    if isinstance(x, bool):
        return "yes" if x else "no"
    if isinstance(x, (float, np.floating)):
        x = float(x)
        if math.isinf(x):
            return "inf"
        if math.isnan(x):
            return "-"
        if x == 0:
            return "0"
        return f"{x:.{digits}g}"
    return str(x)


def _ci(est: float, lo: float, hi: float) -> str:
    if math.isnan(est):
        return "-"
    return f"{_fmt(est)} [{_fmt(lo)}, {_fmt(hi)}]"


def _pct(x: float | None) -> str:
    return "-" if x is None or math.isnan(x) else f"{100 * x:.1f} %"


def _table(headers: Sequence[str], rows: Sequence[Sequence[Any]]) -> str:
    lines = ["| " + " | ".join(headers) + " |", "|" + "|".join("---" for _ in headers) + "|"]
    lines += ["| " + " | ".join(str(c) for c in r) + " |" for r in rows]
    return "\n".join(lines)


def parse_markdown_table(text: str, first_header: str) -> list[dict[str, str]]:
    """Rows of the first Markdown table in ``text`` whose first header cell is ``first_header``."""
    lines = text.splitlines()
    for i, line in enumerate(lines):
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if line.startswith("|") and cells[0] == first_header:
            out = []
            for body in lines[i + 2:]:
                if not body.startswith("|"):
                    break
                out.append(dict(zip(cells, (c.strip() for c in body.strip().strip("|").split("|")))))
            return out
    raise KeyError(f"no table with first header {first_header!r}")


def _write_csv(path: Path, rows: Sequence[Row]) -> None:
    with path.open("w", newline="") as fh:
        w = csv.DictWriter(fh, list(rows[0]) if rows else [], lineterminator="\n")
        w.writeheader()
        w.writerows(rows)


def _slug(text: str) -> str:
    return "".join(c if c.isalnum() or c in "-_." else "_" for c in text)

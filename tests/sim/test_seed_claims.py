"""The seed-claim table (benchmarks/seed_claims.py) and its generated page docs/seed-claims.md."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from benchmarks import seed_claims

ROOT = Path(__file__).resolve().parents[2]
_FIG = re.compile(r"Figs?\.?\s+((?:\d-\d+(?:\s*(?:/|,|\.\.|to|and)\s*)?)+)")
_NUMBER = re.compile(r"(\d)-(\d+)")


def _figures(text: str) -> set[str]:
    """Every ``N-M`` figure number a text mentions after "Fig"/"Figs", ranges (``2-21..2-25``) expanded."""
    out = set()
    for group in _FIG.findall(" ".join(text.split())):
        numbers = [(int(a), int(b)) for a, b in _NUMBER.findall(group)]
        ranged = ".." in group or " to " in group
        if ranged and len(numbers) == 2 and numbers[0][0] == numbers[1][0]:
            numbers = [(numbers[0][0], k) for k in range(numbers[0][1], numbers[1][1] + 1)]
        out |= {f"{a}-{b}" for a, b in numbers}
    return out


def test_figure_parser_expands_lists_and_ranges():
    assert _figures("seed Figs 2-19/2-20 and Fig 3-1; Figs\n 2-21..2-25, not") == {
        "2-19", "2-20", "3-1", "2-21", "2-22", "2-23", "2-24", "2-25"}
    assert _figures("Figs 4-67, 4-75.") == {"4-67", "4-75"}


def test_every_figure_the_tests_and_benchmarks_touch_is_in_the_table():
    sources = [*sorted((ROOT / "tests" / "sim").glob("*.py")), *sorted((ROOT / "benchmarks").glob("*.py"))]
    touched = set()
    for path in sources:
        if path.name not in ("seed_claims.py", Path(__file__).name):
            touched |= _figures(path.read_text())
    in_table = set().union(*(_figures(c.figure) for c in seed_claims.CLAIMS))
    assert touched <= in_table, sorted(touched - in_table)
    assert len({c.figure for c in seed_claims.CLAIMS}) == len(seed_claims.CLAIMS)


def test_docs_page_is_generated_from_the_committed_measurements():
    assert seed_claims.PAGE.read_text() == seed_claims.page(), \
        "regenerate: python -m benchmarks.seed_claims page"


def test_every_implemented_claim_is_measured_and_judged():
    measured = seed_claims.read_measured()
    for c in seed_claims.CLAIMS:
        if c.measure is None:
            assert c.figure not in measured and c.verdict({}) == "not implemented"
            continue
        verdict = c.verdict(measured[c.figure])
        assert verdict.startswith(("reproduced", "not reproduced")), (c.figure, verdict)


@pytest.mark.parametrize(("figure", "key", "value", "expected"), [
    ("Fig 3-3", "diverged", 0.0, "not reproduced"),
    ("Fig 3-10", "diverged", 1.0, "reproduced"),
    ("Fig 4-95", "time of divergence (s)", 4.5, "not reproduced"),
    ("Fig 3-18", "max bank difference after failure (rad)", 2e-3, "not reproduced"),
])
def test_a_verdict_follows_its_criterion(figure, key, value, expected):
    """Moving the deciding number across the criterion changes the verdict computed from the committed row."""
    claim = next(c for c in seed_claims.CLAIMS if c.figure == figure)
    numbers = {**seed_claims.read_measured()[figure], key: value}
    assert claim.verdict(numbers) == expected


@pytest.mark.slow
def test_a_cheap_claim_is_remeasured_as_committed():
    (claim,) = (c for c in seed_claims.CLAIMS if c.figure == "Fig 4-95")
    committed = seed_claims.read_measured()[claim.figure]
    assert claim.measure() == pytest.approx(committed, rel=1e-5)


@pytest.mark.slow
def test_every_claim_is_remeasured_as_committed():
    committed = seed_claims.read_measured()
    for c in seed_claims.CLAIMS:
        if c.measure is not None:
            assert c.measure() == pytest.approx(committed[c.figure], rel=1e-5, nan_ok=True), c.figure

"""The README is a front door: short, its example prints what its prose says, its method table is
the registry, its install lines name this project, and its links resolve."""

from __future__ import annotations

import contextlib
import io
import re
from pathlib import Path

import numpy as np
import pytest

import alloc

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
TEXT = README.read_text()


def _section(title: str) -> str:
    start = TEXT.index(f"\n## {title}")
    end = TEXT.find("\n## ", start + 1)
    return TEXT[start:end if end >= 0 else None]


def test_readme_is_a_front_door():
    assert len(TEXT.splitlines()) <= 200


def test_readme_example_prints_what_the_prose_says():
    block = re.search(r"```python\n(.*?)```", _section("Ten lines with your own `B`"), re.S).group(1)
    out = io.StringIO()
    namespace: dict = {}
    with contextlib.redirect_stdout(out):
        exec(compile(block, "README.md", "exec"), namespace)
    first, second = out.getvalue().splitlines()
    assert first.startswith("exact [") and second.startswith("unattainable [")
    demand = [14.7, 0.3, -0.2, 0.05]
    healthy = namespace["qp"](demand)
    assert healthy.status is alloc.Status.EXACT
    np.testing.assert_allclose(healthy.v_achieved, demand, atol=1e-9)
    failed = namespace["r"]
    assert failed.u[0] == 0.0 and failed.status is alloc.Status.UNATTAINABLE
    # the prose: thrust and roll met, 0.003 N m of pitch and 0.024 N m of yaw left over
    np.testing.assert_allclose(failed.unallocated, [0.0, 0.0, 0.003, 0.024], atol=5e-4)


def test_which_method_when_lists_every_registered_method_once():
    rows = re.findall(r"^\| `([a-z0-9_]+)` \| (.+) \|$", _section("Which method when"), re.M)
    names = [name for name, _ in rows]
    assert sorted(names) == sorted(alloc.methods()) and len(names) == len(set(names))
    assert all(len(reason) > 20 for _, reason in rows)


@pytest.mark.parametrize("path", ["README.md", *sorted(str(p.relative_to(ROOT)) for p in (ROOT / "docs").glob("*.md"))])
def test_install_lines_name_this_distribution(path):
    text = (ROOT / path).read_text()
    # `alloc` on the public index is an unrelated project
    assert not re.search(r"pip install\s+['\"]?alloc(?![-\w])", text), path
    if path == "README.md":
        assert "pip install alloc-toolkit" in text and "make install" in text and ". .venv/bin/activate" in text


def test_the_two_commands_are_make_test_and_make_run():
    blocks = "\n".join(re.findall(r"```bash\n(.*?)```", TEXT, re.S))
    assert re.search(r"^make test\b", blocks, re.M) and re.search(r"^make run\b", blocks, re.M)


def test_readme_links_resolve():
    links = re.findall(r"\]\(([^)#]+)(?:#[^)]*)?\)", TEXT)
    local = [link for link in links if not re.match(r"[a-z]+://", link)]
    assert any(link.startswith("docs/") for link in local)
    for link in local:
        assert (ROOT / link).exists(), link

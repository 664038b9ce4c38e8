"""Every command in the README runs as pasted, in a fresh folder, after the install lines.

The README's ```bash / ```sh / ```console blocks are run in order, each as one pasted script,
in a new temporary folder with the project's environment activated (its ``bin`` first on PATH),
so a block may use a file an earlier block wrote; the ```python blocks run there as scripts.
A block that must not run here is marked by an HTML comment on the line before it:

``<!-- not-run: REASON; covered by PATH::NAME[, PATH::NAME] -->``
    never run by this test (installs, servers, ``make test``, the full sweep); each PATH must
    exist and contain NAME, the test or command that covers the block.
``<!-- slow: REASON; covered by PATH::NAME -->``
    run only with ``-m slow``; in the default run the named test covers it.

Placeholders (``<dir>``, ``[--out DIR]``) belong in prose, never in a code block, so nothing
pasted can fail on them; and no command may write into the checkout (``git status`` is
compared before and after).
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
SHELLS = ("bash", "sh", "console")
BIN = Path(sys.executable).parent  # the environment the tests run in: "after activation"

_BLOCK = re.compile(
    r"(?:<!--\s*(?P<mark>not-run|slow):\s*(?P<note>.*?)\s*-->[ \t]*\n)?"
    r"^```(?P<lang>[A-Za-z]*)[ \t]*\n(?P<body>.*?)^```[ \t]*$",
    re.S | re.M,
)
_PLACEHOLDER = re.compile(r"<[A-Za-z_][A-Za-z0-9_ -]*>|\[--?[A-Za-z]")


@dataclass(frozen=True)
class Block:
    lang: str
    body: str
    mark: str | None
    note: str
    line: int

    @property
    def script(self) -> str:
        """What a user pastes: a console block's ``$ `` lines, any other block whole."""
        if self.lang != "console":
            return self.body
        return "".join(line[2:] + "\n" for line in self.body.splitlines() if line.startswith("$ "))


def _blocks(text: str) -> list[Block]:
    return [Block(m["lang"], m["body"], m["mark"], m["note"] or "", text.count("\n", 0, m.start("lang")) + 1)
            for m in _BLOCK.finditer(text)]


BLOCKS = _blocks(README.read_text())


def _covering(note: str) -> list[tuple[str, str]]:
    _, sep, targets = note.partition("covered by ")
    assert sep, f"marked block without 'covered by PATH::NAME': {note!r}"
    return [tuple(t.strip().split("::", 1)) if "::" in t else (t.strip(), "") for t in targets.split(",")]


def _git_status() -> str | None:
    if shutil.which("git") is None or not (ROOT / ".git").exists():
        return None
    out = subprocess.run(["git", "status", "--porcelain", "--untracked-files=all"], cwd=ROOT,
                         capture_output=True, text=True, check=True)
    return out.stdout


def _env(tmp: Path) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if not k.startswith(("ALLOC_", "PYTEST_", "COV_"))}
    env.update(PATH=f"{BIN}{os.pathsep}{env.get('PATH', '')}", VIRTUAL_ENV=str(BIN.parent),
               MPLBACKEND="Agg", NO_COLOR="1", TERM="dumb", COLUMNS="100")
    return env


def _run(block: Block, tmp: Path) -> None:
    if block.lang == "python":
        script = tmp / f"readme_line_{block.line}.py"
        script.write_text(block.body)
        cmd = [str(BIN / "python"), str(script)]
    else:
        cmd = ["bash", "-euo", "pipefail", "-c", block.script]
    out = subprocess.run(cmd, cwd=tmp, env=_env(tmp), capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, (f"README.md line {block.line} ({block.lang}) exited {out.returncode}:\n"
                                 f"{block.body}\n--- stdout\n{out.stdout[-2000:]}\n--- stderr\n{out.stderr[-4000:]}")


def test_the_readme_has_runnable_blocks_and_only_labelled_ones():
    langs = [b.lang for b in BLOCKS]
    assert "" not in langs, "an unlabelled code block: give it bash/sh/console or python (or text)"
    assert sum(b.lang in SHELLS and b.mark is None for b in BLOCKS) >= 3
    assert sum(b.lang == "python" for b in BLOCKS) >= 1


def test_no_placeholders_in_code_blocks():
    for b in BLOCKS:
        if b.lang in SHELLS:
            assert not _PLACEHOLDER.search(b.body), f"README.md line {b.line}: a placeholder in a code block"


def test_every_skipped_block_names_what_covers_it():
    marked = [b for b in BLOCKS if b.mark]
    assert marked, "the README's servers and long commands must be marked"
    for b in marked:
        for path, name in _covering(b.note):
            target = ROOT / path
            assert target.is_file(), f"README.md line {b.line}: {path} does not exist"
            assert name in target.read_text(), f"README.md line {b.line}: {name!r} not in {path}"
            if path.startswith("tests/") and name:
                assert re.search(rf"^(async )?def {re.escape(name)}\(", target.read_text(), re.M), name


def test_the_long_and_server_commands_are_the_marked_ones():
    runnable = "\n".join(b.script for b in BLOCKS if b.lang in SHELLS and b.mark is None)
    for never_here in ("make test", "make run", "make install", "pip install", "alloc serve"):
        assert never_here not in runnable, f"{never_here!r} would run in the default test"
    assert re.search(r"alloc bench full\b(?!.*--dry-run)", runnable) is None, "the sweep runs only with --dry-run"
    skipped = "\n".join(b.script for b in BLOCKS if b.mark == "not-run")
    assert "make test" in skipped and "make run" in skipped


def _run_all(blocks: list[Block], tmp_path: Path) -> None:
    if not (BIN / "alloc").exists():
        pytest.skip(f"the `alloc` command is not installed in {BIN}")
    before = _git_status()
    try:
        for block in blocks:
            _run(block, tmp_path)
    finally:
        after = _git_status()
    if before is not None:
        new = set(after.splitlines()) - set(before.splitlines())
        # exact in a clone of its own (CI); in a checkout that others edit meanwhile, check who wrote these
        assert not new, f"README commands changed the checkout: {sorted(new)}"


def test_readme_commands_run_as_pasted(tmp_path):
    _run_all([b for b in BLOCKS if (b.lang in SHELLS or b.lang == "python") and b.mark is None], tmp_path)


@pytest.mark.slow
def test_readme_slow_commands_run_as_pasted(tmp_path):
    _run_all([b for b in BLOCKS if (b.lang in SHELLS or b.lang == "python") and b.mark != "not-run"], tmp_path)

"""``alloc bench`` and ``alloc ams plot`` write only where asked: a run from a clone leaves
``git status`` clean, never resumes or overwrites unless told to."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from typer.testing import CliRunner

from alloc._engine._jit_cache import PACKAGES
from alloc.cli import app

REPO = Path(__file__).resolve().parents[2]


def _git(cwd: Path, *args: str) -> str:
    return subprocess.run(["git", *args], cwd=cwd, check=True, capture_output=True, text=True).stdout


@pytest.fixture(scope="module")
def clone(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A fresh repository holding this checkout's files (tracked and new, not ignored), committed as they are."""
    if shutil.which("git") is None:
        pytest.skip("git not installed")
    dst = tmp_path_factory.mktemp("clone")
    for rel in _git(REPO, "ls-files", "-z", "--cached", "--others", "--exclude-standard").split("\0"):
        if rel and (REPO / rel).is_file():
            (dst / rel).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(REPO / rel, dst / rel)
    _git(dst, "init", "-q")
    _git(dst, "add", "-A")
    _git(dst, "-c", "user.name=t", "-c", "user.email=t@t", "commit", "-q", "-m", "snapshot")
    # numba's kernel cache (ignored files): numba keys an entry by the source's content hash,
    # so this checkout's entries load in the clone instead of every kernel compiling again
    # (about 30 s); a kernel not cached here still compiles into the clone's __pycache__
    for package in PACKAGES:
        for index in (REPO / package).glob("**/__pycache__/*.nbi"):
            (dst / index.relative_to(REPO)).parent.mkdir(parents=True, exist_ok=True)
            for f in index.parent.glob(index.name[: -len(".nbi")] + ".*.nbc"):
                shutil.copy2(f, dst / f.relative_to(REPO))
            shutil.copy2(index, dst / index.relative_to(REPO))
    assert _git(dst, "status", "--porcelain", "--untracked-files=all") == ""
    return dst


def _bench(clone: Path, *args: str) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(clone)}
    return subprocess.run([sys.executable, "-m", "benchmarks.compare", *args], cwd=clone, env=env,
                          capture_output=True, text=True, timeout=300)


def test_bench_from_a_clone_leaves_git_status_clean(clone: Path) -> None:
    before = set(clone.iterdir())
    run = _bench(clone, "smoke", "--no-timing", "--workers", "1")
    assert run.returncode == 0, run.stderr
    new = set(clone.iterdir()) - before
    assert len(new) == 1 and next(iter(new)).name.startswith("bench-smoke-")  # a new default folder
    out = next(iter(new))
    assert {"report.md", "run.json", "specs.json", "closed_ice.csv", "open.csv"} <= {p.name for p in out.iterdir()}
    assert _git(clone, "status", "--porcelain", "--untracked-files=all") == ""


def test_explicit_out_gets_everything_and_is_never_resumed_silently(clone: Path) -> None:
    run = _bench(clone, "smoke", "--no-timing", "--workers", "1", "--out", "fresh")
    assert run.returncode == 0, run.stderr
    changed = _git(clone, "status", "--porcelain", "--untracked-files=all").splitlines()
    assert changed and all(line.startswith("?? fresh/") for line in changed)
    assert "3 runs in" in run.stdout and "(0 resumed)" in run.stdout
    report = (clone / "fresh" / "report.md").read_bytes()
    # the same folder again: refused, nothing touched
    again = _bench(clone, "smoke", "--no-timing", "--out", "fresh")
    assert again.returncode != 0 and "--resume" in again.stderr
    assert (clone / "fresh" / "report.md").read_bytes() == report
    # explicitly resumed: nothing re-run
    resumed = _bench(clone, "smoke", "--no-timing", "--out", "fresh", "--resume")
    assert resumed.returncode == 0, resumed.stderr
    assert "0 runs in" in resumed.stdout and "(3 resumed)" in resumed.stdout


def test_ams_plot_needs_an_explicit_out(tmp_path: Path) -> None:
    runner = CliRunner()
    missing = runner.invoke(app, ["ams", "plot", "--vehicle", "harv", "--samples", "50"])
    assert missing.exit_code != 0 and "--out" in missing.output
    png = tmp_path / "a.png"
    ok = runner.invoke(app, ["ams", "plot", "--vehicle", "harv", "--samples", "50", "--out", str(png)])
    assert ok.exit_code == 0, ok.output
    assert png.stat().st_size > 1000



def _one_line(res, *tokens: str) -> None:
    lines = [line for line in res.stderr.splitlines() if line.strip()]
    assert res.exit_code == 2 and len(lines) == 1 and "Traceback" not in res.stderr, res.stderr
    assert all(t in lines[0] for t in tokens), lines


def test_report_checks_its_folder_and_rerenders_only_when_forced(clone: Path) -> None:
    out = clone / "fresh"
    if not (out / "report.md").exists():  # run alone: the sweep of the test above
        assert _bench(clone, "smoke", "--no-timing", "--workers", "1", "--out", "fresh").returncode == 0
    runner = CliRunner()

    def report(*args: str):
        return runner.invoke(app, ["bench", "report", *args], prog_name="alloc")

    # issue 22: a missing or wrong DIR gave a 35-line traceback
    _one_line(report(str(clone / "nope")), "DIR", "no such folder")
    _one_line(report(str(clone)), "DIR", "specs.json")
    _one_line(report(str(clone / "README.md")), "DIR", "not a folder")
    broken = clone / "broken"
    broken.mkdir()
    for name in ("specs.json", "run.json"):
        shutil.copy2(out / name, broken / name)
    _one_line(report(str(broken)), "DIR", "closed_ice.csv")
    (broken / "specs.json").write_text('{"not": "a list"}')
    _one_line(report(str(broken)), "DIR", "specs.json")
    shutil.rmtree(broken)
    before = (out / "report.md").read_text()
    _one_line(report(str(out)), "--force")  # it would rewrite report.md
    assert (out / "report.md").read_text() == before
    forced = report(str(out), "--force")
    assert forced.exit_code == 0, forced.output
    assert f"report: {out / 'report.md'}" in forced.stdout
    assert (out / "report.md").read_text().split("## Headline")[1] == before.split("## Headline")[1]

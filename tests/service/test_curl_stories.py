"""The curl stories paste as written: the README's quick start and the service page's
jam-then-allocate story (docs/service.md), each run against a server started with `make run`'s key."""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
from pathlib import Path

import pytest

from service.process import ServiceProcess

ROOT = Path(__file__).resolve().parents[2]


def _story(page: str, heading: str) -> str:
    """The shell block after the `make run` block in ``page``'s section ``heading``."""
    text = (ROOT / page).read_text()
    start = text.index(heading)
    end = text.find("\n## ", start + 1)
    blocks = re.findall(r"```bash\n(.*?)```", text[start:end if end >= 0 else None], re.S)
    assert re.fullmatch(r"make run( &)?(\s+#.*)?", blocks[0].strip()), blocks[0]
    return blocks[1]


def _run_story(story: str, tmp_path) -> list[str]:
    key = _make_run_key()
    assert key == "s3cret"  # the key the stories fall back to
    with ServiceProcess(tmp_path / "data", api_key=key) as server:
        env = {k: v for k, v in os.environ.items() if k != "ALLOC_API_KEY"}
        out = subprocess.run(["bash", "-euo", "pipefail", "-c", story], env={**env, "ALLOC_URL": server.url},
                             capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    return out.stdout.splitlines()


# the qp optimum to round-off (the active-set and DAQP paths differ in the last bit)
QP_BEFORE_JAM = [6.75084175084175, 0.8249158249158244, 3.03030303030303, 1.4814814814814814]


def _make_run_key() -> str:
    return re.search(r"^ALLOC_API_KEY \?= (\S+)$", (ROOT / "Makefile").read_text(), re.M).group(1)


@pytest.mark.skipif(shutil.which("curl") is None, reason="the README story uses curl")
def test_readme_curl_story_runs_as_written(tmp_path):
    before, event, after = (json.loads(line) for line in _run_story(_story("README.md", "## HTTP service"), tmp_path))
    assert before["status"] == "exact" and before["health_version"] == 0
    assert before["u"] == pytest.approx(QP_BEFORE_JAM, rel=1e-13, abs=1e-13)
    assert event["event"]["seq"] == 1 and event["health"]["effectors"][0]["status"] == "jammed"
    assert after["status"] == "exact" and after["health_version"] == 1 and after["u"][0] == -5.0
    assert after["u"][2] == 20.0 and abs(after["u"][3] - 64 / 3) < 1e-9


@pytest.mark.skipif(shutil.which("curl") is None, reason="the service page's story uses curl")
def test_service_page_curl_story_runs_as_written(tmp_path):
    lines = _run_story(_story("docs/service.md", "## The jam-then-allocate story"), tmp_path)
    assert re.fullmatch(r"vehicle [0-9a-f-]{36}", lines[0])
    before, event, after, history, refused, repair = (json.loads(line) for line in lines[1:7])
    assert before["status"] == "exact" and before["health_version"] == 0
    assert before["u"] == pytest.approx(QP_BEFORE_JAM, rel=1e-13, abs=1e-13)
    assert event["event"]["seq"] == 1 and event["health"]["effectors"][0]["status"] == "jammed"
    assert after["status"] == "exact" and after["health_version"] == 1 and after["u"][0] == -5.0
    assert after["u"][2] == 20.0 and abs(after["u"][3] - 64 / 3) < 1e-9
    assert [e["kind"] for e in history["items"]] == ["jam"]
    assert refused["status"] == 422 and refused["errors"][0]["pointer"] == "/position"
    assert repair["health"]["health_version"] == 2

"""The README's curl story pastes as written: run against a server started with `make run`'s key."""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
from pathlib import Path

import pytest

from service.process import ServiceProcess

ROOT = Path(__file__).resolve().parents[1]


def _story() -> str:
    text = (ROOT / "README.md").read_text()
    section = text[text.index("## Allocation service"):]
    blocks = re.findall(r"```bash\n(.*?)```", section, re.S)
    assert blocks[0].strip() == "make run &"
    return blocks[1]


def _make_run_key() -> str:
    return re.search(r"^ALLOC_API_KEY \?= (\S+)$", (ROOT / "Makefile").read_text(), re.M).group(1)


@pytest.mark.skipif(shutil.which("curl") is None, reason="the README story uses curl")
def test_readme_curl_story_runs_as_written(tmp_path):
    key = _make_run_key()
    assert key == "s3cret"  # the key the story falls back to
    with ServiceProcess(tmp_path / "data", api_key=key) as server:
        env = {k: v for k, v in os.environ.items() if k != "ALLOC_API_KEY"}
        out = subprocess.run(["bash", "-euo", "pipefail", "-c", _story()], env={**env, "ALLOC_URL": server.url},
                             capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    lines = out.stdout.splitlines()
    assert re.fullmatch(r"vehicle [0-9a-f-]{36}", lines[0])
    before, event, after, history, refused, repair = (json.loads(line) for line in lines[1:7])
    assert before["status"] == "exact" and before["health_version"] == 0
    # the qp optimum to round-off (the active-set and DAQP paths differ in the last bit)
    assert before["u"] == pytest.approx([6.75084175084175, 0.8249158249158244, 3.03030303030303,
                                         1.4814814814814814], rel=1e-13, abs=1e-13)
    assert event["event"]["seq"] == 1 and event["health"]["effectors"][0]["status"] == "jammed"
    assert after["status"] == "exact" and after["health_version"] == 1 and after["u"][0] == -5.0
    assert after["u"][2] == 20.0 and abs(after["u"][3] - 64 / 3) < 1e-9
    assert [e["kind"] for e in history["items"]] == ["jam"]
    assert refused["status"] == 422 and refused["errors"][0]["pointer"] == "/position"
    assert repair["health"]["health_version"] == 2

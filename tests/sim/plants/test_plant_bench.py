"""``alloc bench closedloop --plant``: the method comparison on a third-party plant (the F-22 here: the fastest)."""

from __future__ import annotations

import json

import pytest
from typer.testing import CliRunner

from alloc.cli import app

pytest.importorskip("jsbsim", reason="jsbsim (the [plants] extra) does not import here")

runner = CliRunner()


def test_closedloop_on_the_f22_told_flies_blind_diverges():
    # docs/plants-jsbsim.md: a stabilator half jammed at trim at 5 s; blind diverges at 9.60 s
    args = ["bench", "closedloop", "--vehicle", "sim/plants/data/f22_jsbsim.toml", "--plant", "jsbsim:f22",
            "--failure", "jam:stab_l@0", "--method", "qp", "--duration", "11", "--failure-time", "5", "--json"]
    res = runner.invoke(app, args, prog_name="alloc")
    assert res.exit_code == 0, res.stdout + res.stderr
    rows = {r["told"]: r for r in json.loads(res.stdout)}
    assert rows[True]["diverged"] is False and rows[True]["simulated"] == pytest.approx(11.0)
    assert rows[False]["diverged"] is True and rows[False]["simulated"] == pytest.approx(9.6, abs=0.05)


def test_an_unknown_plant_is_refused_naming_it():
    res = runner.invoke(app, ["bench", "closedloop", "--vehicle", "hexa-x", "--plant", "jsbsim:f16", "--failure",
                              "float:motor1"], prog_name="alloc")
    assert res.exit_code == 2 and "--plant" in res.stderr and "jsbsim:f22" in res.stderr

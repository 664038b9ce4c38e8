"""The verdict-driving choices table (sim.choices) and its generated docs page."""

from __future__ import annotations

from dataclasses import fields
from pathlib import Path

from sim.choices import render_markdown, verdict_choices
from sim.settings import SETTING, RunSettings

PAGE = Path(__file__).resolve().parents[2] / "docs" / "verdict-choices.md"


def test_every_verdict_setting_is_listed_and_only_those():
    listed = {c.name.removeprefix("setting ") for c in verdict_choices() if c.name.startswith("setting ")}
    flagged = {f.name for f in fields(RunSettings) if f.metadata[SETTING].verdict}
    assert listed == flagged
    assert "seed" not in listed and "record_every" not in listed  # bookkeeping is not a verdict choice


def test_every_choice_names_value_source_and_place():
    choices = verdict_choices()
    assert len({c.name for c in choices}) == len(choices)
    for c in choices:
        assert c.value and c.where and c.source
        assert c.source.startswith(("seed", "ours")), c


def test_the_project_s_own_choices_are_marked_ours():
    by_name = {c.name: c for c in verdict_choices()}
    for name in ("setting preferred", "setting anti_windup", "setting boundary_layer", "setting rate_window",
                 "setting rate_horizon", "Fig 4-81 bank-angle steps", "daisy groups (ICE)",
                 "divergence bound ICE", "stand-in pilot gain"):
        assert by_name[name].source.startswith("ours"), name
    assert "20 deg at 1 s" in by_name["Fig 4-81 bank-angle steps"].value


def test_docs_page_is_generated():
    assert PAGE.read_text() == render_markdown(), "regenerate: python -c 'from sim.choices import render_markdown; ...'"

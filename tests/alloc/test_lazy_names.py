"""The facade packages' lazily loaded names (:mod:`alloc._lazy`): one definition, two users."""

from __future__ import annotations

import sys
import types

import pytest

import alloc
import alloc.ams
from alloc import _lazy


def test_lazy_names_load_their_submodule_once_and_list_in_dir():
    assert "Problem" in dir(alloc) and "sample_ams" in dir(alloc.ams)
    assert alloc.Problem is sys.modules["alloc.problem"].Problem
    assert vars(alloc)["Problem"] is alloc.Problem  # stored: later look-ups skip __getattr__
    with pytest.raises(AttributeError, match="module 'alloc' has no attribute 'nope'"):
        alloc.nope  # noqa: B018
    with pytest.raises(AttributeError, match="module 'alloc.ams' has no attribute 'nope'"):
        alloc.ams.nope  # noqa: B018


def test_functions_named_like_a_submodule_stay_functions():
    import alloc.ams.coverage  # binds the submodule on its parent: what the test is about
    import alloc.methods

    assert callable(alloc.methods) and "pinv" in alloc.methods()
    assert isinstance(alloc.ams.coverage, types.FunctionType)
    assert isinstance(sys.modules["alloc.methods"], types.ModuleType)


def test_attach_and_keep_function_on_a_scratch_package(monkeypatch):
    pkg = types.ModuleType("scratch_pkg")
    monkeypatch.setitem(sys.modules, "scratch_pkg", pkg)
    loaded = []

    def load(name):
        loaded.append(name)
        return types.SimpleNamespace(answer=42)

    pkg.__getattr__, pkg.__dir__ = _lazy.attach("scratch_pkg", {"answer": "sub"}, ["answer"], load)
    assert pkg.answer == 42 and pkg.answer == 42 and loaded == ["answer"]
    assert "answer" in pkg.__dir__()
    _lazy.keep_function("scratch_pkg", "tool", lambda: len)
    pkg.tool = types.ModuleType("scratch_pkg.tool")  # what importing the submodule does
    assert pkg.tool is len

"""Effector failure catalogue of the comparison sweep, and how a failure reaches a scenario.

A failure in a sweep spec is a name.  Either the scenario defines it (the seed's composite
failures: ICE ``seed``, HARV lat-dir ``plant``/``failure1``/``failure2``), or it is
``<kind><n>`` of the simulator's failure catalogue (:mod:`sim.failure_catalogue`): ``n`` = 1
(single) or 2 (double) effector failures of one kind, effector-only (the plant, delays and
bandwidths stay nominal), so the comparison isolates what an allocator can do about a failed
effector.  Each catalogue name stands for a text of the library's failure grammar
(:mod:`alloc.failure_grammar`), generated from the failure-kind table and the catalogue's
severities (:data:`sim.failure_catalogue.SEVERITY`) on the effectors the scenario names
(``catalogue_effectors`` of its :class:`sim.scenarios.mimo.MimoScenario`): ICE -- single:
``elevon_l``; double: ``elevon_l`` and ``lef_l`` (the two surfaces the seed's ICE failure
degrades); HARV lat-dir -- ``aileron``, then ``aileron`` and ``rudder``.  So ``jam1`` on ICE
is ``jam:elevon_l@15``, and ``alloc sim ice --failure jam1`` flies what the sweep flies.

A *told* allocator is given the same failure as a changed :class:`alloc.Problem`
(:func:`sim.allocation.allocation_problem`); a *blind* one keeps the nominal problem.

A catalogue failure is a :class:`sim.model.Failure`, handed to scenarios that take failure
objects (attribute ``accepts_failure_objects``: the MIMO scenarios of ``sim.scenarios.mimo``).
"""

from __future__ import annotations

import importlib
from dataclasses import replace
from typing import Any

import numpy as np

from sim import criteria as _criteria
from sim.failure_catalogue import (
    LIMIT_FRACTION,
    LOE_FRACTION,
    RATE_FRACTION,
    RIDES_WITH,
    SEVERITY,
    catalogue_kind,
    catalogue_kinds,
    catalogue_names,
)

# FAILED_EFFECTORS (scenario -> effector indices) is read from the scenarios when asked (__getattr__)
__all__ = ["KINDS", "SEVERITY", "RIDES_WITH", "LOE_FRACTION", "LIMIT_FRACTION", "RATE_FRACTION",
           "CATALOGUE_SCENARIOS", "catalogue_kinds", "catalogue_names", "catalogue_texts", "canonical_name",
           "is_catalogue", "make_failure", "failed_effectors", "failure_effectors"]

#: the scenarios the sweep flies catalogue failures on (each names its catalogue effectors)
CATALOGUE_SCENARIOS = ("ice", "harv_latdir")

#: Rows written before the failure kinds had one name (benchmarks/reference/, 2026-11) call loss of
#: effectiveness ``loe``; those CSVs are kept as run, so their names still read as today's.
_LEGACY_KINDS = {"loe": "effectiveness"}


def _scenario(scenario: str) -> Any:
    """The :class:`sim.scenarios.mimo.MimoScenario` of a catalogue scenario (ValueError otherwise)."""
    if scenario not in CATALOGUE_SCENARIOS:
        raise ValueError(f"failure: no catalogue effectors for scenario {scenario!r}; known: {list(CATALOGUE_SCENARIOS)}")
    return importlib.import_module(f"sim.scenarios.{scenario}").SCENARIO


def failed_effectors(scenario: str) -> tuple[str, ...]:
    """The catalogue's failed effectors of ``scenario``, by name (the first for ``<kind>1``, both for ``<kind>2``)."""
    return tuple(_scenario(scenario).catalogue_effectors)


def __getattr__(name: str) -> Any:
    if name == "KINDS":  # read from the table when asked: a kind registered after import counts
        return catalogue_kinds()
    if name == "FAILED_EFFECTORS":  # scenario -> effector indices, from the names the scenarios give
        return {s: tuple(_scenario(s).vehicle().effector_names.index(e) for e in failed_effectors(s))
                for s in CATALOGUE_SCENARIOS}
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def catalogue_texts(scenario: str) -> dict[str, str]:
    """Catalogue name -> its text of the failure grammar on ``scenario`` (``jam1`` -> ``jam:elevon_l@15``)."""
    return _scenario(scenario).catalogue()


def _parse(name: str | None) -> tuple[str, int] | None:
    """``(kind, n)`` of a catalogue name (legacy kind names read as today's), else None."""
    if not isinstance(name, str) or not name[:-1]:
        return None
    return catalogue_kind(_LEGACY_KINDS.get(name[:-1], name[:-1]) + name[-1])


def canonical_name(name: str) -> str:
    """Today's name of a catalogue failure (``loe1`` -> ``effectiveness1``); others unchanged."""
    parsed = _parse(name)
    return f"{parsed[0]}{parsed[1]}" if parsed else name


def is_catalogue(name: str | None) -> bool:
    """Whether ``name`` is a catalogue failure (not one the scenario defines)."""
    return _parse(name) is not None


def make_failure(scenario: str, name: str, time: float) -> Any:
    """The :class:`sim.model.Failure` named ``name`` (``<kind><1|2>``) for ``scenario`` at ``time``:
    the scenario's own resolution of the catalogue name (:meth:`sim.scenarios.mimo.MimoScenario.resolve_failure`)."""
    if _parse(name) is None:
        raise ValueError(f"failure: {name!r} is not a catalogue failure; expected <kind><1|2> with kind in "
                         f"{catalogue_kinds()}")
    failure = _scenario(scenario).resolve_failure(canonical_name(name), float(time))
    return replace(failure, name=name)  # a legacy name (loe1) stays the run's name, as it was run


def failure_effectors(scenario: str, name: str) -> np.ndarray:
    """Indices of the effectors a catalogue failure affects (for the report's captions)."""
    parsed = _parse(name)
    if not parsed:
        return np.array([], dtype=int)
    names = _scenario(scenario).vehicle().effector_names
    return np.array([names.index(e) for e in failed_effectors(scenario)[: parsed[1]]])


def _criteria_source(scenario: str, name: str, time: float | None) -> Any:
    """A catalogue failure by name, for the criteria's saturation shares (None: not a catalogue one)."""
    return make_failure(scenario, name, time or 0.0) if is_catalogue(name) and scenario in CATALOGUE_SCENARIOS else None


# The criteria leave a failure's out-of-command effectors out of the saturation shares; sim never
# imports the benchmarks, so the catalogue tells it its failures.
_criteria.register_failure_source(_criteria_source)

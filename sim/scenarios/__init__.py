"""Scenario registry: closed-loop simulations runnable by name.

A scenario is a callable with the signature::

    run(*, method: str = <default>, failure: str | None = None,
        duration: float | None = None, seed: int = 0, dt: float = 0.0005,
        allocator_knows_failure: bool = False, progress: bool = False,
        **options) -> sim.result.SimResult

registered with :func:`~sim.scenarios.registry.register_scenario` (the registry lives in
:mod:`sim.scenarios.registry`, below the scenario modules), which also attaches the metadata
attributes ``name``, ``description``, ``failures`` (failure name ->
description), ``default_duration``, ``default_method`` and ``default_failure`` (the
failure a run injects when the caller names none; ``None`` for most scenarios).

Two runners fly every scenario:

* :func:`sim.scenarios.mimo.run_mimo` flies a :class:`~sim.scenarios.mimo.MimoScenario`
  (vehicle, allocator, actuators, pilot; ICE and F-18/HARV) through the compiled
  engine :mod:`sim.engine`; such a scenario takes every option of ``run_mimo``
  (frame period, Eq 1.28 on/off, ``u_prev`` source, pilot model, noise, ...) and
  registers with :func:`sim.scenarios.mimo.mimo_scenario`.
* :func:`sim.scenarios.classic.run_classic` integrates a hand-written right-hand
  side with no allocator (the seed's chapter 2-3 pendulum, F-16 and DC-8
  demonstrations); such a scenario registers with
  :func:`sim.scenarios.classic.classic_scenario`.

Scenario modules are imported lazily: :data:`SCENARIO_MODULES` maps each name
to the module that registers it, so importing :mod:`sim.scenarios` stays cheap
and a broken module only breaks its own scenario.
"""

from __future__ import annotations

import importlib

from sim.scenarios.registry import Scenario, register_scenario, registered, registered_names

__all__ = ["Scenario", "register_scenario", "get_scenario", "scenarios", "SCENARIO_MODULES"]

#: Scenario name -> module that registers it (imported on first use).
SCENARIO_MODULES: dict[str, str] = {
    "pendulum": "sim.scenarios.pendulum",
    "f16": "sim.scenarios.f16",
    "dc8": "sim.scenarios.dc8",
    "ice": "sim.scenarios.ice",
    "harv_lon": "sim.scenarios.harv_lon",
    "harv_latdir": "sim.scenarios.harv_latdir",
    "harv_latdir_failure2": "sim.scenarios.harv_latdir",
}


def get_scenario(name: str) -> Scenario:
    """Return the scenario registered as ``name``, importing its module if needed.

    Raises
    ------
    KeyError
        If ``name`` is unknown; the message lists the known scenarios.
    """
    scenario = registered(name)
    if scenario is None:
        module = SCENARIO_MODULES.get(name)
        if module is None:
            raise KeyError(f"unknown scenario {name!r}; known scenarios: {', '.join(scenarios())}")
        importlib.import_module(module)
        scenario = registered(name)
    if scenario is None:
        raise KeyError(f"module {SCENARIO_MODULES[name]!r} did not register scenario {name!r}")
    return scenario


def scenarios() -> list[str]:
    """Names of all known scenarios (registered or lazily importable), sorted."""
    return sorted(set(SCENARIO_MODULES) | registered_names())

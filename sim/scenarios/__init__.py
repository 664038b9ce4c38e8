"""Scenario registry: closed-loop simulations runnable by name.

A scenario is a callable with the signature::

    run(*, method: str = <default>, failure: str | None = None,
        duration: float | None = None, seed: int = 0, dt: float = 0.0005,
        allocator_knows_failure: bool = False, progress: bool = False,
        **options) -> sim.result.SimResult

registered with :func:`register_scenario`, which also attaches the metadata
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
from collections.abc import Callable
from typing import Any, Protocol

from sim.result import SimResult

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


class Scenario(Protocol):
    """What :func:`get_scenario` returns."""

    name: str
    description: str
    failures: dict[str, str]
    default_duration: float
    default_method: str | None
    default_failure: str | None

    def __call__(self, **kwargs: Any) -> SimResult: ...


_REGISTRY: dict[str, Scenario] = {}


def register_scenario(
    name: str,
    *,
    description: str | None = None,
    failures: dict[str, str] | None = None,
    default_duration: float | None = None,
    default_method: str | None = None,
    default_failure: str | None = None,
) -> Callable[[Callable[..., SimResult]], Scenario]:
    """Register ``run`` under ``name`` and attach its metadata.

    Metadata not given here is taken from attributes already set on ``run``
    (``description`` falls back to the first docstring line,
    ``default_duration`` to 10 s, ``failures`` to none).

    Examples
    --------
    >>> @register_scenario("demo", description="...", default_duration=10.0)
    ... def run(*, method="pinv", failure=None, duration=None, **kw): ...
    """

    def decorate(run: Callable[..., SimResult]) -> Scenario:
        if name in _REGISTRY and _REGISTRY[name] is not run:
            raise ValueError(f"scenario {name!r} is already registered")
        doc = (run.__doc__ or "").strip().splitlines()
        run.name = name  # type: ignore[attr-defined]
        run.description = (  # type: ignore[attr-defined]
            description or getattr(run, "description", None) or (doc[0] if doc else name)
        )
        run.failures = dict(failures or getattr(run, "failures", {}) or {})  # type: ignore[attr-defined]
        run.default_duration = float(  # type: ignore[attr-defined]
            default_duration or getattr(run, "default_duration", 10.0)
        )
        run.default_method = default_method or getattr(run, "default_method", None)  # type: ignore[attr-defined]
        run.default_failure = default_failure or getattr(run, "default_failure", None)  # type: ignore[attr-defined]
        if run.default_failure is not None and run.default_failure not in run.failures:  # type: ignore[attr-defined]
            raise ValueError(f"scenario {name!r}: default failure {run.default_failure!r} is not one of its failures")
        _REGISTRY[name] = run  # type: ignore[assignment]
        return run  # type: ignore[return-value]

    return decorate


def get_scenario(name: str) -> Scenario:
    """Return the scenario registered as ``name``, importing its module if needed.

    Raises
    ------
    KeyError
        If ``name`` is unknown; the message lists the known scenarios.
    """
    if name not in _REGISTRY:
        module = SCENARIO_MODULES.get(name)
        if module is None:
            raise KeyError(f"unknown scenario {name!r}; known scenarios: {', '.join(scenarios())}")
        importlib.import_module(module)
    if name not in _REGISTRY:
        raise KeyError(f"module {SCENARIO_MODULES[name]!r} did not register scenario {name!r}")
    return _REGISTRY[name]


def scenarios() -> list[str]:
    """Names of all known scenarios (registered or lazily importable), sorted."""
    return sorted(set(SCENARIO_MODULES) | set(_REGISTRY))

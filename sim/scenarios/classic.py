"""The one runner of the classic single-loop scenarios (pendulum, F-16, DC-8; seed chapters 2-3).

A classic scenario is a hand-written right-hand side ``X' = f(t, X, held)``
with no allocator: the seed's chapter 2 and 3 demonstrations (one force, one
elevator, a square decentralised aileron/rudder design).  Two pieces serve
all of them:

* :func:`run_classic` integrates ``f`` with Heun's method (ODE2, the seed's
  fixed-step solver) and records, at every step, the state, the predictor
  slope ``f(t_k, X_k)`` and the signals ``f`` reports (commands, surfaces).
  It stops at the first sample that fails :func:`sim.result.divergence_check`.
* :func:`classic_scenario` registers a scenario's ``run`` with the registry
  signature of :mod:`sim.scenarios`: it checks the failure name, fills the
  default duration and accepts (and ignores) ``method``,
  ``allocator_knows_failure`` and ``progress``.

Adding a classic scenario is one module: a right-hand side, a
``run(*, failure, duration, dt, seed, **options)`` decorated with
:func:`classic_scenario` that calls :func:`run_classic` and turns the
:class:`ClassicRun` into a :class:`sim.result.SimResult` with
:meth:`ClassicRun.result`.
"""

from __future__ import annotations

import functools
import inspect
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from sim.result import SimResult, divergence_check
from sim.scenarios.registry import Scenario, register_scenario

__all__ = ["ClassicRun", "run_classic", "classic_scenario", "DEFAULT_DT"]

#: The seed's fixed integration step, s.  The same value as :data:`sim.blocks.DEFAULT_DT`
#: (a test keeps them equal), not imported from there: that module loads numba, which
#: the classic scenarios do not need.
DEFAULT_DT = 0.0005

#: ``f(t, X, held) -> (X_dot, signals)``: the state derivative and the signals to record.
Derivative = Callable[[float, np.ndarray, Any], tuple[np.ndarray, Sequence[float] | np.ndarray]]


@dataclass(frozen=True)
class ClassicRun:
    """What :func:`run_classic` recorded, one row per integration step up to the last one flown.

    Attributes
    ----------
    t : ndarray, shape (N,)
        Sample times, ``k dt``.
    states : ndarray, shape (N, n)
        State ``X_k``.
    rates : ndarray, shape (N, n)
        Predictor slope ``f(t_k, X_k)`` at the recorded state.
    signals : ndarray, shape (N, s)
        The signals ``f(t_k, X_k)`` reported, in its order.
    diverged : bool
        True when the run stopped at the divergence bound (the last row is the
        first sample outside it).
    """

    t: np.ndarray
    states: np.ndarray
    rates: np.ndarray
    signals: np.ndarray
    diverged: bool

    def result(self, scenario: str, failure: str | None, failure_time: float, **fields: Any) -> SimResult:
        """The :class:`SimResult` of this run: no allocator, ``failure_time`` kept only when failed.

        ``fields`` are the scenario's channels, references, outputs and
        effectors (see :class:`sim.result.SimResult`).
        """
        return SimResult(
            scenario=scenario, method=None, failure=failure, t=self.t, diverged=self.diverged,
            failure_time=failure_time if failure is not None else None, **fields,
        )


def run_classic(
    derivative: Derivative,
    x0: np.ndarray,
    *,
    duration: float,
    dt: float,
    n_signals: int,
    outputs: slice | Sequence[int],
    output_bound: np.ndarray | float,
    hold: Callable[[float], Any] | None = None,
    after_step: Callable[[np.ndarray], None] | None = None,
) -> ClassicRun:
    """Integrate ``X' = derivative(t, X, held)`` from ``x0`` with Heun's method at the fixed step ``dt``.

    Step ``k`` (``t_k = k dt``, ``k = 0 .. round(duration / dt)``)::

        held  = hold(t_k)                          once per step (plant switch, noise sample)
        k1, s = derivative(t_k, X_k, held)         recorded with X_k
        k2, _ = derivative(t_k + dt, X_k + dt k1, held)
        X_k+1 = X_k + dt/2 (k1 + k2)               then after_step(X_k+1) in place

    Parameters
    ----------
    derivative : callable
        ``(t, X, held) -> (X_dot, signals)``; ``signals`` has ``n_signals`` entries.
    x0 : ndarray, shape (n,)
        Initial state.
    duration, dt : float
        Seconds simulated and the fixed step (the seed's default 0.0005 s).
    n_signals : int
        Length of ``signals``.
    outputs : slice or sequence of int
        State entries checked against ``output_bound`` (:func:`sim.result.divergence_check`;
        the whole state is checked for non-finite values).
    output_bound : float or ndarray
        Divergence bound on ``|X[outputs]|``.
    hold : callable, optional
        ``t -> held``, evaluated once per step and held over it (zero-order hold); default None.
    after_step : callable, optional
        ``X -> None``, applied in place after each step (e.g. an integrator clamp).

    Returns
    -------
    ClassicRun

    Raises
    ------
    ValueError
        If ``dt`` is not finite and positive or ``duration`` not finite and non-negative.
    """
    if not (math.isfinite(dt) and dt > 0):
        raise ValueError(f"dt must be finite and positive, got {dt!r}")
    if not (math.isfinite(duration) and duration >= 0):
        raise ValueError(f"duration must be finite and non-negative, got {duration!r}")
    n_steps = int(round(duration / dt))
    t = np.arange(n_steps + 1) * dt
    x = np.array(x0, dtype=float)
    states = np.full((n_steps + 1, x.size), np.nan)
    rates = np.full((n_steps + 1, x.size), np.nan)
    signals = np.full((n_steps + 1, n_signals), np.nan)
    diverged = False
    last = n_steps
    for k in range(n_steps + 1):
        tk = t[k]
        held = None if hold is None else hold(tk)
        k1, signals[k] = derivative(tk, x, held)
        states[k], rates[k] = x, k1
        if divergence_check(x[outputs], output_bound, x):
            diverged, last = True, k
            break
        if k == n_steps:
            break
        k2 = derivative(tk + dt, x + dt * k1, held)[0]
        x = x + 0.5 * dt * (k1 + k2)
        if after_step is not None:
            after_step(x)
    sl = slice(0, last + 1)
    return ClassicRun(t=t[sl], states=states[sl], rates=rates[sl], signals=signals[sl], diverged=diverged)


#: The registry's keyword arguments (see :mod:`sim.scenarios`) a classic scenario's ``run`` is called with.
_REGISTRY_PARAMETERS = ("method", "failure", "duration", "seed", "dt", "allocator_knows_failure", "progress")


def classic_scenario(
    name: str, *, description: str, failures: Mapping[str, str], default_duration: float
) -> Callable[[Callable[..., SimResult]], Scenario]:
    """Register ``run(*, failure, duration, dt, seed, **options) -> SimResult`` as scenario ``name``.

    The registered callable takes the registry's arguments (``method``,
    ``failure``, ``duration``, ``seed``, ``dt``, ``allocator_knows_failure``,
    ``progress``) and the scenario's options.  It raises ``ValueError`` for a
    failure not in ``failures``, passes ``duration`` (default
    ``default_duration``), ``dt`` and ``seed`` on, and ignores the rest: a
    classic scenario has no allocator (``SimResult.method`` is None) and runs
    in seconds.  Unknown options raise ``TypeError`` from ``run``.
    """

    def decorate(fly: Callable[..., SimResult]) -> Scenario:
        @functools.wraps(fly, assigned=("__module__", "__name__", "__qualname__", "__doc__"))
        def run(
            *, method: str | None = None, failure: str | None = None, duration: float | None = None, seed: int = 0,
            dt: float = DEFAULT_DT, allocator_knows_failure: bool = False, progress: bool = False, **options: Any,
        ) -> SimResult:
            del method, allocator_knows_failure, progress  # no allocator to choose or tell; no progress bar
            if failure not in (None, *failures):
                raise ValueError(f"unknown failure {failure!r} for scenario {name!r}; known: {', '.join(failures)}")
            duration = default_duration if duration is None else float(duration)
            return fly(failure=failure, duration=duration, dt=dt, seed=seed, **options)

        # What inspect.signature shows (the sweep reads it): the registry's arguments, then the options.
        registry = inspect.signature(run, follow_wrapped=False).parameters
        own = [p for n, p in inspect.signature(fly).parameters.items() if n not in _REGISTRY_PARAMETERS]
        run.__signature__ = inspect.Signature(  # type: ignore[attr-defined]
            [registry[n] for n in _REGISTRY_PARAMETERS] + own, return_annotation=SimResult)
        return register_scenario(
            name, description=description, failures=dict(failures), default_duration=default_duration,
            default_method=None,
        )(run)

    return decorate

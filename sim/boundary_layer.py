"""Boundary layers for sliding-mode control laws.

* Static boundary layer (seed section 2.1.8.1): the discontinuous
  ``rho * sgn(sigma)`` of Eq 2.9 is replaced by ``rho * sat(sigma / eps)``
  with a fixed thickness ``eps``.
* Shtessel's dynamic boundary layer (seed section 3.2, Eqs 3.6-3.8): the
  thickness ``eps(t)`` is widened, sample by sample, just enough that the
  postfilter command stays inside the actuator's position and rate limits and
  ``sigma`` stays inside the layer (no integrator wind-up).

The postfilter law of seed section 3.2.1 integrates a pseudo-command ``v``
through a first-order actuator model of bandwidth ``a_delta``::

    v       = v_eq + rho * sat(sigma / eps)          (sign folded into rho)
    delta_c = delta + v / a_delta                    (seed section 3.2.1)

so the actuator rate is ``a_delta * (delta_c - delta) = v``.  Eq 3.8 therefore
bounds ``|v|`` by the rate limit and Eq 3.7 bounds ``|delta + v / a_delta|`` by
the position limit.  (The OCR of Eq 3.8 prints the bound as ``delta_m``; it is
the rate limit, written with a dot in the source.)
"""

from __future__ import annotations

import numpy as np

__all__ = ["sat", "static_boundary_layer", "DynamicBoundaryLayer"]


def sat(x: np.ndarray | float) -> np.ndarray | float:
    """Unit saturation ``sat(x) = min(1, max(-1, x))`` (seed section 2.1.8.1)."""
    return np.clip(x, -1.0, 1.0)


def static_boundary_layer(sigma: np.ndarray | float, rho: np.ndarray | float, eps: np.ndarray | float) -> np.ndarray | float:
    """Continuous switching term ``rho * sat(sigma / eps)`` (seed section 2.1.8.1).

    Parameters
    ----------
    sigma : float or ndarray
        Switching function value(s), Eq 2.14.
    rho : float or ndarray
        Switching gain(s); the sign convention is the caller's.
    eps : float or ndarray
        Boundary-layer thickness, ``eps > 0``.
    """
    if np.any(np.asarray(eps) <= 0):
        raise ValueError(f"boundary-layer thickness eps must be positive, got {eps!r}")
    return rho * sat(np.asarray(sigma) / eps)


class DynamicBoundaryLayer:
    """Shtessel's dynamic boundary layer for a postfilter SMC (seed Eqs 3.6-3.8).

    For each channel the thickness is the smallest ``eps >= eps_min`` such that,
    with the linear (unsaturated) law ``v = v_eq + rho * sigma / eps``,

    * Eq 3.6, integrator wind-up: ``|sigma| <= eps``;
    * Eq 3.7, deflection limit: ``|delta + v / a_delta| <= delta_max``;
    * Eq 3.8, rate limit: ``|v| <= rate_max``.

    Each inequality is an interval for ``v``; their intersection ``[lo, hi]``
    holds ``v_eq`` whenever ``|v_eq| <= rate_max`` and
    ``|delta + v_eq / a_delta| <= delta_max`` (then ``rho * sigma / eps`` only
    has to shrink, which a wider layer always achieves).  If ``v_eq`` alone
    breaks a limit no thickness can help; the command is then clipped to the
    interval nearest ``v_eq`` and :attr:`infeasible` is set for that channel.

    Parameters
    ----------
    rho : float or array_like
        Switching gains (seed section 3.2.1: ``-10``); sign convention as in
        ``v = v_eq + rho * sat(sigma / eps)``.
    eps_min : float or array_like
        Nominal (static) thickness, the layer never gets thinner (``0.1``).
    a_delta : float or array_like
        Design actuator bandwidth in Eq 3.7 (``20`` rad/s).
    delta_max : float or array_like
        Position limit (``0.37`` rad).
    rate_max : float or array_like
        Rate limit (``10`` rad/s).
    """

    def __init__(
        self,
        rho: np.ndarray | float,
        eps_min: np.ndarray | float,
        a_delta: np.ndarray | float,
        delta_max: np.ndarray | float,
        rate_max: np.ndarray | float,
    ) -> None:
        self.rho = np.atleast_1d(np.asarray(rho, dtype=float))
        self.eps_min = np.atleast_1d(np.asarray(eps_min, dtype=float))
        self.a_delta = np.atleast_1d(np.asarray(a_delta, dtype=float))
        self.delta_max = np.atleast_1d(np.asarray(delta_max, dtype=float))
        self.rate_max = np.atleast_1d(np.asarray(rate_max, dtype=float))
        for name in ("eps_min", "a_delta", "delta_max", "rate_max"):
            if np.any(getattr(self, name) <= 0):
                raise ValueError(f"{name} must be positive, got {getattr(self, name)!r}")
        if np.any(self.rho == 0):
            raise ValueError(f"rho must be nonzero, got {self.rho!r}")
        self.infeasible = np.zeros(np.broadcast(self.rho, self.eps_min).shape, dtype=bool)

    def command_interval(self, delta: np.ndarray | float) -> tuple[np.ndarray, np.ndarray]:
        """Interval ``[lo, hi]`` of pseudo-commands ``v`` allowed by Eqs 3.7 and 3.8."""
        delta = np.asarray(delta, dtype=float)
        lo = np.maximum(-self.rate_max, self.a_delta * (-self.delta_max - delta))
        hi = np.minimum(self.rate_max, self.a_delta * (self.delta_max - delta))
        return lo, hi

    def thickness(self, sigma: np.ndarray | float, delta: np.ndarray | float, v_eq: np.ndarray | float = 0.0) -> np.ndarray:
        """Boundary-layer thickness ``eps`` satisfying Eqs 3.6-3.8 (see class docstring)."""
        sigma = np.asarray(sigma, dtype=float)
        v_eq = np.asarray(v_eq, dtype=float)
        lo, hi = self.command_interval(delta)
        # Switching term w = rho*sigma/eps must lie in [lo - v_eq, hi - v_eq].
        w = self.rho * sigma
        room = np.where(w >= 0.0, hi - v_eq, v_eq - lo)  # allowed |w/eps| in the direction of w
        self.infeasible = (v_eq < lo) | (v_eq > hi)
        with np.errstate(divide="ignore", invalid="ignore"):
            eps_limits = np.where(w == 0.0, 0.0, np.where(room > 0.0, np.abs(w) / room, np.inf))
        return np.maximum(np.maximum(self.eps_min, np.abs(sigma)), eps_limits)

    def command(self, sigma: np.ndarray | float, delta: np.ndarray | float, v_eq: np.ndarray | float = 0.0) -> tuple[np.ndarray, np.ndarray]:
        """Pseudo-command ``v = v_eq + rho * sat(sigma / eps)`` and the thickness used.

        Returns
        -------
        v : ndarray
            Pseudo-command (actuator rate demand) inside Eqs 3.7 and 3.8
            whenever that is possible.
        eps : ndarray
            Boundary-layer thickness of this sample.
        """
        eps = self.thickness(sigma, delta, v_eq)
        v = np.asarray(v_eq, dtype=float) + self.rho * sat(np.asarray(sigma, dtype=float) / eps)
        if np.any(self.infeasible):
            lo, hi = self.command_interval(delta)
            v = np.where(self.infeasible, np.clip(v, np.minimum(lo, hi), np.maximum(lo, hi)), v)
        return v, eps

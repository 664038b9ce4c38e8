"""Which axes a vehicle still controls after a failure: rank, conditioning, attainable set, per-axis ranges.

:func:`report` answers, for a problem (or vehicle) and a health state (:mod:`alloc.health`):

* **rank and conditioning** of the healthy effectiveness.  Computed on the generator matrix
  ``G = B_h diag(hi - lo)`` of the effectors that can still move (``B_h``: ``B`` with the
  failures applied; ``lo, hi``: their limits), so effectors of different units and travel
  compare by what their full travel does.  A singular value counts towards the rank when
  it exceeds :data:`RANK_RTOL` times the *nominal* vehicle's largest singular value (a
  failure that leaves only a sliver of authority reads as lost, not as full rank).  The
  condition number is ``s_max / s_min`` over the ``k`` axes (``inf`` below full rank).  Both
  depend on the axes' units (a row in N against rows in N m): they are in the file's units.
* **independently controllable axes**: axis ``i`` is when its unit vector lies in the range
  of ``G`` (residual of its projection below :data:`RANK_RTOL`), i.e. it can be moved with
  every other axis held.  Below full rank the directions no command reaches are listed
  (unit vectors ``n`` in axis space with ``n . v`` fixed for every attainable ``v``).
* **the attainable set** (:class:`alloc.ams.AttainableSet`, seed section 1.3.4.2): its volume
  (units: the product of the axis units) healthy and nominal, and their ratio; and the
  *margin*: the distance from the reference point to the healthy set's boundary (the
  smallest ``h(n) - n . v_ref`` over its unit facet normals; negative outside, 0 on the
  boundary; the "available control authority index" of Du, Quan, Yang and Cai,
  J. Guidance Control Dyn. 38(5), 2015).
* **per-axis ranges**: the attainable interval along each axis through the reference point
  ``v_ref`` with the other axes held at their reference values, healthy and nominal
  (two linear programs each, HiGHS through :func:`scipy.optimize.linprog`).  ``v_ref`` is
  zero for a problem, a vehicle file's axis trims for a vehicle (a hovering multicopter's
  thrust), or ``at``.

A reference point the healthy vehicle cannot reach at all (a quadcopter after a rotor loss
at hover) gives ``reference_attainable = False`` and empty ranges (``NaN``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from .exceptions import ProblemError
from .problem import Problem, as_float_array, check_magnitude

__all__ = ["RANK_RTOL", "AxisRange", "ControllabilityReport", "report"]

#: relative singular-value threshold of the rank (against the nominal largest) and the
#: residual below which an axis direction lies in the range of the effectiveness
RANK_RTOL = 1e-9
#: largest number of k-subsets the volume formula enumerates when AttainableSet cannot (k > 6)
_MAX_VOLUME_SUBSETS = 200_000


@dataclass(frozen=True)
class AxisRange:
    """The attainable interval along one axis through the reference, the other axes held.

    ``low <= 0 <= high`` are offsets from the reference value ``reference`` (``NaN`` when the
    reference is not attainable); ``nominal_low``/``nominal_high`` the same for the healthy
    vehicle.  ``two_sided`` when the axis can move both ways (``low < 0 < high``).
    """

    axis: str
    reference: float
    low: float
    high: float
    nominal_low: float
    nominal_high: float
    independent: bool

    @property
    def two_sided(self) -> bool:
        return bool(self.low < -0.0 and self.high > 0.0)

    @property
    def fraction(self) -> float:
        """Healthy range width over the nominal width (``NaN`` when the nominal width is 0)."""
        nominal = self.nominal_high - self.nominal_low
        width = self.high - self.low
        return width / nominal if nominal > 0 and not math.isnan(width) else math.nan

    def to_dict(self) -> dict[str, Any]:
        return {"axis": self.axis, "reference": self.reference, "low": _num(self.low), "high": _num(self.high),
                "nominal_low": _num(self.nominal_low), "nominal_high": _num(self.nominal_high),
                "independent": self.independent, "two_sided": self.two_sided, "fraction": _num(self.fraction)}


@dataclass(frozen=True)
class ControllabilityReport:
    """What a vehicle controls at a health state (see :mod:`alloc.controllability`)."""

    axes: tuple[str, ...]
    failed: tuple[str, ...]
    active: tuple[str, ...]
    rank: int
    nominal_rank: int
    singular_values: tuple[float, ...]
    nominal_singular_values: tuple[float, ...]
    condition: float
    nominal_condition: float
    rank_rtol: float
    independent_axes: tuple[str, ...]
    uncontrollable_directions: tuple[tuple[float, ...], ...]
    volume: float | None
    nominal_volume: float | None
    margin: float | None
    reference: tuple[float, ...]
    reference_attainable: bool
    ranges: tuple[AxisRange, ...]
    name: str = ""

    @property
    def k(self) -> int:
        return len(self.axes)

    @property
    def full_rank(self) -> bool:
        return self.rank == self.k

    @property
    def volume_fraction(self) -> float | None:
        """Healthy attainable-set volume over the nominal (``None`` when either is unknown or 0)."""
        if self.volume is None or not self.nominal_volume:
            return None
        return self.volume / self.nominal_volume

    def range(self, axis: str) -> AxisRange:
        for r in self.ranges:
            if r.axis == axis:
                return r
        raise ProblemError(f"axis: unknown {axis!r}; axes: {', '.join(self.axes)}", field="axis")

    def to_dict(self) -> dict[str, Any]:
        """JSON-able (infinities and NaN as ``None``)."""
        return {
            "name": self.name, "axes": list(self.axes), "failed": list(self.failed), "active": list(self.active),
            "rank": self.rank, "nominal_rank": self.nominal_rank, "k": self.k, "full_rank": self.full_rank,
            "singular_values": list(self.singular_values),
            "nominal_singular_values": list(self.nominal_singular_values),
            "condition": _num(self.condition), "nominal_condition": _num(self.nominal_condition),
            "rank_rtol": self.rank_rtol, "independent_axes": list(self.independent_axes),
            "uncontrollable_directions": [list(d) for d in self.uncontrollable_directions],
            "volume": self.volume, "nominal_volume": self.nominal_volume, "volume_fraction": self.volume_fraction,
            "margin": _num(self.margin) if self.margin is not None else None,
            "reference": list(self.reference), "reference_attainable": self.reference_attainable,
            "ranges": [r.to_dict() for r in self.ranges],
        }


def _num(x: float) -> float | None:
    return float(x) if x is not None and math.isfinite(x) else None


# --------------------------------------------------------------------------- the report
def report(problem_or_vehicle: Any, health: Any = None, *, at: ArrayLike | None = None) -> ControllabilityReport:
    """Controllability of ``problem_or_vehicle`` at ``health`` (see the module docstring).

    Parameters
    ----------
    problem_or_vehicle : alloc.Problem or alloc.vehicle_file.Vehicle
    health : mapping or sequence, optional
        ``{effector: alloc.EffectorHealth}`` (names or indices), or a sequence of
        :class:`alloc.FailureEvent` applied in order; ``None``: healthy.
    at : array_like (k,), optional
        The reference point of the per-axis ranges and the margin (default: the vehicle's
        axis trims, zero for a problem).
    """
    from .vehicle_file import Vehicle

    name = ""
    if isinstance(problem_or_vehicle, Vehicle):
        nominal = problem_or_vehicle.problem()
        reference = problem_or_vehicle.trim
        name = problem_or_vehicle.name
    elif isinstance(problem_or_vehicle, Problem):
        nominal = problem_or_vehicle
        reference = np.zeros(nominal.k)
    else:
        raise ProblemError(f"problem: expected an alloc.Problem or a Vehicle, got {type(problem_or_vehicle).__name__}",
                           field="problem")
    if at is not None:
        reference = as_float_array("at", at)
        if reference.shape != (nominal.k,):
            raise ProblemError(f"at: expected shape ({nominal.k},), got {reference.shape}", field="at")
        check_magnitude("at", reference)
    healthy = nominal.with_health(_health_map(nominal, health))
    failed = tuple(nominal.names[j] for j in range(nominal.m) if not (
        np.array_equal(nominal.B[:, j], healthy.B[:, j]) and nominal.umin[j] == healthy.umin[j]
        and nominal.umax[j] == healthy.umax[j] and nominal.rate_min[j] == healthy.rate_min[j]
        and nominal.rate_max[j] == healthy.rate_max[j]))

    G0, _ = _generators(nominal)
    G, active = _generators(healthy)
    s0 = np.linalg.svd(G0, compute_uv=False) if G0.size else np.zeros(0)
    scale = float(s0[0]) if s0.size else 0.0
    nominal_rank = int((s0 > RANK_RTOL * scale).sum()) if scale > 0 else 0
    k = nominal.k
    if G.size:
        U, s, _ = np.linalg.svd(G, full_matrices=True)
    else:
        U, s = np.eye(k), np.zeros(0)
    rank = int((s > RANK_RTOL * scale).sum()) if scale > 0 else 0
    Q = U[:, :rank]
    independent = tuple(nominal.axes[i] for i in range(k)
                        if rank and np.linalg.norm(np.eye(k)[i] - Q @ Q[i]) <= RANK_RTOL)
    lost = tuple(tuple(float(x) for x in _canonical_sign(U[:, i])) for i in range(rank, k))

    volume, margin = _volume_and_margin(healthy, reference)
    nominal_volume, _ = _volume_and_margin(nominal, reference)
    attainable = _attainable(healthy, reference)
    nominal_attainable = _attainable(nominal, reference)
    ranges = []
    for i in range(k):
        lo, hi = _axis_range(healthy, reference, i) if attainable else (math.nan, math.nan)
        nlo, nhi = _axis_range(nominal, reference, i) if nominal_attainable else (math.nan, math.nan)
        ranges.append(AxisRange(nominal.axes[i], float(reference[i]), lo, hi, nlo, nhi, nominal.axes[i] in independent))
    return ControllabilityReport(
        axes=nominal.axes, failed=failed, active=tuple(nominal.names[j] for j in np.flatnonzero(active)),
        rank=rank, nominal_rank=nominal_rank,
        singular_values=tuple(float(x) for x in _padded(s, k)), nominal_singular_values=tuple(float(x) for x in
                                                                                              _padded(s0, k)),
        condition=_condition(s, k, scale), nominal_condition=_condition(s0, k, scale), rank_rtol=RANK_RTOL,
        independent_axes=independent, uncontrollable_directions=lost, volume=volume, nominal_volume=nominal_volume,
        margin=margin, reference=tuple(float(x) for x in reference), reference_attainable=attainable,
        ranges=tuple(ranges), name=name,
    )


def _health_map(nominal: Problem, health: Any) -> Mapping[Any, Any]:
    from .health import FailureEvent, apply_event

    if health is None:
        return {}
    if isinstance(health, Mapping):
        return health
    if isinstance(health, FailureEvent):
        health = [health]
    if isinstance(health, Sequence) and not isinstance(health, (str, bytes)):
        state: dict[str, Any] = {}
        for event in health:
            _, state = apply_event(nominal, state, event)
        return state
    raise ProblemError(f"health: expected a mapping of effector to EffectorHealth or a sequence of FailureEvent, "
                       f"got {type(health).__name__}", field="health")


def _generators(p: Problem) -> tuple[np.ndarray, np.ndarray]:
    """``B diag(hi - lo)`` over the effectors that move and act (and the mask of those)."""
    travel = p.umax - p.umin
    active = (travel > 0) & np.any(p.B != 0.0, axis=0)
    return p.B[:, active] * travel[active], active


def _padded(s: np.ndarray, k: int) -> np.ndarray:
    out = np.zeros(k)
    out[: min(k, s.size)] = s[:k]
    return out


def _condition(s: np.ndarray, k: int, scale: float) -> float:
    if s.size < k or scale <= 0 or not s[k - 1] > RANK_RTOL * scale:
        return math.inf
    return float(s[0] / s[k - 1])


def _canonical_sign(v: np.ndarray) -> np.ndarray:
    """``v`` with its largest-magnitude component positive (a direction has no sign)."""
    i = int(np.argmax(np.abs(v)))
    return v if v[i] >= 0 else -v


def _volume_and_margin(p: Problem, reference: np.ndarray) -> tuple[float | None, float | None]:
    from .ams import AttainableSet, zonotope_volume
    from math import comb

    try:
        ams = AttainableSet(p)
    except ProblemError:
        travel = p.umax - p.umin
        n = int(((travel > 0) & np.any(p.B != 0.0, axis=0)).sum())
        if comb(n, p.k) > _MAX_VOLUME_SUBSETS:
            return None, None
        return float(zonotope_volume(p.B, p.umin, p.umax)), None
    if ams.rank < p.k:
        return 0.0, 0.0 if ams.contains(reference) else -math.inf
    margins = ams.offsets - ams.normals @ reference
    return float(ams.volume), float(margins.min()) if margins.size else None


def _attainable(p: Problem, reference: np.ndarray) -> bool:
    """Whether some ``umin <= u <= umax`` has ``B u = reference`` (a feasibility LP)."""
    from scipy.optimize import linprog

    res = linprog(np.zeros(p.m), A_eq=p.B, b_eq=reference, bounds=list(zip(p.umin.tolist(), p.umax.tolist())),
                  method="highs")
    if res.status not in (0, 2):
        raise ProblemError(f"at: the attainability linear program failed ({res.message})", field="at")
    return res.status == 0


def _axis_range(p: Problem, reference: np.ndarray, i: int) -> tuple[float, float]:
    """``(low, high)``: the extremes of ``t`` with ``B u = reference + t e_i`` and ``umin <= u <= umax``
    (``reference`` attainable, so ``low <= 0 <= high``)."""
    from scipy.optimize import linprog

    k, m = p.k, p.m
    e = np.zeros((k, 1))
    e[i] = -1.0
    A_eq = np.hstack([p.B, e])  # B u - t e_i = reference
    bounds = [(float(lo), float(hi)) for lo, hi in zip(p.umin, p.umax)] + [(None, None)]
    out = []
    for sense in (1.0, -1.0):  # minimise t, then maximise it
        c = np.zeros(m + 1)
        c[-1] = sense
        res = linprog(c, A_eq=A_eq, b_eq=reference, bounds=bounds, method="highs")
        if res.status == 2:  # infeasible: the reference point is not attainable
            return math.nan, math.nan
        if res.status != 0:
            raise ProblemError(f"axes[{i}]: the range linear program failed ({res.message})", field="axes")
        out.append(float(res.x[-1]))
    low, high = out
    return min(low, 0.0), max(high, 0.0)

"""Closed-loop simulation result shared by every scenario.

Glossary (one name for one thing):

* ``reference`` -- reference-model outputs the controlled variables must track
  (seed: ``y_m``).
* ``output`` -- true plant outputs for those controlled variables (``y``).
* ``command`` -- pilot / commanded inputs to the reference models (``y_c``).
* ``pseudo`` -- sliding-mode pseudo-commands handed to the allocator; the
  allocator demand ``v`` (seed: ``u_SMC`` before the control distribution).
* ``effectors`` -- actual effector positions after actuator dynamics (``u``).

Tracking error is ``reference - output``.  Metrics are split at
``failure_time``: "before" covers ``t < failure_time`` and "after" covers
``t >= failure_time``.  With no failure, every "after" metric is NaN, written
as ``null`` in JSON.

Divergence rule (documented once, applied by every scenario through
:func:`divergence_check`): a run is *diverged* when any state or output is
non-finite, or when any controlled output exceeds the scenario's bound
``|output| > output_bound`` (a per-channel bound far outside the flight
envelope, chosen by the scenario).  The closed-loop engine (:mod:`sim.engine`)
applies the same bound to each channel's reference-model output: a reference
that leaves it is a pilot-loop runaway (the pilot keeps asking for more while
the plant output stays bounded), a loss of control as well.  A diverged run stops at the first
offending step; its arrays are truncated to the samples actually simulated
(nothing is padded or extrapolated) and ``diverged`` is ``True``.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from alloc.result import Status
from sim.criteria import tracking_metrics, verdict_of

__all__ = ["SimResult", "STATUS_NAMES", "divergence_check", "tracking_metrics"]

#: allocator status codes (index = code): the :class:`alloc.Status` values in their declared order
STATUS_NAMES: tuple[str, ...] = tuple(status.value for status in Status)

# An effector counts as "in saturation" when within this fraction of its
# position (or rate) range of the limit; exact equality is fragile with
# first-order actuators approaching a limit asymptotically.
SATURATION_TOLERANCE = 1e-3


def divergence_check(y: np.ndarray, bound: np.ndarray | float, *states: np.ndarray) -> bool:
    """Return True when the run has diverged (see module docstring).

    Parameters
    ----------
    y : ndarray
        Controlled outputs at the current step.
    bound : float or ndarray
        Scenario bound on ``|y|`` (per channel or scalar).
    *states : ndarray
        Any further states to check for non-finite values.
    """
    if not np.all(np.isfinite(y)) or np.any(np.abs(y) > bound):
        return True
    return any(not np.all(np.isfinite(s)) for s in states)


def _none_if_nan(x: float) -> float | None:
    return None if (x is None or not math.isfinite(x)) else float(x)


@dataclass
class SimResult:
    """Time histories and metadata of one closed-loop run.

    Arrays are sampled on ``t`` (N samples, possibly decimated from the
    integration step).  Shapes: ``reference``, ``output``, ``command`` are
    ``(N, nch)``; ``pseudo`` and ``unallocated`` are ``(N, k)``;
    ``effectors`` and ``effector_rates`` are ``(N, m)``.
    """

    scenario: str
    method: str | None
    failure: str | None
    t: np.ndarray
    channels: list[str]
    reference: np.ndarray
    output: np.ndarray
    command: np.ndarray
    pseudo: np.ndarray | None = None
    effectors: np.ndarray | None = None
    effector_rates: np.ndarray | None = None
    effector_names: list[str] = field(default_factory=list)
    #: (lo, hi), each (m,) or (N, m) when failures change them during the run
    effector_limits: tuple[np.ndarray, np.ndarray] | None = None
    #: (min, max) rates, each (m,) or (N, m)
    rate_limits: tuple[np.ndarray, np.ndarray] | None = None
    failure_time: float | None = None
    diverged: bool = False
    unallocated: np.ndarray | None = None
    extra: dict[str, np.ndarray] = field(default_factory=dict)
    #: time (s) of every allocator call (one per flight-control frame)
    allocator_t: np.ndarray | None = None
    #: status of every allocator call, codes into :data:`STATUS_NAMES`
    allocator_status: np.ndarray | None = None
    #: the run's settings, JSON-ready: every :class:`sim.settings.RunSettings` field as flown (a MIMO
    #: scenario; the engine alone records the :class:`~sim.settings.LoopSettings` ones) and ``pilots``
    settings: dict[str, Any] = field(default_factory=dict)
    #: a ``detected`` run's detections (:func:`sim.detection.detection_record`), None otherwise
    detections: list[dict[str, Any]] | None = None
    #: a ``detected`` run's withdrawn detections (:mod:`alloc.estimation.harm`), None otherwise
    withdrawals: list[dict[str, Any]] | None = None
    #: a ``detected`` run's detector as flown: its response outputs, design and monitor (:mod:`sim.detection`)
    detector: dict[str, Any] | None = None

    # ------------------------------------------------------------------ metrics
    @property
    def duration(self) -> float:
        """Simulated time actually covered (shorter than asked when diverged)."""
        return float(self.t[-1] - self.t[0]) if self.t.size else 0.0

    @property
    def error(self) -> np.ndarray:
        """Tracking error ``reference - output``, shape (N, nch)."""
        return self.reference - self.output

    def _dt(self) -> float:
        return float(self.t[1] - self.t[0]) if self.t.size > 1 else 0.0

    def _saturated(self, x: np.ndarray | None, limits: tuple[np.ndarray, np.ndarray] | None) -> np.ndarray | None:
        if x is None or limits is None:
            return None
        if x.size == 0:
            return np.zeros(x.shape[0], dtype=bool)
        lo, hi = (np.asarray(a, dtype=float) for a in limits)
        span = np.where(np.isfinite(hi - lo), hi - lo, np.inf)
        tol = SATURATION_TOLERANCE * span
        # A limit at zero is a rest position, not a saturation: a one-sided effector
        # (ICE tips and spoiler-slot deflectors, 0..60 deg) sits there whenever unused.
        sat = ((x <= lo + tol) & (lo != 0.0)) | ((x >= hi - tol) & (hi != 0.0))
        # A jammed effector (lo == hi) is not "saturated" in any useful sense.
        sat &= span > 0
        return np.any(sat, axis=1)

    def saturated_samples(self, kind: str) -> np.ndarray | None:
        """Per recorded sample, whether any effector sits at a position (``kind="position"``) or rate
        (``"rate"``) limit, shape (N,); None when the run recorded no effectors or limits."""
        if kind == "position":
            return self._saturated(self.effectors, self.effector_limits)
        if kind == "rate":
            return self._saturated(self.effector_rates, self.rate_limits)
        raise ValueError(f"kind: {kind!r}; expected 'position' or 'rate'")

    def _time_in_saturation(self, kind: str) -> float:
        sat = self.saturated_samples(kind)
        return 0.0 if sat is None else float(np.count_nonzero(sat) * self._dt())

    @property
    def time_in_position_saturation(self) -> float:
        """Seconds during which any effector sits at a position limit (a limit at zero, the
        rest position of a one-sided effector, does not count)."""
        return self._time_in_saturation("position")

    @property
    def time_in_rate_saturation(self) -> float:
        """Seconds during which any effector moves at its rate limit."""
        return self._time_in_saturation("rate")

    def status_fraction(self, status: Status | str) -> float | None:
        """Fraction of allocator calls that returned ``status`` (None: no calls recorded).

        Raises ``ValueError`` for a name that is not an :class:`alloc.Status`.
        """
        if self.allocator_status is None or self.allocator_status.size == 0:
            return None
        return float(np.mean(self.allocator_status == STATUS_NAMES.index(Status(status).value)))

    def summary(self) -> dict[str, Any]:
        """JSON-serialisable metrics (see module docstring for definitions); ``verdict``: the run
        judged by its scenario's engineering criteria (:mod:`sim.criteria`; None without a table)."""
        verdict = verdict_of(self)
        err = self.error
        if self.failure_time is None:
            before = np.ones(self.t.shape, dtype=bool)
        else:
            before = self.t < self.failure_time
        after = ~before if self.failure_time is not None else np.zeros_like(before)
        channels: dict[str, dict[str, float | None]] = {}
        for j, name in enumerate(self.channels):
            rb, mb = tracking_metrics(err[:, j], before)
            ra, ma = tracking_metrics(err[:, j], after)
            channels[name] = {
                "rms_before": _none_if_nan(rb),
                "rms_after": _none_if_nan(ra),
                "max_before": _none_if_nan(mb),
                "max_after": _none_if_nan(ma),
            }
        return {
            "scenario": self.scenario,
            "method": self.method,
            "failure": self.failure,
            "failure_time": self.failure_time,
            "duration": self.duration,
            "diverged": bool(self.diverged),
            "channels": channels,
            "time_in_position_saturation": self.time_in_position_saturation,
            "time_in_rate_saturation": self.time_in_rate_saturation,
            "allocator_calls": None if self.allocator_status is None else int(self.allocator_status.size),
            "fallback_fraction": self.status_fraction(Status.FALLBACK),
            "unattainable_fraction": self.status_fraction(Status.UNATTAINABLE),
            "settings": self.settings,
            "verdict": None if verdict is None else verdict.to_json(),
            **({} if self.detections is None else {"detections": self.detections}),
            **({} if self.withdrawals is None else {"withdrawals": self.withdrawals}),
            **({} if self.detector is None else {"detector": self.detector}),
        }

    def time_histories(self) -> dict[str, np.ndarray | list[str]]:
        """The recorded time histories by column name, one entry per recorded sample.

        Columns: ``t``; per channel ``ref_``, ``out_``, ``cmd_``, ``pseudo_``,
        ``unalloc_``; per effector ``pos_`` and ``rate_``; per pilot its command
        and attitude; ``alloc_status`` (a list of str), the status of the
        allocator call in force at the sample (``exact``/``unattainable``/
        ``fallback``), when the run recorded one.
        """
        columns: dict[str, np.ndarray | list[str]] = {"t": self.t}
        for prefix, arr in (("ref", self.reference), ("out", self.output), ("cmd", self.command),
                            ("pseudo", self.pseudo), ("unalloc", self.unallocated)):
            if arr is not None:
                for j, name in enumerate(self.channels):
                    columns[f"{prefix}_{name}"] = arr[:, j]
        for prefix, arr in (("pos", self.effectors), ("rate", self.effector_rates)):
            if arr is not None:
                for j, name in enumerate(self.effector_names):
                    columns[f"{prefix}_{name}"] = arr[:, j]
        for name, arr in self.extra.items():
            columns[name] = arr
        if self.allocator_status is not None and self.allocator_t is not None and self.allocator_status.size:
            idx = np.searchsorted(self.allocator_t, self.t + 1e-12, side="right") - 1
            columns["alloc_status"] = [STATUS_NAMES[c] if c >= 0 else "" for c in self.allocator_status[np.clip(idx, 0, None)]]
        return columns

    def to_csv(self, path: str | Path) -> Path:
        """Write :meth:`time_histories` as CSV, one row per recorded sample (numbers to 9 digits)."""
        columns = self.time_histories()
        status = columns.pop("alloc_status", None)
        out = Path(path)
        with out.open("w") as fh:
            fh.write(",".join(list(columns) + (["alloc_status"] if status else [])) + "\n")
            table = np.column_stack(list(columns.values()))
            for i, row in enumerate(table):
                fh.write(",".join(f"{x:.9g}" for x in row) + (f",{status[i]}" if status else "") + "\n")
        return out

    def to_parquet(self, path: str | Path) -> Path:
        """Write :meth:`time_histories` as Parquet (float64 columns, exact; ``alloc_status`` as string).

        The run's :attr:`settings` and scenario/method/failure go into the file's
        key-value metadata (``alloc.sim`` key, JSON).  Needs ``pyarrow`` (the ``sim`` extra).
        """
        import pyarrow as pa
        import pyarrow.parquet as pq

        table = pa.table(self.time_histories())
        meta = {"scenario": self.scenario, "method": self.method, "failure": self.failure,
                "failure_time": self.failure_time, "diverged": bool(self.diverged), "settings": self.settings}
        table = table.replace_schema_metadata({"alloc.sim": json.dumps(meta, default=float)})
        out = Path(path)
        pq.write_table(table, out)
        return out

    def to_json(self, path: str | Path) -> None:
        """Write :meth:`summary` to ``path`` as indented JSON."""
        Path(path).write_text(json.dumps(self.summary(), indent=2, allow_nan=False) + "\n")

"""Engineering pass/fail criteria of a closed-loop run, beside (not instead of) divergence.

Divergence (:func:`sim.result.divergence_check`) says only that a run left a bound far outside
the flight envelope.  These criteria say whether an engineer would accept the flight: each
scenario has one table (:data:`CRITERIA`) of limits, each limit with its source or, where
nobody gives a number, the project's choice and why (``source`` starts with ``"ours"``; every
such number is listed by :func:`free_parameters`).

Judged signals (*axes*): every controlled channel (tracking error ``reference - output``).  The
pilot's bank-angle error ``phi_command - phi`` is not judged: the seed puts the lag between
commanded and achieved bank angle "almost entirely" on the pilot (section 4.6, Fig 4-61), and
the pilot here is a stand-in (:mod:`sim.pilot`), so that error would judge the pilot model.
(With the crossover pilot, ``qp`` told on ICE's seed failure has a bank-angle error RMS of
5.3 deg before the failure, 1.7 x the nominal fraction below, while its channels meet theirs.)
Each run is split at the failure as in :mod:`sim.result`: ``before`` is judged against the
nominal limits (MIL-F-8785C Level 1), ``after`` against the failed-state limits (Level 2,
which MIL-F-8785C 3.1.10 accepts in failure states that are not extremely improbable;
recalled).  With no failure the whole run is ``before``.  Criteria (the names in ``broken``):

* ``<axis>_rms_<phase>``, ``<axis>_max_<phase>`` -- RMS and peak ``|error|`` (the same numbers
  as :meth:`sim.result.SimResult.summary`'s channels).
* ``<axis>_excursion_<phase>`` -- peak ``|output|`` of a regulated axis (sideslip, reference 0).
* ``position_saturation_<phase>``, ``rate_saturation_<phase>`` -- fraction of the phase's samples
  in which any effector sits at a position (rate) limit (:meth:`SimResult.saturated_samples`),
  leaving out, from the failure time on, every effector the *injected* failure takes out of
  command (:data:`OUT_OF_COMMAND`: jammed, hard-over, floating; :func:`failed_effectors`).  Such
  an effector sits where the failure put it, on a stop for a hard-over, whatever the allocator
  does, so counting it would break the criterion by construction.  What the allocator believes
  plays no part: the failure comes from the run's scenario (:func:`known_failed_effectors`).
* ``back_in_band_s`` -- seconds from the failure until every axis's ``|error|`` (``|output|``
  for an excursion axis) is inside its nominal peak limit and stays there for
  :data:`RECOVERY_HOLD_S`; ``inf`` when that never happens within the run.  Not judged
  without a failure, or when the failure is at the run's start (nothing to recover to).
* ``diverged`` -- the run diverged (then every metric covers the samples flown).

A metric with no samples (no ``after`` without a failure) is ``None`` and is not judged.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from dataclasses import replace
from typing import TYPE_CHECKING, Any, ClassVar, Protocol

import numpy as np

from alloc.health import Effect

if TYPE_CHECKING:
    from sim.model import Failure

__all__ = [
    "Limit", "AxisLimits", "ScenarioCriteria", "Verdict", "CRITERIA", "criteria_for", "evaluate", "verdict_of",
    "use_scenario", "demand_criteria", "tracking_metrics", "failed_effectors", "known_failed_effectors",
    "register_failure_source",
    "OUT_OF_COMMAND",
    "SATURATION_RULE",
    "back_in_band_time", "free_parameters", "PHASES", "RECOVERY_HOLD_S", "RECOVERY_MAX_S",
    "NOMINAL_RMS_FRACTION", "FAILED_RMS_FRACTION", "NOMINAL_PEAK_FRACTION", "FAILED_PEAK_FRACTION",
    "SATURATION_MAX_FRACTION", "SIDESLIP_RMS_DEG", "render_markdown",
]


class Run(Protocol):
    """What the criteria read of a run (a :class:`sim.result.SimResult` is one).  Declared here so
    that the judge depends on the run's shape, not on the result module, which asks the judge
    for its summary's verdict: one direction of import, result -> criteria."""

    #: a dataclass: the saturation shares copy it with some effectors' columns left out
    __dataclass_fields__: ClassVar[dict[str, Any]]
    scenario: str
    failure: str | None
    t: np.ndarray
    channels: list[str]
    reference: np.ndarray
    output: np.ndarray
    effectors: np.ndarray | None
    effector_rates: np.ndarray | None
    effector_limits: tuple[np.ndarray, np.ndarray] | None
    rate_limits: tuple[np.ndarray, np.ndarray] | None
    failure_time: float | None
    diverged: bool

    def saturated_samples(self, kind: str) -> np.ndarray | None: ...


PHASES = ("before", "after")

#: error RMS limit as a fraction of the demand's RMS, nominal (ours: a quarter of the signal
#: is a clearly visible but usable lag; no standard gives a tracking-error number)
NOMINAL_RMS_FRACTION = 0.25
#: the same after a failure (ours: twice the nominal, as Level 2 allows degraded tracking)
FAILED_RMS_FRACTION = 0.5
#: peak |error| limit as a fraction of the demand's peak, nominal (ours)
NOMINAL_PEAK_FRACTION = 0.5
#: the same after a failure (ours: an error as large as the largest demand is lost tracking)
FAILED_PEAK_FRACTION = 1.0
#: sideslip RMS limit (deg), nominal and failed (ours: a sixth of the MIL-F-8785C excursion lines)
SIDESLIP_RMS_DEG = (1.0, 2.5)
#: sideslip excursion limits (deg), nominal and failed: MIL-F-8785C 3.3.2.4, Table VIII
SIDESLIP_EXCURSION_DEG = (6.0, 15.0)
SIDESLIP_SOURCE = ("MIL-F-8785C 3.3.2.4 Table VIII: adverse sideslip, Level 1 Category A 6 deg, Levels 2-3 "
                   "15 deg (applied as |beta|, not per unit roll command k; recalled, not checked against a "
                   "copy in this checkout)")
#: hold time (s) inside the nominal band that counts as recovered (ours: two periods of the
#: fastest sum-of-sines component a pilot follows, about 1 rad/s)
RECOVERY_HOLD_S = 2.0
#: latest acceptable recovery after the failure (s) (ours: a pilot's corrective action starts
#: about 1 s after a failure; 5 s leaves four for the loop to settle)
RECOVERY_MAX_S = 5.0
#: largest fraction of a phase with any effector on a position (rate) stop (ours: on a stop for
#: half the time an effector has lost half its authority; rate limiting adds phase lag, the
#: Category II PIO trigger).  The seed's own HARV Failure #1 (Fig 4-70: three effectors in
#: "almost constant rate saturation", called Level II) would break the rate limit.
SATURATION_MAX_FRACTION = 0.5
#: the effects of a failure that take an effector out of command: it holds, runs to a stop or
#: trails whatever it is commanded (alloc.health Effect), so its stops say nothing of the allocator
OUT_OF_COMMAND = frozenset({Effect.HOLD, Effect.RUN_TO_STOP, Effect.TRAIL})
#: the saturation shares' rule as the criteria table states it
SATURATION_RULE = ("from the failure time on, effectors the injected failure jams, drives hard-over or lets float "
                   "are left out (the simulation's failure, not the allocator's belief)")


@dataclass(frozen=True)
class Limit:
    """One limit: ``value`` (in the axis's units, seconds or a fraction) and where it comes from."""

    value: float
    source: str


@dataclass(frozen=True)
class AxisLimits:
    """Limits on one judged signal, each a (nominal, failed) pair of :class:`Limit` or None (not judged).

    ``signal`` is a channel name.
    """

    signal: str
    rms: tuple[Limit, Limit] | None = None
    peak: tuple[Limit, Limit] | None = None
    excursion: tuple[Limit, Limit] | None = None
    #: what a limit given as a fraction is a fraction of (empty: absolute limits)
    basis: str = ""

    def band(self) -> float:
        """The nominal peak limit (of the error, or of the output for an excursion axis): the recovery band."""
        pair = self.peak if self.peak is not None else self.excursion
        if pair is None:
            raise ValueError(f"axis {self.signal!r}: no peak or excursion limit to recover into")
        return pair[0].value


@dataclass(frozen=True)
class ScenarioCriteria:
    """A scenario's pass/fail table."""

    scenario: str
    axes: tuple[AxisLimits, ...]
    recovery_hold: Limit
    recovery_max: Limit
    saturation_max: Limit

    def limits(self) -> dict[str, float]:
        """Every criterion's limit by its name (module docstring)."""
        out: dict[str, float] = {}
        for axis in self.axes:
            for kind, pair in (("rms", axis.rms), ("max", axis.peak), ("excursion", axis.excursion)):
                if pair is not None:
                    for phase, limit in zip(PHASES, pair, strict=True):
                        out[f"{axis.signal}_{kind}_{phase}"] = limit.value
        for phase in PHASES:
            out[f"position_saturation_{phase}"] = self.saturation_max.value
            out[f"rate_saturation_{phase}"] = self.saturation_max.value
        out["back_in_band_s"] = self.recovery_max.value
        return out

    def sources(self) -> dict[str, str]:
        """Every criterion's source by its name."""
        out: dict[str, str] = {}
        for axis in self.axes:
            for kind, pair in (("rms", axis.rms), ("max", axis.peak), ("excursion", axis.excursion)):
                if pair is not None:
                    for phase, limit in zip(PHASES, pair, strict=True):
                        out[f"{axis.signal}_{kind}_{phase}"] = limit.source
        for phase in PHASES:
            out[f"position_saturation_{phase}"] = self.saturation_max.source
            out[f"rate_saturation_{phase}"] = self.saturation_max.source
        out["back_in_band_s"] = f"{self.recovery_max.source}; hold {self.recovery_hold.value:g} s: " \
                                f"{self.recovery_hold.source}"
        return out


@dataclass(frozen=True)
class Verdict:
    """A run's verdict: ``passed`` iff nothing in ``broken``; ``metrics`` by criterion name (None: not judged)."""

    passed: bool
    broken: tuple[str, ...]
    metrics: dict[str, float | None]
    limits: dict[str, float]

    def to_json(self) -> dict[str, Any]:
        """``{"pass", "broken", "metrics", "limits"}``; an infinite metric is written as the string ``"inf"``,
        a NaN one (a non-finite signal: diverged) as None."""
        def cell(x: float | None) -> float | str | None:
            if x is None or math.isnan(x):
                return None
            return "inf" if math.isinf(x) else x
        return {"pass": self.passed, "broken": list(self.broken),
                "metrics": {k: cell(v) for k, v in self.metrics.items()}, "limits": dict(self.limits)}


# ----------------------------------------------------------------------------- the table
def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(x))))


def _demand_limits(signal: str, demand: np.ndarray, what: str) -> AxisLimits:
    """RMS and peak error limits as fractions of a demand's RMS and peak (over the seed's run)."""
    rms, peak = _rms(demand), float(np.max(np.abs(demand)))
    rms_why = (f"ours: NOMINAL_RMS_FRACTION {NOMINAL_RMS_FRACTION:g} / FAILED_RMS_FRACTION {FAILED_RMS_FRACTION:g} "
               "x the demand's RMS")
    peak_why = (f"ours: NOMINAL_PEAK_FRACTION {NOMINAL_PEAK_FRACTION:g} / FAILED_PEAK_FRACTION "
                f"{FAILED_PEAK_FRACTION:g} x the demand's peak")
    return AxisLimits(
        signal,
        rms=(Limit(NOMINAL_RMS_FRACTION * rms, rms_why), Limit(FAILED_RMS_FRACTION * rms, rms_why)),
        peak=(Limit(NOMINAL_PEAK_FRACTION * peak, peak_why), Limit(FAILED_PEAK_FRACTION * peak, peak_why)),
        basis=f"{what}: RMS {rms:.3g}, peak {peak:.3g} over the seed's run",
    )


def _sideslip(signal: str) -> AxisLimits:
    rms_why = "ours: about a sixth of the MIL-F-8785C Table VIII excursion line"
    return AxisLimits(
        signal,
        rms=(Limit(SIDESLIP_RMS_DEG[0], rms_why), Limit(SIDESLIP_RMS_DEG[1], rms_why)),
        excursion=(Limit(SIDESLIP_EXCURSION_DEG[0], SIDESLIP_SOURCE), Limit(SIDESLIP_EXCURSION_DEG[1], SIDESLIP_SOURCE)),
    )


def _common(scenario: str, axes: tuple[AxisLimits, ...]) -> ScenarioCriteria:
    return ScenarioCriteria(
        scenario, axes,
        recovery_hold=Limit(RECOVERY_HOLD_S, "ours (RECOVERY_HOLD_S)"),
        recovery_max=Limit(RECOVERY_MAX_S, "ours (RECOVERY_MAX_S)"),
        saturation_max=Limit(SATURATION_MAX_FRACTION, f"ours (SATURATION_MAX_FRACTION); {SATURATION_RULE}"),
    )


def _seed_run(scenario: Any) -> np.ndarray:
    return np.arange(0.0, scenario.default_duration, 0.01)


def _ice(scenario: Any) -> ScenarioCriteria:
    t = _seed_run(scenario)
    phi_c = scenario.pilot({}).attitude_command(t)
    return _common("ice", (
        _demand_limits("alphaw", scenario.commands(t)[:, 0], "the alpha command (deg; seed section 4.7, xi = 5)"),
        _demand_limits("ps", np.gradient(phi_c, t), "the bank-angle command's rate (deg/s; xi = 10)"),
        _sideslip("betaw"),
    ))


def _harv_latdir(scenario: Any) -> ScenarioCriteria:
    t = _seed_run(scenario)
    phi_c = scenario.pilot({}).attitude_command(t)
    return _common("harv_latdir", (
        _sideslip("beta"),
        _demand_limits("ps", np.gradient(phi_c, t), "the bank-angle command's rate (deg/s; seed section 4.6, xi = 6)"),
    ))


def demand_criteria(scenario: str, demands: dict[str, tuple[np.ndarray, str]]) -> ScenarioCriteria:
    """The table of a loop without a seed scenario: per channel, RMS and peak error limits as the same
    fractions of its demand (``demands[channel] = (demand samples, what they are)``), the common recovery
    and saturation limits.  Used for a plant's own loop (``benchmarks/bench_f22_failures.py``)."""
    return _common(scenario, tuple(_demand_limits(c, np.asarray(d, dtype=float), what)
                                   for c, (d, what) in demands.items()))


#: the per-scenario tables, by scenario name: each built from the scenario's own commands and
#: pilot, so from the scenario object the run flew (a seed scenario or a vehicle file's loop)
CRITERIA: dict[str, Callable[[Any], ScenarioCriteria]] = {"ice": _ice, "harv_latdir": _harv_latdir}
#: the scenario objects seen so far, by name: ``@mimo_scenario`` registers the seed's at import and
#: ``run_mimo`` every scenario it flies, so this module never imports a scenario (they import it)
_SCENARIOS: dict[str, Any] = {}
_BUILT: dict[str, ScenarioCriteria] = {}


def use_scenario(scenario: Any) -> None:
    """Make ``scenario`` (a :class:`sim.scenarios.mimo.MimoScenario`) the one whose table is built."""
    if _SCENARIOS.get(scenario.name) is not scenario:
        _SCENARIOS[scenario.name] = scenario
        _BUILT.pop(scenario.name, None)


def criteria_for(scenario: str) -> ScenarioCriteria | None:
    """The scenario's table, or None when it has none or its scenario was never registered
    (import its module, or fly it with ``run_mimo``)."""
    build, flown = CRITERIA.get(scenario), _SCENARIOS.get(scenario)
    if build is None or flown is None:
        return None
    if scenario not in _BUILT:
        _BUILT[scenario] = build(flown)
    return _BUILT[scenario]


def tracking_metrics(err: np.ndarray, mask: np.ndarray) -> tuple[float, float]:
    """RMS and max-abs of ``err`` over the samples selected by ``mask``.

    Returns ``(nan, nan)`` when the mask is empty.
    """
    sel = err[mask]
    if sel.size == 0:
        return math.nan, math.nan
    return float(np.sqrt(np.mean(sel**2))), float(np.max(np.abs(sel)))


# ----------------------------------------------------------------------------- metrics
def back_in_band_time(t: np.ndarray, inside: np.ndarray, failure_time: float, hold_s: float) -> float:
    """Seconds from ``failure_time`` to the first sample from which ``inside`` (bool per sample)
    holds for ``hold_s``; ``inf`` when no such stretch fits in the samples after the failure."""
    after = t >= failure_time
    ta, ok = t[after], inside[after]
    if ta.size == 0:
        return math.inf
    # index of the last sample outside the band at or before each sample (-1: none yet)
    last_out = np.maximum.accumulate(np.where(ok, -1, np.arange(ok.size)))
    start_idx = last_out + 1
    valid = ok & (start_idx < ok.size)
    start_t = np.where(valid, ta[np.minimum(start_idx, ok.size - 1)], np.inf)
    held = valid & (ta - start_t >= hold_s - 1e-9)
    if not np.any(held):
        return math.inf
    first = int(np.argmax(held))
    return float(start_t[first] - failure_time)


def failed_effectors(failure: Failure | None) -> tuple[int, ...]:
    """Indices of the effectors ``failure`` takes out of command (:data:`OUT_OF_COMMAND`), in
    order; a ``repair`` of an effector in the same failure puts it back in command."""
    out: dict[int, None] = {}
    for f in () if failure is None else failure.actuators:
        effects = set(f.spec.effects)
        if Effect.REPAIR in effects:
            out.pop(f.index, None)
        elif effects & OUT_OF_COMMAND:
            out[f.index] = None
    return tuple(out)


#: further places a run's failure is rebuilt from by name: ``(scenario, name, time) -> Failure | None``
#: (the comparison sweep's catalogue registers its own, so this module never imports the benchmarks)
_FAILURE_SOURCES: list[Callable[[str, str, float | None], Failure | None]] = []


def register_failure_source(source: Callable[[str, str, float | None], Failure | None]) -> None:
    """Let :func:`known_failed_effectors` find failures by name in ``source`` (None: not one of its)."""
    if source not in _FAILURE_SOURCES:
        _FAILURE_SOURCES.append(source)


def known_failed_effectors(result: Run) -> tuple[int, ...]:
    """:func:`failed_effectors` of the failure ``result`` flew, rebuilt by name from its scenario or a
    registered source (:func:`register_failure_source`).

    Empty without a failure, or when neither knows the failure's name (a :class:`sim.model.Failure`
    handed straight to the runner from elsewhere): then every effector counts, as without the rule.
    """
    if result.failure is None:
        return ()
    scenario = _SCENARIOS.get(result.scenario)
    if scenario is not None:
        try:
            # its own failures, its catalogue names and grammar texts (sim.failure_catalogue)
            return failed_effectors(scenario.resolve_failure(result.failure, result.failure_time))
        except (KeyError, ValueError):
            pass  # not one the scenario resolves: a registered source may know it
    for source in _FAILURE_SOURCES:
        failure = source(result.scenario, result.failure, result.failure_time)
        if failure is not None:
            return failed_effectors(failure)
    return ()


def _saturation(result: Run, kind: str, excluded: tuple[int, ...]) -> np.ndarray | None:
    """Per sample, whether any effector but ``excluded`` sits at a ``kind`` limit (None: not recorded)."""
    if not excluded or result.effectors is None:
        return result.saturated_samples(kind)
    keep = np.setdiff1d(np.arange(result.effectors.shape[1]), excluded)

    def columns(pair: tuple[np.ndarray, np.ndarray] | None) -> tuple[np.ndarray, np.ndarray] | None:
        return None if pair is None else (np.asarray(pair[0])[..., keep], np.asarray(pair[1])[..., keep])

    rates = None if result.effector_rates is None else result.effector_rates[:, keep]
    kept = replace(result, effectors=result.effectors[:, keep], effector_rates=rates,
                   effector_limits=columns(result.effector_limits), rate_limits=columns(result.rate_limits))
    return kept.saturated_samples(kind)


def _signals(result: Run, axis: AxisLimits) -> tuple[np.ndarray, np.ndarray] | None:
    """(error, output) of an axis, or None when the run does not have that channel."""
    if axis.signal not in result.channels:
        return None
    j = result.channels.index(axis.signal)
    return result.reference[:, j] - result.output[:, j], result.output[:, j]


def _masked(stat: Callable[[np.ndarray], float], x: np.ndarray, mask: np.ndarray) -> float | None:
    return stat(x[mask]) if np.any(mask) else None


def evaluate(result: Run, criteria: ScenarioCriteria, *,
             failed: tuple[int, ...] | None = None) -> Verdict:
    """Judge ``result`` against ``criteria`` (module docstring).

    ``failed``: the effectors left out of the saturation shares from the failure time on;
    None: :func:`known_failed_effectors` of the run.
    """
    excluded = known_failed_effectors(result) if failed is None else tuple(int(i) for i in failed)
    t = result.t
    failure = result.failure_time
    before = np.ones(t.shape, dtype=bool) if failure is None else t < failure
    masks = {"before": before, "after": ~before if failure is not None else np.zeros_like(before)}
    metrics: dict[str, float | None] = {}
    inside = np.ones(t.shape, dtype=bool)
    for axis in criteria.axes:
        signals = _signals(result, axis)
        if signals is None:
            continue
        err, out = signals
        for phase, mask in masks.items():
            rms, peak = tracking_metrics(err, mask) if np.any(mask) else (None, None)
            if axis.rms is not None:
                metrics[f"{axis.signal}_rms_{phase}"] = rms
            if axis.peak is not None:
                metrics[f"{axis.signal}_max_{phase}"] = peak
            if axis.excursion is not None:
                metrics[f"{axis.signal}_excursion_{phase}"] = tracking_metrics(out, mask)[1] if np.any(mask) else None
        inside &= np.abs(err if axis.peak is not None else out) <= axis.band()
    for kind in ("position", "rate"):
        # before the failure every effector counts; after it, only those still in command
        sats = {"before": result.saturated_samples(kind), "after": _saturation(result, kind, excluded)}
        for phase, mask in masks.items():
            sat = sats[phase]
            metrics[f"{kind}_saturation_{phase}"] = (None if sat is None else
                                                     _masked(lambda x: float(np.mean(x)), sat, mask))
    # nothing to recover to before a failure at the start; a stretch shorter than the hold cannot show it
    judge_recovery = (failure is not None and t.size > 0 and failure > t[0]
                      and (result.diverged or t[-1] - failure >= criteria.recovery_hold.value - 1e-9))
    metrics["back_in_band_s"] = (
        (math.inf if result.diverged else back_in_band_time(t, inside, failure, criteria.recovery_hold.value))
        if judge_recovery and failure is not None else None)  # judge_recovery implies it; mypy cannot see it
    limits = criteria.limits()
    broken = [name for name, value in metrics.items()
              if value is not None and name in limits and not value <= limits[name]]
    if result.diverged:
        broken.insert(0, "diverged")
    return Verdict(passed=not broken, broken=tuple(broken), metrics=metrics,
                   limits={k: v for k, v in limits.items() if k in metrics})


def verdict_of(result: Run) -> Verdict | None:
    """The verdict of ``result`` by its scenario's table; None for a scenario without one."""
    criteria = criteria_for(result.scenario)
    return None if criteria is None else evaluate(result, criteria)


def free_parameters() -> list[tuple[str, str, str]]:
    """(name, value, why) of every number in the criteria that no standard or the seed gives."""
    return [
        ("criteria NOMINAL_RMS_FRACTION", f"{NOMINAL_RMS_FRACTION:g}", "error RMS / demand RMS, before the failure"),
        ("criteria FAILED_RMS_FRACTION", f"{FAILED_RMS_FRACTION:g}", "error RMS / demand RMS, after the failure"),
        ("criteria NOMINAL_PEAK_FRACTION", f"{NOMINAL_PEAK_FRACTION:g}", "peak error / demand peak, before"),
        ("criteria FAILED_PEAK_FRACTION", f"{FAILED_PEAK_FRACTION:g}", "peak error / demand peak, after"),
        ("criteria SIDESLIP_RMS_DEG", ", ".join(f"{x:g}" for x in SIDESLIP_RMS_DEG), "sideslip RMS, before, after"),
        ("criteria RECOVERY_HOLD_S", f"{RECOVERY_HOLD_S:g} s", "time inside the nominal band that counts as back"),
        ("criteria RECOVERY_MAX_S", f"{RECOVERY_MAX_S:g} s", "latest acceptable recovery after the failure"),
        ("criteria SATURATION_MAX_FRACTION", f"{SATURATION_MAX_FRACTION:g}",
         "largest share of a phase with any effector on a position or rate stop"),
    ]


_UNITS = {"alphaw": "deg", "betaw": "deg", "beta": "deg", "ps": "deg/s"}


def render_markdown(scenarios: tuple[str, ...] = tuple(CRITERIA)) -> str:
    """The criteria tables as Markdown (``docs/comparison.md`` holds this text; a test checks it)."""
    def row(*cells: str) -> str:
        return "| " + " | ".join(c.replace("|", "\\|") for c in cells) + " |"

    lines = [row("scenario", "criterion", "before the failure", "after the failure", "source"), "|---|---|---|---|---|"]
    for name in scenarios:
        table = criteria_for(name)
        if table is None:
            raise ValueError(f"scenario {name!r}: no criteria table, or its scenario is not imported (import "
                             f"sim.scenarios.{name}); tables exist for {sorted(CRITERIA)}")
        for axis in table.axes:
            unit = _UNITS.get(axis.signal, "")
            for kind, pair in (("error RMS", axis.rms), ("peak error", axis.peak), ("excursion, peak |output|", axis.excursion)):
                if pair is not None:
                    source = " / ".join(dict.fromkeys(limit.source for limit in pair))
                    lines.append(row(name, f"`{axis.signal}` {kind} ({unit})", f"{pair[0].value:.3g}", f"{pair[1].value:.3g}",
                                     source + (f"; the demand: {axis.basis}" if axis.basis and kind != "excursion, peak |output|" else "")))
        share = table.saturation_max
        for kind in ("position", "rate"):
            lines.append(row(name, f"share of the phase with any effector at a {kind} limit", f"{share.value:g}",
                             f"{share.value:g}", share.source))
        lines.append(row(name, f"back inside every nominal peak band and held {table.recovery_hold.value:g} s "
                         "(s after the failure)", "-", f"{table.recovery_max.value:g}",
                         f"{table.recovery_max.source}; hold: {table.recovery_hold.source}"))
    return "\n".join(lines) + "\n"

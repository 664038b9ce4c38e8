"""Sweep definitions: lists of run specs.

A spec is a plain dict (JSON-able, picklable) naming everything a run depends on,
including its seeds, so a run is a pure function of its spec.  ``id`` is a readable,
unique string; CSV rows are sorted by it.

Closed-loop axes: scenario x failure x method x allocator told/blind x simulator setting x
noise seed.  A *simulator setting* (``spec["sim"]``) is a dict of keyword arguments handed
unchanged to the scenario (``sim.scenarios.get_scenario(name)(**spec["sim"], ...)``): the
pilot (``pilot_gain``, ``pilot_delay``, or ``pilot="crossover"``, the simulator's McRuer model)
and the flight-control frame period (:data:`FRAME_PERIOD`).  Settings are built as the
product of *axes* (lists of dicts, merged); :func:`check_simulator_support` refuses, before
any run starts, a setting the simulator in this checkout does not accept.

Glossary: ``told`` -- the allocator is given the failed effectors' new limits
(``allocator_knows_failure=True``, reconfiguration); ``blind`` -- it keeps the nominal
problem; ``detected`` -- it learns of a failure only from the in-loop detector
(``health="detected"``, :mod:`sim.detection`; the failure is silent).  ``static`` is the seed's printed distribution matrix (Eq 4.24 for ICE), which
cannot be told anything, so it only runs blind.  Failures: see :mod:`.failures`.
"""

from __future__ import annotations

import inspect
import itertools
from collections.abc import Sequence
from typing import Any

import alloc

from .failures import catalogue_names, is_catalogue

__all__ = [
    "Spec", "STATIC", "ARMS", "FRAME_PERIOD", "PILOT_SETTINGS", "open_spec", "closed_spec", "closed_grid",
    "setting_tag", "detected_sweep", "quick_sweep", "full_sweep", "tiny_sweep", "smoke_sweep", "check_simulator_support", "SCENARIO_TIMES",
    "FULL_TIMES", "FULL_PILOTS", "seed_length_sweep", "SEED_LENGTH_FAILURES", "SAME_AS_DA", "SAME_AS_FAMILY",
]

Spec = dict[str, Any]

#: The seed's printed static distribution (a simulator method, not a registry one).
STATIC = "static"

#: Closed-loop arms: where the allocator's health comes from (``alloc sim --health``).
ARMS = ("blind", "told", "detected")

#: Scenario keyword for the flight-control frame period (s) of the multi-rate loop; the sweep's
#: frame-rate axis (Hz) is written as this period.  Absent = the seed's 0.5 ms step.
FRAME_PERIOD = "frame_period"

#: Pilot settings of the full sweep (scenario keywords).  The stand-in pilot at gain 1 (the
#: setting in which the seed's Fig 4-110 reproduces), at its default gain 2, and slower with
#: more delay, and the McRuer crossover-model pilot at its stated rule (``sim.pilot``).
PILOT_SETTINGS: tuple[dict[str, Any], ...] = (
    {"pilot_gain": 1.0},
    {"pilot_gain": 2.0},
    {"pilot_gain": 1.5, "pilot_delay": 0.3},
    {"pilot": "crossover"},
)

#: duration and failure time (s) of each scenario's runs in the seed (ICE Fig 4-110: 40 s;
#: HARV lat-dir: 50 s)
SCENARIO_TIMES = {"ice": (40.0, 20.0), "harv_latdir": (50.0, 25.0)}
#: duration and failure time (s) of the full sweep's closed-loop runs: the first half of the
#: seed's runs (the failure moved to mid-run), so that the 40,020-run grid fits one working
#: session on 2 cores (about 0.5 s per run); ``--seed-durations`` runs the seed's lengths
FULL_TIMES = {"ice": (20.0, 10.0), "harv_latdir": (25.0, 12.5)}
#: pilot settings of the full sweep: the principled pilot (McRuer crossover model) and two
#: stand-in pilots (gain 1, in which the seed's Fig 4-110 reproduces; gain 2, the simulator's
#: default and the aggressive one).  ``PILOT_SETTINGS`` adds a slower, more delayed stand-in.
FULL_PILOTS: tuple[dict[str, Any], ...] = (PILOT_SETTINGS[3], PILOT_SETTINGS[0], PILOT_SETTINGS[1])
#: failures the scenario itself defines that the full sweep runs (besides the catalogue)
SCENARIO_FAILURES = {"ice": ("seed",), "harv_latdir": ("failure1", "failure2")}


def setting_tag(sim: dict[str, Any] | None) -> str:
    """Readable, order-independent name of a simulator setting (``default`` when empty)."""
    if not sim:
        return "default"
    return ",".join(f"{k}={v:g}" if isinstance(v, float) else f"{k}={v}" for k, v in sorted(sim.items()))


def open_spec(problem: str, method: str, *, samples: int, demands: int, steps: int, seed: int = 0) -> Spec:
    """One open-loop run of ``method`` on ``problem`` (see :mod:`.openloop`)."""
    return {
        "id": f"open/{problem}/{method}", "kind": "open", "problem": problem, "method": method,
        "samples": samples, "demands": demands, "steps": steps, "seed": seed,
    }


def closed_spec(scenario: str, failure: str, method: str, *, told: bool, seed: int,
                duration: float, failure_time: float, noise: bool = True,
                sim: dict[str, Any] | None = None, history: bool = False, health: str | None = None) -> Spec:
    """One closed-loop run (see :mod:`.closedloop`); ``sim``: scenario keywords passed through;
    ``history``: keep the run's time history (``histories/<id>.npz``) for the report's figures;
    ``health``: the arm (:data:`ARMS`; default ``told`` or ``blind`` from ``told``)."""
    mode = health or ("told" if told else "blind")
    if mode not in ARMS:
        raise ValueError(f"health: {mode!r}; expected one of {ARMS}")
    sim = dict(sim or {})
    return {
        "id": f"closed/{scenario}/{setting_tag(sim)}/{failure}/{method}/{mode}/s{seed:02d}", "kind": "closed",
        "scenario": scenario, "failure": failure, "method": method, "told": mode == "told", "seed": seed,
        "duration": duration, "failure_time": failure_time, "noise": noise, "sim": sim, "history": history,
        "health": mode,
    }


def settings_product(*axes: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """Product of setting axes, each a list of keyword dicts (merged; later axes win)."""
    out = []
    for combo in itertools.product(*axes):
        merged: dict[str, Any] = {}
        for part in combo:
            merged.update(part)
        out.append(merged)
    return out


def closed_grid(scenario: str, failures: Sequence[str], methods: Sequence[str], seeds: Sequence[int], *,
                settings: Sequence[dict[str, Any]] = ({},), duration: float, failure_time: float,
                history_failures: Sequence[str] = (), noise: bool = True,
                arms: Sequence[str] = ("blind", "told")) -> list[Spec]:
    """Every combination of ``arms`` (:data:`ARMS`); ``static`` blind only; histories kept for the
    first seed and setting of ``history_failures``."""
    specs = []
    for j, sim in enumerate(settings):
        for failure in failures:
            for method in methods:
                for arm in (("blind",) if method == STATIC else arms):
                    for s in seeds:
                        keep = j == 0 and s == seeds[0] and failure in history_failures
                        specs.append(closed_spec(scenario, failure, method, told=arm == "told", seed=s,
                                                 duration=duration, failure_time=failure_time, noise=noise, sim=sim,
                                                 history=keep, health=arm))
    return specs


def random_suite(n: int) -> list[str]:
    """Names of the seeded random problems (3 axes, 8 effectors, general position)."""
    return [f"random{i}" for i in range(n)]


def _open_sweep(problems: list[str], methods: list[str], **kw: Any) -> list[Spec]:
    return [open_spec(p, m, **kw) for p in problems for m in methods]


def all_methods() -> list[str]:
    """Every registry method and the seed's static matrix."""
    return [STATIC, *alloc.methods()]


def detected_sweep(seeds: int = 3) -> list[Spec]:
    """The three arms side by side, small: ICE's single jam and hard-over, ``qp`` and ``wls``,
    blind, told and detected, ``seeds`` noise seeds, 10 s with the failure at 5 s, 100 Hz frame;
    and ``static`` blind on the same seeds, the baseline every closed-loop score is relative to
    (without it no run is scored and the report's ``detected_share`` is NaN)."""
    return [spec for failure in ("jam1", "hardover1") for spec in
            closed_grid("ice", [failure], [STATIC, "qp", "wls"], list(range(1, seeds + 1)),
                        settings=[{FRAME_PERIOD: 0.01}], duration=10.0, failure_time=5.0, arms=ARMS)]


def quick_sweep() -> list[Spec]:
    """A few minutes on 2 cores: ICE closed loop (20 s, failure at 10 s, the seed's noise),
    every method blind and told, the seed's failure and a single jam, 3 noise seeds, the
    stand-in pilot at gain 1; open loop on every method (ICE, HARV, 3 random problems,
    2,000 coverage samples).

    Closed-loop specs come first: they are the long runs, so the pool starts them first and
    fills the tail with the short open-loop ones."""
    problems = ["ice", "harv_latdir", *random_suite(3)]
    specs = closed_grid("ice", ["seed", "jam1"], all_methods(), [1, 2, 3], settings=[PILOT_SETTINGS[0]],
                        duration=20.0, failure_time=10.0, history_failures=["seed"])
    specs += _open_sweep(problems, alloc.methods(), samples=2000, demands=200, steps=300)
    return specs


#: failures of the seed-length sweep: each scenario's own and the catalogue's single jam
SEED_LENGTH_FAILURES = {"ice": ("seed", "jam1"), "harv_latdir": ("failure1", "failure2", "jam1")}
#: methods the seed-length sweep leaves out: each computes the allocation of its declared family
#: by another algorithm (alloc.registry.families; today ``da_bisect``, ``da_facet``, ``da_table``,
#: the backends of direct allocation, ``da``).  The full sweep's rows of a family are identical in
#: every column (all 1,320 ICE runs each of the four), so the family's own method stands for them
SAME_AS_FAMILY = tuple(m for m in alloc.methods() if alloc.registry.get_method(m).family != m)
#: the same, by the name the sweep's tests use (direct allocation is today's one family)
SAME_AS_DA = SAME_AS_FAMILY


def seed_length_sweep(seeds: int = 3) -> list[Spec]:
    """The comparison at the seed's run lengths (:data:`SCENARIO_TIMES`: ICE 40 s, failure at
    20 s; HARV lat-dir 50 s, failure at 25 s, ``failure2`` too), judged by the engineering
    criteria (:mod:`sim.criteria`, in every row): every method (``da`` for its three identical
    backends, :data:`SAME_AS_FAMILY`) and ``static``, blind and told; :data:`SEED_LENGTH_FAILURES`;
    the crossover-model pilot at the seed's frame rate; ``seeds`` noise seeds.  Sized for 2
    shared cores (375 runs, about 22 CPU minutes at 3 seeds); no open loop.  Ordered seed by seed."""
    seed_list = list(range(1, seeds + 1))
    methods = [m for m in all_methods() if m not in SAME_AS_FAMILY]
    specs: list[Spec] = []
    for scenario, (duration, t_fail) in SCENARIO_TIMES.items():
        failures = SEED_LENGTH_FAILURES[scenario]
        specs += closed_grid(scenario, failures, methods, seed_list, settings=[PILOT_SETTINGS[3]],
                             duration=duration, failure_time=t_fail, history_failures=[failures[0]])
    # seed by seed (a stable sort): a sweep stopped early holds whole seeds of every cell
    return sorted(specs, key=lambda spec: spec["seed"])


def full_sweep(*, seeds: int = 10, frame_rates: Sequence[float | None] = (None, 100.0),
               pilots: Sequence[dict[str, Any]] = FULL_PILOTS,
               times: dict[str, tuple[float, float]] | None = None) -> list[Spec]:
    """The complete sweep: every method and ``static``; ICE and HARV lat-dir (``times``:
    duration and failure time per scenario, default :data:`FULL_TIMES`; HARV's ``failure2``
    too, not at t = 0 as in the seed) with the scenario's own failures and every catalogue failure
    (5 kinds, single and double); blind and told; frame rates (``None`` = the seed's rate) x
    pilot settings; ``seeds`` noise seeds.  Open loop on 10 random problems with 20,000
    coverage samples."""
    frame_axis = [{} if f is None else {FRAME_PERIOD: 1.0 / float(f)} for f in frame_rates]
    settings = settings_product(pilots, frame_axis)
    seed_list = list(range(1, seeds + 1))
    specs: list[Spec] = []
    for scenario, (duration, t_fail) in (times or FULL_TIMES).items():
        failures = [*SCENARIO_FAILURES[scenario], *catalogue_names()]
        specs += closed_grid(scenario, failures, all_methods(), seed_list, settings=settings, duration=duration,
                             failure_time=t_fail, history_failures=[SCENARIO_FAILURES[scenario][0], "jam1"])
    specs += _open_sweep(["ice", "harv_latdir", *random_suite(10)], alloc.methods(), samples=20_000,
                         demands=1000, steps=2000)
    return specs


def smoke_sweep() -> list[Spec]:
    """Seconds: one open-loop run and two 0.4 s closed-loop runs with stored histories
    (``alloc bench smoke``: checks the machinery end to end, measures nothing)."""
    specs = [closed_spec("ice", "seed", m, told=m != STATIC, seed=1, duration=0.4, failure_time=0.2,
                         sim={"pilot_gain": 1.0}, history=True) for m in (STATIC, "pinv")]
    specs.append(open_spec("ice", "pinv", samples=200, demands=20, steps=20))
    return specs


def tiny_sweep() -> list[Spec]:
    """For the engine tests: a few open-loop runs and three very short closed-loop runs."""
    specs = _open_sweep(["ice", "random0"], ["pinv", "qp", "da_facet"], samples=300, demands=40, steps=40)
    specs += [closed_spec("ice", "seed", m, told=m != STATIC, seed=1, duration=0.6, failure_time=0.3,
                          sim={"pilot_gain": 1.0}, history=True)
              for m in (STATIC, "qp")]
    specs.append(closed_spec("ice", "jam1", "pinv", told=True, seed=2, duration=0.6, failure_time=0.3))
    return specs


# ----------------------------------------------------------------------------- guard
def _accepted(scenario: str) -> tuple[set[str], bool]:
    from sim.scenarios import get_scenario

    fn = get_scenario(scenario)
    params = inspect.signature(fn).parameters
    var_kw = any(p.kind is inspect.Parameter.VAR_KEYWORD for p in params.values())
    mimo = getattr(inspect.getmodule(fn), "SCENARIO", None)
    if var_kw and mimo is not None:  # a MIMO scenario: run_mimo's keywords plus the scenario's declared ones
        from sim.scenarios.mimo import run_mimo

        names = {n for n, p in inspect.signature(run_mimo).parameters.items()
                 if p.kind is not inspect.Parameter.VAR_KEYWORD and n != "scenario"}
        return names | set(mimo.design_options) | set(mimo.input_options), False
    return set(params), var_kw


def check_simulator_support(specs: Sequence[Spec]) -> None:
    """Raise ``ValueError`` naming the scenario and keyword when a spec's simulator setting or
    failure is something the simulator in this checkout does not accept (checked before any run)."""
    seen: set[tuple[str, str]] = set()
    for spec in specs:
        if spec["kind"] != "closed":
            continue
        from sim.scenarios import get_scenario

        scenario = spec["scenario"]
        accepted, var_kw = _accepted(scenario)
        for key in spec["sim"]:
            if (scenario, key) in seen:
                continue
            seen.add((scenario, key))
            if key not in accepted and not var_kw:
                hint = (" (the multi-rate loop of issue 13 is not in this checkout's simulator; run with the "
                        "seed rate only, e.g. --frame-rates seed)") if key == FRAME_PERIOD else ""
                raise ValueError(f"sweep axis {key!r}: scenario {scenario!r} does not accept it{hint}; "
                                 f"it accepts {sorted(accepted)}")
        failure = spec["failure"]
        run = get_scenario(scenario)
        if is_catalogue(failure) or (scenario, f"failure {failure}") in seen:
            continue
        seen.add((scenario, f"failure {failure}"))
        if hasattr(run, "check_failure"):  # its own, its catalogue's or the failure grammar (sim.failure_catalogue)
            try:
                run.check_failure(failure)
            except alloc.AllocError as exc:
                raise ValueError(f"failure {failure!r}: scenario {scenario!r} does not take it: {exc}") from None
        elif failure not in run.failures:
            raise ValueError(f"failure {failure!r}: not a catalogue failure ({', '.join(catalogue_names())}) and "
                             f"not one scenario {scenario!r} defines ({', '.join(run.failures)})")

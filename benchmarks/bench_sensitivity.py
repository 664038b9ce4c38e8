"""One-factor sensitivity of the closed-loop verdicts to every verdict-driving choice.

For each factor of :data:`FACTORS` (each named after its row of the choices table,
:func:`sim.choices.verdict_choices`), the factor alone is moved off its default over a stated
range, everything else at its default, and a fixed small set of verdict runs is flown:

* ICE (seed section 4.7 failure at 20 s, and nominal), 40 s;
* HARV lat-dir with the Fig 4-81 filtered-step input (Failure #2 at 0 s, and nominal), 40 s;
* methods ``static`` (the seed's printed distribution), ``pinv``, ``qp``, ``wls``, the allocator
  told of the failure; noise seed 0.

The sampled-data choices (the boundary-layer rule eps_T, anti-windup, rate horizon and
window, preferred positions, ``u_prev``) do nothing, or almost nothing, at the seed's 2 kHz
loop, so they are also swept at a 100 Hz frame (``base`` = ``100 Hz``), against the 100 Hz
defaults.

A run's verdict is ``bounded`` or ``diverged`` (:mod:`sim.result`: a controlled output or a
reference left the scenario's bound), with the time it diverged.  A *flip* is a verdict that
differs from the same case and method at the factor's default (same base).  A *best flip* is a
change of the bounded method with the least RMS error in the pilot's channel (``ps``; after
the failure, over the whole run when nominal) among the four.

    python -m benchmarks.bench_sensitivity run --out benchmarks/reference/sensitivity-2026-12-02
    python -m benchmarks.bench_sensitivity report --out benchmarks/reference/sensitivity-2026-12-02
    python -m benchmarks.bench_sensitivity run --out benchmarks/reference/sensitivity-2026-12-02b --only \
        "setting pilot" "stand-in pilot gain" "stand-in pilot delay" "stand-in pilot neuromuscular lag" \
        "crossover pilot phase margin" "crossover_wc pilot crossover frequency" "crossover_wc pilot effective delay"
    python -m benchmarks.bench_sensitivity page --out benchmarks/reference/sensitivity-2026-12-02b

``run`` appends to ``runs.csv`` (``runs-I.csv`` with ``--shard I/N``, for N workers) and skips
the runs already recorded (resumable); ``--only`` limits it to named factors.  ``report`` writes
``flips.csv`` and ``report.md`` from every ``runs*.csv``; ``page`` rewrites
``docs/verdict-choices.md`` with the flips column from the committed sweep's ``flips.csv``, the pilot
rows' from the pilot re-run named by ``--out`` (``sensitivity-2026-12-02b``: the pilot factors
alone, with the ``crossover_wc`` rule), and that re-run's pilot table.
"""

from __future__ import annotations

import os

# Small dense products: BLAS threads on a shared two-core machine cost more than their work.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import argparse
import csv
import sys
import time
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from alloc import vehicles
from sim import pilot
from sim.allocation import PREFERRED_POSITIONS, RATE_HORIZONS, RATE_WINDOWS
from sim.engine import simulate
from sim.scenarios import harv_latdir, ice
from sim.scenarios.mimo import MimoScenario, mimo_spec
from sim.settings import ANTI_WINDUP_RULES, BOUNDARY_LAYER_RULES, U_PREV_SOURCES, LoopSpec, RunSettings

METHODS = ("static", "pinv", "qp", "wls")
DURATION = 40.0
#: scenario -> (MimoScenario, its failure, the scenario's own run options)
SCENARIOS: dict[str, tuple[MimoScenario, str, dict[str, Any]]] = {
    "ice": (ice.SCENARIO, "seed", {}),
    "harv_latdir": (harv_latdir.SCENARIO, "failure2", {"phi_command": "filtered_steps"}),
}
#: base frame rates: the seed's single-rate loop, and the 100 Hz frame the sampled-data choices were made at
BASES = {"2000 Hz": None, "100 Hz": 0.01}
#: the channel whose error ranks the methods (the pilot's, in both scenarios)
RANK_CHANNEL = "ps"
#: the controlled channels of both scenarios (HARV lat-dir: beta, ps; ICE: alphaw, ps, betaw)
CHANNELS = ("alphaw", "ps", "betaw", "beta")
FIELDS = ["factor", "level", "base", "scenario", "case", "method", "diverged", "t_end",
          *(f"rms_{c}" for c in CHANNELS), "seconds"]

SpecEdit = Callable[[LoopSpec], LoopSpec]


@dataclass(frozen=True)
class Variant:
    """One level of one factor: run options and/or an edit of the built :class:`LoopSpec`."""

    factor: str
    level: str
    options: Mapping[str, Any] = field(default_factory=dict)
    edit: SpecEdit | None = None
    scenarios: tuple[str, ...] = tuple(SCENARIOS)
    methods: tuple[str, ...] = METHODS
    bases: tuple[str, ...] = ("2000 Hz",)
    #: run options that depend on the scenario (``scenario name -> options``)
    per_scenario: Callable[[str], Mapping[str, Any]] | None = None
    cases: tuple[str, ...] = ("failed", "nominal")


def _default(name: str) -> Any:
    return RunSettings.__dataclass_fields__[name].default


def _alternatives(name: str, values: Iterable[str]) -> list[str]:
    return [v for v in values if v != _default(name)]


def _pilot_edit(**changes: Any) -> SpecEdit:
    return lambda spec: replace(spec, pilots=tuple(replace(p, **changes) for p in spec.pilots))


def _scaled_steps(scale: float) -> SpecEdit:
    # The Fig 4-81 filter is linear: scaling every step level scales the filtered command.
    return _pilot_edit(attitude_command=lambda t: scale * harv_latdir.filtered_steps(t))


def _bound(scale: float) -> SpecEdit:
    return lambda spec: replace(spec, output_bound=scale * np.asarray(spec.output_bound, dtype=float))


def _daisy_groups() -> dict[str, list[list[str]]]:
    groups = vehicles.method_options("ice", "daisy", None)["groups"]
    return {"the vehicle's": groups, "reversed order": groups[::-1],
            "one group": [[name for g in groups for name in g]]}


def _crossover_at(phase_margin: float) -> Callable[[str], Mapping[str, Any]]:
    """The crossover pilot with the gain that gives the pilot loop ``phase_margin`` (sim.pilot)."""
    def options(scenario: str) -> Mapping[str, Any]:
        element = SCENARIOS[scenario][0].pilot_element
        return {"pilot": "crossover", "pilot_gain": pilot.crossover_gain(*element, phase_margin=phase_margin)[0]}
    return options


def _crossover_wc_at(crossover: float) -> Callable[[str], Mapping[str, Any]]:
    """The crossover_wc pilot with the gain that puts its loop's crossover at ``crossover`` (rad/s; sim.pilot)."""
    def options(scenario: str) -> Mapping[str, Any]:
        element = SCENARIOS[scenario][0].pilot_element
        return {"pilot": "crossover_wc", "pilot_gain": pilot.gain_for_crossover(*element, crossover)}
    return options


def factors() -> list[Variant]:
    """Every factor level of the sweep (the defaults are the ``default`` level of each base)."""
    sampled = ("2000 Hz", "100 Hz")
    # the lesser factors fly the failed case only (the budget: 2 shared cores)
    failed = ("failed",)
    out = [Variant("default", "default", bases=tuple(BASES))]
    out += [Variant("stand-in pilot gain", f"{g:g}", {"pilot_gain": g}) for g in (1.0, 1.5, 3.0)]
    out += [Variant("stand-in pilot delay", f"{d:g} s", {"pilot_delay": d}) for d in (0.1, 0.3)]
    out += [Variant("stand-in pilot neuromuscular lag", f"{tn:g} s", edit=_pilot_edit(neuromuscular=tn),
                    cases=failed) for tn in (0.05, 0.1)]
    out += [Variant("setting pilot", p, {"pilot": p}) for p in ("crossover", "crossover_wc")]
    out += [Variant("crossover_wc pilot crossover frequency", f"{wc:g} rad/s", per_scenario=_crossover_wc_at(wc))
            for wc in (1.0, 1.5, 2.5, 3.0)]
    out += [Variant("crossover_wc pilot effective delay", f"{d:g} s", {"pilot": "crossover_wc", "pilot_delay": d})
            for d in (0.1, 0.3, 0.4)]
    out += [Variant("crossover pilot phase margin", f"{pm:g} deg", per_scenario=_crossover_at(pm), cases=failed)
            for pm in (30.0, 60.0)]
    out += [Variant("ICE alpha pilot", "on", {"alpha_pilot": True}, scenarios=("ice",))]
    out += [Variant("Fig 4-81 bank-angle steps", f"{k:g}x", edit=_scaled_steps(k), scenarios=("harv_latdir",))
            for k in (0.25, 0.5, 2.0)]
    out += [Variant("daisy groups (ICE)", name, {"method_options": {"groups": g}}, scenarios=("ice",),
                    methods=("daisy",)) for name, g in _daisy_groups().items()]
    out += [Variant("divergence bound ICE", f"{k:g}x", edit=_bound(k), scenarios=("ice",), cases=failed)
            for k in (0.5, 2.0)]
    out += [Variant("divergence bound HARV lat-dir", f"{k:g}x", edit=_bound(k), scenarios=("harv_latdir",),
                    cases=failed) for k in (0.5, 2.0)]
    out += [Variant("setting noise_scale", f"{k:g}", {"noise_scale": k}, cases=failed) for k in (0.0, 5.0)]
    # The sampled-data choices fly the failed case only as well.  At the seed's
    # 2 kHz the boundary-layer rule and anti-windup "off" are the default by construction
    # (sim.settings.boundary_layer_at, anti_windup_on), so those fly at 100 Hz only.
    for name, values in (("boundary_layer", BOUNDARY_LAYER_RULES), ("anti_windup", ANTI_WINDUP_RULES),
                         ("rate_horizon", RATE_HORIZONS), ("rate_window", RATE_WINDOWS),
                         ("preferred", PREFERRED_POSITIONS), ("u_prev_source", U_PREV_SOURCES)):
        for v in _alternatives(name, values):
            seed_rate_default = name == "boundary_layer" or (name == "anti_windup" and v == "off")
            out.append(Variant(f"setting {name}", v, {name: v}, cases=("failed",),
                               bases=("100 Hz",) if seed_rate_default else sampled))
    return out


def fly(variant: Variant, base: str, scenario: str, case: str, method: str) -> dict[str, Any]:
    """One verdict run: its row of ``runs.csv``."""
    scen, failure, own = SCENARIOS[scenario]
    options = {"frame_period": BASES[base], **own, **variant.options,
               **({} if variant.per_scenario is None else variant.per_scenario(scenario))}
    start = time.process_time()
    spec, _ = mimo_spec(scen, method=method, failure=failure if case == "failed" else None,
                        allocator_knows_failure=True, duration=DURATION, **options)
    if variant.edit is not None:
        spec = variant.edit(spec)
    result = simulate(spec)
    channels = result.summary()["channels"]
    rms = {name: (v["rms_after"] if case == "failed" else v["rms_before"]) for name, v in channels.items()}
    return {"factor": variant.factor, "level": variant.level, "base": base, "scenario": scenario, "case": case,
            "method": method, "diverged": bool(result.diverged), "t_end": round(result.duration, 3),
            **{f"rms_{c}": "" if rms.get(c) is None else f"{rms[c]:.6g}" for c in CHANNELS},
            "seconds": round(time.process_time() - start, 2)}


def _key(row: Mapping[str, Any]) -> tuple[str, ...]:
    return tuple(str(row[k]) for k in ("factor", "level", "base", "scenario", "case", "method"))


def plan(only: Iterable[str] | None = None) -> list[tuple[Variant, str, str, str, str]]:
    """Every run of the sweep, default runs first (a daisy factor's default is its own level)."""
    wanted = None if only is None else set(only)
    runs = []
    # the bounds, the noise, the daisy groups and the lesser pilot levels last: a sweep cut short
    # by its budget keeps the choices the issue names (pilot gain and delay, alpha pilot, Fig 4-81
    # steps, the sampled-data settings)
    late = ("stand-in pilot neuromuscular lag", "crossover pilot phase margin", "daisy groups (ICE)",
            "divergence bound ICE", "divergence bound HARV lat-dir", "setting noise_scale")
    for v in sorted(factors(), key=lambda v: v.factor in late):
        if wanted is not None and v.factor not in wanted and v.factor != "default":
            continue
        for base in v.bases:
            for scenario in v.scenarios:
                for case in v.cases:
                    runs += [(v, base, scenario, case, m) for m in v.methods]
    return runs


def read_runs(path: Path) -> list[dict[str, str]]:
    if not path.exists():
        return []
    with path.open(newline="") as fh:
        return list(csv.DictReader(fh))


def all_runs(out: Path) -> list[dict[str, str]]:
    """Every run recorded in ``out`` (``runs.csv`` and the shards' ``runs-*.csv``), one per key."""
    rows: dict[tuple[str, ...], dict[str, str]] = {}
    for path in sorted(out.glob("runs*.csv")):
        rows.update({_key(r): r for r in read_runs(path)})
    return list(rows.values())


def run(out: Path, only: list[str] | None, shard: tuple[int, int] = (0, 1)) -> None:
    """Fly the runs of the plan not yet recorded in ``out``; shard ``(i, n)`` flies every n-th from the i-th."""
    out.mkdir(parents=True, exist_ok=True)
    index, count = shard
    path = out / ("runs.csv" if count == 1 else f"runs-{index}.csv")
    done = {_key(r) for r in all_runs(out)}
    todo = [p for p in plan(only) if _key({"factor": p[0].factor, "level": p[0].level, "base": p[1],
                                           "scenario": p[2], "case": p[3], "method": p[4]}) not in done]
    todo = todo[index::count]
    new = not path.exists()
    with path.open("a", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=FIELDS)
        if new:
            writer.writeheader()
        for i, (v, base, scenario, case, method) in enumerate(todo, 1):
            row = fly(v, base, scenario, case, method)
            writer.writerow(row)
            fh.flush()
            print(f"[{i}/{len(todo)}] {v.factor} = {v.level} ({base}) {scenario} {case} {method}: "
                  f"{'diverged at ' + str(row['t_end']) + ' s' if row['diverged'] else 'bounded'} "
                  f"({row['seconds']} s)", flush=True)


# ---------------------------------------------------------------------------- flips


def verdict(row: Mapping[str, str]) -> str:
    """``bounded`` or ``diverged at T s``."""
    return f"diverged at {float(row['t_end']):g} s" if row["diverged"] == "True" else "bounded"


def _best(rows: Iterable[Mapping[str, str]]) -> str:
    """The bounded method with the least RMS error in :data:`RANK_CHANNEL` ("none": every one diverged)."""
    bounded = [(float(r[f"rms_{RANK_CHANNEL}"]), r["method"]) for r in rows
               if r["diverged"] != "True" and r[f"rms_{RANK_CHANNEL}"]]
    return min(bounded)[1] if bounded else "none"


def _frame_rate_rows(rows: list[dict[str, str]]) -> list[dict[str, str]]:
    """The frame rate as a factor: the 100 Hz default runs, compared with the 2000 Hz ones."""
    return [{**r, "factor": "setting frame_period", "level": "100 Hz", "base": "2000 Hz"} for r in rows
            if r["factor"] == "default" and r["base"] == "100 Hz"]


def flips(rows: list[dict[str, str]]) -> list[dict[str, Any]]:
    """Per factor level: runs, verdict flips against the default and best-method flips (module docstring).

    A daisy factor's reference is its ``the vehicle's`` level (the default runs fly no daisy).
    """
    rows = [*rows, *_frame_rate_rows(rows)]
    by_key = {_key(r): r for r in rows}
    levels: dict[tuple[str, str, str], list[dict[str, str]]] = {}
    for r in rows:
        if r["factor"] != "default":
            levels.setdefault((r["factor"], r["level"], r["base"]), []).append(r)
    out = []
    for (factor, level, base), group in levels.items():
        ref_level = ("daisy groups (ICE)", "the vehicle's") if factor.startswith("daisy") else ("default", "default")
        if (factor, level) == ref_level:
            continue
        flipped, compared = [], 0
        for r in group:
            ref = by_key.get((*ref_level, base, r["scenario"], r["case"], r["method"]))
            if ref is None:
                continue
            compared += 1
            if (ref["diverged"] == "True") != (r["diverged"] == "True"):
                flipped.append(f"{r['scenario']} {r['case']} {r['method']}: {verdict(ref)} -> {verdict(r)}")
        best_flips = []
        for scenario, case in sorted({(r["scenario"], r["case"]) for r in group}):
            mine = [r for r in group if (r["scenario"], r["case"]) == (scenario, case)]
            refs = [by_key[k] for k in ((*ref_level, base, scenario, case, r["method"]) for r in mine) if k in by_key]
            if len(refs) == len(mine) and len(mine) > 1 and _best(refs) != _best(mine):
                best_flips.append(f"{scenario} {case}: {_best(refs)} -> {_best(mine)}")
        out.append({"factor": factor, "level": level, "base": base, "runs": compared, "flips": len(flipped),
                    "flipped": "; ".join(flipped), "best_flips": "; ".join(best_flips)})
    return out


def flips_by_choice(flip_rows: Iterable[Mapping[str, Any]]) -> dict[str, str]:
    """One line per choice for the choices table: ``"n of N runs flip (level: k, ...)"``."""
    per: dict[str, list[Mapping[str, Any]]] = {}
    for r in flip_rows:
        per.setdefault(str(r["factor"]), []).append(r)
    out = {}
    for factor, rows in per.items():
        n = sum(int(r["flips"]) for r in rows)
        total = sum(int(r["runs"]) for r in rows)
        parts = [f"{r['level']}{'' if r['base'] == '2000 Hz' else ' at ' + str(r['base'])}: {r['flips']}"
                 + (" + best" if r["best_flips"] else "") for r in rows]
        out[factor] = f"{n} of {total} verdicts flip ({', '.join(parts)})"
    return out


def read_flips(path: Path) -> list[dict[str, str]]:
    with path.open(newline="") as fh:
        return list(csv.DictReader(fh))


#: the factors that change the pilot (the report gives their loops' crossover frequency and phase margin)
PILOT_FACTORS = ("default", "stand-in pilot gain", "stand-in pilot delay", "stand-in pilot neuromuscular lag",
                 "setting pilot", "crossover pilot phase margin", "crossover_wc pilot crossover frequency",
                 "crossover_wc pilot effective delay")


def pilot_loop(variant: Variant, scenario: str) -> tuple[float, float]:
    """Crossover frequency (rad/s) and phase margin (deg) of the roll pilot's loop a variant flies."""
    scen, _, own = SCENARIOS[scenario]
    options = {**own, **variant.options, **({} if variant.per_scenario is None else variant.per_scenario(scenario))}
    spec, _ = mimo_spec(scen, method="static", duration=0.01, **options)
    if variant.edit is not None:
        spec = variant.edit(spec)
    p = spec.pilots[0]
    return pilot.crossover_point(*scen.pilot_element, gain=p.gain, delay=p.delay, neuromuscular=p.neuromuscular,
                                 lag=p.lag)


def _pilot_table(rows: list[dict[str, str]]) -> list[str]:
    """Per pilot level and scenario: its loop's crossover frequency, w_c / w_i and phase margin, the bounded
    runs, and the verdict flips against the default (2000 Hz)."""
    lines = ["## Verdicts against the pilot loop's crossover frequency and phase margin", "",
             "The roll pilot's loop on the scenario's controlled element (`sim.pilot.crossover_point`: "
             "pilot gain, delay and lags times the reference model and the attitude integration); "
             f"w_i = {pilot.forcing_bandwidth():.3g} rad/s, the seed's Table 4-2 sum of sines "
             "(`sim.pilot.forcing_bandwidth`; HARV lat-dir flies the Fig 4-81 filtered steps here, which have "
             "no w_i: its ratio is to the sines it flies otherwise); bounded runs of the four methods at "
             "2000 Hz; flips: bounded/diverged verdicts that differ from the default pilot's (the stand-in), "
             "same scenario, case and method.", "",
             "| pilot | scenario | crossover (rad/s) | w_c / w_i | phase margin (deg) | bounded, failed "
             "| bounded, nominal | flips |",
             "|---|---|---|---|---|---|---|---|"]
    variants = {(v.factor, v.level): v for v in factors()}
    default = {(r["scenario"], r["case"], r["method"]): r["diverged"] for r in rows
               if (r["factor"], r["base"]) == ("default", "2000 Hz")}
    w_i = pilot.forcing_bandwidth()
    entries = []
    for (factor, level), v in variants.items():
        if factor not in PILOT_FACTORS:
            continue
        for scenario in v.scenarios:
            mine = [r for r in rows if (r["factor"], r["level"], r["base"], r["scenario"]) ==
                    (factor, level, "2000 Hz", scenario)]
            if not mine:
                continue
            wc, pm = pilot_loop(v, scenario)
            counts = [f"{sum(r['diverged'] != 'True' for r in mine if r['case'] == c)} of "
                      f"{sum(r['case'] == c for r in mine)}" for c in ("failed", "nominal")]
            compared = [r for r in mine if (scenario, r["case"], r["method"]) in default]
            flipped = sum(default[(scenario, r["case"], r["method"])] != r["diverged"] for r in compared)
            entries.append((scenario, wc, f"{factor} = {level}", pm, counts, f"{flipped} of {len(compared)}"))
    for scenario, wc, name, pm, counts, flipped in sorted(entries):
        lines.append(f"| {name} | {scenario} | {wc:.2f} | {wc / w_i:.2f} | {pm:.0f} | {counts[0]} | {counts[1]} "
                     f"| {flipped} |")
    return lines


def pilot_section(reference: Path) -> str:
    """The pilot table of the sweep in ``reference`` as Markdown, headed by where it comes from."""
    rel = reference.relative_to(CHOICES_PAGE.parents[1]).as_posix()
    table = _pilot_table(all_runs(reference))
    table[2] = (f"Generated by `benchmarks.bench_sensitivity.pilot_section()` from the pilot factors of the sweep "
                f"`{rel}` (`runs*.csv`). " + table[2])
    return "\n".join(table) + "\n"


def render_report(rows: list[dict[str, str]], flip_rows: list[dict[str, Any]]) -> str:
    seconds = sum(float(r["seconds"]) for r in rows)
    lines = ["# One-factor sensitivity of the closed-loop verdicts", "",
             f"Written by `python -m benchmarks.bench_sensitivity report` from `runs.csv` ({len(rows)} runs, "
             f"{seconds / 60:.1f} min of CPU). Runs: ICE (seed failure at 20 s, and nominal) and HARV lat-dir "
             "with the Fig 4-81 filtered steps (Failure #2, and nominal), 40 s, methods "
             f"{', '.join(METHODS)}, told, noise seed 0. The sampled-data choices (boundary layer, anti-windup, "
             "rate horizon and window, preferred positions, u_prev) and the neuromuscular lag, crossover phase "
             "margin, divergence bounds and noise scale fly the failed case only; the sampled-data ones fly at "
             "2000 Hz and 100 Hz, the boundary-layer rule and anti-windup off at 100 Hz only (at 2000 Hz they "
             "are the default by construction). The frame rate's row compares the 100 Hz defaults with the "
             "2000 Hz ones. A flip is a bounded/diverged verdict that differs "
             "from the same run at the factor's default (same base frame rate); a best flip is a change of "
             f"the bounded method with the least `{RANK_CHANNEL}` error RMS. A factor missing below was not "
             "flown.", "",
             "## Defaults", "", "| base | scenario | case | " + " | ".join(METHODS) + " |",
             "|---|---|---|" + "---|" * len(METHODS)]
    default = {(r["base"], r["scenario"], r["case"], r["method"]): r for r in rows if r["factor"] == "default"}
    for base in BASES:
        for scenario in SCENARIOS:
            for case in ("failed", "nominal"):
                cells = [verdict(default[k]) if (k := (base, scenario, case, m)) in default else "" for m in METHODS]
                lines.append(f"| {base} | {scenario} | {case} | " + " | ".join(cells) + " |")
    lines += ["", "## Flips per factor level", "", "| factor | level | base | runs | flips | flipped | best flips |",
              "|---|---|---|---|---|---|---|"]
    for r in flip_rows:
        cells = [str(r[k]) for k in ("factor", "level", "base", "runs", "flips", "flipped", "best_flips")]
        lines.append("| " + " | ".join(c.replace("|", "\\|") for c in cells) + " |")
    lines += ["", *_pilot_table(rows)]
    return "\n".join(lines) + "\n"


#: the committed sweep the choices page quotes
REFERENCE = Path(__file__).resolve().parent / "reference" / "sensitivity-2026-12-02"
#: the committed re-run of the pilot factors (with the crossover_wc rule); its flips replace the pilot rows'
REFERENCE_PILOT = Path(__file__).resolve().parent / "reference" / "sensitivity-2026-12-02b"
CHOICES_PAGE = Path(__file__).resolve().parents[1] / "docs" / "verdict-choices.md"


def choices_page(reference: Path = REFERENCE, pilots: Path | None = REFERENCE_PILOT) -> str:
    """``docs/verdict-choices.md`` with the flips column of the committed sweep; with ``pilots``, the pilot
    factors' flips from that re-run instead, and its pilot table (:func:`pilot_section`) after the choices."""
    from sim.choices import render_markdown

    root = CHOICES_PAGE.parents[1]
    sweep = reference.relative_to(root).as_posix()
    flips = flips_by_choice(read_flips(reference / "flips.csv"))
    if pilots is None:
        return render_markdown(flips, sweep=sweep)
    flips.update({k: v for k, v in flips_by_choice(read_flips(pilots / "flips.csv")).items() if k in PILOT_FACTORS})
    sweep += f"` and, for the pilot rows, `{pilots.relative_to(root).as_posix()}"
    return render_markdown(flips, sweep=sweep) + "\n" + pilot_section(pilots)


def report(out: Path) -> None:
    rows = all_runs(out)
    flip_rows = flips(rows)
    with (out / "flips.csv").open("w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=["factor", "level", "base", "runs", "flips", "flipped", "best_flips"])
        writer.writeheader()
        writer.writerows(flip_rows)
    (out / "report.md").write_text(render_report(rows, flip_rows))
    print(f"{len(flip_rows)} factor levels, {sum(int(r['flips']) for r in flip_rows)} flips -> {out}")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="bench_sensitivity", description=__doc__.split("\n")[0])
    parser.add_argument("command", choices=("run", "report", "plan", "page"))
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--only", nargs="*", default=None, help="factor names (the choices table's rows)")
    parser.add_argument("--shard", default="0/1", help="i/n: fly every n-th missing run from the i-th")
    args = parser.parse_args(argv)
    shard = tuple(int(x) for x in args.shard.split("/"))
    if args.command == "plan":
        runs = plan(args.only)
        print(f"{len(runs)} runs")
        return 0
    if args.command == "page":
        CHOICES_PAGE.write_text(choices_page(REFERENCE, args.out.resolve()))
        print(f"wrote {CHOICES_PAGE}")
        return 0
    if args.command == "run":
        run(args.out, args.only, (shard[0], shard[1]))
    report(args.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""``alloc bench quick|full|smoke|report|scaling|openloop|closedloop`` (also ``python -m benchmarks.compare ...``).

``alloc bench openloop --vehicle NAME|FILE`` runs the sweep's open-loop measures
(:mod:`.openloop`) on any vehicle, a user's file among them, with the vehicle's method
defaults, and prints the rows (nothing is written).  ``alloc bench closedloop --vehicle FILE
--failure NAME`` flies a vehicle file's model (the seed's section 4.3 auto-design,
:mod:`sim.user_vehicle`) with every method, blind and told, and prints the sweep's
closed-loop rows (:mod:`.closedloop`).

Runs are fresh unless asked otherwise: every sweep writes into ``--out`` (default: a new
folder ``bench-<sweep>-<UTC timestamp>`` under the current directory, ignored by git) and
refuses a folder that already holds results unless ``--resume`` is given.  The committed
reference report (``benchmarks/reference/``) is only ever written by the documented command
``alloc bench full --out benchmarks/reference`` (see ``benchmarks/reference/README.md``).
"""

from __future__ import annotations

import datetime as dt
import json
import os
import platform
import shlex
import sys
from pathlib import Path
from typing import NoReturn

import typer

from alloc.cli import VEHICLE_HELP, OneLineErrors, finite, load_vehicle_option, read_json_file

from .sweep import (Spec, check_simulator_support, detected_sweep, full_sweep, quick_sweep, seed_length_sweep,
                    smoke_sweep)

app = typer.Typer(cls=OneLineErrors, no_args_is_help=True,
                  help="Allocator comparison: open loop and closed loop, on all local cores or a Dask cluster.")

#: most local worker processes one sweep starts (each holds a simulator, about 0.3 GB)
MAX_WORKERS = 256

_SCHEDULER = typer.Option(None, "--scheduler", metavar="ADDRESS",
                          help="Dask scheduler address (tcp://host:8786); default: local process pool")
_OUT = typer.Option(None, "--out", help="folder for the CSVs, report.md and figures "
                    "(default: a new ./bench-<sweep>-<timestamp>)")
_WORKERS = typer.Option(None, "--workers", min=1, max=MAX_WORKERS, help="local worker processes (default: all cores)")
_RESUME = typer.Option(False, "--resume", help="continue a sweep in --out, skipping the runs already written")
_TIMING = typer.Option(True, "--timing/--no-timing",
                       help="after the sweep, measure per-call latency in this process alone (report's latency)")
_TIMING_CALLS = typer.Option(2000, "--timing-calls", min=10, max=1_000_000, help="timed calls per method and problem")


def _command() -> str:
    """The command line as typed: ``alloc bench ...`` or ``python -m benchmarks.compare ...``."""
    prog = sys.argv[0]
    prog = "python -m benchmarks.compare" if prog.endswith("__main__.py") else Path(prog).name
    return " ".join([prog, *map(shlex.quote, sys.argv[1:])])


def _default_out(name: str) -> Path:
    stamp = dt.datetime.now(dt.UTC).strftime("%Y%m%d-%H%M%S")
    return Path.cwd() / f"bench-{name}-{stamp}"


def _prepare_out(out: Path, specs: list[Spec], resume: bool) -> None:
    """Refuse a folder holding results unless resuming; a resumed folder must hold the same sweep."""
    saved = out / "specs.json"
    if out.exists() and any(out.iterdir()):
        if not resume:
            raise typer.BadParameter(f"{out} is not empty; choose a new folder or pass --resume to continue "
                                     "the sweep in it", param_hint="--out")
        if saved.exists() and json.loads(saved.read_text()) != specs:
            raise typer.BadParameter(f"{out} holds a different sweep (specs.json differs); choose a new folder",
                                     param_hint="--out")
    out.mkdir(parents=True, exist_ok=True)
    saved.write_text(json.dumps(specs, indent=1) + "\n")


def _run(name: str, specs: list[Spec], scheduler: str | None, out: Path | None, workers: int | None,
         resume: bool, timing: bool, timing_calls: int) -> Path:
    import numpy as np

    from .report import make_report
    from .runner import run_sweep

    try:
        check_simulator_support(specs)
    except ValueError as exc:
        raise typer.BadParameter(str(exc)) from None
    out = _default_out(name) if out is None else out
    _prepare_out(out, specs, resume)
    typer.echo(f"{name} sweep: {len(specs)} runs -> {out}")
    outcome = run_sweep(specs, out, workers=workers, scheduler=scheduler, resume=resume, desc=f"{name} sweep")
    engine = (f"Dask scheduler {scheduler}" if scheduler else
              f"local process pool, {workers or os.cpu_count()} workers")
    latency_s = None
    if timing:
        import time

        import alloc

        from .timing import measure_latency, write_timings

        t0 = time.perf_counter()
        write_timings(out, measure_latency(["ice", "harv_latdir"], alloc.methods(), calls=timing_calls))
        latency_s = round(time.perf_counter() - t0, 1)
    meta = {
        "sweep": name, "command": _command(),
        "date": dt.datetime.now(dt.UTC).strftime("%Y-%m-%d %H:%M UTC"),
        "cores": os.cpu_count(), "load_avg_1min": round(os.getloadavg()[0], 2),
        "platform": f"{platform.system()} {platform.machine()}",
        "python": platform.python_version(), "numpy": np.__version__, "engine": engine,
        "runs": len(specs), "ran": outcome.ran, "skipped": outcome.skipped, "wall_s": round(outcome.wall_s, 1),
        "latency_pass_s": latency_s,
    }
    (out / "run.json").write_text(json.dumps(meta, indent=2) + "\n")
    path = make_report(out, specs, meta)
    typer.echo(f"{outcome.ran} runs in {outcome.wall_s:.1f} s ({outcome.skipped} resumed); report: {path}")
    return path


@app.command()
def quick(scheduler: str | None = _SCHEDULER, out: Path | None = _OUT, workers: int | None = _WORKERS,
          resume: bool = _RESUME, timing: bool = _TIMING, timing_calls: int = _TIMING_CALLS) -> None:
    """Every method open loop; ICE closed loop, seed failure and a jam, blind and told, 3 seeds."""
    _run("quick", quick_sweep(), scheduler, out, workers, resume, timing, timing_calls)


@app.command()
def detected(scheduler: str | None = _SCHEDULER, out: Path | None = _OUT, workers: int | None = _WORKERS,
             resume: bool = _RESUME, timing: bool = _TIMING, timing_calls: int = _TIMING_CALLS,
             seeds: int = typer.Option(3, "--seeds", min=1, max=1000, help="noise seeds per cell")) -> None:
    """The detected arm beside told and blind: ICE single jam and hard-over, qp and wls, 10 s, 100 Hz frame."""
    _run("detected", detected_sweep(seeds), scheduler, out, workers, resume, timing, timing_calls)


@app.command("seed-length")
def seed_length(scheduler: str | None = _SCHEDULER, out: Path | None = _OUT, workers: int | None = _WORKERS,
                resume: bool = _RESUME, timing: bool = _TIMING, timing_calls: int = _TIMING_CALLS,
                seeds: int = typer.Option(3, "--seeds", min=2, max=1000, help="noise seeds per cell")) -> None:
    """The seed's run lengths (ICE 40 s, HARV lat-dir 50 s) with the engineering criteria: every method,
    the scenarios' own failures and a single jam, blind and told, crossover pilot, seed frame rate."""
    _run("seed-length", seed_length_sweep(seeds), scheduler, out, workers, resume, timing, timing_calls)


@app.command()
def smoke(scheduler: str | None = _SCHEDULER, out: Path | None = _OUT, workers: int | None = _WORKERS,
          resume: bool = _RESUME, timing: bool = _TIMING, timing_calls: int = _TIMING_CALLS) -> None:
    """Seconds: three tiny runs through the whole machinery (sweep, latency pass, report); measures nothing."""
    _run("smoke", smoke_sweep(), scheduler, out, workers, resume, timing, timing_calls)


_RATE = finite(0.0, low_open=True, unit=" Hz")


def _frame_rates(text: str) -> list[float | None]:
    out: list[float | None] = []
    for part in text.split(","):
        part = part.strip()
        if part == "seed":
            out.append(None)
            continue
        try:
            out.append(_RATE(part))
        except typer.BadParameter as exc:
            raise typer.BadParameter(f"expected 'seed' or a rate in Hz: {exc.message}",
                                     param_hint="--frame-rates") from None
    if len(set(out)) != len(out):
        raise typer.BadParameter(f"a frame rate is given twice in {text!r}", param_hint="--frame-rates")
    return out


@app.command()
def full(scheduler: str | None = _SCHEDULER, out: Path | None = _OUT, workers: int | None = _WORKERS,
         resume: bool = _RESUME, timing: bool = _TIMING, timing_calls: int = _TIMING_CALLS,
         seeds: int = typer.Option(10, "--seeds", min=2, max=1000, help="noise seeds per cell"),
         frame_rates: str = typer.Option("seed,100", "--frame-rates",
                                         help="flight-control frame rates: 'seed' (the seed's 0.5 ms) and/or Hz"),
         seed_durations: bool = typer.Option(False, "--seed-durations",
                                             help="the seed's run lengths (ICE 40 s, HARV 50 s; about twice the "
                                                  "time) instead of their first halves"),
         dry_run: bool = typer.Option(False, "--dry-run", help="print the run count and exit")) -> None:
    """ICE and HARV lat-dir: every method x failure x blind/told x frame rate x pilot x seed (long; --dry-run).

    Failures: the scenario's own and the catalogue's (5 kinds, single and double).

    Runs: ICE 20 s with the failure at 10 s, HARV lat-dir 25 s with the failure at 12.5 s (--seed-durations: 40 s, 50 s).
    """
    from .sweep import SCENARIO_TIMES

    specs = full_sweep(seeds=seeds, frame_rates=_frame_rates(frame_rates),
                       times=SCENARIO_TIMES if seed_durations else None)
    if dry_run:
        closed = sum(s["kind"] == "closed" for s in specs)
        typer.echo(f"full sweep: {len(specs)} runs ({closed} closed loop, {len(specs) - closed} open loop)")
        return
    _run("full", specs, scheduler, out, workers, resume, timing, timing_calls)


def _sweep_folder(out: Path) -> list[Spec]:
    """The specs of the sweep in ``out``, once the folder is checked to hold what a report reads."""
    from .runner import table_of

    def bad(reason: str) -> NoReturn:
        raise typer.BadParameter(f"{out}: {reason}", param_hint="DIR")

    if not out.is_dir():
        bad("no such folder" if not out.exists() else "not a folder")
    for name in ("specs.json", "run.json"):
        if not (out / name).is_file():
            bad(f"holds no {name}; not a sweep folder (one written by `alloc bench quick|full|smoke`)")
    specs = read_json_file(out / "specs.json", "DIR")
    if (not isinstance(specs, list) or not specs
            or not all(isinstance(s, dict) and isinstance(s.get("id"), str) and s.get("kind") in ("open", "closed")
                       and (s["kind"] == "open" or isinstance(s.get("scenario"), str)) for s in specs)):
        bad("specs.json is not a list of sweep specs (id, kind 'open' or 'closed', scenario)")
    if not isinstance(read_json_file(out / "run.json", "DIR"), dict):
        bad("run.json is not a JSON object")
    missing = sorted({f"{table_of(s)}.csv" for s in specs} - {p.name for p in out.iterdir()})
    if missing:
        bad(f"missing result table(s) {missing}: the sweep has not written them (resume it with --resume)")
    return specs


@app.command()
def report(out: Path = typer.Argument(..., metavar="DIR", help="folder of a sweep (holds specs.json, run.json "
                                      "and the CSVs)"),
           force: bool = typer.Option(False, "--force", help="overwrite the folder's existing report.md and "
                                      "figures")) -> None:
    """Re-render report.md and the figures of a sweep folder from its CSVs (no run).

    The folder's report.md, figures and their CSVs are rewritten: a folder that holds a report.md needs --force.
    """
    from .report import make_report

    specs = _sweep_folder(out)
    if (out / "report.md").exists() and not force:
        raise typer.BadParameter(f"{out}: holds a report.md; pass --force to re-render over it", param_hint="DIR")
    try:
        path = make_report(out, specs)
    except (KeyError, ValueError, TypeError) as exc:  # rows that are not the sweep's own
        raise typer.BadParameter(f"{out}: its tables cannot be read as this sweep's results: {exc!r}",
                                 param_hint="DIR") from None
    typer.echo(f"report: {path}")


@app.command()
def scaling(workers: str = typer.Option("1,2,4", help="worker counts, comma-separated"),
            runs: int = typer.Option(24, min=2, max=10_000, help="closed-loop runs (ICE, 8 s each) per measurement"),
            engine: list[str] = typer.Option(["dask", "local"], help="dask (loopback cluster) and/or local"),
            as_json: bool = typer.Option(False, "--json", help="print JSON rows instead of the table")) -> None:
    """Throughput with 1, 2, 4 worker processes on a loopback Dask cluster and the local pool."""
    from .throughput import measure_scaling

    try:
        counts = [int(x) for x in workers.split(",")]
    except ValueError:
        raise typer.BadParameter(f"expected comma-separated worker counts, got {workers!r}", param_hint="--workers") from None
    if not all(1 <= n <= MAX_WORKERS for n in counts):
        raise typer.BadParameter(f"worker counts must be 1 to {MAX_WORKERS}, got {workers!r}", param_hint="--workers")
    unknown = sorted(set(engine) - {"dask", "local"})
    if unknown:
        raise typer.BadParameter(f"unknown engine(s) {unknown}; expected 'dask' and/or 'local'", param_hint="--engine")
    rows = measure_scaling(counts, runs, engine)
    if as_json:
        typer.echo(json.dumps(rows, indent=2))
        return
    typer.echo(f"{runs} closed-loop runs (ICE, 8 s each); {os.cpu_count()} cores, shared with other jobs")
    typer.echo("| engine | workers | wall (s) | runs/s | speed-up vs 1 worker | load avg (1 min) |")
    typer.echo("|---|---|---|---|---|---|")
    for r in rows:
        typer.echo(f"| {r['engine']} | {r['workers']} | {r['wall_s']:.1f} | {r['runs_per_s']:.2f} | "
                   f"{r['speedup']:.2f} | {r['load_avg_1min']:.2f} |")


#: columns of ``alloc bench openloop``'s table (the JSON rows hold every column)
_OPEN_COLUMNS = ("method", "coverage", "unatt_err_mean", "unatt_angle_mean", "effort_mean", "rate_violation_max",
                 "traj_err_mean", "fallbacks")


@app.command()
def openloop(vehicle: str = typer.Option(..., "--vehicle", metavar="NAME|FILE", help=VEHICLE_HELP),
             method: list[str] = typer.Option(None, "--method", help="methods (default: every registered one the "
                                              "vehicle can run; a skipped one is named on stderr); repeatable"),
             samples: int = typer.Option(2000, "--samples", min=1, max=1_000_000,
                                         help="Monte Carlo coverage sample (affine methods: exact polytope)"),
             demands: int = typer.Option(200, "--demands", min=1, max=100_000,
                                         help="demands outside and inside the AMS"),
             steps: int = typer.Option(300, "--steps", min=1, max=100_000, help="steps of the demand trajectory"),
             seed: int = typer.Option(0, "--seed", min=0, max=2**32 - 1, help="seed of every sample"),
             as_json: bool = typer.Option(False, "--json", help="print the rows as JSON")) -> None:
    """Open-loop measures of methods on one vehicle: coverage, unattainable error, effort, rates (the sweep's rows)."""
    import alloc
    from alloc.vehicles import method_options

    from .openloop import run_open
    from .sweep import open_spec

    v = load_vehicle_option(vehicle)
    names: list[str] = []
    for m in method or alloc.methods():
        try:
            method_options(v, m)
        except alloc.AllocError as exc:
            if method:  # asked for by name: an error, as everywhere
                raise
            typer.echo(f"alloc bench openloop: note: {m} skipped on {v.name}: {exc}", err=True)
            continue
        names.append(m)
    rows = []
    for m in names:
        spec = {**open_spec(v.name, m, samples=samples, demands=demands, steps=steps, seed=seed), "vehicle": vehicle}
        rows.append(run_open(spec)[0])
    if as_json:
        typer.echo(json.dumps(rows, indent=2))
        return
    typer.echo(f"{v.name}: {v.k} axes x {v.m} effectors; samples {samples}, demands {demands}, steps {steps}, seed {seed}")
    typer.echo("| " + " | ".join(_OPEN_COLUMNS) + " |")
    typer.echo("|" + "---|" * len(_OPEN_COLUMNS))
    for r in rows:
        typer.echo("| " + " | ".join(r[c] if isinstance(r[c], str) else f"{r[c]:.4g}" for c in _OPEN_COLUMNS) + " |")


#: columns of ``alloc bench closedloop``'s table besides the channels' ``rms_before``/``rms_after``
_CLOSED_COLUMNS = ("method", "told", "diverged", "recover_s", "effort_after", "unattainable_after")


@app.command()
def closedloop(vehicle: str = typer.Option(..., "--vehicle", metavar="NAME|FILE",
                                           help=f"{VEHICLE_HELP}, with a [model] section"),
               failure: str = typer.Option(..., "--failure", help="the failure: <kind>:<effector>[@<value>[:<value>]] "
                                           "(several joined by '+'), e.g. float:motor1, jam:amt_l@30"),
               method: list[str] = typer.Option(None, "--method", help="methods (default: every registered one the "
                                                "vehicle can run; a skipped one is named on stderr); repeatable"),
               failure_time: float = typer.Option(4.0, "--failure-time", parser=finite(0.0, unit=" s"),
                                                  help="failure time (s), before the end of the run"),
               duration: float = typer.Option(8.0, "--duration", parser=finite(0.0, 3600.0, low_open=True, unit=" s"),
                                              help="simulated seconds per run"),
               seed: int = typer.Option(0, "--seed", min=0, max=2**32 - 1, help="noise seed"),
               plant: str = typer.Option("linear", "--plant", metavar="NAME", help="the plant flown: linear (the "
                                         "model, compiled engine), rotorpy or jsbsim:f22 (sim/plants; alloc sim "
                                         "--plant)"),
               as_json: bool = typer.Option(False, "--json", help="print the rows as JSON")) -> None:
    """Closed-loop comparison of methods on a vehicle file's model, blind and told (the sweep's rows; nothing written)."""
    import alloc
    from alloc.vehicles import method_options
    from sim.allocation import STATIC
    from sim.user_vehicle import VehicleScenario, flight_model, vehicle_failure

    from .closedloop import run_closed
    from .sweep import closed_spec

    from sim.plants import check_plant, plant_spec

    try:
        check_plant(plant)
    except alloc.AllocError as exc:
        raise typer.BadParameter(str(exc), param_hint="--plant") from None
    v = load_vehicle_option(vehicle)
    if failure_time >= duration:
        raise typer.BadParameter(f"{failure_time:g} s is not before the end of the run ({duration:g} s)",
                                 param_hint="--failure-time")
    try:  # the file's own failures by name, or the failure grammar on its effectors: refused before any run
        VehicleScenario(v).check_failure(failure)
    except alloc.AllocError as exc:
        raise typer.BadParameter(f"unknown failure {failure!r} for {v.name}: {exc}", param_hint="--failure") from None
    if v.simulation is None:
        design = None
        if plant_spec(plant).design_options is not None:  # the aircraft's loop is designed with its stated options
            design = plant_spec(plant).design_options()
        vehicle_failure(flight_model(v, design=design), failure, failure_time)  # against the trimmed model's limits
    names: list[str] = []
    for m in method or alloc.methods():
        if m == STATIC:  # the loop's fixed pseudo-inverse, no registry method (sim.allocation)
            names.append(m)
            continue
        try:
            method_options(v, m)
        except alloc.AllocError as exc:
            if method:
                raise
            typer.echo(f"alloc bench closedloop: note: {m} skipped on {v.name}: {exc}", err=True)
            continue
        names.append(m)
    rows = []
    for m in names:
        for told in (False, True):
            spec = {**closed_spec(v.name, failure, m, told=told, seed=seed, duration=duration,
                                  failure_time=failure_time), "vehicle": vehicle, "plant": plant}
            try:
                rows.append(run_closed(spec)[0])
            except alloc.AllocError as exc:  # what the plant cannot fly (a vehicle without [body], a kind)
                if plant_spec(plant).flies_scenarios:  # the model's own loop: a real error
                    raise
                raise typer.BadParameter(str(exc), param_hint="--plant") from None
    if as_json:
        typer.echo(json.dumps(rows, indent=2))
        return
    channels = [c[: -len("_rms_after")] for c in rows[0] if c.endswith("_rms_after")] if rows else []
    columns = [*_CLOSED_COLUMNS, *(f"{c}_{w}" for c in channels for w in ("rms_before", "rms_after"))]
    typer.echo(f"{v.name}: failure {failure} at {failure_time:g} s, {duration:g} s runs, seed {seed}, plant {plant}; "
               "tracking errors in the model's output units")
    typer.echo("| " + " | ".join(columns) + " |")
    typer.echo("|" + "---|" * len(columns))
    for r in rows:
        typer.echo("| " + " | ".join(_cell(r.get(c)) for c in columns) + " |")


def _cell(x: object) -> str:
    if isinstance(x, bool) or x is None or isinstance(x, str):
        return str(x)
    return f"{x:.4g}"

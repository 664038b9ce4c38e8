"""``alloc ams ...``: AMS summary, pictures and coverage tables (mounted by ``alloc.cli``)."""

from __future__ import annotations

import json
from pathlib import Path

import typer

from .. import vehicles
from ..problem import Problem
from ..registry import methods as registered_methods

app = typer.Typer(help="Attainable moment set: geometry summary, 3-D pictures, method coverage.",
                  no_args_is_help=True)

HARV_DAISY_GROUPS = [["diff_tail", "aileron", "rudder"], ["roll_tv", "yaw_tv"]]


def ice_mid_up() -> Problem:
    """ICE with the one-sided effectors (AMT, SSD: 0..60 deg) preferring mid-range (30 deg)."""
    p = vehicles.ice()
    up = p.up.copy()
    one_sided = p.umin >= 0
    up[one_sided] = (p.umin[one_sided] + p.umax[one_sided]) / 2
    return p.replace(up=up)


PROBLEMS = {"ice": vehicles.ice, "ice-mid": ice_mid_up, "harv": vehicles.harv_latdir}
PROBLEM_TITLES = {"ice": "ICE", "ice-mid": "ICE (AMT/SSD prefer 30 deg)", "harv": "F-18/HARV lat-dir"}


def get_problem(name: str) -> Problem:
    if name not in PROBLEMS:
        raise typer.BadParameter(f"unknown problem {name!r}; choose one of {sorted(PROBLEMS)}")
    return PROBLEMS[name]()


def default_options(problem: str, method: str) -> dict:
    """Daisy chaining needs groups: aerodynamic surfaces first, thrust vectoring last (Eq 1.25)."""
    if method != "daisy":
        return {}
    return {"groups": vehicles.ice_daisy_groups() if problem.startswith("ice") else HARV_DAISY_GROUPS}


@app.command()
def summary(problem: str = typer.Option("ice", help="ice | ice-mid | harv"),
            as_json: bool = typer.Option(False, "--json", help="print JSON")) -> None:
    """Volume, facets, vertices of the AMS."""
    from .geometry import AttainableSet

    s = AttainableSet(get_problem(problem)).summary()
    if as_json:
        typer.echo(json.dumps(s, indent=2))
        return
    for key, val in s.items():
        typer.echo(f"{key:18s} {val}")


@app.command()
def plot(problem: str = typer.Option("ice", help="ice | ice-mid | harv"),
         method: str = typer.Option("pinv", help="method whose reached region is drawn inside"),
         out: Path = typer.Option(..., "--out",
                               help="PNG file to write (required: a run never overwrites a tracked picture)"),
         samples: int = typer.Option(4000, help="Monte Carlo demands for non-affine methods"),
         seed: int = typer.Option(0)) -> None:
    """3-D picture of the AMS (2-D for k = 2) with the method's reached region inside."""
    from .plot import plot_ams

    plot_ams(get_problem(problem), method, out, samples=samples, seed=seed, name=PROBLEM_TITLES[problem],
             **default_options(problem, method))
    typer.echo(f"wrote {out}")


@app.command("coverage")
def coverage_cmd(problem: str = typer.Option("ice", help="ice | ice-mid | harv"),
                 method: list[str] = typer.Option(None, help="methods (default: all registered)"),
                 samples: int = typer.Option(20_000, help="Monte Carlo sample size"),
                 seed: int = typer.Option(0),
                 as_json: bool = typer.Option(False, "--json", help="print JSON")) -> None:
    """Fraction of the AMS volume each method reaches exactly (Bordignon-Durham)."""
    from .coverage import coverage

    p = get_problem(problem)
    rows = [coverage(p, m, samples=samples, seed=seed, **default_options(problem, m))
            for m in (method or registered_methods())]
    if as_json:
        typer.echo(json.dumps([r.to_dict() for r in rows], indent=2))
        return
    typer.echo("| method | coverage % | +/- 1 s.e. | 95 % CI (Wilson) | estimator | N |")
    typer.echo("|---|---|---|---|---|---|")
    for r in rows:
        se = "exact" if r.estimator == "polytope" else f"{100 * r.stderr:.2f}"
        ci = "-" if r.estimator == "polytope" else f"{100 * r.ci95[0]:.2f} - {100 * r.ci95[1]:.2f}"
        typer.echo(f"| {r.method} | {100 * r.fraction:.2f} | {se} | {ci} | {r.estimator} | {r.samples or '-'} |")

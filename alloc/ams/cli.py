"""``alloc ams ...``: AMS summary, pictures and coverage tables (mounted by ``alloc.cli``)."""

from __future__ import annotations

import json
from pathlib import Path

import typer

from .. import vehicles
from ..cli import OneLineErrors, output_file
from ..exceptions import ProblemError
from ..problem import Problem
from ..registry import DEFAULT_METHOD
from ..registry import methods as registered_methods

app = typer.Typer(cls=OneLineErrors, help="Attainable moment set: geometry summary, 3-D pictures, method coverage.",
                  no_args_is_help=True)

#: largest Monte Carlo sample of one command (memory: about 8 (k + m) bytes per demand, twice)
MAX_SAMPLES = 1_000_000
_SEED = typer.Option(0, min=0, max=2**63 - 1, help="seed of the Monte Carlo sampler (>= 0)")

def get_problem(name: str) -> Problem:
    try:
        return vehicles.problem(name)
    except ProblemError as exc:
        raise typer.BadParameter(str(exc), param_hint="--problem") from None


def default_options(problem: str, method: str) -> dict:
    """Daisy chaining needs groups: the catalogue's, surfaces first (Eq 1.25)."""
    return {"groups": vehicles.daisy_groups(problem)} if method == "daisy" else {}


_PROBLEM_HELP = "a named problem: " + " | ".join(vehicles.names())


@app.command()
def summary(problem: str = typer.Option("ice", help=_PROBLEM_HELP),
            as_json: bool = typer.Option(False, "--json", help="print JSON")) -> None:
    """Volume, facets, vertices of the AMS (volume in the product of the axes' units)."""
    from .geometry import AttainableSet

    s = AttainableSet(get_problem(problem)).summary()
    if as_json:
        typer.echo(json.dumps(s, indent=2))
        return
    for key, val in s.items():
        typer.echo(f"{key:18s} {val}")


@app.command()
def plot(problem: str = typer.Option("ice", help=_PROBLEM_HELP),
         method: str = typer.Option(DEFAULT_METHOD, help="method whose reached region is drawn inside "
                                    "(see `alloc methods`)"),
         out: Path = typer.Option(..., "--out", help="PNG file to write (required; an existing file is refused "
                                  "unless --force, so a run never overwrites a tracked picture)"),
         force: bool = typer.Option(False, "--force", help="overwrite --out if it exists"),
         samples: int = typer.Option(4000, min=1, max=MAX_SAMPLES,
                                     help="Monte Carlo demands for non-affine methods"),
         seed: int = _SEED) -> None:
    """3-D picture of the AMS (2-D for k = 2) with the method's reached region inside (PNG)."""
    from .plot import plot_ams

    output_file(out, force, "--out")
    plot_ams(get_problem(problem), method, out, samples=samples, seed=seed, name=vehicles.lookup(problem).title,
             **default_options(problem, method))
    typer.echo(f"wrote {out}")


@app.command("coverage")
def coverage_cmd(problem: str = typer.Option("ice", help=_PROBLEM_HELP),
                 method: list[str] = typer.Option(None, help="methods (default: all registered)"),
                 samples: int = typer.Option(20_000, min=1, max=MAX_SAMPLES,
                                             help="Monte Carlo sample size (affine methods: exact polytope, "
                                                  "no sample)"),
                 seed: int = _SEED,
                 as_json: bool = typer.Option(False, "--json", help="print JSON")) -> None:
    """Fraction of the AMS volume each method reaches exactly (Bordignon-Durham), in per cent."""
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

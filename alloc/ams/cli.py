"""``alloc ams ...``: AMS summary, pictures and coverage tables (mounted by ``alloc.cli``).

Every sub-command reads one vehicle, ``--vehicle NAME|FILE`` (default ``ice``), as every
``alloc`` command does; the vehicle's ``[methods.<method>]`` defaults (ICE's daisy groups)
apply.  ``--problem NAME`` is the former spelling: still accepted, with a one-line notice on
stderr once the vehicle is read, and refused together with ``--vehicle``.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import typer

from .. import vehicles
from ..cli import VEHICLE_HELP, OneLineErrors, load_vehicle_option, output_file
from ..exceptions import AllocError
from ..registry import DEFAULT_METHOD
from ..registry import methods as registered_methods
from ..vehicle_file import Vehicle

app = typer.Typer(cls=OneLineErrors, help="Attainable moment set: geometry summary, 3-D pictures, method coverage.",
                  no_args_is_help=True)

#: largest Monte Carlo sample of one command (memory: about 8 (k + m) bytes per demand, twice)
MAX_SAMPLES = 1_000_000
#: the vehicle a sub-command reads when none is named
DEFAULT_VEHICLE = "ice"
_SEED = typer.Option(0, min=0, max=2**63 - 1, help="seed of the Monte Carlo sampler (>= 0)")
_VEHICLE = typer.Option(None, "--vehicle", metavar="NAME|FILE", help=f"{VEHICLE_HELP}; default {DEFAULT_VEHICLE}")
_PROBLEM = typer.Option(None, "--problem", metavar="NAME",
                        help="deprecated spelling of --vehicle (prints a notice); not with --vehicle")


def get_vehicle(vehicle: str | None, problem: str | None) -> Vehicle:
    """The vehicle of ``--vehicle`` or the deprecated ``--problem`` (one of them, default ``ice``)."""
    if vehicle is not None and problem is not None:
        raise typer.BadParameter("give --vehicle only (--problem is its deprecated spelling)",
                                 param_hint="--vehicle/--problem")
    if problem is not None:  # the notice after the vehicle is read: an invalid name stays a one-line error
        v = load_vehicle_option(problem, "--problem")
        typer.echo("alloc ams: note: --problem is deprecated; use --vehicle NAME|FILE", err=True)
        return v
    return load_vehicle_option(DEFAULT_VEHICLE if vehicle is None else vehicle)


def default_options(vehicle: Vehicle, method: str) -> dict[str, Any]:
    """The vehicle's defaults for ``method`` (:func:`alloc.vehicles.method_options`)."""
    return vehicles.method_options(vehicle, method)


@app.command()
def summary(vehicle: str | None = _VEHICLE, problem: str | None = _PROBLEM,
            as_json: bool = typer.Option(False, "--json", help="print JSON")) -> None:
    """Volume, facets, vertices of the AMS (volume in the product of the axes' units)."""
    from .geometry import AttainableSet

    s = AttainableSet(get_vehicle(vehicle, problem).problem()).summary()
    if as_json:
        typer.echo(json.dumps(s, indent=2))
        return
    for key, val in s.items():
        typer.echo(f"{key:18s} {val}")


@app.command()
def plot(vehicle: str | None = _VEHICLE, problem: str | None = _PROBLEM,
         method: str = typer.Option(DEFAULT_METHOD, help="method whose reached region is drawn inside "
                                    "(see `alloc methods`)"),
         out: Path = typer.Option(..., "--out", help="PNG file to write (required; an existing file is refused "
                                  "unless --force, so a run never overwrites a tracked picture)"),
         force: bool = typer.Option(False, "--force", help="overwrite --out if it exists"),
         samples: int = typer.Option(4000, min=1, max=MAX_SAMPLES,
                                     help="Monte Carlo demands for non-affine methods"),
         seed: int = _SEED,
         axes: str | None = typer.Option(None, "--axes", metavar="A,B[,C]",
                                            help="the 2 or 3 axes to draw (required for more than 3 axes, "
                                            "e.g. roll,pitch,yaw on a multirotor)"),
         at: list[str] | None = typer.Option(None, "--at", metavar="AXIS=VALUE",
                                                help="fix an axis that is not drawn (repeat for each): the "
                                                "picture is the exact slice there, e.g. --at thrust=-19.6 for "
                                                "hover; without --at it is the exact projection")) -> None:
    """3-D picture of the AMS (2-D for k = 2) with the method's reached region inside (PNG).

    A vehicle with more than three axes is drawn through --axes, as a slice (--at) or a
    projection; the title says which."""
    from .plot import plot_ams

    output_file(out, force, "--out")
    v = get_vehicle(vehicle, problem)
    options = default_options(v, method)
    plot_ams(v.problem(), method, out, samples=samples, seed=seed, name=v.description or v.name,
             axes=_axes_option(axes), at=_at_option(at), units={a.name: a.unit for a in v.axes}, **options)
    typer.echo(f"wrote {out}")


def _axes_option(text: str | None) -> list[str] | None:
    return None if text is None else [a.strip() for a in text.split(",")]


def _at_option(items: list[str] | None) -> dict[str, float] | None:
    """``--at thrust=-19.6`` (repeated, or comma-separated) as a mapping; one line when malformed."""
    if not items:
        return None
    out: dict[str, float] = {}
    for item in (part for text in items for part in text.split(",")):
        name, sep, value = item.partition("=")
        try:
            number = float(value)
        except ValueError:
            number = float("nan")
        if not sep or not name.strip() or not np.isfinite(number) or name.strip() in out:
            raise typer.BadParameter(f"{item!r}: expected AXIS=VALUE with a finite value, each axis once",
                                     param_hint="--at")
        out[name.strip()] = number
    return out


@app.command("coverage")
def coverage_cmd(vehicle: str | None = _VEHICLE, problem: str | None = _PROBLEM,
                 method: list[str] = typer.Option(None, help="methods (default: all registered that the vehicle "
                                                  "can run; a skipped one is named on stderr)"),
                 samples: int = typer.Option(20_000, min=1, max=MAX_SAMPLES,
                                             help="Monte Carlo sample size (affine methods: exact polytope, "
                                                  "no sample)"),
                 seed: int = _SEED,
                 as_json: bool = typer.Option(False, "--json", help="print JSON")) -> None:
    """Fraction of the AMS volume each method reaches exactly (Bordignon-Durham), in per cent."""
    from .coverage import coverage

    v = get_vehicle(vehicle, problem)
    p = v.problem()
    runs: list[tuple[str, dict[str, Any]]] = []
    for m in method or registered_methods():
        try:
            runs.append((m, default_options(v, m)))
        except AllocError as exc:
            if method:  # asked for by name: an error, as everywhere
                raise
            typer.echo(f"alloc ams coverage: note: {m} skipped on {v.name}: {exc}", err=True)
    rows = [coverage(p, m, samples=samples, seed=seed, **options) for m, options in runs]
    if as_json:
        typer.echo(json.dumps([r.to_dict() for r in rows], indent=2))
        return
    typer.echo("| method | coverage % | +/- 1 s.e. | 95 % CI (Wilson) | estimator | N |")
    typer.echo("|---|---|---|---|---|---|")
    for r in rows:
        se = "exact" if r.estimator == "polytope" else f"{100 * r.stderr:.2f}"
        ci = "-" if r.estimator == "polytope" else f"{100 * r.ci95[0]:.2f} - {100 * r.ci95[1]:.2f}"
        typer.echo(f"| {r.method} | {100 * r.fraction:.2f} | {se} | {ci} | {r.estimator} | {r.samples or '-'} |")

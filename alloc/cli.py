"""The ``alloc`` command line: allocate, inspect methods and attainable sets, simulate,
benchmark, and serve.  Every command has ``--help``; most print JSON with ``--json``.

The simulator, attainable-set and benchmark commands live with their packages
(``sim.cli``, ``alloc.ams.cli``, ``benchmarks.compare.cli``) and are mounted here; the
service is imported only when ``alloc serve`` runs.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Optional

import typer

import alloc

app = typer.Typer(
    help=(
        "Control allocation for over-actuated aircraft (seed section 1.3.4).\n\n"
        "Examples:\n\n"
        "  alloc methods\n\n"
        "  alloc allocate --vehicle ice --v 2,30,0.5 --method qp --json\n\n"
        "  alloc sim ice --method qp --failure seed --allocator-knows-failure --plot ice.png\n\n"
        "  alloc ams plot --problem ice-mid --method pinv --out ams.png\n\n"
        "  alloc bench quick\n\n"
        "  alloc serve --port 8000"
    ),
    no_args_is_help=True,
    add_completion=False,
)

VEHICLES = {"ice": "ICE 3 x 11 (seed section 4.7)", "ice-design": "ICE design problem of Eq 4.24",
            "harv": "F-18/HARV lateral-directional 3 x 5 (seed section 4.6)"}


def _vehicle(name: str) -> alloc.Problem:
    from . import vehicles

    if name == "ice":
        return vehicles.ice()
    if name == "ice-design":
        return vehicles.ice(design=True)
    if name == "harv":
        return vehicles.harv_latdir()
    raise typer.BadParameter(f"unknown vehicle {name!r}; known: {', '.join(VEHICLES)}", param_hint="--vehicle")


def _problem_from_file(path: Path) -> alloc.Problem:
    try:
        data = json.loads(path.read_text())
    except (OSError, json.JSONDecodeError) as exc:
        raise typer.BadParameter(f"cannot read a JSON problem from {path}: {exc}", param_hint="--problem") from None
    if not isinstance(data, dict):
        raise typer.BadParameter("the problem file must hold a JSON object", param_hint="--problem")
    known = {"B", "umin", "umax", "up", "Wu", "Wv", "rate_min", "rate_max", "names", "axes"}
    unknown = set(data) - known - {"v", "method"}
    if unknown:
        raise typer.BadParameter(f"unknown field(s) {sorted(unknown)}; known: {sorted(known)}", param_hint="--problem")
    try:
        return alloc.Problem(data["B"], data["umin"], data["umax"], **{k: data[k] for k in known - {"B", "umin", "umax"} if k in data})
    except KeyError as exc:
        raise typer.BadParameter(f"missing field {exc.args[0]!r}", param_hint="--problem") from None


def _floats(text: str, what: str) -> list[float]:
    try:
        return [float(x) for x in text.replace(";", ",").split(",") if x.strip()]
    except ValueError:
        raise typer.BadParameter(f"expected comma-separated numbers, got {text!r}", param_hint=what) from None


def _options(pairs: list[str]) -> dict:
    out = {}
    for pair in pairs:
        key, sep, value = pair.partition("=")
        if not sep:
            raise typer.BadParameter(f"expected key=value, got {pair!r}", param_hint="--option")
        try:
            out[key] = json.loads(value)
        except json.JSONDecodeError:
            out[key] = value
    return out


@app.command("methods")
def methods_command(as_json: bool = typer.Option(False, "--json", help="print JSON")) -> None:
    """List the registered allocation methods, their seed equations and options."""
    infos = [alloc.method_info(name) for name in alloc.methods()]
    if as_json:
        typer.echo(json.dumps(infos, indent=2))
        return
    for info in infos:
        typer.echo(f"{info['name']:<11} {info['equation']:<28} {info['summary']}")
        for opt, doc in info["options"].items():
            typer.echo(f"{'':<13}--option {opt}=...  {doc}")


@app.command("allocate")
def allocate_command(
    v: str = typer.Option(..., "--v", help="demand, comma-separated (one value per axis)"),
    method: str = typer.Option("qp", "--method", "-m", help="allocation method (see `alloc methods`)"),
    vehicle: Optional[str] = typer.Option(None, "--vehicle", help=f"built-in problem: {', '.join(VEHICLES)}"),
    problem: Optional[Path] = typer.Option(None, "--problem", help="JSON file with B, umin, umax and optional fields"),
    option: list[str] = typer.Option([], "--option", "-o", help="method option key=value (value parsed as JSON)"),
    u_prev: Optional[str] = typer.Option(None, "--u-prev", help="previous command, comma-separated (rate limits)"),
    dt: Optional[float] = typer.Option(None, "--dt", help="time step in seconds (rate limits, with --u-prev)"),
    as_json: bool = typer.Option(False, "--json", help="print the result as JSON"),
) -> None:
    """Allocate one demand and print the effector commands."""
    if (vehicle is None) == (problem is None):
        raise typer.BadParameter("give exactly one of --vehicle or --problem", param_hint="--vehicle/--problem")
    p = _vehicle(vehicle) if vehicle is not None else _problem_from_file(problem)
    try:
        result = alloc.allocate(p, _floats(v, "--v"), method,
                                u_prev=None if u_prev is None else _floats(u_prev, "--u-prev"), dt=dt,
                                **_options(option))
    except alloc.AllocError as exc:
        typer.echo(f"error: {exc}", err=True)
        raise typer.Exit(2) from None
    if as_json:
        typer.echo(json.dumps({**result.to_dict(), "names": list(p.names), "axes": list(p.axes)}, indent=2))
        return
    typer.echo(f"method {result.method}: {result.status.value} ({result.iterations} iterations, "
               f"{result.solve_time * 1e6:.0f} us)")
    for name, u in zip(p.names, result.u):
        typer.echo(f"  {name:<12} {u: .6g}")
    for axis, want, got in zip(p.axes, result.v, result.v_achieved):
        typer.echo(f"  {axis:<12} demand {want: .6g}  achieved {got: .6g}")


@app.command("serve")
def serve_command(
    host: str = typer.Option("127.0.0.1", help="bind address"),
    port: int = typer.Option(8000, help="TCP port"),
    data_dir: Optional[Path] = typer.Option(None, help="where the embedded SQLite database lives (ALLOC_DATA_DIR)"),
    database_url: Optional[str] = typer.Option(None, help="SQLAlchemy URL, e.g. postgresql+psycopg://... (ALLOC_DATABASE_URL)"),
    api_key: Optional[str] = typer.Option(None, help="require this X-API-Key on write endpoints (ALLOC_API_KEY)"),
    access_log: bool = typer.Option(False, "--access-log", help="log every request"),
) -> None:
    """Start the allocation and reconfiguration HTTP service (OpenAPI docs at /docs)."""
    from service.main import serve

    serve(host=host, port=port, data_dir=data_dir, database_url=database_url, api_key=api_key, access_log=access_log)


def _mount() -> None:
    from alloc.ams.cli import app as ams_app
    from benchmarks.compare.cli import app as bench_app
    from sim.cli import sim_command

    app.command("sim")(sim_command)
    app.add_typer(ams_app, name="ams")
    app.add_typer(bench_app, name="bench")


_mount()


def main() -> None:  # pragma: no cover - console entry point
    app()


if __name__ == "__main__":  # pragma: no cover
    main()

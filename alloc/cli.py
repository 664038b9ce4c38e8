"""The ``alloc`` command line: allocate, inspect methods and attainable sets, simulate,
benchmark, and serve.  Every command has ``--help``; most print JSON with ``--json``.

The library's own commands (``methods``, ``vehicles``, ``allocate``, ``ams``) live here and in
:mod:`alloc.ams.cli`.  Commands of the packages built on the library (``sim``, ``bench``,
``serve``) register themselves as entry points of the group ``alloc.commands`` (declared in
``pyproject.toml``, the way pytest and Dask discover plugins): the core never imports them,
and loads one only when it runs.  ``alloc --help`` imports no plugin and no compiled kernel.
"""

from __future__ import annotations

import ast
import importlib.machinery
import importlib.util
import json
import re
from functools import cache
from importlib.metadata import EntryPoint, PackageNotFoundError, entry_points, version
from pathlib import Path
from typing import Optional

import typer
from typer.core import TyperCommand, TyperGroup

import alloc
from alloc import DISTRIBUTION

#: entry-point group through which other packages add sub-commands to ``alloc``
COMMAND_GROUP = "alloc.commands"
#: the library's own sub-applications, loaded like the plugins (on use)
_BUILTIN = (EntryPoint("ams", "alloc.ams.cli:app", COMMAND_GROUP),)


@cache
def command_entry_points() -> dict[str, EntryPoint]:
    """Sub-commands by name: the library's own lazily loaded ones and the installed plugins."""
    found = {ep.name: ep for ep in entry_points(group=COMMAND_GROUP)}
    return {**found, **{ep.name: ep for ep in _BUILTIN}}


def _load_command(ep: EntryPoint) -> TyperCommand | TyperGroup:
    """The command behind an entry point: a Typer app or a typer-style function."""
    obj = ep.load()
    if isinstance(obj, typer.Typer):
        cmd = typer.main.get_command(obj)
    else:
        holder = typer.Typer()
        holder.command(ep.name)(obj)
        cmd = typer.main.get_command(holder)
    cmd.name = ep.name
    return cmd


def _summary(ep: EntryPoint) -> str:
    """First line of the entry point's help, read from its source without importing it.

    Listing the sub-commands must not import the simulator, the service or the sweep; a
    function's docstring or a ``Typer(help=...)`` literal is found with :mod:`ast`.
    """
    module, attr = ep.module, ep.attr
    try:
        top, *rest = module.split(".")
        spec = importlib.util.find_spec(top)  # a top-level name: finds, imports nothing
        for i in range(len(rest)):
            spec = importlib.machinery.PathFinder.find_spec(".".join([top, *rest[:i + 1]]),
                                                            spec.submodule_search_locations)
        tree = ast.parse(Path(spec.origin).read_text())
    except (AttributeError, ImportError, OSError, SyntaxError, TypeError, ValueError):
        return ""
    for node in tree.body:
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) and node.name == attr:
            return (ast.get_docstring(node) or "").strip().split("\n")[0]
        if (isinstance(node, ast.Assign) and any(isinstance(t, ast.Name) and t.id == attr for t in node.targets)
                and isinstance(node.value, ast.Call)):
            for kw in node.value.keywords:
                if kw.arg == "help" and isinstance(kw.value, ast.Constant) and isinstance(kw.value.value, str):
                    return kw.value.value.strip().split("\n")[0]
    return ""


def _requirement_name(requirement: str) -> tuple[str, list[str]]:
    """``"alloc[sim,service]>=1; extra == 'x'"`` -> ``("alloc", ["sim", "service"])``."""
    spec = requirement.split(";", 1)[0].strip()
    name = re.split(r"[\s\[<>=!~(]", spec, maxsplit=1)[0]
    extras = re.search(r"\[([^\]]*)\]", spec)
    return name, [e.strip() for e in extras.group(1).split(",")] if extras else []


def missing_requirements(ep: EntryPoint) -> list[str]:
    """Packages of the entry point's extras (``[service]``, ...) that are not installed."""
    if ep.dist is None or not ep.extras:
        return []
    requires = ep.dist.requires or []
    own = ep.dist.metadata["Name"]
    missing: list[str] = []
    todo, seen = list(ep.extras), set()
    while todo:
        extra = todo.pop()
        if extra in seen:
            continue
        seen.add(extra)
        for requirement in requires:
            if not re.search(rf"extra\s*==\s*['\"]{re.escape(extra)}['\"]", requirement):
                continue
            name, sub_extras = _requirement_name(requirement)
            if name == own:
                todo += sub_extras
                continue
            try:
                version(name)
            except PackageNotFoundError:
                missing.append(name)
    return sorted(set(missing))


class PluginGroup(TyperGroup):
    """The top-level group: own commands plus entry-point commands, loaded when they run.

    Help listings get a light stand-in (name and one-line summary); resolving a command
    for execution, or for its own ``--help``, loads the real one.
    """

    def list_commands(self, ctx: typer.Context) -> list[str]:
        return list(super().list_commands(ctx)) + sorted(set(command_entry_points()) - set(self.commands))

    def get_command(self, ctx: typer.Context, cmd_name: str) -> TyperCommand | TyperGroup | None:
        cmd = super().get_command(ctx, cmd_name)
        ep = command_entry_points().get(cmd_name)
        if cmd is None and ep is not None:
            cmd = TyperCommand(cmd_name, help=_summary(ep) or f"see `alloc {cmd_name} --help`")
        return cmd

    def resolve_command(self, ctx: typer.Context, args: list[str]) -> tuple[str | None, TyperCommand | TyperGroup | None, list[str]]:
        name = args[0] if args else None
        ep = command_entry_points().get(name) if name not in self.commands else None
        if ep is not None:
            hint = f"install the extra: pip install '{DISTRIBUTION}[{','.join(ep.extras) or name}]'"
            missing = missing_requirements(ep)
            if missing:
                ctx.fail(f"`alloc {name}` needs {', '.join(missing)}, not installed; {hint}")
            try:
                cmd = _load_command(ep)
            except ImportError as exc:
                ctx.fail(f"`alloc {name}` needs packages that are not installed ({exc}); {hint}")
            return name, cmd, args[1:]
        return super().resolve_command(ctx, args)


def _version(value: bool) -> None:
    if value:
        typer.echo(f"alloc {alloc.__version__}")
        raise typer.Exit()


app = typer.Typer(
    cls=PluginGroup,
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


@app.callback()
def _root(show_version: bool = typer.Option(False, "--version", callback=_version, is_eager=True,
                                            help="print the version and exit")) -> None:
    """The options every sub-command shares (the help text is the app's)."""


def _vehicle(name: str) -> alloc.Problem:
    from . import vehicles

    try:
        return vehicles.problem(name)
    except alloc.ProblemError as exc:
        raise typer.BadParameter(str(exc), param_hint="--vehicle") from None


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


@app.command("vehicles")
def vehicles_command(as_json: bool = typer.Option(False, "--json", help="print JSON")) -> None:
    """List the named problems (the seed's aircraft) that --vehicle and --problem accept."""
    from . import vehicles

    rows = []
    for entry in vehicles.CATALOGUE.values():
        p = entry.problem()
        rows.append({"name": entry.name, "title": entry.title, "source": entry.source, "k": p.k, "m": p.m,
                     "axes": list(p.axes), "effectors": list(p.names), "aliases": list(entry.aliases),
                     "daisy_groups": [list(g) for g in entry.daisy_groups]})
    if as_json:
        typer.echo(json.dumps(rows, indent=2))
        return
    for r in rows:
        alias = f" (also {', '.join(r['aliases'])})" if r["aliases"] else ""
        typer.echo(f"{r['name']:<11} {r['k']} x {r['m']:<3} {r['title']}, {r['source']}{alias}")


@app.command("allocate")
def allocate_command(
    v: str = typer.Option(..., "--v", help="demand, comma-separated (one value per axis)"),
    method: str = typer.Option("qp", "--method", "-m", help="allocation method (see `alloc methods`)"),
    vehicle: Optional[str] = typer.Option(None, "--vehicle", help="a named problem (see `alloc vehicles`), e.g. ice"),
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


def main() -> None:  # pragma: no cover - console entry point
    app()


if __name__ == "__main__":  # pragma: no cover
    main()

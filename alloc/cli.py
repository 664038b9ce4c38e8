"""The ``alloc`` command line: allocate, inspect methods and attainable sets, simulate,
benchmark, and serve.  Every command has ``--help``; most print JSON with ``--json``.

The library's own commands (``methods``, ``vehicles``, ``allocate``, ``ams``) live here and in
:mod:`alloc.ams.cli`.  Commands of the packages built on the library (``sim``, ``bench``,
``serve``) register themselves as entry points of the group ``alloc.commands`` (declared in
``pyproject.toml``, the way pytest and Dask discover plugins): the core never imports them,
and loads one only when it runs.  ``alloc --help`` imports no plugin and no compiled kernel.

Errors: every invalid input, whichever command meets it, ends the same way -- one line on
stderr, ``<command>: error: <field>: <reason>``, and exit status 2 (:data:`EXIT_USAGE`).
:class:`OneLineErrors` does that in one place, for typer's usage errors and for every
:class:`~alloc.AllocError` a command lets through.  The input helpers (:mod:`alloc.cli_input`:
:func:`finite`, :func:`strict_json`, :func:`output_file`) are shared with the plugins' commands.
"""

from __future__ import annotations

import ast
import importlib.machinery
import importlib.util
import json
import math
import re
import statistics
import sys
import time
from functools import cache
from importlib.metadata import EntryPoint, PackageNotFoundError, entry_points, version
from pathlib import Path
from typing import Any, NoReturn

import typer
from typer.core import TyperCommand, TyperGroup

try:  # typer >= 0.2x carries its own copy of click and raises that copy's exceptions
    from typer._click.exceptions import ClickException, UsageError
except ImportError:  # pragma: no cover - older typer on the click package
    from click.exceptions import ClickException, UsageError

import alloc
from alloc import DISTRIBUTION
# output_file is also the sub-commands' (sim, ams, replay): they import it from here
from alloc.cli_input import finite, json_float, read_json_file, strict_json
from alloc.cli_input import output_file as output_file
from alloc.exceptions import AllocError

#: entry-point group through which other packages add sub-commands to ``alloc``
COMMAND_GROUP = "alloc.commands"
#: the library's own sub-applications, loaded like the plugins (on use)
_BUILTIN = (EntryPoint("ams", "alloc.ams.cli:app", COMMAND_GROUP),
            EntryPoint("replay", "alloc.importers.ulog_cli:app", COMMAND_GROUP))
#: exit status of every invalid input (click's usage-error status)
EXIT_USAGE = 2


# ------------------------------------------------------------------ one-line errors
class InputError(ClickException):
    """An invalid input met inside a command: printed as one line, exit status 2."""

    exit_code = EXIT_USAGE

    def __init__(self, message: str, where: str) -> None:
        super().__init__(message)
        self.where = where


#: notes for stderr after a successful command (an importer's skipped lines); an error replaces them
NOTES: list[str] = []


def _one_line(text: str) -> str:
    return " ".join(text.split())


def _report(exc: ClickException, prog: str) -> NoReturn:
    """Print ``exc`` as ``<command>: error: <message>`` on one stderr line and exit."""
    ctx = getattr(exc, "ctx", None)
    where = getattr(exc, "where", None) or (ctx.command_path if ctx is not None else prog)
    message = _one_line(exc.format_message())
    if isinstance(exc, UsageError):
        message += f" (see '{where} --help')"
    typer.echo(f"{where}: error: {message}", err=True)
    sys.exit(exc.exit_code)


class OneLineErrors(TyperGroup):
    """A command group whose invalid inputs end in one stderr line and exit status 2.

    The top-level group's :meth:`main` runs the whole command line and formats every
    click exception (typer's ``BadParameter``, ``UsageError``) as one line,
    instead of typer's usage block and framed panel; :meth:`invoke` turns an
    :class:`~alloc.AllocError` raised by a sub-command into such an error, naming the command.
    Sub-applications (``alloc ams``, ``alloc bench``) use the class too, so that they behave
    the same when run on their own (``python -m benchmarks.compare``).
    """

    def invoke(self, ctx: typer.Context) -> Any:
        try:
            return super().invoke(ctx)
        except AllocError as exc:
            where = " ".join(filter(None, [ctx.command_path, ctx.invoked_subcommand]))
            raise InputError(str(exc), where) from exc

    def main(self, args: Any = None, prog_name: str | None = None, complete_var: str | None = None,
             standalone_mode: bool = True, **extra: Any) -> Any:
        if not standalone_mode:
            return super().main(args, prog_name, complete_var, standalone_mode=False, **extra)
        NOTES.clear()
        try:
            code = super().main(args, prog_name, complete_var, standalone_mode=False, **extra)
        except ClickException as exc:
            NOTES.clear()  # an error is the one stderr line
            if type(exc).__name__ == "NoArgsIsHelpError":  # the help itself (typer's own test)
                if not _rich_help(exc.ctx):  # rich has printed it already
                    typer.echo(exc.format_message())
                sys.exit(exc.exit_code)
            _report(exc, prog_name or "alloc")
        except typer.Abort:
            typer.echo("Aborted!", err=True)
            sys.exit(1)
        for note in NOTES:  # what an importer left out of a file, said once the command has succeeded
            typer.echo(f"note: {note}", err=True)
        NOTES.clear()
        sys.exit(code if isinstance(code, int) else 0)


def _rich_help(ctx: typer.Context) -> bool:
    """Whether typer printed the help itself (rich installed and enabled)."""
    from typer.core import HAS_RICH

    return bool(HAS_RICH) and getattr(ctx.command, "rich_markup_mode", None) is not None


# ------------------------------------------------------------------ plugins
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


class PluginGroup(OneLineErrors):
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
        "  alloc ams plot --vehicle ice-mid --method pinv --out ams.png\n\n"
        "  alloc bench quick\n\n"
        "  alloc serve --port 8000\n\n"
        "An invalid input ends in one line on stderr naming the field, and exit status 2."
    ),
    no_args_is_help=True,
    add_completion=False,
)


@app.callback()
def _root(show_version: bool = typer.Option(False, "--version", callback=_version, is_eager=True,
                                            help="print the version and exit")) -> None:
    """The options every sub-command shares (the help text is the app's)."""


def default_method() -> str:
    """The library's one default method, :data:`alloc.registry.DEFAULT_METHOD`.

    Read on use: the registry loads the compiled kernels, which ``alloc --help`` must not.
    """
    from .registry import DEFAULT_METHOD

    return DEFAULT_METHOD


class DefaultMethodCommand(TyperCommand):
    """A command whose ``--method`` help shows the library's default, read when the help is drawn."""

    def format_help(self, ctx: typer.Context, formatter: Any) -> None:
        for param in self.params:
            if param.name == "method":
                param.show_default = default_method()
        super().format_help(ctx, formatter)


class ExportCommand(DefaultMethodCommand):
    """``alloc export``: its ``--method`` help lists the exportable methods, read from the
    registry when the help is drawn (a method registered by a plugin is listed too)."""

    def format_help(self, ctx: typer.Context, formatter: Any) -> None:
        from .export import exportable

        for param in self.params:
            if param.name == "method":
                param.help = f"method to export: {', '.join(exportable())} (those declaring a C kernel)"
        super().format_help(ctx, formatter)


#: help of every ``--vehicle`` option (alloc allocate, alloc ams, alloc sim, alloc bench)
VEHICLE_HELP = ("a catalogue vehicle (see `alloc vehicles`; ALLOC_VEHICLE_PATH adds folders of files) or a "
                "vehicle file (.toml, .json; PX4 .params or airframe file; ArduPilot .csv factor table or .param file)")


def load_vehicle_option(source: str, param_hint: str = "--vehicle") -> Any:
    """The :class:`~alloc.vehicle_file.Vehicle` a ``--vehicle NAME|FILE`` names, or a one-line usage error.

    A malformed file's error names the file and the field path (``--vehicle x.toml:
    effectors[3].rate_max: must be > 0``); so does every refusal of the bounded readers (a
    FIFO, a device, an oversized or too deeply nested file: :mod:`alloc._files`), and an
    importer's (a PX4 ``.params`` file's parameter), each an :class:`~alloc.AllocError`.
    """
    import warnings

    from . import vehicles
    from .exceptions import SkippedLinesWarning

    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", SkippedLinesWarning)
            vehicle = vehicles.get_vehicle(source)
        for w in caught:  # an importer's list of skipped lines: one note line, not a warning's source dump
            if issubclass(w.category, SkippedLinesWarning):
                NOTES.append(f"{param_hint} {w.message}")
            else:
                warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
        return vehicle
    except AllocError as exc:
        where = "" if exc.field in ("vehicle", "path") else f"{source}: "
        raise typer.BadParameter(f"{where}{exc}", param_hint=param_hint) from None


#: fields of :class:`alloc.Problem` a problem file may hold (``null`` rate: unlimited)
PROBLEM_FIELDS = ("B", "umin", "umax", "up", "Wu", "Wv", "rate_min", "rate_max", "names", "axes")
#: fields of one call a problem file may also hold, as in the body of ``POST /v1/allocate``
CALL_FIELDS = ("v", "method", "options", "u_prev", "dt")


def _problem_from_file(path: Path) -> tuple[alloc.Problem, dict[str, Any]]:
    """The problem in a JSON file, and the call fields it holds (the HTTP request's fields)."""
    data = read_json_file(path, "--problem")

    def bad(reason: str) -> NoReturn:
        raise typer.BadParameter(f"{path}: {reason}", param_hint="--problem")

    if not isinstance(data, dict):
        bad(f"must hold a JSON object with fields {', '.join(PROBLEM_FIELDS)}, got {type(data).__name__}")
    unknown = sorted(set(data) - set(PROBLEM_FIELDS) - set(CALL_FIELDS))
    if unknown:
        bad(f"unknown field(s) {unknown}; known: {list(PROBLEM_FIELDS + CALL_FIELDS)}")
    missing = [f for f in ("B", "umin", "umax") if f not in data]
    if missing:
        bad(f"missing field(s) {missing}")
    fields = {k: data[k] for k in PROBLEM_FIELDS if k in data}
    for name, unlimited in (("rate_min", -math.inf), ("rate_max", math.inf)):
        if isinstance(fields.get(name), list):
            fields[name] = [unlimited if r is None else r for r in fields[name]]
    try:
        problem = alloc.Problem(**fields)
    except (AllocError, ValueError, TypeError, OverflowError) as exc:
        bad(str(exc))
    return problem, {k: data[k] for k in CALL_FIELDS if k in data}


def _floats(text: str, what: str) -> list[float]:
    try:
        values = [json_float(x) for x in text.replace(";", ",").split(",") if x.strip()]
    except ValueError:
        raise typer.BadParameter(f"expected comma-separated finite numbers, got {text!r}", param_hint=what) from None
    if not values:
        raise typer.BadParameter("expected comma-separated numbers, got none", param_hint=what)
    return values


def parse_options(pairs: list[str]) -> dict[str, Any]:
    """``--option key=value`` pairs; a value is read as JSON (numbers, lists, true) or else kept as text."""
    out: dict[str, Any] = {}
    for pair in pairs:
        key, sep, value = pair.partition("=")
        key = key.strip()
        if not sep or not key:
            raise typer.BadParameter(f"expected key=value, got {pair!r}", param_hint="--option")
        if key in out:
            raise typer.BadParameter(f"option {key!r} given twice", param_hint="--option")
        try:
            out[key] = strict_json(value)
        except json.JSONDecodeError:
            out[key] = value  # a word: a backend name, a choice
        except ValueError as exc:
            raise typer.BadParameter(f"{key}: {exc}", param_hint="--option") from None
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
        if info["family"] != info["name"]:
            typer.echo(f"{'':<13}the allocation of {info['family']}, by another algorithm")
        if info["export"] is not None:
            typer.echo(f"{'':<13}alloc export: a C kernel ({info['export']})")


@app.command("vehicles")
def vehicles_command(as_json: bool = typer.Option(False, "--json", help="print JSON")) -> None:
    """List the catalogue's vehicles (bundled, ALLOC_VEHICLE_PATH, entry points) that --vehicle accepts."""
    from . import vehicles

    rows = []
    for entry in vehicles.catalogue().values():
        row: dict[str, Any] = {"name": entry.name, "origin": entry.origin, "aliases": list(entry.aliases)}
        try:
            v = entry.vehicle()
        except alloc.AllocError as exc:  # one broken user file must not hide the others
            rows.append({**row, "error": str(exc)})
            continue
        rows.append({**row, "title": v.description or v.name, "source": v.source or entry.origin, "k": v.k,
                     "m": v.m, "axes": list(v.axis_names), "effectors": list(v.effector_names),
                     "daisy_groups": [list(g) for g in entry.daisy_groups], "methods": v.method_table(),
                     "model": v.model is not None})
    if as_json:
        typer.echo(json.dumps(rows, indent=2))
        return
    for r in rows:
        if "error" in r:
            typer.echo(f"{r['name']:<11} unreadable ({r['origin']}): {_one_line(r['error'])}")
            continue
        alias = f" (also {', '.join(r['aliases'])})" if r["aliases"] else ""
        defaults = f"; defaults for {', '.join(r['methods'])}" if r["methods"] else ""
        typer.echo(f"{r['name']:<11} {r['k']} x {r['m']:<3} {r['title']}, {r['source']}{alias}{defaults}")


#: wall-clock budget of the repeated calls that time one solve (at least one call is made)
TIMING_BUDGET_S = 1.0


def _merge(flag: Any, from_file: dict[str, Any], field: str, hint: str) -> Any:
    if flag is not None and field in from_file:
        raise typer.BadParameter(f"given both in the problem file ({field!r}) and as {hint}; give one",
                                 param_hint=hint)
    return flag if flag is not None else from_file.get(field)


def _fmt_seconds(s: float) -> str:
    return f"{s * 1e6:.0f} us" if s < 1e-3 else f"{s * 1e3:.1f} ms" if s < 1.0 else f"{s:.2f} s"


@app.command("allocate", cls=DefaultMethodCommand)
def allocate_command(
    v: str | None = typer.Option(None, "--v", help="demand, comma-separated, one value per axis (the "
                                    "problem's axes and units: `alloc vehicles --json`); or the file's 'v'"),
    method: str | None = typer.Option(None, "--method", "-m",
                                         help="allocation method (see `alloc methods`); or the file's 'method'"),
    vehicle: str | None = typer.Option(None, "--vehicle", metavar="NAME|FILE",
                                          help=VEHICLE_HELP + "; its [methods.<method>] defaults apply under --option"),
    problem: Path | None = typer.Option(
        None, "--problem", help="JSON file (UTF-8): B, umin, umax and optionally up, Wu, Wv, rate_min, rate_max "
        "(null: unlimited), names, axes -- the fields of alloc.Problem -- and optionally v, method, options, "
        "u_prev, dt, as in the body of POST /v1/allocate"),
    option: list[str] = typer.Option([], "--option", "-o", help="method option key=value (value parsed as JSON, "
                                     "else text; see `alloc methods`); repeatable"),
    u_prev: str | None = typer.Option(None, "--u-prev", help="previous command, comma-separated, one value per "
                                         "effector (rate limits, with --dt)"),
    dt: float | None = typer.Option(None, "--dt", parser=finite(0.0, low_open=True, unit=" s"),
                                       help="time step in seconds, > 0 (rate limits, with --u-prev)"),
    repeat: int = typer.Option(100, "--repeat", min=1, max=1_000_000,
                               help=f"calls timed for the solve time (stopping early after {TIMING_BUDGET_S:g} s)"),
    as_json: bool = typer.Option(False, "--json", help="print the result as JSON"),
    at: list[str] = typer.Option([], "--at", help="a scheduled vehicle's variable NAME=VALUE (tilt=30, airspeed=12; "
                                 "the vehicle's [schedule]); others at their nominal values; repeatable"),
) -> None:
    """Allocate one demand and print the effector commands, the status and honest timings.

    Times (seconds in the JSON), each measured on its own:

    build_time: make_allocator, the method's precomputation (and loading its compiled kernels, once per process);

    first_call_time: the first allocation, which may still load kernels;

    solve_time: the median of --repeat further calls of the same demand (what a control loop pays per call).

    Invalid input: exit 2 and one line on stderr.
    """
    if (vehicle is None) == (problem is None):
        raise typer.BadParameter("give exactly one of --vehicle or --problem", param_hint="--vehicle/--problem")
    vehicle_file = None
    if vehicle is not None:
        vehicle_file = load_vehicle_option(vehicle)
        p, from_file = vehicle_file.problem(), {}
        if at:
            p = _problem_at(vehicle_file, at)
    else:
        if at:
            raise typer.BadParameter("--at needs a scheduled --vehicle", param_hint="--at")
        p, from_file = _problem_from_file(problem)
    demand = _merge(None if v is None else _floats(v, "--v"), from_file, "v", "--v")
    if demand is None:
        raise typer.BadParameter("give the demand with --v (or as 'v' in the problem file)", param_hint="--v")
    previous = _merge(None if u_prev is None else _floats(u_prev, "--u-prev"), from_file, "u_prev", "--u-prev")
    step = _merge(dt, from_file, "dt", "--dt")
    name = _merge(method, from_file, "method", "--method")
    name = default_method() if name is None else name
    options = parse_options(option)
    file_options = from_file.get("options", {})
    if not isinstance(file_options, dict):
        raise typer.BadParameter(f"{problem}: options: must be a JSON object", param_hint="--problem")
    twice = sorted(set(options) & set(file_options))
    if twice:
        raise typer.BadParameter(f"option(s) {twice} given both in the problem file and as --option",
                                 param_hint="--option")
    options.update(file_options)
    if vehicle_file is not None:
        from .vehicles import method_options

        options = method_options(vehicle_file, name, options)

    t0 = time.perf_counter()
    allocator = alloc.make_allocator(p, name, **options)
    build_time = time.perf_counter() - t0
    result = allocator(demand, u_prev=previous, dt=step)
    first_call_time = result.solve_time
    times: list[float] = []
    budget_end = time.perf_counter() + TIMING_BUDGET_S
    while len(times) < repeat and (not times or time.perf_counter() < budget_end):
        times.append(allocator(demand, u_prev=previous, dt=step).solve_time)
    solve_time = statistics.median(times)
    if as_json:
        typer.echo(json.dumps({**result.to_dict(), "solve_time": solve_time, "first_call_time": first_call_time,
                               "build_time": build_time, "timed_calls": len(times),
                               "names": list(p.names), "axes": list(p.axes)}, indent=2))
        return
    typer.echo(f"method {result.method}: {result.status.value} ({result.iterations} iterations)")
    typer.echo(f"  time: solve {_fmt_seconds(solve_time)} (median of {len(times)} calls), first call "
               f"{_fmt_seconds(first_call_time)}, build {_fmt_seconds(build_time)}")
    for label, u in zip(p.names, result.u):
        typer.echo(f"  {label:<12} {u: .6g}")
    for axis, want, got in zip(p.axes, result.v, result.v_achieved):
        typer.echo(f"  {axis:<12} demand {want: .6g}  achieved {got: .6g}")


def _problem_at(vehicle: Any, pairs: list[str]) -> alloc.Problem:
    """The vehicle's problem at ``--at NAME=VALUE`` values (its [schedule]), or a one-line usage error."""
    values: dict[str, float] = {}
    for pair in pairs:
        key, sep, text = pair.partition("=")
        if not sep or not key.strip():
            raise typer.BadParameter(f"expected NAME=VALUE, got {pair[:60]!r}", param_hint="--at")
        try:
            value = float(text)
        except ValueError:
            raise typer.BadParameter(f"{key.strip()[:40]}: {text[:40]!r} is not a number", param_hint="--at") from None
        if key.strip() in values:
            raise typer.BadParameter(f"{key.strip()[:40]} given twice", param_hint="--at")
        values[key.strip()] = value
    try:
        return vehicle.problem_at(values)
    except AllocError as exc:
        raise typer.BadParameter(str(exc), param_hint="--at") from None


@app.command("export", cls=ExportCommand)
def export_command(
    vehicle: str = typer.Option(..., "--vehicle", metavar="NAME|FILE", help=VEHICLE_HELP),
    method: str | None = typer.Option(None, "--method", "-m", help="method to export (alloc.export.exportable())"),
    precision: str = typer.Option("double", "--precision", help="scalar type of the kernel: double or float"),
    out: Path = typer.Option(..., "--out", help="folder for the .h/.c pair (created)"),
    option: list[str] = typer.Option([], "--option", "-o", help="method option key=value (as for allocate)"),
    prefix: str | None = typer.Option(None, "--prefix", help="C prefix of the names and files; default "
                                         "alloc_<method>"),
    certify: bool = typer.Option(False, "--certify", help="active set and lp: enforce the iteration bound certified "
                                 "by sampling the demand set (alloc.export.certify); the same as "
                                 "--iteration-bound certify"),
    iteration_bound: str | None = typer.Option(None, "--iteration-bound", metavar="N|certify",
                                                  help="active set and lp: iterations (lp: pivots) a call may take "
                                                  "before it returns the safe answer (status 2); default the "
                                                  "library's caps"),
    maxit: int | None = typer.Option(None, "--maxit", help="active set: iteration cap per level; default the "
                                        "library's 50 + 10 (m + k)"),
    table: bool | None = typer.Option(None, "--table/--no-table", help="active set: precompute every free "
                                         "set's factorisation (--table) or factorise at run time (--no-table); "
                                         "default: tables when they fit 256 KiB"),
    cache: int | None = typer.Option(None, "--cache", metavar="SLOTS", help="active set without tables: slots "
                                        "of the static cache of recent factorisations (0: none); default as many "
                                        "as fit 16 KiB"),
    warm_start: bool = typer.Option(False, "--warm-start", help="active set: start each call from the last "
                                    "answer's working set (fewer iterations on smooth demands; answers then "
                                    "agree with the library's to round-off, not bit for bit, and depend on the "
                                    "calls before: see docs/export.md)"),
) -> None:
    """Write the allocator as a self-contained C99 kernel (alloc_<method>.h/.c; see docs/export.md)."""
    from .export import ExportError, export_c

    name = default_method() if method is None else method
    if certify and iteration_bound not in (None, "certify"):
        raise ExportError(f"iteration_bound: --certify and --iteration-bound {iteration_bound} disagree; give one",
                          field="iteration_bound")
    bound: int | str | None = "certify" if certify else iteration_bound
    if isinstance(bound, str) and bound != "certify":
        try:
            bound = int(bound)
        except ValueError:
            raise ExportError(f"iteration_bound: expected a positive integer or \"certify\", got {bound!r}",
                              field="iteration_bound") from None
    if out.exists() and not out.is_dir():  # refused before the work, as every output path
        raise typer.BadParameter(f"{out} is a file; give a folder for the .h/.c pair", param_hint="--out")
    kernel = export_c(load_vehicle_option(vehicle), name, precision=precision, options=parse_options(option),
                      prefix=prefix, iteration_bound=bound, maxit=maxit, table=table, cache=cache,
                      warm_start=warm_start)
    try:
        paths = kernel.write(out)
    except OSError as exc:
        raise typer.BadParameter(f"{out}: cannot write the kernel: {exc.strerror or exc}", param_hint="--out") from None
    for path in paths:
        typer.echo(str(path))


def main() -> None:  # pragma: no cover - console entry point
    app()


if __name__ == "__main__":  # pragma: no cover
    main()

"""``alloc bench quick|full`` (also ``python -m benchmarks.compare quick|full``)."""

from __future__ import annotations

import datetime as dt
import json
import os
import platform
import shlex
import sys
from pathlib import Path

import typer

from .sweep import Spec, full_sweep, quick_sweep

app = typer.Typer(help="Allocator comparison: open loop and closed loop, on all local cores or a Dask cluster.",
                  no_args_is_help=True)

_SCHEDULER = typer.Option(None, "--scheduler", metavar="ADDRESS",
                          help="Dask scheduler address (tcp://host:8786); default: local process pool")
_OUT = typer.Option(Path("benchmarks/results"), "--out", help="directory for the CSVs, report.md and PNGs")
_WORKERS = typer.Option(None, "--workers", min=1, help="local worker processes (default: all cores)")
_RESUME = typer.Option(True, "--resume/--no-resume", help="skip runs already in the CSVs")


def _command() -> str:
    """The command line as typed: ``alloc bench ...`` or ``python -m benchmarks.compare ...``."""
    prog = sys.argv[0]
    prog = "python -m benchmarks.compare" if prog.endswith("__main__.py") else Path(prog).name
    return " ".join([prog, *map(shlex.quote, sys.argv[1:])])


def _run(name: str, specs: list[Spec], scheduler: str | None, out: Path, workers: int | None, resume: bool) -> None:
    import numpy as np

    from .report import make_report
    from .runner import run_sweep

    outcome = run_sweep(specs, out, workers=workers, scheduler=scheduler, resume=resume, desc=f"{name} sweep")
    engine = (f"Dask scheduler {scheduler}" if scheduler else
              f"local process pool, {workers or os.cpu_count()} workers")
    meta = {
        "sweep": name, "command": _command(),
        "date": dt.datetime.now(dt.timezone.utc).strftime("%Y-%m-%d %H:%M UTC"),
        "cores": os.cpu_count(), "platform": f"{platform.system()} {platform.machine()}",
        "python": platform.python_version(), "numpy": np.__version__, "engine": engine,
        "runs": len(specs), "ran": outcome.ran, "skipped": outcome.skipped, "wall_s": round(outcome.wall_s, 1),
    }
    (out / "run.json").write_text(json.dumps(meta, indent=2) + "\n")
    path = make_report(out, specs, meta)
    typer.echo(f"{outcome.ran} runs in {outcome.wall_s:.1f} s ({outcome.skipped} resumed); report: {path}")


@app.command()
def quick(scheduler: str | None = _SCHEDULER, out: Path = _OUT, workers: int | None = _WORKERS,
          resume: bool = _RESUME) -> None:
    """Every method open loop; ICE closed loop around the failure (under 3 min on 2 cores)."""
    _run("quick", quick_sweep(), scheduler, out, workers, resume)


@app.command()
def full(scheduler: str | None = _SCHEDULER, out: Path = _OUT, workers: int | None = _WORKERS,
         resume: bool = _RESUME) -> None:
    """The complete sweep: every method, ICE and HARV lat-dir failures, blind and told, 5 seeds (long)."""
    _run("full", full_sweep(), scheduler, out, workers, resume)

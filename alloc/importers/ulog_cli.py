"""``alloc replay``, registered in the ``alloc.commands`` entry-point group (pyulog is optional)."""

from __future__ import annotations

import typer

from .ulog import replay_command

app = typer.Typer(help="Replay a PX4 ULog's torque and thrust setpoints through an allocator; "
                       "how our commands differ from PX4's (JSON, CSV).")
app.command()(replay_command())

"""``python -m benchmarks.compare quick|full`` (same app as ``alloc bench``)."""

from .cli import app

app(prog_name="python -m benchmarks.compare")

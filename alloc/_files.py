"""Reading a user's file with bounds: the one door every reader of user files goes through.

A path named by a user may be a symlink to ``/dev/zero``, a FIFO that never ends, a
directory, or a file far larger than anything the reader means to parse.  :func:`read_user_file`
refuses all of these before it reads, and reads at most ``max_bytes + 1`` bytes, so neither
memory nor time depends on what the path points to.  Its refusals are
:class:`~alloc.exceptions.ProblemError` (a ``ValueError``) naming the field.
"""

from __future__ import annotations

import os
import stat
from pathlib import Path

from .exceptions import ProblemError

__all__ = ["MAX_TEXT_BYTES", "MAX_LOG_BYTES", "read_user_file"]

#: the byte cap of a text file a user hands the library (vehicle TOML/JSON, PX4 parameters and
#: airframes, ArduPilot tables): 8 MiB holds a 512-effector vehicle with a full model many
#: times over (the largest catalogue file is under 64 KiB)
MAX_TEXT_BYTES = 8 * 2**20
#: the byte cap of a binary flight log (ULog); a replay reads a log whole
MAX_LOG_BYTES = 256 * 2**20


def read_user_file(path: str | os.PathLike[str], *, field: str = "path", max_bytes: int = MAX_TEXT_BYTES) -> bytes:
    """The bytes of the regular file at ``path``, at most ``max_bytes`` of them.

    Refused, naming ``field``: a path with a NUL byte, a path that is not a regular file
    after following symlinks (a directory, a FIFO, a device such as ``/dev/zero``, a socket),
    a file that cannot be opened, and a file longer than ``max_bytes``.  The file is opened
    non-blocking, so a FIFO swapped in after the check cannot block the open, and checked again
    on the open descriptor, so the answer concerns the file actually read.
    """
    text = os.fspath(path)
    if "\x00" in str(text):
        raise ProblemError(f"{field}: contains a NUL byte", field=field)
    name = Path(text).name or str(text)
    flags = os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_NOCTTY", 0)
    try:
        fd = os.open(text, flags)
    except OSError as exc:
        raise ProblemError(f"{field}: cannot read {str(text)!r} ({exc.strerror or exc})", field=field) from None
    try:
        info = os.fstat(fd)
        if not stat.S_ISREG(info.st_mode):
            raise ProblemError(f"{field}: {name} is not a regular file (a directory, device, FIFO or socket)",
                               field=field)
        if info.st_size > max_bytes:
            raise ProblemError(f"{field}: {name} is {info.st_size} bytes, more than the {max_bytes} allowed",
                               field=field)
        chunks: list[bytes] = []
        left = max_bytes + 1
        while left > 0:
            chunk = os.read(fd, min(left, 2**20))
            if not chunk:
                break
            chunks.append(chunk)
            left -= len(chunk)
    except OSError as exc:
        raise ProblemError(f"{field}: cannot read {str(text)!r} ({exc.strerror or exc})", field=field) from None
    finally:
        os.close(fd)
    raw = b"".join(chunks)
    if len(raw) > max_bytes:  # the file grew between the check and the read
        raise ProblemError(f"{field}: {name} is more than the {max_bytes} bytes allowed", field=field)
    return raw

"""Reading a user's file with bounds: the one door every reader of user files goes through.

A path named by a user may be a symlink to ``/dev/zero``, a FIFO that never ends, a
directory, or a file far larger than anything the reader means to parse.  :func:`read_user_file`
refuses all of these before it reads, and reads at most ``max_bytes + 1`` bytes, so neither
memory nor time depends on what the path points to.  :func:`parse_toml` and :func:`parse_json`
then parse the text with the nesting bounded (:data:`MAX_DEPTH`), and :func:`check_depth` bounds
an already parsed document.  Every refusal is a :class:`~alloc.exceptions.ProblemError` (a
``ValueError``) naming the field.

The caps, measured on this project's 2-core machine (the worst files found for each parser,
timed in ``tests/alloc/test_file_readers.py``; "loaded": both cores shared with about eight
other processes):

* :data:`MAX_TOML_BYTES` = 128 KiB.  ``tomllib`` is pure Python: the slowest 128 KiB found
  (table headers of 16 dotted parts, ``[k1.a.a...]``) is read and refused in 0.31 s (0.5-1 s
  loaded); 512 KiB of them took 2-4 s loaded.  The largest bundled vehicle (``ice.toml``) is
  12 KiB, a tenth of the cap; a 6 x 512 vehicle with a full ``B`` is 100 KB of TOML.
* :data:`MAX_TEXT_BYTES` = 1 MiB for the other text files (vehicle JSON, PX4 parameters,
  ArduPilot CSV tables): ``json`` is compiled; its slowest 1 MiB found (small nested lists) is
  read and refused in 0.20 s (0.5-1 s loaded).  A 32 x 512 vehicle with a full ``B`` is 0.45 MB
  of JSON, read in 0.13 s.
* :data:`MAX_DEPTH` = 16 levels of nesting (the bundled files reach 8); a TOML dotted key or
  table header of more parts is refused before ``tomllib`` sees it (its cost grows with the
  square of the parts: one 8,000-part key took 1 s and 260 MB).
"""

from __future__ import annotations

import json
import os
import re
import stat
import tomllib
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from .exceptions import ProblemError

__all__ = ["MAX_TEXT_BYTES", "MAX_TOML_BYTES", "MAX_LOG_BYTES", "MAX_DEPTH", "read_user_file", "read_user_text", "params_text",
           "parse_toml", "parse_json", "check_depth"]

#: the byte cap of a text file a user hands the library other than TOML (vehicle JSON, PX4
#: parameters and airframes, ArduPilot CSV tables); see the module docstring for the measurement
MAX_TEXT_BYTES = 2**20
#: the byte cap of a TOML file (vehicle files, ArduPilot tables): ``tomllib`` is pure Python,
#: about 30 times slower per byte than the ``json`` parser
MAX_TOML_BYTES = 128 * 2**10
#: the byte cap of a binary flight log (ULog); a replay reads a log whole
MAX_LOG_BYTES = 256 * 2**20
#: the deepest nesting of a parsed document (tables and lists); the bundled vehicles reach 8
MAX_DEPTH = 16


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


def params_text(source: Any, *, is_path: bool) -> str:
    """A parameter file's text: read from ``source`` when ``is_path`` (or a :class:`~pathlib.Path`),
    else ``source`` itself, held to :data:`MAX_TEXT_BYTES`; refused naming ``path`` or ``params``."""
    if isinstance(source, Path) or (isinstance(source, str) and is_path):
        return read_user_text(source, field="path", max_bytes=MAX_TEXT_BYTES)
    if isinstance(source, str):
        if len(source) > MAX_TEXT_BYTES:
            raise ProblemError(f"params: the text is {len(source)} characters, more than the {MAX_TEXT_BYTES} "
                               "allowed", field="params")
        return source
    raise ProblemError(f"params: expected a path or the file's text, got {type(source).__name__}", field="params")


def read_user_text(path: str | os.PathLike[str], *, field: str = "path", max_bytes: int = MAX_TEXT_BYTES) -> str:
    """:func:`read_user_file` decoded as UTF-8 (refused naming ``field`` when it is not)."""
    raw = read_user_file(path, field=field, max_bytes=max_bytes)
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ProblemError(f"{field}: {_name(path)} is not UTF-8 text ({exc.reason} at byte {exc.start})",
                           field=field) from None


def _name(path: str | os.PathLike[str]) -> str:
    text = str(os.fspath(path))
    return Path(text).name or text


# TOML's strings and comments, each matched whole or to where it would have to end (an unclosed
# string to the end of its line or text: tomllib refuses it there), so one pass is linear
_TOML_STRINGS = re.compile(r"""
    "{3}(?:[^"\\]|\\.|"(?!""))*+(?:"{3}|\Z)     # multi-line basic
  | '{3}(?:[^']|'(?!''))*+(?:'{3}|\Z)           # multi-line literal
  | "(?:[^"\\\n]|\\.)*+(?:"|$)                  # basic
  | '[^'\n]*+(?:'|$)                            # literal
  | \#[^\n]*+                                   # comment
""", re.S | re.M | re.X)
# a run of more than MAX_DEPTH dotted parts, once every string is "": a key or table header
# nesting deeper than a document may (possessive parts and the look-behind keep it linear)
_LONG_KEY = re.compile(rf"""(?<![\w"'.-])(?:[\w-]++|""|'')(?:[ \t]*+\.[ \t]*+(?:[\w-]++|""|'')){{{MAX_DEPTH}}}""")


def parse_toml(text: str, *, field: str = "path", name: str = "the text", root: str = "") -> dict[str, Any]:
    """The TOML document in ``text``, nested at most :data:`MAX_DEPTH` levels.

    Refused naming ``field`` (and ``name``, the file's): invalid TOML, a dotted key or table
    header of more than :data:`MAX_DEPTH` parts or arrays and inline tables nested deeper (both
    found by a linear scan of the text without its strings and comments, before ``tomllib``
    sees it: its cost grows with the square of a key's parts), and an integer too long to
    read; a document nested deeper is refused naming the path below ``root`` (:func:`check_depth`).
    """
    bare = _TOML_STRINGS.sub('""', text)
    long_key = _LONG_KEY.search(bare)
    if long_key is not None:
        line = bare.count("\n", 0, long_key.start()) + 1
        raise ProblemError(f"{field}: {name}: line {line}: a dotted key of more than {MAX_DEPTH} parts "
                           f"(documents nest at most {MAX_DEPTH} levels)", field=field)
    depth = _bracket_depth(bare)
    if depth > MAX_DEPTH:
        raise ProblemError(f"{field}: {name} nests {depth} levels, more than the {MAX_DEPTH} allowed", field=field)
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ProblemError(f"{field}: {name} is not valid TOML ({exc})", field=field) from None
    except RecursionError:  # not reached after the scan; kept so that no parser error escapes
        raise ProblemError(f"{field}: {name} nests more than {MAX_DEPTH} levels", field=field) from None
    except ValueError:
        raise ProblemError(f"{field}: {name}: {_TOO_LONG}", field=field) from None
    check_depth(doc, root=root)
    return doc


#: the one ValueError ``tomllib`` and ``json`` let out besides their decode errors: Python reads
#: an integer of at most 4,300 digits (``sys.get_int_max_str_digits``)
_TOO_LONG = "an integer of more than 4,300 digits (far beyond float64)"


class _DuplicateKey(ValueError):
    pass


def _no_duplicate_keys(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    out = dict(pairs)
    if len(out) != len(pairs):  # JSON's own rule is "last wins"; a vehicle's author meant one of them
        seen: set[str] = set()
        for key, _ in pairs:
            if key in seen:
                raise _DuplicateKey(f"duplicate key {key[:60]!r}")
            seen.add(key)
    return out


def parse_json(text: str, *, field: str = "path", name: str = "the text") -> Any:
    """The JSON document in ``text``, nested at most :data:`MAX_DEPTH` levels, without duplicate keys.

    ``NaN``, ``Infinity`` and numbers beyond float64 are left to the reader of each field (which
    names the field: ``effectors[2].min: must be finite, got nan``); an integer of more than
    4,300 digits, which Python will not read, is refused here naming ``field``.  The nesting is
    measured on the text (the parsed document of 1 MiB of ``[[[]]]`` takes longer to walk than
    to parse).
    """
    try:
        doc = json.loads(text, object_pairs_hook=_no_duplicate_keys)
    except json.JSONDecodeError as exc:
        raise ProblemError(f"{field}: {name} is not valid JSON ({exc})", field=field) from None
    except _DuplicateKey as exc:
        raise ProblemError(f"{field}: {name}: {exc}", field=field) from None
    except RecursionError:
        raise ProblemError(f"{field}: {name} nests more than {MAX_DEPTH} levels", field=field) from None
    except ValueError:
        raise ProblemError(f"{field}: {name}: {_TOO_LONG}", field=field) from None
    depth = _bracket_depth(_JSON_STRING.sub("", text))
    if depth > MAX_DEPTH:
        raise ProblemError(f"{field}: {name} nests {depth} levels, more than the {MAX_DEPTH} allowed", field=field)
    return doc


# valid JSON only (every string terminated), so the possessive scan is linear
_JSON_STRING = re.compile(r'"(?:[^"\\]|\\.)*+"', re.S)
_NOT_BRACKET = re.compile(r"[^\[\]{}]+")


def _bracket_depth(text: str) -> int:
    """The deepest nesting of brackets in a text without strings, counted at compiled speed."""
    brackets = _NOT_BRACKET.sub("", text).encode("ascii")
    if not brackets:
        return 0
    codes = np.frombuffer(brackets, dtype=np.uint8)
    steps = np.where((codes == ord("[")) | (codes == ord("{")), 1, -1)
    return int(np.cumsum(steps).max())


def check_depth(doc: Any, *, root: str = "", max_depth: int = MAX_DEPTH) -> None:
    """Refuse a document (mappings, lists, tuples) nested more than ``max_depth`` levels, naming
    the path of the first too-deep value below ``root`` (``simulation.failures.x.A[0][0]...``).

    Level by level, without recursion, so neither a deep document nor a cyclic one exhausts the
    recursion limit; a level keeps each container's parent (an index), and the path is spelled
    out only for the error.
    """
    if not _is_container(doc):
        return
    levels: list[list[Any]] = [[doc]]
    parents: list[list[int]] = [[-1]]
    while levels[-1]:
        if len(levels) > max_depth:
            where = _spell(root, levels, parents)
            raise ProblemError(f"{where}: nested more than {max_depth} levels", field=where)
        below: list[Any] = []
        index: list[int] = []
        for i, node in enumerate(levels[-1]):
            for child in (node.values() if isinstance(node, Mapping) else node):
                if type(child) not in _SCALARS and child and _is_container(child):  # empty: no deeper
                    below.append(child)
                    index.append(i)
        levels.append(below)
        parents.append(index)


_SCALARS = frozenset((int, float, str, bool, type(None)))


def _is_container(value: Any) -> bool:
    return isinstance(value, (dict, list, tuple, Mapping))


def _spell(root: str, levels: list[list[Any]], parents: list[list[int]]) -> str:
    """The path of the first container of the last level: each step's key found by identity."""
    out, i = [], 0
    for depth in range(len(levels) - 1, 0, -1):
        child, i = levels[depth][i], parents[depth][i]
        parent = levels[depth - 1][i]
        pairs = parent.items() if isinstance(parent, Mapping) else enumerate(parent)
        out.append(next(k for k, v in pairs if v is child))
    text = root
    for key in reversed(out):
        if isinstance(key, int):
            text += f"[{key}]"
        else:
            name = str(key) if len(str(key)) <= 40 else str(key)[:37] + "..."
            text += f".{name}" if text else name
    return text or "document"

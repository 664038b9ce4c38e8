"""A ULog's message structure checked before pyulog reads it, so pyulog's reader cannot loop.

Why: pyulog's definitions reader recovers from a corrupt header (type 0, unknown type with size
0 or above 10,000) by seeking back ``2 + msg_size`` bytes, "to advance by a single byte" -- but it
never checks that ``msg_size`` bytes were read.  Within 64 KiB of the end of the file the read is
short, the seek lands *before* the header, and the reader parses the same bytes forever (issue 39:
one flipped byte in the 151 KB test log, more than 300 s of CPU).  Its data reader's recoveries
(a one-byte step after a corrupt header, each step re-reading up to 64 KiB; a scan for the sync
sequence inside a skipped message) are bounded but jump off the message boundaries, so what it
returns is no longer the log's messages; appended-data offsets make it read ranges again; a
format that contains itself recurses without end; nested arrays of formats expand to
``65535**depth`` fields; and a ``struct.error`` in the data section silently ends the read.

:func:`scan_ulog` walks the messages by their declared sizes and refuses every log on which
pyulog would leave that walk: then pyulog reads exactly the messages walked, each once, and its
work is linear in the bytes (at most :data:`MAX_LOG_MESSAGES` messages, :data:`MAX_SUBSCRIBED_FIELDS`
fields made for subscriptions).  What pyulog cannot read inside a message it flags as corruption
(the caller refuses that) or, for a ``struct.error`` in the data section, stops: the counts of
data messages per subscription this walk returns let the caller check nothing was dropped.
Refusals are :class:`~alloc.exceptions.ProblemError` naming ``ulog`` and the byte offset.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, field

from ..exceptions import ProblemError

__all__ = ["MAX_LOG_MESSAGES", "MAX_LOG_RECORDS", "MAX_SUBSCRIBED_FIELDS", "ULogScan", "scan_ulog"]

#: the most messages a log may hold: a 256 MiB PX4 log of 32-byte messages (its smallest topics
#: are ~45 bytes); it bounds pyulog's per-message Python loop (measured in tests/alloc/test_ulog_hostile.py)
MAX_LOG_MESSAGES = 2**23
#: the most fields pyulog may create for all subscriptions together (a PX4 log: ~150
#: subscriptions of ~30 fields); each subscription also at most one message's 65,535 bytes
MAX_SUBSCRIBED_FIELDS = 2**20
#: the most messages pyulog keeps an object for (log lines, changed parameters, info, dropouts,
#: subscriptions), a few thousand in a PX4 log: each costs it ~10 times its bytes of memory
MAX_LOG_RECORDS = 2**18
#: the deepest nesting of formats (PX4's uORB messages nest at most 3 deep)
MAX_FORMAT_NESTING = 32

HEADER = b"ULog\x01\x12\x35"
SYNC = b"\x2f\x73\x13\x20\x25\x0c\xbb\x12"
#: pyulog's basic field types and their sizes (``ULog._UNPACK_TYPES``)
BASIC_SIZES = {"int8_t": 1, "uint8_t": 1, "int16_t": 2, "uint16_t": 2, "int32_t": 4, "uint32_t": 4,
               "int64_t": 8, "uint64_t": 8, "float": 4, "double": 8, "bool": 1, "char": 1}
_DEFINITIONS = frozenset(b"FIMPQ")  # parsed by the definitions reader (B only first)
_DEFINITIONS_END = frozenset(b"ALC")  # the first of these starts the data section
_DEFINITIONS_SKIPPED = frozenset(b"DOSR")  # skipped by size if 1..10,000 bytes
_DATA = frozenset(b"ALCDOSIMPQ")  # parsed by the data reader
_DATA_SKIPPED = frozenset(b"BFR")  # skipped by size if 1..10,000 bytes with no sync sequence inside
_SKIP_MAX = 10_000  # pyulog's _check_packet_corruption: larger skipped messages are "corrupt"
_MESSAGE_BYTES = 0xFFFF
#: the shortest payload the data reader unpacks without a struct.error (which ends its read)
_DATA_MIN_SIZE = {ord("A"): 3, ord("L"): 9, ord("C"): 11, ord("D"): 2, ord("I"): 1, ord("M"): 2,
                  ord("P"): 1, ord("Q"): 2}


@dataclass
class ULogScan:
    """What the walk found: per subscription ``(name, multi_id)`` its message id and data messages."""

    messages: int = 0
    data_start: int = 0
    subscriptions: dict[int, tuple[str, int]] = field(default_factory=dict)
    data_messages: dict[int, int] = field(default_factory=dict)

    def samples(self, name: str, multi_id: int = 0) -> list[int]:
        """The data-message counts of the subscriptions of ``name`` (one entry per message id)."""
        return [self.data_messages.get(mid, 0) for mid, key in self.subscriptions.items() if key == (name, multi_id)]


def _refuse(offset: int, reason: str) -> ProblemError:
    return ProblemError(f"ulog: byte {offset}: {reason} (a damaged or non-PX4 log)", field="ulog")


def _format(payload: bytes, offset: int) -> tuple[str, list[tuple[str, int, str]]] | None:
    """pyulog's reading of a format message (``ULog.MessageFormat``): its name and (type, array
    size, name) fields, or None where pyulog drops the message."""
    parts = payload.decode("utf-8", "ignore").split(":")
    if len(parts) < 2:
        return None
    fields = []
    for text in parts[1].split(";"):
        if not text:
            continue
        words = text.split(" ")
        if len(words) < 2:
            return None
        type_str = words[0]
        a = type_str.find("[")
        if a == -1:
            fields.append((type_str, 0, words[1]))
            continue
        b = type_str.find("]")
        try:
            size = int(type_str[a + 1:b])
        except ValueError:
            return None
        if not 0 <= size <= _MESSAGE_BYTES:  # pyulog before 1.2 expands any size
            raise _refuse(offset, f"format {parts[0][:40]!r} has an array of {size} elements")
        fields.append((type_str[:a], size, words[1]))
    return parts[0], fields


class _Formats:
    """Expanded sizes of the formats, as pyulog's ``_parse_nested_type`` flattens them."""

    def __init__(self) -> None:
        self.fields: dict[str, list[tuple[str, int, str]]] = {}
        self._bytes: dict[str, int] = {}

    def expanded_bytes(self, name: str, offset: int, stack: tuple[str, ...] = ()) -> int:
        """Bytes (each field at least one, so also a bound on the fields) of ``name`` flattened."""
        if name in self._bytes:
            return self._bytes[name]
        if name not in self.fields:  # pyulog: a KeyError after less work than counted here
            return 0
        if name in stack:
            raise _refuse(offset, f"format {name[:40]!r} contains itself")
        if len(stack) >= MAX_FORMAT_NESTING:
            raise _refuse(offset, f"formats nest more than {MAX_FORMAT_NESTING} deep")
        total = 0
        for type_name, size, _ in self.fields[name]:
            one = BASIC_SIZES[type_name] if type_name in BASIC_SIZES else \
                self.expanded_bytes(type_name, offset, (*stack, name))
            total += max(size, 1) * one
        self._bytes[name] = total
        return total


def _info_struct_error(payload: bytes, prefix: int) -> bool:
    """Whether pyulog's ``_MessageInfo`` (after ``prefix`` leading bytes) raises a struct.error."""
    if len(payload) < prefix + 1:
        return True
    data = payload[prefix:]
    key_len = data[0]
    words = data[1:1 + key_len].decode("utf-8", "ignore").split(" ")
    if len(words) < 2 or words[0].startswith("char[") or words[0] not in BASIC_SIZES:
        return False  # an IndexError pyulog catches, a string or an array: no unpacking
    return len(data) - 1 - key_len != BASIC_SIZES[words[0]]


def scan_ulog(raw: bytes, name: str = "the log") -> ULogScan:
    """Walk the messages of the ULog ``raw`` (the file ``name``) by their sizes; refuse what pyulog
    would not walk the same way."""
    if len(raw) < 16 or raw[:7] != HEADER:
        raise ProblemError(f"ulog: cannot read {name} as a ULog (its first 16 bytes are not a ULog header)",
                           field="ulog")
    scan = ULogScan()
    formats = _Formats()
    offset, appended = _walk_definitions(raw, scan, formats)
    scan.data_start = offset
    _walk_data(raw, offset, scan, formats, appended)
    return scan


def _walk_definitions(raw: bytes, scan: ULogScan, formats: _Formats) -> tuple[int, list[int]]:
    """The definitions section up to the first A/L/C message: its formats, the appended-data
    offsets of its flag bits; the offset where the data section starts."""
    appended: list[int] = []
    offset, end = 16, len(raw)
    while offset < end:
        if end - offset < 3:
            raise _refuse(offset, "the log ends inside its definitions")
        size, kind = struct.unpack_from("<HB", raw, offset)
        start = offset + 3
        if start + size > end:  # pyulog seeks back by more than it read: the loop of issue 39
            raise _refuse(offset, f"a {size}-byte message runs past the end of the definitions")
        if kind in _DEFINITIONS_END:
            break
        scan.messages += 1
        payload = raw[start:start + size]
        if kind == ord("B"):
            if offset != 16:
                raise _refuse(offset, "a flag-bits message that is not the first message")
            if size >= 40 and payload[8] & 1:  # incompat flag DATA_APPENDED
                appended = list(struct.unpack_from("<3Q", payload, 16))
                while appended and appended[-1] == 0:
                    appended.pop()
        elif kind == ord("F"):
            parsed = _format(payload, offset)
            if parsed is not None:
                formats.fields[parsed[0]] = parsed[1]
        elif kind in _DEFINITIONS_SKIPPED:
            if not 1 <= size <= _SKIP_MAX:
                raise _refuse(offset, f"a {chr(kind)!r} message of {size} bytes in the definitions")
        elif kind not in _DEFINITIONS:
            raise _refuse(offset, f"unknown message type {kind:#04x}")
        offset = start + size
    return offset, appended


def _walk_data(raw: bytes, offset: int, scan: ULogScan, formats: _Formats, appended: list[int]) -> None:
    """The data section: every message of a type pyulog's data reader parses without leaving the
    walk; subscriptions and their data-message counts; appended offsets on message boundaries."""
    end = len(raw)
    unpack_header = struct.Struct("<HB").unpack_from
    unpack_id = struct.Struct("<H").unpack_from
    counts = scan.data_messages
    wanted = {o: False for o in appended}
    fields_made = records = 0
    messages = scan.messages
    D, S = ord("D"), ord("S")
    while end - offset >= 3:  # a log cut inside a header or (below) a message: pyulog stops there too
        size, kind = unpack_header(raw, offset)
        start = offset + 3
        if start + size > end:
            break
        messages += 1
        if messages > MAX_LOG_MESSAGES:
            raise _refuse(offset, f"more than {MAX_LOG_MESSAGES} messages")
        if offset in wanted:
            wanted[offset] = True
        if kind == D and size >= 2:  # the bulk of a log: only counted
            (msg_id,) = unpack_id(raw, start)
            if msg_id in counts:
                counts[msg_id] += 1
        elif kind == S:
            pass
        elif kind in _DATA_SKIPPED:
            if not 1 <= size <= _SKIP_MAX or SYNC in raw[start:start + size]:
                raise _refuse(offset, f"a {chr(kind)!r} message of {size} bytes in the data section")
        elif kind not in _DATA:
            raise _refuse(offset, f"unknown message type {kind:#04x}")
        else:
            payload = raw[start:start + size]
            if size < _DATA_MIN_SIZE.get(kind, 0) or (kind == ord("O") and size != 2) or (
                    kind in b"IP" and _info_struct_error(payload, 0)) or (
                    kind in b"MQ" and _info_struct_error(payload, 1)):
                raise _refuse(offset, f"a {chr(kind)!r} message of {size} bytes that cannot be read")
            records += 1  # pyulog keeps an object per message of these kinds
            if records > MAX_LOG_RECORDS:
                raise _refuse(offset, f"more than {MAX_LOG_RECORDS} log, parameter, info, dropout or "
                                      "subscription messages")
            if kind == ord("A"):
                fields_made += _subscribe(payload, offset, scan, formats)
                if fields_made > MAX_SUBSCRIBED_FIELDS:
                    raise _refuse(offset, f"subscriptions of more than {MAX_SUBSCRIBED_FIELDS} fields")
        offset = start + size
    scan.messages = messages
    # pyulog reads up to each appended offset, then seeks to it: anything but a later message
    # boundary makes it read a range twice or from inside a message
    previous = scan.data_start
    for o in appended:
        if not wanted[o] or o <= previous:
            raise _refuse(16, f"appended-data offset {o} is not a later message boundary")
        previous = o


def _subscribe(payload: bytes, offset: int, scan: ULogScan, formats: _Formats) -> int:
    """An A message: the subscription it makes (pyulog's ``_MessageAddLogged``); the fields it expands to."""
    multi_id, msg_id = struct.unpack_from("<BH", payload)
    name = payload[3:].decode("utf-8", "ignore")
    expanded = formats.expanded_bytes(name, offset)
    if expanded > _MESSAGE_BYTES:
        raise _refuse(offset, f"subscription {name[:40]!r}: its format flattens to {expanded} bytes, "
                              "more than a message holds")
    if name in formats.fields and not _has_timestamp(formats.fields[name]):
        raise _refuse(offset, f"subscription {name[:40]!r}: its format has no 64-bit timestamp")
    scan.subscriptions[msg_id] = (name, multi_id)
    scan.data_messages[msg_id] = 0
    return expanded


def _has_timestamp(fields: list[tuple[str, int, str]]) -> bool:
    """Whether pyulog finds 8 bytes at the subscription's timestamp offset.  pyulog sums the sizes
    of the flattened fields before the first one named ``timestamp``, which only a top-level plain
    basic field can be (arrays and nested types get other names); unless that field is 8 bytes
    long, unpacking it can raise the struct.error that silently ends pyulog's read."""
    for type_name, size, name in fields:
        if name == "timestamp" and size == 0 and type_name in BASIC_SIZES:
            return BASIC_SIZES[type_name] == 8
    return False

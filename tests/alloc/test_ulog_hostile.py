"""Hostile ULogs (issue 39): a damaged or patched log is refused with an AllocError naming the
field, quickly, or replayed validly; never a loop, a KeyError/ValueError/IndexError, a traceback.

Seeded mutants of the bundled test log (``tests/alloc/data/px4_sitl_quad.ulg``): flipped bits,
truncations, duplicated, zeroed and shuffled ranges, hostile parameter values
(``CA_ROTOR_COUNT`` 13, 2**31-1, -1, NaN as float ...), timestamps and setpoints patched in the
data messages.  Each runs under an interval timer, so a reader that loops fails the test
instead of hanging it.  A quick run by default; the large one is marked ``slow``.
"""

from __future__ import annotations

import json
import math
import random
import signal
import struct
import time
from collections import Counter
from pathlib import Path
from typing import Any
from collections.abc import Callable, Iterator

import numpy as np
import pytest

pytest.importorskip("pyulog")

from alloc.exceptions import AllocError, ProblemError
from alloc.importers import _ulog_scan
from alloc.importers.px4 import vehicle_from_params
from alloc.importers.ulog import read_ulog, replay

LOG = Path(__file__).parent / "data" / "px4_sitl_quad.ulg"
RAW = LOG.read_bytes()
SEED = 20261205
#: seconds one mutant may take, read and replayed (the bundled log: ~15 ms; a shared 2-core machine)
DEADLINE = 10.0
#: the flip of issue 39: a zero byte of a parameter message's value turned into 4 (bit 2 of
#: byte 91,554) desynchronises the definitions, and pyulog's recovery seeks back for ever
ISSUE_39_FLIP = (91_554, 2)


# ------------------------------------------------------------------ the log's messages
def messages(raw: bytes) -> Iterator[tuple[int, int, int]]:
    """(offset, payload size, type) of each whole message, walked by size."""
    offset = 16
    while offset + 3 <= len(raw):
        size, kind = struct.unpack_from("<HB", raw, offset)
        if offset + 3 + size > len(raw):
            return
        yield offset, size, kind
        offset += 3 + size


def parameter_offsets(raw: bytes) -> dict[str, tuple[int, str, int]]:
    """Parameter name -> (offset of its value, its type, its value's size) in the definitions."""
    out = {}
    for offset, size, kind in messages(raw):
        if kind == ord("A"):
            break
        if kind == ord("P"):
            key_len = raw[offset + 3]
            type_name, name = raw[offset + 4:offset + 4 + key_len].decode().split(" ")
            out[name] = (offset + 4 + key_len, type_name, size - 1 - key_len)
    return out


PARAMS = parameter_offsets(RAW)
#: data-message id of each topic, from the log's own subscriptions (A messages)
TOPIC_IDS = {RAW[o + 6:o + 3 + s].decode(): struct.unpack_from("<H", RAW, o + 4)[0]
             for o, s, k in messages(RAW) if k == ord("A")}
#: byte offset inside a data message's payload (after its 2-byte id): uint64 timestamp,
#: uint64 timestamp_sample, then float xyz[3] / control[12] (the formats of the bundled log)
SAMPLE_AT, VALUES_AT = 2 + 8, 2 + 16


def data_offsets(raw: bytes, topic: str) -> list[int]:
    mid = TOPIC_IDS[topic]
    return [o + 3 for o, s, k in messages(raw) if k == ord("D") and struct.unpack_from("<H", raw, o + 3)[0] == mid]


def with_message(raw: bytes, offset: int, payload: bytes) -> bytes:
    """``raw`` with the message at ``offset`` given a new payload (its size field updated)."""
    size, kind = struct.unpack_from("<HB", raw, offset)
    return raw[:offset] + struct.pack("<HB", len(payload), kind) + payload + raw[offset + 3 + size:]


def patch_parameter(raw: bytes, name: str, value: Any) -> bytes:
    at, type_name, size = PARAMS[name]
    if isinstance(value, float) and type_name == "int32_t":  # retype the parameter as a float
        key = f"float {name}".encode()
        message = next(o for o, s, k in messages(raw) if k == ord("P") and raw[o + 4:o + 4 + raw[o + 3]] ==
                       f"{type_name} {name}".encode())
        return with_message(raw, message, bytes([len(key)]) + key + struct.pack("<f", value))
    code = {"int32_t": "<i", "float": "<f"}[type_name]
    return raw[:at] + struct.pack(code, value) + raw[at + size:]


def rename_in_format(raw: bytes, topic: str, old: bytes, new: bytes) -> bytes:
    """A field of ``topic``'s format renamed (``old`` -> ``new``, any length)."""
    for offset, size, kind in messages(raw):
        payload = raw[offset + 3:offset + 3 + size]
        if kind == ord("F") and payload.startswith(topic.encode() + b":"):
            assert old in payload
            return with_message(raw, offset, payload.replace(old, new, 1))
    raise AssertionError(f"no format {topic}")


# ------------------------------------------------------------------ mutants
HOSTILE_INTS = [0, -1, 1, 2, 3, 5, 11, 12, 13, 255, 2**31 - 1, -(2**31)]
HOSTILE_FLOATS = [math.nan, math.inf, -math.inf, 0.0, -1.0, 1e30, -1e-30, 3.4e38, 0.5]
NUMERIC_PARAMS = sorted(n for n in PARAMS if n.startswith(("CA_", "MPC_THR_HOVER")))


def mutant(rng: random.Random) -> tuple[str, bytes]:
    """One seeded mutant of the bundled log and what was done to it."""
    raw, n = RAW, len(RAW)
    kind = rng.choice(["flip", "flips", "truncate", "duplicate", "zero", "swap", "param", "rotors",
                       "sample_time", "setpoint", "command", "definitions_flip"])
    if kind == "flip":
        at, bit = rng.randrange(n), rng.randrange(8)
        return f"flip byte {at} bit {bit}", raw[:at] + bytes([raw[at] ^ 1 << bit]) + raw[at + 1:]
    if kind == "definitions_flip":  # where issue 39's loop lives: the definitions section
        at, bit = rng.randrange(16, 94_434), rng.randrange(8)
        return f"flip byte {at} bit {bit}", raw[:at] + bytes([raw[at] ^ 1 << bit]) + raw[at + 1:]
    if kind == "flips":
        b = bytearray(raw)
        spots = [(rng.randrange(n), rng.randrange(8)) for _ in range(rng.randint(2, 16))]
        for at, bit in spots:
            b[at] ^= 1 << bit
        return f"flips {spots}", bytes(b)
    if kind == "truncate":
        at = rng.randrange(n)
        return f"truncate at {at}", raw[:at]
    if kind in ("duplicate", "zero", "swap"):
        at = rng.randrange(n)
        length = min(rng.choice([1, 3, 8, 64, 512, 4096, 40_000]), n - at)
        if kind == "duplicate":
            to = rng.randrange(n)
            return f"copy {length} bytes at {at} to {to}", raw[:to] + raw[at:at + length] + raw[to:]
        if kind == "zero":
            return f"zero {length} bytes at {at}", raw[:at] + bytes(length) + raw[at + length:]
        other = rng.randrange(n - length)
        b = bytearray(raw)
        b[at:at + length], b[other:other + length] = raw[other:other + length], raw[at:at + length]
        return f"swap {length} bytes at {at} and {other}", bytes(b)
    if kind == "rotors":
        value = rng.choice(HOSTILE_INTS + [4.0, math.nan, 1e9, -0.0])
        return f"CA_ROTOR_COUNT = {value!r}", patch_parameter(raw, "CA_ROTOR_COUNT", value)
    if kind == "param":
        name = rng.choice(NUMERIC_PARAMS)
        _, type_name, _ = PARAMS[name]
        value = rng.choice(HOSTILE_INTS) if type_name == "int32_t" and rng.random() < 0.7 else \
            rng.choice(HOSTILE_FLOATS)
        return f"{name} = {value!r}", patch_parameter(raw, name, value)
    topic = rng.choice(["vehicle_torque_setpoint", "vehicle_thrust_setpoint", "actuator_motors"])
    at = rng.choice(data_offsets(raw, topic))
    if kind == "sample_time":
        value = rng.choice([0, 1, 2**63, 2**64 - 1, struct.unpack_from("<Q", raw, at + SAMPLE_AT)[0] - 100_000])
        return f"{topic} sample time at {at} = {value}", \
            raw[:at + SAMPLE_AT] + struct.pack("<Q", value) + raw[at + SAMPLE_AT + 8:]
    j = rng.randrange(3 if topic != "actuator_motors" else 12)
    value = rng.choice(HOSTILE_FLOATS)
    spot = at + VALUES_AT + 4 * j
    return f"{topic} value {j} at {at} = {value}", raw[:spot] + struct.pack("<f", value) + raw[spot + 4:]


class Timeout(Exception):
    pass


def _alarm(signum: int, frame: Any) -> None:
    raise Timeout


def within(seconds: float, work: Callable[[], Any]) -> Any:
    """``work()`` interrupted by SIGALRM after ``seconds`` (pyulog's loops are pure Python)."""
    previous = signal.signal(signal.SIGALRM, _alarm)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        return work()
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)


def assert_valid_replay(log: Any, what: str) -> None:
    """What a replay that is not refused must be: finite, increasing, admissible."""
    assert log.t.size >= 1 and np.all(np.isfinite(log.t)) and np.all(np.diff(log.t) > 0), what
    assert np.all(np.isfinite(log.demand)) and np.all(np.isfinite(log.motors)), what
    r = replay(log, "pinv")
    problem = vehicle_from_params(log.params, normalize="px4").problem()
    assert r.u.shape == log.motors.shape and np.all(np.isfinite(r.u)), what
    assert np.all((r.u >= problem.umin - 1e-12) & (r.u <= problem.umax + 1e-12)), what
    s = r.summary()
    assert s["samples"] == log.t.size and abs(sum(s["status"].values()) - 1) < 1e-12, what
    json.dumps(s, allow_nan=False)


def run_mutants(count: int, seed: int, tmp_path: Path) -> Counter:
    rng = random.Random(seed)
    outcome: Counter = Counter()
    path = tmp_path / "mutant.ulg"
    slowest, slowest_what = 0.0, ""
    for k in range(count):
        what, raw = mutant(rng)
        what = f"mutant {k} (seed {seed}): {what}"
        path.write_bytes(raw)
        start = time.perf_counter()
        try:
            within(DEADLINE, lambda: assert_valid_replay(read_ulog(path), what))
            outcome["replayed"] += 1
        except AllocError as exc:
            assert isinstance(exc, ValueError | TypeError), what
            head = str(exc).partition(":")[0]
            assert head and " " not in head.strip(), (what, str(exc))  # the message starts with its field
            outcome[head.split("[")[0]] += 1
        except Timeout:
            pytest.fail(f"{what}: not done within {DEADLINE} s")
        if time.perf_counter() - start > slowest:
            slowest, slowest_what = time.perf_counter() - start, what
    print(f"slowest {1000 * slowest:.0f} ms: {slowest_what}")
    return outcome


def test_quick_mutants_are_refused_by_field_or_replayed(tmp_path: Path) -> None:
    outcome = run_mutants(250, SEED, tmp_path)
    print(dict(outcome))
    assert outcome["replayed"] >= 20 and sum(v for k, v in outcome.items() if k != "replayed") >= 50


@pytest.mark.slow
def test_many_mutants_are_refused_by_field_or_replayed(tmp_path: Path) -> None:
    start = time.perf_counter()
    outcome = run_mutants(2000, SEED + 1, tmp_path)
    print(dict(outcome), f"{time.perf_counter() - start:.1f} s")
    assert outcome["replayed"] >= 200


# ------------------------------------------------------------------ the command line
def cli_cases(count: int, seed: int) -> Iterator[tuple[str, bytes]]:
    rng = random.Random(seed)
    for _ in range(count):
        yield mutant(rng)


def check_cli(cases: Iterator[tuple[str, bytes]], tmp_path: Path) -> Counter:
    from typer.testing import CliRunner

    from alloc.cli import app

    runner = CliRunner()
    path = tmp_path / "mutant.ulg"
    codes: Counter = Counter()
    for what, raw in cases:
        path.write_bytes(raw)
        res = within(DEADLINE, lambda: runner.invoke(app, ["replay", "--ulog", str(path)], prog_name="alloc"))
        where = f"{what}: exit {res.exit_code}, stderr {res.stderr[:300]!r}"
        assert res.exit_code in (0, 2), where
        assert "Traceback" not in res.stdout + res.stderr, where
        if res.exit_code == 2:
            lines = [line for line in res.stderr.splitlines() if line.strip()]
            assert len(lines) == 1 and lines[0].startswith("alloc replay: error: "), where
            assert res.stdout == "", where  # pyulog's own warnings are kept off stdout
        else:
            assert json.loads(res.stdout)["samples"] >= 1, where
        codes[res.exit_code] += 1
    return codes


def test_cli_refuses_every_mutant_in_one_line(tmp_path: Path) -> None:
    issue = [("issue 39 flip", RAW[:ISSUE_39_FLIP[0]] + bytes([RAW[ISSUE_39_FLIP[0]] ^ 4]) +
              RAW[ISSUE_39_FLIP[0] + 1:])]
    issue += [(f"CA_ROTOR_COUNT {v}", patch_parameter(RAW, "CA_ROTOR_COUNT", v)) for v in (13, 2**31 - 1, -1)]
    codes = check_cli(iter(issue + list(cli_cases(30, SEED + 2))), tmp_path)
    assert codes[2] >= 4 + 5


@pytest.mark.slow
def test_cli_many_mutants(tmp_path: Path) -> None:
    codes = check_cli(cli_cases(300, SEED + 3), tmp_path)
    print(dict(codes))
    assert codes[0] >= 20 and codes[2] >= 50


# ------------------------------------------------------------------ issue 39's samples, by name
def read(raw: bytes, tmp_path: Path) -> Any:
    path = tmp_path / "case.ulg"
    path.write_bytes(raw)
    return within(DEADLINE, lambda: read_ulog(path))


def test_pyulog_alone_loops_on_the_issue_39_flip() -> None:
    """Why the scan exists: pyulog's definitions reader, given the flip, never ends (its file
    position cycles: the seek back after a short read lands before the header it came from)."""
    import io

    from pyulog import ULog

    class Counting(io.BytesIO):
        reads = 0

        def read(self, n: int = -1) -> bytes:  # type: ignore[override]
            Counting.reads += 1
            if Counting.reads > 200_000:  # the unmutated log takes ~6,000
                raise RuntimeError("looping")
            return super().read(n)

    at, bit = ISSUE_39_FLIP
    flipped = RAW[:at] + bytes([RAW[at] ^ 1 << bit]) + RAW[at + 1:]
    with pytest.raises(RuntimeError, match="looping"):
        ULog(Counting(flipped), ["actuator_motors"])


def test_issue_39_flip_is_refused_at_once(tmp_path: Path) -> None:
    at, bit = ISSUE_39_FLIP
    start = time.perf_counter()
    with pytest.raises(ProblemError, match=r"^ulog: byte \d+: .* \(a damaged or non-PX4 log\)$") as info:
        read(RAW[:at] + bytes([RAW[at] ^ 1 << bit]) + RAW[at + 1:], tmp_path)
    assert info.value.field == "ulog" and time.perf_counter() - start < 1.0


@pytest.mark.parametrize("value", [13, 2**31 - 1, 255])
def test_rotor_count_beyond_the_logged_controls(tmp_path: Path, value: int) -> None:
    with pytest.raises(ProblemError, match=r"^CA_ROTOR_COUNT: expected an integer 1\.\.12 .* got "
                                           rf"{value} \(actuator_motors\.control\[12\]: missing\)") as info:
        read(patch_parameter(RAW, "CA_ROTOR_COUNT", value), tmp_path)
    assert info.value.field == "CA_ROTOR_COUNT"


@pytest.mark.parametrize("value", [-1, 0, -(2**31), math.nan, 2.5, math.inf])
def test_rotor_count_negative_zero_or_not_an_integer(tmp_path: Path, value: Any) -> None:
    with pytest.raises(ProblemError, match=r"^CA_ROTOR_COUNT: expected an integer 1\.\.12"):
        read(patch_parameter(RAW, "CA_ROTOR_COUNT", value), tmp_path)


def test_rotor_count_missing(tmp_path: Path) -> None:
    at, _, _ = PARAMS["CA_ROTOR_COUNT"]
    raw = RAW.replace(b"int32_t CA_ROTOR_COUNT", b"int32_t CA_ROTOR_COUNX", 1)
    assert raw != RAW and at
    with pytest.raises(ProblemError, match="^CA_ROTOR_COUNT: missing from the log's parameters"):
        read(raw, tmp_path)


def test_fewer_rotors_than_logged_replay_on_those_rotors(tmp_path: Path) -> None:
    log = read(patch_parameter(RAW, "CA_ROTOR_COUNT", 2), tmp_path)
    assert log.motors.shape == (140, 2)
    assert_valid_replay(log, "CA_ROTOR_COUNT 2")


@pytest.mark.parametrize(("topic", "old", "new", "field"), [
    # (pyulog takes data messages of exactly the format's size: fields renamed, not removed)
    ("actuator_motors", b"float[12] control", b"float[12] contrpl", "actuator_motors.control[0]: missing"),
    ("actuator_motors", b"float[12] control", b"float[3] control;float[9] other",
     "CA_ROTOR_COUNT: expected an integer 1..3 (the actuator_motors.control fields of the log), got 4 "
     "(actuator_motors.control[3]: missing)"),
    ("vehicle_torque_setpoint", b"float[3] xyz", b"float[3] xyw", "vehicle_torque_setpoint.xyz[0]: missing"),
    ("vehicle_thrust_setpoint", b"float[3] xyz", b"float[2] xyz;float xyq", "vehicle_thrust_setpoint.xyz[2]: missing"),
    ("actuator_motors", b"timestamp_sample", b"timestamp_sbmple", "actuator_motors.timestamp_sample: missing"),
    ("vehicle_torque_setpoint", b"uint64_t timestamp_sample", b"double timestamp_sample",
     "vehicle_torque_setpoint.timestamp_sample: expected integer microseconds, got float64"),
])
def test_missing_or_retyped_fields_are_named(tmp_path: Path, topic: str, old: bytes, new: bytes, field: str) -> None:
    raw = rename_in_format(RAW, topic, old, new)
    with pytest.raises(ProblemError) as info:
        read(raw, tmp_path)
    assert str(info.value) == field


def test_missing_topic_is_named(tmp_path: Path) -> None:
    raw = RAW.replace(b"vehicle_thrust_setpoint", b"vehicle_thrust_setpoinz")  # its format and subscription
    with pytest.raises(ProblemError, match="^ulog: .* has no vehicle_thrust_setpoint"):
        read(raw, tmp_path)


def test_decreasing_sample_times_are_named(tmp_path: Path) -> None:
    raw = bytearray(RAW)
    torque, thrust = data_offsets(RAW, "vehicle_torque_setpoint"), data_offsets(RAW, "vehicle_thrust_setpoint")
    for at in (torque[10], thrust[10]):  # both, so that they are still sampled together
        struct.pack_into("<Q", raw, at + SAMPLE_AT, 5)
    with pytest.raises(ProblemError, match=r"^vehicle_torque_setpoint\.timestamp_sample: does not increase at "
                                           r"sample 10 \(\d+ then 5\)"):
        read(bytes(raw), tmp_path)
    motors = data_offsets(RAW, "actuator_motors")
    raw = bytearray(RAW)
    raw[motors[7] + SAMPLE_AT:motors[7] + SAMPLE_AT + 8] = RAW[motors[5] + SAMPLE_AT:motors[5] + SAMPLE_AT + 8]
    with pytest.raises(ProblemError, match=r"^actuator_motors\.timestamp_sample: does not increase at sample 7"):
        read(bytes(raw), tmp_path)


def test_non_finite_setpoints_are_named_and_nan_commands_unpaired(tmp_path: Path) -> None:
    torque = data_offsets(RAW, "vehicle_torque_setpoint")
    motors = data_offsets(RAW, "actuator_motors")
    sample = RAW[motors[3] + SAMPLE_AT:motors[3] + SAMPLE_AT + 8]
    at = next(o for o in torque if RAW[o + SAMPLE_AT:o + SAMPLE_AT + 8] == sample)
    raw = RAW[:at + VALUES_AT + 4] + struct.pack("<f", math.inf) + RAW[at + VALUES_AT + 8:]
    with pytest.raises(ProblemError, match=r"^vehicle_torque_setpoint\.xyz\[1\]: not finite at paired sample 3"):
        read(raw, tmp_path)
    # PX4 commands NaN for a stopped motor: that sample is not paired, the rest replays
    raw = RAW[:motors[3] + VALUES_AT] + struct.pack("<f", math.nan) + RAW[motors[3] + VALUES_AT + 4:]
    log = read(raw, tmp_path)
    assert log.t.size == 139
    assert_valid_replay(log, "a NaN command")


def test_a_cut_log_replays_what_it_holds(tmp_path: Path) -> None:
    log = read(RAW[:130_000], tmp_path)
    assert 0 < log.t.size < 140
    assert_valid_replay(log, "a cut log")


# ------------------------------------------------------------------ the scan's bounds
def definitions_end(raw: bytes) -> int:
    return next(o for o, s, k in messages(raw) if k == ord("A"))


def insert_definition(raw: bytes, payload: bytes, kind: bytes = b"F") -> bytes:
    at = definitions_end(raw)
    return raw[:at] + struct.pack("<HB", len(payload), kind[0]) + payload + raw[at:]


def subscribe(raw: bytes, name: bytes, msg_id: int = 900) -> bytes:
    at = definitions_end(raw)
    payload = struct.pack("<BH", 0, msg_id) + name
    return raw[:at] + struct.pack("<HB", len(payload), ord("A")) + payload + raw[at:]


@pytest.mark.parametrize(("formats", "message"), [
    ([b"loop:uint64_t timestamp;loop[2] again;"], "format 'loop' contains itself"),
    ([b"a:uint64_t timestamp;b[300] x;", b"b:c[300] y;", b"c:float z;"], "flattens to 360008 bytes"),
    ([b"a:uint8_t[70000] x;"], "an array of 70000 elements"),
    ([b"a:uint8_t[-1] x;"], "an array of -1 elements"),
    ([b"a:uint8_t timestamp;float x;"], "its format has no 64-bit timestamp"),
    ([b"a:float x;"], "its format has no 64-bit timestamp"),
])
def test_formats_pyulog_would_expand_without_end_are_refused(tmp_path: Path, formats: list[bytes],
                                                             message: str) -> None:
    raw = RAW
    for f in formats:
        raw = insert_definition(raw, f)
    raw = subscribe(raw, b"a" if formats[0].startswith(b"a:") else b"loop")
    with pytest.raises(ProblemError, match=r"^ulog: byte \d+: .*" + message.replace("[", r"\[")):
        read(raw, tmp_path)


def test_deep_nesting_is_refused(tmp_path: Path) -> None:
    raw = insert_definition(RAW, b"n0:uint64_t timestamp;n1 x;")
    for i in range(1, 40):
        raw = insert_definition(raw, b"n%d:n%d x;" % (i, i + 1))
    raw = subscribe(insert_definition(raw, b"n40:float y;"), b"n0")
    with pytest.raises(ProblemError, match=r"formats nest more than 32 deep"):
        read(raw, tmp_path)


def test_counts_beyond_the_bounds_are_refused(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(_ulog_scan, "MAX_LOG_MESSAGES", 2000)
    with pytest.raises(ProblemError, match=r"^ulog: byte \d+: more than 2000 messages"):
        read(RAW, tmp_path)
    monkeypatch.setattr(_ulog_scan, "MAX_LOG_MESSAGES", 2**23)
    monkeypatch.setattr(_ulog_scan, "MAX_LOG_RECORDS", 10)
    with pytest.raises(ProblemError, match=r"more than 10 log, parameter, info, dropout or subscription"):
        read(RAW, tmp_path)
    monkeypatch.setattr(_ulog_scan, "MAX_LOG_RECORDS", 2**18)
    monkeypatch.setattr(_ulog_scan, "MAX_SUBSCRIBED_FIELDS", 100)
    with pytest.raises(ProblemError, match=r"subscriptions of more than 100 fields"):
        read(RAW, tmp_path)


def test_messages_pyulog_would_leave_its_walk_on_are_refused(tmp_path: Path) -> None:
    end = [o for o, s, k in messages(RAW)][-1]  # a message boundary
    cases = {
        "unknown message type 0x7a": RAW[:end] + struct.pack("<HB", 1, ord("z")) + b"x" + RAW[end:],
        "a 'R' message of 12 bytes in the data section": RAW[:end] + struct.pack("<HB", 12, ord("R")) +
        b"ab" + _ulog_scan.SYNC + b"cd" + RAW[end:],
        "a 'O' message of 3 bytes that cannot be read": RAW + struct.pack("<HB", 3, ord("O")) + b"abc",
        "a 'P' message of 15 bytes that cannot be read": RAW + struct.pack("<HB", 15, ord("P")) +
        bytes([9]) + b"float abc" + b"vwxyz",  # a 5-byte float: pyulog's struct.error ends its read
        "a 'D' message of 0 bytes in the definitions": insert_definition(RAW, b"", b"D"),
        "a flag-bits message that is not the first message": insert_definition(RAW, bytes(40), b"B"),
    }
    for message, raw in cases.items():
        with pytest.raises(ProblemError, match=r"^ulog: byte \d+: " + message.replace("'", "'")):
            read(raw, tmp_path)
    # a P message of the right size in the data section is read (a changed parameter)
    fine = RAW + struct.pack("<HB", 14, ord("P")) + bytes([9]) + b"float abc" + struct.pack("<f", 1.0)
    assert read(fine, tmp_path).t.size == 140


def test_appended_offsets_must_be_later_message_boundaries(tmp_path: Path) -> None:
    assert RAW[16 + 2] == ord("B")
    flags = bytearray(RAW)
    flags[16 + 3 + 8] |= 1  # incompat flag DATA_APPENDED
    boundaries = [o for o, s, k in messages(RAW)]
    early, late = boundaries[-100], boundaries[-10]
    for offsets, refused in (([0, late, 0], 0), ([early + 1, 0, 0], early + 1), ([20, 0, 0], 20),
                             ([late, early, 0], early), ([early, late, len(RAW) + 8], len(RAW) + 8),
                             ([early, late, 0], None), ([0, 0, 0], None)):
        raw = bytearray(flags)
        struct.pack_into("<3Q", raw, 16 + 3 + 16, *offsets)
        if refused is not None:
            with pytest.raises(ProblemError, match=rf"appended-data offset {refused} is not a later message"):
                read(bytes(raw), tmp_path)
        elif offsets[0]:  # the scan passes; pyulog forgets its subscriptions at each offset (1.3.0)
            assert _ulog_scan.scan_ulog(bytes(raw)).messages == len(boundaries)
            with pytest.raises(ProblemError, match="has messages pyulog cannot parse"):
                read(bytes(raw), tmp_path)
        else:
            assert read(bytes(raw), tmp_path).t.size == 140


def test_the_scan_costs_less_than_pyulog_on_the_bundled_log() -> None:
    """The bound's price, measured: the scan walks the 2,853 messages in a few ms."""
    import io

    from pyulog import ULog

    def best(work: Callable[[], Any]) -> float:
        times = []
        for _ in range(5):
            start = time.perf_counter()
            work()
            times.append(time.perf_counter() - start)
        return min(times)

    scan = best(lambda: _ulog_scan.scan_ulog(RAW))
    parse = best(lambda: ULog(io.BytesIO(RAW), ["vehicle_torque_setpoint", "vehicle_thrust_setpoint",
                                                "actuator_motors"]))
    print(f"scan {1000 * scan:.1f} ms, pyulog {1000 * parse:.1f} ms")
    assert _ulog_scan.scan_ulog(RAW).messages == 2853
    assert scan < 2 * parse + 0.005

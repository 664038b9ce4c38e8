"""Seeded hostile importer files: PX4 airframes and parameter files, ArduPilot parameter files and factor tables,
each mutated (garbage lines, huge numbers, NaN, duplicated parameters, missing motors or cells, unknown frame
classes, cut lines, stray bytes).  Every file either loads to a finite vehicle or is refused with an
AllocError whose message names the field or the line; where the mutation's line is known the message
must name that line.  Through ``alloc allocate --vehicle`` a refusal is exit 2 and one stderr line.
"""

from __future__ import annotations

import re
import warnings
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

import alloc
from alloc.cli import app
from alloc.exceptions import AllocError, SkippedLinesWarning
from alloc.importers.px4 import reads_parameter

DATA = Path(__file__).parent / "data" / "px4_airframes"
SEEDS = range(180)
BAD_NUMBERS = ["nan", "inf", "-inf", "1e400", "abc", "0x1G", "1" * 400, "${VALUE}", "1,5"]
#: what every refusal starts with: a field (a parameter name, factors, path) or a line
FIELD_OR_LINE = re.compile(r"^(params: line \d+: |factors: |path: |[A-Z][A-Z0-9_]{1,15}: )")

QGC = "".join(f"1\t1\t{name}\t{value}\t{kind}\n" for name, value, kind in [
    ("CA_AIRFRAME", 0, 6), ("CA_ROTOR_COUNT", 4, 6), ("CA_ROTOR0_PX", 0.15, 9), ("CA_ROTOR0_PY", 0.15, 9),
    ("CA_ROTOR1_PX", -0.15, 9), ("CA_ROTOR1_PY", -0.15, 9), ("CA_ROTOR2_PX", 0.15, 9), ("CA_ROTOR2_PY", -0.15, 9),
    ("CA_ROTOR2_KM", -0.05, 9), ("CA_ROTOR3_PX", -0.15, 9), ("CA_ROTOR3_PY", 0.15, 9), ("CA_ROTOR3_KM", -0.05, 9)])
ARDUPILOT = "# ArduCopter\nFRAME_CLASS,4\nFRAME_TYPE,1\nMOT_SLEW_UP_TIME,0.1\nMOT_SLEW_DN_TIME,0.1\n"
CSV = "motor,roll,pitch,yaw,throttle\n" + "".join(
    f"m{i + 1},{r},{p},{y},1\n" for i, (r, p, y) in enumerate([(-0.5, 0.5, 0.5), (0.5, 0.5, -0.5), (0.5, -0.5, 0.5),
                                                                (-0.5, -0.5, -0.5), (0.5, 0.5, 0.5), (-0.5, 0.5, -0.5),
                                                                (-0.5, -0.5, 0.5), (0.5, -0.5, -0.5)]))


def originals() -> dict[str, tuple[str, str]]:
    """kind -> (file name, text) of the files the mutations start from."""
    return {"airframe": ("13000_hostile", (DATA / "1103_standard_vtol_sih.hil").read_text()),
            "hexa": ("6001_hostile", (DATA / "6001_hexa_x").read_text()),
            "tiltrotor": ("13100_hostile", (DATA / "13100_generic_vtol_tiltrotor").read_text()),
            "params": ("hostile.params", QGC), "ardupilot": ("hostile.param", ARDUPILOT),
            "csv": ("hostile.csv", CSV)}


def value_lines(kind: str, lines: list[str]) -> list[int]:
    """Indices of the lines that set a value (the ones a mutation of a value targets)."""
    if kind in ("airframe", "hexa", "tiltrotor"):
        return [i for i, line in enumerate(lines) if line.startswith("param set")]
    if kind == "csv":
        return list(range(1, len(lines)))
    return [i for i, line in enumerate(lines) if line and not line.startswith("#")]


def mutate(seed: int) -> tuple[str, str, str, str | None]:
    """``(kind, file name, text, expected)``: ``expected`` a regex the refusal must match (None: load or refuse)."""
    rng = np.random.default_rng(seed)
    kinds = list(originals())
    kind = kinds[seed % len(kinds)]
    name, text = originals()[kind]
    lines = text.splitlines()
    targets = value_lines(kind, lines)
    i = int(rng.choice(targets))
    op = ["bad_number", "duplicate", "garbage", "huge", "drop", "cut", "bytes", "frame"][int(rng.integers(8))]
    expected: str | None = None
    if op == "bad_number":
        bad = str(rng.choice(BAD_NUMBERS))
        if kind == "csv":
            cells = lines[i].split(",")
            cells[int(rng.integers(1, 5))] = bad
            lines[i] = ",".join(cells)
            expected = rf"^factors: row {i + 1}: " if "," not in bad else None  # '1,5' shifts the cells
        else:
            words = re.split(r"(\s+|,)", lines[i])
            value_at = 2 if kind == "ardupilot" else len(words) - 1 - (2 if kind == "params" else 0)
            words[value_at] = bad
            lines[i] = "".join(words)
            expected = None if "," in bad else rf"^params: line {i + 1}: "
    elif op == "duplicate":
        j = int(rng.integers(i + 1, len(lines) + 1))
        lines.insert(j, lines[i])
        name_of = re.split(r"[\s,]+", lines[i].strip())
        read = kind == "ardupilot" or reads_parameter(name_of[2] if len(name_of) > 2 else "")
        expected = (rf"^factors: row {j + 1}: motor '\S+' is named twice \(first at row {i + 1}\)" if kind == "csv"
                    else rf"^params: line {j + 1}: \S+ is set again \(first at line {i + 1}\)" if read
                    else None)  # a parameter the PX4 importer does not read: the last one kept, as PX4's shell
    elif op == "garbage":
        j = int(rng.integers(1, len(lines) + 1))
        lines.insert(j, "".join(chr(int(c)) for c in rng.integers(33, 127, size=int(rng.integers(1, 30)))))
    elif op == "huge":
        big = f"{float(rng.choice([1e30, 1e49, 9e49, 1e51, -1e300])):g}"
        if kind == "csv":
            cells = lines[i].split(",")
            cells[int(rng.integers(1, 5))] = big
            lines[i] = ",".join(cells)
        else:
            lines[i] = re.sub(r"(-?[\d.]+(e[+-]?\d+)?)(\s+\d+)?$" if kind == "params" else r"(\S+)$",
                              lambda m: big + (m.group(3) or "") if kind == "params" else big, lines[i])
    elif op == "drop":  # missing motors, parameters or cells
        for j in sorted(rng.choice(targets, size=min(len(targets), int(rng.integers(1, 4))), replace=False))[::-1]:
            if kind == "csv" and rng.random() < 0.5:
                lines[j] = ",".join(lines[j].split(",")[:int(rng.integers(1, 4))])  # a row missing cells
            else:
                del lines[j]
    elif op == "cut":
        text = "\n".join(lines)
        return kind, name, text[:int(rng.integers(0, len(text)))], None
    elif op == "bytes":
        raw = bytearray("\n".join(lines).encode())
        for _ in range(int(rng.integers(1, 5))):
            raw[int(rng.integers(len(raw)))] = int(rng.integers(0, 256))
        return kind, name, raw.decode("latin-1"), None
    elif op == "frame":
        if kind == "ardupilot":
            cls = int(rng.choice([0, 6, 7, 13, 99, -1]))
            lines[1] = f"FRAME_CLASS,{cls}"
            expected = rf"^FRAME_CLASS: {cls} is not supported"
        elif kind in ("airframe", "hexa", "tiltrotor", "params"):
            count = int(rng.choice([13, 99, -1]))
            key = "CA_ROTOR_COUNT"
            lines = [line for line in lines if key not in line]
            lines.insert(1, f"param set-default {key} {count}" if kind != "params" else f"1\t1\t{key}\t{count}\t6")
            expected = rf"^{key}: expected an integer 0..12"
    return kind, name, "\n".join(lines) + "\n", expected


def load(path: Path) -> alloc.vehicle_file.Vehicle:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SkippedLinesWarning)
        return alloc.load_vehicle(path)


@pytest.mark.parametrize("seed", SEEDS)
def test_hostile_file_loads_or_is_refused_by_field(seed, tmp_path):
    kind, name, text, expected = mutate(seed)
    path = tmp_path / name
    path.write_bytes(text.encode("utf-8", "surrogateescape") if isinstance(text, str) else text)
    try:
        v = load(path)
    except AllocError as exc:
        message = str(exc)
        assert "\n" not in message and len(message) < 600, message
        assert FIELD_OR_LINE.match(message), (kind, message)
        if expected is not None:
            assert re.match(expected, message), (kind, expected, message)
        return
    assert expected is None, (kind, expected, "loaded")
    B = v.problem().B
    assert np.isfinite(B).all() and (np.abs(B) <= 1e50).all()


def test_the_generator_reaches_every_outcome():
    """The seeds above cover refusals naming a line, refusals naming a field, and files that still load."""
    outcomes = set()
    for seed in SEEDS:
        kind, name, text, expected = mutate(seed)
        outcomes.add((kind, expected is not None))
    assert {k for k, _ in outcomes} == set(originals())
    assert any(e for _, e in outcomes) and any(not e for _, e in outcomes)


@pytest.mark.parametrize("seed", [s for s in SEEDS if mutate(s)[3] is not None][:12])
def test_cli_refuses_a_hostile_vehicle_in_one_line(seed, tmp_path):
    kind, name, text, expected = mutate(seed)
    path = tmp_path / name
    path.write_text(text)
    v = ",".join(["0"] * (5 if kind == "airframe" else 4))
    res = CliRunner().invoke(app, ["allocate", "--vehicle", str(path), "--v", v])
    lines = [line for line in res.stderr.splitlines() if line.strip()]
    assert res.exit_code == 2, (res.stdout, res.stderr)
    assert len(lines) == 1 and "--vehicle" in lines[0] and "Traceback" not in res.stderr, res.stderr
    assert re.search(expected.lstrip("^"), lines[0]), (expected, lines[0])


@pytest.mark.parametrize("name", ["x" * 5000, "x" * 5000 + ".csv", "x" * 5000 + ".params", "a\x00b", "a\x00b.param"])
def test_names_no_file_system_takes_are_refused_by_field(name):
    """A name too long for the file system, or with a NUL byte: a refusal naming path or vehicle, no OSError."""
    from alloc.importers.px4 import read_params
    from alloc.vehicles import get_vehicle

    for call in (alloc.load_vehicle, get_vehicle):
        with pytest.raises(AllocError) as info:
            call(name)
        assert info.value.field in ("path", "vehicle"), str(info.value)
    if "\n" not in name and name.endswith(".params"):
        with pytest.raises(AllocError, match="^path: "):
            read_params(name)

"""``POST /v1/vehicles`` with a flight stack's file (ArduPilot factor tables and parameter files, PX4
``.params`` and airframe files): the service stores the vehicle ``alloc.load_vehicle`` reads from the same
file, bit for bit, and allocates as the library and ``alloc allocate --vehicle FILE`` do; hostile bodies
get 4xx problem+json, never 5xx."""

from __future__ import annotations

import json
import random
import warnings
from pathlib import Path

import numpy as np
import pytest
from fastapi.testclient import TestClient
from typer.testing import CliRunner

import alloc
from alloc.cli import app as cli
from alloc.exceptions import SkippedLinesWarning
from alloc.importers.ardupilot import frame_factors
from alloc.importers.ardupilot_frames import FRAME_TYPES, TABLES, frame_name
from alloc.importers.px4 import read_params
from alloc.vehicle_file import load_vehicle
from service.config import Settings
from service.main import create_app

AIRFRAMES = sorted((Path(__file__).parents[1] / "alloc" / "data" / "px4_airframes").glob("[0-9]*"))
PLAIN = {"content-type": "text/plain"}
CSV = {"content-type": "text/csv"}
PROBLEM_JSON = "application/problem+json"


@pytest.fixture(scope="module")
def client(tmp_path_factory):
    app = create_app(Settings(data_dir=tmp_path_factory.mktemp("vehicle-import")))
    with TestClient(app) as c:
        yield c


def exact(x) -> str:
    """A JSON text whose equality is bit-for-bit equality of every float."""
    return json.dumps(x, sort_keys=True, allow_nan=False)


def library(path: Path):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SkippedLinesWarning)
        return load_vehicle(path)


def qgc_params(airframe: Path) -> str:
    """A QGroundControl ``.params`` file with the parameters of a PX4 airframe file (type 6 for
    integers, 9 for floats, written with ``repr``: read back bit for bit)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SkippedLinesWarning)
        params = read_params(airframe)
    lines = ["# Onboard parameters for Vehicle 1", "#", "# Vehicle-Id Component-Id Name Value Type"]
    lines += [f"1\t1\t{name}\t{value!r}\t{6 if isinstance(value, int) else 9}" for name, value in params.items()]
    return "\n".join(lines) + "\n"


def factor_csv(frame: str) -> str:
    rows = [f"m{i + 1},{','.join(repr(float(x)) for x in row)}" for i, row in enumerate(frame_factors(frame))]
    return "motor,roll,pitch,yaw,throttle\n" + "\n".join(rows) + "\n"


def flight_stack_files(folder: Path) -> list[tuple[Path, str]]:
    """Every kind of file, written to ``folder``: ``(path, import format)``."""
    files = [(path, "px4-airframe") for path in AIRFRAMES]
    for path in AIRFRAMES:
        files.append((folder / f"{path.name.split('.')[0]}.params", "px4-params"))
        files[-1][0].write_text(qgc_params(path))
    for frame_class, frame_type in TABLES:
        name = frame_name(frame_class, frame_type)
        param = folder / f"{name}.param"
        param.write_text(f"# Mission Planner\nFRAME_CLASS,{frame_class}\nFRAME_TYPE,{frame_type}\n"
                         "MOT_SLEW_UP_TIME,0.25\nMOT_SLEW_DN_TIME,0\n")
        files.append((param, "ardupilot-params"))
        table = folder / f"{name}.csv"
        table.write_text(factor_csv(name))
        files.append((table, "ardupilot-csv"))
    parm = folder / "hexa.parm"
    parm.write_text(f"FRAME_CLASS 2\nFRAME_TYPE\t{next(t for t, n in FRAME_TYPES.items() if n == 'x')}\n")
    files.append((parm, "ardupilot-params"))
    return files


def post_file(client, path: Path, form: str, **query: str):
    headers = CSV if form == "ardupilot-csv" else PLAIN
    params = {"name": path.stem, **query} if form == "ardupilot-csv" else {"import": form, "name": path.stem, **query}
    return client.post("/v1/vehicles", content=path.read_bytes(), headers=headers, params=params)


def demand(k: int, seed: int) -> list[float]:
    return np.random.default_rng(seed).uniform(-0.3, 0.3, k).tolist()


def test_every_format_gives_the_librarys_vehicle_and_answers(client, tmp_path):
    files = flight_stack_files(tmp_path)
    assert {form for _, form in files} == {"px4-airframe", "px4-params", "ardupilot-params", "ardupilot-csv"}
    for i, (path, form) in enumerate(files):
        vehicle = library(path)
        problem = vehicle.problem()
        response = post_file(client, path, form)
        assert response.status_code == 201, (path.name, response.text[:300])
        out = response.json()
        assert out["name"] == vehicle.name
        assert exact(out["problem"]) == exact(problem.to_dict()), path.name  # B, limits, rates, names: bit for bit
        document = client.get(f"/v1/vehicles/{out['id']}/document").json()
        expected = vehicle.to_dict()
        # the label of the skipped lines is the file's name in the library, "the body" in the service
        assert document.pop("source").replace("the body", path.name) == expected.pop("source"), path.name
        assert exact(document) == exact(expected), path.name  # the schedule too (the tiltrotor's)
        v = demand(problem.k, i)
        for method in ("pinv", "qp"):
            answer = client.post(f"/v1/vehicles/{out['id']}/allocate", json={"v": v, "method": method})
            assert answer.status_code == 200, answer.text[:300]
            want = alloc.make_allocator(problem, method)(v)
            assert answer.json()["u"] == want.u.tolist() and answer.json()["status"] == want.status.value, \
                (path.name, method)


@pytest.mark.parametrize("index", [0, 3, 5, 9])
def test_the_service_answers_as_the_cli_reads_the_file(client, tmp_path, index):
    path, form = flight_stack_files(tmp_path)[index]
    out = post_file(client, path, form).json()
    v = demand(len(out["problem"]["B"]), index)
    run = CliRunner().invoke(cli, ["allocate", "--vehicle", str(path), "--v", ",".join(map(repr, v)), "--method",
                                   "qp", "--json", "--repeat", "1"])
    assert run.exit_code == 0, run.output
    answer = client.post(f"/v1/vehicles/{out['id']}/allocate", json={"v": v, "method": "qp"}).json()
    cli_out = json.loads(run.stdout[run.stdout.index("{"):])
    assert answer["u"] == cli_out["u"] and answer["status"] == cli_out["status"]


def test_skipped_shell_lines_are_reported_in_source(client):
    path = next(p for p in AIRFRAMES if p.name == "13100_generic_vtol_tiltrotor")
    out = client.post("/v1/vehicles", content=path.read_bytes(), headers=PLAIN, params={"import": "px4-airframe"})
    assert out.status_code == 201 and out.json()["name"] == "px4"  # the importer's default name
    source = client.get(f"/v1/vehicles/{out.json()['id']}/document").json()["source"]
    assert "PX4 airframe file the body: 1 shell line(s) skipped (line 12: '. ${R}etc/init.d/rc.vtol_defaults')" \
        in source


@pytest.mark.parametrize("headers, params, status, where, text", [
    (PLAIN, {}, 422, ["query", "import"], "required for a text/plain body: one of ardupilot-csv, ardupilot-params"),
    (PLAIN, {"import": "mavlink"}, 422, ["query", "import"], "'ardupilot-csv', 'ardupilot-params'"),
    (CSV, {"import": "px4-params"}, 422, ["query", "import"], "a text/csv body is an ArduPilot factor table"),
    ({"content-type": "application/toml"}, {"import": "px4-params"}, 422, ["query", "import"],
     "applies to a flight stack's file sent as text/csv or text/plain"),
    ({"content-type": "application/toml"}, {"name": "x"}, 422, ["query", "name"], "applies to an imported file"),
    ({"content-type": "text/plain; charset=latin-1"}, {"import": "px4-params"}, 415, ["header", "content-type"],
     "charset 'latin-1'"),
    ({"content-type": "application/octet-stream"}, {}, 415, ["header", "content-type"],
     ("as text/csv (an ArduPilot factor table) or as text/plain with ?import=ardupilot-params, px4-params or "
      "px4-airframe")),
    (PLAIN, {"import": "ardupilot-params", "name": "a\x01b"}, 422, ["query", "name"], "String should match"),
])
def test_the_query_must_fit_the_body(client, headers, params, status, where, text):
    response = client.post("/v1/vehicles", content=b"FRAME_CLASS,1\n", headers=headers, params=params)
    assert response.status_code == status, response.text
    assert response.headers["content-type"] == PROBLEM_JSON
    problem = response.json()
    assert problem["errors"][0]["loc"] == where and text in problem["detail"], problem


@pytest.mark.parametrize("form, body, detail, loc", [
    ("ardupilot-params", b"FRAME_CLASS,1\nFRAME_CLASS,2\n",
     "ardupilot-params: params: line 2: FRAME_CLASS is set again (first at line 1)", ["body", "params"]),
    ("ardupilot-params", b"FRAME_CLASS,7\n", "ardupilot-params: FRAME_CLASS: 7 is not supported",
     ["body", "FRAME_CLASS"]),
    ("ardupilot-csv", b"motor,roll,pitch,yaw\nm1,1,nan,0\n", "ardupilot-csv: factors: row 2: pitch: must be finite",
     ["body", "factors"]),
    ("px4-params", b"1\t1\tCA_ROTOR_COUNT\tinf\t6\n", "px4-params: params: line 1: CA_ROTOR_COUNT", ["body", "params"]),
    ("px4-airframe", b"1\t1\tCA_ROTOR_COUNT\t4\t6\n", "px4-airframe: params: the body is not a PX4 airframe file",
     ["body", "params"]),
    ("px4-params", b"\xff\xfe", "the body is not UTF-8 text (invalid start byte at byte 0)", ["body"]),
    ("px4-params", b"#" * (2**20 + 1), "the body is 1,048,577 bytes, more than the 1,048,576", ["body"]),
])
def test_refusals_name_the_line_or_parameter(client, form, body, detail, loc):
    headers = CSV if form == "ardupilot-csv" else PLAIN
    response = client.post("/v1/vehicles", content=body, headers=headers, params={"import": form})
    assert response.status_code == 422, response.text[:300]
    problem = response.json()
    assert problem["type"] in ("urn:alloc:problem:invalid-vehicle-import",) and problem["detail"].startswith(detail), \
        problem["detail"]
    assert problem["errors"][0]["loc"] == loc


def test_a_retried_import_is_created_once(client):
    body, key = b"FRAME_CLASS,2\nFRAME_TYPE,1\n", {"Idempotency-Key": "import-hexa-1"}
    params = {"import": "ardupilot-params"}
    first = client.post("/v1/vehicles", content=body, headers={**PLAIN, **key}, params=params)
    again = client.post("/v1/vehicles", content=body, headers={**PLAIN, **key}, params=params)
    assert first.status_code == again.status_code == 201 and first.json()["id"] == again.json()["id"]
    assert again.headers["Idempotent-Replayed"] == "true"
    other = client.post("/v1/vehicles", content=body, headers={**PLAIN, **key}, params={**params, "name": "other"})
    assert other.status_code == 409  # the name is part of the request


def test_openapi_lists_the_media_types_and_the_query(client):
    post = client.get("/openapi.json").json()["paths"]["/v1/vehicles"]["post"]
    assert {"application/json", "application/toml", "text/csv", "text/plain"} <= set(post["requestBody"]["content"])
    assert {p["name"] for p in post["parameters"]} >= {"import", "name"}
    assert "415" in post["responses"]


# ------------------------------------------------------------------ hostile bodies
def _hostile_bodies(seed: int, count: int, folder: Path) -> list[tuple[str, bytes, str]]:
    """``(content type, body, import format)``: valid files truncated, mutated (numbers replaced by
    NaN, infinities, huge or non-numeric text, lines duplicated or deleted), sent as another
    format, binary noise, and bodies just over the cap."""
    rng = random.Random(seed)
    files = [(path.read_bytes(), form) for path, form in flight_stack_files(folder)]
    forms = ["ardupilot-csv", "ardupilot-params", "px4-params", "px4-airframe"]
    bad_numbers = [b"nan", b"NaN", b"inf", b"-inf", b"1e400", b"1e51", b"0x10", b"", b"1,5", b"\x00", b"\xff",
                   b"9" * 400, b"-0", b"1e-400"]
    out = []
    for _ in range(count):
        body, form = rng.choice(files)
        kind = rng.randrange(7)
        if kind == 0:
            body = body[:rng.randrange(len(body))]
        elif kind == 1:
            lines = body.split(b"\n")
            i = rng.randrange(len(lines))
            words = lines[i].replace(b"\t", b",").split(b",")
            words[rng.randrange(len(words))] = rng.choice(bad_numbers)
            lines[i] = (b"\t" if b"\t" in lines[i] else b",").join(words)
            body = b"\n".join(lines)
        elif kind == 2:
            lines = body.split(b"\n")
            i = rng.randrange(len(lines))
            lines.insert(i, lines[i]) if rng.random() < 0.5 else lines.pop(i)
            body = b"\n".join(lines)
        elif kind == 3:
            form = rng.choice([f for f in forms if f != form])
        elif kind == 4:
            body = bytes(rng.randrange(256) for _ in range(rng.randrange(1, 600)))
        elif kind == 5:
            body = (body * (2**20 // max(len(body), 1) + 2))[:2**20 + rng.randrange(1, 64)]
        else:
            body = body.replace(b"\n", rng.choice([b"\r\n", b"\r", b"\x00", b"\n\n\n", b"\x85", "\u2028".encode()]))
        content_type = "text/csv" if form == "ardupilot-csv" else "text/plain"
        out.append((content_type, body, form))
    return out


def test_seeded_hostile_bodies_get_4xx_never_5xx(client, tmp_path):
    statuses: dict[int, int] = {}
    for content_type, body, form in _hostile_bodies(20261206, 300, tmp_path):
        params = {} if form == "ardupilot-csv" else {"import": form}
        response = client.post("/v1/vehicles", content=body, headers={"content-type": content_type}, params=params)
        statuses[response.status_code] = statuses.get(response.status_code, 0) + 1
        assert response.status_code in (201, 413, 415, 422), (response.status_code, form, body[:200],
                                                              response.text[:300])
        if response.status_code != 201:
            assert response.headers["content-type"] == PROBLEM_JSON and response.json()["detail"]
        else:  # accepted: then the stored vehicle is one the library reads
            vehicle_id = response.json()["id"]
            document = client.get(f"/v1/vehicles/{vehicle_id}/document").json()
            assert alloc.vehicle_file.vehicle_from_dict(document).problem().to_dict() is not None
            client.delete(f"/v1/vehicles/{vehicle_id}")
    assert statuses.get(422, 0) >= 150, statuses  # most mutations are refused, not taken

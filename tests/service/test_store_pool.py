"""The service's two halves: the store (the repository: SQL, versions, idempotency, vehicle
states) knows no allocator; the allocator pool learns of new health from the store, not from
a route; an allocation route hands its request to the pool in one call."""

from __future__ import annotations

import ast
from pathlib import Path

from fastapi.testclient import TestClient
from pydantic import TypeAdapter

from alloc.vehicles import ice
from service.config import Settings
from service.main import create_app
from service.schemas import EventIn

SERVICE = Path(__file__).resolve().parents[2] / "service"
#: the modules of allocators, their builds, pricing and answers: the pool's, not the store's
ALLOCATOR_MODULES = {"allocator_cache", "builds", "cost", "pool", "responses", "warm", "ams"}


def _service_imports(path: Path) -> set[str]:
    """The ``service`` modules ``path`` imports (relative or absolute, anywhere in the file)."""
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom):
            if node.level == 1 and node.module is None:  # from . import x
                found |= {a.name for a in node.names}
            elif node.level == 1 or (node.module or "").startswith("service."):
                found.add((node.module or "").removeprefix("service.").split(".")[0])
        elif isinstance(node, ast.Import):
            found |= {a.name.split(".")[1] for a in node.names if a.name.startswith("service.")}
    return found


def test_the_repository_imports_no_allocator_code():
    for name in ("store.py", "vehicle_state.py", "idempotency.py"):
        imports = _service_imports(SERVICE / name)
        assert "db" in imports  # the parser sees the module's imports
        assert imports & ALLOCATOR_MODULES == set(), (name, imports & ALLOCATOR_MODULES)


def _route(module: str, name: str) -> ast.AsyncFunctionDef:
    tree = ast.parse((SERVICE / "routes" / module).read_text())
    return next(n for n in tree.body if isinstance(n, ast.AsyncFunctionDef) and n.name == name)


def test_allocation_routes_hand_off_to_the_pool_once():
    for module, name in [("vehicles.py", "allocate"), ("vehicles.py", "allocate_batch"),
                         ("vehicles.py", "ams_summary"), ("allocation.py", "allocate"),
                         ("allocation.py", "allocate_batch"), ("ams.py", "ams_summary")]:
        route = _route(module, name)
        params = {a.arg for a in route.args.args}
        assert "pool" in params and "store" not in params, (module, name, params)
        calls = [n for n in ast.walk(route) if isinstance(n, ast.Call) and isinstance(n.func, ast.Attribute)
                 and isinstance(n.func.value, ast.Name) and n.func.value.id == "pool"]
        awaited = [n for n in ast.walk(route) if isinstance(n, ast.Await)]
        assert len(calls) == 1 and len(awaited) == 1 and awaited[0].value is calls[0], (module, name)


def test_the_event_route_leaves_rebuilds_to_the_pool():
    route = _route("vehicles.py", "record_event")
    names = {n.attr for n in ast.walk(route) if isinstance(n, ast.Attribute)}
    assert not names & {"prebuild", "rebuild_after_event", "allocators", "builder"}, names


def test_the_store_tells_the_pool_of_new_health_and_of_deletes(tmp_path):
    """An event recorded through the store itself (no route: as the telemetry's writes do)
    rebuilds the allocators in use for the new version; a delete drops the vehicle's."""
    app = create_app(Settings(data_dir=tmp_path, warmup=False))
    with TestClient(app) as client:
        store, pool = app.state.store, app.state.pool
        vid = client.post("/v1/vehicles", json={**ice().to_dict(), "name": "t"}).json()["id"]
        for method in ("pinv", "qp"):
            r = client.post(f"/v1/vehicles/{vid}/allocate", json={"v": [0.1, 0.2, 0.0], "method": method})
            assert r.status_code == 200, r.text

        def mine() -> list[tuple[int, str]]:
            """(health version, method) of the vehicle's cached allocators."""
            return sorted((k[1], k[2]) for k in pool.allocators.keys_where(lambda k: k[0] == vid))
        assert mine() == [(0, "pinv"), (0, "qp")]
        builds = pool.allocators.builds
        store.record_event(vid, TypeAdapter(EventIn).validate_python(
            {"effector": ice().names[0], "kind": "jam", "position": 0.1}))
        assert pool.builder.wait_idle(timeout=30.0)
        assert pool.allocators.builds == builds + 2
        assert mine() == [(1, "pinv"), (1, "qp")]  # the stale ones dropped, the new ones built
        assert client.delete(f"/v1/vehicles/{vid}").status_code == 204
        assert mine() == []

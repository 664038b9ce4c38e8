"""Digests of the C the generator writes for every exportable method on every catalogue vehicle.

Run before and after a change of the generator's structure (not of its output), with the
checkout's library first on the path (the script's folder is, the checkout is not)::

    PYTHONPATH=. python tests/alloc/export/export_digests.py save before.json
    PYTHONPATH=. python tests/alloc/export/export_digests.py compare before.json

Each case exports one (vehicle, method, settings) and records the sha256 of header + source
(raw text: on one machine the bits are the same; across machines LAPACK's last bits differ,
which is why test_golden.py rounds its literals), or the refusal's type and message.
"""

from __future__ import annotations

import hashlib
import json
import re
import sys
import time

import alloc
import alloc.vehicles
from alloc.export import EXPORTABLE, export_c

ITERATIVE = ("wls", "qp", "dynamic", "lp")
ACTIVE_SET = ("wls", "qp", "dynamic")


def cases() -> list[tuple[str, str, dict]]:
    out = []
    for vehicle in alloc.vehicles.names():
        for method in EXPORTABLE:
            out.append((vehicle, method, {}))
            out.append((vehicle, method, {"precision": "float"}))
            if method in ACTIVE_SET:
                out.append((vehicle, method, {"table": False}))
                out.append((vehicle, method, {"warm_start": True}))
                out.append((vehicle, method, {"maxit": 20, "iteration_bound": 30, "cache": 3}))
            if method == "lp":
                out.append((vehicle, method, {"iteration_bound": 40}))
            if method not in ITERATIVE:
                out.append((vehicle, method, {"maxit": 5}))
            if method == "cgi":
                out.append((vehicle, method, {"options": {"priorities": [2, 1, 1, 0][:alloc.vehicles.problem(vehicle).k]}}))
            if method == "qp":
                out.append((vehicle, method, {"options": {"priorities": [2, 1, 1, 0][:alloc.vehicles.problem(vehicle).k]}}))
            if method in ("pinv", "pinv_scale"):
                out.append((vehicle, method, {"options": {"incremental": True}}))
            if method in ("qp", "lp"):
                out.append((vehicle, method, {"options": {"backend": "daqp" if method == "qp" else "highs"}}))
    for method in ("qp", "lp"):
        out.append(("ice", method, {"iteration_bound": "certify"}))
    out.append(("tailless", "pinv", {"table": True}))
    out.append(("tailless", "lp", {"table": False}))
    out.append(("tailless", "lp", {"warm_start": True}))
    out.append(("tailless", "lp", {"maxit": 3}))
    out.append(("tailless", "nonesuch", {}))
    out.append(("tailless", "da", {}))
    return out


#: a floating literal of the generated source (not part of an identifier)
_LITERAL = re.compile(r"(?<![\w.])-?\d+\.\d*(?:e[-+]?\d+)?")


def rounded_digest(vehicle: str, method: str) -> str:
    """sha256 (16 hex digits) of the double kernel with the default settings, as
    test_golden.py hashes: literals rounded to 1e-9 (LAPACK's last bits differ between
    numpy builds), the library's version and the input's fingerprint masked."""
    kernel = export_c(alloc.vehicles.problem(vehicle), method, precision="double")
    text = (kernel.header + kernel.source).replace(alloc.__version__, "@VERSION@")
    text = _LITERAL.sub(lambda match: repr(round(float(match.group()), 9) + 0.0), text)
    text = re.sub(r"data sha256 [0-9a-f]+", "data sha256 @DATA@", text)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def key(vehicle: str, method: str, settings: dict) -> str:
    return f"{vehicle} {method} {json.dumps(settings, sort_keys=True)}"


def digest(vehicle: str, method: str, settings: dict) -> str:
    try:
        kernel = export_c(vehicle, method, **settings)
    except Exception as exc:  # noqa: BLE001 - the refusal is what is compared
        return f"{type(exc).__name__}: {exc}"
    return hashlib.sha256((kernel.header + "\0" + kernel.source).encode()).hexdigest()


def run() -> dict[str, str]:
    out = {}
    for vehicle, method, settings in cases():
        t0 = time.perf_counter()
        out[key(vehicle, method, settings)] = digest(vehicle, method, settings)
        print(f"{time.perf_counter() - t0:7.2f} s  {key(vehicle, method, settings)}", file=sys.stderr, flush=True)
    return out


if __name__ == "__main__":
    action, path = sys.argv[1], sys.argv[2]
    print(f"library: {alloc.__file__}")
    now = run()
    if action == "save":
        with open(path, "w") as f:
            json.dump(now, f, indent=1, sort_keys=True)
        print(f"{len(now)} cases saved, {sum(not v.count(':') for v in now.values())} kernels")
    else:
        with open(path) as f:
            before = json.load(f)
        diff = sorted(k for k in before.keys() | now.keys() if before.get(k) != now.get(k))
        for k in diff:
            print(f"DIFFERS {k}\n  before {before.get(k)}\n  after  {now.get(k)}")
        kernels = sum(1 for k in now if ":" not in now[k])
        print(f"{len(now)} cases, {kernels} kernels, {len(diff)} differ")
        sys.exit(1 if diff else 0)

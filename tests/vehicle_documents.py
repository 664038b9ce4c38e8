"""Seeded malformed vehicle documents: shared by the library's and the service's tests.

``mutate(doc, rng)`` returns a copy of a vehicle document with one to three hostile edits at
random paths (a junk value, a deleted member, an extra member, an appended list entry).
"""

from __future__ import annotations

import copy
import math
import random
from typing import Any

__all__ = ["JUNK", "paths", "mutate"]

#: the values an edit writes: wrong types, non-finite and huge numbers, bad text, empty containers
JUNK = [None, True, False, "x", "", "\x00", "\ud800", -1, 0, 1, -1.0, 1e60, 10**400, math.inf, -math.inf, math.nan,
        [], {}, [1.0, 2.0], [[1.0]], {"a": 1}, [None], ["m1"], -0.0, 2**63]


def paths(node: Any, prefix: tuple = ()):
    """Every path into ``node`` (tuples of keys and indices), the root first."""
    yield prefix
    if isinstance(node, dict):
        for k, v in node.items():
            yield from paths(v, (*prefix, k))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            yield from paths(v, (*prefix, i))


def mutate(doc: dict, rng: random.Random) -> dict:
    """A copy of ``doc`` with 1-3 hostile edits drawn from ``rng``."""
    doc = copy.deepcopy(doc)
    for _ in range(rng.randint(1, 3)):
        path = rng.choice([p for p in paths(doc) if p])
        parent = doc
        for key in path[:-1]:
            parent = parent[key]
        op = rng.random()
        if op < 0.6:
            parent[path[-1]] = copy.deepcopy(rng.choice(JUNK))
        elif op < 0.8 and isinstance(parent, dict):
            del parent[path[-1]]
        elif isinstance(parent, dict):
            parent[rng.choice(["zz", "name", "B", "rotor", "effectiveness", "weight"])] = copy.deepcopy(rng.choice(JUNK))
        else:
            parent.append(copy.deepcopy(rng.choice(JUNK)))
    return doc

"""The one catalogue of named allocation problems: the seed's aircraft.

Effectiveness, limits and rate limits of the seed's aircraft, and :data:`CATALOGUE`, the
names every command line and benchmark uses for them (``alloc allocate --vehicle NAME``,
``alloc ams summary --problem NAME``, the comparison sweep):

========== ============================================================ ======
name       problem                                                      k x m
========== ============================================================ ======
ice        ICE, axes (alpha, p, beta), seed section 4.7                 3 x 11
ice-design ICE design problem of seed Eq 4.24 (SSD out of pitch, Wu)    3 x 11
ice-mid    ICE with AMT/SSD preferring mid-range (30 deg)               3 x 11
harv       F-18/HARV lateral-directional, seed Eq 4.16 (``harv_latdir``) 3 x 5
========== ============================================================ ======

Each entry also carries its daisy-chain groups (seed Eq 1.25).

Transcribed from the seed (OCR'd: decimal points restored where the scan lost them, e.g.
``-0009123567`` -> ``-0.009123567``) and checked by reproducing the seed's printed
control distribution of Eq 4.24 with the project's own ``pinv`` (tests/test_vehicles.py).
Units: degrees and degrees per second for effectors; the rows of ``B`` are state
derivatives per degree of deflection.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from .exceptions import ProblemError
from .problem import Problem

__all__ = [
    "ICE_B_FULL", "ICE_EFFECTORS", "ICE_STATES", "ICE_BK_SEED", "ice", "ice_mid",
    "HARV_LATDIR_B", "HARV_LATDIR_EFFECTORS", "HARV_LATDIR_BK_SEED", "harv_latdir",
    "ICE_DAISY_GROUPS", "HARV_LATDIR_DAISY_GROUPS", "ice_daisy_groups",
    "NamedProblem", "CATALOGUE", "names", "lookup", "problem", "daisy_groups",
]

# seed section 4.7, B' (11 effectors x 8 states), flight condition M = 0.3, h = 15,000 ft.
# States x = [u w qb theta v pb rb phi]; effectors in the order below.
ICE_STATES = ("u", "w", "q", "theta", "v", "p", "r", "phi")
ICE_EFFECTORS = (
    "elevon_l", "elevon_r", "pitch_flap", "amt_l", "amt_r",
    "ssd_l", "ssd_r", "lef_l", "lef_r", "pitch_tv", "yaw_tv",
)  # seed: de3 de13 de4 de5 de15 de9 de19 de2 de12 de10 de20
ICE_B_FULL = np.array([
    [-0.005969294, -0.267968418, -1.385041358, 0, -0.009123567, 2.411735136, 0.037657455, 0],
    [-0.005969294, -0.267968418, -1.385041358, 0, 0.009123567, -2.411735136, -0.037657455, 0],
    [-0.004085579, -0.230586355, -1.20225331, 0, 0, 0, 0, 0],
    [-0.014173739, -0.084039328, -0.352069164, 0, -0.000248489, 0.536897487, -0.05609334, 0],
    [-0.014173739, -0.084039326, -0.352069164, 0, 0.000248489, -0.536903664, 0.0560923, 0],
    [-0.02523841, 0.111216392, 0.266496208, 0, 0.021932906, -1.196261818, -0.123503836, 0],
    [-0.025238416, 0.111216392, 0.266496208, 0, -0.021932906, 1.196261818, 0.123503836, 0],
    [0.011499932, 0.09704284, 0.233406726, 0, -0.028900689, -0.985320208, 0.185896833, 0],
    [0.011499932, 0.09704284, 0.233406726, 0, 0.028900689, 0.985320208, -0.185896833, 0],
    [-1.1804e-05, -0.123946616, -1.731151121, 0, 0, 0, 0, 0],
    [0, 0, 0, 0, 0.123946616, -0.066733456, -1.227324384, 0],
]).T
ICE_B_FULL.setflags(write=False)

# seed Table 4-5: position limits (deg) and rate limits (deg/s), in ICE_EFFECTORS order.
_ICE_UMIN = np.array([-30, -30, -30, 0, 0, 0, 0, -40, -40, -15, -15], dtype=float)
_ICE_UMAX = np.array([30, 30, 30, 60, 60, 60, 60, 40, 40, 15, 15], dtype=float)
_ICE_RATE = np.array([150, 150, 50, 150, 150, 150, 150, 40, 40, 60, 60], dtype=float)

# The allocation rows: the controlled variables are alpha, p and beta (Eq 4.25); the seed
# allocates with the rows w-dot, p-dot, v-dot of B (found by reproducing Eq 4.24).
_ICE_ROWS = (1, 5, 4)

# seed Eq 4.24 as printed (3 significant digits): the design control distribution B_k.
ICE_BK_SEED = np.array([
    [-0.773, 0.107, -0.097], [-0.773, -0.107, 0.097], [-1.33, 0, 0],
    [-0.485, 0.048, 0.055], [-0.485, -0.048, -0.055], [0, -0.104, 1.06],
    [0, 0.104, -1.06], [0.560, -0.0920, -1.73], [0.560, 0.0920, 1.73],
    [-0.715, 0, 0], [0, 0.01, 6.87],
])
ICE_BK_SEED.setflags(write=False)


def ice(*, design: bool = False) -> Problem:
    """The ICE allocation problem: axes (alpha, p, beta) <- rows (w-dot, p-dot, v-dot), 11 effectors.

    ``design=True`` gives the seed's design problem of Eq 4.24: the spoiler-slot deflectors
    "artificially removed from the pitch channel" (their w-dot entries zeroed) and
    ``Wu = diag[2, 2, 1, ..., 1]`` (seed prints ten entries for eleven effectors; the
    eleventh 1 is what reproduces Eq 4.24).
    """
    B = ICE_B_FULL[list(_ICE_ROWS)].copy()
    Wu = None
    if design:
        B[0, 5:7] = 0.0
        Wu = np.array([2, 2, 1, 1, 1, 1, 1, 1, 1, 1, 1], dtype=float)
    return Problem(
        B, _ICE_UMIN, _ICE_UMAX, Wu=Wu, rate_min=-_ICE_RATE, rate_max=_ICE_RATE,
        names=ICE_EFFECTORS, axes=("alpha", "p", "beta"),
    )


def ice_mid() -> Problem:
    """ICE with the one-sided effectors (AMT, SSD: 0..60 deg) preferring mid-range (30 deg).

    With ``up = 0`` they rest on a limit and the pseudo-inverse family can only push them one
    way; mid-range preferences are what the AMS coverage comparison of section 1.3.4.9 uses.
    """
    p = ice()
    up = p.up.copy()
    one_sided = p.umin >= 0
    up[one_sided] = (p.umin[one_sided] + p.umax[one_sided]) / 2
    return p.replace(up=up)


#: Daisy-chain groups for ICE in the spirit of seed Eq 1.25: aerodynamic surfaces first,
#: then the innovative effectors, then thrust vectoring.
ICE_DAISY_GROUPS = (
    ("elevon_l", "elevon_r", "pitch_flap", "lef_l", "lef_r"),
    ("amt_l", "amt_r", "ssd_l", "ssd_r"),
    ("pitch_tv", "yaw_tv"),
)


def ice_daisy_groups() -> list[list[str]]:
    """:data:`ICE_DAISY_GROUPS` as lists (the ``groups`` option of ``daisy``)."""
    return [list(g) for g in ICE_DAISY_GROUPS]


# seed Eq 4.16: F-18/HARV lateral-directional, x = [beta p r], u = [DT AI RU RTV YTV].
HARV_LATDIR_EFFECTORS = ("diff_tail", "aileron", "rudder", "roll_tv", "yaw_tv")
HARV_LATDIR_B = np.array([
    [0.005629, 0.005764, 0.003685, 0, 0.0904],
    [1.879, 1.328, 0.02922, 0.6754, 0.217],
    [-0.1092, -0.09645, -0.08404, 0.006811, -2.974],
])
HARV_LATDIR_B.setflags(write=False)
# seed Table 4-3: limits (deg) and rate limits (deg/s).
_HARV_UMAX = np.array([17.5, 27.5, 30, 30, 30], dtype=float)
_HARV_RATE = np.array([60, 100, 100, 60, 60], dtype=float)
# seed Eq 4.19: ganged distribution of the (beta, p) pseudo-commands to the five effectors.
HARV_LATDIR_BK_SEED = np.array([[0, 0.6], [0, 1], [1, 0], [0, 0.6], [0.6, 0]])
HARV_LATDIR_BK_SEED.setflags(write=False)


def harv_latdir() -> Problem:
    """F-18/HARV lateral-directional allocation: axes (beta-dot, p-dot, r-dot), 5 effectors."""
    return Problem(
        HARV_LATDIR_B, -_HARV_UMAX, _HARV_UMAX, rate_min=-_HARV_RATE, rate_max=_HARV_RATE,
        names=HARV_LATDIR_EFFECTORS, axes=("beta", "p", "r"),
    )


#: Daisy-chain groups for the HARV lateral-directional suite: surfaces, then thrust vectoring.
HARV_LATDIR_DAISY_GROUPS = (("diff_tail", "aileron", "rudder"), ("roll_tv", "yaw_tv"))


# --------------------------------------------------------------------------- catalogue
@dataclass(frozen=True)
class NamedProblem:
    """An entry of the catalogue: a named problem, where it comes from, its daisy groups."""

    name: str
    title: str
    source: str
    make: Callable[[], Problem]
    daisy_groups: tuple[tuple[str, ...], ...]
    aliases: tuple[str, ...] = ()

    def problem(self) -> Problem:
        return self.make()


#: name -> entry; the one place named problems are defined
CATALOGUE: dict[str, NamedProblem] = {entry.name: entry for entry in (
    NamedProblem("ice", "ICE", "seed section 4.7, Table 4-5", ice, ICE_DAISY_GROUPS),
    NamedProblem("ice-design", "ICE design problem", "seed Eq 4.24", lambda: ice(design=True), ICE_DAISY_GROUPS),
    NamedProblem("ice-mid", "ICE (AMT/SSD prefer 30 deg)", "seed section 4.7, up at mid-range", ice_mid,
                 ICE_DAISY_GROUPS),
    NamedProblem("harv", "F-18/HARV lat-dir", "seed Eq 4.16, Table 4-3", harv_latdir, HARV_LATDIR_DAISY_GROUPS,
                 aliases=("harv_latdir", "harv-latdir")),
)}
_BY_NAME = {**{a: e for e in CATALOGUE.values() for a in e.aliases}, **CATALOGUE}


def names() -> list[str]:
    """The catalogue's names (aliases aside), in catalogue order."""
    return list(CATALOGUE)


def lookup(name: str) -> NamedProblem:
    """The entry named ``name`` (or one of its aliases); unknown names list the known ones."""
    entry = _BY_NAME.get(name) if isinstance(name, str) else None
    if entry is None:
        raise ProblemError(f"vehicle: unknown {name!r}; known: {', '.join(CATALOGUE)}", field="vehicle")
    return entry


def problem(name: str) -> Problem:
    """The allocation problem named ``name`` (see :data:`CATALOGUE`)."""
    return lookup(name).problem()


def daisy_groups(name: str) -> list[list[str]]:
    """Daisy-chain groups (effector names, priority order) of the problem named ``name``."""
    return [list(g) for g in lookup(name).daisy_groups]

"""The one catalogue of named vehicles, and the seed's aircraft transcribed.

The catalogue (:func:`catalogue`, :func:`names`, :func:`lookup`, :func:`get_vehicle`) is
built from vehicle files (:mod:`alloc.vehicle_file`), so every command line and benchmark
reads a vehicle the same way (``alloc allocate|ams|sim|bench ... --vehicle NAME|FILE``).
Its entries come from, in this order:

1. the bundled files ``alloc/data/vehicles/*.toml``:

   ========== ============================================================ ======
   name       vehicle                                                      k x m
   ========== ============================================================ ======
   ice        ICE, axes (alpha, p, beta), seed section 4.7                 3 x 11
   ice-design ICE design problem of seed Eq 4.24 (SSD out of pitch, Wu)    3 x 11
   ice-mid    ICE with AMT/SSD preferring mid-range (30 deg)               3 x 11
   harv       F-18/HARV lateral-directional, seed Eq 4.16 (``harv_latdir``) 3 x 5
   hexa-x     hexacopter example, PX4 6001_hexa_x geometry                 4 x 6
   tailless   tailless example, ICE's eight surfaces                       3 x 8
   x57-dep    distributed propulsion example after NASA's X-57 (14 props)  4 x 18
   ========== ============================================================ ======

2. the vehicle files (:data:`VEHICLE_SUFFIXES`: ``.toml``, ``.json``, PX4 ``.params``, ArduPilot
   ``.csv`` factor tables and ``.param``/``.parm`` files) in the folders named by the
   environment variable ``ALLOC_VEHICLE_PATH`` (:data:`VEHICLE_PATH_ENV`, folders separated
   by ``os.pathsep``), each named by its file name without the extension;
3. the entry points of the group ``alloc.vehicles`` (:data:`ENTRY_POINT_GROUP`) of installed
   packages: the entry's name is the vehicle's, its object a path to a vehicle file or a
   callable returning a vehicle document (a dict) or a :class:`~alloc.vehicle_file.Vehicle`.

A name defined twice (a user file named like a bundled vehicle, say) is refused when it
is looked up, naming both definitions: a user's file never silently replaces the seed's.
Files are read when an entry is first used, not when the names are listed.

Per-vehicle method defaults (daisy groups, priorities, a gang matrix) live in the
vehicle's ``[methods.<name>]`` tables; :func:`method_options` merges them under the
caller's options, the one rule every tool applies.

The seed's aircraft are also transcribed here in Python (:func:`ice`, :func:`harv_latdir`,
:data:`SEED`): tests/alloc/test_vehicles.py checks the bundled files against them bit for bit.

Transcribed from the seed (OCR'd: decimal points restored where the scan lost them, e.g.
``-0009123567`` -> ``-0.009123567``) and checked by reproducing the seed's printed
control distribution of Eq 4.24 with the project's own ``pinv`` (tests/alloc/test_vehicles.py).
Units: degrees and degrees per second for effectors; the rows of ``B`` are state
derivatives per degree of deflection.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from functools import cache, lru_cache, partial
from importlib.metadata import EntryPoint, entry_points
from pathlib import Path
from typing import Any

import numpy as np

from .exceptions import OptionError, ProblemError
from .problem import Problem
from .vehicle_file import DATA_DIR, Vehicle, load_vehicle, vehicle_from_dict

__all__ = [
    "ICE_B_FULL", "ICE_EFFECTORS", "ICE_STATES", "ICE_BK_SEED", "ice", "ice_mid",
    "HARV_LATDIR_B", "HARV_LATDIR_EFFECTORS", "HARV_LATDIR_BK_SEED", "harv_latdir",
    "ICE_DAISY_GROUPS", "HARV_LATDIR_DAISY_GROUPS", "ice_daisy_groups",
    "SEED", "VEHICLE_PATH_ENV", "ENTRY_POINT_GROUP", "VEHICLE_SUFFIXES",
    "NamedProblem", "CATALOGUE", "catalogue", "names", "lookup", "problem", "daisy_groups",
    "get_vehicle", "method_options",
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


# --------------------------------------------------------------------------- the seed, transcribed
#: the seed's aircraft as transcribed above, by catalogue name: the bundled files must
#: yield these problems and daisy groups bit for bit (tests/alloc/test_vehicles.py)
SEED: dict[str, tuple[Callable[[], Problem], tuple[tuple[str, ...], ...]]] = {
    "ice": (ice, ICE_DAISY_GROUPS),
    "ice-design": (lambda: ice(design=True), ICE_DAISY_GROUPS),
    "ice-mid": (ice_mid, ICE_DAISY_GROUPS),
    "harv": (harv_latdir, HARV_LATDIR_DAISY_GROUPS),
}
#: other names of the bundled vehicles (the simulator's scenario is ``harv_latdir``)
_ALIASES = {"harv": ("harv_latdir", "harv-latdir")}


# --------------------------------------------------------------------------- catalogue
#: environment variable naming folders of vehicle files added to the catalogue (``os.pathsep``-separated)
VEHICLE_PATH_ENV = "ALLOC_VEHICLE_PATH"
#: entry-point group through which installed packages add vehicles (name -> path or callable)
ENTRY_POINT_GROUP = "alloc.vehicles"
#: the file extensions a vehicle file may have (:func:`alloc.vehicle_file.load_vehicle`)
VEHICLE_SUFFIXES = (".toml", ".json", ".params", ".csv", ".param", ".parm")


@dataclass(frozen=True)
class NamedProblem:
    """An entry of the catalogue: a named vehicle and where it is defined (read on first use)."""

    name: str
    origin: str
    load: Callable[[], Vehicle] = field(repr=False, compare=False)
    aliases: tuple[str, ...] = ()

    def vehicle(self) -> Vehicle:
        """The vehicle (read once per file version)."""
        return self.load()

    def problem(self) -> Problem:
        return self.vehicle().problem()

    @property
    def title(self) -> str:
        return self.vehicle().description or self.name

    @property
    def source(self) -> str:
        return self.vehicle().source or self.origin

    @property
    def daisy_groups(self) -> tuple[tuple[Any, ...], ...]:
        """The vehicle's ``[methods.daisy] groups`` (``()`` when it declares none)."""
        return tuple(tuple(g) for g in self.vehicle().method_options("daisy").get("groups") or ())


@lru_cache(maxsize=256)
def _read_file(path: str, mtime_ns: int, size: int) -> Vehicle:
    return load_vehicle(path)


def _file_loader(path: Path) -> Callable[[], Vehicle]:
    def load() -> Vehicle:
        try:
            stat = path.stat()
        except OSError as exc:
            raise ProblemError(f"path: cannot read {str(path)!r} ({exc.strerror})", field="path") from exc
        return _read_file(str(path), stat.st_mtime_ns, stat.st_size)

    return load


@cache
def _load_entry_point(ep: EntryPoint) -> Vehicle:
    where = f"entry point {ep.name!r} ({ep.value}) of {ENTRY_POINT_GROUP}"
    try:
        obj = ep.load()
    except Exception as exc:  # a broken plugin must name itself, whatever it raised
        raise ProblemError(f"vehicle: {where} cannot be loaded: {exc!r}", field="vehicle") from exc
    if isinstance(obj, (str, os.PathLike)):
        return load_vehicle(Path(obj))
    if not callable(obj):
        raise ProblemError(f"vehicle: {where} is a {type(obj).__name__}; expected a path or a callable",
                           field="vehicle")
    doc = obj()
    if isinstance(doc, Vehicle):
        return doc
    if isinstance(doc, Mapping):
        return vehicle_from_dict(doc)
    raise ProblemError(f"vehicle: {where} returned a {type(doc).__name__}; expected a vehicle document (dict)",
                       field="vehicle")


@cache
def _entry_points() -> tuple[EntryPoint, ...]:
    """The installed ``alloc.vehicles`` entry points (read once: installing a package restarts a tool)."""
    return tuple(sorted(entry_points(group=ENTRY_POINT_GROUP), key=lambda e: e.name))


def _folder_files(folder: Path) -> list[Path]:
    try:
        return sorted(p for p in folder.iterdir() if p.suffix.lower() in VEHICLE_SUFFIXES and p.is_file())
    except OSError:  # a folder on the path that does not exist (yet) adds nothing, like PATH
        return []


def _definitions() -> list[NamedProblem]:
    """Every definition, in catalogue order (bundled, ALLOC_VEHICLE_PATH, entry points), duplicates kept."""
    bundled = {p.stem: p for p in DATA_DIR.glob("*.toml")}
    order = [n for n in SEED if n in bundled] + sorted(set(bundled) - set(SEED))
    out = [NamedProblem(n, f"bundled {bundled[n].name}", _file_loader(bundled[n]), _ALIASES.get(n, ()))
           for n in order]
    for folder in filter(None, os.environ.get(VEHICLE_PATH_ENV, "").split(os.pathsep)):
        out += [NamedProblem(p.stem, str(p), _file_loader(p)) for p in _folder_files(Path(folder))]
    out += [NamedProblem(ep.name, f"entry point {ep.value}", partial(_load_entry_point, ep))
            for ep in _entry_points()]
    return out


def _index() -> tuple[dict[str, NamedProblem], dict[str, NamedProblem], dict[str, list[str]]]:
    """``(entries, by name or alias, clashes)``: a name defined twice is a clash, kept out of both."""
    entries: dict[str, NamedProblem] = {}
    by_name: dict[str, NamedProblem] = {}
    origins: dict[str, list[str]] = {}
    for entry in _definitions():
        for key in (entry.name, *entry.aliases):
            origins.setdefault(key, []).append(entry.origin)
            by_name.setdefault(key, entry)
        entries.setdefault(entry.name, entry)
    clashes = {k: v for k, v in origins.items() if len(v) > 1}
    return entries, {k: e for k, e in by_name.items() if k not in clashes}, clashes


def catalogue() -> dict[str, NamedProblem]:
    """name -> entry, read now (the environment variable and the installed entry points as they are)."""
    return _index()[0]


def __getattr__(name: str) -> Any:
    if name == "CATALOGUE":  # the catalogue as it is now (ALLOC_VEHICLE_PATH may change)
        return catalogue()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def names() -> list[str]:
    """The catalogue's names (aliases aside), in catalogue order; no file is read."""
    return list(catalogue())


def lookup(name: str) -> NamedProblem:
    """The entry named ``name`` (or one of its aliases); unknown names list the known ones."""
    entries, by_name, clashes = _index()
    if isinstance(name, str) and name in clashes:
        raise ProblemError(f"vehicle: {name!r} is defined {len(clashes[name])} times ({'; '.join(clashes[name])}); "
                           "rename all but one", field="vehicle")
    entry = by_name.get(name) if isinstance(name, str) else None
    if entry is None:
        raise ProblemError(f"vehicle: unknown {name!r}; known: {', '.join(entries)}", field="vehicle")
    return entry


def problem(name: str) -> Problem:
    """The allocation problem of the vehicle named ``name`` (see :func:`catalogue`)."""
    return lookup(name).problem()


def daisy_groups(name: str) -> list[list[str]]:
    """Daisy-chain groups (effector names, priority order) of the vehicle named ``name``.

    Raises OptionError naming ``groups`` for a vehicle that declares none.
    """
    groups = lookup(name).daisy_groups
    if not groups:
        raise OptionError(f"groups: vehicle {name!r} declares no daisy groups ([methods.daisy] groups)",
                          field="groups")
    return [list(g) for g in groups]


def get_vehicle(source: str | os.PathLike[str] | Vehicle) -> Vehicle:
    """The vehicle a ``--vehicle NAME|FILE`` names: a catalogue name (or alias), else a vehicle file.

    A catalogue name wins over a file of that name in the current folder; a path is what
    has a vehicle file's extension (:data:`VEHICLE_SUFFIXES`), a folder separator, or is a file.

    Raises
    ------
    ProblemError
        field ``vehicle`` for a name that is neither (listing the known names), the file's
        field path (``effectors[3].rate_max``) for a malformed file.
    """
    if isinstance(source, Vehicle):
        return source
    if isinstance(source, str):
        entries, by_name, clashes = _index()
        if source in by_name or source in clashes:
            return lookup(source).vehicle()
    if not isinstance(source, (str, os.PathLike)):
        raise ProblemError(f"vehicle: expected a name or a path, got {type(source).__name__}", field="vehicle")
    path = Path(source)
    if path.suffix.lower() in VEHICLE_SUFFIXES or os.sep in str(source) or os.path.isfile(path):  # os.path: a name too long for the file system is no file, not an OSError
        return load_vehicle(path)
    raise ProblemError(f"vehicle: unknown {str(source)!r}; known: {', '.join(entries)}; or a vehicle file "
                       f"({', '.join(VEHICLE_SUFFIXES)})", field="vehicle")


def _needs_from_vehicle(method: str) -> list[str]:
    """Options without which ``method`` silently becomes another method on a vehicle.

    Declared by the option's type: an effector-groups option left at its default ``None``
    makes ``daisy`` one group, i.e. ``pinv_scale``; no other default changes what a method is.
    """
    from .registry import get_method

    spec = get_method(method).options
    return [name for name, opt in spec.items() if opt.type == "groups" and opt.default is None]


def method_options(vehicle: str | os.PathLike[str] | Vehicle | None, method: str,
                   options: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """The options every tool gives ``method`` on ``vehicle``: ``{**vehicle defaults, **options}``.

    The vehicle's defaults are its ``[methods.<method>]`` table; the caller's ``options``
    override them one by one.  ``vehicle=None`` (a problem that is no catalogue vehicle, such
    as a simulator scenario without one): no defaults, the same check.

    Raises
    ------
    OptionError
        naming the option (``groups``) when neither the vehicle nor ``options`` give one the
        method cannot do without (:func:`_needs_from_vehicle`); UnknownMethodError for an
        unregistered method.
    """
    v = None if vehicle is None else get_vehicle(vehicle)
    merged = {**({} if v is None else v.method_options(method)), **(options or {})}
    for name in _needs_from_vehicle(method):
        if merged.get(name) is None:
            who = "no vehicle declares them" if v is None else f"vehicle {v.name!r} declares none"
            raise OptionError(
                f"{name}: method {method!r} needs effector {name} and {who} (without them it is another method); "
                f"give the option, e.g. --option {name}='[[0, 1], [2]]', or [methods.{method}] {name} in the "
                "vehicle file", field=name)
    return merged

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

The seed's aircraft are data only: :func:`ice`, :func:`ice_mid` and :func:`harv_latdir` read
the bundled files (:func:`bundled`); the numbers, with their seed citations, live in those
files alone.  tests/alloc/test_vehicles.py checks that they reproduce the seed's printed
control distributions (Eq 4.24 by the project's own ``pinv``, Eq 4.19 by ``ganging``).
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
    "ice", "ice_mid", "harv_latdir", "ice_daisy_groups", "bundled", "SEED_NAMES",
    "VEHICLE_PATH_ENV", "ENTRY_POINT_GROUP", "VEHICLE_SUFFIXES",
    "NamedProblem", "CATALOGUE", "catalogue", "names", "lookup", "problem", "daisy_groups",
    "get_vehicle", "method_options",
]

#: the seed's aircraft among the bundled files, in catalogue order (their numbers: the files)
SEED_NAMES = ("ice", "ice-design", "ice-mid", "harv")
#: other names of the bundled vehicles (the simulator's scenario is ``harv_latdir``)
_ALIASES = {"harv": ("harv_latdir", "harv-latdir")}


def bundled(name: str) -> Vehicle:
    """The bundled vehicle file ``alloc/data/vehicles/<name>.toml``, read once per file version.

    Unlike :func:`get_vehicle`, never a user's file of the same name: the seed's aircraft
    are these files whatever ``ALLOC_VEHICLE_PATH`` adds.
    """
    return _file_loader(DATA_DIR / f"{name}.toml")()


def ice(*, design: bool = False) -> Problem:
    """The ICE allocation problem (``ice.toml``): axes (alpha, p, beta) <- rows (w-dot, p-dot, v-dot), 11 effectors.

    ``design=True`` gives the seed's design problem of Eq 4.24 (``ice-design.toml``): the
    spoiler-slot deflectors "artificially removed from the pitch channel" (their w-dot
    entries zeroed) and ``Wu = diag[2, 2, 1, ..., 1]`` (seed prints ten entries for eleven
    effectors; the eleventh 1 is what reproduces Eq 4.24).
    """
    return bundled("ice-design" if design else "ice").problem()


def ice_mid() -> Problem:
    """ICE with the one-sided effectors (AMT, SSD: 0..60 deg) preferring mid-range (30 deg), ``ice-mid.toml``.

    With ``up = 0`` they rest on a limit and the pseudo-inverse family can only push them one
    way; mid-range preferences are what the AMS coverage comparison of section 1.3.4.9 uses.
    """
    return bundled("ice-mid").problem()


def ice_daisy_groups() -> list[list[str]]:
    """ICE's daisy-chain groups (``ice.toml`` ``[methods.daisy] groups``, the ``groups`` option of ``daisy``)."""
    return [list(g) for g in bundled("ice").method_options("daisy")["groups"]]


def harv_latdir() -> Problem:
    """F-18/HARV lateral-directional allocation (``harv.toml``): axes (beta-dot, p-dot, r-dot), 5 effectors."""
    return bundled("harv").problem()


def _seed_loop(name: str) -> Any:
    """The ``[simulation]`` section of bundled file ``name`` (the seed's ICE and HARV carry one)."""
    simulation = bundled(name).simulation
    if simulation is None:
        raise ProblemError(f"simulation: bundled vehicle {name!r} has no [simulation] section", field="simulation")
    return simulation


def _read_only(a: Any) -> np.ndarray:
    out = np.array(a, dtype=float)
    out.setflags(write=False)
    return out


#: names the seed's aircraft once had as Python constants, now read from the files
_FROM_FILES: dict[str, Callable[[], Any]] = {
    "ICE_B_FULL": lambda: _read_only(bundled("ice").model.arrays()[1]),  # type: ignore[union-attr]  # ice.toml has one
    "ICE_EFFECTORS": lambda: bundled("ice").effector_names,
    "ICE_BK_SEED": lambda: _read_only(_seed_loop("ice").allocation.static),
    "ICE_DAISY_GROUPS": lambda: tuple(tuple(g) for g in ice_daisy_groups()),
    "HARV_LATDIR_B": lambda: _read_only(bundled("harv").B),
    "HARV_LATDIR_EFFECTORS": lambda: bundled("harv").effector_names,
    "HARV_LATDIR_BK_SEED": lambda: _read_only(_seed_loop("harv").allocation.static),
    "HARV_LATDIR_DAISY_GROUPS": lambda: tuple(tuple(g) for g in bundled("harv").method_options("daisy")["groups"]),
}


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
    files = {p.stem: p for p in DATA_DIR.glob("*.toml")}
    order = [n for n in SEED_NAMES if n in files] + sorted(set(files) - set(SEED_NAMES))
    out = [NamedProblem(n, f"bundled {files[n].name}", _file_loader(files[n]), _ALIASES.get(n, ()))
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
    if name in _FROM_FILES:  # the seed's numbers, from the bundled files (no second copy in Python)
        return _FROM_FILES[name]()
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

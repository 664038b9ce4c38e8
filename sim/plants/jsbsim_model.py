"""JSBSim's bundled F-22 with pass-through flight control, built at run time.

The F-22 as shipped with ``jsbsim`` 1.3.3 has its own flight-control system, which rewrites every
effector position inside ``FGFDMExec.run()`` before the aerodynamics reads it, so positions
written from Python do not hold.  :func:`build_aircraft` writes a copy of the aircraft file
whose ``<flight_control>`` is replaced by pass-through channels (each position the aerodynamics
reads = an external property of ours) and whose aerodynamics, mass, propulsion and ground
reactions are untouched.  The copy goes to a cache directory named by the hash of the generated
file, never into the repository or the installed package.

What the F-22's aerodynamics reads (read from the file by :func:`aero_inputs`, checked in the
tests) and how each is driven here:

============================  ====================================  =================================
property the aero reads       effectors (external properties)       stock FCS limits / rate
============================  ====================================  =================================
``fcs/elevator-pos-rad``      ``stab_l``, ``stab_r``: the mean      +-30 deg, 2 norm/s = 60 deg/s
``fcs/tvc-pos-rad``           ``tvc`` (pitch nozzle)                +-20 deg, 2 norm/s = 40 deg/s
``fcs/left-aileron-pos-rad``  ``aileron`` (antisymmetric pair)      +-25 deg, 2.29 norm/s = 57 deg/s
``fcs/rudder-pos-rad``        ``rudder`` (twin rudders together)    +-30 deg, 2.673 norm/s = 80 deg/s
``fcs/lef-pos-rad``           ``lef`` (leading-edge flaps)          0..35 deg, 0.55 s full travel
``fcs/flap-pos-norm``         ``flap`` (trailing-edge, 1 = 30 deg)  0..30 deg, 3 s per half travel
``fcs/speedbrake-pos-norm``   left at 0 (not an effector)           --
============================  ====================================  =================================

The aerodynamics reads only the *symmetric* stabilator; the stock FCS computes a differential
stabilator that nothing reads.  The two halves here are therefore two effectors whose mean is
the symmetric deflection: identical pitch columns, no roll (the model has none to give).

Trim: JSBSim's trimmer drives ``fcs/pitch-trim-cmd-norm``, ``fcs/aileron-cmd-norm``,
``fcs/rudder-cmd-norm`` and ``fcs/throttle-cmd-norm``; the pass-through channels add the
first three (scaled to radians by the stock ranges) to the stabilator, aileron and rudder, so
the trimmer can move them.  After the trim the plant freezes the trimmed positions into the
external properties and zeroes the trim commands (:mod:`sim.plants.jsbsim`).  Throttle passes
straight to both engines (the stock FADEC's high-alpha throttle floor is dropped: this is an
effector pass-through, not the aircraft's control laws); ``fcs/thrust-norm`` (engine 0 thrust /
26550 lbf, which scales the nozzle's pitch moment) is kept as the stock file computes it.
"""

from __future__ import annotations

import hashlib
import math
import os
import tempfile
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from alloc.exceptions import AllocError

__all__ = ["AIRCRAFT", "Surface", "SURFACES", "MODEL_NAME", "build_aircraft", "aero_inputs", "jsbsim_root",
           "cache_dir", "JSBSimUnavailable"]

#: the bundled aircraft this module copies
AIRCRAFT = "f22"
#: the copy's model name (its directory and file under the cache's ``aircraft/``)
MODEL_NAME = "f22_alloc_passthrough"
DEG = 0.017453292519943295


class JSBSimUnavailable(AllocError, ImportError):
    """The ``jsbsim`` package (the ``[plants]`` extra) is not installed or has no F-22."""


@dataclass(frozen=True)
class Surface:
    """One effector: its external property (degrees), limits and rate from the stock FCS."""

    name: str
    #: our external property, in degrees
    prop: str
    #: the property the aerodynamics reads that this effector drives
    reads: str
    lo: float
    hi: float
    #: rate limit, deg/s, from the stock FCS's actuator (see the module table)
    rate: float
    kind: str
    description: str


#: Effectors in the vehicle file's order.  Limits and rates from the stock f22.xml: the
#: actuators' ``rate_limit`` (norm/s) times the ``aerosurface_scale`` range (rad per norm);
#: the LEF's kinematic traverses -1..1 (0..35 deg) in 0.55 s; the flap's 0..0.5..1 in 3 s each.
SURFACES: tuple[Surface, ...] = (
    Surface("stab_l", "alloc/stab-l-deg", "fcs/elevator-pos-rad", -30.0, 30.0, 2.0 * 30.0, "surface",
            "left stabilator half (the aero reads the mean of the halves)"),
    Surface("stab_r", "alloc/stab-r-deg", "fcs/elevator-pos-rad", -30.0, 30.0, 2.0 * 30.0, "surface",
            "right stabilator half (the aero reads the mean of the halves)"),
    Surface("tvc", "alloc/tvc-deg", "fcs/tvc-pos-rad", -20.0, 20.0, 2.0 * 20.0, "thrust-vector",
            "pitch thrust-vectoring nozzles (both engines together)"),
    Surface("aileron", "alloc/aileron-deg", "fcs/left-aileron-pos-rad", -25.0, 25.0, 2.29 * 25.0, "surface",
            "ailerons, antisymmetric (the aero reads the left one)"),
    Surface("rudder", "alloc/rudder-deg", "fcs/rudder-pos-rad", -30.0, 30.0, 2.673 * 30.0, "surface",
            "twin rudders together"),
    Surface("lef", "alloc/lef-deg", "fcs/lef-pos-rad", 0.0, 35.0, 35.0 / 0.55, "surface",
            "leading-edge flaps, symmetric (lift and drag only)"),
    Surface("flap", "alloc/flap-deg", "fcs/flap-pos-norm", 0.0, 30.0, 15.0 / 3.0, "surface",
            "trailing-edge flaps, symmetric (lift and drag only; 1 norm = 30 deg)"),
)

#: the trimmer's commands added to a surface (norm -> rad by the stock FCS range)
_TRIM_INPUTS = {"fcs/elevator-pos-rad": ("fcs/pitch-trim-cmd-norm", 0.5236),
                "fcs/left-aileron-pos-rad": ("fcs/aileron-cmd-norm", 0.436),
                "fcs/rudder-pos-rad": ("fcs/rudder-cmd-norm", 0.5236)}


def jsbsim_root() -> Path:
    """The installed ``jsbsim`` package's data root (aircraft, engine, systems)."""
    try:
        import jsbsim
    except ImportError as exc:
        raise JSBSimUnavailable("jsbsim: not installed; pip install 'alloc-toolkit[plants]' (jsbsim==1.3.3)") from exc
    root = Path(jsbsim.get_default_root_dir())
    if not (root / "aircraft" / AIRCRAFT / f"{AIRCRAFT}.xml").is_file():
        raise JSBSimUnavailable(f"jsbsim: no aircraft/{AIRCRAFT}/{AIRCRAFT}.xml under {root}")
    return root


def cache_dir() -> Path:
    """Where built aircraft go: ``$ALLOC_CACHE_DIR``, else ``$XDG_CACHE_HOME/alloc``, else the temp dir."""
    base = os.environ.get("ALLOC_CACHE_DIR") or os.environ.get("XDG_CACHE_HOME")
    if base:
        return Path(base) / ("" if os.environ.get("ALLOC_CACHE_DIR") else "alloc")
    return Path(tempfile.gettempdir()) / f"alloc-cache-{os.getuid() if hasattr(os, 'getuid') else 'user'}"


def aero_inputs(source: Path) -> set[str]:
    """Every ``fcs/`` property the file's ``<aerodynamics>`` reads (properties and table variables)."""
    aero = ET.parse(source).getroot().find("aerodynamics")
    found = set()
    for el in aero.iter():
        if el.tag in ("property", "independentVar") and el.text and el.text.strip().startswith("fcs/"):
            found.add(el.text.strip())
    return found


def _el(parent: ET.Element, tag: str, text: str | None = None, **attrib: str) -> ET.Element:
    e = ET.SubElement(parent, tag, attrib)
    if text is not None:
        e.text = text
    return e


def _flight_control() -> ET.Element:
    """The pass-through ``<flight_control>``: each aero input = the sum of our properties (+ trim)."""
    fc = ET.Element("flight_control", name="alloc pass-through")
    for s in SURFACES:
        _el(fc, "property", s.prop, value="0")
    ch = _el(fc, "channel", name="Effectors")
    by_read: dict[str, list[Surface]] = {}
    for s in SURFACES:
        by_read.setdefault(s.reads, []).append(s)
    for reads, surfaces in by_read.items():
        tag = reads.replace("/", "-")
        # degrees -> the unit the aero reads; the stabilator halves average
        scale = (1.0 / 30.0 if reads.endswith("-norm") else DEG) / len(surfaces)
        fn = _el(ch, "fcs_function", name=f"alloc/{tag}")
        fun = _el(fn, "function")
        terms = len(surfaces) + (reads in _TRIM_INPUTS)
        total = _el(fun, "sum") if terms > 1 else fun  # JSBSim refuses a one-term sum
        for s in surfaces:
            prod = _el(total, "product")
            _el(prod, "property", s.prop)
            _el(prod, "value", repr(scale))
        if reads in _TRIM_INPUTS:
            cmd, rad = _TRIM_INPUTS[reads]
            prod = _el(total, "product")
            _el(prod, "property", cmd)
            _el(prod, "value", repr(rad))
        _el(fn, "output", reads)
    thr = _el(fc, "channel", name="Throttle")
    for i, suffix in enumerate(("", "[1]")):
        g = _el(thr, "pure_gain", name=f"alloc/throttle{i}")
        _el(g, "input", f"fcs/throttle-cmd-norm{suffix}")
        _el(g, "gain", "1.0")
        _el(g, "output", f"fcs/throttle-pos-norm{suffix}")
    # the nozzle's pitch moment is scaled by this, as in the stock file
    fn = _el(thr, "fcs_function", name="fcs/thrust-normalized")
    q = _el(_el(fn, "function"), "quotient")
    _el(q, "property", "propulsion/engine/thrust-lbs")
    _el(q, "value", "26550")
    clip = _el(fn, "clipto")
    _el(clip, "min", "0")
    _el(clip, "max", "1.5")
    _el(fn, "output", "fcs/thrust-norm")
    gear = _el(fc, "channel", name="Gear")
    g = _el(gear, "pure_gain", name="alloc/gear")
    _el(g, "input", "gear/gear-cmd-norm")
    _el(g, "gain", "1.0")
    _el(g, "output", "gear/gear-pos-norm")
    return fc


def build_aircraft(directory: Path | None = None) -> Path:
    """Write the pass-through copy (once per generated content); return the directory of aircraft.

    The returned directory holds ``<MODEL_NAME>/<MODEL_NAME>.xml``; engines and systems are
    read from the installed package.  The cache entry is named by the hash of the generated
    file, so a changed source or generator never reuses a stale copy; it is written to a
    temporary name then renamed, so concurrent builders never see half a file.
    """
    source = jsbsim_root() / "aircraft" / AIRCRAFT / f"{AIRCRAFT}.xml"
    tree = ET.parse(source)
    root = tree.getroot()
    old = root.find("flight_control")
    if old is None:
        raise JSBSimUnavailable(f"jsbsim: {source} has no <flight_control> to replace")
    missing = {s.reads for s in SURFACES} - aero_inputs(source)
    if missing:
        raise JSBSimUnavailable(f"jsbsim: {source}'s aerodynamics no longer reads {sorted(missing)}")
    index = list(root).index(old)
    root.remove(old)
    root.insert(index, _flight_control())
    for out in root.findall("output"):  # no data logs
        root.remove(out)
    root.set("name", f"{root.get('name', AIRCRAFT)} (alloc pass-through flight control)")
    data = ET.tostring(root, encoding="utf-8", xml_declaration=True)
    digest = hashlib.sha256(data).hexdigest()[:16]
    aircraft = (directory or cache_dir()) / f"jsbsim-{AIRCRAFT}-{digest}" / "aircraft"
    target = aircraft / MODEL_NAME / f"{MODEL_NAME}.xml"
    if not target.is_file():
        target.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=target.parent, suffix=".xml.tmp")
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
        os.replace(tmp, target)
    return aircraft


# --------------------------------------------------------------------------- the simulator
#: the linear model's state, in order, with units (angles deg, rates deg/s, airspeed m/s)
STATES: tuple[str, ...] = ("vt", "alpha", "q", "theta", "beta", "p", "r", "phi")
STATE_UNITS: tuple[str, ...] = ("m/s", "deg", "deg/s", "deg", "deg", "deg/s", "deg/s", "deg")
FT = 0.3048
_STATE_PROPS = ("velocities/u-fps", "velocities/v-fps", "velocities/w-fps", "velocities/p-rad_sec",
                "velocities/q-rad_sec", "velocities/r-rad_sec", "attitude/phi-rad", "attitude/theta-rad",
                "attitude/psi-rad", "position/h-sl-ft")
_ACCELERATIONS = ("accelerations/udot-ft_sec2", "accelerations/vdot-ft_sec2", "accelerations/wdot-ft_sec2",
                  "accelerations/pdot-rad_sec2", "accelerations/qdot-rad_sec2", "accelerations/rdot-rad_sec2")
#: suspended ``run()`` passes to settle the alpha-dot and beta-dot terms of the aerodynamics, which
#: JSBSim computes from the previous pass's accelerations (a fixed-point iteration)
MAX_SETTLE_PASSES = 20
#: JSBSim's own step; 120 Hz is the rate the bundled aircraft are tuned and scripted at
JSBSIM_DT = 1.0 / 120.0


class TrimError(AllocError, ValueError):
    """JSBSim's trimmer found no trim at the asked condition (names the field)."""


@dataclass(frozen=True)
class TrimCondition:
    """Where the aircraft is trimmed: straight and level (``gamma_deg = 0``) at ``mach`` and ``altitude_ft``.

    The default, M0.7 at 20,000 ft (dynamic pressure 16.0 kPa), is a subsonic cruise inside the
    band where the pass-through copy trims (M0.4-1.5): alpha about 3 deg, between the 0 and 5 deg
    rows of the pitch tables and below M0.9 where the leading-edge-flap schedule of the stock
    FCS would switch off; flaps clean (LEF and trailing-edge flaps at 0).
    """

    mach: float = 0.7
    altitude_ft: float = 20000.0
    gamma_deg: float = 0.0

    def __post_init__(self) -> None:
        checks = (("mach", 0.2, 2.0), ("altitude_ft", 1000.0, 60000.0), ("gamma_deg", -20.0, 20.0))
        for name, lo, hi in checks:
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not lo <= float(value) <= hi:
                raise TrimError(f"{name}: expected a number in [{lo:g}, {hi:g}], got {value!r}", field=name)


class F22:
    """One JSBSim instance of the pass-through F-22, trimmed at ``condition`` and frozen there.

    After construction the effector positions (degrees, :data:`SURFACES` order) are the trimmed
    ones, held by our external properties; the trimmer's commands are zeroed.  ``trim_positions``
    and ``trim_state`` (:data:`STATES`) record the trim, ``trim_residual`` the largest
    body-axis acceleration left at it (ft/s^2 and rad/s^2 as JSBSim reports them).
    """

    def __init__(self, condition: TrimCondition | None = None, *, dt: float = JSBSIM_DT) -> None:
        import jsbsim

        self.condition = condition or TrimCondition()
        root = jsbsim_root()
        aircraft = build_aircraft()
        jsbsim.FGJSBBase().debug_lvl = 0  # no banner, no load messages
        fdm = jsbsim.FGFDMExec(str(root), None)
        fdm.set_debug_level(0)
        fdm.disable_output()
        if not fdm.load_model_with_paths(MODEL_NAME, str(aircraft), str(root / "engine"), str(root / "systems"), True):
            raise JSBSimUnavailable(f"jsbsim: could not load {aircraft / MODEL_NAME}")
        fdm.set_dt(dt)
        c = self.condition
        fdm["ic/h-sl-ft"] = float(c.altitude_ft)
        fdm["ic/mach"] = float(c.mach)
        fdm["ic/gamma-deg"] = float(c.gamma_deg)
        fdm["ic/psi-true-deg"] = 0.0
        fdm["gear/gear-cmd-norm"] = 0.0
        fdm["propulsion/set-running"] = -1
        fdm.run_ic()
        try:
            fdm.do_trim(1)  # full trim: throttle, pitch trim, aileron, rudder, alpha, beta, attitude
        except Exception as exc:  # JSBSim raises its own TrimFailureException
            raise TrimError(f"mach: JSBSim's full trim failed at M{c.mach:g}, {c.altitude_ft:g} ft, gamma "
                            f"{c.gamma_deg:g} deg ({exc})", field="mach") from exc
        self.fdm = fdm
        self.dt = float(dt)
        # freeze: the trimmed positions go to our properties, the trim commands to zero
        positions = []
        for s in SURFACES:
            reads = fdm[s.reads]
            deg = reads * 30.0 if s.reads.endswith("-norm") else reads / DEG
            positions.append(deg)
        for cmd, _ in _TRIM_INPUTS.values():
            fdm[cmd] = 0.0
        self.trim_positions = np.array(positions)
        self.set_positions(self.trim_positions)
        self.throttle = float(fdm["fcs/throttle-cmd-norm"])
        self.trim_props = {p: float(fdm[p]) for p in _STATE_PROPS}
        self.trim_state = self.state()
        self.trim_residual = float(np.max(np.abs(self.accelerations())))

    # ---- effectors
    def set_positions(self, deg: np.ndarray) -> None:
        """Write every surface's external property (degrees, :data:`SURFACES` order)."""
        for s, x in zip(SURFACES, deg, strict=True):
            self.fdm[s.prop] = float(x)

    def positions(self) -> np.ndarray:
        """Our external properties now (degrees, :data:`SURFACES` order; the aero reads the halves' mean)."""
        return np.array([self.fdm[s.prop] for s in SURFACES])

    # ---- state
    def state(self) -> np.ndarray:
        """:data:`STATES` now (m/s, deg, deg/s)."""
        f = self.fdm
        return np.array([f["velocities/vt-fps"] * FT, f["aero/alpha-deg"], np.degrees(f["velocities/q-rad_sec"]),
                         f["attitude/theta-deg"], f["aero/beta-deg"], np.degrees(f["velocities/p-rad_sec"]),
                         np.degrees(f["velocities/r-rad_sec"]), f["attitude/phi-deg"]])

    def set_state(self, x: np.ndarray) -> None:
        """Put the aircraft at :data:`STATES` ``x`` (the trim's altitude, heading and position), no wind.

        Through JSBSim's initial conditions and ``run_ic`` (no integration); attitude first, so
        the body velocities are kept in body axes.
        """
        vt, alpha, q, theta, beta, p, r, phi = (float(v) for v in x)
        a, b = math.radians(alpha), math.radians(beta)
        vt_fps = vt / FT
        f = self.fdm
        f["ic/h-sl-ft"] = self.trim_props["position/h-sl-ft"]
        f["ic/phi-rad"], f["ic/theta-rad"] = math.radians(phi), math.radians(theta)
        f["ic/psi-true-rad"] = self.trim_props["attitude/psi-rad"]
        f["ic/u-fps"] = vt_fps * math.cos(a) * math.cos(b)
        f["ic/v-fps"] = vt_fps * math.sin(b)
        f["ic/w-fps"] = vt_fps * math.sin(a) * math.cos(b)
        f["ic/p-rad_sec"], f["ic/q-rad_sec"], f["ic/r-rad_sec"] = (math.radians(v) for v in (p, q, r))
        f.run_ic()

    def accelerations(self) -> np.ndarray:
        """Body-axis ``(udot, vdot, wdot)`` ft/s^2 and ``(pdot, qdot, rdot)`` rad/s^2 of the current pass."""
        return np.array([self.fdm[a] for a in _ACCELERATIONS])

    def settle(self) -> np.ndarray:
        """Re-run the models without integrating until the accelerations stop changing (alpha-dot terms)."""
        f = self.fdm
        f.suspend_integration()
        try:
            acc = self.accelerations()
            for _ in range(MAX_SETTLE_PASSES):
                f.run()
                new = self.accelerations()
                if np.max(np.abs(new - acc)) <= 1e-12 * max(1.0, float(np.max(np.abs(new)))):
                    return new
                acc = new
            return acc
        finally:
            f.resume_integration()

    def derivatives(self, x: np.ndarray, positions: np.ndarray) -> np.ndarray:
        """``x'`` of :data:`STATES` at state ``x`` with the effectors at ``positions`` (deg), no integration.

        Airspeed, alpha and beta rates from the body accelerations (``u, v, w`` and their
        derivatives); body rates from JSBSim's angular accelerations; the Euler-angle rates
        from their kinematics.
        """
        self.set_positions(positions)
        self.set_state(x)
        return state_rates(x, self.settle())


def state_rates(x: np.ndarray, acc: np.ndarray) -> np.ndarray:
    """``x'`` of :data:`STATES` (m/s, deg) at state ``x`` from JSBSim's body accelerations ``acc``
    (``udot, vdot, wdot`` ft/s^2, ``pdot, qdot, rdot`` rad/s^2, :meth:`F22.accelerations`): airspeed, alpha and
    beta rates from the body velocities and their derivatives, body rates' from the angular accelerations,
    the Euler-angle rates from their kinematics."""
    vt, alpha, _, theta, beta, _, _, phi = x
    a, b = math.radians(alpha), math.radians(beta)
    V = vt / FT
    u, v, w = V * math.cos(a) * math.cos(b), V * math.sin(b), V * math.sin(a) * math.cos(b)
    ud, vd, wd = acc[:3]
    vt_dot = (u * ud + v * vd + w * wd) / V
    alpha_dot = (u * wd - w * ud) / (u * u + w * w)
    beta_dot = (vd * V - v * vt_dot) / (V * V * math.cos(b))
    p, q, r = (math.radians(s) for s in (x[5], x[2], x[6]))
    th, ph = math.radians(theta), math.radians(phi)
    theta_dot = q * math.cos(ph) - r * math.sin(ph)
    phi_dot = p + math.tan(th) * (q * math.sin(ph) + r * math.cos(ph))
    rad = (alpha_dot, acc[4], theta_dot, beta_dot, acc[3], acc[5], phi_dot)
    return np.array([vt_dot * FT, *np.degrees(rad)])

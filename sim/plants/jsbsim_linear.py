"""The F-22's linear model from JSBSim itself: finite differences at the trim, written as a vehicle file.

``x' = A x + B u``, ``y = C x`` with ``x`` = :data:`~sim.plants.jsbsim_model.STATES` (airspeed
m/s; alpha, theta, beta, phi deg; q, p, r deg/s) and ``u`` the allocator's effectors
(:data:`EFFECTORS`: both stabilator halves, the pitch nozzle, ailerons, rudders; degrees), every
variable a deviation from the trim.  Each column of ``A`` and ``B`` is measured on the nonlinear
model by :meth:`~sim.plants.jsbsim_model.F22.derivatives` (no integration), nothing typed in.

Finite differences.  For every variable both one-sided differences are taken with the steps
below; where they agree within :data:`KINK_RTOL` the column is their mean (the central
difference).  Where they do not, a table of the aerodynamics has a breakpoint between
``x0 - h`` and ``x0 + h`` (the F-22's pitch tables are kinked at zero deflection: the nozzle
trims exactly there), the derivative does not exist, and the column is still the mean of the
two sides -- the secant that splits the error evenly -- while both one-sided columns are kept
(:attr:`Linearisation.one_sided`) and written into the vehicle file's comments.  An effector at
a position limit is differenced on its free side only.

The allocator's axes are the angular accelerations (rows ``q``, ``p``, ``r`` of ``B``) and the
controlled outputs ``q``, ``p``, ``r``: each is of relative order one with its row of ``B``
exactly an axis (no fit residual in :func:`sim.autodesign.pseudo_command_map`), and they are
the variables the F-22's own flight-control file regulates (pitch-rate and yaw-rate integrators,
roll-rate command).  Leading-edge and trailing-edge flaps are driven by the plant but left out
of the allocation: their pitch moment is a by-product of their lift (see :func:`effector_survey`).
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from alloc.exceptions import AllocError
from sim.plants.jsbsim_model import (SURFACES, STATE_UNITS, STATES, F22, TrimCondition, jsbsim_root)

__all__ = ["EFFECTORS", "CONTROLLED", "STATE_STEPS", "EFFECTOR_STEP", "KINK_RTOL", "ACTUATOR_BANDWIDTH",
           "Linearisation", "linearise", "vehicle_document", "write_vehicle", "b_envelope", "effector_survey",
           "VEHICLE_FILE"]

#: the allocator's effectors (indices into :data:`SURFACES`): the moment producers
EFFECTORS: tuple[str, ...] = ("stab_l", "stab_r", "tvc", "aileron", "rudder")
#: controlled outputs, one per axis (pitch, roll, yaw)
CONTROLLED: tuple[str, ...] = ("q", "p", "r")
#: finite-difference steps per state (units of :data:`STATES`); small against the tables' spacing
#: (5 deg in alpha) and large against JSBSim's round-off (accelerations to ~1e-12)
STATE_STEPS: tuple[float, ...] = (0.5, 0.1, 0.5, 0.5, 0.1, 0.5, 0.5, 0.5)
#: finite-difference step of an effector, deg
EFFECTOR_STEP = 0.5
#: one-sided columns differing by more than this fraction of their size mark a kink
KINK_RTOL = 0.02
#: first-order actuator bandwidths, rad/s (our choice: the stock F-22 file's actuators have no
#: lag, only rate limits); surfaces as ICE's 40 rad/s first corner, nozzles as HARV's 20 rad/s
ACTUATOR_BANDWIDTH: dict[str, float] = {"stab_l": 40.0, "stab_r": 40.0, "tvc": 20.0, "aileron": 40.0,
                                        "rudder": 40.0}
#: the committed vehicle file this module generates
VEHICLE_FILE = Path(__file__).with_name("data") / "f22_jsbsim.toml"
_INDEX = {s.name: i for i, s in enumerate(SURFACES)}


@dataclass(frozen=True)
class Linearisation:
    """The linear model at a trim and how it was measured.

    ``B_all`` has a column per :data:`SURFACES` entry (flaps included); ``B`` the allocator's
    :data:`EFFECTORS`.  ``one_sided[name] = (forward, backward)`` for every variable whose two
    one-sided columns differ by more than :data:`KINK_RTOL` (a kink at the trim).
    """

    condition: TrimCondition
    trim_state: np.ndarray
    trim_positions: np.ndarray
    throttle: float
    qbar_pa: float
    residual: float
    A: np.ndarray
    B_all: np.ndarray
    one_sided: dict[str, tuple[np.ndarray, np.ndarray]]
    jsbsim_version: str

    @property
    def B(self) -> np.ndarray:
        return self.B_all[:, [_INDEX[e] for e in EFFECTORS]]

    @property
    def B_axes(self) -> np.ndarray:
        """Rows ``q, p, r`` of :attr:`B`: the allocator's effectiveness (deg/s^2 per deg)."""
        return self.B[[STATES.index(c) for c in CONTROLLED]]


def _difference(fun: Any, x0: np.ndarray, j: int, h: float, lo: float = -math.inf, hi: float = math.inf,
                ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
    """``(column, forward, backward)`` of ``fun`` along coordinate ``j`` (see the module docstring)."""
    f0 = fun(x0)
    fwd = bwd = None
    if x0[j] + h <= hi:
        xp = x0.copy()
        xp[j] += h
        fwd = (fun(xp) - f0) / h
    if x0[j] - h >= lo:
        xm = x0.copy()
        xm[j] -= h
        bwd = (f0 - fun(xm)) / h
    if fwd is None or bwd is None:
        col = fwd if bwd is None else bwd
        return col, fwd, bwd
    return 0.5 * (fwd + bwd), fwd, bwd


def _kinked(fwd: np.ndarray | None, bwd: np.ndarray | None) -> bool:
    if fwd is None or bwd is None:
        return False
    size = max(float(np.linalg.norm(fwd)), float(np.linalg.norm(bwd)))
    return size > 0.0 and float(np.linalg.norm(fwd - bwd)) > KINK_RTOL * size


def linearise(condition: TrimCondition | None = None, *, f22: F22 | None = None,
              state_steps: Sequence[float] = STATE_STEPS, effector_step: float = EFFECTOR_STEP,
              at_state: np.ndarray | None = None) -> Linearisation:
    """Trim (or take ``f22``, already trimmed) and measure ``A`` and ``B`` there.

    ``at_state``: measure at this state instead of the trim (the envelope's alpha offsets);
    the effectors stay at their trim positions.
    """
    import jsbsim

    steps = np.asarray(state_steps, dtype=float)
    if steps.shape != (len(STATES),) or not np.all(steps > 0):
        raise AllocError(f"state_steps: expected {len(STATES)} positive steps, got {list(state_steps)!r}",
                         field="state_steps")
    if not (isinstance(effector_step, (int, float)) and 0 < effector_step <= 5):
        raise AllocError(f"effector_step: expected a step in (0, 5] deg, got {effector_step!r}", field="effector_step")
    sim = f22 or F22(condition)
    x0 = sim.trim_state.copy() if at_state is None else np.asarray(at_state, dtype=float)
    u0 = sim.trim_positions.copy()
    one_sided: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    A = np.zeros((len(STATES), len(STATES)))
    for j, name in enumerate(STATES):
        col, fwd, bwd = _difference(lambda x: sim.derivatives(x, u0), x0, j, steps[j])
        A[:, j] = col
        if _kinked(fwd, bwd):
            one_sided[name] = (fwd, bwd)
    B = np.zeros((len(STATES), len(SURFACES)))
    for j, s in enumerate(SURFACES):
        col, fwd, bwd = _difference(lambda u: sim.derivatives(x0, u), u0, j, effector_step, s.lo, s.hi)
        B[:, j] = col
        if _kinked(fwd, bwd):
            one_sided[s.name] = (fwd, bwd)
    sim.set_positions(u0)
    sim.set_state(sim.trim_state)
    return Linearisation(condition=sim.condition, trim_state=sim.trim_state.copy(), trim_positions=u0,
                         throttle=sim.throttle, qbar_pa=float(sim.fdm["aero/qbar-psf"]) * 47.880258889,
                         residual=sim.trim_residual, A=A, B_all=B, one_sided=one_sided,
                         jsbsim_version=str(getattr(jsbsim, "__version__", "unknown")))


# --------------------------------------------------------------------------- the vehicle file
def vehicle_document(lin: Linearisation) -> dict[str, Any]:
    """The vehicle file (format ``alloc-vehicle/1``) of ``lin``: every number a deviation from the trim."""
    c = lin.condition
    effectors = []
    for name in EFFECTORS:
        s = SURFACES[_INDEX[name]]
        trim = float(lin.trim_positions[_INDEX[name]])
        effectors.append({
            "name": name, "kind": s.kind, "unit": "deg",
            "description": f"{s.description}; deviation from its trim {trim:.4f} deg",
            "min": s.lo - trim, "max": s.hi - trim, "rate_max": s.rate,
            "preferred": 0.0, "dynamics": {"bandwidth": ACTUATOR_BANDWIDTH[name]},
        })
    rows = [STATES.index(ch) for ch in CONTROLLED]
    axes = [{"name": n, "unit": "deg/s^2", "description": f"{d} acceleration ({ch}-dot row of B)"}
            for n, d, ch in (("pitch", "pitch", "q"), ("roll", "roll", "p"), ("yaw", "yaw", "r"))]
    B = lin.B
    return {
        "format": "alloc-vehicle/1",
        "name": "f22_jsbsim",
        "description": (f"JSBSim F-22 (pass-through flight control), M{c.mach:g} at {c.altitude_ft:g} ft, "
                        "linearised by finite differences"),
        "source": f"jsbsim {lin.jsbsim_version} aircraft/f22/f22.xml via sim.plants.jsbsim_linear",
        "axes": axes,
        "effectors": effectors,
        "effectiveness": {"B": _rounded(B[rows])},
        "model": {"states": list(STATES), "outputs": list(STATES), "units": list(STATE_UNITS),
                  "A": _rounded(lin.A), "B": _rounded(B), "C": np.eye(len(STATES)).tolist(),
                  "D": np.zeros((len(STATES), len(EFFECTORS))).tolist(), "controlled": list(CONTROLLED)},
    }


def _rounded(M: np.ndarray) -> list[list[float]]:
    return [[float(f"{v:.9g}") for v in row] for row in np.asarray(M)]


def _provenance(lin: Linearisation) -> list[str]:
    c = lin.condition
    x = lin.trim_state
    lines = [
        "Generated by `python -m sim.plants.jsbsim_linear --out FILE`; do not edit by hand.",
        f"Plant: jsbsim {lin.jsbsim_version}, aircraft/f22/f22.xml with its <flight_control> replaced by",
        "pass-through channels (sim/plants/jsbsim_model.py); aerodynamics, mass and engines as shipped.",
        f"Trim (JSBSim full trim): M{c.mach:g}, {c.altitude_ft:g} ft, gamma {c.gamma_deg:g} deg; "
        f"qbar {lin.qbar_pa:.0f} Pa; throttle {lin.throttle:.4f};",
        f"  vt {x[0]:.3f} m/s, alpha {x[1]:.4f} deg, theta {x[3]:.4f} deg; largest body acceleration left "
        f"{lin.residual:.2e} (ft/s^2, rad/s^2).",
        "  trim positions (deg): " + ", ".join(f"{s.name} {p:.4f}" for s, p in zip(SURFACES, lin.trim_positions,
                                                                                   strict=True)),
        "Every state, output and effector is a deviation from that trim; effector limits are the stock",
        "FCS's (stabilator +-30, nozzle +-20, aileron +-25, rudder +-30 deg) minus the trim position, rates",
        "the stock actuators' rate limits; first-order bandwidths are our choice (the file has none).",
        f"Finite differences: state steps {dict(zip(STATES, STATE_STEPS, strict=True))}, effector step "
        f"{EFFECTOR_STEP} deg; column = mean of the one-sided differences.",
    ]
    for name, (fwd, bwd) in lin.one_sided.items():
        if name in EFFECTORS:
            rows = [STATES.index(ch) for ch in CONTROLLED]
            lines.append(f"Kink at the trim in {name}: one-sided q/p/r-dot rows forward "
                         f"{np.round(fwd[rows], 5).tolist()}, backward {np.round(bwd[rows], 5).tolist()} "
                         "(the model holds their mean).")
        else:
            lines.append(f"Kink at the trim in state {name}: forward and backward columns differ by more than "
                         f"{KINK_RTOL:.0%}; the model holds their mean.")
    return lines


def write_vehicle(lin: Linearisation, path: str | Path) -> Path:
    """Write ``lin``'s vehicle file with its provenance in comments; read it back through the validator."""
    from alloc.vehicle_file import load_vehicle, to_toml

    text = "".join(f"# {line}\n" for line in _provenance(lin)) + "\n" + to_toml(vehicle_document(lin))
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text, encoding="utf-8")
    load_vehicle(path)  # the file must read back: its validator names any bad field
    return path


# --------------------------------------------------------------------------- how much B moves
def b_envelope(condition: TrimCondition | None = None, *, qbar_fraction: float = 0.2,
               alpha_offset_deg: float = 3.0) -> dict[str, Any]:
    """Relative change of each allocator column of ``B_axes`` over an envelope around the trim.

    Dynamic pressure ``+-qbar_fraction``: re-trimmed at the same altitude at the Mach that gives
    it (alpha re-trims too).  Alpha ``+-alpha_offset_deg``: the trim state with alpha offset (a
    pull-up or push-over at the trim's airspeed, not an equilibrium; ``B`` is the effectors'
    derivative there).  Each entry is ``|B_j - B0_j| / |B0_j|`` over the q, p, r rows.
    """
    base_cond = condition or TrimCondition()
    base = linearise(base_cond)
    cases: dict[str, Linearisation] = {}
    for sign in (-1, 1):
        mach = base_cond.mach * math.sqrt(1 + sign * qbar_fraction)
        cases[f"qbar {sign * qbar_fraction:+.0%}"] = linearise(
            TrimCondition(mach=mach, altitude_ft=base_cond.altitude_ft, gamma_deg=base_cond.gamma_deg))
    sim = F22(base_cond)
    for sign in (-1, 1):
        x = sim.trim_state.copy()
        x[STATES.index("alpha")] += sign * alpha_offset_deg
        cases[f"alpha {sign * alpha_offset_deg:+g} deg"] = linearise(f22=sim, at_state=x)
    B0 = base.B_axes
    table = {}
    for label, lin in cases.items():
        change = np.linalg.norm(lin.B_axes - B0, axis=0) / np.linalg.norm(B0, axis=0)
        table[label] = dict(zip(EFFECTORS, (float(v) for v in change), strict=True))
    return {"base": base, "cases": cases, "relative_change": table}


def effector_survey(lin: Linearisation) -> dict[str, dict[str, float]]:
    """Per surface (flaps included): q, p, r-dot per degree and the alpha-dot per degree, for the docs."""
    rows = {k: STATES.index(k) for k in ("q", "p", "r", "alpha")}
    return {s.name: {f"{k}_dot": float(lin.B_all[i, j]) for k, i in rows.items()} for j, s in enumerate(SURFACES)}


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m sim.plants.jsbsim_linear",
                                     description="Linearise JSBSim's F-22 at a trim and write its vehicle file.")
    parser.add_argument("--out", type=Path, default=VEHICLE_FILE, help="vehicle file to write")
    parser.add_argument("--mach", type=float, default=TrimCondition.mach)
    parser.add_argument("--altitude-ft", type=float, default=TrimCondition.altitude_ft)
    parser.add_argument("--envelope", action="store_true", help="print the B envelope table as well")
    args = parser.parse_args(argv)
    jsbsim_root()
    cond = TrimCondition(mach=args.mach, altitude_ft=args.altitude_ft)
    lin = linearise(cond)
    print(f"wrote {write_vehicle(lin, args.out)}")
    for name, row in effector_survey(lin).items():
        print(f"  {name:8s} " + "  ".join(f"{k} {v:+.4f}" for k, v in row.items()))
    if args.envelope:
        env = b_envelope(cond)
        print("relative change of B columns (q, p, r-dot rows):")
        print("  case           " + "  ".join(f"{e:>8s}" for e in EFFECTORS))
        for label, row in env["relative_change"].items():
            print(f"  {label:14s} " + "  ".join(f"{row[e]:8.1%}" for e in EFFECTORS))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

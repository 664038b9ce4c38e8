"""Where the seed's aircraft fly: the flight conditions (``--turbulence``, :mod:`sim.world`).

The vehicle files carry the seed's models but not where they fly (the format has no field for
it); these are the conditions of the files' models, found by their ``A``
(:func:`flight_of_seed_model`), so that a scenario and its file fly the same air.  Below the
scenarios and :mod:`sim.file_scenario`, which both read it.
"""

from __future__ import annotations

import numpy as np

from alloc.vehicles import bundled
from sim.model import FlightCondition

__all__ = ["ICE_KINEMATIC", "HARV_LATDIR_ALTITUDE", "HARV_LATDIR_SPEED", "ice", "harv_latdir",
           "flight_of_seed_model"]


# Kinematic elements of A kept at their nominal value by the plant failure ("A-matrix
# is multiplied by 2 -- with the exception of the elements describing kinematic
# relationships", seed section 4.7): the theta and phi rows, the gravity terms
# (theta column in u', w'; phi column in v') and the inertial U0, W0 terms
# (q in u', w'; p, r in v'), identified by value (U0 pi/180 = 5.374, g pi/180 cos(theta0) = 0.545).
ICE_KINEMATIC = np.zeros((8, 8), dtype=bool)  # states u w qb theta v pb rb phi
ICE_KINEMATIC[[3, 7], :] = True
ICE_KINEMATIC[[0, 1], 3] = True
ICE_KINEMATIC[4, 7] = True
ICE_KINEMATIC[[0, 1], 2] = True
ICE_KINEMATIC[4, [5, 6]] = True


def ice() -> FlightCondition:
    """Where ICE flies and what the air moves (``--turbulence``, :mod:`sim.world`).

    seed section 4.7 ("1g, wings-level, M = 0.3, h = 15,000 ft", line 3258 of the OCR'd seed):
    15,000 ft and M 0.3 with the standard atmosphere's 1057.4 ft/s there, V = 317.2 ft/s -- the
    model agrees: the inertial terms of A are U0 pi/180 = 5.3737 and W0 pi/180 = 1.3310, so
    sqrt(U0^2 + W0^2) = 317.2 ft/s.  States u, w, v in ft/s and qb, pb, rb in deg/s (seed
    section 4.7 state list); the aerodynamic entries of A are those the plant failure doubles
    (not :data:`ICE_KINEMATIC`).  Span 37.5 ft: ours (the seed gives none; a fighter's, the F/A-18's).
    """
    deg = 180.0 / np.pi
    s = bundled("ice").model.states.index  # type: ignore[union-attr]  # ice.toml has a model
    return FlightCondition(
        altitude=15000.0, speed=317.2, span=37.5,
        gust_states=((s("u"), "u", 1.0), (s("w"), "w", 1.0), (s("v"), "v", 1.0), (s("pb"), "p", deg),
                     (s("qb"), "q", deg), (s("rb"), "r", deg)),
        aero=~ICE_KINEMATIC, source="seed section 4.7: M 0.3, 15,000 ft; span ours")


#: ft, ft/s: the seed gives no altitude or speed for Eq 4.16 ("this low speed, high angle of attack,
#: flight condition", section 4.6, line 2912 of the OCR'd seed); ours: 25,000 ft and 250 ft/s
#: (about M 0.25), a HARV high-alpha test point's order of magnitude at alpha0 = 29.7 deg
HARV_LATDIR_ALTITUDE, HARV_LATDIR_SPEED = 25000.0, 250.0


def harv_latdir() -> FlightCondition:
    """Where the HARV lat-dir model flies (ours, :data:`HARV_LATDIR_ALTITUDE`, :data:`HARV_LATDIR_SPEED`) and what the air moves:
    sideslip (deg) sees ``v_g / V``, the body rates (deg/s) ``p_g, r_g``; span 37.5 ft (the F/A-18's)."""
    deg = 180.0 / np.pi
    return FlightCondition(altitude=HARV_LATDIR_ALTITUDE, speed=HARV_LATDIR_SPEED, span=37.5,
                           gust_states=((0, "v", deg / HARV_LATDIR_SPEED), (1, "p", deg), (2, "r", deg)),
                           source="ours: the seed gives no altitude or speed for Eq 4.16")


def flight_of_seed_model(A: np.ndarray) -> FlightCondition | None:
    """The flight condition of a seed model given its ``A`` (ICE, HARV lat-dir, HARV lon), else None."""
    from sim.scenarios import harv_lon  # its model is no file's yet

    A = np.asarray(A, dtype=float)
    seed = ((bundled("ice").model, ice), (bundled("harv").model, harv_latdir))
    for model, condition in seed:
        mine = np.asarray(model.arrays()[0]) if model is not None else None
        if mine is not None and A.shape == mine.shape and np.allclose(A, mine, rtol=1e-9, atol=0.0):
            return condition()
    if A.shape == harv_lon.A.shape and np.allclose(A, harv_lon.A, rtol=1e-9, atol=0.0):
        return harv_lon.flight_condition()
    return None

"""The F-22 vehicle file measured from JSBSim, flown in the project's own linear loop (no jsbsim needed)."""

from __future__ import annotations

import numpy as np

from sim.plants.jsbsim_linear import VEHICLE_FILE
from sim.user_vehicle import fly

# the one design option the F-22 model needs changed (sim.plants.jsbsim_loop.DESIGN_OPTIONS says why)
DESIGN = {"stability_margin": 0.005}


def test_linear_loop_stabilator_jam_at_trim_told_flies_blind_diverges():
    told = fly(VEHICLE_FILE, design=DESIGN, failure="jam:stab_l@0", health="told")
    blind = fly(VEHICLE_FILE, design=DESIGN, failure="jam:stab_l@0", health="blind")
    # measured: told flies 20 s; blind diverges at 16.65 s, 6.65 s after the failure at 10 s, as the
    # nonlinear JSBSim loop does 4.6 s after its failure (docs/plants-jsbsim.md)
    assert not told.diverged
    assert blind.diverged
    assert np.isfinite(told.t[-1]) and told.t[-1] >= 19.99

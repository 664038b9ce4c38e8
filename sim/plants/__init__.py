"""Third-party nonlinear plants of the closed loop (the optional ``[plants]`` extra); see :mod:`sim.plant`."""

"""Plants of the closed loop beyond the compiled linear engine (:mod:`sim.plant` states the contract)."""

"""Pilot models (sim.pilot): the crossover rule and the stand-in."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import signal

from sim.pilot import CROSSOVER_NEUROMUSCULAR, crossover_gain, pilot_parameters
from sim.scenarios import harv_latdir, harv_lon, ice


@pytest.mark.parametrize("module", [ice, harv_lon, harv_latdir])
def test_crossover_gain_gives_the_stated_phase_margin(module):
    """Independent check with scipy.signal: |L(j w_c)| = 1 and arg L(j w_c) = -180 + 45 deg."""
    num, den = module.PILOT_ELEMENT
    params = pilot_parameters("crossover", module.PILOT_ELEMENT)
    k, tau, tn = params["gain"], params["delay"], params["neuromuscular"]
    assert tn == CROSSOVER_NEUROMUSCULAR
    loop = signal.TransferFunction(np.polymul([k], num), np.polymul(den, [tn, 1.0]))
    w = np.geomspace(0.05, 50.0, 20000)
    _, h = signal.freqresp(loop, w)
    i = int(np.argmin(np.abs(np.abs(h) - 1.0)))
    phase = np.degrees(np.unwrap(np.angle(h))[i] - w[i] * tau)
    assert abs(h[i]) == pytest.approx(1.0, abs=2e-3)
    assert phase == pytest.approx(-135.0, abs=0.2)
    _, wc = crossover_gain(num, den)
    assert w[i] == pytest.approx(wc, rel=2e-3)


def test_standin_is_the_original_pilot_and_overrides_apply():
    assert pilot_parameters("standin", ice.PILOT_ELEMENT) == {"gain": 2.0, "delay": 0.2, "model": "standin"}
    p = pilot_parameters("crossover", ice.PILOT_ELEMENT, gain=1.5, delay=0.3)
    assert (p["gain"], p["delay"]) == (1.5, 0.3)
    with pytest.raises(ValueError, match="pilot"):
        pilot_parameters("hess", ice.PILOT_ELEMENT)


def test_crossover_pilot_flies_and_is_recorded():
    r = ice.run(method="static", duration=1.0, noise=False, pilot="crossover")
    (p,) = r.settings["pilots"]
    assert p["model"] == "crossover" and p["neuromuscular"] == CROSSOVER_NEUROMUSCULAR
    assert p["gain"] == pytest.approx(pilot_parameters("crossover", ice.PILOT_ELEMENT)["gain"])
    assert not r.diverged and np.any(r.command[:, 1] != 0.0)

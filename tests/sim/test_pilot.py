"""Pilot models (sim.pilot): the crossover rule and the stand-in."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import signal

from sim.pilot import (
    CROSSOVER_DELAY, CROSSOVER_NEUROMUSCULAR, CROSSOVER_WC_DELAY, CROSSOVER_WC_FREQUENCY, crossover_gain, crossover_point,
    forcing_bandwidth, gain_for_crossover, pilot_parameters,
)
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


@pytest.mark.parametrize("module", [ice, harv_lon, harv_latdir])
@pytest.mark.parametrize("margin", [30.0, 45.0, 60.0])
def test_crossover_point_inverts_the_crossover_rule(module, margin):
    k, wc = crossover_gain(*module.PILOT_ELEMENT, phase_margin=margin)
    w, pm = crossover_point(*module.PILOT_ELEMENT, gain=k, delay=CROSSOVER_DELAY, neuromuscular=CROSSOVER_NEUROMUSCULAR)
    assert (w, pm) == pytest.approx((wc, margin), rel=1e-6)


def test_crossover_point_of_the_standin_checked_with_scipy():
    """Independent check: |L(j w_c)| = 1 and the phase margin from scipy.signal's frequency response."""
    num, den = harv_latdir.PILOT_ELEMENT
    wc, pm = crossover_point(num, den, gain=2.0, delay=0.2)
    _, h = signal.freqresp(signal.TransferFunction(np.polymul([2.0], num), den), [wc])
    assert abs(h[0]) == pytest.approx(1.0, rel=1e-9)
    assert pm == pytest.approx(180.0 + np.degrees(np.angle(h[0]) - wc * 0.2), abs=1e-6)
    assert 1.5 < wc < 2.5 and 20.0 < pm < 35.0  # the stand-in flies HARV lat-dir at a 27 deg margin


@pytest.mark.parametrize("gain", [0.0, -1.0, float("nan"), float("inf")])
def test_crossover_point_rejects_a_bad_gain(gain):
    with pytest.raises(ValueError, match="gain"):
        crossover_point(*ice.PILOT_ELEMENT, gain=gain, delay=0.1)


def test_alpha_pilot_closes_the_seed_s_alpha_loop_and_is_off_by_default():
    k, _ = crossover_gain(*ice.ALPHA_PILOT_ELEMENT, lag=ice.ALPHA_PILOT_LAG)
    wc, pm = crossover_point(*ice.ALPHA_PILOT_ELEMENT, gain=k, delay=CROSSOVER_DELAY,
                             neuromuscular=CROSSOVER_NEUROMUSCULAR, lag=ice.ALPHA_PILOT_LAG)
    assert pm == pytest.approx(45.0, abs=1e-6) and 1.0 < wc < 5.0
    off = ice.run(method="pinv", duration=0.5, noise=False)
    assert [p["name"] for p in off.settings["pilots"]] == ["phi"]
    same = ice.run(method="pinv", duration=0.5, noise=False, alpha_pilot=False)
    assert np.array_equal(off.output, same.output)
    on = ice.run(method="pinv", duration=0.5, noise=False, alpha_pilot=True)
    alpha = on.settings["pilots"][1]
    assert (alpha["name"], alpha["lag"], alpha["gain"]) == ("alpha", ice.ALPHA_PILOT_LAG, pytest.approx(k))
    assert not np.array_equal(on.command[:, 0], off.command[:, 0])  # the pilot, not the sum of sines, commands alpha
    with pytest.raises(TypeError, match="alpha_pilot"):
        ice.run(method="pinv", duration=0.1, alpha_pilot="yes")


# ----------------------------------------------------------------------------- crossover_wc
@pytest.mark.parametrize("module", [ice, harv_lon, harv_latdir])
@pytest.mark.parametrize("wc", [0.5, 1.0, 2.0, 3.0])
def test_gain_for_crossover_puts_the_crossover_there_checked_with_scipy(module, wc):
    """Independent check: scipy.signal's |K_p Y_c(j w_c)| = 1, and crossover_point reads w_c back."""
    num, den = module.PILOT_ELEMENT
    k = gain_for_crossover(num, den, wc)
    _, h = signal.freqresp(signal.TransferFunction(np.polymul([k], num), den), [wc])
    assert abs(h[0]) == pytest.approx(1.0, rel=1e-9)
    w, pm = crossover_point(num, den, gain=k, delay=0.2)
    assert w == pytest.approx(wc, rel=1e-9)
    assert pm == pytest.approx(180.0 + np.degrees(np.angle(h[0]) - wc * 0.2), abs=1e-6)


def test_gain_for_crossover_on_seeded_k_over_s_elements():
    """Y_c = K / (s (T s + 1)) has |Y_c(j w)| = K / (w sqrt(1 + (w T)^2)): the gain is its inverse."""
    rng = np.random.default_rng(27)
    for _ in range(40):
        k_c, t_c, wc = rng.uniform(0.1, 50.0), rng.uniform(0.0, 0.5), rng.uniform(0.1, 10.0)
        expected = wc * np.sqrt(1.0 + (wc * t_c) ** 2) / k_c
        assert gain_for_crossover([k_c], [t_c, 1.0, 0.0], wc) == pytest.approx(expected, rel=1e-12)


@pytest.mark.parametrize("wc", [0.0, -1.0, float("nan"), float("inf")])
def test_gain_for_crossover_rejects_a_bad_frequency(wc):
    with pytest.raises(ValueError, match="crossover"):
        gain_for_crossover(*ice.PILOT_ELEMENT, wc)


def test_crossover_wc_rule_states_its_crossover_and_flies():
    for module in (ice, harv_latdir):
        p = pilot_parameters("crossover_wc", module.PILOT_ELEMENT)
        assert (p["delay"], p["model"]) == (CROSSOVER_WC_DELAY, "crossover_wc")
        wc, _ = crossover_point(*module.PILOT_ELEMENT, gain=p["gain"], delay=p["delay"])
        assert wc == pytest.approx(CROSSOVER_WC_FREQUENCY, rel=1e-9)
    assert pilot_parameters("crossover_wc", ice.PILOT_ELEMENT, delay=0.3)["delay"] == 0.3
    r = ice.run(method="static", duration=1.0, noise=False, pilot="crossover_wc")
    (flown,) = r.settings["pilots"]
    assert flown["model"] == "crossover_wc" and flown["neuromuscular"] == 0.0
    assert not r.diverged and np.any(r.command[:, 1] != 0.0)


def test_forcing_bandwidth_of_the_seed_s_sum_of_sines():
    # seed Table 4-2: amplitudes 1, 1, 1 to 0.898 rad/s, 0.5 at 1.396 rad/s, then 0.2, 0.2, 0.08
    assert forcing_bandwidth() == 1.39626
    assert forcing_bandwidth(fraction=1.0) == 0.89760
    assert forcing_bandwidth(fraction=0.2) == 4.19970
    assert forcing_bandwidth([(3.0, 2.0), (-6.0, 1.0)]) == 2.0  # |amplitude|, not its sign
    with pytest.raises(ValueError, match="fraction"):
        forcing_bandwidth(fraction=0.0)
    with pytest.raises(ValueError, match="table"):
        forcing_bandwidth([])

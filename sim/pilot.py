"""Pilot models for the compensatory attitude loops (the seed's Figs 4-6, 4-41, 4-86 are images).

Two rules set the :class:`sim.loop.Pilot` parameters:

``standin``
    The project's original stand-in: ``command = 2 (att_cmd - att)`` delayed
    0.2 s.  Kept for comparison with earlier results; its numbers are not
    derived from anything.

``crossover``
    McRuer's crossover model (McRuer & Krendel; McRuer & Jex 1967): the pilot
    adapts so that, around crossover, the open pilot-vehicle loop is
    ``Y_p Y_c ~ w_c e^{-tau_e s} / s``.  The pilot is the precision model
    ``Y_p = K_p (T_L s + 1) / ((T_I s + 1)(T_N s + 1)) e^{-tau s}``.  Every
    controlled element here is a rate-command attitude loop (the reference
    model followed by an integration, ``Y_c ~ K/s`` below the reference
    model's bandwidth), for which the crossover model calls for neither lead
    nor lag (``T_L = T_I = 0``).  Fixed human-operator constants (ours, from
    the commonly quoted ranges): transport delay ``tau = 0.1 s`` and
    neuromuscular lag ``T_N = 0.1 s`` (together an effective delay of about
    0.2 s at low frequency).  The gain is *not* chosen: ``K_p`` is the one
    that gives the pilot-vehicle loop a phase margin of 45 deg on the
    scenario's controlled element ``Y_c`` (reference model times the
    attitude integration the pilot closes on).  The gain follows from the
    reference model; no verdict enters the rule.

``pilot_gain`` / ``pilot_delay`` given explicitly override the rule's values
(used by the robustness maps to sweep around them).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from scipy import optimize

__all__ = ["PILOT_MODELS", "CROSSOVER_DELAY", "CROSSOVER_NEUROMUSCULAR", "CROSSOVER_PHASE_MARGIN",
           "crossover_gain", "pilot_parameters"]

PILOT_MODELS = ("standin", "crossover")
#: stand-in values (project's original pilot)
STANDIN_GAIN, STANDIN_DELAY = 2.0, 0.2
#: crossover-model constants: transport delay (s), neuromuscular lag (s), phase margin (deg)
CROSSOVER_DELAY = 0.1
CROSSOVER_NEUROMUSCULAR = 0.1
CROSSOVER_PHASE_MARGIN = 45.0


def _loop_phase(w: float, num: Sequence[float], den: Sequence[float], delay: float, tn: float) -> float:
    """Unwrapped phase (rad) of ``Y_c(jw) e^{-jw delay} / (jw tn + 1)``."""
    # Y_c has an integrator: its phase lies in (-pi/2 - n pi/2, -pi/2]; unwrap from low frequency.
    ws = np.geomspace(1e-3, w, 400)
    ph = np.unwrap(np.angle(np.polyval(num, 1j * ws) / np.polyval(den, 1j * ws)))[-1]
    return float(ph - w * delay - np.arctan(w * tn))


def crossover_gain(
    num: Sequence[float], den: Sequence[float], *, delay: float = CROSSOVER_DELAY,
    neuromuscular: float = CROSSOVER_NEUROMUSCULAR, phase_margin: float = CROSSOVER_PHASE_MARGIN,
) -> tuple[float, float]:
    """Pilot gain ``K_p`` and crossover frequency ``w_c`` (rad/s) for a phase margin on ``Y_c = num/den``.

    Solves ``arg(Y_c(j w_c) e^{-j w_c delay} / (j w_c T_N + 1)) = -180 deg + phase_margin``
    and sets ``K_p = 1 / |Y_c(j w_c) / (j w_c T_N + 1)|``.
    """
    target = np.radians(phase_margin - 180.0)
    f = lambda w: _loop_phase(w, num, den, delay, neuromuscular) - target  # noqa: E731
    w_hi = 1e-2
    while f(w_hi) > 0.0:
        w_hi *= 1.5
        if w_hi > 1e3:
            raise ValueError("Y_c: no crossover frequency reaches the phase margin")
    wc = float(optimize.brentq(f, 1e-3, w_hi, xtol=1e-10))
    s = 1j * wc
    mag = abs(np.polyval(num, s) / np.polyval(den, s) / (s * neuromuscular + 1.0))
    return 1.0 / mag, wc


def pilot_parameters(
    model: str, controlled_element: tuple[Sequence[float], Sequence[float]], *,
    gain: float | None = None, delay: float | None = None,
) -> dict[str, Any]:
    """Keyword arguments of :class:`sim.loop.Pilot` for ``model`` (see the module docstring).

    ``controlled_element`` is ``(num, den)`` of what the pilot flies, stick to attitude.
    ``gain`` / ``delay`` override the rule's values.
    """
    if model == "standin":
        return {"gain": STANDIN_GAIN if gain is None else float(gain),
                "delay": STANDIN_DELAY if delay is None else float(delay), "model": "standin"}
    if model == "crossover":
        tau = CROSSOVER_DELAY if delay is None else float(delay)
        kp, _ = crossover_gain(*controlled_element, delay=tau)
        return {"gain": float(kp) if gain is None else float(gain), "delay": tau,
                "neuromuscular": CROSSOVER_NEUROMUSCULAR, "model": "crossover"}
    raise ValueError(f"pilot: unknown pilot model {model!r}; expected one of {PILOT_MODELS}")

"""Every verdict-driving choice of the closed-loop comparison, in one machine-readable list.

A verdict-driving choice can change whether a run stays bounded or which method does better.
:func:`verdict_choices` lists each with its value, its source (a seed section or ``"ours"``:
the project's own choice, with no source in the seed) and where it is set.  The run settings
flagged verdict-driving (:class:`sim.settings.Setting` ``verdict``) are read from
:class:`sim.settings.RunSettings` itself, never re-listed; the others are read from the
constants that set them.  :func:`render_markdown` writes ``docs/verdict-choices.md`` (a test
checks the committed page against it).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import MISSING, dataclass, fields

import numpy as np

from alloc import vehicles
from sim import criteria, pilot
from sim.blocks import band_limited_noise
from sim.scenarios import harv_latdir, ice
from sim.settings import SETTING, RunSettings

__all__ = ["Choice", "verdict_choices", "render_markdown"]


@dataclass(frozen=True)
class Choice:
    """One verdict-driving choice: its name, value as text, source (seed section or ``"ours"``) and where it is set."""

    name: str
    value: str
    source: str
    where: str
    note: str = ""


#: Sources of the run settings' defaults; a setting not named here is ours.
_SETTING_SOURCES = {
    "dt": "seed section 4.5 (fixed step 0.5 ms)",
    "noise": "seed sections 4.6, 4.7 (noise gains)",
    "noise_scale": "seed sections 4.6, 4.7 (1 = the seed's gains)",
    "actuators": "seed section 4.7 (actuator models)",
    "frame_period": "seed section 4.5 (single-rate 2 kHz loop)",
    "rate_aware": "seed Eq 1.28",
    "u_prev_source": "seed Eq 1.28 (u_prev: the previous command)",
    "controller": "seed section 4.3 (observer-based SMC with hedging)",
    "method": "seed sections 4.6, 4.7 (pinv for ICE, ganging for the HARV)",
    "failure": "seed sections 4.6, 4.7",
    "failure_time": "seed sections 4.6, 4.7",
    "duration": "seed sections 4.6, 4.7",
    # the world's defaults are the seed's: its plant is its model, its noise Gaussian, its air still
    "model_error": "seed sections 4.5-4.7 (the simulated plant is the design model)",
    "noise_model": "seed sections 4.6, 4.7 (band-limited Gaussian noise)",
    "turbulence": "seed sections 4.5-4.7 (no turbulence)",
}


def _text(value: object) -> str:
    if isinstance(value, np.ndarray):
        return ", ".join(f"{x:g}" for x in value)
    if isinstance(value, float):
        return f"{value:g}"
    return str(value)


def _settings() -> list[Choice]:
    out = []
    for f in fields(RunSettings):
        spec = f.metadata[SETTING]
        if not spec.verdict:
            continue
        default = None if f.default is MISSING else f.default
        value = spec.none_means if default is None and spec.none_means else _text(default)
        out.append(Choice(name=f"setting {f.name}", value=value, source=_SETTING_SOURCES.get(f.name, "ours"),
                          where=f"sim/settings.py RunSettings.{f.name} ({spec.flag})", note=spec.help))
    return out


def _standin_loops() -> str:
    """The stand-in pilot's loop on each scenario's controlled element, as crossover frequency and phase margin."""
    parts = []
    for name, module in (("ICE", ice), ("HARV lat-dir", harv_latdir)):
        wc, pm = pilot.crossover_point(*module.PILOT_ELEMENT, gain=pilot.STANDIN_GAIN, delay=pilot.STANDIN_DELAY)
        parts.append(f"{name}: crossover {wc:.2f} rad/s, phase margin {pm:.0f} deg")
    return "; ".join(parts)


def _crossover_wc_loops() -> str:
    """The crossover_wc pilot's phase margin on each scenario's controlled element at its defaults."""
    parts = []
    for name, module in (("ICE", ice), ("HARV lat-dir", harv_latdir)):
        p = pilot.pilot_parameters("crossover_wc", module.PILOT_ELEMENT)
        _, pm = pilot.crossover_point(*module.PILOT_ELEMENT, gain=p["gain"], delay=p["delay"])
        parts.append(f"{name}: gain {p['gain']:.3g}, phase margin {pm:.0f} deg")
    return "; ".join(parts)


def _ice_noise_gains() -> str:
    gains = dict(zip(ice.OUTPUTS, ice.vehicle().noise_gains, strict=True))
    values = sorted(set(gains.values()), key=lambda g: -sum(v == g for v in gains.values()))
    others = ", ".join(f"{n} {g:g}" for n, g in gains.items() if g != values[0])
    return f"{values[0]:g} on every output" + (f" but {others}" if others else "")


def verdict_choices() -> list[Choice]:
    """Every verdict-driving choice, settings first (module docstring)."""
    daisy = vehicles.method_options("ice", "daisy", None)["groups"]
    return [
        *_settings(),
        Choice("pilot model", "stand-in: gain times delayed error", "ours", "sim/pilot.py PILOT_MODELS",
               "the seed's pilot is Hess's structural model (its refs 138, 144, 145); not implemented. The "
               "crossover and crossover_wc rules' forms are McRuer & Krendel 1974, their numbers are ours: "
               "McRuer & Jex 1967's regressions of tau_e and w_c on w_i could not be verified here, so none is "
               "used (sim/pilot.py)"),
        Choice("stand-in pilot gain", _text(pilot.STANDIN_GAIN), "ours", "sim/pilot.py STANDIN_GAIN",
               _standin_loops()),
        Choice("stand-in pilot delay", f"{pilot.STANDIN_DELAY:g} s", "ours", "sim/pilot.py STANDIN_DELAY"),
        Choice("stand-in pilot neuromuscular lag", "0 s (none)", "ours", "sim/pilot.py pilot_parameters"),
        Choice("crossover pilot delay", f"{pilot.CROSSOVER_DELAY:g} s", "ours (no source)",
               "sim/pilot.py CROSSOVER_DELAY"),
        Choice("crossover pilot neuromuscular lag", f"{pilot.CROSSOVER_NEUROMUSCULAR:g} s", "ours (no source)",
               "sim/pilot.py CROSSOVER_NEUROMUSCULAR"),
        Choice("crossover pilot phase margin", f"{pilot.CROSSOVER_PHASE_MARGIN:g} deg", "ours",
               "sim/pilot.py CROSSOVER_PHASE_MARGIN"),
        Choice("crossover_wc pilot crossover frequency", f"{pilot.CROSSOVER_WC_FREQUENCY:g} rad/s", "ours",
               "sim/pilot.py CROSSOVER_WC_FREQUENCY",
               f"about the stand-in's; w_c / w_i = {pilot.CROSSOVER_WC_FREQUENCY / pilot.forcing_bandwidth():.2f}. "
               + _crossover_wc_loops()),
        Choice("crossover_wc pilot effective delay", f"{pilot.CROSSOVER_WC_DELAY:g} s", "ours",
               "sim/pilot.py CROSSOVER_WC_DELAY", "transport delay and neuromuscular lag in one (crossover model)"),
        Choice("forcing-function bandwidth w_i", f"{pilot.forcing_bandwidth():.3g} rad/s",
               "ours (rule: the highest seed Table 4-2 frequency with at least "
               f"{pilot.FORCING_AMPLITUDE_FRACTION:g} x the largest amplitude)",
               "sim/pilot.py forcing_bandwidth", "every sum-of-sines input (xi scales amplitudes only); the Fig "
               "4-81 filtered steps have none; informs w_c / w_i only, sets no pilot parameter"),
        Choice("ICE alpha pilot", "off: the alpha sum-of-sines goes straight into the reference model "
               "(alpha_pilot=True closes the loop)",
               "ours (the seed closes a pilot loop on alpha, Figs 4-85, 4-86)", "sim/scenarios/ice.py _pilots",
               f"on: the crossover rule with a lag of {ice.ALPHA_PILOT_LAG:g} s (ours) on the alpha reference model"),
        Choice("Fig 4-81 bank-angle steps", ", ".join(f"{lv:g} deg at {t:g} s" for t, lv in
                                                     zip(harv_latdir.STEP_TIMES, harv_latdir.STEP_LEVELS,
                                                         strict=True)),
               "ours (the seed's figure shows filtered steps; sizes and times are not printed)",
               "alloc/data/vehicles/harv.toml [simulation.pilot.commands.filtered_steps]"),
        Choice("daisy groups (ICE)", " | ".join(", ".join(g) for g in daisy), "ours",
               "alloc/data/vehicles/ice.toml [methods.daisy] groups"),
        Choice("divergence bound ICE", f"|alpha| {ice.OUTPUT_BOUND[0]:g} deg, |p_s| {ice.OUTPUT_BOUND[1]:g} deg/s, "
               f"|beta| {ice.OUTPUT_BOUND[2]:g} deg", "ours", "alloc/data/vehicles/ice.toml [simulation] output_bound"),
        Choice("divergence bound HARV lat-dir", f"|beta| {harv_latdir.OUTPUT_BOUND[0]:g} deg, "
               f"|p_s| {harv_latdir.OUTPUT_BOUND[1]:g} deg/s", "ours", "alloc/data/vehicles/harv.toml [simulation] output_bound"),
        Choice("noise model", "band-limited white noise (power 0.1, 10 ms hold) through 100/(s^2 + 20 s + 100) "
               "times the output gains", "seed sections 4.6, 4.7 (Simulink block and gains)",
               f"sim/blocks.py {band_limited_noise.__name__}"),
        Choice("noise gains ICE", _ice_noise_gains(), "seed section 4.7", "alloc/data/vehicles/ice.toml [simulation] noise"),
        Choice("noise gains HARV lat-dir", _text(harv_latdir.vehicle().noise_gains), "seed section 4.6",
               "alloc/data/vehicles/harv.toml [simulation] noise"),
        # the engineering pass/fail limits no standard or the seed gives (sim.criteria decides each
        # run's verdict with them)
        *(Choice(name, value, "ours", "sim/criteria.py", why) for name, value, why in criteria.free_parameters()),
    ]


def render_markdown(flips: Mapping[str, str] | None = None, sweep: str = "") -> str:
    """``docs/verdict-choices.md``: the choices as one table.

    ``flips`` maps a choice's name to its one-factor sensitivity in words (the ``flips`` column;
    ``benchmarks.bench_sensitivity.flips_by_choice`` of the committed sweep); ``sweep`` names
    that sweep's folder.  A choice the sweep did not move says "not swept".
    """
    intro = ("Generated by `sim.choices.render_markdown()` from the sweep's `flips.csv` (a test checks this "
             "page against both). \"ours\" marks a choice the project made with no source in the seed.")
    if flips is not None:
        intro += (f" The flips column is the one-factor sensitivity sweep `{sweep}` "
                  "(`benchmarks/bench_sensitivity.py`; its `report.md` lists every flipped run): each choice "
                  "moved alone over the stated levels, ICE and HARV lat-dir (Fig 4-81 input), told static, "
                  "pinv, qp and wls, failed and nominal (some factors failed only, the sampled-data settings at "
                  "2000 and 100 Hz: see the report), 40 s; a flip is a bounded/diverged verdict that "
                  "changes against the default, \"+ best\" a change of the best bounded method.")
    lines = ["# Every verdict-driving choice", "", intro, "",
             "| choice | value | source | where it is set | note |" + (" flips |" if flips is not None else ""),
             "|---|---|---|---|---|" + ("---|" if flips is not None else "")]
    for c in verdict_choices():
        cells = [c.name, c.value, c.source, c.where, c.note]
        if flips is not None:
            cells.append(flips.get(c.name, "not swept"))
        lines.append("| " + " | ".join(x.replace("|", "\\|") for x in cells) + " |")
    return "\n".join(lines) + "\n"

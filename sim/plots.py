"""PNG plots of a :class:`sim.result.SimResult`: tracking per channel, effector positions and rates.

Channels carry the seed's names and units (``alpha`` deg, ``p_s`` deg/s,
``beta`` deg), or a vehicle file's names and units (``result.settings["units"]``,
:mod:`sim.user_vehicle`: rotors in their own unit, not degrees); effectors the
vehicle's names, one colour each (tab20 cycle);
the failure time is a labelled line; the run's settings are in the title.
Uses :class:`matplotlib.figure.Figure` directly, so no backend is chosen here.
"""

from __future__ import annotations

from pathlib import Path

from matplotlib import colormaps
from matplotlib.figure import Figure

from sim.result import SimResult

__all__ = ["CHANNEL_LABELS", "channel_label", "plot_result", "settings_line"]

#: internal channel name -> (seed symbol, unit)
CHANNEL_LABELS: dict[str, tuple[str, str]] = {
    "alphaw": ("alpha", "deg"), "alpha": ("alpha", "deg"), "betaw": ("beta", "deg"), "beta": ("beta", "deg"),
    "ps": ("p_s", "deg/s"), "p": ("p", "deg/s"), "q": ("q", "deg/s"), "r": ("r", "deg/s"),
    "phi": ("phi", "deg"), "theta": ("theta", "deg"),
}


def channel_label(name: str) -> str:
    """``"alpha (deg)"`` for ``"alphaw"``; unknown names are shown as they are."""
    symbol, unit = CHANNEL_LABELS.get(name, (name, ""))
    return f"{symbol} ({unit})" if unit else symbol


def settings_line(result: SimResult) -> str:
    """One line of the run's settings (method, failure, frame rate, Eq 1.28, told, noise, pilot)."""
    s = result.settings
    parts = [f"{result.scenario}", f"method={result.method}", f"failure={result.failure}"]
    if s:
        parts.append(f"frame {1.0 / s['frame_period']:.0f} Hz")
        parts.append("rate-aware" if s.get("rate_aware") else "rate-blind")
        parts.append(s.get("health") or ("told" if s.get("allocator_knows_failure") else "blind"))
        parts.append("noise" if s.get("noise") else "no noise")
        for p in s.get("pilots", []):
            parts.append(f"pilot {p['model']} K={p['gain']:.2f} tau={p['delay']:.2f}s")
    return "  ".join(parts)


def _units(result: SimResult) -> tuple[dict[str, str], str, str]:
    """Channel units, effector position and rate units: the run's own (a vehicle file's) or the seed's degrees.

    A vehicle file's effectors of different units share an axis labelled with all of them.
    """
    given = result.settings.get("units") if result.settings else None
    if not given:
        return {}, "deg", "deg/s"
    units = sorted(set(given.get("effectors", {}).values())) or ["1"]
    return dict(given.get("channels", {})), ", ".join(units), ", ".join(f"{u}/s" for u in units)


def plot_result(result: SimResult, path: str | Path) -> Path:
    """Write a multi-panel PNG: one row per channel (reference vs output), pilot loop, effectors, rates."""
    nch = len(result.channels)
    has_eff = result.effectors is not None and result.effectors.size > 0
    outer = [k for k in result.extra if not k.endswith("_command") and f"{k}_command" in result.extra]
    rows = nch + (2 if has_eff else 0) + (1 if outer else 0)
    fig = Figure(figsize=(10, 2.1 * rows + 0.6))
    axes = fig.subplots(rows, 1, sharex=True, squeeze=False)[:, 0]
    t = result.t
    channel_units, position_unit, rate_unit = _units(result)
    for j, name in enumerate(result.channels):
        ax = axes[j]
        ax.plot(t, result.reference[:, j], "k--", lw=1, label="reference")
        ax.plot(t, result.output[:, j], color="tab:blue", lw=1, label="output")
        if name in channel_units:  # a vehicle file's output: its name (and unit, when the file gives one)
            ax.set_ylabel(f"{name} ({channel_units[name]})" if channel_units[name] else name)
        else:
            ax.set_ylabel(channel_label(name))
        ax.legend(loc="upper right", fontsize=7)
    i = nch
    if outer:
        ax = axes[i]
        for k in outer:
            ax.plot(t, result.extra[f"{k}_command"], "k--", lw=1, label=f"{channel_label(k)} command")
            ax.plot(t, result.extra[k], color="tab:green", lw=1, label=channel_label(k))
        ax.set_ylabel("pilot loop (deg)")
        ax.legend(loc="upper right", fontsize=7)
        i += 1
    if has_eff:
        cmap = colormaps["tab10" if result.effectors.shape[1] <= 10 else "tab20"]
        for n, name in enumerate(result.effector_names):
            c = cmap(n % cmap.N)
            axes[i].plot(t, result.effectors[:, n], lw=0.8, color=c, label=name)
            axes[i + 1].plot(t, result.effector_rates[:, n], lw=0.8, color=c)
        axes[i].set_ylabel(f"position ({position_unit})")
        axes[i].legend(fontsize=6, ncol=6, loc="upper right")
        axes[i + 1].set_ylabel(f"rate ({rate_unit})")
    for n, ax in enumerate(axes):
        if result.failure_time is not None:
            ax.axvline(result.failure_time, color="r", lw=0.8, ls=":",
                       label=None if n else f"failure ({result.failure}) t = {result.failure_time:g} s")
        ax.grid(alpha=0.3)
    if result.failure_time is not None:
        axes[0].legend(loc="upper right", fontsize=7)
    axes[-1].set_xlabel("t (s)")
    title = settings_line(result)
    if result.diverged:
        title += f"\nDIVERGED at t = {result.duration:.2f} s"
    fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    out = Path(path)
    fig.savefig(out, dpi=100)
    return out


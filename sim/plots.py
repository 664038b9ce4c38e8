"""PNG plots of a :class:`sim.result.SimResult`: tracking, effector deflections and rates."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


from sim.result import SimResult  # noqa: E402

__all__ = ["plot_result"]


def plot_result(result: SimResult, path: str | Path) -> Path:
    """Write a multi-panel PNG: one row per channel (reference vs output), effectors, rates."""
    nch = len(result.channels)
    has_eff = result.effectors is not None
    rows = nch + (2 if has_eff else 0) + (1 if result.extra else 0)
    fig, axes = plt.subplots(rows, 1, figsize=(9, 2.0 * rows), sharex=True, squeeze=False)
    axes = axes[:, 0]
    t = result.t
    for j, name in enumerate(result.channels):
        ax = axes[j]
        ax.plot(t, result.reference[:, j], "k--", lw=1, label="reference")
        ax.plot(t, result.output[:, j], "b", lw=1, label="output")
        ax.set_ylabel(name)
        ax.legend(loc="upper right", fontsize=7)
    i = nch
    outer = [k for k in result.extra if not k.endswith("_command") and f"{k}_command" in result.extra]
    if outer:
        ax = axes[i]
        for k in outer:
            ax.plot(t, result.extra[f"{k}_command"], "k--", lw=1, label=f"{k} command")
            ax.plot(t, result.extra[k], lw=1, label=k)
        ax.set_ylabel("outer loop")
        ax.legend(loc="upper right", fontsize=7)
        i += 1
    if has_eff:
        axes[i].plot(t, result.effectors, lw=0.8)
        axes[i].set_ylabel("deflection")
        axes[i].legend(result.effector_names, fontsize=6, ncol=6, loc="upper right")
        axes[i + 1].plot(t, result.effector_rates, lw=0.8)
        axes[i + 1].set_ylabel("rate /s")
    for ax in axes:
        if result.failure_time is not None:
            ax.axvline(result.failure_time, color="r", lw=0.8, ls=":")
        ax.grid(alpha=0.3)
    axes[-1].set_xlabel("t (s)")
    title = f"{result.scenario}  method={result.method}  failure={result.failure}"
    if result.diverged:
        title += f"  DIVERGED at t={result.duration:.2f} s"
    fig.suptitle(title)
    fig.tight_layout()
    out = Path(path)
    fig.savefig(out, dpi=100)
    plt.close(fig)
    return out


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit("use `alloc sim SCENARIO --plot FILE`")

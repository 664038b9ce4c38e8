"""Tracking error in a world that is not the model (``docs/world.md``'s measured table).

``sim.scenarios.ice.run(method="qp")``, 40 s, nominal vehicle, seeds 0-4, against each world
setting alone (:mod:`sim.world`): RMS of output minus reference per channel (alpha deg, p_s deg/s,
beta deg), mean [min, max] over the seeds, and how many runs diverged.  About a minute.

    python -m benchmarks.bench_world
"""

from __future__ import annotations

import numpy as np

from sim.scenarios import ice

CASES = (("nominal", {}), ("`--model-error 0.2`", {"model_error": 0.2}),
         ("`--turbulence light`", {"turbulence": "light"}), ("`--turbulence moderate`", {"turbulence": "moderate"}),
         ("`--turbulence severe`", {"turbulence": "severe"}),
         ("`--noise-model student-t`", {"noise_model": "student-t"}),
         ("`--noise-model coloured`", {"noise_model": "coloured"}), ("`--noise-model bias`", {"noise_model": "bias"}),
         ("`--noise-model quantised`", {"noise_model": "quantised"}))
SEEDS = range(5)


def rms_error(result) -> np.ndarray:
    """Per channel: the RMS of output minus reference over the run."""
    return np.sqrt(np.mean((result.output - result.reference) ** 2, axis=0))


def main() -> None:
    print("| world | alpha (deg) | p_s (deg/s) | beta (deg) | diverged |")
    print("|---|---|---|---|---|")
    for name, options in CASES:
        runs = [ice.run(method="qp", seed=seed, **options) for seed in SEEDS]
        v = np.array([rms_error(r) for r in runs])
        cells = [f"{m:.3f} [{lo:.3f}, {hi:.3f}]" for m, lo, hi in zip(v.mean(0), v.min(0), v.max(0), strict=True)]
        print(f"| {name} | " + " | ".join(cells) + f" | {sum(r.diverged for r in runs)}/{len(runs)} |")


if __name__ == "__main__":
    main()

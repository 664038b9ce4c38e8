"""ICE with the seed failure: every registry method, at the seed rate and at slower frame rates.

Run: ``python -m benchmarks.ice_table [--rates 2000 400 100] [--methods ...] --out FILE.csv``.

Setting: seed failure at t = 20 s, 40 s, stand-in pilot gain 1 (0.2 s), noise off
(the band in which Fig 4-110 holds, see docs/robustness.md), preferred mid-range
for one-sided effectors.  For each frame rate, method, allocator told/blind and
rate-aware on/off (off only below the seed rate, where the comparison is asked):
RMS tracking error per channel before/after the failure, divergence time, the
fractions of allocator calls that were unattainable or fell back, and time in
position saturation.  Rows are appended to the CSV as they finish (partial
results survive an interrupted run); a markdown table is printed at the end.
"""

from __future__ import annotations

import argparse
import csv
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

SETTINGS = dict(failure="seed", noise=False, pilot_gain=1.0, duration=40.0)
FIELDS = ["rate_hz", "method", "told", "rate_aware", "diverged_at", "alpha_before", "alpha_after", "ps_before",
          "ps_after", "beta_before", "beta_after", "unattainable", "fallback", "position_saturation_s", "wall_s"]


def fly(job: tuple[float, str, bool, bool]) -> dict[str, Any]:
    from sim.scenarios import get_scenario

    hz, method, told, aware = job
    t0 = time.perf_counter()
    r = get_scenario("ice")(method=method, allocator_knows_failure=told, rate_aware=aware,
                            frame_period=1.0 / hz, **SETTINGS)
    s = r.summary()
    ch = s["channels"]
    row = dict(rate_hz=hz, method=method, told=told, rate_aware=aware,
               diverged_at=round(r.duration, 2) if r.diverged else "",
               unattainable=round(s["unattainable_fraction"], 3), fallback=round(s["fallback_fraction"], 3),
               position_saturation_s=round(s["time_in_position_saturation"], 2),
               wall_s=round(time.perf_counter() - t0, 1))
    for name, key in (("alphaw", "alpha"), ("ps", "ps"), ("betaw", "beta")):
        for when in ("before", "after"):
            v = ch[name][f"rms_{when}"]
            row[f"{key}_{when}"] = "" if v is None else round(v, 3)
    return row


def main() -> None:
    import alloc

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rates", nargs="*", type=float, default=[2000.0, 400.0, 100.0])
    parser.add_argument("--methods", nargs="*", default=["static"] + alloc.methods())
    parser.add_argument("--jobs", type=int, default=1)
    parser.add_argument("--out", type=Path, required=True,
                        help="CSV to write (the committed reference is benchmarks/reference/ice_table.csv)")
    parser.add_argument("--markdown", action="store_true", help="only print the markdown table of --out")
    parser.add_argument("--readme", action="store_true", help="only print the README's compact table of --out")
    args = parser.parse_args()
    if args.markdown or args.readme:
        print(readme_table(args.out) if args.readme else markdown(args.out))
        return
    jobs = []
    for hz in args.rates:
        for method in args.methods:
            for told in ((False,) if method == "static" else (True, False)):
                for aware in ((True,) if hz >= 2000.0 or method == "static" else (True, False)):
                    jobs.append((hz, method, told, aware))
    args.out.parent.mkdir(parents=True, exist_ok=True)
    with args.out.open("w", newline="") as fh:
        writer = csv.DictWriter(fh, FIELDS)
        writer.writeheader()
        with ProcessPoolExecutor(max_workers=args.jobs) as pool:
            for row in pool.map(fly, jobs):
                writer.writerow(row)
                fh.flush()
                print(row, flush=True)


def markdown(path: Path) -> str:
    """The CSV as a markdown table: RMS before -> after per channel, fractions of allocator calls."""
    lines = ["| frame Hz | method | allocator | Eq 1.28 | diverged at (s) | alpha (deg) | p_s (deg/s) | beta (deg) "
             "| unattainable | fallback |", "|---|---|---|---|---|---|---|---|---|---|"]
    with path.open() as fh:
        for row in csv.DictReader(fh):
            def pair(key: str) -> str:
                b, a = row[f"{key}_before"], row[f"{key}_after"]
                return f"{b} -> {a}" if a else (f"{b} -> -" if b else "-")
            told = "-" if row["method"] == "static" else ("told" if row["told"] == "True" else "blind")
            aware = "-" if row["method"] == "static" else ("on" if row["rate_aware"] == "True" else "off")
            lines.append(f"| {float(row['rate_hz']):g} | {row['method']} | {told} | {aware} | {row['diverged_at'] or '-'} "
                         f"| {pair('alpha')} | {pair('ps')} | {pair('beta')} | {row['unattainable']} | {row['fallback']} |")
    return "\n".join(lines)


def readme_table(path: Path) -> str:
    """One row per method and told/blind: the seed rate (before -> after, unattainable), then the RMS
    after the failure (alpha / p_s / beta) or the divergence time at each slower rate, Eq 1.28 on and off."""
    with path.open() as fh:
        rows = list(csv.DictReader(fh))
    slow = sorted({float(r["rate_hz"]) for r in rows} - {2000.0}, reverse=True)
    index = {(float(r["rate_hz"]), r["method"], r["told"], r["rate_aware"]): r for r in rows}

    def after(r: dict[str, str] | None) -> str:
        if r is None:
            return "—"
        if r["diverged_at"]:
            return f"diverged {float(r['diverged_at']):.1f} s"
        return " / ".join(f"{float(r[f'{key}_after']):.2f}" for key in ("alpha", "ps", "beta"))

    head = ["method", "allocator", "2 kHz α deg", "2 kHz p_s deg/s", "2 kHz β deg", "unatt."]
    for hz in slow:
        head += [f"{hz:g} Hz, Eq 1.28 on", f"{hz:g} Hz, off"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    seen = []
    for r in rows:
        key = (r["method"], r["told"])
        if key in seen:
            continue
        seen.append(key)
        method, told = key
        seed = index.get((2000.0, method, told, "True"))
        if seed is None:
            continue
        cells = [method, "—" if method == "static" else ("told" if told == "True" else "blind")]
        if seed["diverged_at"]:
            cells += [f"diverged {float(seed['diverged_at']):.1f} s", "", ""]
        else:
            cells += [f"{seed[f'{k}_before']} → {seed[f'{k}_after']}" for k in ("alpha", "ps", "beta")]
        cells.append(seed["unattainable"])
        for hz in slow:
            cells += [after(index.get((hz, method, told, "True"))),
                      "—" if method == "static" else after(index.get((hz, method, told, "False")))]
        # methods whose rows are identical (pinv and pinv_clip, the da family, ...) share one row
        for line in lines[2:]:
            head_cells = line.split(" | ")
            if head_cells[1:] == cells[1:]:
                lines[lines.index(line)] = " | ".join([head_cells[0] + ", " + method] + cells[1:])
                break
        else:
            lines.append("| " + " | ".join(cells))
    return "\n".join(line if line.endswith("|") else line + " |" for line in lines)


if __name__ == "__main__":
    main()

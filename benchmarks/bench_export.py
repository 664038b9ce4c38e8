"""Generated C kernels (alloc.export) timed natively against wls-alloc (Rust, crates.io).

Usage::

    python -m benchmarks.bench_export [--calls 5000] [--passes 5] [--markdown out.md] [--json out.json]
                                      [--no-rust] [--no-daqp] [--quick] [--problems ...] [--kernels ...]
    python -m benchmarks.bench_export --certify out.md [--calls 5000] [--methods lp ...]

For each problem (ICE 3 x 11, the hexa-x hexacopter 4 x 6, the 6 x 12 tilt-rotor hexacopter of
bench_alloc) and each demand sequence (random: half attainable, half 2.5x past the attainable
set; sines: a sum of sines at 2 kHz), every kernel is compiled with ``cc -O2`` into the native
driver ``benchmarks/native/driver.c``, which times each call on its own (no Python in the
loop) and prints the median, p99 and maximum time, the timer's own floor (an empty timed
region) and the iterations.  ``wls-alloc`` (``benchmarks/native/wls_alloc_bench``, built here
with ``cargo build --release``) runs on the same demands and limits with its own defaults
(f32, its gamma from a condition bound of 4e5, warm start kept from call to call as it does
by default; "cold" resets it each call).  Also reported: each kernel's code size (``size``:
text + data) and stack (``-fstack-usage``: the sum of every function's frame, an upper bound
of the deepest call chain since nothing recurses), and the agreement of every kernel with the
library (through ctypes, not timed): bitwise-equal calls, max |u - u_library| and status
mismatches.  DAQP's C (the sources of the ``daqp`` package, :data:`DAQP_VERSION`, fetched with
``pip download`` from the package index and compiled here with ``-O2``;
``benchmarks/native/daqp_driver.c``) runs on the same demands and limits on the ``wls``
problem at the library's default gamma, set up once, ``f`` updated each call, "cold" (every
bound's state reset, as the generated kernels start) and "warm" (its working set kept); the
kernels "qp warm" and "wls warm" are exported with ``warm_start=True`` (the last working set
kept, as DAQP's "warm"), and their agreement is also measured on the sines, called in order.
``--markdown`` writes the tables of docs/export.md with the machine's state.
"""

from __future__ import annotations

import argparse
import ctypes
import json
import os
import platform
import re
import shutil
import subprocess
import sys
import tarfile
import tempfile
import time
from pathlib import Path

import numpy as np

import alloc
import alloc.vehicles
from alloc.export import ExportError, export_c
from alloc.registry import get_method

from .bench_alloc import hexacopter, random_sequence, sines_sequence

HERE = Path(__file__).resolve().parent
DRIVER = HERE / "native" / "driver.c"
RUST = HERE / "native" / "wls_alloc_bench"
DAQP_DRIVER = HERE / "native" / "daqp_driver.c"
#: the DAQP release whose C sources are timed (its sdist on the package index)
DAQP_VERSION = "0.11.0"
CFLAGS = ["-std=c99", "-O2", "-Wall", "-Wextra", "-Werror", "-pedantic"]
STATUS = {"exact": 0, "unattainable": 1, "fallback": 2}
#: (label, method, precision, options)
KERNELS = (("qp", "qp", "double", {}), ("qp float", "qp", "float", {}), ("wls", "wls", "double", {}),
           ("wls float", "wls", "float", {}), ("pinv_scale", "pinv_scale", "double", {}),
           ("dynamic", "dynamic", "double", {}), ("cgi", "cgi", "double", {}), ("pinv", "pinv", "double", {}),
           ("lp", "lp", "double", {}), ("lp float", "lp", "float", {}))
#: the active set with its opt-in warm start (export_c's warm_start): the last working set as
#: the next call's start, as DAQP's "warm" and wls-alloc's default keep theirs
WARM_KERNELS = (("qp warm", "qp", "double", {}, {"warm_start": True}),
                ("wls warm", "wls", "double", {}, {"warm_start": True}))
#: the qp kernel with every free set's factorisation tabulated where the default does not
#: (beyond the 256 KiB budget: 1.1 MB of code for ICE's 2,048 free sets), up to this many effectors
TABLE_QP_MAX_M = 11
#: where the default qp factorises at run time, also the qp kernel without its factorisation
#: cache ("qp no cache", cache=0): every factorisation computed, the cost of a cache miss


def problems() -> dict[str, alloc.Problem]:
    return {"ICE 3x11": alloc.vehicles.problem("ice"), "hexa-x 4x6": alloc.vehicles.problem("hexa-x"),
            "hexacopter 6x12": hexacopter()}


def compile_driver(kernel, folder: Path) -> tuple[Path, dict]:
    """The native driver linked with ``kernel``; and the kernel's code size and stack."""
    h, c = kernel.write(folder)
    exe = folder / f"drv_{kernel.prefix}"
    upper = kernel.prefix.upper()
    subprocess.run([_cc(), *CFLAGS, f"-I{folder}", f'-DKERNEL_HEADER="{h.name}"', f"-DPREFIX={kernel.prefix}",
                    f"-DPREFIX_UPPER={upper}", str(DRIVER), str(c), "-o", str(exe), "-lm"], check=True)
    obj = folder / f"{kernel.prefix}.o"
    subprocess.run([_cc(), *CFLAGS, "-fstack-usage", "-c", str(c), "-o", str(obj)], check=True, cwd=folder)
    code, static = _sizes(obj)
    return exe, {"code_bytes": code, "static_bytes": static, "stack_bytes": _stack(obj.with_suffix(".su"))}


def _cc() -> str:
    cc = os.environ.get("CC") or shutil.which("cc") or shutil.which("gcc")
    if cc is None:
        raise SystemExit("bench_export: no C compiler (cc, gcc) on PATH")
    return cc


def _sizes(obj: Path) -> tuple[int | None, int | None]:
    """Code bytes (``size`` text + data) and static RAM bytes (data + bss: the limits in force,
    the factorisation cache) of an object."""
    if shutil.which("size") is None:
        return None, None
    out = subprocess.run(["size", str(obj)], capture_output=True, text=True, check=True).stdout.splitlines()
    text, data, bss = (int(x) for x in out[1].split()[:3])
    return text + data, data + bss


def _stack(su: Path) -> int | None:
    if not su.exists():
        return None
    return sum(int(line.split("\t")[1]) for line in su.read_text().splitlines() if "\t" in line)


def run_json(cmd: list[str]) -> dict:
    out = subprocess.run(cmd, capture_output=True, text=True, check=True).stdout
    return json.loads(out.strip().splitlines()[-1])


def build_rust(folder: Path) -> Path | None:
    """wls-alloc's harness, built from crates.io; None (with the reason printed) if it cannot be."""
    cargo = shutil.which("cargo")
    if cargo is None:
        print("wls-alloc: skipped (no cargo on PATH)")
        return None
    target = folder / "rust-target"
    run = subprocess.run([cargo, "build", "--release", "--quiet", "--target-dir", str(target)], cwd=RUST,
                         capture_output=True, text=True)
    if run.returncode != 0:
        print(f"wls-alloc: skipped (cargo build failed: {run.stderr.strip().splitlines()[-1:]})")
        return None
    return target / "release" / "wls_alloc_bench"


def build_daqp(folder: Path) -> Path | None:
    """DAQP's C compiled with the native driver; None (with the reason printed) if it cannot be.

    The sdist is fetched with pip (its own cache keeps it after the first run) and only its
    ``csrc`` tree is compiled: no Python, no CMake."""
    src = folder / "daqp-src"
    run = subprocess.run([sys.executable, "-m", "pip", "download", "--quiet", "--no-deps", "--no-binary", "daqp",
                          f"daqp=={DAQP_VERSION}", "-d", str(src)], capture_output=True, text=True)
    sdists = sorted(src.glob(f"daqp-{DAQP_VERSION}.tar.gz"))
    if run.returncode != 0 or not sdists:
        print(f"daqp: skipped (pip download failed: {run.stderr.strip().splitlines()[-1:]})")
        return None
    with tarfile.open(sdists[0]) as tar:
        tar.extractall(src, filter="data")
    csrc = src / f"daqp-{DAQP_VERSION}" / "csrc"
    exe = folder / "daqp_driver"
    cmd = [_cc(), "-std=c99", "-O2", f"-I{csrc / 'include'}", str(DAQP_DRIVER), *map(str, sorted(csrc.glob("src/*.c"))),
           "-o", str(exe), "-lm"]
    build = subprocess.run(cmd, capture_output=True, text=True)
    if build.returncode != 0:
        print(f"daqp: skipped (compilation failed: {build.stderr.strip().splitlines()[-1:]})")
        return None
    return exe


def rust_problem(p: alloc.Problem, path: Path) -> None:
    wv = np.sqrt(np.diagonal(p.Wv))  # the crate squares its weights
    wu = np.sqrt(np.diagonal(p.Wu))
    np.concatenate([[p.k, p.m], p.B.ravel(), wv, wu, p.umin, p.umax, p.up]).astype("<f8").tofile(path)


def agreement(kernel, folder: Path, p: alloc.Problem, V: np.ndarray, options: dict) -> dict:
    """The kernel against the library on ``V`` through ctypes: bitwise-equal calls, max |du|, statuses."""
    h, c = kernel.write(folder)
    so = folder / f"{kernel.prefix}.so"
    subprocess.run([_cc(), *CFLAGS, "-shared", "-fPIC", str(c), "-o", str(so), "-lm"], check=True)
    lib = ctypes.CDLL(str(so))
    double = kernel.precision == "double"
    dtype = np.float64 if double else np.float32
    f = getattr(lib, f"{kernel.prefix}_allocate")
    f.restype = ctypes.c_int
    f.argtypes = [ctypes.c_void_p, ctypes.c_void_p, ctypes.c_double if double else ctypes.c_float, ctypes.c_void_p]
    reset = getattr(lib, f"{kernel.prefix}_warm_reset", None)
    if reset is not None:  # a warm start from the last sequence (dlopen hands back the loaded library)
        reset()
    allocator = alloc.make_allocator(p, kernel.method, **options)
    same = mismatched = 0
    du = []
    for v in V:
        r = allocator(v)
        vv = np.ascontiguousarray(v, dtype=dtype)
        u = np.zeros(p.m, dtype=dtype)
        status = f(vv.ctypes.data, None, 0.0, u.ctypes.data)
        same += bool(np.array_equal(u.astype(float), r.u))
        mismatched += status != STATUS[r.status.value]
        du.append(float(np.abs(u - r.u).max()))
    d = np.array(du)
    return {"calls": len(V), "bitwise": same, "max_du": float(d.max()), "p99_du": float(np.quantile(d, 0.99)),
            "above_1e-4": int((d > 1e-4).sum()), "status_mismatches": mismatched}


def machine() -> dict:
    model = ""
    try:
        model = next(x.split(":", 1)[1].strip() for x in open("/proc/cpuinfo") if x.startswith("model name"))
    except (OSError, StopIteration):
        pass
    cc = subprocess.run([_cc(), "--version"], capture_output=True, text=True).stdout.splitlines()[0]
    rustc = shutil.which("rustc")
    rust = subprocess.run([rustc, "--version"], capture_output=True, text=True).stdout.strip() if rustc else "none"
    return {"date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()), "cpu": model, "cores": os.cpu_count(),
            "load_1min": os.getloadavg()[0], "cc": cc, "rustc": rust, "python": platform.python_version()}


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--calls", type=int, default=5000, help="demands per sequence")
    ap.add_argument("--passes", type=int, default=5, help="passes over the demands (each call timed)")
    ap.add_argument("--agree", type=int, default=1000, help="demands checked against the library")
    ap.add_argument("--no-rust", action="store_true", help="skip wls-alloc")
    ap.add_argument("--no-daqp", action="store_true", help="skip DAQP's C")
    ap.add_argument("--quick", action="store_true", help="1,000 calls, 2 passes, 200 checked")
    ap.add_argument("--json", help="write the results here")
    ap.add_argument("--markdown", help="write docs/export.md's tables here")
    ap.add_argument("--problems", nargs="*", help="only these problems (default: all)")
    ap.add_argument("--kernels", nargs="*", help="only the kernels of these labels (default: all; e.g. lp \"lp float\")")
    ap.add_argument("--certify", help="only the iteration-bound certification: write its table here")
    ap.add_argument("--methods", nargs="*", help="--certify: only these methods (default qp, wls, dynamic, lp)")
    ap.add_argument("--summarise", nargs="+", metavar="JSON",
                    help="only print the peer ratios over these runs' --json files (repeat_summary)")
    args = ap.parse_args(argv)
    if args.summarise:
        text = repeat_summary([json.loads(Path(f).read_text()) for f in args.summarise])
        print(text, end="")
        return {"summary": text}
    if args.certify:
        rows = certification_rows(args.calls, *([tuple(args.methods)] if args.methods else []))
        Path(args.certify).write_text(certification_markdown(rows))
        return {"certification": rows}
    if args.quick:
        args.calls, args.passes, args.agree = 1000, 2, 200
    out: dict = {"machine": machine(), "calls": args.calls, "passes": args.passes, "rows": [], "agreement": []}
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        rust = None if args.no_rust else build_rust(folder)
        daqp = None if args.no_daqp else build_daqp(folder)
        gamma = get_method("wls").options["gamma"].default
        out["daqp"] = None if daqp is None else {"version": DAQP_VERSION, "gamma": gamma}
        for pname, p in problems().items():
            if args.problems and pname not in args.problems:
                continue
            seqs = {"random": random_sequence(p, args.calls, seed=1), "sines": sines_sequence(p, args.calls, seed=1)}
            files = {}
            for sname, V in seqs.items():
                files[sname] = folder / f"{pname.split()[0]}_{sname}.bin"
                np.ascontiguousarray(V, dtype="<f8").tofile(files[sname])
            kernels: list[tuple[str, str, str, dict, dict]] = [(*row, {}) for row in KERNELS] + list(WARM_KERNELS)
            if pname == "hexa-x 4x6":  # cgi with the vehicle's priority levels
                levels = alloc.vehicles.method_options("hexa-x", "cgi")
                kernels += [("cgi levels", "cgi", "double", levels, {}), ("cgi levels float", "cgi", "float", levels, {})]
            if "#define TABLE 0" in export_c(p, "qp").source:
                kernels.insert(1, ("qp no cache", "qp", "double", {}, {"cache": 0}))
                if p.m <= TABLE_QP_MAX_M:
                    kernels.insert(1, ("qp table", "qp", "double", {}, {"table": True}))
            for label, method, precision, options, form in kernels:
                if args.kernels and label not in args.kernels:
                    continue
                prefix = f"k_{re.sub(r'[^a-z0-9]', '_', pname.lower())}_{label.replace(' ', '_')}"
                try:
                    kernel = export_c(p, method, precision=precision, options=options, prefix=prefix, **form)
                except ExportError as exc:  # cgi beyond the table budget: say so, time the rest
                    print(f"{pname:<16} {label:<16} not exported: {exc}")
                    out.setdefault("skipped", []).append({"problem": pname, "kernel": label, "reason": str(exc)})
                    continue
                sub = folder / prefix
                exe, sizes = compile_driver(kernel, sub)
                table = "#define TABLE 1" in kernel.source
                # a warm start's agreement depends on the sequence: both demand sequences for it
                for sname in ("random", "sines") if form.get("warm_start") else ("random",):
                    out["agreement"].append({"problem": pname, "kernel": label, "table": table, "sequence": sname,
                                             **agreement(kernel, sub, p, seqs[sname][:args.agree], options)})
                for sname, path in files.items():
                    res = run_json([str(exe), str(path), str(args.calls), str(args.passes)])
                    out["rows"].append({"problem": pname, "sequence": sname, "kernel": label, "table": table,
                                        **sizes, **res})
                    _print_row(out["rows"][-1])
            prob = folder / f"{pname.split()[0]}_problem.bin"
            rust_problem(p, prob)
            if daqp is not None:
                for sname, path in files.items():
                    for mode in ("cold", "warm"):
                        res = run_json([str(daqp), str(prob), str(path), str(args.calls), str(args.passes), mode,
                                        repr(gamma)])
                        out["rows"].append({"problem": pname, "sequence": sname, "kernel": f"daqp {mode}",
                                            "table": False, "code_bytes": None, "static_bytes": None, "stack_bytes": None,
                                            **res})
                        _print_row(out["rows"][-1])
            if rust is not None:
                for sname, path in files.items():
                    for mode in ("warm", "cold"):
                        res = run_json([str(rust), str(prob), str(path), str(args.calls), str(args.passes), mode])
                        out["rows"].append({"problem": pname, "sequence": sname, "kernel": f"wls-alloc {mode}",
                                            "table": False, "code_bytes": None, "static_bytes": None, "stack_bytes": None,
                                            **res})
                        _print_row(out["rows"][-1])
    _print_summary(out)
    if args.json:
        Path(args.json).write_text(json.dumps(out, indent=2))
    if args.markdown:
        Path(args.markdown).write_text(markdown(out))
    return out


def certification_rows(calls: int, methods: tuple[str, ...] = ("qp", "wls", "dynamic", "lp")) -> list[dict]:
    """The sampled certification (alloc.export.certify) of each active-set kernel and of ``lp``
    (its simplex's pivots), and the counts the library needs on the benchmark's own demand
    sequences, which are not in the sample."""
    rows = []
    for pname, p in problems().items():
        fresh = np.concatenate([random_sequence(p, calls, seed=1), sines_sequence(p, calls, seed=1)])
        for method in methods:
            kernel = export_c(p, method, iteration_bound="certify")
            cert = kernel.certificate
            allocator = alloc.make_allocator(p, method)
            if cert.unit == "pivots":  # also where the library stops at its cap (a fallback of 0 iterations)
                simplex = allocator.export_data().kernel
                counts = np.array([simplex.pivots(v, p.umin, p.umax) for v in fresh])
                cap, analytic = kernel.maxit - 1, None
            else:
                counts = np.array([allocator(v).iterations for v in fresh])
                cap, analytic = kernel.levels * kernel.maxit, (p.m + 1) * 3 ** p.m
            rows.append({"problem": pname, "method": method, "unit": cert.unit, "bound": cert.bound,
                         "demands": cert.demands, "part_max": cert.part_max, "cap_total": cap,
                         "analytic_per_level": analytic, "levels": kernel.levels,
                         "fresh_demands": len(fresh), "fresh_max": int(counts.max()),
                         "fresh_beyond": int((counts > cert.bound).sum())})
            r = rows[-1]
            print(f"{pname:<16} {method:<8} certified {r['bound']:3d} {r['unit']} on {r['demands']:,} demands "
                  f"{r['part_max']}; benchmark demands max {r['fresh_max']} ({r['fresh_beyond']} beyond); "
                  f"cap {r['cap_total']}", flush=True)
    return rows


def certification_markdown(rows: list[dict]) -> str:
    lines = ["| problem | method | certified bound (per call) | sample demands | max on grid / far / vertices / axes "
             "(/ random) | max on the benchmark's demands | of them beyond the bound | library cap (per call) "
             "| analytic bound (per level) |", "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        pm = r["part_max"]
        parts = " / ".join(str(pm[name]) for name in ("grid", "far", "vertices", "axes", "random") if name in pm)
        # lp counts simplex pivots (bound flips included) and claims no analytic bound
        unit = " pivots" if r.get("unit") == "pivots" else ""
        analytic = "none claimed" if r["analytic_per_level"] is None else f"{r['analytic_per_level']:,}"
        lines.append(f"| {r['problem']} | {r['method']} | {r['bound']}{unit} | {r['demands']:,} | {parts} "
                     f"| {r['fresh_max']} | {r['fresh_beyond']} of {r['fresh_demands']:,} | {r['cap_total']} "
                     f"| {analytic} |")
    return "\n".join(lines) + "\n"


def repeat_summary(runs: list[dict]) -> str:
    """The ``VERSUS`` ratios over several runs (each a ``--json`` output): per problem, demands
    and pair, the median over the runs, their range and how many runs had it above 1.5x (the
    ICE goal's ratio), with each run's time and load; how much one run's ratio can be trusted."""
    lines = ["| run | date | load (1 min) |", "|---|---|---|"]
    lines += [f"| {i + 1} | {r['machine']['date']} | {r['machine']['load_1min']:.2f} |" for i, r in enumerate(runs)]
    lines += ["", "| problem | demands | ratio | runs | median | min | max | runs above 1.5x |",
              "|---|---|---|---|---|---|---|---|"]
    for problem in problems():
        for sequence in ("random", "sines"):
            for kernel, ref in VERSUS:
                got = [x for r in runs if (x := _ratio(r, problem, sequence, kernel, ref)) is not None]
                if got:
                    lines.append(f"| {problem} | {sequence} | {kernel} / {ref} | {len(got)} | {np.median(got):.2f}x | "
                                 f"{min(got):.2f}x | {max(got):.2f}x | {sum(x > 1.5 for x in got)} |")
    return "\n".join(lines) + "\n"


def _print_row(r: dict) -> None:
    floor = max(r["floor_median_ns"], 1.0)
    print(f"{r['problem']:<16} {r['sequence']:<7} {r['kernel']:<16} median {r['median_ns']:8.0f} ns "
          f"p99 {r['p99_ns']:8.0f} worst demand {r['worst_demand_ns']:8.0f} max {r['max_ns']:10.0f}  "
          f"({r['median_ns'] / floor:5.1f}x floor "
          f"{floor:.0f} ns)  it {r['iterations_median']}/{r['iterations_max']}", flush=True)


def _ratio(out: dict, problem: str, sequence: str, kernel: str, ref: str = "wls-alloc warm") -> float | None:
    rows = {r["kernel"]: r for r in out["rows"] if r["problem"] == problem and r["sequence"] == sequence}
    if kernel not in rows or ref not in rows:
        return None
    return rows[kernel]["median_ns"] / rows[ref]["median_ns"]


#: (kernel, reference) pairs of the comparison table: the generated kernels over each peer's median
VERSUS = (("qp", "daqp cold"), ("qp no cache", "daqp cold"), ("qp table", "daqp cold"), ("wls", "daqp cold"),
          ("qp warm", "daqp cold"), ("qp", "daqp warm"), ("qp no cache", "daqp warm"), ("qp table", "daqp warm"),
          ("wls", "daqp warm"), ("qp warm", "daqp warm"), ("wls warm", "daqp warm"))
#: the kernels of the table over wls-alloc's median
VERSUS_RUST = ("qp", "wls", "qp float", "wls float", "qp warm", "wls warm")


def _worst_over_median(out: dict, problem: str, sequence: str, kernel: str) -> float | None:
    rows = [r for r in out["rows"] if (r["problem"], r["sequence"], r["kernel"]) == (problem, sequence, kernel)]
    return rows[0]["worst_demand_ns"] / rows[0]["median_ns"] if rows else None


def _cell(x: float | None) -> str:
    return "" if x is None else f"{x:.2f}x"


def _print_summary(out: dict) -> None:
    print("\nmedian / wls-alloc (warm) median, same run:")
    for problem in problems():
        for sequence in ("random", "sines"):
            parts = [f"{k} {_ratio(out, problem, sequence, k):.2f}x" for k in VERSUS_RUST
                     if _ratio(out, problem, sequence, k) is not None]
            print(f"  {problem:<16} {sequence:<7} " + ", ".join(parts))
    print("\nmedian / DAQP's C median (wls problem), same run; worst demand / median:")
    for problem in problems():
        for sequence in ("random", "sines"):
            parts = [f"{k}/{ref} {_cell(_ratio(out, problem, sequence, k, ref))}" for k, ref in VERSUS]
            parts += [f"{k} worst {_cell(_worst_over_median(out, problem, sequence, k))}" for k in ("qp", "wls")]
            print(f"  {problem:<16} {sequence:<7} " + ", ".join(parts))
    print("\nagreement with the library (random demands):")
    for a in out["agreement"]:
        print(f"  {a['problem']:<16} {a['kernel']:<11} {a.get('sequence', 'random'):<7} bitwise {a['bitwise']}/{a['calls']} p99|du| {a['p99_du']:.1e} "
              f"max|du| {a['max_du']:.1e} (>1e-4: {a['above_1e-4']}) status mismatches {a['status_mismatches']}")


def markdown(out: dict) -> str:
    m = out["machine"]
    lines = [f"Measured {m['date']} on {m['cores']} cores ({m['cpu'] or 'unknown CPU'}), load average "
             f"{m['load_1min']:.1f} at the start, {m['cc']}, {m['rustc']}; {out['calls']:,} demands a sequence, "
             f"{out['passes']} passes, every call timed on its own by the native driver (no Python).", "",
             "| problem | demands | kernel | median ns | p99 ns | worst demand ns | max ns | x floor | x wls-alloc "
             "| iterations median / max | code bytes | static RAM bytes | stack bytes |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in out["rows"]:
        ratio = _ratio(out, r["problem"], r["sequence"], r["kernel"])
        lines.append(
            f"| {r['problem']} | {r['sequence']} | {r['kernel']}{' (table)' if r['table'] else ''} | {r['median_ns']:.0f} "
            f"| {r['p99_ns']:.0f} | {r['worst_demand_ns']:.0f} | {r['max_ns']:.0f} "
            f"| {r['median_ns'] / max(r['floor_median_ns'], 1.0):.1f} "
            f"| {'' if ratio is None else f'{ratio:.2f}'} | {r['iterations_median']} / {r['iterations_max']} "
            f"| {r['code_bytes'] if r['code_bytes'] is not None else ''} "
            f"| {r.get('static_bytes') if r.get('static_bytes') is not None else ''} "
            f"| {r['stack_bytes'] if r['stack_bytes'] is not None else ''} |")
    lines += ["", "Median over wls-alloc's (warm) median in the same run:", "",
              "| problem | demands | " + " | ".join(VERSUS_RUST) + " |", "|---|---|" + "---|" * len(VERSUS_RUST)]
    for problem in dict.fromkeys(r["problem"] for r in out["rows"]):
        for sequence in ("random", "sines"):
            cells = [_ratio(out, problem, sequence, k) for k in VERSUS_RUST]
            lines.append(f"| {problem} | {sequence} | " + " | ".join("" if c is None else f"{c:.2f}x" for c in cells)
                         + " |")
    if out.get("daqp"):
        d = out["daqp"]
        lines += ["", f"Median over DAQP {d['version']}'s C median (the wls problem at gamma = {d['gamma']:g}) in the "
                  "same run, and each kernel's worst demand over its own median:", "",
                  "| problem | demands | " + " | ".join(f"{k} / {ref}" for k, ref in VERSUS)
                  + " | qp worst / median | wls worst / median |", "|---|---|" + "---|" * (len(VERSUS) + 2)]
        for problem in dict.fromkeys(r["problem"] for r in out["rows"]):
            for sequence in ("random", "sines"):
                cells = [_ratio(out, problem, sequence, k, ref) for k, ref in VERSUS]
                cells += [_worst_over_median(out, problem, sequence, k) for k in ("qp", "wls")]
                lines.append(f"| {problem} | {sequence} | " + " | ".join(map(_cell, cells)) + " |")
    lines += ["", "Agreement with the library on the random demands, and for the warm-start kernels also on the "
              "sines, called in order (through ctypes; u in the problem's units):", "",
              "| problem | kernel | demands | calls | bitwise equal | p99 abs(u - u_library) | max | calls above 1e-4 "
              "| status mismatches |",
              "|---|---|---|---|---|---|---|---|---|"]
    for a in out["agreement"]:
        lines.append(f"| {a['problem']} | {a['kernel']}{' (table)' if a['table'] else ''} "
                     f"| {a.get('sequence', 'random')} | {a['calls']} | "
                     f"{a['bitwise']} | {a['p99_du']:.1e} | {a['max_du']:.1e} | {a['above_1e-4']} "
                     f"| {a['status_mismatches']} |")
    for skip in out.get("skipped", []):
        lines.append(f"\nNot exported: {skip['kernel']} on {skip['problem']} ({skip['reason']}).")
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    main(sys.argv[1:])

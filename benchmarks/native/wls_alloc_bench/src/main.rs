//! Native timing of wls-alloc's `ControlAllocator` on the demands bench_export.py writes.
//!
//! usage: wls_alloc_bench PROBLEM.bin DEMANDS.bin N PASSES warm|cold
//!   PROBLEM.bin: f64 nv, nu, then B (nv x nu, row-major), wv (nv), wu (nu), umin, umax, up (nu)
//!   DEMANDS.bin: N x nv f64, row-major
//! Prints one JSON line: per-call ns (median, p99, max over PASSES passes, each call timed on its
//! own), the timer's floor, iterations (median, max), exit codes and a checksum.  "warm" keeps
//! the crate's warm start from call to call (its default), "cold" resets it before every call.
use nalgebra::{Const, OMatrix, OVector};
use std::time::Instant;
use wls_alloc::wls::ControlAllocator;
use wls_alloc::ExitCode;

fn read_f64(path: &str) -> Vec<f64> {
    let bytes = std::fs::read(path).unwrap_or_else(|e| panic!("{path}: {e}"));
    bytes.chunks_exact(8).map(|c| f64::from_le_bytes(c.try_into().unwrap())).collect()
}

// one concrete function per size: the crate's const-generic bounds hold for concrete sizes only
macro_rules! instance {
    ($name:ident, $nu:literal, $nv:literal, $nc:literal) => {
fn $name(p: &[f64], v: &[f64], n: usize, passes: usize, warm: bool) {
    const NU: usize = $nu;
    const NV: usize = $nv;
    const NC: usize = $nc;
    let mut g = OMatrix::<f32, Const<NV>, Const<NU>>::zeros();
    let mut at = 2;
    for i in 0..NV {
        for j in 0..NU {
            g[(i, j)] = p[at] as f32;
            at += 1;
        }
    }
    let take = |at: &mut usize, len: usize| -> Vec<f32> {
        let out = p[*at..*at + len].iter().map(|x| *x as f32).collect();
        *at += len;
        out
    };
    let wv = OVector::<f32, Const<NV>>::from_column_slice(&take(&mut at, NV));
    let wu = OVector::<f32, Const<NU>>::from_column_slice(&take(&mut at, NU));
    let umin = OVector::<f32, Const<NU>>::from_column_slice(&take(&mut at, NU));
    let umax = OVector::<f32, Const<NU>>::from_column_slice(&take(&mut at, NU));
    let up = OVector::<f32, Const<NU>>::from_column_slice(&take(&mut at, NU));
    let demands: Vec<OVector<f32, Const<NV>>> = (0..n)
        .map(|i| OVector::<f32, Const<NV>>::from_iterator(v[i * NV..(i + 1) * NV].iter().map(|x| *x as f32)))
        .collect();
    // the crate's README values: theta 2e-9, condition bound 4e5
    let mut alloc = ControlAllocator::<NU, NV, NC>::new(&g, &wv, wu, 2e-9, 4e5);
    let mut times = Vec::with_capacity(n * passes);
    let mut best = vec![f64::INFINITY; n];
    let mut floor = Vec::with_capacity(n * passes);
    let mut iters = Vec::with_capacity(n);
    let (mut ok, mut limit, mut nan) = (0usize, 0usize, 0usize);
    let mut check = 0.0f64;
    for pass in 0..passes {
        for d in demands.iter() {
            if !warm {
                alloc.set_warmstart(&up);
            }
            let t0 = Instant::now();
            let t1 = Instant::now();
            let stats = alloc.solve(d, &up, &umin, &umax, 100);
            let t2 = Instant::now();
            std::hint::black_box(alloc.solution());
            floor.push((t1 - t0).as_nanos() as f64);
            times.push((t2 - t1).as_nanos() as f64);
            let k = times.len() - 1 - pass * n;
            best[k] = best[k].min((t2 - t1).as_nanos() as f64);
            if pass == 0 {
                iters.push(stats.iterations);
                match stats.exit_code {
                    ExitCode::Success => ok += 1,
                    ExitCode::IterLimit => limit += 1,
                    _ => nan += 1,
                }
                check += alloc.solution().iter().map(|x| *x as f64).sum::<f64>();
            }
        }
    }
    let worst = best.iter().cloned().fold(0.0f64, f64::max);
    times.sort_by(|a, b| a.partial_cmp(b).unwrap());
    floor.sort_by(|a, b| a.partial_cmp(b).unwrap());
    iters.sort();
    let total = times.len();
    let q = |x: &Vec<f64>, f: f64| x[((f * (total - 1) as f64) as usize).min(total - 1)];
    println!(
        "{{\"calls\": {}, \"median_ns\": {:.1}, \"p99_ns\": {:.1}, \"max_ns\": {:.1}, \"worst_demand_ns\": {:.1}, \
         \"floor_median_ns\": {:.1}, \
         \"floor_p99_ns\": {:.1}, \"iterations_median\": {}, \"iterations_max\": {}, \"success\": {}, \
         \"iter_limit\": {}, \"nan\": {}, \"checksum\": {:.17e}}}",
        total, times[total / 2], q(&times, 0.99), times[total - 1], worst, floor[total / 2], q(&floor, 0.99),
        iters[n / 2], iters[n - 1], ok, limit, nan, check
    );
}
    };
}

instance!(run_3x11, 11, 3, 14);
instance!(run_4x6, 6, 4, 10);
instance!(run_6x12, 12, 6, 18);

fn main() {
    let args: Vec<String> = std::env::args().collect();
    if args.len() < 6 {
        eprintln!("usage: wls_alloc_bench PROBLEM.bin DEMANDS.bin N PASSES warm|cold");
        std::process::exit(2);
    }
    let p = read_f64(&args[1]);
    let v = read_f64(&args[2]);
    let n: usize = args[3].parse().unwrap();
    let passes: usize = args[4].parse().unwrap();
    let warm = args[5] == "warm";
    match (p[0] as usize, p[1] as usize) {
        (3, 11) => run_3x11(&p, &v, n, passes, warm),
        (4, 6) => run_4x6(&p, &v, n, passes, warm),
        (6, 12) => run_6x12(&p, &v, n, passes, warm),
        (nv, nu) => {
            eprintln!("wls_alloc_bench: no instance for {nv} x {nu} (add one to main)");
            std::process::exit(2);
        }
    }
}

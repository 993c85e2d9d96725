//! Benchmark of the ONNX Runtime evaluation (run by `scripts/bench_surrogate.sh`).
//!
//! `cargo run --release -p bemcal-surrogate --example bench_surrogate -- DIR THREADS SECONDS [BATCH]`
//!
//! DIR holds a surrogate (e.g. the paper-size random-weight model written by
//! `python/tools/bench_torch.py`). One evaluation = the 8,760 windows of a year for one parameter
//! vector. Prints one `key=value` line per measurement for the script to tabulate.

use std::time::Instant;

use bemcal_surrogate::{Precision, Surrogate};
use bemcal_weather::HourlyFeatures;
use ndarray::Array3;

/// Best rate (calls x per_call per second) over 4 rounds of `seconds / 4`: the machine may be
/// shared; the best round is the least disturbed.
fn best_rate(
    seconds: f64,
    per_call: usize,
    mut f: impl FnMut() -> Result<(), Box<dyn std::error::Error>>,
) -> Result<f64, Box<dyn std::error::Error>> {
    let mut best = 0.0f64;
    for _ in 0..4 {
        let t0 = Instant::now();
        let mut k = 0usize;
        while t0.elapsed().as_secs_f64() < seconds / 4.0 {
            f()?;
            k += per_call;
        }
        best = best.max(k as f64 / t0.elapsed().as_secs_f64());
    }
    Ok(best)
}

fn lcg(state: &mut u64) -> f64 {
    *state = state
        .wrapping_mul(6364136223846793005)
        .wrapping_add(1442695040888963407);
    (*state >> 11) as f64 / (1u64 << 53) as f64
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let dir = args
        .get(1)
        .ok_or("usage: bench_surrogate DIR THREADS SECONDS [BATCH]")?;
    let threads: usize = args.get(2).map_or(Ok(2), |s| s.parse())?;
    let seconds: f64 = args.get(3).map_or(Ok(10.0), |s| s.parse())?;
    let batch: usize = args.get(4).map_or(Ok(4), |s| s.parse())?;

    let mut s = Surrogate::load(dir, threads)?;
    let meta = s.meta().clone();
    let np = meta.params.len();
    let mut rng = 7u64;
    let mut proposal = || -> Vec<f64> {
        meta.params
            .iter()
            .map(|p| p.min + lcg(&mut rng) * (p.max - p.min))
            .collect()
    };

    // Plain graph on the full year of windows (the exported `x` -> `y` LSTM).
    let w = HourlyFeatures::synthetic(8760);
    let hourly = meta.hourly_inputs(&w);
    let p0 = proposal();
    let mut pn = vec![0f32; np];
    meta.normalise_params(&p0, &mut pn)?;
    let n = w.len();
    let mut x = Array3::<f32>::zeros((n, 3, meta.n_features));
    for t in 0..n {
        for st in 0..3 {
            let h = (t + st).saturating_sub(2);
            for j in 0..np {
                x[[t, st, j]] = pn[j];
            }
            for j in 0..hourly.ncols() {
                x[[t, st, np + j]] = hourly[[h, j]];
            }
        }
    }
    let y_plain = s.run_windows(x.view())?;
    // The plain graph gets its (already built) windows; the fast path builds nothing per call.
    let r = best_rate(seconds / 4.0, 1, || {
        s.run_windows(x.view())?;
        Ok(())
    })?;
    println!("ort_plain_evals_per_s={r:.4}");

    // The evaluator's hot path (the fused graph when present): one proposal per call, then
    // `batch` proposals per call.
    println!("hot_path_file={}", s.hot_path_file());
    let mut ev = s.bind(&w)?;
    let y_fast = ev.evaluate(&p0)?.to_owned();
    let max_y = y_plain.iter().fold(0f32, |m, v| m.max(v.abs()));
    let max_d = (&y_fast - &y_plain)
        .iter()
        .fold(0f32, |m, v| m.max(v.abs()));
    println!("fast_vs_plain_rel={:.3e}", max_d / max_y.max(1e-12));
    let r = best_rate(seconds / 4.0, 1, || {
        let p = proposal();
        ev.evaluate(&p)?;
        Ok(())
    })?;
    println!("ort_fast_evals_per_s={r:.4}");
    let r = best_rate(seconds / 4.0, batch, || {
        let ps: Vec<Vec<f64>> = (0..batch).map(|_| proposal()).collect();
        ev.evaluate_batch(&ps)?;
        Ok(())
    })?;
    println!("ort_fast_batch{batch}_evals_per_s={r:.4}");

    // int8 graph.
    if meta.files.fused_int8.is_some() || meta.files.fast_int8.is_some() {
        let mut q = Surrogate::load_with(dir, threads, Precision::Int8)?.bind(&w)?;
        let yq = q.evaluate(&p0)?.to_owned();
        let rmse = ((&yq - &y_fast)
            .mapv(|v| (v as f64).powi(2))
            .mean()
            .unwrap_or(0.0))
        .sqrt();
        let mean = y_fast.mean().unwrap_or(0.0);
        println!("int8_rmse_vs_float_kwh={rmse:.4e}");
        let sigma = meta
            .outputs
            .iter()
            .map(|o| o.sigma_eta_kwh)
            .fold(f64::MAX, f64::min);
        println!("int8_rmse_vs_min_sigma_eta={:.4e}", rmse / sigma.max(1e-12));
        println!("float_mean_output_kwh={mean:.4e}");
        let r = best_rate(seconds / 4.0, 1, || {
            let p = proposal();
            q.evaluate(&p)?;
            Ok(())
        })?;
        println!("ort_fast_int8_evals_per_s={r:.4}");
    }
    Ok(())
}

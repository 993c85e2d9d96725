//! Benchmark of the ONNX Runtime evaluation (run by `scripts/bench_surrogate.sh`).
//!
//! `cargo run --release -p bemcal-surrogate --example bench_surrogate -- DIR THREADS SECONDS [BATCH]`
//!
//! DIR holds a surrogate (e.g. the paper-size random-weight model written by
//! `python/tools/bench_torch.py`). One evaluation = the 8,760 windows of a year for one parameter
//! vector. Prints one `key=value` line per measurement for the script to tabulate.

use std::time::Instant;

use bemcal_surrogate::Surrogate;
use bemcal_weather::{DayType, HourlyFeatures};
use ndarray::Array3;

fn weather() -> HourlyFeatures {
    let tau = std::f64::consts::TAU;
    let n = 8760;
    HourlyFeatures {
        dry_bulb_c: (0..n)
            .map(|t| 10.0 - 12.0 * (tau * t as f64 / 8760.0).cos())
            .collect(),
        rel_humidity_pct: (0..n)
            .map(|t| 60.0 + 20.0 * (tau * t as f64 / 24.0).cos())
            .collect(),
        wind_speed_m_s: (0..n).map(|t| 3.0 + (t % 7) as f64 * 0.3).collect(),
        global_horizontal_wh_m2: (0..n)
            .map(|t| (600.0 * (tau * ((t % 24) as f64 - 6.0) / 24.0).sin()).max(0.0))
            .collect(),
        day_type: (0..n)
            .map(|t| {
                if (t / 24) % 7 >= 5 {
                    DayType::Weekend
                } else {
                    DayType::Weekday
                }
            })
            .collect(),
    }
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
    let w = weather();
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
    let t0 = Instant::now();
    let mut k = 0usize;
    while t0.elapsed().as_secs_f64() < seconds / 3.0 {
        s.run_windows(x.view())?;
        k += 1;
    }
    println!(
        "ort_plain_evals_per_s={:.4}",
        k as f64 / t0.elapsed().as_secs_f64()
    );

    // Structured hot path: one proposal per call, then `batch` proposals per call.
    let mut ev = s.bind(&w)?;
    let y_struct = ev.evaluate(&p0)?.to_owned();
    let max_y = y_plain.iter().fold(0f32, |m, v| m.max(v.abs()));
    let max_d = (&y_struct - &y_plain)
        .iter()
        .fold(0f32, |m, v| m.max(v.abs()));
    println!("structured_vs_plain_rel={:.3e}", max_d / max_y.max(1e-12));
    let t0 = Instant::now();
    let mut k = 0usize;
    while t0.elapsed().as_secs_f64() < seconds / 3.0 {
        let p = proposal();
        ev.evaluate(&p)?;
        k += 1;
    }
    println!(
        "ort_structured_evals_per_s={:.4}",
        k as f64 / t0.elapsed().as_secs_f64()
    );
    let t0 = Instant::now();
    let mut k = 0usize;
    while t0.elapsed().as_secs_f64() < seconds / 3.0 {
        let ps: Vec<Vec<f64>> = (0..batch).map(|_| proposal()).collect();
        ev.evaluate_batch(&ps)?;
        k += batch;
    }
    println!(
        "ort_structured_batch{batch}_evals_per_s={:.4}",
        k as f64 / t0.elapsed().as_secs_f64()
    );
    Ok(())
}

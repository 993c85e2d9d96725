//! The real calibration's difficulty in miniature: a very peaked, strongly correlated Gaussian
//! posterior in the unit cube (sds 0.003-0.03, pairwise correlations 0.9), chains started from
//! uniform random points far from the mode, with a first proposal sd (0.05) ten times too wide.

use bemcal_stats::diagnostics;
use bemcal_stats::mcmc::{self, ChainState, Draws, MhConfig};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Gaussian with precision from the inverse of a block covariance of disjoint pairs.
struct Peaked {
    mean: Vec<f64>,
    sd: Vec<f64>,
    /// Correlation of the pair (2k, 2k+1) for k < pairs; others independent.
    rho: f64,
    pairs: usize,
}

impl Peaked {
    fn new(d: usize, pairs: usize) -> Self {
        let sd = (0..d)
            .map(|i| 0.003 * 10f64.powf((i * 7 % d) as f64 / (d - 1) as f64))
            .collect();
        let mean = (0..d)
            .map(|i| 0.3 + 0.4 * (i * 3 % d) as f64 / (d - 1) as f64)
            .collect();
        Peaked {
            mean,
            sd,
            rho: 0.9,
            pairs,
        }
    }
    fn ln_pdf(&self, x: &[f64]) -> f64 {
        assert!(
            x.iter().all(|v| (0.0..=1.0).contains(v)),
            "out-of-support proposal evaluated"
        );
        let z: Vec<f64> = (0..x.len())
            .map(|i| (x[i] - self.mean[i]) / self.sd[i])
            .collect();
        let mut q = 0.0;
        let mut i = 0;
        while i < z.len() {
            if i / 2 < self.pairs && i + 1 < z.len() {
                let (a, b, r) = (z[i], z[i + 1], self.rho);
                q += (a * a - 2.0 * r * a * b + b * b) / (1.0 - r * r);
                i += 2;
            } else {
                q += z[i] * z[i];
                i += 1;
            }
        }
        -0.5 * q
    }
}

struct Outcome {
    acceptance: Vec<f64>,
    rhat: Vec<f64>,
    ess: Vec<f64>,
    max_z: f64,
}

fn run(g: &Peaked, cfg: &MhConfig, chains: usize, iters: u64, seed: u64) -> Outcome {
    let d = g.mean.len();
    let mut states: Vec<ChainState> = (0..chains)
        .map(|c| {
            let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0xabcd);
            rng.set_stream(c as u64);
            let s: Vec<f64> = (0..d).map(|_| rng.random::<f64>()).collect();
            let lp = g.ln_pdf(&s);
            ChainState::new(cfg.clone(), s, lp, seed, c as u64).unwrap()
        })
        .collect();
    let draws: Vec<Draws> = mcmc::run_segment_batch(&mut states, iters, |pts: &[Vec<f64>]| {
        pts.iter().map(|p| g.ln_pdf(p)).collect()
    })
    .unwrap();
    if std::env::var("PEAKED_DIAG").is_ok() {
        for (s, dr) in states.iter().zip(&draws) {
            let pc = s.proposal_covariance();
            let ratios: Vec<f64> = (0..d).map(|j| (pc[j * d + j]).sqrt() / g.sd[j]).collect();
            let lp0 = dr.log_density[..200].iter().sum::<f64>() / 200.0;
            let lp1 = dr.log_density.iter().sum::<f64>() / dr.len() as f64;
            eprintln!(
                "  lambda {:.3} prop sd/true sd {:.3}..{:.3}  lp first200 {:.1} all {:.1} (expect {})",
                s.proposal_scale(),
                ratios.iter().copied().fold(f64::MAX, f64::min),
                ratios.iter().copied().fold(f64::MIN, f64::max),
                lp0, lp1, -(d as f64) / 2.0
            );
        }
    }
    let mut out = Outcome {
        acceptance: states
            .iter()
            .map(|s| s.acceptance_rate_post_burn_in())
            .collect(),
        rhat: Vec::new(),
        ess: Vec::new(),
        max_z: 0.0,
    };
    for j in 0..d {
        let cols: Vec<Vec<f64>> = draws.iter().map(|c| c.column(j)).collect();
        let all: Vec<f64> = cols.iter().flatten().copied().collect();
        let ess = diagnostics::ess_bulk(&cols).unwrap();
        let mean = all.iter().sum::<f64>() / all.len() as f64;
        let z = (mean - g.mean[j]).abs() / (g.sd[j] / ess.sqrt());
        out.rhat.push(diagnostics::rhat(&cols).unwrap());
        out.ess.push(ess);
        out.max_z = out.max_z.max(z);
    }
    out
}

fn hard_config() -> MhConfig {
    MhConfig {
        burn_in: 2000,
        adapt_start: 500,
        initial_sd: 0.05,
        ..MhConfig::default()
    }
}

fn report(name: &str, o: &Outcome) {
    let max = |v: &[f64]| v.iter().copied().fold(f64::MIN, f64::max);
    let min = |v: &[f64]| v.iter().copied().fold(f64::MAX, f64::min);
    eprintln!(
        "{name}: acceptance {:.3}..{:.3}, max R-hat {:.4}, min bulk ESS {:.0}, max |z| {:.2}",
        min(&o.acceptance),
        max(&o.acceptance),
        max(&o.rhat),
        min(&o.ess),
        o.max_z
    );
}

/// 10-D, 4 chains, 8,000 recorded iterations. A 2,000-iteration burn-in is not enough here
/// (max R-hat 1.04-1.8 over seeds and `adapt_start` choices): the transient from a uniform start
/// takes ~1,000 iterations, and the covariance must then be learned from what is left. With
/// 4,000 (covariance from the second half) every coordinate has R-hat < 1.02.
#[test]
fn peaked_correlated_10d_from_uniform_starts() {
    let g = Peaked::new(10, 3);
    let cfg = MhConfig {
        burn_in: 4000,
        adapt_start: 2000,
        ..hard_config()
    };
    let o = run(&g, &cfg, 4, 4000 + 8000, 17);
    report("10-D", &o);
    for a in &o.acceptance {
        assert!((0.1..=0.5).contains(a), "acceptance {a}");
    }
    for (j, r) in o.rhat.iter().enumerate() {
        assert!(*r < 1.05, "coordinate {j}: R-hat {r}");
    }
    assert!(
        o.max_z < 4.5,
        "a mean is {} MC standard errors off",
        o.max_z
    );
}

/// The paper-size problem (40 dims). Prints acceptance, R-hat and bulk ESS per setting.
#[test]
#[ignore = "benchmark of the paper-size problem; run with --release -- --ignored --nocapture"]
fn peaked_correlated_40d_benchmark() {
    let g = Peaked::new(40, 8);
    for (burn, iters) in [
        (2000, 8000),
        (10_000, 10_000),
        (20_000, 10_000),
        (20_000, 40_000),
    ] {
        for seed in [17, 18] {
            let cfg = MhConfig {
                burn_in: burn,
                adapt_start: burn / 2,
                ..hard_config()
            };
            let o = run(&g, &cfg, 4, burn + iters, seed);
            report(&format!("40-D burn-in {burn} + {iters}, seed {seed}"), &o);
        }
    }
}

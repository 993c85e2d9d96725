//! The real calibration's difficulty in miniature: a very peaked, strongly correlated Gaussian
//! posterior in the unit cube (sds 0.003-0.03, pairwise correlations 0.9), chains started from
//! uniform random points far from the mode, with a first proposal sd (0.05) ten times too wide.

use bemcal_stats::diagnostics;
use bemcal_stats::mcmc::{self, ChainState, Draws, MhConfig};
use bemcal_stats::optim::{self, BfgsConfig};
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
    ind_acceptance: Vec<f64>,
    rhat: Vec<f64>,
    ess: Vec<f64>,
    max_z: f64,
}

fn run(g: &Peaked, cfg: &MhConfig, chains: usize, iters: u64, seed: u64) -> Outcome {
    run_from(g, cfg, chains, iters, seed, false)
}

/// `optimise`: start each chain at the BFGS optimum from its uniform start, with the
/// optimiser's covariance as the first proposal shape.
fn run_from(
    g: &Peaked,
    cfg: &MhConfig,
    chains: usize,
    iters: u64,
    seed: u64,
    optimise: bool,
) -> Outcome {
    let d = g.mean.len();
    let starts: Vec<Vec<f64>> = (0..chains)
        .map(|c| {
            let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0xabcd);
            rng.set_stream(c as u64);
            (0..d).map(|_| rng.random::<f64>()).collect()
        })
        .collect();
    let lps: Vec<f64> = starts.iter().map(|s| g.ln_pdf(s)).collect();
    let mut states: Vec<ChainState> = if optimise {
        let opt = optim::maximise_batch(&starts, &lps, &BfgsConfig::default(), |us| {
            us.iter().map(|u| g.ln_pdf(u)).collect()
        });
        if std::env::var("PEAKED_DIAG").is_ok() {
            for o in &opt {
                eprintln!(
                    "  optimum lp {:.1} (max 0) after {} iterations, {} evaluations",
                    o.log_density, o.iterations, o.evaluations
                );
            }
        }
        mcmc::chains_at_optima(cfg, opt, seed, 0, f64::INFINITY).unwrap()
    } else {
        starts
            .into_iter()
            .zip(lps)
            .enumerate()
            .map(|(c, (s, lp))| ChainState::new(cfg.clone(), s, lp, seed, c as u64).unwrap())
            .collect()
    };
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
        ind_acceptance: states
            .iter()
            .map(|s| s.independence_acceptance_rate())
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
        "{name}: acceptance {:.3}..{:.3} (independence {:.3}..{:.3}), max R-hat {:.4}, min bulk ESS {:.0}, max |z| {:.2}",
        min(&o.acceptance),
        max(&o.acceptance),
        min(&o.ind_acceptance),
        max(&o.ind_acceptance),
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

/// The chain target on the 40-D analogue of the paper-size problem: 4 chains x 10,000
/// iterations (2,000 burn-in) with R-hat <= 1.01 and bulk ESS >= 400 for every coordinate.
/// Random-walk chains from uniform starts reach neither (max R-hat 3.8-4.4, min bulk ESS 4, see
/// the benchmark below); each start optimised first (BFGS + a finite-difference Hessian, 3,362
/// evaluations per chain), the Laplace covariance as proposal shape and half the steps
/// independence proposals from that Gaussian: max R-hat 1.004-1.005, min bulk ESS 2,300-2,700.
#[test]
fn peaked_correlated_40d_meets_the_chain_target_from_optimised_starts() {
    let g = Peaked::new(40, 8);
    let cfg = MhConfig {
        burn_in: 2000,
        adapt_start: 2000,
        independence: 0.5,
        ..hard_config()
    };
    for seed in [17, 18] {
        let o = run_from(&g, &cfg, 4, 10_000, seed, true);
        report(&format!("40-D optimised, seed {seed}"), &o);
        for (j, r) in o.rhat.iter().enumerate() {
            assert!(*r <= 1.01, "coordinate {j}: R-hat {r}");
        }
        for (j, e) in o.ess.iter().enumerate() {
            assert!(*e >= 400.0, "coordinate {j}: bulk ESS {e}");
        }
        assert!(
            o.max_z < 4.5,
            "a mean is {} MC standard errors off",
            o.max_z
        );
    }
}

/// The paper-size problem (40 dims). Prints acceptance, R-hat and bulk ESS per setting.
#[test]
#[ignore = "benchmark of the paper-size problem; run with --release -- --ignored --nocapture"]
fn peaked_correlated_40d_benchmark() {
    let g = Peaked::new(40, 8);
    let settings: Vec<(u64, u64, f64)> = match std::env::var("PEAKED_SETTINGS") {
        // "burn,iters,independence;..."
        Ok(v) => v
            .split(';')
            .map(|t| {
                let f: Vec<&str> = t.split(',').collect();
                (
                    f[0].parse().unwrap(),
                    f[1].parse().unwrap(),
                    f[2].parse().unwrap(),
                )
            })
            .collect(),
        Err(_) => vec![
            (2000, 8000, 0.0),
            (10_000, 10_000, 0.0),
            (20_000, 10_000, 0.0),
            (20_000, 40_000, 0.0),
            (2000, 8000, 0.5),
            (5000, 5000, 0.5),
        ],
    };
    let opt = std::env::var("PEAKED_OPT").is_ok();
    for (burn, iters, p) in settings {
        for seed in [17, 18] {
            let cfg = MhConfig {
                burn_in: burn,
                adapt_start: if opt { burn } else { burn / 2 },
                independence: p,
                ..hard_config()
            };
            let o = run_from(&g, &cfg, 4, burn + iters, seed, opt);
            report(
                &format!(
                    "40-D burn-in {burn} + {iters}, independence {p}, optimised {opt}, seed {seed}"
                ),
                &o,
            );
        }
    }
}

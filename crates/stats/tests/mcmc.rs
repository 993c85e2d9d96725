//! Metropolis-Hastings on known Gaussian targets, determinism, checkpointing and batching.

use bemcal_stats::diagnostics;
use bemcal_stats::mcmc::{self, ChainState, Draws, MhConfig};
use bemcal_stats::Triangular;

/// A multivariate Gaussian log density (up to a constant) from mean and covariance.
struct Gaussian {
    mean: Vec<f64>,
    prec: Vec<f64>,
    d: usize,
}

impl Gaussian {
    fn new(mean: Vec<f64>, cov: &[f64]) -> Self {
        let d = mean.len();
        // Gauss-Jordan inverse (test helper).
        let mut a = cov.to_vec();
        let mut inv = vec![0.0; d * d];
        for i in 0..d {
            inv[i * d + i] = 1.0;
        }
        for c in 0..d {
            let p = a[c * d + c];
            for j in 0..d {
                a[c * d + j] /= p;
                inv[c * d + j] /= p;
            }
            for r in 0..d {
                if r != c {
                    let f = a[r * d + c];
                    for j in 0..d {
                        a[r * d + j] -= f * a[c * d + j];
                        inv[r * d + j] -= f * inv[c * d + j];
                    }
                }
            }
        }
        Gaussian { mean, prec: inv, d }
    }
    fn ln_pdf(&self, x: &[f64]) -> f64 {
        assert!(
            x.iter().all(|v| (0.0..=1.0).contains(v)),
            "out-of-support proposal evaluated"
        );
        let d = self.d;
        let r: Vec<f64> = (0..d).map(|i| x[i] - self.mean[i]).collect();
        let mut q = 0.0;
        for i in 0..d {
            for j in 0..d {
                q += r[i] * self.prec[i * d + j] * r[j];
            }
        }
        -0.5 * q
    }
}

fn run_chains(g: &Gaussian, cfg: &MhConfig, n_chains: usize, iters: u64, seed: u64) -> Vec<Draws> {
    let flat = vec![Triangular::new(0.0, 0.5, 1.0).unwrap(); g.d];
    let starts = mcmc::dispersed_starts(&flat, n_chains, seed);
    starts
        .into_iter()
        .enumerate()
        .map(|(c, s)| {
            let lp = g.ln_pdf(&s);
            let mut st = ChainState::new(cfg.clone(), s, lp, seed, c as u64).unwrap();
            let d = mcmc::run_segment(&mut st, iters, |x| g.ln_pdf(x));
            let acc = st.acceptance_rate_post_burn_in();
            assert!(acc > 0.1 && acc < 0.6, "acceptance {acc}");
            d
        })
        .collect()
}

fn check_recovery(g: &Gaussian, cov: &[f64], draws: &[Draws]) {
    let d = g.d;
    let n: usize = draws.iter().map(|c| c.len()).sum();
    let cols: Vec<Vec<f64>> = (0..d)
        .map(|j| draws.iter().flat_map(|c| c.column(j)).collect())
        .collect();
    let means: Vec<f64> = cols
        .iter()
        .map(|c| c.iter().sum::<f64>() / n as f64)
        .collect();
    for j in 0..d {
        let chains: Vec<Vec<f64>> = draws.iter().map(|c| c.column(j)).collect();
        let ess = diagnostics::ess_bulk(&chains).unwrap();
        let rhat = diagnostics::rhat(&chains).unwrap();
        assert!(rhat < 1.01, "coordinate {j}: rhat {rhat}");
        let sd = cov[j * d + j].sqrt();
        let mcse = sd / ess.sqrt();
        assert!(
            (means[j] - g.mean[j]).abs() < 5.0 * mcse,
            "coordinate {j}: mean {} vs {} (mcse {mcse})",
            means[j],
            g.mean[j]
        );
        for k in 0..d {
            let c: f64 = (0..n)
                .map(|t| (cols[j][t] - means[j]) * (cols[k][t] - means[k]))
                .sum::<f64>()
                / (n - 1) as f64;
            // Compare on the correlation scale; the MC error of a covariance estimate with
            // ESS ~ 1e3..1e4 is a few per cent of sd_j sd_k.
            let scale = (cov[j * d + j] * cov[k * d + k]).sqrt();
            let tol = 6.0 * (1.0 + (cov[j * d + k] / scale).powi(2)).sqrt() / ess.sqrt();
            assert!(
                ((c - cov[j * d + k]) / scale).abs() < tol,
                "cov[{j},{k}] = {c} vs {} (tol {tol})",
                cov[j * d + k]
            );
        }
    }
}

#[test]
fn recovers_correlated_2d_gaussian() {
    let (s1, s2, rho) = (0.05, 0.08, 0.8);
    let cov = vec![s1 * s1, rho * s1 * s2, rho * s1 * s2, s2 * s2];
    let g = Gaussian::new(vec![0.4, 0.6], &cov);
    let cfg = MhConfig {
        burn_in: 3000,
        adapt_start: 300,
        ..MhConfig::default()
    };
    let draws = run_chains(&g, &cfg, 4, 3000 + 15_000, 11);
    check_recovery(&g, &cov, &draws);
}

/// A 10-D Gaussian with AR(1)-like correlations 0.6^|i-j| and sds 0.02-0.056, and its covariance.
fn gaussian_10d() -> (Gaussian, Vec<f64>) {
    let d = 10;
    let sd: Vec<f64> = (0..d).map(|i| 0.02 + 0.004 * i as f64).collect();
    let mut cov = vec![0.0; d * d];
    for i in 0..d {
        for j in 0..d {
            cov[i * d + j] = 0.6f64.powi((i as i32 - j as i32).abs()) * sd[i] * sd[j];
        }
    }
    let mean: Vec<f64> = (0..d).map(|i| 0.3 + 0.04 * i as f64).collect();
    (Gaussian::new(mean, &cov), cov)
}

#[test]
fn recovers_10d_gaussian() {
    let (g, cov) = gaussian_10d();
    let cfg = MhConfig {
        burn_in: 10_000,
        adapt_start: 1000,
        ..MhConfig::default()
    };
    let draws = run_chains(&g, &cfg, 4, 10_000 + 40_000, 5);
    check_recovery(&g, &cov, &draws);
}

fn banana(x: &[f64]) -> f64 {
    assert!(x.iter().all(|v| (0.0..=1.0).contains(v)));
    let a = (x[0] - 0.5) / 0.1;
    let b = (x[1] - 0.3 - 2.0 * (x[0] - 0.5).powi(2)) / 0.05;
    -0.5 * (a * a + b * b) - 0.5 * ((x[2] - 0.95) / 0.05).powi(2)
}

fn cfg_small() -> MhConfig {
    MhConfig {
        burn_in: 400,
        adapt_start: 50,
        adapt_every: 7,
        initial_sd: 0.2,
        ..MhConfig::default()
    }
}

#[test]
fn deterministic_for_a_seed() {
    let run = |seed| {
        let mut s =
            ChainState::new(cfg_small(), vec![0.5, 0.5, 0.5], banana(&[0.5; 3]), seed, 0).unwrap();
        mcmc::run_segment(&mut s, 1000, banana)
    };
    assert_eq!(run(3), run(3));
    assert_ne!(run(3).points, run(4).points);
}

/// Runs 1,500 iterations of a chain with `cfg` at once and in checkpointed segments (split
/// inside burn-in, right at its end and after it; each checkpoint through JSON), asserts that
/// both give the same state and bit-identical draws, and returns the final state.
fn assert_segments_equal_one_run(cfg: MhConfig) -> ChainState {
    let start = vec![0.2, 0.7, 0.9];
    let lp = banana(&start);
    let mut whole = ChainState::new(cfg.clone(), start.clone(), lp, 9, 2).unwrap();
    let all = mcmc::run_segment(&mut whole, 1500, banana);
    assert_eq!(all.len(), 1100);

    let mut st = ChainState::new(cfg, start, lp, 9, 2).unwrap();
    let mut pieces = Draws::new(3);
    for n in [123, 277, 1, 599, 500] {
        pieces.extend(&mcmc::run_segment(&mut st, n, banana));
        let json = serde_json::to_string(&st).unwrap();
        st = serde_json::from_str(&json).unwrap();
    }
    assert_eq!(st, whole);
    assert_eq!(pieces.points, all.points, "draws differ bit for bit");
    assert_eq!(pieces.log_density, all.log_density);
    whole
}

#[test]
fn segments_with_checkpoints_equal_one_run() {
    assert_segments_equal_one_run(cfg_small());
}

#[test]
fn batched_equals_single_chains_and_skips_out_of_support() {
    let starts = [
        vec![0.5, 0.5, 0.98],
        vec![0.1, 0.9, 0.99],
        vec![0.9, 0.2, 0.97],
    ];
    let single: Vec<Draws> = starts
        .iter()
        .enumerate()
        .map(|(c, s)| {
            let mut st = ChainState::new(cfg_small(), s.clone(), banana(s), 1, c as u64).unwrap();
            mcmc::run_segment(&mut st, 900, banana)
        })
        .collect();
    let mut states: Vec<ChainState> = starts
        .iter()
        .enumerate()
        .map(|(c, s)| ChainState::new(cfg_small(), s.clone(), banana(s), 1, c as u64).unwrap())
        .collect();
    let mut calls = 0;
    let mut smaller_batches = 0;
    let batched = mcmc::run_segment_batch(&mut states, 900, |pts: &[Vec<f64>]| {
        calls += 1;
        if pts.len() < 3 {
            smaller_batches += 1;
        }
        pts.iter().map(|p| banana(p)).collect()
    })
    .unwrap();
    assert_eq!(batched, single);
    assert!(calls <= 900);
    // The mode sits near the upper bound of x[2], so some proposals leave the support.
    assert!(smaller_batches > 0);
}

#[test]
fn dispersed_starts_are_seeded_per_chain() {
    let p = vec![Triangular::new(10.0, 12.0, 20.0).unwrap(); 3];
    let a = mcmc::dispersed_starts(&p, 4, 42);
    assert_eq!(a, mcmc::dispersed_starts(&p, 4, 42));
    assert_ne!(a[0], a[1]);
    assert!(a.iter().flatten().all(|u| (0.0..=1.0).contains(u)));
    // Chain c's start does not depend on how many chains are asked for.
    assert_eq!(mcmc::dispersed_starts(&p, 2, 42)[1], a[1]);
}

/// The random-walk / independence mixture started from an optimum with the Laplace covariance
/// (`optim` + `ChainState::with_proposal`): the mixture leaves the posterior invariant, so mean
/// and covariance are recovered, and the independence steps are accepted often.
#[test]
fn mixture_from_the_optimum_recovers_10d_gaussian() {
    use bemcal_stats::optim::{maximise_batch, BfgsConfig};
    let (g, cov) = gaussian_10d();
    let flat = vec![Triangular::new(0.0, 0.5, 1.0).unwrap(); g.d];
    let starts = mcmc::dispersed_starts(&flat, 4, 21);
    let lps: Vec<f64> = starts.iter().map(|s| g.ln_pdf(s)).collect();
    let optima = maximise_batch(&starts, &lps, &BfgsConfig::default(), |us| {
        us.iter().map(|u| g.ln_pdf(u)).collect()
    });
    let cfg = MhConfig {
        burn_in: 1000,
        adapt_start: 1000,
        independence: 0.5,
        ..MhConfig::default()
    };
    let mut states = mcmc::chains_at_optima(&cfg, optima, 21, 0, f64::INFINITY).unwrap();
    let draws = mcmc::run_segment_batch(&mut states, 1000 + 10_000, |pts: &[Vec<f64>]| {
        pts.iter().map(|p| g.ln_pdf(p)).collect()
    })
    .unwrap();
    for s in &states {
        let a = s.independence_acceptance_rate();
        assert!(!s.independence_dropped());
        assert!(a > 0.4, "independence acceptance {a}");
        assert!(s.independence_steps() > 4000);
    }
    check_recovery(&g, &cov, &draws);
}

/// The mixture on a non-Gaussian target against the boundary of the cube (the banana, its
/// third coordinate piled against 1): still invariant, checked against long plain RW chains.
#[test]
fn mixture_on_a_bounded_banana_matches_random_walk() {
    let moments = |cfg: &MhConfig, iters: u64| {
        let mut sum = [0.0f64; 3];
        let mut n = 0.0;
        for c in 0..4u64 {
            let start = vec![0.5, 0.35, 0.9];
            let mut s = ChainState::new(cfg.clone(), start.clone(), banana(&start), 77, c).unwrap();
            let d = mcmc::run_segment(&mut s, iters, banana);
            for i in 0..d.len() {
                for (k, v) in d.point(i).iter().enumerate() {
                    sum[k] += v;
                }
                n += 1.0;
            }
        }
        sum.map(|v| v / n)
    };
    let rw = MhConfig {
        burn_in: 2000,
        adapt_start: 500,
        ..MhConfig::default()
    };
    let mix = MhConfig {
        independence: 0.5,
        ..rw.clone()
    };
    let a = moments(&rw, 42_000);
    let b = moments(&mix, 42_000);
    // Posterior sds are 0.1, ~0.07 and ~0.03; 160,000 draws each.
    for k in 0..3 {
        assert!(
            (a[k] - b[k]).abs() < 0.01,
            "coordinate {k}: {} vs {}",
            a[k],
            b[k]
        );
    }
}

/// An independence proposal far narrower than the posterior (1/10 of its sds in 10 dimensions)
/// is almost never accepted during burn-in, so it is switched off at its end: every recorded
/// iteration is then a random-walk step, and the chain still recovers the posterior. A matched
/// one (the previous test's) is kept.
#[test]
fn an_idle_independence_kernel_is_dropped_after_burn_in() {
    let (g, cov) = gaussian_10d();
    let narrow: Vec<f64> = cov.iter().map(|v| v * 0.01).collect();
    let cfg = MhConfig {
        burn_in: 2000,
        adapt_start: 2000,
        independence: 0.5,
        ..MhConfig::default()
    };
    let mut states: Vec<ChainState> = (0..4)
        .map(|c| {
            ChainState::with_proposal(cfg.clone(), g.mean.clone(), 0.0, &narrow, 5, c).unwrap()
        })
        .collect();
    let draws = mcmc::run_segment_batch(&mut states, 2000 + 20_000, |pts: &[Vec<f64>]| {
        pts.iter().map(|p| g.ln_pdf(p)).collect()
    })
    .unwrap();
    for s in &states {
        assert!(s.independence_dropped());
        assert_eq!(s.independence_steps(), 0);
    }
    check_recovery(&g, &cov, &draws);
}

#[test]
fn mixture_checkpoints_resume_bit_identically() {
    let end = assert_segments_equal_one_run(MhConfig {
        independence: 0.5,
        ..cfg_small()
    });
    assert!(end.independence_steps() > 300);
}

/// Mode pruning at optimised starts (`chains_at_optima` with `restart_below`): two Gaussian
/// modes, the second 50 nats lower; the two chains whose BFGS ends there start in the major
/// mode instead, say so, and all four chains then agree.
#[test]
fn optima_far_below_the_best_start_in_its_mode() {
    use bemcal_stats::optim::{maximise_batch, BfgsConfig};
    let lnp = |u: &[f64]| {
        let q = |m: f64| u.iter().map(|x| (x - m) * (x - m)).sum::<f64>() / (2.0 * 0.03 * 0.03);
        let (a, b) = (-q(0.3), -q(0.7) - 50.0);
        a.max(b) + (1.0 + (-(a - b).abs()).exp()).ln()
    };
    let starts = vec![
        vec![0.25, 0.3],
        vec![0.35, 0.32],
        vec![0.72, 0.7],
        vec![0.68, 0.66],
    ];
    let lps: Vec<f64> = starts.iter().map(|s| lnp(s)).collect();
    let optima = maximise_batch(&starts, &lps, &BfgsConfig::default(), |us| {
        us.iter().map(|u| lnp(u)).collect()
    });
    let cfg = MhConfig {
        burn_in: 500,
        adapt_start: 500,
        ..MhConfig::default()
    };
    let mut states = mcmc::chains_at_optima(&cfg, optima, 5, 0, 20.0).unwrap();
    let moved: Vec<Option<f64>> = states.iter().map(|s| s.moved_from_mode()).collect();
    assert_eq!(moved[..2], [None, None]);
    for gap in moved[2..].iter() {
        let gap = gap.expect("a chain at the minor mode is moved");
        assert!((gap - 50.0).abs() < 1.0, "gap {gap}");
    }
    let draws = mcmc::run_segment_batch(&mut states, 2500, |pts: &[Vec<f64>]| {
        pts.iter().map(|p| lnp(p)).collect()
    })
    .unwrap();
    for j in 0..2 {
        let cols: Vec<Vec<f64>> = draws.iter().map(|d| d.column(j)).collect();
        let g = bemcal_stats::diagnostics::diagnose(&cols).unwrap();
        assert!(g.rhat < 1.05, "coordinate {j}: R-hat {}", g.rhat);
        assert!(
            (g.mean - 0.3).abs() < 0.01,
            "coordinate {j}: mean {}",
            g.mean
        );
    }
    // Without pruning the chains stay in both modes.
    let optima = maximise_batch(&starts, &lps, &BfgsConfig::default(), |us| {
        us.iter().map(|u| lnp(u)).collect()
    });
    let kept = mcmc::chains_at_optima(&cfg, optima, 5, 0, f64::INFINITY).unwrap();
    assert!(kept.iter().all(|s| s.moved_from_mode().is_none()));
    assert!(kept[2].position()[0] > 0.6);
}

//! Chains on the paper-size calibration problem (run by `scripts/bench_chains.sh`).
//!
//! ```text
//! bench_chains [SURROGATE_DIR] --epw EPW [--iterations 10000] [--burn-in 2000] [--chains 4]
//!              [--threads 2] [--seed 1]
//! ```
//!
//! SURROGATE_DIR: an exported surrogate (e.g. the paper-size random-weight model written by
//! `python/tools/bench_torch.py`: 38 parameters, LSTM 2 x 128, lookback 3, 3 outputs).
//! Synthetic observations are the surrogate at a hidden truth (prior modes moved by a seeded
//! fraction of the prior range) times `1 + 0.05 N(0, 1)`, with a month of missing hours. The
//! posterior is the pipeline's (crates/calibrate/src/posterior.rs): triangular priors, the
//! Gaussian likelihood of reference Eq. 7 with `sigma_eta` from the surrogate metadata,
//! `sigma_y` = 2 % of the mean and `sigma_delta` sampled on the log scale under a half-Cauchy
//! prior ([`SigmaDeltaBox`]). Prints evaluations per second, wall time, acceptance, max R-hat,
//! min bulk/tail ESS, ESS per second, and whether the target is met (`BENCH_INT8=1`: the chains
//! evaluate the int8 graph, the observations still come from the float one): 4 chains x 10,000
//! iterations (2,000 burn-in) with R-hat <= 1.01 and bulk ESS >= 400 for every parameter in
//! under 15 minutes. `BENCH_OPTIMISED=1` also prints a check of the Laplace Gaussian at the
//! first optimum (predicted against actual log-posterior changes at 8 of its draws) and, with
//! `BENCH_OPTIMA=FILE`, reuses the optima stored in FILE (or stores them there).
//! `BENCH_HMC=1` (with `BENCH_OPTIMISED=1`): exact-gradient BFGS through the surrogate's VJP
//! graph, a gradient check, then HMC chains (`stats::hmc`) instead of Metropolis-Hastings
//! (`BENCH_HMC_TIME`, `BENCH_HMC_TARGET`, `BENCH_HMC_LENGTH_JITTER`, `BENCH_HMC_ADAPT=0`
//! override the defaults).

use std::time::Instant;

use bemcal_calibrate::posterior::SigmaDeltaBox;
use bemcal_stats::diagnostics::diagnose;
use bemcal_stats::likelihood::{
    ln_prior_log_sigma_delta, GaussianLikelihood, OutputNoise, SigmaPrior,
};
use bemcal_stats::mcmc::{dispersed_starts, run_segment_batch, ChainState, Draws, MhConfig};
use bemcal_stats::prior::Triangular;
use bemcal_surrogate::{Evaluator, Precision, Surrogate};
use bemcal_weather::{Calendar, Epw, Holidays, HourlyFeatures};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;

type BoxResult<T> = Result<T, Box<dyn std::error::Error>>;

/// Target of issue 4: the full run's size and limits.
const TARGET_ITER: u64 = 10_000;
const TARGET_BURN: u64 = 2_000;
const TARGET_SECONDS: f64 = 900.0;
const TARGET_RHAT: f64 = 1.01;
const TARGET_ESS: f64 = 400.0;

struct Args {
    surrogate: Option<String>,
    epw: Option<String>,
    iterations: u64,
    burn_in: u64,
    chains: usize,
    threads: usize,
    seed: u64,
}

fn parse_args() -> BoxResult<Args> {
    let mut a = Args {
        surrogate: None,
        epw: None,
        iterations: TARGET_ITER,
        burn_in: TARGET_BURN,
        chains: 4,
        threads: 2,
        seed: 1,
    };
    let mut it = std::env::args().skip(1);
    while let Some(s) = it.next() {
        let mut val = || it.next().ok_or(format!("{s} needs a value"));
        match s.as_str() {
            "--epw" => a.epw = Some(val()?),
            "--iterations" => a.iterations = val()?.parse()?,
            "--burn-in" => a.burn_in = val()?.parse()?,
            "--chains" => a.chains = val()?.parse()?,
            "--threads" => a.threads = val()?.parse()?,
            "--seed" => a.seed = val()?.parse()?,
            _ if !s.starts_with("--") && a.surrogate.is_none() => a.surrogate = Some(s),
            _ => return Err(format!("unknown argument {s}").into()),
        }
    }
    if a.burn_in >= a.iterations {
        return Err("--burn-in must be below --iterations".into());
    }
    Ok(a)
}

fn loadavg() -> String {
    std::fs::read_to_string("/proc/loadavg")
        .map(|s| s.split_whitespace().take(3).collect::<Vec<_>>().join(" "))
        .unwrap_or_else(|_| "?".into())
}

/// The log posterior over the unit space: `d` calibrated parameters, then `K` coordinates of
/// `ln sigma_delta,k` (as `bemcal_calibrate::posterior::Posterior` in hyperparameter mode,
/// without model constraints: the random-weight surrogate has none).
struct Target<'a> {
    priors: &'a [Triangular],
    lik: &'a GaussianLikelihood,
    sigma_box: &'a SigmaDeltaBox,
    /// The pipeline's default: variances integrated out, AR(1) residuals (no sigma dimensions).
    /// `BENCH_SAMPLED_SIGMA=1` samples ln sigma_delta instead.
    marginal: bool,
}

impl Target<'_> {
    /// Number of sampled sigma coordinates.
    fn k_sig(&self) -> usize {
        if self.marginal {
            0
        } else {
            self.sigma_box.len()
        }
    }
}

impl Target<'_> {
    fn theta(&self, u: &[f64]) -> Vec<f64> {
        self.priors
            .iter()
            .zip(u)
            .map(|(p, u)| p.from_unit(*u))
            .collect()
    }

    fn ln_prior(&self, u: &[f64]) -> f64 {
        let d = self.priors.len();
        let b = self.sigma_box;
        let mut lp: f64 = self
            .priors
            .iter()
            .zip(self.theta(u))
            .map(|(p, x)| p.ln_pdf(x))
            .sum();
        for k in 0..self.k_sig() {
            let ln_s = b.lo[k] + u[d + k] * (b.hi[k] - b.lo[k]);
            lp += ln_prior_log_sigma_delta(ln_s, b.scale[k], SigmaPrior::HalfCauchy);
        }
        lp
    }

    /// Log posterior and its unit-space gradient of a batch (marginal AR(1) likelihood only):
    /// one surrogate call and one VJP call; counts both.
    fn batch_grad(
        &self,
        ev: &mut Evaluator,
        us: &[Vec<f64>],
        evals: &mut u64,
        grads: &mut u64,
    ) -> Vec<(f64, Vec<f64>)> {
        assert!(self.marginal, "HMC runs with the marginal likelihood");
        let mut out: Vec<(f64, Vec<f64>)> = us
            .iter()
            .map(|u| {
                let inside = u.iter().all(|v| (0.0..=1.0).contains(v));
                let lp = if inside {
                    self.ln_prior(u)
                } else {
                    f64::NEG_INFINITY
                };
                let g = bemcal_stats::prior::grad_ln_prior_unit(self.priors, u);
                (lp, g)
            })
            .collect();
        let live: Vec<usize> = (0..us.len()).filter(|&i| out[i].0.is_finite()).collect();
        if live.is_empty() {
            return out;
        }
        let thetas: Vec<Vec<f64>> = live.iter().map(|&i| self.theta(&us[i])).collect();
        *evals += thetas.len() as u64;
        *grads += thetas.len() as u64;
        let pred = ev.evaluate_batch(&thetas).expect("surrogate evaluation");
        let mut cot = ndarray::Array3::<f32>::zeros(pred.dim());
        let per = pred.len() / thetas.len();
        {
            let flat = pred.as_slice().expect("contiguous prediction");
            let cflat = cot.as_slice_mut().expect("contiguous");
            for (b, &i) in live.iter().enumerate() {
                out[i].0 += self.lik.log_marginal_sigma_ar1_gradient(
                    &flat[b * per..(b + 1) * per],
                    &mut cflat[b * per..(b + 1) * per],
                );
            }
        }
        let g = ev
            .vjp_batch(&thetas, cot.view())
            .expect("surrogate gradient");
        for (gb, &i) in g.iter().zip(&live) {
            for ((o, gj), p) in out[i].1.iter_mut().zip(gb).zip(self.priors) {
                *o += gj * p.width();
            }
        }
        out
    }

    /// Log posterior of a batch with one surrogate call; counts the evaluations.
    fn batch(&self, ev: &mut Evaluator, us: &[Vec<f64>], evals: &mut u64) -> Vec<f64> {
        let d = self.priors.len();
        let k_out = self.k_sig();
        let priors: Vec<f64> = us.iter().map(|u| self.ln_prior(u)).collect();
        let live: Vec<usize> = (0..us.len()).filter(|&i| priors[i].is_finite()).collect();
        let mut out = vec![f64::NEG_INFINITY; us.len()];
        if live.is_empty() {
            return out;
        }
        let thetas: Vec<Vec<f64>> = live.iter().map(|&i| self.theta(&us[i])).collect();
        *evals += thetas.len() as u64;
        let pred = ev.evaluate_batch(&thetas).expect("surrogate evaluation");
        let flat = pred.as_slice().expect("contiguous prediction");
        let per = flat.len() / thetas.len();
        for (b, &i) in live.iter().enumerate() {
            if self.marginal {
                out[i] = priors[i]
                    + self
                        .lik
                        .log_marginal_sigma_ar1(&flat[b * per..(b + 1) * per]);
                continue;
            }
            let sd: Vec<f64> = (0..k_out)
                .map(|k| self.sigma_box.sigma(k, us[i][d + k]))
                .collect();
            out[i] = priors[i]
                + self
                    .lik
                    .log_likelihood_with_delta(&flat[b * per..(b + 1) * per], &sd);
        }
        out
    }
}

fn main() -> BoxResult<()> {
    let a = parse_args()?;
    let dir = a
        .surrogate
        .clone()
        .ok_or("usage: bench_chains SURROGATE_DIR --epw EPW [--iterations N] [--burn-in N] [--chains C] [--threads T] [--seed S]")?;
    let epw_path = a.epw.clone().ok_or("--epw EPW is required")?;
    let cpus = std::thread::available_parallelism().map_or(0, |n| n.get());
    println!(
        "machine: {cpus} cores; surrogate threads {}; load average at start {}",
        a.threads,
        loadavg()
    );

    let epw = Epw::read(&epw_path)?;
    let features = HourlyFeatures::from_epw(&epw, &Calendar::new(2021, Holidays::UsFederal));
    // The observations come from the float graph; `BENCH_INT8=1` runs the chains on the int8
    // graph (its error against the float graph then acts as model error).
    let mut ev_truth = Surrogate::load(&dir, a.threads)?.bind(&features)?;
    let int8 = std::env::var("BENCH_INT8").is_ok_and(|v| v == "1");
    let precision = if int8 {
        Precision::Int8
    } else {
        Precision::F32
    };
    let mut ev = Surrogate::load_with(&dir, a.threads, precision)?.bind(&features)?;
    println!("chains evaluate the {precision:?} graph");
    let meta = ev.surrogate().meta().clone();
    let priors: Vec<Triangular> = meta
        .params
        .iter()
        .map(|p| Triangular::new(p.min, p.mode, p.max))
        .collect::<Result<_, _>>()?;
    let (d, k_out, n_h) = (priors.len(), meta.outputs.len(), ev.n_hours());

    // Hidden truth: prior modes moved by a seeded fraction (up to +-15 %) of the prior range.
    let mut rng = ChaCha8Rng::seed_from_u64(a.seed ^ 0x7275_7468);
    let truth: Vec<f64> = priors
        .iter()
        .map(|p| {
            let f: f64 = rng.random_range(-0.15..0.15);
            (p.mode() + f * p.width()).clamp(p.min() + 0.02 * p.width(), p.max() - 0.02 * p.width())
        })
        .collect();
    let clean = ev_truth.evaluate_batch(std::slice::from_ref(&truth))?;
    let clean: Vec<f64> = clean
        .as_slice()
        .ok_or("non-contiguous prediction")?
        .iter()
        .map(|v| *v as f64)
        .collect();
    // Noise 5 % multiplicative; March (hours 1,416 .. 2,160) missing for every output.
    let gap = 1416..2160;
    let observed: Vec<f64> = clean
        .iter()
        .enumerate()
        .map(|(i, v)| {
            if gap.contains(&(i / k_out)) {
                f64::NAN
            } else {
                v * (1.0 + 0.05 * rng.sample::<f64, _>(StandardNormal))
            }
        })
        .collect();
    let stats: Vec<(f64, f64)> = (0..k_out)
        .map(|k| {
            let v: Vec<f64> = (0..n_h)
                .map(|t| observed[t * k_out + k])
                .filter(|v| v.is_finite())
                .collect();
            let m = v.iter().sum::<f64>() / v.len() as f64;
            let s =
                (v.iter().map(|x| (x - m) * (x - m)).sum::<f64>() / (v.len() - 1) as f64).sqrt();
            (m, s)
        })
        .collect();
    let noise: Vec<OutputNoise> = stats
        .iter()
        .zip(meta.sigma_eta_kwh())
        .map(|((m, s), eta)| OutputNoise {
            sigma_y: 0.02 * m.abs(),
            sigma_delta: 0.2 * s,
            sigma_eta: eta,
        })
        .collect();
    let lik = GaussianLikelihood::new(&observed, &noise)?;
    let sd: Vec<f64> = stats.iter().map(|(_, s)| s.max(1e-9)).collect();
    let sigma_box = SigmaDeltaBox::new(&sd, &vec![true; sd.len()]);
    let target = Target {
        priors: &priors,
        lik: &lik,
        sigma_box: &sigma_box,
        marginal: std::env::var("BENCH_SAMPLED_SIGMA").map_or(true, |v| v != "1"),
    };
    let k_sig = target.k_sig();
    println!(
        "likelihood: {}",
        if target.marginal {
            "variances integrated out, AR(1) residuals (the pipeline's default)"
        } else {
            "sigma_delta sampled (half-Cauchy), iid residuals"
        }
    );
    println!(
        "problem: {d} parameters + {k_sig} log sigma_delta, {n_h} h x {k_out} outputs ({} observed), LSTM {} x {}, lookback {}",
        lik.n_observed().iter().sum::<usize>(),
        meta.model.layers,
        meta.model.hidden,
        meta.model.lookback
    );

    // Chains: dispersed starts from the priors, sigma_delta coordinates at 0.6 (as the pipeline).
    let mut starts = dispersed_starts(&priors, a.chains, a.seed);
    for s in &mut starts {
        s.extend(std::iter::repeat_n(0.6, k_sig));
    }
    // As the pipeline's defaults (prior draws, adaptive Metropolis); BENCH_OPTIMISED=1: the
    // `mcmc.start = "optimised"`, `independence = 0.5` variant.
    let prior_starts = !std::env::var("BENCH_OPTIMISED").is_ok_and(|v| v == "1");
    let config = MhConfig {
        burn_in: a.burn_in,
        adapt_start: if prior_starts {
            (a.burn_in / 2).max(100).min(a.burn_in)
        } else {
            a.burn_in
        },
        initial_sd: 0.02,
        independence: if prior_starts {
            0.0
        } else {
            std::env::var("BENCH_INDEPENDENCE").map_or(Ok(0.5), |v| v.parse())?
        },
        ..MhConfig::default()
    };
    let mut evals = 0u64;
    let t_start = Instant::now();
    let init = target.batch(&mut ev, &starts, &mut evals);
    let mut states: Vec<ChainState> = if prior_starts {
        starts
            .iter()
            .zip(init)
            .enumerate()
            .map(|(c, (s, lp))| ChainState::new(config.clone(), s.clone(), lp, a.seed, c as u64))
            .collect::<Result<_, _>>()?
    } else {
        // BENCH_OPTIMA=FILE: the optima (point, log posterior, Laplace covariance) are read
        // from FILE when it exists, else found and written there (for repeated chain runs).
        let cache = std::env::var("BENCH_OPTIMA").ok();
        let optima = match cache
            .as_deref()
            .filter(|f| std::path::Path::new(f).exists())
        {
            Some(f) => {
                let v: Vec<(Vec<f64>, f64, Vec<f64>)> =
                    serde_json::from_str(&std::fs::read_to_string(f)?)?;
                v.into_iter()
                    .map(
                        |(point, log_density, covariance)| bemcal_stats::optim::Optimum {
                            point,
                            log_density,
                            covariance,
                            iterations: 0,
                            evaluations: 0,
                        },
                    )
                    .collect()
            }
            None => {
                let cfg = bemcal_stats::optim::BfgsConfig::default();
                // BENCH_HMC=1: BFGS with the VJP gradient (as the pipeline when the surrogate
                // has the gradient graph); else finite differences.
                let o = if std::env::var("BENCH_HMC").is_ok_and(|v| v == "1") {
                    let cell = std::cell::RefCell::new((&mut ev, &mut evals, 0u64));
                    let o = bemcal_stats::optim::maximise_batch_with_gradient(
                        &starts,
                        &init,
                        &cfg,
                        |us: &[Vec<f64>]| {
                            let c = &mut *cell.borrow_mut();
                            target.batch(c.0, us, c.1)
                        },
                        &mut |us: &[Vec<f64>]| {
                            let c = &mut *cell.borrow_mut();
                            target.batch_grad(c.0, us, c.1, &mut c.2)
                        },
                    );
                    eprintln!(
                        "  BFGS with VJP gradients: {} gradient calls",
                        cell.borrow().2
                    );
                    o
                } else {
                    bemcal_stats::optim::maximise_batch(
                        &starts,
                        &init,
                        &cfg,
                        |us: &[Vec<f64>]| target.batch(&mut ev, us, &mut evals),
                    )
                };
                if let Some(f) = &cache {
                    let v: Vec<_> = o
                        .iter()
                        .map(|o| (&o.point, o.log_density, &o.covariance))
                        .collect();
                    std::fs::write(f, serde_json::to_string(&v)?)?;
                }
                o
            }
        };
        laplace_check(&optima[0], |us| target.batch(&mut ev, us, &mut evals));
        if std::env::var("BENCH_HMC").is_ok_and(|v| v == "1") {
            return run_hmc(
                &a, &target, &mut ev, optima, &priors, &truth, &meta, t_start, evals,
            );
        }
        eprintln!(
            "  optimised starts: log posterior {:?}, {evals} evaluations, {:.0} s",
            optima
                .iter()
                .map(|o| o.log_density.round())
                .collect::<Vec<_>>(),
            t_start.elapsed().as_secs_f64()
        );
        bemcal_stats::mcmc::chains_at_optima(&config, optima, a.seed, 0, 20.0)?
    };
    let mut draws: Vec<Draws> = states.iter().map(|s| Draws::new(s.dim())).collect();
    let segment = 500u64;
    let mut done = 0u64;
    while done < a.iterations {
        let n = segment.min(a.iterations - done);
        let seg = run_segment_batch(&mut states, n, |us: &[Vec<f64>]| {
            target.batch(&mut ev, us, &mut evals)
        })?;
        for (dr, s) in draws.iter_mut().zip(&seg) {
            dr.extend(s);
        }
        done += n;
        let el = t_start.elapsed().as_secs_f64();
        eprintln!(
            "  {done}/{} iterations, {el:.0} s, {:.2} evals/s, load {}",
            a.iterations,
            evals as f64 / el,
            loadavg()
        );
    }
    let wall = t_start.elapsed().as_secs_f64();
    let evals_per_s = evals as f64 / wall;

    // Diagnostics over the post-burn-in draws, every coordinate (sigma_delta included).
    let dim = d + k_sig;
    let (mut max_rhat, mut min_bulk, mut min_tail) = (0.0f64, f64::INFINITY, f64::INFINITY);
    let mut worst = (0usize, 0usize);
    let mut covered = 0;
    for j in 0..dim {
        let cols: Vec<Vec<f64>> = draws.iter().map(|dr| dr.column(j)).collect();
        let g = diagnose(&cols)?;
        if g.rhat > max_rhat {
            max_rhat = g.rhat;
            worst.0 = j;
        }
        if g.ess_bulk < min_bulk {
            min_bulk = g.ess_bulk;
            worst.1 = j;
        }
        min_tail = min_tail.min(g.ess_tail);
        if j < d {
            let u = priors[j].to_unit(truth[j]);
            if (g.q5..=g.q95).contains(&u) {
                covered += 1;
            }
        }
    }
    for (c, s) in states.iter().enumerate() {
        println!(
            "chain {c}: acceptance {:.3} (independence steps {:.3} of {}{}), final log posterior {:.1}",
            s.acceptance_rate_post_burn_in(),
            s.independence_acceptance_rate(),
            s.independence_steps(),
            if s.independence_dropped() {
                "; dropped after burn-in"
            } else {
                ""
            },
            s.log_density()
        );
    }
    let acc: f64 = states
        .iter()
        .map(|s| s.acceptance_rate_post_burn_in())
        .sum::<f64>()
        / states.len() as f64;
    let name = |j: usize| -> String {
        if j < d {
            meta.params[j].name.clone()
        } else {
            format!("ln sigma_delta[{}]", meta.outputs[j - d].name)
        }
    };
    let per_iter = wall / a.iterations as f64;
    let projected = per_iter * TARGET_ITER as f64;
    println!(
        "run: {} chains x {} iterations ({} burn-in), {} surrogate+likelihood evaluations",
        a.chains, a.iterations, a.burn_in, evals
    );
    println!("evaluations per second (surrogate + likelihood): {evals_per_s:.2}");
    println!("total wall time: {wall:.1} s ({per_iter:.3} s per iteration of all chains)");
    println!("post-burn-in acceptance (mean over chains): {acc:.3}");
    println!(
        "max R-hat: {max_rhat:.4} ({}); min bulk ESS: {min_bulk:.0} ({}); min tail ESS: {min_tail:.0}",
        name(worst.0),
        name(worst.1)
    );
    println!(
        "min bulk ESS per second: {:.3}; truth inside the 90 % interval for {covered}/{d} parameters",
        min_bulk / wall
    );
    let converged = max_rhat <= TARGET_RHAT && min_bulk >= TARGET_ESS;
    let full = a.iterations == TARGET_ITER && a.burn_in == TARGET_BURN && a.chains == 4;
    println!(
        "projected wall time of the full run (4 x {TARGET_ITER}, {TARGET_BURN} burn-in) at the measured rate: {:.1} min (limit {:.0} min) -> {}",
        projected / 60.0,
        TARGET_SECONDS / 60.0,
        if projected < TARGET_SECONDS { "within" } else { "OVER" }
    );
    if full {
        println!(
            "TARGET {}: wall {:.1} min < 15: {}, R-hat <= {TARGET_RHAT}: {}, bulk ESS >= {TARGET_ESS}: {}",
            if converged && wall < TARGET_SECONDS { "MET" } else { "NOT MET" },
            wall / 60.0,
            wall < TARGET_SECONDS,
            max_rhat <= TARGET_RHAT,
            min_bulk >= TARGET_ESS
        );
    } else {
        println!(
            "(shortened run: convergence criteria on these draws: R-hat <= {TARGET_RHAT}: {}, bulk ESS >= {TARGET_ESS}: {}; FULL=1 runs the target)",
            max_rhat <= TARGET_RHAT,
            min_bulk >= TARGET_ESS
        );
    }
    println!("load average at end {}", loadavg());
    Ok(())
}

/// How well the Laplace Gaussian at `o` describes the posterior: 8 draws `u = m + L z` each at
/// 1 and 0.5 times its scale, the log-posterior change the Gaussian predicts (`-|z|^2 / 2`
/// times the scale squared) beside the one the target gives. An independence proposal needs
/// the two to agree; the random walk only needs the shape.
fn laplace_check<F: FnMut(&[Vec<f64>]) -> Vec<f64>>(
    o: &bemcal_stats::optim::Optimum,
    mut target: F,
) {
    let d = o.point.len();
    let Some(l) = bemcal_stats::mcmc::cholesky(&o.covariance, d) else {
        eprintln!("  laplace check: covariance not positive definite");
        return;
    };
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    for scale in [1.0, 0.5] {
        let (mut pts, mut pred) = (Vec::new(), Vec::new());
        for _ in 0..8 {
            let z: Vec<f64> = (0..d).map(|_| rng.sample(StandardNormal)).collect();
            pts.push(
                (0..d)
                    .map(|i| o.point[i] + scale * (0..=i).map(|k| l[i * d + k] * z[k]).sum::<f64>())
                    .collect::<Vec<f64>>(),
            );
            pred.push(-0.5 * scale * scale * z.iter().map(|v| v * v).sum::<f64>());
        }
        let lps = target(&pts);
        eprintln!(
            "  laplace check x{scale}: predicted / actual log-posterior change: {}",
            pred.iter()
                .zip(&lps)
                .map(|(p, a)| format!("{p:.0}/{:.0}", a - o.log_density))
                .collect::<Vec<_>>()
                .join(" ")
        );
    }
}

/// `BENCH_HMC=1`: HMC chains (crates/stats/src/hmc.rs) from the optima with the Laplace
/// covariance as metric; gradients through the surrogate's VJP graph.
#[allow(clippy::too_many_arguments)]
fn run_hmc(
    a: &Args,
    target: &Target<'_>,
    ev: &mut Evaluator,
    optima: Vec<bemcal_stats::optim::Optimum>,
    priors: &[Triangular],
    truth: &[f64],
    meta: &bemcal_surrogate::SurrogateMeta,
    t_start: Instant,
    mut evals: u64,
) -> BoxResult<()> {
    use bemcal_stats::hmc::{run_segment_batch as hmc_segment, HmcConfig, HmcState};
    let env = |k: &str, default: f64| -> BoxResult<f64> {
        Ok(std::env::var(k).map_or(Ok(default), |v| v.parse())?)
    };
    let cfg = HmcConfig {
        burn_in: a.burn_in,
        integration_time: env("BENCH_HMC_TIME", HmcConfig::default().integration_time)?,
        max_leapfrog_steps: env("BENCH_HMC_MAX_STEPS", 32.0)? as u32,
        adapt_metric: env("BENCH_HMC_ADAPT", 1.0)? == 1.0,
        target_acceptance: env("BENCH_HMC_TARGET", HmcConfig::default().target_acceptance)?,
        length_jitter: env(
            "BENCH_HMC_LENGTH_JITTER",
            HmcConfig::default().length_jitter,
        )?,
        ..HmcConfig::default()
    };
    println!("HMC: {cfg:?}");
    let mut grads = 0u64;
    // Gradient check at a point 0.01 off the first optimum: the VJP gradient along random
    // directions against central differences of the log posterior.
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let x0: Vec<f64> = optima[0]
        .point
        .iter()
        .map(|&u| (u + 0.01 * rng.sample::<f64, _>(StandardNormal)).clamp(0.02, 0.98))
        .collect();
    let (_, g0) = target
        .batch_grad(ev, std::slice::from_ref(&x0), &mut evals, &mut grads)
        .remove(0);
    for _ in 0..3 {
        let v: Vec<f64> = (0..x0.len()).map(|_| rng.sample(StandardNormal)).collect();
        let h = 1e-4;
        let pm: Vec<Vec<f64>> = [h, -h]
            .iter()
            .map(|s| x0.iter().zip(&v).map(|(x, vi)| x + s * vi).collect())
            .collect();
        let f = target.batch(ev, &pm, &mut evals);
        let fd = (f[0] - f[1]) / (2.0 * h);
        let an: f64 = g0.iter().zip(&v).map(|(g, vi)| g * vi).sum();
        eprintln!("  gradient check: directional derivative {an:.2} (VJP) vs {fd:.2} (central difference)");
    }
    let t_chains = Instant::now();
    let pts: Vec<Vec<f64>> = optima.iter().map(|o| o.point.clone()).collect();
    let init = target.batch_grad(ev, &pts, &mut evals, &mut grads);
    let mut states: Vec<HmcState> = optima
        .iter()
        .zip(&init)
        .enumerate()
        .map(|(c, (o, (lp, g)))| {
            HmcState::new(
                cfg.clone(),
                &o.point,
                Some(&o.covariance),
                *lp,
                g,
                a.seed,
                c as u64,
            )
        })
        .collect::<Result<_, _>>()?;
    let mut draws: Vec<Draws> = states.iter().map(|s| Draws::new(s.dim())).collect();
    let mut done = 0u64;
    let mut tgt = |us: &[Vec<f64>]| target.batch_grad(ev, us, &mut evals, &mut grads);
    while done < a.iterations {
        let n = 25u64.min(a.iterations - done);
        let seg = hmc_segment(&mut states, n, &mut tgt)?;
        for (dr, s) in draws.iter_mut().zip(&seg) {
            dr.extend(s);
        }
        done += n;
        eprintln!(
            "  {done}/{} iterations, {:.0} s, step sizes {:?}, leapfrog steps {:?}, load {}",
            a.iterations,
            t_start.elapsed().as_secs_f64(),
            states
                .iter()
                .map(|s| (s.step_size() * 1000.0).round() / 1000.0)
                .collect::<Vec<_>>(),
            states
                .iter()
                .map(|s| s.leapfrog_steps())
                .collect::<Vec<_>>(),
            loadavg()
        );
    }
    let wall = t_start.elapsed().as_secs_f64();
    let chains_wall = t_chains.elapsed().as_secs_f64();
    let d = priors.len();
    let (mut max_rhat, mut min_bulk, mut min_tail, mut covered) =
        (0.0f64, f64::INFINITY, f64::INFINITY, 0);
    let mut worst = (0usize, 0usize);
    for j in 0..d {
        let cols: Vec<Vec<f64>> = draws.iter().map(|dr| dr.column(j)).collect();
        let g = diagnose(&cols)?;
        if g.rhat > max_rhat {
            (max_rhat, worst.0) = (g.rhat, j);
        }
        if g.ess_bulk < min_bulk {
            (min_bulk, worst.1) = (g.ess_bulk, j);
        }
        min_tail = min_tail.min(g.ess_tail);
        if (g.q5..=g.q95).contains(&priors[j].to_unit(truth[j])) {
            covered += 1;
        }
    }
    for (c, s) in states.iter().enumerate() {
        println!(
            "chain {c}: acceptance {:.3} (mean accept stat {:.3}), step size {:.4}, {} leapfrog steps, divergent {:?}, final log posterior {:.1}",
            s.acceptance_rate_post_burn_in(),
            s.mean_accept_stat(),
            s.step_size(),
            s.leapfrog_steps(),
            s.divergent(),
            s.log_density()
        );
    }
    println!(
        "run: HMC, {} chains x {} iterations ({} burn-in): {grads} gradients, {evals} evaluations in all",
        a.chains, a.iterations, a.burn_in
    );
    println!("chains: {chains_wall:.1} s ({:.2} gradients per second); total wall time with the optimisation: {wall:.1} s", grads as f64 / chains_wall);
    println!(
        "max R-hat: {max_rhat:.4} ({}); min bulk ESS: {min_bulk:.0} ({}); min tail ESS: {min_tail:.0}",
        meta.params[worst.0].name, meta.params[worst.1].name
    );
    println!(
        "min bulk ESS per second of chains: {:.3}; truth inside the 90 % interval for {covered}/{d} parameters",
        min_bulk / chains_wall
    );
    println!(
        "criteria: R-hat <= {TARGET_RHAT}: {}, bulk ESS >= {TARGET_ESS}: {}, chains within {:.0} min: {}",
        max_rhat <= TARGET_RHAT,
        min_bulk >= TARGET_ESS,
        TARGET_SECONDS / 60.0,
        chains_wall < TARGET_SECONDS
    );
    println!("load average at end {}", loadavg());
    Ok(())
}

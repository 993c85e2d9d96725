//! Hamiltonian Monte Carlo for the unit-space posterior, with gradients (Neal 2011, "MCMC using
//! Hamiltonian dynamics", Handbook of MCMC, ch. 5; step-size adaptation of Hoffman & Gelman
//! 2014, JMLR 15, Algorithm 5).
//!
//! - The chain moves in `z = logit(u)`, `u` the unit-space point of [`crate::mcmc`], so the box
//!   `[0, 1]^d` needs no reflections: `ln pi(z) = ln p(u) + sum_i ln(u_i (1 - u_i))` (the
//!   Jacobian), `d ln pi / dz_i = u_i (1 - u_i) d ln p / du_i + 1 - 2 u_i`.
//! - Euclidean metric `M^-1 = L L^T` (e.g. the Laplace covariance at an optimum mapped to
//!   `z`): the momentum is whitened, `rho ~ N(0, I)`, and a leapfrog step is `rho += eps/2 L^T
//!   grad`, `z += eps L rho`, `rho += eps/2 L^T grad`; `H = -ln pi(z) + |rho|^2 / 2`; the end
//!   point is accepted with probability `min(1, exp(H_0 - H_1))`.
//! - Trajectory: `ceil(T' / eps')` steps (at most `max_leapfrog_steps`), `eps'` and `T'` the
//!   step size and `integration_time` jittered uniformly by `+-step_jitter` and
//!   `+-length_jitter` per iteration (Neal 2011, Sec. 5.4.2.2), so the number of steps may
//!   differ between chains. A trajectory that reaches a point of zero
//!   density (a constraint) or an energy error over [`DIVERGENCE`] nats stops and is
//!   rejected; the reverse trajectory passes the same points, so this keeps detailed balance.
//! - Burn-in: dual averaging of `ln eps` towards `target_acceptance` (`mu = ln(10 eps_0)`,
//!   `gamma = 0.05`, `t_0 = 10`, `kappa = 0.75`); with `adapt_metric`, the chain's own states
//!   of the middle half of burn-in give a new metric at 3/4 of it (their covariance shrunk
//!   towards the initial metric with weight `d / (n + d)`) and the step size adaptation
//!   restarts. After burn-in `eps = exp(ln eps_bar)` and the metric are frozen (until a
//!   re-adaptation, below).
//! - Re-adaptation ([`HmcState::readapt`]): when chains are run on past their first target, a
//!   metric estimated from the draws of all chains ([`within_chain_covariance_z`]: hundreds of
//!   states against burn-in's few dozen) replaces each chain's own, and the step size adapts
//!   again over a window of [`readapt_window`] iterations that are not drawn (the windowed
//!   adaptation of Stan, Stan Reference Manual, "HMC algorithm parameters": each window's
//!   covariance sets the next window's metric). Adaptation stays out of the draws.
//! - Randomness per iteration, in this order: two uniforms (step and length jitter), `d`
//!   standard normals (the momentum), one uniform (acceptance): the draws do not depend on how chains are batched or
//!   checkpointed.
//!
//! Why: a random walk needs about `3.3 d` iterations per independent draw in `d` dimensions
//! (Roberts & Rosenthal 2001); HMC's cost grows like `d^(1/4)` gradient evaluations (Beskos et
//! al. 2013), and a gradient through the surrogate's VJP graph costs about 3.3 evaluations.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
use serde::{Deserialize, Serialize};

use crate::error::{Result, StatsError};
use crate::mcmc::{cholesky, f64_bits, DrawStats, Draws};

/// Energy error (nats) past which a trajectory counts as divergent and is rejected.
pub const DIVERGENCE: f64 = 1000.0;

/// Settings of one HMC chain; stored in its [`HmcState`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct HmcConfig {
    /// Iterations discarded as burn-in (adaptation happens in these, and in re-adaptation
    /// windows: [`HmcState::readapt`]).
    pub burn_in: u64,
    /// Target mean acceptance probability of the step-size adaptation.
    pub target_acceptance: f64,
    /// Trajectory length `eps * steps` in the whitened space.
    pub integration_time: f64,
    /// Cap on leapfrog steps per iteration.
    pub max_leapfrog_steps: u32,
    /// Relative jitter of the step size per iteration, in `[0, 1)`.
    pub step_jitter: f64,
    /// Relative jitter of the trajectory length per iteration, in `[0, 1)`: a fixed length
    /// can be close to a multiple of some direction's period and stall it (Neal 2011,
    /// Sec. 5.4.2.2; Hoffman & Gelman 2014, Sec. 1).
    #[serde(default)]
    pub length_jitter: f64,
    /// Initial step size in the whitened space.
    pub initial_step: f64,
    /// Re-estimate the metric from the middle half of burn-in.
    pub adapt_metric: bool,
}

impl Default for HmcConfig {
    fn default() -> Self {
        HmcConfig {
            burn_in: 200,
            // 0.7: the paper-size runs settled at 0.86-0.91 actual acceptance with it (0.8 gave
            // 0.89-0.97 at smaller steps; dual averaging's averaged step is conservative).
            target_acceptance: 0.7,
            integration_time: 2.0,
            max_leapfrog_steps: 32,
            step_jitter: 0.2,
            length_jitter: 0.5,
            initial_step: 0.25,
            adapt_metric: true,
        }
    }
}

impl HmcConfig {
    fn validate(&self) -> Result<()> {
        let bad = |m: &str| Err(StatsError::Invalid(m.into()));
        if !(self.target_acceptance > 0.0 && self.target_acceptance < 1.0) {
            return bad("target_acceptance must be in (0, 1)");
        }
        if !(self.integration_time.is_finite() && self.integration_time > 0.0) {
            return bad("integration_time must be positive");
        }
        if self.max_leapfrog_steps == 0 {
            return bad("max_leapfrog_steps must be at least 1");
        }
        if !(0.0..1.0).contains(&self.step_jitter) || !(0.0..1.0).contains(&self.length_jitter) {
            return bad("step_jitter and length_jitter must be in [0, 1)");
        }
        if !(self.initial_step.is_finite() && self.initial_step > 0.0) {
            return bad("initial_step must be positive");
        }
        Ok(())
    }
}

/// Dual-averaging state (Hoffman & Gelman 2014, Algorithm 5).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
struct DualAveraging {
    #[serde(with = "f64_bits")]
    mu: f64,
    #[serde(with = "f64_bits")]
    h_bar: f64,
    #[serde(with = "f64_bits")]
    ln_eps_bar: f64,
    m: u64,
}

impl DualAveraging {
    fn new(eps: f64) -> Self {
        DualAveraging {
            mu: (10.0 * eps).ln(),
            h_bar: 0.0,
            ln_eps_bar: 0.0,
            m: 0,
        }
    }

    /// One update with acceptance statistic `alpha`; returns the next `ln eps`.
    fn update(&mut self, alpha: f64, target: f64) -> f64 {
        const GAMMA: f64 = 0.05;
        const T0: f64 = 10.0;
        const KAPPA: f64 = 0.75;
        self.m += 1;
        let m = self.m as f64;
        let w = 1.0 / (m + T0);
        self.h_bar = (1.0 - w) * self.h_bar + w * (target - alpha);
        let ln_eps = self.mu - m.sqrt() / GAMMA * self.h_bar;
        let eta = m.powf(-KAPPA);
        self.ln_eps_bar = eta * ln_eps + (1.0 - eta) * self.ln_eps_bar;
        ln_eps
    }
}

/// The complete, serialisable state of one HMC chain (floats as bit patterns: a checkpoint
/// resumes with bit-identical draws).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct HmcState {
    config: HmcConfig,
    /// Position in `z = logit(u)`.
    #[serde(with = "f64_bits::vec")]
    z: Vec<f64>,
    /// `ln pi(z)` (Jacobian included) and its gradient.
    #[serde(with = "f64_bits")]
    ln_pi: f64,
    #[serde(with = "f64_bits::vec")]
    grad: Vec<f64>,
    /// `ln p(u)` of the unit-space posterior at the position (what the draws record).
    #[serde(with = "f64_bits")]
    log_density: f64,
    /// Lower factor `L` of `M^-1`, row-major `d x d`, and the initial one (metric shrinkage).
    #[serde(with = "f64_bits::vec")]
    chol: Vec<f64>,
    #[serde(with = "f64_bits::vec")]
    chol0: Vec<f64>,
    #[serde(with = "f64_bits")]
    ln_eps: f64,
    dual: DualAveraging,
    /// Welford accumulator of `z` over the metric window.
    adapt_n: u64,
    #[serde(with = "f64_bits::vec")]
    adapt_mean: Vec<f64>,
    #[serde(with = "f64_bits::vec")]
    adapt_m2: Vec<f64>,
    iteration: u64,
    accepted: u64,
    accepted_post_burn_in: u64,
    divergent: u64,
    /// Divergent trajectories after burn-in (a sign of a posterior the step size cannot follow).
    divergent_post_burn_in: u64,
    leapfrog_steps: u64,
    /// Sum of the acceptance statistics after burn-in.
    #[serde(with = "f64_bits")]
    accept_stat_post_burn_in: f64,
    /// As [`crate::mcmc::ChainState::moved_from_mode`].
    #[serde(default)]
    moved_from_mode: Option<f64>,
    /// The iteration at which the last re-adaptation window ends ([`HmcState::readapt`]); 0
    /// when none was opened.
    #[serde(default)]
    window_end: u64,
    /// Iterations spent in re-adaptation windows (after burn-in, not drawn).
    #[serde(default)]
    readapted: u64,
    rng: ChaCha8Rng,
}

/// `z = logit(u)` with `u` kept 1e-12 inside the box.
fn logit(u: f64) -> f64 {
    let u = u.clamp(1e-12, 1.0 - 1e-12);
    (u / (1.0 - u)).ln()
}

/// `u = 1 / (1 + e^-z)`.
fn sigmoid(z: f64) -> f64 {
    1.0 / (1.0 + (-z).exp())
}

/// `(ln pi(z), d ln pi / dz)` from the unit-space `(ln p(u), d ln p / du)` (module doc).
fn to_z(u: &[f64], lp: f64, grad_u: &[f64]) -> (f64, Vec<f64>) {
    let jac: f64 = u.iter().map(|&v| (v * (1.0 - v)).ln()).sum();
    let g = u
        .iter()
        .zip(grad_u)
        .map(|(&v, &g)| v * (1.0 - v) * g + 1.0 - 2.0 * v)
        .collect();
    (lp + jac, g)
}

/// `L v` for lower-triangular row-major `L`.
fn lower_mul(l: &[f64], v: &[f64]) -> Vec<f64> {
    let d = v.len();
    (0..d)
        .map(|i| (0..=i).map(|k| l[i * d + k] * v[k]).sum())
        .collect()
}

/// `L^T v` for lower-triangular row-major `L`.
fn lower_t_mul(l: &[f64], v: &[f64]) -> Vec<f64> {
    let d = v.len();
    (0..d)
        .map(|j| (j..d).map(|i| l[i * d + j] * v[i]).sum())
        .collect()
}

/// A unit-space posterior with gradients, batched: for each point `(ln p(u), d ln p / du)`;
/// `ln p = -inf` (any gradient) outside the support or where a constraint fails.
pub trait GradientTarget {
    /// Evaluate all points.
    fn evaluate(&mut self, points: &[Vec<f64>]) -> Vec<(f64, Vec<f64>)>;
}

/// `target` at `points`, checked to return one value per point.
fn evaluate_checked<T: GradientTarget + ?Sized>(
    target: &mut T,
    points: &[Vec<f64>],
) -> Result<Vec<(f64, Vec<f64>)>> {
    let values = target.evaluate(points);
    if values.len() != points.len() {
        return Err(StatsError::Shape(format!(
            "target returned {} values for {} points",
            values.len(),
            points.len()
        )));
    }
    Ok(values)
}

impl<F: FnMut(&[Vec<f64>]) -> Vec<(f64, Vec<f64>)>> GradientTarget for F {
    fn evaluate(&mut self, points: &[Vec<f64>]) -> Vec<(f64, Vec<f64>)> {
        self(points)
    }
}

impl HmcState {
    /// A chain at unit-space `start` with the metric `covariance` (unit space, row-major
    /// `d x d`, e.g. the Laplace covariance; mapped to `z` at `start`), or `sd_u^2 I` per
    /// coordinate with `sd_u = 0.05` when `None`; `(log_density, gradient)` of `start`;
    /// `ChaCha8Rng` seeded from `seed`, stream `stream`.
    pub fn new(
        config: HmcConfig,
        start: &[f64],
        covariance: Option<&[f64]>,
        log_density: f64,
        gradient: &[f64],
        seed: u64,
        stream: u64,
    ) -> Result<Self> {
        config.validate()?;
        let d = start.len();
        if d == 0 || gradient.len() != d {
            return Err(StatsError::Shape(format!(
                "start of {d} coordinates, gradient of {}",
                gradient.len()
            )));
        }
        if let Some(i) = start.iter().position(|u| !(0.0..=1.0).contains(u)) {
            return Err(StatsError::Invalid(format!(
                "start coordinate {i} = {} is outside the unit interval",
                start[i]
            )));
        }
        if !log_density.is_finite() {
            return Err(StatsError::Invalid(format!(
                "the log posterior at the start is {log_density}"
            )));
        }
        let z: Vec<f64> = start.iter().map(|&u| logit(u)).collect();
        let u: Vec<f64> = z.iter().map(|&v| sigmoid(v)).collect();
        // d z / d u = 1 / (u (1 - u)) at the start.
        let jz: Vec<f64> = u
            .iter()
            .map(|&v| 1.0 / (v * (1.0 - v)).max(1e-12))
            .collect();
        let cov_z: Vec<f64> = match covariance {
            Some(c) if c.len() == d * d => (0..d * d)
                .map(|k| {
                    let (i, j) = (k / d, k % d);
                    0.5 * (c[k] + c[j * d + i]) * jz[i] * jz[j]
                })
                .collect(),
            Some(c) => {
                return Err(StatsError::Shape(format!(
                    "metric covariance of {} values for {d} dimensions",
                    c.len()
                )))
            }
            None => (0..d * d)
                .map(|k| {
                    if k / d == k % d {
                        (0.05 * jz[k / d]).powi(2)
                    } else {
                        0.0
                    }
                })
                .collect(),
        };
        let chol = cholesky(&cov_z, d).ok_or_else(|| {
            StatsError::Invalid("the metric covariance is not positive definite".into())
        })?;
        let (ln_pi, grad) = to_z(&u, log_density, gradient);
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        rng.set_stream(stream);
        Ok(HmcState {
            dual: DualAveraging::new(config.initial_step),
            ln_eps: config.initial_step.ln(),
            config,
            z,
            ln_pi,
            grad,
            log_density,
            chol0: chol.clone(),
            chol,
            adapt_n: 0,
            adapt_mean: vec![0.0; d],
            adapt_m2: vec![0.0; d * d],
            iteration: 0,
            accepted: 0,
            accepted_post_burn_in: 0,
            divergent: 0,
            divergent_post_burn_in: 0,
            leapfrog_steps: 0,
            accept_stat_post_burn_in: 0.0,
            moved_from_mode: None,
            window_end: 0,
            readapted: 0,
            rng,
        })
    }

    /// Dimension.
    pub fn dim(&self) -> usize {
        self.z.len()
    }
    /// Unit-space position.
    pub fn position(&self) -> Vec<f64> {
        self.z.iter().map(|&v| sigmoid(v)).collect()
    }
    /// `ln p(u)` at the position.
    pub fn log_density(&self) -> f64 {
        self.log_density
    }
    /// Iterations done.
    pub fn iteration(&self) -> u64 {
        self.iteration
    }
    /// The settings.
    pub fn config(&self) -> &HmcConfig {
        &self.config
    }
    /// Current step size (after burn-in and outside a re-adaptation window: the frozen,
    /// averaged one).
    pub fn step_size(&self) -> f64 {
        self.ln_eps.exp()
    }
    /// Acceptance rate after burn-in (0 before).
    pub fn acceptance_rate_post_burn_in(&self) -> f64 {
        let n = self.drawn();
        if n == 0 {
            0.0
        } else {
            self.accepted_post_burn_in as f64 / n as f64
        }
    }
    /// Mean acceptance statistic `min(1, exp(H_0 - H_1))` after burn-in.
    pub fn mean_accept_stat(&self) -> f64 {
        let n = self.drawn();
        if n == 0 {
            0.0
        } else {
            self.accept_stat_post_burn_in / n as f64
        }
    }
    /// Iterations that were drawn: after burn-in and outside re-adaptation windows.
    pub fn drawn(&self) -> u64 {
        self.iteration
            .saturating_sub(self.config.burn_in)
            .saturating_sub(self.readapted)
    }

    /// Opens a re-adaptation window (module doc): `covariance_z` (row-major `d x d`, in `z =
    /// logit(u)`, e.g. [`within_chain_covariance_z`]) becomes the metric, and the step size
    /// adapts again by dual averaging from the current one over the next `window` iterations,
    /// which are not drawn; then it is frozen at the window's average.
    ///
    /// # Errors
    /// A covariance of the wrong size or not positive definite, or a chain still in burn-in
    /// (whose own adaptation is not finished); the chain is left as it was.
    pub fn readapt(&mut self, covariance_z: &[f64], window: u64) -> Result<()> {
        let d = self.dim();
        if covariance_z.len() != d * d {
            return Err(StatsError::Shape(format!(
                "metric covariance of {} values for {d} dimensions",
                covariance_z.len()
            )));
        }
        if self.iteration < self.config.burn_in {
            return Err(StatsError::Invalid(format!(
                "a chain in burn-in (iteration {} of {}) cannot be re-adapted",
                self.iteration, self.config.burn_in
            )));
        }
        self.chol = cholesky(covariance_z, d).ok_or_else(|| {
            StatsError::Invalid("the re-adapted metric is not positive definite".into())
        })?;
        self.dual = DualAveraging::new(self.ln_eps.exp());
        self.window_end = self.iteration + window;
        Ok(())
    }

    /// Whether a re-adaptation window was ever opened ([`HmcState::readapt`]).
    pub fn was_readapted(&self) -> bool {
        self.window_end > 0
    }

    /// Divergent (stopped and rejected) trajectories, all and after burn-in.
    pub fn divergent(&self) -> (u64, u64) {
        (self.divergent, self.divergent_post_burn_in)
    }
    /// How many nats below the best optimum this chain's own optimum was, when it was started
    /// in the best one's mode instead ([`chains_at_optima`]).
    pub fn moved_from_mode(&self) -> Option<f64> {
        self.moved_from_mode
    }
    /// Leapfrog steps (= gradient evaluations) taken.
    pub fn leapfrog_steps(&self) -> u64 {
        self.leapfrog_steps
    }

    /// Starts an iteration: jittered step, number of steps, momentum after the first half step.
    fn begin(&mut self) -> Trajectory {
        let d = self.dim();
        let jitter: f64 = self.rng.random();
        let eps = self.ln_eps.exp() * (1.0 + self.config.step_jitter * (2.0 * jitter - 1.0));
        let length: f64 = self.rng.random();
        let time =
            self.config.integration_time * (1.0 + self.config.length_jitter * (2.0 * length - 1.0));
        let steps = ((time / eps).ceil() as u32).clamp(1, self.config.max_leapfrog_steps);
        let rho: Vec<f64> = (0..d).map(|_| self.rng.sample(StandardNormal)).collect();
        let h0 = -self.ln_pi + 0.5 * rho.iter().map(|v| v * v).sum::<f64>();
        let ln_u = self.rng.random::<f64>().ln();
        let lg = lower_t_mul(&self.chol, &self.grad);
        let rho = rho
            .iter()
            .zip(&lg)
            .map(|(r, g)| r + 0.5 * eps * g)
            .collect();
        Trajectory {
            eps,
            steps,
            done: 0,
            z: self.z.clone(),
            rho,
            h0,
            ln_u,
            last: None,
            stopped: false,
        }
    }

    /// Accepts or rejects the finished trajectory and adapts.
    fn finish(&mut self, tr: Trajectory, draws: &mut Draws) {
        let readapting = self.iteration >= self.config.burn_in && self.iteration < self.window_end;
        let post_burn_in = self.iteration >= self.config.burn_in && !readapting;
        self.leapfrog_steps += u64::from(tr.done);
        let (eps, steps, divergent) = (tr.eps, tr.done, tr.stopped || tr.last.is_none());
        let mut alpha = 0.0;
        if let (false, Some((ln_pi, grad, lp))) = (tr.stopped, tr.last) {
            let h1 = -ln_pi + 0.5 * tr.rho.iter().map(|v| v * v).sum::<f64>();
            let dh = tr.h0 - h1;
            alpha = if dh >= 0.0 { 1.0 } else { dh.exp() };
            if tr.ln_u < dh {
                self.z = tr.z;
                self.ln_pi = ln_pi;
                self.grad = grad;
                self.log_density = lp;
                self.accepted += 1;
                if post_burn_in {
                    self.accepted_post_burn_in += 1;
                }
            }
        } else {
            self.divergent += 1;
            if post_burn_in {
                self.divergent_post_burn_in += 1;
            }
        }
        self.iteration += 1;
        let t = self.iteration;
        let burn = self.config.burn_in;
        if post_burn_in {
            self.accept_stat_post_burn_in += alpha;
            let stats = DrawStats {
                accept_stat: alpha,
                step_size: eps,
                n_leapfrog: steps,
                divergent,
            };
            draws.push(&self.position(), self.log_density, stats);
            return;
        }
        if readapting {
            self.readapted += 1;
        }
        self.ln_eps = self
            .dual
            .update(alpha, self.config.target_acceptance)
            .clamp(-20.0, 5.0);
        if self.config.adapt_metric && !readapting {
            if t > burn / 4 && t <= 3 * burn / 4 {
                self.adapt_update();
            }
            if t == 3 * burn / 4 && self.adapt_n >= 10 {
                self.refresh_metric();
                self.dual = DualAveraging::new(self.ln_eps.exp());
            }
        }
        if t == burn || (readapting && t == self.window_end) {
            self.ln_eps = self.dual.ln_eps_bar;
        }
    }

    fn adapt_update(&mut self) {
        crate::mcmc::welford_update(
            &mut self.adapt_n,
            &mut self.adapt_mean,
            &mut self.adapt_m2,
            &self.z,
        );
    }

    /// Metric = `(n C + d M0) / (n + d)`: the window's covariance shrunk towards the initial
    /// metric (few states per dimension in a short burn-in).
    fn refresh_metric(&mut self) {
        let d = self.dim();
        let n = self.adapt_n as f64;
        let m0: Vec<f64> = (0..d * d)
            .map(|k| {
                let (i, j) = (k / d, k % d);
                (0..d)
                    .map(|q| self.chol0[i * d + q] * self.chol0[j * d + q])
                    .sum()
            })
            .collect();
        let w = d as f64;
        let c: Vec<f64> = (0..d * d)
            .map(|k| {
                let (i, j) = (k / d, k % d);
                let cov = 0.5 * (self.adapt_m2[k] + self.adapt_m2[j * d + i]) / (n - 1.0);
                (n * cov + w * m0[k]) / (n + w)
            })
            .collect();
        if let Some(l) = cholesky(&c, d) {
            self.chol = l;
        }
    }
}

/// Iterations of the re-adaptation window ([`HmcState::readapt`]) of chains with `burn_in`
/// iterations of burn-in: half of it, the length of its step-size adaptation after the metric
/// is set (at 3/4 of burn-in the step size restarts for the last quarter; twice that here, for
/// a metric that can change more), and at least [`MIN_READAPT_WINDOW`] (dual averaging's first
/// updates overshoot: one update alone leaves the step 3-17 times as large). 0, no
/// re-adaptation, for chains without burn-in (no adaptation asked for).
pub fn readapt_window(burn_in: u64) -> u64 {
    if burn_in == 0 {
        0
    } else {
        (burn_in / 2).max(MIN_READAPT_WINDOW)
    }
}

/// The shortest re-adaptation window ([`readapt_window`]).
pub const MIN_READAPT_WINDOW: u64 = 25;

/// The metric for re-adapted chains: the mean of the chains' own covariances of `z = logit(u)`
/// over their draws (the within-chain variance `W` of R-hat, Gelman et al. 2013, BDA3
/// eq. 11.3, so that chains in different modes do not widen it), shrunk towards its
/// diagonal with weight `d / (n + d)`, `n` the draws of all chains (as burn-in's metric is
/// shrunk). Row-major `d x d`; `None` when a chain has fewer than two draws or the chains
/// differ in dimension.
pub fn within_chain_covariance_z(draws: &[Draws]) -> Option<Vec<f64>> {
    let d = draws.first()?.dim;
    if draws.iter().any(|c| c.dim != d || c.len() < 2) {
        return None;
    }
    let mut w = vec![0.0; d * d];
    for chain in draws {
        let (mut n, mut mean, mut m2) = (0, vec![0.0; d], vec![0.0; d * d]);
        for i in 0..chain.len() {
            let z: Vec<f64> = chain.point(i).iter().map(|&u| logit(u)).collect();
            crate::mcmc::welford_update(&mut n, &mut mean, &mut m2, &z);
        }
        for (acc, v) in w.iter_mut().zip(&m2) {
            *acc += v / (n as f64 - 1.0) / draws.len() as f64;
        }
    }
    let n: f64 = draws.iter().map(|c| c.len() as f64).sum();
    let shrink = d as f64 / (n + d as f64);
    Some(
        (0..d * d)
            .map(|k| {
                let (i, j) = (k / d, k % d);
                let sym = 0.5 * (w[k] + w[j * d + i]);
                if i == j {
                    sym
                } else {
                    (1.0 - shrink) * sym
                }
            })
            .collect(),
    )
}

/// One chain's trajectory in progress.
struct Trajectory {
    eps: f64,
    steps: u32,
    done: u32,
    z: Vec<f64>,
    /// Momentum; between steps it has had its half step at the current `z`.
    rho: Vec<f64>,
    h0: f64,
    ln_u: f64,
    /// `(ln pi, grad_z, ln p)` at the current `z` once evaluated.
    last: Option<(f64, Vec<f64>, f64)>,
    stopped: bool,
}

impl Trajectory {
    fn running(&self) -> bool {
        !self.stopped && self.done < self.steps
    }
}

/// Advances several chains by one iteration each; every leapfrog step of all running chains is
/// one batched `target` call. Post-burn-in states are appended to `draws`.
pub fn step_batch<T: GradientTarget + ?Sized>(
    states: &mut [HmcState],
    target: &mut T,
    draws: &mut [Draws],
) -> Result<()> {
    if draws.len() != states.len() {
        return Err(StatsError::Shape(format!(
            "{} chains but {} draw buffers",
            states.len(),
            draws.len()
        )));
    }
    let mut trs: Vec<Trajectory> = states.iter_mut().map(HmcState::begin).collect();
    loop {
        let live: Vec<usize> = (0..trs.len()).filter(|&c| trs[c].running()).collect();
        if live.is_empty() {
            break;
        }
        // Drift: z += eps L rho.
        let mut points = Vec::with_capacity(live.len());
        for &c in &live {
            let tr = &mut trs[c];
            let step = lower_mul(&states[c].chol, &tr.rho);
            for (z, s) in tr.z.iter_mut().zip(step) {
                *z += tr.eps * s;
            }
            points.push(tr.z.iter().map(|&v| sigmoid(v)).collect::<Vec<f64>>());
        }
        let values = evaluate_checked(target, &points)?;
        for ((&c, u), (lp, g)) in live.iter().zip(&points).zip(values) {
            let tr = &mut trs[c];
            tr.done += 1;
            let (ln_pi, gz) = to_z(u, lp, &g);
            let finite = ln_pi.is_finite() && gz.iter().all(|v| v.is_finite());
            let kinetic = 0.5 * tr.rho.iter().map(|v| v * v).sum::<f64>();
            if !finite || (-ln_pi + kinetic) - tr.h0 > DIVERGENCE {
                tr.stopped = true;
                continue;
            }
            // Kick: a full step, or the closing half step at the end.
            let half = if tr.done == tr.steps { 0.5 } else { 1.0 };
            let lg = lower_t_mul(&states[c].chol, &gz);
            for (r, g) in tr.rho.iter_mut().zip(lg) {
                *r += half * tr.eps * g;
            }
            tr.last = Some((ln_pi, gz, lp));
        }
    }
    for ((s, tr), d) in states.iter_mut().zip(trs).zip(draws.iter_mut()) {
        s.finish(tr, d);
    }
    Ok(())
}

/// Chains started at optima ([`crate::optim::maximise_batch`]) with their Laplace covariances
/// as metrics; an optimum more than `restart_below` nats below the best is replaced by the best
/// ([`crate::optim::keep_best_modes`], recorded in [`HmcState::moved_from_mode`]). The
/// gradients at the starts come from one `target` call; chain `c` gets stream `first_stream + c`.
pub fn chains_at_optima<T: GradientTarget + ?Sized>(
    config: &HmcConfig,
    mut optima: Vec<crate::optim::Optimum>,
    seed: u64,
    first_stream: u64,
    restart_below: f64,
    target: &mut T,
) -> Result<Vec<HmcState>> {
    let moved = crate::optim::keep_best_modes(&mut optima, restart_below);
    let points: Vec<Vec<f64>> = optima.iter().map(|o| o.point.clone()).collect();
    let values = evaluate_checked(target, &points)?;
    let mut states = optima
        .iter()
        .zip(values)
        .enumerate()
        .map(|(c, (o, (lp, g)))| {
            let cov = (o.covariance.len() == o.point.len().pow(2)).then_some(&o.covariance[..]);
            HmcState::new(
                config.clone(),
                &o.point,
                cov,
                lp,
                &g,
                seed,
                first_stream + c as u64,
            )
            .or_else(|_| {
                HmcState::new(
                    config.clone(),
                    &o.point,
                    None,
                    lp,
                    &g,
                    seed,
                    first_stream + c as u64,
                )
            })
        })
        .collect::<Result<Vec<_>>>()?;
    for (c, gap) in moved {
        states[c].moved_from_mode = Some(gap);
    }
    Ok(states)
}

/// Advances several chains by `n` iterations each; returns each chain's post-burn-in draws of
/// this segment (any split into segments gives the same draws).
pub fn run_segment_batch<T: GradientTarget + ?Sized>(
    states: &mut [HmcState],
    n: u64,
    target: &mut T,
) -> Result<Vec<Draws>> {
    let mut draws: Vec<Draws> = states.iter().map(|s| Draws::new(s.dim())).collect();
    for _ in 0..n {
        step_batch(states, target, &mut draws)?;
    }
    Ok(draws)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A correlated Gaussian in the unit box (far from its edges), ln p and gradient.
    fn gaussian(mean: Vec<f64>, prec: Vec<f64>) -> impl FnMut(&[Vec<f64>]) -> Vec<(f64, Vec<f64>)> {
        let d = mean.len();
        move |pts: &[Vec<f64>]| {
            pts.iter()
                .map(|u| {
                    let r: Vec<f64> = (0..d).map(|i| u[i] - mean[i]).collect();
                    let pr: Vec<f64> = (0..d)
                        .map(|i| (0..d).map(|j| prec[i * d + j] * r[j]).sum())
                        .collect();
                    let q: f64 = r.iter().zip(&pr).map(|(a, b)| a * b).sum();
                    (-0.5 * q, pr.iter().map(|v| -v).collect())
                })
                .collect()
        }
    }

    #[test]
    fn recovers_a_correlated_gaussian_and_resumes_bit_exactly() {
        // 6-D, sds 0.002-0.03, two pairs at rho 0.9; metric deliberately off by 2x in scale.
        let d = 6;
        let sd = [0.002, 0.03, 0.01, 0.01, 0.005, 0.02];
        let mut cov = vec![0.0; d * d];
        for i in 0..d {
            cov[i * d + i] = sd[i] * sd[i];
        }
        for (a, b) in [(0, 1), (2, 3)] {
            cov[a * d + b] = 0.9 * sd[a] * sd[b];
            cov[b * d + a] = cov[a * d + b];
        }
        let mean = vec![0.3, 0.6, 0.5, 0.45, 0.7, 0.2];
        // precision by Gauss-Jordan
        let prec = {
            let mut a = cov.clone();
            let mut inv: Vec<f64> = (0..d * d)
                .map(|k| if k / d == k % d { 1.0 } else { 0.0 })
                .collect();
            for i in 0..d {
                let p = a[i * d + i];
                for j in 0..d {
                    a[i * d + j] /= p;
                    inv[i * d + j] /= p;
                }
                for r in 0..d {
                    if r != i {
                        let f = a[r * d + i];
                        for j in 0..d {
                            a[r * d + j] -= f * a[i * d + j];
                            inv[r * d + j] -= f * inv[i * d + j];
                        }
                    }
                }
            }
            inv
        };
        let mut target = gaussian(mean.clone(), prec);
        let metric: Vec<f64> = cov.iter().map(|v| 4.0 * v).collect();
        let cfg = HmcConfig {
            burn_in: 300,
            ..HmcConfig::default()
        };
        let mut states: Vec<HmcState> = (0..4)
            .map(|c| {
                let (lp, g) = target(std::slice::from_ref(&mean)).remove(0);
                HmcState::new(cfg.clone(), &mean, Some(&metric), lp, &g, 7, c).unwrap()
            })
            .collect();
        let mut copy = states.clone();
        let draws = run_segment_batch(&mut states, 2300, &mut target).unwrap();
        // Checkpoint in the middle (JSON round trip) gives the same draws.
        let a = run_segment_batch(&mut copy, 1000, &mut target).unwrap();
        let mut copy: Vec<HmcState> =
            serde_json::from_str(&serde_json::to_string(&copy).unwrap()).unwrap();
        let b = run_segment_batch(&mut copy, 1300, &mut target).unwrap();
        for c in 0..4 {
            let mut ab = a[c].clone();
            ab.extend(&b[c]);
            assert_eq!(ab, draws[c], "chain {c}: resumed draws differ");
            assert!(
                states[c].mean_accept_stat() > 0.6,
                "{}",
                states[c].mean_accept_stat()
            );
            assert_eq!(states[c].divergent().1, 0);
            // One record of the sampler's statistics per draw, which sum to the chain's own
            // counters (the draws are the post-burn-in iterations).
            let stats = draws[c].stats().expect("statistics of every draw");
            assert_eq!(stats.len(), draws[c].len());
            let mean_accept = stats.iter().map(|s| s.accept_stat).sum::<f64>() / stats.len() as f64;
            assert!((mean_accept - states[c].mean_accept_stat()).abs() < 1e-12);
            assert!(stats
                .iter()
                .all(|s| s.step_size > 0.0 && s.n_leapfrog >= 1 && !s.divergent));
        }
        let all: Vec<&[f64]> = draws
            .iter()
            .flat_map(|d| (0..d.len()).map(move |i| d.point(i)))
            .collect();
        let n = all.len() as f64;
        for i in 0..d {
            let m = all.iter().map(|p| p[i]).sum::<f64>() / n;
            assert!(
                (m - mean[i]).abs() < 0.1 * sd[i],
                "mean {i}: {m} vs {}",
                mean[i]
            );
            for j in 0..d {
                let mj = all.iter().map(|p| p[j]).sum::<f64>() / n;
                let c = all.iter().map(|p| (p[i] - m) * (p[j] - mj)).sum::<f64>() / (n - 1.0);
                assert!(
                    (c - cov[i * d + j]).abs() < 0.1 * sd[i] * sd[j],
                    "cov {i} {j}: {c} vs {}",
                    cov[i * d + j]
                );
            }
        }
    }

    #[test]
    fn readaptation_from_the_draws_repairs_a_wrong_metric_and_stays_out_of_the_draws() {
        // 4-D, sd 0.01 each; the metric's first coordinate 10x too wide and burn-in left
        // unable to fix it (adapt_metric off): the step size must shrink for that direction.
        let d = 4;
        let mean = vec![0.5, 0.4, 0.6, 0.5];
        let prec: Vec<f64> = (0..d * d)
            .map(|k| if k / d == k % d { 1e4 } else { 0.0 })
            .collect();
        let mut target = gaussian(mean.clone(), prec);
        let mut metric: Vec<f64> = (0..d * d)
            .map(|k| if k / d == k % d { 1e-4 } else { 0.0 })
            .collect();
        metric[0] = 1e-2;
        let cfg = HmcConfig {
            burn_in: 100,
            adapt_metric: false,
            ..HmcConfig::default()
        };
        let mut states: Vec<HmcState> = (0..4)
            .map(|c| {
                let (lp, g) = target(std::slice::from_ref(&mean)).remove(0);
                HmcState::new(cfg.clone(), &mean, Some(&metric), lp, &g, 3, c).unwrap()
            })
            .collect();
        let before = run_segment_batch(&mut states, 500, &mut target).unwrap();
        let (eps0, steps0) = (states[0].step_size(), states[0].leapfrog_steps());
        let cov = within_chain_covariance_z(&before).expect("a metric from 400 draws a chain");
        let window = readapt_window(cfg.burn_in);
        for s in &mut states {
            s.readapt(&cov, window).unwrap();
        }
        let after = run_segment_batch(&mut states, window + 400, &mut target).unwrap();
        for (c, s) in states.iter().enumerate() {
            assert_eq!(
                after[c].len(),
                400,
                "the window's {window} iterations are not drawn"
            );
            assert_eq!(after[c].stats().unwrap().len(), 400);
            assert_eq!(s.drawn(), 800);
        }
        let eps1 = states[0].step_size();
        let steps1 = states[0].leapfrog_steps() - steps0;
        assert!(eps1 > 3.0 * eps0, "step size {eps0} -> {eps1}");
        assert!(
            (steps1 as f64) < 0.5 * steps0 as f64 * (window + 400) as f64 / 500.0,
            "leapfrog steps {steps0} in 500 iterations, {steps1} in {}",
            window + 400
        );
        // Still the target: means and sds of the draws after re-adaptation.
        for (i, mu) in mean.iter().enumerate() {
            let x: Vec<f64> = after.iter().flat_map(|a| a.column(i)).collect();
            let n = x.len() as f64;
            let m = x.iter().sum::<f64>() / n;
            let sd = (x.iter().map(|v| (v - m).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
            assert!((m - mu).abs() < 0.1 * 0.01, "mean {i}: {m}");
            assert!((sd / 0.01 - 1.0).abs() < 0.15, "sd {i}: {sd}");
        }
        // Half of burn-in, at least 25; none without burn-in.
        assert_eq!(
            (readapt_window(0), readapt_window(4), readapt_window(400)),
            (0, MIN_READAPT_WINDOW, 200)
        );
        // A chain still in burn-in is not re-adapted.
        let (lp, g) = target(std::slice::from_ref(&mean)).remove(0);
        let mut fresh = HmcState::new(cfg, &mean, Some(&metric), lp, &g, 3, 9).unwrap();
        assert!(fresh.readapt(&cov, window).is_err());
    }

    #[test]
    fn the_readapted_metric_is_the_within_chain_covariance() {
        // Two chains far apart, each with z-variance 1 around its own mean: the pooled
        // metric is ~1 (W), not inflated by the chains' distance (which B would add).
        let sig = |z: f64| 1.0 / (1.0 + (-z).exp());
        let stats = DrawStats {
            accept_stat: 1.0,
            step_size: 0.0,
            n_leapfrog: 0,
            divergent: false,
        };
        let mut a = Draws::new(1);
        let mut b = Draws::new(1);
        for k in 0..1000 {
            let z = if k % 2 == 0 { -1.0 } else { 1.0 };
            a.push(&[sig(z - 2.0)], 0.0, stats);
            b.push(&[sig(z + 2.0)], 0.0, stats);
        }
        let w = within_chain_covariance_z(&[a.clone(), b]).unwrap();
        // Each chain: 1,000 values of +-1, sample variance 1000 / 999.
        assert!((w[0] - 1000.0 / 999.0).abs() < 1e-9, "{w:?}");
        assert!(within_chain_covariance_z(&[a, Draws::new(1)]).is_none());
    }

    #[test]
    fn a_posterior_against_the_box_edge_is_sampled_through_the_logit() {
        // p(u) ∝ exp(-u / 0.05) on [0, 1] (an exponential truncated at 1): mean 0.05.
        let mut target = |pts: &[Vec<f64>]| -> Vec<(f64, Vec<f64>)> {
            pts.iter()
                .map(|u| (-u[0] / 0.05, vec![-1.0 / 0.05]))
                .collect()
        };
        let cfg = HmcConfig {
            burn_in: 500,
            ..HmcConfig::default()
        };
        let mut states = vec![HmcState::new(cfg, &[0.05], None, -1.0, &[-20.0], 1, 0).unwrap()];
        let draws = run_segment_batch(&mut states, 20_500, &mut target).unwrap();
        let x = draws[0].column(0);
        let m = x.iter().sum::<f64>() / x.len() as f64;
        assert!((m - 0.05).abs() < 0.004, "mean {m}");
        let below = x.iter().filter(|&&v| v < 0.05 * 2f64.ln()).count() as f64 / x.len() as f64;
        assert!((below - 0.5).abs() < 0.03, "median fraction {below}");
    }

    #[test]
    fn a_constraint_stops_the_trajectory_and_is_never_crossed() {
        // Uniform on the triangle u0 <= u1: every draw satisfies it.
        let mut target = |pts: &[Vec<f64>]| -> Vec<(f64, Vec<f64>)> {
            pts.iter()
                .map(|u| {
                    (
                        if u[0] <= u[1] { 0.0 } else { f64::NEG_INFINITY },
                        vec![0.0, 0.0],
                    )
                })
                .collect()
        };
        let cfg = HmcConfig {
            burn_in: 100,
            ..HmcConfig::default()
        };
        let mut states =
            vec![HmcState::new(cfg, &[0.3, 0.7], None, 0.0, &[0.0, 0.0], 3, 0).unwrap()];
        let draws = run_segment_batch(&mut states, 2100, &mut target).unwrap();
        assert!((0..draws[0].len()).all(|i| draws[0].point(i)[0] <= draws[0].point(i)[1]));
        assert!(states[0].divergent().1 > 0);
    }
}

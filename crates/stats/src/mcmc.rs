//! Random-walk Metropolis-Hastings in the unit space `[0, 1]^d` (reference Algorithm 1) with
//! adaptive Metropolis during burn-in (Haario, Saksman & Tamminen 2001, Bernoulli 7(2)).
//!
//! - The chain moves in the unit space of the priors (`u = (x - min) / (max - min)`); the
//!   target is the log posterior of the unit-space point, up to a constant.
//! - Proposal: `u' = u + L z`, `z ~ N(0, I)`, `L` the lower Cholesky factor of the proposal
//!   covariance. The proposal is symmetric, so the acceptance ratio of Algorithm 1 reduces to
//!   `alpha = p(u' | y) / p(u | y)`; a draw is accepted when `ln U < ln p(u') - ln p(u)`.
//! - Proposals outside `[0, 1]^d` are **rejected** (not clipped) and never sent to the target:
//!   the prior density is zero there.
//! - Adaptive Metropolis: the proposal is `u' = u + lambda L z`. `L` starts as `initial_sd I`;
//!   from iteration `adapt_start` until the end of burn-in it is refreshed every `adapt_every`
//!   iterations to the Cholesky factor of `s_d (Cov + eps I)`, `s_d = 2.38^2 / d`, `Cov` the
//!   running (Welford) covariance of the chain's states.
//! - Global scale (`target_acceptance = Some(a*)`, the default, a* = 0.234): after every
//!   burn-in iteration `ln lambda += k^-0.6 (alpha - a*)` with `alpha = min(1, p(u')/p(u))`
//!   (0 outside the support): Robbins-Monro on the log scale, Andrieu & Thoms (2008), "A tutorial
//!   on adaptive MCMC", Stat. Comput. 18, Algorithm 4. `lambda` restarts at 1 (and `k` at 1)
//!   when the first AM covariance replaces the initial diagonal. `Cov` is then accumulated from
//!   `adapt_start` on only, forgetting the transient from the start (set `adapt_start` to about
//!   half of burn-in), and the first AM refresh waits for `max(2 (d + 1), adapt_every)` states.
//!   With `target_acceptance = None`, `lambda = 1` and `Cov` covers all of burn-in (the plain
//!   Haario et al. 2001 scheme, bit-identical to the chains of earlier versions).
//! - Independence kernel (`independence = p > 0`): once the AM covariance exists, each iteration
//!   is, with probability `p`, an independence Metropolis-Hastings step (Tierney 1994, Ann. Stat.
//!   22(4), Sec. 2.3.3) instead of a random-walk one: `u' = m + L_I z`, a Gaussian (or, with
//!   `independence_dof = Some(nu)`, a Student-t `m + s L_I z`, `s = sqrt(nu / w)`,
//!   `w ~ chi2(nu)`) centred at the AM mean `m` (or the optimum, [`ChainState::with_proposal`]),
//!   shape `L_I L_I^T = c^2 (Cov + eps I)` (`c` = `independence_inflation`), accepted
//!   with `ln U < [ln p(u') - ln q(u')] - [ln p(u) - ln q(u)]`. It is adapted with the AM
//!   covariance during burn-in (adaptive independence MH, Holden, Hauge & Holden 2009; Giordani
//!   & Kohn 2010) and frozen with it. Each kernel leaves the posterior invariant, so does their
//!   random mixture (Tierney 1994, Sec. 2.4). Why: the random walk's autocorrelation time grows
//!   like `d` (about `3.3 d` iterations at best, Roberts & Rosenthal 2001), which caps 4 x 8,000
//!   draws at a bulk ESS near 300 in 38 dimensions; an independence proposal that matches a
//!   nearly Gaussian posterior moves the whole point at once, whatever `d`. The random-walk
//!   half keeps the chain local where the posterior is not Gaussian. Scale adaptation sees the
//!   random-walk steps only.
//!   An independence kernel accepted less than 1 % of the time during burn-in (at least 100
//!   proposals) is switched off at its end ([`ChainState::independence_dropped`]): in 38
//!   dimensions a Gaussian slightly too narrow in a few directions is almost never accepted,
//!   and its evaluations are better spent on the random walk.
//! - After burn-in `lambda`, `L` and the independence proposal are frozen, so the recorded draws
//!   come from a time-homogeneous Metropolis-Hastings chain.
//! - Randomness per iteration, in this order: one uniform choosing the kernel (only with
//!   `independence > 0` once the independence proposal exists), `d` standard normals, one
//!   chi-square (independence steps only), then one uniform — the same whether the proposal is in
//!   the support or not, so a chain's draws do not depend on how it is stepped (alone, batched,
//!   or in checkpointed segments).

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{ChiSquared, StandardNormal};
use serde::{Deserialize, Serialize};

use crate::error::{Result, StatsError};
use crate::prior::Triangular;

/// Burn-in independence proposals needed before the kernel may be switched off
/// ([`ChainState::independence_dropped`]).
pub const INDEPENDENCE_MIN_TRIALS: u64 = 100;
/// Burn-in acceptance rate of the independence kernel below which it is switched off at the end
/// of burn-in. On the paper-size problem it accepted 0-3 proposals in 1,000 (a 38-dimensional
/// Gaussian that is slightly too narrow in a few directions), so half of all evaluations went
/// to steps that never moved the chain (max R-hat in 4 x 2,500 iterations, 500 burn-in: 1.67
/// with the kernel kept, 1.61 switched off after burn-in, 1.55 with `independence = 0`).
pub const INDEPENDENCE_MIN_ACCEPTANCE: f64 = 0.01;

/// Settings of one chain; stored inside its [`ChainState`] so a checkpoint is self-contained.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MhConfig {
    /// Iterations discarded as burn-in (adaptation happens only in these).
    pub burn_in: u64,
    /// Iteration from which the proposal covariance adapts (Haario's `t0`).
    pub adapt_start: u64,
    /// Recompute the proposal factor every this many iterations during adaptation.
    pub adapt_every: u64,
    /// Initial proposal standard deviation per coordinate, in the unit space.
    pub initial_sd: f64,
    /// Regularisation `eps` of `s_d (Cov + eps I)`.
    pub epsilon: f64,
    /// Scale `s_d`; `None` means `2.38^2 / d`.
    pub scale: Option<f64>,
    /// Target acceptance rate of the global scale adaptation during burn-in (Andrieu & Thoms
    /// 2008, Algorithm 4); `None` turns scale adaptation off and estimates the covariance from
    /// the whole burn-in (the plain Haario et al. 2001 scheme). Checkpoints written before this
    /// field existed deserialise as `None`, so they resume with the algorithm they started with.
    #[serde(default)]
    pub target_acceptance: Option<f64>,
    /// Exponent `a` of the Robbins-Monro step `gamma_k = k^-a` of the scale adaptation,
    /// in `(0.5, 1]`.
    #[serde(default = "default_scale_decay")]
    pub scale_decay: f64,
    /// Probability `p` of an independence step once the AM covariance exists (0: random walk
    /// only, the reference's Algorithm 1; checkpoints written before this field existed
    /// deserialise as 0).
    #[serde(default)]
    pub independence: f64,
    /// Degrees of freedom `nu` of a Student-t independence proposal; `None` (the default):
    /// Gaussian. In 40 dimensions a t with `nu = 7` accepted almost nothing even with the exact
    /// covariance (its radius `sqrt(nu / w)` varies far more than the target's typical set is
    /// wide), while the Gaussian at 1.1 x the Laplace scale is accepted about half the time.
    #[serde(default)]
    pub independence_dof: Option<f64>,
    /// Inflation `c` of the independence proposal's scale over the AM covariance's.
    #[serde(default = "default_independence_inflation")]
    pub independence_inflation: f64,
}

fn default_scale_decay() -> f64 {
    0.6
}
fn default_independence_inflation() -> f64 {
    1.1
}

impl Default for MhConfig {
    fn default() -> Self {
        MhConfig {
            burn_in: 5000,
            adapt_start: 500,
            adapt_every: 10,
            initial_sd: 0.05,
            epsilon: 1e-6,
            scale: None,
            target_acceptance: Some(0.234),
            scale_decay: default_scale_decay(),
            independence: 0.0,
            independence_dof: None,
            independence_inflation: default_independence_inflation(),
        }
    }
}

impl MhConfig {
    fn validate(&self) -> Result<()> {
        if self.adapt_every == 0 {
            return Err(StatsError::Invalid("adapt_every must be at least 1".into()));
        }
        if !(self.initial_sd.is_finite() && self.initial_sd > 0.0) {
            return Err(StatsError::Invalid("initial_sd must be positive".into()));
        }
        if !(self.epsilon.is_finite() && self.epsilon >= 0.0) {
            return Err(StatsError::Invalid("epsilon must be non-negative".into()));
        }
        if let Some(s) = self.scale {
            if !(s.is_finite() && s > 0.0) {
                return Err(StatsError::Invalid("scale must be positive".into()));
            }
        }
        if let Some(a) = self.target_acceptance {
            if !(a > 0.0 && a < 1.0) {
                return Err(StatsError::Invalid(
                    "target_acceptance must be in (0, 1)".into(),
                ));
            }
        }
        if !(self.scale_decay > 0.5 && self.scale_decay <= 1.0) {
            return Err(StatsError::Invalid(
                "scale_decay must be in (0.5, 1]".into(),
            ));
        }
        if !(0.0..1.0).contains(&self.independence) {
            return Err(StatsError::Invalid("independence must be in [0, 1)".into()));
        }
        if self
            .independence_dof
            .is_some_and(|nu| !(nu.is_finite() && nu > 0.0))
        {
            return Err(StatsError::Invalid(
                "independence_dof must be positive".into(),
            ));
        }
        if !(self.independence_inflation.is_finite() && self.independence_inflation > 0.0) {
            return Err(StatsError::Invalid(
                "independence_inflation must be positive".into(),
            ));
        }
        Ok(())
    }
}

/// The complete, serialisable state of one chain: resuming from a deserialised `ChainState`
/// continues with bit-identical draws.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
///
/// Floating-point fields are serialised as their IEEE-754 bit patterns (`u64`), so any
/// serialiser (JSON included, whatever its float parsing) restores them exactly.
pub struct ChainState {
    config: MhConfig,
    #[serde(with = "f64_bits::vec")]
    position: Vec<f64>,
    #[serde(with = "f64_bits")]
    log_density: f64,
    iteration: u64,
    accepted: u64,
    accepted_post_burn_in: u64,
    /// Welford running mean and sum of outer products of the states seen during burn-in.
    adapt_n: u64,
    #[serde(with = "f64_bits::vec")]
    adapt_mean: Vec<f64>,
    #[serde(with = "f64_bits::vec")]
    adapt_m2: Vec<f64>,
    /// Lower Cholesky factor `L` of the proposal shape, row-major `d x d`; the proposal
    /// step is `lambda L z`.
    #[serde(with = "f64_bits::vec")]
    chol: Vec<f64>,
    /// `ln lambda`, the global proposal scale (0 when scale adaptation is off).
    #[serde(default, with = "f64_bits")]
    ln_lambda: f64,
    /// Robbins-Monro steps taken since the scale sequence (re)started.
    #[serde(default)]
    scale_steps: u64,
    /// Whether `chol` is an adaptive-Metropolis estimate (false: the initial diagonal).
    #[serde(default)]
    shape_adapted: bool,
    /// Centre `m` of the independence proposal (empty until the first AM refresh).
    #[serde(default, with = "f64_bits::vec")]
    ind_mean: Vec<f64>,
    /// Lower Cholesky factor `L_I` of its shape, row-major `d x d` (empty until ready).
    #[serde(default, with = "f64_bits::vec")]
    ind_chol: Vec<f64>,
    /// Independence steps proposed and accepted after burn-in.
    #[serde(default)]
    ind_proposed: u64,
    #[serde(default)]
    ind_accepted: u64,
    /// Independence steps proposed and accepted during burn-in.
    #[serde(default)]
    ind_burn_proposed: u64,
    #[serde(default)]
    ind_burn_accepted: u64,
    /// Whether the independence kernel was switched off at the end of burn-in (see
    /// [`ChainState::independence_dropped`]).
    #[serde(default)]
    ind_dropped: bool,
    /// How many nats below the best optimum this chain's own optimum was, when the chain was
    /// started in the best one's mode instead ([`crate::optim::keep_best_modes`]).
    #[serde(default)]
    moved_from_mode: Option<f64>,
    rng: ChaCha8Rng,
}

/// What `propose` drew: which kernel, whether the point is in the support, `ln U`.
#[derive(Debug, Clone, Copy)]
struct Pending {
    inside: bool,
    ln_u: f64,
    /// Independence step: `ln q(u) - ln q(u')`, added to the acceptance ratio.
    ln_q_ratio: Option<f64>,
}

/// Exact serialisation of `f64` values as their bit patterns.
pub(crate) mod f64_bits {
    use serde::{Deserialize, Deserializer, Serializer};

    pub fn serialize<S: Serializer>(v: &f64, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_u64(v.to_bits())
    }
    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
        Ok(f64::from_bits(u64::deserialize(d)?))
    }

    pub mod vec {
        use serde::{Deserialize, Deserializer, Serializer};

        pub fn serialize<S: Serializer>(v: &[f64], s: S) -> Result<S::Ok, S::Error> {
            s.collect_seq(v.iter().map(|x| x.to_bits()))
        }
        pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Vec<f64>, D::Error> {
            Ok(Vec::<u64>::deserialize(d)?
                .into_iter()
                .map(f64::from_bits)
                .collect())
        }
    }
}

/// What the sampler did in the transition to one recorded draw: the sampler diagnostics
/// CmdStan writes beside its draws (`accept_stat__`, `stepsize__`, `n_leapfrog__`,
/// `divergent__`; Stan Reference Manual, "MCMC sampling").
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct DrawStats {
    /// Acceptance probability of the transition: `min(1, exp(-dH))` for HMC, the
    /// Metropolis-Hastings ratio `min(1, p(u') q(u) / (p(u) q(u')))` for MH.
    pub accept_stat: f64,
    /// The leapfrog step size used (jittered); 0 for Metropolis-Hastings.
    pub step_size: f64,
    /// Leapfrog steps taken (the trajectory's length); 0 for Metropolis-Hastings.
    pub n_leapfrog: u32,
    /// The trajectory diverged (energy error over the limit, or a non-finite density).
    pub divergent: bool,
}

/// Recorded post-burn-in draws of one chain (unit space) and their log densities.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Draws {
    /// Dimension `d` of a draw.
    pub dim: usize,
    /// Draws, row-major `len x dim`.
    pub points: Vec<f64>,
    /// Log posterior of each draw.
    pub log_density: Vec<f64>,
    /// The sampler's statistics of each draw (absent from checkpoints written before they
    /// were kept: see [`Draws::stats`]).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub stats: Vec<DrawStats>,
}

impl Draws {
    /// No draws yet.
    pub fn new(dim: usize) -> Self {
        Draws {
            dim,
            points: Vec::new(),
            log_density: Vec::new(),
            stats: Vec::new(),
        }
    }
    /// The sampler's statistics of every draw, or `None` when some draws have none (draws
    /// made up rather than sampled, or a chain begun before they were kept).
    pub fn stats(&self) -> Option<&[DrawStats]> {
        (self.stats.len() == self.len() && !self.is_empty()).then_some(&self.stats)
    }
    /// Number of draws.
    pub fn len(&self) -> usize {
        self.log_density.len()
    }
    /// Whether there are no draws.
    pub fn is_empty(&self) -> bool {
        self.log_density.is_empty()
    }
    /// Draw `i`.
    pub fn point(&self, i: usize) -> &[f64] {
        &self.points[i * self.dim..(i + 1) * self.dim]
    }
    /// All draws of coordinate `j`.
    pub fn column(&self, j: usize) -> Vec<f64> {
        self.points
            .iter()
            .skip(j)
            .step_by(self.dim)
            .copied()
            .collect()
    }
    /// Append the draws of a later segment.
    pub fn extend(&mut self, later: &Draws) {
        assert_eq!(self.dim, later.dim, "draws of different dimension");
        self.points.extend_from_slice(&later.points);
        self.log_density.extend_from_slice(&later.log_density);
        self.stats.extend_from_slice(&later.stats);
    }
    pub(crate) fn push(&mut self, x: &[f64], lp: f64, stats: DrawStats) {
        self.points.extend_from_slice(x);
        self.log_density.push(lp);
        self.stats.push(stats);
    }
}

/// Welford's running mean and sum of outer products (`m2`, row-major `d x d`, symmetric up
/// to rounding) updated with the state `x`; `n` counts the states.
pub(crate) fn welford_update(n: &mut u64, mean: &mut [f64], m2: &mut [f64], x: &[f64]) {
    let d = x.len();
    *n += 1;
    let nf = *n as f64;
    let delta: Vec<f64> = (0..d).map(|i| x[i] - mean[i]).collect();
    for (m, dl) in mean.iter_mut().zip(&delta) {
        *m += dl / nf;
    }
    for i in 0..d {
        let after_i = x[i] - mean[i];
        for (j, dj) in delta.iter().enumerate() {
            // Symmetric update: M2 += delta_before x delta_after.
            m2[j * d + i] += dj * after_i;
        }
    }
}

/// Lower Cholesky factor `L` (row-major `d x d`) of a symmetric positive-definite row-major
/// `d x d` matrix; `None` if not positive definite.
pub fn cholesky(a: &[f64], d: usize) -> Option<Vec<f64>> {
    let mut l = vec![0.0; d * d];
    for i in 0..d {
        for j in 0..=i {
            let mut s = a[i * d + j];
            for k in 0..j {
                s -= l[i * d + k] * l[j * d + k];
            }
            if i == j {
                if s.is_nan() || s <= 0.0 || !s.is_finite() {
                    return None;
                }
                l[i * d + i] = s.sqrt();
            } else {
                l[i * d + j] = s / l[j * d + j];
            }
        }
    }
    Some(l)
}

impl ChainState {
    /// A chain at `start` (in `[0, 1]^d`) whose log posterior is `log_density`, with its own
    /// random stream: `ChaCha8Rng` seeded from `seed`, stream `stream` (use the chain index).
    pub fn new(
        config: MhConfig,
        start: Vec<f64>,
        log_density: f64,
        seed: u64,
        stream: u64,
    ) -> Result<Self> {
        config.validate()?;
        let d = start.len();
        if d == 0 {
            return Err(StatsError::Invalid(
                "a chain needs at least one parameter".into(),
            ));
        }
        if let Some(i) = start.iter().position(|u| !(0.0..=1.0).contains(u)) {
            return Err(StatsError::Invalid(format!(
                "start coordinate {i} = {} is outside the unit interval",
                start[i]
            )));
        }
        let mut chol = vec![0.0; d * d];
        for i in 0..d {
            chol[i * d + i] = config.initial_sd;
        }
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        rng.set_stream(stream);
        Ok(ChainState {
            config,
            position: start,
            log_density: if log_density.is_nan() {
                f64::NEG_INFINITY
            } else {
                log_density
            },
            iteration: 0,
            accepted: 0,
            accepted_post_burn_in: 0,
            adapt_n: 0,
            adapt_mean: vec![0.0; d],
            adapt_m2: vec![0.0; d * d],
            chol,
            ln_lambda: 0.0,
            scale_steps: 0,
            shape_adapted: false,
            ind_mean: Vec::new(),
            ind_chol: Vec::new(),
            ind_proposed: 0,
            ind_accepted: 0,
            ind_burn_proposed: 0,
            ind_burn_accepted: 0,
            ind_dropped: false,
            moved_from_mode: None,
            rng,
        })
    }

    /// A chain like [`ChainState::new`] whose proposals start from a Gaussian approximation of
    /// the posterior, mean `start` and `covariance` (row-major `d x d`, e.g. the Laplace
    /// covariance at an optimum, [`crate::optim`]): the random walk's shape is
    /// `s_d covariance` instead of `initial_sd^2 I`, and with `independence > 0` the
    /// independence proposal is the Student-t at `start` with shape
    /// `independence_inflation^2 covariance`, ready from the first iteration. Both are kept
    /// unless the AM covariance replaces them (set `adapt_start >= burn_in` to keep them for
    /// the whole chain). Falls back to [`ChainState::new`] if `covariance` is not positive
    /// definite.
    pub fn with_proposal(
        config: MhConfig,
        start: Vec<f64>,
        log_density: f64,
        covariance: &[f64],
        seed: u64,
        stream: u64,
    ) -> Result<Self> {
        let mut st = ChainState::new(config, start, log_density, seed, stream)?;
        let d = st.dim();
        if covariance.len() != d * d {
            return Err(StatsError::Shape(format!(
                "proposal covariance of {} values for {d} dimensions",
                covariance.len()
            )));
        }
        let c: Vec<f64> = (0..d * d)
            .map(|k| {
                let (i, j) = (k / d, k % d);
                0.5 * (covariance[k] + covariance[j * d + i])
                    + if i == j { st.config.epsilon } else { 0.0 }
            })
            .collect();
        if let Some(l) = cholesky(&c, d) {
            let s_d = st.config.scale.unwrap_or(2.38 * 2.38 / d as f64);
            st.chol = l.iter().map(|v| v * s_d.sqrt()).collect();
            if st.config.independence > 0.0 {
                st.ind_mean = st.position.clone();
                st.ind_chol = l
                    .iter()
                    .map(|v| v * st.config.independence_inflation)
                    .collect();
            }
        }
        Ok(st)
    }

    /// The chain's settings.
    pub fn config(&self) -> &MhConfig {
        &self.config
    }
    /// Dimension `d`.
    pub fn dim(&self) -> usize {
        self.position.len()
    }
    /// Current point (unit space).
    pub fn position(&self) -> &[f64] {
        &self.position
    }
    /// Log posterior of the current point.
    pub fn log_density(&self) -> f64 {
        self.log_density
    }
    /// Iterations completed.
    pub fn iteration(&self) -> u64 {
        self.iteration
    }
    /// Set when the chain was started in the best optimum's mode instead of its own: how many
    /// nats lower its own was (see [`chains_at_optima`]).
    pub fn moved_from_mode(&self) -> Option<f64> {
        self.moved_from_mode
    }
    /// Whether the next iteration is still burn-in.
    pub fn in_burn_in(&self) -> bool {
        self.iteration < self.config.burn_in
    }
    /// Accepted proposals over all iterations.
    pub fn accepted(&self) -> u64 {
        self.accepted
    }
    /// Acceptance rate over all iterations (NaN before the first).
    pub fn acceptance_rate(&self) -> f64 {
        self.accepted as f64 / self.iteration as f64
    }
    /// Acceptance rate after burn-in (NaN before the first post-burn-in iteration).
    pub fn acceptance_rate_post_burn_in(&self) -> f64 {
        let n = self.iteration.saturating_sub(self.config.burn_in);
        self.accepted_post_burn_in as f64 / n as f64
    }
    /// Acceptance rate of the independence steps after burn-in (NaN when none was proposed).
    pub fn independence_acceptance_rate(&self) -> f64 {
        self.ind_accepted as f64 / self.ind_proposed as f64
    }
    /// Independence steps proposed after burn-in.
    pub fn independence_steps(&self) -> u64 {
        self.ind_proposed
    }
    /// Whether the independence kernel was switched off at the end of burn-in because fewer
    /// than [`INDEPENDENCE_MIN_ACCEPTANCE`] of at least [`INDEPENDENCE_MIN_TRIALS`] burn-in
    /// proposals were accepted: every later iteration is then a random-walk step.
    pub fn independence_dropped(&self) -> bool {
        self.ind_dropped
    }
    /// Current global proposal scale `lambda` (1 without scale adaptation).
    pub fn proposal_scale(&self) -> f64 {
        self.ln_lambda.exp()
    }
    /// Current proposal covariance `lambda^2 L L^T`, row-major `d x d`.
    pub fn proposal_covariance(&self) -> Vec<f64> {
        let d = self.dim();
        let l = &self.chol;
        let l2 = (2.0 * self.ln_lambda).exp();
        let mut c = vec![0.0; d * d];
        for i in 0..d {
            for j in 0..d {
                c[i * d + j] = l2 * (0..d).map(|k| l[i * d + k] * l[j * d + k]).sum::<f64>();
            }
        }
        c
    }

    /// Draw the proposal into `buf`.
    fn propose(&mut self, buf: &mut Vec<f64>) -> Pending {
        let d = self.dim();
        buf.clear();
        let independent = self.config.independence > 0.0
            && !self.ind_chol.is_empty()
            && self.rng.random::<f64>() < self.config.independence;
        let z: Vec<f64> = (0..d).map(|_| self.rng.sample(StandardNormal)).collect();
        let mut ln_q_ratio = None;
        if independent {
            // Gaussian draw m + L_I z, or Student-t m + s L_I z with s = sqrt(nu / w),
            // w ~ chi2(nu).
            let nu = self.config.independence_dof;
            let s = match nu {
                Some(nu) => {
                    let w: f64 = self
                        .rng
                        .sample(ChiSquared::new(nu).expect("nu validated positive"));
                    (nu / w).sqrt()
                }
                None => 1.0,
            };
            for i in 0..d {
                let step: f64 = (0..=i).map(|k| self.ind_chol[i * d + k] * z[k]).sum();
                buf.push(self.ind_mean[i] + s * step);
            }
            let r2_new = s * s * z.iter().map(|v| v * v).sum::<f64>();
            let r2_old = self.ind_mahalanobis2(&self.position);
            // ln q(u) - ln q(u') (normalising constants cancel).
            ln_q_ratio = Some(match nu {
                Some(nu) => {
                    -0.5 * (nu + d as f64) * ((r2_old / nu).ln_1p() - (r2_new / nu).ln_1p())
                }
                None => -0.5 * (r2_old - r2_new),
            });
        } else {
            let lambda = self.ln_lambda.exp();
            for i in 0..d {
                let step: f64 = (0..=i).map(|k| self.chol[i * d + k] * z[k]).sum();
                // lambda = 1 exactly without scale adaptation, so this is then `step` bit for bit.
                buf.push(self.position[i] + lambda * step);
            }
        }
        let u: f64 = self.rng.random();
        let inside = buf.iter().all(|v| (0.0..=1.0).contains(v));
        Pending {
            inside,
            ln_u: u.ln(),
            ln_q_ratio,
        }
    }

    /// `|L_I^-1 (x - m)|^2` by forward substitution.
    fn ind_mahalanobis2(&self, x: &[f64]) -> f64 {
        let d = self.dim();
        let l = &self.ind_chol;
        let mut y = vec![0.0; d];
        for i in 0..d {
            let s: f64 = (0..i).map(|k| l[i * d + k] * y[k]).sum();
            y[i] = (x[i] - self.ind_mean[i] - s) / l[i * d + i];
        }
        y.iter().map(|v| v * v).sum()
    }

    /// Accept or reject, adapt, and record. `lp` is `None` for an out-of-support proposal.
    fn finish(&mut self, proposal: &[f64], pending: Pending, lp: Option<f64>, draws: &mut Draws) {
        let Pending {
            ln_u, ln_q_ratio, ..
        } = pending;
        let independence = ln_q_ratio.is_some();
        let post_burn_in = self.iteration >= self.config.burn_in;
        if independence {
            if post_burn_in {
                self.ind_proposed += 1;
            } else {
                self.ind_burn_proposed += 1;
            }
        }
        // Acceptance probability min(1, p(u') q(u) / (p(u) q(u'))) (q = 1 for the symmetric
        // random walk); 0 outside the support or for NaN.
        let mut alpha = 0.0;
        let q = ln_q_ratio.unwrap_or(0.0);
        if let Some(lp) = lp.filter(|lp| !lp.is_nan()) {
            let r = lp - self.log_density + q;
            alpha = acceptance_probability(r);
            // Metropolis-Hastings acceptance (Algorithm 1, step 6).
            if ln_u < r {
                self.accept(proposal, lp, post_burn_in, independence);
            }
        }
        self.iteration += 1;
        let t = self.iteration;
        if t == self.config.burn_in
            && self.ind_burn_proposed >= INDEPENDENCE_MIN_TRIALS
            && (self.ind_burn_accepted as f64)
                < INDEPENDENCE_MIN_ACCEPTANCE * self.ind_burn_proposed as f64
        {
            // The frozen kernel would waste these evaluations: switch it off for good.
            self.ind_mean.clear();
            self.ind_chol.clear();
            self.ind_dropped = true;
        }
        if t > self.config.burn_in {
            let stats = DrawStats {
                accept_stat: alpha,
                step_size: 0.0,
                n_leapfrog: 0,
                divergent: false,
            };
            draws.push(&self.position, self.log_density, stats);
            return;
        }
        self.adapt_burn_in(t, alpha, independence);
    }

    /// Moves the chain to an accepted `proposal` of log density `lp`, counting it.
    fn accept(&mut self, proposal: &[f64], lp: f64, post_burn_in: bool, independence: bool) {
        self.position.copy_from_slice(proposal);
        self.log_density = lp;
        self.accepted += 1;
        if post_burn_in {
            self.accepted_post_burn_in += 1;
            if independence {
                self.ind_accepted += 1;
            }
        } else if independence {
            self.ind_burn_accepted += 1;
        }
    }

    /// The burn-in's adaptation after iteration `t` (acceptance probability `alpha`; an
    /// `independence` step leaves the random walk's scale alone): Haario et al.'s covariance,
    /// and with a target acceptance Robbins-Monro on the scale.
    fn adapt_burn_in(&mut self, t: u64, alpha: f64, independence: bool) {
        match self.config.target_acceptance {
            None => {
                // Plain Haario et al. (2001): covariance of the whole burn-in so far.
                self.adapt_update();
                if t >= self.config.adapt_start
                    && t.is_multiple_of(self.config.adapt_every)
                    && t < self.config.burn_in
                {
                    self.refresh_proposal();
                }
            }
            Some(target) => {
                // Robbins-Monro on ln lambda (Andrieu & Thoms 2008, Algorithm 4, with the
                // covariance part of AM below): ln lambda += gamma_k (alpha_k - target), over
                // the random-walk steps.
                if !independence {
                    self.scale_steps += 1;
                    let gamma = (self.scale_steps as f64).powf(-self.config.scale_decay);
                    self.ln_lambda = (self.ln_lambda + gamma * (alpha - target)).clamp(-40.0, 10.0);
                }
                // AM covariance of the states from `adapt_start` on only: the states before it
                // are the transient from a start far in the tails, whose spread would make the
                // frozen proposal far too wide (Haario et al. 2001 use all states; discarding
                // an initial stretch is the usual remedy, cf. Andrieu & Thoms 2008, Sec. 5).
                if t >= self.config.adapt_start {
                    self.adapt_update();
                }
                if t >= self.config.adapt_start
                    && t.is_multiple_of(self.config.adapt_every)
                    && t < self.config.burn_in
                    && self.adapt_n >= self.min_adapt_samples()
                {
                    let first = !self.shape_adapted;
                    self.refresh_proposal();
                    if first && self.shape_adapted {
                        // s_d Cov is the optimal scale for a Gaussian target; start lambda
                        // afresh from 1 for the new shape.
                        self.ln_lambda = 0.0;
                        self.scale_steps = 0;
                    }
                }
            }
        }
    }

    /// Samples the AM accumulator needs before its covariance replaces the current shape.
    fn min_adapt_samples(&self) -> u64 {
        (2 * (self.dim() as u64 + 1)).max(self.config.adapt_every)
    }

    /// Welford update of the running mean and covariance with the current state.
    fn adapt_update(&mut self) {
        welford_update(
            &mut self.adapt_n,
            &mut self.adapt_mean,
            &mut self.adapt_m2,
            &self.position,
        );
    }

    /// Haario et al. (2001) Eq. (2.1): `C_t = s_d Cov(X_0..X_{t-1}) + s_d eps I_d`.
    fn refresh_proposal(&mut self) {
        let d = self.dim();
        if self.adapt_n < 2 {
            return;
        }
        let s_d = self.config.scale.unwrap_or(2.38 * 2.38 / d as f64);
        let n1 = (self.adapt_n - 1) as f64;
        let mut c = vec![0.0; d * d];
        for i in 0..d {
            for j in 0..d {
                // Symmetrise against rounding.
                let cov = 0.5 * (self.adapt_m2[i * d + j] + self.adapt_m2[j * d + i]) / n1;
                c[i * d + j] = s_d * (cov + if i == j { self.config.epsilon } else { 0.0 });
            }
        }
        if let Some(l) = cholesky(&c, d) {
            if self.config.independence > 0.0 {
                // L_I = (c / sqrt(s_d)) L: the same covariance, at the inflation's scale.
                let f = self.config.independence_inflation / s_d.sqrt();
                self.ind_chol = l.iter().map(|v| v * f).collect();
                self.ind_mean = self.adapt_mean.clone();
            }
            self.chol = l;
            self.shape_adapted = true;
        }
    }
}

/// Advance one chain by one iteration, calling `target` (log posterior of a unit-space point)
/// only for proposals inside `[0, 1]^d`; post-burn-in states are appended to `draws`.
pub fn step<F: FnMut(&[f64]) -> f64>(state: &mut ChainState, target: &mut F, draws: &mut Draws) {
    let mut buf = Vec::with_capacity(state.dim());
    let pending = state.propose(&mut buf);
    let lp = pending.inside.then(|| target(&buf));
    state.finish(&buf, pending, lp, draws);
}

/// Advance one chain by `n` iterations; returns the post-burn-in draws of this segment.
/// Running `a` then `b` iterations (with any checkpoint in between) gives exactly the draws of
/// one run of `a + b`.
pub fn run_segment<F: FnMut(&[f64]) -> f64>(
    state: &mut ChainState,
    n: u64,
    mut target: F,
) -> Draws {
    let mut draws = Draws::new(state.dim());
    for _ in 0..n {
        step(state, &mut target, &mut draws);
    }
    draws
}

/// Advance several chains by one iteration each, calling `target` once with all in-support
/// proposals (in chain order; chains whose proposal left the support are skipped). `target`
/// must return one log posterior per point it was given. Each chain's draws are identical to
/// stepping it alone.
pub fn step_batch<F: FnMut(&[Vec<f64>]) -> Vec<f64>>(
    states: &mut [ChainState],
    target: &mut F,
    draws: &mut [Draws],
) -> Result<()> {
    if draws.len() != states.len() {
        return Err(StatsError::Shape(format!(
            "{} chains but {} draw buffers",
            states.len(),
            draws.len()
        )));
    }
    let mut proposals = Vec::with_capacity(states.len());
    let mut pending = Vec::with_capacity(states.len());
    for s in states.iter_mut() {
        let mut buf = Vec::with_capacity(s.dim());
        // An out-of-support proposal is kept only to finish the step; it is never evaluated.
        pending.push(s.propose(&mut buf));
        proposals.push(buf);
    }
    let batch: Vec<Vec<f64>> = proposals
        .iter()
        .zip(&pending)
        .filter(|(_, p)| p.inside)
        .map(|(p, _)| p.clone())
        .collect();
    let lps = if batch.is_empty() {
        Vec::new()
    } else {
        target(&batch)
    };
    if lps.len() != batch.len() {
        return Err(StatsError::Shape(format!(
            "target returned {} log densities for {} proposals",
            lps.len(),
            batch.len()
        )));
    }
    let mut next = lps.into_iter();
    for ((s, pend), (p, d)) in states
        .iter_mut()
        .zip(pending)
        .zip(proposals.iter().zip(draws.iter_mut()))
    {
        let lp = if pend.inside { next.next() } else { None };
        s.finish(p, pend, lp, d);
    }
    Ok(())
}

/// Advance several chains by `n` iterations each with a batched target; returns each chain's
/// post-burn-in draws of this segment.
pub fn run_segment_batch<F: FnMut(&[Vec<f64>]) -> Vec<f64>>(
    states: &mut [ChainState],
    n: u64,
    mut target: F,
) -> Result<Vec<Draws>> {
    let mut draws: Vec<Draws> = states.iter().map(|s| Draws::new(s.dim())).collect();
    for _ in 0..n {
        step_batch(states, &mut target, &mut draws)?;
    }
    Ok(draws)
}

/// Chains started at optima ([`crate::optim::maximise_batch`]), each with its Laplace
/// covariance as proposal ([`ChainState::with_proposal`]); chain `c` gets random stream
/// `first_stream + c`. An optimum more than `restart_below` nats below the best one is
/// replaced by the best ([`crate::optim::keep_best_modes`]; the chain records the gap,
/// [`ChainState::moved_from_mode`]); `f64::INFINITY` keeps every optimum.
pub fn chains_at_optima(
    config: &MhConfig,
    mut optima: Vec<crate::optim::Optimum>,
    seed: u64,
    first_stream: u64,
    restart_below: f64,
) -> Result<Vec<ChainState>> {
    let moved = crate::optim::keep_best_modes(&mut optima, restart_below);
    let mut states = optima
        .into_iter()
        .enumerate()
        .map(|(c, o)| {
            ChainState::with_proposal(
                config.clone(),
                o.point,
                o.log_density,
                &o.covariance,
                seed,
                first_stream + c as u64,
            )
        })
        .collect::<Result<Vec<_>>>()?;
    for (c, gap) in moved {
        states[c].moved_from_mode = Some(gap);
    }
    Ok(states)
}

/// Dispersed starting points for `n_chains` chains: each a draw from the priors (inverse CDF),
/// mapped to the unit space; chain `c` uses `ChaCha8Rng` seeded from `seed`, stream `c`.
pub fn dispersed_starts(priors: &[Triangular], n_chains: usize, seed: u64) -> Vec<Vec<f64>> {
    (0..n_chains)
        .map(|c| {
            let mut rng = ChaCha8Rng::seed_from_u64(seed);
            rng.set_stream(c as u64);
            priors
                .iter()
                .map(|p| p.to_unit(p.sample(&mut rng)))
                .collect()
        })
        .collect()
}

/// The Metropolis-Hastings acceptance probability `min(1, exp(r))` of a proposal whose log
/// ratio (target and proposal densities) is `r`; 0 for NaN.
fn acceptance_probability(r: f64) -> f64 {
    if r >= 0.0 {
        1.0
    } else if r.is_nan() {
        0.0
    } else {
        r.exp()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cholesky_known() {
        // [[4, 2], [2, 3]] = L L^T with L = [[2, 0], [1, sqrt 2]].
        let l = cholesky(&[4.0, 2.0, 2.0, 3.0], 2).unwrap();
        assert!((l[0] - 2.0).abs() < 1e-15 && (l[2] - 1.0).abs() < 1e-15);
        assert!((l[3] - 2f64.sqrt()).abs() < 1e-15 && l[1] == 0.0);
        assert!(cholesky(&[1.0, 2.0, 2.0, 1.0], 2).is_none());
    }

    #[test]
    fn rejects_bad_start_and_config() {
        assert!(ChainState::new(MhConfig::default(), vec![0.5, 1.2], 0.0, 1, 0).is_err());
        let cfg = MhConfig {
            adapt_every: 0,
            ..MhConfig::default()
        };
        assert!(ChainState::new(cfg, vec![0.5], 0.0, 1, 0).is_err());
    }

    #[test]
    fn old_checkpoints_resume_without_scale_adaptation() {
        let cfg = MhConfig {
            target_acceptance: None,
            ..MhConfig::default()
        };
        let st = ChainState::new(cfg, vec![0.5, 0.5], -1.0, 1, 0).unwrap();
        let mut v = serde_json::to_value(&st).unwrap();
        let o = v.as_object_mut().unwrap();
        for k in ["ln_lambda", "scale_steps", "shape_adapted"] {
            assert!(o.remove(k).is_some());
        }
        let c = o["config"].as_object_mut().unwrap();
        c.remove("target_acceptance").unwrap();
        c.remove("scale_decay").unwrap();
        let back: ChainState = serde_json::from_value(v).unwrap();
        assert_eq!(back, st);
        assert_eq!(back.proposal_scale(), 1.0);
    }

    #[test]
    fn rejects_bad_scale_adaptation() {
        for (t, a) in [
            (Some(0.0), 0.6),
            (Some(1.0), 0.6),
            (Some(0.2), 0.5),
            (Some(0.2), 1.1),
        ] {
            let cfg = MhConfig {
                target_acceptance: t,
                scale_decay: a,
                ..MhConfig::default()
            };
            assert!(ChainState::new(cfg, vec![0.5], 0.0, 1, 0).is_err());
        }
    }
}

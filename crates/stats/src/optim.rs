//! Posterior mode search before sampling: BFGS with finite-difference gradients in the unit
//! cube, from several starts at once (one batched target call per round).
//!
//! Why: on the paper-size problem the posterior of 38 parameters given 3 x 8,760 hours is so
//! peaked that random-walk chains started from prior draws were still climbing after 10,000
//! iterations (the demo's chains: log posterior still rising by 12-36 nats per 500 draws, R-hat
//! 3.8). Optimising each dispersed start first and starting its chain at the optimum, with the
//! optimiser's inverse-Hessian estimate as the first proposal shape, is the initialisation of
//! Pathfinder (Zhang, Carpenter, Gelman & Vehtari 2022, JMLR 23(306), Sec. 2: quasi-Newton paths
//! from dispersed inits, their inverse-Hessian estimates as Gaussian approximations). Separate
//! optimisations that end in different local modes leave chains that disagree, which R-hat then
//! reports.
//!
//! - BFGS in the unit cube: Nocedal & Wright (2006), *Numerical Optimization*, Algorithm 6.1
//!   with the inverse-Hessian update (6.17), `H_0` scaled by (6.20) before the first update, a
//!   backtracking Armijo line search (Algorithm 3.1, `c_1 = 1e-4`), steps capped at `max_step`
//!   (max norm) and trial points projected onto the box; a coordinate at a bound whose descent
//!   points outwards is held there for the iteration (projected quasi-Newton). Updates with
//!   `s^T y <= 0` are skipped (curvature condition). A logit reparametrisation was tried first:
//!   it made a 40-D Gaussian far from quadratic and BFGS stalled 1,700 nats below the mode.
//! - Gradient: forward differences with step `fd_step` (backward at the upper bound), or the
//!   target's own gradient ([`maximise_batch_with_gradient`]: through the surrogate's VJP
//!   graph one gradient costs about 3.3 evaluations instead of `d + 1`, and carries no
//!   finite-difference noise, which at step 1e-4 and ~1e-3 nats of float32 rounding is ~10 nats
//!   per unit: enough to stop BFGS on a mode's flat shoulders).
//! - Laplace covariance: a finite-difference Hessian at the optimum with steps set by the
//!   posterior's own curvature ([`laplace_batch`]).
//! - Stops when an iteration raises the target by less than `tolerance` twice in a row, or
//!   after `max_iterations`.

/// Settings of the mode search.
#[derive(Debug, Clone, PartialEq)]
pub struct BfgsConfig {
    /// BFGS iterations per start at most.
    pub max_iterations: usize,
    /// Forward-difference step in the unit space.
    pub fd_step: f64,
    /// Stop after two iterations that each raise the log density by less than this.
    pub tolerance: f64,
    /// Largest step (max norm) in the unit space.
    pub max_step: f64,
    /// Finish with a finite-difference Hessian at each optimum (`2 d + d (d - 1) / 2`
    /// evaluations) for the covariance; otherwise the BFGS inverse-Hessian estimate.
    pub hessian: bool,
}

impl Default for BfgsConfig {
    fn default() -> Self {
        BfgsConfig {
            max_iterations: 60,
            fd_step: 1e-4,
            tolerance: 0.1,
            max_step: 0.5,
            hessian: true,
        }
    }
}

/// The end of one start's search.
#[derive(Debug, Clone, PartialEq)]
pub struct Optimum {
    /// The best point found (unit space).
    pub point: Vec<f64>,
    /// Its log density.
    pub log_density: f64,
    /// Laplace covariance at `point`, the inverse of the negative log density's Hessian
    /// (finite differences; the BFGS estimate where that Hessian is not positive definite or
    /// `hessian` is off), row-major `d x d`: the first proposal's shape.
    pub covariance: Vec<f64>,
    /// BFGS iterations taken.
    pub iterations: usize,
    /// Target evaluations used.
    pub evaluations: usize,
}

/// One start's search state (minimising `f = -ln p`).
struct Search {
    z: Vec<f64>,
    f: f64,
    g: Vec<f64>,
    /// Inverse Hessian, row-major.
    h: Vec<f64>,
    updated: bool,
    iterations: usize,
    evaluations: usize,
    small_steps: usize,
    done: bool,
}

impl Search {
    /// A search from `u` (clamped into the box) whose log density is `lp`; a start with a
    /// non-finite log density (or no dimension) is done before it begins. The inverse Hessian
    /// starts as the identity.
    fn start(u: &[f64], lp: f64) -> Search {
        let d = u.len();
        let mut h = vec![0.0; d * d];
        for i in 0..d {
            h[i * d + i] = 1.0;
        }
        Search {
            z: u.iter().map(|v| v.clamp(0.0, 1.0)).collect(),
            f: if lp.is_finite() { -lp } else { f64::INFINITY },
            g: vec![0.0; d],
            h,
            updated: false,
            iterations: 0,
            evaluations: 0,
            small_steps: 0,
            done: !lp.is_finite() || d == 0,
        }
    }

    /// The search direction `p = -H g` on the free coordinates, capped at `max_step` in max
    /// norm, with its slope `g^T p`: a coordinate at a bound whose descent points out of the box
    /// stays there this iteration (projected quasi-Newton); steepest descent where `H` lost
    /// positive definiteness (Nocedal & Wright 2006, Algorithm 6.1).
    fn direction(&self, cfg: &BfgsConfig) -> (Vec<f64>, f64) {
        let (s, d) = (self, self.z.len());
        let held: Vec<bool> = (0..d)
            .map(|k| (s.z[k] <= 0.0 && s.g[k] > 0.0) || (s.z[k] >= 1.0 && s.g[k] < 0.0))
            .collect();
        let g_free: Vec<f64> = (0..d).map(|k| if held[k] { 0.0 } else { s.g[k] }).collect();
        let mut p: Vec<f64> = (0..d)
            .map(|r| {
                if held[r] {
                    0.0
                } else {
                    -(0..d).map(|c| s.h[r * d + c] * g_free[c]).sum::<f64>()
                }
            })
            .collect();
        let mut slope: f64 = p.iter().zip(&s.g).map(|(a, b)| a * b).sum();
        if slope >= 0.0 {
            // Not a descent direction (H lost positive definiteness): steepest descent.
            p = s.g.iter().map(|v| -v).collect();
            slope = -s.g.iter().map(|v| v * v).sum::<f64>();
        }
        let norm = p.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        if norm > cfg.max_step {
            let k = cfg.max_step / norm;
            p.iter_mut().for_each(|v| *v *= k);
            slope *= k;
        }
        (p, slope)
    }

    /// Ends an iteration: moves to the line search's accepted point and returns the step
    /// taken, or finishes the search where none was accepted; two steps in a row that gain
    /// less than `tolerance` also finish it.
    fn take_step(
        &mut self,
        accepted: Option<(Vec<f64>, f64)>,
        cfg: &BfgsConfig,
    ) -> Option<Vec<f64>> {
        self.iterations += 1;
        let Some((z, f)) = accepted else {
            self.done = true;
            return None;
        };
        let gain = self.f - f;
        self.small_steps = if gain < cfg.tolerance {
            self.small_steps + 1
        } else {
            0
        };
        let step: Vec<f64> = z.iter().zip(&self.z).map(|(a, b)| a - b).collect();
        self.z = z;
        self.f = f;
        if self.small_steps >= 2 {
            self.done = true;
        }
        Some(step)
    }
}

/// Backtracking line search along `dirs` for the `active` searches, in lockstep (one batched
/// call per halving, at most 30): the first `alpha` in 1, 1/2, ... whose trial point (projected
/// onto the box) meets the Armijo condition `f(z + a p) <= f(z) + c1 a g^T p`, `c1 = 1e-4`
/// (Nocedal & Wright 2006, Eq. 3.4, Algorithm 3.1). Returns the accepted point and its value
/// per search (`None`: no step accepted).
fn line_search(
    searches: &mut [Search],
    active: &[usize],
    dirs: &[(Vec<f64>, f64)],
    eval: &mut impl FnMut(&[Vec<f64>]) -> Vec<f64>,
) -> Vec<Option<(Vec<f64>, f64)>> {
    let mut alpha: Vec<f64> = vec![1.0; searches.len()];
    let mut accepted: Vec<Option<(Vec<f64>, f64)>> = vec![None; searches.len()];
    let mut searching = active.to_vec();
    for _ in 0..30 {
        if searching.is_empty() {
            break;
        }
        let trials: Vec<Vec<f64>> = searching
            .iter()
            .map(|&i| {
                let s = &searches[i];
                (0..s.z.len())
                    .map(|r| (s.z[r] + alpha[i] * dirs[i].0[r]).clamp(0.0, 1.0))
                    .collect()
            })
            .collect();
        let fs = eval(&trials);
        let mut still = Vec::new();
        for ((&i, z), f) in searching.iter().zip(trials).zip(fs) {
            let s = &mut searches[i];
            s.evaluations += 1;
            // Armijo: f(z + a p) <= f(z) + c1 a g^T p (Nocedal & Wright Eq. 3.4).
            if f.is_finite() && f <= s.f + 1e-4 * alpha[i] * dirs[i].1.min(0.0) {
                accepted[i] = Some((z, f));
            } else {
                alpha[i] *= 0.5;
                still.push(i);
            }
        }
        searching = still;
    }
    accepted
}

/// One Newton step with the Laplace covariance, `z - Sigma g` (Nocedal & Wright Eq. 3.30),
/// kept where it raises the target: BFGS stops a few sds short of the mode in 40 dimensions
/// (a 40-D Gaussian: 8-23 nats below it after 60 iterations), which would put an
/// independence proposal's centre off the posterior's.
fn newton_step(
    searches: &[Search],
    out: &mut [Optimum],
    eval: &mut impl FnMut(&[Vec<f64>]) -> Vec<f64>,
) {
    let trials: Vec<Vec<f64>> = searches
        .iter()
        .zip(out.iter())
        .map(|(s, o)| {
            let d = s.z.len();
            (0..d)
                .map(|r| {
                    let step: f64 = (0..d).map(|c| o.covariance[r * d + c] * s.g[c]).sum();
                    (s.z[r] - step).clamp(0.0, 1.0)
                })
                .collect()
        })
        .collect();
    let fs = eval(&trials);
    for ((o, z), f) in out.iter_mut().zip(trials).zip(fs) {
        o.evaluations += 1;
        if f.is_finite() && -f > o.log_density {
            o.point = z;
            o.log_density = -f;
        }
    }
}

/// Stuck-chain detection: the index of the largest of `values` (log posteriors, one per chain)
/// and every entry more than `gap` nats below it, with how far below. `None` when `values` is
/// empty; nothing is below an infinite gap or a best of `-inf`.
pub fn far_below_best(values: &[f64], gap: f64) -> Option<(usize, Vec<(usize, f64)>)> {
    let (best, top) = values
        .iter()
        .copied()
        .enumerate()
        .max_by(|a, b| a.1.total_cmp(&b.1))?;
    let below = values
        .iter()
        .enumerate()
        .map(|(i, v)| (i, top - v))
        .filter(|&(_, d)| d > gap)
        .collect();
    Some((best, below))
}

/// Mode pruning for chains started at optima: every optimum more than `gap` nats below the
/// best one is replaced by the best one (point, log density and Laplace covariance). For modes
/// of similar curvature, a mode `gap` nats lower holds about e^-gap of the best one's mass, so
/// a chain started there contributes nothing to the posterior but keeps R-hat high; the chains
/// moved to the best mode still differ through their random streams. Returns the index of each
/// replaced optimum with its gap. `f64::INFINITY` keeps every optimum.
pub fn keep_best_modes(optima: &mut [Optimum], gap: f64) -> Vec<(usize, f64)> {
    let lps: Vec<f64> = optima.iter().map(|o| o.log_density).collect();
    let Some((best, moved)) = far_below_best(&lps, gap) else {
        return vec![];
    };
    let b = optima[best].clone();
    for &(i, _) in &moved {
        let o = &mut optima[i];
        (o.point, o.log_density, o.covariance) =
            (b.point.clone(), b.log_density, b.covariance.clone());
    }
    moved
}

/// A batched log density with its gradient: `(ln p, d ln p / du)` per point.
pub type GradientFn<'a> = dyn FnMut(&[Vec<f64>]) -> Vec<(f64, Vec<f64>)> + 'a;

/// Maximise `target` (a log density on `[0, 1]^d`, called with a batch of points and returning
/// one value each) from every start; non-finite values count as `-inf`. Gradients by forward
/// differences.
pub fn maximise_batch<F: FnMut(&[Vec<f64>]) -> Vec<f64>>(
    starts: &[Vec<f64>],
    initial_log_density: &[f64],
    cfg: &BfgsConfig,
    target: F,
) -> Vec<Optimum> {
    maximise(starts, initial_log_density, cfg, target, None)
}

/// [`maximise_batch`] with the target's gradient (`gradient`, batched, e.g. through the
/// surrogate's VJP graph) instead of finite differences for BFGS; the Laplace covariance is
/// still [`laplace_batch`]'s (values). `Optimum::evaluations` counts gradient calls as one
/// evaluation each.
pub fn maximise_batch_with_gradient<F: FnMut(&[Vec<f64>]) -> Vec<f64>>(
    starts: &[Vec<f64>],
    initial_log_density: &[f64],
    cfg: &BfgsConfig,
    target: F,
    gradient: &mut GradientFn<'_>,
) -> Vec<Optimum> {
    maximise(starts, initial_log_density, cfg, target, Some(gradient))
}

fn maximise<F: FnMut(&[Vec<f64>]) -> Vec<f64>>(
    starts: &[Vec<f64>],
    initial_log_density: &[f64],
    cfg: &BfgsConfig,
    mut target: F,
    mut gradient: Option<&mut GradientFn<'_>>,
) -> Vec<Optimum> {
    let mut eval = |zs: &[Vec<f64>]| -> Vec<f64> {
        if zs.is_empty() {
            return Vec::new();
        }
        target(zs)
            .into_iter()
            .map(|lp| if lp.is_finite() { -lp } else { f64::INFINITY })
            .collect()
    };
    let mut searches: Vec<Search> = starts
        .iter()
        .zip(initial_log_density)
        .map(|(u, &lp)| Search::start(u, lp))
        .collect();

    bfgs_iterations(&mut searches, cfg, &mut eval, gradient.as_deref_mut());

    let mut out = optima(&searches, cfg, &mut eval, gradient);
    if cfg.hessian {
        newton_step(&searches, &mut out, &mut eval);
    }
    out
}

/// BFGS on every live search at once (Nocedal & Wright 2006, Algorithm 6.1): gradients at
/// the starts, then up to `cfg.max_iterations` rounds of directions, one batched line search,
/// steps, new gradients and inverse-Hessian updates. `eval` gives negative log densities.
fn bfgs_iterations<F: FnMut(&[Vec<f64>]) -> Vec<f64>>(
    searches: &mut [Search],
    cfg: &BfgsConfig,
    eval: &mut F,
    mut gradient: Option<&mut GradientFn<'_>>,
) {
    let d = searches.first().map_or(0, |s| s.z.len());
    let live: Vec<usize> = (0..searches.len()).filter(|&i| !searches[i].done).collect();
    gradients_of(searches, &live, cfg, eval, gradient.as_deref_mut());
    for _ in 0..cfg.max_iterations {
        let active: Vec<usize> = (0..searches.len()).filter(|&i| !searches[i].done).collect();
        if active.is_empty() {
            break;
        }
        // Search directions p = -H g, capped in max norm, with their slopes g^T p.
        let mut dirs: Vec<(Vec<f64>, f64)> = vec![(Vec::new(), 0.0); searches.len()];
        for &i in &active {
            dirs[i] = searches[i].direction(cfg);
        }
        let mut accepted = line_search(searches, &active, &dirs, eval);
        let mut moved = Vec::new();
        for &i in &active {
            if let Some(step) = searches[i].take_step(accepted[i].take(), cfg) {
                moved.push((i, step, searches[i].g.clone()));
            }
        }
        // New gradients (also for starts that just finished: their curvature update).
        let idx: Vec<usize> = moved.iter().map(|(i, _, _)| *i).collect();
        gradients_of(searches, &idx, cfg, eval, gradient.as_deref_mut());
        for (i, step, g_old) in moved {
            let s = &mut searches[i];
            let y: Vec<f64> = (0..d).map(|r| s.g[r] - g_old[r]).collect();
            bfgs_update(&mut s.h, &step, &y, &mut s.updated, d);
        }
    }
}

/// The searches' optima, each with the Laplace covariance at it (see [`laplace_batch`]), or
/// the BFGS estimate where it has none (a non-finite difference) or `cfg.hessian` is off.
fn optima<F: FnMut(&[Vec<f64>]) -> Vec<f64>>(
    searches: &[Search],
    cfg: &BfgsConfig,
    eval: &mut F,
    gradient: Option<&mut GradientFn<'_>>,
) -> Vec<Optimum> {
    let d = searches.first().map_or(0, |s| s.z.len());
    let live: Vec<usize> = (0..searches.len())
        .filter(|&i| cfg.hessian && searches[i].f.is_finite())
        .collect();
    let points: Vec<Vec<f64>> = live.iter().map(|&i| searches[i].z.clone()).collect();
    let lps: Vec<f64> = live.iter().map(|&i| -searches[i].f).collect();
    let pilot: Vec<Vec<f64>> = live
        .iter()
        .map(|&i| {
            let s = &searches[i];
            (0..d).map(|k| s.h[k * d + k].max(0.0).sqrt()).collect()
        })
        .collect();
    let laplace = laplace_impl(
        &points,
        &lps,
        &pilot,
        |zs| eval(zs).into_iter().map(|f| -f).collect(),
        gradient,
    );
    let mut laplace_of: Vec<Option<Laplace>> = vec![None; searches.len()];
    for (i, l) in live.into_iter().zip(laplace) {
        laplace_of[i] = Some(l);
    }
    searches
        .iter()
        .zip(laplace_of)
        .map(|(s, lap)| {
            let mut covariance = s.h.clone();
            let mut evaluations = s.evaluations;
            if let Some(l) = lap {
                evaluations += l.evaluations;
                if let Some(c) = l.covariance {
                    covariance = c;
                }
            }
            Optimum {
                point: s.z.clone(),
                log_density: -s.f,
                covariance,
                iterations: s.iterations,
                evaluations,
            }
        })
        .collect()
}

/// A Laplace approximation's covariance at one point ([`laplace_batch`]).
#[derive(Debug, Clone, PartialEq)]
pub struct Laplace {
    /// Inverse of the negative log density's (repaired) Hessian, row-major `d x d`; `None`
    /// when a difference was not finite or the eigendecomposition failed.
    pub covariance: Option<Vec<f64>>,
    /// Eigen-directions left at [`LAPLACE_MIN_PRECISION`]: flat even along their line probe.
    pub floored: usize,
    /// Target evaluations used.
    pub evaluations: usize,
}

/// Log-density drop per finite-difference step along each coordinate: large enough that the
/// second differences stand far above the surrogate's float32 rounding (about 1e-3 nats on the
/// paper-size problem), small enough to stay in the quadratic part of the posterior.
pub const LAPLACE_STEP_DROP: f64 = 0.5;

/// Laplace covariances at `points` (modes of the log density `target` on `[0, 1]^d`, with
/// log densities `log_density`), from finite-difference Hessians whose steps are set by the
/// posterior's own curvature:
///
/// 1. a pilot central second difference along each coordinate with step `pilot_sd[k] / 2`
///    (clamped to `[1e-4, 0.05]`; e.g. the optimiser's inverse-Hessian sds) gives the
///    curvature `c_k`;
/// 2. the step is then `h_k = sqrt(2 LAPLACE_STEP_DROP / c_k)` (clamped likewise): a drop of
///    about half a nat, so each difference is measured at the posterior's scale;
/// 3. the Hessian from second-order central differences: `H_kk = -(f(+k) + f(-k) - 2 f_0) /
///    h_k^2`, `H_ij` the mean of the forward and backward mixed differences
///    `(f(+i+j) - f(+i) - f(+j) + f_0) / (h_i h_j)` and its mirror (Nocedal & Wright 2006,
///    Sec. 8.1); a coordinate within `h_k` of a bound uses the one-sided forms, stepping away
///    from it;
/// 4. each eigen-direction `v` of `H` with an eigenvalue below [`LAPLACE_MIN_PRECISION`] (flat
///    or curving upwards at the difference steps) is probed along its line, `f(x +- t v)` at
///    `t` in `PROBE_STEPS`; the first `t` whose mean drop reaches `LAPLACE_STEP_DROP` gives
///    the eigenvalue `2 drop / t^2`, never below the floor (an eigenvalue repair of an
///    indefinite Hessian, cf. Nocedal & Wright 2006, Sec. 3.4, with the curvature measured
///    instead of assumed). A ridge on the diagonal was tried first: the 10 % it took to make
///    the paper-size Hessians positive definite made their flat directions as stiff as the
///    rest (an optimum 0.2 nats away counted as 56 nats); a plain floor made them as wide as
///    the prior (draws at 1.5 x its scale fell 555 nats, not 43).
///
/// Why: the earlier one-pass Hessian (forward differences at half the BFGS sds) was not
/// positive definite at the paper-size optima, so the chains' proposals fell back to the BFGS
/// inverse-Hessian estimate, which after 60 iterations in 38 dimensions is still its initial
/// scaled identity in most directions: independence proposals were then accepted 0 times in
/// 4,000. One batched call per pass; `2 d + 2 d + d (d - 1)` evaluations per point, plus 10
/// per probed direction.
pub fn laplace_batch<F: FnMut(&[Vec<f64>]) -> Vec<f64>>(
    points: &[Vec<f64>],
    log_density: &[f64],
    pilot_sd: &[Vec<f64>],
    target: F,
) -> Vec<Laplace> {
    laplace_impl(points, log_density, pilot_sd, target, None)
}

/// [`laplace_batch`] with the target's gradient: step 3 becomes central differences of the
/// gradient at the same steps, `H_:k = -(g(x + h_k e_k) - g(x - h_k e_k)) / (2 h_k)`
/// (forward `-(g(x + h_k e_k) - g(x)) / h_k` within `h_k` of a bound), symmetrised: `2 d + 1`
/// gradient calls instead of `2 d + d (d - 1)` evaluations (at d = 38 and about 3.3
/// evaluations per gradient through the surrogate's VJP graph, ~250 instead of 1,482).
/// `Laplace::evaluations` counts a gradient call as one.
pub fn laplace_batch_with_gradient<F: FnMut(&[Vec<f64>]) -> Vec<f64>>(
    points: &[Vec<f64>],
    log_density: &[f64],
    pilot_sd: &[Vec<f64>],
    target: F,
    gradient: &mut GradientFn<'_>,
) -> Vec<Laplace> {
    laplace_impl(points, log_density, pilot_sd, target, Some(gradient))
}

fn laplace_impl<F: FnMut(&[Vec<f64>]) -> Vec<f64>>(
    points: &[Vec<f64>],
    log_density: &[f64],
    pilot_sd: &[Vec<f64>],
    mut target: F,
    gradient: Option<&mut GradientFn<'_>>,
) -> Vec<Laplace> {
    // Pass 1: pilot curvatures along each coordinate set the steps.
    let steps = curvature_steps(points, log_density, pilot_sd, &mut target);
    // Pass 2: the Hessian at those steps, from gradients when the target has them.
    let hessians: Vec<(Option<Vec<f64>>, usize)> = match gradient {
        Some(grad) => hessians_from_gradients(points, &steps, grad),
        None => hessians_from_values(points, log_density, &steps, &mut target),
    };
    // Pass 3: every eigen-direction the differences found flat or curving upwards
    // (eigenvalue below the floor) is probed along its line at widening steps.
    let mut eig: Vec<Option<(Vec<f64>, Vec<f64>)>> = hessians
        .iter()
        .zip(points)
        .map(|((h, _), x)| h.as_ref().and_then(|h| symmetric_eigen(h, x.len())))
        .collect();
    let (extra, floored) = probe_flat_directions(points, log_density, &mut eig, &mut target);
    hessians
        .into_iter()
        .zip(eig)
        .enumerate()
        .map(|(p, ((_, evaluations), e))| Laplace {
            covariance: e.map(|(u, lam)| inverse_from_eigen(&u, &lam)),
            floored: floored[p],
            evaluations: evaluations + extra[p],
        })
        .collect()
}

/// A finite-difference step clamped to `[1e-4, 0.05]` (0.01 when not finite).
fn clamp_step(h: f64) -> f64 {
    if h.is_finite() {
        h.clamp(1e-4, 0.05)
    } else {
        0.01
    }
}

/// Signed steps: `+h` where `x + h` and `x - h` both fit in the box (central), else the
/// one-sided direction that fits.
fn signed_steps(x: &[f64], h: &[f64]) -> (Vec<f64>, Vec<bool>) {
    let central: Vec<bool> = x
        .iter()
        .zip(h)
        .map(|(x, h)| x - h >= 0.0 && x + h <= 1.0)
        .collect();
    let a = x
        .iter()
        .zip(h)
        .zip(&central)
        .map(|((x, h), c)| if *c || x + 2.0 * h <= 1.0 { *h } else { -*h })
        .collect();
    (a, central)
}

/// `x` moved by `(coordinate, step)` pairs, clamped into the box.
fn shifted(x: &[f64], moves: &[(usize, f64)]) -> Vec<f64> {
    let mut z = x.to_vec();
    for &(k, a) in moves {
        z[k] = (z[k] + a).clamp(0.0, 1.0);
    }
    z
}

/// Two points per coordinate: `x + a_k`, and `x - a_k` (central) or `x + 2 a_k` (one-sided).
fn diagonal_points(x: &[f64], a: &[f64], central: &[bool], pts: &mut Vec<Vec<f64>>) {
    for k in 0..x.len() {
        pts.push(shifted(x, &[(k, a[k])]));
        let other = if central[k] { -a[k] } else { 2.0 * a[k] };
        pts.push(shifted(x, &[(k, other)]));
    }
}

/// The second difference of [`diagonal_points`]' two values about `f0` (central:
/// `f(+) + f(-) - 2 f0`; one-sided: `f(2a) - 2 f(a) + f0`).
fn second_difference(plus: f64, other: f64, f0: f64, central: bool) -> f64 {
    if central {
        plus + other - 2.0 * f0
    } else {
        other - 2.0 * plus + f0
    }
}

/// [`laplace_batch`]'s steps 1-2: a pilot second difference along each coordinate at half
/// the pilot sd gives the curvature `c_k`, and the step `sqrt(2 LAPLACE_STEP_DROP / c_k)`
/// (the pilot step where the curvature is not positive). One batched call.
fn curvature_steps(
    points: &[Vec<f64>],
    log_density: &[f64],
    pilot_sd: &[Vec<f64>],
    target: &mut impl FnMut(&[Vec<f64>]) -> Vec<f64>,
) -> Vec<Vec<f64>> {
    let mut pts = Vec::new();
    let mut pilot = Vec::new();
    for (x, sd) in points.iter().zip(pilot_sd) {
        let h: Vec<f64> = sd.iter().map(|s| clamp_step(0.5 * s)).collect();
        let (a, central) = signed_steps(x, &h);
        diagonal_points(x, &a, &central, &mut pts);
        pilot.push((a, central));
    }
    let f1 = if pts.is_empty() {
        Vec::new()
    } else {
        target(&pts)
    };
    let mut at = 0;
    let mut steps = Vec::new();
    for ((x, &f0), (a, central)) in points.iter().zip(log_density).zip(&pilot) {
        let h: Vec<f64> = (0..x.len())
            .map(|k| {
                let (p, q) = (f1[at + 2 * k], f1[at + 2 * k + 1]);
                let c = -second_difference(p, q, f0, central[k]) / (a[k] * a[k]);
                if c > 0.0 {
                    clamp_step((2.0 * LAPLACE_STEP_DROP / c).sqrt())
                } else {
                    a[k].abs()
                }
            })
            .collect();
        at += 2 * x.len();
        steps.push(h);
    }
    steps
}

/// [`laplace_batch`]'s step 3 from values: the negative log density's Hessian at each point
/// from second-order differences at `steps` (central, or one-sided near a bound; the mixed
/// ones the mean of the forward and backward forms where both fit; Nocedal & Wright 2006,
/// Sec. 8.1), with the evaluations it took (the pilot pass's included). `None` where a value
/// was not finite. One batched call.
fn hessians_from_values(
    points: &[Vec<f64>],
    log_density: &[f64],
    steps: &[Vec<f64>],
    target: &mut impl FnMut(&[Vec<f64>]) -> Vec<f64>,
) -> Vec<(Option<Vec<f64>>, usize)> {
    let mut pts = Vec::new();
    let mut layout = Vec::new();
    for (x, h) in points.iter().zip(steps) {
        let d = x.len();
        let (a, central) = signed_steps(x, h);
        let first = pts.len();
        diagonal_points(x, &a, &central, &mut pts);
        for i in 0..d {
            for j in 0..i {
                pts.push(shifted(x, &[(i, a[i]), (j, a[j])]));
                if central[i] && central[j] {
                    pts.push(shifted(x, &[(i, -a[i]), (j, -a[j])]));
                }
            }
        }
        layout.push((first, a, central));
    }
    let f2 = if pts.is_empty() {
        Vec::new()
    } else {
        target(&pts)
    };
    points
        .iter()
        .zip(log_density)
        .zip(layout)
        .map(|((x, &f0), (first, a, central))| {
            let d = x.len();
            let pairs: usize = (0..d)
                .map(|i| {
                    (0..i)
                        .map(|j| 1 + usize::from(central[i] && central[j]))
                        .sum::<usize>()
                })
                .sum();
            let n_pass2 = 2 * d + pairs;
            let f = &f2[first..first + n_pass2];
            let plus = |k: usize| f[2 * k];
            let other = |k: usize| f[2 * k + 1];
            // Negative log density's Hessian.
            let mut hess = vec![0.0; d * d];
            for k in 0..d {
                hess[k * d + k] =
                    -second_difference(plus(k), other(k), f0, central[k]) / (a[k] * a[k]);
            }
            let mut m = 2 * d;
            for i in 0..d {
                for j in 0..i {
                    let fwd = (f[m] - plus(i) - plus(j) + f0) / (a[i] * a[j]);
                    m += 1;
                    let v = if central[i] && central[j] {
                        let bwd = (f[m] - other(i) - other(j) + f0) / (a[i] * a[j]);
                        m += 1;
                        0.5 * (fwd + bwd)
                    } else {
                        fwd
                    };
                    hess[i * d + j] = -v;
                    hess[j * d + i] = -v;
                }
            }
            let evaluations = 2 * d + n_pass2;
            (
                hess.iter().all(|v| v.is_finite()).then_some(hess),
                evaluations,
            )
        })
        .collect()
}

/// [`laplace_batch`]'s step 4: each eigen-direction of `eig` (eigenvectors column-wise,
/// eigenvalues) with an eigenvalue below [`LAPLACE_MIN_PRECISION`] is probed along its line at
/// [`PROBE_STEPS`]; the first step whose symmetric drop reaches [`LAPLACE_STEP_DROP`] sets its
/// eigenvalue to `2 drop / t^2` (if none does, the largest step's; never below the floor). One
/// batched call. Returns the evaluations and the directions left at the floor, per point.
fn probe_flat_directions(
    points: &[Vec<f64>],
    log_density: &[f64],
    eig: &mut [Option<(Vec<f64>, Vec<f64>)>],
    target: &mut impl FnMut(&[Vec<f64>]) -> Vec<f64>,
) -> (Vec<usize>, Vec<usize>) {
    let mut pts = Vec::new();
    let mut probes = Vec::new(); // (point, eigen index, first probe row)
    for (p, (x, e)) in points.iter().zip(eig.iter()).enumerate() {
        let Some((u, lam)) = e else { continue };
        let d = x.len();
        for k in (0..d).filter(|&k| lam[k] < LAPLACE_MIN_PRECISION) {
            probes.push((p, k, pts.len()));
            for t in PROBE_STEPS {
                for sign in [1.0, -1.0] {
                    pts.push(
                        (0..d)
                            .map(|i| (x[i] + sign * t * u[i * d + k]).clamp(0.0, 1.0))
                            .collect(),
                    );
                }
            }
        }
    }
    let f3 = if pts.is_empty() {
        Vec::new()
    } else {
        target(&pts)
    };
    let mut extra = vec![0usize; points.len()];
    let mut floored = vec![0usize; points.len()];
    for (p, k, first) in probes {
        let f0 = log_density[p];
        extra[p] += 2 * PROBE_STEPS.len();
        let mut curvature = LAPLACE_MIN_PRECISION;
        for (n, t) in PROBE_STEPS.iter().enumerate() {
            let (a, b) = (f3[first + 2 * n], f3[first + 2 * n + 1]);
            let drop = if a.is_finite() && b.is_finite() {
                f0 - 0.5 * (a + b)
            } else {
                f64::INFINITY
            };
            curvature = (2.0 * drop / (t * t)).max(LAPLACE_MIN_PRECISION);
            if drop >= LAPLACE_STEP_DROP {
                break;
            }
        }
        if curvature <= LAPLACE_MIN_PRECISION {
            floored[p] += 1;
        }
        if let Some((_, lam)) = eig[p].as_mut() {
            // A probe into -inf (a constraint) makes the curvature infinite: keep it finite.
            lam[k] = curvature.min(f64::MAX);
        }
    }
    (extra, floored)
}

/// The covariance `U diag(1 / lambda) U^T` from the Hessian's eigenvectors `u` (column-wise,
/// row-major `d x d`) and eigenvalues `lam`.
fn inverse_from_eigen(u: &[f64], lam: &[f64]) -> Vec<f64> {
    let d = lam.len();
    let mut inv = vec![0.0; d * d];
    for i in 0..d {
        for j in 0..=i {
            let v: f64 = (0..d).map(|k| u[i * d + k] * u[j * d + k] / lam[k]).sum();
            inv[i * d + j] = v;
            inv[j * d + i] = v;
        }
    }
    inv
}

/// Hessians of the negative log density at `points` from central differences of the gradient
/// at steps `steps` (forward differences from the gradient at the point within a step of a
/// bound), symmetrised; one batched gradient call. `None` where a gradient is not finite.
fn hessians_from_gradients(
    points: &[Vec<f64>],
    steps: &[Vec<f64>],
    grad: &mut GradientFn<'_>,
) -> Vec<(Option<Vec<f64>>, usize)> {
    let mut pts = Vec::new();
    let mut layout = Vec::new();
    for (x, h) in points.iter().zip(steps) {
        let first = pts.len();
        pts.push(x.clone());
        let mut central = Vec::with_capacity(x.len());
        for (k, &hk) in h.iter().enumerate() {
            let c = x[k] - hk >= 0.0 && x[k] + hk <= 1.0;
            let a = if c || x[k] + hk <= 1.0 { hk } else { -hk };
            let mut z = x.clone();
            z[k] += a;
            pts.push(z);
            if c {
                let mut z = x.clone();
                z[k] -= a;
                pts.push(z);
            }
            central.push((c, a));
        }
        layout.push((first, central));
    }
    let gs = if pts.is_empty() {
        Vec::new()
    } else {
        grad(&pts)
    };
    layout
        .into_iter()
        .map(|(first, central)| {
            let d = central.len();
            let n = 1 + central.iter().filter(|c| c.0).count() + d;
            let g = &gs[first..first + n];
            let ok = g
                .iter()
                .all(|(lp, v)| lp.is_finite() && v.iter().all(|x| x.is_finite()));
            // (plus pass 1's 2 d value evaluations, counted as the value-based path does)
            let n = n + 2 * d;
            if !ok {
                return (None, n);
            }
            // Column k: -(d g / d x_k), g = d ln p / dx.
            let mut hess = vec![0.0; d * d];
            let mut row = 1;
            for (k, &(c, a)) in central.iter().enumerate() {
                let col: Vec<f64> = if c {
                    let (p, m) = (&g[row].1, &g[row + 1].1);
                    row += 2;
                    (0..d).map(|i| -(p[i] - m[i]) / (2.0 * a)).collect()
                } else {
                    let p = &g[row].1;
                    row += 1;
                    (0..d).map(|i| -(p[i] - g[0].1[i]) / a).collect()
                };
                for i in 0..d {
                    hess[i * d + k] = col[i];
                }
            }
            for i in 0..d {
                for j in 0..i {
                    let v = 0.5 * (hess[i * d + j] + hess[j * d + i]);
                    hess[i * d + j] = v;
                    hess[j * d + i] = v;
                }
            }
            (Some(hess), n)
        })
        .collect()
}

/// Smallest eigenvalue [`laplace_batch`] keeps in a Hessian of the unit-space negative log
/// density: 25, the precision of a standard deviation of 0.2, about that of a triangular prior
/// with its mode mid-range (1 / sqrt(24) = 0.20) in the unit space.
pub const LAPLACE_MIN_PRECISION: f64 = 25.0;

/// Steps (unit space) at which [`laplace_batch`] probes a Hessian eigen-direction that the
/// finite differences found flat: the posterior's widths on the paper-size problem are
/// 0.002-0.05 of the prior range.
const PROBE_STEPS: [f64; 5] = [0.003, 0.01, 0.03, 0.1, 0.3];

/// Eigenvectors (columns of row-major `U`) and eigenvalues of the symmetric `a` (row-major
/// `d x d`), ascending; `None` if the decomposition fails.
fn symmetric_eigen(a: &[f64], d: usize) -> Option<(Vec<f64>, Vec<f64>)> {
    let m = faer::Mat::<f64>::from_fn(d, d, |i, j| 0.5 * (a[i * d + j] + a[j * d + i]));
    let evd = m.self_adjoint_eigen(faer::Side::Lower).ok()?;
    let (u, s) = (evd.U(), evd.S().column_vector());
    let vecs = (0..d * d).map(|k| u[(k / d, k % d)]).collect();
    Some((vecs, (0..d).map(|k| s[k]).collect()))
}

/// Gradients of `f = -ln p` at the searches `idx`, one batched call: the target's own
/// (`gradient`) or forward differences.
fn gradients_of<F: FnMut(&[Vec<f64>]) -> Vec<f64>>(
    searches: &mut [Search],
    idx: &[usize],
    cfg: &BfgsConfig,
    eval: &mut F,
    gradient: Option<&mut GradientFn<'_>>,
) {
    if let Some(grad) = gradient {
        if idx.is_empty() {
            return;
        }
        let points: Vec<Vec<f64>> = idx.iter().map(|&i| searches[i].z.clone()).collect();
        let values = grad(&points);
        assert_eq!(values.len(), points.len(), "one gradient per point");
        for (&i, (lp, g)) in idx.iter().zip(values) {
            let s = &mut searches[i];
            s.evaluations += 1;
            let ok = lp.is_finite() && g.iter().all(|v| v.is_finite());
            for (o, v) in s.g.iter_mut().zip(&g) {
                *o = if ok { -v } else { 0.0 };
            }
        }
        return;
    }
    let mut points = Vec::new();
    for &i in idx {
        let s = &searches[i];
        for k in 0..s.z.len() {
            let mut z = s.z.clone();
            z[k] += fd_step(&s.z, k, cfg);
            points.push(z);
        }
    }
    let fs = eval(&points);
    let mut it = fs.into_iter();
    for &i in idx {
        let s = &mut searches[i];
        let d = s.z.len();
        s.evaluations += d;
        for k in 0..d {
            let f = it.next().expect("one value per point");
            // A step into -inf (a constraint) gives no slope information along k.
            s.g[k] = if f.is_finite() {
                (f - s.f) / fd_step(&s.z, k, cfg)
            } else {
                0.0
            };
        }
    }
}

/// Forward step along `k`, backward where it would leave the box.
fn fd_step(z: &[f64], k: usize, cfg: &BfgsConfig) -> f64 {
    if z[k] + cfg.fd_step > 1.0 {
        -cfg.fd_step
    } else {
        cfg.fd_step
    }
}

/// BFGS inverse-Hessian update (Nocedal & Wright Eq. 6.17), with the first update preceded by
/// the scaling `H_0 = (s^T y / y^T y) I` (Eq. 6.20).
fn bfgs_update(h: &mut [f64], s: &[f64], y: &[f64], updated: &mut bool, d: usize) {
    let sy: f64 = s.iter().zip(y).map(|(a, b)| a * b).sum();
    if sy.is_nan() || sy <= 1e-12 {
        return;
    }
    if !*updated {
        let yy: f64 = y.iter().map(|v| v * v).sum();
        let g = sy / yy;
        h.iter_mut().for_each(|v| *v = 0.0);
        for i in 0..d {
            h[i * d + i] = g;
        }
        *updated = true;
    }
    let rho = 1.0 / sy;
    let hy: Vec<f64> = (0..d)
        .map(|r| (0..d).map(|c| h[r * d + c] * y[c]).sum())
        .collect();
    let yhy: f64 = y.iter().zip(&hy).map(|(a, b)| a * b).sum();
    // H+ = H - rho (H y s^T + s y^T H) + (rho^2 y^T H y + rho) s s^T.
    for r in 0..d {
        for c in 0..d {
            h[r * d + c] +=
                -rho * (hy[r] * s[c] + s[r] * hy[c]) + (rho * rho * yhy + rho) * s[r] * s[c];
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn optima_far_below_the_best_move_to_the_best_mode() {
        let at = |x: f64, lp: f64| Optimum {
            point: vec![x],
            log_density: lp,
            covariance: vec![x * 0.01],
            iterations: 1,
            evaluations: 1,
        };
        let mut optima = vec![
            at(0.2, -130.0),
            at(0.5, -100.0),
            at(0.7, -110.0),
            at(0.9, f64::NEG_INFINITY),
        ];
        let moved = keep_best_modes(&mut optima, 20.0);
        assert_eq!(moved[0], (0, 30.0));
        assert_eq!(moved[1].0, 3);
        assert_eq!(moved.len(), 2);
        assert_eq!(
            (
                optima[0].point[0],
                optima[0].log_density,
                optima[0].covariance[0]
            ),
            (0.5, -100.0, 0.005)
        );
        assert_eq!(optima[2].point, vec![0.7]);
        assert_eq!(optima[3].point, vec![0.5]);
        let mut same = vec![at(0.2, -130.0), at(0.5, -100.0)];
        assert!(keep_best_modes(&mut same, f64::INFINITY).is_empty());
        assert_eq!(same[0].point, vec![0.2]);
    }

    /// Central differences are exact for a quadratic: the Laplace covariance of a correlated
    /// Gaussian is its covariance, also with a coordinate too close to a bound for central
    /// steps (one-sided there).
    #[test]
    fn laplace_of_a_correlated_gaussian_is_its_covariance() {
        let sd = [0.02, 0.05, 0.01];
        let rho = 0.8;
        for mean in [[0.3, 0.6, 0.45], [0.3, 0.6, 0.999]] {
            let lp = |u: &[f64]| {
                let a = (u[0] - mean[0]) / sd[0];
                let b = (u[1] - mean[1]) / sd[1];
                let c = (u[2] - mean[2]) / sd[2];
                -0.5 * ((a * a - 2.0 * rho * a * b + b * b) / (1.0 - rho * rho) + c * c)
            };
            let by_values = laplace_batch(&[mean.to_vec()], &[0.0], &[vec![0.1; 3]], |us| {
                us.iter().map(|u| lp(u)).collect()
            });
            // The same from central differences of the exact gradient.
            let mut grad = |us: &[Vec<f64>]| -> Vec<(f64, Vec<f64>)> {
                us.iter()
                    .map(|u| {
                        let a = (u[0] - mean[0]) / sd[0];
                        let b = (u[1] - mean[1]) / sd[1];
                        let c = (u[2] - mean[2]) / sd[2];
                        let k = 1.0 - rho * rho;
                        let g = vec![
                            -(a - rho * b) / (k * sd[0]),
                            -(b - rho * a) / (k * sd[1]),
                            -c / sd[2],
                        ];
                        (lp(u), g)
                    })
                    .collect()
            };
            let by_gradients = laplace_batch_with_gradient(
                &[mean.to_vec()],
                &[0.0],
                &[vec![0.1; 3]],
                |us| us.iter().map(|u| lp(u)).collect(),
                &mut grad,
            );
            assert!(by_gradients[0].evaluations < by_values[0].evaluations);
            for out in [by_values, by_gradients] {
                let c = out[0].covariance.as_ref().expect("positive definite");
                let want = [
                    [sd[0] * sd[0], rho * sd[0] * sd[1], 0.0],
                    [rho * sd[0] * sd[1], sd[1] * sd[1], 0.0],
                    [0.0, 0.0, sd[2] * sd[2]],
                ];
                for i in 0..3 {
                    for j in 0..3 {
                        let scale = sd[i] * sd[j];
                        assert!(
                            (c[i * 3 + j] - want[i][j]).abs() < 1e-6 * scale,
                            "{mean:?} ({i}, {j}): {} vs {}",
                            c[i * 3 + j],
                            want[i][j]
                        );
                    }
                }
                assert_eq!(out[0].floored, 0);
            }
        }
    }

    /// A direction flat at the difference steps but curved further out (quartic) is measured
    /// along its line instead of given an infinite variance; a direction that is flat
    /// everywhere is left at the floor.
    #[test]
    fn flat_directions_are_probed_along_their_line() {
        // x: Gaussian sd 0.01; y: -1e3 (y - 0.5)^4, nearly flat at the difference steps
        // (curvature 5 at 0.05); z: no information at all.
        let lp = |u: &[f64]| {
            let x = (u[0] - 0.5) / 0.01;
            let y = u[1] - 0.5;
            -0.5 * x * x - 1e3 * y.powi(4)
        };
        let out = laplace_batch(&[vec![0.5; 3]], &[0.0], &[vec![0.01; 3]], |us| {
            us.iter().map(|u| lp(u)).collect()
        });
        let l = &out[0];
        let c = l.covariance.as_ref().expect("a covariance");
        assert!((c[0] / 1e-4 - 1.0).abs() < 1e-3, "var x {}", c[0]);
        // The drop 1e3 t^4 first reaches 0.5 nat at t = 0.3 (8.1 nats): eigenvalue 2 drop / t^2
        // = 180.
        assert!((c[4] - 1.0 / 180.0).abs() < 1e-9, "var y {}", c[4]);
        assert!(
            (c[8] - 1.0 / LAPLACE_MIN_PRECISION).abs() < 1e-12,
            "var z {}",
            c[8]
        );
        assert_eq!(l.floored, 1);
        assert_eq!(l.evaluations, 4 * 3 + 3 * 2 + 2 * 10);
    }

    /// A correlated Gaussian in the cube: the optimum is its mean and the inverse-Hessian
    /// estimate approaches its covariance.
    #[test]
    fn the_targets_gradient_finds_the_mode_with_fewer_evaluations() {
        // 10-D correlated Gaussian: BFGS with the exact gradient reaches the mode like the
        // finite-difference version, with far fewer target calls.
        let d = 10;
        let mean: Vec<f64> = (0..d).map(|i| 0.3 + 0.04 * i as f64).collect();
        let sd: Vec<f64> = (0..d).map(|i| 0.01 + 0.004 * i as f64).collect();
        // Precision of sds `sd` and correlation 0.5 between neighbours (tridiagonal).
        let prec = |i: usize, j: usize| -> f64 {
            if i == j {
                1.0 / (sd[i] * sd[i])
            } else if i.abs_diff(j) == 1 {
                -0.4 / (sd[i] * sd[j])
            } else {
                0.0
            }
        };
        let lp = |u: &[f64]| -> f64 {
            let r: Vec<f64> = (0..d).map(|i| u[i] - mean[i]).collect();
            -0.5 * (0..d)
                .map(|i| (0..d).map(|j| r[i] * prec(i, j) * r[j]).sum::<f64>())
                .sum::<f64>()
        };
        let starts = vec![vec![0.5; d], vec![0.2; d]];
        let lps: Vec<f64> = starts.iter().map(|u| lp(u)).collect();
        let cfg = BfgsConfig {
            hessian: false,
            ..BfgsConfig::default()
        };
        let fd = maximise_batch(&starts, &lps, &cfg, |us: &[Vec<f64>]| {
            us.iter().map(|u| lp(u)).collect()
        });
        let mut grad = |us: &[Vec<f64>]| -> Vec<(f64, Vec<f64>)> {
            us.iter()
                .map(|u| {
                    let g = (0..d)
                        .map(|i| -(0..d).map(|j| prec(i, j) * (u[j] - mean[j])).sum::<f64>())
                        .collect();
                    (lp(u), g)
                })
                .collect()
        };
        let an = maximise_batch_with_gradient(
            &starts,
            &lps,
            &cfg,
            |us: &[Vec<f64>]| us.iter().map(|u| lp(u)).collect(),
            &mut grad,
        );
        for (a, f) in an.iter().zip(&fd) {
            // (BFGS stops after two gains under `tolerance` = 0.1 nats)
            assert!(a.log_density > -0.3, "gradient: {}", a.log_density);
            assert!(f.log_density > -0.3, "differences: {}", f.log_density);
            assert!(
                3 * a.evaluations < f.evaluations,
                "{} vs {} evaluations",
                a.evaluations,
                f.evaluations
            );
        }
    }

    #[test]
    fn finds_the_mode_of_a_correlated_gaussian() {
        let mean = [0.3, 0.6, 0.45];
        let sd = [0.02, 0.05, 0.01];
        let rho = 0.8;
        let lp = |u: &[f64]| {
            let a = (u[0] - mean[0]) / sd[0];
            let b = (u[1] - mean[1]) / sd[1];
            let c = (u[2] - mean[2]) / sd[2];
            -0.5 * ((a * a - 2.0 * rho * a * b + b * b) / (1.0 - rho * rho) + c * c)
        };
        let starts = vec![vec![0.9, 0.1, 0.2], vec![0.1, 0.9, 0.8]];
        let lp0: Vec<f64> = starts.iter().map(|s| lp(s)).collect();
        let cfg = BfgsConfig {
            max_iterations: 200,
            tolerance: 1e-8,
            ..BfgsConfig::default()
        };
        let out = maximise_batch(&starts, &lp0, &cfg, |us| us.iter().map(|u| lp(u)).collect());
        for o in &out {
            for (k, (m, s)) in mean.iter().zip(&sd).enumerate() {
                assert!((o.point[k] - m).abs() < 0.05 * s, "{:?}", o.point);
            }
            // Variances within 25 % of the truth.
            for (k, s) in sd.iter().enumerate() {
                let v = o.covariance[k * 3 + k];
                assert!((v / (s * s) - 1.0).abs() < 0.25, "var {k}: {v}");
            }
            assert!(o.evaluations > 0 && o.iterations > 0);
        }
    }
}

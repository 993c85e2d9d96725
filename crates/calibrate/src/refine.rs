//! Surrogate refinement near the posterior (sequential design; `[refine]` in the project).
//!
//! A Latin hypercube over the priors makes the surrogate accurate on average over the prior,
//! not where the posterior is. A refinement round takes posterior draws of the current chains,
//! simulates them in EnergyPlus, adds them to the training set (as design points after the
//! hypercube's) and retrains; the next round's chains start where the previous ones ended.
//! This is the "sequential design" of computer-model calibration (e.g. Kennedy & O'Hagan's
//! successors; here with the reference's LSTM surrogate and likelihood unchanged).
//!
//! Files in the output folder: `refine.json` (the [`RefineLog`]: one entry per finished round,
//! written last, so a round is either recorded whole or redone) and `refine/round_R/` with the
//! round's preliminary `chains.json` and the `surrogate/` its chains used.

use std::path::PathBuf;

use bemcal_energyplus::HourlyOutputs;
use bemcal_stats::lhs::Design;
use bemcal_stats::mcmc::Draws;
use serde::{Deserialize, Serialize};

use crate::calibration::Calibration;
use crate::chains::Sampler;
use crate::error::{write_atomic, Error};
use crate::keys::first_refinement_key;
use crate::metrics::OutputMetrics;
use crate::output::read_record;

/// File of the refinement log in the output folder.
pub const REFINE_FILE: &str = "refine.json";

/// Every finished refinement round, in order.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct RefineLog {
    /// The finished rounds, first round first.
    pub rounds: Vec<RefineRound>,
}

/// One finished round.
#[derive(Debug, Clone, Serialize, Deserialize, schemars::JsonSchema)]
pub struct RefineRound {
    /// 1-based.
    pub round: u32,
    /// Posterior draws simulated and added to the training set.
    pub points: Vec<RefinePoint>,
    /// Posterior draws whose EnergyPlus run failed (left out, with EnergyPlus's message).
    pub failed: Vec<FailedPoint>,
    /// Guideline 14 of the round's surrogate (before retraining) against EnergyPlus at the
    /// added points, all points' hours pooled: the surrogate's error where the posterior is,
    /// out of sample (the held-out RMSE measures it over the prior).
    pub surrogate_error: Vec<OutputMetrics>,
    /// What a calibration through the round's surrogate recovers from EnergyPlus's outputs at
    /// each added point (physical units, as `points`; [`Sampler::recover`]): the surrogate's
    /// error in parameter space where the posterior is, which the final intervals carry
    /// ([`bemcal_stats::surrogate_error`]). Empty in rounds recorded before it existed.
    #[serde(default)]
    pub recovered: Vec<Vec<f64>>,
    /// Where the next round's chains start (unit space), one per chain: see [`next_starts`].
    #[serde(default)]
    pub starts: Vec<Vec<f64>>,
    /// Chains restarted in the best chain's mode (see [`next_starts`]) with how many nats their
    /// best log posterior was below the best chain's.
    #[serde(default)]
    pub restarted: Vec<(usize, f64)>,
    /// The likelihood's temperature the round's chains ran at (1 in rounds recorded before it
    /// existed; [`crate::surrogate_error::chain_temperature`]).
    #[serde(
        default = "crate::posterior::untempered",
        deserialize_with = "bemcal_stats::nan::null_as_nan"
    )]
    #[schemars(with = "bemcal_stats::nan::NumberOrNull")]
    pub temperature: f64,
    /// How far the round's points were moved from the chains' mean (`refine.spread` when it
    /// ran; 1 in rounds recorded before it existed).
    #[serde(
        default = "unmoved",
        deserialize_with = "bemcal_stats::nan::null_as_nan"
    )]
    #[schemars(with = "bemcal_stats::nan::NumberOrNull")]
    pub spread: f64,
}

fn unmoved() -> f64 {
    1.0
}

/// A posterior draw added as a design point.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct RefinePoint {
    /// Key in `simulations/` (after the hypercube's points).
    pub index: usize,
    /// Calibrated parameter values (physical units, plan order).
    pub values: Vec<f64>,
}

/// A posterior draw EnergyPlus could not simulate.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct FailedPoint {
    /// Calibrated parameter values (physical units, plan order).
    pub values: Vec<f64>,
    /// EnergyPlus's message.
    pub error: String,
}

impl RefineLog {
    /// All added points, in round order.
    pub fn points(&self) -> impl Iterator<Item = &RefinePoint> {
        self.rounds.iter().flat_map(|r| r.points.iter())
    }

    /// The simulation key of the first posterior draw of the next round, after
    /// `design_points` hypercube slots: past every draw of every earlier round, those
    /// EnergyPlus could not simulate included (their keys were used too).
    pub fn next_key(&self, design_points: usize) -> usize {
        let drawn_before = (self.rounds.iter())
            .map(|r| r.points.len() + r.failed.len())
            .sum::<usize>();
        first_refinement_key(design_points, drawn_before)
    }
}

/// Up to `k` distinct draws for refinement (unit space), from chains' post-burn-in draws: the
/// highest-posterior draw first (the MAP estimate lives there), then each chain's last draw
/// (where the next round's chains start), then draws evenly spaced through the merged chains.
/// Repeated draws (rejected MH moves) count once.
pub fn pick_draws(draws: &[Draws], k: usize) -> Vec<Vec<f64>> {
    let mut picks: Vec<Vec<f64>> = vec![];
    let add = |p: &[f64], picks: &mut Vec<Vec<f64>>| {
        if picks.len() < k && !picks.iter().any(|q| q.as_slice() == p) {
            picks.push(p.to_vec());
        }
    };
    let best = draws
        .iter()
        .flat_map(|d| (0..d.len()).map(move |i| (d.log_density[i], d.point(i))))
        .max_by(|a, b| a.0.total_cmp(&b.0));
    if let Some((_, p)) = best {
        add(p, &mut picks);
    }
    for d in draws.iter().filter(|d| !d.is_empty()) {
        add(d.point(d.len() - 1), &mut picks);
    }
    let all: Vec<&[f64]> = draws
        .iter()
        .flat_map(|d| (0..d.len()).map(move |i| d.point(i)))
        .collect();
    // Evenly spaced, then the rest in order, until k distinct points or no more draws.
    let step = (all.len() / k.max(1)).max(1);
    for p in all.iter().skip(step / 2).step_by(step).chain(all.iter()) {
        if picks.len() >= k {
            break;
        }
        add(p, &mut picks);
    }
    picks
}

/// The points a refinement round simulates (unit space): [`pick_draws`] of the round's chains,
/// each but the first (the highest-posterior draw) moved `spread` times as far from the
/// chains' mean ([`crate::project::RefineSettings::spread`]). A moved point is kept inside the
/// unit box and where `allowed` (the prior: constraints, refused regions) admits it, by
/// halving its excess spread up to four times, else the draw itself is simulated.
///
/// Why: the surrogate learns its response to a weakly identified parameter over the
/// neighbourhood it is trained on. Draws of a narrow posterior teach it only the posterior's
/// own width, where a wrong slope still recovers its own points; spread points carry
/// EnergyPlus's response over a wider neighbourhood (docs/benchmarks.md, the wall insulation
/// misses of the coverage runs).
pub fn refinement_points(
    draws: &[Draws],
    k: usize,
    spread: f64,
    allowed: impl Fn(&[f64]) -> bool,
) -> Vec<Vec<f64>> {
    let picks = pick_draws(draws, k);
    if spread == 1.0 || picks.is_empty() {
        return picks;
    }
    let center = mean_point(draws);
    let mut out = vec![picks[0].clone()];
    for p in &picks[1..] {
        let mut f = spread;
        let moved = loop {
            let x: Vec<f64> = p
                .iter()
                .zip(&center)
                .map(|(v, c)| (c + f * (v - c)).clamp(1e-3, 1.0 - 1e-3))
                .collect();
            if allowed(&x) {
                break x;
            }
            if f - 1.0 < (spread - 1.0) / 15.0 {
                break p.clone();
            }
            f = 1.0 + (f - 1.0) / 2.0;
        };
        out.push(moved);
    }
    out
}

/// The mean of every draw of every chain (unit space).
fn mean_point(draws: &[Draws]) -> Vec<f64> {
    let n: usize = draws.iter().map(|d| d.len()).sum();
    let dim = draws
        .iter()
        .find(|d| !d.is_empty())
        .map_or(0, |d| d.point(0).len());
    let mut mean = vec![0.0; dim];
    for d in draws {
        for i in 0..d.len() {
            for (m, v) in mean.iter_mut().zip(d.point(i)) {
                *m += v / n as f64;
            }
        }
    }
    mean
}

/// Where the next round's chains start: each chain where it ended (`last`), except a chain
/// whose best log posterior is more than `gap` nats below the best chain's: it is stuck in a
/// mode carrying under e^-gap of the posterior mass, and restarts at one of the best chain's
/// draws (distinct draws spread over its second half). Returns the starts and the restarted
/// chains with their gaps.
pub fn next_starts(
    draws: &[Draws],
    last: &[Vec<f64>],
    gap: f64,
) -> (Vec<Vec<f64>>, Vec<(usize, f64)>) {
    let best_lp: Vec<f64> = draws
        .iter()
        .map(|d| {
            d.log_density
                .iter()
                .copied()
                .fold(f64::NEG_INFINITY, f64::max)
        })
        .collect();
    let Some((best, below)) = bemcal_stats::optim::far_below_best(&best_lp, gap) else {
        return (last.to_vec(), vec![]);
    };
    let restarted: Vec<(usize, f64)> = below.into_iter().filter(|&(c, _)| c < last.len()).collect();
    let mut starts = last.to_vec();
    let d = &draws[best];
    let half = d.len() / 2;
    for (k, &(c, _)) in restarted.iter().enumerate() {
        let i = half + (d.len() - half) * k / (restarted.len() + 1);
        if i < d.len() {
            starts[c] = d.point(i).to_vec();
        }
    }
    (starts, restarted)
}

impl Calibration {
    /// The simulation key of the first posterior draw of the next refinement round, after the
    /// rounds in `log`: after every hypercube slot and every earlier round's draws, failed ones
    /// included (a dropped design point keeps its slot, so keys never collide):
    /// [`RefineLog::next_key`].
    pub fn next_refine_key(&self, log: &RefineLog) -> usize {
        log.next_key(self.project.design.points)
    }

    /// The finished refinement rounds (`refine.json`; none when it does not exist).
    pub fn refine_log(&self) -> Result<RefineLog, Error> {
        let path = self.out.join(REFINE_FILE);
        match read_record(&path) {
            Ok(log) => Ok(log.unwrap_or_default()),
            Err(e) => Err(Error::Input {
                path,
                line: 0,
                message: format!("unreadable refinement log: {e}"),
            }),
        }
    }

    /// Folder of refinement round `round` (1-based).
    pub fn refine_dir(&self, round: u32) -> PathBuf {
        self.out.refine_round(round)
    }

    /// Checkpoint of the chains that run on the surrogate of round `round` (0 = the
    /// hypercube's): `refine/round_{round+1}/chains.json` for the preliminary rounds, the
    /// output folder's `chains.json` for the last.
    pub fn chains_path(&self, round: u32) -> PathBuf {
        if round < self.project.refine.rounds {
            self.refine_dir(round + 1).join("chains.json")
        } else {
            self.out.chains_checkpoint()
        }
    }

    /// The hypercube's design with the refinement points appended (the training set's points).
    pub fn full_design(&self, design: &Design, log: &RefineLog) -> Design {
        let mut d = design.clone();
        for p in log.points() {
            d.points.push(p.values.clone());
        }
        d
    }

    /// Every point EnergyPlus simulated for the surrogate (the settled design, then the
    /// rounds' draws in `log`) and its outputs, as saved in `simulations/`: the training set's
    /// points, and the first-order slopes of model form ([`crate::model_form`]).
    pub fn simulated_points(
        &self,
        log: &RefineLog,
    ) -> Result<(Design, Vec<bemcal_energyplus::HourlyOutputs>), Error> {
        let (outcome, design) = self.settled_design()?;
        let full = self.full_design(&design, log);
        let keys = (outcome.slots.iter().copied()).chain(log.points().map(|p| p.index));
        let outputs = keys
            .zip(&full.points)
            .map(|(i, x)| {
                crate::design::saved_outputs(
                    &self.simulations_dir(),
                    i,
                    &self.inputs.plan.values(x),
                )
                .ok_or_else(|| Error::Stage {
                    stage: "training set",
                    message: format!("point {i}: no simulation saved in simulations/"),
                })
            })
            .collect::<Result<Vec<_>, Error>>()?;
        Ok((full, outputs))
    }

    /// The surrogate folder a retraining after the rounds in `log` warm-starts from: the last
    /// round's surrogate, when `surrogate.warm_start` is on and its weights were kept (a
    /// surrogate trained before warm starts existed has none: train from scratch).
    pub fn warm_start(&self, log: &RefineLog) -> Option<PathBuf> {
        if !self.project.surrogate.warm_start {
            return None;
        }
        let last = log.rounds.last()?;
        let dir = self.refine_dir(last.round).join("surrogate");
        dir.join(bemcal_surrogate::WEIGHTS_FILE)
            .is_file()
            .then_some(dir)
    }

    /// Records a finished round: the surrogate its chains used moves to `refine/round_R/` (so
    /// the next stage trains a new one on the grown training set), then the round is appended
    /// to `refine.json`. In that order: a crash in between only makes a rerun redo the round
    /// from its checkpointed chains and saved simulations.
    pub fn record_round(&self, log: &mut RefineLog, round: RefineRound) -> Result<(), Error> {
        let dir = self.refine_dir(round.round);
        std::fs::create_dir_all(&dir).map_err(|e| Error::io(&dir, e))?;
        let (from, to) = (self.surrogate_dir(), dir.join("surrogate"));
        if from.exists() {
            if to.exists() {
                std::fs::remove_dir_all(&to).map_err(|e| Error::io(&to, e))?;
            }
            std::fs::rename(&from, &to).map_err(|e| Error::io(&from, e))?;
        }
        log.rounds.push(round);
        let json = serde_json::to_vec_pretty(log).map_err(|e| Error::Config(e.to_string()))?;
        write_atomic(&self.out.join(REFINE_FILE), &json)
    }
}

/// A posterior draw of a refinement round after EnergyPlus: its key in `simulations/`, its
/// values (physical units) and its outputs or EnergyPlus's failure.
#[derive(Debug, Clone)]
pub struct SimulatedDraw {
    /// Key in `simulations/` (after the hypercube's points).
    pub index: usize,
    /// Calibrated parameter values (physical units, plan order).
    pub values: Vec<f64>,
    /// EnergyPlus's hourly outputs, or its failure message.
    pub outputs: Result<HourlyOutputs, String>,
}

/// Closes refinement round `round` once its draws are simulated: the draws EnergyPlus could
/// simulate become design points, the others are recorded as failed; the surrogate that ran
/// the round's chains is measured against EnergyPlus at the new points ([`pooled_error`], and
/// in parameter space: what it recovers from their outputs, [`Sampler::recover`]); and
/// the next round's chains start where these ended ([`next_starts`], from the round's merged
/// chains: `draws` and each chain's `last` position). The one rule the driver follows;
/// returns the round and the new points' outputs (in the round's point order).
pub fn close_round(
    round: u32,
    simulated: Vec<SimulatedDraw>,
    sampler: &mut Sampler<'_>,
    draws: &[Draws],
    last: &[Vec<f64>],
    restart_below: f64,
) -> Result<(RefineRound, Vec<HourlyOutputs>), Error> {
    let mut points = vec![];
    let mut failed = vec![];
    let mut outputs = vec![];
    for s in simulated {
        match s.outputs {
            Ok(o) => {
                points.push(RefinePoint {
                    index: s.index,
                    values: s.values,
                });
                outputs.push(o);
            }
            Err(error) => failed.push(FailedPoint {
                values: s.values,
                error,
            }),
        }
    }
    let xs: Vec<Vec<f64>> = points.iter().map(|p| p.values.clone()).collect();
    let predicted = sampler.predict(&xs)?;
    let names = sampler.outputs().to_vec();
    let surrogate_error = pooled_error(&names, &outputs, &predicted)?;
    let recovered = sampler.recover(&xs, &outputs)?;
    let (starts, restarted) = next_starts(draws, last, restart_below);
    let round = RefineRound {
        round,
        points,
        failed,
        surrogate_error,
        recovered,
        starts,
        restarted,
        temperature: sampler.temperature(),
        spread: sampler.spread(),
    };
    Ok((round, outputs))
}

/// Guideline 14 of `predicted` against EnergyPlus's `simulated` outputs, hours of all points
/// pooled, per output (EnergyPlus in the role of the meters).
pub fn pooled_error(
    outputs: &[String],
    simulated: &[HourlyOutputs],
    predicted: &[Vec<Vec<f64>>],
) -> Result<Vec<OutputMetrics>, Error> {
    let mut m = vec![];
    for (k, name) in outputs.iter().enumerate() {
        let mut truth = vec![];
        let mut pred = vec![];
        for (s, p) in simulated.iter().zip(predicted) {
            let series = s.get(name).ok_or_else(|| Error::Stage {
                stage: "refinement",
                message: format!("simulation has no output {name}"),
            })?;
            truth.extend_from_slice(series);
            pred.extend_from_slice(&p[k]);
        }
        m.push(OutputMetrics::hourly(
            name,
            bemcal_stats::metrics::g14(&truth, &pred)?,
        ));
    }
    Ok(m)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn chain(points: &[[f64; 2]], lp: &[f64]) -> Draws {
        let mut d = Draws::new(2);
        for (p, l) in points.iter().zip(lp) {
            d.points.extend_from_slice(p);
            d.log_density.push(*l);
        }
        d
    }

    #[test]
    fn picks_the_map_then_chain_ends_then_spread_draws_without_repeats() {
        let a = chain(
            &[[0.1, 0.1], [0.1, 0.1], [0.2, 0.2], [0.3, 0.3]],
            &[-5.0, -5.0, -1.0, -4.0],
        );
        let b = chain(
            &[[0.6, 0.6], [0.7, 0.7], [0.7, 0.7], [0.8, 0.8]],
            &[-3.0, -2.0, -2.0, -6.0],
        );
        let p = pick_draws(&[a.clone(), b.clone()], 3);
        assert_eq!(p, vec![vec![0.2, 0.2], vec![0.3, 0.3], vec![0.8, 0.8]]);
        let p = pick_draws(&[a.clone(), b.clone()], 10);
        // Only 6 distinct draws exist.
        assert_eq!(p.len(), 6);
        let mut sorted = p.clone();
        sorted.sort_by(|x, y| x[0].total_cmp(&y[0]));
        sorted.dedup();
        assert_eq!(sorted.len(), 6);
        assert!(pick_draws(&[Draws::new(2)], 4).is_empty());
    }

    #[test]
    fn refinement_points_spread_from_the_mean_except_the_best_and_stay_allowed() {
        let a = chain(&[[0.4, 0.5], [0.5, 0.5]], &[-1.0, -2.0]);
        let b = chain(&[[0.6, 0.5], [0.5, 0.6]], &[-3.0, -4.0]);
        let draws = [a, b];
        // Spread 1: the draws themselves.
        assert_eq!(
            refinement_points(&draws, 4, 1.0, |_| true),
            pick_draws(&draws, 4)
        );
        // The mean is (0.5, 0.525): the best draw stays, the others move 3x as far.
        let p = refinement_points(&draws, 4, 3.0, |_| true);
        let near =
            |x: &[f64], y: [f64; 2]| (x[0] - y[0]).abs() < 1e-12 && (x[1] - y[1]).abs() < 1e-12;
        assert!(near(&p[0], [0.4, 0.5]), "{p:?}");
        assert!(near(&p[1], [0.5, 0.45]), "{p:?}"); // a's last draw (0.5, 0.5)
        assert!(near(&p[2], [0.5, 0.75]), "{p:?}"); // b's last draw (0.5, 0.6)
        assert!(near(&p[3], [0.8, 0.45]), "{p:?}"); // (0.6, 0.5)
                                                    // Far from the unit box's centre: clamped inside it.
        let c = chain(&[[0.5, 0.5], [0.9, 0.1]], &[-1.0, -2.0]);
        let p = refinement_points(&[c], 2, 10.0, |_| true);
        assert_eq!(p[1], vec![0.999, 0.001]);
        // Refused where the first coordinate exceeds 0.7: the excess spread is halved (3 -> 2)
        // to (0.7, ...); refused everywhere off the draws: the draw itself.
        let p = refinement_points(&draws, 4, 3.0, |x| x[0] <= 0.7 + 1e-12);
        assert!(near(&p[3], [0.7, 0.475]), "{p:?}");
        let p = refinement_points(&draws, 4, 3.0, |x| {
            pick_draws(&draws, 4).iter().any(|d| d.as_slice() == x)
        });
        assert_eq!(p, pick_draws(&draws, 4));
    }

    #[test]
    fn chains_far_below_the_best_restart_in_its_mode() {
        let a = chain(
            &[[0.1, 0.1], [0.2, 0.2], [0.3, 0.3], [0.4, 0.4]],
            &[-9.0, -1.0, -2.0, -3.0],
        );
        let b = chain(&[[0.6, 0.6], [0.7, 0.7]], &[-30.0, -25.0]);
        let c = chain(&[[0.8, 0.8], [0.9, 0.9]], &[-12.0, -15.0]);
        let last = vec![vec![0.4, 0.4], vec![0.7, 0.7], vec![0.9, 0.9]];
        let (starts, restarted) = next_starts(&[a.clone(), b.clone(), c.clone()], &last, 20.0);
        // b is 24 nats below a: restarted at a draw of a's second half; c (11 below) stays.
        assert_eq!(restarted, vec![(1, 24.0)]);
        assert_eq!(starts[0], last[0]);
        assert_eq!(starts[1], vec![0.3, 0.3]);
        assert_eq!(starts[2], last[2]);
        let (starts, restarted) = next_starts(&[a, b, c], &last, 1e9);
        assert!(restarted.is_empty());
        assert_eq!(starts, last);
    }

    #[test]
    fn the_next_rounds_keys_follow_every_draw_failed_ones_included() {
        let round = |points: &[usize], failed: usize| RefineRound {
            round: 1,
            points: points
                .iter()
                .map(|&index| RefinePoint {
                    index,
                    values: vec![0.0],
                })
                .collect(),
            failed: (0..failed)
                .map(|_| FailedPoint {
                    values: vec![1.0],
                    error: "Fatal".into(),
                })
                .collect(),
            surrogate_error: vec![],
            recovered: vec![],
            starts: vec![],
            restarted: vec![],
            temperature: 1.0,
            spread: 1.0,
        };
        // Round 1 used keys 20..30 and the draw at 23 failed: round 2 starts at 30, not 29.
        let log = RefineLog {
            rounds: vec![round(&[20, 21, 22, 24, 25, 26, 27, 28, 29], 1)],
        };
        assert_eq!(log.next_key(20), 30);
        assert_eq!(RefineLog::default().next_key(20), 20);
    }
}

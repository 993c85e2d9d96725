//! Design points EnergyPlus could not simulate: recorded, replaced by spare hypercube points,
//! dropped past a limit, and explained when too few remain. One rule for every driver: the
//! local pipeline and the coordinator both call [`next_step`] with the attempts so far and do
//! what it says, so a run gives the same design in both.
//!
//! The design has `n` slots, one per hypercube point. Wave 0 simulates the hypercube. Each
//! later wave gives every slot whose last attempt failed (and that has replacements left) the
//! spare point farthest from every point tried so far, successful or failed
//! ([`bemcal_stats::lhs::farthest_candidate`]): the design stays space-filling and moves away
//! from where EnergyPlus failed. The spares are a second hypercube of `n` points with its own
//! seed ([`spare_seed`]). Pure: no I/O.

use bemcal_energyplus::errfile::{failure_reason, is_model_failure};
use bemcal_stats::lhs::{farthest_candidate, Design};
use bemcal_stats::prior::Triangular;
use serde::{Deserialize, Serialize};

use crate::plan::{distance, probabilities, InvalidBall, InvalidRegion, Plan};

/// One simulation of a design slot: the values tried and what came of it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct Attempt {
    /// The hypercube slot (its points are saved as `point_{slot:03}`).
    pub slot: usize,
    /// Calibrated parameter values, physical units, plan order.
    pub values: Vec<f64>,
    /// The failure, as the error's text; `None` for a simulation that succeeded.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
}

/// The failure settings of `[design]`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Policy {
    /// Replacements per slot after its first attempt.
    pub replacements: usize,
    /// Share of the slots that must end with a simulated point.
    pub min_success: f64,
}

impl Policy {
    /// Slots that must succeed out of `n`.
    pub fn floor(&self, n: usize) -> usize {
        ((self.min_success * n as f64).ceil() as usize).clamp(1, n)
    }
}

/// What a driver does next.
#[derive(Debug, Clone, PartialEq)]
pub enum Step {
    /// Simulate these `(slot, values)` and call [`next_step`] again with their attempts added.
    Simulate(Vec<(usize, Vec<f64>)>),
    /// Every slot is settled.
    Done(Outcome),
    /// Too few slots could be simulated: the message groups the failures by reason and
    /// suggests what to change.
    Failed(String),
}

/// The settled design.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Outcome {
    /// Slots with a simulated point, in slot order.
    pub slots: Vec<usize>,
    /// Their points (the values of each slot's successful attempt).
    pub points: Vec<Vec<f64>>,
    /// Every failed attempt, in order.
    pub failed: Vec<Attempt>,
    /// Slots whose simulated point is a spare, with the number of failures before it.
    pub replaced: Vec<(usize, usize)>,
    /// Slots left without a point (every attempt failed).
    pub dropped: Vec<usize>,
}

impl Outcome {
    /// The design to train on: `hypercube` with each slot's simulated point, dropped slots
    /// left out.
    pub fn design(&self, hypercube: &Design, priors: &[Triangular]) -> Design {
        let mut d = hypercube.clone();
        d.points = self.points.clone();
        d.probabilities = self
            .points
            .iter()
            .map(|x| probabilities(priors, x))
            .collect();
        d
    }

    /// Failures grouped by reason, largest group first.
    pub fn reasons(&self) -> Vec<FailureGroup> {
        group_reasons(&self.failed)
    }

    /// The hypercube's slots, settled or dropped.
    pub fn slot_count(&self) -> usize {
        self.slots.len() + self.dropped.len()
    }
}

/// The seed of the spare hypercube for a design seeded `seed`.
pub fn spare_seed(seed: u64) -> u64 {
    seed ^ 0x5EED_5EED_5EED_5EED
}

/// The next step of a design with slots `hypercube.points`, spares `spares.points`, after
/// `attempts` (every attempt so far, in the order they were made).
pub fn next_step(
    plan: &Plan,
    hypercube: &Design,
    spares: &Design,
    policy: Policy,
    attempts: &[Attempt],
) -> Step {
    let priors = &plan.priors[..];
    let n = hypercube.points.len();
    let mut last: Vec<Option<&Attempt>> = vec![None; n];
    let mut tries = vec![0usize; n];
    for a in attempts.iter().filter(|a| a.slot < n) {
        last[a.slot] = Some(a);
        tries[a.slot] += 1;
    }
    // Wave 0: the hypercube's points not tried yet.
    let untried: Vec<(usize, Vec<f64>)> = (0..n)
        .filter(|&s| last[s].is_none())
        .map(|s| (s, hypercube.points[s].clone()))
        .collect();
    if !untried.is_empty() {
        return Step::Simulate(untried);
    }
    // Later waves: a spare for every failed slot with replacements left.
    let mut tried: Vec<Vec<f64>> = attempts
        .iter()
        .map(|a| probabilities(priors, &a.values))
        .collect();
    let mut unused: Vec<&Vec<f64>> = spares
        .points
        .iter()
        .filter(|x| !attempts.iter().any(|a| &a.values == *x))
        .collect();
    let mut wave = vec![];
    for s in 0..n {
        let failed = last[s].is_some_and(|a| a.error.is_some());
        if !failed || tries[s] > policy.replacements {
            continue;
        }
        let candidates: Vec<Vec<f64>> = unused.iter().map(|x| probabilities(priors, x)).collect();
        let Some(k) = farthest_candidate(&tried, &candidates) else {
            break;
        };
        let x = unused.remove(k).clone();
        tried.push(candidates[k].clone());
        wave.push((s, x));
    }
    if !wave.is_empty() {
        return Step::Simulate(wave);
    }
    let mut out = Outcome {
        slots: vec![],
        points: vec![],
        failed: attempts
            .iter()
            .filter(|a| a.error.is_some())
            .cloned()
            .collect(),
        replaced: vec![],
        dropped: vec![],
    };
    for (s, a) in last.iter().enumerate() {
        let a = a.expect("every slot tried");
        if a.error.is_some() {
            out.dropped.push(s);
        } else {
            out.slots.push(s);
            out.points.push(a.values.clone());
            if tries[s] > 1 {
                out.replaced.push((s, tries[s] - 1));
            }
        }
    }
    if out.slots.len() >= policy.floor(n) {
        Step::Done(out)
    } else {
        Step::Failed(failure_message(plan, policy, n, &out))
    }
}

/// The region where EnergyPlus failed ([`InvalidRegion`], the plan's), from its failures.
impl InvalidRegion {
    /// The region of a settled design.
    pub fn from_outcome(outcome: &Outcome, priors: &[Triangular]) -> InvalidRegion {
        let ok: Vec<Vec<f64>> = outcome
            .points
            .iter()
            .map(|x| probabilities(priors, x))
            .collect();
        let balls = outcome
            .failed
            .iter()
            .filter(|a| is_model_failure(a.error.as_deref().unwrap_or_default()))
            .filter_map(|a| {
                let c = probabilities(priors, &a.values);
                let nearest = ok
                    .iter()
                    .map(|o| distance(o, &c))
                    .fold(f64::INFINITY, f64::min);
                nearest.is_finite().then(|| InvalidBall {
                    values: a.values.clone(),
                    radius: 0.5 * nearest,
                    reason: failure_reason(a.error.as_deref().unwrap_or_default()),
                })
            })
            .collect();
        InvalidRegion { balls }
    }
}

/// Failures of one reason ([`failure_reason`]): how many runs, at which slots.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct FailureGroup {
    /// The reason, in a few words ([`failure_reason`]).
    pub reason: String,
    /// Failed runs with this reason.
    pub count: usize,
    /// The hypercube slots they were at, each once, in order of first failure.
    pub points: Vec<usize>,
}

fn group_reasons(failed: &[Attempt]) -> Vec<FailureGroup> {
    let mut groups: Vec<FailureGroup> = vec![];
    for a in failed {
        let reason = failure_reason(a.error.as_deref().unwrap_or_default());
        match groups.iter_mut().find(|g| g.reason == reason) {
            Some(g) => {
                if !g.points.contains(&a.slot) {
                    g.points.push(a.slot);
                }
                g.count += 1;
            }
            None => groups.push(FailureGroup {
                reason,
                count: 1,
                points: vec![a.slot],
            }),
        }
    }
    groups.sort_by_key(|g| std::cmp::Reverse(g.count));
    groups
}

/// Why the design failed: counts, the reasons grouped with their slots, and suggestions.
fn failure_message(plan: &Plan, policy: Policy, n: usize, out: &Outcome) -> String {
    let mut s = format!(
        "only {} of {n} design points could be simulated (at least {} needed: [design] \
         min_success = {}); {} EnergyPlus run(s) failed:",
        out.slots.len(),
        policy.floor(n),
        policy.min_success,
        out.failed.len()
    );
    for g in group_reasons(&out.failed) {
        s.push_str(&format!(
            "\n  {} x {} (design points {:?})",
            g.count, g.reason, g.points
        ));
    }
    let hints = suggestions(&plan.priors, &plan.calibrated, &out.failed);
    if !hints.is_empty() {
        s.push_str("\nwhat to change:");
        for h in hints {
            s.push_str(&format!("\n  - {h}"));
        }
    }
    s
}

/// What a user could change, from the failures' reasons and from where in the priors the failed
/// points lie (`names[i]` is the parameter of `priors[i]`).
pub fn suggestions(priors: &[Triangular], names: &[String], failed: &[Attempt]) -> Vec<String> {
    let mut out = vec![];
    let reasons: Vec<String> = group_reasons(failed)
        .into_iter()
        .map(|g| g.reason)
        .collect();
    for r in &reasons {
        let l = r.to_lowercase();
        let hint = if l.contains("warmup") || l.contains("warm-up") {
            "warm-up did not converge: heavy constructions or a zone that cycles; check the \
             model's constructions and HVAC at these points, or raise Building's maximum \
             warm-up days in your IDF"
        } else if l.contains("coil") && l.contains("ua") {
            "coil sizing failed: size HVAC at fixed design conditions (generated models do) or \
             narrow the priors of the supply-air / chilled-water temperatures and set-points"
        } else if l.contains("time limit") {
            "EnergyPlus ran out of time: a larger model needs a longer limit ([simulation] \
             timeout_s, default 900 s), or fewer time steps per hour"
        } else if l.contains("expected number") || l.contains("out of range") {
            "a parameter value is outside what EnergyPlus accepts for its field: narrow that \
             parameter's prior to the field's range"
        } else {
            continue;
        };
        if !out.iter().any(|h: &String| h == hint) {
            out.push(hint.to_string());
        }
    }
    let model_failures: Vec<&Attempt> = failed
        .iter()
        .filter(|a| is_model_failure(a.error.as_deref().unwrap_or_default()))
        .collect();
    if model_failures.len() >= 2 {
        for (i, p) in priors.iter().enumerate() {
            let q: Vec<f64> = model_failures.iter().map(|a| p.cdf(a.values[i])).collect();
            let name = names
                .get(i)
                .cloned()
                .unwrap_or_else(|| format!("parameter {i}"));
            if q.iter().all(|&v| v <= 0.25) {
                out.push(format!(
                    "the failed points all have low {name} (below its prior's 25th percentile, \
                     {:.4}): raise the prior's minimum ({}) if such values are implausible",
                    p.quantile(0.25),
                    p.min()
                ));
            } else if q.iter().all(|&v| v >= 0.75) {
                out.push(format!(
                    "the failed points all have high {name} (above its prior's 75th \
                     percentile, {:.4}): lower the prior's maximum ({}) if such values are \
                     implausible",
                    p.quantile(0.75),
                    p.max()
                ));
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use bemcal_stats::lhs::{latin_hypercube, LhsOptions};

    fn setup(n: usize) -> (Plan, Design, Design) {
        let priors = vec![
            Triangular::new(0.0, 0.5, 1.0).unwrap(),
            Triangular::new(10.0, 20.0, 30.0).unwrap(),
        ];
        let opts = LhsOptions::default();
        let h = latin_hypercube(&priors, n, 1, &opts).unwrap();
        let s = latin_hypercube(&priors, n, spare_seed(1), &opts).unwrap();
        let plan = Plan {
            calibrated: vec!["shgc".into(), "sat".into()],
            priors,
            units: vec!["-".into(), "C".into()],
            fixed: Default::default(),
            restricted: vec![],
            invalid: Default::default(),
        };
        (plan, h, s)
    }

    fn ok(slot: usize, values: &[f64]) -> Attempt {
        Attempt {
            slot,
            values: values.to_vec(),
            error: None,
        }
    }

    fn bad(slot: usize, values: &[f64], e: &str) -> Attempt {
        Attempt {
            slot,
            values: values.to_vec(),
            error: Some(e.into()),
        }
    }

    const POLICY: Policy = Policy {
        replacements: 2,
        min_success: 0.8,
    };
    const SEVERE: &str = "EnergyPlus failed in /x/point_001: results invalid\n   ** Severe  ** Calculation of cooling coil design UA failed for coil AHU2 COOLING COIL";

    #[test]
    fn a_failed_point_is_replaced_by_the_farthest_spare_then_the_design_is_done() {
        let (plan, h, s) = setup(6);
        let priors = plan.priors.clone();
        let Step::Simulate(wave0) = next_step(&plan, &h, &s, POLICY, &[]) else {
            panic!()
        };
        assert_eq!(wave0.len(), 6);
        let mut attempts: Vec<Attempt> = wave0
            .iter()
            .map(|(i, x)| {
                if *i == 1 {
                    bad(*i, x, SEVERE)
                } else {
                    ok(*i, x)
                }
            })
            .collect();
        let Step::Simulate(wave1) = next_step(&plan, &h, &s, POLICY, &attempts) else {
            panic!()
        };
        assert_eq!(wave1.len(), 1);
        assert_eq!(wave1[0].0, 1);
        assert!(s.points.contains(&wave1[0].1));
        // The chosen spare is the maximin one among all spares.
        let tried: Vec<Vec<f64>> = attempts
            .iter()
            .map(|a| probabilities(&priors, &a.values))
            .collect();
        let cands: Vec<Vec<f64>> = s.points.iter().map(|x| probabilities(&priors, x)).collect();
        assert_eq!(
            s.points[farthest_candidate(&tried, &cands).unwrap()],
            wave1[0].1
        );
        attempts.push(ok(1, &wave1[0].1));
        let Step::Done(out) = next_step(&plan, &h, &s, POLICY, &attempts) else {
            panic!()
        };
        assert_eq!(out.slots, (0..6).collect::<Vec<_>>());
        assert_eq!(out.points[1], wave1[0].1);
        assert_eq!(out.replaced, vec![(1, 1)]);
        assert_eq!(out.failed.len(), 1);
        assert_eq!(
            out.reasons()[0].reason,
            "Calculation of cooling coil design UA failed for coil AHU# COOLING COIL"
        );
        assert_eq!(out.design(&h, &priors).points.len(), 6);
    }

    #[test]
    fn a_slot_failing_every_time_is_dropped_above_the_floor_and_fails_the_design_below_it() {
        let (plan, h, s) = setup(10);
        let mut attempts = vec![];
        loop {
            match next_step(&plan, &h, &s, POLICY, &attempts) {
                Step::Simulate(wave) => attempts.extend(wave.into_iter().map(|(i, x)| {
                    if i == 3 {
                        bad(i, &x, SEVERE)
                    } else {
                        ok(i, &x)
                    }
                })),
                Step::Done(out) => {
                    assert_eq!(out.dropped, vec![3]);
                    assert_eq!(out.failed.len(), 3, "first try + 2 replacements");
                    assert_eq!(out.slots.len(), 9);
                    break;
                }
                Step::Failed(m) => panic!("{m}"),
            }
        }
        // Three slots failing at every try: 7 of 10 is below the floor of 8.
        let mut attempts = vec![];
        let msg = loop {
            match next_step(&plan, &h, &s, POLICY, &attempts) {
                Step::Simulate(wave) => attempts.extend(wave.into_iter().map(|(i, x)| {
                    if i < 3 {
                        bad(i, &x, SEVERE)
                    } else {
                        ok(i, &x)
                    }
                })),
                Step::Done(out) => panic!("{out:?}"),
                Step::Failed(m) => break m,
            }
        };
        assert!(msg.contains("only 7 of 10 design points"), "{msg}");
        assert!(
            msg.contains("9 x Calculation of cooling coil design UA"),
            "{msg}"
        );
        assert!(msg.contains("what to change"), "{msg}");
    }

    #[test]
    fn failures_clustered_at_one_end_of_a_prior_are_pointed_out() {
        let priors = vec![
            Triangular::new(0.0, 0.5, 1.0).unwrap(),
            Triangular::new(10.0, 20.0, 30.0).unwrap(),
        ];
        let failed = vec![bad(0, &[0.05, 20.0], SEVERE), bad(1, &[0.1, 12.0], SEVERE)];
        let hints = suggestions(&priors, &["shgc".into(), "sat".into()], &failed);
        assert!(hints.iter().any(|h| h.contains("low shgc")), "{hints:?}");
        assert!(!hints.iter().any(|h| h.contains("sat")), "{hints:?}");
    }

    #[test]
    fn the_invalid_region_is_a_ball_half_way_to_the_nearest_success() {
        let (plan, _, _) = setup(4);
        let priors = &plan.priors;
        let outcome = Outcome {
            slots: vec![0, 1],
            points: vec![vec![0.5, 20.0], vec![0.9, 20.0]],
            failed: vec![
                bad(2, &[0.1, 20.0], SEVERE),
                bad(
                    3,
                    &[0.5, 28.0],
                    "EnergyPlus exceeded its time limit of 900 s in /x",
                ),
            ],
            replaced: vec![],
            dropped: vec![2, 3],
        };
        let r = InvalidRegion::from_outcome(&outcome, priors);
        assert_eq!(
            r.balls.len(),
            1,
            "a time limit says nothing about the model"
        );
        // F(0.1) = 0.02, F(0.5) = 0.5: radius 0.24 in probability.
        assert!(
            (r.balls[0].radius - 0.24).abs() < 1e-12,
            "{}",
            r.balls[0].radius
        );
        assert!(r.refuses(priors, &[0.15, 20.0]).is_some());
        assert!(r.refuses(priors, &[0.5, 20.0]).is_none());
        assert!(r.refuses(priors, &[0.1, 28.0]).is_none());
    }
}

//! The plan of a calibration: which parameters are calibrated, their priors and units, the
//! values of the others, and the region where EnergyPlus could not simulate design points
//! ([`InvalidRegion`]), which the chains refuse.

use bemcal_energyplus::{Model, ParameterValues};
use bemcal_stats::lhs::PairConstraint;
use bemcal_stats::prior::Triangular;
use serde::{Deserialize, Serialize};

use crate::error::Error;

/// Which parameters are calibrated and the values of the others.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Plan {
    /// Calibrated parameter names, in model order.
    pub calibrated: Vec<String>,
    /// Their priors.
    pub priors: Vec<Triangular>,
    /// Their units, as the model declares them (empty where it declares none).
    pub units: Vec<String>,
    /// Values of every parameter that is not calibrated.
    pub fixed: ParameterValues,
    /// Priors restricted by a constraint with a fixed parameter, as messages for the log.
    pub restricted: Vec<String>,
    /// Where EnergyPlus could not simulate design points (set once the design is settled):
    /// the chains refuse proposals there ([`Plan::refused`]).
    #[serde(default)]
    pub invalid: InvalidRegion,
}

impl Plan {
    /// Builds the plan: `calibrate` empty = all parameters; `fixed` values for the rest
    /// (others at their prior mode).
    pub fn new(
        model: &Model,
        calibrate: &[String],
        fixed: &ParameterValues,
    ) -> Result<Plan, Error> {
        let names: Vec<&str> = model.parameters().iter().map(|p| p.name.as_str()).collect();
        for n in calibrate.iter().chain(fixed.keys()) {
            if !names.contains(&n.as_str()) {
                let why = (model.spec().and_then(|s| s.absent(n)))
                    .map_or(String::new(), |r| format!(" ({r})"));
                return Err(Error::Config(format!(
                    "unknown parameter '{n}'{why}; the model has: {}",
                    names.join(", ")
                )));
            }
        }
        if let Some(n) = calibrate.iter().find(|n| fixed.contains_key(*n)) {
            return Err(Error::Config(format!(
                "parameter '{n}' is both calibrated and fixed"
            )));
        }
        let mut plan = Plan {
            calibrated: vec![],
            priors: vec![],
            units: vec![],
            fixed: ParameterValues::new(),
            restricted: vec![],
            invalid: Default::default(),
        };
        for p in model.parameters() {
            let cal = if calibrate.is_empty() {
                !fixed.contains_key(&p.name)
            } else {
                calibrate.contains(&p.name)
            };
            if cal {
                let t = Triangular::new(p.prior.min, p.prior.mode, p.prior.max)
                    .map_err(|e| Error::Config(format!("prior of {}: {e}", p.name)))?;
                plan.calibrated.push(p.name.clone());
                plan.priors.push(t);
                plan.units.push(p.unit.clone());
            } else {
                let v = fixed.get(&p.name).copied().unwrap_or(p.prior.mode);
                plan.fixed.insert(p.name.clone(), v);
            }
        }
        if plan.calibrated.is_empty() {
            return Err(Error::Config("no parameter left to calibrate".into()));
        }
        // Values that are not calibrated never change: a constraint they break would fail
        // every design point.
        for c in model.constraints() {
            c.check(&plan.fixed).map_err(|e| {
                Error::Config(format!(
                    "{e} (a parameter not calibrated is at its [fixed] value, else at its prior's mode)"
                ))
            })?;
        }
        plan.restrict_to_fixed(model)?;
        Ok(plan)
    }

    /// A constraint between a calibrated and a fixed parameter is a bound on the calibrated
    /// one: its prior is restricted to the feasible range (a triangular prior on
    /// [max(min, bound), max] or [min, min(max, bound)], mode clamped into it), so neither the
    /// design nor the chains propose values EnergyPlus would refuse.
    fn restrict_to_fixed(&mut self, model: &Model) -> Result<(), Error> {
        for c in model.constraints() {
            let lo_cal = self.calibrated.iter().position(|n| *n == c.lower);
            let hi_cal = self.calibrated.iter().position(|n| *n == c.upper);
            let (i, new_min, new_max) = match (lo_cal, hi_cal) {
                (Some(i), None) => {
                    let bound = self.fixed[&c.upper] - c.margin;
                    (i, self.priors[i].min(), self.priors[i].max().min(bound))
                }
                (None, Some(j)) => {
                    let bound = self.fixed[&c.lower] + c.margin;
                    (j, self.priors[j].min().max(bound), self.priors[j].max())
                }
                _ => continue,
            };
            let p = self.priors[i];
            if new_min == p.min() && new_max == p.max() {
                continue;
            }
            if new_min >= new_max {
                return Err(Error::Config(format!(
                    "{} cannot satisfy '{} + {} <= {}' with the fixed value: its prior [{}, {}] lies entirely outside; {}",
                    self.calibrated[i], c.lower, c.margin, c.upper, p.min(), p.max(), c.reason
                )));
            }
            let mode = p.mode().clamp(new_min, new_max);
            self.priors[i] = Triangular::new(new_min, mode, new_max).map_err(|e| {
                Error::Config(format!("restricted prior of {}: {e}", self.calibrated[i]))
            })?;
            self.restricted.push(format!(
                "prior of {} restricted to [{new_min}, {new_max}] (mode {mode}) by '{} + {} <= {}' with the fixed value",
                self.calibrated[i], c.lower, c.margin, c.upper
            ));
        }
        Ok(())
    }

    /// Full parameter values for a vector of calibrated values.
    pub fn values(&self, x: &[f64]) -> ParameterValues {
        let mut v = self.fixed.clone();
        for (n, x) in self.calibrated.iter().zip(x) {
            v.insert(n.clone(), *x);
        }
        v
    }

    /// The model's pairwise constraints between calibrated parameters, as LHS constraints.
    pub fn pair_constraints(&self, model: &Model) -> Vec<PairConstraint> {
        model
            .constraints()
            .iter()
            .filter_map(|c| {
                let i = self.calibrated.iter().position(|n| *n == c.lower)?;
                let j = self.calibrated.iter().position(|n| *n == c.upper)?;
                // lower + margin <= upper  <=>  x_i - x_j <= -margin
                Some(PairConstraint::new(i, j, -c.margin))
            })
            .collect()
    }

    /// Why the chains refuse calibrated values `x`: they lie where EnergyPlus could not
    /// simulate a design point ([`InvalidRegion`]); `None` if they do not.
    pub fn refused(&self, x: &[f64]) -> Option<&InvalidBall> {
        self.invalid.refuses(&self.priors, x)
    }

    /// True if the full parameter set satisfies every model constraint.
    pub fn feasible(&self, model: &Model, x: &[f64]) -> bool {
        let v = self.values(x);
        model.constraints().iter().all(|c| c.check(&v).is_ok())
    }
}

/// Where the model could not be simulated, learned from the design's failures: a ball in
/// probability space around each point EnergyPlus refused (a model failure, not a time limit),
/// of radius half its distance to the nearest point it simulated. The chains refuse proposals
/// inside (their log prior is -inf there, as outside a constraint), so that the posterior does
/// not settle where the surrogate extrapolates and EnergyPlus would fail again. A ball and not
/// the failed point's whole neighbourhood: between a failure and a success the model's edge is
/// unknown, and half-way is the nearest-neighbour guess. Learned by the replacement rule
/// (`InvalidRegion::from_outcome`, in `replacement`).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct InvalidRegion {
    /// One ball per design point EnergyPlus refused (empty: the chains refuse nothing).
    pub balls: Vec<InvalidBall>,
}

/// One failed point's ball.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct InvalidBall {
    /// The failed point, physical units (plan order).
    pub values: Vec<f64>,
    /// Radius in probability space (`p = F(x)` per parameter).
    #[serde(deserialize_with = "bemcal_stats::nan::null_as_nan")]
    #[schemars(with = "bemcal_stats::nan::NumberOrNull")]
    pub radius: f64,
    /// Why EnergyPlus failed there ([`bemcal_energyplus::errfile::failure_reason`]).
    pub reason: String,
}

impl InvalidRegion {
    /// The ball `x` (physical units) lies in, if any.
    pub fn refuses(&self, priors: &[Triangular], x: &[f64]) -> Option<&InvalidBall> {
        if self.balls.is_empty() {
            return None;
        }
        let p = probabilities(priors, x);
        self.balls
            .iter()
            .find(|b| distance(&probabilities(priors, &b.values), &p) < b.radius)
    }
}

/// Euclidean distance (in probability space).
pub(crate) fn distance(a: &[f64], b: &[f64]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y) * (x - y))
        .sum::<f64>()
        .sqrt()
}

/// Calibrated values `x` as their priors' probabilities, `p = F(x)` per parameter.
pub(crate) fn probabilities(priors: &[Triangular], x: &[f64]) -> Vec<f64> {
    priors.iter().zip(x).map(|(p, v)| p.cdf(*v)).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use bemcal_energyplus::BuildingSpec;

    #[test]
    fn unknown_or_doubly_assigned_parameters_are_refused() {
        let model = Model::generated(BuildingSpec::default());
        let e = Plan::new(&model, &["lighting".into()], &Default::default()).unwrap_err();
        assert!(
            e.to_string().contains("unknown parameter 'lighting'"),
            "{e}"
        );
        // A partial day's interval on a calendar without partial days says where they come from.
        let e =
            Plan::new(&model, &["schedule_partial_01".into()], &Default::default()).unwrap_err();
        assert!(e.to_string().contains("no partial days"), "{e}");
        let fixed: ParameterValues = [("shgc".to_string(), 0.4)].into();
        let e = Plan::new(&model, &["shgc".into()], &fixed).unwrap_err();
        assert!(e.to_string().contains("both calibrated and fixed"), "{e}");
    }
}

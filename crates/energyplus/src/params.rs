//! Named calibration parameters, their default triangular priors, and the physical constraints
//! between them.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use crate::Error;

/// A triangular prior (min, mode, max) as written in model and project files. The density
/// itself lives in `bemcal-stats`; this is the record.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct TriangularPrior {
    /// The lower bound.
    pub min: f64,
    /// The most likely value.
    pub mode: f64,
    /// The upper bound.
    pub max: f64,
}

impl TriangularPrior {
    /// A prior, checked: min <= mode <= max and min < max.
    pub fn new(min: f64, mode: f64, max: f64) -> Result<TriangularPrior, String> {
        if !(min.is_finite() && mode.is_finite() && max.is_finite()) {
            return Err(format!("prior ({min}, {mode}, {max}) is not finite"));
        }
        if !(min <= mode && mode <= max && min < max) {
            return Err(format!(
                "prior (min {min}, mode {mode}, max {max}) needs min <= mode <= max and min < max"
            ));
        }
        Ok(TriangularPrior { min, mode, max })
    }

    /// True if `x` lies in the prior's support.
    pub fn contains(&self, x: f64) -> bool {
        x >= self.min && x <= self.max
    }
}

/// A calibration parameter of a model.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ParameterDef {
    /// The parameter's name.
    pub name: String,
    /// Its unit.
    pub unit: String,
    /// What it is.
    pub description: String,
    /// Its triangular prior.
    pub prior: TriangularPrior,
}

/// A physical constraint `value(lower) + margin <= value(upper)` between two parameters.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct Constraint {
    /// The parameter that must stay below.
    pub lower: String,
    /// The parameter that must stay above.
    pub upper: String,
    /// The least gap between them, in their unit.
    pub margin: f64,
    /// Why, for messages.
    pub reason: String,
}

impl Constraint {
    /// Checks the constraint on a set of values; parameters not present are not checked.
    pub fn check(&self, values: &ParameterValues) -> Result<(), Error> {
        if let (Some(lo), Some(hi)) = (values.get(&self.lower), values.get(&self.upper)) {
            if lo + self.margin > hi + 1e-12 {
                return Err(Error::Parameter {
                    name: format!("{} / {}", self.lower, self.upper),
                    message: format!(
                        "{} = {lo} and {} = {hi} violate {} + {} <= {}: {}",
                        self.lower, self.upper, self.lower, self.margin, self.upper, self.reason
                    ),
                });
            }
        }
        Ok(())
    }
}

/// Parameter values by name.
pub type ParameterValues = BTreeMap<String, f64>;

/// Parses `NAME=VALUE` assignments (as given with `--set`).
pub fn parse_assignments(items: &[String]) -> Result<ParameterValues, Error> {
    let mut out = ParameterValues::new();
    for item in items {
        let (k, v) = item.split_once('=').ok_or_else(|| Error::Parameter {
            name: item.clone(),
            message: "expected NAME=VALUE".into(),
        })?;
        let value: f64 = v.trim().parse().map_err(|_| Error::Parameter {
            name: k.trim().to_string(),
            message: format!("value '{v}' is not a number"),
        })?;
        out.insert(k.trim().to_string(), value);
    }
    Ok(out)
}

/// Fills values for every parameter: the given ones (checked against the names and the prior
/// support) and the prior mode for the rest.
pub fn complete_values(
    defs: &[ParameterDef],
    given: &ParameterValues,
) -> Result<ParameterValues, Error> {
    for name in given.keys() {
        if !defs.iter().any(|d| &d.name == name) {
            let known: Vec<&str> = defs.iter().map(|d| d.name.as_str()).collect();
            return Err(Error::Parameter {
                name: name.clone(),
                message: format!("unknown parameter; this model has: {}", known.join(", ")),
            });
        }
    }
    let mut out = ParameterValues::new();
    for d in defs {
        let v = given.get(&d.name).copied().unwrap_or(d.prior.mode);
        if !v.is_finite() {
            return Err(Error::Parameter {
                name: d.name.clone(),
                message: format!("value {v} is not finite"),
            });
        }
        out.insert(d.name.clone(), v);
    }
    Ok(out)
}

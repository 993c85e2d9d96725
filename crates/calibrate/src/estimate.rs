//! How the estimate was settled, for the log and `summary.json`: the note where a fallback
//! draw replaced it ([`fallback_note`]) and the record of `estimate = "best_simulated"`'s
//! choice among the points EnergyPlus simulated ([`EstimateChoice`]).

use serde::{Deserialize, Serialize};

use crate::keys::{is_mapped, CALIBRATED_LABEL};
use crate::mapping::MappingStep;

/// What summary.json says when the estimate was replaced by the next-best draw.
pub fn fallback_note(failures: &[String]) -> String {
    format!(
        "EnergyPlus could not simulate the estimate; calibrated_values and validation are those \
         of the next-best posterior draw that it could simulate (by log posterior; {} failed: {})",
        failures.len(),
        failures.join(" | ")
    )
}

/// One posterior draw EnergyPlus simulated in validation, and how near Guideline 14's hourly
/// limits it is.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct SimulatedFit {
    /// Its validation label: `calibrated` (the MAP draw) or `predictive_NN`.
    pub label: String,
    /// [`crate::metrics::limit_ratio`] of its run: at most 1 when every fitted meter passes hourly (`None`:
    /// its run gave no metrics).
    pub limit_ratio: Option<f64>,
    /// [`crate::metrics::monthly_limit_ratio`] of its run: at most 1 when every fitted meter passes monthly
    /// (`None`: no monthly figures, a calibration period under two months, or an older
    /// summary).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub monthly_limit_ratio: Option<f64>,
}

/// How `estimate = "best_simulated"` chose the estimate, for `summary.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct EstimateChoice {
    /// The label of the draw that became the estimate.
    pub chosen: String,
    /// Every draw EnergyPlus simulated, in validation's order (the MAP draw first), then
    /// the points of the output space mapping, if any.
    pub candidates: Vec<SimulatedFit>,
    /// The steps of output space mapping ([`crate::mapping`]) where EnergyPlus fitted none of
    /// the posterior draws.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub mapping: Vec<MappingStep>,
    /// Where a mapped point became the estimate (it is not a posterior draw): the parameters
    /// whose value there lies outside the posterior's 90 % interval.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub outside_interval: Vec<String>,
}

impl EstimateChoice {
    /// Whether the point chosen is one of the output space mapping's (`mapped_NN`), not a
    /// posterior draw.
    pub fn chose_mapped(&self) -> bool {
        is_mapped(&self.chosen)
    }

    /// The choice in a sentence, for the log and (where a predictive draw became the
    /// estimate) `estimate_note`. `map_failure`: why EnergyPlus could not simulate the MAP
    /// draw, if it could not.
    pub fn describe(&self, map_failure: Option<&str>) -> String {
        let ratio = |label: &str| self.ratio_of(label);
        let map = shown(ratio(CALIBRATED_LABEL));
        let n = self.candidates.len();
        let map_passes_hourly = ratio(CALIBRATED_LABEL).is_some_and(|r| r <= 1.0);
        let map_monthly = self.monthly_of(CALIBRATED_LABEL);
        let map_misses_monthly = map_passes_hourly && map_monthly.is_some_and(|r| r > 1.0);
        let monthly_miss = || {
            format!(
                "passes Guideline 14 hourly at the MAP draw (worst meter at {map} of the hourly \
                 limits) but misses its monthly criteria (worst meter at {} of the monthly \
                 limits)",
                shown(map_monthly)
            )
        };
        if self.chosen == CALIBRATED_LABEL {
            return if map_misses_monthly {
                format!(
                    "EnergyPlus {}, and no other of the {n} points it simulated passes both: it \
                     is the estimate",
                    monthly_miss()
                )
            } else if map_passes_hourly {
                format!(
                    "EnergyPlus passes Guideline 14 hourly at the MAP draw (worst meter at {map} \
                     of the limits): it is the estimate"
                )
            } else {
                format!(
                    "EnergyPlus fails Guideline 14 hourly at the MAP draw (worst meter at {map} of \
                     the limits), and no other of the {n} points it simulated fits better: it is \
                     the estimate"
                )
            };
        }
        if is_mapped(&self.chosen) {
            return self.describe_mapped(map_failure, &map);
        }
        if map_misses_monthly {
            return format!(
                "EnergyPlus {}; at posterior draw {} it passes both (worst meter at {} of the \
                 hourly and {} of the monthly limits), of {n} points simulated: it is the \
                 estimate",
                monthly_miss(),
                self.chosen,
                shown(ratio(&self.chosen)),
                shown(self.monthly_of(&self.chosen)),
            );
        }
        let (than, map_ratio) = match map_failure {
            None => (
                "better than the MAP draw, which fails there".to_string(),
                format!(", the MAP draw's at {map}"),
            ),
            Some(e) => (
                format!("best (EnergyPlus could not simulate the MAP draw: {e})"),
                String::new(),
            ),
        };
        let monthly = match self.monthly_of(&self.chosen) {
            Some(r) if r <= 1.0 => format!(
                "; it passes the monthly criteria too (worst meter at {r:.2} of their limits)"
            ),
            _ => String::new(),
        };
        format!(
            "EnergyPlus at posterior draw {} fits the meters {than} by Guideline 14's hourly \
             criteria (its worst meter at {} of the limits{map_ratio}), of {n} points \
             simulated{monthly}: it is the estimate",
            self.chosen,
            shown(ratio(&self.chosen)),
        )
    }

    /// [`Self::describe`] where a point of the output space mapping became the estimate.
    fn describe_mapped(&self, map_failure: Option<&str>, map: &str) -> String {
        let draws: Vec<&SimulatedFit> = (self.candidates.iter())
            .filter(|c| !is_mapped(&c.label))
            .collect();
        let drawn = draws.len();
        let nearest = |r: fn(&SimulatedFit) -> Option<f64>| {
            shown(draws.iter().filter_map(|c| r(c)).reduce(f64::min))
        };
        let (step, point) = (self.mapping.iter())
            .find_map(|s| Some((s, s.points.iter().find(|p| p.label == self.chosen)?)))
            .map_or(("?".to_string(), 1.0), |(s, p)| {
                (s.anchor.clone(), p.fraction)
            });
        let map = match map_failure {
            None => format!("the MAP draw at {map}"),
            Some(e) => format!("EnergyPlus could not simulate the MAP draw: {e}"),
        };
        let drawn_fit = if draws
            .iter()
            .any(|c| c.limit_ratio.is_some_and(|r| r <= 1.0))
        {
            format!(
                "EnergyPlus passes Guideline 14 hourly at some of the {drawn} posterior draws it \
                 simulated and misses its monthly criteria at each of those (the nearest inside \
                 the monthly limits at {}; {map} of the hourly ones)",
                nearest(|c| (c.limit_ratio? <= 1.0).then_some(c.monthly_limit_ratio?)),
            )
        } else {
            format!(
                "EnergyPlus fails Guideline 14 hourly at every one of the {drawn} posterior draws \
                 it simulated (the best at {} of the limits; {map})",
                nearest(|c| c.limit_ratio)
            )
        };
        let hourly = shown(self.ratio_of(&self.chosen));
        let fit = match self.monthly_of(&self.chosen) {
            Some(m) if m <= 1.0 => {
                format!("{hourly} of the hourly limits and {m:.2} of the monthly ones")
            }
            Some(m) => format!("{hourly} of the hourly limits (the monthly ones at {m:.2})"),
            None => format!("{hourly} of the limits"),
        };
        let d = self.outside_interval.len();
        let outside = if d == 0 {
            "every parameter lies inside the posterior's 90 % interval".to_string()
        } else {
            format!(
                "{d} parameter(s) lie outside the posterior's 90 % interval ({})",
                self.outside_interval.join(", ")
            )
        };
        format!(
            "{drawn_fit}; output space mapping from {step} (the surrogate corrected by \
             EnergyPlus's hourly difference there) found {}, {point:.2} of the way to the \
             corrected surrogate's mode, where EnergyPlus's worst meter is at {fit}: it is the \
             estimate. It is not a posterior draw: {outside}",
            self.chosen,
        )
    }

    /// The hourly limit ratio of the candidate labelled `label`, if it ran with metrics.
    fn ratio_of(&self, label: &str) -> Option<f64> {
        self.fit_of(label).and_then(|c| c.limit_ratio)
    }

    /// The monthly limit ratio of the candidate labelled `label`, if it ran with monthly
    /// figures.
    fn monthly_of(&self, label: &str) -> Option<f64> {
        self.fit_of(label).and_then(|c| c.monthly_limit_ratio)
    }

    /// The candidate labelled `label`.
    fn fit_of(&self, label: &str) -> Option<&SimulatedFit> {
        self.candidates.iter().find(|c| c.label == label)
    }
}

/// A limit ratio as the sentences show it: two decimals, `?` where there is none.
fn shown(r: Option<f64>) -> String {
    r.map_or("?".to_string(), |r| format!("{r:.2}"))
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// A choice of `chosen` among the MAP draw (1.6 of the hourly limits) and two predictive
    /// draws (0.9, 0.7).
    pub(crate) fn choice(chosen: &str) -> EstimateChoice {
        EstimateChoice {
            chosen: chosen.into(),
            candidates: [
                ("calibrated", 1.6),
                ("predictive_00", 0.9),
                ("predictive_01", 0.7),
            ]
            .iter()
            .map(|(l, r)| SimulatedFit {
                label: l.to_string(),
                limit_ratio: Some(*r),
                monthly_limit_ratio: None,
            })
            .collect(),
            mapping: vec![],
            outside_interval: vec![],
        }
    }

    #[test]
    fn a_mapped_point_that_fits_best_is_described_as_no_posterior_draw() {
        let mut c = choice("mapped_02");
        c.candidates[1].limit_ratio = Some(1.9);
        c.candidates[2].limit_ratio = Some(2.1);
        c.candidates.push(SimulatedFit {
            label: "mapped_01".into(),
            limit_ratio: Some(1.3),
            monthly_limit_ratio: None,
        });
        c.candidates.push(SimulatedFit {
            label: "mapped_02".into(),
            limit_ratio: Some(0.85),
            monthly_limit_ratio: None,
        });
        c.mapping = vec![MappingStep::new(
            ("predictive_00", &[1.0]),
            vec![2.0],
            &[0.5, 1.0],
            1,
        )];
        c.outside_interval = vec!["shgc".into()];
        let text = c.describe(None);
        assert!(
            text.contains("at every one of the 3 posterior draws it simulated (the best at 1.60")
                && text.contains("the MAP draw at 1.60")
                && text.contains("from predictive_00")
                && text.contains("found mapped_02, 1.00 of the way")
                && text.contains("worst meter is at 0.85 of the limits")
                && text.contains("1 parameter(s) lie outside the posterior's 90 % interval (shgc)"),
            "{text}"
        );
        // The MAP draw passes hourly and misses monthly, as every draw does: the mapped point
        // that passes both.
        for (label, hourly, monthly) in [
            ("calibrated", 0.8, 1.3),
            ("mapped_01", 0.97, 2.19),
            ("mapped_02", 0.85, 0.9),
        ] {
            let f = c.candidates.iter_mut().find(|f| f.label == label).unwrap();
            (f.limit_ratio, f.monthly_limit_ratio) = (Some(hourly), Some(monthly));
        }
        let text = c.describe(None);
        assert!(
            text.contains(
                "passes Guideline 14 hourly at some of the 3 posterior draws it simulated and \
                 misses its monthly criteria at each of those (the nearest inside the monthly \
                 limits at 1.30; the MAP draw at 0.80 of the hourly ones)"
            ) && text.contains(
                "worst meter is at 0.85 of the hourly limits and 0.90 of the monthly ones"
            ),
            "{text}"
        );
    }
}

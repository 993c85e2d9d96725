//! The last stage: `summary.json`, the calibrated model a user takes away, and the CSV files
//! of draws, hourly outputs and predictive bands.

use bemcal_stats::convergence::Convergence;
use bemcal_stats::lhs::Design;
use bemcal_stats::summary::PosteriorSummary;
use serde::{Deserialize, Serialize};

use crate::calibration::Calibration;
use crate::chain_summary::ChainSummary;
use crate::chains::MovedChain;
use crate::design::read_outcome;
use crate::error::{write_atomic, Error};
use crate::metrics::OutputMetrics;
use crate::output::timestamps;
use crate::project::Estimate;
use crate::replacement::{Attempt, FailureGroup, Outcome};

/// Wall time of each stage, s.
#[derive(Debug, Clone, Default, Serialize, Deserialize, schemars::JsonSchema)]
pub struct Timings {
    /// The Latin hypercube and its spares.
    #[serde(deserialize_with = "bemcal_stats::nan::null_as_nan")]
    #[schemars(with = "bemcal_stats::nan::NumberOrNull")]
    pub design_s: f64,
    /// EnergyPlus at the design points, replacements included.
    #[serde(deserialize_with = "bemcal_stats::nan::null_as_nan")]
    #[schemars(with = "bemcal_stats::nan::NumberOrNull")]
    pub simulations_s: f64,
    /// Training sets and surrogate training, every round's.
    #[serde(deserialize_with = "bemcal_stats::nan::null_as_nan")]
    #[schemars(with = "bemcal_stats::nan::NumberOrNull")]
    pub training_s: f64,
    /// The chains, every round's, extensions included.
    #[serde(deserialize_with = "bemcal_stats::nan::null_as_nan")]
    #[schemars(with = "bemcal_stats::nan::NumberOrNull")]
    pub chains_s: f64,
    /// Summarising the final chains (posterior summary, draws and predictive bands).
    #[serde(deserialize_with = "bemcal_stats::nan::null_as_nan")]
    #[schemars(with = "bemcal_stats::nan::NumberOrNull")]
    pub summary_s: f64,
    /// EnergyPlus at the estimate (or its fallbacks), the initial model and the predictive
    /// draws, with Guideline 14.
    #[serde(deserialize_with = "bemcal_stats::nan::null_as_nan")]
    #[schemars(with = "bemcal_stats::nan::NumberOrNull")]
    pub validation_s: f64,
    /// Refinement rounds: simulating posterior draws (their retraining is in `training_s`,
    /// their preliminary chains in `chains_s`).
    #[serde(default, deserialize_with = "bemcal_stats::nan::null_as_nan")]
    #[schemars(with = "bemcal_stats::nan::NumberOrNull")]
    pub refinement_s: f64,
    /// The measures' savings (`[savings] with_calibration`): EnergyPlus with and without each
    /// measure at posterior draws; 0 without them.
    #[serde(default, deserialize_with = "bemcal_stats::nan::null_as_nan")]
    #[schemars(with = "bemcal_stats::nan::NumberOrNull")]
    pub savings_s: f64,
    /// The whole calibration.
    #[serde(deserialize_with = "bemcal_stats::nan::null_as_nan")]
    #[schemars(with = "bemcal_stats::nan::NumberOrNull")]
    pub total_s: f64,
}

/// Exit status of `bemcal calibrate` (and `bemcal portfolio` when a building's run is
/// affected) when the calibration finished but its chains missed a convergence target: every
/// output was written, and `summary.json` `converged` is false. 1 stays "failed".
pub const NOT_CONVERGED_EXIT: i32 = 3;

fn default_year() -> bemcal_weather::grid::GridYear {
    bemcal_weather::grid::GridYear::calendar(2021)
}

/// `summary.json`.
#[derive(Debug, Clone, Serialize, Deserialize, schemars::JsonSchema)]
pub struct Summary {
    /// The project's name.
    pub project: String,
    /// The grid year of the meters and the model: `2017`, or `"2017-04"` for twelve months from
    /// April 2017.
    #[serde(default = "default_year")]
    pub year: bemcal_weather::grid::GridYear,
    /// What reading the meters decided or dropped (hour convention, daylight saving, rows
    /// outside the year, 29 February, duplicates).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub meter_notes: Vec<String>,
    /// The EPW built from `[measured_weather]`: where each field came from.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub measured_weather: Option<bemcal_weather::measured::BuildReport>,
    /// Loads in the meters that the model does not have, added to its outputs (`[[bases]]`).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub bases: Vec<crate::bases::BaseReport>,
    /// The calibrated outputs: the model outputs that have a meter.
    pub outputs: Vec<String>,
    /// Those of `outputs` whose meters the likelihood left out (`[[meters.columns]] fit =
    /// false`): compared in validation and model form, not fitted.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub not_fitted: Vec<String>,
    /// The calibrated parameters' units and priors.
    pub parameters: Vec<ParameterReport>,
    /// The calibrated parameters' posterior from the chains on the surrogate (physical units):
    /// per-parameter statistics, the MAP draw, correlated pairs, R-hat and ESS.
    pub posterior: PosteriorSummary,
    /// Model-discrepancy standard deviation per output, kWh (`{output: value}`).
    #[serde(with = "bemcal_named")]
    #[schemars(with = "std::collections::BTreeMap<String, f64>")]
    pub sigma_delta_kwh: Vec<(String, f64)>,
    /// AR(1) coefficient of the hourly residuals at the MAP, per output (empty with iid).
    #[serde(default, with = "bemcal_named")]
    #[schemars(with = "std::collections::BTreeMap<String, f64>")]
    pub residual_ar1: Vec<(String, f64)>,
    /// What the likelihood's model-form discrepancy (`mcmc.discrepancy`) carries at the MAP,
    /// per fitted meter; absent without it.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub discrepancy_carried: Vec<crate::carried::Carried>,
    /// The surrogate's held-out error per output, kWh (`{output: value}`).
    #[serde(with = "bemcal_named")]
    #[schemars(with = "std::collections::BTreeMap<String, f64>")]
    pub sigma_eta_kwh: Vec<(String, f64)>,
    /// How the surrogate's first training started, where `[surrogate] pretrained` named a
    /// pretrained network: from it, or from random weights and why.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub surrogate_start: Option<crate::pretrained::SurrogateStart>,
    /// Acceptance rate after burn-in, per chain (of the final chains).
    pub acceptance_rate: Vec<f64>,
    /// Times the final chains were extended because a convergence target was missed.
    #[serde(default)]
    pub chain_extensions: u32,
    /// The likelihood's temperature of the final chains (`mcmc.temperature`): they sample
    /// `p(theta) L(theta)^(1/T)`; with `measured_at_round`, `T` was measured from the
    /// surrogate's error at that refinement round's points.
    #[serde(default = "crate::posterior::ChainTemperature::one")]
    pub temperature: crate::posterior::ChainTemperature,
    /// Chains started in the best optimum's mode instead of their own (`mcmc.restart_below`).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub moved_chains: Vec<MovedChain>,
    /// Chains whose independence kernel was switched off after burn-in (accepted under 1 %,
    /// `stats::mcmc::INDEPENDENCE_MIN_ACCEPTANCE`): their recorded draws are random-walk steps.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub independence_dropped: Vec<usize>,
    /// Which posterior point the estimate is (`[validation] estimate`).
    pub estimate: Estimate,
    /// Set when the estimate is not the statistic's own point: EnergyPlus failed there and the
    /// next-best draw was validated instead, or (`best_simulated`) it fits a predictive draw
    /// better.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub estimate_note: Option<String>,
    /// With `estimate = "best_simulated"`: each draw EnergyPlus simulated, its worst fitted
    /// meter's ratio to Guideline 14's hourly limits, and the one chosen.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub estimate_choice: Option<crate::estimate::EstimateChoice>,
    /// The calibrated parameters at the estimate (`{parameter: value}`, in the model's order).
    #[serde(with = "bemcal_named")]
    #[schemars(with = "std::collections::BTreeMap<String, f64>")]
    pub calibrated_values: Vec<(String, f64)>,
    /// Guideline 14 of EnergyPlus at the estimate against the meters, per output.
    pub validation: Vec<OutputMetrics>,
    /// The same for the initial model (the prior modes); empty with `validation.initial =
    /// false`.
    pub initial: Vec<OutputMetrics>,
    /// The held-out period (`[validation] holdout`): its hours fit nothing; `validation`'s
    /// `held_out` judges the model on them.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub holdout: Option<HoldoutReport>,
    /// Hourly predictive intervals from EnergyPlus at posterior draws and their coverage of
    /// the measured hours, in-sample and held out (`validation/predictive_intervals.csv`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub predictive: Option<crate::predictive::PredictiveReport>,
    /// Whether the calibrated model can reach each meter, where its residuals sit, what to
    /// change, and an additive discrepancy reported apart from the parameters
    /// (`validation/discrepancy.csv`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub model_form: Option<crate::model_form::ModelFormReport>,
    /// Guideline 14 of the surrogate's prediction at the estimate against the meters: next to
    /// `validation` (EnergyPlus at the same point) it separates surrogate error from
    /// calibration error (the surrogate fitting the meters while EnergyPlus does not means the
    /// surrogate, not the posterior, is the bottleneck: more design points or training).
    #[serde(default)]
    pub surrogate_at_estimate: Vec<OutputMetrics>,
    /// The posterior's intervals with the surrogate's error carried in: the intervals to read
    /// (`posterior`'s are the chains' own, on the surrogate, narrower by the surrogate's error
    /// in parameter space). Absent without a refinement round, which measures that error.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub surrogate_error: Option<crate::surrogate_error::SurrogateError>,
    /// Every parameter meets `mcmc.rhat_target` and `mcmc.ess_target` (`convergence`); when
    /// false the estimate and intervals are not to be trusted, and `bemcal calibrate` exits
    /// with status 3 ([`NOT_CONVERGED_EXIT`]).
    pub converged: bool,
    /// The verdict behind `converged`: targets, worst figures, the parameters short of them.
    #[serde(default)]
    pub convergence: Convergence,
    /// Points of the settled design (the hypercube's slots with a simulated point), before
    /// refinement.
    pub design_points: usize,
    /// What the hypercube's constraint repair changed.
    pub design_repair: bemcal_stats::lhs::RepairReport,
    /// What EnergyPlus made of the design: failed runs, replacements, usable warnings.
    #[serde(default)]
    pub design: DesignReport,
    /// The final surrogate's held-out accuracy (its metadata's `held_out`: the held-out design
    /// points and, per output, RMSE and mean in kWh, CV-RMSE and NMBE in %).
    pub surrogate_held_out: serde_json::Value,
    /// Surrogate refinement rounds (empty without `[refine]`).
    #[serde(default)]
    pub refinement: Vec<crate::refine::RefineRound>,
    /// Wall time of each stage, s.
    pub timings: Timings,
    /// Retrofit measures' savings over posterior draws (`bemcal savings`; absent until run).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub savings: Option<crate::measures::SavingsReport>,
}

impl Summary {
    /// The outputs read as bills, with how many bills judge each (the validation's).
    pub fn billed_outputs(&self) -> Vec<(&str, usize)> {
        (self.validation.iter())
            .filter(|v| v.resolution == crate::metrics::Resolution::Bills)
            .map(|v| (v.output.as_str(), v.metrics.n))
            .collect()
    }
}

/// The JSON Schema of `summary.json`, from the types that write it and that every reader in
/// Rust reads it with (`bemcal reference` writes it to `docs/reference/summary.schema.json`).
/// A number that may be `null` is NaN: a statistic that could not be computed.
pub fn summary_schema() -> schemars::Schema {
    let mut s = schemars::schema_for!(Summary);
    s.insert("title".into(), "bemcal summary.json".into());
    s
}

/// The held-out period in `summary.json`.
#[derive(Debug, Clone, Serialize, Deserialize, schemars::JsonSchema)]
pub struct HoldoutReport {
    /// As the project wrote it.
    pub period: String,
    /// Hour slots held out.
    pub hours: usize,
    /// Per output, the measured hours held out and those left to calibrate with.
    #[serde(with = "bemcal_named")]
    #[schemars(with = "std::collections::BTreeMap<String, MeasuredHours>")]
    pub measured_hours: Vec<(String, MeasuredHours)>,
}

/// Measured hours of one meter on either side of the held-out period.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct MeasuredHours {
    /// Measured hours in the held-out period (they judge the model).
    pub held_out: usize,
    /// Measured hours left to calibrate with.
    pub calibration: usize,
}

impl HoldoutReport {
    fn of(inp: &crate::inputs::Inputs) -> Option<HoldoutReport> {
        let h = inp.held_out.as_ref()?;
        let count = |v: &[f64]| v.iter().filter(|x| x.is_finite()).count();
        Some(HoldoutReport {
            period: h.period.clone(),
            hours: h.hour_count(),
            measured_hours: inp
                .outputs
                .iter()
                .enumerate()
                .map(|(k, o)| {
                    let hours = MeasuredHours {
                        held_out: count(&h.measured[k]),
                        calibration: count(&inp.measured[k]),
                    };
                    (o.clone(), hours)
                })
                .collect(),
        })
    }
}

/// The design stage's record in `summary.json`: which design points EnergyPlus could not
/// simulate and why, what replaced them, and the Severe messages accepted as usable.
#[derive(Debug, Clone, Default, Serialize, Deserialize, schemars::JsonSchema)]
pub struct DesignReport {
    /// Hypercube points (slots).
    pub slots: usize,
    /// Slots with a simulated point (trained on).
    pub simulated: usize,
    /// Every failed EnergyPlus run: slot, values and error text.
    pub failed: Vec<Attempt>,
    /// Failures grouped by reason, largest first.
    pub reasons: Vec<FailureGroup>,
    /// Slots simulated at a spare point after failing.
    pub replaced: Vec<usize>,
    /// Slots left without a point.
    pub dropped: Vec<usize>,
    /// What a user could change (from the reasons and where the failures lie in the priors).
    pub suggestions: Vec<String>,
    /// Severe messages after which a design point's results were used, with why.
    pub notes: Vec<PointNote>,
    /// Where the chains refused proposals because EnergyPlus failed there.
    #[serde(default)]
    pub invalid_region: crate::plan::InvalidRegion,
}

/// A Severe message accepted as usable at a design point.
#[derive(Debug, Clone, Serialize, Deserialize, schemars::JsonSchema)]
pub struct PointNote {
    /// The design point's hypercube slot.
    pub point: usize,
    /// The message's first line, with why the results stand.
    pub message: String,
}

impl DesignReport {
    /// The report of a settled design; usable messages are read from the saved runs.
    pub fn new(cal: &Calibration, outcome: &Outcome) -> DesignReport {
        let dir = cal.simulations_dir();
        let plan = &cal.inputs.plan;
        DesignReport {
            slots: outcome.slot_count(),
            simulated: outcome.slots.len(),
            failed: outcome.failed.clone(),
            reasons: outcome.reasons(),
            replaced: outcome.replaced.iter().map(|r| r.0).collect(),
            dropped: outcome.dropped.clone(),
            suggestions: crate::replacement::suggestions(
                &plan.priors,
                &plan.calibrated,
                &outcome.failed,
            ),
            notes: outcome
                .slots
                .iter()
                .flat_map(|&point| {
                    crate::design::point_notes(&dir, point)
                        .into_iter()
                        .map(move |message| PointNote { point, message })
                })
                .collect(),
            invalid_region: plan.invalid.clone(),
        }
    }
}

/// A parameter's prior next to its posterior.
#[derive(Debug, Clone, Serialize, Deserialize, schemars::JsonSchema)]
pub struct ParameterReport {
    /// The calibrated parameter.
    pub name: String,
    /// Its unit, as the model declares it (empty where it declares none).
    pub unit: String,
    /// Its prior's minimum (the parameter's unit).
    #[serde(deserialize_with = "bemcal_stats::nan::null_as_nan")]
    #[schemars(with = "bemcal_stats::nan::NumberOrNull")]
    pub prior_min: f64,
    /// Its prior's mode (the parameter's unit).
    #[serde(deserialize_with = "bemcal_stats::nan::null_as_nan")]
    #[schemars(with = "bemcal_stats::nan::NumberOrNull")]
    pub prior_mode: f64,
    /// Its prior's maximum (the parameter's unit).
    #[serde(deserialize_with = "bemcal_stats::nan::null_as_nan")]
    #[schemars(with = "bemcal_stats::nan::NumberOrNull")]
    pub prior_max: f64,
}

/// Assembles `summary.json` from the stages' results and writes it, with the calibrated model
/// and the bases' file.
pub fn write_summary(
    cal: &Calibration,
    design: &Design,
    chains: &ChainSummary,
    validation: Vec<OutputMetrics>,
    initial: Vec<OutputMetrics>,
    timings: Timings,
) -> Result<Summary, Error> {
    let inp = &cal.inputs;
    // EnergyPlus at the estimate and at the predictive draws, read once for both judges.
    let at_estimate = crate::predictive::run_at_estimate(cal, chains);
    let draws = crate::predictive::draw_runs(cal, chains);
    let summary = Summary {
        project: cal.project.name.clone(),
        year: inp.year,
        meter_notes: inp.meter_notes.clone(),
        measured_weather: inp.measured_weather.clone(),
        bases: inp.base_reports.clone(),
        outputs: inp.outputs.clone(),
        not_fitted: inp.not_fitted(),
        parameters: inp
            .plan
            .calibrated
            .iter()
            .zip(&inp.plan.priors)
            .zip(&inp.plan.units)
            .map(|((n, p), u)| ParameterReport {
                name: n.clone(),
                unit: u.clone(),
                prior_min: p.min(),
                prior_mode: p.mode(),
                prior_max: p.max(),
            })
            .collect(),
        converged: chains.convergence.converged,
        convergence: chains.convergence.clone(),
        posterior: chains.posterior.clone(),
        sigma_delta_kwh: chains.sigma_delta_kwh.clone(),
        residual_ar1: chains.residual_ar1.clone(),
        discrepancy_carried: chains.discrepancy_carried.clone(),
        sigma_eta_kwh: inp
            .outputs
            .iter()
            .cloned()
            .zip(chains.sigma_eta.iter().copied())
            .collect(),
        surrogate_start: crate::pretrained::read_start(&[
            &cal.out.pretrained(),
            &cal.surrogate_dir(),
        ]),
        acceptance_rate: chains.acceptance.clone(),
        chain_extensions: chains.extensions,
        temperature: chains.temperature,
        estimate: cal.project.validation.estimate,
        estimate_note: chains.estimate_note.clone(),
        estimate_choice: chains.estimate_choice.clone(),
        moved_chains: chains.moved_chains.clone(),
        independence_dropped: chains.independence_dropped.clone(),
        calibrated_values: inp
            .plan
            .calibrated
            .iter()
            .cloned()
            .zip(chains.estimate.clone())
            .collect(),
        validation,
        initial,
        holdout: HoldoutReport::of(inp),
        predictive: crate::predictive::assess(cal, chains, at_estimate.as_ref(), &draws)?,
        model_form: at_estimate
            .as_ref()
            .map(|e| crate::model_form::report(cal, e, &draws, &chains.posterior))
            .transpose()?,
        surrogate_at_estimate: chains.surrogate_at_estimate.clone(),
        surrogate_error: chains.surrogate_error.clone(),
        design_points: design.points.len(),
        design_repair: design.repair,
        design: read_outcome(&cal.simulations_dir())
            .map(|o| DesignReport::new(cal, &o))
            .unwrap_or_default(),
        surrogate_held_out: chains.held_out.clone(),
        refinement: cal.refine_log()?.rounds,
        timings,
        savings: None,
    };
    write_calibrated_model(cal, &chains.estimate)?;
    write_bases_csv(cal)?;
    let json = serde_json::to_vec_pretty(&summary).map_err(|e| Error::Config(e.to_string()))?;
    write_atomic(&cal.out.summary_json(), &json)?;
    Ok(summary)
}

/// The calibrated model a user takes away: `calibrated.idf` (the model at `estimate`, the
/// validated calibrated values, with the fixed values) and `calibrated.toml` (every parameter
/// value, readable by `bemcal simulate --values`).
pub fn write_calibrated_model(cal: &Calibration, estimate: &[f64]) -> Result<(), Error> {
    let inp = &cal.inputs;
    let values = inp.plan.values(estimate);
    let idf = inp.model.instantiate(&values, inp.runner.idd())?;
    let scratch = cal.out.join("calibrated.expand");
    let _ = std::fs::remove_dir_all(&scratch);
    let simulated = inp.runner.simulated_input(&idf, &scratch)?;
    let _ = std::fs::remove_dir_all(&scratch);
    write_atomic(
        &cal.out.calibrated_idf(),
        simulated
            .to_text_with_field_names(inp.runner.idd())
            .as_bytes(),
    )?;
    // The project by its file name, from its own folder: a run through a coordinator loads a
    // copy of it, whose path means nothing where the results are downloaded.
    let project_file = cal
        .project
        .path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "project.toml".into());
    let mut toml = format!(
        "# Parameter values of the calibrated model of '{}' (estimate: {}; calibrated and fixed).\n\
         # Simulate it from the project's folder (its model with the priors' schedule intervals,\n\
         # and its weather, as the calibration loaded them):\n\
         #   bemcal simulate --project {project_file} --values calibrated.toml --out hourly.csv\n\
         # or run EnergyPlus on calibrated.idf (HVAC templates expanded) with weather file {}.\n",
        cal.project.name,
        serde_json::to_value(cal.project.validation.estimate)
            .ok()
            .and_then(|v| v.as_str().map(str::to_string))
            .unwrap_or_default(),
        inp.weather_path
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default()
    );
    for (name, v) in &values {
        toml.push_str(&format!("{name} = {v}\n"));
    }
    write_atomic(&cal.out.calibrated_toml(), toml.as_bytes())
}

/// `validation/bases.csv`: the hourly bases of the outputs that have one (`[[bases]]`), which
/// the report adds to the EnergyPlus runs before drawing them against the meters.
fn write_bases_csv(cal: &Calibration) -> Result<(), Error> {
    let inp = &cal.inputs;
    let with: Vec<usize> = (0..inp.outputs.len())
        .filter(|&k| inp.has_base(k))
        .collect();
    if with.is_empty() {
        return Ok(());
    }
    let mut s = String::from("timestamp");
    for &k in &with {
        s.push_str(&format!(",{}", inp.outputs[k]));
    }
    s.push('\n');
    for (t, ts) in timestamps(inp.year, inp.bases[0].len()) {
        s.push_str(&ts);
        for &k in &with {
            let b = inp.bases[k][t];
            s.push_str(&if b.is_finite() {
                format!(",{b:.6}")
            } else {
                ",".into()
            });
        }
        s.push('\n');
    }
    write_atomic(&cal.out.bases_csv(), s.as_bytes())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The names of the properties under `schema` (every object, definitions included) whose
    /// schema says `number` alone.
    fn numbers_that_refuse_null(schema: &serde_json::Value, at: &str, out: &mut Vec<String>) {
        match schema {
            serde_json::Value::Object(m) => {
                if let Some(serde_json::Value::Object(props)) = m.get("properties") {
                    for (name, p) in props {
                        if p.get("type") == Some(&serde_json::json!("number")) {
                            out.push(format!("{at}.{name}"));
                        }
                    }
                }
                for (k, v) in m {
                    numbers_that_refuse_null(v, &format!("{at}/{k}"), out);
                }
            }
            serde_json::Value::Array(a) => {
                a.iter().for_each(|v| numbers_that_refuse_null(v, at, out))
            }
            _ => {}
        }
    }

    #[test]
    fn every_number_field_of_summary_json_reads_null_as_nan() {
        let schema = serde_json::to_value(summary_schema()).unwrap();
        let mut refused = vec![];
        numbers_that_refuse_null(&schema, "", &mut refused);
        assert!(
            refused.is_empty(),
            "serde_json writes NaN as null: give these f64 fields \
             #[serde(deserialize_with = \"bemcal_stats::nan::null_as_nan\")] and \
             #[schemars(with = \"bemcal_stats::nan::NumberOrNull\")]: {refused:?}"
        );
        assert_eq!(schema["title"], "bemcal summary.json");
        let required = schema["required"].as_array().unwrap();
        for name in ["outputs", "posterior", "timings"] {
            assert!(required.contains(&name.into()), "{name}");
        }
        let metrics = &schema["$defs"]["OutputMetrics"]["required"];
        for name in ["output", "nmbe", "cv_rmse"] {
            assert!(
                metrics.as_array().unwrap().contains(&name.into()),
                "a number that may be null stays required: {name}, {metrics}"
            );
        }
        for name in ["holdout", "convergence", "year"] {
            assert!(!required.contains(&name.into()), "{name}");
        }
    }
}

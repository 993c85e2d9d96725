//! Stage 7c, model form: for each meter, whether the calibrated model can reach it, where its
//! hourly residuals sit (hour of day, working or off day, month, outdoor temperature), what a
//! user could change, and an additive discrepancy fitted to the residuals and reported apart
//! from the parameters (`summary.json` `model_form`, `validation/discrepancy.csv`).
//!
//! A calibration that passes its chains' checks can still leave a meter out of the model's
//! reach (a system the model lacks, a meter that holds more than the model's output, a prior
//! that excludes the building): this stage says so in words instead of leaving a failed
//! Guideline 14 line to be read. Numerics in [`bemcal_stats::model_form`]; the words (which
//! factor points to which part of the model) are this module's rule, [`findings`].

use bemcal_energyplus::HourlyOutputs;
use bemcal_stats::metrics::{g14, G14Metrics};
use bemcal_stats::model_form::{
    additive_discrepancy, levers, marginal_slopes, partial_fit, pattern, piled_at_bound,
    quantile_bands, reach, slope, Bound, FactorGroups, PartialFit, Pattern, Reach, Verdict,
};
use bemcal_stats::summary::PosteriorSummary;
use serde::{Deserialize, Serialize};

use crate::calibration::Calibration;
use crate::error::{write_atomic, Error};
use crate::output::timestamps;

/// Outdoor temperature bands (equal counts of hours) the residuals are grouped by.
pub const TEMPERATURE_BANDS: usize = 10;

/// A pattern is named in the findings when its grouping explains at least this share of the
/// residuals' variance (`eta^2`).
pub const PATTERN_ETA2: f64 = 0.10;

/// A level miss is called a constant offset when the residuals' mean carries at least this
/// share of their mean square.
pub const OFFSET_SHARE: f64 = 0.5;

/// The model is said to follow the weather when the outdoor temperature explains at least
/// this share of its hourly variation beyond the calendar ([`WeatherShare`]) ...
pub const WEATHER_SHARE_MODEL: f64 = 0.2;

/// ... and the meter hardly to, when both the share the temperature explains of the meter and
/// the size of what it explains, relative to the meter's mean, are below this fraction of the
/// model's. The share alone would count a meter's noise against it, the size alone the
/// model's level (a model at three times the meter's level varies three times as much).
pub const WEATHER_FRACTION: f64 = 0.5;

/// The levers named in an out-of-reach meter's finding (all count in the together figure).
pub const LEVERS_NAMED: usize = 3;

const MONTHS: [&str; 12] = [
    "Jan", "Feb", "Mar", "Apr", "May", "Jun", "Jul", "Aug", "Sep", "Oct", "Nov", "Dec",
];

/// What the residuals are grouped by.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum Factor {
    /// Hour of the day, local standard time (24 groups).
    HourOfDay,
    /// Working day or off day (weekend, holiday, or the meters' off days).
    DayKind,
    /// Calendar month.
    Month,
    /// Outdoor dry-bulb temperature, [`TEMPERATURE_BANDS`] bands of equal hours.
    OutdoorTemperature,
}

/// The model-form record in `summary.json`.
#[derive(Debug, Clone, Serialize, Deserialize, schemars::JsonSchema)]
pub struct ModelFormReport {
    /// Posterior draws of EnergyPlus the reach is judged with (besides the estimate).
    pub draws: usize,
    /// Each meter's model form (a meter with too few hours to judge is left out).
    pub meters: Vec<MeterForm>,
    /// Parameters whose posterior median lies against a prior bound.
    pub piled: Vec<PiledParameter>,
    /// The piled parameters in words, with what to change ([`PiledParameter::finding`]).
    pub parameter_findings: Vec<String>,
}

/// One meter's model form, over the calibration period's measured hours.
#[derive(Debug, Clone, Serialize, Deserialize, schemars::JsonSchema)]
pub struct MeterForm {
    /// The calibrated output (and its meter).
    pub output: String,
    /// The meter's total against the model's (with its base) at the estimate and at the
    /// posterior draws, kWh, and the verdict: whether the model can reach the meter.
    pub reach: Reach,
    /// The residuals (measured - model, kWh per hour) grouped by each factor.
    pub patterns: Vec<FactorPattern>,
    /// Slope of the residuals on the outdoor dry-bulb temperature, kWh per hour per K.
    #[serde(deserialize_with = "bemcal_stats::nan::null_as_nan")]
    #[schemars(with = "bemcal_stats::nan::NumberOrNull")]
    pub temperature_slope_kwh_per_k: f64,
    /// The additive discrepancy fitted to the residuals at the estimate.
    pub discrepancy: Discrepancy,
    /// How closely the meter and the model follow the weather file's outdoor temperature
    /// (absent in summaries written before it was measured).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub weather: Option<WeatherShare>,
    /// For a meter out of reach, what the calibrated parameters could do about it within
    /// their priors ([`Levers`]); absent for a meter reached, or where the design's runs
    /// could not be read.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub levers: Option<Levers>,
    /// In words: whether the model reaches the meter, and what to look at if not.
    pub findings: Vec<String>,
}

/// How far each calibrated parameter moves a meter's total toward the meter within its prior,
/// to first order: slopes of the total over the EnergyPlus runs of the design and the
/// refinement rounds ([`bemcal_stats::model_form::marginal_slopes`]), from each parameter's
/// posterior median to the prior bound on the meter's side ([`bemcal_stats::model_form::levers`]).
#[derive(Debug, Clone, Serialize, Deserialize, schemars::JsonSchema)]
pub struct Levers {
    /// EnergyPlus runs the slopes are taken over.
    pub runs: usize,
    /// The meter's total minus the model's at the estimate, kWh (what closing it needs).
    #[serde(deserialize_with = "bemcal_stats::nan::null_as_nan")]
    #[schemars(with = "bemcal_stats::nan::NumberOrNull")]
    pub gap_kwh: f64,
    /// The parameters that move the total toward the meter, largest first.
    pub parameters: Vec<MeterLever>,
}

/// One parameter as a lever on a meter's total ([`Levers`]).
#[derive(Debug, Clone, Serialize, Deserialize, schemars::JsonSchema)]
pub struct MeterLever {
    /// The calibrated parameter.
    pub parameter: String,
    /// Its posterior median (the parameter's unit).
    #[serde(deserialize_with = "bemcal_stats::nan::null_as_nan")]
    #[schemars(with = "bemcal_stats::nan::NumberOrNull")]
    pub median: f64,
    /// The prior bound on the meter's side.
    pub bound: Bound,
    /// That bound's value.
    #[serde(deserialize_with = "bemcal_stats::nan::null_as_nan")]
    #[schemars(with = "bemcal_stats::nan::NumberOrNull")]
    pub bound_value: f64,
    /// The total's change from the median to the bound, kWh.
    #[serde(deserialize_with = "bemcal_stats::nan::null_as_nan")]
    #[schemars(with = "bemcal_stats::nan::NumberOrNull")]
    pub moves_kwh: f64,
    /// The value it alone would need to close the gap (the parameter's unit).
    #[serde(deserialize_with = "bemcal_stats::nan::null_as_nan")]
    #[schemars(with = "bemcal_stats::nan::NumberOrNull")]
    pub alone_needs: f64,
    /// Its prior's range (max - min), the scale of how far beyond it `alone_needs` lies.
    #[serde(deserialize_with = "bemcal_stats::nan::null_as_nan")]
    #[schemars(with = "bemcal_stats::nan::NumberOrNull")]
    pub prior_range: f64,
}

impl Levers {
    /// In words: the largest levers, what all of them together move against the gap, and
    /// whether the priors can reach the meter at all.
    pub fn finding(&self) -> String {
        let mwh = |x: f64| x / 1000.0;
        if self.parameters.is_empty() {
            return format!(
                "no calibrated parameter moves it toward the meter ({:+.1} MWh needed) within \
                 its prior, to first order over {} EnergyPlus runs: look at the meter's scope, \
                 the weather and the systems the model has",
                mwh(self.gap_kwh),
                self.runs
            );
        }
        let named: Vec<String> = (self.parameters.iter().take(LEVERS_NAMED))
            .map(|l| {
                format!(
                    "{} to its prior's {} bound {:.4} (median {:.4}) {:+.1} MWh",
                    l.parameter,
                    l.bound.as_str(),
                    l.bound_value,
                    l.median,
                    mwh(l.moves_kwh)
                )
            })
            .collect();
        let together: f64 = self.parameters.iter().map(|l| l.moves_kwh).sum();
        let first = &self.parameters[0];
        let verdict = if together.abs() < self.gap_kwh.abs() {
            format!(
                "no setting inside these priors reaches the meter: widen a prior only where a \
                 value beyond is physical ({} alone would need {:.4}, {:.1} times its prior's \
                 range beyond the bound), else look at what the model lacks (the meter's scope, \
                 the weather, a system or a load)",
                first.parameter,
                first.alone_needs,
                (first.alone_needs - first.bound_value).abs() / first.prior_range
            )
        } else {
            "the priors could reach the meter together, yet the posterior stays away: the other \
             meters, or the surrogate's error, hold it"
                .into()
        };
        format!(
            "what would move it, to first order over the {} EnergyPlus runs the surrogate \
             learned from: {}; all {} together {:+.1} MWh of the {:+.1} MWh needed: {verdict}",
            self.runs,
            named.join(", "),
            self.parameters.len(),
            mwh(together),
            mwh(self.gap_kwh)
        )
    }
}

/// The share of the hourly variation beyond the calendar (hour of day by day kind, month) that
/// the outdoor temperature of the weather the model ran with explains
/// ([`bemcal_stats::model_form::partial_fit`], over the meter's calibration hours), for the
/// meter and for the model at the estimate. A model that follows the weather where the meter
/// does not ([`WeatherShare::unlike_the_meters`]) suggests that the weather is not the metered
/// period's (a typical year cannot match actual meters hour by hour, however the parameters
/// are set), or that the meter lacks the model's response to it.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct WeatherShare {
    /// What the outdoor temperature explains of the meter.
    pub meter: PartialFit,
    /// What it explains of the model at the estimate.
    pub model: PartialFit,
    /// Whether the weather was built from measured observations (`[measured_weather]`).
    pub measured_weather: bool,
}

impl WeatherShare {
    /// The rule: the model follows the weather ([`WEATHER_SHARE_MODEL`]), the meter varies
    /// beyond the calendar at all (a flat or dead meter is another finding), and the weather
    /// explains less than [`WEATHER_FRACTION`] of the model's share and relative size of the
    /// meter.
    pub fn unlike_the_meters(&self) -> bool {
        let (meter, model) = (&self.meter, &self.model);
        model.share >= WEATHER_SHARE_MODEL
            && meter.base_rms > 0.01 * meter.mean
            && meter.share < WEATHER_FRACTION * model.share
            && meter.relative_explained() < WEATHER_FRACTION * model.relative_explained()
    }

    /// In words, with what to change.
    pub fn finding(&self) -> String {
        let weather = if self.measured_weather {
            "the measured weather's station (its distance and elevation, its time zone, its \
             filled gaps)"
        } else {
            "the weather file, if it is not the metered period's (a typical year cannot match \
             actual meters hour by hour: calibrate with the metered year's weather, \
             [measured_weather] or `bemcal weather`)"
        };
        format!(
            "the model follows the weather's outdoor temperature ({:.0} % of its hourly \
             variation beyond the hour of the day, the day kind and the month: {:.1} kWh/h \
             RMS), the meter hardly does ({:.0} %: {:.1} kWh/h): {weather}, or a meter that \
             does not respond to the outdoor temperature as the model does (a system or \
             control the model lacks)",
            100.0 * self.model.share,
            self.model.explained_rms,
            100.0 * self.meter.share,
            self.meter.explained_rms
        )
    }
}

/// The residuals grouped by one factor.
#[derive(Debug, Clone, Serialize, Deserialize, schemars::JsonSchema)]
pub struct FactorPattern {
    /// What the residuals are grouped by.
    pub factor: Factor,
    /// The groups' mean residuals (kWh per hour) and the share of the residuals' variance they
    /// explain (`eta^2`).
    #[serde(flatten)]
    pub pattern: Pattern,
}

/// The additive discrepancy `delta(hour of day x day kind) + delta(month) + delta(outdoor
/// temperature band)` fitted to the calibration period's residuals at the estimate
/// (`validation/discrepancy.csv` has it hourly).
#[derive(Debug, Clone, Serialize, Deserialize, schemars::JsonSchema)]
pub struct Discrepancy {
    /// Share of the residuals' mean square it removes.
    #[serde(deserialize_with = "bemcal_stats::nan::null_as_nan")]
    #[schemars(with = "bemcal_stats::nan::NumberOrNull")]
    pub share: f64,
    /// Guideline 14 of model + discrepancy over the calibration period.
    pub corrected: G14Metrics,
    /// The same on the held-out period, where the discrepancy was not fitted.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub held_out: Option<G14Metrics>,
}

/// A parameter piled against a prior bound.
#[derive(Debug, Clone, Serialize, Deserialize, schemars::JsonSchema)]
pub struct PiledParameter {
    /// The calibrated parameter.
    pub name: String,
    /// The prior bound its posterior median lies against.
    pub bound: Bound,
    /// Its posterior median (the parameter's unit).
    #[serde(deserialize_with = "bemcal_stats::nan::null_as_nan")]
    #[schemars(with = "bemcal_stats::nan::NumberOrNull")]
    pub median: f64,
    /// Its prior's minimum (the parameter's unit).
    #[serde(deserialize_with = "bemcal_stats::nan::null_as_nan")]
    #[schemars(with = "bemcal_stats::nan::NumberOrNull")]
    pub prior_min: f64,
    /// Its prior's maximum (the parameter's unit).
    #[serde(deserialize_with = "bemcal_stats::nan::null_as_nan")]
    #[schemars(with = "bemcal_stats::nan::NumberOrNull")]
    pub prior_max: f64,
}

impl PiledParameter {
    /// In words, with what to change.
    pub fn finding(&self) -> String {
        let (which, at) = match self.bound {
            Bound::Lower => ("lower", self.prior_min),
            Bound::Upper => ("upper", self.prior_max),
        };
        format!(
            "{} is piled against its prior's {which} bound (median {:.4} against {at}): widen \
             that prior if a value beyond is physical; if not, it compensates for something the \
             model lacks",
            self.name, self.median
        )
    }
}

/// One factor's group of every hour slot, and the groups' labels.
struct FactorHours {
    factor: Factor,
    group: Vec<usize>,
    labels: Vec<String>,
}

impl FactorHours {
    fn groups(&self) -> FactorGroups<'_> {
        FactorGroups {
            group: &self.group,
            levels: self.labels.len(),
        }
    }
}

/// The hour groups of every factor, for one year's hour slots.
struct Groups {
    /// Hour of day, day kind, month, outdoor temperature band: the patterns, in this order.
    factors: [FactorHours; 4],
    /// Hour of day x day kind (48 groups), the discrepancy's time term.
    hour_by_kind: Vec<usize>,
}

impl Groups {
    fn new(cal: &Calibration) -> Groups {
        let f = &cal.inputs.features;
        let n = f.len();
        let hour: Vec<usize> = (0..n).map(|t| t % 24).collect();
        let kind: Vec<usize> = f
            .day_type
            .iter()
            .map(|d| usize::from(d.is_off_day()))
            .collect();
        let month: Vec<usize> = (0..n)
            .map(|t| bemcal_weather::grid::slot_month(t) as usize - 1)
            .collect();
        let (band, band_labels) = quantile_bands(&f.dry_bulb_c, TEMPERATURE_BANDS);
        let hour_by_kind = hour.iter().zip(&kind).map(|(h, k)| h + 24 * k).collect();
        let hours = |factor, group, labels| FactorHours {
            factor,
            group,
            labels,
        };
        Groups {
            factors: [
                hours(
                    Factor::HourOfDay,
                    hour,
                    (0..24).map(|h| format!("{h:02}")).collect(),
                ),
                hours(
                    Factor::DayKind,
                    kind,
                    vec!["working day".into(), "off day".into()],
                ),
                hours(Factor::Month, month, MONTHS.map(String::from).to_vec()),
                hours(Factor::OutdoorTemperature, band, band_labels),
            ],
            hour_by_kind,
        }
    }

    /// The calendar's terms: hour of day x day kind, month.
    fn calendar_terms(&self) -> [FactorGroups<'_>; 2] {
        let [_, _, month, _] = &self.factors;
        [
            FactorGroups {
                group: &self.hour_by_kind,
                levels: 48,
            },
            month.groups(),
        ]
    }

    /// The weather's term: the outdoor temperature band.
    fn weather_terms(&self) -> [FactorGroups<'_>; 1] {
        [self.factors[3].groups()]
    }

    /// The discrepancy's terms: hour of day x day kind, month, outdoor temperature band.
    fn discrepancy_terms(&self) -> [FactorGroups<'_>; 3] {
        let [_, _, month, temperature] = &self.factors;
        [
            FactorGroups {
                group: &self.hour_by_kind,
                levels: 48,
            },
            month.groups(),
            temperature.groups(),
        ]
    }
}

/// The model form of EnergyPlus's hourly outputs at the estimate and at posterior draws
/// against the calibration's meters (with their bases), and the posterior's medians against
/// the priors; writes `validation/discrepancy.csv`. A meter with too few hours to judge is
/// left out (its Guideline 14 line says so already).
pub fn report(
    cal: &Calibration,
    at_estimate: &HourlyOutputs,
    draws: &[HourlyOutputs],
    posterior: &PosteriorSummary,
) -> Result<ModelFormReport, Error> {
    let inp = &cal.inputs;
    let groups = Groups::new(cal);
    let mut meters = vec![];
    let mut columns: Vec<(String, Vec<f64>)> = vec![];
    for (k, name) in inp.outputs.iter().enumerate() {
        // A meter read as bills has no hours to find a form in.
        let Some(sim) = at_estimate.get(name).filter(|_| inp.bills[k].is_none()) else {
            continue;
        };
        let model = inp.with_base(k, sim);
        let sims: Vec<Vec<f64>> = draws
            .iter()
            .filter_map(|o| o.get(name).map(|s| inp.with_base(k, s)))
            .collect();
        let Ok((form, delta, corrected)) = meter_form(cal, &groups, k, &model, &sims) else {
            continue;
        };
        columns.push((format!("{name}_model"), model));
        columns.push((format!("{name}_discrepancy"), delta));
        columns.push((format!("{name}_corrected"), corrected));
        meters.push(form);
    }
    write_discrepancy_csv(cal, &columns)?;
    add_levers(cal, posterior, &mut meters, draws.len());
    let piled = piled_parameters(cal, posterior);
    Ok(ModelFormReport {
        draws: draws.len(),
        meters,
        parameter_findings: piled.iter().map(PiledParameter::finding).collect(),
        piled,
    })
}

/// A meter's form, its hourly discrepancy and the model corrected by it.
type MeterHours = (MeterForm, Vec<f64>, Vec<f64>);

/// One meter's form, its hourly discrepancy and the model corrected by it.
fn meter_form(
    cal: &Calibration,
    groups: &Groups,
    k: usize,
    model: &[f64],
    draws: &[Vec<f64>],
) -> Result<MeterHours, bemcal_stats::StatsError> {
    let inp = &cal.inputs;
    let measured = &inp.measured[k];
    let reach = reach(measured, model, draws)?;
    let patterns = groups
        .factors
        .iter()
        .map(|f| {
            Ok(FactorPattern {
                factor: f.factor,
                pattern: pattern(measured, model, &f.group, &f.labels)?,
            })
        })
        .collect::<Result<Vec<_>, bemcal_stats::StatsError>>()?;
    let residual: Vec<f64> = measured.iter().zip(model).map(|(y, s)| y - s).collect();
    let temperature_slope_kwh_per_k = slope(&inp.features.dry_bulb_c, &residual);
    let additive = additive_discrepancy(measured, model, &groups.discrepancy_terms())?;
    let corrected: Vec<f64> = model
        .iter()
        .zip(&additive.delta)
        .map(|(m, d)| m + d)
        .collect();
    let discrepancy = Discrepancy {
        share: additive.share,
        corrected: g14(measured, &corrected)?,
        held_out: inp
            .held_out
            .as_ref()
            .and_then(|h| g14(&h.measured[k], &corrected).ok()),
    };
    // The model over the meter's hours only, so that both shares are of the same hours.
    let model_at_meter: Vec<f64> = measured
        .iter()
        .zip(model)
        .map(|(y, s)| if y.is_finite() { *s } else { f64::NAN })
        .collect();
    let share = |y: &[f64]| partial_fit(y, &groups.calendar_terms(), &groups.weather_terms());
    let weather = Some(WeatherShare {
        meter: share(measured)?,
        model: share(&model_at_meter)?,
        measured_weather: inp.measured_weather.is_some(),
    });
    let mut form = MeterForm {
        output: inp.outputs[k].clone(),
        reach,
        patterns,
        temperature_slope_kwh_per_k,
        discrepancy,
        weather,
        levers: None,
        findings: vec![],
    };
    form.findings = findings(&form, draws.len());
    Ok((form, additive.delta, corrected))
}

/// Whether the model cannot reach the meter's level at the estimate or any posterior draw.
fn out_of_reach(r: &Reach) -> bool {
    r.verdict == Verdict::Level && !r.within_draws
}

/// [`Levers`] for every meter out of reach, and their finding (the design's runs read once,
/// only where a meter needs them; none where they cannot be read).
fn add_levers(
    cal: &Calibration,
    posterior: &PosteriorSummary,
    meters: &mut [MeterForm],
    draws: usize,
) {
    if !meters.iter().any(|m| out_of_reach(&m.reach)) {
        return;
    }
    let Some((design, runs)) =
        (cal.refine_log().ok()).and_then(|log| cal.simulated_points(&log).ok())
    else {
        return;
    };
    let inp = &cal.inputs;
    let plan = &inp.plan;
    let medians: Vec<f64> = (plan.calibrated.iter())
        .map(|name| {
            (posterior.parameters.iter())
                .find(|p| &p.name == name)
                .map_or(f64::NAN, |p| p.median)
        })
        .collect();
    let bounds: Vec<(f64, f64)> = plan.priors.iter().map(|p| (p.min(), p.max())).collect();
    for m in meters.iter_mut().filter(|m| out_of_reach(&m.reach)) {
        let Some(k) = inp.outputs.iter().position(|o| *o == m.output) else {
            continue;
        };
        let measured = &inp.measured[k];
        let totals: Vec<f64> = (runs.iter())
            .map(|o| {
                o.get(&m.output).map_or(f64::NAN, |sim| {
                    let with_base = inp.with_base(k, sim);
                    (measured.iter().zip(&with_base))
                        .filter(|(y, _)| y.is_finite())
                        .map(|(_, s)| s)
                        .sum()
                })
            })
            .collect();
        let gap = m.reach.measured_kwh - m.reach.estimate_kwh;
        let slopes = marginal_slopes(&design.points, &totals);
        let parameters = levers(gap, &medians, &slopes, &bounds)
            .into_iter()
            .map(|l| MeterLever {
                parameter: plan.calibrated[l.index].clone(),
                median: medians[l.index],
                bound: if l.bound == bounds[l.index].1 {
                    Bound::Upper
                } else {
                    Bound::Lower
                },
                bound_value: l.bound,
                moves_kwh: l.moves_kwh,
                alone_needs: l.alone_needs,
                prior_range: bounds[l.index].1 - bounds[l.index].0,
            })
            .collect();
        m.levers = Some(Levers {
            runs: totals.iter().filter(|t| t.is_finite()).count(),
            gap_kwh: gap,
            parameters,
        });
        m.findings = findings(m, draws);
    }
}

/// Parameters whose posterior median lies against a bound of their prior.
fn piled_parameters(cal: &Calibration, posterior: &PosteriorSummary) -> Vec<PiledParameter> {
    let plan = &cal.inputs.plan;
    plan.calibrated
        .iter()
        .zip(&plan.priors)
        .filter_map(|(name, prior)| {
            let p = posterior.parameters.iter().find(|p| &p.name == name)?;
            let bound = piled_at_bound(prior.min(), prior.max(), p.median)?;
            Some(PiledParameter {
                name: name.clone(),
                bound,
                median: p.median,
                prior_min: prior.min(),
                prior_max: prior.max(),
            })
        })
        .collect()
}

/// The rule that turns a meter's figures into words: the verdict, then (for a meter not
/// reached) a constant offset, a weather file unlike the meter's period, the strongest
/// residual pattern with the part of the model it points to, and what the discrepancy
/// removes.
pub fn findings(form: &MeterForm, draws: usize) -> Vec<String> {
    let r = &form.reach;
    let mwh = |x: f64| x / 1000.0;
    let mut out = vec![match r.verdict {
        Verdict::Reached => format!(
            "reached: NMBE {:+.1} %, CV-RMSE {:.1} % at the estimate",
            r.nmbe, r.cv_rmse
        ),
        Verdict::Level if !r.within_draws => format!(
            "out of reach: EnergyPlus at the estimate and {draws} posterior draws gives \
             {:.1}..{:.1} MWh over the calibration hours, the meter {:.1} MWh (NMBE {:+.1} %): \
             no posterior draw reaches its level",
            mwh(r.draws_kwh[0]),
            mwh(r.draws_kwh[1]),
            mwh(r.measured_kwh),
            r.nmbe
        ),
        Verdict::Level => format!(
            "level missed at the estimate (NMBE {:+.1} %) although posterior draws span \
             {:.1}..{:.1} MWh around the meter's {:.1} MWh: the surrogate's error near the \
             posterior (more refinement rounds or design points) or a compromise with the \
             other meters",
            r.nmbe,
            mwh(r.draws_kwh[0]),
            mwh(r.draws_kwh[1]),
            mwh(r.measured_kwh)
        ),
        Verdict::Shape => format!(
            "level reached (NMBE {:+.1} %), hourly shape missed (CV-RMSE {:.1} %)",
            r.nmbe, r.cv_rmse
        ),
    }];
    if r.verdict == Verdict::Reached {
        return out;
    }
    let side = |x: f64| if x > 0.0 { "below" } else { "above" };
    // The residuals' mean square is mean^2 + variance, and (NMBE / CV-RMSE)^2 is the share of
    // it the mean carries (Guideline 14's denominators cancel).
    let offset_share = (r.nmbe / r.cv_rmse).powi(2);
    if r.verdict == Verdict::Level && offset_share >= OFFSET_SHARE {
        let mean = r.nmbe / 100.0 * r.measured_kwh / r.hours.max(1) as f64;
        out.push(format!(
            "mostly a constant offset ({:.0} % of the misfit): the model is {} the meter by \
             {:.1} kWh every hour on average: a load the model lacks (a base: [[bases]]), a \
             meter that holds more or other than the model's output, or a system unlike the \
             model's",
            100.0 * offset_share.min(1.0),
            side(mean),
            mean.abs()
        ));
    }
    if let Some(w) = form.weather.filter(WeatherShare::unlike_the_meters) {
        out.push(w.finding());
    }
    let strongest = form
        .patterns
        .iter()
        .filter(|p| p.pattern.eta_squared >= PATTERN_ETA2)
        .max_by(|a, b| a.pattern.eta_squared.total_cmp(&b.pattern.eta_squared));
    if let Some(p) = strongest {
        out.push(pattern_finding(form, p));
    }
    if let Some(l) = &form.levers {
        out.push(l.finding());
    }
    let d = &form.discrepancy;
    out.push(format!(
        "an additive discrepancy (hour of day by day kind, month, outdoor temperature) removes \
         {:.0} % of the misfit: NMBE {:+.1} %, CV-RMSE {:.1} % with it{}",
        100.0 * d.share,
        d.corrected.nmbe,
        d.corrected.cv_rmse,
        d.held_out.map_or(String::new(), |h| format!(
            "; on the held-out period, where it was not fitted, {:+.1} % / {:.1} %",
            h.nmbe, h.cv_rmse
        ))
    ));
    out
}

/// The strongest pattern in words, with the part of the model it points to.
fn pattern_finding(form: &MeterForm, p: &FactorPattern) -> String {
    let g = &p.pattern.groups;
    let eta = p.pattern.eta_squared;
    let by = |f: fn(&f64, &f64) -> std::cmp::Ordering| {
        g.iter()
            .max_by(|a, b| f(&a.mean_residual.abs(), &b.mean_residual.abs()))
            .map(|x| (x.label.clone(), x.mean_residual))
            .unwrap_or_default()
    };
    let (worst, worst_r) = by(f64::total_cmp);
    match p.factor {
        Factor::OutdoorTemperature => {
            let (cold, warm) = (g.first(), g.last());
            format!(
                "the residuals follow the outdoor temperature (eta^2 {eta:.2}; {:+.2} kWh per \
                 hour per K; {:+.1} kWh/h at {} C, {:+.1} at {} C): the envelope (insulation, \
                 glazing, infiltration), outdoor air, the plant's efficiency, or the weather \
                 (calibrate with the metered year's: [measured_weather])",
                form.temperature_slope_kwh_per_k,
                cold.map_or(0.0, |c| c.mean_residual),
                cold.map_or("", |c| c.label.as_str()),
                warm.map_or(0.0, |c| c.mean_residual),
                warm.map_or("", |c| c.label.as_str()),
            )
        }
        Factor::HourOfDay => format!(
            "the residuals follow the hour of the day (eta^2 {eta:.2}; largest at {worst}:00, \
             {worst_r:+.1} kWh/h): the schedules (occupied hours, start and stop times; \
             pre-calibration's schedule priors in priors.toml)"
        ),
        Factor::DayKind => format!(
            "working and off days differ (eta^2 {eta:.2}; {}): the day-type calendar \
             (day_types_file = \"precal/calendar.csv\" in the building spec) or the holidays",
            g.iter()
                .map(|x| format!("{} {:+.1} kWh/h", x.label, x.mean_residual))
                .collect::<Vec<_>>()
                .join(", ")
        ),
        Factor::Month => format!(
            "a seasonal pattern (eta^2 {eta:.2}; largest in {worst}, {worst_r:+.1} kWh/h): a \
             system that runs part of the year (economiser, heating season, a process load) \
             or the weather (calibrate with the metered year's: [measured_weather])"
        ),
    }
}

/// `validation/discrepancy.csv`: per hour and meter, the model at the estimate (with its
/// base), the fitted discrepancy, and their sum.
fn write_discrepancy_csv(cal: &Calibration, columns: &[(String, Vec<f64>)]) -> Result<(), Error> {
    let mut s = String::from("timestamp");
    for (name, _) in columns {
        s.push(',');
        s.push_str(name);
    }
    s.push('\n');
    let n = columns.first().map_or(0, |c| c.1.len());
    for (h, ts) in timestamps(cal.inputs.year, n) {
        s.push_str(&ts);
        for (_, v) in columns {
            s.push_str(&format!(",{:.4}", v[h]));
        }
        s.push('\n');
    }
    write_atomic(&cal.out.validation().join("discrepancy.csv"), s.as_bytes())
}

#[cfg(test)]
mod tests {
    use super::*;
    use bemcal_stats::model_form::Group;

    /// A fit of a series of mean `mean` whose calendar leaves `base_rms`.
    fn fit(share: f64, explained_rms: f64, base_rms: f64, mean: f64) -> PartialFit {
        PartialFit {
            share,
            explained_rms,
            base_rms,
            mean,
        }
    }

    fn form(verdict: Verdict, nmbe: f64, within: bool, patterns: Vec<FactorPattern>) -> MeterForm {
        MeterForm {
            output: "heating_kwh".into(),
            reach: Reach {
                hours: 8760,
                measured_kwh: 760_000.0,
                estimate_kwh: 2_580_000.0,
                draws_kwh: [2_500_000.0, 2_700_000.0],
                within_draws: within,
                nmbe,
                cv_rmse: 300.0,
                verdict,
            },
            patterns,
            temperature_slope_kwh_per_k: 3.5,
            discrepancy: Discrepancy {
                share: 0.9,
                corrected: g14(&[1.0, 2.0, 3.0], &[1.0, 2.0, 3.0]).unwrap(),
                held_out: None,
            },
            weather: None,
            levers: None,
            findings: vec![],
        }
    }

    fn lever(parameter: &str, bound_value: f64, moves_kwh: f64, alone_needs: f64) -> MeterLever {
        MeterLever {
            parameter: parameter.into(),
            median: 1.0,
            bound: Bound::Upper,
            bound_value,
            moves_kwh,
            alone_needs,
            prior_range: 1.0,
        }
    }

    #[test]
    fn levers_say_whether_the_priors_can_reach_the_meter() {
        // The meter 1,820 MWh below the model: two levers move it 300 MWh down together.
        let mut f = form(Verdict::Level, -239.0, false, vec![]);
        f.levers = Some(Levers {
            runs: 36,
            gap_kwh: -1_820_000.0,
            parameters: vec![
                lever("infiltration_ach", 0.1, -200_000.0, -7.5),
                lever("heating_setpoint_occupied", 19.0, -100_000.0, 2.0),
            ],
        });
        let text = findings(&f, 8).join("\n");
        assert!(
            text.contains("over the 36 EnergyPlus runs the surrogate learned from")
                && text.contains(
                    "infiltration_ach to its prior's upper bound 0.1000 (median 1.0000) -200.0 MWh"
                )
                && text.contains("all 2 together -300.0 MWh of the -1820.0 MWh needed")
                && text.contains("no setting inside these priors reaches the meter")
                && text.contains(
                    "infiltration_ach alone would need -7.5000, 7.6 times its prior's range"
                ),
            "{text}"
        );
        f.levers.as_mut().unwrap().gap_kwh = -250_000.0;
        let text = findings(&f, 8).join("\n");
        assert!(text.contains("could reach the meter together"), "{text}");
        f.levers.as_mut().unwrap().parameters.clear();
        let text = findings(&f, 8).join("\n");
        assert!(text.contains("no calibrated parameter moves it"), "{text}");
    }

    fn groups(means: &[f64]) -> Vec<Group> {
        means
            .iter()
            .enumerate()
            .map(|(i, m)| Group {
                label: format!("{i:02}"),
                hours: 100,
                mean_residual: *m,
                mean_measured: 80.0,
            })
            .collect()
    }

    #[test]
    fn an_unreachable_offset_meter_is_named_with_what_to_change() {
        // A level 200 kWh/h too high at every hour: out of reach, a constant offset, the
        // temperature pattern named, the piled parameter named.
        let patterns = vec![
            FactorPattern {
                factor: Factor::HourOfDay,
                pattern: Pattern {
                    eta_squared: 0.02,
                    groups: groups(&[-205.0, -195.0]),
                },
            },
            FactorPattern {
                factor: Factor::OutdoorTemperature,
                pattern: Pattern {
                    eta_squared: 0.4,
                    groups: groups(&[-260.0, -140.0]),
                },
            },
        ];
        let f = findings(&form(Verdict::Level, -240.0, false, patterns), 8);
        assert!(f[0].starts_with("out of reach"), "{f:?}");
        assert!(f[0].contains("760.0 MWh"), "{f:?}");
        assert!(
            f[1].contains("constant offset") && f[1].contains("above"),
            "{f:?}"
        );
        assert!(f[2].contains("outdoor temperature"), "{f:?}");
        assert!(f[3].contains("removes 90 %"), "{f:?}");
        let piled = PiledParameter {
            name: "wall_insulation_k".into(),
            bound: Bound::Lower,
            median: 0.0201,
            prior_min: 0.02,
            prior_max: 0.06,
        };
        let line = piled.finding();
        assert!(
            line.contains("wall_insulation_k") && line.contains("lower bound"),
            "{line}"
        );
    }

    #[test]
    fn a_model_that_follows_the_weather_where_the_meter_does_not_blames_the_weather_file() {
        // Measured (summary.json `model_form.meters[].weather`): share, explained RMS, the
        // calendar's leftover RMS and the mean, kWh/h. The RSF's 2011 heating meter calibrated
        // with the Golden TMY3: named, with the fix.
        let rsf_heating = WeatherShare {
            meter: fit(0.028, 22.3, 134.2, 89.6),
            model: fit(0.774, 66.1, 75.1, 97.6),
            measured_weather: false,
        };
        let mut f = form(Verdict::Shape, -8.9, true, vec![]);
        f.weather = Some(rsf_heating);
        let lines = findings(&f, 8);
        assert!(
            lines[1].contains("77 %") && lines[1].contains("(3 %: 22.3 kWh/h)"),
            "{lines:?}"
        );
        assert!(
            lines[1].contains("not the metered period's")
                && lines[1].contains("[measured_weather]"),
            "{lines:?}"
        );
        // With measured weather, the station is what to check.
        f.weather = Some(WeatherShare {
            measured_weather: true,
            ..rsf_heating
        });
        assert!(findings(&f, 8)[1].contains("station"));
        // `make actual-weather`: meters EnergyPlus made with 2017's weather, calibrated with
        // the station's TMY3 (heating, cooling): named.
        for (meter, model) in [
            (fit(0.004, 0.26, 4.0, 8.3), fit(0.617, 2.62, 3.34, 8.6)),
            (fit(0.055, 0.63, 2.68, 2.5), fit(0.687, 2.18, 2.64, 2.3)),
        ] {
            let w = WeatherShare {
                meter,
                model,
                measured_weather: false,
            };
            assert!(w.unlike_the_meters(), "{w:?}");
        }
        // Not named:
        for (meter, model) in [
            // the same meters calibrated with 2017's weather (heating);
            (fit(0.628, 3.17, 4.0, 8.3), fit(0.640, 3.19, 3.99, 8.3)),
            // the demo's electricity, made with the weather it is calibrated with, whose 5 %
            // noise leaves the meter a small share of a variation as large as the model's;
            (fit(0.057, 2.84, 11.9, 180.4), fit(0.284, 2.09, 3.93, 174.1)),
            // the RSF's cooling, where the model runs at 16 times the meter's level: the
            // meter's variation with the temperature is, relative to its level, over half the
            // model's;
            (fit(0.118, 1.71, 4.92, 3.8), fit(0.671, 50.9, 62.1, 61.8)),
            // a dead meter, all zeros;
            (fit(0.0, 0.0, 0.0, 0.0), fit(0.774, 66.1, 75.2, 97.6)),
            // and a model that hardly follows the weather.
            (fit(0.01, 0.1, 20.0, 50.0), fit(0.1, 5.0, 15.0, 50.0)),
        ] {
            f.weather = Some(WeatherShare {
                meter,
                model,
                measured_weather: false,
            });
            assert!(
                !findings(&f, 8)
                    .iter()
                    .any(|l| l.contains("follows the weather's")),
                "{meter:?} / {model:?}"
            );
        }
    }

    #[test]
    fn a_reached_meter_is_one_line_and_a_level_within_the_draws_blames_the_surrogate() {
        let f = findings(&form(Verdict::Reached, 1.0, true, vec![]), 8);
        assert_eq!(f.len(), 1);
        assert!(f[0].starts_with("reached"));
        let f = findings(&form(Verdict::Level, -14.0, true, vec![]), 8);
        assert!(f[0].contains("surrogate"), "{f:?}");
    }
}

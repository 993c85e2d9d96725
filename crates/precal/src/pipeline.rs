//! The whole pre-calibration of one building-year: meters + outdoor temperature -> quality,
//! disaggregation, day-type clusters, schedule priors and `priors.toml` content.

use serde::{Deserialize, Serialize};

use crate::disaggregate::{
    disaggregate_cooling, disaggregate_electricity, disaggregate_heating, DerivedSeries,
    Disaggregation, DisaggregationOptions,
};
use crate::meters::{quality, MeterData, MeterQuality, MeterRole, HOURS};
use crate::schedule::{
    cluster_days, daily_profiles, day_type_schedules, DailyProfiles, DayLabel, DayTypeClusters,
    DayTypeSchedule, ScheduleOptions, ScheduleSource,
};
use crate::PrecalError;

/// Options of [`run`]; the `[precalibration]` table of a project file.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PrecalOptions {
    /// Disaggregation options.
    pub disaggregation: DisaggregationOptions,
    /// Schedule analysis options.
    pub schedule: ScheduleOptions,
}

/// One parameter of `priors.toml`: a triangular prior.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ParameterPrior {
    /// Parameter name (`schedule_weekday_01`, ..., `hot_water_peak_flow`).
    pub name: String,
    /// Lower bound.
    pub min: f64,
    /// Mode.
    pub mode: f64,
    /// Upper bound.
    pub max: f64,
    /// Unit (`-` for fractions).
    #[serde(default)]
    pub unit: String,
    /// Where the prior comes from.
    #[serde(default)]
    pub source: String,
}

/// Interval boundaries per day type: the hour (1..=24) at which each interval ends.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ScheduleBoundaries {
    /// Weekday intervals.
    pub weekday_boundaries: Vec<usize>,
    /// Weekend (and holiday) intervals.
    pub weekend_boundaries: Vec<usize>,
    /// Partial days' intervals, where the meters show partial days
    /// ([`crate::schedule::DayLabel::Partial`]).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub partial_boundaries: Vec<usize>,
}

/// The content of `priors.toml`, the file the calibration reads (written by pre-calibration,
/// or by hand: both parts are optional).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct PriorsFile {
    /// Schedule interval boundaries (generated models only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub schedule: Option<ScheduleBoundaries>,
    /// Triangular priors.
    #[serde(default)]
    pub parameter: Vec<ParameterPrior>,
}

/// Everything the pre-calibration found.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Precalibration {
    /// The meters on the hourly grid.
    pub meters: MeterData,
    /// Quality per meter.
    pub quality: Vec<MeterQuality>,
    /// Bases and derived series.
    pub disaggregation: Disaggregation,
    /// The series the daily profiles came from.
    pub schedule_series: DerivedSeries,
    /// Normalised daily profiles.
    pub profiles: DailyProfiles,
    /// Day-type clusters and the calendar.
    pub clusters: DayTypeClusters,
    /// Weekday and weekend quartiles and intervals (and partial days', where they are).
    pub schedules: Vec<DayTypeSchedule>,
    /// The priors file content.
    pub priors: PriorsFile,
    /// Decisions worth reporting.
    pub notes: Vec<String>,
    /// What the day types say about the model's calendar ([`crate::advice`]).
    #[serde(default)]
    pub advice: Vec<crate::advice::Suggestion>,
}

/// A `[[bases]]` entry of the project file that pre-calibration suggests: a load in a meter
/// that a building model usually lacks ([`Precalibration::suggested_bases`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SuggestedBase {
    /// The model output whose meter holds the load (the default output name of the meter's
    /// role: `electricity_kwh`, `cooling_kwh`).
    pub output: String,
    /// The sub-meter that measures the load hour by hour, if one does.
    pub submeter: Option<String>,
    /// Else a constant load, kWh per hour.
    pub kwh_per_hour: Option<f64>,
    /// Why, in words.
    pub why: String,
}

/// A cooling base is suggested when it is at least this share of the cooling meter's mean:
/// smaller, it is the meter's noise floor, not a load.
pub const COOLING_BASE_SHARE: f64 = 0.05;

impl Precalibration {
    /// The `[[bases]]` this pre-calibration suggests (reference section 2.2.1's bases, where a
    /// model usually lacks them): a data-center sub-meter, hour by hour, on the electricity
    /// meter; a cooling base through the heating season (server rooms, labs, process cooling) of
    /// at least [`COOLING_BASE_SHARE`] of the cooling meter's mean. Not the night electricity
    /// base (the building's own unoccupied load, which the model has) nor the heating base (hot
    /// water, which the model's `hot_water_peak_flow` prior carries).
    pub fn suggested_bases(&self) -> Vec<SuggestedBase> {
        let mut out = vec![];
        let electricity = self.meters.get(&MeterRole::Electricity).is_some();
        if let Some(dc) = self.meters.submeter("data_center").filter(|_| electricity) {
            let median = self
                .disaggregation
                .estimate("electricity_base_kw")
                .map_or(f64::NAN, |e| e.value);
            out.push(SuggestedBase {
                output: "electricity_kwh".into(),
                submeter: Some(dc.role.name().to_string()),
                kwh_per_hour: None,
                why: format!(
                    "the data_center sub-meter, hour by hour (median {median:.1} kW), if the \
                     electricity meter includes it and the model has no data center"
                ),
            });
        }
        let cooling_mean = self
            .quality
            .iter()
            .find(|q| q.meter == MeterRole::Cooling.name())
            .map(|q| q.mean_kwh);
        let base = self.disaggregation.estimate("cooling_base_kw");
        if let (Some(mean), Some(base)) = (cooling_mean, base) {
            if base.value > 0.0 && base.value >= COOLING_BASE_SHARE * mean {
                out.push(SuggestedBase {
                    output: "cooling_kwh".into(),
                    submeter: None,
                    kwh_per_hour: Some(base.value),
                    why: format!(
                        "cooling all through the heating season ({:.0} % of the meter's mean; \
                         {}): server rooms, labs or process cooling, if the model has none",
                        100.0 * base.value / mean,
                        base.method
                    ),
                });
            }
        }
        out
    }

    /// The weekday or weekend schedule (always there), or the partial days' (where they are).
    pub fn schedule(&self, label: DayLabel) -> Option<&DayTypeSchedule> {
        self.schedules.iter().find(|s| s.label == label)
    }

    /// Hourly fractions before merging (2 x 24) and intervals after.
    pub fn reduction(&self) -> (usize, usize) {
        (
            self.schedules.iter().map(|s| s.hours.len()).sum(),
            self.schedules.iter().map(|s| s.intervals.len()).sum(),
        )
    }
}

fn sum_series(parts: &[&[f64]]) -> Vec<f64> {
    (0..HOURS)
        .map(|t| parts.iter().map(|p| p[t]).sum::<f64>())
        .collect()
}

/// Runs the pre-calibration on `meters` with the hourly outdoor dry bulb `outdoor_c` (8,760
/// values in the same hour order, e.g. from the EPW).
pub fn run(
    meters: MeterData,
    outdoor_c: &[f64],
    opts: &PrecalOptions,
) -> Result<Precalibration, PrecalError> {
    if outdoor_c.len() != HOURS {
        return Err(PrecalError::Invalid(format!(
            "outdoor temperature needs {HOURS} hourly values, got {}",
            outdoor_c.len()
        )));
    }
    let year = meters.year;
    let mut notes = Vec::new();
    let quality: Vec<MeterQuality> = meters
        .series
        .iter()
        .map(|s| quality(s.role.name(), &s.values, year, 24))
        .collect();
    let (dis, e_base) = disaggregate(&meters, outdoor_c, &opts.disaggregation, &mut notes);
    let schedule_series = schedule_series(&meters, &dis, e_base, opts.schedule.source)?;
    let profiles = daily_profiles(&schedule_series.values, opts.schedule.normalise_quantile)?;
    if !profiles.skipped_days.is_empty() {
        notes.push(format!(
            "{} days with missing hours skipped in the schedule analysis",
            profiles.skipped_days.len()
        ));
    }
    let (clusters, _) = cluster_days(&profiles, year, &opts.schedule)?;
    let schedules = day_type_schedules(&profiles, &clusters, &opts.schedule)?;
    let priors = priors_file(&schedules, &dis, &mut notes);
    let advice = crate::advice::calendar_advice(&clusters);
    Ok(Precalibration {
        meters,
        quality,
        disaggregation: dis,
        schedule_series,
        profiles,
        clusters,
        schedules,
        priors,
        notes,
        advice,
    })
}

/// The base loads (reference section 2.2.1): heating and cooling against the outdoor
/// temperature, the electricity base (or the data-center sub-meter); returns them with the
/// electricity base in kW.
fn disaggregate(
    meters: &MeterData,
    outdoor_c: &[f64],
    d_opts: &DisaggregationOptions,
    notes: &mut Vec<String>,
) -> (Disaggregation, f64) {
    let mut dis = Disaggregation::default();
    if let Some(h) = meters.get(&MeterRole::Heating) {
        disaggregate_heating(&h.values, outdoor_c, meters.year, d_opts, &mut dis);
    } else {
        notes.push("no heating meter: heating base not estimated".into());
    }
    if let Some(c) = meters.get(&MeterRole::Cooling) {
        disaggregate_cooling(&c.values, outdoor_c, d_opts, &mut dis);
    } else {
        notes.push("no cooling meter: cooling base not estimated".into());
    }
    let elec = meters
        .get(&MeterRole::Electricity)
        .map(|s| s.values.as_slice());
    let dc = meters.submeter("data_center").map(|s| s.values.as_slice());
    let e_base = disaggregate_electricity(elec, dc, d_opts, &mut dis);
    (dis, e_base)
}

/// The series whose daily profiles give the day types and schedules: the lighting and plug
/// sub-meters summed, or the electricity less its base (`source` decides; `Auto`: the
/// sub-meters where there are any).
fn schedule_series(
    meters: &MeterData,
    dis: &Disaggregation,
    e_base: f64,
    source: ScheduleSource,
) -> Result<DerivedSeries, PrecalError> {
    let lighting = meters.submeter("lighting").map(|s| s.values.as_slice());
    let plug = meters.submeter("plug_loads").map(|s| s.values.as_slice());
    let subs: Vec<&[f64]> = [lighting, plug].into_iter().flatten().collect();
    let names: Vec<&str> = [("lighting", lighting), ("plug_loads", plug)]
        .iter()
        .filter(|(_, s)| s.is_some())
        .map(|(n, _)| *n)
        .collect();
    let use_subs = match source {
        ScheduleSource::Submeters => {
            if subs.is_empty() {
                return Err(PrecalError::Invalid(
                    "schedule source 'submeters' needs a lighting or plug_loads meter".into(),
                ));
            }
            true
        }
        ScheduleSource::Electricity => false,
        ScheduleSource::Auto => !subs.is_empty(),
    };
    if use_subs {
        return Ok(DerivedSeries {
            name: "schedule_series".into(),
            values: sum_series(&subs),
            method: format!("sum of the {} sub-meters", names.join(" + ")),
        });
    }
    let e = dis.get("electricity_variable").ok_or_else(|| {
        PrecalError::Invalid(
            "no electricity meter (nor lighting / plug_loads sub-meters) for the schedule analysis"
                .into(),
        )
    })?;
    Ok(DerivedSeries {
        name: "schedule_series".into(),
        values: e.values.clone(),
        method: format!("electricity minus the {e_base:.3} kW electricity base"),
    })
}

/// `priors.toml`: the day types' schedule boundaries and interval priors, and the hot-water
/// peak flow from the heating base.
fn priors_file(
    schedules: &[DayTypeSchedule],
    dis: &Disaggregation,
    notes: &mut Vec<String>,
) -> PriorsFile {
    let mut parameter = Vec::new();
    for s in schedules {
        for (i, iv) in s.intervals.iter().enumerate() {
            parameter.push(ParameterPrior {
                name: format!("schedule_{}_{:02}", s.label.as_str(), i + 1),
                min: iv.prior.min,
                mode: iv.prior.mode,
                max: iv.prior.max,
                unit: "-".into(),
                source: format!(
                    "DTW day-type cluster '{}', hours {}-{}, box-plot quartiles",
                    s.label.as_str(),
                    iv.start_hour,
                    iv.end_hour
                ),
            });
        }
    }
    match dis.estimate("hot_water_peak_flow_m3s") {
        Some(e) if e.value.is_finite() && e.value > 0.0 => parameter.push(ParameterPrior {
            name: "hot_water_peak_flow".into(),
            min: 0.0,
            mode: e.value,
            max: 2.0 * e.value,
            unit: "m3/s".into(),
            source: format!(
                "heating base peak {:.2} kW -> {} (min 0, max 2 x mode)",
                dis.estimate("heating_base_peak_kw").map_or(f64::NAN, |p| p.value),
                e.method
            ),
        }),
        _ => notes.push(
            "hot_water_peak_flow prior not derived: no positive heating base in the non-heating season \
             (the heating meter may exclude domestic hot water)"
                .into(),
        ),
    }
    PriorsFile {
        schedule: Some(ScheduleBoundaries {
            weekday_boundaries: schedules[0].boundaries(),
            weekend_boundaries: schedules[1].boundaries(),
            partial_boundaries: schedules.get(2).map_or(vec![], |s| s.boundaries()),
        }),
        parameter,
    }
}

//! Stage 0, the inputs: the project's model (with pre-calibration priors applied), the
//! weather it simulates with, and the meters it is compared with.

use bemcal_weather::grid::GridYear;
use std::path::{Path, PathBuf};

use bemcal_energyplus::{Engine, Model, RunOptions, Runner};
use bemcal_precal::meters::{read_meters, MeterData, MeterRole};
use bemcal_precal::pipeline::PriorsFile;
use bemcal_weather::{Epw, HourlyFeatures};

use crate::bills::BilledMeter;
use crate::error::{write_atomic, Error};
use crate::plan::Plan;
use crate::project::{excerpt, Project};

/// Loaded inputs of a calibration: model (with pre-calibration priors applied), weather,
/// measurements.
pub struct Inputs {
    /// Runs EnergyPlus (the engine found on this machine, default run options).
    pub runner: Runner,
    /// The project's model, with the priors file's priors and schedule applied.
    pub model: Model,
    /// Which parameters are calibrated, their priors, and the values of the others.
    pub plan: Plan,
    /// The EPW the model simulates with ([`weather_for`]).
    pub weather_path: PathBuf,
    /// How the EPW was built from `[measured_weather]` (None: the project's EPW as it is).
    pub measured_weather: Option<bemcal_weather::measured::BuildReport>,
    /// The surrogate's hourly weather features, from that EPW on the model's calendar.
    pub features: HourlyFeatures,
    /// The grid year of the meters and the model (a calendar year or twelve months from another
    /// month).
    pub year: GridYear,
    /// What reading the meters decided or dropped ([`bemcal_precal::meters::MeterData::notes`]).
    pub meter_notes: Vec<String>,
    /// Calibration outputs: the model outputs that have a meter, in model order.
    pub outputs: Vec<String>,
    /// Per output, its meter over the calibration period (kWh, NaN = missing or held out):
    /// what the likelihood, the surrogate's checks and the in-sample Guideline 14 see.
    pub measured: Vec<Vec<f64>>,
    /// Per output, whether the likelihood fits its meter (`[[meters.columns]] fit`, default
    /// true); a meter not fitted is still compared in validation and model form.
    pub fitted: Vec<bool>,
    /// The held-out period (`[validation] holdout`): its hours and the meters there.
    pub held_out: Option<HeldOut>,
    /// Per output, the hourly load (kWh) in its meter that the model does not have
    /// (`[[bases]]`; zeros without one): the model plus this is compared with the meter.
    pub bases: Vec<Vec<f64>>,
    /// What each base is, for the summary.
    pub base_reports: Vec<crate::bases::BaseReport>,
    /// Per output, its bills where its meter is read as bills (`[[meters.bills]]`; its
    /// hourly `measured` is then missing throughout).
    pub bills: Vec<Option<BilledMeter>>,
}

/// The hours of a held-out period and the meters' values in them: they check the calibration
/// and never fit it ([`Inputs::measured`] is NaN there).
#[derive(Debug, Clone)]
pub struct HeldOut {
    /// The period as the project wrote it.
    pub period: String,
    /// Per hour slot, whether it is held out.
    pub hours: Vec<bool>,
    /// Per output, the meter in the held-out hours (NaN elsewhere and where missing).
    pub measured: Vec<Vec<f64>>,
}

impl HeldOut {
    /// Hour slots held out.
    pub fn hour_count(&self) -> usize {
        self.hours.iter().filter(|o| **o).count()
    }

    /// Splits `measured` (whole meters) by `hours`: the calibration period's values stay in
    /// `measured` (NaN in held-out hours), the held-out values move to the returned period.
    pub fn split(period: String, hours: Vec<bool>, measured: &mut [Vec<f64>]) -> HeldOut {
        let held = measured
            .iter_mut()
            .map(|m| {
                m.iter_mut()
                    .zip(&hours)
                    .map(|(v, &out)| {
                        if out {
                            std::mem::replace(v, f64::NAN)
                        } else {
                            f64::NAN
                        }
                    })
                    .collect()
            })
            .collect();
        HeldOut {
            period,
            hours,
            measured: held,
        }
    }
}

impl Inputs {
    /// The outputs whose meters the likelihood leaves out (`fit = false`), in output order.
    pub fn not_fitted(&self) -> Vec<String> {
        self.outputs
            .iter()
            .zip(&self.fitted)
            .filter(|(_, f)| !**f)
            .map(|(o, _)| o.clone())
            .collect()
    }

    /// Meter `k` whole: the calibration period's values and the held-out ones.
    pub fn meter(&self, k: usize) -> Vec<f64> {
        match &self.held_out {
            None => self.measured[k].clone(),
            Some(h) => self.measured[k]
                .iter()
                .zip(&h.measured[k])
                .zip(&h.hours)
                .map(|((m, o), &out)| if out { *o } else { *m })
                .collect(),
        }
    }

    /// The bills' likelihoods of the billed outputs that are fitted
    /// ([`crate::bills::BilledMeter::likelihood`]).
    pub fn bill_likelihoods(
        &self,
    ) -> Result<Vec<bemcal_stats::likelihood::intervals::IntervalLikelihood>, Error> {
        let (n_h, n_out) = (self.features.len(), self.outputs.len());
        (0..n_out)
            .filter(|&k| self.fitted[k])
            .filter_map(|k| Some((k, self.bills[k].as_ref()?)))
            .map(|(k, b)| b.likelihood(k, n_out, n_h, &self.bases[k]))
            .collect()
    }

    /// Per hour slot, whether it belongs to the calibration period (not held out).
    pub fn calibration_hours(&self) -> Vec<bool> {
        match &self.held_out {
            None => vec![true; self.features.len()],
            Some(h) => h.hours.iter().map(|o| !o).collect(),
        }
    }

    /// The part of meter `k` the model simulates: the meter less its base (NaN where either is
    /// missing). The likelihood compares the surrogate with this.
    pub fn model_share(&self, k: usize) -> Vec<f64> {
        self.measured[k]
            .iter()
            .zip(&self.bases[k])
            .map(|(m, b)| m - b)
            .collect()
    }

    /// The likelihood's observations (the reference's y, Eq. 5), row-major `hours x outputs`:
    /// each fitted meter's model share; NaN where it is missing or held out, and at every hour
    /// of a meter with `fit = false` (the likelihood leaves it out).
    pub fn likelihood_observations(&self) -> Vec<f64> {
        let (n_h, n_out) = (self.features.len(), self.outputs.len());
        let mut observed = vec![f64::NAN; n_h * n_out];
        for k in (0..n_out).filter(|&k| self.fitted[k]) {
            for (h, v) in self.model_share(k).iter().enumerate() {
                observed[h * n_out + k] = *v;
            }
        }
        observed
    }

    /// True when output `k` has a base (`[[bases]]`).
    pub fn has_base(&self, k: usize) -> bool {
        self.base_reports
            .iter()
            .any(|b| b.output == self.outputs[k])
    }

    /// A model output `sim` of output `k` with its base added: what the meter is compared with.
    pub fn with_base(&self, k: usize, sim: &[f64]) -> Vec<f64> {
        sim.iter().zip(&self.bases[k]).map(|(s, b)| s + b).collect()
    }
}

/// Resolves the project's weather reference ([`weather_reference`]).
pub fn resolve_weather(project: &Project, engine: &Engine) -> Result<PathBuf, Error> {
    weather_reference(&project.weather, &project.base, engine)
}

/// A weather reference: `bundled:FILE` from the engine's `WeatherData`, or a path (relative to
/// `base`).
pub fn weather_reference(reference: &str, base: &Path, engine: &Engine) -> Result<PathBuf, Error> {
    match reference.strip_prefix("bundled:") {
        Some(name) if !is_file_name(name) => Err(Error::Config(format!(
            "weather 'bundled:{}': a bundled weather file is named by its file name alone",
            bemcal_excerpt::excerpt(name, 80)
        ))),
        Some(name) => engine.bundled_weather(name).ok_or_else(|| {
            Error::Config(format!(
                "weather 'bundled:{name}': no such file in {}",
                engine.root.join("WeatherData").display()
            ))
        }),
        None => Ok(base.join(reference)),
    }
}

/// A plain file name: one normal path component (no folder, no `..`).
fn is_file_name(name: &str) -> bool {
    let mut parts = Path::new(name).components();
    matches!(parts.next(), Some(std::path::Component::Normal(_))) && parts.next().is_none()
}

/// The weather a calibration simulates with: the project's EPW, or with `[measured_weather]`
/// the EPW of `year` built from the measured weather onto it (written beside the project as
/// `measured-weather/YEAR.epw` with its report `YEAR.json`, rewritten only when it changes).
pub fn weather_for(
    project: &Project,
    engine: &Engine,
    year: GridYear,
) -> Result<(PathBuf, Option<bemcal_weather::measured::BuildReport>), Error> {
    let tmy = resolve_weather(project, engine)?;
    let Some(m) = &project.measured_weather else {
        return Ok((tmy, None));
    };
    let year = m.year.unwrap_or(year);
    let (text, report) = m.source(project).build_epw(&tmy, year, m.max_gap_h, 60)?;
    let path = project.resolve(Path::new(&format!("measured-weather/{year}.epw")));
    let report_json =
        serde_json::to_vec_pretty(&report).map_err(|e| Error::Config(e.to_string()))?;
    if std::fs::read(&path).ok().as_deref() != Some(text.as_bytes()) {
        write_atomic(&path, text.as_bytes())?;
        write_atomic(&path.with_extension("json"), &report_json)?;
    }
    Ok((path, Some(report)))
}

/// Loads the model, checks the project against it ([`Project::check_model`]) and applies a
/// priors file to it.
pub fn load_model(project: &Project, runner: &Runner) -> Result<Model, Error> {
    let path = project.resolve(&project.model);
    let mut model = Model::load(&path, runner.idd())?;
    project.check_model(&model, runner.idd())?;
    if let Some(p) = &project.priors {
        let path = project.resolve(p);
        let text = std::fs::read_to_string(&path).map_err(|e| Error::io(&path, e))?;
        let pf: PriorsFile = bemcal_energyplus::parse_toml(&text, &path).map_err(Error::from)?;
        if let Some(b) = &pf.schedule {
            let mut spec = model.spec().cloned().ok_or_else(|| Error::Input {
                path: path.clone(),
                line: 0,
                message: "[schedule] boundaries apply to generated building models only".into(),
            })?;
            let hours = |b: &[usize]| b.iter().map(|&h| h as u32).collect::<Vec<u32>>();
            spec.weekday_boundaries = hours(&b.weekday_boundaries);
            spec.weekend_boundaries = hours(&b.weekend_boundaries);
            spec.partial_boundaries = hours(&b.partial_boundaries);
            spec.validate().map_err(|m| Error::Input {
                path: path.clone(),
                line: 0,
                message: m,
            })?;
            let p0 = model.path.clone();
            model = Model::generated(spec);
            model.path = p0;
        }
        for e in &pf.parameter {
            let prior =
                bemcal_energyplus::TriangularPrior::new(e.min, e.mode, e.max).map_err(|m| {
                    Error::Input {
                        path: path.clone(),
                        line: 0,
                        message: format!("parameter {}: {m}", e.name),
                    }
                })?;
            model
                .set_prior(&e.name, prior)
                .map_err(|err| Error::Input {
                    path: path.clone(),
                    line: 0,
                    message: err.to_string(),
                })?;
        }
    }
    Ok(model)
}

/// Loads everything a calibration needs and checks it fits together.
pub fn load_inputs(project: &Project) -> Result<Inputs, Error> {
    let engine = Engine::locate()?;
    let options = RunOptions {
        limits: project.simulation.limits(),
        ..RunOptions::default()
    };
    let runner = Runner::new(engine, options)?;
    let model = load_model(project, &runner)?;
    let plan = Plan::new(&model, &project.calibrate, &project.fixed)?;
    let calendar = model.calendar();
    let (weather_path, measured_weather) = weather_for(project, runner.engine(), calendar.year)?;
    let epw = Epw::read(&weather_path)?;
    let features = HourlyFeatures::from_epw(&epw, &calendar);
    let data = match project.meters_file() {
        Some(path) => read_meters(
            &path,
            &project.meters,
            Some(calendar.year),
            Some(epw.location.time_zone_h),
        )?,
        // Bills alone: no hourly meter; the year is the model's.
        None => MeterData {
            year: calendar.year,
            source: Default::default(),
            series: vec![],
            notes: vec![],
        },
    };
    let billed = read_bills(project, calendar.year)?;
    let (outputs, mut measured, mut bills) = metered_outputs(project, &model, &data, billed)?;
    let fitted = fitted_outputs(project, &outputs)?;
    let held_out = hold_out(project, &data, &outputs, &mut measured, &mut bills)?;
    let mut meter_notes = data.notes.clone();
    meter_notes.extend(bills.iter().flatten().flat_map(|b| {
        b.table
            .notes
            .iter()
            .map(|n| format!("{}: {n}", b.table.path.display()))
            .chain(b.notes.iter().cloned())
    }));
    // A fitted meter with no reading left (every hour excluded or missing) would add nothing
    // to the likelihood: the chains would sample the prior without a word.
    let no_reading = |k: usize| match &bills[k] {
        Some(b) => b.calibration_bills() == 0,
        None => !measured[k].iter().any(|v| v.is_finite()),
    };
    if let Some(k) = (0..outputs.len()).find(|&k| fitted[k] && no_reading(k)) {
        return Err(project.error_at(
            &["meters", "columns"],
            format!(
                "the meter of {} has no reading left to fit (every hour missing or excluded): \
                 give it readings, or say fit = false to compare it only",
                outputs[k]
            ),
        ));
    }
    let (bases, base_reports) = crate::bases::bases_of(project, &outputs, &data)?;
    Ok(Inputs {
        runner,
        model,
        plan,
        weather_path,
        measured_weather,
        features,
        year: calendar.year,
        meter_notes,
        outputs,
        measured,
        fitted,
        held_out,
        bases,
        base_reports,
        bills,
    })
}

/// The project's bills (`[[meters.bills]]`), read and placed on the grid of `year`, by role.
fn read_bills(project: &Project, year: GridYear) -> Result<Vec<BilledMeter>, Error> {
    let mut out: Vec<BilledMeter> = vec![];
    for spec in &project.meters.bills {
        let table = bemcal_precal::meters::read_bills(&project.resolve(&spec.file), spec)?;
        if let Some(other) = out.iter().find(|b| b.table.role == spec.role) {
            return Err(project.error_at(
                &["meters", "bills"],
                format!(
                    "two bills files for role '{}' ({} and {}): give one file per meter",
                    spec.role,
                    other.table.path.display(),
                    spec.file.display()
                ),
            ));
        }
        out.push(BilledMeter::on_grid(table, year)?);
    }
    Ok(out)
}

/// The model's outputs that have a meter (in the model's order) and each meter's readings;
/// an output `[outputs]` names must have its meter, and at least one output must.
type Metered = (Vec<String>, Vec<Vec<f64>>, Vec<Option<BilledMeter>>);

/// The model's outputs that have a meter, hourly or billed (in the model's order), each hourly
/// meter's readings (missing throughout for a billed one) and each billed one's bills; a role
/// read both ways is refused.
fn metered_outputs(
    project: &Project,
    model: &Model,
    data: &MeterData,
    mut billed: Vec<BilledMeter>,
) -> Result<Metered, Error> {
    let (mut outputs, mut measured, mut bills) = (vec![], vec![], vec![]);
    let roles = project.output_roles();
    for o in model.outputs() {
        let Some(role) = roles.get(&o.name).map(|r| MeterRole::from(r.clone())) else {
            continue;
        };
        let bill = billed.iter().position(|b| b.table.role == role);
        match (data.get(&role), bill) {
            (Some(_), Some(_)) => {
                return Err(project.error_at(
                    &["meters", "bills"],
                    format!(
                        "role '{role}' is read both from {} and as bills: a meter is read one way",
                        project.meters_name()
                    ),
                ))
            }
            (Some(s), None) => {
                outputs.push(o.name.clone());
                measured.push(s.values.clone());
                bills.push(None);
            }
            (None, Some(i)) => {
                outputs.push(o.name.clone());
                measured.push(vec![
                    f64::NAN;
                    data.series
                        .first()
                        .map_or(bemcal_precal::meters::HOURS, |s| s
                            .values
                            .len())
                ]);
                bills.push(Some(billed.swap_remove(i)));
            }
            (None, None) => {}
        }
    }
    if let Some(b) = billed.first() {
        return Err(project.error_at(
            &["meters", "bills"],
            format!(
                "bills of role '{}' ({}): no model output has that role (outputs: {})",
                b.table.role,
                b.table.path.display(),
                roles.keys().cloned().collect::<Vec<_>>().join(", ")
            ),
        ));
    }
    // Checked at load against listed columns; with columns detected from the headers, a role
    // that `[outputs]` names explicitly must be among those found.
    for (name, role) in &project.outputs {
        let billed = project.meters.bills.iter().any(|b| b.role.name() == role);
        if data.get(&MeterRole::from(role.clone())).is_none() && !billed {
            return Err(project.error_at(
                &["outputs", name],
                format!(
                    "[outputs] {} = \"{}\": {} has no meter of role '{}' (it has: {})",
                    excerpt(name),
                    excerpt(role),
                    project.meters_name(),
                    excerpt(role),
                    data.series
                        .iter()
                        .map(|s| s.role.name().to_string())
                        .collect::<Vec<_>>()
                        .join(", ")
                ),
            ));
        }
    }
    if outputs.is_empty() {
        return Err(Error::Config(format!(
            "no model output has a meter: outputs map {:?}, meters found: {:?}",
            roles,
            data.series
                .iter()
                .map(|s| s.role.name().to_string())
                .collect::<Vec<_>>()
        )));
    }
    Ok((outputs, measured, bills))
}

/// The project's held-out period (`[validation] holdout`), taken out of `measured` and the
/// bills: those hours never enter the likelihood. Refused where it holds out every reading of a meter.
fn hold_out(
    project: &Project,
    data: &MeterData,
    outputs: &[String],
    measured: &mut [Vec<f64>],
    bills: &mut [Option<BilledMeter>],
) -> Result<Option<HeldOut>, Error> {
    Ok(match &project.validation.holdout {
        None => None,
        Some(h) => {
            let at = |m: String| project.error_at(&["validation", "holdout"], m);
            let hours = data.held_out_hours(h).map_err(at)?;
            let held = HeldOut::split(h.to_string(), hours, measured);
            // A billed meter's bills are held out whole where they touch the period.
            bills
                .iter_mut()
                .flatten()
                .for_each(|b| b.hold_out(&held.hours));
            if let Some(k) = (0..measured.len())
                .find(|&k| bills[k].is_none() && !measured[k].iter().any(|v| v.is_finite()))
            {
                return Err(at(format!(
                    "holdout '{h}' holds out every measured hour of {}: nothing is left to calibrate it with",
                    outputs[k]
                )));
            }
            Some(held)
        }
    })
}

/// Per output (`outputs`, named by the model), whether the calibration fits its meter: not
/// when a listed column of its role says `fit = false`. At least one must be fitted.
fn fitted_outputs(project: &Project, outputs: &[String]) -> Result<Vec<bool>, Error> {
    let roles = project.output_roles();
    let fitted: Vec<bool> = outputs
        .iter()
        .map(|o| {
            roles
                .get(o)
                .is_none_or(|r| project.fits(&MeterRole::from(r.clone())))
        })
        .collect();
    if !fitted.contains(&true) {
        return Err(project.error_at(
            &["meters", "columns"],
            format!(
                "every meter the model has ({}) says fit = false: the calibration needs at \
                 least one meter to fit",
                outputs.join(", ")
            ),
        ));
    }
    Ok(fitted)
}

#[cfg(test)]
mod tests {
    //! `[[meters.columns]] fit = false`: a meter read and compared but left out of the
    //! likelihood (issue 19: a meter the model cannot reach, such as the RSF's cooling).

    use super::load_inputs;
    use crate::project::Project;

    fn project(dir: &std::path::Path, fit: [bool; 2]) -> Project {
        std::fs::copy(
            std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
                .join("../../examples/office/small.toml"),
            dir.join("model.toml"),
        )
        .unwrap();
        let mut meters = String::from("timestamp,heating_kwh,electricity_kwh\n");
        let start = chrono::NaiveDate::from_ymd_opt(2021, 1, 1)
            .unwrap()
            .and_hms_opt(0, 0, 0)
            .unwrap();
        for t in 0..8760 {
            let ts = start + chrono::Duration::hours(t);
            meters.push_str(&format!("{},2,3\n", ts.format("%Y-%m-%dT%H:%M")));
        }
        std::fs::write(dir.join("meters.csv"), meters).unwrap();
        std::fs::write(
            dir.join("project.toml"),
            format!(
                "model = \"model.toml\"\nweather = \"bundled:USA_CO_Golden-NREL.724666_TMY3.epw\"\n\
                 [meters]\nfile = \"meters.csv\"\n\
                 [[meters.columns]]\ncolumn = \"heating_kwh\"\nrole = \"heating\"\nunit = \"kWh\"\nfit = {}\n\
                 [[meters.columns]]\ncolumn = \"electricity_kwh\"\nrole = \"electricity\"\nunit = \"kWh\"\nfit = {}\n",
                fit[0], fit[1]
            ),
        )
        .unwrap();
        Project::load(&dir.join("project.toml")).unwrap()
    }

    #[test]
    fn a_meter_with_fit_false_is_read_but_not_fitted_and_one_must_be_fitted() {
        if bemcal_energyplus::Engine::locate().is_err() {
            eprintln!("no EnergyPlus; skipping");
            return;
        }
        let dir = tempfile::tempdir().unwrap();
        let inputs = load_inputs(&project(dir.path(), [false, true])).unwrap();
        assert_eq!(inputs.outputs, ["heating_kwh", "electricity_kwh"]);
        assert_eq!(inputs.fitted, [false, true]);
        // Still read: validation and model form compare it.
        assert!(inputs.measured[0].iter().all(|v| *v == 2.0));

        let Err(e) = load_inputs(&project(dir.path(), [false, false])) else {
            panic!("every meter fit = false was accepted");
        };
        let e = e.to_string();
        assert!(
            e.contains("project.toml") && e.contains("fit = false") && e.contains("at least one"),
            "{e}"
        );

        // A fitted meter with no reading (an empty column) is refused, not silently the prior.
        project(dir.path(), [true, false]);
        let meters = std::fs::read_to_string(dir.path().join("meters.csv")).unwrap();
        std::fs::write(dir.path().join("meters.csv"), meters.replace(",2,3", ",,3")).unwrap();
        let Err(e) = load_inputs(&Project::load(&dir.path().join("project.toml")).unwrap()) else {
            panic!("a fitted meter with no reading was accepted");
        };
        assert!(e.to_string().contains("no reading left to fit"), "{e}");

        // `fit` is about a meter the model is compared with: refused on a base's column, and
        // where two columns of one role disagree.
        let refused = |extra: &str, line: usize, expected: &str| {
            project(dir.path(), [false, true]);
            let path = dir.path().join("project.toml");
            let text = std::fs::read_to_string(&path).unwrap();
            std::fs::write(&path, format!("{text}{extra}")).unwrap();
            let Err(e) = load_inputs(&Project::load(&path).unwrap()) else {
                panic!("accepted: {extra}");
            };
            let e = e.to_string();
            assert!(
                e.contains(&format!("project.toml:{line}")) && e.contains(expected),
                "{e}"
            );
        };
        refused(
            "[[meters.columns]]\ncolumn = \"electricity_kwh\"\nrole = \"plug\"\nfit = false\n\
             [[bases]]\noutput = \"heating_kwh\"\nsubmeter = \"plug\"\n",
            18,
            "which no model output is compared with",
        );
        refused(
            "[[meters.columns]]\ncolumn = \"electricity_kwh\"\nrole = \"heating\"\n",
            17,
            "one column per role",
        );
    }
}

//! After a finished calibration: the savings of retrofit measures as a posterior predictive
//! (issue 70). EnergyPlus simulates evenly spaced posterior draws with and without each measure
//! (and the estimate, for the point figure beside the intervals), under the calibration's
//! weather and, where the calibration used the metered year's, under the site's typical year
//! too; [`bemcal_stats::savings`] turns the per-draw totals into intervals and drivers.
//!
//! Runs are cached under `savings/<weather>/<measure>/point_NNN.json` by their parameter
//! values ([`crate::design::simulate_point`]), so a rerun, another measure or more draws
//! simulate only what is new. A draw whose simulation fails is left out with its reason.
//!
//! Two parameters the posterior ties together (`|rho| >= SPLIT_CORRELATION`) are a
//! combination the meters constrain, not each one: by default ([`Split::Priors`]) each draw's
//! split between them is drawn again from their priors along that line
//! ([`bemcal_stats::split`]), so that a saving resting on one of them carries the split's
//! uncertainty instead of the chains' (which a surrogate's small errors can pin wrongly).

use std::path::{Path, PathBuf};

use bemcal_energyplus::params::ParameterValues;
use bemcal_energyplus::HourlyOutputs;
use bemcal_stats::savings::{
    corrected, correction, residuals, savings, savings_percent, spread, variance_shares, Correction,
};
use bemcal_weather::grid::slot_month;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::calibration::{Calibration, Log};
use crate::design::simulate_point;
use crate::error::{write_atomic, Error};
use crate::measures::{
    what_would_narrow, Driver, Measure, MeasureSavings, OutputSavings, Partner, RedrawnSplit,
    SavingsMethod, SavingsReport, SavingsWeather,
};
use crate::output::read_record;
use crate::summary::Summary;

mod split;
mod surrogate;

use split::{redraw_splits, split_lines, split_note, split_warning};
use surrogate::SurrogateSide;

/// A parameter explaining at least this share of a saving's variance is named as a driver.
pub const DRIVER_SHARE: f64 = 0.1;

/// A driver explaining at least this share of a saving's variance, tied in the posterior to
/// another parameter ([`SPLIT_CORRELATION`]), makes the saving rest on a split the meters do
/// not make: said in its warning ([`split_warning`]).
pub const SPLIT_SHARE: f64 = 0.5;

/// Two parameters whose posterior correlation reaches this (in size) are a combination the
/// meters constrain, not each one: their split is drawn again from the priors. Measured: the
/// lighting and equipment densities on one electricity meter sit at -0.98 to -1.00; a pair at
/// -0.80 whose two members the meters both narrowed to 0.12 of their priors (lighting density
/// and cooling set-point, tests/savings.rs), redrawn, put the cooling set-point +1 K's saving
/// at 1,491 [1,082, 1,868] kWh against the true 2,201 (2,141 [2,090, 2,177] as the chains have
/// it): below this, the meters do inform the split.
pub const SPLIT_CORRELATION: f64 = 0.95;

/// What `bemcal savings` simulates.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SavingsOptions {
    /// Posterior draws EnergyPlus simulates with and without each measure.
    pub draws: usize,
    /// Posterior draws the surrogate evaluates, corrected onto EnergyPlus's (0: EnergyPlus
    /// alone).
    pub surrogate_draws: usize,
    /// EnergyPlus processes at once.
    pub parallel: usize,
    /// How two parameters the posterior ties together are split at each draw.
    pub split: Split,
}

/// How a saving treats two parameters the posterior ties together (`bemcal savings --split`,
/// `[savings] split`).
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, schemars::JsonSchema,
)]
#[serde(rename_all = "snake_case")]
pub enum Split {
    /// Each draw's split between them drawn again from their priors along the line the meters
    /// constrain ([`bemcal_stats::split::redraw_on_line`]): the default.
    #[default]
    Priors,
    /// The chains' draws as they are.
    Chains,
}

/// The seed of the splits' redraws: the same draws on a rerun, so that cached runs serve.
const SPLIT_SEED: u64 = 70;

/// Simulates `measures` over posterior draws of the finished calibration in `cal.out` (as
/// `opts` says), writes `savings` into its `summary.json` and returns it: a [`SavingsPlan`],
/// its runs simulated here ([`simulate_all`]), and [`SavingsPlan::finish`].
pub fn estimate_savings(
    cal: &Calibration,
    measures: &[Measure],
    opts: SavingsOptions,
    log: Log<'_>,
) -> Result<SavingsReport, Error> {
    let plan = SavingsPlan::new(cal, measures, opts.draws, opts.split)?;
    log(&plan.describe());
    let runs = simulate_all(cal, &plan, opts.parallel, log)?;
    plan.finish(cal, runs, opts.surrogate_draws, None, log)
}

/// One EnergyPlus run of the savings: a point (a posterior draw, or the estimate after them)
/// under one weather, without a measure or with one.
#[derive(Debug, Clone, PartialEq)]
pub struct SavingsRun {
    /// The weather it runs under.
    pub weather: SavingsWeather,
    /// The measure (an index into [`SavingsPlan::measures`]), or none: the baseline.
    pub measure: Option<usize>,
    /// The point's key: its file is `point_<key>.json` in [`SavingsPlan::run_rel`]'s folder.
    pub key: usize,
    /// The parameters' values, the measure applied.
    pub values: ParameterValues,
}

/// What a finished calibration's savings simulate, decided once ([`SavingsPlan::new`]): the
/// posterior draws (their splits redrawn where the posterior ties two parameters), the
/// estimate, the weathers and, per weather and point, the baseline's run and each measure's
/// ([`SavingsPlan::runs`]). Whoever simulates the runs (here, or a coordinator's workers)
/// hands their results to [`SavingsPlan::finish`] in the same order.
pub struct SavingsPlan {
    /// The measures, checked.
    pub measures: Vec<Measure>,
    /// Every run, per weather, per point (the draws, then the estimate), the baseline and
    /// then each measure.
    pub runs: Vec<SavingsRun>,
    notes_of: Vec<Vec<String>>,
    summary: Summary,
    posterior: PosteriorDraws,
    lines: Vec<RedrawnSplit>,
    rows: Vec<Vec<f64>>,
    points: Vec<ParameterValues>,
    weathers: Vec<(SavingsWeather, PathBuf)>,
    models: Vec<bemcal_energyplus::Model>,
}

impl SavingsPlan {
    /// The plan of `measures` over `draws` posterior draws of the finished calibration in
    /// `cal.out`, two tied parameters split as `split` says.
    pub fn new(
        cal: &Calibration,
        measures: &[Measure],
        draws: usize,
        split: Split,
    ) -> Result<SavingsPlan, Error> {
        check_draws(draws).map_err(Error::Config)?;
        let inp = &cal.inputs;
        let plan = &inp.plan;
        let notes_of = check_measures(cal, measures)?;
        let summary = finished_summary(cal)?;
        let posterior = PosteriorDraws::read(cal)?;
        let lines = split_lines(cal, &summary, &posterior.rows, split);
        let rows = redraw_splits(cal, &lines, posterior.evenly(draws), SPLIT_SEED);
        let estimate = estimate_point(&summary, &plan.calibrated)?;
        let points: Vec<ParameterValues> = rows
            .iter()
            .chain(std::iter::once(&estimate))
            .map(|x| plan.values(x))
            .collect();
        let weathers = weathers(cal)?;
        let models = (measures.iter())
            .map(|m| m.model(&inp.model, inp.runner.idd()))
            .collect::<Result<Vec<_>, _>>()
            .map_err(|message| cal.project.error_at(&["measures"], message))?;
        let mut runs = vec![];
        for (w, _) in &weathers {
            for (key, v) in points.iter().enumerate() {
                let run = |measure, values| SavingsRun {
                    weather: *w,
                    measure,
                    key,
                    values,
                };
                runs.push(run(None, v.clone()));
                for (j, m) in measures.iter().enumerate() {
                    runs.push(run(Some(j), m.apply(v)));
                }
            }
        }
        Ok(SavingsPlan {
            measures: measures.to_vec(),
            runs,
            notes_of,
            summary,
            posterior,
            lines,
            rows,
            points,
            weathers,
            models,
        })
    }

    /// One line for the log: how many runs.
    pub fn describe(&self) -> String {
        format!(
            "savings: {} measure(s) at {} posterior draws and the estimate, {} weather(s): {} \
             EnergyPlus runs (cached ones reloaded)",
            self.measures.len(),
            self.rows.len(),
            self.weathers.len(),
            self.runs.len()
        )
    }

    /// The folder of `run`'s file, relative to the output folder.
    pub fn run_rel(&self, run: &SavingsRun) -> String {
        run_rel(run.weather, run.measure.map(|j| &self.measures[j]))
    }

    /// `run`'s file, relative to the output folder ([`run_file`]).
    pub fn run_file(&self, run: &SavingsRun) -> String {
        run_file(run.weather, run.measure.map(|j| &self.measures[j]), run.key)
    }

    /// The weathers the plan's runs are under, with their files.
    pub fn weathers(&self) -> &[(SavingsWeather, PathBuf)] {
        &self.weathers
    }

    /// The weather file of `run`.
    fn weather_path(&self, run: &SavingsRun) -> &Path {
        let (_, path) = (self.weathers.iter())
            .find(|(w, _)| *w == run.weather)
            .expect("a plan's runs are under its weathers");
        path
    }

    /// The model of `run`: the measure's building where it edits one.
    fn model<'a>(&'a self, cal: &'a Calibration, run: &SavingsRun) -> &'a bemcal_energyplus::Model {
        run.measure.map_or(&cal.inputs.model, |j| &self.models[j])
    }

    /// The savings from the runs' results (one per [`SavingsPlan::runs`], in order; a failed
    /// run: its reason), corrected by `surrogate_draws` of the surrogate where that is more
    /// than 0: written into `summary.json` (`savings`, and `timings` where given: the
    /// calibration's with its savings stage) and returned.
    pub fn finish(
        self,
        cal: &Calibration,
        runs: Vec<Result<HourlyOutputs, String>>,
        surrogate_draws: usize,
        timings: Option<crate::summary::Timings>,
        log: Log<'_>,
    ) -> Result<SavingsReport, Error> {
        if runs.len() != self.runs.len() {
            return Err(Error::Config(format!(
                "savings: {} results for {} runs",
                runs.len(),
                self.runs.len()
            )));
        }
        let simulated = Simulated {
            cal,
            summary: &self.summary,
            rows: &self.rows,
            points: &self.points,
            weathers: self.weathers.iter().map(|(w, _)| *w).collect(),
            measures: self.measures.len(),
            runs,
            lines: &self.lines,
        };
        let mut surrogate = match surrogate_draws {
            0 => None,
            n => SurrogateSide::load(cal, self.posterior.evenly(n), &self.rows, &self.lines, log)?,
        };
        let mut out = vec![];
        for (j, m) in self.measures.iter().enumerate() {
            let mut ms = simulated.measure(j, m, self.notes_of[j].clone());
            if let Some(side) = surrogate.as_mut() {
                // Inside the surrogate's training range: its model, priors and calibrated
                // parameters (a measure that edits the model, or a parameter held fixed, has
                // a note).
                if !m.edits_model() && ms.beyond_prior.is_empty() && ms.notes.is_empty() {
                    side.correct(&simulated, j, m, &mut ms)?;
                }
            }
            out.push(ms);
        }
        let failed = simulated.runs.iter().filter(|r| r.is_err()).count();
        if failed > 0 {
            log(&format!(
                "savings: {failed} of {} EnergyPlus runs failed and are left out (reasons in \
                 summary.json savings.measures[].failed)",
                simulated.runs.len()
            ));
        }
        let mut notes = report_notes(&self.summary, self.rows.len());
        notes.extend(self.lines.iter().map(split_note));
        let report = SavingsReport {
            draws: self.rows.len(),
            draws_file: self.posterior.file.clone(),
            notes,
            split_redrawn: self.lines.clone(),
            measures: out,
        };
        let mut summary = self.summary;
        summary.savings = Some(report.clone());
        if let Some(t) = timings {
            summary.timings = t;
        }
        let json = serde_json::to_vec_pretty(&summary).map_err(|e| Error::Config(e.to_string()))?;
        write_atomic(&cal.out.summary_json(), &json)?;
        Ok(report)
    }
}

/// A savings run as a measure job names it (`MeasureJob`'s weather word and measure JSON,
/// empty for the baseline): its weather and its measure, checked.
pub fn parse_run(
    weather: &str,
    measure_json: &str,
) -> Result<(SavingsWeather, Option<Measure>), String> {
    let w: SavingsWeather = serde_json::from_value(serde_json::Value::String(weather.into()))
        .map_err(|e| format!("a savings run's weather {weather:?}: {e}"))?;
    let measure = match measure_json {
        "" => None,
        json => {
            let m: Measure =
                serde_json::from_str(json).map_err(|e| format!("a savings run's measure: {e}"))?;
            m.check()?;
            Some(m)
        }
    };
    Ok((w, measure))
}

/// Posterior draws a saving needs: at least 2 (an interval needs a spread).
pub fn check_draws(draws: usize) -> Result<(), String> {
    match draws {
        0 | 1 => Err(format!(
            "{draws} posterior draws for the savings: at least 2 (an interval needs a spread)"
        )),
        _ => Ok(()),
    }
}

/// The weathers a saving is estimated under: the calibration's and, where the calibration
/// used the metered year's weather, the site's typical year.
fn weathers(cal: &Calibration) -> Result<Vec<(SavingsWeather, PathBuf)>, Error> {
    let mut weathers = vec![(SavingsWeather::Calibration, cal.inputs.weather_path.clone())];
    if cal.project.measured_weather.is_some() {
        let typical = crate::inputs::resolve_weather(&cal.project, cal.inputs.runner.engine())?;
        weathers.push((SavingsWeather::Typical, typical));
    }
    Ok(weathers)
}

/// The folder of a savings run's file under `weather`, with `measure` or without (the
/// baseline), relative to the output folder: `savings/<weather>/<baseline | measure>`.
pub fn run_rel(weather: SavingsWeather, measure: Option<&Measure>) -> String {
    let folder = measure.map_or_else(|| "baseline".to_string(), Measure::runs_folder);
    format!("savings/{}/{folder}", weather.as_str())
}

/// A savings run's file, relative to the output folder: `point_<key>.json` in [`run_rel`]'s
/// folder (where the worker writes it, the coordinator checks and places it).
pub fn run_file(weather: SavingsWeather, measure: Option<&Measure>, key: usize) -> String {
    format!(
        "{}/{}",
        run_rel(weather, measure),
        crate::output::point_file(key)
    )
}

/// What one savings run needs besides its values, outside a plan (as a worker runs it): the
/// weather file and the model (the measure's building where it edits one), and its folder.
pub struct SavingsRunInputs {
    weather: PathBuf,
    model: bemcal_energyplus::Model,
    dir: PathBuf,
}

impl SavingsRunInputs {
    /// The inputs of a run under `weather` with `measure` (none: the baseline), its folder
    /// [`run_rel`]'s in `cal.out`.
    pub fn of(
        cal: &Calibration,
        weather: SavingsWeather,
        measure: Option<&Measure>,
    ) -> Result<SavingsRunInputs, Error> {
        let path = (weathers(cal)?.into_iter())
            .find(|(w, _)| *w == weather)
            .map(|(_, p)| p)
            .ok_or_else(|| {
                Error::Config(format!(
                    "savings under the {} weather: the project has no measured weather",
                    weather.as_str()
                ))
            })?;
        let model = match measure {
            Some(m) => {
                (m.model(&cal.inputs.model, cal.inputs.runner.idd())).map_err(Error::Config)?
            }
            None => cal.inputs.model.clone(),
        };
        let dir = cal.out.join(run_rel(weather, measure));
        std::fs::create_dir_all(&dir).map_err(|e| Error::io(&dir, e))?;
        Ok(SavingsRunInputs {
            weather: path,
            model,
            dir,
        })
    }

    /// EnergyPlus (or the cached file) at `values`, saved as `point_<key>.json` in the run's
    /// folder; its outputs and EnergyPlus's wall time (none where the file was there).
    pub fn simulate(
        &self,
        cal: &Calibration,
        key: usize,
        values: &ParameterValues,
    ) -> crate::design::PointRun {
        let runner = &cal.inputs.runner;
        simulate_point(runner, &self.model, values, &self.weather, &self.dir, key)
    }
}

/// Each measure checked against the model and the calibration (the first refused: an error
/// at the project's `measures`), with the notes a reader needs ([`Measure::check_model`]).
fn check_measures(cal: &Calibration, measures: &[Measure]) -> Result<Vec<Vec<String>>, Error> {
    let (inp, plan) = (&cal.inputs, &cal.inputs.plan);
    if measures.is_empty() {
        return Err(cal.project.error_at(
            &["measures"],
            "no measures: add [[measures]] to the project (a name and set, scale or offset \
             of parameters, building fields, or idf edits)"
                .into(),
        ));
    }
    (measures.iter())
        .map(|m| {
            m.check()
                .and_then(|()| {
                    m.check_model(&inp.model, inp.runner.idd(), &plan.calibrated, &plan.fixed)
                })
                .map_err(|message| cal.project.error_at(&["measures"], message))
        })
        .collect()
}

/// The finished calibration's `summary.json`, or why there is none to estimate savings from.
fn finished_summary(cal: &Calibration) -> Result<Summary, Error> {
    read_record(&cal.out.summary_json())
        .map_err(|e| Error::Input {
            path: cal.out.summary_json(),
            line: e.line(),
            message: format!("not a calibration's summary.json: {e}"),
        })?
        .ok_or_else(|| {
            Error::Config(format!(
                "no finished calibration in {}: savings need its summary.json and draws.csv \
                 (run bemcal calibrate first)",
                cal.out.display()
            ))
        })
}

/// A point's runs without and with a measure (a failed run: its reason).
type Pair<'a> = (
    Result<&'a HourlyOutputs, String>,
    Result<&'a HourlyOutputs, String>,
);

/// The savings' runs: per weather, per point (the draws, then the estimate), the baseline and
/// then each measure.
struct Simulated<'a> {
    cal: &'a Calibration,
    summary: &'a Summary,
    rows: &'a [Vec<f64>],
    points: &'a [ParameterValues],
    weathers: Vec<SavingsWeather>,
    measures: usize,
    runs: Vec<Result<HourlyOutputs, String>>,
    /// The pairs whose split was drawn again.
    lines: &'a [RedrawnSplit],
}

impl Simulated<'_> {
    /// Every point's pair for measure `j` under weather `k`.
    fn pairs(&self, k: usize, j: usize) -> Vec<Pair<'_>> {
        let per_point = 1 + self.measures;
        let at = |i: usize, slot: usize| {
            self.runs[(k * self.points.len() + i) * per_point + slot]
                .as_ref()
                .map_err(Clone::clone)
        };
        (0..self.points.len())
            .map(|i| (at(i, 0), at(i, 1 + j)))
            .collect()
    }

    /// Measure `j`'s savings on every output under every weather.
    fn measure(&self, j: usize, m: &Measure, notes: Vec<String>) -> MeasureSavings {
        let mut outputs = vec![];
        let mut failed = vec![];
        for (k, w) in self.weathers.iter().enumerate() {
            let pairs = self.pairs(k, j);
            for (i, (b, a)) in pairs.iter().enumerate() {
                for e in [b.as_ref().err(), a.as_ref().err()].into_iter().flatten() {
                    let which = if i == self.rows.len() {
                        "the estimate".to_string()
                    } else {
                        format!("draw {i}")
                    };
                    failed.push(format!("{} weather, {which}: {e}", w.as_str()));
                }
            }
            outputs.extend(output_savings(
                self.cal,
                self.summary,
                self.lines,
                *w,
                self.rows,
                &pairs,
            ));
        }
        let beyond_prior = beyond_prior(&self.cal.inputs.model, m, self.points);
        MeasureSavings {
            measure: m.name.clone(),
            edits: m.describe(),
            method: SavingsMethod::Energyplus,
            method_note: method_note(m, &beyond_prior, &notes),
            surrogate_draws: 0,
            beyond_prior,
            notes,
            failed,
            outputs,
        }
    }
}

/// Every run of `plan` (reloaded where cached), in order, `parallel` at once; a failed run
/// is its reason.
pub fn simulate_all(
    cal: &Calibration,
    plan: &SavingsPlan,
    parallel: usize,
    log: Log<'_>,
) -> Result<Vec<Result<HourlyOutputs, String>>, Error> {
    let inp = &cal.inputs;
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(parallel.max(1))
        .build()
        .map_err(|e| Error::Config(format!("thread pool: {e}")))?;
    let done = std::sync::atomic::AtomicUsize::new(0);
    let n = plan.runs.len();
    Ok(pool.install(|| {
        (plan.runs.par_iter())
            .map(|run| {
                let dir = cal.out.join(plan.run_rel(run));
                let r = std::fs::create_dir_all(&dir)
                    .map_err(|e| Error::io(&dir, e))
                    .and_then(|()| {
                        let (model, weather) = (plan.model(cal, run), plan.weather_path(run));
                        simulate_point(&inp.runner, model, &run.values, weather, &dir, run.key)
                    })
                    .map(|(o, _)| o)
                    .map_err(|e| bemcal_excerpt::shorten(&e.to_string()).into_owned());
                let k = done.fetch_add(1, std::sync::atomic::Ordering::SeqCst) + 1;
                if k.is_multiple_of(20) || k == n {
                    log(&format!("savings: {k} of {n} runs"));
                }
                r
            })
            .collect()
    }))
}

/// The calibration's posterior draws of the calibrated parameters (in the plan's order), read
/// once: from `draws_with_surrogate_error.csv` where the calibration carried the surrogate's
/// error into its draws (as its predictive intervals do), else `draws.csv`.
struct PosteriorDraws {
    /// The file's name.
    file: String,
    /// Every draw, in the file's order.
    rows: Vec<Vec<f64>>,
}

impl PosteriorDraws {
    fn read(cal: &Calibration) -> Result<PosteriorDraws, Error> {
        let with_error = cal.out.draws_with_surrogate_error_csv();
        let path = if with_error.is_file() {
            with_error
        } else {
            cal.out.draws_csv()
        };
        let file = path
            .file_name()
            .map(|f| f.to_string_lossy().into_owned())
            .unwrap_or_default();
        let bad = |line: usize, message: String| Error::Input {
            path: path.clone(),
            line,
            message,
        };
        let mut reader =
            csv::Reader::from_path(&path).map_err(|e| bad(0, format!("cannot read: {e}")))?;
        let header = reader.headers().map_err(|e| bad(1, e.to_string()))?.clone();
        let columns: Vec<usize> = (cal.inputs.plan.calibrated.iter())
            .map(|n| {
                header.iter().position(|h| h == n).ok_or_else(|| {
                    bad(
                        1,
                        format!(
                        "no column '{n}': the draws are of another calibration than the project's"
                    ),
                    )
                })
            })
            .collect::<Result<_, _>>()?;
        let mut rows = vec![];
        for (r, record) in reader.records().enumerate() {
            let record = record.map_err(|e| bad(r + 2, e.to_string()))?;
            let row = columns
                .iter()
                .map(|&c| record.get(c).and_then(|v| v.trim().parse::<f64>().ok()))
                .collect::<Option<Vec<f64>>>()
                .ok_or_else(|| {
                    bad(
                        r + 2,
                        "expected a number in every parameter's column".into(),
                    )
                })?;
            rows.push(row);
        }
        if rows.is_empty() {
            return Err(bad(0, "no draws".into()));
        }
        Ok(PosteriorDraws { file, rows })
    }

    /// `k` evenly spaced draws ([`evenly`]).
    fn evenly(&self, k: usize) -> Vec<Vec<f64>> {
        (evenly(self.rows.len(), k).into_iter())
            .map(|i| self.rows[i].clone())
            .collect()
    }
}

/// `k` indices spread evenly over `0..n` (all of them where `k >= n`).
pub fn evenly(n: usize, k: usize) -> Vec<usize> {
    if k >= n {
        return (0..n).collect();
    }
    (0..k).map(|i| ((2 * i + 1) * n) / (2 * k)).collect()
}

/// The calibration's estimate in the plan's order, from `summary.json`.
fn estimate_point(summary: &Summary, calibrated: &[String]) -> Result<Vec<f64>, Error> {
    calibrated
        .iter()
        .map(|n| {
            summary
                .calibrated_values
                .iter()
                .find(|(m, _)| m == n)
                .map(|(_, v)| *v)
                .ok_or_else(|| {
                    Error::Config(format!(
                        "summary.json has no calibrated value of {n}: it is of another calibration"
                    ))
                })
        })
        .collect()
}

/// An output's energy over the year (index 0) and each month (1-12: January to December), kWh.
pub type Periods = [f64; 13];

/// The year's and each month's totals of an hourly series on the 8,760-slot grid.
pub fn periods(hours: impl IntoIterator<Item = f64>) -> Periods {
    let mut p = [0.0; 13];
    for (t, v) in hours.into_iter().enumerate() {
        p[0] += v;
        p[slot_month(t) as usize] += v;
    }
    p
}

/// One output's energy at each draw without and with a measure, and the draws' parameters.
struct PerDraw {
    base: Vec<Periods>,
    after: Vec<Periods>,
    params: Vec<Vec<f64>>,
}

/// One output's savings per weather from the pairs (without, with) of every point (the draws,
/// then the estimate).
fn output_savings(
    cal: &Calibration,
    summary: &Summary,
    lines: &[RedrawnSplit],
    weather: SavingsWeather,
    rows: &[Vec<f64>],
    pairs: &[Pair<'_>],
) -> Vec<OutputSavings> {
    let n = rows.len();
    let ok: Vec<usize> = (0..n)
        .filter(|&i| pairs[i].0.is_ok() && pairs[i].1.is_ok())
        .collect();
    if ok.is_empty() {
        return vec![];
    }
    let mut out = vec![];
    for spec in cal.inputs.model.outputs() {
        let name = &spec.name;
        let of = |o: &HourlyOutputs| periods(o.get(name).unwrap_or(&[]).iter().copied());
        let d = PerDraw {
            base: ok
                .iter()
                .map(|&i| of(pairs[i].0.as_ref().unwrap()))
                .collect(),
            after: ok
                .iter()
                .map(|&i| of(pairs[i].1.as_ref().unwrap()))
                .collect(),
            params: ok.iter().map(|&i| rows[i].clone()).collect(),
        };
        let at_estimate_kwh = match &pairs[n] {
            (Ok(b), Ok(a)) => of(b)[0] - of(a)[0],
            _ => f64::NAN,
        };
        out.extend(summarise(
            cal,
            summary,
            lines,
            weather,
            name,
            &d,
            at_estimate_kwh,
        ));
    }
    out
}

/// A saving's figures from its per-draw energies.
fn summarise(
    cal: &Calibration,
    summary: &Summary,
    lines: &[RedrawnSplit],
    weather: SavingsWeather,
    name: &str,
    d: &PerDraw,
    at_estimate_kwh: f64,
) -> Option<OutputSavings> {
    let period = |p: usize, of: &[Periods]| of.iter().map(|x| x[p]).collect::<Vec<f64>>();
    let (base, after) = (period(0, &d.base), period(0, &d.after));
    let s = savings(&base, &after);
    let monthly_kwh = (1..13)
        .filter_map(|p| spread(&savings(&period(p, &d.base), &period(p, &d.after))))
        .collect();
    let params: Vec<Vec<f64>> = (0..cal.inputs.plan.calibrated.len())
        .map(|k| d.params.iter().map(|x| x[k]).collect())
        .collect();
    let drivers = drivers(cal, summary, &variance_shares(&params, &s));
    Some(OutputSavings {
        output: name.to_string(),
        weather,
        n: base.len(),
        baseline_kwh: spread(&base)?.median,
        savings_kwh: spread(&s)?,
        savings_percent: spread(&savings_percent(&base, &after))?,
        at_estimate_kwh,
        monthly_kwh,
        drivers: drivers.clone(),
        warning: [warning(cal, summary, name), split_warning(&drivers, lines)]
            .into_iter()
            .flatten()
            .reduce(|a, b| format!("{a}; {b}")),
        correction: None,
    })
}

/// The parameters explaining [`DRIVER_SHARE`] or more of a saving's variance, largest first.
fn drivers(cal: &Calibration, summary: &Summary, shares: &[f64]) -> Vec<Driver> {
    let mut d: Vec<Driver> = (cal.inputs.plan.calibrated.iter())
        .zip(shares)
        .filter(|(_, s)| **s >= DRIVER_SHARE)
        .map(|(name, share)| Driver {
            parameter: name.clone(),
            share: *share,
            width_ratio: (summary.posterior.parameters.iter())
                .find(|p| &p.name == name)
                .map_or(f64::NAN, |p| p.width_ratio),
            would_narrow: what_would_narrow(name).to_string(),
            moves_with: (summary.posterior.correlated_pairs.iter())
                .filter(|c| c.rho.abs() >= SPLIT_CORRELATION)
                .filter_map(|c| {
                    let other = if &c.a == name {
                        &c.b
                    } else if &c.b == name {
                        &c.a
                    } else {
                        return None;
                    };
                    Some(Partner {
                        parameter: other.clone(),
                        correlation: c.rho,
                    })
                })
                .collect(),
        })
        .collect();
    d.sort_by(|a, b| b.share.total_cmp(&a.share));
    d
}

/// Why an output's savings may not be trusted as they stand: no meter, a meter that checked
/// but did not fit, or Guideline 14 missed at the estimate.
fn warning(cal: &Calibration, summary: &Summary, output: &str) -> Option<String> {
    if !cal.inputs.outputs.iter().any(|o| o == output) {
        return Some("no meter: this saving rests on the model alone".into());
    }
    if summary.not_fitted.iter().any(|o| o == output) {
        return Some(
            "its meter was not fitted (fit = false): the calibration did not learn from it".into(),
        );
    }
    let v = summary.validation.iter().find(|v| v.output == output)?;
    (!v.metrics.pass).then(|| {
        format!(
            "misses ASHRAE Guideline 14 {} at the estimate (NMBE {:.1} %, CV-RMSE {:.1} %): the \
             model does not follow this meter, and its savings are the model's",
            if v.resolution.is_hourly() {
                "hourly"
            } else {
                "on its bills"
            },
            v.metrics.nmbe,
            v.metrics.cv_rmse
        )
    })
}

/// The parameters the measure takes outside their prior's support at some point.
fn beyond_prior(
    model: &bemcal_energyplus::Model,
    measure: &Measure,
    points: &[ParameterValues],
) -> Vec<String> {
    let edits = measure.edits();
    (model.parameters().iter())
        .filter(|p| edits.iter().any(|(n, _)| *n == p.name))
        .filter(|p| {
            points.iter().any(|v| {
                let after = measure.apply(v);
                after.get(&p.name).is_some_and(|x| !p.prior.contains(*x))
            })
        })
        .map(|p| p.name.clone())
        .collect()
}

/// Why EnergyPlus simulates the measure: it leaves the surrogate's training range (the
/// building, a prior's support, or a parameter the surrogate held fixed), or the surrogate
/// route was not asked for.
fn method_note(m: &Measure, beyond_prior: &[String], not_calibrated: &[String]) -> String {
    if !m.building.is_empty() {
        "EnergyPlus at every draw: the measure edits the building, which the surrogate was \
         trained with fixed"
            .into()
    } else if !m.idf.is_empty() {
        "EnergyPlus at every draw: the measure edits the IDF's objects, which the surrogate \
         was trained with fixed"
            .into()
    } else if !beyond_prior.is_empty() {
        format!(
            "EnergyPlus at every draw: the measure takes {} outside its prior, the surrogate's \
             training range",
            beyond_prior.join(", ")
        )
    } else if !not_calibrated.is_empty() {
        "EnergyPlus at every draw: the measure edits a parameter the surrogate was trained \
         with fixed"
            .into()
    } else {
        "EnergyPlus at every draw (--surrogate-draws N adds the surrogate at N draws, corrected \
         onto EnergyPlus at these)"
            .into()
    }
}

/// Which of `draws` savings end the 90 % interval, and how often a further posterior draw
/// falls inside ([`bemcal_stats::savings::interval_rank`]).
fn interval_note(draws: usize) -> String {
    let (k, inside) = bemcal_stats::savings::interval_rank(draws, 0.9);
    let ends = if k == 1 {
        "the smallest and largest".to_string()
    } else {
        format!("the {k}th smallest and largest")
    };
    let mut note = format!(
        "the 90 % interval's ends are {ends} of {draws} draws' savings: a further posterior \
         draw falls inside with probability {:.0} %",
        100.0 * inside
    );
    if inside < 0.9 {
        note.push_str(
            " (fewer than 19 draws cannot make a 90 % interval: give --draws 19 or more, or \
             --surrogate-draws)",
        );
    }
    note
}

/// How the model's errors and the chains' temperature enter the savings.
fn report_notes(summary: &Summary, draws: usize) -> Vec<String> {
    let mut notes = vec![
        "each saving is a difference of two EnergyPlus runs at the same posterior draw: an \
         additive discrepancy (the model-form term, the bases the model does not have) is the \
         same in both and cancels; the intervals carry the parameters' posterior spread, not a \
         model-form error that changes with the measure"
            .to_string(),
        interval_note(draws),
    ];
    let t = summary.temperature.value;
    if t > 1.0 {
        notes.push(format!(
            "the chains sampled at temperature T = {t:.1}: the draws spread as the surrogate's \
             error allows, which widens these intervals beyond what the meters alone say"
        ));
    }
    notes
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A saving driven by a parameter the posterior ties to another warns that the split is
    /// not the meters'; a minor driver, or one on its own, does not.
    #[test]
    fn a_saving_on_a_split_the_meters_do_not_make_is_warned() {
        let driver = |name: &str, share: f64, partner: Option<(&str, f64)>| Driver {
            parameter: name.into(),
            share,
            width_ratio: 0.1,
            would_narrow: what_would_narrow(name).into(),
            moves_with: partner
                .map(|(p, r)| Partner {
                    parameter: p.into(),
                    correlation: r,
                })
                .into_iter()
                .collect(),
        };
        let led = [driver(
            "lighting_power_density",
            0.98,
            Some(("equipment_power_density", -0.99)),
        )];
        let w = split_warning(&led, &[]).unwrap();
        assert!(
            w.contains("equipment_power_density (posterior correlation -0.99)")
                && w.contains("likely too narrow")
                && w.contains("lighting sub-meter"),
            "{w}"
        );
        let line = RedrawnSplit {
            a: "equipment_power_density".into(),
            b: "lighting_power_density".into(),
            correlation: -0.99,
            direction: [0.7, -0.7],
        };
        let w = split_warning(&led, &[line]).unwrap();
        assert!(w.contains("drawn from their priors"), "{w}");
        let minor = [
            driver("cooling_setpoint_occupied", 0.8, None),
            driver(
                "lighting_power_density",
                0.2,
                Some(("equipment_power_density", -0.99)),
            ),
        ];
        assert_eq!(split_warning(&minor, &[]), None);
    }

    #[test]
    fn evenly_spaced_draws_cover_the_chains() {
        assert_eq!(evenly(10, 5), vec![1, 3, 5, 7, 9]);
        assert_eq!(evenly(3, 5), vec![0, 1, 2]);
        assert_eq!(evenly(800, 4), vec![100, 300, 500, 700]);
    }

    #[test]
    fn periods_follow_the_grid() {
        let p = periods(vec![1.0; 8760]);
        assert_eq!(p[0], 8760.0);
        assert_eq!(p[1], 31.0 * 24.0);
        assert_eq!(p[2], 28.0 * 24.0);
        assert_eq!(p[1..].iter().sum::<f64>(), 8760.0);
    }
}

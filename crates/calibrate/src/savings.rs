//! After a finished calibration: the savings of retrofit measures as a posterior predictive
//! (issue 70). EnergyPlus simulates evenly spaced posterior draws with and without each measure
//! (and the estimate, for the point figure beside the intervals), under the calibration's
//! weather and, where the calibration used the metered year's, under the site's typical year
//! too; [`bemcal_stats::savings`] turns the per-draw totals into intervals and drivers.
//!
//! Runs are cached under `savings/<weather>/<measure>/point_NNN.json` by their parameter
//! values ([`crate::design::simulate_point`]), so a rerun, another measure or more draws
//! simulate only what is new. A draw whose simulation fails is left out with its reason.

use std::path::{Path, PathBuf};

use bemcal_energyplus::params::ParameterValues;
use bemcal_energyplus::HourlyOutputs;
use bemcal_stats::savings::{savings, savings_percent, spread, variance_shares};
use bemcal_weather::grid::slot_month;
use rayon::prelude::*;

use crate::calibration::{Calibration, Log};
use crate::design::simulate_point;
use crate::error::{write_atomic, Error};
use crate::measures::{
    what_would_narrow, Driver, Measure, MeasureSavings, OutputSavings, SavingsMethod,
    SavingsReport, SavingsWeather,
};
use crate::output::read_record;
use crate::summary::Summary;

/// A parameter explaining at least this share of a saving's variance is named as a driver.
pub const DRIVER_SHARE: f64 = 0.1;

/// Simulates `measures` at `draws` posterior draws of the finished calibration in `cal.out`
/// (with `parallel` EnergyPlus processes), writes `savings` into its `summary.json` and returns
/// it.
pub fn estimate_savings(
    cal: &Calibration,
    measures: &[Measure],
    draws: usize,
    parallel: usize,
    log: Log<'_>,
) -> Result<SavingsReport, Error> {
    let inp = &cal.inputs;
    let plan = &inp.plan;
    if measures.is_empty() {
        return Err(cal.project.error_at(
            &["measures"],
            "no measures: add [[measures]] to the project (a name and set, scale or offset \
             of parameters)"
                .into(),
        ));
    }
    let mut notes_of = vec![];
    for m in measures {
        m.check()
            .and_then(|()| m.check_model(&inp.model, &plan.calibrated, &plan.fixed))
            .map(|n| notes_of.push(n))
            .map_err(|message| cal.project.error_at(&["measures"], message))?;
    }
    let mut summary: Summary = read_record(&cal.out.summary_json())
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
        })?;
    let (draws_file, rows) = posterior_draws(cal, draws)?;
    let estimate = estimate_point(&summary, &plan.calibrated)?;
    let points: Vec<ParameterValues> = rows
        .iter()
        .chain(std::iter::once(&estimate))
        .map(|x| plan.values(x))
        .collect();
    let mut weathers = vec![(SavingsWeather::Calibration, inp.weather_path.clone())];
    if cal.project.measured_weather.is_some() {
        let typical = crate::inputs::resolve_weather(&cal.project, inp.runner.engine())?;
        weathers.push((SavingsWeather::Typical, typical));
    }
    let root = cal.out.join("savings");
    let mut jobs: Vec<(PathBuf, &Path, usize, ParameterValues)> = vec![];
    for (w, path) in &weathers {
        for (i, v) in points.iter().enumerate() {
            jobs.push((root.join(w.as_str()).join("baseline"), path, i, v.clone()));
            for m in measures {
                let dir = root.join(w.as_str()).join(m.folder());
                jobs.push((dir, path, i, m.apply(v)));
            }
        }
    }
    log(&format!(
        "savings: {} measure(s) at {} posterior draws and the estimate, {} weather(s): {} \
         EnergyPlus runs (cached ones reloaded)",
        measures.len(),
        rows.len(),
        weathers.len(),
        jobs.len()
    ));
    let simulated = Simulated {
        cal,
        summary: &summary,
        rows: &rows,
        points: &points,
        weathers: weathers.iter().map(|(w, _)| *w).collect(),
        measures: measures.len(),
        runs: simulate_all(cal, &jobs, parallel, log)?,
    };
    let out = (measures.iter().enumerate())
        .map(|(j, m)| simulated.measure(j, m, notes_of[j].clone()))
        .collect();
    let report = SavingsReport {
        draws: rows.len(),
        draws_file,
        notes: report_notes(&summary, rows.len()),
        measures: out,
    };
    summary.savings = Some(report.clone());
    let json = serde_json::to_vec_pretty(&summary).map_err(|e| Error::Config(e.to_string()))?;
    write_atomic(&cal.out.summary_json(), &json)?;
    Ok(report)
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
            method_note: method_note(&beyond_prior, &notes),
            beyond_prior,
            notes,
            failed,
            outputs,
        }
    }
}

/// Every job's run (reloaded where cached), in order; a failed run is its reason.
fn simulate_all(
    cal: &Calibration,
    jobs: &[(PathBuf, &Path, usize, ParameterValues)],
    parallel: usize,
    log: Log<'_>,
) -> Result<Vec<Result<HourlyOutputs, String>>, Error> {
    let inp = &cal.inputs;
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(parallel.max(1))
        .build()
        .map_err(|e| Error::Config(format!("thread pool: {e}")))?;
    let done = std::sync::atomic::AtomicUsize::new(0);
    Ok(pool.install(|| {
        jobs.par_iter()
            .map(|(dir, weather, i, values)| {
                let r = std::fs::create_dir_all(dir)
                    .map_err(|e| Error::io(dir, e))
                    .and_then(|()| {
                        simulate_point(&inp.runner, &inp.model, values, weather, dir, *i)
                    })
                    .map(|(o, _)| o)
                    .map_err(|e| bemcal_excerpt::shorten(&e.to_string()).into_owned());
                let n = done.fetch_add(1, std::sync::atomic::Ordering::SeqCst) + 1;
                if n.is_multiple_of(20) || n == jobs.len() {
                    log(&format!("savings: {n} of {} runs", jobs.len()));
                }
                r
            })
            .collect()
    }))
}

/// `k` evenly spaced rows of the posterior draws (the calibrated parameters, in the plan's
/// order): from `draws_with_surrogate_error.csv` where the calibration carried the surrogate's
/// error into its draws (as its predictive intervals do), else `draws.csv`.
fn posterior_draws(cal: &Calibration, k: usize) -> Result<(String, Vec<Vec<f64>>), Error> {
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
    Ok((
        file,
        evenly(rows.len(), k)
            .into_iter()
            .map(|i| rows[i].clone())
            .collect(),
    ))
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

/// One output's savings per weather from the pairs (without, with) of every point (the draws,
/// then the estimate).
fn output_savings(
    cal: &Calibration,
    summary: &Summary,
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
        let annual = |o: &HourlyOutputs| o.get(name).map_or(f64::NAN, |h| h.iter().sum());
        let monthly = |o: &HourlyOutputs| monthly_totals(o.get(name).unwrap_or(&[]));
        let base: Vec<f64> = ok
            .iter()
            .map(|&i| annual(pairs[i].0.as_ref().unwrap()))
            .collect();
        let after: Vec<f64> = ok
            .iter()
            .map(|&i| annual(pairs[i].1.as_ref().unwrap()))
            .collect();
        let s = savings(&base, &after);
        let (Some(savings_kwh), Some(savings_pct), Some(baseline)) = (
            spread(&s),
            spread(&savings_percent(&base, &after)),
            spread(&base),
        ) else {
            continue;
        };
        let months_b: Vec<[f64; 12]> = ok
            .iter()
            .map(|&i| monthly(pairs[i].0.as_ref().unwrap()))
            .collect();
        let months_a: Vec<[f64; 12]> = ok
            .iter()
            .map(|&i| monthly(pairs[i].1.as_ref().unwrap()))
            .collect();
        let monthly_kwh = (0..12)
            .filter_map(|m| {
                let b: Vec<f64> = months_b.iter().map(|x| x[m]).collect();
                let a: Vec<f64> = months_a.iter().map(|x| x[m]).collect();
                spread(&savings(&b, &a))
            })
            .collect();
        let at_estimate_kwh = match &pairs[n] {
            (Ok(b), Ok(a)) => annual(b) - annual(a),
            _ => f64::NAN,
        };
        let params: Vec<Vec<f64>> = (0..cal.inputs.plan.calibrated.len())
            .map(|k| ok.iter().map(|&i| rows[i][k]).collect())
            .collect();
        out.push(OutputSavings {
            output: name.clone(),
            weather,
            n: ok.len(),
            baseline_kwh: baseline.median,
            savings_kwh,
            savings_percent: savings_pct,
            at_estimate_kwh,
            monthly_kwh,
            drivers: drivers(cal, summary, &variance_shares(&params, &s)),
            warning: warning(cal, summary, name),
        });
    }
    out
}

/// January to December totals of an hourly series on the 8,760-slot grid.
fn monthly_totals(hours: &[f64]) -> [f64; 12] {
    let mut m = [0.0; 12];
    for (t, v) in hours.iter().enumerate() {
        m[slot_month(t) as usize - 1] += v;
    }
    m
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

/// Why EnergyPlus simulates the measure: it leaves the surrogate's training range (a prior's
/// support, or a parameter the surrogate held fixed), or the surrogate route is not built.
fn method_note(beyond_prior: &[String], not_calibrated: &[String]) -> String {
    if !beyond_prior.is_empty() {
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
        "EnergyPlus at every draw (a surrogate route corrected by EnergyPlus at a few draws is \
         not built yet)"
            .into()
    }
}

/// How the model's errors and the chains' temperature enter the savings.
fn report_notes(summary: &Summary, draws: usize) -> Vec<String> {
    let mut notes = vec![
        "each saving is a difference of two EnergyPlus runs at the same posterior draw: an \
         additive discrepancy (the model-form term, the bases the model does not have) is the \
         same in both and cancels; the intervals carry the parameters' posterior spread, not a \
         model-form error that changes with the measure"
            .to_string(),
        format!(
            "the 90 % interval's ends are the 5 % and 95 % quantiles of {draws} draws' savings"
        ),
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

    #[test]
    fn evenly_spaced_draws_cover_the_chains() {
        assert_eq!(evenly(10, 5), vec![1, 3, 5, 7, 9]);
        assert_eq!(evenly(3, 5), vec![0, 1, 2]);
        assert_eq!(evenly(800, 4), vec![100, 300, 500, 700]);
    }

    #[test]
    fn monthly_totals_follow_the_grid() {
        let m = monthly_totals(&vec![1.0; 8760]);
        assert_eq!(m[0], 31.0 * 24.0);
        assert_eq!(m[1], 28.0 * 24.0);
        assert_eq!(m.iter().sum::<f64>(), 8760.0);
    }
}

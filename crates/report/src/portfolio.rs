//! The portfolio page: a portfolio's summary (one row per building: state, Guideline 14 per
//! output, max R-hat, run time, failure) as `portfolio.csv`, `portfolio.json` and a
//! self-contained `portfolio.html` linking each building's report.

use std::path::Path;

use serde::Serialize;

use crate::error::ReportError;
use crate::html::esc;
use crate::io::write_atomic;

/// G14 metrics of one output at the calibrated parameters.
#[derive(Debug, Clone, Serialize)]
pub struct OutputRow {
    /// The model output (and its meter).
    pub output: String,
    /// Normalised mean bias error, %.
    pub nmbe: f64,
    /// Coefficient of variation of the RMSE, %.
    pub cv_rmse: f64,
    /// Both within Guideline 14's hourly limits.
    pub pass: bool,
    /// The calibration fitted this meter (false: `fit = false`, compared only; its pass or
    /// fail does not count in the building's [`BuildingRow::g14_pass`]).
    pub fitted: bool,
}

/// Where a building's calibration is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum BuildingState {
    /// Its run is in a stage.
    Running,
    /// Its run finished: summary and results stored.
    Done,
    /// It failed to load, or its run failed in a stage.
    Failed,
    /// Its run was cancelled.
    Cancelled,
}

impl BuildingState {
    /// The word `portfolio.json`, `portfolio.csv` and the page show.
    pub fn word(self) -> &'static str {
        match self {
            BuildingState::Running => "running",
            BuildingState::Done => "done",
            BuildingState::Failed => "failed",
            BuildingState::Cancelled => "cancelled",
        }
    }
}

impl std::fmt::Display for BuildingState {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.word())
    }
}

/// One building in the summary.
#[derive(Debug, Clone, Serialize)]
pub struct BuildingRow {
    /// The building's name in the portfolio's manifest.
    pub building: String,
    /// Its run on the coordinator (empty for a building that failed to load locally).
    pub run: String,
    /// Where its calibration is.
    pub state: BuildingState,
    /// The stage reached (where it failed, for a failed one).
    pub stage: String,
    /// Why it failed: the loader's message or the job's error (EnergyPlus error lines).
    pub error: Option<String>,
    /// Every fitted output passes ASHRAE Guideline 14 (None: no validation). A meter left
    /// out of the fit (`fit = false`) is shown, not counted.
    pub g14_pass: Option<bool>,
    /// Guideline 14 per output at the estimate.
    pub outputs: Vec<OutputRow>,
    /// The largest R-hat over the parameters (None: no chains yet).
    pub max_rhat: Option<f64>,
    /// The chains met their R-hat and ESS targets (None: no chains yet).
    pub converged: Option<bool>,
    /// The calibrated parameters at the estimate, in the model's order (`{name: value}` in
    /// portfolio.json, one column per parameter in portfolio.csv).
    #[serde(serialize_with = "bemcal_named::serialize")]
    pub estimate: Vec<(String, f64)>,
    /// Wall time of its run, s.
    pub run_time_s: f64,
    /// The workers' busy seconds on its jobs (attempts that ended done or failed): what the
    /// building cost in worker time, whatever else ran beside it and however long it waited.
    pub worker_s: f64,
    /// [`BuildingRow::worker_s`] by the stage whose jobs took it (`{stage: seconds}` in
    /// portfolio.json, a `worker_s_<stage>` column each in portfolio.csv), stages in run order.
    #[serde(serialize_with = "bemcal_named::serialize")]
    pub worker_s_by_stage: Vec<(String, f64)>,
    /// Design simulations EnergyPlus ran for it.
    pub simulations_run: u32,
    /// Design simulations it took from the coordinator's cache (the same inputs run earlier,
    /// for another building or run).
    pub simulations_shared: u32,
    /// The building's report, relative to the summary folder.
    pub report: Option<String>,
}

/// `portfolio.json`.
#[derive(Debug, Clone, Serialize)]
pub struct PortfolioSummary {
    /// The portfolio's id on the coordinator.
    pub portfolio: String,
    /// Its name (the manifest's `name`).
    pub name: String,
    /// Buildings in it.
    pub buildings: usize,
    /// Buildings whose calibration finished.
    pub done: usize,
    /// Buildings that failed (to load, or in a stage).
    pub failed: usize,
    /// Design simulations EnergyPlus ran, over all buildings.
    pub simulations_run: u32,
    /// Design simulations taken from the coordinator's cache, over all buildings.
    pub simulations_shared: u32,
    /// The workers' busy seconds over all buildings ([`BuildingRow::worker_s`]).
    pub worker_s: f64,
    /// Finished buildings per hour of one worker's busy time (their [`BuildingRow::worker_s`]
    /// summed): the portfolio's throughput per core where a worker runs one job at a time.
    /// None before a building has finished.
    pub buildings_per_worker_hour: Option<f64>,
    /// One row per building: those submitted, then those whose files could not be read.
    pub rows: Vec<BuildingRow>,
}

/// Stages over all rows' worker seconds, in first-seen order.
fn stage_names(p: &PortfolioSummary) -> Vec<String> {
    let mut names: Vec<String> = vec![];
    for (n, _) in p.rows.iter().flat_map(|r| &r.worker_s_by_stage) {
        if !names.contains(n) {
            names.push(n.clone());
        }
    }
    names
}

/// [`PortfolioSummary::buildings_per_worker_hour`] of `rows`.
pub fn buildings_per_worker_hour(rows: &[BuildingRow]) -> Option<f64> {
    let done: Vec<&BuildingRow> = rows
        .iter()
        .filter(|r| r.state == BuildingState::Done)
        .collect();
    let busy: f64 = done.iter().map(|r| r.worker_s).sum();
    (!done.is_empty() && busy > 0.0).then(|| 3600.0 * done.len() as f64 / busy)
}

/// Parameter names over all rows' estimates, in first-seen order.
fn parameter_names(p: &PortfolioSummary) -> Vec<String> {
    let mut names: Vec<String> = vec![];
    for (n, _) in p.rows.iter().flat_map(|r| &r.estimate) {
        if !names.contains(n) {
            names.push(n.clone());
        }
    }
    names
}

fn csv_field(s: &str) -> String {
    if s.contains([',', '"', '\n', '\r']) {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_string()
    }
}

fn num(v: Option<f64>, digits: usize) -> String {
    v.filter(|v| v.is_finite())
        .map_or(String::new(), |v| format!("{v:.digits$}"))
}

/// Output names over all rows, in first-seen order.
fn output_names(p: &PortfolioSummary) -> Vec<String> {
    let mut names: Vec<String> = vec![];
    for r in &p.rows {
        for o in &r.outputs {
            if !names.contains(&o.output) {
                names.push(o.output.clone());
            }
        }
    }
    names
}

/// Writes `portfolio.csv` (one line per building; per output NMBE, CV-RMSE and G14 pass; the
/// estimate of every calibrated parameter),
/// `portfolio.json` and `portfolio.html` (a self-contained table linking each report) in `dir`.
pub fn write(dir: &Path, p: &PortfolioSummary) -> Result<(), ReportError> {
    std::fs::create_dir_all(dir).map_err(|source| ReportError::Io {
        path: dir.to_path_buf(),
        source,
    })?;
    let names = output_names(p);
    write_atomic(
        &dir.join("portfolio.csv"),
        portfolio_csv(p, &names, &parameter_names(p)).as_bytes(),
    )?;
    let json = serde_json::to_string_pretty(p).map_err(|e| ReportError::Parse {
        path: dir.join("portfolio.json"),
        msg: e.to_string(),
    })?;
    write_atomic(&dir.join("portfolio.json"), json.as_bytes())?;
    write_atomic(
        &dir.join("portfolio.html"),
        portfolio_html(p, &names).as_bytes(),
    )?;
    Ok(())
}

/// `portfolio.csv`: a row per building with its state, Guideline 14 per output and estimates.
fn portfolio_csv(p: &PortfolioSummary, names: &[String], parameters: &[String]) -> String {
    let mut csv = String::from(
        "building,run,state,stage,g14_pass,max_rhat,converged,run_time_s,worker_s,simulations_run,simulations_shared",
    );
    let stages = stage_names(p);
    for st in &stages {
        csv.push_str(&format!(",worker_s_{st}"));
    }
    for n in names {
        csv.push_str(&format!(
            ",{n}_nmbe_pct,{n}_cv_rmse_pct,{n}_g14_pass,{n}_fitted"
        ));
    }
    for n in parameters {
        csv.push_str(&format!(",{}", csv_field(n)));
    }
    csv.push_str(",error\n");
    for r in &p.rows {
        csv.push_str(&format!(
            "{},{},{},{},{},{},{},{:.1},{:.1},{},{}",
            csv_field(&r.building),
            r.run,
            r.state,
            r.stage,
            r.g14_pass.map_or(String::new(), |b| b.to_string()),
            num(r.max_rhat, 4),
            r.converged.map_or(String::new(), |b| b.to_string()),
            r.run_time_s,
            r.worker_s,
            r.simulations_run,
            r.simulations_shared
        ));
        for st in &stages {
            let v = r.worker_s_by_stage.iter().find(|(k, _)| k == st);
            csv.push_str(&format!(
                ",{}",
                v.map_or(String::new(), |(_, v)| format!("{v:.1}"))
            ));
        }
        for n in names {
            match r.outputs.iter().find(|o| &o.output == n) {
                Some(o) => csv.push_str(&format!(
                    ",{},{},{},{}",
                    num(Some(o.nmbe), 3),
                    num(Some(o.cv_rmse), 3),
                    o.pass,
                    o.fitted
                )),
                None => csv.push_str(",,,,"),
            }
        }
        for n in parameters {
            let v = r.estimate.iter().find(|(k, _)| k == n).map(|(_, v)| *v);
            csv.push_str(&format!(",{}", v.map_or(String::new(), |v| v.to_string())));
        }
        csv.push_str(&format!(
            ",{}\n",
            csv_field(r.error.as_deref().unwrap_or(""))
        ));
    }
    csv
}

/// `portfolio.html`: the same table, with each building's report linked or its error shown.
fn portfolio_html(p: &PortfolioSummary, names: &[String]) -> String {
    let mut h = format!(
        "<!DOCTYPE html>\n<html><head><meta charset=\"utf-8\"><title>Portfolio {name}</title><style>\
         body{{font-family:sans-serif;margin:2em}}table{{border-collapse:collapse}}\
         td,th{{border:1px solid #ccc;padding:4px 8px;text-align:right}}td.l,th.l{{text-align:left}}\
         .pass{{color:#1a7f37}}.fail{{color:#b42318;font-weight:bold}}pre{{white-space:pre-wrap;margin:0;text-align:left;max-width:60em}}\
         </style></head><body>\n<h1>Portfolio {name}</h1>\n<p>{n} buildings: {d} done, {f} failed; \
         {sr} EnergyPlus design runs, {ss} shared between buildings; {wh:.1} worker-hours{per}. \
         ASHRAE Guideline 14 (hourly): |NMBE| &le; 10 %, CV-RMSE &le; 30 %.</p>\n<table>\n<tr>\
         <th class=\"l\">building</th><th class=\"l\">state</th><th>G14</th><th>max R-hat</th>\
         <th>run time (s)</th><th>worker time (s)</th>",
        name = esc(&p.name),
        n = p.buildings,
        d = p.done,
        f = p.failed,
        sr = p.simulations_run,
        ss = p.simulations_shared,
        wh = p.worker_s / 3600.0,
        per = p
            .buildings_per_worker_hour
            .map_or(String::new(), |b| format!(", {b:.2} finished buildings per worker-hour"))
    );
    for n in names {
        h.push_str(&format!(
            "<th>{0} NMBE %</th><th>{0} CV-RMSE %</th>",
            esc(n)
        ));
    }
    h.push_str("<th class=\"l\">report / error</th></tr>\n");
    for r in &p.rows {
        let g14 = match r.g14_pass {
            Some(true) => "<span class=\"pass\">pass</span>",
            Some(false) => "<span class=\"fail\">FAIL</span>",
            None => "",
        };
        h.push_str(&format!(
            "<tr><td class=\"l\">{}</td><td class=\"l\">{}</td><td>{g14}</td><td>{}</td><td>{:.0}</td><td>{:.0}</td>",
            esc(&r.building),
            if r.state == BuildingState::Failed {
                format!("<span class=\"fail\">failed</span> ({})", esc(&r.stage))
            } else {
                r.state.word().to_string()
            },
            num(r.max_rhat, 3),
            r.run_time_s,
            r.worker_s
        ));
        for n in names {
            match r.outputs.iter().find(|o| &o.output == n) {
                Some(o) => {
                    let c = if o.pass { "pass" } else { "fail" };
                    let not_fitted = if o.fitted { "" } else { " (not fitted)" };
                    h.push_str(&format!(
                        "<td class=\"{c}\">{}</td><td class=\"{c}\">{}{not_fitted}</td>",
                        num(Some(o.nmbe), 1),
                        num(Some(o.cv_rmse), 1)
                    ))
                }
                None => h.push_str("<td></td><td></td>"),
            }
        }
        let last = match (&r.report, &r.error) {
            (_, Some(e)) => format!("<pre>{}</pre>", esc(e)),
            (Some(rep), None) => format!("<a href=\"{0}\">{0}</a>", esc(rep)),
            (None, None) => String::new(),
        };
        h.push_str(&format!("<td class=\"l\">{last}</td></tr>\n"));
    }
    h.push_str("</table>\n</body></html>\n");
    h
}

//! The portfolio page: a portfolio's summary (one row per building: state, Guideline 14 per
//! output, max R-hat, run time, failure) as `portfolio.csv`, `portfolio.json` and a
//! self-contained `portfolio.html` linking each building's report; where buildings estimated
//! their measures' savings, `portfolio_savings.csv` and a table of them on the page.

use std::path::Path;

use bemcal_calibrate::measures::SavingsWeather;
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

/// One measure's saving on one output of a building, under one weather, from its
/// `summary.json` `savings` (`[savings] with_calibration`): a row of `portfolio_savings.csv`.
#[derive(Debug, Clone, Serialize)]
pub struct SavingsRow {
    /// The measure's name.
    pub measure: String,
    /// The model output (and its meter).
    pub output: String,
    /// The weather simulated.
    pub weather: SavingsWeather,
    /// The annual baseline at the draws' median, kWh.
    pub baseline_kwh: f64,
    /// The annual saving: median and 90 % credible interval, kWh.
    pub savings_kwh: bemcal_stats::savings::Spread,
    /// The median saving in percent of each draw's baseline.
    pub percent: f64,
    /// Why the saving is the model's rather than the building's, where it is (no meter, not
    /// fitted, Guideline 14 missed at the estimate).
    pub warning: Option<String>,
}

impl SavingsRow {
    /// Every measure's rows of a calibration's savings, in the summary's order.
    pub fn of(savings: &bemcal_calibrate::measures::SavingsReport) -> Vec<SavingsRow> {
        (savings.measures.iter())
            .flat_map(|m| {
                m.outputs.iter().map(|o| SavingsRow {
                    measure: m.measure.clone(),
                    output: o.output.clone(),
                    weather: o.weather,
                    baseline_kwh: o.baseline_kwh,
                    savings_kwh: o.savings_kwh,
                    percent: o.savings_percent.median,
                    warning: o.warning.clone(),
                })
            })
            .collect()
    }
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
    /// Its measures' savings, where its calibration estimated them (`[savings]
    /// with_calibration`); also `portfolio_savings.csv`, a row each.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub savings: Vec<SavingsRow>,
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
    if p.rows.iter().any(|r| !r.savings.is_empty()) {
        write_atomic(
            &dir.join("portfolio_savings.csv"),
            savings_csv(p).as_bytes(),
        )?;
    }
    Ok(())
}

/// `portfolio_savings.csv`: a row per building, measure, output and weather (tidy: one
/// saving a line, for a pivot table), its median, 90 % interval and warning.
fn savings_csv(p: &PortfolioSummary) -> String {
    let mut csv = String::from(
        "building,measure,output,weather,baseline_kwh,savings_kwh,savings_kwh_q5,savings_kwh_q95,savings_pct,warning\n",
    );
    for r in &p.rows {
        for s in &r.savings {
            let [lo, hi] = s.savings_kwh.interval_90;
            csv.push_str(&format!(
                "{},{},{},{},{},{},{},{},{},{}\n",
                csv_field(&r.building),
                csv_field(&s.measure),
                csv_field(&s.output),
                s.weather.as_str(),
                num(Some(s.baseline_kwh), 0),
                num(Some(s.savings_kwh.median), 0),
                num(Some(lo), 0),
                num(Some(hi), 0),
                num(Some(s.percent), 2),
                csv_field(s.warning.as_deref().unwrap_or(""))
            ));
        }
    }
    csv
}

/// The page's savings table: a row per building, measure and output under the calibration's
/// weather (the typical year's are in `portfolio_savings.csv`); empty where no building
/// estimated savings.
fn savings_html(p: &PortfolioSummary) -> String {
    let rows: Vec<(&BuildingRow, &SavingsRow)> = (p.rows.iter())
        .flat_map(|r| r.savings.iter().map(move |s| (r, s)))
        .filter(|(_, s)| s.weather == SavingsWeather::Calibration)
        .collect();
    if rows.is_empty() {
        return String::new();
    }
    let mut h = String::from(
        "<h2>Savings of retrofit measures</h2>\n<p>Each building's measures over its posterior \
         draws (EnergyPlus with and without each; the calibration's weather; \
         <code>portfolio_savings.csv</code> has every weather): the median saving and its 90 % \
         credible interval. A warning says where the saving is the model's rather than the \
         building's.</p>\n<table>\n<tr><th class=\"l\">building</th><th class=\"l\">measure</th>\
         <th class=\"l\">output</th><th>baseline (kWh)</th><th>saves (kWh)</th>\
         <th>90 % interval (kWh)</th><th>%</th><th class=\"l\">warning</th></tr>\n",
    );
    for (r, s) in rows {
        let [lo, hi] = s.savings_kwh.interval_90;
        h.push_str(&format!(
            "<tr><td class=\"l\">{}</td><td class=\"l\">{}</td><td class=\"l\">{}</td>\
             <td>{}</td><td>{}</td><td>[{}, {}]</td><td>{}</td><td class=\"l\">{}</td></tr>\n",
            esc(&r.building),
            esc(&s.measure),
            esc(&s.output),
            num(Some(s.baseline_kwh), 0),
            num(Some(s.savings_kwh.median), 0),
            num(Some(lo), 0),
            num(Some(hi), 0),
            num(Some(s.percent), 1),
            esc(s.warning.as_deref().unwrap_or(""))
        ));
    }
    h.push_str("</table>\n");
    h
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
    h.push_str("</table>\n");
    h.push_str(&savings_html(p));
    h.push_str("</body></html>\n");
    h
}

#[cfg(test)]
mod tests {
    use super::*;
    use bemcal_stats::savings::Spread;

    /// A finished building with one measure's saving on two outputs under one weather, and
    /// one that failed to load.
    fn summary() -> PortfolioSummary {
        let saving = |output: &str, median: f64, warning: Option<&str>| SavingsRow {
            measure: "LED, 0.6 x lighting".into(),
            output: output.into(),
            weather: SavingsWeather::Calibration,
            baseline_kwh: 10_000.0,
            savings_kwh: Spread {
                median,
                interval_50: [median - 10.0, median + 10.0],
                interval_90: [median - 40.0, median + 40.0],
            },
            percent: median / 100.0,
            warning: warning.map(String::from),
        };
        let done = BuildingRow {
            building: "north".into(),
            run: "r1".into(),
            state: BuildingState::Done,
            stage: "done".into(),
            error: None,
            g14_pass: Some(true),
            outputs: vec![],
            max_rhat: Some(1.004),
            converged: Some(true),
            estimate: vec![],
            run_time_s: 100.0,
            worker_s: 180.0,
            worker_s_by_stage: vec![("savings".into(), 20.0)],
            simulations_run: 6,
            simulations_shared: 0,
            report: Some("north/report.html".into()),
            savings: vec![
                saving("electricity_kwh", 1_200.0, None),
                saving(
                    "lighting_kwh",
                    1_500.0,
                    Some("no meter: the model's saving"),
                ),
            ],
        };
        let failed = BuildingRow {
            building: "annex".into(),
            state: BuildingState::Failed,
            error: Some("meters.csv: line 3".into()),
            savings: vec![],
            report: None,
            ..done.clone()
        };
        PortfolioSummary {
            portfolio: "p1".into(),
            name: "campus".into(),
            buildings: 2,
            done: 1,
            failed: 1,
            simulations_run: 6,
            simulations_shared: 0,
            worker_s: 180.0,
            buildings_per_worker_hour: Some(20.0),
            rows: vec![done, failed],
        }
    }

    /// The buildings' savings come out as one tidy CSV row each (names with commas quoted),
    /// a table on the page with the warning, and in portfolio.json; a portfolio without
    /// savings writes no savings file.
    #[test]
    fn the_buildings_savings_are_a_csv_row_each_and_a_table() {
        let dir = tempfile::tempdir().unwrap();
        let p = summary();
        write(dir.path(), &p).unwrap();
        let csv = std::fs::read_to_string(dir.path().join("portfolio_savings.csv")).unwrap();
        let lines: Vec<&str> = csv.lines().collect();
        assert_eq!(lines.len(), 3, "{csv}");
        assert_eq!(
            lines[1],
            "north,\"LED, 0.6 x lighting\",electricity_kwh,calibration,10000,1200,1160,1240,12.00,"
        );
        assert!(lines[2].ends_with(",no meter: the model's saving"), "{csv}");
        let html = std::fs::read_to_string(dir.path().join("portfolio.html")).unwrap();
        assert!(html.contains("<h2>Savings of retrofit measures</h2>"));
        assert!(
            html.contains("[1160, 1240]") && html.contains("no meter"),
            "{html}"
        );
        let json = std::fs::read_to_string(dir.path().join("portfolio.json")).unwrap();
        let v: serde_json::Value = serde_json::from_str(&json).unwrap();
        assert_eq!(v["rows"][0]["savings"][0]["savings_kwh"]["median"], 1200.0);
        assert!(v["rows"][1].get("savings").is_none(), "{}", v["rows"][1]);

        let none = tempfile::tempdir().unwrap();
        let mut p = summary();
        p.rows.iter_mut().for_each(|r| r.savings.clear());
        write(none.path(), &p).unwrap();
        assert!(!none.path().join("portfolio_savings.csv").exists());
        let html = std::fs::read_to_string(none.path().join("portfolio.html")).unwrap();
        assert!(!html.contains("Savings of retrofit measures"));
    }
}

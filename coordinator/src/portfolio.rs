//! Portfolios: many buildings (each its own project) calibrated together on one coordinator.
//! A portfolio is a set of runs sharing a portfolio id; the lease order is fair across runs
//! (`db::Store::lease`) and identical simulations are shared between them. This module reads
//! the manifest, submits the buildings, follows their progress and builds the summary, which
//! the report crate writes (`portfolio.csv`, `portfolio.json`, `portfolio.html`).

use std::path::{Path, PathBuf};

use bemcal_calibrate::measures::SavingsReport;
use serde::Deserialize;

pub use bemcal_report::portfolio::{
    buildings_per_worker_hour, write, BuildingRow, BuildingState, OutputRow, PortfolioSummary,
    SavingsRow,
};

use crate::client::{self, Client};
use crate::proto::{self, RunState, RunStatus};

/// One building of a manifest.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Building {
    /// The building's name (unique in the manifest).
    pub name: String,
    /// Project file, relative to the manifest.
    pub project: PathBuf,
}

/// `MANIFEST.toml`: `name = "..."` (optional) and `[[building]] name, project`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Manifest {
    /// The portfolio's name.
    #[serde(default)]
    pub name: String,
    /// Its buildings, in order.
    #[serde(rename = "building", default)]
    pub buildings: Vec<Building>,
}

/// Reads a manifest; project paths come back resolved against its folder.
pub fn load_manifest(path: &Path) -> anyhow::Result<Manifest> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| anyhow::anyhow!("cannot read {}: {e}", path.display()))?;
    parse_manifest(&text, path)
}

/// Parses a manifest's text read from `path` (its folder resolves the project paths). An error
/// names the file and line and quotes at most an excerpt of the input.
pub fn parse_manifest(text: &str, path: &Path) -> anyhow::Result<Manifest> {
    let mut m: Manifest = bemcal_energyplus::parse_toml(text, path)?;
    if m.buildings.is_empty() {
        anyhow::bail!("{}: no [[building]] entries", path.display());
    }
    let base = path.parent().unwrap_or(Path::new("."));
    for (i, b) in m.buildings.iter_mut().enumerate() {
        if b.name.is_empty()
            || b.name.len() > 100
            || b.name.starts_with('.')
            || !b
                .name
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || "-_.".contains(c))
        {
            anyhow::bail!(
                "{}: building {} has name {:?}: use 1-100 of A-Z a-z 0-9 - _ . (it names a folder)",
                path.display(),
                i + 1,
                bemcal_client::excerpt(&b.name, 100)
            );
        }
        b.project = base.join(&b.project);
    }
    for (i, b) in m.buildings.iter().enumerate() {
        if m.buildings[..i].iter().any(|o| o.name == b.name) {
            anyhow::bail!(
                "{}: building name {:?} is used twice",
                path.display(),
                bemcal_client::excerpt(&b.name, 100)
            );
        }
    }
    if m.name.is_empty() {
        m.name = path
            .file_stem()
            .map_or("portfolio".into(), |s| s.to_string_lossy().to_string());
    }
    Ok(m)
}

/// A new portfolio id.
pub fn new_id() -> String {
    format!("p{}", &crate::auth::random_token()[..10])
}

/// The buildings of `m` a rerun of the portfolio must submit, given the portfolio's `runs` on
/// the coordinator so far: those with no run, or whose latest run failed or was cancelled (a
/// building whose files were fixed gets a new run). A building whose latest run is running
/// or done keeps it: the coordinator goes on with a running one where it stopped, and a done
/// one is not calibrated again. In manifest order.
pub fn to_resubmit<'m>(m: &'m Manifest, runs: &[RunStatus]) -> Vec<&'m Building> {
    let runs = latest_per_building(runs.to_vec());
    m.buildings
        .iter()
        .filter(|b| {
            !runs.iter().any(|r| {
                r.building == b.name && matches!(r.state(), RunState::Running | RunState::Done)
            })
        })
        .collect()
}

/// Each building's latest run (by submission time, then id), in submission order: a building
/// submitted again after a failure is its new run, not both.
pub fn latest_per_building(mut runs: Vec<RunStatus>) -> Vec<RunStatus> {
    runs.sort_by(|a, b| (a.created_ms, &a.run_id).cmp(&(b.created_ms, &b.run_id)));
    let mut out: Vec<RunStatus> = vec![];
    for r in runs {
        match out
            .iter_mut()
            .find(|o| !o.building.is_empty() && o.building == r.building)
        {
            Some(o) => *o = r,
            None => out.push(r),
        }
    }
    out
}

/// Submits every building; a building whose files cannot even be bundled here is returned
/// with its error (the coordinator records the others, failed ones included).
pub async fn submit(
    c: &mut Client,
    m: &Manifest,
    id: &str,
    policy: bemcal_client::bundle::Policy,
) -> anyhow::Result<Vec<(String, Result<String, String>)>> {
    submit_buildings(c, &m.buildings.iter().collect::<Vec<_>>(), id, policy).await
}

/// Submits `buildings` into portfolio `id` ([`submit`]).
pub async fn submit_buildings(
    c: &mut Client,
    buildings: &[&Building],
    id: &str,
    policy: bemcal_client::bundle::Policy,
) -> anyhow::Result<Vec<(String, Result<String, String>)>> {
    let mut out = vec![];
    for b in buildings {
        let r = client::submit_building(c, &b.project, None, id, &b.name, policy)
            .await
            .map(|s| s.run_id)
            .map_err(|e| format!("{e:#}"));
        out.push((b.name.clone(), r));
    }
    Ok(out)
}

/// The runs of a portfolio, each building's latest ([`latest_per_building`]), with their
/// summaries (one GetRun per run) when `full`.
pub async fn statuses(c: &mut Client, id: &str, full: bool) -> anyhow::Result<Vec<RunStatus>> {
    let runs = c
        .list_runs(proto::ListRunsRequest {
            portfolio: id.to_string(),
        })
        .await
        .map_err(|e| anyhow::anyhow!("{}", e.message()))?
        .into_inner()
        .runs;
    let runs = latest_per_building(runs);
    if !full {
        return Ok(runs);
    }
    let mut out = vec![];
    for r in runs {
        out.push(
            c.get_run(proto::RunRequest { run_id: r.run_id })
                .await
                .map_err(|e| anyhow::anyhow!("{}", e.message()))?
                .into_inner(),
        );
    }
    Ok(out)
}

/// Where a building's run is, in words: `simulate 3/12`, `done`, `FAILED at design: ...`.
pub fn progress(s: &RunStatus) -> String {
    let g = s.stages.iter().find(|g| g.stage == s.stage);
    let stage = s.stage().word();
    match (s.state(), g) {
        (RunState::Running, Some(g)) if g.total > 1 => {
            format!("{stage} {}/{}", g.done, g.total)
        }
        (RunState::Running, _) => stage.to_string(),
        (RunState::Failed, _) => format!("FAILED at {stage}: {}", s.error),
        (state, _) => state.word().to_string(),
    }
}

/// A run's state as its building's row shows it (a reply without one: still running).
fn building_state(s: RunState) -> BuildingState {
    match s {
        RunState::Running | RunState::Unspecified => BuildingState::Running,
        RunState::Done => BuildingState::Done,
        RunState::Failed => BuildingState::Failed,
        RunState::Cancelled => BuildingState::Cancelled,
    }
}

/// Follows a portfolio until every run has ended, calling `on_change` with a building's run
/// whenever its stage (or state) changes.
pub async fn follow(
    c: &mut Client,
    id: &str,
    on_change: &dyn Fn(&RunStatus),
) -> anyhow::Result<Vec<RunStatus>> {
    let mut last: Vec<(String, String)> = vec![];
    loop {
        let runs = statuses(c, id, false).await?;
        for r in &runs {
            let key = format!("{} {}", r.state().word(), r.stage().word());
            match last.iter_mut().find(|l| l.0 == r.run_id) {
                Some(l) if l.1 == key => continue,
                Some(l) => l.1 = key,
                None => last.push((r.run_id.clone(), key)),
            }
            on_change(r);
        }
        if runs.iter().all(|r| r.state() != RunState::Running) {
            return statuses(c, id, true).await;
        }
        tokio::time::sleep(std::time::Duration::from_millis(1000)).await;
    }
}

/// The calibrated values of a `summary.json`, in the model's order (an object keyed by name,
/// or the `[name, value]` pairs of older summaries); empty when it has none.
fn estimate(summary_json: &str) -> Vec<(String, f64)> {
    #[derive(serde::Deserialize)]
    struct Calibrated {
        #[serde(default, with = "bemcal_calibrate::named")]
        calibrated_values: Vec<(String, f64)>,
    }
    serde_json::from_str::<Calibrated>(summary_json)
        .map(|c| c.calibrated_values)
        .unwrap_or_default()
}

/// The summary row of a run.
pub fn row(s: &RunStatus) -> BuildingRow {
    let summary: serde_json::Value = serde_json::from_str(&s.summary_json).unwrap_or_default();
    let not_fitted = |output: &str| {
        summary["not_fitted"]
            .as_array()
            .is_some_and(|n| n.iter().any(|o| o.as_str() == Some(output)))
    };
    let outputs: Vec<OutputRow> = summary["validation"]
        .as_array()
        .map(|v| {
            v.iter()
                .map(|o| {
                    let output = o["output"].as_str().unwrap_or_default().to_string();
                    OutputRow {
                        fitted: !not_fitted(&output),
                        output,
                        nmbe: o["nmbe"].as_f64().unwrap_or(f64::NAN),
                        cv_rmse: o["cv_rmse"].as_f64().unwrap_or(f64::NAN),
                        pass: o["pass"].as_bool().unwrap_or(false),
                    }
                })
                .collect()
        })
        .unwrap_or_default();
    let elapsed = if s.finished_ms > 0 {
        s.finished_ms.saturating_sub(s.created_ms)
    } else {
        crate::now_ms().saturating_sub(s.created_ms)
    } as f64
        / 1000.0;
    BuildingRow {
        building: if s.building.is_empty() {
            s.name.clone()
        } else {
            s.building.clone()
        },
        run: s.run_id.clone(),
        state: building_state(s.state()),
        stage: s.stage().word().to_string(),
        error: (!s.error.is_empty()).then(|| s.error.clone()),
        g14_pass: outputs
            .iter()
            .any(|o| o.fitted)
            .then(|| outputs.iter().filter(|o| o.fitted).all(|o| o.pass)),
        max_rhat: summary["posterior"]["max_rhat"].as_f64(),
        converged: summary["converged"].as_bool(),
        estimate: estimate(&s.summary_json),
        run_time_s: summary["timings"]["total_s"].as_f64().unwrap_or(elapsed),
        worker_s: s.stages.iter().map(|p| p.worker_seconds).sum(),
        worker_s_by_stage: s
            .stages
            .iter()
            .filter(|p| p.worker_seconds > 0.0)
            .map(|p| (p.stage().word().to_string(), p.worker_seconds))
            .collect(),
        simulations_run: s.simulations_run,
        simulations_shared: s.simulations_shared,
        outputs,
        report: None,
        savings: (summary.get("savings").cloned())
            .and_then(|v| serde_json::from_value::<SavingsReport>(v).ok())
            .map_or(vec![], |r| SavingsRow::of(&r)),
    }
}

/// The summary of a portfolio's runs; `local_failures`: buildings that never reached the
/// coordinator (their files could not be read), with the reason.
pub fn summarize(
    id: &str,
    name: &str,
    runs: &[RunStatus],
    local_failures: &[(String, String)],
) -> PortfolioSummary {
    let mut rows: Vec<BuildingRow> = runs.iter().map(row).collect();
    for (b, e) in local_failures {
        rows.push(BuildingRow {
            building: b.clone(),
            run: String::new(),
            state: BuildingState::Failed,
            stage: "submit".into(),
            error: Some(e.clone()),
            g14_pass: None,
            outputs: vec![],
            max_rhat: None,
            converged: None,
            estimate: vec![],
            run_time_s: 0.0,
            worker_s: 0.0,
            worker_s_by_stage: vec![],
            simulations_run: 0,
            simulations_shared: 0,
            report: None,
            savings: vec![],
        });
    }
    PortfolioSummary {
        portfolio: id.to_string(),
        name: name.to_string(),
        buildings: rows.len(),
        done: rows
            .iter()
            .filter(|r| r.state == BuildingState::Done)
            .count(),
        failed: rows
            .iter()
            .filter(|r| r.state == BuildingState::Failed)
            .count(),
        simulations_run: rows.iter().map(|r| r.simulations_run).sum(),
        simulations_shared: rows.iter().map(|r| r.simulations_shared).sum(),
        worker_s: rows.iter().map(|r| r.worker_s).sum(),
        buildings_per_worker_hour: buildings_per_worker_hour(&rows),
        rows,
    }
}

/// Downloads each finished building's files into `out/<building>/`.
pub async fn fetch(c: &mut Client, runs: &[RunStatus], out: &Path) -> anyhow::Result<()> {
    for r in runs.iter().filter(|r| r.state() == RunState::Done) {
        let name = if r.building.is_empty() {
            &r.run_id
        } else {
            &r.building
        };
        let name = crate::artifacts::safe_relative(name).map_err(|e| anyhow::anyhow!(e))?;
        client::fetch_results(c, &r.run_id, &out.join(name)).await?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::{row, to_resubmit, Building, Manifest, RunState, RunStatus};

    /// A rerun submits the buildings with no run and those whose latest run failed or was
    /// cancelled; a running or finished one keeps its run, and an old failure of a building
    /// that has run again since does not count.
    #[test]
    fn a_rerun_submits_only_the_buildings_without_a_live_or_finished_run() {
        let m = Manifest {
            name: "campus".into(),
            buildings: ["done", "running", "failed", "cancelled", "new", "fixed"]
                .iter()
                .map(|n| Building {
                    name: n.to_string(),
                    project: format!("{n}/project.toml").into(),
                })
                .collect(),
        };
        let run = |building: &str, state: RunState, created_ms: u64| RunStatus {
            run_id: format!("r-{building}-{created_ms}"),
            building: building.into(),
            state: state.into(),
            created_ms,
            ..Default::default()
        };
        let runs = vec![
            run("done", RunState::Done, 1),
            run("running", RunState::Running, 2),
            run("failed", RunState::Failed, 3),
            run("cancelled", RunState::Cancelled, 4),
            run("fixed", RunState::Failed, 5),
            run("fixed", RunState::Done, 6),
        ];
        let names: Vec<&str> = to_resubmit(&m, &runs)
            .iter()
            .map(|b| b.name.as_str())
            .collect();
        assert_eq!(names, ["failed", "cancelled", "new"]);
        let latest = super::latest_per_building(runs);
        assert_eq!(latest.len(), 5);
        assert_eq!(
            latest
                .iter()
                .find(|r| r.building == "fixed")
                .unwrap()
                .state(),
            RunState::Done
        );
    }

    /// A meter left out of the fit (`fit = false`, summary `not_fitted`) is shown with its
    /// Guideline 14 figures and does not fail the building.
    #[test]
    fn a_meter_not_fitted_is_shown_and_not_counted_in_the_buildings_pass() {
        let status = |not_fitted: &str| RunStatus {
            run_id: "r1".into(),
            name: "rsf".into(),
            state: RunState::Done.into(),
            summary_json: format!(
                r#"{{"validation": [
                    {{"output": "heating_kwh", "nmbe": 2.0, "cv_rmse": 20.0, "pass": true}},
                    {{"output": "cooling_kwh", "nmbe": -900.0, "cv_rmse": 1600.0, "pass": false}}],
                   "not_fitted": [{not_fitted}]}}"#
            ),
            ..Default::default()
        };
        let r = row(&status(r#""cooling_kwh""#));
        assert_eq!(r.g14_pass, Some(true));
        assert_eq!(
            r.outputs.iter().map(|o| o.fitted).collect::<Vec<_>>(),
            [true, false]
        );
        let r = row(&status(""));
        assert_eq!(r.g14_pass, Some(false));
        assert!(r.outputs.iter().all(|o| o.fitted));
    }

    /// A building whose summary has savings (the report's fixture: one measure, two outputs)
    /// gets a savings row per output; one without has none.
    #[test]
    fn a_buildings_savings_are_read_from_its_summary() {
        let fixture = concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../crates/report/tests/fixtures/summary.json"
        );
        let status = |summary_json: String| RunStatus {
            run_id: "r1".into(),
            state: RunState::Done.into(),
            summary_json,
            ..Default::default()
        };
        let r = row(&status(std::fs::read_to_string(fixture).unwrap()));
        let got: Vec<(&str, &str)> = (r.savings.iter())
            .map(|s| (s.measure.as_str(), s.output.as_str()))
            .collect();
        assert_eq!(
            got,
            [
                ("cooling set-point +1 K", "cooling_kwh"),
                ("cooling set-point +1 K", "lighting_kwh")
            ]
        );
        assert!(r.savings[0].savings_kwh.median.is_finite());
        assert!(row(&status("{}".into())).savings.is_empty());
    }
}

//! `bemcal portfolio`: many buildings calibrated together (fair scheduling across buildings,
//! identical simulations shared), with a summary per building.

use std::path::{Path, PathBuf};

use anyhow::Context;

use bemcal_client::bundle::Policy;
use bemcal_client::client::Client;
use bemcal_client::proto::RunStatus;
use bemcal_coordinator::portfolio::{self, PortfolioSummary};

use super::coordinator::ClientArgs;
use super::progress::{Progress, ProgressFormat, Sink};

/// Calibrate a portfolio of buildings (a manifest of projects).
#[derive(Debug, clap::Args)]
pub struct Args {
    #[command(subcommand)]
    pub command: Sub,
}

#[derive(Debug, clap::Subcommand)]
pub enum Sub {
    /// Submit every building of MANIFEST.toml to a coordinator; prints the portfolio id.
    Submit {
        /// `[[building]] name = "...", project = "path/to/project.toml"` (relative to it).
        manifest: PathBuf,
        #[command(flatten)]
        client: ClientArgs,
        /// Send files that lie outside a building's project folder too (links out of it
        /// included); without it such a building is not submitted, with the reason.
        #[arg(long)]
        allow_outside: bool,
    },
    /// Run a portfolio through a coordinator and worker processes on loopback; writes
    /// OUT/<building>/ (with report.html), portfolio.csv, portfolio.json and portfolio.html.
    /// Exits non-zero if any building failed (after writing everything that finished). Run it
    /// again into the same OUT to go on: finished buildings stand, running ones go on where
    /// they stopped, failed or cancelled ones are submitted again.
    Run {
        /// The portfolio manifest (as for `submit`).
        manifest: PathBuf,
        /// Worker processes.
        #[arg(long, default_value_t = 2)]
        local_workers: usize,
        /// Folder for every building's results and the portfolio's files.
        #[arg(long)]
        out: PathBuf,
        /// How progress is written on standard error: `text` for people, `json` for programs
        /// (one object a line: log lines, and a `building` event whenever one's stage changes).
        #[arg(long, value_enum, default_value_t)]
        progress: ProgressFormat,
    },
    /// Per building: state, stage, G14 per output, NMBE, CV-RMSE, max R-hat, run time, the
    /// workers' busy seconds, errors.
    Status {
        /// Portfolio id (printed by `submit`).
        portfolio: String,
        #[command(flatten)]
        client: ClientArgs,
        /// Print portfolio.json to stdout.
        #[arg(long)]
        json: bool,
    },
    /// Download the finished buildings (OUT/<building>/, report.html) and the summary files.
    Results {
        /// Portfolio id (printed by `submit`).
        portfolio: String,
        /// Folder to write the finished buildings and the summary files into.
        #[arg(long)]
        out: PathBuf,
        #[command(flatten)]
        client: ClientArgs,
    },
}

pub fn run(a: Args) -> anyhow::Result<()> {
    match a.command {
        Sub::Submit {
            manifest,
            client,
            allow_outside,
        } => submit(&manifest, client, Policy { allow_outside }),
        Sub::Status {
            portfolio: id,
            client,
            json,
        } => status(&id, client, json),
        Sub::Results {
            portfolio: id,
            out,
            client,
        } => results(&id, &out, client),
        Sub::Run {
            manifest,
            local_workers,
            out,
            progress,
        } => run_local(
            &manifest,
            local_workers,
            &out,
            &Progress::new(progress, Sink::Stderr),
        ),
    }
}

/// `portfolio submit`: every building of the manifest submitted; prints the portfolio id.
fn submit(manifest: &Path, client: ClientArgs, policy: Policy) -> anyhow::Result<()> {
    let rt = bemcal_client::runtime()?;
    let m = portfolio::load_manifest(manifest)?;
    let connect = client.connect()?;
    let id = portfolio::new_id();
    let subs = rt.block_on(async {
        let mut c = connect.client()?;
        portfolio::submit(&mut c, &m, &id, policy).await
    })?;
    for (b, r) in &subs {
        match r {
            Ok(run) => eprintln!("{b}: run {run}"),
            Err(e) => eprintln!("{b}: not submitted: {e}"),
        }
    }
    println!("{id}");
    Ok(())
}

/// `portfolio status`: the table (or JSON) of a portfolio's runs.
fn status(id: &str, client: ClientArgs, json: bool) -> anyhow::Result<()> {
    let rt = bemcal_client::runtime()?;
    let connect = client.connect()?;
    let runs = rt.block_on(async {
        let mut c = connect.client()?;
        portfolio::statuses(&mut c, id, true).await
    })?;
    if runs.is_empty() {
        anyhow::bail!("no portfolio {id:?} on the coordinator");
    }
    let p = portfolio::summarize(id, id, &runs, &[]);
    if json {
        println!("{}", serde_json::to_string_pretty(&p)?);
    } else {
        print_table(&p);
    }
    Ok(())
}

/// `portfolio results`: every finished building's files downloaded, and the portfolio table.
fn results(id: &str, out: &Path, client: ClientArgs) -> anyhow::Result<()> {
    let rt = bemcal_client::runtime()?;
    let connect = client.connect()?;
    let runs = rt.block_on(async {
        let mut c = connect.client()?;
        let runs = portfolio::statuses(&mut c, id, true).await?;
        portfolio::fetch(&mut c, &runs, out).await?;
        Ok::<_, anyhow::Error>(runs)
    })?;
    if runs.is_empty() {
        anyhow::bail!("no portfolio {id:?} on the coordinator");
    }
    let p = finish(out, id, id, &runs, &[])?;
    print_table(&p);
    Ok(())
}

/// Where `portfolio run` keeps the id of the portfolio it submitted, in OUT/.distributed.
const PORTFOLIO_ID_FILE: &str = "portfolio.id";

/// `portfolio run`: a local coordinator and workers calibrate every building; a failed one
/// makes the exit status non-zero after the others' results are written. A rerun into the
/// same `out` goes on with the same portfolio ([`portfolio::to_resubmit`]).
fn run_local(
    manifest: &Path,
    local_workers: usize,
    out: &Path,
    progress: &Progress,
) -> anyhow::Result<()> {
    let rt = bemcal_client::runtime()?;
    let m = portfolio::load_manifest(manifest)?;
    let log = |s: &str| progress.log(s);
    std::fs::create_dir_all(out)?;
    let (children, connect) =
        super::coordinator::start_local(out, local_workers.max(1), 0, progress)?;
    // A rerun into the same folder goes on with the same portfolio (the coordinator's state
    // is kept in OUT/.distributed): what finished stands, what was running goes on.
    let id_file = out.join(".distributed").join(PORTFOLIO_ID_FILE);
    let earlier = std::fs::read_to_string(&id_file)
        .ok()
        .map(|s| s.trim().to_string())
        .filter(|s| !s.is_empty());
    let id = match &earlier {
        Some(id) => id.clone(),
        None => {
            let id = portfolio::new_id();
            bemcal_durable::write_atomic(&id_file, id.as_bytes())
                .with_context(|| format!("writing {}", id_file.display()))?;
            id
        }
    };
    let (runs, local_failures) = rt.block_on(async {
        let mut c: Client = connect.client()?;
        // On loopback the files never leave this machine: a building's files may lie anywhere
        // (special files of the system are still refused).
        let local = Policy {
            allow_outside: true,
        };
        let todo = match &earlier {
            None => m.buildings.iter().collect(),
            Some(id) => {
                let runs = portfolio::statuses(&mut c, id, false).await?;
                let todo = portfolio::to_resubmit(&m, &runs);
                log(&format!(
                    "going on with portfolio {id} from {}: {} of {} buildings keep their runs \
                     (done or running), {} submitted (new, failed or cancelled before)",
                    id_file.display(),
                    m.buildings.len() - todo.len(),
                    m.buildings.len(),
                    todo.len()
                ));
                todo
            }
        };
        let subs = portfolio::submit_buildings(&mut c, &todo, &id, local).await?;
        let mut failed = vec![];
        for (b, r) in subs {
            match r {
                Ok(run) => log(&format!("{b}: submitted as run {run}")),
                Err(e) => {
                    log(&format!("{b}: FAILED before submission: {e}"));
                    failed.push((b, e));
                }
            }
        }
        let runs = portfolio::follow(&mut c, &id, &|r: &RunStatus| {
            progress.building(r, &portfolio::progress(r))
        })
        .await?;
        portfolio::fetch(&mut c, &runs, out).await?;
        Ok::<_, anyhow::Error>((runs, failed))
    })?;
    drop(children);
    let p = finish(out, &id, &m.name, &runs, &local_failures)?;
    print_table(&p);
    log(&format!(
        "portfolio {}: {} of {} buildings done, {} failed; wrote {}/portfolio.{{csv,json,html}}",
        m.name,
        p.done,
        p.buildings,
        p.failed,
        out.display()
    ));
    // Every finished building's results are written above; a failed one still makes
    // the exit status non-zero, so that scripts and CI notice it.
    if p.failed > 0 {
        anyhow::bail!(
            "{} of {} buildings failed (reasons in {}/portfolio.csv); the others' results are written",
            p.failed,
            p.buildings,
            out.display()
        );
    }
    Ok(())
}

/// Writes each finished building's report.html, then the summary files.
fn finish(
    out: &Path,
    id: &str,
    name: &str,
    runs: &[RunStatus],
    local_failures: &[(String, String)],
) -> anyhow::Result<PortfolioSummary> {
    let mut p = portfolio::summarize(id, name, runs, local_failures);
    for r in p
        .rows
        .iter_mut()
        .filter(|r| r.state == portfolio::BuildingState::Done)
    {
        let dir = out.join(&r.building);
        match bemcal_report::write_report(&dir, None) {
            Ok(_) => r.report = Some(format!("{}/report.html", r.building)),
            Err(e) => eprintln!("{}: no report: {e}", r.building),
        }
    }
    portfolio::write(out, &p)?;
    Ok(p)
}

fn print_table(p: &PortfolioSummary) {
    println!(
        "{:<20} {:<9} {:<9} {:>5} {:>8} {:>8} {:>8}  outputs (NMBE % / CV-RMSE %)",
        "building", "state", "stage", "G14", "R-hat", "time s", "worker s"
    );
    for r in &p.rows {
        let outs: Vec<String> = r
            .outputs
            .iter()
            .map(|o| {
                format!(
                    "{} {:.1}/{:.1}{}{}",
                    o.output,
                    o.nmbe,
                    o.cv_rmse,
                    if o.pass { "" } else { " FAIL" },
                    if o.fitted { "" } else { " (not fitted)" }
                )
            })
            .collect();
        println!(
            "{:<20} {:<9} {:<9} {:>5} {:>8} {:>8.0} {:>8.0}  {}",
            r.building,
            r.state.word(),
            r.stage,
            match r.g14_pass {
                Some(true) => "pass",
                Some(false) => "FAIL",
                None => "-",
            },
            r.max_rhat.map_or("-".into(), |v| format!("{v:.3}")),
            r.run_time_s,
            r.worker_s,
            outs.join(", ")
        );
        if let Some(e) = &r.error {
            println!("  error: {}", e.replace('\n', "\n         "));
        }
    }
    println!(
        "{} buildings: {} done, {} failed; simulations run {}, shared {}; {:.2} worker-hours{}",
        p.buildings,
        p.done,
        p.failed,
        p.simulations_run,
        p.simulations_shared,
        p.worker_s / 3600.0,
        p.buildings_per_worker_hour
            .map_or(String::new(), |b| format!(
                ", {b:.2} finished buildings per worker-hour"
            ))
    );
}

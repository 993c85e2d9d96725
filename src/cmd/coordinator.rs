//! `bemcal coordinator`: serves runs to workers over gRPC; also the client options shared by
//! `submit`, `status`, `watch`, `results`, `cancel` and `worker`, and the local mode of
//! `bemcal calibrate --local-workers N`.

use std::io::{BufRead, Write};
use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::process::{Child, Stdio};

use anyhow::Context;
use bemcal_calibrate::Summary;
use bemcal_client::auth::{
    load_client_tokens, load_token, load_token_if_any, load_worker_token, random_token,
    DEFAULT_CLIENT, TOKEN_ENV,
};
use bemcal_client::client::{self, Connect};
use bemcal_client::proto::{self, ListRunsRequest, RunRequest, RunState};
use bemcal_coordinator::db::{AuditFilter, Store};
use bemcal_coordinator::driver::Config;
use bemcal_coordinator::server::{serve, Options};

/// Serve calibration runs to pull-based workers (state in DATA/coordinator.db); or, with a
/// subcommand, look after its workers and read its audit trail.
#[derive(Debug, clap::Args)]
#[command(args_conflicts_with_subcommands = true, subcommand_negates_reqs = true)]
pub struct Args {
    #[command(subcommand)]
    pub admin: Option<Admin>,
    /// Address to listen on (port 0: any free port; the bound address is printed).
    #[arg(long, default_value = "127.0.0.1:50051")]
    pub listen: SocketAddr,
    /// State folder (database, artifacts, run folders).
    #[arg(long, required = true)]
    pub data: Option<PathBuf>,
    /// File with the bearer token (default: env BEMCAL_TOKEN): the client `default`, and the
    /// token workers register with when there is no --worker-token-file. Optional with
    /// --client-tokens.
    #[arg(long)]
    pub token_file: Option<PathBuf>,
    /// File of named client tokens, one `NAME TOKEN` a line (`#` comments): each run records
    /// the name of the token that submitted it, and the limits apply per name.
    #[arg(long)]
    pub client_tokens: Option<PathBuf>,
    /// File with the enrollment token workers register with (default: env
    /// BEMCAL_WORKER_TOKEN); each worker then gets a credential of its own, and the token alone
    /// leases nothing. Without it the --token-file token registers workers.
    #[arg(long)]
    pub worker_token_file: Option<PathBuf>,
    /// Runs one client may have running at once (a portfolio counts once); a submission past
    /// it is refused (0: no limit).
    #[arg(long, default_value_t = 8)]
    pub max_runs_per_client: u32,
    /// Requests a second one client may make on average, in bursts of up to ten seconds'
    /// worth; past it calls are refused until the client slows down (0: no limit; workers are
    /// not limited).
    #[arg(long, default_value_t = 0.0)]
    pub client_rate: f64,
    #[command(flatten)]
    pub log: super::logging::LogArgs,
    /// TLS certificate (PEM); with --tls-key, serve https.
    #[arg(long, requires = "tls_key")]
    pub tls_cert: Option<PathBuf>,
    /// TLS private key (PEM) of --tls-cert.
    #[arg(long, requires = "tls_cert")]
    pub tls_key: Option<PathBuf>,
    /// Seconds a lease lasts without a heartbeat.
    #[arg(long, default_value_t = 30.0)]
    pub lease_ttl: f64,
    /// Failed attempts after which a job fails its run.
    #[arg(long, default_value_t = 3)]
    pub max_failures: u32,
    /// Chains per chain-segment job (0: all in one job); the draws are the local path's either
    /// way.
    #[arg(long, default_value_t = 0)]
    pub chains_per_job: usize,
    /// Hours an artifact that no run, job or cached simulation refers to is kept before it is
    /// removed (checked at start and hourly).
    #[arg(long, default_value_t = 24.0)]
    pub artifact_grace_hours: f64,
    /// Largest the artifact store may grow, GB (0: no limit); uploads past it are refused.
    #[arg(long, default_value_t = 0.0)]
    pub max_store_gb: f64,
    /// Uploads received at once; more wait their turn.
    #[arg(long, default_value_t = 16)]
    pub max_uploads: usize,
    /// Most one run's job outputs may take, GB (0: no limit): the completion that would pass
    /// it is refused and the run fails, saying so.
    #[arg(long, default_value_t = 0.0)]
    pub max_run_gb: f64,
    /// Serve Prometheus metrics (`GET /metrics`, plain HTTP, no token) on this address, e.g.
    /// 0.0.0.0:9464 (port 0: any free port; the bound address is printed).
    #[arg(long, env = "BEMCAL_METRICS_LISTEN")]
    pub metrics_listen: Option<SocketAddr>,
}

/// Looking after a coordinator's workers and reading its audit trail, from its state folder
/// (run where the coordinator's data is, e.g. `kubectl exec`; the coordinator may be running).
#[derive(Debug, clap::Subcommand)]
pub enum Admin {
    /// The registered workers: id, name, when registered, whether revoked, leases held.
    Workers {
        /// The coordinator's state folder.
        #[arg(long)]
        data: PathBuf,
    },
    /// Revokes a worker: its credential is refused within a second and its leases are given
    /// back; the other workers go on.
    RevokeWorker {
        /// The coordinator's state folder.
        #[arg(long)]
        data: PathBuf,
        /// The worker's id (as `bemcal coordinator workers` lists it).
        id: String,
    },
    /// The audit trail: submissions, registrations, leases, completions, failures and
    /// refusals, oldest first.
    Audit {
        /// The coordinator's state folder.
        #[arg(long)]
        data: PathBuf,
        /// Only the events of this run.
        #[arg(long)]
        run: Option<String>,
        /// Only the events of this actor (client:NAME, worker:ID, enroller, operator).
        #[arg(long)]
        actor: Option<String>,
        /// Only the last N events (0: all).
        #[arg(long, default_value_t = 200)]
        last: usize,
        /// One JSON object a line instead of text.
        #[arg(long)]
        json: bool,
    },
}

/// Opens the coordinator's database in `data` (which must hold one).
fn open_store(data: &Path) -> anyhow::Result<Store> {
    let db = data.join("coordinator.db");
    if !db.is_file() {
        anyhow::bail!("no coordinator database at {}", db.display());
    }
    Store::open(&db).map_err(|e| anyhow::anyhow!("{}: {e}", db.display()))
}

fn admin(a: Admin) -> anyhow::Result<()> {
    let ms = |t: u64| {
        format!(
            "{:.0} s ago",
            (bemcal_client::now_ms().saturating_sub(t)) as f64 / 1e3
        )
    };
    match a {
        Admin::Workers { data } => {
            let store = open_store(&data)?;
            println!(
                "{:<40} {:<24} {:>16} {:>16} {:>6}",
                "id", "name", "registered", "revoked", "leases"
            );
            for w in store.workers()? {
                println!(
                    "{:<40} {:<24} {:>16} {:>16} {:>6}",
                    w.id,
                    w.name,
                    ms(w.registered_ms),
                    w.revoked_ms.map_or("-".into(), ms),
                    w.leases
                );
            }
        }
        Admin::RevokeWorker { data, id } => {
            let store = open_store(&data)?;
            if !store.revoke_worker(&id, "operator")? {
                anyhow::bail!(
                    "no worker {id:?} (bemcal coordinator workers --data {} lists them)",
                    data.display()
                );
            }
            println!("worker {id} revoked: a running coordinator refuses it within a second");
        }
        Admin::Audit {
            data,
            run,
            actor,
            last,
            json,
        } => {
            let store = open_store(&data)?;
            let filter = AuditFilter { run, actor, last };
            for ev in store.audit_events(&filter)? {
                match json {
                    true => println!("{}", serde_json::to_string(&ev)?),
                    false => println!("{}", ev.text()),
                }
            }
        }
    }
    Ok(())
}

/// Where the coordinator is and how to authenticate.
#[derive(Debug, Clone, clap::Args)]
pub struct ClientArgs {
    /// Coordinator URL (default: env BEMCAL_COORDINATOR, else the local default).
    #[arg(
        long,
        env = "BEMCAL_COORDINATOR",
        default_value = "http://127.0.0.1:50051"
    )]
    pub coordinator: String,
    /// File with the bearer token (default: env BEMCAL_TOKEN).
    #[arg(long)]
    pub token_file: Option<PathBuf>,
    /// CA certificate (PEM) for an https coordinator.
    #[arg(long)]
    pub tls_ca: Option<PathBuf>,
}

impl ClientArgs {
    pub fn connect(&self) -> anyhow::Result<Connect> {
        Ok(Connect {
            url: self.coordinator.clone(),
            token: load_token(self.token_file.as_deref())?,
            tls_ca: self.tls_ca.clone(),
        })
    }
}

/// The named client tokens and the enrollment token of a coordinator's arguments.
fn tokens(a: &Args) -> anyhow::Result<(Vec<(String, String)>, String)> {
    let mut clients = match &a.client_tokens {
        Some(f) => load_client_tokens(f)?,
        None => vec![],
    };
    let token = match a.client_tokens {
        Some(_) => load_token_if_any(a.token_file.as_deref())?,
        None => Some(load_token(a.token_file.as_deref())?),
    };
    if let Some(t) = &token {
        if clients.iter().any(|(n, c)| n == DEFAULT_CLIENT || c == t) {
            anyhow::bail!(
                "the --client-tokens file names the client {DEFAULT_CLIENT} or holds the \
                 --token-file token: leave one of them out"
            );
        }
        clients.push((DEFAULT_CLIENT.into(), t.clone()));
    }
    let worker_token = load_worker_token(a.worker_token_file.as_deref())?;
    if let Some(w) = &worker_token {
        if let Some((name, _)) = clients.iter().find(|(_, c)| c == w) {
            anyhow::bail!("the worker token must differ from the client tokens ({name}'s)");
        }
    }
    let enroll = worker_token.or(token).ok_or_else(|| {
        anyhow::anyhow!(
            "workers need a token to register with: give --worker-token-file (or \
             BEMCAL_WORKER_TOKEN), or a --token-file token"
        )
    })?;
    Ok((clients, enroll))
}

pub fn run(a: Args) -> anyhow::Result<()> {
    if let Some(admin_cmd) = a.admin {
        return admin(admin_cmd);
    }
    let data = a.data.clone().context("--data is required")?;
    let (clients, enroll) = tokens(&a)?;
    if !a.client_rate.is_finite() || a.client_rate < 0.0 {
        anyhow::bail!("--client-rate must be a number of requests a second, 0 for no limit");
    }
    a.log.init();
    if a.artifact_grace_hours.is_nan() || a.artifact_grace_hours < 0.1 {
        anyhow::bail!("--artifact-grace-hours must be at least 0.1 (uploads need time to be used)");
    }
    if !a.max_store_gb.is_finite() || a.max_store_gb < 0.0 {
        anyhow::bail!("--max-store-gb must be a number of GB, 0 for no limit");
    }
    if !a.max_run_gb.is_finite() || a.max_run_gb < 0.0 {
        anyhow::bail!("--max-run-gb must be a number of GB, 0 for no limit");
    }
    if a.lease_ttl.is_nan() || a.lease_ttl < 1.0 {
        anyhow::bail!("--lease-ttl must be at least 1 s");
    }
    let opts = Options {
        listen: a.listen,
        data,
        clients,
        enroll,
        client_rate: a.client_rate,
        tls: a.tls_cert.zip(a.tls_key),
        metrics: a.metrics_listen,
        config: Config {
            lease_ttl_ms: (a.lease_ttl * 1000.0) as u64,
            max_failures: a.max_failures.max(1),
            chains_per_job: a.chains_per_job,
            artifact_grace_ms: (a.artifact_grace_hours * 3.6e6) as u64,
            max_store_bytes: (a.max_store_gb * 1e9) as u64,
            max_uploads: a.max_uploads.max(1),
            // Any quota above 0 is at least a byte (0 is no limit).
            max_run_bytes: ((a.max_run_gb * 1e9).round() as u64).max(u64::from(a.max_run_gb > 0.0)),
            max_runs_per_client: a.max_runs_per_client,
        },
    };
    let rt = bemcal_client::runtime()?;
    rt.block_on(serve(
        opts,
        |addr, metrics| {
            println!("listening on {addr}");
            if let Some(m) = metrics {
                println!("metrics on {}", bemcal_client::metrics::url(m));
            }
            let _ = std::io::stdout().flush();
        },
        bemcal_client::shutdown_signal(),
    ))
}

/// Kills the local coordinator and workers when dropped (SIGTERM, then wait).
struct Children(Vec<Child>);

impl Drop for Children {
    fn drop(&mut self) {
        for c in self.0.iter().rev() {
            // SAFETY: sending a signal to a child process we started.
            unsafe {
                libc::kill(c.id() as i32, libc::SIGTERM);
            }
        }
        for c in self.0.iter_mut().rev() {
            let t0 = std::time::Instant::now();
            while t0.elapsed().as_secs() < 20 {
                if let Ok(Some(_)) = c.try_wait() {
                    break;
                }
                std::thread::sleep(std::time::Duration::from_millis(100));
            }
            let _ = c.kill();
            let _ = c.wait();
        }
    }
}

/// Starts a coordinator (state in `out/.distributed/coordinator`, `chains_per_job` as its
/// `--chains-per-job`) and `workers` worker processes on loopback; they stop when the returned
/// guard is dropped. What the workers log (warnings) goes through `progress`, so that it is an
/// event of its own with `--progress json` and does not break the bars on a terminal.
pub(crate) fn start_local(
    out: &Path,
    workers: usize,
    chains_per_job: usize,
    progress: &super::progress::Progress,
) -> anyhow::Result<(impl Drop, Connect)> {
    let log = |m: &str| progress.log(m);
    let exe = std::env::current_exe().context("locating the bemcal binary")?;
    let base = out.join(".distributed");
    std::fs::create_dir_all(&base)?;
    let token = random_token();
    let mut coord = bemcal_pyenv::child_command(&exe)
        .args(["coordinator", "--listen", "127.0.0.1:0", "--data"])
        .arg(base.join("coordinator"))
        .arg("--chains-per-job")
        .arg(chains_per_job.to_string())
        // The calibration prints its own progress; the audit trail stays in the database. A
        // RUST_LOG of the user's would override the level and flood the progress.
        .args(["--log-level", "off"])
        .env_remove("RUST_LOG")
        .env(TOKEN_ENV, &token)
        .stdout(Stdio::piped())
        .spawn()
        .context("starting the coordinator")?;
    let mut line = String::new();
    std::io::BufReader::new(coord.stdout.take().context("coordinator stdout")?)
        .read_line(&mut line)?;
    let mut children = Children(vec![coord]);
    let addr = line
        .trim()
        .strip_prefix("listening on ")
        .with_context(|| format!("the coordinator did not start: {line:?}"))?
        .to_string();
    let url = format!("http://{addr}");
    log(&format!("coordinator on {url}; starting {workers} workers"));
    for i in 0..workers {
        // A local worker's coordinator stops with it: nothing to drain for.
        let mut w = bemcal_pyenv::child_command(&exe)
            .args([
                "worker",
                "--coordinator",
                &url,
                "--slots",
                "1",
                "--drain",
                "2",
            ])
            .arg("--id")
            .arg(format!("local-{i}"))
            // Its warnings only: the calibration prints its own progress.
            .args(["--log-level", "warn"])
            .env_remove("RUST_LOG")
            .arg("--cache")
            .arg(base.join(format!("worker-{i}")))
            .env(TOKEN_ENV, &token)
            .stderr(Stdio::piped())
            .spawn()
            .context("starting a worker")?;
        if let Some(stderr) = w.stderr.take() {
            let (progress, name) = (progress.clone(), format!("worker local-{i}"));
            std::thread::spawn(move || {
                for line in std::io::BufReader::new(stderr)
                    .lines()
                    .map_while(Result::ok)
                {
                    progress.log(&format!("{name}: {line}"));
                }
            });
        }
        children.0.push(w);
    }
    Ok((
        children,
        Connect {
            url,
            token,
            tls_ca: None,
        },
    ))
}

/// `bemcal calibrate --local-workers N`: a coordinator and N worker processes on loopback run
/// the calibration; the results land in `out` as with the single-process path. A surrogate
/// already in `out/surrogate` is reused (as the local path does). `chains_per_job` splits the
/// chains into jobs of that many (0: all in one job, bit-identical to the local path).
pub fn calibrate_local(
    project: &Path,
    out: &Path,
    workers: usize,
    chains_per_job: usize,
    progress: &super::progress::Progress,
) -> anyhow::Result<Summary> {
    let log = |m: &str| progress.log(m);
    let (children, connect) = start_local(out, workers, chains_per_job, progress)?;
    let surrogate = bemcal_calibrate::OutputDir::new(out).surrogate();
    let reuse = bemcal_surrogate_meta_ok(&surrogate);
    let rt = bemcal_client::runtime()?;
    let summary = rt.block_on(async {
        let mut c = connect.client()?;
        if reuse {
            log("surrogate: reusing the one trained earlier");
        }
        // A run that an interrupted calibration left in this folder is resumed by the
        // coordinator. The same project again is that run (the coordinator answers it, with
        // every job it finished); a run of another project would compete with the new one for
        // the workers: cancelled (its simulations stay in the coordinator's cache and the new
        // run reuses them).
        // On loopback the files never leave this machine: they may lie outside the project's
        // folder (special files of the system are still refused).
        let local = bemcal_client::bundle::Policy {
            allow_outside: true,
        };
        let sub =
            client::submit_project(&mut c, project, reuse.then_some(surrogate.as_path()), local)
                .await?;
        let run = sub.run_id;
        if sub.resumed {
            log(&format!(
                "run {run}, left running by an interrupted calibration of this project in this \
                 folder, goes on where it stopped"
            ));
        } else {
            log(&format!("run {run} submitted"));
        }
        let runs = c
            .list_runs(ListRunsRequest::default())
            .await?
            .into_inner()
            .runs;
        for left in runs
            .iter()
            .filter(|s| s.state() == RunState::Running && s.run_id != run)
        {
            c.cancel(RunRequest {
                run_id: left.run_id.clone(),
            })
            .await?;
            log(&format!(
                "run {} was left running by an interrupted calibration of another project in \
                 this folder: cancelled (the new run reuses its simulations)",
                left.run_id
            ));
        }
        let mut said = 0;
        let st = client::watch(&mut c, &run, |s| {
            // The driver's messages since the last change (the same as a local calibration
            // prints), then the stage and its jobs.
            for l in s.log.iter().skip(said) {
                log(l);
            }
            said = said.max(s.log.len());
            progress.run(s);
        })
        .await?;
        if st.state() != RunState::Done {
            anyhow::bail!("run {run} {}: {}", st.state().word(), st.error);
        }
        log(&format!(
            "EnergyPlus design simulations: {} run, {} from the coordinator's cache",
            st.simulations_run, st.simulations_shared
        ));
        let savings: Vec<bool> = (st.jobs.iter())
            .filter(|j| j.stage() == proto::Stage::Savings)
            .map(|j| j.cached)
            .collect();
        if !savings.is_empty() {
            let cached = savings.iter().filter(|c| **c).count();
            log(&format!(
                "EnergyPlus savings runs: {} run, {cached} from the coordinator's cache",
                savings.len() - cached
            ));
        }
        let n = client::fetch_results(&mut c, &run, out).await?;
        log(&format!("{n} result files written to {}", out.display()));
        let s: Summary = serde_json::from_str(&st.summary_json)?;
        Ok::<_, anyhow::Error>(s)
    })?;
    drop(children);
    Ok(summary)
}

fn bemcal_surrogate_meta_ok(dir: &Path) -> bool {
    bemcal_surrogate::SurrogateMeta::read(dir).is_ok()
}

//! The coordinator's durable state in SQLite: runs, stages, jobs, leases, attempts, artifacts,
//! the simulation cache and results. The schema lives here, in one place, versioned with
//! `PRAGMA user_version`; every state change is one transaction, committed before the caller
//! acknowledges anything.

use std::path::Path;
use std::sync::Mutex;

use prost::Message;
use rusqlite::{params, Connection, OptionalExtension};

use crate::audit::Event;
use crate::now_ms;
use crate::proto;
use crate::states::{JobKind, JobState, RunState, Stage};

/// Migrations, in order; `user_version` = how many have been applied.
const MIGRATIONS: &[&str] = &[
    r#"
CREATE TABLE runs (
    id          TEXT PRIMARY KEY,
    name        TEXT NOT NULL,
    state       TEXT NOT NULL,              -- running, done, failed, cancelled
    stage       TEXT NOT NULL,              -- design, simulate, train, chains, merge, validate, summary, done
    error       TEXT,
    bundle      TEXT NOT NULL,              -- JSON [File]: the project bundle
    surrogate   TEXT NOT NULL,              -- JSON [File]: a given surrogate (empty: train one)
    chain_target INTEGER NOT NULL DEFAULT 0, -- iterations per chain to reach (extensions raise it)
    extensions  INTEGER NOT NULL DEFAULT 0,
    merge       TEXT,                       -- JSON: merged chains (posterior summary, estimate)
    summary     TEXT,                       -- summary.json when done
    created_ms  INTEGER NOT NULL,
    finished_ms INTEGER
);
CREATE TABLE stages (
    run_id      TEXT NOT NULL REFERENCES runs(id),
    stage       TEXT NOT NULL,
    started_ms  INTEGER NOT NULL,
    finished_ms INTEGER,
    PRIMARY KEY (run_id, stage)
);
CREATE TABLE jobs (
    id          INTEGER PRIMARY KEY AUTOINCREMENT,
    run_id      TEXT NOT NULL REFERENCES runs(id),
    stage       TEXT NOT NULL,
    kind        TEXT NOT NULL,              -- simulate, train, chains, validate
    label       TEXT NOT NULL,              -- e.g. 'point 3', 'chains 0-1 segment 2'
    spec        BLOB NOT NULL,              -- prost-encoded proto Job (kind, bundle, inputs)
    cache_key   TEXT,                       -- simulations: hash of model + weather + values
    state       TEXT NOT NULL,              -- queued, leased, done, failed, cancelled
    lease_id    INTEGER,
    failures    INTEGER NOT NULL DEFAULT 0,
    outputs     TEXT,                       -- JSON [File]
    result      TEXT,                       -- JSON from the worker
    error       TEXT,
    cached      INTEGER NOT NULL DEFAULT 0, -- 1: answered from the simulation cache
    created_ms  INTEGER NOT NULL,
    finished_ms INTEGER
);
CREATE INDEX jobs_queue ON jobs(state, id);
CREATE INDEX jobs_run ON jobs(run_id, stage);
CREATE TABLE leases (
    id          INTEGER PRIMARY KEY AUTOINCREMENT,
    job_id      INTEGER NOT NULL REFERENCES jobs(id),
    worker_id   TEXT NOT NULL,
    granted_ms  INTEGER NOT NULL,
    expires_ms  INTEGER NOT NULL,
    active      INTEGER NOT NULL DEFAULT 1
);
CREATE INDEX leases_active ON leases(active, expires_ms);
CREATE TABLE attempts (
    lease_id    INTEGER PRIMARY KEY REFERENCES leases(id),
    job_id      INTEGER NOT NULL REFERENCES jobs(id),
    worker_id   TEXT NOT NULL,
    started_ms  INTEGER NOT NULL,
    ended_ms    INTEGER,
    outcome     TEXT,                       -- done, failed, lost, returned, stale
    error       TEXT
);
CREATE TABLE artifacts (
    sha256      TEXT PRIMARY KEY,
    size        INTEGER NOT NULL,
    created_ms  INTEGER NOT NULL
);
CREATE TABLE sim_cache (
    key         TEXT PRIMARY KEY,
    outputs     TEXT NOT NULL,              -- JSON [File]
    result      TEXT
);
CREATE TABLE results (
    run_id      TEXT NOT NULL REFERENCES runs(id),
    path        TEXT NOT NULL,
    sha256      TEXT NOT NULL,
    size        INTEGER NOT NULL,
    PRIMARY KEY (run_id, path)
);
"#,
    r#"
ALTER TABLE runs ADD COLUMN portfolio TEXT;           -- portfolio id (NULL: a lone run)
ALTER TABLE runs ADD COLUMN building TEXT;            -- the building's name in its portfolio
ALTER TABLE runs ADD COLUMN last_lease INTEGER NOT NULL DEFAULT 0; -- when it was last served (a sequence)
CREATE INDEX runs_portfolio ON runs(portfolio);
CREATE INDEX jobs_cache ON jobs(cache_key, state);
"#,
    r#"
ALTER TABLE runs ADD COLUMN refine TEXT;              -- JSON RefineLog: finished refinement rounds
ALTER TABLE stages ADD COLUMN seconds_before REAL NOT NULL DEFAULT 0; -- earlier visits of a stage
"#,
    r#"
CREATE INDEX jobs_run_state ON jobs(run_id, state, id); -- a run's queued / leased jobs (leasing)
"#,
    r#"
CREATE TABLE run_log (                                -- the driver's messages, each once per run
    run_id TEXT NOT NULL,
    ms     INTEGER NOT NULL,
    line   TEXT NOT NULL,
    UNIQUE (run_id, line)
);
"#,
    r#"
CREATE TABLE run_files (                              -- each distinct file a run's jobs produced
    run_id TEXT NOT NULL,                             -- (answers from the simulation cache not
    sha256 TEXT NOT NULL,                             -- counted): its quota's running total
    size   INTEGER NOT NULL,
    PRIMARY KEY (run_id, sha256)
);
INSERT OR IGNORE INTO run_files (run_id, sha256, size)
    SELECT j.run_id, json_extract(f.value, '$.sha256'), json_extract(f.value, '$.size')
    FROM jobs j, json_each(j.outputs) f
    WHERE j.state = 'done' AND j.cached = 0 AND json_valid(j.outputs);
"#,
    r#"
ALTER TABLE runs ADD COLUMN client TEXT;              -- the client (its token's name) that submitted it
CREATE INDEX runs_client ON runs(client, state);
CREATE TABLE workers (                                -- registered workers (docs/cluster.md)
    id                TEXT PRIMARY KEY,               -- name and a random suffix: leases' worker_id
    name              TEXT NOT NULL,                  -- the name it registered under
    credential_sha256 TEXT NOT NULL UNIQUE,           -- its credential's SHA-256 (never the credential)
    registered_ms     INTEGER NOT NULL,
    revoked_ms        INTEGER                         -- set: its credential is refused
);
CREATE INDEX workers_revoked ON workers(revoked_ms);
CREATE TABLE audit (                                  -- who did what (crate::audit)
    id       INTEGER PRIMARY KEY AUTOINCREMENT,
    ms       INTEGER NOT NULL,
    actor    TEXT NOT NULL,                           -- client:NAME, worker:ID, enroller, coordinator, operator
    action   TEXT NOT NULL,                           -- submit, lease, complete, fail, refuse-..., ...
    run_id   TEXT,
    job_id   INTEGER,
    lease_id INTEGER,
    detail   TEXT NOT NULL DEFAULT ''
);
CREATE INDEX audit_run ON audit(run_id, id);
CREATE INDEX audit_actor ON audit(actor, id);
"#,
];

pub use bemcal_client::File;

/// The coordinator's figures at one moment (see [`Store::metrics_snapshot`]).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct MetricsSnapshot {
    /// (kind, state, jobs).
    pub jobs: Vec<(String, String, u64)>,
    /// (state, runs).
    pub runs: Vec<(String, u64)>,
    /// (kind, outcome, attempts); outcomes: done, failed, lost, returned, stale, refused (the
    /// outputs would have taken the run past its quota).
    pub attempts: Vec<(String, String, u64)>,
    /// (kind, seconds) of every attempt that finished its job.
    pub durations: Vec<(String, f64)>,
    /// Bytes in the artifact store.
    pub artifact_bytes: u64,
}

/// Errors of the store.
#[derive(Debug, thiserror::Error)]
pub enum DbError {
    /// SQLite's error.
    #[error("database: {0}")]
    Sql(#[from] rusqlite::Error),
    /// A stored value that does not read back (a bad JSON column, an unknown word).
    #[error("database: {0}")]
    Other(String),
}

type Result<T> = std::result::Result<T, DbError>;

/// A run row.
#[derive(Debug, Clone)]
pub struct RunRow {
    /// The run's id (`r` and 10 random characters).
    pub id: String,
    /// The project's name.
    pub name: String,
    /// Running, done, failed or cancelled.
    pub state: RunState,
    /// The stage it is in (where it failed, for a failed run).
    pub stage: Stage,
    /// Why it failed.
    pub error: Option<String>,
    /// The project bundle's files (artifacts).
    pub bundle: Vec<File>,
    /// A surrogate given at submission (empty: one is trained).
    pub surrogate: Vec<File>,
    /// `summary.json`, when done.
    pub summary: Option<String>,
    /// When it was submitted, ms since the Unix epoch.
    pub created_ms: u64,
    /// When it ended, ms since the Unix epoch.
    pub finished_ms: Option<u64>,
    /// The portfolio it belongs to.
    pub portfolio: Option<String>,
    /// Its building's name in that portfolio.
    pub building: Option<String>,
    /// The client (its token's name) that submitted it; none for runs from before clients had
    /// names.
    pub client: Option<String>,
}

impl RunRow {
    /// Whether a submission of `bundle` and `surrogate` as building `building` of `portfolio`
    /// (empty: a lone run) is this run's again: the same files by path and content, in any
    /// order. While the run is running, such a submission is answered with it (a client that
    /// was interrupted comes back to its run, and every job the run finished is kept).
    pub fn is_submission_of(
        &self,
        bundle: &[File],
        surrogate: &[File],
        portfolio: &str,
        building: &str,
    ) -> bool {
        fn sorted(f: &[File]) -> Vec<&File> {
            let mut v: Vec<&File> = f.iter().collect();
            v.sort_by(|a, b| a.path.cmp(&b.path));
            v
        }
        self.portfolio.as_deref().unwrap_or("") == portfolio
            && self.building.as_deref().unwrap_or("") == building
            && sorted(&self.bundle) == sorted(bundle)
            && sorted(&self.surrogate) == sorted(surrogate)
    }
}

/// A job row.
#[derive(Debug, Clone)]
pub struct JobRow {
    /// The job's id (creation order).
    pub id: u64,
    /// The run it belongs to.
    pub run_id: String,
    /// The stage that created it.
    pub stage: Stage,
    /// Simulate, train, chains or validate.
    pub kind: JobKind,
    /// How logs and status name it (`point 3`, `chains 0-1 segment 2`).
    pub label: String,
    /// What a worker is sent: kind, bundle and inputs.
    pub spec: proto::Job,
    /// Queued, leased, done, failed or cancelled.
    pub state: JobState,
    /// Failed attempts so far.
    pub failures: u32,
    /// The files it produced (artifacts).
    pub outputs: Vec<File>,
    /// The worker's JSON result (or its reported failure).
    pub result: Option<String>,
    /// Answered from the simulation cache (the same inputs run before).
    pub cached: bool,
}

/// What a job completion or failure changed.
#[derive(Debug, Clone, PartialEq)]
pub enum Outcome {
    /// Recorded; the run should be advanced.
    Recorded(String),
    /// Nothing changed (late duplicate, unknown lease, run no longer running).
    Ignored,
    /// The outputs were refused and the run failed: with them its jobs' outputs would have
    /// held this many bytes, over its quota ([`Store::complete_within`]).
    OverQuota {
        /// The run.
        run: String,
        /// Its outputs' bytes with the refused ones.
        bytes: u64,
    },
}

/// The SQLite store (one connection; every call is short).
pub struct Store {
    conn: Mutex<Connection>,
}

/// Whether `run` is running (a run that has ended takes no more stages, jobs or results).
fn running_in(tx: &rusqlite::Transaction<'_>, run: &str) -> Result<bool> {
    let state: Option<String> = tx
        .query_row("SELECT state FROM runs WHERE id = ?1", [run], |r| r.get(0))
        .optional()?;
    Ok(state.as_deref() == Some(RunState::Running.as_str()))
}

/// [`Store::end_run`] inside a transaction.
fn end_run_in(
    tx: &rusqlite::Transaction<'_>,
    run: &str,
    state: RunState,
    error: Option<&str>,
) -> Result<bool> {
    // A stored message is never longer than a reply may be.
    let error = error.map(|e| crate::excerpt(e, crate::MAX_ERROR_BYTES));
    let now = now_ms() as i64;
    let n = tx.execute(
        "UPDATE runs SET state = ?2, error = COALESCE(?3, error), finished_ms = ?4
         WHERE id = ?1 AND state = 'running'",
        params![run, state, error, now],
    )?;
    if n > 0 {
        tx.execute(
            "UPDATE stages SET finished_ms = ?2 WHERE run_id = ?1 AND finished_ms IS NULL",
            params![run, now],
        )?;
        tx.execute(
            "UPDATE jobs SET state = 'cancelled' WHERE run_id = ?1 AND state IN ('queued', 'leased')",
            [run],
        )?;
        tx.execute(
            "UPDATE leases SET active = 0 WHERE active = 1 AND job_id IN (SELECT id FROM jobs WHERE run_id = ?1)",
            [run],
        )?;
        if state == RunState::Done {
            tx.execute(
                "UPDATE runs SET stage = ?2 WHERE id = ?1",
                params![run, Stage::Done.as_str()],
            )?;
        }
    }
    Ok(n > 0)
}

/// Bytes of the distinct files a run's jobs produced (answers from the simulation cache cost
/// it nothing), before and after `more` is added: what [`Store::complete_within`] holds to a
/// run's quota. Read from the run's running list (`run_files`, one row per file), not from
/// every finished job's outputs: a completion costs the same at its run's thousandth job as
/// at its first.
fn run_output_bytes(
    tx: &rusqlite::Transaction<'_>,
    run: &str,
    more: &[File],
) -> Result<(u64, u64)> {
    let before: i64 = tx.query_row(
        "SELECT COALESCE(SUM(size), 0) FROM run_files WHERE run_id = ?1",
        [run],
        |r| r.get(0),
    )?;
    let before = before.max(0) as u64;
    let mut new = std::collections::HashMap::new();
    for f in more {
        let known: bool = tx.query_row(
            "SELECT EXISTS (SELECT 1 FROM run_files WHERE run_id = ?1 AND sha256 = ?2)",
            params![run, f.sha256],
            |r| r.get(0),
        )?;
        if !known {
            new.insert(f.sha256.as_str(), f.size);
        }
    }
    let after = new.values().fold(before, |a, &b| a.saturating_add(b));
    Ok((before, after))
}

/// Adds a finished job's `outputs` to its run's list of files ([`run_output_bytes`]).
fn record_run_files(tx: &rusqlite::Transaction<'_>, run: &str, outputs: &[File]) -> Result<()> {
    for f in outputs {
        tx.execute(
            "INSERT OR IGNORE INTO run_files (run_id, sha256, size) VALUES (?1, ?2, ?3)",
            params![run, f.sha256, f.size as i64],
        )?;
    }
    Ok(())
}

fn files_json(f: &[File]) -> String {
    serde_json::to_string(f).unwrap_or_else(|_| "[]".into())
}

fn parse_files(s: Option<String>) -> Vec<File> {
    s.and_then(|s| serde_json::from_str(&s).ok())
        .unwrap_or_default()
}

/// The columns a [`RunRow`] reads. `chain_target`, `extensions`, `merge` and `refine` are
/// left from the coordinator's own driver: the one driver keeps that state in the run's
/// output folder (`chains_summary.json`, `refine.json`).
const RUN_COLS: &str =
    "id, name, state, stage, error, bundle, surrogate, summary, created_ms, finished_ms, portfolio, building, client";
const JOB_COLS: &str =
    "id, run_id, stage, kind, label, spec, state, failures, outputs, result, cached";

/// [`JOB_COLS`] of the table aliased `j` (`j.id, j.run_id, ...`), for queries that join jobs.
fn job_cols_of_j() -> String {
    JOB_COLS
        .split(", ")
        .map(|c| format!("j.{c}"))
        .collect::<Vec<_>>()
        .join(", ")
}

fn run_row(r: &rusqlite::Row<'_>) -> rusqlite::Result<RunRow> {
    Ok(RunRow {
        id: r.get(0)?,
        name: r.get(1)?,
        state: r.get(2)?,
        stage: crate::states::stage_column(r, 3)?,
        error: r.get(4)?,
        bundle: parse_files(r.get(5)?),
        surrogate: parse_files(r.get(6)?),
        summary: r.get(7)?,
        created_ms: r.get::<_, i64>(8)? as u64,
        finished_ms: r.get::<_, Option<i64>>(9)?.map(|v| v as u64),
        portfolio: r.get(10)?,
        building: r.get(11)?,
        client: r.get(12)?,
    })
}

fn job_row(r: &rusqlite::Row<'_>) -> rusqlite::Result<JobRow> {
    job_row_at(r, 0)
}

/// A job from the [`JOB_COLS`] starting at column `at`.
fn job_row_at(r: &rusqlite::Row<'_>, at: usize) -> rusqlite::Result<JobRow> {
    let spec: Vec<u8> = r.get(at + 5)?;
    Ok(JobRow {
        id: r.get::<_, i64>(at)? as u64,
        run_id: r.get(at + 1)?,
        stage: crate::states::stage_column(r, at + 2)?,
        kind: r.get(at + 3)?,
        label: r.get(at + 4)?,
        spec: proto::Job::decode(spec.as_slice()).unwrap_or_default(),
        state: r.get(at + 6)?,
        failures: r.get::<_, i64>(at + 7)? as u32,
        outputs: parse_files(r.get(at + 8)?),
        result: r.get(at + 9)?,
        cached: r.get::<_, i64>(at + 10)? != 0,
    })
}

/// A new job to add.
#[derive(Debug, Clone)]
pub struct NewJob {
    /// The stage that creates it.
    pub stage: Stage,
    /// Simulate, train, chains or validate.
    pub kind: JobKind,
    /// How logs and status name it.
    pub label: String,
    /// What a worker is sent.
    pub spec: proto::Job,
    /// For a simulation: the hash of its model, weather and values, under which its outputs
    /// are shared with every job of the same inputs.
    pub cache_key: Option<String>,
}

/// A run to record ([`Store::admit_run`]).
#[derive(Debug, Clone)]
pub struct NewRun<'a> {
    /// Its id.
    pub id: &'a str,
    /// The project's name.
    pub name: &'a str,
    /// The project bundle's files.
    pub bundle: &'a [File],
    /// A surrogate given at submission (empty: one is trained).
    pub surrogate: &'a [File],
    /// The client that submits it (empty: none named).
    pub client: &'a str,
    /// The portfolio it belongs to (empty: a lone run).
    pub portfolio: &'a str,
    /// Its building's name in that portfolio.
    pub building: &'a str,
}

/// Whether a run was admitted ([`Store::admit_run`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Admission {
    /// Recorded.
    Admitted,
    /// Not recorded: its client already runs this many runs (a portfolio counted once).
    Refused {
        /// The client's runs (and portfolios) running.
        running: u64,
    },
}

/// A registered worker ([`Store::workers`]).
#[derive(Debug, Clone, PartialEq)]
pub struct WorkerRow {
    /// Its id (leases' `worker_id`).
    pub id: String,
    /// The name it registered under.
    pub name: String,
    /// When it registered, ms since the Unix epoch.
    pub registered_ms: u64,
    /// When it was revoked, if it was.
    pub revoked_ms: Option<u64>,
    /// Its leases active now.
    pub leases: u64,
}

/// Which audit events to read ([`Store::audit_events`]).
#[derive(Debug, Clone, Default)]
pub struct AuditFilter {
    /// Only those of this run.
    pub run: Option<String>,
    /// Only those of this actor (`client:NAME`, `worker:ID`, ...).
    pub actor: Option<String>,
    /// Only the last this many (0: all).
    pub last: usize,
}

/// Records `ev` in the audit table inside `tx`, and logs it ([`crate::audit::emit`]).
fn audit_in(tx: &rusqlite::Transaction<'_>, ev: &Event) -> Result<()> {
    tx.execute(
        "INSERT INTO audit (ms, actor, action, run_id, job_id, lease_id, detail)
         VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7)",
        params![
            ev.ms as i64,
            ev.actor,
            ev.action,
            ev.run,
            ev.job.map(|j| j as i64),
            ev.lease.map(|l| l as i64),
            ev.detail
        ],
    )?;
    crate::audit::emit(ev);
    Ok(())
}

/// A fresh lease id: a random 63-bit number (positive as SQLite's integer) no lease has yet.
fn new_lease_id(tx: &rusqlite::Transaction<'_>) -> Result<i64> {
    for _ in 0..8 {
        let b = crate::auth::random_bytes::<8>()
            .map_err(|e| DbError::Other(format!("no random lease id: {e}")))?;
        let id = (u64::from_le_bytes(b) >> 1) as i64;
        let taken: bool = tx.query_row(
            "SELECT EXISTS (SELECT 1 FROM leases WHERE id = ?1)",
            [id],
            |r| r.get(0),
        )?;
        if id != 0 && !taken {
            return Ok(id);
        }
    }
    Err(DbError::Other("no free lease id in 8 draws".into()))
}

impl Store {
    /// Opens (creating and migrating) the database at `path`.
    pub fn open(path: &Path) -> Result<Store> {
        let mut conn = Connection::open(path)?;
        conn.pragma_update(None, "journal_mode", "WAL")?;
        conn.pragma_update(None, "synchronous", "FULL")?;
        conn.pragma_update(None, "foreign_keys", "ON")?;
        conn.busy_timeout(std::time::Duration::from_secs(10))?;
        let version: i64 = conn.pragma_query_value(None, "user_version", |r| r.get(0))?;
        if version as usize > MIGRATIONS.len() {
            return Err(DbError::Other(format!(
                "{} has schema version {version}, newer than this bemcal ({})",
                path.display(),
                MIGRATIONS.len()
            )));
        }
        for (i, m) in MIGRATIONS.iter().enumerate().skip(version as usize) {
            let tx = conn.transaction()?;
            tx.execute_batch(m)?;
            tx.pragma_update(None, "user_version", (i + 1) as i64)?;
            tx.commit()?;
        }
        Ok(Store {
            conn: Mutex::new(conn),
        })
    }

    fn with<T>(&self, f: impl FnOnce(&mut Connection) -> Result<T>) -> Result<T> {
        let mut c = self
            .conn
            .lock()
            .map_err(|_| DbError::Other("store lock poisoned".into()))?;
        f(&mut c)
    }

    /// Records a new run at stage `design` (of no named client: runs made by the coordinator's
    /// own tests and tools).
    pub fn create_run(
        &self,
        id: &str,
        name: &str,
        bundle: &[File],
        surrogate: &[File],
    ) -> Result<()> {
        let run = NewRun {
            id,
            name,
            bundle,
            surrogate,
            client: "",
            portfolio: "",
            building: "",
        };
        self.admit_run(&run, 0, None).map(|_| ())
    }

    /// Records `run` at stage `design`, unless its client already has `max_running` runs
    /// running (0: no limit); a portfolio counts once, however many buildings it has, and a
    /// building of a portfolio the client is running is always admitted. Decided and recorded
    /// in one transaction, with `audit` (the submission's event, its run filled in) when given.
    pub fn admit_run(
        &self,
        run: &NewRun<'_>,
        max_running: u32,
        audit: Option<Event>,
    ) -> Result<Admission> {
        self.with(|c| {
            let now = now_ms() as i64;
            let tx = c.transaction()?;
            let client = (!run.client.is_empty()).then_some(run.client);
            let portfolio = (!run.portfolio.is_empty()).then_some(run.portfolio);
            if let (Some(client), true) = (client, max_running > 0) {
                let running: i64 = tx.query_row(
                    "SELECT COUNT(DISTINCT COALESCE('p:' || portfolio, 'r:' || id)) FROM runs
                     WHERE client = ?1 AND state = 'running'",
                    [client],
                    |r| r.get(0),
                )?;
                let in_portfolio: bool = tx.query_row(
                    "SELECT EXISTS (SELECT 1 FROM runs WHERE client = ?1 AND state = 'running'
                     AND portfolio = ?2)",
                    params![client, portfolio],
                    |r| r.get(0),
                )?;
                if running >= max_running as i64 && !in_portfolio {
                    return Ok(Admission::Refused {
                        running: running as u64,
                    });
                }
            }
            tx.execute(
                "INSERT INTO runs (id, name, state, stage, bundle, surrogate, created_ms, client,
                                   portfolio, building)
                 VALUES (?1, ?2, 'running', 'design', ?3, ?4, ?5, ?6, ?7, ?8)",
                params![
                    run.id,
                    run.name,
                    files_json(run.bundle),
                    files_json(run.surrogate),
                    now,
                    client,
                    portfolio,
                    portfolio.map(|_| run.building)
                ],
            )?;
            tx.execute(
                "INSERT INTO stages (run_id, stage, started_ms) VALUES (?1, 'design', ?2)",
                params![run.id, now],
            )?;
            if let Some(ev) = audit {
                audit_in(&tx, &ev.run(run.id))?;
            }
            tx.commit()?;
            Ok(Admission::Admitted)
        })
    }

    /// Makes a run part of `portfolio` as building `building`.
    pub fn set_portfolio(&self, id: &str, portfolio: &str, building: &str) -> Result<()> {
        self.with(|c| {
            c.execute(
                "UPDATE runs SET portfolio = ?2, building = ?3 WHERE id = ?1",
                params![id, portfolio, building],
            )?;
            Ok(())
        })
    }

    /// Runs of a portfolio, in submission order.
    pub fn portfolio_runs(&self, portfolio: &str) -> Result<Vec<RunRow>> {
        self.with(|c| {
            let mut st = c.prepare(&format!(
                "SELECT {RUN_COLS} FROM runs WHERE portfolio = ?1 ORDER BY created_ms, rowid"
            ))?;
            let rows = st
                .query_map([portfolio], run_row)?
                .collect::<rusqlite::Result<Vec<_>>>()?;
            Ok(rows)
        })
    }

    /// The run `id`, if there is one.
    pub fn run(&self, id: &str) -> Result<Option<RunRow>> {
        self.with(|c| {
            Ok(c.query_row(
                &format!("SELECT {RUN_COLS} FROM runs WHERE id = ?1"),
                [id],
                run_row,
            )
            .optional()?)
        })
    }

    /// Every run, oldest first.
    pub fn runs(&self) -> Result<Vec<RunRow>> {
        self.with(|c| {
            let mut st = c.prepare(&format!("SELECT {RUN_COLS} FROM runs ORDER BY created_ms"))?;
            let rows = st
                .query_map([], run_row)?
                .collect::<rusqlite::Result<Vec<_>>>()?;
            Ok(rows)
        })
    }

    /// Ids of runs still running (to resume after a restart).
    pub fn running_runs(&self) -> Result<Vec<String>> {
        self.with(|c| {
            let mut st = c.prepare("SELECT id FROM runs WHERE state = 'running'")?;
            let rows = st
                .query_map([], |r| r.get(0))?
                .collect::<rusqlite::Result<Vec<String>>>()?;
            Ok(rows)
        })
    }

    /// Moves a run to `stage`, closing the previous stage and opening the new one; jobs given
    /// are added in the same transaction. A stage visited again (chains of a later refinement
    /// round, an extension) keeps the seconds of its earlier visits.
    /// A run that has ended (cancelled, failed, over its quota) while its driver worked is
    /// left as it is.
    pub fn set_stage(&self, run: &str, stage: Stage, jobs: Vec<NewJob>) -> Result<()> {
        self.with(|c| {
            let now = now_ms() as i64;
            let tx = c.transaction()?;
            if !running_in(&tx, run)? {
                return Ok(());
            }
            tx.execute(
                "UPDATE stages SET finished_ms = ?2 WHERE run_id = ?1 AND finished_ms IS NULL",
                params![run, now],
            )?;
            tx.execute(
                "INSERT INTO stages (run_id, stage, started_ms) VALUES (?1, ?2, ?3)
                 ON CONFLICT(run_id, stage) DO UPDATE SET
                    seconds_before = seconds_before
                        + (COALESCE(finished_ms, excluded.started_ms) - started_ms) / 1000.0,
                    started_ms = excluded.started_ms, finished_ms = NULL",
                params![run, stage.as_str(), now],
            )?;
            tx.execute(
                "UPDATE runs SET stage = ?2 WHERE id = ?1",
                params![run, stage.as_str()],
            )?;
            for j in jobs {
                insert_job(&tx, run, j)?;
            }
            tx.commit()?;
            Ok(())
        })
    }

    /// Adds jobs to a run without changing its stage (none to a run that has ended).
    pub fn add_jobs(&self, run: &str, jobs: Vec<NewJob>) -> Result<()> {
        self.with(|c| {
            let tx = c.transaction()?;
            if !running_in(&tx, run)? {
                return Ok(());
            }
            for j in jobs {
                insert_job(&tx, run, j)?;
            }
            tx.commit()?;
            Ok(())
        })
    }

    /// Stage durations (s) of a run, by stage name.
    pub fn stage_seconds(&self, run: &str) -> Result<Vec<(Stage, f64)>> {
        self.with(|c| {
            let mut st = c.prepare(
                "SELECT stage, started_ms, COALESCE(finished_ms, ?2), seconds_before FROM stages WHERE run_id = ?1",
            )?;
            let rows = st
                .query_map(params![run, now_ms() as i64], |r| {
                    Ok((
                        crate::states::stage_column(r, 0)?,
                        r.get::<_, f64>(3)?
                            + (r.get::<_, i64>(2)? - r.get::<_, i64>(1)?) as f64 / 1000.0,
                    ))
                })?
                .collect::<rusqlite::Result<Vec<_>>>()?;
            Ok(rows)
        })
    }

    /// Ends a run: `done`, `failed` (with the reason) or `cancelled`. Open jobs are cancelled.
    pub fn end_run(&self, run: &str, state: RunState, error: Option<&str>) -> Result<bool> {
        self.with(|c| {
            let tx = c.transaction()?;
            let ended = end_run_in(&tx, run, state, error)?;
            tx.commit()?;
            Ok(ended)
        })
    }

    /// Records the result files and summary of a finished run and marks it done.
    pub fn finish_run(&self, run: &str, files: &[File], summary: &str) -> Result<()> {
        self.with(|c| {
            let tx = c.transaction()?;
            // A run that ended while its summary was written keeps its end.
            if !running_in(&tx, run)? {
                return Ok(());
            }
            tx.execute("DELETE FROM results WHERE run_id = ?1", [run])?;
            for f in files {
                tx.execute(
                    "INSERT INTO results (run_id, path, sha256, size) VALUES (?1, ?2, ?3, ?4)",
                    params![run, f.path, f.sha256, f.size as i64],
                )?;
            }
            tx.execute(
                "UPDATE runs SET summary = ?2 WHERE id = ?1",
                params![run, summary],
            )?;
            end_run_in(&tx, run, RunState::Done, None)?;
            tx.commit()?;
            Ok(())
        })
    }

    /// The result files of a finished run, by path.
    pub fn results(&self, run: &str) -> Result<Vec<File>> {
        self.with(|c| {
            let mut st = c.prepare(
                "SELECT path, sha256, size FROM results WHERE run_id = ?1 ORDER BY path",
            )?;
            let rows = st
                .query_map([run], |r| {
                    Ok(File {
                        path: r.get(0)?,
                        sha256: r.get(1)?,
                        size: r.get::<_, i64>(2)? as u64,
                    })
                })?
                .collect::<rusqlite::Result<Vec<_>>>()?;
            Ok(rows)
        })
    }

    /// Records a message of the driver for `run` (a message it gave before is not repeated:
    /// the driver runs again after every change and says what it found settled again).
    pub fn add_log(&self, run: &str, line: &str) -> Result<()> {
        let line = crate::excerpt(line, crate::MAX_ERROR_BYTES);
        self.with(|c| {
            c.execute(
                "INSERT OR IGNORE INTO run_log (run_id, ms, line) VALUES (?1, ?2, ?3)",
                params![run, now_ms() as i64, line],
            )?;
            Ok(())
        })
    }

    /// The driver's messages for `run`, in order.
    pub fn log_lines(&self, run: &str) -> Result<Vec<String>> {
        self.with(|c| {
            let mut st = c.prepare("SELECT line FROM run_log WHERE run_id = ?1 ORDER BY rowid")?;
            let rows = st
                .query_map([run], |r| r.get(0))?
                .collect::<rusqlite::Result<Vec<String>>>()?;
            Ok(rows)
        })
    }

    /// Jobs of a run (optionally of one stage), in creation order.
    pub fn jobs(&self, run: &str, stage: Option<Stage>) -> Result<Vec<JobRow>> {
        self.with(|c| {
            let mut st = c.prepare(&format!(
                "SELECT {JOB_COLS} FROM jobs WHERE run_id = ?1 AND (?2 IS NULL OR stage = ?2) ORDER BY id"
            ))?;
            let rows = st
                .query_map(params![run, stage.map(Stage::as_str)], job_row)?
                .collect::<rusqlite::Result<Vec<_>>>()?;
            Ok(rows)
        })
    }

    /// Per job of a run: `(job id, attempts, worker of the live or finishing attempt)`.
    pub fn job_attempts(&self, run: &str) -> Result<Vec<(u64, u32, String)>> {
        self.with(|c| {
            let mut st = c.prepare(
                "SELECT j.id, COUNT(a.lease_id),
                        COALESCE((SELECT worker_id FROM attempts b WHERE b.job_id = j.id
                                  AND (b.outcome = 'done' OR b.outcome IS NULL)
                                  ORDER BY b.started_ms DESC LIMIT 1), '')
                 FROM jobs j LEFT JOIN attempts a ON a.job_id = j.id
                 WHERE j.run_id = ?1 GROUP BY j.id ORDER BY j.id",
            )?;
            let rows = st
                .query_map([run], |r| {
                    Ok((
                        r.get::<_, i64>(0)? as u64,
                        r.get::<_, i64>(1)? as u32,
                        r.get(2)?,
                    ))
                })?
                .collect::<rusqlite::Result<Vec<_>>>()?;
            Ok(rows)
        })
    }

    /// The workers' busy seconds on a run's jobs, by the stage that created them: the
    /// attempts that ended done or failed (a job's own failure costs its time too); an attempt
    /// lost with its worker, returned or stale is run again and not counted. Stages without
    /// such attempts are left out.
    pub fn worker_seconds(&self, run: &str) -> Result<Vec<(Stage, f64)>> {
        self.with(|c| {
            let mut st = c.prepare_cached(
                "SELECT j.stage, SUM(a.ended_ms - a.started_ms) FROM attempts a
                 JOIN jobs j ON j.id = a.job_id
                 WHERE j.run_id = ?1 AND a.outcome IN ('done', 'failed')
                 GROUP BY j.stage",
            )?;
            let rows = st
                .query_map([run], |r| {
                    Ok((
                        crate::states::stage_column(r, 0)?,
                        r.get::<_, i64>(1)?.max(0) as f64 / 1000.0,
                    ))
                })?
                .collect::<rusqlite::Result<Vec<_>>>()?;
            Ok(rows)
        })
    }

    /// Number of attempts (leases granted) for a run's jobs.
    pub fn attempts(&self, run: &str) -> Result<u64> {
        self.with(|c| {
            Ok(c.query_row(
                "SELECT COUNT(*) FROM attempts a JOIN jobs j ON j.id = a.job_id WHERE j.run_id = ?1",
                [run],
                |r| r.get::<_, i64>(0),
            )? as u64)
        })
    }

    /// What `/metrics` reports, read in one transaction: jobs by kind and state, runs by
    /// state, attempts by kind and outcome (`lost` = a lease that expired), the durations of
    /// finished attempts by kind, and the artifact store's size. Every figure is derived from
    /// the durable record, so the counters survive a restart.
    pub fn metrics_snapshot(&self) -> Result<MetricsSnapshot> {
        self.with(|c| {
            let tx = c.transaction()?;
            let pairs = |sql: &str| -> rusqlite::Result<Vec<(String, String, u64)>> {
                let mut st = tx.prepare(sql)?;
                let rows = st
                    .query_map([], |r| Ok((r.get(0)?, r.get(1)?, r.get::<_, i64>(2)? as u64)))?
                    .collect();
                rows
            };
            let jobs = pairs("SELECT kind, state, COUNT(*) FROM jobs GROUP BY kind, state")?;
            let attempts = pairs(
                "SELECT j.kind, a.outcome, COUNT(*) FROM attempts a JOIN jobs j ON j.id = a.job_id
                 WHERE a.outcome IS NOT NULL GROUP BY j.kind, a.outcome",
            )?;
            let runs = {
                let mut st = tx.prepare("SELECT state, COUNT(*) FROM runs GROUP BY state")?;
                let rows = st
                    .query_map([], |r| Ok((r.get(0)?, r.get::<_, i64>(1)? as u64)))?
                    .collect::<rusqlite::Result<Vec<(String, u64)>>>()?;
                rows
            };
            let durations = {
                let mut st = tx.prepare(
                    "SELECT j.kind, a.ended_ms - a.started_ms FROM attempts a JOIN jobs j ON j.id = a.job_id
                     WHERE a.outcome = 'done' AND a.ended_ms IS NOT NULL",
                )?;
                let rows = st
                    .query_map([], |r| Ok((r.get(0)?, r.get::<_, i64>(1)?.max(0) as f64 / 1e3)))?
                    .collect::<rusqlite::Result<Vec<(String, f64)>>>()?;
                rows
            };
            let artifact_bytes: i64 =
                tx.query_row("SELECT COALESCE(SUM(size), 0) FROM artifacts", [], |r| r.get(0))?;
            Ok(MetricsSnapshot {
                jobs,
                runs,
                attempts,
                durations,
                artifact_bytes: artifact_bytes.max(0) as u64,
            })
        })
    }

    /// Counts of queued and leased jobs of running runs.
    pub fn queue_depth(&self) -> Result<(u64, u64)> {
        self.with(|c| {
            let q = |s: &str| -> rusqlite::Result<i64> {
                c.query_row("SELECT COUNT(*) FROM jobs WHERE state = ?1", [s], |r| {
                    r.get(0)
                })
            };
            Ok((q("queued")? as u64, q("leased")? as u64))
        })
    }

    /// Hands a queued job of a running run to `worker` for `ttl_ms`, fairly across runs: the
    /// run with the fewest jobs leased now goes first, ties to the run served longest ago
    /// (round-robin), and within a run the oldest job (its earliest stage first). A simulation
    /// whose inputs (cache key) another job is simulating now waits: its outputs will be shared
    /// when that one completes.
    pub fn lease(&self, worker: &str, ttl_ms: u64) -> Result<Option<proto::Job>> {
        self.with(|c| {
            let now = now_ms() as i64;
            let tx = c.transaction()?;
            let job = tx
                .query_row(
                    &format!(
                        // Each run's oldest eligible job first, then the runs ordered: the
                        // leased count is counted once per run, not once per queued job.
                        "WITH eligible AS (
                           SELECT j.run_id AS run_id, MIN(j.id) AS first
                           FROM jobs j JOIN runs r ON r.id = j.run_id
                           WHERE j.state = 'queued' AND r.state = 'running'
                             AND (j.cache_key IS NULL OR NOT EXISTS (
                                  SELECT 1 FROM jobs k WHERE k.cache_key = j.cache_key AND k.state = 'leased'))
                           GROUP BY j.run_id)
                         SELECT {} FROM eligible e JOIN runs r ON r.id = e.run_id JOIN jobs j ON j.id = e.first
                         ORDER BY (SELECT COUNT(*) FROM jobs k WHERE k.run_id = e.run_id AND k.state = 'leased'),
                                  r.last_lease, e.first
                         LIMIT 1",
                        job_cols_of_j()
                    ),
                    [],
                    job_row,
                )
                .optional()?;
            let Some(job) = job else {
                return Ok(None);
            };
            // Unguessable: a lease id names no other lease, and a worker cannot work out
            // another's from its own.
            let lease = new_lease_id(&tx)?;
            tx.execute(
                "INSERT INTO leases (id, job_id, worker_id, granted_ms, expires_ms) VALUES (?1, ?2, ?3, ?4, ?5)",
                params![lease, job.id as i64, worker, now, now + ttl_ms as i64],
            )?;
            tx.execute(
                "INSERT INTO attempts (lease_id, job_id, worker_id, started_ms) VALUES (?1, ?2, ?3, ?4)",
                params![lease, job.id as i64, worker, now],
            )?;
            tx.execute(
                "UPDATE jobs SET state = 'leased', lease_id = ?2 WHERE id = ?1",
                params![job.id as i64, lease],
            )?;
            // The order in which runs were last served (lease ids are random, not ordered).
            tx.execute(
                "UPDATE runs SET last_lease = (SELECT COALESCE(MAX(last_lease), 0) + 1 FROM runs)
                 WHERE id = ?1",
                [&job.run_id],
            )?;
            audit_in(
                &tx,
                &Event::new(format!("worker:{worker}"), "lease")
                    .run(&job.run_id)
                    .job(job.id)
                    .lease(lease as u64)
                    .detail(&job.label),
            )?;
            tx.commit()?;
            let mut spec = job.spec;
            spec.job_id = job.id;
            spec.lease_id = lease as u64;
            spec.run_id = job.run_id;
            spec.lease_ttl_ms = ttl_ms as u32;
            Ok(Some(spec))
        })
    }

    /// Extends a live lease; false when it is gone.
    pub fn heartbeat(&self, lease: u64, ttl_ms: u64) -> Result<bool> {
        self.with(|c| {
            let n = c.execute(
                "UPDATE leases SET expires_ms = ?2 WHERE id = ?1 AND active = 1
                 AND job_id IN (SELECT id FROM jobs WHERE state = 'leased' AND lease_id = ?1)",
                params![lease as i64, (now_ms() + ttl_ms) as i64],
            )?;
            Ok(n > 0)
        })
    }

    /// The worker that took lease `lease` and the job it was for (whatever their states now),
    /// if the lease exists.
    pub fn leased_job(&self, lease: u64) -> Result<Option<(String, JobRow)>> {
        self.with(|c| {
            let cols = job_cols_of_j();
            Ok(c.query_row(
                &format!(
                    "SELECT l.worker_id, {cols} FROM leases l JOIN jobs j ON j.id = l.job_id
                     WHERE l.id = ?1"
                ),
                [lease as i64],
                |r| {
                    let worker: String = r.get(0)?;
                    // The job's columns follow the worker's.
                    let job = job_row_at(r, 1)?;
                    Ok((worker, job))
                },
            )
            .optional()?)
        })
    }

    /// Extends every active lease by `ttl_ms` from now (on start-up: workers could not
    /// heartbeat while the coordinator was down).
    pub fn refresh_leases(&self, ttl_ms: u64) -> Result<()> {
        self.with(|c| {
            c.execute(
                "UPDATE leases SET expires_ms = ?1 WHERE active = 1",
                [(now_ms() + ttl_ms) as i64],
            )?;
            Ok(())
        })
    }

    /// Records a finished job (durably) from lease `lease`. A job already done (a late
    /// duplicate) is left as it is. A simulation's outputs also answer every queued job with the
    /// same cache key (other buildings of a portfolio with the same inputs); the runs of those
    /// jobs are returned besides the outcome, to be advanced too.
    pub fn complete(
        &self,
        lease: u64,
        outputs: &[File],
        result: &str,
    ) -> Result<(Outcome, Vec<String>)> {
        self.complete_within(lease, outputs, result, 0)
    }

    /// [`Store::complete`], holding the run to `max_run_bytes` (0: no limit): where the
    /// outputs would take the distinct files its jobs produced past it, they are not recorded
    /// and the run fails, saying so ([`Outcome::OverQuota`]). Checked and decided in one
    /// transaction, so that two completions at once cannot both slip under the quota.
    pub fn complete_within(
        &self,
        lease: u64,
        outputs: &[File],
        result: &str,
        max_run_bytes: u64,
    ) -> Result<(Outcome, Vec<String>)> {
        self.with(|c| {
            let now = now_ms() as i64;
            let tx = c.transaction()?;
            let Some(held) = held_lease(&tx, lease)? else {
                return Ok((Outcome::Ignored, vec![]));
            };
            let event = |action: &str, detail: String| held.event(lease, action, detail);
            let HeldLease {
                job,
                ref state,
                ref run,
                cache_key: ref key,
                ref run_state,
                ref label,
                ..
            } = held;
            let fresh = (state == "queued" || state == "leased") && run_state == "running";
            // Over the quota only by what these outputs add: a completion that adds nothing
            // (a simulation reporting EnergyPlus's failure, a file the run already has) is
            // recorded even where a lowered quota is already passed.
            let (before, bytes) = match fresh && max_run_bytes > 0 {
                true => run_output_bytes(&tx, run, outputs)?,
                false => (0, 0),
            };
            let over = max_run_bytes > 0 && bytes > max_run_bytes && bytes > before;
            let outcome = match (fresh, over) {
                (false, _) => "stale",
                (true, true) => "refused",
                (true, false) => "done",
            };
            // A repeated completion (a retry after a lost reply) leaves the first one's outcome.
            tx.execute(
                "UPDATE attempts SET ended_ms = ?2, outcome = ?3 WHERE lease_id = ?1 AND ended_ms IS NULL",
                params![lease as i64, now, outcome],
            )?;
            tx.execute("UPDATE leases SET active = 0 WHERE id = ?1", [lease as i64])?;
            if !fresh {
                let why = format!("{label}: ignored, the job is {state} and its run {run_state}");
                audit_in(&tx, &event("complete-stale", why))?;
                tx.commit()?;
                return Ok((Outcome::Ignored, vec![]));
            }
            if over {
                let msg = format!(
                    "stopped: with the outputs of job {job} the run's files would take {bytes} \
                     bytes, over the coordinator's per-run quota of {max_run_bytes} bytes \
                     (--max-run-gb)"
                );
                audit_in(&tx, &event("refuse-complete", format!("{label}: {msg}")))?;
                end_run_in(&tx, run, RunState::Failed, Some(&msg))?;
                tx.commit()?;
                let run = run.clone();
                return Ok((Outcome::OverQuota { run, bytes }, vec![]));
            }
            audit_in(&tx, &event("complete", format!("{label}: {result}")))?;
            tx.execute(
                "UPDATE jobs SET state = 'done', outputs = ?2, result = ?3, finished_ms = ?4, lease_id = NULL WHERE id = ?1",
                params![job, files_json(outputs), result, now],
            )?;
            record_run_files(&tx, run, outputs)?;
            tx.execute(
                "UPDATE leases SET active = 0 WHERE job_id = ?1",
                [job],
            )?;
            let mut shared = vec![];
            if let Some(k) = key {
                tx.execute(
                    "INSERT OR REPLACE INTO sim_cache (key, outputs, result) VALUES (?1, ?2, ?3)",
                    params![k, files_json(outputs), result],
                )?;
                shared = {
                    let mut st = tx.prepare(
                        "SELECT DISTINCT run_id FROM jobs WHERE cache_key = ?1 AND state = 'queued' AND run_id != ?2",
                    )?;
                    let rows = st
                        .query_map(params![k, run], |r| r.get(0))?
                        .collect::<rusqlite::Result<Vec<String>>>()?;
                    rows
                };
                tx.execute(
                    "UPDATE jobs SET state = 'done', outputs = ?2, result = ?3, cached = 1, finished_ms = ?4
                     WHERE cache_key = ?1 AND state = 'queued'",
                    params![k, files_json(outputs), result, now],
                )?;
            }
            tx.commit()?;
            Ok((Outcome::Recorded(run.clone()), shared))
        })
    }

    /// Records a failed attempt. `requeue`: the worker gives the job back (not a failure).
    /// After `max_failures` failures the job fails and so does its run, with the error.
    pub fn fail(
        &self,
        lease: u64,
        error: &str,
        requeue: bool,
        max_failures: u32,
    ) -> Result<Outcome> {
        self.with(|c| {
            let tx = c.transaction()?;
            let out = fail_in(
                &tx,
                lease,
                error,
                if requeue { "returned" } else { "failed" },
                max_failures,
            )?;
            tx.commit()?;
            Ok(out)
        })
    }

    /// Expires leases whose heartbeats stopped: their jobs are queued again (each loss counts
    /// as a failed attempt). Returns the runs that changed.
    pub fn expire(&self, max_failures: u32) -> Result<Vec<String>> {
        self.with(|c| {
            let tx = c.transaction()?;
            let expired: Vec<i64> = {
                let mut st =
                    tx.prepare("SELECT id FROM leases WHERE active = 1 AND expires_ms < ?1")?;
                let rows = st
                    .query_map([now_ms() as i64], |r| r.get(0))?
                    .collect::<rusqlite::Result<Vec<i64>>>()?;
                rows
            };
            let mut runs = vec![];
            for l in expired {
                if let Outcome::Recorded(r) = fail_in(
                    &tx,
                    l as u64,
                    "lease expired: the worker stopped sending heartbeats",
                    "lost",
                    max_failures,
                )? {
                    runs.push(r);
                }
            }
            tx.commit()?;
            Ok(runs)
        })
    }

    /// Records a new worker registered as `name` with the credential whose SHA-256 is
    /// `credential_sha256`, by `actor` (the enrollment token's holder); returns its id: the
    /// name and a random suffix, unique.
    pub fn register_worker(
        &self,
        name: &str,
        credential_sha256: &str,
        actor: &str,
    ) -> Result<String> {
        self.with(|c| {
            let tx = c.transaction()?;
            for _ in 0..8 {
                let b = crate::auth::random_bytes::<4>()
                    .map_err(|e| DbError::Other(format!("no random worker id: {e}")))?;
                let id = format!("{name}-{}", hex::encode(b));
                let n = tx.execute(
                    "INSERT OR IGNORE INTO workers (id, name, credential_sha256, registered_ms)
                     VALUES (?1, ?2, ?3, ?4)",
                    params![id, name, credential_sha256, now_ms() as i64],
                )?;
                if n == 1 {
                    audit_in(
                        &tx,
                        &Event::new(actor, "register").detail(format!("worker {id} (name {name})")),
                    )?;
                    tx.commit()?;
                    return Ok(id);
                }
            }
            Err(DbError::Other(format!(
                "no free worker id for {name} in 8 draws"
            )))
        })
    }

    /// Every registered worker's credential: `(SHA-256, worker id, revoked)`.
    pub fn worker_credentials(&self) -> Result<Vec<(String, String, bool)>> {
        self.with(|c| {
            let mut st =
                c.prepare("SELECT credential_sha256, id, revoked_ms IS NOT NULL FROM workers")?;
            let rows = st
                .query_map([], |r| Ok((r.get(0)?, r.get(1)?, r.get(2)?)))?
                .collect::<rusqlite::Result<Vec<_>>>()?;
            Ok(rows)
        })
    }

    /// Revokes worker `id` (by `actor`): its credential is refused from now on (a running
    /// coordinator learns of it within a second, [`Store::revoked_since`]). False when there is
    /// no such worker; a worker revoked already stays revoked since then.
    pub fn revoke_worker(&self, id: &str, actor: &str) -> Result<bool> {
        self.with(|c| {
            let tx = c.transaction()?;
            let known: bool = tx.query_row(
                "SELECT EXISTS (SELECT 1 FROM workers WHERE id = ?1)",
                [id],
                |r| r.get(0),
            )?;
            if !known {
                return Ok(false);
            }
            tx.execute(
                "UPDATE workers SET revoked_ms = ?2 WHERE id = ?1 AND revoked_ms IS NULL",
                params![id, now_ms() as i64],
            )?;
            audit_in(
                &tx,
                &Event::new(actor, "revoke").detail(format!("worker {id}")),
            )?;
            tx.commit()?;
            Ok(true)
        })
    }

    /// Workers revoked at or after `ms`: `(id, when)`.
    pub fn revoked_since(&self, ms: u64) -> Result<Vec<(String, u64)>> {
        self.with(|c| {
            let mut st = c.prepare("SELECT id, revoked_ms FROM workers WHERE revoked_ms >= ?1")?;
            let rows = st
                .query_map([ms as i64], |r| Ok((r.get(0)?, r.get::<_, i64>(1)? as u64)))?
                .collect::<rusqlite::Result<Vec<_>>>()?;
            Ok(rows)
        })
    }

    /// The registered workers, in registration order, with their active leases.
    pub fn workers(&self) -> Result<Vec<WorkerRow>> {
        self.with(|c| {
            let mut st = c.prepare(
                "SELECT w.id, w.name, w.registered_ms, w.revoked_ms,
                        (SELECT COUNT(*) FROM leases l WHERE l.worker_id = w.id AND l.active = 1)
                 FROM workers w ORDER BY w.registered_ms, w.rowid",
            )?;
            let rows = st
                .query_map([], |r| {
                    Ok(WorkerRow {
                        id: r.get(0)?,
                        name: r.get(1)?,
                        registered_ms: r.get::<_, i64>(2)? as u64,
                        revoked_ms: r.get::<_, Option<i64>>(3)?.map(|v| v as u64),
                        leases: r.get::<_, i64>(4)? as u64,
                    })
                })?
                .collect::<rusqlite::Result<Vec<_>>>()?;
            Ok(rows)
        })
    }

    /// Gives back every active lease of `worker` (revoked): their jobs are queued again, not
    /// counted as failures. Returns the runs that changed.
    pub fn return_leases_of(&self, worker: &str, max_failures: u32) -> Result<Vec<String>> {
        self.with(|c| {
            let tx = c.transaction()?;
            let leases: Vec<i64> = {
                let mut st =
                    tx.prepare("SELECT id FROM leases WHERE worker_id = ?1 AND active = 1")?;
                let rows = st
                    .query_map([worker], |r| r.get(0))?
                    .collect::<rusqlite::Result<Vec<i64>>>()?;
                rows
            };
            let mut runs = vec![];
            for l in leases {
                let error = "the worker's credential was revoked";
                if let Outcome::Recorded(r) =
                    fail_in(&tx, l as u64, error, "returned", max_failures)?
                {
                    runs.push(r);
                }
            }
            tx.commit()?;
            Ok(runs)
        })
    }

    /// Records `ev` in the audit trail (and logs it).
    pub fn audit(&self, ev: &Event) -> Result<()> {
        self.with(|c| {
            let tx = c.transaction()?;
            audit_in(&tx, ev)?;
            tx.commit()?;
            Ok(())
        })
    }

    /// The audit trail's events that `filter` selects, oldest first.
    pub fn audit_events(&self, filter: &AuditFilter) -> Result<Vec<Event>> {
        self.with(|c| {
            let mut st = c.prepare(
                "SELECT ms, actor, action, run_id, job_id, lease_id, detail FROM (
                   SELECT * FROM audit WHERE (?1 IS NULL OR run_id = ?1) AND (?2 IS NULL OR actor = ?2)
                   ORDER BY id DESC LIMIT ?3)
                 ORDER BY id",
            )?;
            let limit = if filter.last == 0 { -1 } else { filter.last as i64 };
            let rows = st
                .query_map(params![filter.run, filter.actor, limit], |r| {
                    Ok(Event {
                        ms: r.get::<_, i64>(0)? as u64,
                        actor: r.get(1)?,
                        action: r.get(2)?,
                        run: r.get(3)?,
                        job: r.get::<_, Option<i64>>(4)?.map(|v| v as u64),
                        lease: r.get::<_, Option<i64>>(5)?.map(|v| v as u64),
                        detail: r.get(6)?,
                    })
                })?
                .collect::<rusqlite::Result<Vec<_>>>()?;
            Ok(rows)
        })
    }

    /// Looks up the simulation cache.
    pub fn cached_simulation(&self, key: &str) -> Result<Option<(Vec<File>, Option<String>)>> {
        self.with(|c| {
            Ok(c.query_row(
                "SELECT outputs, result FROM sim_cache WHERE key = ?1",
                [key],
                |r| Ok((parse_files(r.get(0)?), r.get(1)?)),
            )
            .optional()?)
        })
    }

    /// Notes an artifact the coordinator holds.
    /// Artifacts recorded before `before_ms` that nothing in the database refers to: no run's
    /// bundle, surrogate or results, no job's spec or outputs, no simulation-cache entry (an
    /// upload whose submit or completion never came, a stale completion's outputs).
    pub fn unreferenced_artifacts(&self, before_ms: u64) -> Result<Vec<String>> {
        self.with(|c| {
            let mut referenced = std::collections::HashSet::new();
            for sql in [
                "SELECT bundle FROM runs",
                "SELECT surrogate FROM runs",
                "SELECT spec FROM jobs",
                "SELECT outputs FROM jobs WHERE outputs IS NOT NULL",
                "SELECT outputs FROM sim_cache",
                "SELECT sha256 FROM results",
            ] {
                let mut st = c.prepare(sql)?;
                let mut rows = st.query([])?;
                while let Some(r) = rows.next()? {
                    if let rusqlite::types::ValueRef::Text(t) | rusqlite::types::ValueRef::Blob(t) =
                        r.get_ref(0)?
                    {
                        sha256s_in(t, &mut referenced);
                    }
                }
            }
            let mut st = c.prepare("SELECT sha256 FROM artifacts WHERE created_ms < ?1")?;
            let old = st
                .query_map([before_ms as i64], |r| r.get::<_, String>(0))?
                .collect::<rusqlite::Result<Vec<_>>>()?;
            Ok(old
                .into_iter()
                .filter(|s| !referenced.contains(s))
                .collect())
        })
    }

    /// Bytes of every artifact recorded.
    pub fn artifact_bytes(&self) -> Result<u64> {
        self.with(|c| {
            Ok(
                c.query_row("SELECT COALESCE(SUM(size), 0) FROM artifacts", [], |r| {
                    r.get::<_, i64>(0)
                })? as u64,
            )
        })
    }

    /// Forgets artifacts (after their files are removed).
    pub fn remove_artifacts(&self, shas: &[String]) -> Result<()> {
        self.with(|c| {
            let tx = c.transaction()?;
            for s in shas {
                tx.execute("DELETE FROM artifacts WHERE sha256 = ?1", [s])?;
            }
            tx.commit()?;
            Ok(())
        })
    }

    /// Records an artifact in the store (`sha` = its SHA-256, `size` in bytes).
    pub fn add_artifact(&self, sha: &str, size: u64) -> Result<()> {
        self.with(|c| {
            c.execute(
                "INSERT OR IGNORE INTO artifacts (sha256, size, created_ms) VALUES (?1, ?2, ?3)",
                params![sha, size as i64, now_ms() as i64],
            )?;
            Ok(())
        })
    }
}

/// Every sha256 (64 lowercase hex characters in a row) in `bytes`: the artifacts a JSON list of
/// files or a proto job refers to.
fn sha256s_in(bytes: &[u8], out: &mut std::collections::HashSet<String>) {
    let hex = |b: &u8| b.is_ascii_digit() || (b'a'..=b'f').contains(b);
    let mut i = 0;
    while i < bytes.len() {
        let run = bytes[i..].iter().take_while(|b| hex(b)).count();
        if run == 64 {
            out.insert(String::from_utf8_lossy(&bytes[i..i + 64]).into_owned());
        }
        i += run.max(1);
    }
}

/// What a completion of a lease needs to know of it ([`held_lease`]).
struct HeldLease {
    job: i64,
    state: String,
    run: String,
    cache_key: Option<String>,
    run_state: String,
    worker: String,
    label: String,
}

impl HeldLease {
    /// The audit event of `action` on this lease (`lease`), by its worker.
    fn event(&self, lease: u64, action: &str, detail: String) -> Event {
        Event::new(format!("worker:{}", self.worker), action)
            .run(&self.run)
            .job(self.job as u64)
            .lease(lease)
            .detail(detail)
    }
}

/// Lease `lease`'s job, its run and the worker that took it, whatever their states.
fn held_lease(tx: &rusqlite::Transaction<'_>, lease: u64) -> Result<Option<HeldLease>> {
    Ok(tx
        .query_row(
            "SELECT j.id, j.state, j.run_id, j.cache_key, r.state, l.worker_id, j.label
             FROM leases l JOIN jobs j ON j.id = l.job_id JOIN runs r ON r.id = j.run_id
             WHERE l.id = ?1",
            [lease as i64],
            |r| {
                Ok(HeldLease {
                    job: r.get(0)?,
                    state: r.get(1)?,
                    run: r.get(2)?,
                    cache_key: r.get(3)?,
                    run_state: r.get(4)?,
                    worker: r.get(5)?,
                    label: r.get(6)?,
                })
            },
        )
        .optional()?)
}

fn insert_job(tx: &rusqlite::Transaction<'_>, run: &str, j: NewJob) -> Result<()> {
    let now = now_ms() as i64;
    let cached = match &j.cache_key {
        Some(k) => tx
            .query_row(
                "SELECT outputs, result FROM sim_cache WHERE key = ?1",
                [k],
                |r| Ok((r.get::<_, String>(0)?, r.get::<_, Option<String>>(1)?)),
            )
            .optional()?,
        None => None,
    };
    let spec = j.spec.encode_to_vec();
    match cached {
        Some((outputs, result)) => {
            tx.execute(
                "INSERT INTO jobs (run_id, stage, kind, label, spec, cache_key, state, outputs, result, cached, created_ms, finished_ms)
                 VALUES (?1, ?2, ?3, ?4, ?5, ?6, 'done', ?7, ?8, 1, ?9, ?9)",
                params![run, j.stage.as_str(), j.kind, j.label, spec, j.cache_key, outputs, result, now],
            )?;
        }
        None => {
            tx.execute(
                "INSERT INTO jobs (run_id, stage, kind, label, spec, cache_key, state, created_ms)
                 VALUES (?1, ?2, ?3, ?4, ?5, ?6, 'queued', ?7)",
                params![
                    run,
                    j.stage.as_str(),
                    j.kind,
                    j.label,
                    spec,
                    j.cache_key,
                    now
                ],
            )?;
        }
    }
    Ok(())
}

fn fail_in(
    tx: &rusqlite::Transaction<'_>,
    lease: u64,
    error: &str,
    outcome: &str,
    max_failures: u32,
) -> Result<Outcome> {
    let now = now_ms() as i64;
    type Row = (i64, String, Option<i64>, i64, String, String, String);
    let row: Option<Row> = tx
        .query_row(
            "SELECT j.id, j.state, j.lease_id, j.failures, j.run_id, j.label, l.worker_id
             FROM leases l JOIN jobs j ON j.id = l.job_id WHERE l.id = ?1 AND l.active = 1",
            [lease as i64],
            |r| {
                Ok((
                    r.get(0)?,
                    r.get(1)?,
                    r.get(2)?,
                    r.get(3)?,
                    r.get(4)?,
                    r.get(5)?,
                    r.get(6)?,
                ))
            },
        )
        .optional()?;
    tx.execute("UPDATE leases SET active = 0 WHERE id = ?1", [lease as i64])?;
    tx.execute(
        "UPDATE attempts SET ended_ms = ?2, outcome = ?3, error = ?4 WHERE lease_id = ?1 AND ended_ms IS NULL",
        params![lease as i64, now, outcome, error],
    )?;
    let Some((job, state, cur, failures, run, label, worker)) = row else {
        return Ok(Outcome::Ignored);
    };
    if state != "leased" || cur != Some(lease as i64) {
        return Ok(Outcome::Ignored);
    }
    let action = match outcome {
        "returned" => "return",
        "lost" => "lost",
        _ => "fail",
    };
    let event = |detail: String| {
        Event::new(format!("worker:{worker}"), action)
            .run(&run)
            .job(job as u64)
            .lease(lease)
            .detail(detail)
    };
    let failures = failures + if outcome == "returned" { 0 } else { 1 };
    if failures >= max_failures as i64 {
        tx.execute(
            "UPDATE jobs SET state = 'failed', failures = ?2, error = ?3, lease_id = NULL, finished_ms = ?4 WHERE id = ?1",
            params![job, failures, error, now],
        )?;
        let reason = format!("{label} failed {failures} times; last error: {error}");
        audit_in(
            tx,
            &event(format!(
                "{label}: failure {failures} of {max_failures}, the job and its run fail: {error}"
            )),
        )?;
        end_run_in(tx, &run, RunState::Failed, Some(&reason))?;
    } else {
        tx.execute(
            "UPDATE jobs SET state = 'queued', failures = ?2, error = ?3, lease_id = NULL WHERE id = ?1",
            params![job, failures, error],
        )?;
        let detail = match outcome {
            "returned" => format!("{label}: given back, queued again: {error}"),
            _ => format!(
                "{label}: failure {failures} of {max_failures}, queued for a retry: {error}"
            ),
        };
        audit_in(tx, &event(detail))?;
    }
    Ok(Outcome::Recorded(run))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn store(name: &str) -> (Store, std::path::PathBuf) {
        let dir = std::env::temp_dir().join(format!(
            "bemcal-db-{name}-{}-{}",
            std::process::id(),
            now_ms()
        ));
        std::fs::create_dir_all(&dir).unwrap();
        (Store::open(&dir.join("coordinator.db")).unwrap(), dir)
    }

    fn jobs(n: usize, key: impl Fn(usize) -> Option<String>) -> Vec<NewJob> {
        (0..n)
            .map(|i| NewJob {
                stage: Stage::Simulate,
                kind: JobKind::Simulate,
                label: format!("point {i}"),
                spec: proto::Job::default(),
                cache_key: key(i),
            })
            .collect()
    }

    #[test]
    fn artifacts_nothing_refers_to_are_found_once_past_their_grace() {
        let (s, dir) = store("gc");
        let sha = |c: char| c.to_string().repeat(64);
        let file = |c: char| File {
            path: format!("{c}.txt"),
            sha256: sha(c),
            size: 1,
        };
        for c in ['a', 'b', 'c', 'd', 'e'] {
            s.add_artifact(&sha(c), 1).unwrap();
        }
        // a: a run's bundle; b: a job's spec (proto bytes); c: a job's outputs; d, e: nothing.
        s.create_run("R", "r", &[file('a')], &[]).unwrap();
        let spec = proto::Job {
            inputs: vec![proto::FileRef::from(&file('b'))],
            ..Default::default()
        };
        let job = NewJob {
            spec,
            ..jobs(1, |_| None).remove(0)
        };
        s.set_stage("R", Stage::Simulate, vec![job]).unwrap();
        let lease = s.lease("w", 60_000).unwrap().unwrap().lease_id;
        s.complete(lease, &[file('c')], "{}").unwrap();
        let later = now_ms() + 1;
        let mut orphans = s.unreferenced_artifacts(later).unwrap();
        orphans.sort();
        assert_eq!(orphans, vec![sha('d'), sha('e')]);
        // Within their grace period, nothing is collected.
        assert!(s.unreferenced_artifacts(0).unwrap().is_empty());
        s.remove_artifacts(&orphans).unwrap();
        assert!(s.unreferenced_artifacts(later).unwrap().is_empty());
        let _ = std::fs::remove_dir_all(dir);
    }

    #[test]
    fn worker_seconds_count_finished_and_failed_attempts_by_stage_not_returned_ones() {
        let (s, dir) = store("busy");
        s.create_run("R", "r", &[], &[]).unwrap();
        s.set_stage("R", Stage::Simulate, jobs(3, |_| None))
            .unwrap();
        let lease = |s: &Store| s.lease("w", 60_000).unwrap().unwrap().lease_id;
        let (a, b) = (lease(&s), lease(&s));
        s.complete(a, &[], "{}").unwrap();
        s.fail(b, "EnergyPlus: Severe", false, 3).unwrap();
        // A lease given back (a worker stopping) is run again: its time is not the run's cost.
        let c = lease(&s);
        s.fail(c, "worker stopping", true, 3).unwrap();
        // Durations set outright: 2 s, 3 s and (not counted) 7 s.
        s.with(|conn| {
            for (l, secs) in [(a, 2_000), (b, 3_000), (c, 7_000)] {
                conn.execute(
                    "UPDATE attempts SET started_ms = ended_ms - ?2 WHERE lease_id = ?1",
                    params![l as i64, secs],
                )?;
            }
            Ok(())
        })
        .unwrap();
        assert_eq!(s.worker_seconds("R").unwrap(), vec![(Stage::Simulate, 5.0)]);
        assert!(s.worker_seconds("other").unwrap().is_empty());
        let _ = std::fs::remove_dir_all(dir);
    }

    #[test]
    fn lease_alternates_between_runs_instead_of_draining_the_first() {
        let (s, dir) = store("fair");
        s.create_run("A", "big", &[], &[]).unwrap();
        s.create_run("B", "small", &[], &[]).unwrap();
        s.set_stage("A", Stage::Simulate, jobs(50, |_| None))
            .unwrap();
        s.set_stage("B", Stage::Simulate, jobs(2, |_| None))
            .unwrap();
        // Leases held (workers busy): A, B, A, B, then only A is left.
        let held: Vec<proto::Job> = (0..6)
            .map(|_| s.lease("w", 60_000).unwrap().unwrap())
            .collect();
        let order: Vec<&str> = held.iter().map(|j| j.run_id.as_str()).collect();
        assert_eq!(order, ["A", "B", "A", "B", "A", "A"]);
        // A third run arriving while A and B hold leases goes first (it has none leased).
        s.create_run("C", "third", &[], &[]).unwrap();
        s.set_stage("C", Stage::Simulate, jobs(2, |_| None))
            .unwrap();
        assert_eq!(s.lease("w", 60_000).unwrap().unwrap().run_id, "C");
        std::fs::remove_dir_all(dir).ok();

        // One worker completing each job before the next lease: still round-robin.
        let (s, dir) = store("fair1");
        s.create_run("A", "big", &[], &[]).unwrap();
        s.create_run("B", "small", &[], &[]).unwrap();
        s.set_stage("A", Stage::Simulate, jobs(50, |_| None))
            .unwrap();
        s.set_stage("B", Stage::Simulate, jobs(2, |_| None))
            .unwrap();
        let mut order = vec![];
        for _ in 0..6 {
            let j = s.lease("w", 60_000).unwrap().unwrap();
            order.push(j.run_id.clone());
            s.complete(j.lease_id, &[], "{}").unwrap();
        }
        assert_eq!(order, ["A", "B", "A", "B", "A", "A"]);
        std::fs::remove_dir_all(dir).ok();
    }

    #[test]
    fn identical_simulations_of_two_runs_run_once() {
        let (s, dir) = store("share");
        s.create_run("A", "a", &[], &[]).unwrap();
        s.create_run("B", "b", &[], &[]).unwrap();
        s.set_stage("A", Stage::Simulate, jobs(2, |i| Some(format!("k{i}"))))
            .unwrap();
        s.set_stage("B", Stage::Simulate, jobs(2, |i| Some(format!("k{i}"))))
            .unwrap();
        let j1 = s.lease("w1", 60_000).unwrap().unwrap();
        let j2 = s.lease("w2", 60_000).unwrap().unwrap();
        // The second lease is B's other simulation, not its copy of the first.
        assert_eq!((j1.run_id.as_str(), j2.run_id.as_str()), ("A", "B"));
        assert!(s.lease("w3", 60_000).unwrap().is_none(), "copies must wait");
        let f = File {
            path: "point.json".into(),
            sha256: "ab".repeat(32),
            size: 1,
        };
        let (o, shared) = s
            .complete(j1.lease_id, std::slice::from_ref(&f), "{}")
            .unwrap();
        assert_eq!(o, Outcome::Recorded("A".into()));
        assert_eq!(shared, vec!["B".to_string()]);
        let (_, shared) = s.complete(j2.lease_id, &[f], "{}").unwrap();
        assert_eq!(shared, vec!["A".to_string()]);
        for run in ["A", "B"] {
            let j = s.jobs(run, None).unwrap();
            assert!(j.iter().all(|j| j.state == JobState::Done), "{j:?}");
            assert_eq!(j.iter().filter(|j| j.cached).count(), 1, "{j:?}");
            assert!(j.iter().all(|j| j.outputs[0].path == "point.json"));
        }
        assert_eq!(s.attempts("A").unwrap() + s.attempts("B").unwrap(), 2);
        std::fs::remove_dir_all(dir).ok();
    }

    #[test]
    fn a_run_is_held_to_its_quota_of_output_bytes() {
        let (s, dir) = store("quota");
        s.create_run("A", "a", &[], &[]).unwrap();
        s.create_run("B", "b", &[], &[]).unwrap();
        s.set_stage("A", Stage::Simulate, jobs(5, |_| None))
            .unwrap();
        s.set_stage("B", Stage::Simulate, jobs(1, |_| None))
            .unwrap();
        let file = |c: char, size: u64| File {
            path: format!("{c}.json"),
            sha256: c.to_string().repeat(64),
            size,
        };
        let lease = |run: &str| loop {
            let j = s.lease("w", 60_000).unwrap().unwrap();
            if j.run_id == run {
                break j.lease_id;
            }
            s.complete(j.lease_id, &[file('b', 900)], "{}").unwrap();
        };
        // A quota of 1,000 bytes: 600 + the same 600-byte file again (counted once) + 300.
        let (o, _) = s
            .complete_within(lease("A"), &[file('x', 600)], "{}", 1_000)
            .unwrap();
        assert_eq!(o, Outcome::Recorded("A".into()));
        let (o, _) = s
            .complete_within(lease("A"), &[file('x', 600)], "{}", 1_000)
            .unwrap();
        assert_eq!(o, Outcome::Recorded("A".into()));
        let (o, _) = s
            .complete_within(lease("A"), &[file('y', 300)], "{}", 1_000)
            .unwrap();
        assert_eq!(o, Outcome::Recorded("A".into()));
        // A quota lowered below what the run holds (a restart with a smaller --max-run-gb):
        // a completion that adds nothing is still recorded.
        let (o, _) = s
            .complete_within(lease("A"), &[file('x', 600)], "{}", 500)
            .unwrap();
        assert_eq!(o, Outcome::Recorded("A".into()));
        // The next 200 bytes would make 1,100: refused, and the run fails saying why. B's
        // 900 bytes were never A's.
        let (o, _) = s
            .complete_within(lease("A"), &[file('z', 200)], "{}", 1_000)
            .unwrap();
        assert_eq!(
            o,
            Outcome::OverQuota {
                run: "A".into(),
                bytes: 1_100
            }
        );
        let a = s.run("A").unwrap().unwrap();
        assert_eq!(a.state, RunState::Failed);
        let e = a.error.unwrap();
        assert!(
            e.contains("1100 bytes") && e.contains("--max-run-gb"),
            "{e}"
        );
        let done: Vec<_> = s.jobs("A", None).unwrap();
        assert_eq!(
            done.iter().filter(|j| j.state == JobState::Done).count(),
            4,
            "the refused outputs are not recorded: {done:?}"
        );
        assert!(done
            .iter()
            .all(|j| j.outputs.iter().all(|f| f.sha256 != file('z', 0).sha256)));
        // The running list holds A's files once each (900 bytes; z was refused); a
        // database from before the list has it filled from the finished jobs' outputs by the
        // migration that made it: the same rows.
        let files = |s: &Store| -> Vec<(String, String, i64)> {
            s.with(|c| {
                let mut st = c.prepare(
                    "SELECT run_id, sha256, size FROM run_files ORDER BY run_id, sha256",
                )?;
                let rows = st
                    .query_map([], |r| Ok((r.get(0)?, r.get(1)?, r.get(2)?)))?
                    .collect::<rusqlite::Result<Vec<_>>>()?;
                Ok(rows)
            })
            .unwrap()
        };
        let kept = files(&s);
        let short = |c: char| c.to_string().repeat(64);
        assert_eq!(
            kept.iter()
                .filter(|f| f.0 == "A")
                .cloned()
                .collect::<Vec<_>>(),
            vec![("A".into(), short('x'), 600), ("A".into(), short('y'), 300)]
        );
        let backfill = MIGRATIONS
            .iter()
            .find(|m| m.contains("INSERT OR IGNORE INTO run_files"))
            .unwrap();
        let backfill = &backfill[backfill.find("INSERT OR IGNORE INTO run_files").unwrap()..];
        s.with(|c| {
            c.execute("DELETE FROM run_files", [])?;
            c.execute_batch(backfill)?;
            Ok(())
        })
        .unwrap();
        assert_eq!(files(&s), kept);
        // A run that has ended takes no more stages or jobs (its driver may still be working).
        s.set_stage("A", Stage::Train, jobs(1, |_| None)).unwrap();
        s.add_jobs("A", jobs(1, |_| None)).unwrap();
        let after = s.run("A").unwrap().unwrap();
        assert_eq!((after.state, after.stage), (RunState::Failed, a.stage));
        assert_eq!(s.jobs("A", None).unwrap().len(), 5);
        std::fs::remove_dir_all(dir).ok();
    }

    /// Lease ids are random 63-bit numbers, not a sequence another worker could guess, and
    /// each lease records who took it, in the audit trail too.
    #[test]
    fn lease_ids_are_unguessable_and_every_lease_is_audited() {
        let (s, dir) = store("ids");
        s.create_run("A", "a", &[], &[]).unwrap();
        s.set_stage("A", Stage::Simulate, jobs(20, |_| None))
            .unwrap();
        let ids: Vec<u64> = (0..20)
            .map(|_| s.lease("w1", 60_000).unwrap().unwrap().lease_id)
            .collect();
        let distinct: std::collections::HashSet<_> = ids.iter().collect();
        assert_eq!(distinct.len(), 20);
        assert!(ids.iter().all(|&i| i > 0 && i <= i64::MAX as u64));
        // Not consecutive: at most a couple of neighbours by chance.
        let steps = ids.windows(2).filter(|w| w[1] == w[0] + 1).count();
        assert!(steps < 2, "{ids:?}");
        // Large: a sequence would be below 21.
        assert!(
            ids.iter().filter(|&&i| i > 1 << 40).count() >= 19,
            "{ids:?}"
        );
        let (held, job) = s.leased_job(ids[3]).unwrap().unwrap();
        assert_eq!(held, "w1");
        s.complete(ids[3], &[], "{\"seconds\":1.0}").unwrap();
        s.fail(ids[4], "EnergyPlus crashed", false, 3).unwrap();
        s.fail(ids[5], "shutting down", true, 3).unwrap();
        let trail = s.audit_events(&AuditFilter::default()).unwrap();
        let leases = trail.iter().filter(|e| e.action == "lease").count();
        assert_eq!(leases, 20);
        let done = trail.iter().find(|e| e.action == "complete").unwrap();
        assert_eq!(
            (
                done.actor.as_str(),
                done.lease,
                done.job,
                done.run.as_deref()
            ),
            ("worker:w1", Some(ids[3]), Some(job.id), Some("A"))
        );
        let failed = trail.iter().find(|e| e.action == "fail").unwrap();
        assert!(
            failed
                .detail
                .contains("failure 1 of 3, queued for a retry: EnergyPlus crashed"),
            "{failed:?}"
        );
        let back = trail.iter().find(|e| e.action == "return").unwrap();
        assert!(back.detail.contains("given back"), "{back:?}");
        // A filter by run and the last n.
        let last = s
            .audit_events(&AuditFilter {
                run: Some("A".into()),
                last: 2,
                ..Default::default()
            })
            .unwrap();
        assert_eq!(
            last.iter().map(|e| e.action.as_str()).collect::<Vec<_>>(),
            ["fail", "return"]
        );
        std::fs::remove_dir_all(dir).ok();
    }

    /// A worker's id is its name and a random suffix (a second worker of the same name is
    /// another worker); revoking one marks it alone, gives its leases back and is audited.
    #[test]
    fn workers_register_under_their_own_ids_and_one_is_revoked_alone() {
        let (s, dir) = store("workers");
        let w1 = s.register_worker("node", "aa", "enroller").unwrap();
        let w2 = s.register_worker("node", "bb", "enroller").unwrap();
        assert!(w1.starts_with("node-") && w2.starts_with("node-") && w1 != w2);
        assert!(
            s.register_worker("node", "aa", "enroller").is_err(),
            "one credential, one worker"
        );
        s.create_run("A", "a", &[], &[]).unwrap();
        s.set_stage("A", Stage::Simulate, jobs(2, |_| None))
            .unwrap();
        let l1 = s.lease(&w1, 60_000).unwrap().unwrap();
        let l2 = s.lease(&w2, 60_000).unwrap().unwrap();
        let t0 = now_ms();
        assert!(s.revoke_worker(&w1, "operator").unwrap());
        assert!(!s.revoke_worker("node-nobody", "operator").unwrap());
        let revoked = s.revoked_since(t0).unwrap();
        assert_eq!(
            revoked.iter().map(|r| r.0.as_str()).collect::<Vec<_>>(),
            [w1.as_str()]
        );
        let creds = s.worker_credentials().unwrap();
        assert!(creds.contains(&("aa".into(), w1.clone(), true)));
        assert!(creds.contains(&("bb".into(), w2.clone(), false)));
        assert_eq!(s.return_leases_of(&w1, 3).unwrap(), vec!["A".to_string()]);
        let by_id = |id: u64| {
            s.jobs("A", None)
                .unwrap()
                .into_iter()
                .find(|j| j.id == id)
                .unwrap()
        };
        assert_eq!(by_id(l1.job_id).state, JobState::Queued);
        assert_eq!(
            by_id(l1.job_id).failures,
            0,
            "a revoked worker's job is not a failure"
        );
        assert_eq!(by_id(l2.job_id).state, JobState::Leased);
        let ws = s.workers().unwrap();
        assert_eq!(ws.len(), 2);
        assert!(ws[0].revoked_ms.is_some() && ws[0].leases == 0);
        assert!(ws[1].revoked_ms.is_none() && ws[1].leases == 1);
        let actions: Vec<(String, String)> = s
            .audit_events(&AuditFilter::default())
            .unwrap()
            .into_iter()
            .filter(|e| e.action != "lease")
            .map(|e| (e.actor, e.action))
            .collect();
        let w1a = format!("worker:{w1}");
        assert_eq!(
            actions,
            [
                ("enroller".to_string(), "register".to_string()),
                ("enroller".into(), "register".into()),
                ("operator".into(), "revoke".into()),
                (w1a, "return".into()),
            ]
        );
        std::fs::remove_dir_all(dir).ok();
    }

    /// A client runs at most `max` runs at once, a portfolio counting once; other clients are
    /// not held back, and a run that ends frees its place.
    #[test]
    fn each_client_runs_at_most_its_limit() {
        let (s, dir) = store("limits");
        let new = |id: &'static str, client: &'static str, portfolio: &'static str| NewRun {
            id,
            name: id,
            bundle: &[],
            surrogate: &[],
            client,
            portfolio,
            building: id,
        };
        let admit = |r: NewRun<'_>| {
            s.admit_run(&r, 2, Some(Event::new("client:x", "submit")))
                .unwrap()
        };
        assert_eq!(admit(new("A1", "alice", "")), Admission::Admitted);
        for b in ["P1", "P2", "P3"] {
            assert_eq!(admit(new(b, "alice", "campus")), Admission::Admitted);
        }
        assert_eq!(
            admit(new("A2", "alice", "")),
            Admission::Refused { running: 2 }
        );
        assert_eq!(
            admit(new("Q1", "alice", "other")),
            Admission::Refused { running: 2 }
        );
        assert_eq!(admit(new("B1", "bob", "")), Admission::Admitted);
        s.end_run("A1", RunState::Cancelled, None).unwrap();
        assert_eq!(admit(new("A2", "alice", "")), Admission::Admitted);
        assert_eq!(
            s.run("A2").unwrap().unwrap().client.as_deref(),
            Some("alice")
        );
        assert_eq!(
            s.run("P2").unwrap().unwrap().portfolio.as_deref(),
            Some("campus")
        );
        let submits = s
            .audit_events(&AuditFilter::default())
            .unwrap()
            .into_iter()
            .filter(|e| e.action == "submit")
            .count();
        assert_eq!(submits, 6, "each admitted run, none refused");
        std::fs::remove_dir_all(dir).ok();
    }
}

//! The coordinator's executor of the one driver (`bemcal_calibrate::driver`): the driver's
//! expensive work (EnergyPlus runs, training, chain segments, validation) becomes jobs leased
//! to workers, the cheap work (the design, the training set, the summaries) is done here.
//! [`State::advance`] is called after every change (a job finished or failed, a submit, a
//! restart); it runs the driver, which reads what is settled from the run's output folder and
//! asks [`Leased`] for the rest: a job's result once it is done, else the job queued and
//! [`Ready::Pending`]. The rules of the calibration are the driver's, the same as
//! `bemcal calibrate` on one machine follows; only how work is done and where the job state
//! is kept (SQLite) are this file's.
//!
//! A run's folders: `DATA/runs/<id>/project` (the bundle laid out) and `DATA/runs/<id>/out`
//! (the same layout as the local `bemcal calibrate` output folder).

use std::path::{Path, PathBuf};
use std::sync::Arc;

use bemcal_calibrate::design::saved_outputs;
use bemcal_calibrate::driver::{
    drive, Executor, LazySampler, PointResult, Ready, ValidationResult,
};
use bemcal_calibrate::output::{OutputDir, DRAWS_FILE, STATES_FILE, WARM_FILE};
use bemcal_calibrate::posterior::Checkpoint;
use bemcal_calibrate::savings::{SavingsPlan, SavingsRun};
use bemcal_calibrate::sequence::{Round, ValidationRun};
use bemcal_calibrate::Project;
use bemcal_calibrate::{stage_seconds, Calibration, Error, Summary, Timings};
use bemcal_stats::chain::Chain;
use bemcal_stats::mcmc::Draws;
use sha2::{Digest, Sha256};

use crate::artifacts::{safe_relative, ArtifactDir};
use crate::bundle;
use crate::db::{File, JobRow, NewJob, RunRow, Store};
use crate::proto::{self, job::Kind};
use crate::states::{JobKind, JobState, RunState, Stage};
use bemcal_client::{parse_result, ReportedFailure};

/// Settings of the coordinator that shape runs.
#[derive(Debug, Clone)]
pub struct Config {
    /// Lease length without a heartbeat, ms.
    pub lease_ttl_ms: u64,
    /// Failed attempts after which a job (and its run) fails.
    pub max_failures: u32,
    /// Chains per chain-segment job; 0 = all chains in one job. The surrogate evaluates each
    /// chain's proposal on its own (`p` is `[1, n_params]`), so the draws are the
    /// single-process path's, bit for bit, however the chains are split (tests/distributed.rs).
    pub chains_per_job: usize,
    /// Artifacts that nothing refers to are removed once they are this old (ms): an upload
    /// whose submit or completion never came gets this long to be used.
    pub artifact_grace_ms: u64,
    /// Largest the artifact store may grow (bytes); an upload past it is refused. 0: no limit.
    pub max_store_bytes: u64,
    /// Uploads received at once; more wait their turn.
    pub max_uploads: usize,
    /// Most bytes the distinct files one run's jobs produce may take (bytes); the completion
    /// that would pass it is refused and the run fails, saying so. 0: no limit.
    pub max_run_bytes: u64,
    /// Runs one client may have running at once (a portfolio counts once); a submission past
    /// it is refused. 0: no limit.
    pub max_runs_per_client: u32,
}

impl Default for Config {
    fn default() -> Self {
        Config {
            lease_ttl_ms: 30_000,
            max_failures: 3,
            chains_per_job: 0,
            artifact_grace_ms: 24 * 3600 * 1000,
            max_store_bytes: 0,
            max_uploads: 16,
            max_run_bytes: 0,
            max_runs_per_client: 8,
        }
    }
}

/// Shared coordinator state.
pub struct State {
    /// Runs, jobs, leases and results (SQLite).
    pub store: Store,
    /// The content-addressed artifact files.
    pub artifacts: ArtifactDir,
    /// The coordinator's data folder.
    pub data: PathBuf,
    /// Settings that shape runs.
    pub config: Config,
    /// Asks the driver task to advance a run.
    pub kick: tokio::sync::mpsc::UnboundedSender<String>,
    /// Permits for uploads in progress ([`Config::max_uploads`]).
    pub uploads: tokio::sync::Semaphore,
    /// The registered workers' credentials, as the token check sees them.
    pub credentials: crate::auth::WorkerCredentials,
}

type Result<T> = std::result::Result<T, String>;

fn err<E: std::fmt::Display>(e: E) -> String {
    e.to_string()
}

/// A store or artifact failure, as the driver's error.
fn ex<E: std::fmt::Display>(e: E) -> Error {
    Error::Executor(e.to_string())
}

/// The failure a tolerant job (a simulation, a validation that may fail) reported as its
/// result, if any.
fn reported_failure(j: &JobRow) -> Option<String> {
    if !j.outputs.is_empty() {
        return None;
    }
    parse_result::<ReportedFailure>(j.result.as_deref()?).map(|f| f.error)
}

impl State {
    /// Folder of a run.
    pub fn run_dir(&self, run: &str) -> PathBuf {
        self.data.join("runs").join(run)
    }

    /// Stores bytes as an artifact (file + row).
    pub fn put_artifact(&self, bytes: &[u8]) -> Result<String> {
        let sha = self.artifacts.put(bytes, None).map_err(err)?;
        self.store
            .add_artifact(&sha, bytes.len() as u64)
            .map_err(err)?;
        Ok(sha)
    }

    /// Removes the artifacts nothing refers to that are older than the grace period
    /// ([`Config::artifact_grace_ms`]); returns how many and their bytes.
    pub fn collect_artifacts(&self) -> Result<(usize, u64)> {
        let before = crate::now_ms().saturating_sub(self.config.artifact_grace_ms);
        let orphans = self.store.unreferenced_artifacts(before).map_err(err)?;
        let mut bytes = 0;
        for sha in &orphans {
            bytes += std::fs::metadata(self.artifacts.path(sha)).map_or(0, |m| m.len());
            self.artifacts.remove(sha).map_err(err)?;
        }
        self.store.remove_artifacts(&orphans).map_err(err)?;
        Ok((orphans.len(), bytes))
    }

    /// Advances `run` as far as it goes now; an error fails the run with its message.
    pub fn advance(&self, run: &str) {
        if let Err(e) = self.advance_inner(run) {
            let _ = self.store.end_run(run, RunState::Failed, Some(&e));
        }
    }

    /// Runs the driver on `run` once; a finished calibration's files become its results.
    fn advance_inner(&self, run: &str) -> Result<()> {
        let Some(r) = self.store.run(run).map_err(err)? else {
            return Ok(());
        };
        if r.state != RunState::Running {
            return Ok(());
        }
        // Nothing to decide while a wave is out: every stage's jobs but the chains' come back
        // as a whole (chain groups go on segment by segment, each on its own).
        if r.stage != Stage::Chains {
            let jobs = self.store.jobs(run, Some(r.stage)).map_err(err)?;
            if jobs
                .iter()
                .any(|j| matches!(j.state, JobState::Queued | JobState::Leased))
            {
                return Ok(());
            }
        }
        let project = self.project(&r)?;
        let mut cal = Calibration::load(project, &self.run_dir(&r.id).join("out")).map_err(err)?;
        let mut exec = Leased {
            st: self,
            stage: r.stage,
            r,
            inputs_hash: None,
        };
        let log = |m: &str| {
            // A message that cannot be stored is not worth failing the run for.
            let _ = self.store.add_log(run, m);
        };
        match drive(&mut cal, &mut exec, &log).map_err(err)? {
            Ready::Pending => Ok(()),
            Ready::Done(summary) => self.finish(&exec.r, &cal, &summary),
        }
    }

    /// Records a finished run: every file of its output folder as an artifact, and its
    /// summary.
    fn finish(&self, r: &RunRow, cal: &Calibration, summary: &Summary) -> Result<()> {
        let mut files = vec![];
        for p in crate::client::walk(&cal.out).map_err(err)? {
            let rel = p
                .strip_prefix(&cal.out)
                .map_err(err)?
                .to_string_lossy()
                .replace('\\', "/");
            if rel.ends_with(".partial") {
                continue;
            }
            let bytes = std::fs::read(&p).map_err(err)?;
            files.push(File {
                path: rel,
                sha256: self.put_artifact(&bytes)?,
                size: bytes.len() as u64,
            });
        }
        let json = serde_json::to_string_pretty(summary).map_err(err)?;
        self.store.finish_run(&r.id, &files, &json).map_err(err)
    }

    /// Copies job outputs into the run's output folder.
    fn place(&self, out: &Path, files: &[File]) -> Result<()> {
        for f in files {
            let p = out.join(safe_relative(&f.path)?);
            let bytes = self.artifacts.read(&f.sha256).map_err(err)?;
            bemcal_calibrate::write_atomic(&p, &bytes).map_err(err)?;
        }
        Ok(())
    }

    fn project(&self, r: &RunRow) -> Result<Project> {
        let pdir = self.run_dir(&r.id).join("project");
        let pf = pdir.join(bundle::PROJECT_FILE);
        if !pf.is_file() {
            bundle::materialize(&r.bundle, &self.artifacts, &pdir)?;
        }
        Project::load_submitted(&pf).map_err(err)
    }
}

/// The coordinator's [`Executor`]: each piece of work is a job (or, for the chains, a job per
/// group of chains and segment) found in SQLite by what it does, queued when it is not there,
/// and read back into the run's output folder once done.
pub struct Leased<'s> {
    st: &'s State,
    r: RunRow,
    /// The run's stage as stored.
    stage: Stage,
    /// [`Leased::inputs_hash`], once computed.
    inputs_hash: Option<String>,
}

impl Leased<'_> {
    /// The jobs of `specs` (one stage's), matched to the run's jobs by `same`: those missing
    /// are queued; done when every one is (a simulation served from the cache is done at
    /// once).
    fn wave(
        &self,
        specs: Vec<NewJob>,
        same: impl Fn(&JobRow, &NewJob) -> bool,
    ) -> std::result::Result<Ready<Vec<JobRow>>, Error> {
        let Some(stage) = specs.first().map(|s| s.stage) else {
            return Ok(Ready::Done(vec![]));
        };
        let jobs = || self.st.store.jobs(&self.r.id, Some(stage)).map_err(ex);
        let mut existing = jobs()?;
        let missing: Vec<NewJob> = specs
            .iter()
            .filter(|s| !existing.iter().any(|j| same(j, s)))
            .cloned()
            .collect();
        if !missing.is_empty() {
            self.st.store.add_jobs(&self.r.id, missing).map_err(ex)?;
            existing = jobs()?;
        }
        let rows: Vec<JobRow> = specs
            .iter()
            .filter_map(|s| existing.iter().rev().find(|j| same(j, s)).cloned())
            .collect();
        if rows.len() == specs.len() && rows.iter().all(|j| j.state == JobState::Done) {
            Ok(Ready::Done(rows))
        } else {
            Ok(Ready::Pending)
        }
    }

    /// Hash of everything a simulation depends on besides the parameter values: the bundle's
    /// files except the project file and the meters, the weather file's content, and the
    /// project's `[simulation]` limits where they are not the defaults (a run stopped at a
    /// limit is cached with its failure, which another project's higher limit would not have).
    fn inputs_hash(&mut self, cal: &Calibration) -> std::result::Result<String, Error> {
        if let Some(h) = &self.inputs_hash {
            return Ok(h.clone());
        }
        let meters = cal.project.meters.file.clone().unwrap_or_default();
        let mut h = Sha256::new();
        // A cached simulation is only valid for the generator/runner that made it.
        h.update(format!(
            "simulation revision {}\n",
            bemcal_energyplus::SIMULATION_REVISION
        ));
        let limits = &cal.project.simulation;
        if *limits != bemcal_calibrate::project::SimulationSettings::default() {
            h.update(format!(
                "limits {} s {} GiB {} GiB\n",
                limits.timeout_s, limits.memory_gib, limits.max_output_gib
            ));
        }
        for f in &self.r.bundle {
            if f.path != bundle::PROJECT_FILE && Path::new(&f.path) != meters {
                h.update(format!("{} {}\n", f.path, f.sha256));
            }
        }
        let w = std::fs::read(&cal.inputs.weather_path)
            .map_err(|e| Error::Executor(format!("{}: {e}", cal.inputs.weather_path.display())))?;
        h.update(Sha256::digest(&w));
        let hash = hex::encode(h.finalize());
        self.inputs_hash = Some(hash.clone());
        Ok(hash)
    }

    /// The job simulating point `i` at `x`: a design point (`round` 0) or a posterior draw of
    /// refinement round `round`, cached by inputs and values. Every simulation job reports an
    /// EnergyPlus failure as its result (cached with it: the same inputs fail the same way).
    fn simulation_job(
        &self,
        cal: &Calibration,
        inputs_hash: &str,
        (i, x): &(usize, Vec<f64>),
        round: u32,
    ) -> NewJob {
        let values = serde_json::to_string(&cal.inputs.plan.values(x)).unwrap_or_default();
        let key = hex::encode(Sha256::digest(format!("tolerant\n{inputs_hash}\n{values}")));
        NewJob {
            stage: if round > 0 {
                Stage::Refine
            } else {
                Stage::Simulate
            },
            kind: JobKind::Simulate,
            label: if round > 0 {
                format!("simulation of posterior draw {i} (refinement round {round})")
            } else {
                format!("simulation of design point {i}")
            },
            spec: proto::Job {
                bundle: crate::client::refs(&self.r.bundle),
                kind: Some(Kind::Simulate(proto::SimulateJob {
                    point: *i as u32,
                    values: x.clone(),
                    refine_round: round,
                })),
                ..Default::default()
            },
            cache_key: Some(key),
        }
    }

    /// The job of one savings run of `plan`, cached by what it simulates: the inputs, the
    /// weather file's content, the measure's building and IDF edits and the parameters' values with
    /// the measure applied (a renamed measure, or another run of the same building, reuses it).
    fn measure_job(
        &self,
        (inputs_hash, weather_hash): (&str, &str),
        plan: &SavingsPlan,
        run: &SavingsRun,
    ) -> std::result::Result<NewJob, Error> {
        let measure = run.measure.map(|j| &plan.measures[j]);
        let values = serde_json::to_string(&run.values).map_err(ex)?;
        let measure_json = match measure {
            Some(m) => serde_json::to_string(m).map_err(ex)?,
            None => String::new(),
        };
        // A measure without IDF edits keys as before they existed (cached runs keep their keys).
        let building = measure.map_or(
            String::new(),
            bemcal_calibrate::measures::Measure::model_edits_key,
        );
        let key = hex::encode(Sha256::digest(format!(
            "measure\n{inputs_hash}\n{weather_hash}\n{building}\n{values}"
        )));
        let what = measure.map_or("the baseline".to_string(), |m| {
            format!("measure {:?}", m.name)
        });
        Ok(NewJob {
            stage: Stage::Savings,
            kind: JobKind::Measure,
            label: format!(
                "savings: {what} at point {} ({} weather)",
                run.key,
                run.weather.as_str()
            ),
            spec: proto::Job {
                bundle: crate::client::refs(&self.r.bundle),
                kind: Some(Kind::Measure(proto::MeasureJob {
                    point: run.key as u32,
                    values_json: values,
                    weather: run.weather.as_str().into(),
                    measure_json,
                })),
                ..Default::default()
            },
            cache_key: Some(key),
        })
    }

    /// The training job of round `round` for the training set in `dataset/`, warm-started
    /// from the weights in the surrogate folder `init`.
    fn train_job(
        &self,
        cal: &Calibration,
        round: u32,
        init: Option<&Path>,
    ) -> std::result::Result<NewJob, Error> {
        let mut inputs = vec![];
        for p in crate::client::walk(&cal.out.dataset()).map_err(ex)? {
            let bytes = std::fs::read(&p).map_err(|source| Error::Io {
                path: p.clone(),
                source,
            })?;
            let rel = p.strip_prefix(&cal.out).map_err(ex)?;
            inputs.push(self.artifact(rel.to_string_lossy().replace('\\', "/"), &bytes)?);
        }
        let mut train = proto::TrainJob {
            round,
            ..Default::default()
        };
        if let Some(dir) = init {
            let p = dir.join(bemcal_surrogate::WEIGHTS_FILE);
            let bytes = std::fs::read(&p).map_err(|source| Error::Io {
                path: p.clone(),
                source,
            })?;
            train.init = WARM_START_DIR.into();
            let path = format!("{WARM_START_DIR}/{}", bemcal_surrogate::WEIGHTS_FILE);
            inputs.push(self.artifact(path, &bytes)?);
            // How the first training started (a pretrained network's verdict) goes on with it.
            let verdict = dir.join(bemcal_surrogate::pretrained::VERDICT_FILE);
            if let Ok(bytes) = std::fs::read(&verdict) {
                let path = format!(
                    "{WARM_START_DIR}/{}",
                    bemcal_surrogate::pretrained::VERDICT_FILE
                );
                inputs.push(self.artifact(path, &bytes)?);
            }
        }
        Ok(NewJob {
            stage: Stage::Train,
            kind: JobKind::Train,
            label: match round {
                0 => "surrogate training".into(),
                r => format!("surrogate training (after refinement round {r})"),
            },
            spec: proto::Job {
                bundle: crate::client::refs(&self.r.bundle),
                inputs,
                kind: Some(Kind::Train(train)),
                ..Default::default()
            },
            cache_key: None,
        })
    }

    /// `bytes` stored as an artifact, as a job input at `path`.
    fn artifact(&self, path: String, bytes: &[u8]) -> std::result::Result<proto::FileRef, Error> {
        Ok(proto::FileRef {
            path,
            sha256: self.st.put_artifact(bytes).map_err(ex)?,
            size: bytes.len() as u64,
        })
    }

    /// The current surrogate's files: the latest trained one (refinement retrains), else
    /// the one given at submit.
    fn surrogate_files(&self) -> std::result::Result<Vec<File>, Error> {
        let jobs = self
            .st
            .store
            .jobs(&self.r.id, Some(Stage::Train))
            .map_err(ex)?;
        if let Some(j) = jobs.iter().rev().find(|j| j.state == JobState::Done) {
            return Ok(j.outputs.clone());
        }
        if !self.r.surrogate.is_empty() {
            return Ok(self.r.surrogate.clone());
        }
        Err(Error::Executor("no trained surrogate".into()))
    }

    /// `simulations/design.json` of the settled design, as a job input (chain jobs refuse
    /// proposals where EnergyPlus failed).
    fn settled_design_file(
        &self,
        cal: &Calibration,
    ) -> std::result::Result<Option<proto::FileRef>, Error> {
        let name = bemcal_calibrate::design::OUTCOME_FILE;
        let Ok(bytes) = std::fs::read(cal.simulations_dir().join(name)) else {
            return Ok(None);
        };
        self.artifact(format!("simulations/{name}"), &bytes)
            .map(Some)
    }

    /// A round's first segment of chains `first..first + count` starts at `starts` (where
    /// the previous round's chains ended or restarted), as `warm.json`.
    fn warm_starts(
        &self,
        starts: &[Vec<f64>],
        first: usize,
        count: usize,
    ) -> std::result::Result<proto::FileRef, Error> {
        let mine = starts
            .get(first..first + count)
            .ok_or_else(|| Error::Executor(format!("chains {first}: no starting points")))?;
        let bytes = serde_json::to_vec(mine).map_err(ex)?;
        self.artifact(WARM_FILE.into(), &bytes)
    }

    /// Chains per chain job of `n` chains ([`Config::chains_per_job`]; 0: all in one).
    fn chains_per_group(&self, n: usize) -> usize {
        match self.st.config.chains_per_job {
            0 => n,
            k => k.min(n),
        }
    }

    /// The chain jobs of `round` as groups of [`Config::chains_per_job`] chains, each group
    /// segment after segment (a segment from the last one's checkpoint); the segments of
    /// each group so far, in order.
    fn chain_groups(
        &self,
        cal: &Calibration,
        round: Round,
    ) -> std::result::Result<Vec<(usize, Vec<JobRow>)>, Error> {
        let n = cal.project.mcmc.chains;
        let per = self.chains_per_group(n);
        let jobs = self
            .st
            .store
            .jobs(&self.r.id, Some(Stage::Chains))
            .map_err(ex)?;
        Ok((0..n)
            .step_by(per.max(1))
            .map(|first| {
                let mut mine: Vec<JobRow> = jobs
                    .iter()
                    .filter(|j| {
                        matches!(&j.spec.kind, Some(Kind::Chains(c))
                            if c.first_chain as usize == first
                                && c.chains as usize == per.min(n - first)
                                && c.round == round.index())
                    })
                    .cloned()
                    .collect();
                mine.sort_by_key(|j| segment_of(j).map_or(0, |c| c.segment));
                (first, mine)
            })
            .collect())
    }

    /// The next segment of chains `first..first + count` of `round` after `done` (to
    /// `target` iterations per chain in all).
    #[allow(clippy::too_many_arguments)]
    fn segment_job(
        &self,
        cal: &Calibration,
        round: Round,
        (first, count): (usize, usize),
        done: &[JobRow],
        target: u64,
        starts: Option<&[Vec<f64>]>,
        temperature: f64,
        readapted: Option<&[u8]>,
    ) -> std::result::Result<NewJob, Error> {
        let reached = segments_reached(done);
        let mut inputs = crate::client::refs(&self.surrogate_files()?);
        if let Some(f) = self.settled_design_file(cal)? {
            inputs.push(f);
        }
        if let Some(states) = readapted {
            inputs.push(self.artifact(STATES_FILE.into(), states)?);
        } else if let Some(last) = done.last() {
            let states = last
                .outputs
                .iter()
                .find(|f| f.path == STATES_FILE)
                .ok_or_else(|| Error::Executor(format!("{}: no states.json", last.label)))?;
            inputs.push(states.into());
        } else if let Some(s) = starts {
            inputs.push(self.warm_starts(s, first, count)?);
        }
        let seg = done.len() as u32;
        Ok(NewJob {
            stage: Stage::Chains,
            kind: JobKind::Chains,
            label: segment_label(round, first, count, seg),
            spec: proto::Job {
                bundle: crate::client::refs(&self.r.bundle),
                inputs,
                kind: Some(Kind::Chains(proto::ChainSegmentJob {
                    first_chain: first as u32,
                    chains: count as u32,
                    iterations: cal.project.mcmc.segment.min(target - reached),
                    segment: seg,
                    round: round.index(),
                    temperature,
                    target,
                })),
                ..Default::default()
            },
            cache_key: None,
        })
    }

    /// The chains of each group merged, segments in order up to `target` iterations per chain
    /// (an extension's later segments left out): each chain's last state and all its draws.
    fn merged(
        &self,
        groups: &[(usize, Vec<JobRow>)],
        target: u64,
    ) -> std::result::Result<Checkpoint, Error> {
        let (mut states, mut draws): (Vec<Chain>, Vec<Draws>) = (vec![], vec![]);
        for (_, segments) in groups {
            let (mut acc, mut last_states, mut reached): (Vec<Draws>, Vec<Chain>, u64) =
                (vec![], vec![], 0);
            for j in segments {
                let n = segment_of(j).map_or(0, |c| c.iterations);
                if reached + n > target {
                    break;
                }
                reached += n;
                let get = |name: &str| -> std::result::Result<Vec<u8>, Error> {
                    let f = j
                        .outputs
                        .iter()
                        .find(|f| f.path == name)
                        .ok_or_else(|| Error::Executor(format!("{}: no {name}", j.label)))?;
                    self.st.artifacts.read(&f.sha256).map_err(ex)
                };
                let d: Vec<Draws> = serde_json::from_slice(&get(DRAWS_FILE)?).map_err(ex)?;
                last_states = serde_json::from_slice(&get(STATES_FILE)?).map_err(ex)?;
                if acc.is_empty() {
                    acc = d;
                } else {
                    for (a, b) in acc.iter_mut().zip(&d) {
                        a.extend(b);
                    }
                }
            }
            states.extend(last_states);
            draws.extend(acc);
        }
        // The temperature the segments ran at.
        let temperature = match groups
            .iter()
            .filter_map(|(_, segments)| segments.first())
            .find_map(segment_of)
        {
            Some(c) => c.likelihood_temperature().map_err(Error::Executor)?,
            None => 1.0,
        };
        Ok(Checkpoint {
            states,
            draws,
            temperature,
            target,
            likelihood: None,
        })
    }

    /// The states an extension's first segments start from, as each group's `states.json`:
    /// when every group's chains reached the target they were last asked for and `iterations`
    /// is higher, the merged chains re-adapted from all their draws
    /// ([`bemcal_stats::chain::readapt`], as the local executor's `run_chains` does); `None`
    /// otherwise, or where the draws give no metric (each group then goes on from its own).
    fn readapted_states(
        &self,
        groups: &[(usize, Vec<JobRow>)],
        iterations: u64,
    ) -> std::result::Result<Option<Vec<Vec<u8>>>, Error> {
        let mut reached = None;
        for (_, done) in groups {
            let Some(last) = done.last().and_then(segment_of) else {
                return Ok(None);
            };
            if done.iter().any(|j| j.state != JobState::Done) {
                return Ok(None);
            }
            let r = segments_reached(done);
            if last.target == 0 || r != last.target || r >= iterations {
                return Ok(None);
            }
            if reached.is_some_and(|x| x != r) {
                return Ok(None);
            }
            reached = Some(r);
        }
        let Some(reached) = reached else {
            return Ok(None);
        };
        let mut ck = self.merged(groups, reached)?;
        if !bemcal_stats::chain::readapt(&mut ck.states, &ck.draws) {
            return Ok(None);
        }
        let mut out = vec![];
        let mut states = ck.states.as_slice();
        for (_, done) in groups {
            let count = done
                .last()
                .and_then(segment_of)
                .map_or(0, |c| c.chains as usize);
            let (mine, rest) = states.split_at(count.min(states.len()));
            out.push(serde_json::to_vec(mine).map_err(ex)?);
            states = rest;
        }
        Ok(Some(out))
    }
}

/// Iterations per chain a group's segments `done` have run.
fn segments_reached(done: &[JobRow]) -> u64 {
    done.iter()
        .filter_map(segment_of)
        .map(|c| c.iterations)
        .sum()
}

/// A chain job's segment.
fn segment_of(j: &JobRow) -> Option<&proto::ChainSegmentJob> {
    match &j.spec.kind {
        Some(Kind::Chains(c)) => Some(c),
        _ => None,
    }
}

impl Executor for Leased<'_> {
    fn enter(&mut self, stage: Stage) -> std::result::Result<(), Error> {
        // `Done` is the finished run's, set with its results.
        if stage != self.stage && stage != Stage::Done {
            self.st
                .store
                .set_stage(&self.r.id, stage, vec![])
                .map_err(ex)?;
            self.stage = stage;
        }
        Ok(())
    }

    /// Places each point's outputs as `simulations/point_iii.json` (cached outputs may come
    /// from another run's point: they are named after this one's) and reads them back,
    /// checking they answer the point's values.
    fn simulate(
        &mut self,
        cal: &Calibration,
        wave: &[(usize, Vec<f64>)],
        round: u32,
    ) -> std::result::Result<Ready<Vec<PointResult>>, Error> {
        let hash = self.inputs_hash(cal)?;
        let specs = wave
            .iter()
            .map(|p| self.simulation_job(cal, &hash, p, round))
            .collect();
        let rows = match self.wave(specs, |j, s| j.spec.kind == s.spec.kind)? {
            Ready::Done(rows) => rows,
            Ready::Pending => return Ok(Ready::Pending),
        };
        let mut results = vec![];
        for (j, (i, x)) in rows.iter().zip(wave) {
            if let Some(e) = reported_failure(j) {
                results.push(Err(e));
                continue;
            }
            let files: Vec<File> = j
                .outputs
                .iter()
                .map(|f| File {
                    path: OutputDir::point_rel(*i),
                    ..f.clone()
                })
                .collect();
            self.st.place(&cal.out, &files).map_err(ex)?;
            let o = saved_outputs(&cal.simulations_dir(), *i, &cal.inputs.plan.values(x))
                .ok_or_else(|| {
                    Error::Executor(format!(
                        "point {i}: the worker's outputs did not match its parameter values"
                    ))
                })?;
            results.push(Ok(o));
        }
        Ok(Ready::Done(results))
    }

    /// Places each run's point file in its folder of `savings/` (cached files may come from
    /// another run: they are named after this one's) and reads it back, checking it answers
    /// the run's values.
    fn savings(
        &mut self,
        cal: &Calibration,
        plan: &SavingsPlan,
    ) -> std::result::Result<Ready<Vec<PointResult>>, Error> {
        let hash = self.inputs_hash(cal)?;
        // Each weather file's content, hashed once.
        let mut weather_hashes = vec![];
        for (w, path) in plan.weathers() {
            let bytes = std::fs::read(path)
                .map_err(|e| Error::Executor(format!("{}: {e}", path.display())))?;
            weather_hashes.push((*w, hex::encode(Sha256::digest(&bytes))));
        }
        let mut specs = vec![];
        for run in &plan.runs {
            let (_, weather_hash) = (weather_hashes.iter())
                .find(|(w, _)| *w == run.weather)
                .expect("a plan's runs are under its weathers");
            specs.push(self.measure_job((&hash, weather_hash), plan, run)?);
        }
        let rows = match self.wave(specs, |j, s| j.spec.kind == s.spec.kind)? {
            Ready::Done(rows) => rows,
            Ready::Pending => return Ok(Ready::Pending),
        };
        let mut results = vec![];
        for (j, run) in rows.iter().zip(&plan.runs) {
            if let Some(e) = reported_failure(j) {
                results.push(Err(e));
                continue;
            }
            let files: Vec<File> = (j.outputs.iter())
                .map(|f| File {
                    path: plan.run_file(run),
                    ..f.clone()
                })
                .collect();
            self.st.place(&cal.out, &files).map_err(ex)?;
            let dir = cal.out.join(plan.run_rel(run));
            let o = saved_outputs(&dir, run.key, &run.values).ok_or_else(|| {
                Error::Executor(format!(
                    "{}: the worker's outputs did not match the run's parameter values",
                    j.label
                ))
            })?;
            results.push(Ok(o));
        }
        Ok(Ready::Done(results))
    }

    /// The design's surrogate is the one given at submit when there is one.
    fn train(
        &mut self,
        cal: &Calibration,
        round: u32,
        init: Option<&Path>,
    ) -> std::result::Result<Ready<()>, Error> {
        if round == 0 && !self.r.surrogate.is_empty() {
            self.st.place(&cal.out, &self.r.surrogate).map_err(ex)?;
            return Ok(Ready::Done(()));
        }
        let jobs = self
            .st
            .store
            .jobs(&self.r.id, Some(Stage::Train))
            .map_err(ex)?;
        let mine = jobs
            .iter()
            .rev()
            .find(|j| matches!(&j.spec.kind, Some(Kind::Train(t)) if t.round == round));
        match mine {
            Some(j) if j.state == JobState::Done => {
                self.st.place(&cal.out, &j.outputs).map_err(ex)?;
                Ok(Ready::Done(()))
            }
            Some(_) => Ok(Ready::Pending),
            None => {
                let job = self.train_job(cal, round, init)?;
                self.st.store.add_jobs(&self.r.id, vec![job]).map_err(ex)?;
                Ok(Ready::Pending)
            }
        }
    }

    /// Each group's next segment once its last is done, until every group reaches
    /// `iterations`; the final chains' merged checkpoint is written as `chains.json`.
    fn chains(
        &mut self,
        cal: &Calibration,
        round: Round,
        iterations: u64,
        starts: Option<&[Vec<f64>]>,
        sampler: &mut LazySampler<'_>,
    ) -> std::result::Result<Ready<Checkpoint>, Error> {
        let groups = self.chain_groups(cal, round)?;
        let n = cal.project.mcmc.chains;
        let per = self.chains_per_group(n);
        let mut next = vec![];
        let mut short = false;
        // As run_chains does locally, in any round (in practice the final one's extensions).
        let readapted = self.readapted_states(&groups, iterations)?;
        for (g, (first, done)) in groups.iter().enumerate() {
            if done.iter().any(|j| j.state != JobState::Done) {
                short = true;
                continue;
            }
            if segments_reached(done) < iterations {
                short = true;
                let count = per.min(n - first);
                next.push(self.segment_job(
                    cal,
                    round,
                    (*first, count),
                    done,
                    iterations,
                    starts,
                    sampler.temperature().value,
                    readapted.as_ref().map(|r| r[g].as_slice()),
                )?);
            }
        }
        if !next.is_empty() {
            self.st.store.add_jobs(&self.r.id, next).map_err(ex)?;
        }
        if short {
            return Ok(Ready::Pending);
        }
        let mut ck = self.merged(&groups, iterations)?;
        ck.likelihood = Some(cal.project.mcmc.likelihood_form());
        if round.is_final() {
            let bytes = serde_json::to_vec(&ck).map_err(ex)?;
            bemcal_calibrate::write_atomic(&cal.out.chains_checkpoint(), &bytes)?;
        }
        Ok(Ready::Done(ck))
    }

    /// Places each run's files; its metrics are the job's result.
    fn validate(
        &mut self,
        cal: &Calibration,
        runs: &[ValidationRun],
    ) -> std::result::Result<Ready<Vec<ValidationResult>>, Error> {
        let specs = runs
            .iter()
            .map(|run| validation_job(&self.r, run))
            .collect();
        let same = |j: &JobRow, s: &NewJob| match (&j.spec.kind, &s.spec.kind) {
            (Some(Kind::Validate(a)), Some(Kind::Validate(b))) => {
                a.index == b.index && a.label == b.label && a.values == b.values
            }
            _ => false,
        };
        let rows = match self.wave(specs, same)? {
            Ready::Done(rows) => rows,
            Ready::Pending => return Ok(Ready::Pending),
        };
        let mut results = vec![];
        for (j, run) in rows.iter().zip(runs) {
            if let Some(e) = reported_failure(j) {
                results.push(Err(e));
                continue;
            }
            self.st.place(&cal.out, &j.outputs).map_err(ex)?;
            // Guideline 14 from the run's file, as the single process computes it.
            results.push(Ok(cal.validated(run.key, &run.values)?));
        }
        Ok(Ready::Done(results))
    }

    /// The seconds of each stage as SQLite recorded them.
    fn timings(&self) -> Timings {
        let mut t = Timings::default();
        for (stage, secs) in self.st.store.stage_seconds(&self.r.id).unwrap_or_default() {
            if let Some(b) = stage_seconds(&mut t, stage) {
                *b += secs;
            }
        }
        t.total_s = (crate::now_ms().saturating_sub(self.r.created_ms)) as f64 / 1000.0;
        t
    }

    /// The driver runs again after every finished job: what it finds settled is not news.
    fn announces_reuse(&self) -> bool {
        false
    }
}

/// The job of a validation run of the sequence; the calibrated model's and a predictive
/// draw's tolerate an EnergyPlus failure ([`ValidationRun::tolerates_failure`]: the driver then
/// validates the next-best draw, or leaves the draw out).
fn validation_job(r: &RunRow, run: &ValidationRun) -> NewJob {
    NewJob {
        stage: Stage::Validate,
        kind: JobKind::Validate,
        label: format!("validation ({})", run.label),
        spec: proto::Job {
            bundle: crate::client::refs(&r.bundle),
            kind: Some(Kind::Validate(proto::ValidateJob {
                index: run.key as u32,
                label: run.label.clone(),
                values: run.values.clone(),
                tolerate_failure: run.tolerates_failure(),
            })),
            ..Default::default()
        },
        cache_key: None,
    }
}

/// How the job of segment `seg` of chains `first..first + count` in `round` is labelled.
fn segment_label(round: Round, first: usize, count: usize, seg: u32) -> String {
    let last = first + count - 1;
    match round {
        Round::Preliminary { index } => format!(
            "chains {first}-{last} segment {seg} (refinement round {})",
            index + 1
        ),
        Round::Final { .. } => format!("chains {first}-{last} segment {seg}"),
    }
}

/// Where a warm-started training job finds the previous surrogate's weights (job-relative).
const WARM_START_DIR: &str = "init";

/// Runs advanced at the same time (each run by one task at a time).
pub const DRIVER_PARALLEL: usize = 4;

/// Starts the driver: advances runs off the async threads, up to [`DRIVER_PARALLEL`] runs at
/// once (so one building's slow in-process stage, e.g. its merge, does not hold up the next
/// jobs of the others in a portfolio), never the same run twice at once: a run kicked while it
/// is being advanced is advanced again afterwards.
pub fn spawn_driver(
    st: Arc<State>,
    mut rx: tokio::sync::mpsc::UnboundedReceiver<String>,
) -> tokio::task::JoinHandle<()> {
    tokio::spawn(async move {
        // Run -> kicked again while being advanced.
        let busy: Arc<std::sync::Mutex<std::collections::HashMap<String, bool>>> = Arc::default();
        let permits = Arc::new(tokio::sync::Semaphore::new(DRIVER_PARALLEL));
        while let Some(run) = rx.recv().await {
            {
                let mut b = busy.lock().unwrap_or_else(|e| e.into_inner());
                if let Some(again) = b.get_mut(&run) {
                    *again = true;
                    continue;
                }
                b.insert(run.clone(), false);
            }
            let (st, busy, permits) = (st.clone(), busy.clone(), permits.clone());
            tokio::spawn(async move {
                let _permit = permits.acquire_owned().await;
                loop {
                    let (st2, r) = (st.clone(), run.clone());
                    let _ = tokio::task::spawn_blocking(move || st2.advance(&r)).await;
                    let again = {
                        let mut b = busy.lock().unwrap_or_else(|e| e.into_inner());
                        if b.get(&run) == Some(&true) {
                            b.insert(run.clone(), false);
                            true
                        } else {
                            b.remove(&run);
                            false
                        }
                    };
                    if !again {
                        break;
                    }
                }
            });
        }
    })
}

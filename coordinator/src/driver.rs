//! The run driver: walks a run through its stages. It is called after every change (a job
//! finished or failed, a submit, a restart) and is idempotent: it reads the durable state,
//! does the cheap stages in-process (design, training set, merge and diagnostics, summary) and
//! queues jobs for the expensive ones (EnergyPlus runs, training, chain segments, validation).
//!
//! A run's folders: `DATA/runs/<id>/project` (the bundle laid out) and `DATA/runs/<id>/out`
//! (the same layout as the local `bemcal calibrate` output folder).

use std::path::{Path, PathBuf};
use std::sync::Arc;

use bemcal_calibrate::output::{OutputDir, DRAWS_FILE, STATES_FILE, WARM_FILE};
use bemcal_calibrate::posterior::Checkpoint;
use bemcal_calibrate::refine::{
    close_round, refinement_points, RefineLog, SimulatedDraw, REFINE_FILE,
};
use bemcal_calibrate::replacement::{Attempt, Step};
use bemcal_calibrate::sequence::{
    after_final_chains, next_validation, validation_runs, AfterFinalChains, Round, ValidationRun,
};
use bemcal_calibrate::Project;
use bemcal_calibrate::{write_summary, Calibration, ChainSummary, OutputMetrics, Timings};
use bemcal_energyplus::HourlyOutputs;
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
    /// Chains per chain-segment job; 0 = all chains in one job (the same batches as the
    /// single-process path, so the draws are bit-identical to it).
    pub chains_per_job: usize,
    /// Artifacts that nothing refers to are removed once they are this old (ms): an upload
    /// whose submit or completion never came gets this long to be used.
    pub artifact_grace_ms: u64,
    /// Largest the artifact store may grow (bytes); an upload past it is refused. 0: no limit.
    pub max_store_bytes: u64,
    /// Uploads received at once; more wait their turn.
    pub max_uploads: usize,
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
}

/// The stages a run goes through, in order (every [`Stage`] but `Done`).
pub const STAGES: &[Stage] = &[
    Stage::Design,
    Stage::Simulate,
    Stage::Train,
    Stage::Chains,
    Stage::Merge,
    Stage::Refine,
    Stage::Validate,
    Stage::Summary,
];

type Result<T> = std::result::Result<T, String>;

fn err<E: std::fmt::Display>(e: E) -> String {
    e.to_string()
}

/// A finished simulation job, read back: the point (its key in `simulations/`, its values, and
/// its outputs or EnergyPlus's failure) and the refinement round it belongs to.
struct Simulated {
    /// 0 for a design point, else the refinement round of the draw.
    refine_round: u32,
    point: SimulatedDraw,
}

/// The failure a tolerant (refinement) simulation job reported in its result, if any.
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

    fn load(&self, r: &RunRow) -> Result<Calibration> {
        let project = self.project(r)?;
        Calibration::load(project, &self.run_dir(&r.id).join("out")).map_err(err)
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

    fn advance_inner(&self, run: &str) -> Result<()> {
        loop {
            let Some(r) = self.store.run(run).map_err(err)? else {
                return Ok(());
            };
            if r.state != RunState::Running {
                return Ok(());
            }
            let progressed = match r.stage {
                Stage::Design => self.stage_design(&r)?,
                Stage::Simulate => self.stage_simulate(&r)?,
                Stage::Train => self.stage_train(&r)?,
                Stage::Chains => self.stage_chains(&r)?,
                Stage::Merge => self.stage_merge(&r)?,
                Stage::Refine => self.stage_refine(&r)?,
                Stage::Validate => self.stage_validate(&r)?,
                Stage::Summary => self.stage_summary(&r)?,
                Stage::Done => false,
            };
            if !progressed {
                return Ok(());
            }
        }
    }

    fn stage_design(&self, r: &RunRow) -> Result<bool> {
        let cal = self.load(r)?;
        let design = cal.design().map_err(err)?;
        let inputs_hash = self.simulation_inputs_hash(r, &cal)?;
        let Step::Simulate(wave) = cal.design_step(&design, &cal.spares().map_err(err)?, &[])
        else {
            return Err("design: nothing to simulate".into());
        };
        let jobs = wave
            .iter()
            .map(|(i, x)| self.simulation_job(r, &cal, &inputs_hash, *i, x, 0))
            .collect();
        self.store
            .set_stage(&r.id, Stage::Simulate, jobs)
            .map_err(err)?;
        Ok(true)
    }

    /// The job simulating point `i` at `x`: a design point (`refine_round` 0) or a posterior
    /// draw of refinement round `refine_round`, cached by inputs and values (a refinement job
    /// may report an EnergyPlus failure as its result, so its key is kept apart).
    fn simulation_job(
        &self,
        r: &RunRow,
        cal: &Calibration,
        inputs_hash: &str,
        i: usize,
        x: &[f64],
        refine_round: u32,
    ) -> NewJob {
        let values = serde_json::to_string(&cal.inputs.plan.values(x)).unwrap_or_default();
        // Every simulation job reports an EnergyPlus failure as its result (cached with it:
        // the same inputs fail the same way).
        let key = hex::encode(Sha256::digest(format!("tolerant\n{inputs_hash}\n{values}")));
        NewJob {
            stage: if refine_round > 0 {
                Stage::Refine
            } else {
                Stage::Simulate
            },
            kind: JobKind::Simulate,
            label: if refine_round > 0 {
                format!("simulation of posterior draw {i} (refinement round {refine_round})")
            } else {
                format!("simulation of design point {i}")
            },
            spec: proto::Job {
                bundle: crate::client::refs(&r.bundle),
                kind: Some(Kind::Simulate(proto::SimulateJob {
                    point: i as u32,
                    values: x.to_vec(),
                    refine_round,
                })),
                ..Default::default()
            },
            cache_key: Some(key),
        }
    }

    /// Places the outputs of finished simulation jobs in the run's `simulations/` and reads
    /// them back (checking they belong to the job's values).
    fn simulated(&self, cal: &Calibration, jobs: &[JobRow]) -> Result<Vec<Simulated>> {
        let mut out = vec![];
        for j in jobs {
            let Some(Kind::Simulate(s)) = &j.spec.kind else {
                return Err(format!("job {} is not a simulation", j.id));
            };
            if let Some(e) = reported_failure(j) {
                out.push(Simulated {
                    refine_round: s.refine_round,
                    point: SimulatedDraw {
                        index: s.point as usize,
                        values: s.values.clone(),
                        outputs: Err(e),
                    },
                });
                continue;
            }
            // Cached outputs may come from another run's point: name them after this one's.
            let files: Vec<File> = j
                .outputs
                .iter()
                .map(|f| File {
                    path: OutputDir::point_rel(s.point as usize),
                    ..f.clone()
                })
                .collect();
            self.place(&cal.out, &files)?;
            let (o, ran) = cal
                .simulate_point(s.point as usize, &s.values)
                .map_err(err)?;
            if ran.is_some() {
                return Err(format!(
                    "point {}: the worker's outputs did not match its parameter values",
                    s.point
                ));
            }
            out.push(Simulated {
                refine_round: s.refine_round,
                point: SimulatedDraw {
                    index: s.point as usize,
                    values: s.values.clone(),
                    outputs: Ok(o),
                },
            });
        }
        Ok(out)
    }

    /// The refinement rounds finished so far.
    fn refine_log(&self, r: &RunRow) -> Result<RefineLog> {
        match &r.refine {
            Some(j) => serde_json::from_str(j).map_err(|e| format!("refinement log: {e}")),
            None => Ok(RefineLog::default()),
        }
    }

    /// The training job for the training set in `dataset`; `init`: the weights file of the
    /// surrogate to warm-start from (a refinement round's retraining).
    fn train_job(
        &self,
        r: &RunRow,
        cal: &Calibration,
        dataset: &Path,
        init: Option<&File>,
    ) -> Result<NewJob> {
        let mut inputs = vec![];
        for p in crate::client::walk(dataset).map_err(err)? {
            let bytes = std::fs::read(&p).map_err(err)?;
            let rel = p.strip_prefix(&cal.out).map_err(err)?;
            inputs.push(proto::FileRef {
                path: rel.to_string_lossy().replace('\\', "/"),
                sha256: self.put_artifact(&bytes)?,
                size: bytes.len() as u64,
            });
        }
        let mut train = proto::TrainJob::default();
        if let Some(w) = init {
            train.init = WARM_START_DIR.into();
            inputs.push(proto::FileRef {
                path: format!("{WARM_START_DIR}/{}", bemcal_surrogate::WEIGHTS_FILE),
                sha256: w.sha256.clone(),
                size: w.size,
            });
        }
        Ok(NewJob {
            stage: Stage::Train,
            kind: JobKind::Train,
            label: "surrogate training".into(),
            spec: proto::Job {
                bundle: crate::client::refs(&r.bundle),
                inputs,
                kind: Some(Kind::Train(train)),
                ..Default::default()
            },
            cache_key: None,
        })
    }

    /// Hash of everything a simulation depends on besides the parameter values: the bundle's
    /// files except the project file and the meters, and the weather file's content.
    fn simulation_inputs_hash(&self, r: &RunRow, cal: &Calibration) -> Result<String> {
        let meters = cal.project.meters.file.clone().unwrap_or_default();
        let mut h = Sha256::new();
        // A cached simulation is only valid for the generator/runner that made it.
        h.update(format!(
            "simulation revision {}\n",
            bemcal_energyplus::SIMULATION_REVISION
        ));
        for f in &r.bundle {
            if f.path != bundle::PROJECT_FILE && Path::new(&f.path) != meters {
                h.update(format!("{} {}\n", f.path, f.sha256));
            }
        }
        let w = std::fs::read(&cal.inputs.weather_path)
            .map_err(|e| format!("{}: {e}", cal.inputs.weather_path.display()))?;
        h.update(Sha256::digest(&w));
        Ok(hex::encode(h.finalize()))
    }

    fn stage_simulate(&self, r: &RunRow) -> Result<bool> {
        let jobs = self.store.jobs(&r.id, Some(Stage::Simulate)).map_err(err)?;
        if jobs.iter().any(|j| j.state != JobState::Done) {
            return Ok(false);
        }
        let cal = self.load(r)?;
        let hypercube = cal.design().map_err(err)?;
        // Every attempt so far, in the order the waves were queued: the rule of
        // `bemcal_calibrate::replacement` says what comes next, as in the local pipeline.
        let simulated = self.simulated(&cal, &jobs)?;
        let attempts: Vec<Attempt> = simulated
            .iter()
            .map(|s| Attempt {
                slot: s.point.index,
                values: s.point.values.clone(),
                error: s.point.outputs.as_ref().err().cloned(),
            })
            .collect();
        let outcome = match cal.design_step(&hypercube, &cal.spares().map_err(err)?, &attempts) {
            Step::Simulate(wave) => {
                let hash = self.simulation_inputs_hash(r, &cal)?;
                let jobs = wave
                    .iter()
                    .map(|(i, x)| self.simulation_job(r, &cal, &hash, *i, x, 0))
                    .collect();
                self.store.add_jobs(&r.id, jobs).map_err(err)?;
                // Advance again at once: a wave served whole from the simulation cache is
                // done already, and no completion will come to kick this run.
                return Ok(true);
            }
            Step::Failed(message) => return Err(format!("design: {message}")),
            Step::Done(outcome) => outcome,
        };
        cal.record_outcome(&outcome).map_err(err)?;
        // The last attempt of each settled slot is its success; place it last so that its
        // file is the one left in `simulations/`.
        let mut by_slot: std::collections::HashMap<usize, HourlyOutputs> = Default::default();
        for s in simulated {
            if let Ok(o) = s.point.outputs {
                by_slot.insert(s.point.index, o);
            }
        }
        let outputs = outcome
            .slots
            .iter()
            .map(|i| {
                by_slot
                    .remove(i)
                    .ok_or_else(|| format!("design point {i}: no simulation"))
            })
            .collect::<Result<Vec<_>>>()?;
        let design = outcome.design(&hypercube, &cal.inputs.plan.priors);
        let dataset = cal
            .training_set(design.points.len(), &design, &outputs)
            .map_err(err)?;
        if !r.surrogate.is_empty() {
            self.place(&cal.out, &r.surrogate)?;
            if !cal.has_surrogate() {
                return Err("the surrogate given at submit is not a valid surrogate folder".into());
            }
            let jobs = self.chain_jobs(r, &cal.project)?;
            self.store
                .set_stage(&r.id, Stage::Chains, jobs)
                .map_err(err)?;
            return Ok(true);
        }
        let job = self.train_job(r, &cal, &dataset, None)?;
        self.store
            .set_stage(&r.id, Stage::Train, vec![job])
            .map_err(err)?;
        Ok(true)
    }

    /// The current surrogate: the latest trained one (refinement retrains), else the one
    /// given at submit.
    fn surrogate_files(&self, r: &RunRow) -> Result<Vec<File>> {
        let jobs = self.store.jobs(&r.id, Some(Stage::Train)).map_err(err)?;
        if let Some(j) = jobs.iter().rev().find(|j| j.state == JobState::Done) {
            return Ok(j.outputs.clone());
        }
        if !r.surrogate.is_empty() {
            return Ok(r.surrogate.clone());
        }
        Err("no trained surrogate".to_string())
    }

    fn stage_train(&self, r: &RunRow) -> Result<bool> {
        let jobs = self.store.jobs(&r.id, Some(Stage::Train)).map_err(err)?;
        if jobs.is_empty() || jobs.iter().any(|j| j.state != JobState::Done) {
            return Ok(false);
        }
        let cal = self.load(r)?;
        self.place(&cal.out, &self.surrogate_files(r)?)?;
        if !cal.has_surrogate() {
            return Err("training produced no valid surrogate".into());
        }
        let jobs = self.chain_jobs(r, &cal.project)?;
        self.store
            .set_stage(&r.id, Stage::Chains, jobs)
            .map_err(err)?;
        Ok(true)
    }

    /// `simulations/design.json` of a run whose design is settled, as a job input.
    fn settled_design_file(&self, r: &RunRow) -> Result<Option<proto::FileRef>> {
        let path = self
            .run_dir(&r.id)
            .join("out")
            .join("simulations")
            .join(bemcal_calibrate::design::OUTCOME_FILE);
        let Ok(bytes) = std::fs::read(&path) else {
            return Ok(None);
        };
        Ok(Some(proto::FileRef {
            path: format!("simulations/{}", bemcal_calibrate::design::OUTCOME_FILE),
            sha256: self.put_artifact(&bytes)?,
            size: bytes.len() as u64,
        }))
    }

    /// Next chain-segment jobs of the current refinement round: for each group of chains whose
    /// latest segment is done and short of the round's target, the following segment (from
    /// that segment's checkpoint; a round's first segment starts where the same chains ended
    /// in the previous round, `warm.json`).
    fn chain_jobs(&self, r: &RunRow, project: &Project) -> Result<Vec<NewJob>> {
        let done = self.store.jobs(&r.id, Some(Stage::Chains)).map_err(err)?;
        let m = &project.mcmc;
        let n = m.chains;
        let per = if self.config.chains_per_job == 0 {
            n
        } else {
            self.config.chains_per_job.min(n)
        };
        let log = self.refine_log(r)?;
        let round = Round::after(project, log.rounds.len() as u32);
        // The final chains' target grows with each extension (`after_final_chains`).
        let target = match round {
            Round::Final { .. } => r.chain_target,
            Round::Preliminary { .. } => round.iterations(project),
        };
        let surrogate = self.surrogate_files(r)?;
        let settled = self.settled_design_file(r)?;
        let group = |first: usize, round: Round| -> Vec<&JobRow> {
            done.iter()
                .filter(|j| {
                    matches!(&j.spec.kind, Some(Kind::Chains(c))
                        if c.first_chain as usize == first && c.round == round.index())
                })
                .collect()
        };
        let states_of = |j: &JobRow| -> Result<File> {
            j.outputs
                .iter()
                .find(|f| f.path == STATES_FILE)
                .cloned()
                .ok_or_else(|| format!("{}: no states.json", j.label))
        };
        let mut jobs = vec![];
        for first in (0..n).step_by(per) {
            let count = per.min(n - first);
            let mine = group(first, round);
            if mine.iter().any(|j| j.state != JobState::Done) {
                continue;
            }
            let reached: u64 = mine
                .iter()
                .map(|j| match &j.spec.kind {
                    Some(Kind::Chains(c)) => c.iterations,
                    _ => 0,
                })
                .sum();
            if reached >= target {
                continue;
            }
            let mut inputs = crate::client::refs(&surrogate);
            // The settled design: where EnergyPlus failed, the chains refuse proposals.
            if let Some(f) = &settled {
                inputs.push(f.clone());
            }
            if let Some(last) = mine.last() {
                inputs.push((&states_of(last)?).into());
            } else if let Some(prev) = log.rounds.last().filter(|p| !p.starts.is_empty()) {
                inputs.push(self.warm_starts(&prev.starts, first, count)?);
            }
            let seg = mine.len() as u32;
            jobs.push(NewJob {
                stage: Stage::Chains,
                kind: JobKind::Chains,
                label: segment_label(round, first, count, seg),
                spec: proto::Job {
                    bundle: crate::client::refs(&r.bundle),
                    inputs,
                    kind: Some(Kind::Chains(proto::ChainSegmentJob {
                        first_chain: first as u32,
                        chains: count as u32,
                        iterations: m.segment.min(target - reached),
                        segment: seg,
                        round: round.index(),
                    })),
                    ..Default::default()
                },
                cache_key: None,
            });
        }
        Ok(jobs)
    }

    /// A round's first segment of chains `first..first + count` starts where the previous
    /// round's chains ended (or restarted: `next_starts`): their `starts`, as `warm.json`.
    fn warm_starts(
        &self,
        starts: &[Vec<f64>],
        first: usize,
        count: usize,
    ) -> Result<proto::FileRef> {
        let mine = starts
            .get(first..first + count)
            .ok_or_else(|| format!("chains {first}: no starting points"))?;
        let bytes = serde_json::to_vec(mine).map_err(err)?;
        Ok(proto::FileRef {
            path: WARM_FILE.into(),
            sha256: self.put_artifact(&bytes)?,
            size: bytes.len() as u64,
        })
    }

    fn stage_chains(&self, r: &RunRow) -> Result<bool> {
        let jobs = self.store.jobs(&r.id, Some(Stage::Chains)).map_err(err)?;
        let project = self.project(r)?;
        let target_jobs = self.chain_jobs(r, &project)?;
        if !target_jobs.is_empty() {
            self.store.add_jobs(&r.id, target_jobs).map_err(err)?;
            return Ok(false);
        }
        if jobs.iter().any(|j| j.state != JobState::Done) {
            return Ok(false);
        }
        self.store
            .set_stage(&r.id, Stage::Merge, vec![])
            .map_err(err)?;
        Ok(true)
    }

    fn project(&self, r: &RunRow) -> Result<Project> {
        let pdir = self.run_dir(&r.id).join("project");
        let pf = pdir.join(bundle::PROJECT_FILE);
        if !pf.is_file() {
            bundle::materialize(&r.bundle, &self.artifacts, &pdir)?;
        }
        Project::load_submitted(&pf).map_err(err)
    }

    /// The chains of refinement round `round`, merged: each chain's last state and all its
    /// draws, segments in order.
    fn merged_chains(&self, r: &RunRow, round: u32) -> Result<(Vec<Chain>, Vec<Draws>)> {
        let jobs = self.store.jobs(&r.id, Some(Stage::Chains)).map_err(err)?;
        let mut groups: Vec<(u32, Vec<&JobRow>)> = vec![];
        for j in &jobs {
            let Some(Kind::Chains(c)) = &j.spec.kind else {
                continue;
            };
            if c.round != round {
                continue;
            }
            match groups.iter_mut().find(|g| g.0 == c.first_chain) {
                Some(g) => g.1.push(j),
                None => groups.push((c.first_chain, vec![j])),
            }
        }
        groups.sort_by_key(|g| g.0);
        let mut states: Vec<Chain> = vec![];
        let mut draws: Vec<Draws> = vec![];
        for (_, seg) in &groups {
            let mut acc: Vec<Draws> = vec![];
            let mut last_states = vec![];
            for j in seg {
                let get = |name: &str| -> Result<Vec<u8>> {
                    let f = j
                        .outputs
                        .iter()
                        .find(|f| f.path == name)
                        .ok_or_else(|| format!("{}: no {name}", j.label))?;
                    self.artifacts.read(&f.sha256).map_err(err)
                };
                let d: Vec<Draws> = serde_json::from_slice(&get(DRAWS_FILE)?).map_err(err)?;
                last_states = serde_json::from_slice(&get(STATES_FILE)?).map_err(err)?;
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
        Ok((states, draws))
    }

    fn stage_merge(&self, r: &RunRow) -> Result<bool> {
        let cal = self.load(r)?;
        self.place(&cal.out, &self.surrogate_files(r)?)?;
        let log = self.refine_log(r)?;
        let round = Round::after(&cal.project, log.rounds.len() as u32);
        let (states, draws) = self.merged_chains(r, round.index())?;
        let mut sampler = cal.sampler().map_err(err)?;
        if let Round::Preliminary { index } = round {
            // Refinement round `index + 1`: simulate posterior draws of these chains.
            let post = sampler.posterior();
            let first = cal.next_refine_key(&log);
            let hash = self.simulation_inputs_hash(r, &cal)?;
            let refine = &cal.project.refine;
            let jobs = refinement_points(&draws, refine.points, refine.spread, |u| {
                post.ln_prior(u).is_finite()
            })
            .iter()
            .enumerate()
            .map(|(j, u)| self.simulation_job(r, &cal, &hash, first + j, &post.theta(u), index + 1))
            .collect();
            self.store
                .set_stage(&r.id, Stage::Refine, jobs)
                .map_err(err)?;
            return Ok(true);
        }
        let mut chains = sampler.summarize(&states, &draws, &log).map_err(err)?;
        chains.extensions = r.extensions;
        if let AfterFinalChains::Extend { iterations } =
            after_final_chains(&cal.project.mcmc, &chains, r.chain_target)
        {
            self.store.extend_chains(&r.id, iterations).map_err(err)?;
            self.store
                .set_stage(&r.id, Stage::Chains, vec![])
                .map_err(err)?;
            return Ok(true);
        }
        let ck = Checkpoint { states, draws };
        let bytes = serde_json::to_vec(&ck).map_err(err)?;
        bemcal_calibrate::write_atomic(&cal.out.chains_checkpoint(), &bytes).map_err(err)?;
        self.store
            .set_merge(&r.id, &serde_json::to_string(&chains).map_err(err)?)
            .map_err(err)?;
        let initial = cal.project.validation.initial.then(|| cal.initial_point());
        let jobs = validation_runs(&chains, initial)
            .iter()
            .map(|run| validation_job(r, run))
            .collect();
        self.store
            .set_stage(&r.id, Stage::Validate, jobs)
            .map_err(err)?;
        Ok(true)
    }

    /// End of a refinement round: once its posterior draws are simulated, records the round
    /// (with the current surrogate's error at the draws), builds the grown training set and
    /// queues the retraining, in one transaction.
    fn stage_refine(&self, r: &RunRow) -> Result<bool> {
        let mut log = self.refine_log(r)?;
        let round = log.rounds.len() as u32 + 1;
        let in_round =
            |j: &JobRow| matches!(&j.spec.kind, Some(Kind::Simulate(s)) if s.refine_round == round);
        let jobs: Vec<JobRow> = self
            .store
            .jobs(&r.id, Some(Stage::Refine))
            .map_err(err)?
            .into_iter()
            .filter(in_round)
            .collect();
        if jobs.iter().any(|j| j.state != JobState::Done) {
            return Ok(false);
        }
        let cal = self.load(r)?;
        self.place(&cal.out, &self.surrogate_files(r)?)?;
        // Every simulation so far (design points, then every round's draws), read back once.
        let mut sims = self.store.jobs(&r.id, Some(Stage::Simulate)).map_err(err)?;
        sims.extend(self.store.jobs(&r.id, Some(Stage::Refine)).map_err(err)?);
        let simulated = self.simulated(&cal, &sims)?;
        let (states, draws) = self.merged_chains(r, round - 1)?;
        let last: Vec<Vec<f64>> = states.iter().map(|s| s.position().to_vec()).collect();
        let this_round = simulated
            .iter()
            .filter(|s| s.refine_round == round)
            .map(|s| s.point.clone())
            .collect();
        let (closed, _) = close_round(
            round,
            this_round,
            &mut cal.sampler().map_err(err)?,
            &draws,
            &last,
            cal.project.refine.restart_below,
        )
        .map_err(err)?;
        log.rounds.push(closed);
        // The grown training set: design points, then every round's draws.
        let (outcome, design) = cal.settled_design().map_err(err)?;
        let by_index: std::collections::HashMap<usize, HourlyOutputs> = simulated
            .into_iter()
            .filter_map(|s| s.point.outputs.ok().map(|o| (s.point.index, o)))
            .collect();
        let full = cal.full_design(&design, &log);
        let indices = outcome
            .slots
            .iter()
            .copied()
            .chain(log.points().map(|p| p.index));
        let outputs = indices
            .map(|i| {
                by_index
                    .get(&i)
                    .cloned()
                    .ok_or_else(|| format!("point {i}: no simulation"))
            })
            .collect::<Result<Vec<_>>>()?;
        let dataset = cal
            .training_set(design.points.len(), &full, &outputs)
            .map_err(err)?;
        // Warm start from the weights of the surrogate this round's chains used.
        let weights = format!("surrogate/{}", bemcal_surrogate::WEIGHTS_FILE);
        let init = match cal.project.surrogate.warm_start {
            true => self
                .surrogate_files(r)?
                .into_iter()
                .find(|f| f.path == weights),
            false => None,
        };
        let job = self.train_job(r, &cal, &dataset, init.as_ref())?;
        let json = serde_json::to_string(&log).map_err(err)?;
        self.store
            .set_stage_refined(&r.id, Stage::Train, vec![job], Some(&json))
            .map_err(err)?;
        Ok(true)
    }

    fn stage_validate(&self, r: &RunRow) -> Result<bool> {
        let jobs = self.store.jobs(&r.id, Some(Stage::Validate)).map_err(err)?;
        if jobs.iter().any(|j| j.state != JobState::Done) {
            return Ok(false);
        }
        // EnergyPlus failed at the estimate (and at the fallbacks so far): the next-best draw.
        let tried: Vec<&JobRow> = jobs.iter().filter(|j| is_calibrated(j)).collect();
        let failures: Vec<String> = tried.iter().filter_map(|j| reported_failure(j)).collect();
        if failures.len() == tried.len() {
            match next_validation(&self.merged(r)?, &failures) {
                Ok(run) => {
                    let job = validation_job(r, &run);
                    self.store.add_jobs(&r.id, vec![job]).map_err(err)?;
                    // As in the design: a cached validation is done already.
                    return Ok(true);
                }
                Err(message) => return Err(format!("validation: {message}")),
            }
        }
        self.store
            .set_stage(&r.id, Stage::Summary, vec![])
            .map_err(err)?;
        Ok(true)
    }

    /// The merged chains recorded at the merge.
    fn merged(&self, r: &RunRow) -> Result<ChainSummary> {
        serde_json::from_str(
            r.merge
                .as_deref()
                .ok_or_else(|| "merged chains are missing".to_string())?,
        )
        .map_err(err)
    }

    fn stage_summary(&self, r: &RunRow) -> Result<bool> {
        let cal = self.load(r)?;
        let jobs = self.store.jobs(&r.id, Some(Stage::Validate)).map_err(err)?;
        let mut validation = vec![];
        let mut initial = vec![];
        let mut chains = self.merged(r)?;
        let failures: Vec<String> = jobs
            .iter()
            .filter(|j| is_calibrated(j))
            .filter_map(reported_failure)
            .collect();
        for j in &jobs {
            if reported_failure(j).is_some() {
                continue;
            }
            self.place(&cal.out, &j.outputs)?;
            let m: Vec<OutputMetrics> =
                serde_json::from_str(j.result.as_deref().unwrap_or("[]")).map_err(err)?;
            match &j.spec.kind {
                Some(Kind::Validate(v)) if v.label == "initial" => initial = m,
                _ if is_calibrated(j) => {
                    chains.settle_estimate(&failures);
                    validation = m
                }
                // A predictive draw: its run is placed for the intervals.
                _ => {}
            }
        }
        let (_, design) = cal.settled_design().map_err(err)?;
        let log = self.refine_log(r)?;
        if !log.rounds.is_empty() {
            let json = serde_json::to_vec_pretty(&log).map_err(err)?;
            bemcal_calibrate::write_atomic(&cal.out.join(REFINE_FILE), &json).map_err(err)?;
        }
        let secs = self.store.stage_seconds(&r.id).map_err(err)?;
        let s = |stage: Stage| {
            secs.iter()
                .filter(|x| x.0 == stage)
                .map(|x| x.1)
                .sum::<f64>()
        };
        let timings = Timings {
            design_s: s(Stage::Design),
            simulations_s: s(Stage::Simulate),
            training_s: s(Stage::Train),
            chains_s: s(Stage::Chains),
            summary_s: s(Stage::Merge),
            validation_s: s(Stage::Validate),
            refinement_s: s(Stage::Refine),
            total_s: (crate::now_ms().saturating_sub(r.created_ms)) as f64 / 1000.0,
        };
        let summary =
            write_summary(&cal, &design, &chains, validation, initial, timings).map_err(err)?;
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
        let json = serde_json::to_string_pretty(&summary).map_err(err)?;
        self.store.finish_run(&r.id, &files, &json).map_err(err)?;
        Ok(false)
    }
}

/// The job of a validation run of the sequence; the calibrated model's and a predictive
/// draw's tolerate an EnergyPlus failure ([`ValidationRun::tolerates_failure`]: the driver then
/// validates the next-best draw, or leaves the draw out).
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

/// A validation job of the calibrated model (the estimate or a fallback draw).
fn is_calibrated(j: &JobRow) -> bool {
    matches!(&j.spec.kind, Some(Kind::Validate(v)) if v.label == "calibrated")
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

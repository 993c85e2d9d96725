//! The gRPC service: leases, heartbeats, completions, artifacts, submissions and run status.

use std::pin::Pin;
use std::sync::Arc;

use tokio_stream::Stream;
use tonic::{Code, Request, Response, Status, Streaming};

use crate::artifacts::{safe_relative, valid_sha};
use crate::audit::Event;
use crate::auth::{
    caller, check_name, new_credential, require_client, require_client_or_worker, require_enroller,
    require_worker, token_sha256,
};
use crate::db::{Admission, File, JobRow, NewRun, Outcome, RunRow};
use crate::driver::State;
use crate::proto::coordinator_server::Coordinator;
use crate::proto::job::Kind;
use crate::proto::*;
use crate::states::{wire_stage, JobKind, JobState, RunState, Stage};
use crate::{bundle, excerpt, CHUNK_BYTES, MAX_ERROR_BYTES};
use bemcal_calibrate::design::check_point_file;
use bemcal_calibrate::output::{DRAWS_FILE, STATES_FILE};
use bemcal_calibrate::savings::{parse_run, run_file};
use bemcal_calibrate::OutputDir;

/// Largest artifact accepted (bytes).
pub const MAX_ARTIFACT_BYTES: u64 = 1 << 30;

/// The coordinator service over the shared state.
pub struct Service {
    /// The coordinator's shared state.
    pub st: Arc<State>,
}

/// An error reply, its message cut to [`MAX_ERROR_BYTES`]: whatever input it quotes, a
/// reply stays short (a client that sent megabytes and hung up is not sent them back).
fn refuse(code: Code, message: impl AsRef<str>) -> Status {
    Status::new(code, excerpt(message.as_ref(), MAX_ERROR_BYTES))
}

fn internal<E: std::fmt::Display>(e: E) -> Status {
    refuse(Code::Internal, e.to_string())
}

fn invalid(message: impl AsRef<str>) -> Status {
    refuse(Code::InvalidArgument, message)
}

/// A run id as the coordinator makes them (`r` and hex), or at least a short plain word.
fn check_run_id(id: &str) -> Result<(), Status> {
    let plain = |c: char| c.is_ascii_alphanumeric() || c == '-' || c == '_';
    if id.is_empty() || id.len() > 64 || !id.chars().all(plain) {
        return Err(invalid(format!(
            "run id {:?} ({} bytes) is not a run id: 1-64 letters, digits, '-' or '_'",
            excerpt(id, 20),
            id.len()
        )));
    }
    Ok(())
}

fn check_files(st: &State, files: &[FileRef]) -> Result<Vec<File>, Status> {
    files
        .iter()
        .map(|f| {
            safe_relative(&f.path).map_err(invalid)?;
            if !valid_sha(&f.sha256) || !st.artifacts.has(&f.sha256) {
                return Err(refuse(
                    Code::FailedPrecondition,
                    format!("{}: artifact {:?} was not uploaded", f.path, f.sha256),
                ));
            }
            // The size recorded is the file's, not the one claimed: quotas count it.
            let stored = std::fs::metadata(st.artifacts.path(&f.sha256)).map_err(internal)?;
            if stored.len() != f.size {
                return Err(invalid(format!(
                    "{}: artifact {} holds {} bytes, not {}",
                    f.path,
                    excerpt(&f.sha256, 16),
                    stored.len(),
                    f.size
                )));
            }
            Ok(File::from(f))
        })
        .collect()
}

/// What a worker hands over for `job` is what that kind of job produces: a result of the job's
/// kind, and for a simulation either EnergyPlus's failure (no outputs) or exactly its point
/// file; a validation brings its point file, a chain segment its states and draws. A point
/// file (a simulation's, a validation's) must hold a year of finite, plausible hourly series
/// ([`check_point_file`]). Only a simulation, or a validation that tolerates failure, may
/// report EnergyPlus's failure. Nothing that fails here is recorded, let alone cached.
fn check_result(
    st: &State,
    job: &JobRow,
    outputs: &[File],
    result: &JobResult,
) -> Result<(), String> {
    use job_result::Outcome;
    let kind = job.spec.kind.as_ref();
    let fits = match (kind, &result.outcome) {
        (Some(Kind::Simulate(_)), Some(Outcome::Simulated(_))) => true,
        (Some(Kind::Simulate(_)), Some(Outcome::EnergyplusFailed(_))) => outputs.is_empty(),
        (Some(Kind::Measure(_)), Some(Outcome::Simulated(_))) => true,
        (Some(Kind::Measure(_)), Some(Outcome::EnergyplusFailed(_))) => outputs.is_empty(),
        (Some(Kind::Validate(v)), Some(Outcome::EnergyplusFailed(_))) => {
            v.tolerate_failure && outputs.is_empty()
        }
        (Some(Kind::Validate(v)), Some(Outcome::Validated(_))) => {
            let point = OutputDir::validation_point_rel(v.index as usize);
            outputs.iter().any(|f| f.path == point)
        }
        (Some(Kind::Train(_)), Some(Outcome::Trained(_))) => true,
        (Some(Kind::Chains(_)), Some(Outcome::Chains(_))) => {
            let mut names: Vec<&str> = outputs.iter().map(|f| f.path.as_str()).collect();
            names.sort_unstable();
            let mut want = [DRAWS_FILE, STATES_FILE];
            want.sort_unstable();
            names == want
        }
        _ => false,
    };
    if !fits {
        return Err(format!(
            "a {} job completed with the result `{}` and {} output file(s)",
            job.kind,
            result.word(),
            outputs.len()
        ));
    }
    let point = match (kind, &result.outcome) {
        (Some(Kind::Simulate(s)), Some(Outcome::Simulated(run))) => {
            let want = OutputDir::point_rel(s.point as usize);
            match outputs {
                [f] if f.path == want => {}
                _ => return Err(format!("a simulation brings one file, {want}")),
            }
            if run.seconds.is_some_and(|t| !t.is_finite() || t < 0.0) {
                return Err("a simulation's seconds must be a finite, non-negative number".into());
            }
            &outputs[0]
        }
        (Some(Kind::Measure(m)), Some(Outcome::Simulated(_))) => {
            // Exactly the file of the run the job asked for, in its measure's folder.
            let (weather, measure) = parse_run(&m.weather, &m.measure_json)?;
            let want = run_file(weather, measure.as_ref(), m.point as usize);
            match outputs {
                [f] if f.path == want => f,
                _ => return Err(format!("a savings run brings one file, {want}")),
            }
        }
        (Some(Kind::Validate(v)), Some(Outcome::Validated(_))) => {
            let want = OutputDir::validation_point_rel(v.index as usize);
            match outputs.iter().find(|f| f.path == want) {
                Some(f) => f,
                None => return Err(format!("a validation brings {want}")),
            }
        }
        _ => return Ok(()),
    };
    let bytes = st
        .artifacts
        .read(&point.sha256)
        .map_err(|e| e.to_string())?;
    check_point_file(&bytes).map_err(|e| format!("{}: {e}", point.path))
}

/// A worker of another protocol revision gets no job (`FailedPrecondition`, naming both
/// revisions and releases): what it would compute could differ from what this coordinator's
/// jobs ask for.
fn check_protocol(worker: &str, protocol: u32) -> Result<(), Status> {
    if protocol == bemcal_client::PROTOCOL {
        return Ok(());
    }
    Err(refuse(
        Code::FailedPrecondition,
        format!(
            "worker {:?} speaks protocol {} and this coordinator (bemcal {}) protocol {}: \
             run workers of the coordinator's release",
            excerpt(worker, 100),
            protocol,
            env!("CARGO_PKG_VERSION"),
            bemcal_client::PROTOCOL
        ),
    ))
}

impl Service {
    /// Records `ev` in the audit trail; a failure to is logged, not the caller's error.
    fn audit(&self, ev: Event) {
        if let Err(e) = self.st.store.audit(&ev) {
            tracing::error!(target: "bemcal::audit", "audit trail not written: {e}: {}", ev.text());
        }
    }

    /// The registered worker calling, when it is the one `claimed` names (a request's
    /// `worker_id`); else `PermissionDenied`, recorded as `refuse-{call}`.
    fn worker<T>(
        &self,
        req: &Request<T>,
        claimed: &str,
        call: &str,
        lease: u64,
    ) -> Result<String, Status> {
        let id = require_worker(req).inspect_err(|e| {
            let who = caller(req).map_or("unknown".into(), |c| c.actor());
            let ev = Event::new(who, &format!("refuse-{call}")).detail(e.message());
            self.audit(if lease > 0 { ev.lease(lease) } else { ev });
        })?;
        if claimed != id {
            let msg = format!(
                "worker_id {:?} is not this credential's worker ({id})",
                excerpt(claimed, 100)
            );
            let ev = Event::new(format!("worker:{id}"), &format!("refuse-{call}")).detail(&msg);
            self.audit(if lease > 0 { ev.lease(lease) } else { ev });
            return Err(refuse(Code::PermissionDenied, msg));
        }
        Ok(id)
    }

    /// The lease's job when `worker` holds it; `PermissionDenied` when another worker does
    /// (recorded as `refuse-{call}`). An unknown lease is `None` (the store then ignores the
    /// call, as for a late duplicate).
    fn own_lease(&self, lease: u64, worker: &str, call: &str) -> Result<Option<JobRow>, Status> {
        match self.st.store.leased_job(lease).map_err(internal)? {
            Some((holder, job)) if holder != worker => {
                self.audit(
                    Event::new(format!("worker:{worker}"), &format!("refuse-{call}"))
                        .run(&job.run_id)
                        .job(job.id)
                        .lease(lease)
                        .detail(format!("{}: the lease is worker {holder}'s", job.label)),
                );
                Err(refuse(
                    Code::PermissionDenied,
                    format!("lease {lease} belongs to another worker"),
                ))
            }
            Some((_, job)) => Ok(Some(job)),
            None => Ok(None),
        }
    }

    fn kick(&self, o: Outcome) {
        match o {
            // A run over its quota has ended (its error says why): the driver is told too.
            Outcome::Recorded(run) | Outcome::OverQuota { run, .. } => {
                let _ = self.st.kick.send(run);
            }
            Outcome::Ignored => {}
        }
    }

    /// The status of a run, with per-stage progress.
    pub fn status(&self, r: &RunRow, with_results: bool) -> Result<RunStatus, Status> {
        let jobs = self.st.store.jobs(&r.id, None).map_err(internal)?;
        let busy = self.st.store.worker_seconds(&r.id).map_err(internal)?;
        // The stages a run goes through, in order (every stage but `Done`; the savings only
        // where the run has reached them: a project without `[savings] with_calibration`
        // never does).
        let savings = r.stage == Stage::Savings || jobs.iter().any(|j| j.stage == Stage::Savings);
        let order: Vec<Stage> = Stage::ALL
            .iter()
            .copied()
            .filter(|s| *s != Stage::Done && (*s != Stage::Savings || savings))
            .collect();
        let cur = order
            .iter()
            .position(|s| *s == r.stage)
            .unwrap_or(order.len());
        let stages = order
            .iter()
            .enumerate()
            .map(|(i, s)| {
                let mine: Vec<_> = jobs.iter().filter(|j| j.stage == *s).collect();
                let state = if i < cur {
                    StageState::Done
                } else if i == cur {
                    StageState::from(r.state)
                } else {
                    StageState::Pending
                };
                let (done, total) = if mine.is_empty() {
                    let d = (i < cur) as u32;
                    (d, 1)
                } else {
                    (
                        mine.iter().filter(|j| j.state == JobState::Done).count() as u32,
                        mine.len() as u32,
                    )
                };
                StageProgress {
                    stage: wire_stage(*s).into(),
                    state: state.into(),
                    done,
                    total,
                    running: mine.iter().filter(|j| j.state == JobState::Leased).count() as u32,
                    worker_seconds: busy
                        .iter()
                        .find(|(b, _)| b == s)
                        .map_or(0.0, |(_, secs)| *secs),
                }
            })
            .collect();
        Ok(RunStatus {
            run_id: r.id.clone(),
            name: r.name.clone(),
            state: crate::proto::RunState::from(r.state).into(),
            stage: wire_stage(r.stage).into(),
            error: r.error.clone().unwrap_or_default(),
            stages,
            results: if with_results {
                crate::client::refs(&self.st.store.results(&r.id).map_err(internal)?)
            } else {
                vec![]
            },
            created_ms: r.created_ms,
            finished_ms: r.finished_ms.unwrap_or(0),
            portfolio: r.portfolio.clone().unwrap_or_default(),
            building: r.building.clone().unwrap_or_default(),
            client: r.client.clone().unwrap_or_default(),
            simulations_run: jobs
                .iter()
                .filter(|j| j.kind == JobKind::Simulate && j.state == JobState::Done && !j.cached)
                .count() as u32,
            simulations_shared: jobs
                .iter()
                .filter(|j| j.kind == JobKind::Simulate && j.state == JobState::Done && j.cached)
                .count() as u32,
            jobs_total: jobs.len() as u32,
            attempts_total: self.st.store.attempts(&r.id).map_err(internal)? as u32,
            summary_json: if with_results {
                r.summary.clone().unwrap_or_default()
            } else {
                String::new()
            },
            log: if with_results {
                self.st.store.log_lines(&r.id).map_err(internal)?
            } else {
                vec![]
            },
            jobs: if with_results {
                self.job_infos(&r.id, &jobs)?
            } else {
                vec![]
            },
        })
    }

    /// A run's jobs as status shows them, with their attempts and workers.
    fn job_infos(&self, run: &str, jobs: &[JobRow]) -> Result<Vec<JobInfo>, Status> {
        let att = self.st.store.job_attempts(run).map_err(internal)?;
        Ok(jobs
            .iter()
            .map(|j| {
                let a = att.iter().find(|a| a.0 == j.id);
                JobInfo {
                    job_id: j.id,
                    stage: wire_stage(j.stage).into(),
                    label: j.label.clone(),
                    state: crate::proto::JobState::from(j.state).into(),
                    attempts: a.map_or(0, |a| a.1),
                    worker: a.map_or(String::new(), |a| a.2.clone()),
                    cached: j.cached,
                    result_json: j.result.clone().unwrap_or_default(),
                }
            })
            .collect())
    }

    /// Checks a submitted bundle the way a run will load it (the project file, the model, the
    /// parameters, the meters CSV and the weather) in run `id`'s folder: the project's name, or
    /// why it is invalid (its folder then removed).
    async fn load_submitted(
        &self,
        id: &str,
        files: &[File],
    ) -> Result<Result<String, String>, Status> {
        let (st, idc, files) = (self.st.clone(), id.to_string(), files.to_vec());
        let project = tokio::task::spawn_blocking(move || -> Result<_, String> {
            let dir = st.run_dir(&idc);
            let pdir = dir.join("project");
            let pf = bundle::materialize(&files, &st.artifacts, &pdir)?;
            let project =
                bemcal_calibrate::Project::load_submitted(&pf).map_err(|e| e.to_string())?;
            bemcal_calibrate::load_inputs(&project).map_err(|e| e.to_string())?;
            Ok(project.name)
        })
        .await
        .map_err(internal)?;
        Ok(project.map_err(|e| {
            let dir = self.st.run_dir(id);
            let _ = std::fs::remove_dir_all(&dir);
            let prefix = format!("{}/", dir.join("project").display());
            format!("invalid project: {}", e.replace(&prefix, ""))
        }))
    }
}

type ChunkStream = Pin<Box<dyn Stream<Item = Result<Chunk, Status>> + Send>>;

#[tonic::async_trait]
impl Coordinator for Service {
    async fn health(&self, _: Request<HealthRequest>) -> Result<Response<HealthReply>, Status> {
        let (q, l) = self.st.store.queue_depth().map_err(internal)?;
        Ok(Response::new(HealthReply {
            version: env!("CARGO_PKG_VERSION").into(),
            queued_jobs: q,
            leased_jobs: l,
        }))
    }

    async fn register(
        &self,
        req: Request<RegisterRequest>,
    ) -> Result<Response<RegisterReply>, Status> {
        let actor = caller(&req).map_or("unknown".into(), |c| c.actor());
        require_enroller(&req).inspect_err(|e| {
            self.audit(Event::new(&actor, "refuse-register").detail(e.message()));
        })?;
        let r = req.into_inner();
        check_name(&r.name).map_err(|e| invalid(format!("worker {e}")))?;
        check_protocol(&r.name, r.protocol)?;
        let credential = new_credential().map_err(internal)?;
        let sha = token_sha256(&credential);
        let worker_id = self
            .st
            .store
            .register_worker(&r.name, &sha, &actor)
            .map_err(internal)?;
        self.st.credentials.add(&sha, &worker_id, false);
        Ok(Response::new(RegisterReply {
            worker_id,
            credential,
        }))
    }

    async fn lease(&self, req: Request<LeaseRequest>) -> Result<Response<LeaseReply>, Status> {
        let worker = self.worker(&req, &req.get_ref().worker_id, "lease", 0)?;
        let r = req.into_inner();
        check_protocol(&worker, r.protocol)?;
        if r.free_slots == 0 {
            return Ok(Response::new(LeaseReply { job: None }));
        }
        let job = self
            .st
            .store
            .lease(&worker, self.st.config.lease_ttl_ms)
            .map_err(internal)?;
        Ok(Response::new(LeaseReply { job }))
    }

    async fn heartbeat(
        &self,
        req: Request<HeartbeatRequest>,
    ) -> Result<Response<HeartbeatReply>, Status> {
        let (claimed, lease) = (req.get_ref().worker_id.clone(), req.get_ref().lease_id);
        let worker = self.worker(&req, &claimed, "heartbeat", lease)?;
        if self.own_lease(lease, &worker, "heartbeat")?.is_none() {
            return Ok(Response::new(HeartbeatReply { ok: false }));
        }
        let ok = self
            .st
            .store
            .heartbeat(lease, self.st.config.lease_ttl_ms)
            .map_err(internal)?;
        Ok(Response::new(HeartbeatReply { ok }))
    }

    async fn complete(&self, req: Request<CompleteRequest>) -> Result<Response<Ack>, Status> {
        let (claimed, lease) = (req.get_ref().worker_id.clone(), req.get_ref().lease_id);
        let worker = self.worker(&req, &claimed, "complete", lease)?;
        let r = req.into_inner();
        let Some(job) = self.own_lease(lease, &worker, "complete")? else {
            return Ok(Response::new(Ack {}));
        };
        let refused = |e: &Status| {
            self.audit(
                Event::new(format!("worker:{worker}"), "refuse-complete")
                    .run(&job.run_id)
                    .job(job.id)
                    .lease(lease)
                    .detail(format!("{}: {}", job.label, e.message())),
            );
        };
        let outputs = check_files(&self.st, &r.outputs).inspect_err(refused)?;
        let result = r.result.unwrap_or_default();
        if let Some(job_result::Outcome::EnergyplusFailed(f)) = &result.outcome {
            if f.error.len() > 1 << 20 {
                let e = invalid("an EnergyPlus failure's error over 1 MiB");
                refused(&e);
                return Err(e);
            }
        }
        // What a finished job hands over is checked before it is recorded (and, for a
        // simulation, shared with every run with the same inputs).
        let (st, checked_job, files, checked) = (
            self.st.clone(),
            job.clone(),
            outputs.clone(),
            result.clone(),
        );
        tokio::task::spawn_blocking(move || check_result(&st, &checked_job, &files, &checked))
            .await
            .map_err(internal)?
            .map_err(|e| invalid(format!("lease {lease}: {e}")))
            .inspect_err(refused)?;
        // Committed before the reply: a worker that hears "ok" may forget the job.
        let (o, shared) = self
            .st
            .store
            .complete_within(
                lease,
                &outputs,
                &result.to_text(),
                self.st.config.max_run_bytes,
            )
            .map_err(internal)?;
        self.kick(o);
        for run in shared {
            let _ = self.st.kick.send(run);
        }
        Ok(Response::new(Ack {}))
    }

    async fn fail(&self, req: Request<FailRequest>) -> Result<Response<Ack>, Status> {
        let (claimed, lease) = (req.get_ref().worker_id.clone(), req.get_ref().lease_id);
        let worker = self.worker(&req, &claimed, "fail", lease)?;
        let r = req.into_inner();
        if self.own_lease(lease, &worker, "fail")?.is_none() {
            return Ok(Response::new(Ack {}));
        }
        let error: String = r.error.chars().take(8000).collect();
        let o = self
            .st
            .store
            .fail(lease, &error, r.requeue, self.st.config.max_failures)
            .map_err(internal)?;
        self.kick(o);
        Ok(Response::new(Ack {}))
    }

    async fn put_artifact(
        &self,
        req: Request<Streaming<Chunk>>,
    ) -> Result<Response<ArtifactInfo>, Status> {
        require_client_or_worker(&req)?;
        let mut stream = req.into_inner();
        let first = stream
            .message()
            .await?
            .ok_or_else(|| invalid("empty upload"))?;
        if !valid_sha(&first.sha256) {
            return Err(invalid("the first chunk must carry the sha256"));
        }
        if first.size > MAX_ARTIFACT_BYTES {
            return Err(refuse(
                Code::ResourceExhausted,
                format!(
                    "artifact of {} bytes is over the limit of {MAX_ARTIFACT_BYTES}",
                    first.size
                ),
            ));
        }
        // At most max_uploads at once (more wait), and the store within its limit.
        let _permit = self.st.uploads.acquire().await.map_err(internal)?;
        let limit = self.st.config.max_store_bytes;
        if limit > 0 && !self.st.artifacts.has(&first.sha256) {
            let held = self.st.store.artifact_bytes().map_err(internal)?;
            if held.saturating_add(first.size) > limit {
                return Err(refuse(
                    Code::ResourceExhausted,
                    format!(
                        "the artifact store holds {held} bytes of its {limit}-byte limit: an \
                         artifact of {} bytes does not fit (the coordinator's --max-store-gb)",
                        first.size
                    ),
                ));
            }
        }
        // Streamed to disk as it arrives: an upload holds one chunk in memory, whatever its size.
        let mut upload = self
            .st
            .artifacts
            .upload(&first.sha256, first.size)
            .map_err(internal)?;
        upload
            .write(&first.data)
            .map_err(|e| invalid(e.to_string()))?;
        while let Some(c) = stream.message().await? {
            upload.write(&c.data).map_err(|e| invalid(e.to_string()))?;
        }
        let st = self.st.clone();
        let size = first.size;
        let sha = first.sha256.clone();
        tokio::task::spawn_blocking(move || -> Result<(), Status> {
            upload.finish().map_err(|e| invalid(e.to_string()))?;
            st.store.add_artifact(&sha, size).map_err(internal)
        })
        .await
        .map_err(internal)??;
        Ok(Response::new(ArtifactInfo {
            sha256: first.sha256,
            size,
        }))
    }

    type GetArtifactStream = ChunkStream;

    async fn get_artifact(
        &self,
        req: Request<ArtifactRequest>,
    ) -> Result<Response<Self::GetArtifactStream>, Status> {
        require_client_or_worker(&req)?;
        let sha = req.into_inner().sha256;
        if !valid_sha(&sha) {
            return Err(invalid("not a sha256"));
        }
        let path = self.st.artifacts.path(&sha);
        let file = std::fs::File::open(&path)
            .map_err(|_| refuse(Code::NotFound, format!("no artifact {sha}")))?;
        let size = file.metadata().map_err(internal)?.len();
        // Read from disk a chunk at a time as the client takes them: a download holds a few
        // chunks in memory, whatever its size.
        let (tx, rx) = tokio::sync::mpsc::channel(2);
        tokio::task::spawn_blocking(move || {
            let mut file = file;
            // An empty artifact is one empty chunk; otherwise chunks until the end of the file.
            let mut sent = false;
            loop {
                let mut data = Vec::with_capacity(CHUNK_BYTES);
                let read = std::io::Read::read_to_end(
                    &mut std::io::Read::take(&mut file, CHUNK_BYTES as u64),
                    &mut data,
                );
                let chunk = match read {
                    Ok(0) if sent => return,
                    Ok(_) => Ok(Chunk {
                        sha256: sha.clone(),
                        size,
                        data,
                    }),
                    Err(e) => Err(internal(e)),
                };
                let last = !matches!(&chunk, Ok(c) if c.data.len() == CHUNK_BYTES);
                if tx.blocking_send(chunk).is_err() || last {
                    return;
                }
                sent = true;
            }
        });
        Ok(Response::new(Box::pin(
            tokio_stream::wrappers::ReceiverStream::new(rx),
        )))
    }

    async fn missing_artifacts(
        &self,
        req: Request<ArtifactList>,
    ) -> Result<Response<ArtifactList>, Status> {
        require_client_or_worker(&req)?;
        let list = req.into_inner();
        if list.sha256.len() > 100_000 {
            return Err(invalid("too many hashes"));
        }
        Ok(Response::new(ArtifactList {
            sha256: list
                .sha256
                .into_iter()
                .filter(|s| !self.st.artifacts.has(s))
                .collect(),
        }))
    }

    async fn submit(&self, req: Request<SubmitRequest>) -> Result<Response<SubmitReply>, Status> {
        let client = require_client(&req)?;
        let actor = format!("client:{client}");
        let r = req.into_inner();
        let bundle_files = check_files(&self.st, &r.bundle)?;
        let surrogate = check_files(&self.st, &r.surrogate)?;
        if let Some(f) = surrogate.iter().find(|f| !f.path.starts_with("surrogate/")) {
            return Err(invalid(format!(
                "surrogate file {} must be under surrogate/",
                f.path
            )));
        }
        // The same project again while its run still runs: that run (it goes on, keeping its
        // finished jobs), not a second one competing with it for the workers.
        let store = &self.st.store;
        for id in store.running_runs().map_err(internal)? {
            // Another client's run of the same project is not this client's: it gets a run
            // of its own (the simulation cache still shares what both simulate).
            let same = store.run(&id).map_err(internal)?.is_some_and(|run| {
                run.client.as_ref().is_none_or(|c| *c == client)
                    && run.is_submission_of(&bundle_files, &surrogate, &r.portfolio, &r.building)
            });
            if same {
                self.audit(Event::new(&actor, "resume").run(&id));
                return Ok(Response::new(SubmitReply {
                    run_id: id,
                    resumed: true,
                }));
            }
        }
        let id = format!("r{}", &crate::auth::random_token()[..10]);
        let where_ = match r.portfolio.is_empty() {
            true => String::new(),
            false => format!(
                ", building {} of portfolio {}",
                excerpt(&r.building, 100),
                excerpt(&r.portfolio, 100)
            ),
        };
        let (name, invalid_msg) = match self.load_submitted(&id, &bundle_files).await? {
            Ok(name) => (name, None),
            Err(msg) if r.portfolio.is_empty() => {
                self.audit(Event::new(&actor, "refuse-submit").detail(&msg));
                return Err(invalid(msg));
            }
            // In a portfolio the building is reported as failed, with the loader's reason,
            // and the other buildings go on.
            Err(msg) => (r.building.clone(), Some(msg)),
        };
        let run = NewRun {
            id: &id,
            name: &name,
            bundle: &bundle_files,
            surrogate: &surrogate,
            client: &client,
            portfolio: &r.portfolio,
            building: &r.building,
        };
        // A building that is already a failed run takes no place among the client's runs.
        let limit = match invalid_msg {
            Some(_) => 0,
            None => self.st.config.max_runs_per_client,
        };
        let detail = format!("project {}{where_}", excerpt(&name, 100));
        let ev = Event::new(&actor, "submit").detail(&detail);
        match store.admit_run(&run, limit, Some(ev)).map_err(internal)? {
            Admission::Admitted => {}
            Admission::Refused { running } => {
                let _ = std::fs::remove_dir_all(self.st.run_dir(&id));
                let msg = format!(
                    "client {client} has {running} run(s) running (a portfolio counts once), the \
                     coordinator's limit (--max-runs-per-client {limit}): wait for one to end or \
                     cancel one"
                );
                self.audit(Event::new(&actor, "refuse-submit").detail(format!("{detail}: {msg}")));
                return Err(refuse(Code::ResourceExhausted, msg));
            }
        }
        match invalid_msg {
            Some(msg) => {
                store
                    .end_run(&id, RunState::Failed, Some(&msg))
                    .map_err(internal)?;
            }
            None => {
                let _ = self.st.kick.send(id.clone());
            }
        }
        Ok(Response::new(SubmitReply {
            run_id: id,
            resumed: false,
        }))
    }

    async fn list_runs(
        &self,
        req: Request<ListRunsRequest>,
    ) -> Result<Response<ListRunsReply>, Status> {
        require_client(&req)?;
        let p = req.into_inner().portfolio;
        let runs = if p.is_empty() {
            self.st.store.runs()
        } else {
            self.st.store.portfolio_runs(&p)
        }
        .map_err(internal)?;
        let runs = runs
            .iter()
            .map(|r| self.status(r, false))
            .collect::<Result<Vec<_>, _>>()?;
        Ok(Response::new(ListRunsReply { runs }))
    }

    async fn get_run(&self, req: Request<RunRequest>) -> Result<Response<RunStatus>, Status> {
        require_client(&req)?;
        let id = req.into_inner().run_id;
        check_run_id(&id)?;
        let r = self
            .st
            .store
            .run(&id)
            .map_err(internal)?
            .ok_or_else(|| refuse(Code::NotFound, format!("no run {id:?}")))?;
        Ok(Response::new(self.status(&r, true)?))
    }

    async fn cancel(&self, req: Request<RunRequest>) -> Result<Response<RunStatus>, Status> {
        let client = require_client(&req)?;
        let id = req.into_inner().run_id;
        check_run_id(&id)?;
        if self.st.store.run(&id).map_err(internal)?.is_none() {
            return Err(refuse(Code::NotFound, format!("no run {id:?}")));
        }
        let ended = self
            .st
            .store
            .end_run(&id, RunState::Cancelled, Some("cancelled by request"))
            .map_err(internal)?;
        let ev = Event::new(format!("client:{client}"), "cancel").run(&id);
        self.audit(match ended {
            true => ev,
            false => ev.detail("the run had ended already"),
        });
        let r = self
            .st
            .store
            .run(&id)
            .map_err(internal)?
            .ok_or_else(|| refuse(Code::NotFound, id))?;
        Ok(Response::new(self.status(&r, false)?))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A point file as a worker would upload it: `hours` of each output, `bad` at hour 100.
    fn point(hours: usize, bad: Option<&str>) -> Vec<u8> {
        let series: Vec<String> = (0..hours)
            .map(|h| match (h, bad) {
                (100, Some(b)) => b.to_string(),
                _ => format!("{}.5", h % 7),
            })
            .collect();
        format!(
            r#"{{"values": {{"a": 1.0}}, "outputs": {{"names": ["heating_kwh", "electricity_kwh"], "series": [[{0}], [{0}]]}}}}"#,
            series.join(",")
        )
        .into_bytes()
    }

    /// What is cached is a year of finite, plausible hours: a day, NaN, a negative meter or an
    /// absurd one is refused, each saying why.
    #[test]
    fn only_a_year_of_plausible_hours_is_a_simulated_point() {
        check_point_file(&point(8760, None)).unwrap();
        for (bytes, says) in [
            (point(24, None), "24 hours simulated, not 8760"),
            (point(8784, None), "8784 hours simulated, not 8760"),
            (point(8760, Some("NaN")), "not a simulated point's file"),
            (point(8760, Some("-3.0")), "hour 100 holds -3 kWh"),
            (
                point(8760, Some("1e12")),
                "hour 100 holds 1000000000000 kWh",
            ),
        ] {
            let e = check_point_file(&bytes).unwrap_err();
            assert!(e.contains(says), "{says}: {e}");
        }
        // serde_json reads no NaN; a number too large for an f64 is infinite, and refused.
        let e = check_point_file(&point(8760, Some("1e999"))).unwrap_err();
        assert!(
            e.contains("not a simulated point's file") || e.contains("finite"),
            "{e}"
        );
    }
}

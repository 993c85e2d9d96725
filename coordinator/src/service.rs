//! The gRPC service: leases, heartbeats, completions, artifacts, submissions and run status.

use std::pin::Pin;
use std::sync::Arc;

use tokio_stream::Stream;
use tonic::{Code, Request, Response, Status, Streaming};

use crate::artifacts::{safe_relative, valid_sha};
use crate::auth::{require, Role};
use crate::db::{File, JobRow, Outcome, RunRow};
use crate::driver::State;
use crate::proto::coordinator_server::Coordinator;
use crate::proto::job::Kind;
use crate::proto::*;
use crate::states::{wire_stage, JobKind, JobState, RunState, Stage};
use crate::{bundle, excerpt, CHUNK_BYTES, MAX_ERROR_BYTES};
use bemcal_calibrate::design::check_point_file;
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
/// file, holding finite hourly series; a validation brings its point file. Only a simulation,
/// or a validation that tolerates failure, may report EnergyPlus's failure.
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
        (Some(Kind::Validate(v)), Some(Outcome::EnergyplusFailed(_))) => {
            v.tolerate_failure && outputs.is_empty()
        }
        (Some(Kind::Validate(v)), Some(Outcome::Validated(_))) => {
            let point = OutputDir::validation_point_rel(v.index as usize);
            outputs.iter().any(|f| f.path == point)
        }
        (Some(Kind::Train(_)), Some(Outcome::Trained(_))) => true,
        (Some(Kind::Chains(_)), Some(Outcome::Chains(_))) => true,
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
    let (Some(Kind::Simulate(s)), Some(Outcome::Simulated(run))) = (kind, &result.outcome) else {
        return Ok(());
    };
    let want = OutputDir::point_rel(s.point as usize);
    match outputs {
        [f] if f.path == want => {}
        _ => return Err(format!("a simulation brings one file, {want}")),
    }
    if run.seconds.is_some_and(|t| !t.is_finite() || t < 0.0) {
        return Err("a simulation's seconds must be a finite, non-negative number".into());
    }
    let bytes = st
        .artifacts
        .read(&outputs[0].sha256)
        .map_err(|e| e.to_string())?;
    check_point_file(&bytes).map_err(|e| format!("{want}: {e}"))
}

fn check_worker(id: &str) -> Result<(), Status> {
    if id.is_empty() || id.len() > 200 {
        return Err(invalid("worker_id must be 1-200 characters"));
    }
    Ok(())
}

/// A worker of another protocol revision gets no job (`FailedPrecondition`, naming both
/// revisions and releases): what it would compute could differ from what this coordinator's
/// jobs ask for.
fn check_protocol(r: &LeaseRequest) -> Result<(), Status> {
    if r.protocol == bemcal_client::PROTOCOL {
        return Ok(());
    }
    Err(refuse(
        Code::FailedPrecondition,
        format!(
            "worker {:?} speaks protocol {} and this coordinator (bemcal {}) protocol {}: \
             run workers of the coordinator's release",
            r.worker_id,
            r.protocol,
            env!("CARGO_PKG_VERSION"),
            bemcal_client::PROTOCOL
        ),
    ))
}

impl Service {
    /// The lease's job when `worker` holds it; `PermissionDenied` when another worker does.
    /// An unknown lease is `None` (the store then ignores the call, as for a late duplicate).
    fn own_lease(&self, lease: u64, worker: &str) -> Result<Option<JobRow>, Status> {
        match self.st.store.leased_job(lease).map_err(internal)? {
            Some((holder, _)) if holder != worker => Err(refuse(
                Code::PermissionDenied,
                format!("lease {lease} belongs to another worker"),
            )),
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
        // The stages a run goes through, in order (every stage but `Done`).
        let order: Vec<Stage> = Stage::ALL
            .iter()
            .copied()
            .filter(|s| *s != Stage::Done)
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
                let att = self.st.store.job_attempts(&r.id).map_err(internal)?;
                jobs.iter()
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
                    .collect()
            } else {
                vec![]
            },
        })
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

    async fn lease(&self, req: Request<LeaseRequest>) -> Result<Response<LeaseReply>, Status> {
        require(&req, Role::Worker)?;
        let r = req.into_inner();
        check_worker(&r.worker_id)?;
        check_protocol(&r)?;
        if r.free_slots == 0 {
            return Ok(Response::new(LeaseReply { job: None }));
        }
        let job = self
            .st
            .store
            .lease(&r.worker_id, self.st.config.lease_ttl_ms)
            .map_err(internal)?;
        Ok(Response::new(LeaseReply { job }))
    }

    async fn heartbeat(
        &self,
        req: Request<HeartbeatRequest>,
    ) -> Result<Response<HeartbeatReply>, Status> {
        require(&req, Role::Worker)?;
        let r = req.into_inner();
        check_worker(&r.worker_id)?;
        if self.own_lease(r.lease_id, &r.worker_id)?.is_none() {
            return Ok(Response::new(HeartbeatReply { ok: false }));
        }
        let ok = self
            .st
            .store
            .heartbeat(r.lease_id, self.st.config.lease_ttl_ms)
            .map_err(internal)?;
        Ok(Response::new(HeartbeatReply { ok }))
    }

    async fn complete(&self, req: Request<CompleteRequest>) -> Result<Response<Ack>, Status> {
        require(&req, Role::Worker)?;
        let r = req.into_inner();
        check_worker(&r.worker_id)?;
        let outputs = check_files(&self.st, &r.outputs)?;
        let result = r.result.unwrap_or_default();
        if let Some(job_result::Outcome::EnergyplusFailed(f)) = &result.outcome {
            if f.error.len() > 1 << 20 {
                return Err(invalid("an EnergyPlus failure's error over 1 MiB"));
            }
        }
        let Some(job) = self.own_lease(r.lease_id, &r.worker_id)? else {
            return Ok(Response::new(Ack {}));
        };
        // What a finished job hands over is checked before it is recorded (and, for a
        // simulation, shared with every run with the same inputs).
        let (st, files, checked) = (self.st.clone(), outputs.clone(), result.clone());
        tokio::task::spawn_blocking(move || check_result(&st, &job, &files, &checked))
            .await
            .map_err(internal)?
            .map_err(|e| invalid(format!("lease {}: {e}", r.lease_id)))?;
        // Committed before the reply: a worker that hears "ok" may forget the job.
        let (o, shared) = self
            .st
            .store
            .complete_within(
                r.lease_id,
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
        require(&req, Role::Worker)?;
        let r = req.into_inner();
        check_worker(&r.worker_id)?;
        if self.own_lease(r.lease_id, &r.worker_id)?.is_none() {
            return Ok(Response::new(Ack {}));
        }
        let error: String = r.error.chars().take(8000).collect();
        let o = self
            .st
            .store
            .fail(r.lease_id, &error, r.requeue, self.st.config.max_failures)
            .map_err(internal)?;
        self.kick(o);
        Ok(Response::new(Ack {}))
    }

    async fn put_artifact(
        &self,
        req: Request<Streaming<Chunk>>,
    ) -> Result<Response<ArtifactInfo>, Status> {
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
        require(&req, Role::Client)?;
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
            let same = store.run(&id).map_err(internal)?.is_some_and(|run| {
                run.is_submission_of(&bundle_files, &surrogate, &r.portfolio, &r.building)
            });
            if same {
                return Ok(Response::new(SubmitReply {
                    run_id: id,
                    resumed: true,
                }));
            }
        }
        let id = format!("r{}", &crate::auth::random_token()[..10]);
        let st = self.st.clone();
        let (idc, files) = (id.clone(), bundle_files.clone());
        // Validate the way a run will load it: the project file, the model, the parameters,
        // the meters CSV and the weather.
        let project = tokio::task::spawn_blocking(move || -> Result<_, String> {
            let dir = st.run_dir(&idc);
            let pdir = dir.join("project");
            let pf = bundle::materialize(&files, &st.artifacts, &pdir)?;
            let project =
                bemcal_calibrate::Project::load_submitted(&pf).map_err(|e| e.to_string())?;
            bemcal_calibrate::load_inputs(&project).map_err(|e| e.to_string())?;
            Ok(project)
        })
        .await
        .map_err(internal)?;
        let project = match project {
            Ok(p) => p,
            Err(e) => {
                let dir = self.st.run_dir(&id);
                let _ = std::fs::remove_dir_all(&dir);
                let prefix = format!("{}/", dir.join("project").display());
                let msg = format!("invalid project: {}", e.replace(&prefix, ""));
                if r.portfolio.is_empty() {
                    return Err(invalid(msg));
                }
                // In a portfolio the building is reported as failed, with the loader's reason,
                // and the other buildings go on.
                let store = &self.st.store;
                store
                    .create_run(&id, &r.building, &bundle_files, &surrogate)
                    .map_err(internal)?;
                store
                    .set_portfolio(&id, &r.portfolio, &r.building)
                    .map_err(internal)?;
                store
                    .end_run(&id, RunState::Failed, Some(&msg))
                    .map_err(internal)?;
                return Ok(Response::new(SubmitReply {
                    run_id: id,
                    resumed: false,
                }));
            }
        };
        self.st
            .store
            .create_run(&id, &project.name, &bundle_files, &surrogate)
            .map_err(internal)?;
        if !r.portfolio.is_empty() {
            self.st
                .store
                .set_portfolio(&id, &r.portfolio, &r.building)
                .map_err(internal)?;
        }
        let _ = self.st.kick.send(id.clone());
        Ok(Response::new(SubmitReply {
            run_id: id,
            resumed: false,
        }))
    }

    async fn list_runs(
        &self,
        req: Request<ListRunsRequest>,
    ) -> Result<Response<ListRunsReply>, Status> {
        require(&req, Role::Client)?;
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
        require(&req, Role::Client)?;
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
        require(&req, Role::Client)?;
        let id = req.into_inner().run_id;
        check_run_id(&id)?;
        if self.st.store.run(&id).map_err(internal)?.is_none() {
            return Err(refuse(Code::NotFound, format!("no run {id:?}")));
        }
        self.st
            .store
            .end_run(&id, RunState::Cancelled, Some("cancelled by request"))
            .map_err(internal)?;
        let r = self
            .st
            .store
            .run(&id)
            .map_err(internal)?
            .ok_or_else(|| refuse(Code::NotFound, id))?;
        Ok(Response::new(self.status(&r, false)?))
    }
}

//! Attacks on a coordinator on loopback, each a reproduction of issue 21 or 68: the coordinator
//! survives, answers with a short clear error, leaks nothing and stores nothing bad; workers are
//! who their credentials say, and the audit trail records who did what.

mod common;

use std::path::Path;
use std::time::Duration;

use bemcal_client::client::{submit_project, upload, Client, Connect};
use bemcal_client::proto::{
    CompleteRequest, FileRef, HealthRequest, HeartbeatRequest, JobResult, JobState, LeaseRequest,
    ListRunsRequest, RegisterRequest, RunRequest, RunState, SubmitRequest,
};
use common::*;

const TOKEN: &str = "client-token-0123456789abcdef";
const WORKER_TOKEN: &str = "worker-token-0123456789abcdef";

/// A coordinator with separate client and worker tokens.
fn start(dir: &Path) -> (Proc, String) {
    let wt = dir.join("worker.token");
    std::fs::write(&wt, WORKER_TOKEN).unwrap();
    coordinator(
        &dir.join("data"),
        "127.0.0.1:0",
        TOKEN,
        &["--worker-token-file", wt.to_str().unwrap()],
    )
}

fn client(url: &str, token: &str) -> Client {
    Connect {
        url: url.into(),
        token: token.into(),
        tls_ca: None,
    }
    .client()
    .unwrap()
}

/// Registers a worker named `name` with the enrollment token `enroll`: its id and a client that
/// carries its own credential.
async fn register(url: &str, enroll: &str, name: &str) -> (String, Client) {
    let r = client(url, enroll)
        .register(RegisterRequest {
            name: name.into(),
            protocol: bemcal_client::PROTOCOL,
        })
        .await
        .unwrap()
        .into_inner();
    (r.worker_id, client(url, &r.credential))
}

/// A simulated point's file with the three outputs of [`small`]: `hours` of `value`, and `bad`
/// at hour 100 when given.
fn point_file(hours: usize, value: &str, bad: Option<&str>) -> String {
    let series: Vec<&str> = (0..hours)
        .map(|h| match (h, bad) {
            (100, Some(b)) => b,
            _ => value,
        })
        .collect();
    let s = series.join(",");
    format!(
        "{{\"values\": {{}}, \"outputs\": {{\"names\": [\"heating_kwh\", \"cooling_kwh\", \
         \"electricity_kwh\"], \"series\": [[{s}], [{s}], [{s}]]}}}}"
    )
}

/// The coordinator's audit trail in `data`, as `bemcal coordinator audit` prints it.
fn audit(data: &Path) -> String {
    let out = run_ok(
        bemcal()
            .args(["coordinator", "audit", "--last", "0", "--data"])
            .arg(data),
    );
    String::from_utf8(out.stdout).unwrap()
}

/// Meters that load: a year of constant hourly readings.
fn flat_meters() -> String {
    let mut s = String::from("timestamp,heating_kwh,cooling_kwh,electricity_kwh\n");
    let t0 = chrono::NaiveDate::from_ymd_opt(2021, 1, 1)
        .unwrap()
        .and_hms_opt(0, 0, 0)
        .unwrap();
    for h in 0..8760 {
        let t = t0 + chrono::Duration::hours(h);
        s.push_str(&format!("{},10,5,20\n", t.format("%Y-%m-%dT%H:%M")));
    }
    s
}

/// The small project in `dir` with `meters` as its meters file.
fn small(dir: &Path, meters: &str) -> std::path::PathBuf {
    std::fs::create_dir_all(dir).unwrap();
    std::fs::write(dir.join("model.toml"), common::small_model()).unwrap();
    std::fs::write(dir.join("meters.csv"), meters).unwrap();
    let p = dir.join("project.toml");
    std::fs::write(&p, small_project("attacked", 4)).unwrap();
    p
}

/// Uploads `files` (path, text) and submits them as a bundle.
async fn submit_raw(c: &mut Client, files: &[(&str, &str)]) -> Result<String, tonic::Status> {
    let mut bundle = vec![];
    for (path, text) in files {
        let sha = upload(c, text.as_bytes().to_vec()).await?;
        bundle.push(FileRef {
            path: path.to_string(),
            sha256: sha,
            size: text.len() as u64,
        });
    }
    let r = c
        .submit(SubmitRequest {
            bundle,
            ..Default::default()
        })
        .await?;
    Ok(r.into_inner().run_id)
}

fn alive(p: &mut Proc) -> bool {
    p.0.try_wait().unwrap().is_none()
}

#[test]
fn hostile_inputs_get_short_errors_and_the_coordinator_lives() {
    if !have_engine() {
        eprintln!("skipped: run `make setup` first");
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let (mut proc, url) = start(dir.path());
    let rt = bemcal_client::runtime().unwrap();
    rt.block_on(async {
        let mut c = client(&url, TOKEN);
        // A 3 MiB run id: refused in a short message, also by clients that hang up at once.
        let huge = "r".repeat(3 << 20);
        let e = c
            .get_run(RunRequest {
                run_id: huge.clone(),
            })
            .await
            .unwrap_err();
        assert_eq!(e.code(), tonic::Code::InvalidArgument);
        assert!(e.message().len() < 300, "{} bytes", e.message().len());
        for _ in 0..20 {
            let mut c = client(&url, TOKEN);
            let call = c.get_run(RunRequest {
                run_id: huge.clone(),
            });
            let _ = tokio::time::timeout(Duration::from_millis(1), call).await;
        }
        // A meters file with an unbalanced quote, and one with a 3 MiB cell.
        let cell = "9".repeat(3 << 20);
        for (name, bad) in [
            (
                "quote",
                "timestamp,heating_kwh\n\"2017-01-01T00:00,1\n".to_string(),
            ),
            (
                "cell",
                format!("timestamp,heating_kwh\n2017-01-01T00:00,{cell}\n"),
            ),
        ] {
            let p = small(&dir.path().join(name), &bad);
            let e = submit_project(&mut c, &p, None, Default::default())
                .await
                .unwrap_err();
            let msg = format!("{e:#}");
            assert!(msg.contains("meters.csv"), "{name}: {msg}");
            assert!(msg.len() < 1_200, "{name}: {} bytes", msg.len());
        }
        let h = c.health(HealthRequest {}).await.unwrap().into_inner();
        assert_eq!(h.queued_jobs, 0);
    });
    assert!(alive(&mut proc), "the coordinator died");
    // A refused submission leaves no run folder behind.
    let runs = dir.path().join("data/runs");
    let left = std::fs::read_dir(&runs).map_or(0, |d| d.count());
    assert_eq!(left, 0, "run folders left in {}", runs.display());
}

#[test]
fn a_submitted_project_reads_only_its_own_files() {
    if !have_engine() {
        eprintln!("skipped: run `make setup` first");
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let (mut proc, url) = start(dir.path());
    let model = common::small_model();
    let project = small_project("attacked", 4);
    let rt = bemcal_client::runtime().unwrap();
    rt.block_on(async {
        let mut c = client(&url, TOKEN);
        let cases = [
            (
                "meters outside the bundle",
                project.replace("file = \"meters.csv\"", "file = \"/proc/self/environ\""),
                "relative paths inside its folder",
            ),
            (
                "meters up the tree",
                project.replace("file = \"meters.csv\"", "file = \"../../coordinator.db\""),
                "relative paths inside its folder",
            ),
            (
                "a bundled weather path",
                project.replace(
                    "bundled:USA_CO_Golden-NREL.724666_TMY3.epw",
                    "bundled:/etc/hostname",
                ),
                "file name alone",
            ),
        ];
        for (what, text, expected) in cases {
            let e = submit_raw(
                &mut c,
                &[
                    ("project.toml", &text),
                    ("model.toml", &model),
                    ("meters.csv", "timestamp,heating_kwh\n"),
                ],
            )
            .await
            .unwrap_err();
            assert_eq!(e.code(), tonic::Code::InvalidArgument, "{what}");
            assert!(e.message().contains(expected), "{what}: {}", e.message());
            assert!(!e.message().contains(TOKEN), "{what}: the token leaked");
            assert!(
                !e.message().contains("BEMCAL"),
                "{what}: the environment leaked"
            );
        }
    });
    assert!(alive(&mut proc));
    let runs = dir.path().join("data/runs");
    assert_eq!(std::fs::read_dir(&runs).map_or(0, |d| d.count()), 0);
}

#[test]
fn leases_belong_to_their_worker_and_outputs_are_checked() {
    if !have_engine() {
        eprintln!("skipped: run `make setup` first");
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let (mut proc, url) = start(dir.path());
    let p = small(&dir.path().join("project"), &flat_meters());
    let rt = bemcal_client::runtime().unwrap();
    let (id1, id2) = rt.block_on(async {
        let mut c = client(&url, TOKEN);
        let mut enroll = client(&url, WORKER_TOKEN);
        // Roles: the enrollment token cannot submit, a client cannot register a worker.
        let e = submit_project(&mut enroll, &p, None, Default::default())
            .await
            .unwrap_err();
        assert!(format!("{e:#}").contains("client token"), "{e:#}");
        let run = submit_project(&mut c, &p, None, Default::default())
            .await
            .unwrap()
            .run_id;
        let hello = RegisterRequest {
            name: "w1".into(),
            protocol: bemcal_client::PROTOCOL,
        };
        let e = c.register(hello).await.unwrap_err();
        assert_eq!(e.code(), tonic::Code::PermissionDenied);
        // Two workers of the same name are two workers, each with its own credential.
        let (id1, mut w1) = register(&url, WORKER_TOKEN, "w1").await;
        let (id2, mut w2) = register(&url, WORKER_TOKEN, "w1").await;
        assert!(id1.starts_with("w1-") && id2.starts_with("w1-") && id1 != id2);
        let lease = |id: &str| LeaseRequest {
            worker_id: id.into(),
            free_slots: 1,
            protocol: bemcal_client::PROTOCOL,
        };
        // Neither a client nor the enrollment token leases; a worker leases only as itself.
        for mut other in [c.clone(), enroll.clone()] {
            let e = other.lease(lease(&id1)).await.unwrap_err();
            assert_eq!(e.code(), tonic::Code::PermissionDenied, "{e:?}");
        }
        let e = w2.lease(lease(&id1)).await.unwrap_err();
        assert_eq!(e.code(), tonic::Code::PermissionDenied);
        assert!(
            e.message().contains("not this credential's worker"),
            "{e:?}"
        );
        // A worker of another protocol revision (0: built before the field) gets no job, and
        // is told why.
        for old in [0, bemcal_client::PROTOCOL + 1] {
            let e = w1
                .lease(LeaseRequest {
                    protocol: old,
                    ..lease(&id1)
                })
                .await
                .unwrap_err();
            assert_eq!(e.code(), tonic::Code::FailedPrecondition);
            let (theirs, ours) = (
                format!("speaks protocol {old} "),
                format!(") protocol {}:", bemcal_client::PROTOCOL),
            );
            assert!(
                e.message().contains(&theirs) && e.message().contains(&ours),
                "{}",
                e.message()
            );
        }
        // The design's simulations are queued once the driver has laid out the run.
        let mut job = None;
        for _ in 0..120 {
            job = w1.lease(lease(&id1)).await.unwrap().into_inner().job;
            if job.is_some() {
                break;
            }
            tokio::time::sleep(Duration::from_millis(250)).await;
        }
        let job = job.expect("no job queued within 30 s");
        let id = job.lease_id;
        // Another worker can neither heartbeat nor complete the lease, whether it sends its own
        // id or the lease holder's.
        let forged = |worker: &str, outputs: Vec<FileRef>, result: JobResult| CompleteRequest {
            worker_id: worker.into(),
            lease_id: id,
            outputs,
            result: Some(result),
        };
        let Some(bemcal_client::proto::job::Kind::Simulate(s)) = &job.kind else {
            panic!("the first job is a design simulation");
        };
        let year = point_file(8760, "1.5", None);
        let year_file = FileRef {
            path: format!("simulations/point_{:03}.json", s.point),
            sha256: upload(&mut w2, year.as_bytes().to_vec()).await.unwrap(),
            size: year.len() as u64,
        };
        for claimed in [&id2, &id1] {
            let hb = HeartbeatRequest {
                worker_id: claimed.clone(),
                lease_id: id,
            };
            let e = w2.heartbeat(hb).await.unwrap_err();
            assert_eq!(e.code(), tonic::Code::PermissionDenied, "{claimed}: {e:?}");
            let e = w2
                .complete(forged(
                    claimed,
                    vec![year_file.clone()],
                    JobResult::simulated(Some(1.0)),
                ))
                .await
                .unwrap_err();
            assert_eq!(e.code(), tonic::Code::PermissionDenied, "{claimed}: {e:?}");
        }
        // The lease's own worker cannot hand over what a simulation does not produce: another
        // kind of job's result, or none.
        for result in [JobResult::chains(100), JobResult::default()] {
            let e = w1.complete(forged(&id1, vec![], result)).await.unwrap_err();
            assert_eq!(e.code(), tonic::Code::InvalidArgument, "{}", e.message());
            assert!(
                e.message()
                    .contains("a simulate job completed with the result"),
                "{}",
                e.message()
            );
        }
        // Nor a point file that is not a year of finite, plausible hours: a day, a year with
        // NaN (JSON has none: a worker's serde_json writes null), a negative meter.
        let bad = [
            (point_file(24, "1.5", None), "24 hours simulated, not 8760"),
            (
                point_file(8760, "1.5", Some("NaN")),
                "not a simulated point's file",
            ),
            (
                point_file(8760, "1.5", Some("null")),
                "not a simulated point's file",
            ),
            (
                point_file(8760, "1.5", Some("-5.0")),
                "hour 100 holds -5 kWh",
            ),
        ];
        for (text, says) in bad {
            let file = FileRef {
                sha256: upload(&mut w1, text.as_bytes().to_vec()).await.unwrap(),
                size: text.len() as u64,
                ..year_file.clone()
            };
            let e = w1
                .complete(forged(&id1, vec![file], JobResult::simulated(Some(1.0))))
                .await
                .unwrap_err();
            assert_eq!(e.code(), tonic::Code::InvalidArgument, "{says}: {e:?}");
            assert!(e.message().contains(says), "{says}: {}", e.message());
        }
        // Nothing forged was recorded: the job is still leased, and its own worker may go on.
        let hb = HeartbeatRequest {
            worker_id: id1.clone(),
            lease_id: id,
        };
        assert!(w1.heartbeat(hb.clone()).await.unwrap().into_inner().ok);
        let st = c
            .get_run(RunRequest {
                run_id: run.clone(),
            })
            .await
            .unwrap()
            .into_inner();
        assert_eq!(st.client, "default");
        let j = st.jobs.iter().find(|j| j.job_id == job.job_id).unwrap();
        assert_eq!(j.state(), JobState::Leased);
        assert_eq!(j.worker, id1);
        assert!(j.result_json.is_empty());
        // The same project submitted again while its run runs (an interrupted client coming
        // back) is that run, its lease untouched; once the run has ended, a new one.
        let again = submit_project(&mut c, &p, None, Default::default())
            .await
            .unwrap();
        assert_eq!((again.run_id.as_str(), again.resumed), (run.as_str(), true));
        assert!(w1.heartbeat(hb).await.unwrap().into_inner().ok);
        c.cancel(RunRequest {
            run_id: run.clone(),
        })
        .await
        .unwrap();
        let after = submit_project(&mut c, &p, None, Default::default())
            .await
            .unwrap();
        assert!(after.run_id != run && !after.resumed, "{after:?}");
        // Nothing forged was cached either: the new run's simulations (the same inputs) all
        // wait for a worker.
        let mut jobs = vec![];
        for _ in 0..120 {
            jobs = c
                .get_run(RunRequest {
                    run_id: after.run_id.clone(),
                })
                .await
                .unwrap()
                .into_inner()
                .jobs;
            if !jobs.is_empty() {
                break;
            }
            tokio::time::sleep(Duration::from_millis(250)).await;
        }
        assert!(!jobs.is_empty(), "the new run laid out no jobs within 30 s");
        assert!(
            jobs.iter()
                .all(|j| !j.cached && j.state() == JobState::Queued),
            "{jobs:?}"
        );
        c.cancel(RunRequest {
            run_id: after.run_id,
        })
        .await
        .unwrap();
        (id1, id2)
    });
    assert!(alive(&mut proc));
    // The audit trail says who did what: the submissions, the registrations, the lease, and
    // each refusal with the worker and the reason.
    let trail = audit(&dir.path().join("data"));
    let has = |needle: &str| {
        assert!(
            trail.lines().any(|l| l.contains(needle)),
            "no {needle:?} in the audit trail:\n{trail}"
        )
    };
    has("submit client:default run=");
    has("resume client:default run=");
    has("cancel client:default run=");
    has("refuse-register client:default");
    has("register enroller: worker w1-");
    has(&format!("lease worker:{id1} run="));
    has("refuse-lease client:default");
    has(&format!("refuse-lease worker:{id2}"));
    has(&format!("refuse-complete worker:{id2} lease="));
    has(&format!("the lease is worker {id1}'s"));
    has(&format!("is not this credential's worker ({id2})"));
    has(&format!("refuse-complete worker:{id1} run="));
    has("24 hours simulated, not 8760");
}

#[test]
fn the_artifact_store_keeps_to_its_limit() {
    let dir = tempfile::tempdir().unwrap();
    // 2,000 bytes.
    let (mut proc, url) = coordinator(
        &dir.path().join("data"),
        "127.0.0.1:0",
        TOKEN,
        &["--max-store-gb", "0.000002"],
    );
    let rt = bemcal_client::runtime().unwrap();
    rt.block_on(async {
        let mut c = client(&url, TOKEN);
        let a = upload(&mut c, vec![b'a'; 1_500]).await.unwrap();
        let e = upload(&mut c, vec![b'b'; 1_500]).await.unwrap_err();
        assert_eq!(e.code(), tonic::Code::ResourceExhausted);
        assert!(e.message().contains("2000-byte limit"), "{}", e.message());
        // What is stored stays there and can be sent again.
        assert_eq!(upload(&mut c, vec![b'a'; 1_500]).await.unwrap(), a);
    });
    assert!(alive(&mut proc));
}

#[test]
fn a_run_past_its_quota_of_output_bytes_fails_saying_so() {
    if !have_engine() {
        eprintln!("skipped: run `make setup` first");
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let wt = dir.path().join("worker.token");
    std::fs::write(&wt, WORKER_TOKEN).unwrap();
    // A simulated point of a year, the same size whichever design point it is: two fit in
    // the run's quota, the third does not.
    let size = point_file(8760, "0.5", None).len();
    let quota = size * 5 / 2;
    let gb = format!("{}", quota as f64 / 1e9);
    let (mut proc, url) = coordinator(
        &dir.path().join("data"),
        "127.0.0.1:0",
        TOKEN,
        &[
            "--worker-token-file",
            wt.to_str().unwrap(),
            "--max-run-gb",
            &gb,
        ],
    );
    let p = small(&dir.path().join("project"), &flat_meters());
    let rt = bemcal_client::runtime().unwrap();
    rt.block_on(async {
        let mut c = client(&url, TOKEN);
        let (id, mut w) = register(&url, WORKER_TOKEN, "w1").await;
        let run = submit_project(&mut c, &p, None, Default::default())
            .await
            .unwrap()
            .run_id;
        let lease = LeaseRequest {
            worker_id: id.clone(),
            free_slots: 1,
            protocol: bemcal_client::PROTOCOL,
        };
        let mut completed = 0;
        for _ in 0..240 {
            let Some(job) = w.lease(lease.clone()).await.unwrap().into_inner().job else {
                tokio::time::sleep(Duration::from_millis(250)).await;
                continue;
            };
            let Some(bemcal_client::proto::job::Kind::Simulate(s)) = &job.kind else {
                panic!("the design's simulations come first");
            };
            let point = point_file(8760, &format!("{}.5", s.point % 10), None);
            assert_eq!(point.len(), size);
            let sha = upload(&mut w, point.as_bytes().to_vec()).await.unwrap();
            // The size a worker claims is checked against the file's: a quota counts bytes.
            let e = w
                .complete(CompleteRequest {
                    worker_id: id.clone(),
                    lease_id: job.lease_id,
                    outputs: vec![FileRef {
                        path: format!("simulations/point_{:03}.json", s.point),
                        sha256: sha.clone(),
                        size: 1,
                    }],
                    result: Some(JobResult::simulated(Some(1.0))),
                })
                .await
                .unwrap_err();
            assert!(
                e.message()
                    .contains(&format!("holds {} bytes, not 1", point.len())),
                "{}",
                e.message()
            );
            w.complete(CompleteRequest {
                worker_id: id.clone(),
                lease_id: job.lease_id,
                outputs: vec![FileRef {
                    path: format!("simulations/point_{:03}.json", s.point),
                    sha256: sha,
                    size: point.len() as u64,
                }],
                result: Some(JobResult::simulated(Some(1.0))),
            })
            .await
            .unwrap();
            completed += 1;
            if completed == 3 {
                break;
            }
        }
        assert_eq!(completed, 3, "three simulations were leased");
        let st = c
            .get_run(RunRequest {
                run_id: run.clone(),
            })
            .await
            .unwrap()
            .into_inner();
        assert_eq!(st.state(), RunState::Failed, "{st:?}");
        assert!(
            st.error
                .contains(&format!("per-run quota of {quota} bytes (--max-run-gb)")),
            "{}",
            st.error
        );
        let done = st
            .jobs
            .iter()
            .filter(|j| j.state() == JobState::Done)
            .count();
        assert_eq!(done, 2, "the third point's outputs are not recorded");
        // Nothing more is handed out for it.
        assert!(w.lease(lease).await.unwrap().into_inner().job.is_none());
    });
    assert!(alive(&mut proc));
}

/// Revoking one worker stops that worker alone: its credential is refused within a second, its
/// lease is given back (not counted as a failure), and the other worker goes on; the operator's
/// revocation and the refusals are in the audit trail.
#[test]
fn a_revoked_worker_is_refused_and_the_others_go_on() {
    if !have_engine() {
        eprintln!("skipped: run `make setup` first");
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let (mut proc, url) = start(dir.path());
    let data = dir.path().join("data");
    let p = small(&dir.path().join("project"), &flat_meters());
    let rt = bemcal_client::runtime().unwrap();
    let (id1, id2) = rt.block_on(async {
        let mut c = client(&url, TOKEN);
        let (id1, mut w1) = register(&url, WORKER_TOKEN, "w1").await;
        let (id2, mut w2) = register(&url, WORKER_TOKEN, "w2").await;
        let run = submit_project(&mut c, &p, None, Default::default())
            .await
            .unwrap()
            .run_id;
        let lease = |id: &str| LeaseRequest {
            worker_id: id.into(),
            free_slots: 1,
            protocol: bemcal_client::PROTOCOL,
        };
        let mut job = None;
        for _ in 0..120 {
            job = w1.lease(lease(&id1)).await.unwrap().into_inner().job;
            if job.is_some() {
                break;
            }
            tokio::time::sleep(Duration::from_millis(250)).await;
        }
        let job = job.expect("no job queued within 30 s");
        let out = run_ok(
            bemcal()
                .args(["coordinator", "revoke-worker", "--data"])
                .arg(&data)
                .arg(&id1),
        );
        assert!(String::from_utf8_lossy(&out.stdout).contains("revoked"));
        // Within a second or two the coordinator refuses the credential.
        let hb = HeartbeatRequest {
            worker_id: id1.clone(),
            lease_id: job.lease_id,
        };
        let mut refused = None;
        for _ in 0..40 {
            match w1.heartbeat(hb.clone()).await {
                Ok(_) => tokio::time::sleep(Duration::from_millis(100)).await,
                Err(e) => {
                    refused = Some(e);
                    break;
                }
            }
        }
        let e = refused.expect("the revoked worker's heartbeat was still taken after 4 s");
        assert_eq!(e.code(), tonic::Code::Unauthenticated);
        assert!(e.message().contains("revoked"), "{e:?}");
        let e = w1.lease(lease(&id1)).await.unwrap_err();
        assert_eq!(e.code(), tonic::Code::Unauthenticated);
        // The other worker goes on, and gets the revoked worker's job back among the queued.
        let mut taken = vec![];
        for _ in 0..8 {
            match w2.lease(lease(&id2)).await.unwrap().into_inner().job {
                Some(j) => taken.push(j.job_id),
                None => break,
            }
        }
        assert!(
            taken.contains(&job.job_id),
            "{taken:?} lacks {}",
            job.job_id
        );
        let st = c
            .get_run(RunRequest {
                run_id: run.clone(),
            })
            .await
            .unwrap()
            .into_inner();
        assert_eq!(st.state(), RunState::Running, "{}", st.error);
        c.cancel(RunRequest { run_id: run }).await.unwrap();
        (id1, id2)
    });
    assert!(alive(&mut proc));
    let workers = run_ok(
        bemcal()
            .args(["coordinator", "workers", "--data"])
            .arg(&data),
    );
    let workers = String::from_utf8(workers.stdout).unwrap();
    let line = |id: &str| {
        workers
            .lines()
            .find(|l| l.starts_with(id))
            .unwrap_or("")
            .to_string()
    };
    assert!(
        line(&id1).contains(" ago ") && line(&id1).matches(" ago").count() == 2,
        "{workers}"
    );
    assert!(line(&id2).matches(" ago").count() == 1, "{workers}");
    let trail = audit(&data);
    for needle in [
        format!("revoke operator: worker {id1}"),
        format!("return worker:{id1}"),
        "the worker's credential was revoked".to_string(),
        format!("refuse-revoked worker:{id1}"),
        format!("lease worker:{id2}"),
    ] {
        assert!(trail.contains(&needle), "no {needle:?} in:\n{trail}");
    }
}

/// Named clients: each run records its client, each client runs at most its limit (another
/// client is not held back), the same project of another client is a run of its own, and the
/// refusal is in the audit trail.
#[test]
fn clients_have_names_and_their_own_limits() {
    if !have_engine() {
        eprintln!("skipped: run `make setup` first");
        return;
    }
    const ALICE: &str = "alice-token-0123456789abcdef";
    const BOB: &str = "bob-token-0123456789abcdef";
    let dir = tempfile::tempdir().unwrap();
    let tokens = dir.path().join("clients");
    std::fs::write(&tokens, format!("# the team\nalice {ALICE}\nbob {BOB}\n")).unwrap();
    let data = dir.path().join("data");
    let (mut proc, url) = coordinator(
        &data,
        "127.0.0.1:0",
        TOKEN,
        &[
            "--client-tokens",
            tokens.to_str().unwrap(),
            "--max-runs-per-client",
            "1",
        ],
    );
    let a = small(&dir.path().join("a"), &flat_meters());
    let b = small(
        &dir.path().join("b"),
        &flat_meters().replace(",10,5,20", ",11,5,20"),
    );
    let rt = bemcal_client::runtime().unwrap();
    rt.block_on(async {
        let (mut alice, mut bob) = (client(&url, ALICE), client(&url, BOB));
        let a1 = submit_project(&mut alice, &a, None, Default::default())
            .await
            .unwrap();
        let e = submit_project(&mut alice, &b, None, Default::default())
            .await
            .unwrap_err();
        let msg = format!("{e:#}");
        assert!(
            msg.contains("client alice has 1 run(s) running")
                && msg.contains("--max-runs-per-client 1"),
            "{msg}"
        );
        let b1 = submit_project(&mut bob, &b, None, Default::default())
            .await
            .unwrap();
        // Alice's project again is her run; Bob's project is not hers to resume.
        let again = submit_project(&mut alice, &a, None, Default::default())
            .await
            .unwrap();
        assert_eq!(
            again,
            bemcal_client::client::Submitted {
                resumed: true,
                ..a1.clone()
            }
        );
        alice
            .cancel(RunRequest {
                run_id: a1.run_id.clone(),
            })
            .await
            .unwrap();
        let b2 = submit_project(&mut alice, &b, None, Default::default())
            .await
            .unwrap();
        assert!(!b2.resumed && b2.run_id != b1.run_id, "{b2:?}");
        let runs = alice
            .list_runs(ListRunsRequest::default())
            .await
            .unwrap()
            .into_inner()
            .runs;
        let client_of = |id: &str| runs.iter().find(|r| r.run_id == id).unwrap().client.clone();
        assert_eq!(client_of(&a1.run_id), "alice");
        assert_eq!(client_of(&b1.run_id), "bob");
        assert_eq!(client_of(&b2.run_id), "alice");
        for (c, r) in [(&mut alice, b2), (&mut bob, b1)] {
            c.cancel(RunRequest { run_id: r.run_id }).await.unwrap();
        }
    });
    assert!(alive(&mut proc));
    let trail = audit(&data);
    for needle in [
        "submit client:alice run=",
        "refuse-submit client:alice: project attacked: client alice has 1 run(s) running",
        "submit client:bob run=",
        "resume client:alice run=",
        "cancel client:bob run=",
    ] {
        assert!(trail.contains(needle), "no {needle:?} in:\n{trail}");
    }
}

//! Attacks on a coordinator on loopback, each a reproduction of issue 21: the coordinator
//! survives, answers with a short clear error, leaks nothing and stores nothing bad.

mod common;

use std::path::Path;
use std::time::Duration;

use bemcal_client::client::{submit_project, upload, Client, Connect};
use bemcal_client::proto::{
    CompleteRequest, FileRef, HealthRequest, HeartbeatRequest, JobResult, JobState, LeaseRequest,
    RunRequest, RunState, SubmitRequest,
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
    rt.block_on(async {
        let mut c = client(&url, TOKEN);
        let mut w = client(&url, WORKER_TOKEN);
        // Roles: a worker cannot submit, a client cannot lease.
        let e = submit_project(&mut w, &p, None, Default::default())
            .await
            .unwrap_err();
        assert!(format!("{e:#}").contains("client token"), "{e:#}");
        let run = submit_project(&mut c, &p, None, Default::default())
            .await
            .unwrap()
            .run_id;
        let lease = |id: &str| LeaseRequest {
            worker_id: id.into(),
            free_slots: 1,
            protocol: bemcal_client::PROTOCOL,
        };
        let e = c.lease(lease("w1")).await.unwrap_err();
        assert_eq!(e.code(), tonic::Code::PermissionDenied);
        // A worker of another protocol revision (0: built before the field) gets no job, and
        // is told why.
        for old in [0, bemcal_client::PROTOCOL + 1] {
            let e = w
                .lease(LeaseRequest {
                    protocol: old,
                    ..lease("w0")
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
            job = w.lease(lease("w1")).await.unwrap().into_inner().job;
            if job.is_some() {
                break;
            }
            tokio::time::sleep(Duration::from_millis(250)).await;
        }
        let job = job.expect("no job queued within 30 s");
        let id = job.lease_id;
        // Another worker can neither heartbeat nor complete the lease.
        let hb = HeartbeatRequest {
            worker_id: "w2".into(),
            lease_id: id,
        };
        assert_eq!(
            w.heartbeat(hb).await.unwrap_err().code(),
            tonic::Code::PermissionDenied
        );
        let forged = |worker: &str, outputs: Vec<FileRef>, result: JobResult| CompleteRequest {
            worker_id: worker.into(),
            lease_id: id,
            outputs,
            result: Some(result),
        };
        let e = w
            .complete(forged("w2", vec![], JobResult::simulated(Some(1.0))))
            .await
            .unwrap_err();
        assert_eq!(e.code(), tonic::Code::PermissionDenied);
        // The lease's own worker cannot hand over what a simulation does not produce: another
        // kind of job's result, or none.
        for result in [JobResult::chains(100), JobResult::default()] {
            let e = w.complete(forged("w1", vec![], result)).await.unwrap_err();
            assert_eq!(e.code(), tonic::Code::InvalidArgument, "{}", e.message());
            assert!(
                e.message()
                    .contains("a simulate job completed with the result"),
                "{}",
                e.message()
            );
        }
        let point =
            "{\"values\": {}, \"outputs\": {\"names\": [\"heating_kwh\"], \"series\": [[1.0]]}}";
        let sha = upload(&mut w, point.as_bytes().to_vec()).await.unwrap();
        let Some(bemcal_client::proto::job::Kind::Simulate(s)) = &job.kind else {
            panic!("the first job is a design simulation");
        };
        let file = FileRef {
            path: format!("simulations/point_{:03}.json", s.point),
            sha256: sha,
            size: point.len() as u64,
        };
        let e = w
            .complete(forged("w1", vec![file], JobResult::simulated(Some(1.0))))
            .await
            .unwrap_err();
        assert!(e.message().contains("hours simulated"), "{}", e.message());
        // Nothing forged was recorded: the job is still leased, and its own worker may go on.
        let hb = HeartbeatRequest {
            worker_id: "w1".into(),
            lease_id: id,
        };
        assert!(w.heartbeat(hb).await.unwrap().into_inner().ok);
        let st = c
            .get_run(RunRequest {
                run_id: run.clone(),
            })
            .await
            .unwrap()
            .into_inner();
        let j = st.jobs.iter().find(|j| j.job_id == job.job_id).unwrap();
        assert_eq!(j.state(), JobState::Leased);
        assert!(j.result_json.is_empty());
        // The same project submitted again while its run runs (an interrupted client coming
        // back) is that run, its lease untouched; once the run has ended, a new one.
        let again = submit_project(&mut c, &p, None, Default::default())
            .await
            .unwrap();
        assert_eq!((again.run_id.as_str(), again.resumed), (run.as_str(), true));
        let hb = HeartbeatRequest {
            worker_id: "w1".into(),
            lease_id: id,
        };
        assert!(w.heartbeat(hb).await.unwrap().into_inner().ok);
        c.cancel(RunRequest {
            run_id: run.clone(),
        })
        .await
        .unwrap();
        let after = submit_project(&mut c, &p, None, Default::default())
            .await
            .unwrap();
        assert!(after.run_id != run && !after.resumed, "{after:?}");
        c.cancel(RunRequest {
            run_id: after.run_id,
        })
        .await
        .unwrap();
    });
    assert!(alive(&mut proc));
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
    // 1,500 bytes a run.
    let (mut proc, url) = coordinator(
        &dir.path().join("data"),
        "127.0.0.1:0",
        TOKEN,
        &[
            "--worker-token-file",
            wt.to_str().unwrap(),
            "--max-run-gb",
            "0.0000015",
        ],
    );
    let p = small(&dir.path().join("project"), &flat_meters());
    let rt = bemcal_client::runtime().unwrap();
    rt.block_on(async {
        let mut c = client(&url, TOKEN);
        let mut w = client(&url, WORKER_TOKEN);
        let run = submit_project(&mut c, &p, None, Default::default())
            .await
            .unwrap()
            .run_id;
        let lease = LeaseRequest {
            worker_id: "w1".into(),
            free_slots: 1,
            protocol: bemcal_client::PROTOCOL,
        };
        // A simulated point of a day (537 bytes): two fit, the third does not.
        let mut completed = 0;
        for _ in 0..240 {
            let Some(job) = w.lease(lease.clone()).await.unwrap().into_inner().job else {
                tokio::time::sleep(Duration::from_millis(250)).await;
                continue;
            };
            let Some(bemcal_client::proto::job::Kind::Simulate(s)) = &job.kind else {
                panic!("the design's simulations come first");
            };
            let series: Vec<String> = (0..24).map(|h| format!("{}.{h:02}", s.point)).collect();
            let point = format!(
                "{{\"values\": {{}}, \"outputs\": {{\"names\": [\"heating_kwh\", \"cooling_kwh\", \
                 \"electricity_kwh\"], \"series\": [[{0}], [{0}], [{0}]]}}}}",
                series.join(", ")
            );
            let sha = upload(&mut w, point.as_bytes().to_vec()).await.unwrap();
            // The size a worker claims is checked against the file's: a quota counts bytes.
            let e = w
                .complete(CompleteRequest {
                    worker_id: "w1".into(),
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
                worker_id: "w1".into(),
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
                .contains("per-run quota of 1500 bytes (--max-run-gb)"),
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

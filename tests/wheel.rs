//! Issue 22, the Python route: the wheel this repository builds (maturin, `pyproject.toml`)
//! installs with pip into a fresh virtual environment outside the repository, and the `bemcal`
//! it installs finds EnergyPlus, ONNX Runtime, PyTorch and ArviZ in that environment:
//! `--version`, `doctor` (each component tried for real), the bundled example's `params`, one
//! EnergyPlus run, and `import bemcal`.
//!
//! The environment is seeded with the packages `make setup` installed from the package index
//! into `.venv` (the same pins), hard-linked, and pip then installs the wheel with
//! `--no-index`: it must find every dependency the wheel declares already satisfied, and `pip
//! check` must find them consistent. Unpacking PyTorch and its CUDA libraries a second time
//! (5.8 GB) took 121 s of this test on 2 cores; `BEMCAL_WHEEL_FROM_INDEX=1` still installs
//! them from the index, as a user's `pip install` does. Skipped (with a message) when
//! `make setup` has not run (maturin comes with it).

use std::path::{Path, PathBuf};
use std::process::Command;

mod common;
use common::repo;

/// Runs `cmd` in `cwd` with no bemcal or Python variable inherited; returns its stdout.
fn run_in(cwd: &Path, cmd: &mut Command) -> String {
    for var in [
        "BEMCAL_VENV",
        "BEMCAL_ENERGYPLUS",
        "BEMCAL_PYTHON",
        "BEMCAL_BIN",
        "ORT_DYLIB_PATH",
        "PYTHONPATH",
        "VIRTUAL_ENV",
    ] {
        cmd.env_remove(var);
    }
    let out = cmd.current_dir(cwd).output().unwrap();
    assert!(
        out.status.success(),
        "{cmd:?} failed:\n{}\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// The Cargo profile this test was built with (`target/debug` is the `dev` profile's folder),
/// so that maturin reuses the build `make test` made instead of compiling the workspace again
/// in another profile.
fn cargo_profile() -> String {
    let bin = Path::new(env!("CARGO_BIN_EXE_bemcal"));
    let dir = bin.parent().and_then(Path::file_name).unwrap();
    match dir.to_str().unwrap() {
        "debug" => "dev".to_string(),
        other => other.to_string(),
    }
}

/// Whether `var` is one Cargo (or nextest) sets for a test process about the test's own
/// package (`CARGO_MANIFEST_DIR`, `CARGO_PKG_*`, `CARGO_BIN_EXE_*`, ...), as opposed to Cargo's
/// configuration (`CARGO_HOME`, `CARGO_PROFILE_*`, ...).
fn set_for_the_test(var: &str) -> bool {
    [
        "CARGO_MANIFEST_DIR",
        "CARGO_MANIFEST_PATH",
        "CARGO_CRATE_NAME",
        "CARGO_BIN_NAME",
        "CARGO_PRIMARY_PACKAGE",
        "CARGO_TARGET_TMPDIR",
        "OUT_DIR",
    ]
    .contains(&var)
        || ["CARGO_PKG_", "CARGO_BIN_EXE_", "NEXTEST"]
            .iter()
            .any(|p| var.starts_with(p))
}

/// The wheel to install: the one `make test` built before the tests started (in
/// `BEMCAL_TEST_WHEEL_DIR`), else one built here into `into`.
///
/// `make test` builds it first because maturin runs Cargo, and Cargo links `target/release/bemcal`
/// again on every build, fresh or not: a test starting `bemcal` in that moment fails with "No
/// such file or directory". So a run that builds the wheel here must run this test alone
/// (nextest's default profile does); with the wheel built first, the `ci` profile `make test`
/// uses runs it beside the others.
fn the_wheel(into: &Path) -> PathBuf {
    match std::env::var_os("BEMCAL_TEST_WHEEL_DIR") {
        Some(dir) => one_wheel_in(&repo().join(dir)),
        None => build_wheel(into),
    }
}

/// The one `.whl` file in `dir`.
fn one_wheel_in(dir: &Path) -> PathBuf {
    let wheels: Vec<PathBuf> = std::fs::read_dir(dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "whl"))
        .collect();
    assert_eq!(wheels.len(), 1, "{}: {wheels:?}", dir.display());
    wheels.into_iter().next().unwrap()
}

/// Builds the wheel with the repository environment's maturin; returns its path.
///
/// Without the test's own Cargo variables: build scripts that read one of them (ring's reads
/// `CARGO_MANIFEST_DIR`) would see it change, and Cargo would compile them and everything above
/// them again (ring, rustls, tonic, the client, coordinator, worker and binary: 264 s of the
/// wheel test on 2 cores), then once more at the next `cargo build`.
fn build_wheel(into: &Path) -> PathBuf {
    let maturin = repo().join(".venv/bin/maturin");
    let mut cmd = Command::new(maturin);
    for (var, _) in std::env::vars_os() {
        if var.to_str().is_some_and(set_for_the_test) {
            cmd.env_remove(var);
        }
    }
    run_in(
        &repo(),
        cmd.args(["build", "--profile", &cargo_profile(), "--out"])
            .arg(into),
    );
    one_wheel_in(into)
}

/// The Python packages of the repository's `.venv` (installed by `make setup` from the package
/// index) hard-linked into the fresh environment `env`, where it has none of that name: pip
/// there sees them as installed, with their metadata. Directories are made, files linked (a
/// copy where a link cannot be made); nothing in `.venv` is written.
fn seed_from_the_repository_environment(env: &Path) {
    let site = |python: &Path| -> PathBuf {
        let out = run_in(
            &repo(),
            Command::new(python).args([
                "-c",
                "import sysconfig; print(sysconfig.get_paths()['purelib'])",
            ]),
        );
        PathBuf::from(out.trim())
    };
    let (from, into) = (
        site(&repo().join(".venv/bin/python")),
        site(&env.join("bin/python")),
    );
    assert_eq!(
        from.file_name(),
        into.file_name(),
        "the same site-packages layout"
    );
    let from_parent = from.parent().unwrap().file_name();
    assert_eq!(
        from_parent,
        into.parent().unwrap().file_name(),
        "`python3` is the Python of .venv (set BEMCAL_WHEEL_FROM_INDEX=1 otherwise)"
    );
    fn link_tree(from: &Path, into: &Path) {
        if from.is_dir() {
            std::fs::create_dir_all(into).unwrap();
            for e in std::fs::read_dir(from).unwrap() {
                let e = e.unwrap();
                link_tree(&e.path(), &into.join(e.file_name()));
            }
        } else if std::fs::hard_link(from, into).is_err() {
            std::fs::copy(from, into).unwrap();
        }
    }
    for e in std::fs::read_dir(&from).unwrap() {
        let e = e.unwrap();
        if !into.join(e.file_name()).exists() {
            link_tree(&e.path(), &into.join(e.file_name()));
        }
    }
}

#[test]
fn the_wheel_installs_into_a_fresh_environment_and_finds_its_dependencies() {
    if !repo().join(".venv/bin/maturin").exists() {
        eprintln!("skipping: no maturin in .venv (run `make setup`)");
        return;
    }
    // Inside target/: on the file system of `.venv`, whose files are hard-linked.
    let tmp = tempfile::tempdir_in(repo().join("target")).unwrap();
    let wheel = the_wheel(&tmp.path().join("wheels"));
    let env = tmp.path().join("env");
    let work = tmp.path().join("work");
    std::fs::create_dir_all(&work).unwrap();
    run_in(
        &work,
        Command::new("python3").args(["-m", "venv"]).arg(&env),
    );
    let from_index = std::env::var_os("BEMCAL_WHEEL_FROM_INDEX").is_some();
    if !from_index {
        seed_from_the_repository_environment(&env);
    }
    let mut pip = Command::new(env.join("bin/pip"));
    // --no-compile: no bytecode compiled at install (Python compiles a module when it is first
    // imported); it halves the install's time here and installs the same files.
    pip.args([
        "install",
        "--quiet",
        "--no-compile",
        "--disable-pip-version-check",
    ]);
    if !from_index {
        pip.arg("--no-index");
    }
    run_in(&work, pip.arg(&wheel));
    let check = run_in(
        &work,
        Command::new(env.join("bin/pip")).args(["check", "--disable-pip-version-check"]),
    );
    assert!(check.contains("No broken requirements"), "{check}");

    let bemcal = env.join("bin/bemcal");
    let version = run_in(&work, Command::new(&bemcal).arg("--version"));
    assert!(version.starts_with("bemcal "), "{version}");

    // Every component found in the environment the binary is installed in, and tried.
    let doctor = run_in(&work, Command::new(&bemcal).arg("doctor"));
    eprintln!("{doctor}");
    let prefix = env.canonicalize().unwrap();
    for (component, expect) in [
        ("Python environment", prefix.display().to_string()),
        ("EnergyPlus", "Version 25.2.0".to_string()),
        ("ONNX Runtime", "(loaded)".to_string()),
        ("PyTorch", "torch 2.15.0".to_string()),
        ("ArviZ", "arviz 0.23".to_string()),
    ] {
        let line = doctor
            .lines()
            .find(|l| l.starts_with(component))
            .unwrap_or_else(|| panic!("no {component} line:\n{doctor}"));
        assert!(
            line.contains(" ok ") && line.contains(&expect),
            "{component}: {line}"
        );
        if component != "Python environment" {
            assert!(line.contains(&prefix.display().to_string()), "{line}");
        }
    }

    // The bundled example, written out and read, then simulated once by EnergyPlus.
    run_in(
        &work,
        Command::new(&bemcal).args(["example", "office", "--out", "office"]),
    );
    let params = run_in(
        &work,
        Command::new(&bemcal).args(["params", "--model", "office/model.toml"]),
    );
    assert!(
        params.contains("wall_insulation_conductivity") && params.contains("schedule_weekday_01"),
        "{params}"
    );
    let sim = run_in(
        &work,
        Command::new(&bemcal).args([
            "simulate",
            "--model",
            "office/small.toml",
            "--weather",
            "bundled:USA_CO_Golden-NREL.724666_TMY3.epw",
            "--out",
            "small.csv",
            "--json",
        ]),
    );
    let annual: serde_json::Value = serde_json::from_str(sim.trim()).unwrap();
    assert!(
        annual["annual_kwh"]["electricity_kwh"].as_f64().unwrap() > 1000.0,
        "{sim}"
    );

    // The Python module, and the binary it runs.
    let py = run_in(
        &work,
        Command::new(env.join("bin/python")).args([
            "-c",
            "import bemcal; print(bemcal.__version__); print(bemcal.binary())",
        ]),
    );
    let mut lines = py.lines();
    assert_eq!(lines.next(), Some("0.1.0"), "{py}");
    assert_eq!(
        Path::new(lines.next().unwrap()).canonicalize().unwrap(),
        bemcal.canonicalize().unwrap(),
        "{py}"
    );
}

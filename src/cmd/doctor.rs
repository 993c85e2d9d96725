//! `bemcal doctor`: where bemcal finds what it runs (Python environment, EnergyPlus, ONNX Runtime,
//! PyTorch, the Python module's ArviZ), each tried for real; exit status 1 if one is missing.

use std::process::Command;

use bemcal_energyplus::Engine;

/// Check the environment bemcal runs in: the Python environment it found and how, EnergyPlus
/// (its version), ONNX Runtime (loaded), PyTorch and ArviZ (imported). Runs nothing else.
#[derive(Debug, clap::Args)]
pub struct Args {}

/// One component's state.
struct Found {
    what: &'static str,
    /// `Ok(where and version)` or `Err(why not)`.
    result: Result<String, String>,
    /// Whether a calibration needs it (ArviZ is only for `bemcal.load` and `export`).
    required: bool,
}

pub fn run(_: Args) -> anyhow::Result<()> {
    let venv = bemcal_pyenv::find_venv();
    let python = venv.as_deref().map(bemcal_pyenv::python);
    let mut found = vec![Found {
        what: "Python environment",
        result: venv
            .as_ref()
            .map(|v| v.display().to_string())
            .ok_or_else(|| bemcal_pyenv::INSTALL_HINT.to_string()),
        required: true,
    }];
    found.push(Found {
        what: "EnergyPlus",
        result: Engine::locate().map_err(|e| e.to_string()).and_then(|e| {
            let version = first_line(Command::new(&e.executable).arg("--version"))?;
            Ok(format!("{} ({version})", e.executable.display()))
        }),
        required: true,
    });
    found.push(Found {
        what: "EnergyPlus sandbox",
        result: Ok(bemcal_energyplus::confine::Sandbox::probe()
            .describe()
            .to_string()),
        required: false,
    });
    found.push(Found {
        what: "ONNX Runtime",
        result: bemcal_surrogate::ort_library_path()
            .and_then(|p| bemcal_surrogate::ort_environment().map(|_| p))
            .map(|p| format!("{} (loaded)", p.display()))
            .map_err(|e| e.to_string()),
        required: true,
    });
    for (what, module, required) in [("PyTorch", "torch", true), ("ArviZ", "arviz", false)] {
        let result = match &python {
            None => Err("no Python environment".to_string()),
            Some(py) => first_line(Command::new(py).args([
                "-W",
                "ignore",
                "-c",
                &format!("import {module}; print({module}.__version__)"),
            ]))
            .map(|v| format!("{module} {v} ({})", py.display())),
        };
        found.push(Found {
            what,
            result,
            required,
        });
    }
    let mut missing = 0;
    for f in &found {
        match &f.result {
            Ok(s) => println!("{:<20} ok       {s}", f.what),
            Err(e) => {
                let level = if f.required { "MISSING" } else { "absent" };
                missing += usize::from(f.required);
                println!("{:<20} {level:<8} {}", f.what, bemcal_excerpt::shorten(e));
            }
        }
    }
    if missing > 0 {
        anyhow::bail!("{missing} required component(s) missing");
    }
    Ok(())
}

/// The first line a command prints, or why it could not run.
fn first_line(cmd: &mut Command) -> Result<String, String> {
    let out = cmd
        .output()
        .map_err(|e| format!("cannot start {:?}: {e}", cmd.get_program()))?;
    let text = String::from_utf8_lossy(&out.stdout);
    let line = text.lines().next().unwrap_or("").trim().to_string();
    if !out.status.success() {
        let err = String::from_utf8_lossy(&out.stderr);
        return Err(format!(
            "{:?} failed: {}",
            cmd.get_program(),
            err.lines().last().unwrap_or("")
        ));
    }
    Ok(line)
}

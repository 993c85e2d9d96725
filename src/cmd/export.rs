//! `bemcal export`: a calibration's posterior as an ArviZ InferenceData file (netCDF), written
//! by the `bemcal` Python module (`bemcal.load`) in bemcal's Python environment.

use std::ffi::OsStr;
use std::path::PathBuf;

use anyhow::{anyhow, bail};

/// Write a calibration's InferenceData (posterior, sample stats, prior, observed data,
/// posterior predictive, weather) to a file that ArviZ and xarray open.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// A finished calibration's output folder.
    pub out_dir: PathBuf,
    /// File format (netcdf: ArviZ's `InferenceData.to_netcdf`, one group per netCDF group).
    #[arg(long, value_parser = ["netcdf"], default_value = "netcdf")]
    pub format: String,
    /// File to write (default: OUT_DIR/posterior.nc).
    #[arg(long)]
    pub to: Option<PathBuf>,
}

pub fn run(a: Args) -> anyhow::Result<()> {
    if !a.out_dir.join("summary.json").is_file() {
        bail!(
            "{}: no summary.json (is it the --out folder of a finished calibration?)",
            a.out_dir.display()
        );
    }
    let to = a.to.unwrap_or_else(|| a.out_dir.join("posterior.nc"));
    let venv = bemcal_pyenv::find_venv().ok_or_else(|| {
        anyhow!(
            "no Python environment found; {}",
            bemcal_pyenv::INSTALL_HINT
        )
    })?;
    let args: [&OsStr; 6] = [
        "export".as_ref(),
        a.out_dir.as_os_str(),
        "--format".as_ref(),
        a.format.as_ref(),
        "--to".as_ref(),
        to.as_os_str(),
    ];
    let status = bemcal_pyenv::run_module(&venv, &args)?;
    if status != 0 {
        bail!(
            "writing {} failed (python -m bemcal export: status {status})",
            to.display()
        );
    }
    Ok(())
}

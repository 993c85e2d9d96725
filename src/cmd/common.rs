//! Helpers shared by subcommands (loading models, writing hourly CSV).

use bemcal_weather::grid::GridYear;
use std::io::Write;
use std::path::Path;

use anyhow::Context;
use bemcal_energyplus::{Engine, HourlyOutputs, Model, RunOptions, Runner};

/// Finds EnergyPlus and loads a model file.
pub fn load_model(path: &Path) -> anyhow::Result<(Model, Runner)> {
    let runner = runner()?;
    let model = Model::load(path, runner.idd())?;
    Ok((model, runner))
}

/// Finds EnergyPlus: a runner with the default options.
pub fn runner() -> anyhow::Result<Runner> {
    Ok(Runner::new(Engine::locate()?, RunOptions::default())?)
}

/// The year a model simulates (its `year`, 2021 by default).
pub fn model_year(model: &Model) -> GridYear {
    model.calendar().year
}

/// Writes `timestamp,<output>...` with ISO 8601 local, hour-beginning timestamps, in time order
/// (the grid's slots: no 29 February; a year from April lists April first).
pub fn write_hourly_csv(
    path: &Path,
    year: GridYear,
    outputs: &HourlyOutputs,
) -> anyhow::Result<()> {
    let file =
        std::fs::File::create(path).with_context(|| format!("creating {}", path.display()))?;
    let mut w = std::io::BufWriter::new(file);
    writeln!(w, "timestamp,{}", outputs.names.join(","))?;
    for t in year.chronological(outputs.hours()) {
        write!(w, "{}", year.slot_time(t).format("%Y-%m-%dT%H:%M"))?;
        for s in &outputs.series {
            write!(w, ",{:.6}", s[t])?;
        }
        writeln!(w)?;
    }
    w.flush()?;
    Ok(())
}

/// A weather reference: a path, or `bundled:FILE` from EnergyPlus's `WeatherData` (EnergyPlus
/// is looked for only then).
pub fn resolve_weather_ref(reference: &str) -> anyhow::Result<std::path::PathBuf> {
    if !reference.starts_with("bundled:") {
        return Ok(reference.into());
    }
    Ok(bemcal_calibrate::weather_reference(
        reference,
        Path::new("."),
        &Engine::locate()?,
    )?)
}

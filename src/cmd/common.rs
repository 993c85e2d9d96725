//! Helpers shared by subcommands (loading models, writing hourly CSV).

use std::io::Write;
use std::path::Path;

use anyhow::Context;
use bemcal_energyplus::{Engine, HourlyOutputs, Model, RunOptions, Runner};

/// Finds EnergyPlus and loads a model file.
pub fn load_model(path: &Path) -> anyhow::Result<(Model, Runner)> {
    let engine = Engine::locate()?;
    let runner = Runner::new(engine, RunOptions::default())?;
    let model = Model::load(path, runner.idd())?;
    Ok((model, runner))
}

/// The calendar year a model simulates (2021 for IDF models without a spec).
pub fn model_year(model: &Model) -> i32 {
    model.spec().map_or(2021, |s| s.year)
}

/// Writes `timestamp,<output>...` with ISO 8601 local, hour-beginning timestamps.
pub fn write_hourly_csv(path: &Path, year: i32, outputs: &HourlyOutputs) -> anyhow::Result<()> {
    let file =
        std::fs::File::create(path).with_context(|| format!("creating {}", path.display()))?;
    let mut w = std::io::BufWriter::new(file);
    writeln!(w, "timestamp,{}", outputs.names.join(","))?;
    let start = chrono::NaiveDate::from_ymd_opt(year, 1, 1)
        .context("bad year")?
        .and_hms_opt(0, 0, 0)
        .context("bad time")?;
    for t in 0..outputs.hours() {
        let ts = start + chrono::Duration::hours(t as i64);
        write!(w, "{}", ts.format("%Y-%m-%dT%H:%M"))?;
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

//! `bemcal simulate`: one annual EnergyPlus run of a model at given parameter values.

use std::path::PathBuf;

use anyhow::Context;
use bemcal_energyplus::params::parse_assignments;

use super::common;

/// Run EnergyPlus once and write the hourly outputs (kWh) as CSV.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Model file: a building spec (TOML) or an `[idf]` parameter map.
    #[arg(long)]
    pub model: PathBuf,
    /// EnergyPlus weather file (EPW), or `bundled:FILE` from EnergyPlus's WeatherData folder
    /// (e.g. `bundled:USA_CO_Golden-NREL.724666_TMY3.epw`).
    #[arg(long)]
    pub weather: String,
    /// Parameter values from a file: a calibration's `calibrated.toml` (NAME = VALUE lines) or
    /// its `summary.json` (its calibrated values); --set overrides them.
    #[arg(long)]
    pub values: Option<PathBuf>,
    /// Parameter value, NAME=VALUE (repeatable); others stay at their prior mode.
    #[arg(long = "set", value_name = "NAME=VALUE")]
    pub set: Vec<String>,
    /// Output CSV: timestamp (ISO 8601 local time, hour beginning) and one column per output.
    #[arg(long)]
    pub out: PathBuf,
    /// Keep the EnergyPlus run directory here instead of a temporary one.
    #[arg(long)]
    pub keep: Option<PathBuf>,
    /// Print the annual totals as JSON.
    #[arg(long)]
    pub json: bool,
}

pub fn run(a: Args) -> anyhow::Result<()> {
    let (model, runner) = common::load_model(&a.model)?;
    let mut given = match &a.values {
        Some(p) => read_values(p)?,
        None => Default::default(),
    };
    given.extend(parse_assignments(&a.set)?);
    let idf = model.instantiate(&given, runner.idd())?;
    let tmp = tempfile::tempdir().context("creating a temporary run directory")?;
    let dir = a.keep.clone().unwrap_or_else(|| tmp.path().join("run"));
    let weather = common::resolve_weather_ref(&a.weather)?;
    let result = runner.run(&idf, &weather, model.outputs(), &dir)?;
    common::write_hourly_csv(&a.out, common::model_year(&model), &result.outputs)?;
    let totals = result.outputs.totals();
    if a.json {
        let obj: serde_json::Map<String, serde_json::Value> = totals
            .iter()
            .map(|(n, t)| (n.clone(), serde_json::json!(t)))
            .collect();
        println!(
            "{}",
            serde_json::json!({"annual_kwh": obj, "seconds": result.seconds, "warnings": result.warnings})
        );
    } else {
        println!(
            "annual totals ({:.1} s, {} warnings):",
            result.seconds, result.warnings
        );
        for (n, t) in totals {
            println!("  {n:<18} {t:>14.0} kWh");
        }
        println!("wrote {}", a.out.display());
    }
    Ok(())
}

/// Parameter values from `calibrated.toml` (name = value) or `summary.json` (calibrated_values).
fn read_values(
    path: &std::path::Path,
) -> anyhow::Result<bemcal_energyplus::params::ParameterValues> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    if path.extension().is_some_and(|e| e == "json") {
        #[derive(serde::Deserialize)]
        struct Calibrated {
            #[serde(with = "bemcal_calibrate::named")]
            calibrated_values: Vec<(String, f64)>,
        }
        let s: Calibrated = serde_json::from_str(&text).with_context(|| {
            format!(
                "{}: expected a calibration's summary.json with calibrated_values",
                path.display()
            )
        })?;
        return Ok(s.calibrated_values.into_iter().collect());
    }
    let table: std::collections::BTreeMap<String, f64> =
        toml::from_str(&text).with_context(|| {
            format!(
                "{}: expected NAME = NUMBER lines (a calibration's calibrated.toml)",
                path.display()
            )
        })?;
    Ok(table.into_iter().collect())
}

//! `bemcal predict`: evaluates a trained surrogate for one parameter vector over a weather year.

use std::path::PathBuf;

use anyhow::{bail, Context};
use bemcal_surrogate::predict::{hour_beginning_timestamps, write_csv};
use bemcal_surrogate::Surrogate;
use bemcal_weather::{Calendar, Epw, Holidays, HourlyFeatures};

/// Predict hourly meters with a trained surrogate (parameters not set are at their prior mode).
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Surrogate directory written by `bemcal train`.
    #[arg(long)]
    pub surrogate: PathBuf,
    /// EPW weather file, or `bundled:FILE` from EnergyPlus's WeatherData folder.
    #[arg(long)]
    pub weather: String,
    /// Year for day types and timestamps: `2021`, or `2021-04` for twelve months from April
    /// (US federal holidays; `--model` takes the model's calendar instead).
    #[arg(long, default_value = "2021")]
    pub year: bemcal_weather::grid::GridYear,
    /// Model file whose calendar to use (a building spec or an `[idf]` model file): its year,
    /// holidays and the day types of its `day_types_file` (pre-calibration's `calendar.csv`),
    /// as the calibration did.
    #[arg(long, conflicts_with = "year")]
    pub model: Option<PathBuf>,
    /// Parameter value, NAME=VALUE (repeatable).
    #[arg(long = "set", value_name = "NAME=VALUE")]
    pub set: Vec<String>,
    /// Output CSV: timestamp,<output>... (8,760 rows, hour beginning, local standard time).
    #[arg(long)]
    pub out: PathBuf,
    /// ONNX Runtime intra-op threads.
    #[arg(long, default_value_t = 2)]
    pub threads: usize,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let surrogate = Surrogate::load(&args.surrogate, args.threads)?;
    let meta = surrogate.meta().clone();
    let mut values = meta.param_modes();
    for s in &args.set {
        let (name, value) = s
            .split_once('=')
            .with_context(|| format!("--set '{s}': expected NAME=VALUE"))?;
        let Some(i) = meta.params.iter().position(|p| p.name == name.trim()) else {
            bail!(
                "--set '{s}': unknown parameter '{}'; the surrogate has: {}",
                name.trim(),
                meta.params
                    .iter()
                    .map(|p| p.name.as_str())
                    .collect::<Vec<_>>()
                    .join(", ")
            );
        };
        let v: f64 = value
            .trim()
            .parse()
            .with_context(|| format!("--set '{s}': '{}' is not a number", value.trim()))?;
        let p = &meta.params[i];
        if !(p.min..=p.max).contains(&v) {
            eprintln!(
                "warning: {} = {v} is outside the training range [{}, {}]",
                p.name, p.min, p.max
            );
        }
        values[i] = v;
    }
    let calendar = match &args.model {
        Some(path) => {
            let text = std::fs::read_to_string(path)
                .with_context(|| format!("cannot read {}", path.display()))?;
            bemcal_energyplus::Model::calendar_from_toml(&text, path)?
        }
        None => Calendar::new(args.year, Holidays::UsFederal),
    };
    let epw = Epw::read(&super::common::resolve_weather_ref(&args.weather)?)?;
    let features = HourlyFeatures::from_epw(&epw, &calendar);
    let mut ev = surrogate.bind(&features)?;
    let y = ev.evaluate(&values)?;
    let ts = hour_beginning_timestamps(
        calendar.year,
        epw.hours.iter().map(|h| (h.month, h.day, h.hour)),
    );
    write_csv(&args.out, &ts, &meta.output_names(), y)
        .with_context(|| format!("cannot write {}", args.out.display()))?;
    println!("wrote {} ({} rows)", args.out.display(), ts.len());
    for (k, name) in meta.output_names().iter().enumerate() {
        println!(
            "  {name}: {:.1} kWh/year",
            y.column(k).iter().map(|v| *v as f64).sum::<f64>()
        );
    }
    Ok(())
}

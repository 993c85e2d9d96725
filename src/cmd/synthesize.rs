//! `bemcal synthesize`: measurements from EnergyPlus at hidden "true" parameters, with noise and
//! a gap, for demonstrations and tests.

use std::path::PathBuf;

use anyhow::Context;
use bemcal_calibrate::synth::{measurements, InjectedBias, SynthOptions};
use bemcal_energyplus::params::parse_assignments;

use super::common;

/// Simulate a model at given (true) parameters and write noisy hourly meters with a gap.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Model file: a building spec (TOML) or an `[idf]` parameter map.
    #[arg(long)]
    pub model: PathBuf,
    /// EnergyPlus weather file (EPW) of the synthetic year, or `bundled:FILE` from
    /// EnergyPlus's WeatherData folder.
    #[arg(long)]
    pub weather: String,
    /// True parameter value, NAME=VALUE (repeatable); others at their prior mode.
    #[arg(long = "set", value_name = "NAME=VALUE")]
    pub set: Vec<String>,
    /// Draw the true values of all parameters from their priors with this seed instead.
    #[arg(long)]
    pub truth_seed: Option<u64>,
    /// With --truth-seed: draw only these parameters (repeatable); the others stay at their
    /// prior modes, as a calibration of only these assumes.
    #[arg(long, value_name = "NAME", requires = "truth_seed")]
    pub draw: Vec<String>,
    /// Multiplicative noise sd.
    #[arg(long, default_value_t = 0.05)]
    pub noise: f64,
    /// Missing hours, START:END (hours of the year); default 15 July - 15 August.
    #[arg(long)]
    pub gap: Option<String>,
    /// A known model-form error, METER=AMPLITUDE: adds AMPLITUDE x the meter's annual mean x an
    /// hour-of-day x season pattern (1 in 9-17 h, 0.3 otherwise; x0.5 Dec-Feb, x1.5 Jun-Aug) to
    /// the meter column METER (e.g. `electricity_kwh=0.2`) before the noise: a building the model
    /// cannot be, with the difference known (`[mcmc] discrepancy` must carry it).
    #[arg(long, value_name = "METER=AMPLITUDE")]
    pub bias: Option<String>,
    /// Seed of the noise.
    #[arg(long, default_value_t = 42)]
    pub seed: u64,
    /// Meters CSV to write.
    #[arg(long)]
    pub out: PathBuf,
    /// Where to write the true values (JSON).
    #[arg(long)]
    pub truth: Option<PathBuf>,
}

pub fn run(a: Args) -> anyhow::Result<()> {
    let (model, runner) = common::load_model(&a.model)?;
    let mut given = parse_assignments(&a.set)?;
    if let Some(seed) = a.truth_seed {
        let plan = bemcal_calibrate::plan::Plan::new(&model, &a.draw, &Default::default())?;
        let d = bemcal_calibrate::design::make_design(&plan, &model, 1, seed, 0)?;
        for (n, v) in plan.calibrated.iter().zip(&d.points[0]) {
            given.entry(n.clone()).or_insert(*v);
        }
    }
    let values = model.values(&given)?;
    let idf = model.instantiate(&values, runner.idd())?;
    let tmp = tempfile::tempdir()?;
    let weather = common::resolve_weather_ref(&a.weather)?;
    let r = runner.run(&idf, &weather, model.outputs(), &tmp.path().join("truth"))?;
    let mut opts = SynthOptions {
        relative_noise: a.noise,
        seed: a.seed,
        ..Default::default()
    };
    if let Some(g) = &a.gap {
        let (s, e) = g.split_once(':').context("--gap expects START:END")?;
        opts.gap = Some((s.parse()?, e.parse()?));
    }
    if let Some(b) = &a.bias {
        opts.bias = Some(injected_bias(b, &r.outputs, common::model_year(&model))?);
    }
    let m = measurements(&r.outputs, &opts);
    common::write_hourly_csv(&a.out, common::model_year(&model), &m)?;
    if let Some(p) = &a.truth {
        std::fs::write(p, serde_json::to_string_pretty(&values)?)?;
    }
    println!("wrote {} (EnergyPlus {:.1} s)", a.out.display(), r.seconds);
    Ok(())
}

/// `--bias METER=AMPLITUDE` against the simulated meters' column names.
fn injected_bias(
    spec: &str,
    outputs: &bemcal_energyplus::HourlyOutputs,
    year: bemcal_weather::grid::GridYear,
) -> anyhow::Result<InjectedBias> {
    let (meter, amplitude) = spec
        .split_once('=')
        .with_context(|| format!("--bias expects METER=AMPLITUDE, got {spec:?}"))?;
    let amplitude: f64 = amplitude
        .trim()
        .parse()
        .with_context(|| format!("--bias {spec:?}: AMPLITUDE must be a number"))?;
    let j = outputs
        .names
        .iter()
        .position(|n| n == meter.trim())
        .with_context(|| {
            format!(
                "--bias {spec:?}: no meter column {:?}; the model writes {}",
                meter.trim(),
                outputs.names.join(", ")
            )
        })?;
    Ok(InjectedBias::hour_season(
        j,
        amplitude,
        year,
        outputs.hours(),
    ))
}

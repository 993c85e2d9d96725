//! `bemcal simulate`: one annual EnergyPlus run of a model at given parameter values.

use std::path::PathBuf;

use anyhow::Context;
use bemcal_energyplus::params::parse_assignments;

use super::common;

/// Run EnergyPlus once and write the hourly outputs (kWh) as CSV.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Model file: a building spec (TOML) or an `[idf]` parameter map.
    #[arg(long, required_unless_present = "project", conflicts_with = "project")]
    pub model: Option<PathBuf>,
    /// A calibration's project file instead of --model: its model as the calibration loaded it
    /// (with the schedule intervals of its `priors` file) and, without --weather, its weather
    /// (the metered year's EPW where it has `[measured_weather]`).
    #[arg(long)]
    pub project: Option<PathBuf>,
    /// EnergyPlus weather file (EPW), or `bundled:FILE` from EnergyPlus's WeatherData folder
    /// (e.g. `bundled:USA_CO_Golden-NREL.724666_TMY3.epw`); with --project, the project's
    /// weather by default.
    #[arg(long, required_unless_present = "project")]
    pub weather: Option<String>,
    /// Parameter values from a file: a calibration's `calibrated.toml` (NAME = VALUE lines),
    /// its `summary.json` (its calibrated values), or its `draws.csv` with --draw (any
    /// posterior draw, over the `calibrated.toml` beside it for the parameters not sampled);
    /// --set overrides them.
    #[arg(long)]
    pub values: Option<PathBuf>,
    /// With --values draws.csv: the posterior draw, CHAIN:DRAW as draws.csv numbers them
    /// (e.g. 2:417).
    #[arg(long, value_name = "CHAIN:DRAW", requires = "values")]
    pub draw: Option<String>,
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
    let (model, runner, project_weather) = match (&a.project, &a.model) {
        (Some(project), _) => {
            let (model, runner, weather) = model_of_project(project)?;
            (model, runner, Some(weather))
        }
        (None, Some(model)) => {
            let (model, runner) = common::load_model(model)?;
            (model, runner, None)
        }
        (None, None) => anyhow::bail!("simulate needs --model or --project"),
    };
    let mut given = match &a.values {
        Some(p) => read_values(p, a.draw.as_deref())?,
        None => Default::default(),
    };
    given.extend(parse_assignments(&a.set)?);
    let idf = model.instantiate(&given, runner.idd())?;
    let tmp = tempfile::tempdir().context("creating a temporary run directory")?;
    let dir = a.keep.clone().unwrap_or_else(|| tmp.path().join("run"));
    let weather = match (&a.weather, project_weather) {
        (Some(w), _) => common::resolve_weather_ref(w)?,
        (None, Some(w)) => w,
        (None, None) => anyhow::bail!("simulate needs --weather with --model"),
    };
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

/// The model of a calibration's project as the calibration loads it (`priors` applied), its
/// runner, and the weather it simulates with.
fn model_of_project(
    path: &std::path::Path,
) -> anyhow::Result<(bemcal_energyplus::Model, bemcal_energyplus::Runner, PathBuf)> {
    let project = bemcal_calibrate::Project::load(path)?;
    let runner = common::runner()?;
    let model = bemcal_calibrate::load_model(&project, &runner)?;
    let (weather, _) =
        bemcal_calibrate::weather_for(&project, runner.engine(), common::model_year(&model))?;
    Ok((model, runner, weather))
}

/// Parameter values from `calibrated.toml` (name = value), `summary.json` (calibrated_values)
/// or `draws.csv` (the draw `draw` names).
fn read_values(
    path: &std::path::Path,
    draw: Option<&str>,
) -> anyhow::Result<bemcal_energyplus::params::ParameterValues> {
    let is_csv = path.extension().is_some_and(|e| e == "csv");
    anyhow::ensure!(
        draw.is_none() || is_csv,
        "--draw picks a row of a calibration's draws.csv, not of {}",
        path.display()
    );
    if is_csv {
        let draw = draw.with_context(|| {
            format!(
                "{}: a draws file needs --draw CHAIN:DRAW (which posterior draw)",
                path.display()
            )
        })?;
        let which = parse_draw(draw)?;
        let draws = bemcal_report::io::read_draws(path)?;
        let values = draw_values(&draws, which).with_context(|| path.display().to_string())?;
        // draws.csv holds the calibrated parameters only: the fixed ones (and those a
        // `calibrate = [...]` subset or priors.toml set) come from calibrated.toml beside it.
        let beside = path.with_file_name("calibrated.toml");
        let mut all = if beside.is_file() {
            read_values(&beside, None)?
        } else {
            eprintln!(
                "note: no calibrated.toml beside {}: the parameters the calibration did not \
                 sample stay at their prior modes here (set them with --set)",
                path.display()
            );
            Default::default()
        };
        all.extend(values);
        return Ok(all);
    }
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

/// `--draw CHAIN:DRAW`.
fn parse_draw(which: &str) -> anyhow::Result<(usize, u64)> {
    which
        .split_once(':')
        .and_then(|(c, d)| {
            Some((
                c.trim().parse::<usize>().ok()?,
                d.trim().parse::<u64>().ok()?,
            ))
        })
        .with_context(|| {
            format!(
                "--draw {}: expected CHAIN:DRAW, two whole numbers such as 0:250",
                bemcal_excerpt::excerpt(which, 40)
            )
        })
}

/// The calibrated parameters' values of draw `(chain, draw)` (as `draws.csv` numbers them) of
/// a calibration's draws.
fn draw_values(
    draws: &bemcal_report::io::Draws,
    (chain, draw): (usize, u64),
) -> anyhow::Result<Vec<(String, f64)>> {
    // CHAIN as the file numbers its chains (from 1 in CmdStan's).
    let offset = draws.numbering.first();
    let index = chain.checked_sub(offset);
    index
        .and_then(|c| draws.parameters_at(c, draw))
        .with_context(|| {
            let numbers = index
                .and_then(|c| draws.numbers.get(c))
                .unwrap_or(&draws.numbers[0]);
            let first = numbers.first().copied().unwrap_or_default();
            let last = numbers.last().copied().unwrap_or_default();
            format!(
                "no draw {chain}:{draw}: the file has chains {offset} to {} and draws {first} to \
             {last} per chain ({} each)",
                draws.chains.len() - 1 + offset,
                draws.len()
            )
        })
}

#[cfg(test)]
mod tests {
    use super::*;

    const DRAWS: &str = "chain,draw,lighting_power_density,cooling_setpoint_occupied,\
sigma_delta_heating_kwh,log_posterior,accept_stat__,stepsize__,n_leapfrog__,divergent__
0,0,12.0,25.2,3.1,-8554.7,1,1.09,3,0
0,1,12.5,24.4,3.0,-8554.8,1,1.19,3,0
1,0,13.0,23.0,2.9,-8555.0,0.9,1.1,7,0
1,1,13.5,22.5,2.8,-8556.0,0.8,1.1,7,0
";

    /// `draw_values` of a draws file's text; an error with the folder written as `DIR`.
    fn draw_of(text: &str, which: &str) -> Result<Vec<(String, f64)>, String> {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("draws.csv");
        std::fs::write(&p, text).unwrap();
        let shown =
            |e: anyhow::Error| format!("{e:#}").replace(&dir.path().display().to_string(), "DIR");
        let which = parse_draw(which).map_err(shown)?;
        let draws = bemcal_report::io::read_draws(&p).map_err(|e| shown(e.into()))?;
        draw_values(&draws, which).map_err(shown)
    }

    /// CHAIN is the file's own chain number: from 1 in a CmdStan-numbered file.
    #[test]
    fn a_draw_of_a_file_numbered_from_one_is_named_as_the_file_numbers_it() {
        let from_one = "chain,draw,a\n1,0,1.0\n1,1,2.0\n2,0,3.0\n2,1,4.0\n";
        assert_eq!(
            draw_of(from_one, "2:1").unwrap(),
            vec![("a".to_string(), 4.0)]
        );
        let e = draw_of(from_one, "0:0").unwrap_err();
        assert!(e.contains("chains 1 to 2"), "{e}");
    }

    #[test]
    fn a_draw_of_draws_csv_gives_its_parameters_only() {
        assert_eq!(
            draw_of(DRAWS, "1:0").unwrap(),
            vec![
                ("lighting_power_density".to_string(), 13.0),
                ("cooling_setpoint_occupied".to_string(), 23.0)
            ]
        );
        let e = draw_of(DRAWS, "2:0").unwrap_err();
        assert!(e.contains("chains 0 to 1 and draws 0 to 1"), "{e}");
        let e = draw_of(DRAWS, "first").unwrap_err();
        assert!(e.contains("CHAIN:DRAW"), "{e}");
        let bad = DRAWS.replace("13.0,23.0", "13.0,inf");
        let e = draw_of(&bad, "1:0").unwrap_err();
        assert!(
            e.contains(
                "DIR/draws.csv: line 4, column 'cooling_setpoint_occupied': an infinite value"
            ),
            "{e}"
        );
        let e = draw_of("a,b\n1,2\n", "0:0").unwrap_err();
        assert!(e.contains("missing column 'chain'"), "{e}");
        let e = draw_of("chain,draw,a\n", "0:0").unwrap_err();
        assert!(e.contains("header only"), "{e}");
    }
}

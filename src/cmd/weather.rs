//! `bemcal weather`: an EPW of a metered year from measured weather (NOAA ISD-lite files or a
//! CSV of a station), merged onto the site's typical-year EPW.

use std::path::PathBuf;

use anyhow::{bail, Context};
use bemcal_weather::measured::{BuildReport, Field, Stamp};
use bemcal_weather::station::{CsvColumn, CsvSpec, Source, TimeBasis, Unit};

/// Build the EPW of a metered year from measured weather.
///
/// Observations are placed in the hours of the year in local standard time (the TMY file's
/// zone), gaps up to --max-gap hours interpolated, longer ones filled from the TMY file, global
/// horizontal radiation split into direct and diffuse by Erbs' model; every field no station
/// measures stays the TMY file's. Writes OUT and OUT with `.json` (what was measured, filled).
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The site's typical-year EPW (a path, or bundled:FILE from EnergyPlus's WeatherData).
    #[arg(long)]
    pub tmy: String,
    /// Year of the file to build (the metered year): `2017`, or `2017-04` for twelve months
    /// from April 2017 (January-March then hold 2018's weather).
    #[arg(long)]
    pub year: bemcal_weather::grid::GridYear,
    /// NOAA ISD-lite station-year files (UTC, gzipped or not); give the next year's too for
    /// the last hours of the year in local time.
    #[arg(long = "isd-lite", num_args = 1.., conflicts_with = "csv")]
    pub isd_lite: Vec<PathBuf>,
    /// A CSV of measured weather (with --column, --time-column, --time-zone).
    #[arg(long)]
    pub csv: Option<PathBuf>,
    /// A CSV column: NAME=FIELD:UNIT, FIELD one of dry_bulb, dew_point, rel_humidity,
    /// pressure (station), wind_direction, wind_speed, global_horizontal, sky_cover; UNIT one of
    /// C F K % Pa hPa kPa inHg m/s km/h mph kn W/m2 deg tenths oktas (repeatable).
    #[arg(long = "column", value_name = "NAME=FIELD:UNIT")]
    pub columns: Vec<String>,
    /// The CSV's time-stamp column.
    #[arg(long, default_value = "timestamp")]
    pub time_column: String,
    /// The CSV's time-stamp format (chrono, e.g. "%m/%d/%Y %H:%M"); ISO 8601 by default.
    #[arg(long)]
    pub time_format: Option<String>,
    /// The CSV's time: utc, local_standard, or an IANA zone with its daylight saving
    /// (America/Denver).
    #[arg(long, default_value = "utc")]
    pub time_zone: String,
    /// What a CSV stamp means: instant, interval_ending, interval_beginning.
    #[arg(long, default_value = "instant")]
    pub stamp: String,
    /// Interval of interval-mean CSV rows, minutes (for interval_beginning).
    #[arg(long, default_value_t = 60)]
    pub interval_min: u32,
    /// Longest gap, hours, filled by linear interpolation; longer ones come from the TMY file.
    #[arg(long, default_value_t = 6)]
    pub max_gap: usize,
    /// The EPW to write.
    #[arg(long)]
    pub out: PathBuf,
}

fn parse_column(s: &str) -> anyhow::Result<CsvColumn> {
    let (name, rest) = s
        .split_once('=')
        .with_context(|| format!("--column '{s}': expected NAME=FIELD:UNIT"))?;
    let (field, unit) = rest
        .split_once(':')
        .with_context(|| format!("--column '{s}': expected NAME=FIELD:UNIT"))?;
    let field: Field = serde_json::from_value(serde_json::json!(field))
        .with_context(|| format!("--column '{s}': unknown field '{field}'"))?;
    let unit: Unit = serde_json::from_value(serde_json::json!(unit))
        .with_context(|| format!("--column '{s}': unknown unit '{unit}'"))?;
    Ok(CsvColumn {
        column: name.to_string(),
        field,
        unit,
    })
}

fn source(a: &Args) -> anyhow::Result<Source> {
    if !a.isd_lite.is_empty() {
        return Ok(Source::IsdLite(a.isd_lite.clone()));
    }
    let Some(file) = &a.csv else {
        bail!("give the measured weather: --isd-lite FILE... or --csv FILE --column ...");
    };
    if a.columns.is_empty() {
        bail!("--csv needs at least one --column NAME=FIELD:UNIT");
    }
    let stamp: Stamp = serde_json::from_value(serde_json::json!(a.stamp)).with_context(|| {
        format!(
            "--stamp '{}': expected instant, interval_ending or interval_beginning",
            a.stamp
        )
    })?;
    let spec = CsvSpec {
        timestamp_column: a.time_column.clone(),
        timestamp_format: a.time_format.clone(),
        time_zone: a
            .time_zone
            .parse::<TimeBasis>()
            .map_err(|e| anyhow::anyhow!("--time-zone: {e}"))?,
        stamp,
        columns: a
            .columns
            .iter()
            .map(|c| parse_column(c))
            .collect::<anyhow::Result<_>>()?,
    };
    Ok(Source::Csv {
        file: file.clone(),
        spec,
    })
}

pub fn run(a: Args) -> anyhow::Result<()> {
    let tmy = super::common::resolve_weather_ref(&a.tmy)?;
    let (text, report) = source(&a)?.build_epw(&tmy, a.year, a.max_gap, a.interval_min)?;
    std::fs::write(&a.out, text).with_context(|| format!("writing {}", a.out.display()))?;
    let json = a.out.with_extension("json");
    std::fs::write(&json, serde_json::to_string_pretty(&report)?)
        .with_context(|| format!("writing {}", json.display()))?;
    print_report(&report);
    println!("wrote {} and {}", a.out.display(), json.display());
    Ok(())
}

fn print_report(r: &BuildReport) {
    println!(
        "{} for {}: {} observations, {} outside the year{}",
        r.source,
        r.year,
        r.observations,
        r.outside_year,
        if r.leap_day_dropped {
            "; February 29 left out (8,760-hour file)"
        } else {
            ""
        }
    );
    println!(
        "  {:<18} {:>9} {:>13} {:>9} {:>14} {:>12}",
        "field", "measured", "interpolated", "from TMY", "longest TMY h", "implausible"
    );
    for f in &r.fields {
        if let Some(from) = &f.derived_from {
            println!("  {:<18} computed from {from}", f.field.name());
            continue;
        }
        println!(
            "  {:<18} {:>9} {:>13} {:>9} {:>14} {:>12}",
            f.field.name(),
            f.measured_h,
            f.interpolated_h,
            f.from_tmy_h,
            f.longest_tmy_run_h,
            f.implausible
        );
    }
    println!(
        "  solar radiation: {}",
        match r.solar {
            bemcal_weather::measured::SolarSource::MeasuredGlobalErbs =>
                "measured global horizontal, split by Erbs et al. (1982)",
            bemcal_weather::measured::SolarSource::Tmy => "the TMY file's (none measured)",
        }
    );
}

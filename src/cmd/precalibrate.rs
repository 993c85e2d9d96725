//! `bemcal precalibrate`: meters + weather -> disaggregated series, day-type calendar, schedule
//! priors and `priors.toml` (reference section 2.2). All logic lives in `bemcal-precal`.

use std::path::PathBuf;

use bemcal_precal::io::{write_outputs, PrecalProject};
use bemcal_precal::meters::{read_meters, MeterSpec};
use bemcal_weather::Epw;

/// Pre-calibration: disaggregate the meters and derive schedule priors from day-type clusters.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Meters CSV (overrides the project's `[meters] file`).
    #[arg(long)]
    pub meters: Option<PathBuf>,
    /// EPW weather file (outdoor temperature for the heating / non-heating seasons), or
    /// `bundled:FILE` from EnergyPlus's WeatherData folder.
    #[arg(long)]
    pub weather: String,
    /// Project TOML with `[meters]` and `[precalibration]` tables. Without it, meter columns
    /// are detected from their names (heating / cooling / electricity / total building, unit kW).
    #[arg(long)]
    pub project: Option<PathBuf>,
    /// Year of the meters: `2017`, or `2017-04` for twelve months from April 2017 (default:
    /// the project's, else inferred from the timestamps).
    #[arg(long)]
    pub year: Option<bemcal_weather::grid::GridYear>,
    /// Output directory.
    #[arg(long, default_value = "precal")]
    pub out: PathBuf,
    /// DTW band: largest warp |i - j| in hours (overrides the project).
    #[arg(long)]
    pub band: Option<i64>,
    /// Number of day-type clusters (default: chosen by silhouette over 2..=6).
    #[arg(long)]
    pub k: Option<usize>,
    /// Largest difference of medians for merging adjacent hours into one interval.
    #[arg(long)]
    pub merge_tolerance: Option<f64>,
    /// Largest number of schedule intervals per day type.
    #[arg(long)]
    pub max_intervals: Option<usize>,
    /// Holidays of the calendar the day types are compared with: us_federal, uk, none, or a
    /// file of dates (YYYY-MM-DD per line).
    #[arg(long)]
    pub holidays: Option<String>,
    /// Hours to leave out, as `[validation] holdout` (overrides the project): `last 3 months`,
    /// `oct,nov,dec`, or `2017-06-01..2017-08-31`.
    #[arg(long)]
    pub holdout: Option<bemcal_weather::period::Holdout>,
}

/// `--holidays`: a table's name or a file of dates.
pub fn parse_holidays(s: &str) -> anyhow::Result<bemcal_weather::Holidays> {
    use bemcal_weather::Holidays;
    Ok(match s {
        "us_federal" => Holidays::UsFederal,
        "uk" | "uk_england_wales" => Holidays::UkEnglandWales,
        "none" => Holidays::None,
        file => Holidays::Dates(bemcal_weather::read_holiday_list(std::path::Path::new(
            file,
        ))?),
    })
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let project = match &args.project {
        Some(p) => PrecalProject::read(p)?,
        None => PrecalProject::default(),
    };
    let spec = project.meters.clone().unwrap_or_else(MeterSpec::default);
    let meters_path = match (
        args.meters.clone().or_else(|| spec.file.clone()),
        spec.bills.is_empty(),
    ) {
        (Some(p), _) => p,
        (None, true) => {
            anyhow::bail!("no meters file: pass --meters or set [meters] file in the project")
        }
        // Day types, schedules and bases come from hourly readings, which bills do not have.
        (None, false) => anyhow::bail!(
            "the project's meters are bills alone ([[meters.bills]]): pre-calibration reads hourly \
             or sub-hourly meters (day types, schedule priors, bases), so with bills alone the \
             calibration keeps the model's default priors: calibrate without a priors file"
        ),
    };
    let epw = Epw::read(&super::common::resolve_weather_ref(&args.weather)?)?;
    let year = args.year.or(project.year);
    let mut meters = read_meters(&meters_path, &spec, year, Some(epw.location.time_zone_h))?;
    let holdout = match (&args.holdout, &project.validation.holdout, &args.project) {
        (Some(h), _, _) => Some((h, "--holdout".to_string())),
        (None, Some(h), Some(p)) => Some((h, format!("{}: [validation] holdout", p.display()))),
        _ => None,
    };
    if let Some((h, from)) = holdout {
        meters
            .hold_out(h)
            .map_err(|m| anyhow::anyhow!("{from}: {m} (meters {})", meters_path.display()))?;
    }
    let mut opts = project.precalibration.clone();
    if let Some(b) = args.band {
        opts.schedule.band = b;
    }
    if args.k.is_some() {
        opts.schedule.k = args.k;
    }
    if let Some(t) = args.merge_tolerance {
        opts.schedule.merge_tolerance = t;
    }
    if args.max_intervals.is_some() {
        opts.schedule.max_intervals = args.max_intervals;
    }
    if let Some(h) = &args.holidays {
        opts.schedule.holidays = parse_holidays(h)?;
    }
    let outdoor: Vec<f64> = epw.hours.iter().map(|h| h.dry_bulb_c).collect();
    let result = bemcal_precal::pipeline::run(meters, &outdoor, &opts)?;
    let written = write_outputs(&args.out, &result)?;
    print!(
        "{}",
        bemcal_precal::io::summary_text(&result, &args.out.display().to_string())
    );
    println!();
    for p in written {
        println!("wrote {}", p.display());
    }
    Ok(())
}

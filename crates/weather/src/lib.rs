//! EnergyPlus weather (EPW) files: the hourly features the surrogate needs and the day-type
//! calendar.
//!
//! An EPW file has eight header lines (LOCATION, DESIGN CONDITIONS, ..., DATA PERIODS) and then
//! one comma-separated row of 35 fields per hour. [`Epw::read`] parses the fields bemcal uses and
//! reports malformed input with its file, line and field. [`Calendar`] turns the rows' month/day
//! into day types (weekday, weekend, holiday) for a chosen calendar year, because typical-year
//! (TMY) files mix source years and so carry no usable weekday.
#![deny(missing_docs)]

pub mod calendar;
pub mod grid;
pub mod measured;
pub mod period;
pub mod solar;
pub mod station;

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use station::excerpt;

pub use calendar::{
    easter_sunday, read_day_type_calendar, read_holiday_list, uk_bank_holidays,
    us_federal_holidays, Calendar, DayType, Holidays,
};

/// Hours in a non-leap year: the length of every EPW file bemcal accepts.
pub const HOURS_PER_YEAR: usize = 8760;

/// Errors from reading a weather file.
#[derive(Debug, thiserror::Error)]
pub enum WeatherError {
    /// The file could not be read at all.
    #[error("cannot read weather file {path}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The operating system's error.
        #[source]
        source: std::io::Error,
    },
    /// A line or field is not what the EPW format requires.
    #[error("{path}:{line}: {}", bemcal_excerpt::shorten(.message))]
    Malformed {
        /// The file.
        path: PathBuf,
        /// The line at fault (1-based).
        line: usize,
        /// What was expected, with a short excerpt of what was found.
        message: String,
    },
}

/// Site information from the EPW `LOCATION` header.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Location {
    /// The site's city (the header's field 2).
    pub city: String,
    /// Its state or province.
    pub state: String,
    /// Its country.
    pub country: String,
    /// Latitude, degrees north.
    pub latitude_deg: f64,
    /// Longitude, degrees east (west is negative).
    pub longitude_deg: f64,
    /// Hours from UTC (standard time).
    pub time_zone_h: f64,
    /// Elevation above sea level, m.
    pub elevation_m: f64,
}

impl Location {
    /// The `LOCATION` header, the first line of EPW text (`path` names it in errors).
    pub fn parse(text: &str, path: &Path) -> Result<Location, WeatherError> {
        let err = |message: String| WeatherError::Malformed {
            path: path.to_path_buf(),
            line: 1,
            message,
        };
        let first = text
            .lines()
            .next()
            .ok_or_else(|| err("empty file; expected an EPW LOCATION header".into()))?;
        let loc: Vec<&str> = first.split(',').map(str::trim).collect();
        if loc.first() != Some(&"LOCATION") || loc.len() < 10 {
            return Err(err(
                "expected 'LOCATION,city,state,country,source,WMO,lat,lon,tz,elevation'".into(),
            ));
        }
        let num = |i: usize, what: &str| -> Result<f64, WeatherError> {
            loc[i].parse::<f64>().map_err(|_| {
                err(format!(
                    "LOCATION {what} '{}' is not a number",
                    excerpt(loc[i])
                ))
            })
        };
        // Range checks: a time zone of 99 (a missing-value code) or a latitude of 400 would
        // otherwise shift every solar position and every meter's alignment without a word.
        let ranged = |i: usize, what: &str, lo: f64, hi: f64, unit: &str| {
            let v = num(i, what)?;
            if !(lo..=hi).contains(&v) {
                return Err(err(if v.is_finite() {
                    format!("LOCATION {what} {v} is outside {lo}..{hi:+} {unit}")
                } else {
                    format!("LOCATION {what} {v} is not a finite number")
                }));
            }
            Ok(v)
        };
        Ok(Location {
            city: loc[1].to_string(),
            state: loc[2].to_string(),
            country: loc[3].to_string(),
            latitude_deg: ranged(6, "latitude", -90.0, 90.0, "degrees")?,
            longitude_deg: ranged(7, "longitude", -180.0, 180.0, "degrees")?,
            time_zone_h: ranged(8, "time zone", -12.0, 14.0, "hours from UTC")?,
            elevation_m: ranged(9, "elevation", f64::MIN, f64::MAX, "m")?,
        })
    }
}

/// One hourly EPW record (the fields bemcal uses).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct WeatherHour {
    /// Month, 1..=12.
    pub month: u32,
    /// Day of the month.
    pub day: u32,
    /// EPW hour, 1..=24, hour-ending: hour 1 covers 00:00-01:00.
    pub hour: u32,
    /// Dry-bulb air temperature, C.
    pub dry_bulb_c: f64,
    /// Dew-point temperature, C.
    pub dew_point_c: f64,
    /// Relative humidity, %.
    pub rel_humidity_pct: f64,
    /// Station atmospheric pressure, Pa.
    pub pressure_pa: f64,
    /// Global horizontal radiation, Wh/m2 over the hour.
    pub global_horizontal_wh_m2: f64,
    /// Direct normal radiation, Wh/m2 over the hour.
    pub direct_normal_wh_m2: f64,
    /// Diffuse horizontal radiation, Wh/m2 over the hour.
    pub diffuse_horizontal_wh_m2: f64,
    /// Wind direction, degrees clockwise from north (where it blows from).
    pub wind_direction_deg: f64,
    /// Wind speed, m/s.
    pub wind_speed_m_s: f64,
}

/// A parsed EPW file: its location and 8,760 hourly records in file order (Jan 1 hour 1 first).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Epw {
    /// The site, from the `LOCATION` header.
    pub location: Location,
    /// The 8,760 hourly records.
    pub hours: Vec<WeatherHour>,
}

impl Epw {
    /// Reads and validates an EPW file.
    pub fn read(path: impl AsRef<Path>) -> Result<Epw, WeatherError> {
        let path = path.as_ref();
        let text = std::fs::read_to_string(path).map_err(|source| WeatherError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        Epw::parse(&text, path)
    }

    /// Parses EPW text; `path` is used only in error messages.
    pub fn parse(text: &str, path: &Path) -> Result<Epw, WeatherError> {
        let err = |line: usize, message: String| WeatherError::Malformed {
            path: path.to_path_buf(),
            line,
            message,
        };
        let mut lines = text.lines().enumerate();
        let location = Location::parse(text, path)?;
        lines.next();
        // Skip the remaining header lines up to and including DATA PERIODS.
        let mut header_end = None;
        for (i, line) in lines.by_ref() {
            if line.starts_with("DATA PERIODS") {
                header_end = Some(i);
                break;
            }
        }
        if header_end.is_none() {
            return Err(err(
                2,
                "no 'DATA PERIODS' header line before the hourly data".into(),
            ));
        }
        let mut hours = Vec::with_capacity(HOURS_PER_YEAR);
        let mut seen: std::collections::HashMap<(u32, u32, u32), usize> =
            std::collections::HashMap::with_capacity(HOURS_PER_YEAR);
        for (i, line) in lines {
            let lineno = i + 1;
            if line.trim().is_empty() {
                continue;
            }
            let h = parse_hour(line, lineno, path)?;
            // A repeated month/day/hour means another hour is missing: every later row would
            // be simulated an hour off.
            if let Some(first) = seen.insert((h.month, h.day, h.hour), lineno) {
                return Err(err(
                    lineno,
                    format!(
                        "month {} day {} hour {} again: line {first} has the same hour \
                         (a duplicated hour; an EPW has each hour of the year once)",
                        h.month, h.day, h.hour
                    ),
                ));
            }
            hours.push(h);
        }
        if hours.len() != HOURS_PER_YEAR {
            return Err(err(
                text.lines().count(),
                format!(
                    "expected {HOURS_PER_YEAR} hourly rows (one non-leap year), found {}",
                    hours.len()
                ),
            ));
        }
        Ok(Epw { location, hours })
    }
}

/// One hourly row of an EPW (file line `lineno`): the fields bemcal reads, each a finite
/// number, month, day and hour in range, dry bulb and relative humidity plausible.
fn parse_hour(line: &str, lineno: usize, path: &Path) -> Result<WeatherHour, WeatherError> {
    let err = |line: usize, message: String| WeatherError::Malformed {
        path: path.to_path_buf(),
        line,
        message,
    };
    let f: Vec<&str> = line.split(',').collect();
    if f.len() < 22 {
        return Err(err(
            lineno,
            format!(
                "expected at least 22 comma-separated fields, found {}",
                f.len()
            ),
        ));
    }
    let field = |idx: usize, name: &str| -> Result<f64, WeatherError> {
        match f[idx].trim().parse::<f64>() {
            Ok(v) if v.is_finite() => Ok(v),
            Ok(_) => Err(err(
                lineno,
                format!(
                    "field {} ({name}) '{}' is not a finite number",
                    idx + 1,
                    excerpt(f[idx])
                ),
            )),
            Err(_) => Err(err(
                lineno,
                format!(
                    "field {} ({name}) '{}' is not a number",
                    idx + 1,
                    excerpt(f[idx])
                ),
            )),
        }
    };
    let int = |idx: usize, name: &str, lo: u32, hi: u32| -> Result<u32, WeatherError> {
        let v = f[idx].trim().parse::<u32>().map_err(|_| {
            err(
                lineno,
                format!(
                    "field {} ({name}) '{}' is not an integer",
                    idx + 1,
                    excerpt(f[idx])
                ),
            )
        })?;
        if v < lo || v > hi {
            return Err(err(
                lineno,
                format!("field {} ({name}) = {v}, expected {lo}..={hi}", idx + 1),
            ));
        }
        Ok(v)
    };
    let h = WeatherHour {
        month: int(1, "month", 1, 12)?,
        day: int(2, "day", 1, 31)?,
        hour: int(3, "hour", 1, 24)?,
        dry_bulb_c: field(6, "dry bulb temperature")?,
        dew_point_c: field(7, "dew point temperature")?,
        rel_humidity_pct: field(8, "relative humidity")?,
        pressure_pa: field(9, "atmospheric pressure")?,
        global_horizontal_wh_m2: field(13, "global horizontal radiation")?,
        direct_normal_wh_m2: field(14, "direct normal radiation")?,
        diffuse_horizontal_wh_m2: field(15, "diffuse horizontal radiation")?,
        wind_direction_deg: field(20, "wind direction")?,
        wind_speed_m_s: field(21, "wind speed")?,
    };
    if !(-90.0..=70.0).contains(&h.dry_bulb_c) {
        return Err(err(
            lineno,
            format!("dry bulb {} C is outside -90..70 C", h.dry_bulb_c),
        ));
    }
    if !(0.0..=110.0).contains(&h.rel_humidity_pct) {
        return Err(err(
            lineno,
            format!(
                "relative humidity {} % is outside 0..110 %",
                h.rel_humidity_pct
            ),
        ));
    }
    Ok(h)
}

/// The hourly weather features the surrogate takes (the reference's five: dry bulb, humidity,
/// wind speed, solar radiation, day type), one value per hour of the year.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct HourlyFeatures {
    /// Dry-bulb air temperature, C.
    pub dry_bulb_c: Vec<f64>,
    /// Relative humidity, %.
    pub rel_humidity_pct: Vec<f64>,
    /// Wind speed, m/s.
    pub wind_speed_m_s: Vec<f64>,
    /// Global horizontal radiation, Wh/m2.
    pub global_horizontal_wh_m2: Vec<f64>,
    /// The day type of the hour's date.
    pub day_type: Vec<DayType>,
}

impl HourlyFeatures {
    /// Names of the features in the order of [`HourlyFeatures::row`].
    pub const NAMES: [&'static str; 5] = [
        "dry_bulb_c",
        "rel_humidity_pct",
        "wind_speed_m_s",
        "global_horizontal_wh_m2",
        "day_type",
    ];

    /// Extracts the features from an EPW file with day types from `calendar`.
    pub fn from_epw(epw: &Epw, calendar: &Calendar) -> HourlyFeatures {
        HourlyFeatures {
            dry_bulb_c: epw.hours.iter().map(|h| h.dry_bulb_c).collect(),
            rel_humidity_pct: epw.hours.iter().map(|h| h.rel_humidity_pct).collect(),
            wind_speed_m_s: epw.hours.iter().map(|h| h.wind_speed_m_s).collect(),
            global_horizontal_wh_m2: epw
                .hours
                .iter()
                .map(|h| h.global_horizontal_wh_m2)
                .collect(),
            day_type: calendar.hourly_day_types(epw),
        }
    }

    /// A smooth synthetic year of `n` hours (seasonal dry bulb, daily humidity and sun, a
    /// weekly wind pattern, Saturdays and Sundays as weekends from hour 0 a Monday), for
    /// benchmarks that time the surrogate and need no real climate.
    pub fn synthetic(n: usize) -> HourlyFeatures {
        let tau = std::f64::consts::TAU;
        HourlyFeatures {
            dry_bulb_c: (0..n)
                .map(|t| 10.0 - 12.0 * (tau * t as f64 / 8760.0).cos())
                .collect(),
            rel_humidity_pct: (0..n)
                .map(|t| 60.0 + 20.0 * (tau * t as f64 / 24.0).cos())
                .collect(),
            wind_speed_m_s: (0..n).map(|t| 3.0 + (t % 7) as f64 * 0.3).collect(),
            global_horizontal_wh_m2: (0..n)
                .map(|t| (600.0 * (tau * ((t % 24) as f64 - 6.0) / 24.0).sin()).max(0.0))
                .collect(),
            day_type: (0..n)
                .map(|t| match (t / 24) % 7 {
                    5 | 6 => DayType::Weekend,
                    _ => DayType::Weekday,
                })
                .collect(),
        }
    }

    /// Number of hours.
    pub fn len(&self) -> usize {
        self.dry_bulb_c.len()
    }

    /// True when there are no hours.
    pub fn is_empty(&self) -> bool {
        self.dry_bulb_c.is_empty()
    }

    /// The five features of hour `t`, in [`HourlyFeatures::NAMES`] order.
    pub fn row(&self, t: usize) -> [f64; 5] {
        [
            self.dry_bulb_c[t],
            self.rel_humidity_pct[t],
            self.wind_speed_m_s[t],
            self.global_horizontal_wh_m2[t],
            self.day_type[t].code(),
        ]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use chrono::{Datelike, NaiveDate};

    #[test]
    fn synthetic_year_has_weekends_and_its_cycles() {
        let f = HourlyFeatures::synthetic(8760);
        assert_eq!(f.len(), 8760);
        let day = |d: usize| f.day_type[d * 24 + 12];
        assert_eq!(
            (day(4), day(5), day(6), day(7)),
            (
                DayType::Weekday,
                DayType::Weekend,
                DayType::Weekend,
                DayType::Weekday
            )
        );
        assert!(f.dry_bulb_c[0] < -1.9 && f.dry_bulb_c[4380] > 21.9);
        assert_eq!(f.global_horizontal_wh_m2[0], 0.0);
        assert!(f.global_horizontal_wh_m2[12] > 599.0);
    }

    fn shared_epw(name: &str) -> Option<PathBuf> {
        let p = Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../../shared/data/epw")
            .join(name);
        p.exists().then_some(p)
    }

    #[test]
    fn reads_real_tmy3_file() {
        let Some(p) = shared_epw("USA_CO_Golden-NREL.724666_TMY3.epw") else {
            eprintln!("shared data not present; skipping");
            return;
        };
        let epw = Epw::read(&p).unwrap();
        assert_eq!(epw.hours.len(), HOURS_PER_YEAR);
        assert!((epw.location.latitude_deg - 39.74).abs() < 0.1);
        assert_eq!(epw.location.time_zone_h, -7.0);
        let (m, d, h) = (epw.hours[0].month, epw.hours[0].day, epw.hours[0].hour);
        assert_eq!((m, d, h), (1, 1, 1));
        let mean_t: f64 = epw.hours.iter().map(|h| h.dry_bulb_c).sum::<f64>() / 8760.0;
        assert!((5.0..15.0).contains(&mean_t), "Golden annual mean {mean_t}");
        let jul: f64 = epw.hours[4344..5088]
            .iter()
            .map(|h| h.dry_bulb_c)
            .sum::<f64>()
            / 744.0;
        assert!(jul > 18.0, "July mean {jul}");
    }

    /// A minimal valid EPW (constant weather, 2021's calendar, no leap day) as lines.
    fn tiny_epw_lines(time_zone: &str) -> Vec<String> {
        let mut lines = vec![
            format!("LOCATION,Golden,CO,USA,TMY3,724666,39.74,-105.18,{time_zone},1829.0"),
            "DESIGN CONDITIONS,0".into(),
            "TYPICAL/EXTREME PERIODS,0".into(),
            "GROUND TEMPERATURES,0".into(),
            "HOLIDAYS/DAYLIGHT SAVINGS,No,0,0,0".into(),
            "COMMENTS 1,synthetic".into(),
            "COMMENTS 2,synthetic".into(),
            "DATA PERIODS,1,1,Data,Friday, 1/ 1,12/31".into(),
        ];
        let mut day = NaiveDate::from_ymd_opt(2021, 1, 1).unwrap();
        while day.year() == 2021 {
            for hour in 1..=24 {
                lines.push(format!(
                    "2021,{},{},{hour},0,?,10.0,2.0,50,83000,0,0,300,0,0,0,0,0,0,0,180,3.0",
                    day.month(),
                    day.day()
                ));
            }
            day = day.succ_opt().unwrap();
        }
        lines
    }

    #[test]
    fn a_duplicated_hour_or_an_impossible_time_zone_is_refused_naming_the_line() {
        let lines = tiny_epw_lines("-7.0");
        let epw = Epw::parse(&lines.join("\n"), Path::new("x.epw")).unwrap();
        assert_eq!(epw.hours.len(), HOURS_PER_YEAR);

        // Hour 3 of January 2 (line 8 + 24 + 3 = 35) written as hour 2 again.
        let mut dup = lines.clone();
        assert!(dup[34].starts_with("2021,1,2,3,"), "{}", dup[34]);
        dup[34] = dup[34].replacen("2021,1,2,3,", "2021,1,2,2,", 1);
        let e = Epw::parse(&dup.join("\n"), Path::new("x.epw"))
            .unwrap_err()
            .to_string();
        assert_eq!(
            e,
            "x.epw:35: month 1 day 2 hour 2 again: line 34 has the same hour \
             (a duplicated hour; an EPW has each hour of the year once)"
        );

        for (tz, what) in [
            ("99", "time zone 99 is outside -12..+14 hours from UTC"),
            (
                "-12.5",
                "time zone -12.5 is outside -12..+14 hours from UTC",
            ),
            ("inf", "time zone inf is not a finite number"),
        ] {
            let e = Epw::parse(&tiny_epw_lines(tz).join("\n"), Path::new("x.epw"))
                .unwrap_err()
                .to_string();
            assert_eq!(e, format!("x.epw:1: LOCATION {what}"));
        }
        for tz in ["-12", "14", "5.5", "-3.5"] {
            Epw::parse(&tiny_epw_lines(tz).join("\n"), Path::new("x.epw")).unwrap();
        }

        // A non-finite reading, and a long bad cell quoted as an excerpt.
        let mut bad = lines.clone();
        bad[20] = bad[20].replacen(",83000,", ",inf,", 1);
        let e = Epw::parse(&bad.join("\n"), Path::new("x.epw"))
            .unwrap_err()
            .to_string();
        assert_eq!(
            e,
            "x.epw:21: field 10 (atmospheric pressure) 'inf' is not a finite number"
        );
        let mut bad = lines.clone();
        bad[20] = bad[20].replacen(",83000,", &format!(",{},", "9".repeat(5000) + "x"), 1);
        let e = Epw::parse(&bad.join("\n"), Path::new("x.epw"))
            .unwrap_err()
            .to_string();
        assert!(
            e.starts_with("x.epw:21: field 10 (atmospheric pressure) '999"),
            "{e}"
        );
        assert!(
            e.len() < 200,
            "the message quotes an excerpt: {} bytes",
            e.len()
        );
    }

    #[test]
    fn malformed_row_names_line_and_field() {
        let Some(p) = shared_epw("USA_CO_Golden-NREL.724666_TMY3.epw") else {
            return;
        };
        let text = std::fs::read_to_string(&p).unwrap();
        let mut lines: Vec<String> = text.lines().map(String::from).collect();
        let mut f: Vec<String> = lines[20].split(',').map(String::from).collect();
        f[6] = "warm".into();
        lines[20] = f.join(",");
        let e = Epw::parse(&lines.join("\n"), Path::new("x.epw")).unwrap_err();
        let msg = e.to_string();
        assert!(msg.starts_with("x.epw:21:"), "{msg}");
        assert!(msg.contains("dry bulb"), "{msg}");
        let short: Vec<&str> = text.lines().take(100).collect();
        let short = short.join("\n");
        let e = Epw::parse(&short, Path::new("x.epw")).unwrap_err();
        assert!(e.to_string().contains("expected 8760 hourly rows"), "{e}");
    }
}

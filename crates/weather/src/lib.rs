//! EnergyPlus weather (EPW) files: the hourly features the surrogate needs and the day-type
//! calendar.
//!
//! An EPW file has eight header lines (LOCATION, DESIGN CONDITIONS, ..., DATA PERIODS) and then
//! one comma-separated row of 35 fields per hour. [`Epw::read`] parses the fields bemcal uses and
//! reports malformed input with its file, line and field. [`Calendar`] turns the rows' month/day
//! into day types (weekday, weekend, holiday) for a chosen calendar year, because typical-year
//! (TMY) files mix source years and so carry no usable weekday.

pub mod measured;
pub mod solar;
pub mod station;

use std::fmt;
use std::path::{Path, PathBuf};

use chrono::{Datelike, NaiveDate, Weekday};
use serde::{Deserialize, Serialize};

/// Hours in a non-leap year: the length of every EPW file bemcal accepts.
pub const HOURS_PER_YEAR: usize = 8760;

/// Errors from reading a weather file.
#[derive(Debug, thiserror::Error)]
pub enum WeatherError {
    /// The file could not be read at all.
    #[error("cannot read weather file {path}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// A line or field is not what the EPW format requires.
    #[error("{path}:{line}: {message}")]
    Malformed {
        path: PathBuf,
        line: usize,
        message: String,
    },
}

/// Site information from the EPW `LOCATION` header.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Location {
    pub city: String,
    pub state: String,
    pub country: String,
    pub latitude_deg: f64,
    pub longitude_deg: f64,
    /// Hours from UTC (standard time).
    pub time_zone_h: f64,
    pub elevation_m: f64,
}

/// One hourly EPW record (the fields bemcal uses).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct WeatherHour {
    pub month: u32,
    pub day: u32,
    /// EPW hour, 1..=24, hour-ending: hour 1 covers 00:00-01:00.
    pub hour: u32,
    pub dry_bulb_c: f64,
    pub dew_point_c: f64,
    pub rel_humidity_pct: f64,
    pub pressure_pa: f64,
    /// Global horizontal radiation, Wh/m2 over the hour.
    pub global_horizontal_wh_m2: f64,
    pub direct_normal_wh_m2: f64,
    pub diffuse_horizontal_wh_m2: f64,
    pub wind_direction_deg: f64,
    pub wind_speed_m_s: f64,
}

/// A parsed EPW file: its location and 8,760 hourly records in file order (Jan 1 hour 1 first).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Epw {
    pub location: Location,
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
        let (_, first) = lines
            .next()
            .ok_or_else(|| err(1, "empty file; expected an EPW LOCATION header".into()))?;
        let loc: Vec<&str> = first.split(',').map(str::trim).collect();
        if loc.first() != Some(&"LOCATION") || loc.len() < 10 {
            return Err(err(
                1,
                "expected 'LOCATION,city,state,country,source,WMO,lat,lon,tz,elevation'".into(),
            ));
        }
        let num = |i: usize, what: &str| -> Result<f64, WeatherError> {
            loc[i]
                .parse::<f64>()
                .map_err(|_| err(1, format!("LOCATION {what} '{}' is not a number", loc[i])))
        };
        let location = Location {
            city: loc[1].to_string(),
            state: loc[2].to_string(),
            country: loc[3].to_string(),
            latitude_deg: num(6, "latitude")?,
            longitude_deg: num(7, "longitude")?,
            time_zone_h: num(8, "time zone")?,
            elevation_m: num(9, "elevation")?,
        };
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
        for (i, line) in lines {
            let lineno = i + 1;
            if line.trim().is_empty() {
                continue;
            }
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
                f[idx].trim().parse::<f64>().map_err(|_| {
                    err(
                        lineno,
                        format!("field {} ({name}) '{}' is not a number", idx + 1, f[idx]),
                    )
                })
            };
            let int = |idx: usize, name: &str, lo: u32, hi: u32| -> Result<u32, WeatherError> {
                let v = f[idx].trim().parse::<u32>().map_err(|_| {
                    err(
                        lineno,
                        format!("field {} ({name}) '{}' is not an integer", idx + 1, f[idx]),
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

/// The kind of day, as the surrogate and the schedules see it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum DayType {
    Weekday,
    Weekend,
    Holiday,
}

impl DayType {
    /// The numeric code used as a surrogate input: weekday 0, weekend 1, holiday 2.
    pub fn code(self) -> f64 {
        match self {
            DayType::Weekday => 0.0,
            DayType::Weekend => 1.0,
            DayType::Holiday => 2.0,
        }
    }

    /// True for days that run the weekend schedule in the building model (weekends and holidays).
    pub fn is_off_day(self) -> bool {
        !matches!(self, DayType::Weekday)
    }
}

impl fmt::Display for DayType {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            DayType::Weekday => "weekday",
            DayType::Weekend => "weekend",
            DayType::Holiday => "holiday",
        })
    }
}

/// Which public holidays count as holidays.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Holidays {
    /// No holidays: every Monday-Friday is a weekday.
    None,
    /// The US federal holidays, with the observed-day rule (Saturday -> Friday, Sunday -> Monday).
    #[default]
    UsFederal,
}

/// Maps dates of one calendar year to day types.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct Calendar {
    pub year: i32,
    #[serde(default)]
    pub holidays: Holidays,
}

impl Calendar {
    pub fn new(year: i32, holidays: Holidays) -> Calendar {
        Calendar { year, holidays }
    }

    /// Day type of a date in this calendar's year; `None` for an impossible date (e.g. 2/30).
    pub fn day_type(&self, month: u32, day: u32) -> Option<DayType> {
        let date = NaiveDate::from_ymd_opt(self.year, month, day)?;
        if self.is_holiday(date) {
            return Some(DayType::Holiday);
        }
        Some(match date.weekday() {
            Weekday::Sat | Weekday::Sun => DayType::Weekend,
            _ => DayType::Weekday,
        })
    }

    /// Day types for every hour of an EPW file.
    pub fn hourly_day_types(&self, epw: &Epw) -> Vec<DayType> {
        epw.hours
            .iter()
            .map(|h| self.day_type(h.month, h.day).unwrap_or(DayType::Weekday))
            .collect()
    }

    fn is_holiday(&self, date: NaiveDate) -> bool {
        match self.holidays {
            Holidays::None => false,
            Holidays::UsFederal => us_federal_holidays(self.year).contains(&date),
        }
    }
}

/// US federal holidays of a year as observed (fixed-date holidays falling on a weekend move to
/// the nearest weekday).
pub fn us_federal_holidays(year: i32) -> Vec<NaiveDate> {
    let fixed = |m, d| observed(NaiveDate::from_ymd_opt(year, m, d).expect("valid date"));
    let nth = |m, wd, n| NaiveDate::from_weekday_of_month_opt(year, m, wd, n).expect("valid date");
    let last_monday_may = (1..=5)
        .rev()
        .find_map(|n| NaiveDate::from_weekday_of_month_opt(year, 5, Weekday::Mon, n))
        .expect("May has a Monday");
    vec![
        fixed(1, 1),
        nth(1, Weekday::Mon, 3),
        nth(2, Weekday::Mon, 3),
        last_monday_may,
        fixed(6, 19),
        fixed(7, 4),
        nth(9, Weekday::Mon, 1),
        nth(10, Weekday::Mon, 2),
        fixed(11, 11),
        nth(11, Weekday::Thu, 4),
        fixed(12, 25),
    ]
}

fn observed(d: NaiveDate) -> NaiveDate {
    match d.weekday() {
        Weekday::Sat => d.pred_opt().expect("date"),
        Weekday::Sun => d.succ_opt().expect("date"),
        _ => d,
    }
}

/// The hourly weather features the surrogate takes (the reference's five: dry bulb, humidity,
/// wind speed, solar radiation, day type), one value per hour of the year.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct HourlyFeatures {
    pub dry_bulb_c: Vec<f64>,
    pub rel_humidity_pct: Vec<f64>,
    pub wind_speed_m_s: Vec<f64>,
    pub global_horizontal_wh_m2: Vec<f64>,
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

    #[test]
    fn calendar_day_types() {
        let cal = Calendar::new(2021, Holidays::UsFederal);
        // 2021-01-01 was a Friday and New Year's Day.
        assert_eq!(cal.day_type(1, 1), Some(DayType::Holiday));
        assert_eq!(cal.day_type(1, 2), Some(DayType::Weekend));
        assert_eq!(cal.day_type(1, 4), Some(DayType::Weekday));
        // July 4 2021 was a Sunday: observed Monday July 5.
        assert_eq!(cal.day_type(7, 5), Some(DayType::Holiday));
        // Thanksgiving 2021: Nov 25.
        assert_eq!(cal.day_type(11, 25), Some(DayType::Holiday));
        let none = Calendar::new(2021, Holidays::None);
        assert_eq!(none.day_type(1, 1), Some(DayType::Weekday));
        assert_eq!(cal.day_type(2, 30), None);
    }
}

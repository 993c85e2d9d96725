//! Readers of measured weather into [`Observation`]s (UTC): NOAA ISD-lite files and CSV files
//! of a building's or a weather service's station, with a column map and units.

use std::io::Read;
use std::path::{Path, PathBuf};
use std::str::FromStr;

use chrono::{Duration, NaiveDateTime, TimeZone};
use serde::{Deserialize, Serialize};

use crate::measured::{station_pressure_pa, Field, Observation, Stamp};
use crate::WeatherError;

fn malformed(path: &Path, line: usize, message: String) -> WeatherError {
    WeatherError::Malformed {
        path: path.to_path_buf(),
        line,
        message,
    }
}

/// Reads a file as text, gunzipping it when it starts with the gzip magic bytes.
pub fn read_text(path: &Path) -> Result<String, WeatherError> {
    let io = |source| WeatherError::Io {
        path: path.to_path_buf(),
        source,
    };
    let bytes = std::fs::read(path).map_err(io)?;
    if bytes.starts_with(&[0x1f, 0x8b]) {
        let mut text = String::new();
        flate2::read::MultiGzDecoder::new(&bytes[..])
            .read_to_string(&mut text)
            .map_err(io)?;
        return Ok(text);
    }
    String::from_utf8(bytes).map_err(|e| {
        malformed(
            path,
            1,
            format!("not UTF-8 text (byte {})", e.utf8_error().valid_up_to()),
        )
    })
}

/// Parses NOAA ISD-lite text (`isd-lite-format.txt`: year, month, day, hour in UTC, then air
/// temperature and dew point in tenths of C, sea-level pressure in tenths of hPa, wind direction
/// in degrees, wind speed in tenths of m/s, sky cover code, precipitation; -9999 missing) of a
/// station at `elevation_m` (sea-level pressure is converted to station pressure).
pub fn parse_isd_lite(
    text: &str,
    path: &Path,
    elevation_m: f64,
) -> Result<Vec<Observation>, WeatherError> {
    let mut out = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let lineno = i + 1;
        if line.trim().is_empty() {
            continue;
        }
        let f: Vec<&str> = line.split_whitespace().collect();
        if f.len() < 10 {
            return Err(malformed(
                path,
                lineno,
                format!(
                    "ISD-lite lines have 12 fields (year month day hour temperature ...), found {}: '{}'",
                    f.len(),
                    excerpt(line)
                ),
            ));
        }
        let int = |k: usize, what: &str| -> Result<i64, WeatherError> {
            f[k].parse::<i64>().map_err(|_| {
                malformed(
                    path,
                    lineno,
                    format!(
                        "ISD-lite field {} ({what}) '{}' is not an integer",
                        k + 1,
                        f[k]
                    ),
                )
            })
        };
        let date = chrono::NaiveDate::from_ymd_opt(
            int(0, "year")? as i32,
            int(1, "month")? as u32,
            int(2, "day")? as u32,
        )
        .ok_or_else(|| malformed(path, lineno, format!("no such date: '{}'", excerpt(line))))?;
        let hour = int(3, "hour")?;
        if !(0..=23).contains(&hour) {
            return Err(malformed(
                path,
                lineno,
                format!("ISD-lite hour {hour}, expected 0..=23"),
            ));
        }
        let utc = date.and_hms_opt(hour as u32, 0, 0).expect("valid hour");
        let value = |k: usize, what: &str, scale: f64| -> Result<Option<f64>, WeatherError> {
            let v = int(k, what)?;
            Ok((v != -9999).then_some(v as f64 / scale))
        };
        let mut values = [None; 8];
        values[Field::DryBulb.index()] = value(4, "air temperature", 10.0)?;
        values[Field::DewPoint.index()] = value(5, "dew point", 10.0)?;
        values[Field::Pressure.index()] = value(6, "sea-level pressure", 10.0)?
            .map(|hpa| station_pressure_pa(hpa * 100.0, elevation_m));
        values[Field::WindDirection.index()] = value(7, "wind direction", 1.0)?;
        values[Field::WindSpeed.index()] = value(8, "wind speed", 10.0)?;
        // Codes 0-8 are oktas; 9-19 (obscured, partial, thin/dark layers) have no fraction.
        values[Field::SkyCover.index()] = value(9, "sky cover", 1.0)?
            .filter(|code| (0.0..=8.0).contains(code))
            .map(|oktas| oktas * 10.0 / 8.0);
        out.push(Observation { utc, values });
    }
    if out.is_empty() {
        return Err(malformed(
            path,
            1,
            "no ISD-lite observations in the file".into(),
        ));
    }
    Ok(out)
}

/// Reads one ISD-lite file (plain or gzipped).
pub fn read_isd_lite(path: &Path, elevation_m: f64) -> Result<Vec<Observation>, WeatherError> {
    parse_isd_lite(&read_text(path)?, path, elevation_m)
}

/// The time in which a CSV's time stamps are written.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TimeBasis {
    /// Coordinated universal time.
    Utc,
    /// The site's local standard time all year (as EPW files are): the offset of the TMY file.
    LocalStandard,
    /// Local clock time of an IANA zone, with its daylight saving (`America/Denver`).
    Zone(chrono_tz::Tz),
}

impl FromStr for TimeBasis {
    type Err = String;

    fn from_str(s: &str) -> Result<TimeBasis, String> {
        match s {
            "utc" | "UTC" => Ok(TimeBasis::Utc),
            "local_standard" => Ok(TimeBasis::LocalStandard),
            _ => s
                .parse::<chrono_tz::Tz>()
                .map(TimeBasis::Zone)
                .map_err(|_| {
                    format!(
                    "time zone '{s}': expected 'utc', 'local_standard' or an IANA zone such as \
                     'America/Denver' or 'Europe/London'"
                )
                }),
        }
    }
}

impl Serialize for TimeBasis {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        match self {
            TimeBasis::Utc => s.serialize_str("utc"),
            TimeBasis::LocalStandard => s.serialize_str("local_standard"),
            TimeBasis::Zone(tz) => s.serialize_str(tz.name()),
        }
    }
}

impl<'de> Deserialize<'de> for TimeBasis {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<TimeBasis, D::Error> {
        String::deserialize(d)?
            .parse()
            .map_err(serde::de::Error::custom)
    }
}

impl schemars::JsonSchema for TimeBasis {
    fn schema_name() -> std::borrow::Cow<'static, str> {
        "TimeBasis".into()
    }

    fn json_schema(_: &mut schemars::SchemaGenerator) -> schemars::Schema {
        schemars::json_schema!({
            "description": "The time in which the time stamps are written: \"utc\" (or \"UTC\"), \"local_standard\" (the site's standard time all year, as EPW files are), or an IANA zone (\"America/Denver\"), local clock time with its daylight saving.",
            "type": "string",
            "examples": ["utc", "local_standard", "America/Denver"]
        })
    }
}

/// [`Unit`]'s schema takes its aliases too (serde's `alias`, which the derive leaves out).
fn unit_aliases(schema: &mut schemars::Schema) {
    let alias = schemars::json_schema!({
        "type": "string",
        "const": "mbar",
        "description": "Millibar (hectopascal, `hPa`)."
    })
    .to_value();
    if let Some(variants) = schema.get_mut("oneOf").and_then(|v| v.as_array_mut()) {
        variants.push(alias);
    } else if let Some(names) = schema.get_mut("enum").and_then(|v| v.as_array_mut()) {
        names.push("mbar".into());
    }
}

/// A unit a weather CSV column may be in.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema)]
#[schemars(transform = unit_aliases)]
pub enum Unit {
    /// Degrees Celsius.
    #[serde(rename = "C")]
    Celsius,
    /// Degrees Fahrenheit.
    #[serde(rename = "F")]
    Fahrenheit,
    /// Kelvin.
    #[serde(rename = "K")]
    Kelvin,
    /// Percent (relative humidity).
    #[serde(rename = "%")]
    Percent,
    /// Pascal.
    #[serde(rename = "Pa")]
    Pascal,
    /// Hectopascal (millibar).
    #[serde(rename = "hPa", alias = "mbar")]
    Hectopascal,
    /// Kilopascal.
    #[serde(rename = "kPa")]
    Kilopascal,
    /// Inches of mercury.
    #[serde(rename = "inHg")]
    InchMercury,
    /// Metres per second.
    #[serde(rename = "m/s")]
    MetrePerSecond,
    /// Kilometres per hour.
    #[serde(rename = "km/h")]
    KilometrePerHour,
    /// Miles per hour.
    #[serde(rename = "mph")]
    MilePerHour,
    /// Knots.
    #[serde(rename = "kn")]
    Knot,
    /// Watts per square metre.
    #[serde(rename = "W/m2")]
    WattPerSquareMetre,
    /// Degrees (wind direction).
    #[serde(rename = "deg")]
    Degree,
    /// Tenths of the sky (cover).
    #[serde(rename = "tenths")]
    Tenths,
    /// Eighths of the sky (cover).
    #[serde(rename = "oktas")]
    Oktas,
}

impl Unit {
    /// The unit's name as written in a column map.
    pub fn name(self) -> &'static str {
        match self {
            Unit::Celsius => "C",
            Unit::Fahrenheit => "F",
            Unit::Kelvin => "K",
            Unit::Percent => "%",
            Unit::Pascal => "Pa",
            Unit::Hectopascal => "hPa",
            Unit::Kilopascal => "kPa",
            Unit::InchMercury => "inHg",
            Unit::MetrePerSecond => "m/s",
            Unit::KilometrePerHour => "km/h",
            Unit::MilePerHour => "mph",
            Unit::Knot => "kn",
            Unit::WattPerSquareMetre => "W/m2",
            Unit::Degree => "deg",
            Unit::Tenths => "tenths",
            Unit::Oktas => "oktas",
        }
    }

    /// Converts `v` in this unit to `field`'s unit, or says why the unit does not fit the field.
    pub fn convert(self, field: Field, v: f64) -> Result<f64, String> {
        use Field::*;
        use Unit::*;
        Ok(match (field, self) {
            (DryBulb | DewPoint, Celsius) => v,
            (DryBulb | DewPoint, Fahrenheit) => (v - 32.0) * 5.0 / 9.0,
            (DryBulb | DewPoint, Kelvin) => v - 273.15,
            (RelHumidity, Percent) => v,
            (Pressure, Pascal) => v,
            (Pressure, Hectopascal) => v * 100.0,
            (Pressure, Kilopascal) => v * 1000.0,
            (Pressure, InchMercury) => v * 3386.389,
            (WindSpeed, MetrePerSecond) => v,
            (WindSpeed, KilometrePerHour) => v / 3.6,
            (WindSpeed, MilePerHour) => v * 0.44704,
            (WindSpeed, Knot) => v * 0.514444,
            (WindDirection, Degree) => v,
            (GlobalHorizontal, WattPerSquareMetre) => v,
            (SkyCover, Tenths) => v,
            (SkyCover, Oktas) => v * 10.0 / 8.0,
            (SkyCover, Percent) => v / 10.0,
            _ => {
                return Err(format!(
                    "unit '{}' does not fit field {}",
                    self.name(),
                    field.name()
                ))
            }
        })
    }
}

/// One column of a weather CSV: its header, the field it measures and its unit.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct CsvColumn {
    /// The column's header.
    pub column: String,
    /// The field it measures.
    pub field: Field,
    /// Its unit.
    pub unit: Unit,
}

/// How to read a CSV of measured weather.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CsvSpec {
    /// Header of the time-stamp column.
    pub timestamp_column: String,
    /// A chrono format (`%m/%d/%Y %H:%M`); by default ISO 8601 (`2017-01-01T00:00`, a space for
    /// the `T`, seconds optional).
    #[serde(default)]
    pub timestamp_format: Option<String>,
    /// The time the stamps are in.
    pub time_zone: TimeBasis,
    /// What a stamp means (an instant, or the end or start of an averaging interval).
    #[serde(default)]
    pub stamp: Stamp,
    /// The measured columns.
    pub columns: Vec<CsvColumn>,
}

fn parse_time(s: &str, format: Option<&str>) -> Option<NaiveDateTime> {
    let s = s.trim();
    if let Some(f) = format {
        return NaiveDateTime::parse_from_str(s, f).ok();
    }
    [
        "%Y-%m-%dT%H:%M:%S",
        "%Y-%m-%dT%H:%M",
        "%Y-%m-%d %H:%M:%S",
        "%Y-%m-%d %H:%M",
    ]
    .iter()
    .find_map(|f| NaiveDateTime::parse_from_str(s, f).ok())
}

/// Parses a CSV of measured weather; `standard_offset_h` is the site's standard time (the TMY
/// file's), used for [`TimeBasis::LocalStandard`].
pub fn parse_weather_csv(
    text: &str,
    path: &Path,
    spec: &CsvSpec,
    standard_offset_h: f64,
) -> Result<Vec<Observation>, WeatherError> {
    let mut reader = csv::ReaderBuilder::new()
        .flexible(true)
        .from_reader(text.as_bytes());
    let headers = reader
        .headers()
        .map_err(|e| malformed(path, 1, format!("cannot read the header row: {e}")))?
        .clone();
    let find = |name: &str| -> Result<usize, WeatherError> {
        headers
            .iter()
            .position(|h| h.trim() == name)
            .ok_or_else(|| {
                let names: Vec<&str> = headers.iter().take(12).collect();
                malformed(
                    path,
                    1,
                    format!(
                        "no column '{name}' in the header (it has: {})",
                        names.join(", ")
                    ),
                )
            })
    };
    let time_col = find(&spec.timestamp_column)?;
    let mut columns = Vec::new();
    for c in &spec.columns {
        c.unit
            .convert(c.field, 0.0)
            .map_err(|e| malformed(path, 1, format!("column '{}': {e}", c.column)))?;
        columns.push((find(&c.column)?, c));
    }
    let mut out: Vec<Observation> = Vec::new();
    for (i, record) in reader.records().enumerate() {
        let lineno = i + 2;
        let record = record.map_err(|e| malformed(path, lineno, e.to_string()))?;
        let stamp = record.get(time_col).unwrap_or("");
        let local = parse_time(stamp, spec.timestamp_format.as_deref()).ok_or_else(|| {
            malformed(
                path,
                lineno,
                format!(
                    "column '{}': '{}' is not a time ({})",
                    spec.timestamp_column,
                    excerpt(stamp),
                    spec.timestamp_format
                        .as_deref()
                        .unwrap_or("expected ISO 8601, e.g. 2017-01-01 13:00")
                ),
            )
        })?;
        let previous = out.last().map(|o| o.utc);
        let utc = spec
            .time_zone
            .to_utc(local, standard_offset_h, previous)
            .ok_or_else(|| {
                malformed(
                    path,
                    lineno,
                    format!(
                        "'{stamp}' does not exist in {} (the hour skipped when clocks go forward)",
                        spec_zone_name(spec.time_zone)
                    ),
                )
            })?;
        let mut values = [None; 8];
        for (k, c) in &columns {
            let raw = record.get(*k).unwrap_or("").trim();
            if raw.is_empty() || raw.eq_ignore_ascii_case("nan") || raw.eq_ignore_ascii_case("na") {
                continue;
            }
            let v: f64 = raw.parse().map_err(|_| {
                malformed(
                    path,
                    lineno,
                    format!("column '{}': '{}' is not a number", c.column, excerpt(raw)),
                )
            })?;
            values[c.field.index()] = Some(c.unit.convert(c.field, v).expect("checked above"));
        }
        out.push(Observation { utc, values });
    }
    if out.is_empty() {
        return Err(malformed(path, 2, "no rows after the header".into()));
    }
    Ok(out)
}

fn spec_zone_name(b: TimeBasis) -> String {
    match b {
        TimeBasis::Utc => "UTC".into(),
        TimeBasis::LocalStandard => "local standard time".into(),
        TimeBasis::Zone(tz) => tz.name().into(),
    }
}

impl TimeBasis {
    /// UTC of a local time stamp written in this basis (`standard_offset_h`: the site's
    /// standard offset, for `LocalStandard`). In the hour that repeats when clocks go back, the
    /// earlier instant is taken unless the previous row already reached it (`previous`: the
    /// UTC of the row before, rows in time order). `None`: a clock time the zone skips.
    pub fn to_utc(
        self,
        local: NaiveDateTime,
        standard_offset_h: f64,
        previous: Option<NaiveDateTime>,
    ) -> Option<NaiveDateTime> {
        match self {
            TimeBasis::Utc => Some(local),
            TimeBasis::LocalStandard => {
                Some(local - Duration::minutes((standard_offset_h * 60.0).round() as i64))
            }
            TimeBasis::Zone(tz) => match tz.from_local_datetime(&local) {
                chrono::LocalResult::Single(t) => Some(t.naive_utc()),
                chrono::LocalResult::Ambiguous(a, b) => {
                    let (a, b) = (a.naive_utc(), b.naive_utc());
                    Some(if previous.is_some_and(|p| p >= a) {
                        b
                    } else {
                        a
                    })
                }
                chrono::LocalResult::None => None,
            },
        }
    }
}

/// Reads a CSV of measured weather (plain or gzipped).
pub fn read_weather_csv(
    path: &Path,
    spec: &CsvSpec,
    standard_offset_h: f64,
) -> Result<Vec<Observation>, WeatherError> {
    parse_weather_csv(&read_text(path)?, path, spec, standard_offset_h)
}

/// At most 60 bytes of a line, for messages.
pub(crate) fn excerpt(s: &str) -> std::borrow::Cow<'_, str> {
    bemcal_excerpt::excerpt(s, 60)
}

/// The measured sources of an EPW build, as named in a project or on the command line.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Source {
    /// NOAA ISD-lite station-year files (several for a period across years).
    IsdLite(Vec<PathBuf>),
    /// A CSV of measured weather.
    Csv {
        /// The CSV file.
        file: PathBuf,
        /// How to read it.
        spec: CsvSpec,
    },
}

impl Source {
    /// What the source's time stamps mean: ISD-lite observations are instants, a CSV says.
    pub fn stamp(&self) -> Stamp {
        match self {
            Source::IsdLite(_) => Stamp::Instant,
            Source::Csv { spec, .. } => spec.stamp,
        }
    }

    /// The EPW of `year` from this source's observations merged onto the TMY file `tmy`
    /// ([`crate::measured::build_epw`]): reads the TMY file and the observations.
    pub fn build_epw(
        &self,
        tmy: &Path,
        year: crate::grid::GridYear,
        max_interpolated_gap_h: usize,
        interval_min: u32,
    ) -> Result<(String, crate::measured::BuildReport), WeatherError> {
        let tmy_text = read_text(tmy)?;
        let observations = self.observations(&crate::Location::parse(&tmy_text, tmy)?)?;
        let opts = crate::measured::BuildOptions {
            year,
            max_interpolated_gap_h,
            stamp: self.stamp(),
            interval_min,
            source: self.describe(),
        };
        crate::measured::build_epw(&tmy_text, tmy, &observations, &opts)
    }

    /// Reads the observations of this source for a site at `location` (its elevation converts
    /// sea-level pressure, its standard time reads local-standard stamps).
    pub fn observations(
        &self,
        location: &crate::Location,
    ) -> Result<Vec<Observation>, WeatherError> {
        match self {
            Source::IsdLite(files) => {
                let mut all = Vec::new();
                for f in files {
                    all.extend(read_isd_lite(f, location.elevation_m)?);
                }
                Ok(all)
            }
            Source::Csv { file, spec } => read_weather_csv(file, spec, location.time_zone_h),
        }
    }

    /// A one-line description for the EPW header and the report.
    pub fn describe(&self) -> String {
        let name = |p: &PathBuf| {
            p.file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_default()
        };
        match self {
            Source::IsdLite(files) => format!(
                "NOAA ISD-lite {}",
                files.iter().map(name).collect::<Vec<_>>().join(" ")
            ),
            Source::Csv { file, .. } => format!("measured weather CSV {}", name(file)),
        }
    }
}

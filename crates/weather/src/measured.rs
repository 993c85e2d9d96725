//! An EPW of a metered year from measured weather, merged onto the site's typical-year file.
//!
//! ASHRAE Guideline 14 calibrates against the weather of the metering period, and nobody has an
//! EPW of last year. Stations give hourly or sub-hourly observations of some quantities (NOAA
//! ISD-lite: temperature, dew point, pressure, wind, sky cover, in UTC; a building's own station
//! or a weather service: temperature, humidity, wind, global horizontal radiation). [`build_epw`]
//! places each [`Observation`] in the hour of the year it belongs to (local standard time,
//! hour-ending, as EPW rows are), fills short gaps by linear interpolation and long ones from the
//! typical-year (TMY) file, derives what EnergyPlus needs and the station did not give (relative
//! humidity from dry bulb and dew point, direct and diffuse solar from global horizontal by Erbs'
//! model: [`crate::solar`]), and writes the TMY file's rows with the measured fields replaced,
//! so that every field no station measures (ground temperatures, illuminance, visibility,
//! precipitation) stays the site's typical value. A [`BuildReport`] counts, per field, the hours
//! measured, interpolated and taken from the TMY file.
//!
//! Leap years: EnergyPlus reads a weather file of 8,760 rows unless its header declares a leap
//! year, and bemcal's meters, surrogate and calendar are 8,760-hour years; February 29 is
//! therefore left out (as typical-year files do) and the report says so.
//!
//! Years that start in another month ([`GridYear`], `2017-04`): the rows stay in calendar order
//! (EnergyPlus reads a weather file by month and day) and January to the month before the first
//! hold the next year's weather, with that year in their year field.

use chrono::{Datelike, Duration, NaiveDateTime, Timelike};

use crate::grid::GridYear;
use serde::{Deserialize, Serialize};

use crate::solar;
use crate::{WeatherError, HOURS_PER_YEAR};
use std::path::Path;

/// A quantity a weather station measures, as EnergyPlus takes it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum Field {
    /// Dry-bulb air temperature, C.
    DryBulb,
    /// Dew-point temperature, C.
    DewPoint,
    /// Relative humidity, %.
    RelHumidity,
    /// Station (not sea-level) atmospheric pressure, Pa.
    Pressure,
    /// Wind direction, degrees clockwise from north (the direction it blows from).
    WindDirection,
    /// Wind speed, m/s.
    WindSpeed,
    /// Global horizontal radiation, W/m2 averaged over the interval (Wh/m2 over an hour).
    GlobalHorizontal,
    /// Total sky cover, tenths (0..=10).
    SkyCover,
}

impl Field {
    /// Every field, in the order of [`Observation::values`].
    pub const ALL: [Field; 8] = [
        Field::DryBulb,
        Field::DewPoint,
        Field::RelHumidity,
        Field::Pressure,
        Field::WindDirection,
        Field::WindSpeed,
        Field::GlobalHorizontal,
        Field::SkyCover,
    ];

    /// Position in [`Observation::values`].
    pub fn index(self) -> usize {
        self as usize
    }

    /// The field's column in an EPW data row (0-based).
    fn epw_column(self) -> usize {
        match self {
            Field::DryBulb => 6,
            Field::DewPoint => 7,
            Field::RelHumidity => 8,
            Field::Pressure => 9,
            Field::GlobalHorizontal => 13,
            Field::WindDirection => 20,
            Field::WindSpeed => 21,
            Field::SkyCover => 22,
        }
    }

    /// The field's name in files and messages.
    pub fn name(self) -> &'static str {
        match self {
            Field::DryBulb => "dry_bulb",
            Field::DewPoint => "dew_point",
            Field::RelHumidity => "rel_humidity",
            Field::Pressure => "pressure",
            Field::WindDirection => "wind_direction",
            Field::WindSpeed => "wind_speed",
            Field::GlobalHorizontal => "global_horizontal",
            Field::SkyCover => "sky_cover",
        }
    }

    /// The plausible range of the field (values outside are treated as missing and counted).
    fn range(self) -> (f64, f64) {
        match self {
            Field::DryBulb | Field::DewPoint => (-70.0, 60.0),
            Field::RelHumidity => (0.0, 100.0),
            Field::Pressure => (31_000.0, 120_000.0),
            Field::WindDirection => (0.0, 360.0),
            Field::WindSpeed => (0.0, 40.0),
            Field::GlobalHorizontal => (0.0, 1_400.0),
            Field::SkyCover => (0.0, 10.0),
        }
    }
}

/// How an observation's time stamp relates to what it measured.
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, schemars::JsonSchema,
)]
#[serde(rename_all = "snake_case")]
pub enum Stamp {
    /// A value at that instant (synoptic observations such as ISD-lite): it goes to the EPW
    /// hour ending at the nearest whole hour.
    #[default]
    Instant,
    /// A mean over the interval that ends at the stamp.
    IntervalEnding,
    /// A mean over the interval that begins at the stamp (of length `interval_min`).
    IntervalBeginning,
}

/// One observation: a time in UTC and the fields measured then (`None`: not measured).
#[derive(Debug, Clone, PartialEq)]
pub struct Observation {
    /// When it was observed, UTC.
    pub utc: NaiveDateTime,
    /// Each [`Field`] in the order of [`Field::ALL`], in its unit.
    pub values: [Option<f64>; 8],
}

/// Options of [`build_epw`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BuildOptions {
    /// The year the EPW covers: a calendar year or twelve months from another month.
    pub year: GridYear,
    /// Gaps up to this many hours are interpolated linearly; longer ones come from the TMY file.
    pub max_interpolated_gap_h: usize,
    /// What the observations' time stamps mean.
    pub stamp: Stamp,
    /// Interval of interval-mean observations, minutes (used with [`Stamp::IntervalBeginning`]).
    pub interval_min: u32,
    /// A line for the EPW's COMMENTS 2 header: where the measured data came from.
    pub source: String,
}

/// How one field of the built EPW was obtained, in hours.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct FieldReport {
    /// The field.
    pub field: Field,
    /// Hours with a measured value (the mean of the observations in the hour).
    pub measured_h: usize,
    /// Hours filled by linear interpolation across a short gap.
    pub interpolated_h: usize,
    /// Hours taken from the TMY file (long gaps, the ends of the year, or never measured).
    pub from_tmy_h: usize,
    /// Longest run of hours taken from the TMY file.
    pub longest_tmy_run_h: usize,
    /// Observations outside the field's plausible range, dropped.
    pub implausible: usize,
    /// For a humidity field computed from the other two (dry bulb and dew point or relative
    /// humidity), their names: its counts are then those of the measured humidity field.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub derived_from: Option<String>,
}

/// Where the solar radiation of the built EPW came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum SolarSource {
    /// Measured global horizontal, split into direct and diffuse by Erbs et al. (1982).
    MeasuredGlobalErbs,
    /// The TMY file's solar fields (no radiation was measured).
    Tmy,
}

/// What [`build_epw`] did, for the user and the calibration report.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct BuildReport {
    /// Where the measured data came from (the EPW's COMMENTS 2 line).
    pub source: String,
    /// The year built.
    pub year: GridYear,
    /// Observations given.
    pub observations: usize,
    /// Observations outside the year (in local standard time), left out.
    pub outside_year: usize,
    /// True when the year holds a 29 February, left out.
    pub leap_day_dropped: bool,
    /// Where the solar radiation came from.
    pub solar: SolarSource,
    /// How each field was obtained.
    pub fields: Vec<FieldReport>,
}

impl BuildReport {
    /// Report of one field.
    pub fn field(&self, f: Field) -> &FieldReport {
        &self.fields[f.index()]
    }
}

/// Index of the EPW hour (0..8760, hour-ending, February 29 skipped) that local standard time
/// `t` ends, or `None` outside `year` or on February 29. Midnight belongs to hour 24 of the day
/// before.
pub fn hour_slot(year: GridYear, t: NaiveDateTime) -> Option<usize> {
    let ending = t - Duration::seconds(1);
    year.slot_of(ending.date().and_hms_opt(ending.hour(), 0, 0)?)
}

/// Day of year (1-based, February 29 counted as in the real calendar) of EPW hour `slot`.
fn slot_doy(year: GridYear, slot: usize) -> f64 {
    year.day_date(slot / 24).ordinal() as f64
}

/// The EPW hour an observation belongs to, after moving it to local standard time.
fn observation_slot(o: &Observation, time_zone_h: f64, opts: &BuildOptions) -> Option<usize> {
    let lst = o.utc + Duration::minutes((time_zone_h * 60.0).round() as i64);
    let t = match opts.stamp {
        Stamp::Instant => {
            let rounded = lst + Duration::minutes(30);
            rounded
                .with_minute(0)
                .and_then(|r| r.with_second(0))
                .unwrap_or(rounded)
        }
        Stamp::IntervalEnding => lst,
        Stamp::IntervalBeginning => lst + Duration::minutes(opts.interval_min as i64),
    };
    hour_slot(opts.year, t)
}

/// Hourly means of each field: sums and counts per slot (wind direction as a unit vector).
struct Hourly {
    sum: Vec<[f64; 8]>,
    count: Vec<[u32; 8]>,
    /// Sine sums of wind direction (cosines are in `sum`).
    sin: Vec<f64>,
    implausible: [usize; 8],
}

impl Hourly {
    fn new() -> Hourly {
        Hourly {
            sum: vec![[0.0; 8]; HOURS_PER_YEAR],
            count: vec![[0; 8]; HOURS_PER_YEAR],
            sin: vec![0.0; HOURS_PER_YEAR],
            implausible: [0; 8],
        }
    }

    fn add(&mut self, slot: usize, o: &Observation) {
        for f in Field::ALL {
            let Some(v) = o.values[f.index()] else {
                continue;
            };
            let (lo, hi) = f.range();
            if !v.is_finite() || v < lo || v > hi {
                self.implausible[f.index()] += 1;
                continue;
            }
            let i = f.index();
            if f == Field::WindDirection {
                self.sum[slot][i] += v.to_radians().cos();
                self.sin[slot] += v.to_radians().sin();
            } else {
                self.sum[slot][i] += v;
            }
            self.count[slot][i] += 1;
        }
    }

    fn mean(&self, slot: usize, f: Field) -> Option<f64> {
        let i = f.index();
        let n = self.count[slot][i];
        if n == 0 {
            return None;
        }
        if f == Field::WindDirection {
            let deg = self.sin[slot].atan2(self.sum[slot][i]).to_degrees();
            return Some(if deg < 0.0 { deg + 360.0 } else { deg });
        }
        Some(self.sum[slot][i] / n as f64)
    }
}

/// How an hour's value was obtained.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Origin {
    Measured,
    Interpolated,
    Tmy,
}

/// Fills a series' gaps: runs of up to `max_gap` missing hours between two values are
/// interpolated linearly (wind direction along the shorter arc), the rest taken from `tmy`.
fn fill(
    series: &[Option<f64>],
    tmy: &[f64],
    max_gap: usize,
    circular: bool,
) -> (Vec<f64>, Vec<Origin>) {
    let n = series.len();
    let mut out = vec![0.0; n];
    let mut origin = vec![Origin::Tmy; n];
    let mut t = 0;
    while t < n {
        if let Some(v) = series[t] {
            out[t] = v;
            origin[t] = Origin::Measured;
            t += 1;
            continue;
        }
        let start = t;
        while t < n && series[t].is_none() {
            t += 1;
        }
        let len = t - start;
        let bounded = start > 0 && t < n;
        if bounded && len <= max_gap {
            let (a, b) = (out[start - 1], series[t].expect("run ends at a value"));
            let delta = if circular {
                (b - a + 540.0).rem_euclid(360.0) - 180.0
            } else {
                b - a
            };
            for (k, slot) in (start..t).enumerate() {
                let v = a + delta * (k + 1) as f64 / (len + 1) as f64;
                out[slot] = if circular { v.rem_euclid(360.0) } else { v };
                origin[slot] = Origin::Interpolated;
            }
        } else {
            out[start..t].copy_from_slice(&tmy[start..t]);
        }
    }
    (out, origin)
}

fn report_of(field: Field, origin: &[Origin], implausible: usize) -> FieldReport {
    let count = |o| origin.iter().filter(|&&x| x == o).count();
    let mut longest = 0;
    let mut run = 0;
    for &o in origin {
        run = if o == Origin::Tmy { run + 1 } else { 0 };
        longest = longest.max(run);
    }
    FieldReport {
        field,
        measured_h: count(Origin::Measured),
        interpolated_h: count(Origin::Interpolated),
        from_tmy_h: count(Origin::Tmy),
        longest_tmy_run_h: longest,
        implausible,
        derived_from: None,
    }
}

/// Saturation vapour pressure over water, hPa (Alduchov & Eskridge 1996, "Improved Magnus form
/// approximation of saturation vapor pressure", J. Appl. Meteor. 35, 601-609, eq. 21).
pub fn saturation_vapour_pressure_hpa(t_c: f64) -> f64 {
    6.1094 * (17.625 * t_c / (t_c + 243.04)).exp()
}

/// Relative humidity, %, from dry bulb and dew point (the same Magnus form), at most 100.
pub fn relative_humidity_pct(dry_bulb_c: f64, dew_point_c: f64) -> f64 {
    (100.0 * saturation_vapour_pressure_hpa(dew_point_c)
        / saturation_vapour_pressure_hpa(dry_bulb_c))
    .min(100.0)
}

/// Dew point, C, from dry bulb and relative humidity (the Magnus form inverted).
pub fn dew_point_c(dry_bulb_c: f64, rel_humidity_pct: f64) -> f64 {
    let g = (rel_humidity_pct.max(1.0) / 100.0).ln() + 17.625 * dry_bulb_c / (243.04 + dry_bulb_c);
    243.04 * g / (17.625 - g)
}

/// Station pressure, Pa, from sea-level pressure at elevation `z_m` (the standard atmosphere:
/// ASHRAE Handbook of Fundamentals 2017, ch. 1, eq. 3).
pub fn station_pressure_pa(sea_level_pa: f64, z_m: f64) -> f64 {
    sea_level_pa * (1.0 - 2.25577e-5 * z_m).powf(5.2559)
}

/// The TMY file's lines split into header and rows of fields, with its location.
struct TmyText<'a> {
    header: Vec<&'a str>,
    rows: Vec<Vec<&'a str>>,
    location: crate::Location,
}

fn split_tmy<'a>(text: &'a str, path: &Path) -> Result<TmyText<'a>, WeatherError> {
    // Validates the file as bemcal reads any EPW (8,760 rows, numeric fields).
    let epw = crate::Epw::parse(text, path)?;
    let mut header = Vec::new();
    let mut rows = Vec::with_capacity(HOURS_PER_YEAR);
    let mut in_data = false;
    for line in text.lines() {
        if in_data {
            if !line.trim().is_empty() {
                rows.push(line.split(',').collect());
            }
        } else {
            header.push(line);
            in_data = line.starts_with("DATA PERIODS");
        }
    }
    Ok(TmyText {
        header,
        rows,
        location: epw.location,
    })
}

/// Builds the EPW text of `opts.year` from `observations` merged onto the TMY file `tmy_text`
/// (its `tmy_path` names it in errors). Pure: no file is read or written.
pub fn build_epw(
    tmy_text: &str,
    tmy_path: &Path,
    observations: &[Observation],
    opts: &BuildOptions,
) -> Result<(String, BuildReport), WeatherError> {
    let tmy = split_tmy(tmy_text, tmy_path)?;
    let loc = &tmy.location;
    let mut hourly = Hourly::new();
    let mut outside = 0;
    for o in observations {
        match observation_slot(o, loc.time_zone_h, opts) {
            Some(slot) => hourly.add(slot, o),
            None => outside += 1,
        }
    }
    let (filled, mut reports) = fill_fields(&tmy, &hourly, opts);
    // What the observations gave, before a humidity field derived from the other is reported.
    let measured: Vec<bool> = reports.iter().map(|r| r.measured_h > 0).collect();
    let humidity_from_dew_point = derive_humidity_report(&mut reports, &measured);
    let solar = if measured[Field::GlobalHorizontal.index()] {
        SolarSource::MeasuredGlobalErbs
    } else {
        SolarSource::Tmy
    };
    let merged = Merged {
        filled,
        measured,
        humidity_from_dew_point,
        solar,
    };
    let mut out = String::with_capacity(tmy_text.len());
    write_header(&mut out, &tmy.header, opts);
    for (t, row) in tmy.rows.iter().enumerate() {
        out.push_str(&merged.row(row, t, loc, opts.year).join(","));
        out.push('\n');
    }
    let report = BuildReport {
        source: opts.source.clone(),
        year: opts.year,
        observations: observations.len(),
        outside_year: outside,
        leap_day_dropped: opts.year.spans_leap_day(),
        solar,
        fields: reports,
    };
    Ok((out, report))
}

/// Each field's hourly series: the observations' hourly means, gaps up to
/// `opts.max_interpolated_gap_h` interpolated, longer ones from the TMY file; with its report.
fn fill_fields(
    tmy: &TmyText<'_>,
    hourly: &Hourly,
    opts: &BuildOptions,
) -> (Vec<Vec<f64>>, Vec<FieldReport>) {
    let tmy_value = |f: Field| -> Vec<f64> {
        tmy.rows
            .iter()
            .map(|r| r[f.epw_column()].trim().parse::<f64>().unwrap_or(f64::NAN))
            .collect()
    };
    let mut filled: Vec<Vec<f64>> = Vec::new();
    let mut reports = Vec::new();
    for f in Field::ALL {
        let series: Vec<Option<f64>> = (0..HOURS_PER_YEAR).map(|t| hourly.mean(t, f)).collect();
        let (values, origin) = fill(
            &series,
            &tmy_value(f),
            opts.max_interpolated_gap_h,
            f == Field::WindDirection,
        );
        reports.push(report_of(f, &origin, hourly.implausible[f.index()]));
        filled.push(values);
    }
    (filled, reports)
}

/// Which humidity field the rows compute from dry bulb and the other: relative humidity from
/// the dew point when the dew point was measured or relative humidity was not (returns
/// `true`), else the dew point from relative humidity. When the source field was measured, the
/// derived field's report becomes the source's, saying so.
fn derive_humidity_report(reports: &mut [FieldReport], measured: &[bool]) -> bool {
    let measured = |f: Field| measured[f.index()];
    let humidity_from_dew_point = measured(Field::DewPoint) || !measured(Field::RelHumidity);
    let (derived, from) = if humidity_from_dew_point {
        (Field::RelHumidity, Field::DewPoint)
    } else {
        (Field::DewPoint, Field::RelHumidity)
    };
    if measured(from) {
        let implausible = reports[derived.index()].implausible;
        reports[derived.index()] = FieldReport {
            field: derived,
            implausible,
            derived_from: Some(format!("dry_bulb and {}", from.name())),
            ..reports[from.index()].clone()
        };
    }
    humidity_from_dew_point
}

/// The TMY file's header lines, with `COMMENTS 2` naming the source and `DATA PERIODS` the
/// year's first weekday.
fn write_header(out: &mut String, header: &[&str], opts: &BuildOptions) {
    for line in header {
        if line.starts_with("COMMENTS 2") {
            out.push_str(&format!(
                "COMMENTS 2,bemcal weather: {} merged onto this TMY file for {}\n",
                opts.source.replace(',', ";"),
                opts.year
            ));
        } else if line.starts_with("DATA PERIODS") {
            let jan1 = opts.year.day_date(0);
            out.push_str(&format!(
                "DATA PERIODS,1,1,Data,{}, 1/ 1,12/31\n",
                crate::grid::weekday_name(jan1.weekday())
            ));
        } else {
            out.push_str(line);
            out.push('\n');
        }
    }
}

/// The filled fields and what was measured, for writing the EPW's rows.
struct Merged {
    filled: Vec<Vec<f64>>,
    measured: Vec<bool>,
    humidity_from_dew_point: bool,
    solar: SolarSource,
}

impl Merged {
    fn v(&self, f: Field, t: usize) -> f64 {
        self.filled[f.index()][t]
    }

    fn measured(&self, f: Field) -> bool {
        self.measured[f.index()]
    }

    /// Row `t` of the EPW: the TMY row with the year, the filled fields and, from measured
    /// global radiation, its Erbs split.
    fn row(&self, row: &[&str], t: usize, loc: &crate::Location, year: GridYear) -> Vec<String> {
        let v = |f: Field| self.v(f, t);
        let mut r: Vec<String> = row.iter().map(|s| s.to_string()).collect();
        r[0] = year.day_date(t / 24).year().to_string();
        let t_db = v(Field::DryBulb);
        let (t_dp, rh) = if self.humidity_from_dew_point {
            let dp = v(Field::DewPoint).min(t_db);
            (dp, relative_humidity_pct(t_db, dp))
        } else {
            let rh = v(Field::RelHumidity).clamp(1.0, 100.0);
            (dew_point_c(t_db, rh), rh)
        };
        r[6] = format!("{t_db:.1}");
        r[7] = format!("{t_dp:.1}");
        r[8] = format!("{:.0}", rh);
        r[9] = format!("{:.0}", v(Field::Pressure));
        if self.measured(Field::DryBulb)
            || self.measured(Field::DewPoint)
            || self.measured(Field::SkyCover)
        {
            // Horizontal infrared radiation: missing, so that EnergyPlus derives it from this
            // row's dry bulb, dew point and opaque sky cover instead of the TMY year's.
            r[12] = "9999".into();
        }
        if self.solar == SolarSource::MeasuredGlobalErbs {
            let hour_mid = (t % 24) as f64 + 0.5;
            let z = solar::zenith_deg(
                slot_doy(year, t),
                hour_mid,
                loc.latitude_deg,
                loc.longitude_deg,
                loc.time_zone_h,
            );
            // Measured radiation is kept as it is; at sunrise and sunset (zenith past 87 deg at
            // mid-hour) Erbs' split makes all of it diffuse.
            let ghi = v(Field::GlobalHorizontal).max(0.0);
            let split = solar::erbs(ghi, z, slot_doy(year, t));
            r[13] = format!("{ghi:.0}");
            r[14] = format!("{:.0}", split.direct_normal);
            r[15] = format!("{:.0}", split.diffuse_horizontal);
            // Illuminance of the TMY year no longer matches: missing, EnergyPlus derives it.
            for field in &mut r[16..=18] {
                *field = "999999".into();
            }
            r[19] = "9999".into();
        }
        r[20] = format!("{:.0}", v(Field::WindDirection));
        r[21] = format!("{:.1}", v(Field::WindSpeed));
        if self.measured(Field::SkyCover) {
            let tenths = v(Field::SkyCover).round().clamp(0.0, 10.0);
            r[22] = format!("{tenths:.0}");
            r[23] = format!("{tenths:.0}");
        }
        r
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use chrono::NaiveDate;

    fn at(y: i32, m: u32, d: u32, h: u32, min: u32) -> NaiveDateTime {
        NaiveDate::from_ymd_opt(y, m, d)
            .unwrap()
            .and_hms_opt(h, min, 0)
            .unwrap()
    }

    #[test]
    fn hour_slots_are_hour_ending_and_skip_february_29() {
        assert_eq!(hour_slot(2017.into(), at(2017, 1, 1, 0, 0)), None); // hour 24 of 2016-12-31
        assert_eq!(hour_slot(2017.into(), at(2017, 1, 1, 0, 15)), Some(0));
        assert_eq!(hour_slot(2017.into(), at(2017, 1, 1, 1, 0)), Some(0));
        assert_eq!(hour_slot(2017.into(), at(2017, 1, 2, 0, 0)), Some(23));
        assert_eq!(hour_slot(2017.into(), at(2018, 1, 1, 0, 0)), Some(8759));
        assert_eq!(hour_slot(2016.into(), at(2016, 2, 29, 12, 0)), None);
        assert_eq!(hour_slot(2016.into(), at(2016, 3, 1, 1, 0)), Some(59 * 24));
        assert_eq!(hour_slot(2016.into(), at(2017, 1, 1, 0, 0)), Some(8759));
        assert_eq!(slot_doy(2016.into(), 59 * 24), 61.0); // March 1 of a leap year
                                                          // Twelve months from April 2016: January 2017 is slot 0, March 2017 is not a leap year.
        let april: GridYear = "2016-04".parse().unwrap();
        assert_eq!(hour_slot(april, at(2017, 1, 1, 1, 0)), Some(0));
        assert_eq!(hour_slot(april, at(2016, 1, 1, 1, 0)), None);
        assert_eq!(hour_slot(april, at(2016, 4, 1, 1, 0)), Some(90 * 24));
        assert_eq!(slot_doy(april, 59 * 24), 60.0);
    }

    #[test]
    fn short_gaps_are_interpolated_long_ones_come_from_the_tmy_file() {
        let s = [
            Some(1.0),
            None,
            None,
            Some(4.0),
            None,
            None,
            None,
            Some(0.0),
            None,
        ];
        let tmy = [9.0; 9];
        let (v, o) = fill(&s, &tmy, 2, false);
        assert_eq!(&v[..4], &[1.0, 2.0, 3.0, 4.0]);
        assert_eq!(&v[4..7], &[9.0, 9.0, 9.0]);
        assert_eq!(v[8], 9.0); // the end of the series has no right-hand value
        let r = report_of(Field::DryBulb, &o, 0);
        assert_eq!((r.measured_h, r.interpolated_h, r.from_tmy_h), (3, 2, 4));
        assert_eq!(r.longest_tmy_run_h, 3);
        // Wind direction across north takes the shorter arc.
        let (v, _) = fill(&[Some(350.0), None, Some(10.0)], &[0.0; 3], 2, true);
        assert!(
            (v[1] - 0.0).abs() < 1e-9 || (v[1] - 360.0).abs() < 1e-9,
            "{}",
            v[1]
        );
    }

    #[test]
    fn humidity_and_pressure_conversions() {
        assert!((relative_humidity_pct(20.0, 20.0) - 100.0).abs() < 1e-9);
        let rh = relative_humidity_pct(25.0, 10.0);
        assert!((rh - 38.7).abs() < 0.3, "{rh}"); // psychrometric tables: 38.6 %
        assert!((dew_point_c(25.0, rh) - 10.0).abs() < 1e-6);
        // 1,609 m (Denver): the standard atmosphere's 83.4 kPa at 101.325 kPa sea level.
        let p = station_pressure_pa(101_325.0, 1609.0);
        assert!((p - 83_400.0).abs() < 200.0, "{p}");
    }
}

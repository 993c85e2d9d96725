//! EPW files of a metered year built from measured weather, on the real public data in
//! `../shared/data` (NOAA ISD-lite 2017, TMY3 files): UTC conversion, gaps, leap years, a CSV
//! with global horizontal radiation only, daylight saving and the errors a user sees.

use std::path::{Path, PathBuf};

use bemcal_weather::measured::{build_epw, BuildOptions, Field, SolarSource, Stamp};
use bemcal_weather::station::{
    parse_weather_csv, read_isd_lite, CsvColumn, CsvSpec, TimeBasis, Unit,
};
use bemcal_weather::Epw;

fn shared(rel: &str) -> Option<PathBuf> {
    let p = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../../shared/data")
        .join(rel);
    if !p.exists() {
        eprintln!("shared data {rel} not present; skipping");
    }
    p.exists().then_some(p)
}

const MSP_TMY: &str = "epw/USA_MN_Minneapolis-St.Paul.Intl.AP.726580_TMY3.epw";
const MSP_ISD: &str = "noaa_isd_lite_2017/726580-14922-2017.gz";
const GOLDEN_TMY: &str = "epw/USA_CO_Golden-NREL.724666_TMY3.epw";

fn options(year: i32, stamp: Stamp, source: &str) -> BuildOptions {
    BuildOptions {
        year: year.into(),
        max_interpolated_gap_h: 6,
        stamp,
        interval_min: 60,
        source: source.into(),
    }
}

#[test]
fn isd_lite_in_utc_becomes_the_local_standard_hours_of_the_year() {
    let (Some(tmy), Some(isd)) = (shared(MSP_TMY), shared(MSP_ISD)) else {
        return;
    };
    let tmy_text = std::fs::read_to_string(&tmy).unwrap();
    let tmy_epw = Epw::parse(&tmy_text, &tmy).unwrap();
    let obs = read_isd_lite(&isd, tmy_epw.location.elevation_m).unwrap();
    assert_eq!(obs.len(), 8759);
    let (text, report) = build_epw(
        &tmy_text,
        &tmy,
        &obs,
        &options(2017, Stamp::Instant, "NOAA ISD-lite 726580-14922-2017"),
    )
    .unwrap();
    let epw = Epw::parse(&text, Path::new("built.epw")).unwrap();

    // Minneapolis is UTC-6: EPW hour 1 of January 1 (01:00 local standard time) is the
    // 07:00 UTC observation (-2.8 C, dew point -8.3 C, 240 deg, 5.1 m/s); 00:00 local of
    // January 1 is hour 24 of 2016-12-31, so the first seven UTC observations (00:00-06:00)
    // fall outside the year.
    let h = &epw.hours[0];
    assert_eq!((h.month, h.day, h.hour), (1, 1, 1));
    assert_eq!(h.dry_bulb_c, -2.8);
    assert_eq!(h.dew_point_c, -8.3);
    assert_eq!((h.wind_direction_deg, h.wind_speed_m_s), (240.0, 5.1));
    assert_eq!(report.outside_year, 7);
    // The last seven hours of the year (local) are in the next year's UTC file: from the TMY.
    let db = report.field(Field::DryBulb);
    assert!(db.measured_h >= 8_740, "{db:?}");
    assert!(db.from_tmy_h >= 7 && db.longest_tmy_run_h >= 7, "{db:?}");
    assert_eq!(epw.hours[8759].dry_bulb_c, tmy_epw.hours[8759].dry_bulb_c);
    // Sea-level pressure converted to the station's 254 m: about 3 % lower.
    let p_ratio = epw.hours[0].pressure_pa / 100_940.0;
    assert!((0.965..0.975).contains(&p_ratio), "{p_ratio}");
    // ISD-lite has no solar radiation: the TMY file's is kept.
    assert_eq!(report.solar, SolarSource::Tmy);
    assert_eq!(
        epw.hours[4500].global_horizontal_wh_m2,
        tmy_epw.hours[4500].global_horizontal_wh_m2
    );
    // Humidity follows the measured dew point.
    let rh = report.field(Field::RelHumidity);
    assert_eq!(rh.derived_from.as_deref(), Some("dry_bulb and dew_point"));
    assert_eq!(rh.measured_h, report.field(Field::DewPoint).measured_h);
    assert!(epw.hours.iter().all(|h| h.dew_point_c <= h.dry_bulb_c));
    // 2017 is not the typical year: the temperatures differ hour by hour, not in climate.
    let mean = |e: &Epw| e.hours.iter().map(|h| h.dry_bulb_c).sum::<f64>() / 8760.0;
    let (m17, mtmy) = (mean(&epw), mean(&tmy_epw));
    assert!((m17 - mtmy).abs() < 3.0, "2017 {m17:.2} C, TMY {mtmy:.2} C");
    let same = epw
        .hours
        .iter()
        .zip(&tmy_epw.hours)
        .filter(|(a, b)| a.dry_bulb_c == b.dry_bulb_c)
        .count();
    assert!(same < 1_000, "{same} hours equal to the TMY file");
    // The header names the year's first weekday (January 1 2017 was a Sunday) and the source.
    assert!(text.contains("DATA PERIODS,1,1,Data,Sunday, 1/ 1,12/31"));
    assert!(text.contains("COMMENTS 2,bemcal weather: NOAA ISD-lite"));
    assert!(text.lines().nth(8).unwrap().starts_with("2017,1,1,1,"));
}

/// Twelve months from April 2017 with only the 2017 station-year file: April-December are the
/// station's, January-March (2018, not in the file) come from the TMY file and are counted,
/// and each row carries its own year, in calendar order as EnergyPlus reads weather files.
#[test]
fn a_year_from_april_takes_its_first_quarter_from_the_next_year() {
    let (Some(tmy), Some(isd)) = (shared(MSP_TMY), shared(MSP_ISD)) else {
        return;
    };
    let tmy_text = std::fs::read_to_string(&tmy).unwrap();
    let tmy_epw = Epw::parse(&tmy_text, &tmy).unwrap();
    let obs = read_isd_lite(&isd, tmy_epw.location.elevation_m).unwrap();
    let opts = BuildOptions {
        year: "2017-04".parse().unwrap(),
        ..options(2017, Stamp::Instant, "NOAA ISD-lite 726580-14922-2017")
    };
    let (text, report) = build_epw(&tmy_text, &tmy, &obs, &opts).unwrap();
    let epw = Epw::parse(&text, Path::new("built.epw")).unwrap();
    let april = 90 * 24;
    // January-March 2018: the TMY file's hours; April-December 2017: the station's.
    assert!(epw.hours[..april]
        .iter()
        .zip(&tmy_epw.hours)
        .all(|(a, b)| a.dry_bulb_c == b.dry_bulb_c));
    let same = epw.hours[april..]
        .iter()
        .zip(&tmy_epw.hours[april..])
        .filter(|(a, b)| a.dry_bulb_c == b.dry_bulb_c)
        .count();
    assert!(
        same < 1_000,
        "{same} hours of April-December equal to the TMY file"
    );
    let db = report.field(Field::DryBulb);
    assert!(
        db.from_tmy_h >= april && db.longest_tmy_run_h >= april - 7,
        "{db:?}"
    );
    // 2017's January-March observations fall outside the year; April's first hours do not.
    assert!(report.outside_year >= april - 24, "{}", report.outside_year);
    // Rows in calendar order, each with its year; the header names the weekday of
    // 1 January 2018 (a Monday), the first row's date.
    let rows: Vec<&str> = text.lines().skip(8).collect();
    assert!(rows[0].starts_with("2018,1,1,1,"), "{}", rows[0]);
    assert!(rows[april].starts_with("2017,4,1,1,"), "{}", rows[april]);
    assert!(text.contains("DATA PERIODS,1,1,Data,Monday, 1/ 1,12/31"));
    assert!(text.contains("for 2017-04"));
}

/// A CSV of a station that measures global horizontal radiation only, in UTC, made from the
/// Golden TMY3 file's own measured-quality GHI: the built file keeps every hour's GHI and
/// splits it into direct and diffuse with Erbs' model, close to the TMY3's own split.
#[test]
fn csv_with_global_horizontal_only_is_split_by_erbs() {
    let Some(tmy) = shared(GOLDEN_TMY) else {
        return;
    };
    let tmy_text = std::fs::read_to_string(&tmy).unwrap();
    let tmy_epw = Epw::parse(&tmy_text, &tmy).unwrap();
    // Hour-ending LST hour h of day d ends at (d, h) local standard = +7 h in UTC.
    let start = chrono::NaiveDate::from_ymd_opt(2019, 1, 1)
        .unwrap()
        .and_hms_opt(7, 0, 0)
        .unwrap();
    let mut csv = String::from("time_utc,ghi\n");
    for (t, h) in tmy_epw.hours.iter().enumerate() {
        let end = start + chrono::Duration::hours(t as i64 + 1);
        csv.push_str(&format!(
            "{},{}\n",
            end.format("%Y-%m-%d %H:%M"),
            h.global_horizontal_wh_m2
        ));
    }
    let spec = CsvSpec {
        timestamp_column: "time_utc".into(),
        timestamp_format: None,
        time_zone: TimeBasis::Utc,
        stamp: Stamp::IntervalEnding,
        columns: vec![CsvColumn {
            column: "ghi".into(),
            field: Field::GlobalHorizontal,
            unit: Unit::WattPerSquareMetre,
        }],
    };
    let obs = parse_weather_csv(&csv, Path::new("ghi.csv"), &spec, -7.0).unwrap();
    let (text, report) = build_epw(
        &tmy_text,
        &tmy,
        &obs,
        &options(2019, Stamp::IntervalEnding, "ghi.csv"),
    )
    .unwrap();
    let epw = Epw::parse(&text, Path::new("built.epw")).unwrap();
    assert_eq!(report.solar, SolarSource::MeasuredGlobalErbs);
    assert_eq!(report.field(Field::GlobalHorizontal).measured_h, 8760);
    // Dry bulb was not measured: it is the TMY file's, hour for hour.
    assert_eq!(report.field(Field::DryBulb).from_tmy_h, 8760);
    assert!(epw
        .hours
        .iter()
        .zip(&tmy_epw.hours)
        .all(|(a, b)| a.dry_bulb_c == b.dry_bulb_c));
    let kept = epw
        .hours
        .iter()
        .zip(&tmy_epw.hours)
        .filter(|(a, b)| a.global_horizontal_wh_m2 == b.global_horizontal_wh_m2)
        .count();
    assert!(
        kept >= 8_700,
        "GHI kept in {kept} hours (the rest: sun below the horizon at mid-hour)"
    );
    let sum =
        |e: &Epw, f: fn(&bemcal_weather::WeatherHour) -> f64| e.hours.iter().map(f).sum::<f64>();
    let dni = sum(&epw, |h| h.direct_normal_wh_m2) / sum(&tmy_epw, |h| h.direct_normal_wh_m2);
    let dhi =
        sum(&epw, |h| h.diffuse_horizontal_wh_m2) / sum(&tmy_epw, |h| h.diffuse_horizontal_wh_m2);
    eprintln!("Erbs / TMY3 annual: direct normal {dni:.3}, diffuse horizontal {dhi:.3}");
    assert!((0.85..1.15).contains(&dni), "direct normal ratio {dni}");
    assert!((0.85..1.15).contains(&dhi), "diffuse ratio {dhi}");
    // Closure: GHI = DHI + DNI cos(zenith) holds by construction; spot-check noon of June 21.
    let noon = 171 * 24 + 12;
    let h = &epw.hours[noon];
    assert!(h.direct_normal_wh_m2 > 0.0 && h.diffuse_horizontal_wh_m2 < h.global_horizontal_wh_m2);
}

#[test]
fn local_clock_time_with_daylight_saving_and_a_leap_day() {
    let Some(tmy) = shared(GOLDEN_TMY) else {
        return;
    };
    let tmy_text = std::fs::read_to_string(&tmy).unwrap();
    let spec = |tz: &str| CsvSpec {
        timestamp_column: "time".into(),
        timestamp_format: Some("%m/%d/%Y %H:%M".into()),
        time_zone: tz.parse().unwrap(),
        stamp: Stamp::Instant,
        columns: vec![CsvColumn {
            column: "temp".into(),
            field: Field::DryBulb,
            unit: Unit::Fahrenheit,
        }],
    };
    // 12:00 daylight time on July 1 2017 is 11:00 standard: EPW hour 11 of day 182. The
    // repeated 01:00 of November 5 is first daylight (00:00 standard: hour 24 of November 4),
    // then standard (hour 1 of November 5).
    // A CSV read in `zone` and built into the EPW of `year`: its text, report and records.
    let build = |csv: &str, zone: &str, year: i32| {
        let obs = parse_weather_csv(csv, Path::new("w.csv"), &spec(zone), -7.0).unwrap();
        let opts = options(year, Stamp::Instant, "w.csv");
        let (text, report) = build_epw(&tmy_text, &tmy, &obs, &opts).unwrap();
        let epw = Epw::parse(&text, Path::new("b.epw")).unwrap();
        (text, report, epw)
    };
    let csv = "time,temp\n07/01/2017 12:00,86\n11/05/2017 01:00,50\n11/05/2017 01:00,41\n";
    let (_, _, epw) = build(csv, "America/Denver", 2017);
    assert!((epw.hours[181 * 24 + 10].dry_bulb_c - 30.0).abs() < 1e-9);
    assert!((epw.hours[307 * 24 + 23].dry_bulb_c - 10.0).abs() < 1e-9);
    assert!((epw.hours[308 * 24].dry_bulb_c - 5.0).abs() < 1e-9);

    // 2016 is a leap year: February 29 is left out, March 1 01:00 is hour 1 of day 60.
    let csv = "time,temp\n02/28/2016 23:00,32\n02/29/2016 12:00,50\n03/01/2016 01:00,59\n";
    let (text, report, epw) = build(csv, "local_standard", 2016);
    assert!(report.leap_day_dropped);
    assert_eq!(report.outside_year, 1);
    assert!((epw.hours[58 * 24 + 22].dry_bulb_c - 0.0).abs() < 1e-9);
    assert!((epw.hours[59 * 24].dry_bulb_c - 15.0).abs() < 1e-9);
    assert_eq!((epw.hours[59 * 24].month, epw.hours[59 * 24].day), (3, 1));
    assert!(text.contains("DATA PERIODS,1,1,Data,Friday, 1/ 1,12/31"));
}

#[test]
fn bad_weather_input_names_file_line_and_field() {
    let spec = CsvSpec {
        timestamp_column: "time".into(),
        timestamp_format: None,
        time_zone: TimeBasis::Utc,
        stamp: Stamp::Instant,
        columns: vec![CsvColumn {
            column: "rh".into(),
            field: Field::RelHumidity,
            unit: Unit::Percent,
        }],
    };
    let e = parse_weather_csv(
        "time,rh\n2017-01-01 00:00,55\n2017-01-01 01:00,wet\n",
        Path::new("w.csv"),
        &spec,
        0.0,
    )
    .unwrap_err()
    .to_string();
    assert!(
        e.starts_with("w.csv:3:") && e.contains("'rh'") && e.contains("'wet'"),
        "{e}"
    );
    let e = parse_weather_csv(
        "time,RH\n2017-01-01 00:00,55\n",
        Path::new("w.csv"),
        &spec,
        0.0,
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("no column 'rh'") && e.contains("RH"), "{e}");
    let mut wrong_unit = spec.clone();
    wrong_unit.columns[0].unit = Unit::Fahrenheit;
    let e = parse_weather_csv(
        "time,rh\n2017-01-01 00:00,55\n",
        Path::new("w.csv"),
        &wrong_unit,
        0.0,
    )
    .unwrap_err()
    .to_string();
    assert!(
        e.contains("unit 'F' does not fit field rel_humidity"),
        "{e}"
    );
    let e = bemcal_weather::station::parse_isd_lite(
        "2017 01 01 00 -56 -106\n",
        Path::new("x.isd"),
        0.0,
    )
    .unwrap_err()
    .to_string();
    assert!(e.starts_with("x.isd:1:") && e.contains("12 fields"), "{e}");
    assert!("Mars/Olympus"
        .parse::<TimeBasis>()
        .unwrap_err()
        .contains("IANA"));
}

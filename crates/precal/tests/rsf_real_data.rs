//! The pre-calibration on the real NREL RSF 2011 meters (skipped when ../shared/data is absent).

use std::path::{Path, PathBuf};

use bemcal_precal::meters::{read_meters, MeterRole, MeterSpec};
use bemcal_precal::pipeline::{run, PrecalOptions};
use bemcal_precal::schedule::DayLabel;
use bemcal_weather::{DayType, Epw};

fn shared(rel: &str) -> Option<PathBuf> {
    let p = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../../shared/data")
        .join(rel);
    p.exists().then_some(p)
}

fn rsf() -> Option<(PathBuf, PathBuf)> {
    Some((
        shared("nrel_rsf_2011/rsfmeasureddata2011.csv")?,
        shared("epw/USA_CO_Golden-NREL.724666_TMY3.epw")?,
    ))
}

#[test]
fn rsf_meters_ingest_with_auto_detection() {
    let Some((csv, _)) = rsf() else {
        eprintln!("shared data absent; skipping");
        return;
    };
    let m = read_meters(&csv, &MeterSpec::default(), None, None).unwrap();
    assert_eq!(m.year, 2011.into());
    assert!(
        m.notes.iter().any(|n| n.contains("hour-ending")),
        "{:?}",
        m.notes
    );
    assert!(
        m.notes.iter().any(|n| n.contains("none (standard time)")),
        "{:?}",
        m.notes
    );
    let h = m.get(&MeterRole::Heating).unwrap();
    assert_eq!(h.values.len(), 8760);
    // First row "01/01/2011 01:00" (hour-ending) = slot 0; the last hour of the year is absent.
    assert_eq!(h.values[0], 936.0);
    assert!(h.values[8759].is_nan());
    assert_eq!(h.values.iter().filter(|v| v.is_nan()).count(), 1);
    // Row "1/13/2011 0:00" (unpadded) = 12 January 23:00 hour-beginning.
    let e = m.get(&MeterRole::Electricity).unwrap();
    assert!(e.values[11 * 24 + 23].is_finite());
    let mean_dc: f64 = m.submeter("data_center").unwrap().values[..8759]
        .iter()
        .sum::<f64>()
        / 8759.0;
    assert!((mean_dc - 102.0).abs() < 1.5, "{mean_dc}");
    assert!(m.submeter("lighting").is_some() && m.submeter("plug_loads").is_some());
}

#[test]
fn rsf_precalibration_finds_bases_day_types_and_intervals() {
    let Some((csv, epw)) = rsf() else {
        eprintln!("shared data absent; skipping");
        return;
    };
    let m = read_meters(&csv, &MeterSpec::default(), None, None).unwrap();
    let w = Epw::read(&epw).unwrap();
    let outdoor: Vec<f64> = w.hours.iter().map(|h| h.dry_bulb_c).collect();
    let r = run(m, &outdoor, &PrecalOptions::default()).unwrap();
    let est = |n: &str| r.disaggregation.estimate(n).unwrap().value;

    // Data center: a near-constant ~100 kW electricity base.
    let dc = est("electricity_base_kw");
    assert!((95.0..110.0).contains(&dc), "data center base {dc}");
    assert!(r
        .disaggregation
        .estimate("electricity_base_kw")
        .unwrap()
        .method
        .contains("data_center"));
    // Heating base: non-heating season is summer (Golden), where RSF heating is ~0: the base is
    // small next to the winter heating (hundreds of kW).
    let nh = &r.disaggregation.non_heating_months;
    assert!(
        nh.contains(&7) && nh.contains(&8) && !nh.contains(&1),
        "{nh:?}"
    );
    let hb = est("heating_base_mean_kw");
    assert!((0.0..20.0).contains(&hb), "heating base {hb}");
    let sh = &r.disaggregation.get("space_heating").unwrap().values;
    let jan: f64 = sh[..744].iter().filter(|v| v.is_finite()).sum::<f64>() / 744.0;
    assert!(jan > 200.0, "January space heating {jan}");
    // Cooling base from winter: RSF cooling is ~0 in winter.
    assert!(est("cooling_base_kw") < 5.0);

    // Day types: the weekday cluster(s) hold mostly calendar weekdays, weekend mostly off days.
    let c = &r.clusters;
    assert!((2..=6).contains(&c.clustering.k));
    let (mut wd_in_wd, mut n_wd, mut off_in_we, mut n_we) = (0, 0, 0, 0);
    for d in &c.days {
        match d.label {
            Some(DayLabel::Weekday) => {
                n_wd += 1;
                wd_in_wd += usize::from(d.calendar == DayType::Weekday);
            }
            Some(DayLabel::Weekend) => {
                n_we += 1;
                off_in_we += usize::from(d.calendar.is_off_day());
            }
            // The RSF's day types are weak: labelled by the calendar, never partial.
            Some(DayLabel::Partial) => panic!("a partial day on {}", d.date),
            None => {}
        }
    }
    assert!(n_wd > 200 && n_we > 80, "weekday {n_wd}, weekend {n_we}");
    assert!(wd_in_wd as f64 / n_wd as f64 > 0.9, "{wd_in_wd}/{n_wd}");
    assert!(off_in_we as f64 / n_we as f64 > 0.8, "{off_in_we}/{n_we}");

    // Intervals: 48 hourly fractions reduced.
    let (before, after) = r.reduction();
    assert_eq!(before, 48);
    assert!((4..48).contains(&after), "{after}");
    let wd = r.schedule(DayLabel::Weekday).unwrap();
    let we = r.schedule(DayLabel::Weekend).unwrap();
    assert_eq!(*wd.boundaries().last().unwrap(), 24);
    // Weekday daytime fractions exceed weekend daytime fractions.
    assert!(wd.hours[11].median > we.hours[11].median + 0.1);
    for p in &r.priors.parameter {
        assert!(p.min < p.max && p.min <= p.mode && p.mode <= p.max, "{p:?}");
    }
    let n_sched = r
        .priors
        .parameter
        .iter()
        .filter(|p| p.name.starts_with("schedule_"))
        .count();
    assert_eq!(n_sched, after);
    // The data center is suggested as a base of the electricity meter, hour by hour from its
    // sub-meter; the night electricity base (the building's own) is not.
    let suggested = r.suggested_bases();
    assert!(
        suggested
            .iter()
            .any(|b| b.output == "electricity_kwh" && b.submeter.as_deref() == Some("data_center")),
        "{suggested:?}"
    );
    let text = bemcal_precal::io::summary_text(&r, "precal");
    assert!(
        text.contains("[[bases]]\n  output = \"electricity_kwh\"\n  submeter = \"data_center\""),
        "{text}"
    );
    eprintln!("{text}");
}

#[test]
fn rsf_example_project_matches_auto_detection_and_writes_outputs() {
    let Some((csv, epw)) = rsf() else {
        eprintln!("shared data absent; skipping");
        return;
    };
    let proj_path = Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/rsf_project.toml");
    let proj = bemcal_precal::io::PrecalProject::read(&proj_path).unwrap();
    assert_eq!(proj.year, Some(2011.into()));
    let spec = proj.meters.clone().unwrap();
    let m = read_meters(&csv, &spec, proj.year, None).unwrap();
    let auto = read_meters(&csv, &MeterSpec::default(), None, None).unwrap();
    for s in &m.series {
        assert_eq!(s.values.len(), 8760);
        let a = auto.get(&s.role).unwrap();
        assert!(s
            .values
            .iter()
            .zip(&a.values)
            .all(|(x, y)| x == y || (x.is_nan() && y.is_nan())));
    }
    let w = Epw::read(&epw).unwrap();
    let outdoor: Vec<f64> = w.hours.iter().map(|h| h.dry_bulb_c).collect();
    let r = run(m, &outdoor, &proj.precalibration).unwrap();
    let dir = std::env::temp_dir().join(format!("bemcal-precal-test-{}", std::process::id()));
    let written = bemcal_precal::io::write_outputs(&dir, &r).unwrap();
    assert_eq!(written.len(), 7);
    let priors = bemcal_precal::io::read_priors(&dir.join("priors.toml")).unwrap();
    assert_eq!(priors, r.priors);
    assert_eq!(priors.parameter[0].name, "schedule_weekday_01");
    assert_eq!(
        *priors
            .schedule
            .as_ref()
            .unwrap()
            .weekend_boundaries
            .last()
            .unwrap(),
        24
    );
    let text = std::fs::read_to_string(dir.join("disaggregated.csv")).unwrap();
    assert_eq!(text.lines().count(), 8761);
    let cal = std::fs::read_to_string(dir.join("calendar.csv")).unwrap();
    assert_eq!(cal.lines().count(), 366);
    std::fs::remove_dir_all(&dir).unwrap();
}

/// 15-minute AMI readings, interval-ending, in local clock time with US daylight saving, made
/// from the RSF's real hourly whole-building load (each hour's energy spread over its four
/// quarters, the local clock shifted in summer): read back, they are the hourly meter again,
/// whether the column is energy per quarter (kWh, summed) or mean power (kW, averaged).
#[test]
fn fifteen_minute_meters_in_clock_time_aggregate_to_the_hourly_meter() {
    use chrono::{Duration, NaiveDate};
    let Some((csv, _)) = rsf() else {
        return;
    };
    let hourly = read_meters(&csv, &MeterSpec::default(), None, None).unwrap();
    let e = &hourly.get(&MeterRole::Electricity).unwrap().values;
    let dst_start = NaiveDate::from_ymd_opt(2011, 3, 13)
        .unwrap()
        .and_hms_opt(2, 0, 0)
        .unwrap();
    let dst_end = NaiveDate::from_ymd_opt(2011, 11, 6)
        .unwrap()
        .and_hms_opt(1, 0, 0)
        .unwrap();
    let start = NaiveDate::from_ymd_opt(2011, 1, 1)
        .unwrap()
        .and_hms_opt(0, 0, 0)
        .unwrap();
    let mut text = String::from("time,kwh,kw\n");
    for (t, v) in e.iter().enumerate().take(8759) {
        for q in 0..4 {
            // The quarter's start in standard time, on the local clock, stamped at its end.
            let begin = start + Duration::hours(t as i64) + Duration::minutes(15 * q);
            let in_dst = begin >= dst_start && begin < dst_end;
            let stamp = begin + Duration::hours(i64::from(in_dst)) + Duration::minutes(15);
            text.push_str(&format!(
                "{},{},{}\n",
                stamp.format("%Y-%m-%d %H:%M"),
                v / 4.0,
                v
            ));
        }
    }
    // Stated conventions, and the same detected: the first stamp 00:15 on January 1 says
    // interval-ending, the missing spring 02:00-02:45 stamps say the US clock.
    let stated = "convention = \"hour_ending\"\ndst = \"us\"\n";
    for (column, unit, conventions) in [
        ("kwh", "kWh", stated),
        ("kw", "kW", stated),
        ("kwh", "kWh", ""),
    ] {
        let spec: MeterSpec = toml::from_str(&format!(
            "timestamp_column = \"time\"\n{conventions}\
             [[columns]]\ncolumn = \"{column}\"\nrole = \"electricity\"\nunit = \"{unit}\"\n"
        ))
        .unwrap();
        let m = bemcal_precal::meters::parse_meters(
            &text,
            Path::new("ami.csv"),
            &spec,
            Some(2011.into()),
            None,
        )
        .unwrap();
        assert!(
            m.notes.iter().any(|n| n.contains("every 15 min")),
            "{:?}",
            m.notes
        );
        let got = &m.get(&MeterRole::Electricity).unwrap().values;
        let worst = (0..8759)
            .map(|t| (got[t] - e[t]).abs())
            .fold(0.0_f64, f64::max);
        assert!(worst < 1e-9, "{unit}: worst hourly difference {worst} kWh");
        assert!(got[8759].is_nan());
    }
}

/// The RSF's heating meter reads zero from 4 to 30 March 2011 (Golden's March is
/// not without heating: February averages 300 kW, April 65 kW): the quality summary lists that
/// run beside the summer's, and `exclude` makes it missing.
#[test]
fn rsf_heating_outage_is_listed_and_can_be_excluded() {
    let Some((csv, _)) = rsf() else {
        eprintln!("shared data absent; skipping");
        return;
    };
    let mut spec = MeterSpec::default();
    let m = read_meters(&csv, &spec, None, None).unwrap();
    let h = m.get(&MeterRole::Heating).unwrap();
    let q = bemcal_precal::meters::quality("heating", &h.values, m.year, 24);
    let starts: Vec<&str> = q.zero_runs.iter().map(|z| &z.start[..10]).collect();
    let march = q
        .zero_runs
        .iter()
        .find(|z| z.start.starts_with("2011-03"))
        .unwrap_or_else(|| panic!("no zero run in March: {starts:?}"));
    // 4 March 03:00 to 30 March 10:00, hour-beginning.
    assert_eq!(
        (march.start.as_str(), march.hours),
        ("2011-03-04 03:00:00", 26 * 24 + 8)
    );
    // With June-September the non-heating season and the months below 10 C the heating season
    // (what pre-calibration finds for these meters and the Golden TMY3), the March run is the
    // one in its meter's season; the summer's and the cooling meter's seven (all in the cold
    // months) are off-season.
    use bemcal_precal::meters::zero_run_in_off_season;
    let (summer, cold) = ([6, 7, 8, 9], [1, 2, 3, 4, 10, 11, 12]);
    let judge = |role, z| zero_run_in_off_season(&role, z, m.year, &summer, &cold);
    assert_eq!(q.zero_runs.len(), 2, "{:?}", q.zero_runs);
    let in_season: Vec<&str> = q
        .zero_runs
        .iter()
        .filter(|z| judge(MeterRole::Heating, z) == Some(false))
        .map(|z| &z.start[..10])
        .collect();
    assert_eq!(in_season, ["2011-03-04"]);
    let c = m.get(&MeterRole::Cooling).unwrap();
    let qc = bemcal_precal::meters::quality("cooling", &c.values, m.year, 24);
    assert_eq!(qc.zero_runs.len(), 7, "{:?}", qc.zero_runs);
    assert!(qc
        .zero_runs
        .iter()
        .all(|z| judge(MeterRole::Cooling, z) == Some(true)));
    spec.columns = bemcal_precal::meters::detect_columns(
        &["Date and Time", "Total Heating (kW)"],
        Some("Date and Time"),
    );
    spec.timestamp_column = Some("Date and Time".into());
    spec.columns[0].exclude = Some("2011-03-04..2011-03-30".parse().unwrap());
    let x = read_meters(&csv, &spec, None, None).unwrap();
    let hx = x.get(&MeterRole::Heating).unwrap();
    let missing = hx.values.iter().filter(|v| v.is_nan()).count();
    assert_eq!(missing, 1 + 27 * 24, "{:?}", x.notes);
}

//! The calendar as the meters tell it (issue 72): pre-calibration reads the building's days off
//! from what the days look like and says what to change in the model file. (The building closed
//! on Thursdays and Fridays, calibrated with its day-type file, is in tests/calibrate.rs.)

mod common;

use std::path::Path;

use common::{bemcal, have_engine, run_ok, small_model};

/// The dates of `calendar.csv` whose calendar day type is `holiday`.
fn calendar_holidays(calendar: &str) -> Vec<String> {
    calendar
        .lines()
        .skip(1)
        .filter(|l| l.split(',').nth(1) == Some("holiday"))
        .map(|l| l.split(',').next().unwrap().to_string())
        .collect()
}

/// A CSV's `column` summed over the rows whose timestamp falls on one of `dates`.
fn sum_on(path: &Path, column: &str, dates: &[String]) -> f64 {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let col = header
        .iter()
        .position(|h| *h == column)
        .unwrap_or_else(|| panic!("no {column} in {}", path.display()));
    lines
        .map(|l| l.split(',').collect::<Vec<&str>>())
        .filter(|r| dates.iter().any(|d| r[0].starts_with(d.as_str())))
        .filter_map(|r| r[col].parse::<f64>().ok())
        .filter(|v| v.is_finite())
        .sum()
}

/// A building that works every US federal holiday (meters from EnergyPlus with `holidays =
/// "none"`): pre-calibration labels the holidays as working days, suggests `holidays = "none"`
/// with the evidence, and the model with that line runs the weekday schedule on those dates
/// (EnergyPlus at the same values then matches the meters there; without it, the model runs
/// them on the weekend schedule and misses).
#[test]
fn holidays_the_building_works_are_said_and_the_line_mends_them() {
    if !have_engine() {
        eprintln!("skipping: no .venv (run `make setup`)");
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let small = small_model();
    assert!(!small.contains("holidays"), "the small model sets holidays");
    std::fs::write(dir.join("model.toml"), &small).unwrap();
    std::fs::write(
        dir.join("truth.toml"),
        format!("{small}\nholidays = \"none\"\n"),
    )
    .unwrap();
    let weather = "bundled:USA_CO_Golden-NREL.724666_TMY3.epw";
    run_ok(
        bemcal()
            .args(["synthesize", "--model"])
            .arg(dir.join("truth.toml"))
            .args(["--weather", weather, "--gap", "0:0", "--out"])
            .arg(dir.join("meters.csv")),
    );
    run_ok(
        bemcal()
            .args(["precalibrate", "--meters"])
            .arg(dir.join("meters.csv"))
            .args(["--weather", weather, "--out"])
            .arg(dir.join("precal")),
    );
    let summary = std::fs::read_to_string(dir.join("precal/summary.txt")).unwrap();
    // The calendar's holidays (US federal, the default) are labelled working days, by what they
    // look like.
    let calendar = std::fs::read_to_string(dir.join("precal/calendar.csv")).unwrap();
    let holidays = calendar_holidays(&calendar);
    assert!(holidays.len() >= 10, "{holidays:?}");
    let worked = calendar
        .lines()
        .filter(|l| {
            l.split(',').nth(1) == Some("holiday") && l.split(',').nth(3) == Some("weekday")
        })
        .count();
    assert_eq!(worked, holidays.len(), "{calendar}");
    assert!(
        summary.contains(&format!(
            "holidays worked: {worked} of {worked} calendar holidays look like working days"
        )) && summary.contains("holidays = \"none\""),
        "{summary}"
    );
    // No other advice about this ordinary weekly pattern.
    assert!(
        !summary.contains("days off on calendar weekdays")
            && !summary.contains("working days on calendar weekends")
            && !summary.contains("weak day types"),
        "{summary}"
    );
    // The line pasted as the summary prints it: the model runs the holidays on the weekday
    // schedule, as the building.
    let line = summary
        .lines()
        .find_map(|l| l.find("holidays = ").map(|i| l[i..].trim()))
        .unwrap();
    assert_eq!(line, "holidays = \"none\"", "{summary}");
    let mended = format!("{small}\n{line}\n");
    std::fs::write(dir.join("mended.toml"), mended).unwrap();
    let simulate = |model: &str, out: &str| {
        run_ok(
            bemcal()
                .args(["simulate", "--model"])
                .arg(dir.join(model))
                .args(["--weather", weather, "--out"])
                .arg(dir.join(out)),
        );
        sum_on(&dir.join(out), "electricity_kwh", &holidays)
    };
    let measured = sum_on(&dir.join("meters.csv"), "electricity_kwh", &holidays);
    let with_line = simulate("mended.toml", "mended.csv");
    let without = simulate("model.toml", "model.csv");
    eprintln!(
        "electricity on the {} holidays, kWh: meters {measured:.0}, with holidays = \"none\" \
         {with_line:.0}, with the calendar's holidays {without:.0}",
        holidays.len()
    );
    // The meters carry synthesize's 5 % noise (no gap): a sum over ten days' hours is within a
    // few %.
    assert!(
        (with_line - measured).abs() < 0.05 * measured,
        "with the line: {with_line:.0} against the meters' {measured:.0}"
    );
    assert!(
        without < 0.9 * measured,
        "without the line the holidays should run the weekend schedule: {without:.0} against {measured:.0}"
    );
}

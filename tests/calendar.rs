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

/// The weather of these tests.
const WEATHER: &str = "bundled:USA_CO_Golden-NREL.724666_TMY3.epw";

/// EnergyPlus on `model` in `dir` with `set` (`--set NAME=VALUE` pairs): `command` is
/// `synthesize` (meters with noise, no gap) or `simulate`, into `out`.
fn energyplus(dir: &Path, command: &str, model: &str, set: &[String], out: &str) {
    let gap: &[&str] = if command == "synthesize" {
        &["--gap", "0:0"]
    } else {
        &[]
    };
    run_ok(
        bemcal()
            .args([command, "--model"])
            .arg(dir.join(model))
            .args(["--weather", WEATHER])
            .args(gap)
            .args(set)
            .arg("--out")
            .arg(dir.join(out)),
    );
}

/// Pre-calibration of `dir`'s meters.csv into `dir/precal`; its summary.txt.
fn precalibrate(dir: &Path) -> String {
    run_ok(
        bemcal()
            .args(["precalibrate", "--meters"])
            .arg(dir.join("meters.csv"))
            .args(["--weather", WEATHER, "--out"])
            .arg(dir.join("precal")),
    );
    std::fs::read_to_string(dir.join("precal/summary.txt")).unwrap()
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
    energyplus(dir, "synthesize", "truth.toml", &[], "meters.csv");
    let summary = precalibrate(dir);
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
        energyplus(dir, "simulate", model, &[], out);
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

/// A building open on Saturday mornings (meters from EnergyPlus with its Saturdays labelled
/// `partial` in a day-type file, their own intervals 0-8, 8-13, 13-24 at 0.05 / 0.8 / 0.05,
/// Sundays and holidays at 0.05): pre-calibration labels the Saturdays partial days by what
/// they look like, writes their schedule priors and boundaries, and suggests the day-type
/// file; the model with it runs the Saturdays on their own intervals (EnergyPlus at the same
/// values then matches the meters on those dates; with the Saturday-Sunday rule it runs them
/// as days off and misses).
#[test]
fn saturday_half_days_run_their_own_schedule() {
    if !have_engine() {
        eprintln!("skipping: no .venv (run `make setup`)");
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let small = small_model();
    assert!(!small.contains("year"), "the small model sets its year");
    let small = format!("{small}\nyear = 2021\n");
    let saturdays: Vec<String> = (0..52)
        .map(|w| {
            (chrono::NaiveDate::from_ymd_opt(2021, 1, 2).unwrap() + chrono::Duration::weeks(w))
                .to_string()
        })
        .collect();
    let mut calendar = String::from("date,label\n");
    for d in &saturdays {
        calendar.push_str(&format!("{d},partial\n"));
    }
    std::fs::write(dir.join("true_calendar.csv"), calendar).unwrap();
    let half_day = "partial_boundaries = [8, 13, 24]\n";
    std::fs::write(
        dir.join("truth.toml"),
        format!("{small}{half_day}day_types_file = \"true_calendar.csv\"\n"),
    )
    .unwrap();
    std::fs::write(dir.join("model.toml"), &small).unwrap();
    let mut truth: Vec<String> = (1..=10)
        .map(|i| format!("schedule_weekend_{i:02}=0.05"))
        .collect();
    truth.extend(
        ["0.05", "0.8", "0.05"]
            .iter()
            .enumerate()
            .map(|(i, v)| format!("schedule_partial_{:02}={v}", i + 1)),
    );
    let set: Vec<String> = truth
        .iter()
        .flat_map(|t| ["--set".into(), t.clone()])
        .collect();
    energyplus(dir, "synthesize", "truth.toml", &set, "meters.csv");
    let summary = precalibrate(dir);
    let calendar = std::fs::read_to_string(dir.join("precal/calendar.csv")).unwrap();
    let label = |date: &str| {
        calendar
            .lines()
            .find(|l| l.starts_with(date))
            .and_then(|l| l.split(',').nth(3))
            .unwrap_or("")
            .to_string()
    };
    let partial = saturdays.iter().filter(|d| label(d) == "partial").count();
    let others = calendar
        .lines()
        .filter(|l| l.split(',').nth(3) == Some("partial"))
        .count()
        - partial;
    assert!(
        partial >= 48 && others == 0,
        "{partial} Saturdays and {others} other days partial:\n{summary}"
    );
    assert!(
        summary.contains("partial days: cluster") && summary.contains("day_types_file = \""),
        "{summary}"
    );
    let priors = std::fs::read_to_string(dir.join("precal/priors.toml")).unwrap();
    assert!(
        priors.contains("partial_boundaries") && priors.contains("schedule_partial_01"),
        "{priors}"
    );
    // The line pasted: the Saturdays run their own intervals.
    let line = summary
        .lines()
        .find_map(|l| {
            l.find("day_types_file = ")
                .map(|i| l[i..].trim().to_string())
        })
        .unwrap();
    std::fs::write(
        dir.join("mended.toml"),
        format!(
            "{small}{half_day}{}\n",
            line.replace(&dir.join("precal").display().to_string(), "precal")
        ),
    )
    .unwrap();
    let simulate = |model: &str, set: &[String], out: &str| {
        energyplus(dir, "simulate", model, set, out);
        sum_on(&dir.join(out), "electricity_kwh", &saturdays)
    };
    let measured = sum_on(&dir.join("meters.csv"), "electricity_kwh", &saturdays);
    let with_line = simulate("mended.toml", &set, "mended.csv");
    // The rule's Saturdays run the weekend intervals (the partial ones are no parameters).
    let rule_set: Vec<String> = truth
        .iter()
        .filter(|t| !t.starts_with("schedule_partial_"))
        .flat_map(|t| ["--set".into(), t.clone()])
        .collect();
    let without = simulate("model.toml", &rule_set, "rule.csv");
    let said = summary
        .lines()
        .find(|l| l.contains("partial days: cluster"));
    eprintln!("{}", said.unwrap_or(""));
    eprintln!(
        "electricity on the 52 Saturdays, kWh: meters {measured:.0}, with the day-type file \
         {with_line:.0}, with the Saturday-Sunday rule {without:.0}"
    );
    assert!(
        (with_line - measured).abs() < 0.05 * measured,
        "with the line: {with_line:.0} against the meters' {measured:.0}"
    );
    assert!(
        without < 0.9 * measured,
        "with the rule the Saturdays run as days off: {without:.0} against {measured:.0}"
    );
}

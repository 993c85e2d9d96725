//! Real EnergyPlus runs of generated models. Skipped (with a message) when no engine is installed.

use std::path::PathBuf;

use bemcal_energyplus::{
    building::{BuildingSpec, Zoning},
    params::ParameterValues,
    Engine, Error, Model, RunOptions, Runner,
};

fn runner() -> Option<Runner> {
    match Engine::locate() {
        Ok(e) => Some(Runner::new(e, RunOptions::default()).unwrap()),
        Err(e) => {
            eprintln!("skipping: {e}");
            None
        }
    }
}

/// A one-storey, one-zone-per-floor box: the smallest model that exercises the whole HVAC, at
/// one zone time step per hour (an annual run 0.57 of the time at four, its annual meters within
/// 2 %) with the HVAC step held at the zone's (0.57 of the time again, within 0.3 %); the
/// warm-up tests use [`warm_up_spec`].
fn small_spec() -> BuildingSpec {
    BuildingSpec {
        storeys: 1,
        footprint_m: [20.0, 15.0],
        zoning: Zoning::OnePerFloor,
        timesteps_per_hour: 1,
        minimum_system_timestep_minutes: Some(0),
        ..BuildingSpec::default()
    }
}

/// [`small_spec`] at four time steps per hour, as the warm-up tests' convergence figures were
/// measured.
fn warm_up_spec() -> BuildingSpec {
    BuildingSpec {
        timesteps_per_hour: 4,
        minimum_system_timestep_minutes: None,
        ..small_spec()
    }
}

fn weather(r: &Runner) -> PathBuf {
    r.engine()
        .bundled_weather("USA_CO_Golden-NREL.724666_TMY3.epw")
        .expect("engine ships Golden weather")
}

fn simulate(
    r: &Runner,
    model: &Model,
    set: &[(&str, f64)],
    dir: &std::path::Path,
) -> Result<bemcal_energyplus::HourlyOutputs, Error> {
    let given: ParameterValues = set.iter().map(|(k, v)| (k.to_string(), *v)).collect();
    let idf = model.instantiate(&given, r.idd())?;
    Ok(r.run(&idf, &weather(r), model.outputs(), dir)?.outputs)
}

#[test]
fn small_model_runs_and_reports_meters() {
    let Some(r) = runner() else { return };
    let tmp = tempfile::tempdir().unwrap();
    let model = Model::generated(small_spec());
    let out = simulate(&r, &model, &[], &tmp.path().join("base")).unwrap();
    assert_eq!(out.hours(), 8760);
    for (name, total) in out.totals() {
        eprintln!("{name}: {total:.0} kWh");
        assert!(total > 0.0, "{name} is zero");
    }
}

fn total(out: &bemcal_energyplus::HourlyOutputs, name: &str) -> f64 {
    out.get(name).unwrap().iter().sum()
}

#[test]
fn more_lighting_power_raises_electricity() {
    let Some(r) = runner() else { return };
    let tmp = tempfile::tempdir().unwrap();
    let model = Model::generated(small_spec());
    let lo = simulate(
        &r,
        &model,
        &[("lighting_power_density", 8.0)],
        &tmp.path().join("lo"),
    )
    .unwrap();
    let hi = simulate(
        &r,
        &model,
        &[("lighting_power_density", 14.0)],
        &tmp.path().join("hi"),
    )
    .unwrap();
    let (l0, l1) = (total(&lo, "lighting_kwh"), total(&hi, "lighting_kwh"));
    assert!(
        (l1 / l0 - 14.0 / 8.0).abs() < 0.01,
        "lights scale with density: {l0} -> {l1}"
    );
    assert!(total(&hi, "electricity_kwh") > total(&lo, "electricity_kwh") + 0.9 * (l1 - l0));
}

#[test]
fn lower_cooling_setpoint_raises_cooling() {
    let Some(r) = runner() else { return };
    let tmp = tempfile::tempdir().unwrap();
    let model = Model::generated(small_spec());
    let warm = simulate(
        &r,
        &model,
        &[("cooling_setpoint_occupied", 25.5)],
        &tmp.path().join("w"),
    )
    .unwrap();
    let cool = simulate(
        &r,
        &model,
        &[("cooling_setpoint_occupied", 21.5)],
        &tmp.path().join("c"),
    )
    .unwrap();
    let (c0, c1) = (total(&warm, "cooling_kwh"), total(&cool, "cooling_kwh"));
    assert!(c1 > c0 * 1.02, "cooling {c0} -> {c1}");
}

#[test]
fn one_weekday_interval_changes_only_its_hours_on_weekdays() {
    let Some(r) = runner() else { return };
    // 2021 has 261 Monday-Fridays, 12 of them federal holidays as observed (New Year's Day
    // 2022, a Saturday, is observed on Friday 31 December 2021).
    assert_eq!(weekday_interval_hours(&r, 2021.into()), 2 * (261 - 12));
}

/// In a leap year EnergyPlus simulates no 29 February and counts weekdays on, one day behind the
/// real calendar from 1 March; across a year end it runs from the first month's weekday. The
/// weekday schedule must still fall on the real weekdays, as the meters' dates have them.
#[test]
fn weekdays_are_the_real_ones_in_a_leap_year_and_across_a_year_end() {
    let Some(r) = runner() else { return };
    for year in ["2020", "2021-04"] {
        let year = year.parse().unwrap();
        assert_eq!(
            weekday_interval_hours(&r, year),
            2 * working_days(year),
            "{year}"
        );
    }
}

/// Monday-Fridays of the grid year that are not US federal holidays, by the real calendar.
fn working_days(year: bemcal_weather::grid::GridYear) -> usize {
    use chrono::Datelike;
    let holidays: Vec<_> = (year.first_year()..=year.first_year() + 1)
        .flat_map(bemcal_weather::us_federal_holidays)
        .collect();
    year.first_date()
        .iter_days()
        .take_while(|d| *d <= year.last_date())
        .filter(|d| year.covers(*d) && d.weekday().num_days_from_monday() < 5)
        .filter(|d| !holidays.contains(d))
        .count()
}

/// Simulates the small model of `year` at two values of the weekday schedule's interval 5
/// (09:00-11:00) and checks that exactly that interval's hours on the calendar's weekdays
/// (the real dates of the grid year) changed, by the ratio of the values; returns their count.
fn weekday_interval_hours(r: &Runner, year: bemcal_weather::grid::GridYear) -> usize {
    let tmp = tempfile::tempdir().unwrap();
    let spec = BuildingSpec {
        year,
        ..small_spec()
    };
    let model = Model::generated(spec.clone());
    // Interval 5 of the default weekday boundaries [6, 7, 8, 9, 11, ...] is 09:00-11:00.
    assert_eq!(&spec.weekday_boundaries[3..5], &[9, 11]);
    let a = simulate(
        r,
        &model,
        &[("schedule_weekday_05", 0.5)],
        &tmp.path().join("a"),
    )
    .unwrap();
    let b = simulate(
        r,
        &model,
        &[("schedule_weekday_05", 0.8)],
        &tmp.path().join("b"),
    )
    .unwrap();
    let cal = spec.calendar();
    let (la, lb) = (
        a.get("lighting_kwh").unwrap(),
        b.get("lighting_kwh").unwrap(),
    );
    let mut changed = 0;
    for t in 0..8760 {
        let hour = t % 24;
        let date = year.day_date(t / 24);
        let dt = cal
            .day_type(chrono::Datelike::month(&date), chrono::Datelike::day(&date))
            .unwrap();
        let inside = dt == bemcal_weather::DayType::Weekday && (9..11).contains(&hour);
        if inside {
            assert!(
                (lb[t] / la[t] - 1.6).abs() < 1e-3,
                "{year}: hour {t} ({date}, {dt}): {} vs {}",
                la[t],
                lb[t]
            );
            changed += 1;
        } else {
            assert!(
                (la[t] - lb[t]).abs() < 1e-9,
                "{year}: hour {t} ({date}, {dt}, {hour}h) changed: {} vs {}",
                la[t],
                lb[t]
            );
        }
    }
    changed
}

#[test]
fn parallel_runs_do_not_interfere() {
    let Some(r) = runner() else { return };
    let tmp = tempfile::tempdir().unwrap();
    let model = Model::generated(small_spec());
    let (a, b) = std::thread::scope(|s| {
        let ha = s.spawn(|| simulate(&r, &model, &[], &tmp.path().join("p1")));
        let hb = s.spawn(|| simulate(&r, &model, &[], &tmp.path().join("p2")));
        (ha.join().unwrap().unwrap(), hb.join().unwrap().unwrap())
    });
    assert_eq!(a, b, "identical inputs in parallel give identical outputs");
    // Reusing a run directory is refused rather than silently mixing outputs.
    let again = simulate(&r, &model, &[], &tmp.path().join("p1")).unwrap_err();
    assert!(again.to_string().contains("already holds a run"), "{again}");
}

#[test]
fn impossible_parameters_are_rejected_before_energyplus() {
    let Some(r) = runner() else { return };
    let tmp = tempfile::tempdir().unwrap();
    let model = Model::generated(small_spec());
    let dir = tmp.path().join("bad");
    let e = simulate(
        &r,
        &model,
        &[
            ("heating_setpoint_occupied", 23.0),
            ("cooling_setpoint_occupied", 21.0),
        ],
        &dir,
    )
    .unwrap_err();
    let msg = e.to_string();
    assert!(
        msg.contains("heating_setpoint_occupied") && msg.contains("cooling_setpoint_occupied"),
        "{msg}"
    );
    assert!(!dir.exists(), "EnergyPlus never started");
    let e = simulate(
        &r,
        &model,
        &[
            ("chilled_water_supply_temp", 8.0),
            ("supply_air_temp", 10.0),
        ],
        &dir,
    )
    .unwrap_err();
    assert!(e.to_string().contains("chilled water + 3 K"), "{e}");
    let e = simulate(&r, &model, &[("lighting_power", 8.0)], &dir).unwrap_err();
    assert!(e.to_string().contains("unknown parameter"), "{e}");
}

#[test]
fn severe_error_with_exit_code_zero_is_a_failure() {
    // One warm-up day leaves the loads 25 times the tolerance from converged: far outside
    // the margin, so these results are refused.
    let Some(r) = runner() else { return };
    let tmp = tempfile::tempdir().unwrap();
    let model = Model::generated(warm_up_spec());
    let mut idf = model.instantiate(&Default::default(), r.idd()).unwrap();
    let b = idf
        .objects
        .iter_mut()
        .find(|o| o.class == "Building")
        .unwrap();
    b.fields[6] = "1".into();
    b.fields[7] = "1".into();
    let dir = tmp.path().join("warmup");
    let e = r
        .run(&idf, &weather(&r), model.outputs(), &dir)
        .unwrap_err();
    let msg = e.to_string();
    assert!(msg.contains("exit code 0"), "{msg}");
    assert!(msg.contains("CheckWarmupConvergence"), "{msg}");
    assert!(
        dir.join("eplusmtr.csv").exists(),
        "EnergyPlus wrote results, and they were still refused"
    );
}

/// The issue's "did not converge after 25 warmup days" made on purpose: two warm-up days leave
/// the small model's cooling load 0.43 and its temperature 2 K from converged, against
/// tolerances widened to 0.1 and 0.5 K (the IDD maximum): not converged, but within `errfile::WARMUP_MARGIN`
/// (with EnergyPlus's 0.04 the same run is 10.6x its tolerance and refused, see
/// `severe_error_with_exit_code_zero_is_a_failure`). The run is a success, the message a note,
/// and its results are those of a converged run to 1 %.
#[test]
fn warm_up_severe_within_the_margin_is_a_note_and_its_results_are_used() {
    let Some(r) = runner() else { return };
    let tmp = tempfile::tempdir().unwrap();
    let model = Model::generated(warm_up_spec());
    let base = model.instantiate(&Default::default(), r.idd()).unwrap();
    let short = (2..=6)
        .find_map(|days| {
            let mut idf = base.clone();
            let b = idf
                .objects
                .iter_mut()
                .find(|o| o.class == "Building")
                .unwrap();
            b.fields[3] = "0.1".into();
            b.fields[4] = "0.5".into();
            b.fields[6] = days.to_string();
            b.fields[7] = "1".into();
            let dir = tmp.path().join(format!("w{days}"));
            let run = r.run(&idf, &weather(&r), model.outputs(), &dir);
            eprintln!("{days} warm-up days: {:?}", run.as_ref().map(|x| &x.notes));
            run.ok().filter(|x| {
                x.notes.iter().any(|n| {
                    n.contains(&format!("did not converge after {days} warmup days"))
                        && n.contains("within the margin")
                })
            })
        })
        .expect("a run with a usable warm-up Severe");
    assert_eq!(short.outputs.hours(), 8760);
    let full = r
        .run(
            &base,
            &weather(&r),
            model.outputs(),
            &tmp.path().join("w50"),
        )
        .unwrap();
    assert!(full.notes.is_empty(), "{:?}", full.notes);
    for (name, t) in full.outputs.totals() {
        let t2 = total(&short.outputs, &name);
        eprintln!("{name}: {t:.0} kWh converged, {t2:.0} kWh with the warm-up note");
        assert!(
            (t2 - t).abs() <= 0.01 * t.abs().max(1.0),
            "{name}: {t} vs {t2}"
        );
    }
}

/// A user's IDF, `dir/mine.idf`: here the small generated building, written out as plain text.
fn users_idf(r: &Runner, dir: &std::path::Path) -> bemcal_energyplus::idf::Idf {
    let generated = Model::generated(small_spec());
    let idf = generated.instantiate(&Default::default(), r.idd()).unwrap();
    std::fs::write(dir.join("mine.idf"), idf.to_text()).unwrap();
    idf
}

#[test]
fn users_own_idf_with_a_parameter_map() {
    let Some(r) = runner() else { return };
    let tmp = tempfile::tempdir().unwrap();
    users_idf(&r, tmp.path());
    let map = r#"
[idf]
path = "mine.idf"

[[parameter]]
name = "lpd"
unit = "W/m2"
prior = { min = 5.0, mode = 10.0, max = 15.0 }
targets = [{ class = "Lights", object = "*", field = "Watts per Floor Area" }]

[[parameter]]
name = "wall_k"
unit = "W/m-K"
prior = { min = 0.03, mode = 0.04, max = 0.05 }
targets = [{ class = "Material", object = "Wall Insulation", field = "Conductivity" }]

[[output]]
name = "lighting_kwh"
meters = ["InteriorLights:Electricity"]

[[output]]
name = "electricity_kwh"
meters = ["Electricity:Facility"]
"#;
    let path = tmp.path().join("mine.toml");
    std::fs::write(&path, map).unwrap();
    let model = Model::load(&path, r.idd()).unwrap();
    assert_eq!(model.parameters().len(), 2);
    let a = simulate(&r, &model, &[("lpd", 6.0)], &tmp.path().join("a")).unwrap();
    let b = simulate(&r, &model, &[("lpd", 12.0)], &tmp.path().join("b")).unwrap();
    let (la, lb) = (total(&a, "lighting_kwh"), total(&b, "lighting_kwh"));
    assert!((lb / la - 2.0).abs() < 0.01, "lighting {la} -> {lb}");

    // Mistakes in the map name the field, the class and what exists.
    let bad = map.replace("Watts per Floor Area", "Watts per Square Foot");
    std::fs::write(&path, bad).unwrap();
    let e = Model::load(&path, r.idd()).unwrap_err().to_string();
    assert!(
        e.contains("mine.toml")
            && e.contains("has no field 'Watts per Square Foot'")
            && e.contains("Watts per Floor Area"),
        "{e}"
    );
    let bad = map.replace(
        "object = \"Wall Insulation\"",
        "object = \"Wall Insulatoin\"",
    );
    std::fs::write(&path, bad).unwrap();
    let e = Model::load(&path, r.idd()).unwrap_err().to_string();
    assert!(
        e.contains("no object Wall Insulatoin of class Material"),
        "{e}"
    );
}

/// A user's IDF runs the calendar of its model file: `year` and `holidays_file` replace the
/// IDF's own run period (2021, from the generated building it was written from) and special
/// days; EnergyPlus then runs 2017's weekdays and the listed holidays on the weekend schedule.
/// `bemcal predict` reads the same calendar without EnergyPlus (`Model::calendar_from_toml`).
#[test]
fn users_idf_runs_the_calendar_of_its_model_file() {
    use chrono::Datelike;
    let Some(r) = runner() else { return };
    let tmp = tempfile::tempdir().unwrap();
    let idf = users_idf(&r, tmp.path());
    let run_period = |idf: &bemcal_energyplus::idf::Idf| -> Vec<Vec<String>> {
        idf.of_class("RunPeriod")
            .map(|o| o.fields.clone())
            .collect()
    };
    let special = |idf: &bemcal_energyplus::idf::Idf| -> Vec<(String, String)> {
        idf.of_class("RunPeriodControl:SpecialDays")
            .map(|o| (o.fields[1].clone(), o.fields[3].clone()))
            .collect()
    };
    assert_eq!(run_period(&idf)[0][3], "2021", "the IDF as the user has it");
    std::fs::write(
        tmp.path().join("closures.csv"),
        "date,name\n2017-01-02,New Year (observed)\n2017-03-15,plant shutdown\n",
    )
    .unwrap();
    let map = r#"
year = 2017
holidays_file = "closures.csv"

[idf]
path = "mine.idf"

[[parameter]]
name = "lighting_multiplier"
prior = { min = 0.5, mode = 1.0, max = 1.5 }
targets = [{ class = "Lights", object = "*", field = "Watts per Floor Area", edit = "scale" }]

[[output]]
name = "lighting_kwh"
meters = ["InteriorLights:Electricity"]
"#;
    let path = tmp.path().join("mine.toml");
    std::fs::write(&path, map).unwrap();
    let model = Model::load(&path, r.idd()).unwrap();
    let calendar = model.calendar();
    assert_eq!(calendar.year, 2017.into());
    assert_eq!(
        Model::calendar_from_toml(map, &path).unwrap(),
        calendar,
        "predict's calendar"
    );
    assert_eq!(
        Model::named_files(map, &path).unwrap(),
        vec![PathBuf::from("mine.idf"), PathBuf::from("closures.csv")]
    );
    let simulated = model.instantiate(&ParameterValues::new(), r.idd()).unwrap();
    let periods = run_period(&simulated);
    assert_eq!(periods.len(), 1, "{periods:?}");
    assert_eq!(
        periods[0][1..8],
        ["1", "1", "2017", "12", "31", "2017", "Sunday"].map(String::from)
    );
    assert_eq!(
        special(&simulated),
        vec![
            ("1/2".to_string(), "Holiday".to_string()),
            ("3/15".to_string(), "Holiday".to_string())
        ],
        "only the listed holidays: the IDF's 2021 US holidays are gone"
    );

    let out = r
        .run(
            &simulated,
            &weather(&r),
            model.outputs(),
            &tmp.path().join("a"),
        )
        .unwrap()
        .outputs;
    let lighting = out.get("lighting_kwh").unwrap();
    let day = |month: u32, d: u32| -> f64 {
        let n = chrono::NaiveDate::from_ymd_opt(2017, month, d)
            .unwrap()
            .ordinal0() as usize;
        lighting[24 * n..24 * (n + 1)].iter().sum()
    };
    let (holiday, tuesday, sunday) = (day(1, 2), day(1, 3), day(1, 1));
    let (shutdown, wednesday) = (day(3, 15), day(3, 22));
    eprintln!(
        "lighting kWh: Mon 2 Jan (holiday) {holiday:.1}, Tue 3 Jan {tuesday:.1}, Sun 1 Jan \
         {sunday:.1}; Wed 15 Mar (holiday) {shutdown:.1}, Wed 22 Mar {wednesday:.1}"
    );
    assert!(
        (holiday - sunday).abs() < 1e-6 * sunday,
        "{holiday} vs {sunday}"
    );
    assert!(holiday < 0.8 * tuesday, "{holiday} vs {tuesday}");
    assert!(shutdown < 0.8 * wednesday, "{shutdown} vs {wednesday}");
}

/// An EPW of 2017 built from the Minneapolis ISD-lite observations (UTC) merged onto the TMY3
/// file: EnergyPlus reads it without a Severe (horizontal infrared left for EnergyPlus to
/// derive), and the year's weather moves the results against the typical year's.
#[test]
fn energyplus_runs_on_an_epw_built_from_isd_lite() {
    use bemcal_weather::measured::{build_epw, BuildOptions, Stamp};
    let Some(r) = runner() else { return };
    let shared = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data");
    let tmy = shared.join("epw/USA_MN_Minneapolis-St.Paul.Intl.AP.726580_TMY3.epw");
    let isd = shared.join("noaa_isd_lite_2017/726580-14922-2017.gz");
    if !tmy.exists() || !isd.exists() {
        eprintln!("shared data not present; skipping");
        return;
    }
    let tmy_text = std::fs::read_to_string(&tmy).unwrap();
    let obs = bemcal_weather::station::read_isd_lite(&isd, 254.0).unwrap();
    let opts = BuildOptions {
        year: 2017.into(),
        max_interpolated_gap_h: 6,
        stamp: Stamp::Instant,
        interval_min: 60,
        source: "ISD-lite 726580-14922-2017".into(),
    };
    let (text, _) = build_epw(&tmy_text, &tmy, &obs, &opts).unwrap();
    let tmp = tempfile::tempdir().unwrap();
    let built = tmp.path().join("msp2017.epw");
    std::fs::write(&built, text).unwrap();
    let model = Model::generated(BuildingSpec {
        year: 2017.into(),
        ..small_spec()
    });
    let idf = model.instantiate(&ParameterValues::new(), r.idd()).unwrap();
    let actual = r
        .run(&idf, &built, model.outputs(), &tmp.path().join("a"))
        .unwrap();
    let typical = r
        .run(&idf, &tmy, model.outputs(), &tmp.path().join("t"))
        .unwrap();
    let (ha, ht) = (
        total(&actual.outputs, "heating_kwh"),
        total(&typical.outputs, "heating_kwh"),
    );
    eprintln!("heating 2017 {ha:.0} kWh, TMY3 {ht:.0} kWh");
    assert!(
        ha > 0.0 && (ha - ht).abs() / ht > 0.02,
        "2017 {ha}, TMY {ht}"
    );
}

/// Relative `[idf]` edits of a user's IDF: one multiplier scales the lighting power of every
/// `Lights` object, one offset moves every value of the cooling set-point schedules (matched by
/// a name pattern); EnergyPlus's cooling answers the offset. Non-numeric targets are refused at
/// load, naming the object and field.
/// The fields of the `Schedule:Compact` called `name`.
fn schedule(idf: &bemcal_energyplus::idf::Idf, name: &str) -> Vec<String> {
    idf.of_class("Schedule:Compact")
        .find(|o| o.name() == Some(name))
        .unwrap()
        .fields
        .clone()
}

/// Asserts that a schedule's fields `after` are those `before` with every value moved by `by`
/// (`Through:`, `For:`, `Until:` and the type limits unchanged); returns how many moved.
fn assert_offset(after: &[String], before: &[String], by: f64) -> usize {
    assert_eq!(after.len(), before.len());
    let mut moved = 0;
    for (a, b) in after.iter().zip(before) {
        match (a.parse::<f64>(), b.parse::<f64>()) {
            (Ok(x), Ok(y)) => {
                assert!((x - y - by).abs() < 1e-9, "{a} vs {b}");
                moved += 1;
            }
            _ => assert_eq!(a, b),
        }
    }
    moved
}

#[test]
fn relative_idf_edits_scale_and_offset_the_users_values() {
    let Some(r) = runner() else { return };
    let tmp = tempfile::tempdir().unwrap();
    let idf = users_idf(&r, tmp.path());
    let map = r#"
[idf]
path = "mine.idf"

[[parameter]]
name = "lighting_multiplier"
prior = { min = 0.5, mode = 1.0, max = 1.5 }
targets = [{ class = "Lights", object = "*", field = "Watts per Floor Area", edit = "scale" }]

[[parameter]]
name = "cooling_setpoint_offset"
unit = "K"
prior = { min = -2.0, mode = 0.0, max = 2.0 }
targets = [{ class = "Schedule:Compact", object = "cool*", field = "*", edit = "offset" }]

[[output]]
name = "cooling_kwh"
meters = ["DistrictCooling:Facility"]

[[output]]
name = "lighting_kwh"
meters = ["InteriorLights:Electricity"]
"#;
    let path = tmp.path().join("mine.toml");
    std::fs::write(&path, map).unwrap();
    let model = Model::load(&path, r.idd()).unwrap();
    let at = |m: f64, o: f64| {
        let given: ParameterValues = [
            ("lighting_multiplier".to_string(), m),
            ("cooling_setpoint_offset".to_string(), o),
        ]
        .into();
        model.instantiate(&given, r.idd()).unwrap()
    };
    let lpd = |idf: &bemcal_energyplus::idf::Idf| -> Vec<f64> {
        idf.of_class("Lights")
            .map(|o| o.fields[5].parse().unwrap())
            .collect()
    };
    let original = lpd(&idf);
    assert!(!original.is_empty());
    for (a, b) in lpd(&at(0.5, 0.0)).iter().zip(&original) {
        assert!((a - 0.5 * b).abs() < 1e-9, "{a} vs {b}");
    }
    assert_offset(
        &schedule(&at(1.0, 1.5), "Cooling Setpoint"),
        &schedule(&idf, "Cooling Setpoint"),
        1.5,
    );
    // The heating schedule does not match "cool*".
    assert_eq!(
        schedule(&at(1.0, 1.5), "Heating Setpoint"),
        schedule(&idf, "Heating Setpoint")
    );
    let cool = |o: f64, d: &str| {
        let out = simulate(
            &r,
            &model,
            &[("cooling_setpoint_offset", o)],
            &tmp.path().join(d),
        )
        .unwrap();
        total(&out, "cooling_kwh")
    };
    let (lo, hi) = (cool(-2.0, "lo"), cool(2.0, "hi"));
    eprintln!("cooling with set-points -2 K: {lo:.0} kWh, +2 K: {hi:.0} kWh");
    assert!(lo > 1.1 * hi, "cooling {lo} (-2 K) vs {hi} (+2 K)");

    let bad = map.replace(
        "field = \"Watts per Floor Area\"",
        "field = \"Schedule Name\"",
    );
    std::fs::write(&path, bad).unwrap();
    let e = Model::load(&path, r.idd()).unwrap_err().to_string();
    assert!(
        e.contains("needs a number in Lights") && e.contains("Schedule Name"),
        "{e}"
    );
}

/// The day-type calendar the meters show (`day_types_file`, pre-calibration's calendar.csv
/// format): a Friday-Saturday weekend (Sundays worked, Fridays off) runs the weekend
/// schedule on every Friday and the weekday schedule on every Sunday, in EnergyPlus and in the
/// surrogate's day types.
#[test]
fn a_day_type_calendar_moves_the_weekend() {
    use chrono::{Datelike, Weekday};
    let Some(r) = runner() else { return };
    let tmp = tempfile::tempdir().unwrap();
    let mut csv = String::from("date,calendar_day_type,cluster,label\n");
    let mut d = chrono::NaiveDate::from_ymd_opt(2021, 1, 1).unwrap();
    while d.year() == 2021 {
        let label = match d.weekday() {
            Weekday::Fri | Weekday::Sat => "weekend",
            _ => "weekday",
        };
        csv.push_str(&format!("{d},x,0,{label}\n"));
        d = d.succ_opt().unwrap();
    }
    std::fs::write(tmp.path().join("calendar.csv"), csv).unwrap();
    let text = "storeys = 1\nfootprint_m = [20.0, 15.0]\nzoning = \"one_per_floor\"\n\
                timesteps_per_hour = 4\nday_types_file = \"calendar.csv\"\n";
    let spec = BuildingSpec::from_toml(text, &tmp.path().join("m.toml")).unwrap();
    let moved = Model::generated(spec.clone());
    let usual = Model::generated(small_spec());
    let a = simulate(&r, &moved, &[], &tmp.path().join("moved")).unwrap();
    let b = simulate(&r, &usual, &[], &tmp.path().join("usual")).unwrap();
    let daily = |o: &bemcal_energyplus::HourlyOutputs, day: usize| -> f64 {
        o.get("lighting_kwh").unwrap()[day * 24..day * 24 + 24]
            .iter()
            .sum()
    };
    // 2021-01-08 is a Friday, 01-10 a Sunday, 01-13 a Wednesday.
    let (fri, sun, wed) = (7, 9, 12);
    assert!(
        (daily(&a, fri) - daily(&b, sun)).abs() < 1e-6,
        "Friday runs the weekend schedule"
    );
    assert!(
        (daily(&a, sun) - daily(&b, wed)).abs() < 1e-6,
        "Sunday runs the weekday schedule"
    );
    assert!(
        daily(&a, wed) > daily(&a, fri),
        "{} vs {}",
        daily(&a, wed),
        daily(&a, fri)
    );
    let cal = spec.calendar();
    assert_eq!(cal.day_type(1, 8), Some(bemcal_weather::DayType::Weekend));
    assert_eq!(cal.day_type(1, 10), Some(bemcal_weather::DayType::Weekday));
    // New Year's Day (a Friday) is listed as a weekend day; a listed weekday overrides a holiday.
    assert_eq!(cal.day_type(1, 1), Some(bemcal_weather::DayType::Weekend));
}

/// The other air systems (issue 19: a real building's system, not only the reference's VAV
/// reheat) simulate, and their options and the set-points move the results the way physics
/// says: an economizer takes cooling off the coils, heat recovery takes heating off the DOAS's
/// coils, and the fan coils follow the zones' cooling set-point.
#[test]
fn economizer_and_doas_fan_coils_simulate_and_respond() {
    let Some(r) = runner() else { return };
    let tmp = tempfile::tempdir().unwrap();
    let run = |spec: BuildingSpec, set: &[(&str, f64)], name: &str| {
        let out = simulate(&r, &Model::generated(spec), set, &tmp.path().join(name)).unwrap();
        (total(&out, "heating_kwh"), total(&out, "cooling_kwh"))
    };
    let econ = BuildingSpec {
        economizer: true,
        ..small_spec()
    };
    let (_, c_vav) = run(small_spec(), &[], "vav");
    let (_, c_econ) = run(econ, &[], "econ");
    assert!(
        c_econ < 0.97 * c_vav,
        "economizer: cooling {c_vav} -> {c_econ}"
    );
    let doas = |hr: f64| BuildingSpec {
        hvac: bemcal_energyplus::HvacSystem::DoasFanCoil,
        heat_recovery_effectiveness: hr,
        ..small_spec()
    };
    let warm = [("cooling_setpoint_occupied", 25.5)];
    let (h_none, _) = run(doas(0.0), &warm, "doas0");
    let (h_hr, c_warm) = run(doas(0.7), &warm, "doas7");
    let (_, c_cool) = run(doas(0.7), &[("cooling_setpoint_occupied", 21.5)], "doas7c");
    eprintln!("DOAS heating {h_none:.0} -> {h_hr:.0} kWh with heat recovery; cooling {c_warm:.0} -> {c_cool:.0} kWh at 25.5 -> 21.5 C");
    assert!(
        h_hr < 0.95 * h_none,
        "heat recovery: heating {h_none} -> {h_hr}"
    );
    assert!(
        c_cool > 1.02 * c_warm,
        "fan coils: cooling {c_warm} -> {c_cool}"
    );
}

/// The bundled `own-idf` example (`examples/own-idf`): its map loads against the IDD and each
/// parameter edits what its description says in the example's IDF, an IDF with IDF Editor's
/// field comments, and nothing else: people, lights, equipment, infiltration and both
/// set-point schedules.
#[test]
fn the_own_idf_examples_map_edits_its_objects() {
    let Some(r) = runner() else { return };
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../examples/own-idf");
    let model = Model::load(&dir.join("model.toml"), r.idd()).unwrap();
    let at = |given: &[(&str, f64)]| {
        let values: ParameterValues = given.iter().map(|(k, v)| (k.to_string(), *v)).collect();
        model.instantiate(&values, r.idd()).unwrap()
    };
    let field = |idf: &bemcal_energyplus::idf::Idf, class: &str, name: &str| -> Vec<String> {
        let i = r.idd().field_index(class, name).unwrap();
        idf.of_class(class).map(|o| o.fields[i].clone()).collect()
    };
    let number = |idf: &bemcal_energyplus::idf::Idf, class: &str, name: &str| -> f64 {
        let v = field(idf, class, name);
        assert_eq!(v.len(), 1, "{class}: {v:?}");
        v[0].parse().unwrap()
    };
    // At the prior modes the IDF's own values (10 m2 per person, 10 and 17.5 W/m2, 0.2 ACH).
    let modes = at(&[]);
    let people = ("People", "Floor Area per Person");
    let lights = ("Lights", "Watts per Floor Area");
    let equipment = ("ElectricEquipment", "Watts per Floor Area");
    let infiltration = ("ZoneInfiltration:DesignFlowRate", "Air Changes per Hour");
    assert_eq!(number(&modes, people.0, people.1), 10.0);
    assert_eq!(number(&modes, lights.0, lights.1), 10.0);
    assert_eq!(number(&modes, equipment.0, equipment.1), 17.5);
    assert_eq!(number(&modes, infiltration.0, infiltration.1), 0.2);

    let edited = at(&[
        ("floor_area_per_person", 14.0),
        ("lighting_scale", 1.25),
        ("equipment_scale", 0.8),
        ("infiltration_scale", 1.8),
        ("heating_setpoint_offset", -1.0),
        ("cooling_setpoint_offset", 1.0),
    ]);
    let close = |a: f64, b: f64| assert!((a - b).abs() < 1e-9, "{a} vs {b}");
    close(number(&edited, people.0, people.1), 14.0);
    close(number(&edited, lights.0, lights.1), 12.5);
    close(number(&edited, equipment.0, equipment.1), 14.0);
    close(number(&edited, infiltration.0, infiltration.1), 0.36);
    for (name, by) in [("Heating Setpoint", -1.0), ("Cooling Setpoint", 1.0)] {
        let moved = assert_offset(&schedule(&edited, name), &schedule(&modes, name), by);
        assert!(moved >= 4, "{name}: {moved} values moved");
    }
    // Nothing else changed: every other schedule and every object of another class.
    assert_eq!(modes.objects.len(), edited.objects.len());
    for (a, b) in modes.objects.iter().zip(&edited.objects) {
        let mapped = [people.0, lights.0, equipment.0, infiltration.0].contains(&a.class.as_str())
            || a.name() == Some("Heating Setpoint")
            || a.name() == Some("Cooling Setpoint");
        if !mapped {
            assert_eq!(a, b);
        }
    }
}

/// The process of the EnergyPlus run in `dir`, found by its working folder. Not this test's own
/// binary (`energyplus-HASH`): a child between fork and exec still runs it, with this process's
/// environment (a race that failed the environment test once).
fn process_in(dir: &std::path::Path) -> Option<u32> {
    let want = dir.canonicalize().ok()?;
    let this = std::env::current_exe().ok();
    for entry in std::fs::read_dir("/proc").ok()?.flatten() {
        let Ok(pid) = entry.file_name().to_string_lossy().parse::<u32>() else {
            continue;
        };
        let cwd = std::fs::read_link(entry.path().join("cwd")).ok();
        let exe = std::fs::read_link(entry.path().join("exe")).ok();
        let is_energyplus = exe.is_some_and(|e| {
            e.to_string_lossy().contains("energyplus") && this.as_deref() != Some(e.as_path())
        });
        if is_energyplus && cwd.as_deref() == Some(want.as_path()) {
            return Some(pid);
        }
    }
    None
}

/// A submitted model is untrusted code (issue 68): EnergyPlus starts with a cleared environment,
/// so a model's code could not read the worker's token. Read from /proc/PID/environ while it
/// runs.
#[test]
fn energyplus_runs_without_bemcal_variables_in_its_environment() {
    let Some(r) = runner() else { return };
    // SAFETY: set before the run's threads start; no other test reads this variable.
    unsafe { std::env::set_var("BEMCAL_TOKEN", "a-secret-the-model-must-not-see") };
    let model = Model::generated(warm_up_spec());
    let dir = tempfile::tempdir().unwrap();
    let run_dir = dir.path().join("run");
    let environ = std::thread::scope(|s| {
        let run = s.spawn(|| simulate(&r, &model, &[], &run_dir));
        let mut found = None;
        while !run.is_finished() && found.is_none() {
            // An exiting (zombie) process reads as an empty environment: look again.
            if let Some(pid) = process_in(&run_dir) {
                found = std::fs::read(format!("/proc/{pid}/environ"))
                    .ok()
                    .filter(|e| !e.is_empty());
            }
            std::thread::sleep(std::time::Duration::from_millis(5));
        }
        run.join().unwrap().unwrap();
        found.expect("EnergyPlus's process seen while it ran")
    });
    let vars: Vec<String> = environ
        .split(|&b| b == 0)
        .map(|v| String::from_utf8_lossy(v).to_string())
        .filter(|v| !v.is_empty())
        .collect();
    assert!(vars.iter().all(|v| !v.starts_with("BEMCAL_")), "{vars:?}");
    assert!(vars.iter().any(|v| v.starts_with("PATH=")), "{vars:?}");
    let names: Vec<&str> = vars.iter().filter_map(|v| v.split('=').next()).collect();
    assert_eq!(names.len(), 4, "only PATH, LANG, HOME, TMPDIR: {names:?}");
}

/// A run past its wall-time or output limit is a failed simulation with that reason.
#[test]
fn a_run_past_its_limits_fails_with_the_reason() {
    let Some(r) = runner() else { return };
    let model = Model::generated(warm_up_spec());
    let dir = tempfile::tempdir().unwrap();
    let slow = r.with_limits(bemcal_energyplus::confine::Limits {
        wall: std::time::Duration::from_millis(300),
        ..Default::default()
    });
    let e = simulate(&slow, &model, &[], &dir.path().join("slow")).unwrap_err();
    assert!(matches!(e, Error::Timeout { .. }), "{e}");
    assert!(e.to_string().contains("time limit"), "{e}");
    let small = r.with_limits(bemcal_energyplus::confine::Limits {
        output_bytes: Some(256 << 10),
        ..Default::default()
    });
    let e = simulate(&small, &model, &[], &dir.path().join("big")).unwrap_err();
    assert!(e.to_string().contains("output limit"), "{e}");
}

/// An own IDF with code or a file outside the run folder is refused at load, naming the object
/// and its line.
#[test]
fn an_idf_with_code_or_outside_files_is_refused_with_object_and_line() {
    let Some(r) = runner() else { return };
    let dir = tempfile::tempdir().unwrap();
    let cases = [
        ("PythonPlugin:Instance,\n  Steal, No, stealer, Plugin;\n", "PythonPlugin:Instance 'Steal'"),
        (
            "ExternalInterface,\n  PtolemyServer;\n",
            "ExternalInterface",
        ),
        (
            "Schedule:File,\n  Occ, Fraction, /proc/self/environ, 1, 0;\n",
            "Schedule:File 'Occ' field 'File Name'",
        ),
        (
            "Table:IndependentVariable,\n  T, Linear, Constant, -10, 10, , , ../../x.csv, 1, 1, 1;\n",
            "'External File Name'",
        ),
    ];
    for (object, what) in cases {
        let idf = dir.path().join("model.idf");
        std::fs::write(&idf, format!("Version,25.2;\n\n{object}")).unwrap();
        let map = dir.path().join("model.toml");
        std::fs::write(
            &map,
            "[idf]\npath = \"model.idf\"\n[[output]]\nname = \"electricity_kwh\"\nmeters = [\"Electricity:Facility\"]\n",
        )
        .unwrap();
        let e = Model::load(&map, r.idd()).unwrap_err().to_string();
        assert!(e.contains("model.idf:3:") && e.contains(what), "{e}");
    }
}

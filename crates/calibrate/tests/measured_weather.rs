//! A project that names measured weather: the calibration's inputs are simulated and featured
//! with the EPW of the metered year built from it (NOAA ISD-lite, Minneapolis 2017, real data
//! in `../shared/data`).

use std::path::Path;

use bemcal_calibrate::pipeline::load_inputs;
use bemcal_calibrate::project::Project;

#[test]
fn project_with_isd_lite_weather_simulates_the_metered_year() {
    let shared = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data");
    let tmy = shared.join("epw/USA_MN_Minneapolis-St.Paul.Intl.AP.726580_TMY3.epw");
    let isd = shared.join("noaa_isd_lite_2017/726580-14922-2017.gz");
    if !tmy.exists() || !isd.exists() {
        eprintln!("shared data not present; skipping");
        return;
    }
    if bemcal_energyplus::Engine::locate().is_err() {
        eprintln!("no EnergyPlus; skipping");
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::copy(&isd, d.join("726580-14922-2017.gz")).unwrap();
    std::fs::write(
        d.join("model.toml"),
        "storeys = 1\nfootprint_m = [20.0, 15.0]\nzoning = \"one_per_floor\"\nyear = 2017\n",
    )
    .unwrap();
    let mut meters = String::from("timestamp,electricity_kwh\n");
    let start = chrono::NaiveDate::from_ymd_opt(2017, 1, 1)
        .unwrap()
        .and_hms_opt(0, 0, 0)
        .unwrap();
    for t in 0..8760 {
        let ts = start + chrono::Duration::hours(t);
        meters.push_str(&format!("{},{}\n", ts.format("%Y-%m-%dT%H:%M"), 3.0));
    }
    std::fs::write(d.join("meters.csv"), meters).unwrap();
    std::fs::write(
        d.join("project.toml"),
        format!(
            "model = \"model.toml\"\nweather = \"{}\"\n\
             [measured_weather]\nisd_lite = [\"726580-14922-2017.gz\"]\n\
             [meters]\nfile = \"meters.csv\"\n\
             [[meters.columns]]\ncolumn = \"electricity_kwh\"\nrole = \"electricity\"\nunit = \"kWh\"\n",
            tmy.display()
        ),
    )
    .unwrap();
    let project = Project::load(&d.join("project.toml")).unwrap();
    let inputs = load_inputs(&project).unwrap();
    assert_eq!(inputs.weather_path, d.join("measured-weather/2017.epw"));
    assert!(d.join("measured-weather/2017.json").is_file());
    let report = inputs.measured_weather.as_ref().expect("built");
    assert_eq!(report.year, 2017);
    // The 07:00 UTC observation of January 1 is the first hour in local standard time.
    assert_eq!(inputs.features.dry_bulb_c[0], -2.8);

    // Both sources at once is a clear error naming the section.
    let text = std::fs::read_to_string(d.join("project.toml")).unwrap();
    std::fs::write(
        d.join("bad.toml"),
        text.replace(
            "[measured_weather]\n",
            "[measured_weather]\ncsv = \"w.csv\"\n",
        ),
    )
    .unwrap();
    let e = Project::load(&d.join("bad.toml")).unwrap_err().to_string();
    assert!(
        e.contains("[measured_weather]") && e.contains("not both"),
        "{e}"
    );
}

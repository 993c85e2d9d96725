//! A project that names measured weather: the calibration's inputs are simulated and featured
//! with the EPW of the metered year built from it (NOAA ISD-lite, Minneapolis 2017, real data
//! in `../shared/data`).

use std::path::Path;

use bemcal_calibrate::load_inputs;
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
    assert_eq!(report.year, 2017.into());
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

/// `[[bases]]` on the real RSF 2011 meters: the data-center sub-meter is a base of the
/// whole-building electricity meter; the likelihood sees the meter less the base, and a model
/// output is compared with the meter after the base is added back.
#[test]
fn a_submeter_base_is_taken_from_the_meter_the_model_is_compared_with() {
    let shared = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data");
    let rsf = shared.join("nrel_rsf_2011/rsfmeasureddata2011.csv");
    let tmy = shared.join("epw/USA_CO_Golden-NREL.724666_TMY3.epw");
    if !rsf.exists() || bemcal_energyplus::Engine::locate().is_err() {
        eprintln!("shared data or EnergyPlus absent; skipping");
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(
        d.join("model.toml"),
        "storeys = 1\nfootprint_m = [20.0, 15.0]\nzoning = \"one_per_floor\"\nyear = 2011\n",
    )
    .unwrap();
    let project = |bases: &str| {
        format!(
            "model = \"model.toml\"\nweather = \"{}\"\n{bases}\n[meters]\nfile = \"{}\"\n\
             timestamp_column = \"Date and Time\"\nconvention = \"hour_ending\"\ndst = \"none\"\n\
             [[meters.columns]]\ncolumn = \"Total Building (kW)\"\nrole = \"electricity\"\nunit = \"kW\"\n\
             [[meters.columns]]\ncolumn = \"Total Data Center (kW)\"\nrole = \"data_center\"\nunit = \"kW\"\n",
            tmy.display(),
            rsf.display()
        )
    };
    let headers = std::fs::read_to_string(&rsf).unwrap();
    let headers = headers.lines().next().unwrap();
    assert!(headers.contains("Total Data Center"), "{headers}");
    std::fs::write(
        d.join("p.toml"),
        project("[[bases]]\noutput = \"electricity_kwh\"\nsubmeter = \"data_center\""),
    )
    .unwrap();
    let inputs = load_inputs(&Project::load(&d.join("p.toml")).unwrap()).unwrap();
    let k = inputs
        .outputs
        .iter()
        .position(|o| o == "electricity_kwh")
        .unwrap();
    let (meter, base, share) = (&inputs.measured[k], &inputs.bases[k], inputs.model_share(k));
    // Hour 0: whole building and data center of 01/01/2011 01:00 (hour-ending).
    assert!(base[0] > 80.0 && base[0] < 130.0, "data center {}", base[0]);
    assert_eq!(share[0], meter[0] - base[0]);
    let mean = |v: &[f64]| {
        let f: Vec<f64> = v.iter().copied().filter(|x| x.is_finite()).collect();
        f.iter().sum::<f64>() / f.len() as f64
    };
    // The data center is about 102 kW of the building's 268 kW.
    assert!((mean(base) - 102.0).abs() < 2.0, "{}", mean(base));
    assert!((mean(&share) - (mean(meter) - mean(base))).abs() < 1.0);
    assert_eq!(inputs.with_base(k, &[1.0])[0], 1.0 + base[0]);
    assert_eq!(inputs.base_reports.len(), 1);
    assert_eq!(inputs.base_reports[0].source, "submeter data_center");

    // A base on an output that is not calibrated, or a sub-meter the file lacks, is an error.
    std::fs::write(
        d.join("bad.toml"),
        project("[[bases]]\noutput = \"electricity_kwh\"\nsubmeter = \"server_room\""),
    )
    .unwrap();
    let e = load_inputs(&Project::load(&d.join("bad.toml")).unwrap())
        .err()
        .unwrap()
        .to_string();
    assert!(
        e.contains("server_room") && e.contains("data_center"),
        "{e}"
    );
    std::fs::write(
        d.join("bad.toml"),
        project("[[bases]]\noutput = \"electricity_kwh\"\nsubmeter = \"x\"\nkwh_per_hour = 3.0"),
    )
    .unwrap();
    let e = Project::load(&d.join("bad.toml")).unwrap_err().to_string();
    assert!(e.contains("one of them"), "{e}");
}

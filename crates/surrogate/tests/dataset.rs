//! Training-set construction, validation and round trip (no Python needed).

mod common;

use bemcal_surrogate::{ParamSpec, TrainingSet};
use ndarray::{Array2, Array3};

#[test]
fn round_trip_and_split_by_design_point() {
    let weather = common::synthetic_weather(240);
    let set = common::synthetic_set(6, &weather);
    assert_eq!(set.split.held_out.len(), 1);
    assert_eq!(set.split.train.len(), 5);
    let dir = tempfile::tempdir().unwrap();
    set.write(dir.path()).unwrap();
    for f in ["params.npy", "weather.npy", "outputs.npy", "dataset.json"] {
        assert!(dir.path().join(f).exists(), "{f}");
    }
    let back = TrainingSet::read(dir.path()).unwrap();
    assert_eq!(back, set);
    let meta: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("dataset.json")).unwrap())
            .unwrap();
    assert_eq!(meta["weather_features"][0], "dry_bulb_c");
    assert_eq!(meta["output_unit"], "kWh");
}

#[test]
fn shape_errors_are_clear() {
    let weather = common::synthetic_weather(48);
    let params = vec![
        ParamSpec::new("a", 0.0, 1.0, 0.5),
        ParamSpec::new("b", 0.0, 1.0, 0.5),
    ];
    let names = vec!["heating_kwh".to_string()];
    let e = TrainingSet::new(
        params.clone(),
        Array2::zeros((4, 3)),
        &weather,
        names.clone(),
        Array3::zeros((4, 48, 1)),
        0,
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("3 columns but 2 parameters"), "{e}");
    let e = TrainingSet::new(
        params.clone(),
        Array2::zeros((4, 2)),
        &weather,
        names.clone(),
        Array3::zeros((4, 47, 1)),
        0,
    )
    .unwrap_err()
    .to_string();
    assert!(
        e.contains("expected [n_points=4, n_hours=48, n_outputs=1]"),
        "{e}"
    );
    let mut out = Array3::zeros((4, 48, 1));
    out[[2, 5, 0]] = f64::NAN;
    let e = TrainingSet::new(
        params.clone(),
        Array2::zeros((4, 2)),
        &weather,
        names.clone(),
        out,
        0,
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("design point 2 at hour 5"), "{e}");
    let bad = vec![
        ParamSpec::new("a", 1.0, 0.0, 0.5),
        ParamSpec::new("b", 0.0, 1.0, 0.5),
    ];
    let e = TrainingSet::new(
        bad,
        Array2::zeros((4, 2)),
        &weather,
        names,
        Array3::zeros((4, 48, 1)),
        0,
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("max > min"), "{e}");
}

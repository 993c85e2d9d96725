//! End to end: synthetic training set -> Python trainer (a few epochs) -> ONNX -> Rust/ort,
//! with parity against the torch outputs the trainer wrote (`parity.json`).
//! Skipped (with a message) when the Python environment or ONNX Runtime is absent.

mod common;

use bemcal_surrogate::parity::relative_error;
use bemcal_surrogate::{
    train, LrSchedule, ParityFixture, Precision, Surrogate, SurrogateError, TimeFeatures,
    TrainOptions,
};
use ndarray::Array3;

fn environment_ready() -> bool {
    if bemcal_surrogate::train::find_python().is_none() {
        eprintln!(
            "SKIPPED: no Python environment (.venv); {}",
            bemcal_pyenv::INSTALL_HINT
        );
        return false;
    }
    if let Err(e) = bemcal_surrogate::surrogate::ort_library_path() {
        eprintln!("SKIPPED: {e}");
        return false;
    }
    true
}

fn train_small(
    time_features: TimeFeatures,
    lr_schedule: LrSchedule,
) -> Option<(tempfile::TempDir, bemcal_surrogate::TrainReport)> {
    if !environment_ready() {
        return None;
    }
    let weather = common::synthetic_weather(8760);
    let set = common::synthetic_set(6, &weather);
    let tmp = tempfile::tempdir().unwrap();
    let ds = tmp.path().join("dataset");
    set.write(&ds).unwrap();
    let opts = TrainOptions {
        epochs: 2,
        patience: 5,
        seed: 3,
        batch_size: 512,
        time_features,
        threads: 1,
        quiet: true,
        lr_schedule,
        ..TrainOptions::default()
    };
    let report = train(&ds, &tmp.path().join("model"), &opts).expect("training runs");
    Some((tmp, report))
}

#[test]
fn warm_start_continues_from_the_saved_weights() {
    let Some((tmp, first)) = train_small(TimeFeatures::None, LrSchedule::Constant) else {
        return;
    };
    let dir = tmp.path().join("model");
    assert!(dir.join(bemcal_surrogate::WEIGHTS_FILE).is_file());
    // No epochs from the saved weights: the same model, so the same held-out error.
    let opts = TrainOptions {
        epochs: 0,
        seed: 3,
        batch_size: 512,
        threads: 1,
        quiet: true,
        init: Some(dir.clone()),
        ..TrainOptions::default()
    };
    let again = train(&tmp.path().join("dataset"), &tmp.path().join("warm"), &opts).unwrap();
    for o in &first.meta.outputs {
        let (a, b) = (
            first.meta.held_out.metrics[&o.name].rmse_kwh,
            again.meta.held_out.metrics[&o.name].rmse_kwh,
        );
        assert!((a - b).abs() <= 1e-5 * a, "{}: {a} vs {b}", o.name);
    }
    let meta: serde_json::Value =
        serde_json::from_slice(&std::fs::read(tmp.path().join("warm/surrogate.json")).unwrap())
            .unwrap();
    assert_eq!(meta["training"]["init"], dir.to_str().unwrap());
    // A folder without weights is refused with a message that says so.
    let opts = TrainOptions {
        init: Some(tmp.path().join("dataset")),
        ..opts
    };
    let e = train(&tmp.path().join("dataset"), &tmp.path().join("bad"), &opts).unwrap_err();
    assert!(e.to_string().contains("weights.pt"), "{e}");
}

#[test]
fn trains_exports_and_matches_torch() {
    let Some((tmp, report)) = train_small(TimeFeatures::HourSchedule, LrSchedule::Cosine) else {
        return;
    };
    let meta = &report.meta;
    let json: serde_json::Value =
        serde_json::from_slice(&std::fs::read(tmp.path().join("model/surrogate.json")).unwrap())
            .unwrap();
    assert_eq!(json["training"]["lr_schedule"], "cosine");
    assert_eq!(
        meta.output_names(),
        ["heating_kwh", "cooling_kwh", "electricity_kwh"]
    );
    assert_eq!(meta.training.epochs_run, 2);
    assert_eq!(meta.held_out.points.len(), 1);
    for o in &meta.outputs {
        let m = &meta.held_out.metrics[&o.name];
        assert!(m.rmse_kwh.is_finite() && m.rmse_kwh > 0.0);
        assert_eq!(o.sigma_eta_kwh, m.rmse_kwh);
        assert!(m.cv_rmse_pct.is_some());
    }
    assert_eq!(meta.n_features, 3 + 5 + 4);

    let dir = tmp.path().join("model");
    let parity = ParityFixture::read(&dir).unwrap();
    let mut s = Surrogate::load(&dir, 1).expect("loads");
    // Plain graph on explicit windows (train() has checked this too).
    let e = s.parity_error(&parity).unwrap();
    assert!(e < 1e-4, "plain graph vs torch: relative error {e:.2e}");

    // Structured hot path over the whole year.
    let params = parity.params_raw.clone();
    let weather = common::synthetic_weather(8760);
    // The evaluator's default is the fused graph.
    assert_eq!(s.hot_path_file(), "surrogate_fused.onnx");
    // Fused graph vs the plain graph over the whole year (every window built explicitly).
    let hourly = meta.hourly_inputs(&weather);
    let np = meta.params.len();
    let mut pn = vec![0f32; np];
    meta.normalise_params(&params, &mut pn).unwrap();
    let mut xy = Array3::<f32>::zeros((8760, 3, meta.n_features));
    for t in 0..8760usize {
        for st in 0..3usize {
            let h = (t + st).saturating_sub(2);
            for j in 0..np {
                xy[[t, st, j]] = pn[j];
            }
            for j in 0..hourly.ncols() {
                xy[[t, st, np + j]] = hourly[[h, j]];
            }
        }
    }
    let y_plain_year = s.run_windows(xy.view()).unwrap();
    let mut ev = s.bind(&weather).unwrap();
    let y = ev.evaluate(&params).unwrap().to_owned();
    assert_eq!(y.dim(), (8760, 3));
    let max_y = y_plain_year.iter().fold(0f32, |m, v| m.max(v.abs()));
    let max_d = (&y - &y_plain_year)
        .iter()
        .fold(0f32, |m, v| m.max(v.abs()));
    let e = max_d / max_y.max(1e-12);
    assert!(
        e < 1e-4,
        "fused graph vs plain graph: relative error {e:.2e}"
    );
    let e = relative_error(y.view(), &parity.y_year);
    assert!(
        e < 1e-4,
        "structured graph vs torch: relative error {e:.2e}"
    );
    assert!(y.iter().all(|v| *v >= 0.0));

    // A batch gives the same numbers as single evaluations.
    let modes = ev.surrogate().meta().param_modes();
    let yb = ev
        .evaluate_batch(&[params.clone(), modes.clone()])
        .unwrap()
        .to_owned();
    let y_modes = ev.evaluate(&modes).unwrap().to_owned();
    let d1 = (&yb.index_axis(ndarray::Axis(0), 0) - &y)
        .iter()
        .fold(0f32, |m, v| m.max(v.abs()));
    let d2 = (&yb.index_axis(ndarray::Axis(0), 1) - &y_modes)
        .iter()
        .fold(0f32, |m, v| m.max(v.abs()));
    assert!(d1 < 1e-4 && d2 < 1e-4, "batch vs single: {d1} {d2}");
    // Three workers splitting the (proposal, chunk) items unevenly: the same numbers.
    let mut ev3 = Surrogate::load(&dir, 3).unwrap().bind(&weather).unwrap();
    let y3 = ev3
        .evaluate_batch(&[params.clone(), modes.clone()])
        .unwrap()
        .to_owned();
    let d3 = (&y3 - &yb).iter().fold(0f32, |m, v| m.max(v.abs()));
    assert!(d3 < 1e-5, "3 workers vs 1: {d3}");

    // The int8 graph: present, its measured error recorded, and close to the float graph.
    let int8 = meta.int8.as_ref().expect("int8 accuracy in the metadata");
    assert_eq!(int8.file, "surrogate_fused_int8.onnx");
    assert_eq!(int8.ratio_to_sigma_eta.len(), 3);
    for (name, r) in &int8.ratio_to_sigma_eta {
        eprintln!("int8 {name}: RMSE vs float / sigma_eta = {r:.4}");
        assert!(*r < 0.1, "int8 {name}: RMSE vs float / sigma_eta = {r}");
    }
    let mut q = Surrogate::load_with(&dir, 1, Precision::Int8)
        .unwrap()
        .bind(&weather)
        .unwrap();
    let yq = q.evaluate(&params).unwrap().to_owned();
    for k in 0..3 {
        let rmse = ((&yq.column(k) - &y.column(k))
            .mapv(|v| (v as f64).powi(2))
            .mean()
            .unwrap())
        .sqrt();
        let sigma = meta.outputs[k].sigma_eta_kwh;
        assert!(
            rmse < 0.1 * sigma,
            "int8 output {k}: RMSE vs float {rmse} vs sigma_eta {sigma}"
        );
    }

    // The VJP graph: the trainer checked it against torch autograd; here its gradient of the
    // year's total kWh against central differences of the fused graph (raw parameters, so the
    // 1 / (max - min) chain rule is included), and 1 vs 3 workers splitting the chunks.
    let meta_json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("surrogate.json")).unwrap())
            .unwrap();
    let e = meta_json["onnxruntime_check"]["vjp_vs_torch"]
        .as_f64()
        .unwrap();
    // (a float32 sum over 26,280 hour-outputs with a random-sign cotangent: cancellation makes
    // its relative error larger than the outputs' 1e-7)
    assert!(e < 1e-3, "vjp graph vs torch autograd: {e:.2e}");
    assert!(ev.has_gradient());
    let ones = Array3::<f32>::ones((2, 8760, 3));
    let g1 = ev
        .vjp_batch(&[params.clone(), modes.clone()], ones.view())
        .unwrap();
    let g3 = ev3
        .vjp_batch(&[params.clone(), modes.clone()], ones.view())
        .unwrap();
    let total = |ev: &mut bemcal_surrogate::Evaluator, x: &[f64]| -> f64 {
        ev.evaluate(x).unwrap().iter().map(|&v| f64::from(v)).sum()
    };
    for (j, spec) in meta.params.iter().enumerate() {
        let h = 0.01 * (spec.max - spec.min);
        let (mut up, mut dn) = (params.clone(), params.clone());
        up[j] += h;
        dn[j] -= h;
        let fd = (total(&mut ev, &up) - total(&mut ev, &dn)) / (2.0 * h);
        let scale = g1[0].iter().fold(0f64, |m, v| m.max(v.abs()));
        assert!(
            (g1[0][j] - fd).abs() < 0.01 * scale,
            "d total / d {}: vjp {} vs central difference {fd}",
            spec.name,
            g1[0][j]
        );
        for i in 0..2 {
            assert!(
                (g1[i][j] - g3[i][j]).abs() <= 1e-4 * scale,
                "3 workers vs 1"
            );
        }
    }

    // Wrong parameter count is a clear error.
    let e = ev.evaluate(&[1.0]).unwrap_err().to_string();
    assert!(
        e.contains(
            "1 parameter values given; the surrogate takes 3 (u_wall, lpd_w_m2, setpoint_heat_c)"
        ),
        "{e}"
    );

    // Metadata validation on load.
    let meta_path = dir.join("surrogate.json");
    let good = std::fs::read_to_string(&meta_path).unwrap();
    let mut v: serde_json::Value = serde_json::from_str(&good).unwrap();
    v["format_version"] = 99.into();
    std::fs::write(&meta_path, v.to_string()).unwrap();
    let e = Surrogate::load(&dir, 1).unwrap_err();
    assert!(
        matches!(e, SurrogateError::Metadata { .. }) && e.to_string().contains("format_version"),
        "{e}"
    );
    let mut v: serde_json::Value = serde_json::from_str(&good).unwrap();
    v.as_object_mut().unwrap().remove("outputs");
    std::fs::write(&meta_path, v.to_string()).unwrap();
    let e = Surrogate::load(&dir, 1).unwrap_err().to_string();
    assert!(e.contains("missing field `outputs`"), "{e}");
    let mut v: serde_json::Value = serde_json::from_str(&good).unwrap();
    v["n_features"] = 11.into();
    v["feature_names"].as_array_mut().unwrap().pop();
    v["params"].as_array_mut().unwrap().pop();
    std::fs::write(&meta_path, v.to_string()).unwrap();
    let e = Surrogate::load(&dir, 1).unwrap_err().to_string();
    assert!(e.contains("graph and surrogate.json do not match"), "{e}");
    std::fs::write(&meta_path, good).unwrap();
}

/// The trainer's Adam (`bemcal_train/adam.py`, written out so that training does not import
/// `torch._dynamo`) makes the same update as `torch.optim.Adam`: the same weights after 50 steps
/// of a small LSTM, and no `torch._dynamo` imported on the way.
#[test]
fn the_trainers_adam_is_torchs() {
    let Some(python) = bemcal_surrogate::train::find_python() else {
        eprintln!("SKIPPED: no Python environment (.venv)");
        return;
    };
    let out = std::process::Command::new(python)
        .args(["-m", "bemcal_train.adam"])
        .env(
            "PYTHONPATH",
            concat!(env!("CARGO_MANIFEST_DIR"), "/../../python"),
        )
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    eprintln!("{text}");
    assert!(
        out.status.success(),
        "{text}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(text.contains("imported by ours: False"), "{text}");
}

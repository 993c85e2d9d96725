//! Agreement with ArviZ on the fixture written by `python/tools/diagnostics_reference.py`.

use bemcal_stats::diagnostics;

fn close(name: &str, what: &str, got: f64, want: Option<f64>) {
    match want {
        None => assert!(got.is_nan(), "{name} {what}: expected NaN, got {got}"),
        Some(w) => {
            let rel = (got - w).abs() / w.abs().max(1e-12);
            assert!(
                rel < 1e-4,
                "{name} {what}: got {got}, ArviZ {w} (rel {rel:e})"
            );
        }
    }
}

#[test]
fn diagnostics_match_arviz() {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/fixtures/arviz_reference.json"
    );
    let text = std::fs::read_to_string(path).expect("fixture");
    let v: serde_json::Value = serde_json::from_str(&text).unwrap();
    let sets = v["sets"].as_array().unwrap();
    assert!(sets.len() >= 5);
    for s in sets {
        let name = s["name"].as_str().unwrap();
        let chains: Vec<Vec<f64>> = s["draws"]
            .as_array()
            .unwrap()
            .iter()
            .map(|c| {
                c.as_array()
                    .unwrap()
                    .iter()
                    .map(|x| x.as_f64().unwrap())
                    .collect()
            })
            .collect();
        let d = diagnostics::diagnose(&chains).unwrap();
        let f = |k: &str| s[k].as_f64();
        close(name, "rhat", d.rhat, f("rhat"));
        close(name, "ess_bulk", d.ess_bulk, f("ess_bulk"));
        close(name, "ess_tail", d.ess_tail, f("ess_tail"));
        close(name, "mean", d.mean, f("mean"));
        close(name, "sd", d.sd, f("sd"));
        close(name, "q5", d.q5, f("q5"));
        close(name, "q50", d.q50, f("q50"));
        close(name, "q95", d.q95, f("q95"));
    }
}

//! DTW agrees with dtaidistance (pure Python and C paths) to 1e-9.
//! Fixture written by python/tools/dtw_reference.py.

use bemcal_precal::dtw::{distance, Band};

#[test]
fn dtw_matches_dtaidistance_fixture() {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/fixtures/dtw_reference.json"
    );
    let text = std::fs::read_to_string(path).expect("fixture present");
    let v: serde_json::Value = serde_json::from_str(&text).unwrap();
    let cases = v["cases"].as_array().unwrap();
    assert!(cases.len() >= 100);
    let mut real = 0;
    let mut with_c = 0;
    for c in cases {
        let s = |k: &str| -> Vec<f64> {
            c[k].as_array()
                .unwrap()
                .iter()
                .map(|x| x.as_f64().unwrap())
                .collect()
        };
        let (s1, s2) = (s("s1"), s("s2"));
        let band = match c["window"].as_u64() {
            Some(w) => Band::from_dtaidistance_window(w as usize).unwrap(),
            None => Band::unconstrained(),
        };
        assert_eq!(band.max_shift, c["band"].as_u64().map(|b| b as usize));
        let got = distance(&s1, &s2, band);
        let want = c["distance_py"].as_f64().unwrap();
        assert!(
            (got - want).abs() <= 1e-9,
            "{}: window {:?}: {got} vs dtaidistance {want}",
            c["label"],
            c["window"]
        );
        if let Some(wc) = c["distance_c"].as_f64() {
            assert!((got - wc).abs() <= 1e-9, "{}: C {wc} vs {got}", c["label"]);
            with_c += 1;
        }
        if c["label"].as_str().unwrap().starts_with("rsf") {
            real += 1;
        }
    }
    assert!(real > 0, "fixture has real RSF profiles");
    assert!(with_c > 0, "fixture has C-path values");
}

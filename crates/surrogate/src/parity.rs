//! The trainer's parity fixture (`parity.json`): PyTorch outputs at a few explicit windows and
//! over one held-out point's year, written beside the graphs so that the graphs, as ONNX
//! Runtime evaluates them here, can be checked against the network they were exported from.
//! [`crate::train()`] runs [`Surrogate::parity_error`] on every surrogate it trains.

use std::path::Path;

use ndarray::{Array3, ArrayView2};
use serde::Deserialize;

use crate::surrogate::{Surrogate, SurrogateError};

/// File name of the fixture in a surrogate directory.
pub const PARITY_FILE: &str = "parity.json";

/// Largest relative error (see [`relative_error`]) between ONNX Runtime and PyTorch accepted
/// for a trained surrogate: float32 round-off of a 2 x 128 LSTM is ~1e-6.
pub const PARITY_TOLERANCE: f64 = 1e-4;

/// PyTorch's outputs (kWh) for a held-out design point, as the trainer wrote them.
#[derive(Debug, Clone, Deserialize)]
pub struct ParityFixture {
    /// Index of the design point in the training set.
    pub point: usize,
    /// Its parameters, physical units, in the surrogate's parameter order.
    pub params_raw: Vec<f64>,
    /// The hours whose windows are in `x`.
    pub hours: Vec<usize>,
    /// Shape of `x`: windows x lookback x features.
    pub x_shape: [usize; 3],
    /// The windows, normalised as the plain graph takes them, row-major.
    pub x: Vec<f32>,
    /// PyTorch's outputs on `x`: one row per window, one value per output.
    pub y_windows: Vec<Vec<f64>>,
    /// PyTorch's outputs over the point's year: one row per hour.
    pub y_year: Vec<Vec<f64>>,
}

impl ParityFixture {
    /// Reads `dir/parity.json`.
    pub fn read(dir: &Path) -> Result<ParityFixture, SurrogateError> {
        let path = dir.join(PARITY_FILE);
        let bad = |message: String| SurrogateError::Metadata {
            path: path.clone(),
            message,
        };
        let text = std::fs::read_to_string(&path).map_err(|e| bad(format!("cannot read: {e}")))?;
        let f: ParityFixture =
            serde_json::from_str(&text).map_err(|e| bad(format!("invalid parity fixture: {e}")))?;
        let [b, l, n] = f.x_shape;
        if f.x.len() != b * l * n || f.y_windows.len() != b {
            return Err(bad(format!(
                "x has {} values and y_windows {} rows, x_shape {:?} says {} and {b}",
                f.x.len(),
                f.y_windows.len(),
                f.x_shape,
                b * l * n
            )));
        }
        Ok(f)
    }

    /// The windows `x` as an array (windows x lookback x features).
    pub fn windows(&self) -> Array3<f32> {
        let [b, l, n] = self.x_shape;
        Array3::from_shape_vec((b, l, n), self.x.clone()).expect("shape checked on read")
    }
}

/// `max |got - want| / max |want|` over all values: the fixture's definition of the error.
pub fn relative_error(got: ArrayView2<'_, f32>, want: &[Vec<f64>]) -> f64 {
    let (mut max_diff, mut max_abs) = (0.0f64, 0.0f64);
    for (row, want) in got.rows().into_iter().zip(want) {
        for (a, b) in row.iter().zip(want) {
            max_diff = max_diff.max((*a as f64 - b).abs());
            max_abs = max_abs.max(b.abs());
        }
    }
    max_diff / max_abs.max(1e-12)
}

impl Surrogate {
    /// The plain graph's [`relative_error`] against PyTorch on the fixture's windows.
    pub fn parity_error(&mut self, fixture: &ParityFixture) -> Result<f64, SurrogateError> {
        let y = self.run_windows(fixture.windows().view())?;
        Ok(relative_error(y.view(), &fixture.y_windows))
    }

    /// The hot path's [`relative_error`] against PyTorch over the fixture's year
    /// (`y_year`), on the hourly inputs this runtime builds from `weather` (the training set's
    /// raw `[n_hours, 5]`): checks [`crate::SurrogateMeta::hourly_inputs`], the schedule
    /// inputs among them, against the trainer's features as well as the graphs.
    pub fn year_parity_error(
        self,
        fixture: &ParityFixture,
        weather: ArrayView2<'_, f64>,
    ) -> Result<f64, SurrogateError> {
        let hourly = self.meta().hourly_inputs_raw(weather);
        let mut ev = self.bind_hourly(hourly)?;
        let y = ev.evaluate(&fixture.params_raw)?;
        Ok(relative_error(y, &fixture.y_year))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn relative_error_is_max_difference_over_max_magnitude() {
        let got = ndarray::array![[1.0f32, -2.0], [3.5, 0.0]];
        let want = vec![vec![1.0, -2.5], vec![4.0, 0.25]];
        // max |diff| = 0.5 (two places), max |want| = 4.
        assert!((relative_error(got.view(), &want) - 0.125).abs() < 1e-12);
    }

    #[test]
    fn a_fixture_whose_sizes_disagree_is_refused_with_its_path() {
        let dir = tempfile::tempdir().unwrap();
        let text = r#"{"point": 1, "params_raw": [0.5], "hours": [0], "x_shape": [1, 3, 2],
            "x": [0, 0, 0, 0, 0], "y_windows": [[1.0]], "y_year": [[1.0]]}"#;
        std::fs::write(dir.path().join(PARITY_FILE), text).unwrap();
        let e = ParityFixture::read(dir.path()).unwrap_err().to_string();
        assert!(
            e.contains(PARITY_FILE) && e.contains("x has 5 values"),
            "{e}"
        );
        let e = ParityFixture::read(&dir.path().join("nowhere"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("cannot read"), "{e}");
    }
}

//! The keys of a calibration's EnergyPlus runs, in one place. Each run is saved under its key
//! in its folder (`point_{key:03}.json`, [`crate::output::point_file`]), so two runs that
//! share a folder never share a key.
//!
//! ```text
//! simulations/   0 .. n-1   the hypercube's slots (a replaced slot keeps its key, a dropped
//!                           one leaves it unused)
//!                n ..       the refinement rounds' posterior draws, failed ones included
//!                           (first_refinement_key)
//! validation/    0          the estimate ("calibrated")
//!                1          the initial model (INITIAL_KEY, "initial")
//!                2 ..= 4    the fallbacks, the next-best draws (candidate_key, FALLBACKS)
//!                10 ..      the predictive draws (FIRST_PREDICTIVE_KEY, "predictive_NN")
//!                1000 ..    the points of output space mapping (FIRST_MAPPED_KEY, "mapped_NN")
//! ```
//!
//! Pure: no I/O.

/// The simulation key of the first posterior draw of a refinement round, after
/// `design_points` hypercube slots and `drawn_before` draws of the earlier rounds (those
/// EnergyPlus could not simulate included: their keys were used too).
pub fn first_refinement_key(design_points: usize, drawn_before: usize) -> usize {
    design_points + drawn_before
}

/// Draws tried, in order, when EnergyPlus fails at the estimate.
pub const FALLBACKS: usize = 3;

/// Key of the initial model (the prior modes) in `validation/`.
pub const INITIAL_KEY: usize = 1;

/// The key in `validation/` of the `rank`-th candidate: 0 the estimate, then `rank + 1` (1 is
/// the initial model).
pub fn candidate_key(rank: usize) -> usize {
    if rank == 0 {
        0
    } else {
        rank + 1
    }
}

/// The label of the calibrated model's validation run (`validation/calibrated.csv`): the
/// estimate, or the fallback that replaced it.
pub const CALIBRATED_LABEL: &str = "calibrated";

/// Key of the first predictive draw in `validation/` (0 is the estimate, 1 the initial model,
/// 2.. the fallbacks).
pub const FIRST_PREDICTIVE_KEY: usize = 10;

/// The label (and `validation/LABEL.csv`) of predictive draw `j`.
pub fn predictive_label(j: usize) -> String {
    format!("predictive_{j:02}")
}

/// The predictive draw (index into `ChainSummary::predictive`) whose run is under `key` in
/// `validation/`, if it is one's (`ChainSummary::predictive_candidates` gives draw `j` the
/// key `FIRST_PREDICTIVE_KEY + j`).
pub fn draw_of_key(key: usize) -> Option<usize> {
    key.checked_sub(FIRST_PREDICTIVE_KEY)
}

/// Whether a validation label is a predictive draw's.
pub fn is_predictive(label: &str) -> bool {
    label.starts_with("predictive_")
}

/// The key in `validation/` of the first mapped point (`mapped_01`); the next ones follow.
/// Above every predictive draw's (`Project::validate` caps `validation.predictive_draws`).
pub const FIRST_MAPPED_KEY: usize = 1000;

/// The label of the `n`-th mapped point (from 1).
pub fn mapped_label(n: usize) -> String {
    format!("mapped_{n:02}")
}

/// Whether a validation label is a mapped point's.
pub fn is_mapped(label: &str) -> bool {
    label.starts_with("mapped_")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn labels_say_whose_run_they_are() {
        assert!(is_predictive(&predictive_label(3)) && !is_predictive("calibrated"));
        assert!(is_mapped("mapped_03") && !is_mapped("predictive_03"));
        assert_eq!(draw_of_key(FIRST_PREDICTIVE_KEY + 2), Some(2));
        assert_eq!(
            (0..=FALLBACKS).map(candidate_key).collect::<Vec<_>>(),
            [0, 2, 3, 4]
        );
    }
}

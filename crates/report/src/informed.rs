//! Which parameters the meters informed, and why the others were not: the rule and its
//! sentence, shared by the report's first screen and `bemcal calibrate`'s last lines.
//!
//! A parameter whose posterior 90 % interval is nearly its prior's learnt little from the
//! data. Untempered, that is the data's fault (the meters do not see the parameter). With the
//! likelihood tempered (`p(theta) L(theta)^(1/T)`, the surrogate's error taken in so that the
//! intervals hold), it is the surrogate's: for independent Gaussian readings `L^(1/T)` is the
//! likelihood of `1/T` as many readings, so a large `T` leaves the posterior near the prior.

/// Width ratio (posterior 90 % interval / prior's) above this: the data barely informed it.
pub const WIDTH_RATIO_LIMIT: f64 = 0.9;

/// Whether a posterior-to-prior width ratio says the meters barely informed the parameter.
pub fn uninformed(width_ratio: f64) -> bool {
    width_ratio > WIDTH_RATIO_LIMIT
}

/// The sentence for `count` of `total` parameters barely informed (each interval over
/// [`WIDTH_RATIO_LIMIT`] of its prior's), under the likelihood's temperature `t` (1: the
/// posterior itself).
pub fn why_uninformed(count: usize, total: usize, t: f64) -> String {
    let head = format!(
        "{count} of {total} parameters have a posterior 90 % interval over {:.0} % of the prior's",
        100.0 * WIDTH_RATIO_LIMIT
    );
    if t > 1.0 {
        format!(
            "{head}: the chains sampled the likelihood tempered by T = {t:.1} for the surrogate's \
             error (so that the intervals hold), which weighs the meters as 1/T as many readings \
             would. The posterior stays near the prior because the surrogate is far from \
             EnergyPlus, not because the meters are silent: more design points or refinement \
             rounds would narrow it."
        )
    } else {
        format!("{head}: the meters did not inform them (not identifiable from these data).")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_limit_is_exclusive() {
        assert!(!uninformed(WIDTH_RATIO_LIMIT));
        assert!(uninformed(0.91));
        assert!(!uninformed(f64::NAN));
    }

    #[test]
    fn tempered_posteriors_blame_the_surrogate() {
        let t = why_uninformed(30, 38, 1256.3);
        assert!(t.starts_with("30 of 38 parameters have a posterior 90 % interval over 90 %"));
        assert!(t.contains("T = 1256.3") && t.contains("surrogate is far from EnergyPlus"));
        let u = why_uninformed(2, 6, 1.0);
        assert!(u.contains("the meters did not inform them") && !u.contains("T ="));
    }
}

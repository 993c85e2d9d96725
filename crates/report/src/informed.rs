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

/// Width ratio below this: the posterior learned the parameter (its 90 % interval is narrower
/// than half the prior's). The share of such parameters, beside the temperature, is how much a
/// calibration learned, reported beside Guideline 14.
pub const LEARNED_LIMIT: f64 = 0.5;

/// Whether a posterior-to-prior width ratio says the posterior learned the parameter.
pub fn learned(width_ratio: f64) -> bool {
    width_ratio < LEARNED_LIMIT
}

/// How much the posterior learned: how many of the parameters' posterior-to-prior width ratios
/// are under [`LEARNED_LIMIT`], and the likelihood's temperature `t` (1: the posterior itself),
/// with the buildings of the pretrained network's family it pooled, where it did.
pub fn how_much_learned(width_ratios: &[f64], t: f64, pooled_with: Option<u32>) -> String {
    let n = width_ratios.iter().filter(|w| learned(**w)).count();
    let total = width_ratios.len();
    let share = if total == 0 {
        0.0
    } else {
        100.0 * n as f64 / total as f64
    };
    let tempered = match (t > 1.0, pooled_with) {
        (true, Some(n)) => format!(
            "tempered by T = {t:.1} (its own surrogate error pooled with {n} buildings of the \
             pretrained network's family)"
        ),
        (true, None) => format!("tempered by T = {t:.1}"),
        (false, _) => "T = 1".to_string(),
    };
    format!(
        "the posterior learned {n} of {total} parameters ({share:.0} %: 90 % interval narrower \
         than half the prior's), the likelihood {tempered}"
    )
}

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

/// What meters read as bills can and cannot say (issue 69), for `billed` outputs with their
/// numbers of bills; None without any. The figures are measured comparisons of the same
/// buildings' meters hourly and as bills (docs/benchmarks.md, "Bills against hourly meters").
pub fn what_bills_say(billed: &[(&str, usize)]) -> Option<String> {
    if billed.is_empty() {
        return None;
    }
    let list: Vec<String> = billed
        .iter()
        .map(|(output, n)| format!("{output} as {n} bills"))
        .collect();
    Some(format!(
        "{} read: a bill gives the meter's total over its days, not its hours, so what shapes the \
         day and the response to one cold or hot day is left to the hourly meters. What an hourly \
         (or daily) meter would add, measured: on make quick's building every meter hourly gave \
         intervals a third as wide as heating and cooling as bills (median 0.02 of the prior's \
         against 0.06); on the NREL RSF 2011 its hourly heating meter taught the posterior 1 of 9 \
         parameters (T = 264), its heating bills none (T = 2,685) (docs/benchmarks.md, \"Bills \
         against hourly meters\").",
        list.join(", ")
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bills_are_said_with_what_an_hourly_meter_would_add() {
        assert_eq!(what_bills_say(&[]), None);
        let s = what_bills_say(&[("heating_kwh", 10), ("cooling_kwh", 12)]).unwrap();
        assert!(
            s.starts_with("heating_kwh as 10 bills, cooling_kwh as 12 bills read"),
            "{s}"
        );
        assert!(
            s.contains("What an hourly (or daily) meter would add"),
            "{s}"
        );
    }

    #[test]
    fn the_limit_is_exclusive() {
        assert!(!uninformed(WIDTH_RATIO_LIMIT));
        assert!(uninformed(0.91));
        assert!(!uninformed(f64::NAN));
    }

    #[test]
    fn learned_is_narrower_than_half_the_prior() {
        assert!(learned(0.49) && !learned(0.5) && !learned(f64::NAN));
        assert_eq!(
            how_much_learned(&[0.1, 0.3, 0.95], 1.0, None),
            "the posterior learned 2 of 3 parameters (67 %: 90 % interval narrower than half \
             the prior's), the likelihood T = 1"
        );
        assert!(how_much_learned(&[0.8], 651.7, None).ends_with("0 of 1 parameters (0 %: 90 % interval narrower than half the prior's), the likelihood tempered by T = 651.7"));
        assert!(how_much_learned(&[0.2], 79.5, Some(3))
            .ends_with("tempered by T = 79.5 (its own surrogate error pooled with 3 buildings of the pretrained network's family)"));
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

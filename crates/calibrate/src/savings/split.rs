//! Two parameters the posterior ties together: the lines along which each draw's split is drawn
//! again from the priors ([`Split::Priors`]), and the warning where a saving rests on such a
//! split.

use super::*;

/// The lines along which the draws' splits are drawn again: under [`Split::Priors`], every
/// pair of calibrated parameters the posterior ties together, with the major axis of their
/// draws ([`bemcal_stats::split::ridge_direction`], over `all` the draws).
pub(super) fn split_lines(
    cal: &Calibration,
    summary: &Summary,
    all: &[Vec<f64>],
    split: Split,
) -> Vec<RedrawnSplit> {
    if split == Split::Chains {
        return vec![];
    }
    let at = |name: &str| cal.inputs.plan.calibrated.iter().position(|c| c == name);
    let column = |k: usize| all.iter().map(|r| r[k]).collect::<Vec<f64>>();
    (summary.posterior.correlated_pairs.iter())
        .filter(|c| c.rho.abs() >= SPLIT_CORRELATION)
        .filter_map(|c| {
            let (a, b) = (at(&c.a)?, at(&c.b)?);
            let direction = bemcal_stats::split::ridge_direction(&column(a), &column(b))?;
            Some(RedrawnSplit {
                a: c.a.clone(),
                b: c.b.clone(),
                correlation: c.rho,
                direction,
            })
        })
        .collect()
}

/// `rows` with each line's split drawn again at every draw (one uniform number per draw and
/// line from `seed`); a draw the model's constraints would refuse keeps its own.
pub(super) fn redraw_splits(
    cal: &Calibration,
    lines: &[RedrawnSplit],
    rows: Vec<Vec<f64>>,
    seed: u64,
) -> Vec<Vec<f64>> {
    use rand::{Rng, SeedableRng};
    if lines.is_empty() {
        return rows;
    }
    let plan = &cal.inputs.plan;
    let at = |name: &str| plan.calibrated.iter().position(|c| c == name);
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    rows.into_iter()
        .map(|mut x| {
            for l in lines {
                let u: f64 = rng.random();
                let (Some(a), Some(b)) = (at(&l.a), at(&l.b)) else {
                    continue;
                };
                let (xa, xb) = bemcal_stats::split::redraw_on_line(
                    (x[a], x[b]),
                    l.direction,
                    (&plan.priors[a], &plan.priors[b]),
                    u,
                );
                let mut y = x.clone();
                (y[a], y[b]) = (xa, xb);
                if plan.feasible(&cal.inputs.model, &y) {
                    x = y;
                }
            }
            x
        })
        .collect()
}

/// What a redrawn split means, for the report's notes.
pub(super) fn split_note(l: &RedrawnSplit) -> String {
    format!(
        "{} and {} are tied in the posterior (correlation {:+.2}): the meters constrain a \
         combination of them, and each draw's split between them was drawn again from their \
         priors along it (bemcal savings --split chains keeps the chains')",
        l.a, l.b, l.correlation
    )
}

/// Where a saving rests on a split the meters do not make: its main driver (a share of
/// [`SPLIT_SHARE`] or more) tied in the posterior to another parameter. The meters then
/// constrain a combination of the two. Where its split was drawn again from the priors
/// (`lines`), the interval carries that uncertainty and the warning says what would narrow it;
/// where the chains' split stands, the surrogate's small errors can pin it too tightly
/// (measured: `make savings-weather`, lighting against equipment on one electricity meter,
/// docs/benchmarks.md), and the warning says the interval is likely too narrow.
pub(super) fn split_warning(drivers: &[Driver], lines: &[RedrawnSplit]) -> Option<String> {
    let d = drivers
        .iter()
        .find(|d| d.share >= SPLIT_SHARE && !d.moves_with.is_empty())?;
    let with: Vec<String> = (d.moves_with.iter())
        .map(|p| {
            format!(
                "{} (posterior correlation {:+.2})",
                p.parameter, p.correlation
            )
        })
        .collect();
    let redrawn = d.moves_with.iter().all(|p| {
        lines.iter().any(|l| {
            (l.a == d.parameter && l.b == p.parameter) || (l.b == d.parameter && l.a == p.parameter)
        })
    });
    let consequence = if redrawn {
        "so each draw's split was drawn from their priors along that combination and the \
         interval carries the priors' uncertainty of it"
    } else {
        "so the split is not the meters' finding and this interval is likely too narrow"
    };
    Some(format!(
        "it rests on {}, tied to {}: the meters constrain them together, not apart, {}; {} \
         would separate them",
        d.parameter,
        with.join(" and "),
        consequence,
        d.would_narrow
    ))
}

//! Chains that settled in different modes of the posterior, and what separates them.
//!
//! A large R-hat says the chains disagree; it does not say how. Where the posterior has two
//! modes (a model that is not the building can fit a meter two ways: more equipment and fewer
//! people, or the reverse), each chain stays in one, and R-hat stays high however long they
//! run. [`chain_modes`] groups the chains by their means: two chains are in one mode when no
//! parameter's means differ by more than [`MODE_GAP`] of the chains' pooled within-chain
//! standard deviation (single linkage; the within-chain scale is R-hat's `W`, Gelman et al.
//! 2013, Bayesian Data Analysis, Sec. 11.4), and names the parameters that separate the modes,
//! with each mode's mean log density: which one the data prefer. Pure: no I/O.

use serde::{Deserialize, Serialize};

/// Chains whose means differ by more than this many pooled within-chain standard deviations
/// in some parameter are in different modes.
pub const MODE_GAP: f64 = 4.0;

/// Chains grouped into modes.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct ChainModes {
    /// The chains of each mode (0-based), the mode of the highest mean log density first.
    pub chains: Vec<Vec<usize>>,
    /// Each mode's mean log density of its draws.
    pub log_density: Vec<f64>,
    /// The parameters whose means differ between the first two modes by more than
    /// [`MODE_GAP`] within-chain standard deviations, the largest separation first.
    pub separated_by: Vec<Separation>,
}

/// One parameter that separates two modes.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct Separation {
    /// The parameter's index.
    pub parameter: usize,
    /// Its mean in each mode (the modes' order).
    pub means: Vec<f64>,
    /// The difference of the first two modes' means in pooled within-chain standard deviations.
    #[serde(deserialize_with = "crate::nan::null_as_nan")]
    #[schemars(with = "crate::nan::NumberOrNull")]
    pub gap_sd: f64,
}

/// The modes of `draws[j][c]` (parameter j, chain c: its draws) with `log_density[c]` (chain
/// c's draws' log densities); `None` for fewer than two chains or where all chains share one
/// mode.
pub fn chain_modes(draws: &[Vec<Vec<f64>>], log_density: &[Vec<f64>]) -> Option<ChainModes> {
    let chains = log_density.len();
    if chains < 2 || draws.iter().any(|p| p.len() != chains) {
        return None;
    }
    let mean = |x: &[f64]| x.iter().sum::<f64>() / x.len().max(1) as f64;
    let means: Vec<Vec<f64>> = draws
        .iter()
        .map(|p| p.iter().map(|c| mean(c)).collect())
        .collect();
    // The pooled within-chain SD of each parameter (R-hat's W, square-rooted).
    let within: Vec<f64> = draws
        .iter()
        .zip(&means)
        .map(|(p, m)| {
            let w: f64 = (p.iter().zip(m))
                .map(|(c, mc)| {
                    c.iter().map(|x| (x - mc).powi(2)).sum::<f64>() / (c.len().max(2) - 1) as f64
                })
                .sum::<f64>()
                / chains as f64;
            w.sqrt()
        })
        .collect();
    let gap = |a: usize, b: usize, j: usize| (means[j][a] - means[j][b]).abs() / within[j];
    let apart =
        |a: usize, b: usize| (0..draws.len()).any(|j| within[j] > 0.0 && gap(a, b, j) > MODE_GAP);
    // Single linkage: a chain joins the first mode holding a chain it is not apart from.
    let mut label: Vec<usize> = (0..chains).collect();
    for a in 0..chains {
        for b in 0..a {
            if !apart(a, b) {
                let (from, to) = (label[a].max(label[b]), label[a].min(label[b]));
                label
                    .iter_mut()
                    .filter(|l| **l == from)
                    .for_each(|l| *l = to);
            }
        }
    }
    let mut groups: Vec<Vec<usize>> = vec![];
    for c in 0..chains {
        match groups.iter_mut().find(|g| label[g[0]] == label[c]) {
            Some(g) => g.push(c),
            None => groups.push(vec![c]),
        }
    }
    if groups.len() < 2 {
        return None;
    }
    let group_lp = |g: &[usize]| {
        mean(
            &g.iter()
                .flat_map(|&c| log_density[c].iter().copied())
                .collect::<Vec<_>>(),
        )
    };
    groups.sort_by(|a, b| group_lp(b).total_cmp(&group_lp(a)));
    let group_mean =
        |g: &[usize], j: usize| mean(&g.iter().map(|&c| means[j][c]).collect::<Vec<_>>());
    let mut separated_by: Vec<Separation> = (0..draws.len())
        .filter(|&j| within[j] > 0.0)
        .map(|j| {
            let m: Vec<f64> = groups.iter().map(|g| group_mean(g, j)).collect();
            Separation {
                parameter: j,
                gap_sd: (m[0] - m[1]).abs() / within[j],
                means: m,
            }
        })
        .filter(|s| s.gap_sd > MODE_GAP)
        .collect();
    separated_by.sort_by(|a, b| b.gap_sd.total_cmp(&a.gap_sd));
    Some(ChainModes {
        log_density: groups.iter().map(|g| group_lp(g)).collect(),
        chains: groups,
        separated_by,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A chain of `n` draws around `centre` (a deterministic wiggle of SD about 0.7).
    fn chain(centre: f64, n: usize) -> Vec<f64> {
        (0..n)
            .map(|i| centre + ((i * 7 % 11) as f64 - 5.0) / 4.5)
            .collect()
    }

    #[test]
    fn two_modes_are_found_with_what_separates_them() {
        // Parameter 0 splits chains {0, 2} (near 11.5) from {1, 3} (near 15); parameter 1 does
        // not; chains 1 and 3 have the higher log density.
        let draws = vec![
            vec![
                chain(11.5, 100),
                chain(15.0, 100),
                chain(11.6, 100),
                chain(15.1, 100),
            ],
            vec![
                chain(5.0, 100),
                chain(5.1, 100),
                chain(5.0, 100),
                chain(4.9, 100),
            ],
        ];
        let lp = vec![
            vec![-10.0; 100],
            vec![-8.0; 100],
            vec![-10.0; 100],
            vec![-8.0; 100],
        ];
        let m = chain_modes(&draws, &lp).unwrap();
        assert_eq!(m.chains, vec![vec![1, 3], vec![0, 2]]);
        assert_eq!(m.log_density, vec![-8.0, -10.0]);
        assert_eq!(m.separated_by.len(), 1);
        let s = &m.separated_by[0];
        assert_eq!(s.parameter, 0);
        assert!((s.means[0] - s.means[1] - 3.5).abs() < 1e-9, "{s:?}");
        assert!(s.gap_sd > MODE_GAP, "{s:?}");
    }

    #[test]
    fn chains_in_one_mode_give_none() {
        let draws = vec![vec![chain(5.0, 100), chain(5.2, 100), chain(4.9, 100)]];
        let lp = vec![vec![-1.0; 100]; 3];
        assert_eq!(chain_modes(&draws, &lp), None);
        assert_eq!(
            chain_modes(&[vec![chain(5.0, 10)]], &[vec![-1.0; 10]]),
            None
        );
    }
}

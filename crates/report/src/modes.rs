//! Chains settled in different modes of the posterior, in a sentence: the terminal's warning
//! and the report's first screen say the same ([`bemcal_stats::modes`]).

use bemcal_stats::modes::ChainModes;
use bemcal_stats::summary::ParameterSummary;

/// Parameters named in the sentence, the largest separation first.
pub const NAMED: usize = 4;

/// Which chains settled where, what separates the modes (each parameter's mean per mode and
/// the gap in within-chain standard deviations) and which mode the data prefer.
pub fn modes_sentence(m: &ChainModes, parameters: &[ParameterSummary]) -> String {
    let chains = |g: &[usize]| {
        g.iter()
            .map(|c| c.to_string())
            .collect::<Vec<_>>()
            .join(", ")
    };
    let modes: Vec<String> = (m.chains.iter().zip(&m.log_density))
        .map(|(g, lp)| format!("chains {} (mean log density {lp:.1})", chains(g)))
        .collect();
    let separated: Vec<String> = (m.separated_by.iter().take(NAMED))
        .map(|s| {
            let name = parameters.get(s.parameter).map_or("?", |p| p.name.as_str());
            let means: Vec<String> = s.means.iter().map(|x| format!("{x:.4}")).collect();
            format!(
                "{name} {} ({:.0} SDs apart)",
                means.join(" against "),
                s.gap_sd
            )
        })
        .collect();
    format!(
        "the chains settled in {} places: {}; separated by {}: either modes of the posterior \
         (the data fit more than one way, the first best; longer chains will not merge them, \
         and the intervals pool what the meters cannot tell apart: a sub-meter or a prior that \
         rules one out would) or chains not mixed yet (longer chains would merge them)",
        m.chains.len(),
        modes.join(" and "),
        if separated.is_empty() {
            "no parameter on its own once the places' chains are pooled".to_string()
        } else {
            separated.join(", ")
        }
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use bemcal_stats::modes::Separation;

    #[test]
    fn the_sentence_names_the_chains_and_what_separates_them() {
        let m = ChainModes {
            chains: vec![vec![1, 3], vec![0, 2]],
            log_density: vec![-8.0, -10.0],
            separated_by: vec![Separation {
                parameter: 0,
                means: vec![15.05, 11.55],
                gap_sd: 5.2,
            }],
        };
        let p: ParameterSummary = serde_json::from_value(serde_json::json!({
            "name": "equipment_power_density", "unit": "W/m2", "mean": 13.0, "sd": 1.0,
            "median": 13.0, "q5": 11.0, "q95": 15.0, "map": 15.0, "rhat": 1.6,
            "ess_bulk": 7.0, "ess_tail": 9.0, "width_ratio": 0.4
        }))
        .unwrap();
        let s = modes_sentence(&m, &[p]);
        assert!(
            s.starts_with("the chains settled in 2 places: chains 1, 3 (mean log density -8.0) and chains 0, 2")
                && s.contains("equipment_power_density 15.0500 against 11.5500 (5 SDs apart)"),
            "{s}"
        );
    }
}

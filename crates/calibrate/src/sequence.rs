//! The calibration's sequence, written once: which chains run after how many refinement rounds
//! and for how long, what the finished final chains lead to (an extension or the validation),
//! and which EnergyPlus runs validate the result, in which order; and the stages themselves
//! ([`Stage`]). The one driver ([`crate::driver::drive`]) takes each of these transitions from
//! here, whichever executor does the work (this process, or workers leased jobs by the
//! coordinator). Pure: no I/O. The stages' names live in [`crate::stage`], below everything
//! that names one.
//!
//! ```text
//! design -> simulate (failed points replaced) -> train
//!   -> chains of Round::Preliminary(r) -> EnergyPlus at its draws -> retrain   (refine.rounds times)
//!   -> chains of Round::Final -> AfterFinalChains::Extend (while short of the targets)
//!                             -> AfterFinalChains::Validate -> validation_runs
//!      (the estimate; while EnergyPlus fails there, next_validation) -> summary
//! ```

use crate::chain_summary::ChainSummary;
use crate::chains::extended_target;
use crate::keys::{CALIBRATED_LABEL, INITIAL_KEY};
use crate::posterior::Drawn;
use crate::project::{McmcSettings, Project};
use crate::validation::{next_candidate, ValidationStep};

pub use crate::stage::Stage;

/// The chains of one round. `index` is the number of refinement rounds finished before them:
/// the key of their checkpoint (`OutputDir::chains_checkpoint_of`), their sampler settings
/// (`Sampler::config_for`) and the coordinator's chain jobs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Round {
    /// Before refinement round `index + 1`: `refine.iterations` per chain, then posterior draws
    /// of these chains are simulated by EnergyPlus and the surrogate is retrained.
    Preliminary {
        /// Refinement rounds finished before these chains.
        index: u32,
    },
    /// The final chains: `mcmc.iterations` per chain, extended while they miss a convergence
    /// target ([`after_final_chains`]).
    Final {
        /// Refinement rounds finished before these chains (all of `refine.rounds`).
        index: u32,
    },
}

impl Round {
    /// The round whose chains run after `finished` refinement rounds.
    pub fn after(project: &Project, finished: u32) -> Round {
        if finished < project.refine.rounds {
            Round::Preliminary { index: finished }
        } else {
            Round::Final { index: finished }
        }
    }

    /// Refinement rounds finished before these chains.
    pub fn index(self) -> u32 {
        match self {
            Round::Preliminary { index } | Round::Final { index } => index,
        }
    }

    /// Whether these are the final chains.
    pub fn is_final(self) -> bool {
        matches!(self, Round::Final { .. })
    }

    /// Iterations per chain, burn-in included, before any extension.
    pub fn iterations(self, project: &Project) -> u64 {
        match self {
            Round::Preliminary { .. } => project.refine.iterations,
            Round::Final { .. } => project.mcmc.iterations,
        }
    }

    /// How logs name these chains: `chains`, or `refinement round N chains`.
    pub fn label(self) -> String {
        match self {
            Round::Preliminary { index } => format!("refinement round {} chains", index + 1),
            Round::Final { .. } => "chains".into(),
        }
    }
}

/// What the final chains, summarised, lead to.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum AfterFinalChains {
    /// They miss a convergence target and extensions are left: run them on from their
    /// checkpoint to this many iterations per chain, then summarise again.
    Extend {
        /// The new iteration target per chain, burn-in included.
        iterations: u64,
    },
    /// Converged, or out of extensions: validate.
    Validate,
}

/// The final chains' next step: an extension while `chains.convergence` misses its targets and
/// `mcmc.max_extensions` allows (the rule [`extended_target`]), else the validation. `target`:
/// the iterations per chain they ran to; `drawn`: where they stand.
pub fn after_final_chains(
    m: &McmcSettings,
    chains: &ChainSummary,
    target: u64,
    drawn: Drawn,
) -> AfterFinalChains {
    match extended_target(m, &chains.convergence, chains.extensions, target, drawn) {
        Some(iterations) => AfterFinalChains::Extend { iterations },
        None => AfterFinalChains::Validate,
    }
}

/// What a validation run is for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ValidationRole {
    /// The calibrated model: the estimate (`rank` 0) or the `rank`-th next-best draw after
    /// EnergyPlus failed at those before it.
    Calibrated {
        /// 0 for the estimate; `k` for the `k`-th fallback draw ([`crate::keys::FALLBACKS`]).
        rank: usize,
    },
    /// The initial model (the prior modes), for comparison (`validation.initial`).
    Initial,
    /// A posterior draw of the predictive intervals (`validation.predictive_draws`).
    Predictive,
    /// A point of the output space mapping where EnergyPlus fitted no posterior draw
    /// ([`crate::mapping`]).
    Mapped,
}

/// One EnergyPlus run of the validation stage, saved as `validation/<label>.csv` under `key`.
#[derive(Debug, Clone, PartialEq)]
pub struct ValidationRun {
    /// What the run is for.
    pub role: ValidationRole,
    /// Its key in `validation/`.
    pub key: usize,
    /// `calibrated`, `initial`, `predictive_NN` or `mapped_NN`.
    pub label: String,
    /// Parameter values (the calibrated ones, in the plan's order).
    pub values: Vec<f64>,
}

impl ValidationRun {
    /// Whether an EnergyPlus failure here leaves the calibration going: at the calibrated model
    /// the next-best draw is validated instead ([`next_validation`]), a predictive draw is left
    /// out of the intervals, a mapped point out of the search; the initial model's failure
    /// fails the validation.
    pub fn tolerates_failure(&self) -> bool {
        self.role != ValidationRole::Initial
    }
}

/// The validation runs the driver starts once the final chains are settled, in this order:
/// the estimate, the initial model at `initial` (when `validation.initial`), and the posterior
/// draws of the predictive intervals.
pub fn validation_runs(chains: &ChainSummary, initial: Option<Vec<f64>>) -> Vec<ValidationRun> {
    let mut runs = vec![];
    if let Ok(estimate) = next_validation(chains, &[]) {
        runs.push(estimate);
    }
    if let Some(values) = initial {
        runs.push(ValidationRun {
            role: ValidationRole::Initial,
            key: INITIAL_KEY,
            label: "initial".into(),
            values,
        });
    }
    runs.extend(
        chains
            .predictive_candidates()
            .into_iter()
            .map(|(c, label)| ValidationRun {
                role: ValidationRole::Predictive,
                key: c.key,
                label,
                values: c.values,
            }),
    );
    runs
}

/// The calibrated model's run after EnergyPlus failed at the first `failures.len()`
/// candidates (the rule [`next_candidate`]), or the message that every candidate failed.
pub fn next_validation(
    chains: &ChainSummary,
    failures: &[String],
) -> Result<ValidationRun, String> {
    match next_candidate(chains, failures) {
        ValidationStep::Validate(c) => Ok(ValidationRun {
            role: ValidationRole::Calibrated { rank: c.rank },
            key: c.key,
            label: CALIBRATED_LABEL.into(),
            values: c.values,
        }),
        ValidationStep::Exhausted(message) => Err(message),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::chain_summary::tests::chains;
    use std::path::Path;

    fn project(extra: &str) -> Project {
        let text = format!(
            "model = \"m.toml\"\nweather = \"w.epw\"\n[meters]\nfile = \"meters.csv\"\n{extra}"
        );
        let p: Project = bemcal_energyplus::parse_toml(&text, Path::new("project.toml"))
            .unwrap_or_else(|e| panic!("{e}"));
        p.validate().unwrap_or_else(|e| panic!("{e}"));
        p
    }

    #[test]
    fn preliminary_rounds_then_the_final_chains_each_for_its_iterations() {
        let p = project("[refine]\nrounds = 2\niterations = 300\nburn_in = 100\n[mcmc]\niterations = 900\nburn_in = 300\n");
        let rounds: Vec<Round> = (0..3).map(|k| Round::after(&p, k)).collect();
        assert_eq!(
            rounds,
            [
                Round::Preliminary { index: 0 },
                Round::Preliminary { index: 1 },
                Round::Final { index: 2 }
            ]
        );
        let its: Vec<u64> = rounds.iter().map(|r| r.iterations(&p)).collect();
        assert_eq!(its, [300, 300, 900]);
        assert_eq!(rounds[1].label(), "refinement round 2 chains");
        assert_eq!(rounds[2].label(), "chains");
        assert!(rounds[2].is_final() && rounds[2].index() == 2);
        // Without refinement the first chains are the final ones.
        let p = project("[refine]\nrounds = 0\n");
        assert_eq!(Round::after(&p, 0), Round::Final { index: 0 });
    }

    #[test]
    fn final_chains_are_extended_while_short_and_allowed_then_validated() {
        let p = project("[mcmc]\niterations = 500\nburn_in = 100\nmax_extensions = 1\n");
        let mut c = chains(0);
        let (first, extended) = (
            Drawn {
                draws: 400,
                readapted: false,
            },
            Drawn {
                draws: 800,
                readapted: true,
            },
        );
        // Not converged (the default verdict), no extension yet: one step of 400 draws more,
        // after the HMC chains' re-adaptation window of 50.
        assert_eq!(
            after_final_chains(&p.mcmc, &c, 500, first),
            AfterFinalChains::Extend { iterations: 950 }
        );
        c.extensions = 1;
        assert_eq!(
            after_final_chains(&p.mcmc, &c, 950, extended),
            AfterFinalChains::Validate
        );
        c.extensions = 0;
        c.convergence.converged = true;
        assert_eq!(
            after_final_chains(&p.mcmc, &c, 500, first),
            AfterFinalChains::Validate
        );
    }

    #[test]
    fn validation_runs_the_estimate_the_initial_model_and_the_predictive_draws_in_order() {
        let mut c = chains(1);
        c.predictive = vec![vec![5.0], vec![6.0]];
        let runs = validation_runs(&c, Some(vec![9.0]));
        let got: Vec<(ValidationRole, usize, &str, f64)> = runs
            .iter()
            .map(|r| (r.role, r.key, r.label.as_str(), r.values[0]))
            .collect();
        assert_eq!(
            got[0],
            (ValidationRole::Calibrated { rank: 0 }, 0, "calibrated", 0.0)
        );
        assert_eq!(
            got[1],
            (ValidationRole::Initial, INITIAL_KEY, "initial", 9.0)
        );
        assert_eq!(got.len(), 4);
        assert!(got[2..].iter().all(|g| g.0 == ValidationRole::Predictive));
        // Keys never collide: the estimate, the initial model, fallbacks, predictive draws.
        let mut keys: Vec<usize> = runs.iter().map(|r| r.key).collect();
        keys.push(next_validation(&c, &["failed".into()]).unwrap().key);
        keys.sort_unstable();
        keys.dedup();
        assert_eq!(keys.len(), 5);
        assert!(!runs[1].tolerates_failure());
        assert!(runs[0].tolerates_failure() && runs[2].tolerates_failure());
        // Without `validation.initial`: the estimate and the draws only.
        assert_eq!(validation_runs(&c, None).len(), 3);
    }

    #[test]
    fn after_the_estimate_fails_the_next_best_draw_then_a_message() {
        let c = chains(1);
        let fail = |n: usize| next_validation(&c, &vec!["EnergyPlus failed".to_string(); n]);
        let r = fail(1).unwrap();
        assert_eq!(
            (r.role, r.values.clone()),
            (ValidationRole::Calibrated { rank: 1 }, vec![1.0])
        );
        assert_eq!(r.label, "calibrated");
        assert!(fail(2)
            .unwrap_err()
            .contains("at the estimate and at the next 1 draws"));
    }
}

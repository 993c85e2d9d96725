//! The stages of a calibration and their names, the one list of the stage words: a vocabulary
//! module with no imports, so that every module can name a stage without reaching up to the
//! sequence ([`crate::sequence`]) that orders them.

/// The stages of a calibration, in the order the driver ([`crate::driver`]) enters them; a
/// stage is entered again for each refinement round and extension. The coordinator stores a
/// run's stage as [`Stage::as_str`]; both executors time the stages by it ([`crate::summary::Timings`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Stage {
    /// The Latin hypercube and its spares (in-process).
    Design,
    /// EnergyPlus at the design points, failed points replaced.
    Simulate,
    /// The training set and the surrogate's training.
    Train,
    /// The chains of a round (or an extension of the final ones).
    Chains,
    /// The final chains summarised (in-process).
    Merge,
    /// EnergyPlus at a refinement round's posterior draws.
    Refine,
    /// EnergyPlus at the estimate (or its fallbacks), the initial model and the predictive draws.
    Validate,
    /// `summary.json` and the output files (in-process).
    Summary,
    /// EnergyPlus at posterior draws with and without each measure (`[savings]
    /// with_calibration`), their savings added to `summary.json`.
    Savings,
    /// Finished.
    Done,
}

impl Stage {
    /// Every stage, in order.
    pub const ALL: &'static [Stage] = &[
        Stage::Design,
        Stage::Simulate,
        Stage::Train,
        Stage::Chains,
        Stage::Merge,
        Stage::Refine,
        Stage::Validate,
        Stage::Summary,
        Stage::Savings,
        Stage::Done,
    ];

    /// The stage's name: `design`, `simulate`, ... (the coordinator's SQL and its replies,
    /// `bemcal status`, errors). The one list of the stage words: the wire's stage
    /// (`proto::Stage` in `proto/bemcal.proto`, `STAGE_` and the word in upper case) is found
    /// by its word, derived from its proto name, so a new stage is a variant here (and in
    /// [`Stage::ALL`]) and a value there; a coordinator test checks the two lists agree.
    pub fn as_str(self) -> &'static str {
        match self {
            Stage::Design => "design",
            Stage::Simulate => "simulate",
            Stage::Train => "train",
            Stage::Chains => "chains",
            Stage::Merge => "merge",
            Stage::Refine => "refine",
            Stage::Validate => "validate",
            Stage::Summary => "summary",
            Stage::Savings => "savings",
            Stage::Done => "done",
        }
    }
}

impl std::str::FromStr for Stage {
    type Err = String;
    fn from_str(s: &str) -> Result<Stage, String> {
        Stage::ALL
            .iter()
            .copied()
            .find(|x| x.as_str() == s)
            .ok_or_else(|| format!("unknown Stage {s:?}"))
    }
}

impl std::fmt::Display for Stage {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

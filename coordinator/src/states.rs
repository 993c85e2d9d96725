//! The typed states of runs and jobs. They are text only in the database (each type converts
//! itself at the SQL boundary, [`rusqlite::ToSql`] / [`rusqlite::types::FromSql`]) and on the
//! wire (the proto's enums, each with its `From`), and users read the same words
//! (`proto::RunState::word`).

use crate::proto;

/// Declares an enum whose variants are stored as fixed words.
macro_rules! words {
    ($(#[$m:meta])* $name:ident { $($(#[$vm:meta])* $v:ident = $s:literal,)+ }) => {
        $(#[$m])*
        #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
        pub enum $name { $($(#[$vm])* $v,)+ }

        impl $name {
            /// Every value, in order.
            pub const ALL: &'static [$name] = &[$($name::$v,)+];

            /// The word stored in the database and sent on the wire.
            pub fn as_str(self) -> &'static str {
                match self { $($name::$v => $s,)+ }
            }
        }

        impl std::str::FromStr for $name {
            type Err = String;
            fn from_str(s: &str) -> Result<Self, String> {
                match s {
                    $($s => Ok($name::$v),)+
                    _ => Err(format!("unknown {} {s:?}", stringify!($name))),
                }
            }
        }

        impl std::fmt::Display for $name {
            fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                f.write_str(self.as_str())
            }
        }

        impl rusqlite::ToSql for $name {
            fn to_sql(&self) -> rusqlite::Result<rusqlite::types::ToSqlOutput<'_>> {
                Ok(self.as_str().into())
            }
        }

        impl rusqlite::types::FromSql for $name {
            fn column_result(v: rusqlite::types::ValueRef<'_>) -> rusqlite::types::FromSqlResult<Self> {
                v.as_str()?
                    .parse()
                    .map_err(|e: String| rusqlite::types::FromSqlError::Other(e.into()))
            }
        }
    };
}

/// Where a run is in its calibration: the driver's stages (`bemcal_calibrate::sequence`),
/// stored as their names (`stage_column` reads one back).
pub use bemcal_calibrate::sequence::Stage;

/// The [`Stage`] in column `i` of a row.
pub(crate) fn stage_column(r: &rusqlite::Row<'_>, i: usize) -> rusqlite::Result<Stage> {
    let s: String = r.get(i)?;
    s.parse().map_err(|e: String| {
        rusqlite::Error::FromSqlConversionFailure(i, rusqlite::types::Type::Text, e.into())
    })
}

words! {
    /// A run's state.
    RunState {
        /// Submitted and not finished.
        Running = "running",
        /// Finished: its summary and results are stored.
        Done = "done",
        /// Stopped by an error (its `error` says which).
        Failed = "failed",
        /// Cancelled by a client.
        Cancelled = "cancelled",
    }
}

words! {
    /// A job's state.
    JobState {
        /// Waiting for a worker.
        Queued = "queued",
        /// Leased to a worker.
        Leased = "leased",
        /// Completed, its outputs stored.
        Done = "done",
        /// Failed too often (its run failed).
        Failed = "failed",
        /// Its run ended first.
        Cancelled = "cancelled",
    }
}

words! {
    /// What a job does on a worker.
    JobKind {
        /// EnergyPlus at a point.
        Simulate = "simulate",
        /// The surrogate's training.
        Train = "train",
        /// A segment of chains.
        Chains = "chains",
        /// EnergyPlus at the estimate or the initial model, against the meters.
        Validate = "validate",
    }
}

/// The wire's stage (a function: both types are other crates').
pub fn wire_stage(s: Stage) -> proto::Stage {
    match s {
        Stage::Design => proto::Stage::Design,
        Stage::Simulate => proto::Stage::Simulate,
        Stage::Train => proto::Stage::Train,
        Stage::Chains => proto::Stage::Chains,
        Stage::Merge => proto::Stage::Merge,
        Stage::Refine => proto::Stage::Refine,
        Stage::Validate => proto::Stage::Validate,
        Stage::Summary => proto::Stage::Summary,
        Stage::Done => proto::Stage::Done,
    }
}

/// The wire's run state.
impl From<RunState> for proto::RunState {
    fn from(s: RunState) -> Self {
        match s {
            RunState::Running => proto::RunState::Running,
            RunState::Done => proto::RunState::Done,
            RunState::Failed => proto::RunState::Failed,
            RunState::Cancelled => proto::RunState::Cancelled,
        }
    }
}

/// The wire's state of a run's current stage: the run's own.
impl From<RunState> for proto::StageState {
    fn from(s: RunState) -> Self {
        match s {
            RunState::Running => proto::StageState::Running,
            RunState::Done => proto::StageState::Done,
            RunState::Failed => proto::StageState::Failed,
            RunState::Cancelled => proto::StageState::Cancelled,
        }
    }
}

/// The wire's job state.
impl From<JobState> for proto::JobState {
    fn from(s: JobState) -> Self {
        match s {
            JobState::Queued => proto::JobState::Queued,
            JobState::Leased => proto::JobState::Leased,
            JobState::Done => proto::JobState::Done,
            JobState::Failed => proto::JobState::Failed,
            JobState::Cancelled => proto::JobState::Cancelled,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_wire_shows_each_state_with_its_stored_word() {
        for s in Stage::ALL {
            assert_eq!(wire_stage(*s).word(), s.as_str());
        }
        for s in RunState::ALL {
            assert_eq!(proto::RunState::from(*s).word(), s.as_str());
            assert_eq!(proto::StageState::from(*s).word(), s.as_str());
        }
        for s in JobState::ALL {
            assert_eq!(proto::JobState::from(*s).word(), s.as_str());
        }
    }

    #[test]
    fn every_word_reads_back_as_its_value() {
        for s in Stage::ALL {
            assert_eq!(s.as_str().parse::<Stage>(), Ok(*s));
        }
        for s in JobState::ALL {
            assert_eq!(s.as_str().parse::<JobState>(), Ok(*s));
        }
        assert!("runing"
            .parse::<RunState>()
            .unwrap_err()
            .contains("unknown RunState"));
    }
}

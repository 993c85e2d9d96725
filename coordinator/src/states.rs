//! The typed states of runs and jobs. They are text only in the database (each type converts
//! itself at the SQL boundary, [`rusqlite::ToSql`] / [`rusqlite::types::FromSql`]) and on the
//! wire (the proto's enums, each with its `From`), and users read the same words: a run's or a
//! job's state is stored as its wire value's `word()` (`proto::RunState::word`), so the words
//! are listed once, in the client crate.

use crate::proto;

/// Declares an enum stored as words: its `ALL`, parsing, display and the SQL conversions,
/// through the `as_str` the declaring macro ([`words!`], [`wire_words!`]) writes.
macro_rules! stored_enum {
    ($(#[$m:meta])* $name:ident { $($(#[$vm:meta])* $v:ident,)+ }) => {
        $(#[$m])*
        #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
        pub enum $name { $($(#[$vm])* $v,)+ }

        impl $name {
            /// Every value, in order.
            pub const ALL: &'static [$name] = &[$($name::$v,)+];
        }

        impl std::str::FromStr for $name {
            type Err = String;
            fn from_str(s: &str) -> Result<Self, String> {
                $name::ALL
                    .iter()
                    .copied()
                    .find(|v| v.as_str() == s)
                    .ok_or_else(|| format!("unknown {} {s:?}", stringify!($name)))
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
            fn column_result(
                v: rusqlite::types::ValueRef<'_>,
            ) -> rusqlite::types::FromSqlResult<Self> {
                v.as_str()?
                    .parse()
                    .map_err(|e: String| rusqlite::types::FromSqlError::Other(e.into()))
            }
        }
    };
}

/// Declares an enum whose variants are stored as fixed words.
macro_rules! words {
    ($(#[$m:meta])* $name:ident { $($(#[$vm:meta])* $v:ident = $s:literal,)+ }) => {
        stored_enum!($(#[$m])* $name { $($(#[$vm])* $v,)+ });

        impl $name {
            /// The word stored in the database.
            pub fn as_str(self) -> &'static str {
                match self { $($name::$v => $s,)+ }
            }
        }
    };
}

/// Declares an enum that has a twin on the wire (`proto::$name`, the same variants): its
/// `From`, and its stored word, the wire value's `word()` (one list of words, the client's).
macro_rules! wire_words {
    ($(#[$m:meta])* $name:ident { $($(#[$vm:meta])* $v:ident,)+ }) => {
        stored_enum!($(#[$m])* $name { $($(#[$vm])* $v,)+ });

        impl $name {
            /// The word stored in the database and shown to users: the wire value's.
            pub fn as_str(self) -> &'static str {
                proto::$name::from(self).word()
            }
        }

        /// The wire's value.
        impl From<$name> for proto::$name {
            fn from(s: $name) -> Self {
                match s { $($name::$v => proto::$name::$v,)+ }
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

wire_words! {
    /// A run's state.
    RunState {
        /// Submitted and not finished.
        Running,
        /// Finished: its summary and results are stored.
        Done,
        /// Stopped by an error (its `error` says which).
        Failed,
        /// Cancelled by a client.
        Cancelled,
    }
}

wire_words! {
    /// A job's state.
    JobState {
        /// Waiting for a worker.
        Queued,
        /// Leased to a worker.
        Leased,
        /// Completed, its outputs stored.
        Done,
        /// Failed too often (its run failed).
        Failed,
        /// Its run ended first.
        Cancelled,
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
    fn stored_words_are_those_of_existing_databases() {
        // The words come from the client's wire enums; a database written by any earlier
        // build holds these, so they must not change.
        let words = |w: Vec<&str>| w.join(" ");
        let run: Vec<&str> = RunState::ALL.iter().map(|s| s.as_str()).collect();
        assert_eq!(words(run), "running done failed cancelled");
        let job: Vec<&str> = JobState::ALL.iter().map(|s| s.as_str()).collect();
        assert_eq!(words(job), "queued leased done failed cancelled");
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

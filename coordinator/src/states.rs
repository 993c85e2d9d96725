//! The typed states of runs and jobs. They are text only in the database (each type converts
//! itself at the SQL boundary, [`rusqlite::ToSql`] / [`rusqlite::types::FromSql`]) and on the
//! wire (the proto's enums, each with its `From`), and users read the same words: a run's or a
//! job's state is stored as its wire value's `word()` (`proto::RunState::word`, derived in the
//! client crate from the proto's names), so no list of these words is written anywhere. A run's
//! stage is stored as its name, [`Stage::as_str`] (calibrate's, the one list of stage words),
//! and goes on the wire as the proto's stage of that word ([`wire_stage`]).

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
/// `From`, and its stored word, the wire value's `word()` (derived from the proto's names).
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
        /// EnergyPlus at a posterior draw with a measure or without (the savings).
        Measure = "measure",
    }
}

/// The wire's stage (a function: both types are other crates'): the proto's value with the
/// stage's word (`proto::Stage::word`, derived from the proto's names; the words themselves are
/// [`Stage::as_str`]'s). A stage the proto lacks would go as `unspecified`: the unit test
/// `each_stage_is_its_wire_stage` fails first.
pub fn wire_stage(s: Stage) -> proto::Stage {
    proto::Stage::from_word(s.as_str()).unwrap_or(proto::Stage::Unspecified)
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

    /// Both ways, no stage missed: each calibration stage has a wire stage of its word, and
    /// each wire stage but `unspecified` is a calibration stage's.
    #[test]
    fn each_stage_is_its_wire_stage() {
        for s in Stage::ALL {
            assert_ne!(wire_stage(*s), proto::Stage::Unspecified, "{s}");
            assert_eq!(wire_stage(*s).word(), s.as_str());
        }
        let wire: Vec<proto::Stage> = proto::Stage::values().skip(1).collect();
        assert_eq!(wire.len(), Stage::ALL.len());
        for w in wire {
            let s: Stage = w.word().parse().unwrap();
            assert_eq!(wire_stage(s), w);
        }
    }

    #[test]
    fn the_wire_shows_each_state_with_its_stored_word() {
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

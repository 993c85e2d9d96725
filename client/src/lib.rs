//! The client side of bemcal's coordinator protocol, shared by the CLI, the workers and the
//! coordinator: the gRPC types (`proto/bemcal.proto`), an authenticated channel
//! ([`client::Connect`]), content-addressed artifacts and their transfer in chunks, and project
//! bundles. It links no server state (no SQLite): a worker or a CLI command depends on this
//! crate, not on the coordinator.
#![deny(missing_docs)]

pub mod artifacts;
pub mod auth;
pub mod bundle;
pub mod client;
pub mod metrics;

use serde::{Deserialize, Serialize};

/// Generated protocol types, client and server (package `bemcal.v1`).
#[allow(clippy::too_many_lines)]
pub mod proto {
    tonic::include_proto!("bemcal.v1");
}

/// Declares `word` (the stage or state as users read it: in `bemcal status`, `portfolio.json`,
/// error messages) for proto enums, derived from the proto's own names with no list of words:
/// a value's word is its name after the enum's prefix, in lower case (`STAGE_DESIGN` is
/// `design`, `JOB_STATE_QUEUED` `queued`), the prefix being what comes before `UNSPECIFIED` in
/// the name of value 0 ([`words_of`]). A value added to the proto has its word.
macro_rules! words_from_names {
    ($($name:ident)+) => {$(
        impl proto::$name {
            /// Every value, from 0 (`Unspecified`) on (the values are numbered without gaps).
            pub fn values() -> impl Iterator<Item = proto::$name> {
                (0_i32..).map_while(|i| proto::$name::try_from(i).ok())
            }

            /// As users read it: its proto name after the enum's prefix, in lower case
            /// (`unspecified` for a reply without one).
            pub fn word(self) -> &'static str {
                static WORDS: std::sync::OnceLock<Vec<String>> = std::sync::OnceLock::new();
                let words =
                    WORDS.get_or_init(|| words_of(proto::$name::values().map(|v| v.as_str_name())));
                words.get(self as usize).map_or_else(|| self.as_str_name(), String::as_str)
            }

            /// The value users read as `word` (the inverse of `word`), if any.
            pub fn from_word(word: &str) -> Option<proto::$name> {
                proto::$name::values().find(|v| v.word() == word)
            }
        }
    )+};
}

words_from_names!(Stage RunState StageState JobState);

/// The words of an enum's values, from their proto names in order of value: each name after the
/// prefix that value 0's name has before `UNSPECIFIED` (none if it has no such name), in lower
/// case.
fn words_of(names: impl Iterator<Item = &'static str>) -> Vec<String> {
    let names: Vec<&str> = names.collect();
    let prefix = names
        .first()
        .and_then(|n| n.strip_suffix("UNSPECIFIED"))
        .unwrap_or("");
    names
        .iter()
        .map(|n| n.strip_prefix(prefix).unwrap_or(n).to_ascii_lowercase())
        .collect()
}

impl proto::ChainSegmentJob {
    /// The likelihood's temperature the job's chains run at: 0 (a job written before the field
    /// existed) is 1.
    ///
    /// # Errors
    /// Any other value below 1, or not finite.
    pub fn likelihood_temperature(&self) -> Result<f64, String> {
        match self.temperature {
            0.0 => Ok(1.0),
            t if t.is_finite() && t >= 1.0 => Ok(t),
            t => Err(format!("chain job with temperature {t} (at least 1)")),
        }
    }
}

/// The revision of the coordinator/worker protocol this build speaks, sent with every lease
/// request (`LeaseRequest::protocol`); a coordinator leases only to workers of its own revision.
/// Raised whenever a job gains a field that changes what a worker computes:
/// - 1: `ChainSegmentJob::temperature` (the likelihood's temperature, issue 20).
/// - 2: HMC states re-adapted at an extension (`window_end`, `readapted`: an older worker would
///   drop them and draw the adaptation window).
/// - 3: a completion's result is a typed `JobResult` (it was JSON text), and a validation's
///   Guideline 14 figures are the coordinator's to compute from the job's files.
/// - 4: workers register (`Register`) and call with their own credential; the worker token
///   alone no longer leases.
/// - 5: `MeasureJob`, the measures' savings runs (`[savings] with_calibration`).
pub const PROTOCOL: u32 = 5;

/// Largest gRPC message either side accepts (artifacts travel in chunks well below it).
pub const MAX_MESSAGE_BYTES: usize = 16 * 1024 * 1024;

/// Size of one artifact chunk.
pub const CHUNK_BYTES: usize = 1024 * 1024;

/// A file by relative path and content hash (the serde twin of `proto::FileRef`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct File {
    /// Where it goes, relative to the bundle's or the job's folder.
    pub path: String,
    /// Its content's SHA-256, hex.
    pub sha256: String,
    /// Its size, bytes.
    pub size: u64,
}

impl From<&proto::FileRef> for File {
    fn from(f: &proto::FileRef) -> File {
        File {
            path: f.path.clone(),
            sha256: f.sha256.clone(),
            size: f.size,
        }
    }
}

impl From<&File> for proto::FileRef {
    fn from(f: &File) -> proto::FileRef {
        proto::FileRef {
            path: f.path.clone(),
            sha256: f.sha256.clone(),
            size: f.size,
        }
    }
}

/// The stored form of [`proto::EnergyPlusFailure`]: the result of a job whose EnergyPlus run
/// failed in a way the calibration handles (a design point or refinement draw EnergyPlus could
/// not simulate, a validation candidate). The job is done, and the driver decides what follows
/// (a replacement point, the next-best draw).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ReportedFailure {
    /// EnergyPlus's reason.
    pub error: String,
}

/// The stored form of [`proto::SimulationRun`]: the result of a simulation job that ran (its
/// point file is the job's one output).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SimulationRun {
    /// EnergyPlus's wall time; none when the worker had the point already.
    pub seconds: Option<f64>,
}

use proto::job_result::Outcome;

impl proto::JobResult {
    /// A simulation that ran (`seconds`: EnergyPlus's wall time) or was already there.
    pub fn simulated(seconds: Option<f64>) -> proto::JobResult {
        Self::of(Outcome::Simulated(proto::SimulationRun { seconds }))
    }

    /// EnergyPlus's failure, reported as the job's result.
    pub fn energyplus_failed(error: String) -> proto::JobResult {
        Self::of(Outcome::EnergyplusFailed(proto::EnergyPlusFailure {
            error,
        }))
    }

    /// A training done.
    pub fn trained() -> proto::JobResult {
        Self::of(Outcome::Trained(proto::TrainingDone {}))
    }

    /// A chain segment done, its chains at `iteration`.
    pub fn chains(iteration: u64) -> proto::JobResult {
        Self::of(Outcome::Chains(proto::ChainSegmentDone { iteration }))
    }

    /// A validation run done.
    pub fn validated() -> proto::JobResult {
        Self::of(Outcome::Validated(proto::ValidationDone {}))
    }

    fn of(outcome: Outcome) -> proto::JobResult {
        proto::JobResult {
            outcome: Some(outcome),
        }
    }

    /// The result's kind as the proto names it (`missing` without one), for messages.
    pub fn word(&self) -> &'static str {
        match &self.outcome {
            Some(Outcome::Simulated(_)) => "simulated",
            Some(Outcome::EnergyplusFailed(_)) => "energyplus_failed",
            Some(Outcome::Trained(_)) => "trained",
            Some(Outcome::Chains(_)) => "chains",
            Some(Outcome::Validated(_)) => "validated",
            None => "missing",
        }
    }

    /// The result as the coordinator stores and shows it (the one place a result becomes
    /// text): `{"seconds": s}`, `{"error": "..."}`, `{"iteration": n}` or `{}`.
    pub fn to_text(&self) -> String {
        let v = match &self.outcome {
            Some(Outcome::Simulated(s)) => {
                serde_json::to_value(SimulationRun { seconds: s.seconds })
            }
            Some(Outcome::EnergyplusFailed(f)) => serde_json::to_value(ReportedFailure {
                error: f.error.clone(),
            }),
            Some(Outcome::Chains(c)) => Ok(serde_json::json!({ "iteration": c.iteration })),
            Some(Outcome::Trained(_)) | Some(Outcome::Validated(_)) | None => {
                Ok(serde_json::json!({}))
            }
        };
        v.map(|v| v.to_string()).unwrap_or_else(|_| "{}".into())
    }
}

/// A stored job result read back, if it is one of type `T`.
pub fn parse_result<T: serde::de::DeserializeOwned>(json: &str) -> Option<T> {
    serde_json::from_str(json).ok()
}

/// Longest error message a coordinator replies with or stores about a request (bytes). Errors
/// quote at most an [`excerpt`] of the input they refuse, so a hostile or mistaken multi-MB
/// input never travels back in a reply, a log line or the database.
pub const MAX_ERROR_BYTES: usize = 1000;

pub use bemcal_excerpt::{excerpt, EXCERPT_BYTES};

/// Milliseconds since the Unix epoch (lease expiry survives coordinator restarts).
pub fn now_ms() -> u64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_millis() as u64)
        .unwrap_or(0)
}

/// A multi-threaded async runtime for the command-line front end.
pub fn runtime() -> std::io::Result<tokio::runtime::Runtime> {
    tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
}

/// Completes on SIGTERM or Ctrl-C.
pub async fn shutdown_signal() {
    #[cfg(unix)]
    {
        use tokio::signal::unix::{signal, SignalKind};
        match signal(SignalKind::terminate()) {
            Ok(mut term) => {
                tokio::select! {
                    _ = term.recv() => {}
                    _ = tokio::signal::ctrl_c() => {}
                }
            }
            Err(_) => {
                let _ = tokio::signal::ctrl_c().await;
            }
        }
    }
    #[cfg(not(unix))]
    {
        let _ = tokio::signal::ctrl_c().await;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The words derived from the proto's names are those users have always read (`bemcal
    /// status`, `portfolio.json`, the coordinator's database), each reads back as its value, and
    /// no value is missed (`values` would stop at a gap in the numbering).
    #[test]
    fn each_wire_value_reads_as_its_word() {
        fn words<E: Copy>(values: impl Iterator<Item = E>, word: fn(E) -> &'static str) -> String {
            values.map(word).collect::<Vec<_>>().join(" ")
        }
        // The stage words are calibrate's (`Stage::as_str`; the coordinator's tests hold the
        // wire's to them, stage by stage): no list of them here.
        assert_eq!(proto::Stage::Unspecified.word(), "unspecified");
        assert_eq!(proto::Stage::Design.word(), "design");
        assert_eq!(
            words(proto::RunState::values(), proto::RunState::word),
            "unspecified running done failed cancelled"
        );
        assert_eq!(
            words(proto::StageState::values(), proto::StageState::word),
            "unspecified pending running done failed cancelled"
        );
        assert_eq!(
            words(proto::JobState::values(), proto::JobState::word),
            "unspecified queued leased done failed cancelled"
        );
        for i in 0..256 {
            if let Ok(s) = proto::Stage::try_from(i) {
                assert_eq!(proto::Stage::from_word(s.word()), Some(s));
            }
            if let Ok(s) = proto::StageState::try_from(i) {
                assert_eq!(proto::StageState::from_word(s.word()), Some(s));
            }
            if let Ok(s) = proto::RunState::try_from(i) {
                assert_eq!(proto::RunState::from_word(s.word()), Some(s));
            }
            if let Ok(s) = proto::JobState::try_from(i) {
                assert_eq!(proto::JobState::from_word(s.word()), Some(s));
            }
        }
        assert_eq!(proto::Stage::from_word("STAGE_DESIGN"), None);
    }

    /// Each result is stored as the JSON its readers expect; an EnergyPlus failure reads back
    /// as one, and no other result does.
    #[test]
    fn results_are_stored_as_their_readers_expect() {
        let failed = proto::JobResult::energyplus_failed("Lights: watts < 0".into());
        assert_eq!(failed.to_text(), r#"{"error":"Lights: watts < 0"}"#);
        assert_eq!(
            parse_result::<ReportedFailure>(&failed.to_text()).map(|f| f.error),
            Some("Lights: watts < 0".into())
        );
        let ran = proto::JobResult::simulated(Some(5.5));
        assert_eq!(ran.to_text(), r#"{"seconds":5.5}"#);
        assert_eq!(
            parse_result::<SimulationRun>(&ran.to_text()),
            Some(SimulationRun { seconds: Some(5.5) })
        );
        assert_eq!(
            proto::JobResult::simulated(None).to_text(),
            r#"{"seconds":null}"#
        );
        assert_eq!(
            proto::JobResult::chains(300).to_text(),
            r#"{"iteration":300}"#
        );
        for r in [
            proto::JobResult::trained(),
            proto::JobResult::validated(),
            proto::JobResult::default(),
        ] {
            assert_eq!(r.to_text(), "{}");
        }
        for r in [
            ran,
            proto::JobResult::chains(1),
            proto::JobResult::trained(),
        ] {
            assert!(
                parse_result::<ReportedFailure>(&r.to_text()).is_none(),
                "{r:?}"
            );
        }
        assert_eq!(proto::JobResult::default().word(), "missing");
    }
}

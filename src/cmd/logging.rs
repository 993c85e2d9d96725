//! How the long-running processes (`coordinator`, `worker`) log: `tracing` events (the
//! coordinator's audit trail under the target `bemcal::audit`, with the fields `actor`,
//! `action`, `run`, `job`, `lease`, `detail`; the worker's under `bemcal_worker`) on standard
//! error, as text or one JSON object a line for log shippers. `RUST_LOG`, where set, is the
//! filter (`RUST_LOG=bemcal=debug,h2=info`); else `--log-level`.

/// `--log-format`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, clap::ValueEnum)]
pub enum LogFormat {
    /// `TIME LEVEL TARGET: fields`, coloured on a terminal.
    #[default]
    Text,
    /// One JSON object a line: `timestamp`, `level`, `target` and the event's fields.
    Json,
}

/// `--log-level`: the least severe events written, of bemcal's own (other libraries': warnings
/// and errors only).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, clap::ValueEnum)]
pub enum LogLevel {
    /// Nothing (a coordinator's database keeps the whole audit trail whatever this says).
    Off,
    /// Errors only.
    Error,
    /// Errors and warnings.
    Warn,
    /// All but routine leases and completions.
    #[default]
    Info,
    /// Every event.
    Debug,
}

impl LogLevel {
    /// The `tracing` filter this level means where `RUST_LOG` is not set.
    fn filter(self) -> &'static str {
        match self {
            LogLevel::Off => "off",
            LogLevel::Error => "error",
            LogLevel::Warn => "warn",
            LogLevel::Info => "warn,bemcal=info",
            LogLevel::Debug => "warn,bemcal=debug",
        }
    }
}

/// The logging flags of a long-running command.
#[derive(Debug, Clone, clap::Args)]
pub struct LogArgs {
    /// How events are logged on standard error: text, or json (one object a line).
    #[arg(long, value_enum, default_value_t)]
    pub log_format: LogFormat,
    /// Which events are logged (RUST_LOG, where set, overrides it): off, error, warn, info (all
    /// but routine ones: a coordinator's leases and completions), debug (all).
    #[arg(long, value_enum, default_value_t)]
    pub log_level: LogLevel,
}

impl LogArgs {
    /// Installs the process's subscriber (once; a second call is a no-op).
    pub fn init(&self) {
        use std::io::IsTerminal;
        use tracing_subscriber::EnvFilter;
        let filter = match std::env::var("RUST_LOG") {
            Ok(f) if !f.trim().is_empty() => EnvFilter::new(f),
            _ => EnvFilter::new(self.log_level.filter()),
        };
        let builder = tracing_subscriber::fmt()
            .with_env_filter(filter)
            .with_writer(std::io::stderr);
        let _ = match self.log_format {
            LogFormat::Text => builder
                .with_ansi(std::io::stderr().is_terminal())
                .try_init(),
            LogFormat::Json => builder.json().flatten_event(true).try_init(),
        };
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every level is a filter `tracing` accepts, bemcal's own events at the level asked.
    #[test]
    fn every_level_is_a_valid_filter() {
        for l in [
            LogLevel::Off,
            LogLevel::Error,
            LogLevel::Warn,
            LogLevel::Info,
            LogLevel::Debug,
        ] {
            let f: Result<tracing_subscriber::EnvFilter, _> = l.filter().parse();
            assert!(f.is_ok(), "{l:?}: {}", l.filter());
        }
    }
}

//! EnergyPlus 25.2: engine discovery, isolated runs, hourly meter output, and parametric building
//! models with named calibration parameters.
//!
//! - [`engine::Engine`] finds the `energyplus` executable (bemcal's `.venv` or `$BEMCAL_ENERGYPLUS`).
//! - [`model::Model`] is what gets calibrated: a generated building ([`building::BuildingSpec`]) or
//!   a user's IDF with a parameter map ([`model::ParameterMap`]); it lists its parameters with
//!   priors and turns a set of values into an IDF, refusing physically impossible combinations.
//! - [`runner::Runner`] runs one simulation in its own directory, treats `** Severe` / `** Fatal`
//!   in `eplusout.err` as failure whatever the exit code, and returns hourly outputs in kWh.
#![deny(missing_docs)]

pub mod building;
pub mod calendar;
pub mod confine;
pub mod engine;
pub mod errfile;
pub mod idd;
pub mod idf;
pub mod meters;
pub mod model;
pub mod params;
pub mod runner;
pub mod screen;

use std::path::PathBuf;

pub use building::{BuildingSpec, HvacSystem};
pub use engine::Engine;
pub use meters::{HourlyOutputs, OutputSpec};
pub use model::Model;
pub use params::{ParameterDef, ParameterValues, TriangularPrior};
pub use runner::{RunOptions, Runner};

/// Revision of what the runner and the model generator make of a given spec and parameter
/// values. Caches of simulation results key on it: bump it whenever the same inputs would now
/// simulate differently.
pub const SIMULATION_REVISION: u32 = 3;

/// Errors of the simulation layer. Each names the file, line, parameter or run directory
/// concerned.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// EnergyPlus could not be found.
    #[error("EnergyPlus not found: {0}")]
    EngineNotFound(String),
    /// A file could not be read or written.
    #[error("cannot access {path}")]
    Io {
        /// The file or folder.
        path: PathBuf,
        /// The operating system's error.
        #[source]
        source: std::io::Error,
    },
    /// A model, spec or parameter-map file is malformed.
    #[error("{path}:{line}: {}", bemcal_excerpt::shorten(.message))]
    Input {
        /// The file.
        path: PathBuf,
        /// The line at fault (0: the file as a whole).
        line: usize,
        /// What was expected, with a short excerpt of what was found.
        message: String,
    },
    /// A parameter is unknown, missing, out of range or violates a constraint.
    #[error("parameter {}: {}", bemcal_excerpt::excerpt(.name, 80), bemcal_excerpt::shorten(.message))]
    Parameter {
        /// The parameter.
        name: String,
        /// What is wrong with it.
        message: String,
    },
    /// EnergyPlus ran but failed (severe/fatal errors, missing output).
    #[error("EnergyPlus failed in {dir}: {message}\n{}", .details.join("\n"))]
    Simulation {
        /// The run's folder.
        dir: PathBuf,
        /// What failed.
        message: String,
        /// EnergyPlus's Severe and Fatal lines.
        details: Vec<String>,
    },
    /// EnergyPlus exceeded its time limit and was killed.
    #[error(
        "EnergyPlus exceeded its time limit of {seconds} s in {dir} (a project's [simulation] timeout_s sets it)"
    )]
    Timeout {
        /// The run's folder.
        dir: PathBuf,
        /// The limit, s.
        seconds: f64,
    },
    /// EnergyPlus ended by a signal: past its output or memory limit, or killed.
    #[error("EnergyPlus stopped in {dir}: {message}")]
    Limit {
        /// The run's folder.
        dir: PathBuf,
        /// Which limit, where one explains it.
        message: String,
    },
}

/// Parses TOML text into `T`; an error names the file and the line of the offending key.
pub fn parse_toml<T: serde::de::DeserializeOwned>(
    text: &str,
    path: &std::path::Path,
) -> Result<T, Error> {
    toml::from_str(text).map_err(|e| {
        let line = e
            .span()
            .map(|s| text[..s.start].matches('\n').count() + 1)
            .unwrap_or(0);
        // toml's own message names the value, not its key: the line's text says which.
        let found = line.checked_sub(1).and_then(|i| text.lines().nth(i));
        let at = match found.map(str::trim) {
            Some(found) if !found.is_empty() => {
                format!(" (in `{}`)", bemcal_excerpt::excerpt(found, 80))
            }
            _ => String::new(),
        };
        Error::Input {
            path: path.to_path_buf(),
            line,
            message: format!("{}{at}", e.message().trim_end()),
        }
    })
}

pub(crate) fn io_err(path: impl Into<PathBuf>) -> impl FnOnce(std::io::Error) -> Error {
    let path = path.into();
    move |source| Error::Io { path, source }
}

/// The 1-based line of a key in TOML text, for messages about a value that parsed but is not
/// acceptable: `keys` is the path to it (`["fixed", "shgc"]`; an array index as a number,
/// `["meters", "columns", "2", "role"]`). 0 when the text does not parse or has no such key
/// (a default value), as the file-level messages write it.
pub fn toml_line(text: &str, keys: &[&str]) -> usize {
    use toml::de::{DeTable, DeValue};
    let Ok(root) = DeTable::parse(text) else {
        return 0;
    };
    let line = |byte: usize| text[..byte.min(text.len())].matches('\n').count() + 1;
    let mut table = root.get_ref();
    let mut value: Option<&toml::Spanned<DeValue>> = None;
    let mut key_start = 0;
    for (n, k) in keys.iter().enumerate() {
        if n > 0 {
            match value.map(|v| v.get_ref()) {
                Some(DeValue::Table(t)) => table = t,
                Some(DeValue::Array(a)) => {
                    let Some(item) = k.parse::<usize>().ok().and_then(|i| a.get(i)) else {
                        return 0;
                    };
                    key_start = item.span().start;
                    value = Some(item);
                    continue;
                }
                _ => return 0,
            }
        }
        let Some((key, v)) = table.iter().find(|(key, _)| key.get_ref().as_ref() == *k) else {
            return 0;
        };
        key_start = key.span().start;
        value = Some(v);
    }
    if keys.is_empty() {
        0
    } else {
        line(key_start)
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn toml_line_finds_keys_tables_and_array_items() {
        let text = "name = \"x\"\n\n[fixed]\nshgc = 0.5\n[[meters.columns]]\nrole = \"a\"\n\
                    [[meters.columns]]\ncolumn = \"c\"\nrole = \"b\"\n[priors.shgc]\nmin = 1\n";
        assert_eq!(super::toml_line(text, &["name"]), 1);
        assert_eq!(super::toml_line(text, &["fixed", "shgc"]), 4);
        assert_eq!(
            super::toml_line(text, &["meters", "columns", "0", "role"]),
            6
        );
        assert_eq!(
            super::toml_line(text, &["meters", "columns", "1", "role"]),
            9
        );
        assert_eq!(super::toml_line(text, &["priors", "shgc", "min"]), 11);
        for missing in [
            &["year"][..],
            &["fixed", "lpd"],
            &["meters", "columns", "2"],
            &[],
        ] {
            assert_eq!(super::toml_line(text, missing), 0, "{missing:?}");
        }
        assert_eq!(super::toml_line("a = [", &["a"]), 0);
    }
}

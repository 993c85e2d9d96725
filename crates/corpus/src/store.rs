//! The corpus folder.
//!
//! | path                   | content                                                             |
//! |------------------------|---------------------------------------------------------------------|
//! | `corpus.json`          | [`CorpusInfo`]: format, simulation revision, outputs, features      |
//! | `weather/<climate>.npy`| float32 `[8760, 5]`: the climate's hourly features ([`WEATHER_FEATURES`]) under the corpus calendar |
//! | `cases/<key>.npy`      | float16 `[8760, n_outputs]`: the case's meters in Wh per m2 of floor per hour |
//! | `index.jsonl`          | one [`Finished`] per line, in the order they finished               |
//! | `failures.jsonl`       | one [`Failed`] per line: EnergyPlus refused the case, and why       |
//!
//! A case is done once its line is in `index.jsonl` (written after its array, atomically), so
//! a corpus stopped at any moment resumes without losing or repeating a finished case.

use std::collections::BTreeSet;
use std::io::Write;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::draw::Case;
use crate::{io_err, Error};

/// Format of the corpus folder.
pub const FORMAT_VERSION: u32 = 1;

/// The weather features of `weather/<climate>.npy`, in order.
pub const WEATHER_FEATURES: [&str; 5] = bemcal_weather::HourlyFeatures::NAMES;

/// What the corpus folder holds, written once.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CorpusInfo {
    /// [`FORMAT_VERSION`].
    pub format: u32,
    /// The simulation revision the cases were simulated at.
    pub simulation_revision: u32,
    /// The outputs (columns of every case's array).
    pub outputs: Vec<String>,
    /// Their unit.
    pub output_unit: String,
    /// The weather features (columns of every climate's array).
    pub weather_features: Vec<String>,
}

/// A finished case: what was drawn and how long EnergyPlus took.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Finished {
    /// The case's key (its array is `cases/<key>.npy`).
    pub key: String,
    /// The drawn case.
    #[serde(flatten)]
    pub case: Case,
    /// Conditioned floor area, m2 (the arrays are per m2 of it).
    pub floor_area_m2: f64,
    /// EnergyPlus's wall time, s.
    pub seconds: f64,
    /// Usable warnings EnergyPlus wrote.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub notes: Vec<String>,
}

/// A case EnergyPlus could not simulate: data, with its reason.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Failed {
    /// The case's key.
    pub key: String,
    /// The drawn case.
    #[serde(flatten)]
    pub case: Case,
    /// Why (EnergyPlus's message and its first lines).
    pub reason: String,
}

/// An open corpus folder.
#[derive(Debug)]
pub struct Store {
    dir: PathBuf,
    finished: BTreeSet<String>,
    failed: BTreeSet<String>,
}

impl Store {
    /// Opens (creating it) the corpus folder `dir`; its `corpus.json` must match `info` where
    /// one exists (another revision or other outputs are another corpus).
    pub fn open(dir: &Path, info: &CorpusInfo) -> Result<Store, Error> {
        for sub in ["cases", "weather"] {
            let d = dir.join(sub);
            std::fs::create_dir_all(&d).map_err(io_err(&d))?;
        }
        let path = dir.join("corpus.json");
        match std::fs::read(&path) {
            Ok(bytes) => {
                let found: CorpusInfo = serde_json::from_slice(&bytes).map_err(|e| Error::Io {
                    path: path.clone(),
                    message: format!("not a corpus description: {e}"),
                })?;
                if &found != info {
                    return Err(Error::Io {
                        path,
                        message: format!(
                            "a corpus of simulation revision {} with outputs {:?}, where this one is revision {} with {:?}: use another folder",
                            found.simulation_revision, found.outputs, info.simulation_revision, info.outputs
                        ),
                    });
                }
            }
            Err(_) => {
                let json = serde_json::to_vec_pretty(info).expect("serialises");
                bemcal_durable::write_atomic(&path, &json).map_err(io_err(&path))?;
            }
        }
        let finished = read_lines::<Finished>(&dir.join("index.jsonl"))?
            .into_iter()
            .map(|f| f.key)
            .collect();
        let failed = read_lines::<Failed>(&dir.join("failures.jsonl"))?
            .into_iter()
            .map(|f| f.key)
            .collect();
        Ok(Store {
            dir: dir.to_path_buf(),
            finished,
            failed,
        })
    }

    /// The folder.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// Whether the case with `key` is settled (finished or failed).
    pub fn settled(&self, key: &str) -> bool {
        self.finished.contains(key) || self.failed.contains(key)
    }

    /// Finished and failed cases so far.
    pub fn counts(&self) -> (usize, usize) {
        (self.finished.len(), self.failed.len())
    }

    /// Writes a climate's features unless present.
    pub fn write_weather(&self, climate: &str, rows: &[[f64; 5]]) -> Result<(), Error> {
        let path = self.dir.join("weather").join(format!("{climate}.npy"));
        if path.exists() {
            return Ok(());
        }
        let data: Vec<u8> = rows
            .iter()
            .flatten()
            .flat_map(|&x| (x as f32).to_le_bytes())
            .collect();
        let bytes = npy("<f4", [rows.len(), 5], &data);
        bemcal_durable::write_atomic(&path, &bytes).map_err(io_err(&path))
    }

    /// Records a finished case: its array (`series[output][hour]`, Wh/m2), then its line.
    pub fn finish(&mut self, f: Finished, series: &[Vec<f64>]) -> Result<(), Error> {
        let hours = series.first().map_or(0, Vec::len);
        let data: Vec<u8> = (0..hours)
            .flat_map(|t| series.iter().map(move |s| s[t]))
            .flat_map(|x| half::f16::from_f64(x).to_le_bytes())
            .collect();
        let path = self.dir.join("cases").join(format!("{}.npy", f.key));
        let bytes = npy("<f2", [hours, series.len()], &data);
        bemcal_durable::write_atomic(&path, &bytes).map_err(io_err(&path))?;
        append_line(&self.dir.join("index.jsonl"), &f)?;
        self.finished.insert(f.key);
        Ok(())
    }

    /// Records a failed case.
    pub fn fail(&mut self, f: Failed) -> Result<(), Error> {
        append_line(&self.dir.join("failures.jsonl"), &f)?;
        self.failed.insert(f.key);
        Ok(())
    }
}

/// Reads a JSON-lines file (missing: empty). A torn last line (a stop mid-write) is ignored;
/// a bad line elsewhere is an error naming it.
pub fn read_lines<T: serde::de::DeserializeOwned>(path: &Path) -> Result<Vec<T>, Error> {
    let text = match std::fs::read_to_string(path) {
        Ok(t) => t,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(vec![]),
        Err(e) => return Err(io_err(path)(e)),
    };
    let lines: Vec<&str> = text.lines().filter(|l| !l.trim().is_empty()).collect();
    let mut out = Vec::with_capacity(lines.len());
    for (i, line) in lines.iter().enumerate() {
        match serde_json::from_str(line) {
            Ok(v) => out.push(v),
            Err(_) if i + 1 == lines.len() && !text.ends_with('\n') => {}
            Err(e) => {
                return Err(Error::Io {
                    path: path.to_path_buf(),
                    message: format!(
                        "line {}: {e} (in `{}`)",
                        i + 1,
                        bemcal_excerpt::excerpt(line, 80)
                    ),
                })
            }
        }
    }
    Ok(out)
}

fn append_line<T: Serialize>(path: &Path, value: &T) -> Result<(), Error> {
    let mut line = serde_json::to_vec(value).expect("serialises");
    line.push(b'\n');
    let mut file = std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(path)
        .map_err(io_err(path))?;
    file.write_all(&line).map_err(io_err(path))?;
    file.sync_data().map_err(io_err(path))
}

/// A NumPy `.npy` file (format 1.0, C order) of `descr` elements in `shape`.
fn npy(descr: &str, shape: [usize; 2], data: &[u8]) -> Vec<u8> {
    let mut header = format!(
        "{{'descr': '{descr}', 'fortran_order': False, 'shape': ({}, {}), }}",
        shape[0], shape[1]
    );
    // Magic (6) + version (2) + length (2) + header + '\n', padded to a multiple of 64.
    let unpadded = 10 + header.len() + 1;
    header.push_str(&" ".repeat((64 - unpadded % 64) % 64));
    header.push('\n');
    let mut out = b"\x93NUMPY\x01\x00".to_vec();
    out.extend_from_slice(&(header.len() as u16).to_le_bytes());
    out.extend_from_slice(header.as_bytes());
    out.extend_from_slice(data);
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn npy_header_is_aligned() {
        let b = npy("<f2", [3, 2], &[0; 12]);
        assert_eq!(&b[..6], b"\x93NUMPY");
        let len = u16::from_le_bytes([b[8], b[9]]) as usize;
        assert_eq!((10 + len) % 64, 0);
        assert_eq!(b.len(), 10 + len + 12);
        assert!(std::str::from_utf8(&b[10..10 + len])
            .unwrap()
            .contains("(3, 2)"));
    }

    #[test]
    fn torn_last_line_is_ignored_and_a_bad_line_named() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("x.jsonl");
        std::fs::write(&p, "{\"a\":1}\n{\"a\":").unwrap();
        let v: Vec<serde_json::Value> = read_lines(&p).unwrap();
        assert_eq!(v.len(), 1);
        std::fs::write(&p, "{\"a\":1}\nnot json\n{\"a\":2}\n").unwrap();
        let e = read_lines::<serde_json::Value>(&p).unwrap_err().to_string();
        assert!(e.contains("line 2"), "{e}");
    }
}

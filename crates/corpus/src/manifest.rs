//! What a corpus draws: the building-spec space, the climates and the parameters' population
//! priors, with the seed that makes it reproducible.

use std::path::{Path, PathBuf};

use bemcal_energyplus::building::{HeatingSource, HvacSystem, Zoning};
use bemcal_weather::Holidays;
use serde::{Deserialize, Serialize};

use crate::Error;

/// A corpus manifest (TOML).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Manifest {
    /// The corpus's name.
    pub name: String,
    /// Seed of every draw.
    pub seed: u64,
    /// Cases (building-years) to draw; a corpus of fewer is the first of these.
    pub cases: usize,
    /// Parameter points simulated per drawn building (and climate): 1 for a family corpus,
    /// more for the buildings a learning curve fine-tunes on.
    #[serde(default = "one")]
    pub points_per_building: usize,
    /// The calendar year simulated (its weekdays; TMY weather has no year of its own).
    #[serde(default = "default_year")]
    pub year: i32,
    /// Holidays, on the weekend schedule.
    #[serde(default)]
    pub holidays: Holidays,
    /// EnergyPlus time steps per hour of every case.
    #[serde(default = "default_timesteps")]
    pub timesteps_per_hour: u32,
    /// Each parameter's population prior: uniform over its default prior's support widened by
    /// this share of its range on each side (clamped to physical bounds, [`crate::draw`]).
    #[serde(default = "default_widen")]
    pub widen: f64,
    /// The building-spec space.
    pub spec: SpecSpace,
    /// The climates, each a weather file.
    pub climates: Vec<Climate>,
}

/// Ranges and choices of the building spec. A range `[a, b]` is drawn uniformly (integers
/// inclusive).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SpecSpace {
    /// Storeys above ground.
    pub storeys: [u32; 2],
    /// Footprint length (east-west), m.
    pub length_m: [f64; 2],
    /// Length over width of the footprint.
    pub aspect: [f64; 2],
    /// Floor-to-floor height, m.
    pub floor_to_floor_m: [f64; 2],
    /// Window-to-wall ratio.
    pub window_to_wall: [f64; 2],
    /// Zonings drawn from.
    pub zoning: Vec<Zoning>,
    /// Heating sources drawn from.
    pub heating_source: Vec<HeatingSource>,
    /// HVAC systems drawn from.
    pub hvac: Vec<HvacSystem>,
    /// Start hour of the occupied period on weekdays.
    pub occupied_start: [u32; 2],
    /// End hour of the occupied period.
    pub occupied_end: [u32; 2],
    /// Chance that each interior boundary of the default schedule intervals is dropped (so
    /// that cases have 12 weekday intervals or fewer, as pre-calibration's merged intervals).
    #[serde(default)]
    pub merge_boundaries: f64,
}

/// A climate of the corpus.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Climate {
    /// Short name (a file name: letters, digits, `-`, `_`).
    pub name: String,
    /// The weather file: a path relative to the manifest, or `bundled:FILE` (EnergyPlus's
    /// WeatherData, resolved by the caller).
    pub weather: String,
}

fn one() -> usize {
    1
}
fn default_year() -> i32 {
    2021
}
fn default_timesteps() -> u32 {
    4
}
fn default_widen() -> f64 {
    0.25
}

impl Manifest {
    /// Reads and checks a manifest file.
    pub fn load(path: &Path) -> Result<Manifest, Error> {
        let text = std::fs::read_to_string(path).map_err(crate::io_err(path))?;
        Manifest::parse(&text, path)
    }

    /// Parses and checks a manifest's text (`path` names it in errors).
    pub fn parse(text: &str, path: &Path) -> Result<Manifest, Error> {
        let m: Manifest = bemcal_energyplus::parse_toml(text, path).map_err(|e| match e {
            bemcal_energyplus::Error::Input {
                path,
                line,
                message,
            } => Error::Manifest {
                path,
                line,
                message,
            },
            other => Error::EnergyPlus(other),
        })?;
        m.check().map_err(|(key, message)| Error::Manifest {
            path: path.to_path_buf(),
            line: bemcal_energyplus::toml_line(text, &key),
            message,
        })?;
        Ok(m)
    }

    /// The content hash of the manifest (what the corpus folder records beside its cases).
    pub fn fingerprint(&self) -> String {
        use sha2::Digest;
        let json = serde_json::to_vec(self).expect("a manifest serialises");
        hex::encode(&sha2::Sha256::digest(json)[..8])
    }

    /// The climate's weather file, `bundled:` references left to `bundled` (the caller knows
    /// where EnergyPlus keeps its weather), others relative to the manifest's folder.
    pub fn weather_path(
        &self,
        climate: &Climate,
        manifest: &Path,
        bundled: &dyn Fn(&str) -> Result<PathBuf, Error>,
    ) -> Result<PathBuf, Error> {
        match climate.weather.strip_prefix("bundled:") {
            Some(file) => bundled(file),
            None => Ok(manifest
                .parent()
                .unwrap_or(Path::new("."))
                .join(&climate.weather)),
        }
    }

    fn check(&self) -> Result<(), (Vec<&'static str>, String)> {
        let s = &self.spec;
        let range_f = |key: &'static str, r: [f64; 2], lo: f64, hi: f64| {
            if r[0].is_finite() && r[1].is_finite() && lo <= r[0] && r[0] <= r[1] && r[1] <= hi {
                Ok(())
            } else {
                Err((
                    vec!["spec", key],
                    format!("spec.{key} = {r:?}, expected [a, b] with {lo} <= a <= b <= {hi}"),
                ))
            }
        };
        let range_u = |key: &'static str, r: [u32; 2], lo: u32, hi: u32| {
            if lo <= r[0] && r[0] <= r[1] && r[1] <= hi {
                Ok(())
            } else {
                Err((
                    vec!["spec", key],
                    format!("spec.{key} = {r:?}, expected [a, b] with {lo} <= a <= b <= {hi}"),
                ))
            }
        };
        range_u("storeys", s.storeys, 1, 60)?;
        range_f("length_m", s.length_m, 3.0, 1000.0)?;
        range_f("aspect", s.aspect, 1.0, 20.0)?;
        range_f("floor_to_floor_m", s.floor_to_floor_m, 2.4, 10.0)?;
        range_f("window_to_wall", s.window_to_wall, 0.01, 0.9)?;
        range_u("occupied_start", s.occupied_start, 0, 23)?;
        range_u("occupied_end", s.occupied_end, 1, 24)?;
        if s.occupied_start[1] >= s.occupied_end[0] {
            return Err((
                vec!["spec", "occupied_end"],
                "spec.occupied_end must start after spec.occupied_start ends".into(),
            ));
        }
        if !(0.0..1.0).contains(&s.merge_boundaries) {
            return Err((
                vec!["spec", "merge_boundaries"],
                format!(
                    "spec.merge_boundaries = {}, expected 0..1",
                    s.merge_boundaries
                ),
            ));
        }
        for (key, empty) in [
            ("zoning", s.zoning.is_empty()),
            ("heating_source", s.heating_source.is_empty()),
            ("hvac", s.hvac.is_empty()),
        ] {
            if empty {
                return Err((
                    vec!["spec", key],
                    format!("spec.{key} is empty: name at least one"),
                ));
            }
        }
        if self.cases == 0 || self.points_per_building == 0 {
            return Err((
                vec!["cases"],
                "cases and points_per_building must be > 0".into(),
            ));
        }
        if !(0.0..=2.0).contains(&self.widen) {
            return Err((
                vec!["widen"],
                format!("widen = {}, expected 0..2", self.widen),
            ));
        }
        if self.climates.is_empty() {
            return Err((
                vec!["climates"],
                "no [[climates]]: name at least one".into(),
            ));
        }
        for c in &self.climates {
            let ok = !c.name.is_empty()
                && c.name
                    .chars()
                    .all(|ch| ch.is_ascii_alphanumeric() || ch == '-' || ch == '_');
            if !ok {
                return Err((
                    vec!["climates"],
                    format!(
                        "climate name {:?}: expected letters, digits, - or _",
                        c.name
                    ),
                ));
            }
        }
        Ok(())
    }
}

//! Submitted projects: the one path rule of a project that a coordinator or worker lays out
//! from a bundle. Every file it (or its model) names must be a regular file inside the bundle's
//! folder; a local run (`Project::load`) accepts any path the user's own shell can read.

use std::path::{Path, PathBuf};

use crate::error::Error;
use crate::project::Project;

const MIB: u64 = 1 << 20;

/// What a file of a submitted project is, which sets the most bytes it may hold
/// ([`SubmittedFile::max_bytes`]): a coordinator reads these whole, so each kind gets a cap
/// well above what a real input of its kind needs and far below the host's memory.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SubmittedFile {
    /// The model file (TOML).
    Model,
    /// A priors file (TOML).
    Priors,
    /// An EPW weather file (a year of hourly rows is about 1.6 MB; sub-hourly, a few times
    /// that).
    Weather,
    /// The meters' CSV (a year of 15-minute readings of 20 columns is about 8 MB; of
    /// 1-minute readings, about 120 MB).
    Meters,
    /// Measured weather: a CSV, or NOAA ISD-lite files.
    MeasuredWeather,
    /// A file the model names: its IDF, a holidays or a day-types file.
    ModelInput,
    /// A file of the pretrained surrogate's folder (`[surrogate] pretrained`): its card or
    /// its weights (the family's network: about 100 kB at 64 units, 400 kB at 128).
    Pretrained,
}

impl SubmittedFile {
    /// The most bytes a file of this kind may hold.
    pub fn max_bytes(self) -> u64 {
        match self {
            SubmittedFile::Model | SubmittedFile::Priors => 16 * MIB,
            SubmittedFile::Weather => 64 * MIB,
            SubmittedFile::Meters => 512 * MIB,
            SubmittedFile::MeasuredWeather | SubmittedFile::ModelInput => 256 * MIB,
            SubmittedFile::Pretrained => 64 * MIB,
        }
    }

    /// The kind in words, for errors.
    fn name(self) -> &'static str {
        match self {
            SubmittedFile::Model => "model file",
            SubmittedFile::Priors => "priors file",
            SubmittedFile::Weather => "weather file",
            SubmittedFile::Meters => "meters file",
            SubmittedFile::MeasuredWeather => "measured weather file",
            SubmittedFile::ModelInput => "model's input file",
            SubmittedFile::Pretrained => "pretrained surrogate's file",
        }
    }
}

/// Where a submitted project's file may be: `written`, relative to `dir`, names a regular
/// file inside `root` (both canonical or `dir` under `root`): a relative path without `..`,
/// not leaving `root` through a link, at most `kind`'s [`SubmittedFile::max_bytes`]. Returns
/// its real path. The one path rule of submitted projects (coordinator and workers).
pub fn file_inside(
    root: &Path,
    dir: &Path,
    written: &Path,
    kind: SubmittedFile,
) -> Result<PathBuf, String> {
    let shown = written.display().to_string();
    let shown = bemcal_excerpt::excerpt(&shown, 120);
    let plain = written
        .components()
        .all(|c| matches!(c, std::path::Component::Normal(_)));
    if !plain || written.as_os_str().is_empty() {
        return Err(format!(
            "'{shown}': a submitted project names its files by relative paths inside its \
             folder, without '..'"
        ));
    }
    let real = std::fs::canonicalize(dir.join(written)).map_err(|e| format!("'{shown}': {e}"))?;
    if !real.starts_with(root) {
        return Err(format!("'{shown}' leads outside the project's folder"));
    }
    let meta = std::fs::metadata(&real).map_err(|e| format!("'{shown}': {e}"))?;
    if !meta.is_file() {
        return Err(format!("'{shown}' is not a regular file"));
    }
    if meta.len() > kind.max_bytes() {
        return Err(format!(
            "'{shown}' is {} bytes, over the limit of {} MiB for a {} of a submitted project",
            meta.len(),
            kind.max_bytes() / MIB,
            kind.name()
        ));
    }
    Ok(real)
}

impl Project {
    /// Loads a project submitted to a coordinator, laid out from its bundle in `path`'s
    /// folder: as [`Project::load`], and every file the project and its model name must be a
    /// regular file inside that folder ([`file_inside`]), and `bundled:` weather a plain file
    /// name. A local run ([`Project::load`]) accepts any path the user's own shell can read.
    pub fn load_submitted(path: &Path) -> Result<Project, Error> {
        let p = Project::load(path)?;
        let refuse = |message: String| Error::Input {
            path: path.into(),
            line: 0,
            message,
        };
        let root = std::fs::canonicalize(&p.base)
            .map_err(|e| refuse(format!("the project's folder: {e}")))?;
        for (kind, f) in p.named_files() {
            file_inside(&root, &p.base, f, kind).map_err(&refuse)?;
        }
        // A bundled network (`bundled:NAME`) is in the worker's binary: nothing to check.
        let folder = p
            .surrogate
            .pretrained
            .as_ref()
            .filter(|d| bemcal_surrogate::pretrained::bundled_name(d).is_none());
        if let Some(dir) = folder {
            for f in bemcal_surrogate::pretrained::FILES {
                file_inside(&root, &p.base, &dir.join(f), SubmittedFile::Pretrained)
                    .map_err(&refuse)?;
            }
        }
        let model = file_inside(&root, &p.base, &p.model, SubmittedFile::Model).map_err(&refuse)?;
        let text = std::fs::read_to_string(&model).map_err(|e| refuse(format!("model: {e}")))?;
        let dir = model.parent().unwrap_or(&root);
        for f in bemcal_energyplus::Model::named_files(&text, &p.model)? {
            file_inside(&root, dir, &f, SubmittedFile::ModelInput)
                .map_err(|e| refuse(format!("in the model: {e}")))?;
        }
        Ok(p)
    }

    /// Every input file the project names, as written (relative to its folder), with its
    /// kind: the model, the priors, the weather unless `bundled:`, the meters (and their bills) and the measured
    /// weather. The model's own files are [`bemcal_energyplus::Model::named_files`].
    pub fn named_files(&self) -> Vec<(SubmittedFile, &Path)> {
        use SubmittedFile::*;
        let mut files = vec![(Model, self.model.as_path())];
        files.extend(self.priors.as_deref().map(|f| (Priors, f)));
        if !self.weather.starts_with("bundled:") {
            files.push((Weather, Path::new(&self.weather)));
        }
        files.extend(self.meters.file.as_deref().map(|f| (Meters, f)));
        files.extend(self.meters.bills.iter().map(|b| (Meters, b.file.as_path())));
        if let Some(m) = &self.measured_weather {
            files.extend(m.csv.as_deref().map(|f| (MeasuredWeather, f)));
            files.extend(m.isd_lite.iter().map(|f| (MeasuredWeather, f.as_path())));
        }
        files
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_kind_of_file_has_its_own_cap() {
        let dir = tempfile::tempdir().unwrap();
        let root = std::fs::canonicalize(dir.path()).unwrap();
        // A sparse 20 MiB file: over a model file's 16 MiB, under a meters file's 512 MiB.
        let f = std::fs::File::create(root.join("big.csv")).unwrap();
        f.set_len(20 * MIB).unwrap();
        let big = Path::new("big.csv");
        let e = file_inside(&root, &root, big, SubmittedFile::Model).unwrap_err();
        assert!(
            e.contains("over the limit of 16 MiB for a model file"),
            "{e}"
        );
        assert!(e.len() < 200, "{e}");
        assert_eq!(
            file_inside(&root, &root, big, SubmittedFile::Meters).unwrap(),
            root.join("big.csv")
        );
        assert!(file_inside(&root, &root, big, SubmittedFile::Weather).is_ok());
        f.set_len(65 * MIB).unwrap();
        let e = file_inside(&root, &root, big, SubmittedFile::Weather).unwrap_err();
        assert!(e.contains("64 MiB for a weather file"), "{e}");
        // Every kind's cap stays far below the 1 GiB an artifact may hold.
        for k in [
            SubmittedFile::Model,
            SubmittedFile::Priors,
            SubmittedFile::Weather,
            SubmittedFile::Meters,
            SubmittedFile::MeasuredWeather,
            SubmittedFile::ModelInput,
        ] {
            assert!(k.max_bytes() <= 512 * MIB);
        }
    }
}

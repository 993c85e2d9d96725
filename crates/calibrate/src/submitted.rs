//! Submitted projects: the one path rule of a project that a coordinator or worker lays out
//! from a bundle. Every file it (or its model) names must be a regular file inside the bundle's
//! folder; a local run (`Project::load`) accepts any path the user's own shell can read.

use std::path::{Path, PathBuf};

use crate::project::Project;
use crate::Error;

/// Largest input file a submitted project may name (bytes; an artifact is at most as large).
pub const MAX_SUBMITTED_FILE_BYTES: u64 = 1 << 30;

/// Where a submitted project's file may be: `written`, relative to `dir`, names a regular
/// file inside `root` (both canonical or `dir` under `root`): a relative path without `..`,
/// not leaving `root` through a link, at most [`MAX_SUBMITTED_FILE_BYTES`]. Returns its
/// real path. The one path rule of submitted projects (coordinator and workers).
pub fn file_inside(root: &Path, dir: &Path, written: &Path) -> Result<PathBuf, String> {
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
    if meta.len() > MAX_SUBMITTED_FILE_BYTES {
        return Err(format!(
            "'{shown}' is {} bytes, over the limit of {MAX_SUBMITTED_FILE_BYTES}",
            meta.len()
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
        for f in p.named_files() {
            file_inside(&root, &p.base, f).map_err(&refuse)?;
        }
        let model = file_inside(&root, &p.base, &p.model).map_err(&refuse)?;
        let text = std::fs::read_to_string(&model).map_err(|e| refuse(format!("model: {e}")))?;
        let dir = model.parent().unwrap_or(&root);
        for f in bemcal_energyplus::Model::named_files(&text, &p.model)? {
            file_inside(&root, dir, &f).map_err(|e| refuse(format!("in the model: {e}")))?;
        }
        Ok(p)
    }

    /// Every input file the project names, as written (relative to its folder): the model,
    /// the priors, the weather unless `bundled:`, the meters and the measured weather. The
    /// model's own files are [`bemcal_energyplus::Model::named_files`].
    pub fn named_files(&self) -> Vec<&Path> {
        let mut files = vec![self.model.as_path()];
        files.extend(self.priors.as_deref());
        if !self.weather.starts_with("bundled:") {
            files.push(Path::new(&self.weather));
        }
        files.extend(self.meters.file.as_deref());
        if let Some(m) = &self.measured_weather {
            files.extend(m.csv.as_deref());
            files.extend(m.isd_lite.iter().map(PathBuf::as_path));
        }
        files
    }
}

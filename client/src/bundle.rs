//! Project bundles: the files a calibration needs (project file, model, IDF, priors, meters,
//! weather unless bundled with EnergyPlus), under relative paths, so a coordinator or worker can
//! lay them out in a folder of its own and load the project from there.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use crate::artifacts::{safe_relative, ArtifactDir};
use crate::File;

/// Name of the project file in a bundle.
pub const PROJECT_FILE: &str = "project.toml";

/// What a bundle may hold. A project's files are sent to a coordinator that others share, so
/// only regular files travel; a file outside the project's folder (a symlink in the folder
/// that points out of it included) only where the user says so; a file of the system's
/// special folders (`/proc`, `/sys`, `/dev`) never.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Policy {
    /// Files outside the project's folder may travel (`--allow-outside`).
    pub allow_outside: bool,
}

/// Folders whose files are never bundled, whatever the policy: their "regular" files are the
/// kernel's views of processes and devices (`/proc/self/environ` holds a process's secrets).
pub const NEVER_BUNDLED: [&str; 3] = ["/proc", "/sys", "/dev"];

/// Collects a project's files: `(relative path in the bundle, bytes)`, project file first. Paths
/// that leave the project's folder are renamed under `files/` and the project file is rewritten
/// to point at them. Each file is checked against `policy` first.
pub fn collect(project_file: &Path, policy: Policy) -> anyhow::Result<Vec<(String, Vec<u8>)>> {
    let text = std::fs::read_to_string(project_file)
        .map_err(|e| anyhow::anyhow!("cannot read {}: {e}", project_file.display()))?;
    let mut doc: toml::Table = toml::from_str(&text)
        .map_err(|e| anyhow::anyhow!("{}: {}", project_file.display(), e.message()))?;
    let mut files = Collector {
        project_file,
        base: match project_file.parent() {
            Some(p) if !p.as_os_str().is_empty() => p,
            _ => Path::new("."),
        },
        files: BTreeMap::new(),
        policy,
    };
    let str_at = |t: &toml::Table, k: &str| t.get(k).and_then(|v| v.as_str()).map(str::to_string);
    let model = str_at(&doc, "model")
        .ok_or_else(|| anyhow::anyhow!("{}: missing model = \"...\"", project_file.display()))?;
    let model_name = files.place(&model)?;
    if let Some(p) = str_at(&doc, "priors") {
        let n = files.place(&p)?;
        doc.insert("priors".into(), n.into());
    }
    if let Some(w) = str_at(&doc, "weather") {
        if !w.starts_with("bundled:") {
            let n = files.place(&w)?;
            doc.insert("weather".into(), n.into());
        }
    }
    if let Some(mw) = doc
        .get_mut("measured_weather")
        .and_then(|v| v.as_table_mut())
    {
        if let Some(f) = str_at(mw, "csv") {
            let n = files.place(&f)?;
            mw.insert("csv".into(), n.into());
        }
        if let Some(list) = mw.get_mut("isd_lite").and_then(|v| v.as_array_mut()) {
            for item in list.iter_mut() {
                if let Some(f) = item.as_str().map(str::to_string) {
                    *item = files.place(&f)?.into();
                }
            }
        }
    }
    if let Some(m) = doc.get_mut("meters").and_then(|v| v.as_table_mut()) {
        if let Some(f) = str_at(m, "file") {
            let n = files.place(&f)?;
            m.insert("file".into(), n.into());
        }
        // `[[meters.bills]]`: each bills file travels too.
        if let Some(list) = m.get_mut("bills").and_then(|v| v.as_array_mut()) {
            for b in list.iter_mut().filter_map(|b| b.as_table_mut()) {
                if let Some(f) = str_at(b, "file") {
                    let n = files.place(&f)?;
                    b.insert("file".into(), n.into());
                }
            }
        }
    }
    if let Some(sur) = doc.get_mut("surrogate").and_then(|v| v.as_table_mut()) {
        // A bundled network (`bundled:NAME`) is in the worker's binary, as bundled weather is.
        if let Some(f) = str_at(sur, "pretrained").filter(|f| !f.starts_with("bundled:")) {
            let n = files.place_folder(&f, &PRETRAINED_FILES, &PRETRAINED_OPTIONAL)?;
            sur.insert("pretrained".into(), n.into());
        }
    }
    doc.insert("model".into(), model_name.clone().into());
    files.beside_model(&model_name)?;
    let mut out = vec![(
        PROJECT_FILE.to_string(),
        toml::to_string(&doc)?.into_bytes(),
    )];
    for (name, src) in files.files {
        if name == PROJECT_FILE {
            anyhow::bail!("a project input may not be named {PROJECT_FILE}");
        }
        let bytes = std::fs::read(&src)
            .map_err(|e| anyhow::anyhow!("cannot read {}: {e}", src.display()))?;
        out.push((name, bytes));
    }
    Ok(out)
}

/// The files of a pretrained surrogate's folder (`[surrogate] pretrained`) that travel: those
/// of `bemcal_surrogate::pretrained::FILES` (the client does not depend on it; a test in the
/// CLI holds the two lists equal).
pub const PRETRAINED_FILES: [&str; 2] = ["card.json", "weights.pt"];

/// The files of a pretrained surrogate's folder that travel where present: its family record
/// (`bemcal_surrogate::pretrained::FAMILY_FILE`).
pub const PRETRAINED_OPTIONAL: [&str; 1] = ["family.json"];

/// The files of a bundle being collected: each one's name in the bundle and where it is read.
struct Collector<'a> {
    project_file: &'a Path,
    /// The project file's folder: relative paths in it start there.
    base: &'a Path,
    files: BTreeMap<String, PathBuf>,
    policy: Policy,
}

impl Collector<'_> {
    /// Adds the file a project names as `p` and returns its name in the bundle: `p` itself
    /// when it is a safe relative path, else `files/N-<file name>`.
    fn place(&mut self, p: &str) -> anyhow::Result<String> {
        let src = if Path::new(p).is_absolute() {
            PathBuf::from(p)
        } else {
            self.base.join(p)
        };
        let name = match safe_relative(p) {
            Ok(_) => p.to_string(),
            Err(_) => format!("files/{}-{}", self.files.len(), bundle_stem(&src)),
        };
        self.check(p, &src)?;
        self.files.insert(name.clone(), src);
        Ok(name)
    }

    /// Adds `files` of the folder a project names as `p` and returns the folder's name in the
    /// bundle: `p` itself when it is a safe relative path, else `files/N-<folder name>`.
    fn place_folder(
        &mut self,
        p: &str,
        files: &[&str],
        optional: &[&str],
    ) -> anyhow::Result<String> {
        let src = if Path::new(p).is_absolute() {
            PathBuf::from(p)
        } else {
            self.base.join(p)
        };
        let name = match safe_relative(p) {
            Ok(_) => p.trim_end_matches('/').to_string(),
            Err(_) => format!("files/{}-{}", self.files.len(), bundle_stem(&src)),
        };
        let present = optional.iter().filter(|f| src.join(f).exists());
        for f in files.iter().chain(present) {
            self.check(&format!("{p}/{f}"), &src.join(f))?;
            self.files.insert(format!("{name}/{f}"), src.join(f));
        }
        Ok(name)
    }

    /// Refuses what `policy` does not let travel: a missing or non-regular file, a special
    /// file of the system, a file outside the project's folder without `allow_outside`.
    fn check(&self, named: &str, src: &Path) -> anyhow::Result<()> {
        let at = self.project_file.display();
        let meta = std::fs::metadata(src)
            .map_err(|_| anyhow::anyhow!("{at}: file {} not found", src.display()))?;
        let real = src.canonicalize()?;
        if NEVER_BUNDLED.iter().any(|d| real.starts_with(d)) {
            anyhow::bail!(
                "{at}: '{named}' is {}, a special file of the system: never sent to a coordinator",
                real.display()
            );
        }
        if !meta.is_file() {
            anyhow::bail!(
                "{at}: '{named}' is not a regular file (a folder, socket, FIFO or device): only regular files are sent"
            );
        }
        let folder = self.base.canonicalize()?;
        if !real.starts_with(&folder) && !self.policy.allow_outside {
            anyhow::bail!(
                "{at}: '{named}' is outside the project's folder ({}{}): copy it into {}, or send it with --allow-outside",
                real.display(),
                if src.canonicalize().ok().as_deref() != Some(src) && src.is_symlink() { ", through a link" } else { "" },
                folder.display()
            );
        }
        Ok(())
    }

    /// Adds the files a model file names relative to itself (an `[idf]` table's `path`, a
    /// calendar's `holidays_file` and `day_types_file`), beside the model in the bundle.
    fn beside_model(&mut self, model_name: &str) -> anyhow::Result<()> {
        let model_src = self.files[model_name].clone();
        let model_text = std::fs::read_to_string(&model_src)
            .map_err(|e| anyhow::anyhow!("cannot read {}: {e}", model_src.display()))?;
        let Ok(mt) = toml::from_str::<toml::Table>(&model_text) else {
            return Ok(());
        };
        let beside_model = ["holidays_file", "day_types_file"]
            .iter()
            .filter_map(|k| mt.get(*k).and_then(|v| v.as_str()));
        let idf_path = mt
            .get("idf")
            .and_then(|v| v.as_table())
            .and_then(|t| t.get("path"))
            .and_then(|v| v.as_str());
        for idf in idf_path.into_iter().chain(beside_model) {
            let dir = Path::new(model_name).parent().unwrap_or(Path::new(""));
            let rel = dir.join(idf).to_string_lossy().replace('\\', "/");
            safe_relative(&rel).map_err(|e| {
                anyhow::anyhow!(
                    "{}: '{idf}': {e} (keep the model's files beside it)",
                    model_src.display()
                )
            })?;
            let src = model_src.parent().unwrap_or(Path::new(".")).join(idf);
            self.check(idf, &src)?;
            self.files.insert(rel, src);
        }
        Ok(())
    }
}

/// A file's name made safe for a bundle: characters other than ASCII letters, digits and
/// `._-` become `_`.
fn bundle_stem(src: &Path) -> String {
    src.file_name()
        .map(|s| s.to_string_lossy().to_string())
        .unwrap_or_else(|| "file".into())
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || "._-".contains(c) {
                c
            } else {
                '_'
            }
        })
        .collect()
}

/// Lays out `files` (from `store`) under `dir`, checking every path; returns the project file.
/// The layout is written durably in a sibling folder and renamed into place: `dir` holds
/// either a whole bundle or nothing (a crash mid-layout leaves only the sibling, redone on
/// the next call).
pub fn materialize(files: &[File], store: &ArtifactDir, dir: &Path) -> Result<PathBuf, String> {
    if !files.iter().any(|f| f.path == PROJECT_FILE) {
        return Err(format!("the bundle has no {PROJECT_FILE}"));
    }
    let io = |p: &Path, e: std::io::Error| format!("{}: {e}", p.display());
    // A name of this call's own: two callers (worker slots) may lay out one bundle at once.
    let partial = bemcal_durable::temporary_beside(dir);
    for f in files {
        let rel = safe_relative(&f.path)?;
        let bytes = store
            .read(&f.sha256)
            .map_err(|e| format!("artifact {} ({}) is missing: {e}", f.sha256, f.path))?;
        let p = partial.join(rel);
        bemcal_durable::write_atomic(&p, &bytes).map_err(|e| io(&p, e))?;
    }
    if dir.join(PROJECT_FILE).is_file() {
        // Laid out meanwhile by another caller.
        let _ = std::fs::remove_dir_all(&partial);
        return Ok(dir.join(PROJECT_FILE));
    }
    if dir.exists() {
        // An earlier layout without its project file (written before layouts were atomic).
        std::fs::remove_dir_all(dir).map_err(|e| io(dir, e))?;
    }
    if let Err(e) = std::fs::rename(&partial, dir) {
        let _ = std::fs::remove_dir_all(&partial);
        if !dir.join(PROJECT_FILE).is_file() {
            return Err(io(dir, e));
        }
    }
    // The rename itself is durable once the parent folder is synced.
    bemcal_durable::sync_folder(dir.parent());
    Ok(dir.join(PROJECT_FILE))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bills_files_travel_with_the_project() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        std::fs::write(d.join("model.toml"), "storeys = 1\n").unwrap();
        std::fs::write(d.join("gas.csv"), "start,end,quantity\n").unwrap();
        std::fs::write(
            d.join("p.toml"),
            "model = \"model.toml\"\n[[meters.bills]]\nfile = \"gas.csv\"\nrole = \"heating\"\n",
        )
        .unwrap();
        let files = collect(
            &d.join("p.toml"),
            Policy {
                allow_outside: false,
            },
        )
        .unwrap();
        let (name, bytes) = files.iter().find(|(n, _)| n.ends_with("gas.csv")).unwrap();
        assert_eq!(bytes, b"start,end,quantity\n");
        let project = String::from_utf8(files[0].1.clone()).unwrap();
        assert!(project.contains(&format!("file = \"{name}\"")), "{project}");
    }

    #[test]
    fn measured_weather_and_calendar_files_travel_with_the_project() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        let outside = tempfile::tempdir().unwrap();
        let isd = outside.path().join("726580-14922-2017.gz");
        for (name, text) in [
            (
                "model.toml",
                "storeys = 1\nday_types_file = \"calendar.csv\"\n",
            ),
            ("calendar.csv", "date,label\n"),
            ("meters.csv", "timestamp,e\n"),
            ("tmy.epw", "LOCATION\n"),
        ] {
            std::fs::write(d.join(name), text).unwrap();
        }
        std::fs::write(&isd, b"isd").unwrap();
        std::fs::write(
            d.join("p.toml"),
            format!(
                "model = \"model.toml\"\nweather = \"tmy.epw\"\n\
                 [measured_weather]\nisd_lite = [\"{}\"]\n[meters]\nfile = \"meters.csv\"\n",
                isd.display()
            ),
        )
        .unwrap();
        let files = collect(
            &d.join("p.toml"),
            Policy {
                allow_outside: true,
            },
        )
        .unwrap();
        let names: Vec<&str> = files.iter().map(|(n, _)| n.as_str()).collect();
        let renamed = names
            .iter()
            .find(|n| n.ends_with("726580-14922-2017.gz"))
            .expect("ISD-lite file bundled");
        let project = String::from_utf8(files[0].1.clone()).unwrap();
        assert!(project.contains(renamed), "{project}");
        assert_eq!(files.iter().find(|(n, _)| n == renamed).unwrap().1, b"isd");
        // The building spec's day-type calendar travels beside it.
        assert!(names.contains(&"calendar.csv"), "{names:?}");
    }

    fn project_naming(d: &Path, meters: &str) -> PathBuf {
        std::fs::write(d.join("model.toml"), "storeys = 1\n").unwrap();
        let p = d.join("p.toml");
        std::fs::write(
            &p,
            format!("model = \"model.toml\"\n[meters]\nfile = \"{meters}\"\n"),
        )
        .unwrap();
        p
    }

    #[test]
    fn a_pretrained_surrogate_travels_as_its_files() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path().join("project");
        std::fs::create_dir_all(d.join("pre")).unwrap();
        let outside = dir.path().join("family");
        std::fs::create_dir_all(&outside).unwrap();
        for f in PRETRAINED_FILES {
            std::fs::write(d.join("pre").join(f), f).unwrap();
            std::fs::write(outside.join(f), f).unwrap();
        }
        std::fs::write(d.join("model.toml"), "").unwrap();
        let project = |pre: &str| {
            let p = d.join("project.toml");
            std::fs::write(
                &p,
                format!("model = \"model.toml\"\n[surrogate]\npretrained = \"{pre}\"\n"),
            )
            .unwrap();
            p
        };
        let names = |b: &[(String, Vec<u8>)]| b.iter().map(|(n, _)| n.clone()).collect::<Vec<_>>();
        let inside = collect(&project("pre"), Policy::default()).unwrap();
        assert_eq!(
            names(&inside),
            [
                "project.toml",
                "model.toml",
                "pre/card.json",
                "pre/weights.pt"
            ]
        );
        // The family record travels with them where the folder has one.
        std::fs::write(d.join("pre").join(PRETRAINED_OPTIONAL[0]), "{}").unwrap();
        let with_family = collect(&project("pre"), Policy::default()).unwrap();
        assert_eq!(
            names(&with_family)[2..],
            ["pre/card.json", "pre/family.json", "pre/weights.pt"]
        );
        // Outside the folder: refused without the option, renamed into files/ with it.
        let e = collect(&project("../family"), Policy::default())
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("'../family/card.json' is outside the project's folder"),
            "{e}"
        );
        let allowed = Policy {
            allow_outside: true,
        };
        let b = collect(&project("../family"), allowed).unwrap();
        assert_eq!(
            names(&b)[1..3],
            ["files/1-family/card.json", "files/1-family/weights.pt"]
        );
        let text = String::from_utf8(b[0].1.clone()).unwrap();
        assert!(text.contains("pretrained = \"files/1-family\""), "{text}");
        // A network the binary ships travels as its name, as bundled weather does.
        let b = collect(&project("bundled:conditioned-200"), Policy::default()).unwrap();
        assert_eq!(names(&b), ["project.toml", "model.toml"]);
        let text = String::from_utf8(b[0].1.clone()).unwrap();
        assert!(
            text.contains("pretrained = \"bundled:conditioned-200\""),
            "{text}"
        );
    }

    #[test]
    fn files_outside_the_folder_travel_only_when_allowed() {
        let dir = tempfile::tempdir().unwrap();
        let outside = tempfile::tempdir().unwrap();
        let meters = outside.path().join("meters.csv");
        std::fs::write(&meters, "timestamp,e\n").unwrap();
        let p = project_naming(dir.path(), &meters.display().to_string());
        let e = collect(&p, Policy::default()).unwrap_err().to_string();
        assert!(
            e.contains("outside the project's folder") && e.contains("--allow-outside"),
            "{e}"
        );
        let allowed = Policy {
            allow_outside: true,
        };
        assert_eq!(collect(&p, allowed).unwrap().len(), 3);
        // A link inside the folder that points out of it follows the same rule.
        std::os::unix::fs::symlink(&meters, dir.path().join("linked.csv")).unwrap();
        let p = project_naming(dir.path(), "linked.csv");
        let e = collect(&p, Policy::default()).unwrap_err().to_string();
        assert!(e.contains("through a link"), "{e}");
        assert_eq!(collect(&p, allowed).unwrap().len(), 3);
    }

    #[test]
    fn special_files_never_travel() {
        let dir = tempfile::tempdir().unwrap();
        let allowed = Policy {
            allow_outside: true,
        };
        for special in ["/proc/self/environ", "/dev/null"] {
            let p = project_naming(dir.path(), special);
            let e = collect(&p, allowed).unwrap_err().to_string();
            assert!(e.contains("special file of the system"), "{special}: {e}");
            assert!(!e.contains("BEMCAL"), "{e}");
        }
        let fifo = dir.path().join("fifo.csv");
        let c = std::ffi::CString::new(fifo.to_str().unwrap()).unwrap();
        // SAFETY: a plain system call on a valid C string.
        assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o600) }, 0);
        let p = project_naming(dir.path(), "fifo.csv");
        let e = collect(&p, allowed).unwrap_err().to_string();
        assert!(e.contains("not a regular file"), "{e}");
    }
}

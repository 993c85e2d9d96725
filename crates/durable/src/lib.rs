//! Durable, atomic file writes, the one way bemcal writes a result file that others read
//! (checkpoints, design points, priors, training sets, downloaded results, bundles' files).
//!
//! [`write_atomic`] (or [`AtomicFile`], for a file written in pieces) writes a temporary file
//! beside the target, syncs it to disk, renames it over the target and syncs the folder: a reader (or a rerun after a crash or `kill -9`) sees
//! either the old file or the whole new one, never a part.

#![deny(missing_docs)]

use std::io::Write;
use std::path::{Path, PathBuf};

/// Writes `bytes` to `path` atomically and durably, creating its folder if needed.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    let mut file = AtomicFile::create(path)?;
    file.write_all(bytes)?;
    file.commit()
}

/// A file written in pieces (an upload as it arrives) and put in place whole by
/// [`AtomicFile::commit`]: synced, renamed over its target, the folder synced. Dropped before
/// that, it leaves nothing behind.
pub struct AtomicFile {
    file: std::fs::File,
    tmp: PathBuf,
    path: PathBuf,
}

impl AtomicFile {
    /// Starts the file that will be `path`, creating its folder if needed.
    pub fn create(path: &Path) -> std::io::Result<AtomicFile> {
        if let Some(parent) = path.parent().filter(|p| !p.as_os_str().is_empty()) {
            std::fs::create_dir_all(parent)?;
        }
        let tmp = temporary_beside(path);
        Ok(AtomicFile {
            file: std::fs::File::create(&tmp)?,
            tmp,
            path: path.into(),
        })
    }

    /// Puts the file in place: its bytes reach the disk before its name does.
    pub fn commit(self) -> std::io::Result<()> {
        self.file.sync_all()?;
        std::fs::rename(&self.tmp, &self.path)?;
        sync_folder(self.path.parent());
        Ok(())
    }
}

impl Write for AtomicFile {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.file.write(buf)
    }

    fn flush(&mut self) -> std::io::Result<()> {
        self.file.flush()
    }
}

impl Drop for AtomicFile {
    fn drop(&mut self) {
        // After `commit` the temporary name is gone and this does nothing.
        let _ = std::fs::remove_file(&self.tmp);
    }
}

/// Syncs a folder so that a rename into it survives a crash (best effort: some file systems
/// cannot open folders for syncing).
pub fn sync_folder(folder: Option<&Path>) {
    let folder = match folder {
        Some(f) if !f.as_os_str().is_empty() => f,
        _ => Path::new("."),
    };
    if let Ok(d) = std::fs::File::open(folder) {
        let _ = d.sync_all();
    }
}

/// A temporary name beside `path` (a hidden `.NAME.PID-N.partial`), of this process and call:
/// two writers, threads or processes, never share one. Also for a folder laid out whole and
/// then renamed into place.
pub fn temporary_beside(path: &Path) -> PathBuf {
    static CALLS: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
    let n = CALLS.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().to_string())
        .unwrap_or_default();
    path.with_file_name(format!(".{name}.{}-{n}.partial", std::process::id()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_write_replaces_the_file_whole_and_leaves_no_temporary() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("sub").join("priors.toml");
        write_atomic(&p, b"old").unwrap();
        write_atomic(&p, b"new contents").unwrap();
        assert_eq!(std::fs::read(&p).unwrap(), b"new contents");
        let names: Vec<_> = std::fs::read_dir(p.parent().unwrap())
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert_eq!(names, vec![std::ffi::OsString::from("priors.toml")]);
    }

    #[test]
    fn a_file_in_pieces_appears_whole_on_commit_and_not_at_all_when_dropped() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("artifact");
        let mut f = AtomicFile::create(&p).unwrap();
        f.write_all(b"first ").unwrap();
        assert!(!p.exists());
        f.write_all(b"second").unwrap();
        f.commit().unwrap();
        assert_eq!(std::fs::read(&p).unwrap(), b"first second");
        let mut f = AtomicFile::create(&dir.path().join("dropped")).unwrap();
        f.write_all(b"half").unwrap();
        drop(f);
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
    }

    #[test]
    fn a_failed_write_leaves_the_old_file() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("f");
        write_atomic(&p, b"old").unwrap();
        // A folder where the file should go: the rename fails, the temporary is removed.
        let q = dir.path().join("d");
        std::fs::create_dir_all(q.join("x")).unwrap();
        assert!(write_atomic(&q, b"new").is_err());
        assert_eq!(std::fs::read(&p).unwrap(), b"old");
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 2);
    }
}

//! Content-addressed artifacts: files named by their sha256, stored once under
//! `DIR/ab/abcdef...`, written atomically and checked on the way in.

use std::path::{Path, PathBuf};

use sha2::{Digest, Sha256};

/// sha256 of bytes, lowercase hex.
pub fn sha256_hex(bytes: &[u8]) -> String {
    hex::encode(Sha256::digest(bytes))
}

/// True when `s` looks like a sha256 in lowercase hex (so it is safe as a file name).
pub fn valid_sha(s: &str) -> bool {
    s.len() == 64
        && s.bytes()
            .all(|b| b.is_ascii_digit() || (b'a'..=b'f').contains(&b))
}

/// A folder of artifacts.
#[derive(Debug, Clone)]
pub struct ArtifactDir {
    root: PathBuf,
}

impl ArtifactDir {
    pub fn new(root: &Path) -> std::io::Result<ArtifactDir> {
        std::fs::create_dir_all(root)?;
        Ok(ArtifactDir { root: root.into() })
    }

    /// Where the artifact `sha` lives (whether or not it is there).
    pub fn path(&self, sha: &str) -> PathBuf {
        self.root.join(&sha[..2]).join(sha)
    }

    pub fn has(&self, sha: &str) -> bool {
        valid_sha(sha) && self.path(sha).is_file()
    }

    /// Stores `bytes`, checking them against `sha` when given; returns the sha.
    pub fn put(&self, bytes: &[u8], sha: Option<&str>) -> std::io::Result<String> {
        let got = sha256_hex(bytes);
        if let Some(want) = sha {
            if want != got {
                return Err(std::io::Error::new(
                    std::io::ErrorKind::InvalidData,
                    format!("artifact content has sha256 {got}, announced {want}"),
                ));
            }
        }
        let p = self.path(&got);
        if p.is_file() {
            return Ok(got);
        }
        std::fs::create_dir_all(p.parent().expect("artifact folder"))?;
        // Unique per call: two threads may store the same content at once.
        static SEQ: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
        let n = SEQ.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        let tmp = p.with_extension(format!("partial{}-{n}", std::process::id()));
        std::fs::write(&tmp, bytes)?;
        std::fs::rename(&tmp, &p)?;
        Ok(got)
    }

    pub fn read(&self, sha: &str) -> std::io::Result<Vec<u8>> {
        if !valid_sha(sha) {
            return Err(std::io::Error::new(
                std::io::ErrorKind::InvalidInput,
                format!("not a sha256: {sha:?}"),
            ));
        }
        std::fs::read(self.path(sha))
    }
}

/// Checks a relative path from a client: no absolute paths, no `..`, plain characters only.
pub fn safe_relative(p: &str) -> Result<PathBuf, String> {
    let path = Path::new(p);
    let ok = !p.is_empty()
        && p.len() < 512
        && path
            .components()
            .all(|c| matches!(c, std::path::Component::Normal(_)))
        && p.chars()
            .all(|c| c.is_ascii_alphanumeric() || "._-/ +".contains(c));
    if ok {
        Ok(path.into())
    } else {
        Err(format!(
            "file path {p:?} must be relative, without '..', of plain characters"
        ))
    }
}

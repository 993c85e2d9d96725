//! Content-addressed artifacts: files named by their sha256, stored once under
//! `DIR/ab/abcdef...`, written atomically and checked on the way in.

use std::path::{Path, PathBuf};

use bemcal_durable::AtomicFile;
use sha2::{Digest, Sha256};
use std::io::Write;

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

/// An artifact being received ([`ArtifactDir::upload`]): the bytes go to a durable
/// [`AtomicFile`] as they arrive, hashed on the way; [`Upload::finish`] checks the size and
/// hash and puts the file in place. Dropped unfinished, it leaves nothing behind.
pub struct Upload {
    file: AtomicFile,
    hasher: Sha256,
    received: u64,
    sha: String,
    size: u64,
}

impl Upload {
    /// Appends a piece; more bytes than announced is an error.
    pub fn write(&mut self, data: &[u8]) -> std::io::Result<()> {
        self.received += data.len() as u64;
        if self.received > self.size {
            return Err(std::io::Error::new(
                std::io::ErrorKind::InvalidData,
                "more bytes than announced",
            ));
        }
        self.hasher.update(data);
        self.file.write_all(data)
    }

    /// Checks the size and the hash, and stores the artifact durably.
    pub fn finish(self) -> std::io::Result<()> {
        let bad = |m: String| std::io::Error::new(std::io::ErrorKind::InvalidData, m);
        if self.received != self.size {
            return Err(bad(format!(
                "{} bytes received, {} announced",
                self.received, self.size
            )));
        }
        let got = hex::encode(self.hasher.finalize());
        if got != self.sha {
            return Err(bad(format!(
                "artifact content has sha256 {got}, announced {}",
                self.sha
            )));
        }
        self.file.commit()
    }
}

/// A folder of artifacts.
#[derive(Debug, Clone)]
pub struct ArtifactDir {
    root: PathBuf,
}

impl ArtifactDir {
    /// The store in `root`, created when missing.
    pub fn new(root: &Path) -> std::io::Result<ArtifactDir> {
        std::fs::create_dir_all(root)?;
        Ok(ArtifactDir { root: root.into() })
    }

    /// Where the artifact `sha` lives (whether or not it is there).
    pub fn path(&self, sha: &str) -> PathBuf {
        self.root.join(&sha[..2]).join(sha)
    }

    /// Removes the artifact `sha` (nothing when it is not there).
    pub fn remove(&self, sha: &str) -> std::io::Result<()> {
        if !valid_sha(sha) {
            return Ok(());
        }
        match std::fs::remove_file(self.path(sha)) {
            Err(e) if e.kind() != std::io::ErrorKind::NotFound => Err(e),
            _ => Ok(()),
        }
    }

    /// Whether the artifact `sha` is stored (false for a name that is not a SHA-256).
    pub fn has(&self, sha: &str) -> bool {
        valid_sha(sha) && self.path(sha).is_file()
    }

    /// Starts storing the artifact `sha` of `size` bytes, received piece by piece: memory stays
    /// at one piece whatever the size.
    pub fn upload(&self, sha: &str, size: u64) -> std::io::Result<Upload> {
        if !valid_sha(sha) {
            return Err(std::io::Error::new(
                std::io::ErrorKind::InvalidInput,
                "not a sha256",
            ));
        }
        Ok(Upload {
            file: AtomicFile::create(&self.path(sha))?,
            hasher: Sha256::new(),
            received: 0,
            sha: sha.into(),
            size,
        })
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
        bemcal_durable::write_atomic(&p, bytes)?;
        Ok(got)
    }

    /// The artifact `sha`'s bytes.
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
            "file path {:?} must be relative, without '..', of plain characters, under 512 bytes",
            crate::excerpt(p, crate::EXCERPT_BYTES)
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_upload_in_pieces_is_stored_only_when_whole_and_right() {
        let dir = tempfile::tempdir().unwrap();
        let store = ArtifactDir::new(dir.path()).unwrap();
        let bytes: Vec<u8> = (0..3_000_000u32).map(|i| (i % 251) as u8).collect();
        let sha = sha256_hex(&bytes);
        let mut up = store.upload(&sha, bytes.len() as u64).unwrap();
        for piece in bytes.chunks(1 << 20) {
            up.write(piece).unwrap();
        }
        up.finish().unwrap();
        assert_eq!(store.read(&sha).unwrap(), bytes);
        // A wrong hash, a short upload, or too many bytes: nothing stored, nothing left over.
        let other = sha256_hex(b"other");
        let mut up = store.upload(&other, 5).unwrap();
        up.write(b"wrong").unwrap();
        assert!(up.finish().is_err());
        let mut up = store.upload(&other, 5).unwrap();
        up.write(b"oth").unwrap();
        assert!(up
            .finish()
            .unwrap_err()
            .to_string()
            .contains("3 bytes received"));
        let mut up = store.upload(&other, 5).unwrap();
        assert!(up.write(b"other!").is_err());
        drop(up);
        assert!(!store.has(&other));
        let left: Vec<_> = std::fs::read_dir(store.path(&other).parent().unwrap())
            .unwrap()
            .collect();
        assert!(left.is_empty(), "{left:?}");
    }
}

//! The worker's cache: artifacts by hash (fetched once), project bundles laid out once per
//! content, and one fresh folder per job with its inputs.

use std::path::{Path, PathBuf};

use bemcal_client::artifacts::{safe_relative, ArtifactDir};
use bemcal_client::bundle;
use bemcal_client::client::{download, Client};
use bemcal_client::proto;
use bemcal_client::File;
use sha2::{Digest, Sha256};

/// The cache folder.
pub struct Cache {
    root: PathBuf,
    artifacts: ArtifactDir,
}

impl Cache {
    /// The cache in `root`: artifacts under `root/artifacts`, beside the job folders.
    pub fn new(root: &Path) -> std::io::Result<Cache> {
        Ok(Cache {
            root: root.into(),
            artifacts: ArtifactDir::new(&root.join("artifacts"))?,
        })
    }

    /// Makes sure an artifact is in the cache.
    pub async fn fetch(&self, client: &mut Client, sha: &str) -> Result<PathBuf, String> {
        if !self.artifacts.has(sha) {
            let bytes = download(client, sha).await.map_err(|e| e.to_string())?;
            self.artifacts
                .put(&bytes, Some(sha))
                .map_err(|e| e.to_string())?;
        }
        Ok(self.artifacts.path(sha))
    }

    /// Lays out the job's bundle (shared between jobs) and a fresh job folder with its inputs;
    /// returns `(project file, job folder)`.
    pub async fn prepare(
        &self,
        mut client: Client,
        job: &proto::Job,
    ) -> Result<(PathBuf, PathBuf), String> {
        for f in job.bundle.iter().chain(&job.inputs) {
            self.fetch(&mut client, &f.sha256).await?;
        }
        let files: Vec<File> = job.bundle.iter().map(File::from).collect();
        let mut h = Sha256::new();
        for f in &files {
            h.update(format!("{} {}\n", f.path, f.sha256));
        }
        let key = hex::encode(h.finalize());
        let dir = self.root.join("bundles").join(&key[..16]);
        if !dir.join(bundle::PROJECT_FILE).is_file() {
            bundle::materialize(&files, &self.artifacts, &dir)?;
        }
        let work = self
            .root
            .join("work")
            .join(format!("job{}-lease{}", job.job_id, job.lease_id));
        let _ = std::fs::remove_dir_all(&work);
        for f in &job.inputs {
            let p = work.join(safe_relative(&f.path)?);
            if let Some(parent) = p.parent() {
                std::fs::create_dir_all(parent).map_err(|e| e.to_string())?;
            }
            std::fs::copy(self.artifacts.path(&f.sha256), &p)
                .map_err(|e| format!("{}: {e}", p.display()))?;
        }
        std::fs::create_dir_all(&work).map_err(|e| e.to_string())?;
        Ok((dir.join(bundle::PROJECT_FILE), work))
    }
}

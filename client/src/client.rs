//! The client side of the protocol: an authenticated (and, with a CA file, TLS) channel, and
//! chunked artifact upload and download. Used by workers and by the CLI.

use std::path::{Path, PathBuf};
use std::time::Duration;

use tonic::service::interceptor::InterceptedService;
use tonic::transport::{Certificate, Channel, ClientTlsConfig, Endpoint};

use crate::artifacts::sha256_hex;
use crate::auth::AddToken;
use crate::proto::coordinator_client::CoordinatorClient;
use crate::proto::{self, ArtifactList, ArtifactRequest, Chunk};
use crate::File;
use crate::{CHUNK_BYTES, MAX_MESSAGE_BYTES};

/// An authenticated client of the coordinator.
pub type Client = CoordinatorClient<InterceptedService<Channel, AddToken>>;

/// How to reach the coordinator.
#[derive(Debug, Clone)]
pub struct Connect {
    /// `http://HOST:PORT` or `https://HOST:PORT`.
    pub url: String,
    /// The bearer token.
    pub token: String,
    /// CA certificate (PEM) to trust for `https://`.
    pub tls_ca: Option<PathBuf>,
}

impl Connect {
    /// Connects (lazily: the first call opens the connection, and a lost connection reopens).
    pub fn client(&self) -> anyhow::Result<Client> {
        let mut ep = Endpoint::from_shared(self.url.clone())
            .map_err(|e| anyhow::anyhow!("bad coordinator URL {:?}: {e}", self.url))?
            .connect_timeout(Duration::from_secs(5))
            .tcp_nodelay(true);
        if self.url.starts_with("https://") {
            let mut tls = ClientTlsConfig::new();
            if let Some(ca) = &self.tls_ca {
                let pem = std::fs::read(ca)
                    .map_err(|e| anyhow::anyhow!("cannot read CA file {}: {e}", ca.display()))?;
                tls = tls.ca_certificate(Certificate::from_pem(pem));
            }
            ep = ep.tls_config(tls)?;
        }
        let channel = ep.connect_lazy();
        Ok(
            CoordinatorClient::with_interceptor(channel, AddToken::new(&self.token)?)
                .max_decoding_message_size(MAX_MESSAGE_BYTES)
                .max_encoding_message_size(MAX_MESSAGE_BYTES),
        )
    }
}

/// Uploads `bytes` as an artifact unless the coordinator has it; returns its sha256.
pub async fn upload(client: &mut Client, bytes: Vec<u8>) -> Result<String, tonic::Status> {
    let sha = sha256_hex(&bytes);
    let missing = client
        .missing_artifacts(ArtifactList {
            sha256: vec![sha.clone()],
        })
        .await?
        .into_inner();
    if missing.sha256.is_empty() {
        return Ok(sha);
    }
    let size = bytes.len() as u64;
    let mut chunks: Vec<Chunk> = bytes
        .chunks(CHUNK_BYTES)
        .map(|c| Chunk {
            sha256: String::new(),
            size: 0,
            data: c.to_vec(),
        })
        .collect();
    if chunks.is_empty() {
        chunks.push(Chunk::default());
    }
    chunks[0].sha256 = sha.clone();
    chunks[0].size = size;
    let info = client
        .put_artifact(tokio_stream::iter(chunks))
        .await?
        .into_inner();
    if info.sha256 != sha {
        return Err(tonic::Status::data_loss(
            "artifact hash mismatch after upload",
        ));
    }
    Ok(sha)
}

/// Uploads a file as an artifact named `rel` (its relative path in a bundle or job folder).
pub async fn upload_file(client: &mut Client, path: &Path, rel: &str) -> anyhow::Result<File> {
    let bytes =
        std::fs::read(path).map_err(|e| anyhow::anyhow!("cannot read {}: {e}", path.display()))?;
    let size = bytes.len() as u64;
    let sha = upload(client, bytes).await?;
    Ok(File {
        path: rel.to_string(),
        sha256: sha,
        size,
    })
}

/// Downloads an artifact, checking its hash.
pub async fn download(client: &mut Client, sha: &str) -> anyhow::Result<Vec<u8>> {
    let mut stream = client
        .get_artifact(ArtifactRequest {
            sha256: sha.to_string(),
        })
        .await?
        .into_inner();
    let mut bytes = vec![];
    while let Some(c) = stream.message().await? {
        bytes.extend_from_slice(&c.data);
    }
    let got = sha256_hex(&bytes);
    if got != sha {
        anyhow::bail!("artifact {sha}: downloaded content has sha256 {got}");
    }
    Ok(bytes)
}

/// Uploads every file under `dir` (recursively) with paths `prefix/<relative path>`.
pub async fn upload_dir(
    client: &mut Client,
    dir: &Path,
    prefix: &str,
) -> anyhow::Result<Vec<File>> {
    let mut out = vec![];
    for p in walk(dir)? {
        let rel = p
            .strip_prefix(dir)
            .map_err(|e| anyhow::anyhow!("{e}"))?
            .to_string_lossy()
            .replace('\\', "/");
        let rel = if prefix.is_empty() {
            rel
        } else {
            format!("{prefix}/{rel}")
        };
        out.push(upload_file(client, &p, &rel).await?);
    }
    Ok(out)
}

/// Files under `dir`, recursively, sorted.
pub fn walk(dir: &Path) -> std::io::Result<Vec<PathBuf>> {
    let mut out = vec![];
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d)? {
            let e = e?;
            let t = e.file_type()?;
            if t.is_dir() {
                stack.push(e.path());
            } else if t.is_file() {
                out.push(e.path());
            }
        }
    }
    out.sort();
    Ok(out)
}

/// Converts files to protocol references.
pub fn refs(files: &[File]) -> Vec<proto::FileRef> {
    files.iter().map(proto::FileRef::from).collect()
}

/// A submission's answer.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Submitted {
    /// The run's id.
    pub run_id: String,
    /// The same project was still running (an interrupted client's run): this is that run,
    /// going on with every job it finished.
    pub resumed: bool,
}

/// Bundles a project (uploading its files) and submits it; `surrogate`: a trained surrogate
/// folder to use instead of training. A project whose run is still running gets that run.
pub async fn submit_project(
    client: &mut Client,
    project_file: &Path,
    surrogate: Option<&Path>,
    policy: crate::bundle::Policy,
) -> anyhow::Result<Submitted> {
    submit_building(client, project_file, surrogate, "", "", policy).await
}

/// Submits a project as building `building` of portfolio `portfolio` (empty: a lone run).
/// In a portfolio an invalid project is not refused: it becomes a failed run with the reason.
pub async fn submit_building(
    client: &mut Client,
    project_file: &Path,
    surrogate: Option<&Path>,
    portfolio: &str,
    building: &str,
    policy: crate::bundle::Policy,
) -> anyhow::Result<Submitted> {
    let files = crate::bundle::collect(project_file, policy)?;
    let mut bundle = vec![];
    for (rel, bytes) in files {
        let size = bytes.len() as u64;
        let sha = upload(client, bytes).await?;
        bundle.push(proto::FileRef {
            path: rel,
            sha256: sha,
            size,
        });
    }
    let surrogate = match surrogate {
        Some(d) => refs(&upload_dir(client, d, "surrogate").await?),
        None => vec![],
    };
    let r = client
        .submit(proto::SubmitRequest {
            bundle,
            surrogate,
            portfolio: portfolio.to_string(),
            building: building.to_string(),
        })
        .await
        .map_err(|e| anyhow::anyhow!("{}", e.message()))?
        .into_inner();
    Ok(Submitted {
        run_id: r.run_id,
        resumed: r.resumed,
    })
}

/// Downloads a finished run's files into `out` (the layout of the local `calibrate`).
pub async fn fetch_results(client: &mut Client, run: &str, out: &Path) -> anyhow::Result<usize> {
    let st = client
        .get_run(proto::RunRequest {
            run_id: run.to_string(),
        })
        .await
        .map_err(|e| anyhow::anyhow!("{}", e.message()))?
        .into_inner();
    if st.state() != proto::RunState::Done {
        anyhow::bail!(
            "run {run} is {} (stage {}){}",
            st.state().word(),
            st.stage().word(),
            if st.error.is_empty() {
                String::new()
            } else {
                format!(": {}", st.error)
            }
        );
    }
    for f in &st.results {
        let rel = crate::artifacts::safe_relative(&f.path).map_err(|e| anyhow::anyhow!(e))?;
        let bytes = download(client, &f.sha256).await?;
        bemcal_durable::write_atomic(&out.join(rel), &bytes)?;
    }
    Ok(st.results.len())
}

/// A stage's state in words, with its running jobs: `running (2 running)`, `done`.
pub fn stage_state(s: &proto::StageProgress) -> String {
    match s.running {
        0 => s.state().word().to_string(),
        n => format!("{} ({n} running)", s.state().word()),
    }
}

/// One line per stage: `stage  state  done/total (running)`.
pub fn progress_lines(st: &proto::RunStatus) -> Vec<String> {
    st.stages
        .iter()
        .map(|s| {
            let width = 20usize;
            let filled = if s.total == 0 {
                0
            } else {
                (s.done as usize * width) / s.total as usize
            };
            format!(
                "  {:<9} [{}{}] {:>3}/{:<3} {}",
                s.stage().word(),
                "#".repeat(filled),
                "-".repeat(width - filled),
                s.done,
                s.total,
                stage_state(s)
            )
        })
        .collect()
}

/// Follows a run until it ends, calling `on_change` whenever its progress changes; returns
/// the final status.
pub async fn watch(
    client: &mut Client,
    run: &str,
    mut on_change: impl FnMut(&proto::RunStatus),
) -> anyhow::Result<proto::RunStatus> {
    let mut last = String::new();
    let mut unreachable_since: Option<std::time::Instant> = None;
    loop {
        let r = client
            .get_run(proto::RunRequest {
                run_id: run.to_string(),
            })
            .await;
        let st = match r {
            Ok(r) => {
                unreachable_since = None;
                r.into_inner()
            }
            Err(e) if e.code() == tonic::Code::Unavailable => {
                // The coordinator may be restarting.
                let t = *unreachable_since.get_or_insert_with(std::time::Instant::now);
                if t.elapsed() > Duration::from_secs(300) {
                    anyhow::bail!("coordinator unreachable: {}", e.message());
                }
                tokio::time::sleep(Duration::from_millis(500)).await;
                continue;
            }
            Err(e) => anyhow::bail!("{}", e.message()),
        };
        let key = format!(
            "{} {} {:?} {}",
            st.state().word(),
            st.stage().word(),
            progress_lines(&st),
            st.log.len()
        );
        if key != last {
            on_change(&st);
            last = key;
        }
        if st.state() != proto::RunState::Running {
            return Ok(st);
        }
        tokio::time::sleep(Duration::from_millis(500)).await;
    }
}

//! Bearer-token authentication: every call carries `authorization: Bearer <token>`; the
//! coordinator refuses calls without the right one.

use std::path::Path;

use tonic::metadata::MetadataValue;
use tonic::{Request, Status};

/// Environment variable holding the token when no `--token-file` is given.
pub const TOKEN_ENV: &str = "BEMCAL_TOKEN";

/// Environment variable holding the coordinator's separate worker token when no
/// `--worker-token-file` is given.
pub const WORKER_TOKEN_ENV: &str = "BEMCAL_WORKER_TOKEN";

/// Reads the token from `file` (first line, trimmed) or from `BEMCAL_TOKEN`.
pub fn load_token(file: Option<&Path>) -> anyhow::Result<String> {
    read_token(file, TOKEN_ENV)?
        .ok_or_else(|| anyhow::anyhow!("no token: give --token-file FILE or set {TOKEN_ENV}"))
}

/// Reads the coordinator's separate worker token from `file` or `BEMCAL_WORKER_TOKEN`; none
/// when neither is given (then the one token serves clients and workers).
pub fn load_worker_token(file: Option<&Path>) -> anyhow::Result<Option<String>> {
    read_token(file, WORKER_TOKEN_ENV)
}

/// A token from the first line of `file`, else from the environment variable `env`.
fn read_token(file: Option<&Path>, env: &str) -> anyhow::Result<Option<String>> {
    let token = match file {
        Some(p) => std::fs::read_to_string(p)
            .map_err(|e| anyhow::anyhow!("cannot read token file {}: {e}", p.display()))?
            .lines()
            .next()
            .unwrap_or("")
            .trim()
            .to_string(),
        None => std::env::var(env).unwrap_or_default().trim().to_string(),
    };
    if token.is_empty() {
        return Ok(None);
    }
    if token.len() < 16 || !token.chars().all(|c| c.is_ascii_graphic()) {
        anyhow::bail!("the token must be at least 16 printable ASCII characters without spaces");
    }
    Ok(Some(token))
}

/// A fresh random token (hex of 32 bytes from the OS).
pub fn random_token() -> String {
    use std::io::Read;
    let mut b = [0u8; 32];
    if let Ok(mut f) = std::fs::File::open("/dev/urandom") {
        let _ = f.read_exact(&mut b);
    }
    // Mix in time and pid in case /dev/urandom is unavailable.
    let t = format!("{:?}{}{}", b, crate::now_ms(), std::process::id());
    hex::encode(<sha2::Sha256 as sha2::Digest>::digest(t.as_bytes()))
}

/// Who a call comes from, by the token it carries: the coordinator's roles.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Role {
    /// A submitter (CLI, portfolio): submits, watches, cancels runs and moves artifacts.
    Client,
    /// A worker: leases jobs, heartbeats, completes or fails them, and moves artifacts.
    Worker,
    /// Both (one token for both roles, as in a local run or a coordinator started without a
    /// separate worker token).
    Both,
}

impl Role {
    /// Whether this role may act as `needed` ([`Role::Client`] or [`Role::Worker`]).
    pub fn allows(self, needed: Role) -> bool {
        self == Role::Both || self == needed
    }
}

/// Server side: checks the bearer token in constant time and records the caller's [`Role`] in
/// the request's extensions for the service to check.
#[derive(Clone)]
pub struct CheckToken {
    client: String,
    worker: Option<String>,
}

impl CheckToken {
    /// One token for every caller.
    pub fn new(token: &str) -> CheckToken {
        CheckToken::with_roles(token, None)
    }

    /// A client token and, when given, a separate worker token: then a client cannot lease
    /// or complete jobs and a worker cannot submit or cancel runs.
    pub fn with_roles(client: &str, worker: Option<&str>) -> CheckToken {
        CheckToken {
            client: format!("Bearer {client}"),
            worker: worker.map(|w| format!("Bearer {w}")),
        }
    }
}

/// Constant-time equality of a received header and an expected one.
fn same(got: &[u8], expected: &[u8]) -> bool {
    let mut diff = got.len() ^ expected.len();
    for (i, x) in expected.iter().enumerate() {
        diff |= (*x ^ got.get(i).copied().unwrap_or(0)) as usize;
    }
    diff == 0
}

impl tonic::service::Interceptor for CheckToken {
    fn call(&mut self, mut req: Request<()>) -> Result<Request<()>, Status> {
        let got = req
            .metadata()
            .get("authorization")
            .and_then(|v| v.to_str().ok())
            .unwrap_or("")
            .as_bytes();
        let role = match &self.worker {
            None if same(got, self.client.as_bytes()) => Some(Role::Both),
            Some(w) if same(got, w.as_bytes()) => Some(Role::Worker),
            Some(_) if same(got, self.client.as_bytes()) => Some(Role::Client),
            _ => None,
        };
        match role {
            Some(role) => {
                req.extensions_mut().insert(role);
                Ok(req)
            }
            None => Err(Status::unauthenticated(
                "missing or wrong bearer token (authorization: Bearer <token>)",
            )),
        }
    }
}

/// The caller's role recorded by [`CheckToken`], or `PermissionDenied` when it may not act as
/// `needed`.
pub fn require<T>(req: &Request<T>, needed: Role) -> Result<(), Status> {
    match req.extensions().get::<Role>() {
        Some(role) if role.allows(needed) => Ok(()),
        _ => Err(Status::permission_denied(match needed {
            Role::Worker => "this call needs the worker token",
            _ => "this call needs the client token",
        })),
    }
}

/// Client side: adds the bearer token to every call.
#[derive(Clone)]
pub struct AddToken {
    value: MetadataValue<tonic::metadata::Ascii>,
}

impl AddToken {
    /// Adds `authorization: Bearer <token>`; a token that cannot be a header value is an error.
    pub fn new(token: &str) -> anyhow::Result<AddToken> {
        let value = format!("Bearer {token}")
            .parse()
            .map_err(|_| anyhow::anyhow!("the token is not valid header text"))?;
        Ok(AddToken { value })
    }
}

impl tonic::service::Interceptor for AddToken {
    fn call(&mut self, mut req: Request<()>) -> Result<Request<()>, Status> {
        req.metadata_mut()
            .insert("authorization", self.value.clone());
        Ok(req)
    }
}

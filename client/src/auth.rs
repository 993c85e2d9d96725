//! Bearer-token authentication: every call carries `authorization: Bearer <token>`; the
//! coordinator refuses calls without the right one.

use std::path::Path;

use tonic::metadata::MetadataValue;
use tonic::{Request, Status};

/// Environment variable holding the token when no `--token-file` is given.
pub const TOKEN_ENV: &str = "BEMCAL_TOKEN";

/// Reads the token from `file` (first line, trimmed) or from `BEMCAL_TOKEN`.
pub fn load_token(file: Option<&Path>) -> anyhow::Result<String> {
    let token = match file {
        Some(p) => std::fs::read_to_string(p)
            .map_err(|e| anyhow::anyhow!("cannot read token file {}: {e}", p.display()))?
            .lines()
            .next()
            .unwrap_or("")
            .trim()
            .to_string(),
        None => std::env::var(TOKEN_ENV)
            .unwrap_or_default()
            .trim()
            .to_string(),
    };
    if token.is_empty() {
        anyhow::bail!("no token: give --token-file FILE or set {TOKEN_ENV}");
    }
    if token.len() < 16 || !token.chars().all(|c| c.is_ascii_graphic()) {
        anyhow::bail!("the token must be at least 16 printable ASCII characters without spaces");
    }
    Ok(token)
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

/// Server side: checks the bearer token in constant time.
#[derive(Clone)]
pub struct CheckToken {
    expected: String,
}

impl CheckToken {
    pub fn new(token: &str) -> CheckToken {
        CheckToken {
            expected: format!("Bearer {token}"),
        }
    }
}

impl tonic::service::Interceptor for CheckToken {
    fn call(&mut self, req: Request<()>) -> Result<Request<()>, Status> {
        let got = req
            .metadata()
            .get("authorization")
            .and_then(|v| v.to_str().ok())
            .unwrap_or("");
        let (a, b) = (got.as_bytes(), self.expected.as_bytes());
        let mut diff = a.len() ^ b.len();
        for (i, x) in b.iter().enumerate() {
            diff |= (*x ^ a.get(i).copied().unwrap_or(0)) as usize;
        }
        if diff == 0 {
            Ok(req)
        } else {
            Err(Status::unauthenticated(
                "missing or wrong bearer token (authorization: Bearer <token>)",
            ))
        }
    }
}

/// Client side: adds the bearer token to every call.
#[derive(Clone)]
pub struct AddToken {
    value: MetadataValue<tonic::metadata::Ascii>,
}

impl AddToken {
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

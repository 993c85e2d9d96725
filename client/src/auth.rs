//! Bearer-token authentication and the callers' identities. Every call carries
//! `authorization: Bearer <token>`: a client's token (each with a name, the coordinator's
//! `--client-tokens`), the enrollment token workers register with, or a registered worker's own
//! credential. The coordinator's interceptor ([`CheckToken`]) records who called as a
//! [`Caller`] in the request, and the service decides by it what the caller may do.

use std::collections::HashMap;
use std::path::Path;
use std::sync::{Arc, Mutex, RwLock};
use std::time::Instant;

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

/// Reads the token from `file` or `BEMCAL_TOKEN`, if either gives one (a coordinator with
/// named client tokens may have no `default` one).
pub fn load_token_if_any(file: Option<&Path>) -> anyhow::Result<Option<String>> {
    read_token(file, TOKEN_ENV)
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

/// `n` bytes from the operating system's random source (for credentials and lease ids: never a
/// weaker fallback).
pub fn random_bytes<const N: usize>() -> std::io::Result<[u8; N]> {
    use std::io::Read;
    let mut b = [0u8; N];
    std::fs::File::open("/dev/urandom")?.read_exact(&mut b)?;
    Ok(b)
}

/// A worker's new credential: 32 bytes from the operating system, hex.
pub fn new_credential() -> std::io::Result<String> {
    Ok(hex::encode(random_bytes::<32>()?))
}

/// The SHA-256 (hex) of a token: what the coordinator stores of a worker's credential.
pub fn token_sha256(token: &str) -> String {
    crate::artifacts::sha256_hex(token.as_bytes())
}

/// A client's or worker's name: 1-100 ASCII letters, digits, '.', '-' or '_'.
pub fn check_name(name: &str) -> Result<(), String> {
    let plain = |c: char| c.is_ascii_alphanumeric() || matches!(c, '.' | '-' | '_');
    if name.is_empty() || name.len() > 100 || !name.chars().all(plain) {
        return Err(format!(
            "name {:?} ({} bytes): use 1-100 letters, digits, '.', '-' or '_'",
            crate::excerpt(name, 40),
            name.len()
        ));
    }
    Ok(())
}

/// The name of the client whose token is the coordinator's one `--token-file` token.
pub const DEFAULT_CLIENT: &str = "default";

/// Named client tokens from `file`: one `NAME TOKEN` a line (blank lines and lines starting
/// with `#` ignored). Names and tokens are each unique; a token follows [`load_token`]'s rules.
pub fn load_client_tokens(file: &Path) -> anyhow::Result<Vec<(String, String)>> {
    let text = std::fs::read_to_string(file)
        .map_err(|e| anyhow::anyhow!("cannot read client tokens {}: {e}", file.display()))?;
    let mut out: Vec<(String, String)> = vec![];
    for (i, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let at = || format!("{} line {}", file.display(), i + 1);
        let mut parts = line.split_whitespace();
        let (Some(name), Some(token), None) = (parts.next(), parts.next(), parts.next()) else {
            anyhow::bail!("{}: expected `NAME TOKEN`", at());
        };
        check_name(name).map_err(|e| anyhow::anyhow!("{}: {e}", at()))?;
        if token.len() < 16 || !token.chars().all(|c| c.is_ascii_graphic()) {
            anyhow::bail!(
                "{}: the token must be at least 16 printable ASCII characters",
                at()
            );
        }
        if out.iter().any(|(n, _)| n == name) {
            anyhow::bail!("{}: client {name} is named twice", at());
        }
        if out.iter().any(|(_, t)| t == token) {
            anyhow::bail!("{}: client {name}'s token is another client's", at());
        }
        out.push((name.to_string(), token.to_string()));
    }
    if out.is_empty() {
        anyhow::bail!("{}: no client tokens", file.display());
    }
    Ok(out)
}

/// Who a call comes from, by the token it carries: recorded by [`CheckToken`] in the request's
/// extensions.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Caller {
    /// A client token: submits, watches and cancels runs and moves artifacts. `enrolls`: the
    /// token is also the enrollment token (a coordinator with one token for everything).
    Client {
        /// The token's name (`default` for the coordinator's one `--token-file` token).
        name: String,
        /// Whether the token also registers workers.
        enrolls: bool,
    },
    /// The enrollment token (the coordinator's worker token): registers workers, nothing else.
    Enroller,
    /// A registered worker, by the id the coordinator gave it: leases, heartbeats, completes
    /// and fails its own jobs and moves artifacts.
    Worker(String),
}

impl Caller {
    /// How the audit trail names the caller: `client:NAME`, `worker:ID` or `enroller`.
    pub fn actor(&self) -> String {
        match self {
            Caller::Client { name, .. } => format!("client:{name}"),
            Caller::Enroller => "enroller".into(),
            Caller::Worker(id) => format!("worker:{id}"),
        }
    }
}

/// The registered workers' credentials, by SHA-256: shared by the interceptor, which looks them
/// up, and the coordinator, which adds one at each registration and marks revocations.
#[derive(Clone, Default)]
pub struct WorkerCredentials(Arc<RwLock<HashMap<String, (String, bool)>>>);

impl WorkerCredentials {
    /// Knows the credential whose SHA-256 is `sha256` as worker `id` (`revoked`: refused).
    pub fn add(&self, sha256: &str, id: &str, revoked: bool) {
        if let Ok(mut m) = self.0.write() {
            m.insert(sha256.to_string(), (id.to_string(), revoked));
        }
    }

    /// Refuses worker `id`'s credential from now on; false when no credential is that worker's.
    pub fn revoke(&self, id: &str) -> bool {
        let Ok(mut m) = self.0.write() else {
            return false;
        };
        let mut found = false;
        for (_, revoked) in m.values_mut().filter(|(w, _)| w == id) {
            *revoked = true;
            found = true;
        }
        found
    }

    /// The worker whose credential `token` is: `Ok(id)`, `Err(id)` when it is revoked, `None`
    /// when no worker's.
    fn lookup(&self, token: &str) -> Option<Result<String, String>> {
        let m = self.0.read().ok()?;
        let (id, revoked) = m.get(&token_sha256(token))?;
        Some(if *revoked {
            Err(id.clone())
        } else {
            Ok(id.clone())
        })
    }
}

/// A token bucket per client: `per_second` requests a second on average, bursts of up to
/// `burst`.
struct RateLimit {
    per_second: f64,
    burst: f64,
    buckets: Mutex<HashMap<String, (f64, Instant)>>,
}

impl RateLimit {
    /// Takes a request from `name`'s bucket; false when it is empty.
    fn allow(&self, name: &str) -> bool {
        let Ok(mut b) = self.buckets.lock() else {
            return true;
        };
        let now = Instant::now();
        let (tokens, last) = b.entry(name.to_string()).or_insert((self.burst, now));
        let refill = now.duration_since(*last).as_secs_f64() * self.per_second;
        *tokens = (*tokens + refill).min(self.burst);
        *last = now;
        if *tokens >= 1.0 {
            *tokens -= 1.0;
            true
        } else {
            false
        }
    }
}

/// A call the interceptor refused, as the coordinator's log and audit trail are told of it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Refusal {
    /// A revoked worker's credential.
    Revoked {
        /// The worker.
        worker: String,
    },
    /// A client over its request rate.
    RateLimited {
        /// The client's name.
        client: String,
    },
    /// No token, or one nobody has.
    Unknown,
}

/// What the coordinator does with a refusal (logs it; audits a revoked worker's).
pub type OnRefusal = Arc<dyn Fn(&Refusal) + Send + Sync>;

/// Server side: checks the bearer token (clients' and the enrollment token in constant time; a
/// worker's credential by its SHA-256) and records the [`Caller`] in the request's extensions
/// for the service to check.
#[derive(Clone)]
pub struct CheckToken {
    clients: Arc<Vec<(String, String)>>,
    enroll: Option<String>,
    workers: WorkerCredentials,
    rate: Option<Arc<RateLimit>>,
    on_refusal: Option<OnRefusal>,
}

impl CheckToken {
    /// One token for every caller: the client [`DEFAULT_CLIENT`], which also registers workers
    /// (whose credentials `workers` holds).
    pub fn new(token: &str, workers: WorkerCredentials) -> CheckToken {
        CheckToken::with_clients(
            &[(DEFAULT_CLIENT.into(), token.into())],
            Some(token),
            workers,
        )
    }

    /// Named client tokens (`(name, token)`), the enrollment token (a client token here makes
    /// that client an enroller too; `None`: no worker can register) and the registered
    /// workers' credentials.
    pub fn with_clients(
        clients: &[(String, String)],
        enroll: Option<&str>,
        workers: WorkerCredentials,
    ) -> CheckToken {
        CheckToken {
            clients: Arc::new(
                clients
                    .iter()
                    .map(|(n, t)| (n.clone(), format!("Bearer {t}")))
                    .collect(),
            ),
            enroll: enroll.map(|t| format!("Bearer {t}")),
            workers,
            rate: None,
            on_refusal: None,
        }
    }

    /// Holds each client to `per_second` requests a second on average, in bursts of up to
    /// `burst` (workers are not limited); `per_second` 0: no limit.
    pub fn rate_limited(mut self, per_second: f64, burst: f64) -> CheckToken {
        self.rate = (per_second > 0.0).then(|| {
            Arc::new(RateLimit {
                per_second,
                burst: burst.max(1.0),
                buckets: Mutex::new(HashMap::new()),
            })
        });
        self
    }

    /// Tells `f` of every call refused.
    pub fn on_refusal(mut self, f: OnRefusal) -> CheckToken {
        self.on_refusal = Some(f);
        self
    }

    fn refused(&self, r: Refusal) {
        if let Some(f) = &self.on_refusal {
            f(&r);
        }
    }

    /// Who `header` (the `authorization` value) is, or why not.
    fn identify(&self, header: &[u8]) -> Result<Caller, Status> {
        // Every client token is compared, whichever matches.
        let mut client = None;
        for (name, token) in self.clients.iter() {
            if same(header, token.as_bytes()) {
                client = Some(name.clone());
            }
        }
        let enrolls = self
            .enroll
            .as_ref()
            .is_some_and(|e| same(header, e.as_bytes()));
        match (client, enrolls) {
            (Some(name), enrolls) => return Ok(Caller::Client { name, enrolls }),
            (None, true) => return Ok(Caller::Enroller),
            (None, false) => {}
        }
        let token = std::str::from_utf8(header)
            .ok()
            .and_then(|h| h.strip_prefix("Bearer "));
        match token.and_then(|t| self.workers.lookup(t)) {
            Some(Ok(id)) => Ok(Caller::Worker(id)),
            Some(Err(worker)) => {
                let msg = format!("worker {worker}'s credential was revoked");
                self.refused(Refusal::Revoked { worker });
                Err(Status::unauthenticated(msg))
            }
            None => {
                self.refused(Refusal::Unknown);
                Err(Status::unauthenticated(
                    "missing or wrong bearer token (authorization: Bearer <token>)",
                ))
            }
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
        let header = req
            .metadata()
            .get("authorization")
            .map(|v| v.as_bytes())
            .unwrap_or(b"");
        let caller = self.identify(header)?;
        if let (Caller::Client { name, .. }, Some(rate)) = (&caller, &self.rate) {
            if !rate.allow(name) {
                let msg = format!(
                    "client {name} is over its rate of {} requests a second (the \
                     coordinator's --client-rate): slow down",
                    rate.per_second
                );
                self.refused(Refusal::RateLimited {
                    client: name.clone(),
                });
                return Err(Status::resource_exhausted(msg));
            }
        }
        req.extensions_mut().insert(caller);
        Ok(req)
    }
}

/// The caller [`CheckToken`] recorded (none on a server without it).
pub fn caller<T>(req: &Request<T>) -> Option<&Caller> {
    req.extensions().get::<Caller>()
}

/// The client's name, or `PermissionDenied` when the caller is not a client.
pub fn require_client<T>(req: &Request<T>) -> Result<String, Status> {
    match caller(req) {
        Some(Caller::Client { name, .. }) => Ok(name.clone()),
        _ => Err(Status::permission_denied("this call needs a client token")),
    }
}

/// The registered worker's id, or `PermissionDenied` when the caller is not one (the
/// enrollment token only registers workers).
pub fn require_worker<T>(req: &Request<T>) -> Result<String, Status> {
    match caller(req) {
        Some(Caller::Worker(id)) => Ok(id.clone()),
        _ => Err(Status::permission_denied(
            "this call needs a registered worker's credential (a worker registers with the \
             worker token first)",
        )),
    }
}

/// `Ok` when the caller may register workers (the enrollment token), else `PermissionDenied`.
pub fn require_enroller<T>(req: &Request<T>) -> Result<(), Status> {
    match caller(req) {
        Some(Caller::Enroller) | Some(Caller::Client { enrolls: true, .. }) => Ok(()),
        _ => Err(Status::permission_denied(
            "registering a worker needs the worker (enrollment) token",
        )),
    }
}

/// The caller as the audit trail names it, when it is a client or a registered worker (who may
/// move artifacts); `PermissionDenied` for the enrollment token alone.
pub fn require_client_or_worker<T>(req: &Request<T>) -> Result<String, Status> {
    match caller(req) {
        Some(c @ (Caller::Client { .. } | Caller::Worker(_))) => Ok(c.actor()),
        _ => Err(Status::permission_denied(
            "artifacts need a client token or a registered worker's credential",
        )),
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

#[cfg(test)]
mod tests {
    use super::*;
    use tonic::service::Interceptor;

    fn call(check: &mut CheckToken, token: &str) -> Result<Caller, Status> {
        let mut req = Request::new(());
        req.metadata_mut()
            .insert("authorization", format!("Bearer {token}").parse().unwrap());
        check
            .call(req)
            .map(|r| r.extensions().get::<Caller>().cloned().unwrap())
    }

    /// Each token is its caller: named clients, the enrollment token, a registered worker by
    /// its credential; a revoked credential and a wrong token are refused, and the refusal is
    /// told.
    #[test]
    fn tokens_name_their_callers_and_revoked_credentials_are_refused() {
        let workers = WorkerCredentials::default();
        let (a, b) = (new_credential().unwrap(), new_credential().unwrap());
        assert_ne!(a, b);
        workers.add(&token_sha256(&a), "w1-00000001", false);
        workers.add(&token_sha256(&b), "w2-00000002", false);
        let told = Arc::new(Mutex::new(vec![]));
        let sink = told.clone();
        let clients = [
            ("alice".to_string(), "alice-token-0123456789".to_string()),
            ("bob".to_string(), "bob-token-0123456789ab".to_string()),
        ];
        let mut check =
            CheckToken::with_clients(&clients, Some("enroll-token-0123456789"), workers.clone())
                .on_refusal(Arc::new(move |r: &Refusal| {
                    sink.lock().unwrap().push(r.clone())
                }));
        let alice = Caller::Client {
            name: "alice".into(),
            enrolls: false,
        };
        assert_eq!(call(&mut check, "alice-token-0123456789").unwrap(), alice);
        assert_eq!(
            call(&mut check, "enroll-token-0123456789").unwrap(),
            Caller::Enroller
        );
        assert_eq!(
            call(&mut check, &a).unwrap(),
            Caller::Worker("w1-00000001".into())
        );
        // A credential is a worker's only while it is not revoked; the others go on.
        assert!(workers.revoke("w1-00000001"));
        let e = call(&mut check, &a).unwrap_err();
        assert_eq!(e.code(), tonic::Code::Unauthenticated);
        assert!(
            e.message().contains("w1-00000001's credential was revoked"),
            "{e:?}"
        );
        assert_eq!(
            call(&mut check, &b).unwrap(),
            Caller::Worker("w2-00000002".into())
        );
        let e = call(&mut check, "alice-token-012345678X").unwrap_err();
        assert_eq!(e.code(), tonic::Code::Unauthenticated);
        assert_eq!(
            *told.lock().unwrap(),
            vec![
                Refusal::Revoked {
                    worker: "w1-00000001".into()
                },
                Refusal::Unknown
            ]
        );
        // One token for everything: the client `default`, who also registers workers.
        let mut one = CheckToken::new("one-token-0123456789", WorkerCredentials::default());
        let default = call(&mut one, "one-token-0123456789").unwrap();
        assert_eq!(
            default,
            Caller::Client {
                name: DEFAULT_CLIENT.into(),
                enrolls: true
            }
        );
    }

    /// What each caller may do: only workers lease, only the enrollment token registers, only
    /// clients submit, and the enrollment token alone moves no artifacts.
    #[test]
    fn each_caller_may_do_its_own_calls() {
        let with = |c: Caller| {
            let mut r = Request::new(());
            r.extensions_mut().insert(c);
            r
        };
        let client = with(Caller::Client {
            name: "a".into(),
            enrolls: false,
        });
        let one = with(Caller::Client {
            name: "default".into(),
            enrolls: true,
        });
        let enroller = with(Caller::Enroller);
        let worker = with(Caller::Worker("w-1".into()));
        assert_eq!(require_worker(&worker).unwrap(), "w-1");
        for r in [&client, &one, &enroller] {
            let e = require_worker(r).unwrap_err();
            assert_eq!(e.code(), tonic::Code::PermissionDenied);
        }
        assert!(require_enroller(&enroller).is_ok() && require_enroller(&one).is_ok());
        assert!(require_enroller(&client).is_err() && require_enroller(&worker).is_err());
        assert_eq!(require_client(&one).unwrap(), "default");
        assert!(require_client(&worker).is_err() && require_client(&enroller).is_err());
        assert_eq!(require_client_or_worker(&worker).unwrap(), "worker:w-1");
        assert_eq!(require_client_or_worker(&client).unwrap(), "client:a");
        assert!(require_client_or_worker(&enroller).is_err());
    }

    /// A client over its rate is refused while the others are not; its bucket refills.
    #[test]
    fn each_client_has_its_own_rate() {
        let clients = [
            ("a".to_string(), "a-token-0123456789ab".to_string()),
            ("b".to_string(), "b-token-0123456789ab".to_string()),
        ];
        let mut check = CheckToken::with_clients(&clients, None, WorkerCredentials::default())
            .rate_limited(20.0, 3.0);
        for _ in 0..3 {
            call(&mut check, "a-token-0123456789ab").unwrap();
        }
        let e = call(&mut check, "a-token-0123456789ab").unwrap_err();
        assert_eq!(e.code(), tonic::Code::ResourceExhausted);
        assert!(e.message().contains("client a is over its rate"), "{e:?}");
        call(&mut check, "b-token-0123456789ab").unwrap();
        std::thread::sleep(std::time::Duration::from_millis(120));
        call(&mut check, "a-token-0123456789ab").unwrap();
        // No enrollment token: nobody registers workers.
        let e = call(&mut check, "enroll-token-0123456789").unwrap_err();
        assert_eq!(e.code(), tonic::Code::Unauthenticated);
    }

    #[test]
    fn client_token_files_name_each_token_once() {
        let dir = tempfile::tempdir().unwrap();
        let f = dir.path().join("clients");
        let read = |text: &str| {
            std::fs::write(&f, text).unwrap();
            load_client_tokens(&f).map_err(|e| e.to_string())
        };
        assert_eq!(
            read("# team\nalice alice-token-0123456789\n\n bob  bob-token-0123456789ab \n")
                .unwrap(),
            vec![
                ("alice".into(), "alice-token-0123456789".into()),
                ("bob".into(), "bob-token-0123456789ab".into())
            ]
        );
        for (bad, says) in [
            (
                "alice alice-token-0123456789\nalice other-token-0123456789",
                "named twice",
            ),
            (
                "alice same-token-0123456789\nbob same-token-0123456789",
                "another client's",
            ),
            ("al/ce alice-token-0123456789", "letters, digits"),
            ("alice short", "at least 16"),
            ("alice", "NAME TOKEN"),
            ("# nobody\n", "no client tokens"),
        ] {
            let e = read(bad).unwrap_err();
            assert!(e.contains(says), "{bad:?}: {e}");
        }
    }
}

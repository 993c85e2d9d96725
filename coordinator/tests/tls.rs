//! TLS end to end: a coordinator serving a certificate signed by a private CA, reached by a
//! client that trusts that CA (the deployment in docs/cluster.md "Kubernetes"), and refused to
//! clients that speak plaintext, trust another CA or send the wrong token.

use std::path::Path;
use std::time::Duration;

use bemcal_coordinator::client::Connect;
use bemcal_coordinator::driver::Config;
use bemcal_coordinator::proto::HealthRequest;
use bemcal_coordinator::server::{serve, Options};
use rcgen::{
    BasicConstraints, CertificateParams, CertifiedIssuer, DnType, IsCa, KeyPair, KeyUsagePurpose,
};

const TOKEN: &str = "tls-test-token-0123456789";

/// A self-signed CA.
fn ca(name: &str) -> CertifiedIssuer<'static, KeyPair> {
    let mut params = CertificateParams::new(Vec::<String>::new()).unwrap();
    params.is_ca = IsCa::Ca(BasicConstraints::Unconstrained);
    params.distinguished_name.push(DnType::CommonName, name);
    params.key_usages = vec![KeyUsagePurpose::KeyCertSign, KeyUsagePurpose::CrlSign];
    CertifiedIssuer::self_signed(params, KeyPair::generate().unwrap()).unwrap()
}

/// Writes `ca.pem`, the coordinator's `tls.crt` / `tls.key` for `localhost` signed by it, and
/// `other-ca.pem`, a CA that signed nothing here.
fn write_certificates(dir: &Path) {
    let ca = ca("bemcal test CA");
    let mut params = CertificateParams::new(vec!["localhost".to_string()]).unwrap();
    params
        .distinguished_name
        .push(DnType::CommonName, "bemcal-coordinator");
    let key = KeyPair::generate().unwrap();
    let cert = params.signed_by(&key, &ca).unwrap();
    std::fs::write(dir.join("ca.pem"), ca.pem()).unwrap();
    std::fs::write(dir.join("tls.crt"), cert.pem()).unwrap();
    std::fs::write(dir.join("tls.key"), key.serialize_pem()).unwrap();
    std::fs::write(dir.join("other-ca.pem"), self::ca("another CA").pem()).unwrap();
}

#[test]
fn tls_coordinator_serves_clients_that_trust_its_ca() {
    let dir = tempfile::tempdir().unwrap();
    write_certificates(dir.path());
    let rt = bemcal_coordinator::runtime().unwrap();
    rt.block_on(async {
        let (addr_tx, addr_rx) = tokio::sync::oneshot::channel();
        let (stop_tx, stop_rx) = tokio::sync::oneshot::channel::<()>();
        let opts = Options {
            listen: "127.0.0.1:0".parse().unwrap(),
            data: dir.path().join("coordinator"),
            clients: vec![("default".into(), TOKEN.into())],
            enroll: TOKEN.into(),
            client_rate: 0.0,
            tls: Some((dir.path().join("tls.crt"), dir.path().join("tls.key"))),
            metrics: None,
            config: Config::default(),
        };
        let server = tokio::spawn(serve(
            opts,
            move |a, _| {
                let _ = addr_tx.send(a);
            },
            async move {
                let _ = stop_rx.await;
            },
        ));
        let port = addr_rx.await.expect("the coordinator did not start").port();
        let connect = |scheme: &str, ca: Option<&str>, token: &str| Connect {
            url: format!("{scheme}://localhost:{port}"),
            token: token.into(),
            tls_ca: ca.map(|f| dir.path().join(f)),
        };
        let health = |c: Connect| async move {
            let mut client = c.client().unwrap();
            tokio::time::timeout(Duration::from_secs(20), client.health(HealthRequest {}))
                .await
                .expect("no answer in 20 s")
        };

        // Trusting the CA that signed the coordinator's certificate: served.
        let reply = health(connect("https", Some("ca.pem"), TOKEN)).await;
        let reply = reply.expect("a TLS client trusting the CA was refused");
        assert_eq!(reply.get_ref().queued_jobs, 0);

        // The right CA but the wrong token: refused by the token check, over TLS.
        let wrong = health(connect("https", Some("ca.pem"), "not-the-token-0123456789")).await;
        assert_eq!(
            wrong.expect_err("a wrong token was accepted").code(),
            tonic::Code::Unauthenticated
        );

        // Trusting another CA: the handshake fails, nothing is served.
        let other = health(connect("https", Some("other-ca.pem"), TOKEN)).await;
        let status = other.expect_err("a client trusting another CA was served");
        assert_eq!(status.code(), tonic::Code::Unavailable, "{status}");

        // Plaintext against the TLS port: refused.
        let plain = health(connect("http", None, TOKEN)).await;
        assert!(
            plain.is_err(),
            "a plaintext client was served by the TLS coordinator"
        );

        let _ = stop_tx.send(());
        server.await.unwrap().unwrap();
    });
}

//! The Kubernetes manifests (k8s/) and the Dockerfile, checked as far as a machine without a
//! cluster or a container engine allows: the YAML parses, the names, ports, keys and flags agree
//! with each other and with the `bemcal` CLI, and the probes work against a real coordinator.

use std::collections::BTreeMap;
use std::io::BufRead;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

use serde_yaml_ng::Value;

mod common;

const BIN: &str = env!("CARGO_BIN_EXE_bemcal");

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn k8s_files() -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(root().join("k8s"))
        .expect("k8s/ exists")
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "yaml" || e == "yml"))
        .collect();
    v.sort();
    v
}

fn parse_all(path: &Path) -> Vec<Value> {
    let text = std::fs::read_to_string(path).unwrap();
    serde_yaml_ng::Deserializer::from_str(&text)
        .map(|d| {
            <Value as serde::Deserialize>::deserialize(d)
                .unwrap_or_else(|e| panic!("{}: not YAML: {e}", path.display()))
        })
        .filter(|v| !v.is_null())
        .collect()
}

/// Every object the kustomization deploys (its `resources`), in order.
fn deployed() -> Vec<Value> {
    let k = &parse_all(&root().join("k8s/kustomization.yaml"))[0];
    k["resources"]
        .as_sequence()
        .expect("kustomization resources")
        .iter()
        .flat_map(|r| parse_all(&root().join("k8s").join(r.as_str().unwrap())))
        .collect()
}

fn find<'a>(objs: &'a [Value], kind: &str, name: &str) -> &'a Value {
    objs.iter()
        .find(|o| o["kind"] == kind && o["metadata"]["name"] == name)
        .unwrap_or_else(|| panic!("no {kind} {name} in the kustomization"))
}

fn s(v: &Value) -> &str {
    v.as_str()
        .unwrap_or_else(|| panic!("expected a string, got {v:?}"))
}

fn containers(o: &Value) -> &Vec<Value> {
    o["spec"]["template"]["spec"]["containers"]
        .as_sequence()
        .expect("containers")
}

fn container<'a>(objs: &'a [Value], deployment: &str) -> &'a Value {
    let c = containers(find(objs, "Deployment", deployment));
    assert_eq!(c.len(), 1, "{deployment}: one container");
    &c[0]
}

fn config(objs: &[Value]) -> BTreeMap<String, String> {
    find(objs, "ConfigMap", "bemcal-config")["data"]
        .as_mapping()
        .unwrap()
        .iter()
        .map(|(k, v)| (s(k).to_string(), s(v).to_string()))
        .collect()
}

/// The container's args with `$(VAR)` expanded as the kubelet does, from the ConfigMap
/// (envFrom) and literal env values; an undefined variable fails the test (the kubelet would
/// pass it through verbatim).
fn args(objs: &[Value], deployment: &str) -> Vec<String> {
    let c = container(objs, deployment);
    let mut env = BTreeMap::new();
    for e in c["envFrom"].as_sequence().into_iter().flatten() {
        assert_eq!(s(&e["configMapRef"]["name"]), "bemcal-config");
        env.extend(config(objs));
    }
    for e in c["env"].as_sequence().into_iter().flatten() {
        if let Some(v) = e["value"].as_str() {
            env.insert(s(&e["name"]).to_string(), v.to_string());
        }
    }
    c["args"]
        .as_sequence()
        .expect("args")
        .iter()
        .map(|a| {
            let a = s(a);
            match a.strip_prefix("$(").and_then(|r| r.strip_suffix(')')) {
                Some(var) => env
                    .get(var)
                    .unwrap_or_else(|| panic!("{deployment}: $({var}) is not defined"))
                    .clone(),
                None => {
                    assert!(!a.contains("$("), "{deployment}: partial expansion in {a}");
                    a.to_string()
                }
            }
        })
        .collect()
}

fn flag<'a>(args: &'a [String], name: &str) -> &'a str {
    let i = args
        .iter()
        .position(|a| a == name)
        .unwrap_or_else(|| panic!("{name} missing from {args:?}"));
    &args[i + 1]
}

/// The container's gRPC port (its only port, or the one named `grpc`).
fn container_port(objs: &[Value], deployment: &str) -> u64 {
    let ports = container(objs, deployment)["ports"].as_sequence().unwrap();
    let grpc = match ports.len() {
        1 => &ports[0],
        _ => ports
            .iter()
            .find(|p| p["name"] == "grpc")
            .expect("a port named grpc"),
    };
    grpc["containerPort"].as_u64().unwrap()
}

fn help(sub: &str) -> String {
    let out = Command::new(BIN).args([sub, "--help"]).output().unwrap();
    assert!(out.status.success(), "bemcal {sub} --help failed");
    String::from_utf8(out.stdout).unwrap()
}

#[test]
fn every_manifest_parses_and_the_kustomization_lists_them() {
    let files = k8s_files();
    assert!(files.len() >= 5, "{files:?}");
    let k = &parse_all(&root().join("k8s/kustomization.yaml"))[0];
    assert_eq!(k["kind"], "Kustomization");
    let listed: Vec<&str> = k["resources"]
        .as_sequence()
        .unwrap()
        .iter()
        .map(s)
        .collect();
    for f in &files {
        let docs = parse_all(f);
        assert!(!docs.is_empty(), "{}: empty", f.display());
        let name = f.file_name().unwrap().to_str().unwrap();
        for d in &docs {
            assert!(d["apiVersion"].is_string(), "{name}: apiVersion");
            assert!(d["kind"].is_string(), "{name}: kind");
            if d["kind"] != "Kustomization" {
                assert!(d["metadata"]["name"].is_string(), "{name}: metadata.name");
            }
        }
        // Everything but the kustomization itself and the examples (the Secret, KEDA's
        // ScaledObject) is deployed.
        if name != "kustomization.yaml" && !name.ends_with(".example.yaml") {
            assert!(
                listed.contains(&name),
                "{name} not in kustomization resources"
            );
        }
    }
    for r in &listed {
        assert!(
            root().join("k8s").join(r).exists(),
            "{r} listed but missing"
        );
    }
    // The kinds the deployment needs.
    let objs = deployed();
    find(&objs, "Deployment", "bemcal-coordinator");
    find(&objs, "Service", "bemcal-coordinator");
    find(&objs, "PersistentVolumeClaim", "bemcal-coordinator-data");
    find(&objs, "Deployment", "bemcal-worker");
    find(&objs, "HorizontalPodAutoscaler", "bemcal-worker");
    find(&objs, "ConfigMap", "bemcal-config");
}

#[test]
fn coordinator_is_one_pod_with_its_data_on_the_volume() {
    let objs = deployed();
    let d = find(&objs, "Deployment", "bemcal-coordinator");
    assert_eq!(d["spec"]["replicas"].as_u64(), Some(1));
    assert_eq!(d["spec"]["strategy"]["type"], "Recreate");
    let a = args(&objs, "bemcal-coordinator");
    assert_eq!(a[0], "coordinator");
    let data = flag(&a, "--data");
    let c = container(&objs, "bemcal-coordinator");
    let mount = c["volumeMounts"]
        .as_sequence()
        .unwrap()
        .iter()
        .find(|m| m["mountPath"] == data)
        .unwrap_or_else(|| panic!("--data {data} is not a volume mount"));
    let vol = d["spec"]["template"]["spec"]["volumes"]
        .as_sequence()
        .unwrap()
        .iter()
        .find(|v| v["name"] == mount["name"])
        .unwrap();
    let claim = s(&vol["persistentVolumeClaim"]["claimName"]);
    let pvc = find(&objs, "PersistentVolumeClaim", claim);
    assert!(pvc["spec"]["resources"]["requests"]["storage"].is_string());
    // Its numeric flags parse.
    assert!(flag(&a, "--lease-ttl").parse::<f64>().unwrap() >= 1.0);
    flag(&a, "--max-failures").parse::<u32>().unwrap();
    flag(&a, "--chains-per-job").parse::<usize>().unwrap();
}

#[test]
fn service_container_listen_and_probe_ports_agree() {
    let objs = deployed();
    let a = args(&objs, "bemcal-coordinator");
    let listen: std::net::SocketAddr = flag(&a, "--listen").parse().unwrap();
    assert!(
        listen.ip().is_unspecified(),
        "--listen {listen}: must listen on all interfaces in a pod"
    );
    let port = container_port(&objs, "bemcal-coordinator");
    assert_eq!(listen.port() as u64, port);
    let svc = find(&objs, "Service", "bemcal-coordinator");
    let sp = &svc["spec"]["ports"].as_sequence().unwrap()[0];
    assert_eq!(sp["targetPort"].as_u64(), Some(port));
    // The Service selects the coordinator's pods.
    let labels =
        &find(&objs, "Deployment", "bemcal-coordinator")["spec"]["template"]["metadata"]["labels"];
    for (k, v) in svc["spec"]["selector"].as_mapping().unwrap() {
        assert_eq!(&labels[s(k)], v, "selector {k:?}");
    }
    // The metrics port: --metrics-listen, the container's "metrics" port, the Service's, and
    // the scrape annotation agree.
    let metrics: std::net::SocketAddr = flag(&a, "--metrics-listen").parse().unwrap();
    assert!(metrics.ip().is_unspecified(), "--metrics-listen {metrics}");
    let c = container(&objs, "bemcal-coordinator");
    let named = |ports: &Value, key: &str| -> Option<u64> {
        ports
            .as_sequence()?
            .iter()
            .find(|p| p["name"] == "metrics")?[key]
            .as_u64()
    };
    assert_eq!(
        named(&c["ports"], "containerPort"),
        Some(metrics.port() as u64)
    );
    assert_eq!(
        named(&svc["spec"]["ports"], "targetPort"),
        Some(metrics.port() as u64)
    );
    let annotations = &find(&objs, "Deployment", "bemcal-coordinator")["spec"]["template"]
        ["metadata"]["annotations"];
    assert_eq!(
        annotations["prometheus.io/port"],
        metrics.port().to_string().as_str()
    );
    // Probes: native gRPC probes (grpc.health.v1.Health/Check) on that port.
    let c = container(&objs, "bemcal-coordinator");
    for p in ["startupProbe", "readinessProbe", "livenessProbe"] {
        assert_eq!(c[p]["grpc"]["port"].as_u64(), Some(port), "{p}");
        let svc = c[p]["grpc"]["service"].as_str().unwrap_or("");
        assert!(
            svc.is_empty() || svc == "bemcal.v1.Coordinator",
            "{p}: service {svc}"
        );
    }
}

#[test]
fn worker_points_at_the_coordinator_service() {
    let objs = deployed();
    let a = args(&objs, "bemcal-worker");
    assert_eq!(a[0], "worker");
    let url = flag(&a, "--coordinator");
    let rest = url
        .strip_prefix("http://")
        .expect("plain http inside the cluster");
    let (host, port) = rest.trim_end_matches('/').rsplit_once(':').unwrap();
    let svc = find(&objs, "Service", "bemcal-coordinator");
    let name = s(&svc["metadata"]["name"]);
    assert!(
        host == name || host.starts_with(&format!("{name}.")),
        "{url}: host is not the Service {name}"
    );
    let sp = &svc["spec"]["ports"].as_sequence().unwrap()[0];
    assert_eq!(port.parse::<u64>().ok(), sp["port"].as_u64());
    // The readiness probe uses the same URL (from the ConfigMap, through the environment).
    let probe = &container(&objs, "bemcal-worker")["readinessProbe"]["exec"]["command"];
    let cmd: Vec<&str> = probe.as_sequence().unwrap().iter().map(s).collect();
    assert_eq!(cmd[..2], ["sh", "-c"]);
    assert!(cmd[2].contains("bemcal status --health --coordinator \"$BEMCAL_COORDINATOR\""));
    assert_eq!(config(&objs)["BEMCAL_COORDINATOR"], url);
    // Slots and drain parse; the grace period covers the drain and the 10 s give-back.
    assert!(flag(&a, "--slots").parse::<usize>().unwrap() >= 1);
    let drain: u64 = flag(&a, "--drain").parse().unwrap();
    let grace = find(&objs, "Deployment", "bemcal-worker")["spec"]["template"]["spec"]
        ["terminationGracePeriodSeconds"]
        .as_u64()
        .unwrap();
    assert!(
        grace >= drain + 10,
        "grace {grace} s < drain {drain} s + 10 s"
    );
}

#[test]
fn token_secret_key_matches_every_reference() {
    let secret = &parse_all(&root().join("k8s/secret.example.yaml"))[0];
    assert_eq!(secret["kind"], "Secret");
    let name = s(&secret["metadata"]["name"]);
    let keys: Vec<&str> = secret["stringData"]
        .as_mapping()
        .unwrap()
        .keys()
        .map(s)
        .collect();
    // The placeholders must not be usable tokens (spaces: bemcal refuses them).
    for k in &keys {
        assert!(s(&secret["stringData"][*k]).contains(' '), "{k}");
    }
    let objs = deployed();
    assert!(
        !objs.iter().any(|o| o["kind"] == "Secret"),
        "a Secret in the kustomization would overwrite the real token on every apply"
    );
    for d in ["bemcal-coordinator", "bemcal-worker"] {
        let env = container(&objs, d)["env"].as_sequence().unwrap();
        let tok = env
            .iter()
            .find(|e| e["name"] == "BEMCAL_TOKEN")
            .unwrap_or_else(|| panic!("{d}: no BEMCAL_TOKEN"));
        let r = &tok["valueFrom"]["secretKeyRef"];
        assert_eq!(s(&r["name"]), name, "{d}");
        assert!(keys.contains(&s(&r["key"])), "{d}: key {:?}", r["key"]);
    }
    // Workers carry the worker token, which the coordinator knows as its worker token, and
    // which is not the clients' token.
    let key_of = |d: &str, var: &str| -> String {
        let env = container(&objs, d)["env"].as_sequence().unwrap();
        let e = env
            .iter()
            .find(|e| e["name"] == var)
            .unwrap_or_else(|| panic!("{d}: no {var}"));
        s(&e["valueFrom"]["secretKeyRef"]["key"]).to_string()
    };
    let worker_key = key_of("bemcal-worker", "BEMCAL_TOKEN");
    assert_eq!(
        worker_key,
        key_of("bemcal-coordinator", "BEMCAL_WORKER_TOKEN")
    );
    assert_ne!(worker_key, key_of("bemcal-coordinator", "BEMCAL_TOKEN"));
    assert!(keys.contains(&worker_key.as_str()));
}

#[test]
fn every_container_has_resource_requests_and_limits() {
    fn mem_bytes(q: &str) -> f64 {
        for (suf, m) in [
            ("Ki", 1024f64),
            ("Mi", 1024f64.powi(2)),
            ("Gi", 1024f64.powi(3)),
        ] {
            if let Some(n) = q.strip_suffix(suf) {
                return n.parse::<f64>().unwrap() * m;
            }
        }
        q.parse().unwrap()
    }
    fn cpu(q: &str) -> f64 {
        match q.strip_suffix('m') {
            Some(n) => n.parse::<f64>().unwrap() / 1000.0,
            None => q.parse().unwrap(),
        }
    }
    let objs = deployed();
    let deployments: Vec<&Value> = objs.iter().filter(|o| o["kind"] == "Deployment").collect();
    assert_eq!(deployments.len(), 2);
    for d in deployments {
        for c in containers(d) {
            let r = &c["resources"];
            let who = format!("{}/{}", s(&d["metadata"]["name"]), s(&c["name"]));
            let (rc, lc) = (cpu(s(&r["requests"]["cpu"])), cpu(s(&r["limits"]["cpu"])));
            let (rm, lm) = (
                mem_bytes(s(&r["requests"]["memory"])),
                mem_bytes(s(&r["limits"]["memory"])),
            );
            assert!(rc > 0.0 && lc >= rc, "{who}: cpu {rc} / {lc}");
            assert!(rm > 0.0 && lm >= rm, "{who}: memory {rm} / {lm}");
        }
    }
    // A worker slot runs the largest job kind: surrogate training (PyTorch, ~1-2 GB RSS) and
    // one EnergyPlus core.
    let r = &container(&objs, "bemcal-worker")["resources"];
    assert!(mem_bytes(s(&r["limits"]["memory"])) >= 2.0 * 1024f64.powi(3));
    assert!(cpu(s(&r["requests"]["cpu"])) >= 1.0);
}

#[test]
fn hpa_scales_the_worker_deployment_on_cpu() {
    let objs = deployed();
    let h = find(&objs, "HorizontalPodAutoscaler", "bemcal-worker");
    assert_eq!(h["apiVersion"], "autoscaling/v2");
    let t = &h["spec"]["scaleTargetRef"];
    assert_eq!(t["apiVersion"], "apps/v1");
    assert_eq!(t["kind"], "Deployment");
    find(&objs, "Deployment", s(&t["name"]));
    assert_eq!(s(&t["name"]), "bemcal-worker");
    let m = &h["spec"]["metrics"].as_sequence().unwrap()[0];
    assert_eq!(m["type"], "Resource");
    assert_eq!(m["resource"]["name"], "cpu");
    assert_eq!(m["resource"]["target"]["type"], "Utilization");
    let (lo, hi) = (
        h["spec"]["minReplicas"].as_u64().unwrap(),
        h["spec"]["maxReplicas"].as_u64().unwrap(),
    );
    assert!(1 <= lo && lo <= hi);
    // The HPA owns the replica count: a fixed one in the Deployment would fight it on apply.
    assert!(find(&objs, "Deployment", "bemcal-worker")["spec"]["replicas"].is_null());
}

#[test]
fn every_flag_in_the_manifests_is_one_the_cli_takes() {
    let objs = deployed();
    let mut used = 0;
    for d in ["bemcal-coordinator", "bemcal-worker"] {
        let a = args(&objs, d);
        let h = help(&a[0]);
        for f in a.iter().filter(|a| a.starts_with("--")) {
            assert!(h.contains(&format!("{f} ")), "bemcal {}: no flag {f}", a[0]);
            used += 1;
        }
    }
    // The worker's readiness probe runs `bemcal status --health --coordinator`.
    assert!(help("status").contains("--coordinator "));
    assert!(used >= 8);
}

#[test]
fn dockerfile_builds_bemcal_and_installs_its_runtime() {
    let df = std::fs::read_to_string(root().join("Dockerfile")).unwrap();
    let lines: Vec<&str> = df
        .lines()
        .map(str::trim)
        .filter(|l| !l.starts_with('#'))
        .collect();
    let from: Vec<&str> = lines
        .iter()
        .copied()
        .filter(|l| l.starts_with("FROM "))
        .collect();
    assert_eq!(from.len(), 2, "multi-stage: {from:?}");
    assert!(from[0].starts_with("FROM rust:1-bookworm AS "));
    assert!(from[1].starts_with("FROM python:3.11-slim-bookworm"));
    assert!(df.contains("cargo build --release --locked -p bemcal"));
    assert!(df.contains("libx11-6"));
    assert!(df.contains("python/requirements.txt"));
    assert!(df.contains("-r /opt/bemcal/requirements.txt"));
    // The Makefile's exec bits for the EnergyPlus payload tools.
    for t in [
        "energyplus",
        "ExpandObjects",
        "ConvertInputFormat",
        "EPMacro",
        "ReadVarsESO",
    ] {
        assert!(
            df.contains(&format!("$payload/{t}")) || df.contains(&format!("/{t}\"")),
            "{t}"
        );
    }
    assert!(df.contains("BEMCAL_VENV=/opt/bemcal/venv"));
    assert!(df.contains("COPY --from=build /usr/local/bin/bemcal /usr/local/bin/bemcal"));
    assert_eq!(
        lines.iter().rev().find(|l| l.starts_with("ENTRYPOINT")),
        Some(&r#"ENTRYPOINT ["bemcal"]"#)
    );
    // Non-root, with the uid the pods' securityContext runs as.
    let user = lines
        .iter()
        .rev()
        .find_map(|l| l.strip_prefix("USER "))
        .unwrap();
    let uid: u64 = user.split(':').next().unwrap().parse().unwrap();
    assert_ne!(uid, 0);
    let objs = deployed();
    for d in ["bemcal-coordinator", "bemcal-worker"] {
        let sc = &find(&objs, "Deployment", d)["spec"]["template"]["spec"]["securityContext"];
        assert_eq!(sc["runAsUser"].as_u64(), Some(uid), "{d}");
        assert_eq!(sc["runAsNonRoot"].as_bool(), Some(true), "{d}");
        assert_eq!(
            container(&objs, d)["image"],
            "bemcal",
            "{d}: image (set by kustomize)"
        );
    }
    // The ENTRYPOINT binary carries the subcommands the manifests run.
    for sub in ["coordinator", "worker", "status", "submit"] {
        help(sub);
    }
    // The build context leaves out build outputs and the local venv.
    let ignore = std::fs::read_to_string(root().join(".dockerignore")).unwrap();
    for p in ["target", ".venv", ".git"] {
        assert!(ignore.lines().any(|l| l.trim() == p), ".dockerignore: {p}");
    }
}

/// The probes against a real coordinator started with the manifests' flags (on loopback): the
/// standard gRPC health service answers SERVING without a token (what the kubelet's `grpc`
/// probe calls, for the overall server and the readiness probe's service name), the worker's
/// readiness command succeeds with the token and fails without the right one.
#[test]
fn probes_pass_against_a_real_coordinator() {
    let objs = deployed();
    let mut a = args(&objs, "bemcal-coordinator");
    let dir = tempfile::tempdir().unwrap();
    *a.iter_mut()
        .skip_while(|x| *x != "--listen")
        .nth(1)
        .unwrap() = "127.0.0.1:0".into();
    *a.iter_mut().skip_while(|x| *x != "--data").nth(1).unwrap() =
        dir.path().join("data").to_str().unwrap().into();
    *a.iter_mut()
        .skip_while(|x| *x != "--metrics-listen")
        .nth(1)
        .unwrap() = "127.0.0.1:0".into();
    let token = "k8s-test-token-0123456789abcdef";
    let mut child = Command::new(BIN)
        .args(&a)
        .env("BEMCAL_TOKEN", token)
        .stdout(Stdio::piped())
        .spawn()
        .unwrap();
    struct Kill(std::process::Child);
    impl Drop for Kill {
        fn drop(&mut self) {
            let _ = self.0.kill();
            let _ = self.0.wait();
        }
    }
    let mut line = String::new();
    let mut reader = std::io::BufReader::new(child.stdout.take().unwrap());
    reader.read_line(&mut line).unwrap();
    let _guard = Kill(child);
    let addr = line
        .trim()
        .strip_prefix("listening on ")
        .unwrap()
        .to_string();
    let url = format!("http://{addr}");
    // The metrics port the manifests open answers a scrape, without a token.
    let mut line = String::new();
    reader.read_line(&mut line).unwrap();
    let metrics = line.trim().strip_prefix("metrics on ").unwrap().to_string();
    let (code, page) = common::http_get(&metrics);
    assert_eq!(code, 200, "{page}");
    assert!(
        page.contains("bemcal_jobs{kind=\"simulate\",state=\"queued\"} 0"),
        "{page}"
    );

    let coord = container(&objs, "bemcal-coordinator");
    let services: Vec<String> = ["startupProbe", "readinessProbe", "livenessProbe"]
        .iter()
        .map(|p| {
            coord[*p]["grpc"]["service"]
                .as_str()
                .unwrap_or("")
                .to_string()
        })
        .collect();
    let rt = tokio::runtime::Runtime::new().unwrap();
    rt.block_on(async {
        use tonic_health::pb::health_check_response::ServingStatus;
        use tonic_health::pb::{health_client::HealthClient, HealthCheckRequest};
        let ch = tonic::transport::Endpoint::from_shared(url.clone())
            .unwrap()
            .connect()
            .await
            .unwrap();
        let mut c = HealthClient::new(ch);
        for svc in &services {
            let t0 = std::time::Instant::now();
            loop {
                let r = c
                    .check(HealthCheckRequest {
                        service: svc.clone(),
                    })
                    .await;
                match r {
                    Ok(r) if r.get_ref().status == ServingStatus::Serving as i32 => break,
                    other if t0.elapsed().as_secs() >= 10 => {
                        panic!("health of {svc:?}: {other:?}")
                    }
                    _ => tokio::time::sleep(std::time::Duration::from_millis(100)).await,
                }
            }
        }
    });

    // The worker readiness probe's command, as the kubelet runs it in the container.
    let probe = &container(&objs, "bemcal-worker")["readinessProbe"]["exec"]["command"];
    let cmd: Vec<String> = probe
        .as_sequence()
        .unwrap()
        .iter()
        .map(|x| s(x).to_string())
        .collect();
    let bin_dir = Path::new(BIN).parent().unwrap();
    let path = format!(
        "{}:{}",
        bin_dir.display(),
        std::env::var("PATH").unwrap_or_default()
    );
    let run = |tok: &str| {
        Command::new(&cmd[0])
            .args(&cmd[1..])
            .env("PATH", &path)
            .env("BEMCAL_COORDINATOR", &url)
            .env("BEMCAL_TOKEN", tok)
            .stderr(Stdio::null())
            .status()
            .unwrap()
    };
    assert!(run(token).success(), "worker readiness probe failed");
    assert!(
        !run("wrong-token-0123456789abcdef").success(),
        "the probe must fail with a wrong token"
    );
}

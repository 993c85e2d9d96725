//! Prometheus metrics of the coordinator, served as text at `GET /metrics` on their own
//! address (`bemcal coordinator --metrics-listen`), without a token, as Kubernetes scrapes.
//!
//! Every figure is computed at scrape time from the database ([`crate::db::Store::metrics_snapshot`]):
//! the counters (attempts by outcome, lease expiries) are counts of durable rows, so they never
//! go back after a restart, and two coordinators' figures cannot disagree with their state.
//! `bemcal_jobs{state="queued"}` is the queue depth that worker autoscaling reads (KEDA's
//! Prometheus scaler; see docs/operations.md).

use std::sync::Arc;

use prometheus_client::encoding::text::encode;
use prometheus_client::encoding::EncodeLabelSet;
use prometheus_client::metrics::counter::Counter;
use prometheus_client::metrics::family::Family;
use prometheus_client::metrics::gauge::Gauge;
use prometheus_client::metrics::histogram::Histogram;
use prometheus_client::registry::{Registry, Unit};

use crate::db::MetricsSnapshot;
use crate::driver::State;
use crate::states::{JobKind, JobState, RunState};

#[derive(Clone, Debug, Hash, PartialEq, Eq, EncodeLabelSet)]
struct KindState {
    kind: String,
    state: String,
}

#[derive(Clone, Debug, Hash, PartialEq, Eq, EncodeLabelSet)]
struct KindOutcome {
    kind: String,
    outcome: String,
}

#[derive(Clone, Debug, Hash, PartialEq, Eq, EncodeLabelSet)]
struct OfState {
    state: String,
}

#[derive(Clone, Debug, Hash, PartialEq, Eq, EncodeLabelSet)]
struct Kind {
    kind: String,
}

/// The exposition text (OpenMetrics) of a snapshot. Every kind and state is present, at 0
/// when none is, so that a dashboard's series exist before the first job.
pub fn render(s: &MetricsSnapshot) -> String {
    let mut registry = Registry::with_prefix("bemcal");
    register_jobs(&mut registry, s);
    register_runs(&mut registry, s);
    register_attempts(&mut registry, s);
    register_durations(&mut registry, s);
    register_store(&mut registry, s);

    let mut text = String::new();
    encode(&mut text, &registry).expect("writing to a String cannot fail");
    text
}

/// Jobs by kind and state, every pair present (0 where none).
fn register_jobs(registry: &mut Registry, s: &MetricsSnapshot) {
    let jobs = Family::<KindState, Gauge>::default();
    for kind in JobKind::ALL {
        for state in JobState::ALL {
            let _ = jobs.get_or_create(&labels(kind.as_str(), state.as_str()));
        }
    }
    for (kind, state, n) in &s.jobs {
        jobs.get_or_create(&labels(kind, state)).set(*n as i64);
    }
    registry.register(
        "jobs",
        "Jobs by kind and state (queued = the queue depth)",
        jobs,
    );
}

/// Runs by state, every state present.
fn register_runs(registry: &mut Registry, s: &MetricsSnapshot) {
    let runs = Family::<OfState, Gauge>::default();
    for state in RunState::ALL {
        let _ = runs.get_or_create(&OfState {
            state: state.as_str().into(),
        });
    }
    for (state, n) in &s.runs {
        runs.get_or_create(&OfState {
            state: state.clone(),
        })
        .set(*n as i64);
    }
    registry.register("runs", "Runs by state", runs);
}

/// Leases that ended, by kind and outcome, and the lease expiries among them.
fn register_attempts(registry: &mut Registry, s: &MetricsSnapshot) {
    let attempts = Family::<KindOutcome, Counter>::default();
    for kind in JobKind::ALL {
        for outcome in ["done", "failed", "lost", "returned", "stale", "refused"] {
            let _ = attempts.get_or_create(&KindOutcome {
                kind: kind.as_str().into(),
                outcome: outcome.into(),
            });
        }
    }
    for (kind, outcome, n) in &s.attempts {
        attempts
            .get_or_create(&KindOutcome {
                kind: kind.clone(),
                outcome: outcome.clone(),
            })
            .inc_by(*n);
    }
    registry.register(
        "job_attempts",
        "Leases that ended, by job kind and outcome (done; failed: the worker reported an error; \
         lost: the lease expired without heartbeats; returned: given back; stale: a late duplicate; \
         refused: outputs past the run's quota)",
        attempts,
    );

    let lost: u64 = s
        .attempts
        .iter()
        .filter(|(_, o, _)| o == "lost")
        .map(|(_, _, n)| n)
        .sum();
    let expiries = Counter::<u64>::default();
    expiries.inc_by(lost);
    registry.register(
        "lease_expiries",
        "Leases that expired without heartbeats",
        expiries,
    );
}

/// Wall time of the finished attempts, per job kind.
fn register_durations(registry: &mut Registry, s: &MetricsSnapshot) {
    let durations = Family::<Kind, Histogram>::new_with_constructor(|| {
        Histogram::new(bemcal_client::metrics::DURATION_BUCKETS.iter().copied())
    });
    for kind in JobKind::ALL {
        let _ = durations.get_or_create(&Kind {
            kind: kind.as_str().into(),
        });
    }
    for (kind, seconds) in &s.durations {
        durations
            .get_or_create(&Kind { kind: kind.clone() })
            .observe(*seconds);
    }
    registry.register_with_unit(
        "job_duration",
        "Wall time of the attempts that finished their job, lease to completion",
        Unit::Seconds,
        durations,
    );
}

/// Bytes held in the artifact store.
fn register_store(registry: &mut Registry, s: &MetricsSnapshot) {
    let store = Gauge::<i64>::default();
    store.set(s.artifact_bytes as i64);
    registry.register_with_unit(
        "artifact_store",
        "Bytes held in the artifact store",
        Unit::Bytes,
        store,
    );
}

fn labels(kind: &str, state: &str) -> KindState {
    KindState {
        kind: kind.into(),
        state: state.into(),
    }
}

/// Serves `GET /metrics` on `addr` in the background until `shutdown` completes (each scrape
/// reads a snapshot of the database off the async threads and renders it); returns the bound
/// address.
pub async fn spawn(
    st: Arc<State>,
    addr: std::net::SocketAddr,
    shutdown: impl std::future::Future<Output = ()> + Send + 'static,
) -> anyhow::Result<std::net::SocketAddr> {
    let scrape = move || {
        let st = st.clone();
        async move {
            match tokio::task::spawn_blocking(move || st.store.metrics_snapshot()).await {
                Ok(Ok(s)) => Ok(render(&s)),
                Ok(Err(e)) => Err(format!("database: {e}")),
                Err(e) => Err(e.to_string()),
            }
        }
    };
    bemcal_client::metrics::spawn(addr, scrape, shutdown).await
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_snapshot_renders_every_family_with_its_counts() {
        let s = MetricsSnapshot {
            jobs: vec![
                ("simulate".into(), "queued".into(), 7),
                ("train".into(), "leased".into(), 1),
            ],
            runs: vec![("running".into(), 2)],
            attempts: vec![
                ("simulate".into(), "done".into(), 12),
                ("simulate".into(), "lost".into(), 2),
            ],
            durations: vec![("simulate".into(), 3.0), ("simulate".into(), 40.0)],
            artifact_bytes: 4096,
        };
        let text = render(&s);
        for line in [
            "bemcal_jobs{kind=\"simulate\",state=\"queued\"} 7",
            "bemcal_jobs{kind=\"chains\",state=\"queued\"} 0",
            "bemcal_runs{state=\"running\"} 2",
            "bemcal_job_attempts_total{kind=\"simulate\",outcome=\"done\"} 12",
            "bemcal_lease_expiries_total 2",
            "bemcal_job_duration_seconds_count{kind=\"simulate\"} 2",
            "bemcal_job_duration_seconds_bucket{le=\"5.0\",kind=\"simulate\"} 1",
            "bemcal_artifact_store_bytes 4096",
        ] {
            assert!(text.contains(line), "no `{line}` in\n{text}");
        }
        assert!(text.ends_with("# EOF\n"));
    }
}

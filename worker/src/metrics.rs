//! A worker's own Prometheus metrics (`bemcal worker --metrics-listen`): jobs it finished by
//! kind and outcome, their durations, and its busy slots. In-process counters (a worker keeps
//! no state across restarts; the coordinator's `/metrics` holds the durable totals).

use std::sync::Arc;
use std::time::Duration;

use bemcal_client::proto::{self, job::Kind};
use prometheus_client::encoding::text::encode;
use prometheus_client::encoding::EncodeLabelSet;
use prometheus_client::metrics::counter::Counter;
use prometheus_client::metrics::family::Family;
use prometheus_client::metrics::gauge::Gauge;
use prometheus_client::metrics::histogram::Histogram;
use prometheus_client::registry::{Registry, Unit};

/// How a job ended on this worker.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Outcome {
    /// Completed and reported.
    Done,
    /// Failed (the error was reported).
    Failed,
    /// Given back at shutdown.
    Returned,
}

impl Outcome {
    fn as_str(self) -> &'static str {
        match self {
            Outcome::Done => "done",
            Outcome::Failed => "failed",
            Outcome::Returned => "returned",
        }
    }
}

#[derive(Clone, Debug, Hash, PartialEq, Eq, EncodeLabelSet)]
struct KindOutcome {
    kind: &'static str,
    outcome: &'static str,
}

#[derive(Clone, Debug, Hash, PartialEq, Eq, EncodeLabelSet)]
struct OfKind {
    kind: &'static str,
}

/// The worker's metrics; cheap to share (`Arc`).
pub struct Metrics {
    registry: Registry,
    jobs: Family<KindOutcome, Counter>,
    durations: Family<OfKind, Histogram>,
    busy: Gauge,
}

/// A job's kind as the coordinator's metrics name it.
pub fn kind_name(job: &proto::Job) -> &'static str {
    match job.kind {
        Some(Kind::Simulate(_)) => "simulate",
        Some(Kind::Train(_)) => "train",
        Some(Kind::Chains(_)) => "chains",
        Some(Kind::Validate(_)) => "validate",
        Some(Kind::Measure(_)) => "measure",
        None => "unknown",
    }
}

impl Metrics {
    /// Metrics of a worker with `slots` slots.
    pub fn new(slots: usize) -> Arc<Metrics> {
        let mut registry = Registry::with_prefix("bemcal_worker");
        let jobs = Family::<KindOutcome, Counter>::default();
        let durations = Family::<OfKind, Histogram>::new_with_constructor(|| {
            Histogram::new(bemcal_client::metrics::DURATION_BUCKETS.iter().copied())
        });
        let busy = Gauge::default();
        let total = Gauge::<i64>::default();
        total.set(slots as i64);
        for kind in ["simulate", "train", "chains", "validate"] {
            for outcome in [Outcome::Done, Outcome::Failed, Outcome::Returned] {
                let _ = jobs.get_or_create(&KindOutcome {
                    kind,
                    outcome: outcome.as_str(),
                });
            }
            let _ = durations.get_or_create(&OfKind { kind });
        }
        registry.register(
            "jobs",
            "Jobs this worker ended, by kind and outcome",
            jobs.clone(),
        );
        registry.register_with_unit(
            "job_duration",
            "Wall time of the jobs this worker completed, lease to report",
            Unit::Seconds,
            durations.clone(),
        );
        registry.register("busy_slots", "Slots running a job now", busy.clone());
        registry.register("slots", "Jobs this worker runs at once", total);
        Arc::new(Metrics {
            registry,
            jobs,
            durations,
            busy,
        })
    }

    /// A job started.
    pub fn started(&self) {
        self.busy.inc();
    }

    /// A job of `kind` ended with `outcome` after `took`.
    pub fn ended(&self, kind: &'static str, outcome: Outcome, took: Duration) {
        self.busy.dec();
        self.jobs
            .get_or_create(&KindOutcome {
                kind,
                outcome: outcome.as_str(),
            })
            .inc();
        if outcome == Outcome::Done {
            self.durations
                .get_or_create(&OfKind { kind })
                .observe(took.as_secs_f64());
        }
    }

    /// The exposition text.
    pub fn render(&self) -> String {
        let mut text = String::new();
        encode(&mut text, &self.registry).expect("writing to a String cannot fail");
        text
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn jobs_are_counted_by_kind_and_outcome() {
        let m = Metrics::new(2);
        m.started();
        m.started();
        m.ended("simulate", Outcome::Done, Duration::from_secs(3));
        let text = m.render();
        assert!(text.contains("bemcal_worker_busy_slots 1"), "{text}");
        assert!(text.contains("bemcal_worker_slots 2"), "{text}");
        assert!(
            text.contains("bemcal_worker_jobs_total{kind=\"simulate\",outcome=\"done\"} 1"),
            "{text}"
        );
        assert!(
            text.contains("bemcal_worker_job_duration_seconds_count{kind=\"simulate\"} 1"),
            "{text}"
        );
    }
}

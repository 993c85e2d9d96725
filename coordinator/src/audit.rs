//! The audit trail: who did what, when. Every submission, resumption and cancellation (with the
//! client), every worker registered or revoked, every lease, completion, failure, return and
//! lost lease (with the worker and the reason), and every refusal (a worker that is not the
//! lease's, a revoked credential, a result that fails its checks, a client over its limits) is
//! a row of the `audit` table ([`crate::db::Store::audit`]), written in the same transaction as
//! the change it records where there is one, and a `tracing` event ([`emit`]; leases and
//! completions at the `debug` level).

use serde::Serialize;

/// One event of the audit trail.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Event {
    /// When, ms since the Unix epoch.
    pub ms: u64,
    /// Who: `client:NAME`, `worker:ID`, `enroller`, `coordinator` (its own decisions) or
    /// `operator` (`bemcal coordinator revoke-worker`).
    pub actor: String,
    /// What: `submit`, `resume`, `cancel`, `register`, `revoke`, `lease`, `complete`, `fail`,
    /// `return`, `lost`, or `refuse-...` for a refusal.
    pub action: String,
    /// The run concerned, if any.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub run: Option<String>,
    /// The job concerned, if any.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub job: Option<u64>,
    /// The lease concerned, if any.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub lease: Option<u64>,
    /// Why, or what was done (a job's label, an error, a refusal's reason).
    pub detail: String,
}

impl Event {
    /// `actor` did `action`, now.
    pub fn new(actor: impl Into<String>, action: &str) -> Event {
        Event {
            ms: crate::now_ms(),
            actor: actor.into(),
            action: action.into(),
            run: None,
            job: None,
            lease: None,
            detail: String::new(),
        }
    }

    /// ... to run `run`.
    pub fn run(mut self, run: &str) -> Event {
        self.run = Some(run.to_string());
        self
    }

    /// ... to job `job`.
    pub fn job(mut self, job: u64) -> Event {
        self.job = Some(job);
        self
    }

    /// ... under lease `lease`.
    pub fn lease(mut self, lease: u64) -> Event {
        self.lease = Some(lease);
        self
    }

    /// ... saying `detail` (cut to [`crate::MAX_ERROR_BYTES`]).
    pub fn detail(mut self, detail: impl AsRef<str>) -> Event {
        self.detail = crate::excerpt(detail.as_ref(), crate::MAX_ERROR_BYTES).into_owned();
        self
    }

    /// Whether the event is routine (leases and completions: logged only at `debug`).
    pub fn routine(&self) -> bool {
        matches!(self.action.as_str(), "lease" | "complete")
    }

    /// The event as one line of text.
    pub fn text(&self) -> String {
        let mut s = format!("{} {} {}", self.ms, self.action, self.actor);
        if let Some(r) = &self.run {
            s.push_str(&format!(" run={r}"));
        }
        if let Some(j) = self.job {
            s.push_str(&format!(" job={j}"));
        }
        if let Some(l) = self.lease {
            s.push_str(&format!(" lease={l}"));
        }
        if !self.detail.is_empty() {
            s.push_str(&format!(": {}", self.detail.replace('\n', " | ")));
        }
        s
    }
}

/// Logs `ev` through `tracing` (target `bemcal::audit`, structured fields `actor`, `action`,
/// `run`, `job`, `lease`, `detail`): routine leases and completions at `debug`, the rest at
/// `info`. The binary's subscriber decides what is written and how (text or JSON, `RUST_LOG`).
pub fn emit(ev: &Event) {
    macro_rules! event {
        ($level:expr) => {
            tracing::event!(
                target: "bemcal::audit",
                $level,
                actor = %ev.actor,
                action = %ev.action,
                run = ev.run.as_deref(),
                job = ev.job,
                lease = ev.lease,
                detail = %ev.detail,
            )
        };
    }
    match ev.routine() {
        true => event!(tracing::Level::DEBUG),
        false => event!(tracing::Level::INFO),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_event_reads_as_one_line_of_text_or_json() {
        let ev = Event::new("worker:w1-0a1b", "refuse-complete")
            .run("r1")
            .job(3)
            .lease(77)
            .detail("lease 77 belongs to worker:w0-ffff\nsecond line");
        let t = ev.text();
        assert!(
            t.ends_with(
                "refuse-complete worker:w1-0a1b run=r1 job=3 lease=77: lease 77 belongs to \
                 worker:w0-ffff | second line"
            ),
            "{t}"
        );
        let v = serde_json::to_value(&ev).unwrap();
        assert_eq!(v["actor"], "worker:w1-0a1b");
        assert_eq!(v["lease"], 77);
        let bare = serde_json::to_value(Event::new("client:a", "cancel")).unwrap();
        assert!(bare.get("run").is_none(), "{bare}");
        assert!(Event::new("w", "lease").routine() && !Event::new("w", "fail").routine());
    }
}

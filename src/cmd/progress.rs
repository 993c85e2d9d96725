//! How a long command shows its progress (`calibrate`, `portfolio run`, `watch`): lines for
//! people (`--progress text`, the default: on a terminal, a bar per stage updated in place by
//! `indicatif`, the log lines above them; elsewhere plain lines) or one JSON object a line for programs
//! (`--progress json`: the Python module, notebooks, log shippers). Both are written here, from
//! the same events, so that neither has to be parsed out of the other.
//!
//! The JSON events, each with `event` and `elapsed_s` (seconds since the command started):
//! - `{"event": "log", "message": ...}`: a line of the calibration's log (the driver's messages,
//!   what was reused or resumed);
//! - `{"event": "run", "run": ..., "state": ..., "stage": ..., "stages": [{"stage", "state",
//!   "done", "total", "running", "worker_seconds"}, ...]}`: a coordinator run's progress, each
//!   time it changes;
//! - `{"event": "building", "building": ..., "run": ..., "state": ..., "stage": ...,
//!   "progress": ...}`: a portfolio building's state or stage changed.

use std::io::{IsTerminal, Write};
use std::sync::{Arc, Mutex};
use std::time::Instant;

use indicatif::{MultiProgress, ProgressBar, ProgressDrawTarget, ProgressStyle};

use bemcal_client::proto::RunStatus;

/// `--progress`: how progress is written.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, clap::ValueEnum)]
pub enum ProgressFormat {
    /// Lines for people: `[   12.3 s] message`; a run's stages as a bar each (on a terminal,
    /// redrawn in place).
    #[default]
    Text,
    /// One JSON object a line (module docs).
    Json,
}

/// Where progress goes.
#[derive(Debug, Clone, Copy)]
pub enum Sink {
    /// Standard error: the command's results go to standard output.
    Stderr,
    /// Standard output: progress is the command's output (`watch`).
    Stdout,
}

/// Writes a command's progress events in its format.
#[derive(Debug, Clone)]
pub struct Progress {
    format: ProgressFormat,
    sink: Sink,
    t0: Instant,
    /// Text on a terminal: the stages' bars, drawn in place.
    bars: Option<Arc<Mutex<Bars>>>,
}

impl Progress {
    /// Progress in `format` to `sink`, its clock started now; text on a terminal gets bars.
    pub fn new(format: ProgressFormat, sink: Sink) -> Progress {
        let terminal = match sink {
            Sink::Stderr => std::io::stderr().is_terminal(),
            Sink::Stdout => std::io::stdout().is_terminal(),
        };
        let bars = (format == ProgressFormat::Text && terminal).then(|| {
            let target = match sink {
                Sink::Stderr => ProgressDrawTarget::stderr(),
                Sink::Stdout => ProgressDrawTarget::stdout(),
            };
            Arc::new(Mutex::new(Bars::new(target)))
        });
        Progress {
            format,
            sink,
            t0: Instant::now(),
            bars,
        }
    }

    fn elapsed(&self) -> f64 {
        self.t0.elapsed().as_secs_f64()
    }

    fn write(&self, text: &str) {
        if let Some(b) = &self.bars {
            // Above the bars, which are drawn again below it.
            if let Ok(b) = b.lock() {
                let _ = b.multi.println(text);
                return;
            }
        }
        // A closed pipe must not stop a calibration: progress is lost, the results are not.
        let _ = match self.sink {
            Sink::Stderr => writeln!(std::io::stderr().lock(), "{text}"),
            Sink::Stdout => writeln!(std::io::stdout().lock(), "{text}"),
        };
    }

    fn json(&self, mut event: serde_json::Value) {
        event["elapsed_s"] = ((self.elapsed() * 10.0).round() / 10.0).into();
        self.write(&event.to_string());
    }

    /// Ends the bars where they stand (a failed run's too), so that what the command prints
    /// next goes below them and is not drawn over; call it when the run has ended, before
    /// printing its results.
    pub fn finish(&self) {
        if let Some(b) = &self.bars {
            if let Ok(b) = b.lock() {
                for (_, bar) in &b.stages {
                    bar.abandon();
                }
            }
        }
    }

    /// A line of the log.
    pub fn log(&self, message: &str) {
        match self.format {
            ProgressFormat::Text => self.write(&format!("[{:>7.1} s] {message}", self.elapsed())),
            ProgressFormat::Json => self.json(serde_json::json!({
                "event": "log",
                "message": message,
            })),
        }
    }

    /// A coordinator run's progress: its stage and each stage's jobs.
    pub fn run(&self, s: &RunStatus) {
        match self.format {
            ProgressFormat::Text => match &self.bars {
                Some(b) => {
                    let head = head(s);
                    let said = b.lock().map(|mut b| b.update(s, &head)).unwrap_or(true);
                    if !said {
                        self.log(&head);
                    }
                }
                None => {
                    self.log(&head(s));
                    for l in bemcal_client::client::progress_lines(s) {
                        self.write(&l);
                    }
                }
            },
            ProgressFormat::Json => self.json(serde_json::json!({
                "event": "run",
                "run": s.run_id,
                "state": s.state().word(),
                "stage": s.stage().word(),
                "stages": stages_json(s),
            })),
        }
    }

    /// A portfolio building's state or stage changed; `progress` says where it is in words
    /// (`simulate 3/12`, `FAILED at design: ...`).
    pub fn building(&self, s: &RunStatus, progress: &str) {
        match self.format {
            ProgressFormat::Text => self.log(&format!("{}: {progress}", s.building)),
            ProgressFormat::Json => self.json(serde_json::json!({
                "event": "building",
                "building": s.building,
                "run": s.run_id,
                "state": s.state().word(),
                "stage": s.stage().word(),
                "progress": progress,
            })),
        }
    }
}

/// A run's line above its stages: `run r0123456789 chains (running)`.
fn head(s: &RunStatus) -> String {
    format!(
        "run {} {} ({})",
        s.run_id,
        s.stage().word(),
        s.state().word()
    )
}

/// The stages' bars on a terminal (`indicatif`), one a stage as the run reports it, in the
/// layout of [`bemcal_client::client::progress_lines`].
#[derive(Debug)]
struct Bars {
    multi: MultiProgress,
    /// Each stage's word and its bar, in the order they appeared.
    stages: Vec<(String, ProgressBar)>,
    /// The run's last `stage (state)`, said once a change.
    head: String,
}

impl Bars {
    fn new(target: ProgressDrawTarget) -> Bars {
        Bars {
            multi: MultiProgress::with_draw_target(target),
            stages: vec![],
            head: String::new(),
        }
    }

    /// Moves the bars to `s`; whether `head` was already said (false: say it).
    fn update(&mut self, s: &RunStatus, head: &str) -> bool {
        for g in &s.stages {
            let word = g.stage().word();
            let bar = match self.stages.iter().find(|(w, _)| w == word) {
                Some((_, b)) => b.clone(),
                None => {
                    let style = ProgressStyle::with_template(
                        "  {prefix:<9} [{bar:20}] {pos:>3}/{len:<3} {msg}",
                    )
                    .expect("a valid template")
                    .progress_chars("#-");
                    let b = self.multi.add(ProgressBar::new(0).with_style(style));
                    b.set_prefix(word.to_string());
                    self.stages.push((word.to_string(), b.clone()));
                    b
                }
            };
            bar.set_length(u64::from(g.total));
            bar.set_position(u64::from(g.done));
            bar.set_message(bemcal_client::client::stage_state(g));
        }
        let said = self.head == head;
        self.head = head.to_string();
        said
    }
}

/// A run's stages as JSON (`status --json` and the `run` event).
pub fn stages_json(s: &RunStatus) -> Vec<serde_json::Value> {
    s.stages
        .iter()
        .map(|g| {
            serde_json::json!({
                "stage": g.stage().word(),
                "state": g.state().word(),
                "done": g.done,
                "total": g.total,
                "running": g.running,
                "worker_seconds": g.worker_seconds,
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use bemcal_client::proto::{RunState, StageProgress};

    /// Each JSON event is one line that parses, with its kind and clock.
    #[test]
    fn json_events_are_one_object_a_line() {
        let p = Progress::new(ProgressFormat::Json, Sink::Stderr);
        let s = RunStatus {
            run_id: "r1".into(),
            building: "north".into(),
            state: RunState::Running.into(),
            stages: vec![StageProgress {
                done: 3,
                total: 12,
                running: 2,
                worker_seconds: 41.5,
                ..Default::default()
            }],
            ..Default::default()
        };
        let stages = stages_json(&s);
        assert_eq!(stages.len(), 1);
        assert_eq!(stages[0]["done"], 3);
        assert_eq!(stages[0]["worker_seconds"], 41.5);
        let mut event = serde_json::json!({"event": "log", "message": "a \"quoted\"\nline"});
        event["elapsed_s"] = 0.0.into();
        let line = event.to_string();
        assert!(!line.contains('\n'), "{line}");
        let back: serde_json::Value = serde_json::from_str(&line).unwrap();
        assert_eq!(back["message"], "a \"quoted\"\nline");
        // Writing does not panic on either sink.
        p.log("a line");
        p.run(&s);
        p.building(&s, "simulate 3/12");
        p.finish();
    }

    /// On a terminal each stage has one bar, moved in place; the run's head is said once a
    /// change.
    #[test]
    fn bars_follow_the_stages_in_place() {
        let mut bars = Bars::new(ProgressDrawTarget::hidden());
        let mut s = RunStatus {
            stages: vec![StageProgress {
                done: 3,
                total: 12,
                running: 2,
                ..Default::default()
            }],
            ..Default::default()
        };
        assert!(!bars.update(&s, "simulate (running)"));
        s.stages[0].done = 12;
        s.stages[0].running = 0;
        assert!(bars.update(&s, "simulate (running)"));
        assert_eq!(bars.stages.len(), 1);
        let b = &bars.stages[0].1;
        assert_eq!((b.position(), b.length()), (12, Some(12)));
        assert!(!b.message().contains("running"), "{}", b.message());
        assert!(!bars.update(&s, "train (running)"));
        let p = Progress {
            format: ProgressFormat::Text,
            sink: Sink::Stderr,
            t0: Instant::now(),
            bars: Some(Arc::new(Mutex::new(bars))),
        };
        // Ended where they stand: a bar short of its length stays short.
        p.finish();
        let b = p.bars.as_ref().unwrap().lock().unwrap();
        assert!(b.stages.iter().all(|(_, bar)| bar.is_finished()));
    }
}

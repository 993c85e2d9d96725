//! `eplusout.err`, read and classified: which messages end a run, which invalidate its results,
//! and which leave usable results behind (reported, not failed).
//!
//! EnergyPlus exits with code 0 whatever happened, so the err file is the verdict. Its messages
//! are `** Warning **`, `** Severe  **` and `**  Fatal  **` lines, each followed by `**   ~~~   **`
//! continuation lines. A Severe is not always fatal to the results: the classes and the reason
//! for each are in [`Class`] and [`classify`].

/// What a message means for the run's results.
#[derive(Debug, Clone, PartialEq)]
pub enum Class {
    /// EnergyPlus stopped: no results.
    Fatal,
    /// The run went on but its results are not to be trusted (every Severe not known to be
    /// harmless falls here: the cautious default).
    Invalidating,
    /// The run completed and its results are usable; `reason` says why, for the run's notes.
    Usable {
        /// Why the results stand.
        reason: String,
    },
}

/// One message of `eplusout.err`: its first line and its continuation lines.
#[derive(Debug, Clone, PartialEq)]
pub struct Message {
    /// As EnergyPlus wrote it.
    pub severity: Severity,
    /// Its first line, then its continuation lines (`**   ~~~   **`).
    pub lines: Vec<String>,
}

/// A message's own severity, as EnergyPlus wrote it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Severity {
    /// `** Warning **`.
    Warning,
    /// `** Severe  **`.
    Severe,
    /// `**  Fatal  **`: the run stopped.
    Fatal,
}

/// Warm-up non-convergence is usable while every failed comparison is within this multiple of
/// its tolerance. Warm-up only sets the building's thermal state at the start of the run
/// period: a zone whose day-to-day peak load still differs by a few tolerances after the
/// maximum number of warm-up days starts January 1 slightly off, and that difference decays
/// within days (a few hours of 8,760). Beyond the margin the zone oscillates or drifts, and
/// the run is refused.
pub const WARMUP_MARGIN: f64 = 10.0;

/// The err file, read.
#[derive(Debug, Clone, Default)]
pub struct ErrFile {
    /// Severe and Fatal messages, in order.
    pub problems: Vec<Message>,
    /// Warning messages: how many, and the first line of each distinct kind (see [`kind`]).
    pub warnings: usize,
    /// Per kind of warning: its first line and how many.
    pub warning_kinds: Vec<(String, usize)>,
    /// "EnergyPlus Completed Successfully" was written.
    pub completed: bool,
    /// The last lines, for a failure that left no message.
    pub tail: Vec<String>,
}

impl ErrFile {
    /// Parses the text of an `eplusout.err`.
    pub fn parse(text: &str) -> ErrFile {
        let mut all: Vec<Message> = vec![];
        for line in text.lines() {
            let t = line.trim_start();
            let severity = if t.starts_with("** Severe") {
                Some(Severity::Severe)
            } else if t.starts_with("**  Fatal") || t.starts_with("** Fatal") {
                Some(Severity::Fatal)
            } else if t.starts_with("** Warning") {
                Some(Severity::Warning)
            } else {
                None
            };
            match severity {
                Some(severity) => all.push(Message {
                    severity,
                    lines: vec![t.to_string()],
                }),
                None if t.starts_with("**   ~~~") => {
                    if let Some(m) = all.last_mut() {
                        m.lines.push(t.to_string());
                    }
                }
                None => {}
            }
        }
        let mut out = ErrFile {
            completed: text.contains("EnergyPlus Completed Successfully"),
            tail: {
                let mut t: Vec<String> = text.lines().rev().take(6).map(String::from).collect();
                t.reverse();
                t
            },
            ..ErrFile::default()
        };
        for m in all {
            if m.severity == Severity::Warning {
                out.warnings += 1;
                let k = kind(&m.lines[0]);
                match out.warning_kinds.iter_mut().find(|(w, _)| *w == k) {
                    Some((_, n)) => *n += 1,
                    None => out.warning_kinds.push((k, 1)),
                }
            } else {
                out.problems.push(m);
            }
        }
        out
    }

    /// The messages with their classes (Severe and Fatal only), in order.
    pub fn classified(&self) -> Vec<(&Message, Class)> {
        self.problems
            .iter()
            .map(|m| (m, classify(m, self.completed)))
            .collect()
    }
}

/// The class of a Severe or Fatal message; `completed`: the run completed.
///
/// - A Fatal, or any Severe of a run that did not complete: [`Class::Fatal`].
/// - `CheckWarmupConvergence ... did not converge after N warmup days` with every failed
///   comparison within [`WARMUP_MARGIN`] times its tolerance: [`Class::Usable`] (why: see
///   [`WARMUP_MARGIN`]); beyond it: [`Class::Invalidating`].
/// - Any other Severe: [`Class::Invalidating`].
pub fn classify(m: &Message, completed: bool) -> Class {
    if m.severity == Severity::Fatal || !completed {
        return Class::Fatal;
    }
    if m.lines[0].contains("CheckWarmupConvergence: User supplied maximum warmup days") {
        // The companion of a non-convergence message, which is judged on its own.
        return Class::Usable {
            reason: "the maximum number of warm-up days was reached".into(),
        };
    }
    if m.lines[0].contains("CheckWarmupConvergence") && m.lines[0].contains("did not converge") {
        let ratios: Vec<f64> = m.lines.iter().filter_map(|l| failed_ratio(l)).collect();
        let worst = ratios.iter().copied().fold(0.0, f64::max);
        return if worst <= WARMUP_MARGIN {
            Class::Usable {
                reason: format!(
                    "warm-up did not converge (worst comparison {worst:.1}x its tolerance, within \
                     the margin of {WARMUP_MARGIN}x): only the state at the start of the run \
                     period is affected"
                ),
            }
        } else {
            Class::Invalidating
        };
    }
    Class::Invalidating
}

/// `..Max Cool Load Comparison = 0.0740 vs Loads Convergence Tolerance=0.04 - Fail Convergence`
/// -> 1.85 (comparison / tolerance) for a failed comparison; None otherwise.
fn failed_ratio(line: &str) -> Option<f64> {
    if !line.contains("Fail Convergence") {
        return None;
    }
    let (_, rest) = line.split_once("Comparison =")?;
    let (value, rest) = rest.split_once("vs")?;
    let (_, tol) = rest.split_once('=')?;
    let tol = tol.split(" -").next()?;
    let v: f64 = value.trim().parse().ok()?;
    let t: f64 = tol.trim().parse().ok()?;
    (t > 0.0).then(|| v.abs() / t)
}

/// A message's kind: its first line without the `** Warning **` prefix, numbers and quoted
/// names (so that "Zone=\"F1\"" and "Zone=\"F2\"" are one kind), cut to 120 characters.
pub fn kind(first_line: &str) -> String {
    let body = first_line
        .trim_start_matches(|c: char| c == '*' || c.is_whitespace())
        .trim_start_matches("Warning")
        .trim_start_matches("Severe")
        .trim_start_matches("Fatal")
        .trim_start_matches(|c: char| c == '*' || c.is_whitespace());
    let mut out = String::new();
    let mut in_quote = false;
    for c in body.chars() {
        if c == '"' {
            if !in_quote {
                out.push_str("\"..\"");
            }
            in_quote = !in_quote;
        } else if in_quote {
        } else if c.is_ascii_digit() {
            if !out.ends_with('#') {
                out.push('#');
            }
        } else if c != '.' || !out.ends_with('#') {
            out.push(c);
        }
    }
    out.chars().take(120).collect()
}

/// Why a simulation failed, in a few words that group alike failures: the [`kind`] of the
/// first EnergyPlus message in a failed run's error text (as [`crate::Error`] displays it, or as
/// it comes back from a worker), "EnergyPlus time limit of S s ([simulation] timeout_s)", the
/// limit a run stopped at (without its folder), or the text's first line.
pub fn failure_reason(error_text: &str) -> String {
    if let Some((_, after)) = error_text.split_once("exceeded its time limit") {
        return match after
            .strip_prefix(" of ")
            .and_then(|t| t.split_once(" s"))
            .map(|(secs, _)| secs)
            .filter(|secs| secs.len() <= 24)
        {
            Some(secs) => format!("EnergyPlus time limit of {secs} s ([simulation] timeout_s)"),
            None => "EnergyPlus time limit ([simulation] timeout_s)".into(),
        };
    }
    if let Some(line) = error_text.lines().find(|l| {
        let t = l.trim_start();
        t.starts_with("** Severe") || t.starts_with("**  Fatal") || t.starts_with("** Fatal")
    }) {
        return kind(line);
    }
    let first = error_text.lines().next().unwrap_or_default();
    // "EnergyPlus failed in DIR: message": the message without the run's own folder.
    match first.split_once(": ") {
        Some((head, rest))
            if head.starts_with("EnergyPlus failed in")
                || head.starts_with("EnergyPlus stopped in") =>
        {
            rest.chars().take(160).collect()
        }
        _ => first.chars().take(160).collect(),
    }
}

/// True when a failure says something about the parameter values, i.e. EnergyPlus ran and
/// refused or could not simulate them; false for a time limit, a missing engine or a file
/// problem, which tell nothing about where the model is valid.
pub fn is_model_failure(error_text: &str) -> bool {
    error_text.starts_with("EnergyPlus failed in") && !error_text.contains("did not run")
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The message of the 3-storey building, as EnergyPlus 25.2 writes it.
    const WARMUP: &str = "   ** Severe  ** CheckWarmupConvergence: Loads Initialization, Zone=\"F3\" did not converge after 25 warmup days.
   **   ~~~   ** See Warmup Convergence Information in .eio file for details.
   **   ~~~   ** ..Environment(RunPeriod)=\"RUN PERIOD 1\"
   **   ~~~   ** ..Max Temp Comparison = 2.13E-002 vs Temperature Convergence Tolerance=0.40 - Pass Convergence
   **   ~~~   ** ..Min Temp Comparison = 1.07E-002 vs Temperature Convergence Tolerance=0.40 - Pass Convergence
   **   ~~~   ** ..Max Heat Load Comparison = 0.0000 vs Loads Convergence Tolerance=4.00E-002 - Pass Convergence
   **   ~~~   ** ..Max Cool Load Comparison = 7.4000E-002 vs Loads Convergence Tolerance=4.00E-002 - Fail Convergence
   ** Warning ** Zone \"F1\" has no air flow.
   ** Warning ** Zone \"F2\" has no air flow.
   ************* EnergyPlus Completed Successfully-- 2 Warning; 1 Severe Errors; Elapsed Time=00hr 00min  3.10sec
";

    #[test]
    fn warm_up_within_the_margin_is_usable() {
        let e = ErrFile::parse(WARMUP);
        assert!(e.completed);
        assert_eq!(e.problems.len(), 1);
        assert_eq!(e.problems[0].lines.len(), 7);
        assert_eq!(e.warnings, 2);
        assert_eq!(
            e.warning_kinds,
            vec![("Zone \"..\" has no air flow.".to_string(), 2)]
        );
        match &e.classified()[0].1 {
            Class::Usable { reason } => assert!(reason.contains("1.8x"), "{reason}"),
            c => panic!("{c:?}"),
        }
    }

    #[test]
    fn warm_up_far_outside_the_margin_or_a_run_that_stopped_is_not() {
        let far = WARMUP.replace("7.4000E-002 vs", "0.9 vs");
        assert_eq!(ErrFile::parse(&far).classified()[0].1, Class::Invalidating);
        let stopped = WARMUP.replace("EnergyPlus Completed Successfully", "EnergyPlus Terminated");
        assert_eq!(ErrFile::parse(&stopped).classified()[0].1, Class::Fatal);
    }

    #[test]
    fn other_severes_invalidate_and_fatals_stop() {
        let text = "   ** Severe  ** Calculation of cooling coil design UA failed for coil AHU2 COOLING COIL
   **   ~~~   ** Design inlet air temperature = 20.1
   **  Fatal  ** Program terminates
   ************* EnergyPlus Terminated--Fatal Error Detected. 0 Warning; 1 Severe Errors;
";
        let e = ErrFile::parse(text);
        let c: Vec<Class> = e.classified().into_iter().map(|(_, c)| c).collect();
        assert_eq!(c, vec![Class::Fatal, Class::Fatal]);
        let done = text.replace("EnergyPlus Terminated", "EnergyPlus Completed Successfully");
        let e = ErrFile::parse(&done.replace("   **  Fatal  ** Program terminates\n", ""));
        assert_eq!(e.classified()[0].1, Class::Invalidating);
        let shown = format!(
            "EnergyPlus failed in /tmp/x/point_004: results invalid: 1 message\n{}",
            e.problems[0].lines.join("\n")
        );
        assert_eq!(
            failure_reason(&shown),
            "Calculation of cooling coil design UA failed for coil AHU# COOLING COIL"
        );
        assert!(is_model_failure(&shown));
        let late = "EnergyPlus exceeded its time limit of 900 s in /tmp/x";
        assert_eq!(
            failure_reason(late),
            "EnergyPlus time limit of 900 s ([simulation] timeout_s)"
        );
        assert!(!is_model_failure(late));
        let stopped = |dir: &str| {
            failure_reason(&format!(
                "EnergyPlus stopped in {dir}: it wrote a file past its output limit of 2048 MB"
            ))
        };
        assert_eq!(stopped("/a/point_001"), stopped("/b/point_002"));
        assert_eq!(
            stopped("/a"),
            "it wrote a file past its output limit of 2048 MB"
        );
    }
}

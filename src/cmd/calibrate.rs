//! `bemcal calibrate`: the whole calibration on this machine.

use std::path::PathBuf;

use bemcal_calibrate::project::ErrorModelSetting;
use bemcal_calibrate::{calibrate, Project};
use bemcal_report::informed::{how_much_learned, uninformed, what_bills_say, why_uninformed};

use super::progress::{Progress, ProgressFormat, Sink};

/// Run design points, training, chains and validation for a project; write summary.json,
/// draws.csv, the surrogate and the validation runs under --out.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Project file (TOML).
    pub project: PathBuf,
    /// Output folder (reused: finished stages are not redone).
    #[arg(long)]
    pub out: PathBuf,
    /// Print summary.json to stdout when done.
    #[arg(long)]
    pub json: bool,
    /// Run through a coordinator and this many worker processes on loopback instead.
    #[arg(long)]
    pub local_workers: Option<usize>,
    /// With --local-workers: chains per chain job, so that the workers run the chains side by
    /// side (0: all chains in one job). The draws are the single-process path's either way; an
    /// extension re-adapts all chains together.
    #[arg(long, default_value_t = 0, requires = "local_workers")]
    pub chains_per_job: usize,
    /// Hours that check the calibration and never fit it, as `[validation] holdout`
    /// (overrides the project): `last 3 months`, `oct,nov,dec`, `2017-06-01..2017-08-31`.
    #[arg(long)]
    pub holdout: Option<bemcal_weather::period::Holdout>,
    /// How progress is written on standard error: `text` for people, `json` for programs (one
    /// object a line: log lines and, with --local-workers, each stage's jobs).
    #[arg(long, value_enum, default_value_t)]
    pub progress: ProgressFormat,
}

/// The calibration finished and wrote everything, but its chains missed a convergence target:
/// `main` prints this and exits with [`bemcal_calibrate::NOT_CONVERGED_EXIT`].
#[derive(Debug)]
pub struct NotConverged(pub String);

impl std::fmt::Display for NotConverged {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for NotConverged {}

/// The lines that say a finished calibration did not converge, and what to do.
fn not_converged(s: &bemcal_calibrate::Summary, out: &std::path::Path) -> NotConverged {
    NotConverged(format!(
        "NOT CONVERGED: {}.\nThe estimate, the intervals and the validation above come from \
         chains that have not mixed: do not use them as a calibration. Every output was written \
         to {} (draws.csv, chains.json); run `bemcal calibrate` again with more \
         `[mcmc] iterations` or `max_extensions` (the chains continue from their checkpoint only \
         when the output folder is kept), or see `bemcal diagnose`. Exit status {}.",
        s.convergence,
        out.display(),
        bemcal_calibrate::NOT_CONVERGED_EXIT
    ))
}

pub fn run(a: Args) -> anyhow::Result<()> {
    let mut project = Project::load(&a.project)?;
    if let Some(h) = &a.holdout {
        anyhow::ensure!(
            a.local_workers.is_none(),
            "--holdout with --local-workers: write `holdout = \"{h}\"` under [validation] in {} \
             instead (the workers read the project file)",
            a.project.display()
        );
        project.validation.holdout = Some(h.clone());
    }
    let progress = Progress::new(a.progress, Sink::Stderr);
    let s = match a.local_workers {
        Some(n) => super::coordinator::calibrate_local(
            &a.project,
            &a.out,
            n.max(1),
            a.chains_per_job,
            &progress,
        ),
        None => calibrate(&project, &a.out, &|m: &str| progress.log(m)).map_err(Into::into),
    };
    progress.finish();
    let s = s?;
    write_report(&project, &a.out);
    if a.json {
        println!("{}", serde_json::to_string_pretty(&s)?);
        return converged_or_not(&s, &a.out);
    }
    print_meters(&s);
    print_posterior(&s);
    print_surrogate_error(&s);
    print_posterior_notes(&s);
    print_guideline14(&s);
    print_held_out(&s);
    print_model_form(&s);
    print_start(&s);
    print_refinement(&s);
    // `[savings] with_calibration`: the measures' savings, as `bemcal savings` prints them.
    if let Some(r) = &s.savings {
        println!();
        super::savings::print_table(r);
    }
    print_timings(&s, &a.out);
    converged_or_not(&s, &a.out)
}

/// `report.html` in the output folder, on every path (in process, local workers), with the
/// pre-calibration's figures where the project's priors come from a pre-calibration folder. A
/// report that cannot be written is said, and the calibration still stands.
pub(super) fn write_report(project: &Project, out: &std::path::Path) {
    let precal = project
        .priors
        .as_ref()
        .and_then(|p| {
            project
                .resolve(p)
                .parent()
                .map(std::path::Path::to_path_buf)
        })
        .filter(|d| d.join("calendar.csv").is_file());
    let written = bemcal_report::write_report(out, precal.as_deref())
        .or_else(|_| bemcal_report::write_report(out, None));
    match written {
        Ok(path) => eprintln!("report: {}", path.display()),
        Err(e) => eprintln!(
            "report: not written ({e}); `bemcal report {}` tries again",
            out.display()
        ),
    }
}

/// The meters' year and what ingestion decided.
fn print_meters(s: &bemcal_calibrate::Summary) {
    println!(
        "\nmeters of {} ({} to {}):",
        s.year,
        s.year.first_date(),
        s.year.last_date()
    );
    for note in &s.meter_notes {
        println!("  {note}");
    }
}

/// The posterior table: priors, posterior summaries, the estimate, R-hat, ESS, width.
fn print_posterior(s: &bemcal_calibrate::Summary) {
    let t = s.temperature.value;
    let tempered = if t > 1.0 {
        format!("; likelihood tempered, T = {t:.1}")
    } else {
        String::new()
    };
    println!(
        "\nposterior ({} chains; {}{tempered}):",
        s.acceptance_rate.len(),
        s.convergence
    );
    println!(
        "{:<30} {:>9} {:>9} {:>9} | {:>9} {:>9} {:>9} {:>9} {:>6} {:>6} {:>5}",
        "parameter",
        "prior min",
        "mode",
        "max",
        "mean",
        "q5",
        "q95",
        "estimate",
        "rhat",
        "ess",
        "width"
    );
    for (p, r) in s.posterior.parameters.iter().zip(&s.parameters) {
        let est = s
            .calibrated_values
            .iter()
            .find(|(n, _)| *n == p.name)
            .map_or(f64::NAN, |(_, v)| *v);
        println!(
            "{:<30} {:>9.4} {:>9.4} {:>9.4} | {:>9.4} {:>9.4} {:>9.4} {:>9.4} {:>6.3} {:>6.0} {:>5.2}",
            p.name, r.prior_min, r.prior_mode, r.prior_max, p.mean, p.q5, p.q95, est, p.rhat, p.ess_bulk, p.width_ratio
        );
    }
    let params = &s.posterior.parameters;
    let ratios: Vec<f64> = params.iter().map(|p| p.width_ratio).collect();
    let pooled = s.temperature.pooled_with_buildings;
    println!("{}", how_much_learned(&ratios, t, pooled));
    let barely = params.iter().filter(|p| uninformed(p.width_ratio)).count();
    if barely > 0 {
        println!("note: {}", why_uninformed(barely, params.len(), t));
    }
    if let Some(note) = what_bills_say(&s.billed_outputs()) {
        println!("note: {note}");
    }
}

/// The intervals with the surrogate's error, when a refinement round measured it.
fn print_surrogate_error(s: &bemcal_calibrate::Summary) {
    if let Some(e) = &s.surrogate_error {
        println!(
            "\nwith the surrogate's error (what a calibration through the round-{} surrogate recovered \
             at {} EnergyPlus points, added to the draws; the intervals to read):",
            e.round, e.points
        );
        println!(
            "{:<30} {:>9} {:>9} {:>9} {:>9}",
            "parameter", "q5", "median", "q95", "rms shift"
        );
        for p in &e.parameters {
            println!(
                "{:<30} {:>9.4} {:>9.4} {:>9.4} {:>9.4}",
                p.name, p.q5, p.median, p.q95, p.rms_shift
            );
        }
    }
}

/// Correlated pairs, chains moved to the best mode, independence steps switched off.
fn print_posterior_notes(s: &bemcal_calibrate::Summary) {
    if let Some(m) = &s.posterior.modes {
        println!(
            "warning: {}",
            bemcal_report::modes::modes_sentence(m, &s.posterior.parameters)
        );
    }
    for c in &s.posterior.correlated_pairs {
        println!(
            "warning: {} and {} are strongly correlated (rho = {:.2}): not separately identifiable",
            c.a, c.b, c.rho
        );
    }
    for m in &s.moved_chains {
        println!(
            "note: chain {} started in the best optimum's mode (its own optimum was {:.0} nats lower; mcmc.restart_below)",
            m.chain, m.nats_below
        );
    }
    if !s.independence_dropped.is_empty() {
        println!(
            "note: chains {:?} switched their independence steps off after burn-in (accepted under {} %): random-walk draws only",
            s.independence_dropped,
            bemcal_stats::mcmc::INDEPENDENCE_MIN_ACCEPTANCE * 100.0
        );
    }
}

/// Guideline 14 hourly: the initial model, the calibrated one and the surrogate at the estimate.
fn print_guideline14(s: &bemcal_calibrate::Summary) {
    println!("\nASHRAE Guideline 14 (hourly: |NMBE| <= 10 %, CV-RMSE <= 30 %):");
    println!(
        "{:<18} {:>22} {:>22}      {:>22}",
        "output", "initial NMBE / CV-RMSE", "calibrated NMBE / CV", "surrogate at estimate"
    );
    for v in &s.validation {
        let init = s.initial.iter().find(|i| i.output == v.output);
        let sur = s
            .surrogate_at_estimate
            .iter()
            .find(|i| i.output == v.output);
        println!(
            "{:<18} {:>22} {:>6.1} % / {:5.1} % {:4} {:>22}",
            v.label(),
            metrics_pair(init),
            v.metrics.nmbe,
            v.metrics.cv_rmse,
            if v.metrics.pass { "pass" } else { "FAIL" },
            metrics_pair(sur)
        );
    }
    for v in &s.validation {
        if let Some(d) = &v.demand {
            println!("{}", d.sentence(&v.output));
        }
    }
    if let Some(note) = &s.estimate_note {
        println!("estimate: {note}");
    }
    if !s.not_fitted.is_empty() {
        println!(
            "not fitted (fit = false), compared only: {}",
            s.not_fitted.join(", ")
        );
    }
}

/// How the surrogate's first training started, where a pretrained network was named.
fn print_start(s: &bemcal_calibrate::Summary) {
    use bemcal_calibrate::SurrogateStart;
    match &s.surrogate_start {
        Some(SurrogateStart::Pretrained {
            pretrained,
            corpus_cases,
        }) => println!(
            "\nsurrogate: fine-tuned from the pretrained network {pretrained} ({corpus_cases} corpus cases)"
        ),
        Some(SurrogateStart::Scratch { reason }) => println!(
            "\nsurrogate: trained from random weights, not the pretrained network: {reason}"
        ),
        None => {}
    }
}

/// Each refinement round: draws added, failures, the surrogate's error at them.
fn print_refinement(s: &bemcal_calibrate::Summary) {
    for r in &s.refinement {
        println!(
            "\nrefinement round {}: {} posterior draws added, {} failed in EnergyPlus; surrogate vs EnergyPlus at them (NMBE / CV-RMSE): {}",
            r.round,
            r.points.len(),
            r.failed.len(),
            r.surrogate_error
                .iter()
                .map(|m| format!("{} {}", m.output, metrics_pair(Some(m))))
                .collect::<Vec<_>>()
                .join(", ")
        );
    }
}

/// The stages' timings and the files written.
fn print_timings(s: &bemcal_calibrate::Summary, out: &std::path::Path) {
    let t = &s.timings;
    println!(
        "\ntimings: design {:.0} s, simulations {:.0} s, training {:.0} s, chains {:.0} s, refinement {:.0} s, summary {:.0} s, validation {:.0} s, {}total {:.0} s",
        t.design_s, t.simulations_s, t.training_s, t.chains_s, t.refinement_s, t.summary_s, t.validation_s,
        if t.savings_s > 0.0 { format!("savings {:.0} s, ", t.savings_s) } else { String::new() },
        t.total_s
    );
    println!(
        "wrote {}/summary.json, draws.csv, posterior_predictive.csv, validation/ (discrepancy.csv: the model-form discrepancy), calibrated.idf",
        out.display()
    );
}

/// `NMBE / CV-RMSE` of a Guideline 14 comparison, `-` where there is none.
fn metrics_pair(m: Option<&bemcal_calibrate::OutputMetrics>) -> String {
    m.map_or("-".to_string(), |i| {
        format!("{:6.1} % / {:5.1} %", i.metrics.nmbe, i.metrics.cv_rmse)
    })
}

/// Whether the model reaches each meter, and what to look at where it does not.
fn print_model_form(s: &bemcal_calibrate::Summary) {
    let Some(f) = &s.model_form else { return };
    println!("\nmodel form (can the calibrated model reach each meter?):");
    for m in &f.meters {
        for (i, line) in m.findings.iter().enumerate() {
            let name = if i == 0 { m.output.as_str() } else { "" };
            println!("{name:<18} {line}");
        }
    }
    for line in &f.parameter_findings {
        println!("{:<18} {line}", "parameters");
    }
}

/// Monthly Guideline 14, the held-out period's, and the predictive intervals' coverage.
fn print_held_out(s: &bemcal_calibrate::Summary) {
    let pm = |m: Option<&bemcal_stats::metrics::G14Metrics>| {
        m.map_or("-".to_string(), |m| {
            format!(
                "{:6.1} % / {:5.1} % {}",
                m.nmbe,
                m.cv_rmse,
                if m.pass { "pass" } else { "FAIL" }
            )
        })
    };
    println!(
        "\nGuideline 14 of the calibrated model, monthly (|NMBE| <= 5 %, CV-RMSE <= 15 %){}:",
        if s.holdout.is_some() {
            ", and on the held-out period"
        } else {
            ""
        }
    );
    println!(
        "{:<18} {:>28} {:>28} {:>28}",
        "output", "monthly, calibration period", "held out, hourly", "held out, monthly"
    );
    for v in &s.validation {
        let h = v.held_out.as_ref();
        println!(
            "{:<18} {:>28} {:>28} {:>28}",
            v.label(),
            pm(v.monthly.as_ref()),
            pm(h.map(|h| &h.hourly)),
            pm(h.and_then(|h| h.monthly.as_ref()))
        );
    }
    if let Some(h) = &s.holdout {
        println!(
            "held out: {} ({} hours; measured hours held out / calibrated on: {})",
            h.period,
            h.hours,
            h.measured_hours
                .iter()
                .map(|(o, h)| format!("{o} {} / {}", h.held_out, h.calibration))
                .collect::<Vec<_>>()
                .join(", ")
        );
    }
    if let Some(p) = &s.predictive {
        print_predictive(p);
    }
}

/// The hourly predictive intervals' coverage per meter, in-sample and held out, and the error
/// models the held-out hours favour.
fn print_predictive(p: &bemcal_calibrate::predictive::PredictiveReport) {
    println!(
        "\nhourly predictive intervals (EnergyPlus at {} posterior draws{}, {} failed, each + the noise \
         of its own residuals under each meter's error model, by default {}; recalibrated on the \
         calibration period, so that they hold their nominal share there: the held-out hours \
         are the check): share of measured hours inside (PIT: where a meter reads 0 in hours \
         the draws may find idle, each such reading counted by its share of probability \
         inside, the share to hold against nominal), mean width [the posterior's own \
         intervals before recalibration]",
        p.draws,
        if p.with_surrogate_error { " with the surrogate's error" } else { "" },
        p.failed,
        quoted(p.error_model.as_str())
    );
    let cov = |c: &[bemcal_stats::predictive::Coverage]| {
        c.iter()
            .map(|c| {
                let pit = c
                    .pit_fraction
                    .map_or(String::new(), |f| format!("PIT {:.1} %, ", f * 100.0));
                format!(
                    "{:.0} %: {:5.1} % ({pit}{:.1} kWh)",
                    c.nominal * 100.0,
                    c.fraction * 100.0,
                    c.mean_width
                )
            })
            .collect::<Vec<_>>()
            .join(", ")
    };
    // The error model each meter's held-out hours favour, as one `error_model` setting.
    let default = match p.error_model {
        ErrorModelSetting::Fixed(m) => Some(m),
        ErrorModelSetting::Auto => None,
    };
    let (mut entries, mut differs) = (vec![], false);
    for o in &p.outputs {
        let Some(m) = o.by_error_model.first() else {
            continue;
        };
        let c = &m.coverage;
        let before = m.before_recalibration.as_ref();
        println!(
            "{:<18} in-sample  {}{}",
            o.output,
            cov(&c.in_sample),
            before_recalibration(before.map(|b| &b.in_sample))
        );
        if let Some(line) = cross_validation_line(o, default) {
            println!("{:<18} {line}", "");
        }
        if !c.held_out.is_empty() {
            println!(
                "{:<18} held out   {}{}",
                "",
                cov(&c.held_out),
                before_recalibration(before.map(|b| &b.held_out))
            );
        }
        if let Some(r) = &o.running {
            println!("{:<18} {}", "", running_hours(r));
        }
        let model = match &o.held_out_favours {
            Some(f) => {
                println!("{:<18} {}", "", held_out_choice(f, m.error_model));
                f.error_model
            }
            None => m.error_model,
        };
        differs |= model != m.error_model;
        // The entry this meter needs for its favoured model: one the default would not give.
        if default.map_or(model != m.error_model, |d| model != d) {
            entries.push((o.output.as_str(), model.as_str()));
        }
    }
    if differs {
        let entries: Vec<String> = std::iter::once(("default", p.error_model.as_str()))
            .chain(entries)
            .map(|(k, m)| format!("{} = {}", toml_key(k), quoted(m)))
            .collect();
        println!(
            "to use the error models the held-out hours favour (chosen on them: judge the \
             choice on another period): [validation] error_model = {{ {} }}",
            entries.join(", ")
        );
    }
    print_totals(p, &cov);
    for b in &p.bills {
        println!("{}", b.sentence());
    }
}

/// The coverage of the hours a meter runs, and how many hours read zero: `running (reads
/// above 0): in-sample 44.1 / 88.5 %, held out 52.4 / 94.5 %; 8.8 % of the calibration hours
/// read 0 (12.7 % held out), inside every interval that starts at 0`.
fn running_hours(r: &bemcal_calibrate::predictive::RunningHours) -> String {
    let shares = |c: &[bemcal_stats::predictive::Coverage]| {
        (c.iter().map(|c| format!("{:.1}", c.fraction * 100.0)))
            .collect::<Vec<_>>()
            .join(" / ")
    };
    let c = &r.coverage;
    let held = match c.held_out.is_empty() {
        true => String::new(),
        false => format!(", held out {} %", shares(&c.held_out)),
    };
    let idle_held = r
        .idle_held_out
        .map_or(String::new(), |s| format!(" ({:.1} % held out)", s * 100.0));
    format!(
        "running (reads above 0): in-sample {} %{held}; {:.1} % of the calibration hours read \
         0{idle_held}, inside every interval that starts at 0",
        shares(&c.in_sample),
        r.idle_in_sample * 100.0
    )
}

/// The shares inside the intervals before recalibration, `  [76.9 %, 99.6 %]` (empty without).
fn before_recalibration(c: Option<&Vec<bemcal_stats::predictive::Coverage>>) -> String {
    c.map_or(String::new(), |c| {
        let f: Vec<String> = (c.iter())
            .map(|c| format!("{:.1} %", c.fraction * 100.0))
            .collect();
        format!("  [{}]", f.join(", "))
    })
}

/// An error model as the project file spells it, quoted (`"hour_of_day"`).
fn model_name(m: bemcal_stats::predictive::ErrorModel) -> String {
    quoted(m.as_str())
}

/// A name as the project file spells it, quoted (`"auto"`).
fn quoted(name: &str) -> String {
    format!("\"{name}\"")
}

/// A meter's error models judged month by month out of time, and the one its intervals take
/// where the default does not name it: `months judged out of time (9), points from nominal a
/// month: "level" 3.1, "constant" 5.0, "hour_of_day" 4.2; they favour "level"; "auto" takes
/// it`.
fn cross_validation_line(
    o: &bemcal_calibrate::predictive::OutputPredictive,
    default: Option<bemcal_stats::predictive::ErrorModel>,
) -> Option<String> {
    let own = o.by_error_model.first()?.error_model;
    let taken = match default {
        Some(d) if d != own => Some(format!("its own error model: {}", model_name(own))),
        Some(_) => None,
        None => Some(format!("\"auto\" takes {}", model_name(own))),
    };
    let mut months = 0;
    let misses: Vec<String> = (o.by_error_model.iter())
        .filter_map(|m| {
            let cv = m.cross_validated.as_ref()?;
            months = months.max(cv.months);
            Some(format!(
                "{} {:.1}",
                model_name(m.error_model),
                cv.mean_month_miss_points
            ))
        })
        .collect();
    if misses.is_empty() {
        return taken.map(|t| format!("({t})"));
    }
    let favours = (o.cross_validation_favours.as_ref())
        .map(|f| format!("; they favour {}", model_name(f.error_model)));
    Some(format!(
        "months judged out of time ({months}), points from nominal a month: {}{}{}",
        misses.join(", "),
        favours.unwrap_or_default(),
        taken.map(|t| format!("; {t}")).unwrap_or_default()
    ))
}

/// A TOML key: bare where it may be, quoted otherwise.
fn toml_key(k: &str) -> String {
    let bare = !k.is_empty()
        && k.chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-');
    match bare {
        true => k.to_string(),
        false => serde_json::to_string(k).unwrap_or_default(),
    }
}

/// The error model a meter's held-out hours favour, in words.
fn held_out_choice(
    f: &bemcal_calibrate::predictive::Favoured,
    configured: bemcal_stats::predictive::ErrorModel,
) -> String {
    let configured_miss = f
        .configured_miss_points
        .map_or("-".to_string(), |m| format!("{m:.1}"));
    if f.error_model == configured {
        format!(
            "this meter's held-out hours favour its error model ({}: {:.1} points from nominal)",
            model_name(configured),
            f.miss_points
        )
    } else {
        format!(
            "this meter's held-out hours favour {} ({:.1} points from nominal against \
             {configured_miss} for {}; within 2 points the narrower intervals win)",
            model_name(f.error_model),
            f.miss_points,
            model_name(configured),
        )
    }
}

/// Coverage of the intervals of daily and monthly totals, with the AR(1) noise of a sum and
/// as if hours were independent.
fn print_totals(
    p: &bemcal_calibrate::predictive::PredictiveReport,
    cov: &dyn Fn(&[bemcal_stats::predictive::Coverage]) -> String,
) {
    if p.outputs.iter().all(|o| o.totals.is_empty()) {
        return;
    }
    println!(
        "\nintervals of daily and monthly totals: share of whole measured days / months inside \
         (AR(1) noise of a sum, recalibrated on the calibration period's days [before \
         recalibration]; as if hours were independent)"
    );
    for o in &p.outputs {
        for t in &o.totals {
            let name = format!("{} {:?}", o.output, t.period).to_lowercase();
            let before = t.before_recalibration.as_ref();
            println!(
                "{name:<24} phi {:.2}  in-sample  {}{} | independent {}",
                o.residual_phi,
                cov(&t.ar1.in_sample),
                before_recalibration(before.map(|b| &b.in_sample)),
                cov(&t.independent.in_sample)
            );
            if !t.ar1.held_out.is_empty() {
                println!(
                    "{:<34}held out   {}{} | independent {}",
                    "",
                    cov(&t.ar1.held_out),
                    before_recalibration(before.map(|b| &b.held_out)),
                    cov(&t.independent.held_out)
                );
            }
        }
    }
}

fn converged_or_not(s: &bemcal_calibrate::Summary, out: &std::path::Path) -> anyhow::Result<()> {
    if s.converged {
        Ok(())
    } else {
        Err(not_converged(s, out).into())
    }
}

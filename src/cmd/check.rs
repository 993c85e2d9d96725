//! `bemcal check`: load and validate a project and everything it names, run nothing.

use std::path::PathBuf;

use bemcal_calibrate::project::Temperature;
use bemcal_calibrate::{load_inputs, Project};

/// Load a project and everything it names (model, priors, weather or measured weather, meters,
/// bases) and check that they fit together, without simulating or training anything; prints
/// what a calibration would use. Exit status 1 with the first problem (file, line, field).
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Project file (TOML).
    pub project: PathBuf,
}

pub fn run(a: Args) -> anyhow::Result<()> {
    let project = Project::load(&a.project)?;
    let inp = load_inputs(&project)?;
    println!("project {}: OK", a.project.display());
    println!(
        "  model {}: {} parameters, {} calibrated ({})",
        inp.model.path.display(),
        inp.model.parameters().len(),
        inp.plan.calibrated.len(),
        inp.plan.calibrated.join(", ")
    );
    for note in &inp.plan.restricted {
        println!("  note: {note}");
    }
    println!(
        "  weather {} (year {})",
        inp.weather_path.display(),
        inp.year
    );
    for note in &inp.meter_notes {
        println!("  meters: {note}");
    }
    for ((name, series), bills) in inp.outputs.iter().zip(&inp.measured).zip(&inp.bills) {
        if let Some(b) = bills {
            let fitted = (b.compared.iter().zip(&b.held_out)).filter(|(_, out)| !**out);
            println!(
                "  bills for {name}: {} of {} in the calibration period, {:.0} kWh over them",
                b.calibration_bills(),
                b.table.bills.len(),
                fitted.map(|((i, _), _)| b.table.bills[*i].kwh).sum::<f64>()
            );
            continue;
        }
        let known = series.iter().filter(|v| v.is_finite()).count();
        println!(
            "  meter for {name}: {known} of {} hours measured (calibration period), {:.0} kWh over them",
            series.len(),
            series.iter().filter(|v| v.is_finite()).sum::<f64>()
        );
    }
    if let Some(h) = &inp.held_out {
        let kept = inp
            .measured
            .first()
            .map_or(0, |m| m.iter().filter(|v| v.is_finite()).count());
        println!(
            "  held out: {} ({} hours; they fit nothing and judge the model; {kept} measured hours of {} left to calibrate with)",
            h.period,
            h.hour_count(),
            inp.outputs.first().map_or("-", String::as_str)
        );
    }
    for b in &inp.base_reports {
        println!(
            "  base of {}: {}, {:.0} kWh",
            b.output, b.source, b.annual_kwh
        );
    }
    let m = &project.mcmc;
    println!(
        "  chains: {} x {} iterations ({} burn-in), {:?} from {:?} starts; converged when R-hat <= {} and bulk / tail ESS >= {} (at most {} extensions)",
        m.chains,
        m.iterations,
        m.burn_in,
        m.kernel,
        m.start,
        m.rhat_target,
        m.ess_target,
        m.max_extensions
    );
    match m.temperature {
        Temperature::Fixed(1.0) => {}
        Temperature::Fixed(t) => {
            println!("  likelihood temperature {t}: the chains sample p(theta) L(theta)^(1/{t})")
        }
        Temperature::SurrogateError => println!(
            "  likelihood temperature measured from the surrogate's error at each refinement \
             round's points (the first round's chains at 1)"
        ),
    }
    println!(
        "  design {} points; refinement {} round(s) of {} draws",
        project.design.points, project.refine.rounds, project.refine.points
    );
    Ok(())
}

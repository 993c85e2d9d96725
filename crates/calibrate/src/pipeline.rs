//! The whole calibration on one machine: design points -> simulations -> training set ->
//! surrogate -> chains -> diagnostics and summary -> validation. Every stage writes its results
//! under the output folder and reuses them on a rerun, so an interrupted calibration continues
//! where it stopped.

use std::path::{Path, PathBuf};
use std::time::Instant;

use bemcal_energyplus::{Engine, Model, RunOptions, Runner};
use bemcal_precal::meters::{read_meters, MeterRole};
use bemcal_stats::likelihood::{GaussianLikelihood, OutputNoise};
use bemcal_stats::mcmc::{dispersed_starts, Draws, MhConfig};
use bemcal_stats::metrics::{g14, G14Metrics};
use bemcal_stats::prior::Prior;
use bemcal_stats::summary::{predictive_bands, summarize, PosteriorSummary};
use bemcal_surrogate::{ParamSpec, Split, Surrogate, TrainOptions, TrainingSet};
use bemcal_weather::{Calendar, Epw, Holidays, HourlyFeatures};
use ndarray::{Array2, Array3};
use serde::{Deserialize, Serialize};

use crate::design::{make_design, simulate_design, simulate_point, write_design_csv, Plan};
use crate::posterior::{run_chains, Posterior, SigmaDeltaBox};
use crate::project::{Estimate, Project, SigmaDeltaMode};
use crate::{write_atomic, Error};

/// Loaded inputs of a calibration: model (with pre-calibration priors applied), weather,
/// measurements.
pub struct Inputs {
    pub runner: Runner,
    pub model: Model,
    pub plan: Plan,
    pub weather_path: PathBuf,
    pub features: HourlyFeatures,
    pub year: i32,
    /// Calibration outputs (model output names) and their measured series (kWh, NaN = missing).
    pub outputs: Vec<String>,
    pub measured: Vec<Vec<f64>>,
}

/// The priors file written by `bemcal precalibrate`.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct PriorsFile {
    #[serde(default)]
    pub schedule: Option<ScheduleBounds>,
    #[serde(default, rename = "parameter")]
    pub parameters: Vec<PriorEntry>,
}

/// Schedule interval boundaries from pre-calibration.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ScheduleBounds {
    pub weekday_boundaries: Vec<u32>,
    pub weekend_boundaries: Vec<u32>,
}

/// One prior from pre-calibration.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct PriorEntry {
    pub name: String,
    pub min: f64,
    pub mode: f64,
    pub max: f64,
    #[serde(default)]
    pub unit: String,
    #[serde(default)]
    pub source: String,
}

/// Resolves a weather reference: a path, or `bundled:FILE` from the engine's `WeatherData`.
pub fn resolve_weather(project: &Project, engine: &Engine) -> Result<PathBuf, Error> {
    if let Some(name) = project.weather.strip_prefix("bundled:") {
        return engine.bundled_weather(name).ok_or_else(|| {
            Error::Config(format!(
                "weather 'bundled:{name}': no such file in {}",
                engine.root.join("WeatherData").display()
            ))
        });
    }
    Ok(project.resolve(Path::new(&project.weather)))
}

/// Loads the model and applies a priors file to it.
pub fn load_model(project: &Project, runner: &Runner) -> Result<Model, Error> {
    let path = project.resolve(&project.model);
    let mut model = Model::load(&path, runner.idd())?;
    if let Some(p) = &project.priors {
        let path = project.resolve(p);
        let text = std::fs::read_to_string(&path).map_err(|e| Error::io(&path, e))?;
        let pf: PriorsFile = toml::from_str(&text).map_err(|e| Error::Input {
            path: path.clone(),
            line: e
                .span()
                .map(|s| text[..s.start].lines().count().max(1))
                .unwrap_or(0),
            message: e.message().to_string(),
        })?;
        if let Some(b) = &pf.schedule {
            let mut spec = model.spec().cloned().ok_or_else(|| Error::Input {
                path: path.clone(),
                line: 0,
                message: "[schedule] boundaries apply to generated building models only".into(),
            })?;
            spec.weekday_boundaries = b.weekday_boundaries.clone();
            spec.weekend_boundaries = b.weekend_boundaries.clone();
            spec.validate().map_err(|m| Error::Input {
                path: path.clone(),
                line: 0,
                message: m,
            })?;
            let p0 = model.path.clone();
            model = Model::generated(spec);
            model.path = p0;
        }
        for e in &pf.parameters {
            let prior =
                bemcal_energyplus::TriangularPrior::new(e.min, e.mode, e.max).map_err(|m| {
                    Error::Input {
                        path: path.clone(),
                        line: 0,
                        message: format!("parameter {}: {m}", e.name),
                    }
                })?;
            model
                .set_prior(&e.name, prior)
                .map_err(|err| Error::Input {
                    path: path.clone(),
                    line: 0,
                    message: err.to_string(),
                })?;
        }
    }
    Ok(model)
}

/// Loads everything a calibration needs and checks it fits together.
pub fn load_inputs(project: &Project) -> Result<Inputs, Error> {
    let engine = Engine::locate()?;
    let runner = Runner::new(engine, RunOptions::default())?;
    let model = load_model(project, &runner)?;
    let plan = Plan::new(&model, &project.calibrate, &project.fixed)?;
    let weather_path = resolve_weather(project, runner.engine())?;
    let epw = Epw::read(&weather_path)?;
    let calendar = model
        .spec()
        .map(|s| s.calendar())
        .unwrap_or(Calendar::new(2021, Holidays::UsFederal));
    let features = HourlyFeatures::from_epw(&epw, &calendar);
    let meters_path = project.meters_file();
    let data = read_meters(
        &meters_path,
        &project.meters,
        Some(calendar.year),
        Some(epw.location.time_zone_h),
    )?;
    let mut outputs = vec![];
    let mut measured = vec![];
    let roles = project.output_roles();
    for o in model.outputs() {
        if let Some(role) = roles.get(&o.name) {
            if let Some(s) = data.get(&MeterRole::from(role.clone())) {
                outputs.push(o.name.clone());
                measured.push(s.values.clone());
            }
        }
    }
    for (name, role) in &roles {
        if !model.outputs().iter().any(|o| &o.name == name) {
            return Err(Error::Config(format!(
                "[outputs] {name} = \"{role}\": the model has no output {name} (it has {})",
                model
                    .outputs()
                    .iter()
                    .map(|o| o.name.as_str())
                    .collect::<Vec<_>>()
                    .join(", ")
            )));
        }
    }
    if outputs.is_empty() {
        return Err(Error::Config(format!(
            "no model output has a meter: outputs map {:?}, meters found: {:?}",
            roles,
            data.series
                .iter()
                .map(|s| s.role.name().to_string())
                .collect::<Vec<_>>()
        )));
    }
    Ok(Inputs {
        runner,
        model,
        plan,
        weather_path,
        features,
        year: calendar.year,
        outputs,
        measured,
    })
}

/// Wall time of each stage, s.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct Timings {
    pub design_s: f64,
    pub simulations_s: f64,
    pub training_s: f64,
    pub chains_s: f64,
    pub summary_s: f64,
    pub validation_s: f64,
    pub total_s: f64,
}

/// Metrics of one model against the meters, per output.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct OutputMetrics {
    pub output: String,
    #[serde(flatten)]
    pub metrics: G14Metrics,
}

/// `summary.json`.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Summary {
    pub project: String,
    pub outputs: Vec<String>,
    pub parameters: Vec<ParameterReport>,
    pub posterior: PosteriorSummary,
    pub sigma_delta_kwh: Vec<(String, f64)>,
    pub sigma_eta_kwh: Vec<(String, f64)>,
    pub acceptance_rate: Vec<f64>,
    pub estimate: Estimate,
    pub calibrated_values: Vec<(String, f64)>,
    pub validation: Vec<OutputMetrics>,
    pub initial: Vec<OutputMetrics>,
    pub converged: bool,
    pub design_points: usize,
    pub design_repair: bemcal_stats::lhs::RepairReport,
    pub surrogate_held_out: serde_json::Value,
    pub timings: Timings,
}

/// A parameter's prior next to its posterior.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ParameterReport {
    pub name: String,
    pub unit: String,
    pub prior_min: f64,
    pub prior_mode: f64,
    pub prior_max: f64,
}

/// Progress messages.
pub type Log<'a> = &'a (dyn Fn(&str) + Sync);

/// Runs the whole calibration of `project` into `out`.
pub fn calibrate(project: &Project, out: &Path, log: Log<'_>) -> Result<Summary, Error> {
    let t_all = Instant::now();
    std::fs::create_dir_all(out).map_err(|e| Error::io(out, e))?;
    let inp = load_inputs(project)?;
    let mut timings = Timings::default();
    log(&format!(
        "model {}: {} parameters, {} calibrated; outputs {:?}; weather {}",
        inp.model.path.display(),
        inp.model.parameters().len(),
        inp.plan.calibrated.len(),
        inp.outputs,
        inp.weather_path.display()
    ));

    // Design points.
    let t = Instant::now();
    let design = make_design(
        &inp.plan,
        &inp.model,
        project.design.points,
        project.design.seed,
        project.design.maximin_iterations,
    )?;
    write_design_csv(&out.join("design.csv"), &inp.plan, &design)?;
    timings.design_s = t.elapsed().as_secs_f64();
    log(&format!(
        "design: {} points over {} parameters (constraint repair: {} swaps, {} cells resampled)",
        design.points.len(),
        inp.plan.calibrated.len(),
        design.repair.swaps,
        design.repair.resampled_in_stratum + design.repair.resampled_outside_stratum
    ));
    let t = Instant::now();
    let sims = simulate_design(
        &inp.runner,
        &inp.model,
        &inp.plan,
        &design,
        &inp.weather_path,
        &out.join("simulations"),
        project.design.parallel,
        &|done, n| log(&format!("simulations: {done}/{n}")),
    )?;
    timings.simulations_s = t.elapsed().as_secs_f64();
    log(&format!(
        "simulations: {} run ({:.1} s each on average), {} reused",
        sims.seconds.len(),
        sims.seconds.iter().sum::<f64>() / sims.seconds.len().max(1) as f64,
        sims.reused
    ));

    // Training set and surrogate.
    let t = Instant::now();
    let n_pts = design.points.len();
    let n_h = inp.features.len();
    let n_out = inp.outputs.len();
    let mut points = Array2::zeros((n_pts, inp.plan.calibrated.len()));
    let mut y = Array3::zeros((n_pts, n_h, n_out));
    for (i, (x, o)) in design.points.iter().zip(&sims.outputs).enumerate() {
        for (j, v) in x.iter().enumerate() {
            points[[i, j]] = *v;
        }
        for (k, name) in inp.outputs.iter().enumerate() {
            let s = o.get(name).ok_or_else(|| Error::Stage {
                stage: "training set",
                message: format!("design point {i} has no output {name}"),
            })?;
            for (h, v) in s.iter().enumerate() {
                y[[i, h, k]] = *v;
            }
        }
    }
    let params: Vec<ParamSpec> = inp
        .plan
        .calibrated
        .iter()
        .zip(&inp.plan.priors)
        .map(|(n, p)| ParamSpec::new(n.clone(), p.min(), p.max(), p.mode()))
        .collect();
    let split = Split::by_design_point(
        n_pts,
        project.surrogate.held_out_fraction,
        project.surrogate.seed,
    )?;
    let set = TrainingSet::new(params, points, &inp.features, inp.outputs.clone(), y, 0)?
        .with_split(split)?;
    let dataset_dir = out.join("dataset");
    set.write(&dataset_dir)?;
    let sur_dir = out.join("surrogate");
    if bemcal_surrogate::SurrogateMeta::read(&sur_dir).is_err() {
        log("training the surrogate (PyTorch)...");
        let opts = TrainOptions {
            epochs: project.surrogate.epochs,
            patience: project.surrogate.patience,
            seed: project.surrogate.seed,
            batch_size: project.surrogate.batch_size,
            time_features: project
                .surrogate
                .time_features
                .parse()
                .map_err(Error::Config)?,
            threads: project.surrogate.threads,
            quiet: true,
            ..TrainOptions::default()
        };
        bemcal_surrogate::train(&dataset_dir, &sur_dir, &opts)?;
    } else {
        log("surrogate: reusing the one trained earlier");
    }
    let surrogate = Surrogate::load(&sur_dir, project.surrogate.threads)?;
    let meta = surrogate.meta().clone();
    if meta.output_names() != inp.outputs {
        return Err(Error::Stage {
            stage: "surrogate",
            message: format!(
                "surrogate in {} predicts {:?}, the calibration needs {:?}; delete it to retrain",
                sur_dir.display(),
                meta.output_names(),
                inp.outputs
            ),
        });
    }
    let sigma_eta = meta.sigma_eta_kwh();
    timings.training_s = t.elapsed().as_secs_f64();
    log(&format!(
        "surrogate: held-out RMSE (sigma_eta) {:?} kWh",
        inp.outputs
            .iter()
            .zip(&sigma_eta)
            .map(|(n, s)| format!("{n} {s:.2}"))
            .collect::<Vec<_>>()
    ));
    let mut eval = surrogate.bind(&inp.features)?;

    // Likelihood.
    let mut observed = vec![f64::NAN; n_h * n_out];
    for (k, s) in inp.measured.iter().enumerate() {
        for (h, v) in s.iter().enumerate() {
            observed[h * n_out + k] = *v;
        }
    }
    let stats: Vec<(f64, f64)> = inp.measured.iter().map(|s| mean_sd(s)).collect();
    let noise: Vec<OutputNoise> = stats
        .iter()
        .zip(&sigma_eta)
        .map(|((m, sd), eta)| OutputNoise {
            sigma_y: project.mcmc.sigma_y_fraction * m.abs(),
            sigma_delta: project.mcmc.sigma_delta_fraction * sd,
            sigma_eta: *eta,
        })
        .collect();
    let likelihood = GaussianLikelihood::new(&observed, &noise)?;
    let sd: Vec<f64> = stats.iter().map(|(_, s)| s.max(1e-9)).collect();
    let sbox = SigmaDeltaBox::new(&sd);
    let post = Posterior {
        plan: &inp.plan,
        model: &inp.model,
        likelihood: &likelihood,
        sigma_box: (project.mcmc.sigma_delta == SigmaDeltaMode::Sampled).then_some(&sbox),
    };

    // Chains.
    let t = Instant::now();
    let d = inp.plan.calibrated.len();
    let mut starts = dispersed_starts(&inp.plan.priors, project.mcmc.chains, project.mcmc.seed);
    for s in &mut starts {
        // Feasible start: redraw towards the prior mode until the constraints hold.
        let modes: Vec<f64> = inp
            .plan
            .priors
            .iter()
            .map(|p| p.to_unit(p.mode()))
            .collect();
        let mut tries = 0;
        while !inp.plan.feasible(&inp.model, &post.theta(s)) && tries < 50 {
            for (u, m) in s.iter_mut().zip(&modes) {
                *u = 0.5 * (*u + m);
            }
            tries += 1;
        }
        if post.sigma_box.is_some() {
            s.extend(std::iter::repeat_n(0.6, n_out));
        }
    }
    let config = MhConfig {
        burn_in: project.mcmc.burn_in,
        adapt_start: (project.mcmc.burn_in / 4)
            .max(100)
            .min(project.mcmc.burn_in),
        initial_sd: project.mcmc.initial_sd,
        ..MhConfig::default()
    };
    let ck = run_chains(
        &post,
        &mut eval,
        &starts,
        config,
        project.mcmc.iterations,
        project.mcmc.segment,
        project.mcmc.seed,
        &out.join("chains.json"),
        &|done, n| log(&format!("chains: {done}/{n} iterations")),
    )?;
    timings.chains_s = t.elapsed().as_secs_f64();
    let acceptance: Vec<f64> = ck
        .states
        .iter()
        .map(|s| s.acceptance_rate_post_burn_in())
        .collect();
    log(&format!(
        "chains: acceptance after burn-in {acceptance:.3?}"
    ));

    // Summary and draws.
    let t = Instant::now();
    let theta_draws: Vec<Draws> = ck.draws.iter().map(|dr| sub_draws(dr, d)).collect();
    let priors: Vec<Prior> = inp
        .plan
        .calibrated
        .iter()
        .zip(&inp.plan.priors)
        .zip(&inp.plan.units)
        .map(|((n, p), u)| Prior::new(n.clone(), u.clone(), *p))
        .collect();
    let posterior = summarize(&priors, &theta_draws)?;
    write_draws_csv(
        &out.join("draws.csv"),
        &post,
        &inp.outputs,
        &ck.draws,
        &sbox,
    )?;
    let sigma_delta_kwh: Vec<(String, f64)> = match post.sigma_box {
        Some(b) => (0..n_out)
            .map(|k| {
                let mut v: Vec<f64> = ck
                    .draws
                    .iter()
                    .flat_map(|dr| dr.column(d + k))
                    .map(|u| b.sigma(k, u))
                    .collect();
                v.sort_by(f64::total_cmp);
                (inp.outputs[k].clone(), v[v.len() / 2])
            })
            .collect(),
        None => inp
            .outputs
            .iter()
            .zip(&noise)
            .map(|(n, z)| (n.clone(), z.sigma_delta))
            .collect(),
    };
    // Posterior predictive bands from draws spread over all chains.
    let all: Vec<Vec<f64>> = theta_draws
        .iter()
        .flat_map(|dr| (0..dr.len()).map(move |i| dr.point(i).to_vec()))
        .collect();
    let step = (all.len() / project.mcmc.predictive_draws.max(1)).max(1);
    let picks: Vec<Vec<f64>> = all.iter().step_by(step).map(|u| post.theta(u)).collect();
    let mut pred = vec![Vec::<f32>::with_capacity(picks.len() * n_h); n_out];
    for chunk in picks.chunks(8) {
        let y = eval.evaluate_batch(chunk)?;
        for b in 0..chunk.len() {
            for (k, p) in pred.iter_mut().enumerate() {
                p.extend((0..n_h).map(|h| y[[b, h, k]]));
            }
        }
    }
    let mut bands = vec![];
    for p in &pred {
        bands.push(predictive_bands(p, picks.len(), n_h)?);
    }
    write_bands_csv(
        &out.join("posterior_predictive.csv"),
        inp.year,
        &inp.outputs,
        &inp.measured,
        &bands,
    )?;
    timings.summary_s = t.elapsed().as_secs_f64();

    // Validation with EnergyPlus.
    let t = Instant::now();
    let estimate: Vec<f64> = match project.validation.estimate {
        Estimate::Map => posterior.map_point.clone(),
        Estimate::Mean => posterior.parameters.iter().map(|p| p.mean).collect(),
        Estimate::Median => posterior.parameters.iter().map(|p| p.median).collect(),
    };
    let vdir = out.join("validation");
    std::fs::create_dir_all(&vdir).map_err(|e| Error::io(&vdir, e))?;
    let mut runs = vec![("calibrated", inp.plan.values(&estimate))];
    if project.validation.initial {
        let modes: Vec<f64> = inp.plan.priors.iter().map(|p| p.mode()).collect();
        runs.push(("initial", inp.plan.values(&modes)));
    }
    let mut metrics: Vec<Vec<OutputMetrics>> = vec![];
    for (i, (label, values)) in runs.iter().enumerate() {
        log(&format!("validation: EnergyPlus at the {label} parameters"));
        let (o, _) = simulate_point(&inp.runner, &inp.model, values, &inp.weather_path, &vdir, i)?;
        write_outputs_csv(&vdir.join(format!("{label}.csv")), inp.year, &o)?;
        let mut m = vec![];
        for (k, name) in inp.outputs.iter().enumerate() {
            let sim = o.get(name).expect("model output");
            m.push(OutputMetrics {
                output: name.clone(),
                metrics: g14(&inp.measured[k], sim)?,
            });
        }
        metrics.push(m);
    }
    timings.validation_s = t.elapsed().as_secs_f64();
    timings.total_s = t_all.elapsed().as_secs_f64();

    let summary = Summary {
        project: project.name.clone(),
        outputs: inp.outputs.clone(),
        parameters: inp
            .plan
            .calibrated
            .iter()
            .zip(&inp.plan.priors)
            .zip(&inp.plan.units)
            .map(|((n, p), u)| ParameterReport {
                name: n.clone(),
                unit: u.clone(),
                prior_min: p.min(),
                prior_mode: p.mode(),
                prior_max: p.max(),
            })
            .collect(),
        converged: posterior.max_rhat <= 1.01,
        posterior,
        sigma_delta_kwh,
        sigma_eta_kwh: inp.outputs.iter().cloned().zip(sigma_eta).collect(),
        acceptance_rate: acceptance,
        estimate: project.validation.estimate,
        calibrated_values: inp.plan.calibrated.iter().cloned().zip(estimate).collect(),
        validation: metrics.first().cloned().unwrap_or_default(),
        initial: metrics.get(1).cloned().unwrap_or_default(),
        design_points: n_pts,
        design_repair: design.repair,
        surrogate_held_out: serde_json::to_value(&meta.held_out).unwrap_or_default(),
        timings,
    };
    let json = serde_json::to_vec_pretty(&summary).map_err(|e| Error::Config(e.to_string()))?;
    write_atomic(&out.join("summary.json"), &json)?;
    Ok(summary)
}

fn mean_sd(s: &[f64]) -> (f64, f64) {
    let v: Vec<f64> = s.iter().copied().filter(|x| x.is_finite()).collect();
    let n = v.len().max(1) as f64;
    let m = v.iter().sum::<f64>() / n;
    let var = v.iter().map(|x| (x - m) * (x - m)).sum::<f64>() / (n - 1.0).max(1.0);
    (m, var.sqrt())
}

fn sub_draws(d: &Draws, dim: usize) -> Draws {
    let mut out = Draws::new(dim);
    for i in 0..d.len() {
        out.points.extend_from_slice(&d.point(i)[..dim]);
    }
    out.log_density = d.log_density.clone();
    out
}

fn write_draws_csv(
    path: &Path,
    post: &Posterior<'_>,
    outputs: &[String],
    draws: &[Draws],
    sbox: &SigmaDeltaBox,
) -> Result<(), Error> {
    let d = post.plan.calibrated.len();
    let mut s = format!("chain,draw,{}", post.plan.calibrated.join(","));
    if post.sigma_box.is_some() {
        for o in outputs {
            s.push_str(&format!(",sigma_delta_{o}"));
        }
    }
    s.push_str(",log_posterior\n");
    for (c, dr) in draws.iter().enumerate() {
        for i in 0..dr.len() {
            let u = dr.point(i);
            s.push_str(&format!("{c},{i}"));
            for x in post.theta(u) {
                s.push_str(&format!(",{x}"));
            }
            if post.sigma_box.is_some() {
                for k in 0..outputs.len() {
                    s.push_str(&format!(",{}", sbox.sigma(k, u[d + k])));
                }
            }
            s.push_str(&format!(",{}\n", dr.log_density[i]));
        }
    }
    write_atomic(path, s.as_bytes())
}

fn timestamps(year: i32, n: usize) -> Vec<String> {
    let start = chrono::NaiveDate::from_ymd_opt(year, 1, 1)
        .and_then(|d| d.and_hms_opt(0, 0, 0))
        .expect("valid year");
    (0..n)
        .map(|t| {
            (start + chrono::Duration::hours(t as i64))
                .format("%Y-%m-%dT%H:%M")
                .to_string()
        })
        .collect()
}

/// Writes hourly outputs as `timestamp,<output>...`.
pub fn write_outputs_csv(
    path: &Path,
    year: i32,
    o: &bemcal_energyplus::HourlyOutputs,
) -> Result<(), Error> {
    let mut s = format!("timestamp,{}\n", o.names.join(","));
    for (t, ts) in timestamps(year, o.hours()).iter().enumerate() {
        s.push_str(ts);
        for series in &o.series {
            s.push_str(&format!(",{:.6}", series[t]));
        }
        s.push('\n');
    }
    write_atomic(path, s.as_bytes())
}

fn write_bands_csv(
    path: &Path,
    year: i32,
    outputs: &[String],
    measured: &[Vec<f64>],
    bands: &[bemcal_stats::summary::PredictiveBands],
) -> Result<(), Error> {
    let mut s = String::from("timestamp");
    for o in outputs {
        s.push_str(&format!(",{o}_measured,{o}_q5,{o}_q50,{o}_q95"));
    }
    s.push('\n');
    let n = bands.first().map_or(0, |b| b.q50.len());
    for (t, ts) in timestamps(year, n).iter().enumerate() {
        s.push_str(ts);
        for (k, b) in bands.iter().enumerate() {
            let m = measured[k][t];
            let m = if m.is_finite() {
                format!("{m:.4}")
            } else {
                String::new()
            };
            s.push_str(&format!(
                ",{m},{:.4},{:.4},{:.4}",
                b.q5[t], b.q50[t], b.q95[t]
            ));
        }
        s.push('\n');
    }
    write_atomic(path, s.as_bytes())
}

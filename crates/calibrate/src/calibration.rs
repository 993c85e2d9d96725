//! A loaded calibration ([`Calibration`]): the project, its inputs and the output folder, with
//! one method per stage that the driver and the workers call.

use std::path::{Path, PathBuf};

use bemcal_energyplus::HourlyOutputs;
use bemcal_stats::lhs::Design;
use bemcal_surrogate::{ParamSpec, Split, TrainOptions, TrainingSet};
use ndarray::{Array2, Array3};

use crate::design::{
    make_design, read_outcome, simulate_point, write_design_csv, write_outcome, OUTCOME_FILE,
};
use crate::error::Error;
use crate::inputs::{load_inputs, Inputs};
use crate::output::OutputDir;
use crate::project::Project;
use crate::replacement::{Attempt, Outcome, Policy};
use crate::stage::Stage;

/// Progress messages.
pub type Log<'a> = &'a (dyn Fn(&str) + Sync);

/// A loaded calibration: the project, its inputs and the output folder. Each stage is a method;
/// the driver ([`crate::driver::drive`]) calls them in order, and the executors do the
/// expensive ones here ([`calibrate`](crate::local::calibrate)) or on workers (simulations, training
/// and chain segments as separate jobs).
pub struct Calibration {
    /// The project file's settings.
    pub project: Project,
    /// The model, weather, meters and bases, checked against each other.
    pub inputs: Inputs,
    /// The output folder every stage writes to and a rerun resumes from.
    pub out: OutputDir,
}

impl Calibration {
    /// Loads the project's inputs; `out` is where every stage writes.
    pub fn load(project: Project, out: &Path) -> Result<Calibration, Error> {
        std::fs::create_dir_all(out).map_err(|e| Error::io(out, e))?;
        let inputs = load_inputs(&project)?;
        let mut cal = Calibration {
            project,
            inputs,
            out: OutputDir::new(out),
        };
        if let Some(outcome) = read_outcome(&cal.simulations_dir()) {
            cal.learn_invalid_region(&outcome);
        }
        Ok(cal)
    }

    /// What the chains are fitted to ([`FittedData`], recorded in `holdout.txt`). A rerun
    /// into the folder reuses chains fitted to the same.
    pub fn fitted_data(&self) -> FittedData {
        FittedData {
            holdout: match &self.inputs.held_out {
                Some(h) => format!("{} ({} hours)", h.period, h.hour_count()),
                None => NO_HOLDOUT.into(),
            },
            not_fitted: self.inputs.not_fitted(),
            readings: Some(readings_fingerprint(&self.inputs)),
        }
    }

    /// Takes the region where EnergyPlus failed from a settled design into the plan, so that
    /// the chains refuse proposals there (see [`crate::plan::InvalidRegion`]).
    pub fn learn_invalid_region(&mut self, outcome: &Outcome) {
        self.inputs.plan.invalid =
            crate::plan::InvalidRegion::from_outcome(outcome, &self.inputs.plan.priors);
    }

    /// Stage 1: the design (deterministic for the project's seed); writes `design.csv`.
    pub fn design(&self) -> Result<Design, Error> {
        let p = &self.project.design;
        let d = make_design(
            &self.inputs.plan,
            &self.inputs.model,
            p.points,
            p.seed,
            p.maximin_iterations,
        )?;
        write_design_csv(&self.out.design_csv(), &self.inputs.plan, &d)?;
        Ok(d)
    }

    /// The spare hypercube that replaces design points EnergyPlus cannot simulate
    /// ([`crate::replacement`]; deterministic for the project's seed).
    pub fn spares(&self) -> Result<Design, Error> {
        let p = &self.project.design;
        make_design(
            &self.inputs.plan,
            &self.inputs.model,
            p.points,
            crate::replacement::spare_seed(p.seed),
            p.maximin_iterations,
        )
    }

    /// What to do about design points that fail (`[design]` replacements and floor).
    pub fn design_policy(&self) -> Policy {
        Policy {
            replacements: self.project.design.replacements,
            min_success: self.project.design.min_success,
        }
    }

    /// The next step of the design after `attempts` (the one rule the driver follows).
    pub fn design_step(
        &self,
        hypercube: &Design,
        spares: &Design,
        attempts: &[Attempt],
    ) -> crate::replacement::Step {
        crate::replacement::next_step(
            &self.inputs.plan,
            hypercube,
            spares,
            self.design_policy(),
            attempts,
        )
    }

    /// Records the settled design in the simulations folder (`design.json`).
    pub fn record_outcome(&self, outcome: &Outcome) -> Result<(), Error> {
        write_outcome(&self.simulations_dir(), outcome)
    }

    /// The settled design (after replacements) and the points trained on: errors if the
    /// design stage has not finished.
    pub fn settled_design(&self) -> Result<(Outcome, Design), Error> {
        let outcome = read_outcome(&self.simulations_dir()).ok_or_else(|| Error::Stage {
            stage: Stage::Design.as_str(),
            message: format!(
                "no settled design in {}",
                self.simulations_dir().join(OUTCOME_FILE).display()
            ),
        })?;
        let design = outcome.design(&self.design()?, &self.inputs.plan.priors);
        Ok((outcome, design))
    }

    /// Folder of the design-point simulations.
    pub fn simulations_dir(&self) -> PathBuf {
        self.out.simulations()
    }

    /// Stage 2, one job: simulates design point `i` (or reloads it if already done).
    pub fn simulate_point(
        &self,
        i: usize,
        x: &[f64],
    ) -> Result<(HourlyOutputs, Option<f64>), Error> {
        let dir = self.simulations_dir();
        std::fs::create_dir_all(&dir).map_err(|e| Error::io(&dir, e))?;
        simulate_point(
            &self.inputs.runner,
            &self.inputs.model,
            &self.inputs.plan.values(x),
            &self.inputs.weather_path,
            &dir,
            i,
        )
    }

    /// Stage 3: the training set from the design and its simulated outputs; writes `dataset/`.
    /// The first `base` points are the settled design's, the rest refinement draws.
    pub fn training_set(
        &self,
        base: usize,
        design: &Design,
        sims: &[HourlyOutputs],
    ) -> Result<PathBuf, Error> {
        let inp = &self.inputs;
        let n_pts = design.points.len();
        let (n_h, n_out) = (inp.features.len(), inp.outputs.len());
        let mut points = Array2::zeros((n_pts, inp.plan.calibrated.len()));
        let mut y = Array3::zeros((n_pts, n_h, n_out));
        for (i, (x, o)) in design.points.iter().zip(sims).enumerate() {
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
        let sp = &self.project.surrogate;
        // Nested over refinement rounds (see `Split::nested`): the hypercube's points split as
        // always, each appended draw keeps its side in every later round.
        let split = Split::nested(base.min(n_pts), n_pts, sp.held_out_fraction, sp.seed)?;
        let set = TrainingSet::new(params, points, &inp.features, inp.outputs.clone(), y, 0)?
            .with_split(split)?;
        let dir = self.out.dataset();
        set.write(&dir)?;
        Ok(dir)
    }

    /// Folder of the trained surrogate.
    pub fn surrogate_dir(&self) -> PathBuf {
        self.out.surrogate()
    }

    /// True once a valid surrogate is in place.
    pub fn has_surrogate(&self) -> bool {
        bemcal_surrogate::SurrogateMeta::read(&self.surrogate_dir()).is_ok()
    }

    /// Stage 4, one job: trains the surrogate on `dataset/` into `surrogate/`, starting from
    /// the weights in the surrogate folder `init` when given (a refinement round's warm start,
    /// see [`Calibration::warm_start`]; then at most `surrogate.warm_epochs` epochs).
    pub fn train(&self, init: Option<&Path>) -> Result<(), Error> {
        let sp = &self.project.surrogate;
        // The first training starts from the pretrained network where one is given and it
        // covers this building (crate::pretrained); a refinement round's from the last weights.
        // Where the start's verdict is, to carry into the new surrogate's folder: the fold's
        // folder at the first training, the warm start's at a retraining.
        let (init, verdict_from) = match (init, &sp.pretrained) {
            (Some(dir), _) => (Some(dir.to_path_buf()), Some(dir.to_path_buf())),
            (None, Some(pretrained)) => (
                crate::pretrained::start(
                    &self.inputs,
                    sp,
                    &crate::pretrained::source(&self.project, pretrained, &self.out.pretrained())?,
                    &self.out.dataset(),
                    &self.out.pretrained(),
                )?,
                Some(self.out.pretrained()),
            ),
            (None, None) => (None, None),
        };
        let opts = TrainOptions {
            epochs: match init {
                Some(_) => sp.epochs.min(sp.warm_epochs),
                None => sp.epochs,
            },
            patience: sp.patience,
            seed: sp.seed,
            batch_size: sp.batch_size,
            time_features: sp.time_features.parse().map_err(Error::Config)?,
            threads: sp.threads,
            quiet: true,
            init,
            hidden: sp.hidden,
            lr: sp.lr,
            lr_schedule: sp.lr_schedule,
            ..TrainOptions::default()
        };
        bemcal_surrogate::train(&self.out.dataset(), &self.surrogate_dir(), &opts)?;
        crate::pretrained::carry(verdict_from.as_deref(), &self.surrogate_dir())
    }
}

/// What a folder's chains were fitted to, as `holdout.txt` records it in three lines: the
/// held-out period (`none`), `not fitted:` and the meters that say `fit = false` (`none`),
/// and `fitted readings:` with a fingerprint of the fitted readings.
#[derive(Debug, Clone, PartialEq)]
pub struct FittedData {
    /// The held-out period and its hour count, or `none`.
    pub holdout: String,
    /// The meters the likelihood leaves out, in output order.
    pub not_fitted: Vec<String>,
    /// The fitted readings' fingerprint; `None` in a file written before it was recorded.
    pub readings: Option<String>,
}

impl FittedData {
    /// `holdout.txt`'s text.
    pub fn to_text(&self) -> String {
        let not_fitted = match self.not_fitted.is_empty() {
            true => EVERY_METER_FITTED.to_string(),
            false => self.not_fitted.join(", "),
        };
        let mut text = format!("{}\n{NOT_FITTED} {not_fitted}", self.holdout);
        if let Some(r) = &self.readings {
            text.push_str(&format!("\n{FITTED_READINGS} {r}"));
        }
        text
    }

    /// Reads `holdout.txt`'s text (a missing file reads as `none`). A file written before it
    /// had its `not fitted:` line takes the meters from `not_fitted_before` (the folder's
    /// summary named them).
    pub(crate) fn parse(text: &str, not_fitted_before: impl FnOnce() -> Vec<String>) -> Self {
        let mut lines = text.trim().lines().map(str::trim);
        let holdout = lines.next().unwrap_or(NO_HOLDOUT).to_string();
        let (mut not_fitted, mut readings) = (None, None);
        for line in lines {
            if let Some(n) = line.strip_prefix(NOT_FITTED).map(str::trim) {
                not_fitted = Some(match n == EVERY_METER_FITTED {
                    true => vec![],
                    false => n.split(',').map(|m| m.trim().to_string()).collect(),
                });
            } else if let Some(r) = line.strip_prefix(FITTED_READINGS) {
                readings = Some(r.trim().to_string());
            }
        }
        FittedData {
            holdout,
            not_fitted: not_fitted.unwrap_or_else(not_fitted_before),
            readings,
        }
    }

    /// The period and meters, for a message: `holdout H, every meter fitted` or `holdout H,
    /// not fitted: M`.
    pub(crate) fn describe(&self) -> String {
        match self.not_fitted.is_empty() {
            true => format!("holdout {}, every meter fitted", self.holdout),
            false => format!(
                "holdout {}, {NOT_FITTED} {}",
                self.holdout,
                self.not_fitted.join(", ")
            ),
        }
    }
}

/// The first 16 hex digits of the SHA-256 of what the likelihood fits: each fitted meter's
/// name and its hourly series less its base (NaN where missing, excluded or held out), and
/// its bills (hours and totals less the base) where it is read as bills. A
/// changed meter file, `exclude` period, base or meter time zone changes it. Deterministic:
/// the path from the files to these series has no parallel sums and no hash-ordered maps;
/// values enter rounded to 9 significant digits, in text, so the fingerprint does not depend
/// on how a platform prints or stores the last bits.
pub(crate) fn readings_fingerprint(inputs: &crate::inputs::Inputs) -> String {
    use sha2::{Digest, Sha256};
    let mut h = Sha256::new();
    for k in (0..inputs.outputs.len()).filter(|&k| inputs.fitted[k]) {
        h.update(inputs.outputs[k].as_bytes());
        for v in inputs.model_share(k) {
            match v.is_finite() {
                true => h.update(format!(";{v:.8e}").as_bytes()),
                false => h.update(b";-"),
            }
        }
        h.update(b"\n");
        if let Some(b) = &inputs.bills[k] {
            // The bills fitted: their hours and totals less the base.
            for r in b.readings(&inputs.bases[k]) {
                let (first, last) = (r.hours[0], r.hours[r.hours.len() - 1]);
                h.update(
                    format!("bill {first}..{last} {};{:.8e}\n", r.hours.len(), r.total).as_bytes(),
                );
            }
        }
    }
    h.finalize()[..8]
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect()
}

/// The label of `holdout.txt`'s third line ([`readings_fingerprint`]).
const FITTED_READINGS: &str = "fitted readings:";

/// The label of `holdout.txt`'s second line.
const NOT_FITTED: &str = "not fitted:";

/// Its value when every meter is fitted.
const EVERY_METER_FITTED: &str = "none";

/// `holdout.txt`'s first line without a held-out period.
const NO_HOLDOUT: &str = "none";

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn holdout_txt_reads_back_what_it_records_and_older_files_as_they_were() {
        let now = FittedData {
            holdout: "last 2 months (1464 hours)".into(),
            not_fitted: vec!["cooling_kwh".into(), "heating_kwh".into()],
            readings: Some("0123456789abcdef".into()),
        };
        let never = || panic!("the file names its meters");
        assert_eq!(FittedData::parse(&now.to_text(), never), now);
        let every = FittedData {
            not_fitted: vec![],
            ..now.clone()
        };
        assert_eq!(FittedData::parse(&every.to_text(), never), every);
        // Before the fingerprint: two lines; before the meters' line: the summary's.
        let old = FittedData::parse("none\nnot fitted: none\n", never);
        assert_eq!((old.holdout.as_str(), old.readings), ("none", None));
        let oldest = FittedData::parse("", || vec!["heating_kwh".into()]);
        assert_eq!(oldest.not_fitted, ["heating_kwh"]);
        assert_eq!(oldest.describe(), "holdout none, not fitted: heating_kwh");
    }
}

//! The surrogate route of `bemcal savings --surrogate-draws N`: the calibration's surrogate at
//! many posterior draws, with and without a measure, corrected onto EnergyPlus at the draws both
//! simulated (control variates, [`bemcal_stats::savings::correction`]).

use super::*;

/// The surrogate's side: the calibration's last surrogate bound to its weather, many posterior
/// draws, and its energy without any measure there and at EnergyPlus's draws.
pub(super) struct SurrogateSide {
    evaluator: bemcal_surrogate::Evaluator,
    many: Vec<Vec<f64>>,
    /// `[draw][output]`, the outputs in the calibration's order (its metered ones).
    base_many: Vec<Vec<Periods>>,
    base_few: Vec<Vec<Periods>>,
}

impl SurrogateSide {
    /// The surrogate of `cal.out` at the posterior draws `many` (their splits redrawn along
    /// `lines`) and at `few` (EnergyPlus's); `None`, said in the log, where it cannot serve
    /// (none, or of other parameters).
    pub(super) fn load(
        cal: &Calibration,
        many: Vec<Vec<f64>>,
        few: &[Vec<f64>],
        lines: &[RedrawnSplit],
        log: Log<'_>,
    ) -> Result<Option<SurrogateSide>, Error> {
        let inp = &cal.inputs;
        let dir = cal.surrogate_dir();
        let loaded = bemcal_surrogate::Surrogate::load(&dir, cal.project.surrogate.threads);
        let surrogate = match loaded {
            Ok(s) => s,
            Err(e) => {
                log(&format!("savings: EnergyPlus alone (no surrogate: {e})"));
                return Ok(None);
            }
        };
        let names: Vec<&str> = surrogate
            .meta()
            .params
            .iter()
            .map(|p| p.name.as_str())
            .collect();
        if names != inp.plan.calibrated || surrogate.meta().output_names() != inp.outputs {
            log("savings: EnergyPlus alone (the surrogate is of other parameters or outputs)");
            return Ok(None);
        }
        let mut evaluator = surrogate.bind(&inp.features)?;
        let many = redraw_splits(cal, lines, many, SPLIT_SEED + 1);
        let base_many = surrogate_periods(&mut evaluator, &many)?;
        let base_few = surrogate_periods(&mut evaluator, few)?;
        Ok(Some(SurrogateSide {
            evaluator,
            many,
            base_many,
            base_few,
        }))
    }

    /// Replaces measure `j`'s metered outputs under the calibration's weather by the
    /// surrogate's draws corrected onto EnergyPlus's at the draws both simulated.
    pub(super) fn correct(
        &mut self,
        sim: &Simulated<'_>,
        j: usize,
        m: &Measure,
        ms: &mut MeasureSavings,
    ) -> Result<(), Error> {
        let cal = sim.cal;
        let plan = &cal.inputs.plan;
        let pairs = sim.pairs(0, j);
        let ok: Vec<usize> = (0..sim.rows.len())
            .filter(|&i| pairs[i].0.is_ok() && pairs[i].1.is_ok())
            .collect();
        if ok.len() < 2 {
            return Ok(());
        }
        let edit = |x: &Vec<f64>| {
            let after = m.apply(&plan.values(x));
            plan.calibrated
                .iter()
                .map(|n| after[n])
                .collect::<Vec<f64>>()
        };
        let after_many = surrogate_periods(
            &mut self.evaluator,
            &self.many.iter().map(edit).collect::<Vec<_>>(),
        )?;
        let few: Vec<Vec<f64>> = ok.iter().map(|&i| edit(&sim.rows[i])).collect();
        let after_few = surrogate_periods(&mut self.evaluator, &few)?;
        let mut r2 = vec![];
        for (k, name) in cal.inputs.outputs.iter().enumerate() {
            let Some(slot) = (ms.outputs.iter())
                .position(|o| &o.output == name && o.weather == SavingsWeather::Calibration)
            else {
                continue;
            };
            let ep = |i: usize, with: bool| {
                let run = if with { &pairs[i].1 } else { &pairs[i].0 };
                let o = run.as_ref().expect("ok draws only");
                periods(o.get(name).unwrap_or(&[]).iter().copied())
            };
            let at = |v: &[Vec<Periods>], p: usize| v.iter().map(|x| x[k][p]).collect::<Vec<f64>>();
            let base_few: Vec<Vec<Periods>> =
                ok.iter().map(|&i| self.base_few[i].clone()).collect();
            let mut d = PerDraw {
                base: vec![[0.0; 13]; self.many.len()],
                after: vec![[0.0; 13]; self.many.len()],
                params: self.many.clone(),
            };
            let mut annual = None;
            for p in 0..13 {
                let ep_base: Vec<f64> = ok.iter().map(|&i| ep(i, false)[p]).collect();
                let ep_after: Vec<f64> = ok.iter().map(|&i| ep(i, true)[p]).collect();
                let base = corrected_onto(&at(&base_few, p), &ep_base, &at(&self.base_many, p)).0;
                let s_few = savings(&at(&base_few, p), &at(&after_few, p));
                let s_many = savings(&at(&self.base_many, p), &at(&after_many, p));
                let (saved, line) = corrected_onto(&s_few, &savings(&ep_base, &ep_after), &s_many);
                for (di, (b, s)) in base.iter().zip(&saved).enumerate() {
                    d.base[di][p] = *b;
                    d.after[di][p] = b - s;
                }
                if p == 0 {
                    annual = Some(line);
                }
            }
            let at_estimate = ms.outputs[slot].at_estimate_kwh;
            if let Some(mut o) = summarise(
                cal,
                sim.summary,
                sim.lines,
                SavingsWeather::Calibration,
                name,
                &d,
                at_estimate,
            ) {
                o.correction = annual;
                r2.push(format!("{name} {:.2}", annual.map_or(f64::NAN, |c| c.r2)));
                ms.outputs[slot] = o;
            }
        }
        ms.method = SavingsMethod::SurrogateCorrected;
        ms.surrogate_draws = self.many.len();
        ms.method_note = format!(
            "the surrogate at {} posterior draws, corrected onto EnergyPlus at {} (the share of \
             EnergyPlus's annual savings the line explains: {}); outputs without a meter by \
             EnergyPlus alone",
            self.many.len(),
            ok.len(),
            r2.join(", ")
        );
        Ok(())
    }
}

/// The surrogate's savings at many draws corrected onto EnergyPlus's (`few_energyplus`) at
/// the draws where both simulated (`few_surrogate`), and the line.
fn corrected_onto(
    few_surrogate: &[f64],
    few_energyplus: &[f64],
    many: &[f64],
) -> (Vec<f64>, Correction) {
    let line = correction(few_surrogate, few_energyplus);
    let r = residuals(&line, few_surrogate, few_energyplus);
    (corrected(&line, many, &r), line)
}

/// The surrogate's energy per output over the year and each month at each of `xs`.
fn surrogate_periods(
    evaluator: &mut bemcal_surrogate::Evaluator,
    xs: &[Vec<f64>],
) -> Result<Vec<Vec<Periods>>, Error> {
    let mut out = Vec::with_capacity(xs.len());
    for chunk in xs.chunks(8) {
        let y = evaluator.evaluate_batch(chunk)?;
        let (b, h, k) = y.dim();
        for i in 0..b {
            out.push(
                (0..k)
                    .map(|o| periods((0..h).map(|t| f64::from(y[[i, t, o]]))))
                    .collect(),
            );
        }
    }
    Ok(out)
}

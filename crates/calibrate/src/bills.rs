//! Meters read as utility bills (issue 69): each bill's total is fitted and judged, never spread
//! over hours. A billed output is one of the calibration's outputs (the surrogate predicts its
//! hours) whose hourly meter is missing throughout; its bills sit here, on the grid.
//!
//! * **Likelihood**: each bill of the calibration period against the sum of the surrogate's
//!   hours over it, its error an AR(1) of the hours summed with [`BILL_AR1`], the scale
//!   integrated out ([`bemcal_stats::likelihood::intervals`]). The temperature divides it as
//!   it divides the hourly meters'.
//! * **Held out**: a bill touching a held-out hour is held out whole.
//! * **Validation**: Guideline 14 on the bills' totals, by the monthly criteria (NMBE 5 %,
//!   CV-RMSE 15 %): the data's own resolution ([`OutputMetrics::resolution`]).

use bemcal_precal::meters::BillTable;
use bemcal_stats::likelihood::intervals::{sum_weight, IntervalLikelihood, IntervalReading};
use bemcal_stats::metrics::{g14_totals, G14Metrics};
use bemcal_stats::predictive::readings::{
    choose_scale, reading_quantiles, ReadingScale, LEVEL_FLOORS,
};
use bemcal_stats::predictive::ErrorModel;
use bemcal_weather::grid::GridYear;
use serde::{Deserialize, Serialize};

use crate::error::Error;
use crate::metrics::DemandMetrics;
use crate::project::ErrorModelSetting;

/// The AR(1) coefficient of the hourly errors summed over a bill. With the scale integrated
/// out it sets only the bills' relative weights, which for bills of similar length hardly
/// differ (hourly residuals of building models run at 0.8-0.95).
pub const BILL_AR1: f64 = 0.9;

/// The levels of a bill's predictive interval: the 90 % and 50 % central intervals and the
/// median.
const LEVELS: [f64; 5] = [0.05, 0.25, 0.5, 0.75, 0.95];

/// One meter's predictive intervals per bill (issue 69), in `summary.json`'s `predictive`:
/// EnergyPlus at the posterior draws the validation simulated, each bill's total plus the
/// error of a bill at the scale of that draw's own residuals over the calibration period's
/// bills, constant or following the bill's level ([`bemcal_stats::predictive::readings`]),
/// bounded below by zero for a meter that never reads below it.
#[derive(Debug, Clone, Serialize, Deserialize, schemars::JsonSchema)]
pub struct BillsPredictive {
    /// The calibrated output (and its meter).
    pub output: String,
    /// How a bill's error scales with its level: the meter's `[validation] error_model`
    /// (`constant` and `hour_of_day`: constant; `level`: the level, its floor the one the
    /// bills favour; `auto`: whichever the bills favour, [`choose_scale`]). Absent from a
    /// summary written before it: constant.
    #[serde(default = "constant_scale")]
    pub error_scale: ReadingScale,
    /// Share of the calibration period's bills inside their 50 % and 90 % intervals.
    pub in_sample: [f64; 2],
    /// The same for the held-out bills, where there are any.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub held_out: Option<[f64; 2]>,
    /// Each compared bill.
    pub bills: Vec<BillInterval>,
}

impl BillsPredictive {
    /// One line for the report and the CLI.
    pub fn sentence(&self) -> String {
        let count = |held_out: bool| self.bills.iter().filter(|b| b.held_out == held_out).count();
        let held = self.held_out.map_or(String::new(), |h| {
            format!(
                "; the {} held-out bills {:.0} / {:.0} %",
                count(true),
                100.0 * h[0],
                100.0 * h[1]
            )
        });
        format!(
            "{} (bills): the 50 % / 90 % intervals of a bill (EnergyPlus's total at each draw, \
             plus a bill's error at the scale of that draw's own residuals, {}) hold {:.0} / \
             {:.0} % of the calibration period's {} bills{held}",
            self.output,
            self.error_scale.describe(),
            100.0 * self.in_sample[0],
            100.0 * self.in_sample[1],
            count(false)
        )
    }
}

/// What summaries written before [`BillsPredictive::error_scale`] used.
fn constant_scale() -> ReadingScale {
    ReadingScale::Constant
}

/// One bill's predictive interval.
#[derive(Debug, Clone, Serialize, Deserialize, schemars::JsonSchema)]
pub struct BillInterval {
    /// The first day billed (`YYYY-MM-DD`).
    pub start: String,
    /// The last day billed.
    pub end: String,
    /// Held out (it touches the held-out period).
    pub held_out: bool,
    /// The bill, kWh.
    #[serde(deserialize_with = "bemcal_stats::nan::null_as_nan")]
    #[schemars(with = "bemcal_stats::nan::NumberOrNull")]
    pub measured_kwh: f64,
    /// The 5, 25, 50, 75 and 95 % quantiles, kWh.
    pub quantiles: [f64; 5],
}

/// One output's bills on the grid.
#[derive(Debug, Clone)]
pub struct BilledMeter {
    /// The bills as read (kWh), with their notes.
    pub table: BillTable,
    /// The bills the year holds whole: index into `table.bills` and its hour slots (time order).
    pub compared: Vec<(usize, Vec<usize>)>,
    /// Per compared bill, whether it is held out (it touches the held-out period).
    pub held_out: Vec<bool>,
    /// What placing the bills decided (bills outside the year).
    pub notes: Vec<String>,
}

impl BilledMeter {
    /// The bills of `table` on the grid of `year`; a bill reaching outside the year is not
    /// compared (noted). Refused when no bill lies inside the year.
    pub fn on_grid(table: BillTable, year: GridYear) -> Result<BilledMeter, Error> {
        let mut compared = vec![];
        let mut outside = vec![];
        for (i, b) in table.bills.iter().enumerate() {
            match b.hours(year) {
                Some(h) if !h.is_empty() => compared.push((i, h)),
                _ => outside.push(format!("line {}", b.line)),
            }
        }
        if compared.is_empty() {
            return Err(Error::Config(format!(
                "{}: no bill lies inside the model's year {year} ({} bills, from {} to {})",
                table.path.display(),
                table.bills.len(),
                table.bills[0].start,
                table.bills[table.bills.len() - 1].end
            )));
        }
        let notes = match outside.is_empty() {
            true => vec![],
            false => vec![format!(
                "{}: {} bills reach outside the year {year} and are not compared ({})",
                table.path.display(),
                outside.len(),
                outside.join(", ")
            )],
        };
        Ok(BilledMeter {
            held_out: vec![false; compared.len()],
            table,
            compared,
            notes,
        })
    }

    /// Holds out every compared bill that touches an hour `held[t]`.
    pub fn hold_out(&mut self, held: &[bool]) {
        for ((_, hours), out) in self.compared.iter().zip(&mut self.held_out) {
            *out = hours.iter().any(|&t| held.get(t).copied().unwrap_or(false));
        }
    }

    /// The compared bills of the calibration period (`held_out = false`) or of the held-out
    /// period: their hours and measured totals (kWh).
    fn bills_of(&self, held_out: bool) -> impl Iterator<Item = (&[usize], f64)> {
        self.compared
            .iter()
            .zip(&self.held_out)
            .filter(move |(_, &h)| h == held_out)
            .map(|((i, hours), _)| (hours.as_slice(), self.table.bills[*i].kwh))
    }

    /// Bills of the calibration period.
    pub fn calibration_bills(&self) -> usize {
        self.held_out.iter().filter(|h| !**h).count()
    }

    /// The likelihood of output `k` of `n_outputs` over `n_hours`: the calibration period's
    /// bills less `base` (the output's hourly base, kWh) over their hours.
    pub fn likelihood(
        &self,
        k: usize,
        n_outputs: usize,
        n_hours: usize,
        base: &[f64],
    ) -> Result<IntervalLikelihood, Error> {
        Ok(IntervalLikelihood::new(
            k,
            n_outputs,
            n_hours,
            self.readings(base),
            BILL_AR1,
        )?)
    }

    /// What the likelihood fits: the calibration period's bills less `base` (the output's
    /// hourly base, kWh) over their hours.
    pub fn readings(&self, base: &[f64]) -> Vec<IntervalReading> {
        self.bills_of(false)
            .map(|(hours, kwh)| IntervalReading {
                hours: hours.to_vec(),
                total: kwh - hours.iter().map(|&t| base[t]).sum::<f64>(),
            })
            .collect()
    }

    /// The billed peak demands of the calibration period against the peak hour of `sim` (with
    /// its base, kWh an hour) over each bill ([`DemandMetrics`]); None under two bills with a
    /// demand.
    pub fn demand(&self, sim: &[f64]) -> Option<DemandMetrics> {
        let (y, s): (Vec<f64>, Vec<f64>) = (self.compared.iter().zip(&self.held_out))
            .filter(|(_, &out)| !out)
            .filter_map(|((i, hours), _)| {
                let billed = self.table.bills[*i].demand_kw?;
                let peak = hours.iter().map(|&t| sim[t]).fold(f64::NAN, f64::max);
                Some((billed, peak))
            })
            .unzip();
        DemandMetrics::of(&y, &s)
    }

    /// Predictive intervals of every compared bill from `sims`, EnergyPlus's hours (with the
    /// output's base) at each posterior draw, the error's scale as `setting` says
    /// ([`BillsPredictive`]); None under three bills in the calibration period.
    pub fn predictive(
        &self,
        output: &str,
        sims: &[Vec<f64>],
        setting: ErrorModelSetting,
    ) -> Option<BillsPredictive> {
        let totals: Vec<Vec<f64>> = (sims.iter())
            .map(|sim| {
                (self.compared.iter())
                    .map(|(_, hours)| hours.iter().map(|&t| sim[t]).sum())
                    .collect()
            })
            .collect();
        let measured: Vec<f64> = (self.compared.iter())
            .map(|(i, _)| self.table.bills[*i].kwh)
            .collect();
        let weights: Vec<f64> = (self.compared.iter())
            .map(|(_, h)| sum_weight(h.len(), BILL_AR1))
            .collect();
        let hours: Vec<usize> = self.compared.iter().map(|(_, h)| h.len()).collect();
        let fitted: Vec<bool> = self.held_out.iter().map(|h| !h).collect();
        let levels = LEVEL_FLOORS.map(|floor| ReadingScale::Level { floor });
        let candidates: Vec<ReadingScale> = match setting {
            ErrorModelSetting::Fixed(ErrorModel::Constant | ErrorModel::HourOfDay) => {
                vec![ReadingScale::Constant]
            }
            ErrorModelSetting::Fixed(ErrorModel::Level) => levels.to_vec(),
            ErrorModelSetting::Auto => std::iter::once(ReadingScale::Constant)
                .chain(levels)
                .collect(),
        };
        let scale = choose_scale(&candidates, &totals, &measured, &weights, &hours, &fitted);
        let mut q = reading_quantiles(
            &totals, &measured, &weights, &hours, &fitted, scale, &LEVELS,
        )?;
        // An energy meter does not read below zero: the intervals are those of max(0, Y), as
        // the hourly meters' are.
        if measured.iter().all(|m| *m >= 0.0) {
            q.iter_mut().flatten().for_each(|x| *x = x.max(0.0));
        }
        let bills: Vec<BillInterval> = (self.compared.iter().zip(&self.held_out).zip(q))
            .map(|(((i, _), &held_out), q)| {
                let b = &self.table.bills[*i];
                BillInterval {
                    start: b.start.to_string(),
                    end: (b.end - chrono::Duration::days(1)).to_string(),
                    held_out,
                    measured_kwh: b.kwh,
                    quantiles: [q[0], q[1], q[2], q[3], q[4]],
                }
            })
            .collect();
        let inside = |held_out: bool| -> Option<[f64; 2]> {
            let of: Vec<&BillInterval> = bills.iter().filter(|b| b.held_out == held_out).collect();
            let share = |lo: usize, hi: usize| {
                let n = of.iter().filter(|b| {
                    b.quantiles[lo] <= b.measured_kwh && b.measured_kwh <= b.quantiles[hi]
                });
                n.count() as f64 / of.len() as f64
            };
            (!of.is_empty()).then(|| [share(1, 3), share(0, 4)])
        };
        Some(BillsPredictive {
            output: output.to_string(),
            error_scale: scale,
            in_sample: inside(false)?,
            held_out: inside(true),
            bills,
        })
    }

    /// Guideline 14 of the hourly simulation `sim` (with its base) on the bills of the
    /// calibration period or the held-out one; None under two bills.
    pub fn metrics(&self, sim: &[f64], held_out: bool) -> Option<G14Metrics> {
        let (y, s): (Vec<f64>, Vec<f64>) = self
            .bills_of(held_out)
            .map(|(hours, kwh)| (kwh, hours.iter().map(|&t| sim[t]).sum::<f64>()))
            .unzip();
        g14_totals(&y, &s).ok()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use bemcal_precal::meters::bills::parse_bills;
    use bemcal_precal::meters::{BillEnd, BillSpec, MeterRole};

    /// The bills of `csv` (in kWh) on the grid of 2021.
    fn meter_of(csv: &str) -> BilledMeter {
        let spec = BillSpec {
            file: "gas.csv".into(),
            role: MeterRole::Heating,
            unit: Some("kWh".into()),
            calorific_value_kwh_per_m3: None,
            end: BillEnd::Inclusive,
            estimated: Default::default(),
        };
        let table = parse_bills(csv, std::path::Path::new("gas.csv"), &spec).unwrap();
        BilledMeter::on_grid(table, GridYear::calendar(2021)).unwrap()
    }

    fn meter() -> BilledMeter {
        meter_of(
            "start,end,quantity,demand_kw\n2020-12-10,2021-01-09,100,\n2021-01-10,2021-02-08,300,2\n\
             2021-02-09,2021-03-10,200,1\n2021-03-11,2021-04-09,150,1\n",
        )
    }

    #[test]
    fn bills_outside_the_year_are_noted_and_a_held_out_hour_holds_its_bill_out() {
        let mut m = meter();
        assert_eq!(m.compared.len(), 3);
        assert!(
            m.notes[0]
                .contains("1 bills reach outside the year 2021 and are not compared (line 2)"),
            "{:?}",
            m.notes
        );
        // Hold out from 1 April: the bill of 11 March - 9 April goes whole.
        let held: Vec<bool> = (0..8760).map(|t| t >= 90 * 24).collect();
        m.hold_out(&held);
        assert_eq!(m.held_out, vec![false, false, true]);
        assert_eq!(m.calibration_bills(), 2);
        // A flat 0.4 kWh an hour: 30 days = 288 kWh against 300, 30 days against 200.
        let sim = vec![0.4; 8760];
        let g = m.metrics(&sim, false).unwrap();
        assert_eq!(g.n, 2);
        assert!(
            (g.nmbe - (12.0 - 88.0) / 250.0 * 100.0).abs() < 1e-9,
            "{g:?}"
        );
        // Billed demand against the peak hour (0.5 kWh on 20 January), over the two bills of
        // the calibration period: residuals 1.5 and 0.6.
        let mut sim = sim;
        sim[19 * 24 + 12] = 0.5;
        let d = m.demand(&sim).unwrap();
        assert_eq!((d.bills, d.mean_measured_kw), (2, 1.5));
        assert!((d.nmbe - 2.1 / 1.5 * 100.0).abs() < 1e-9, "{d:?}");
        // Predictive intervals need three bills in the calibration period: two here.
        assert!(m
            .predictive("heating", &[sim.clone()], ErrorModelSetting::Auto)
            .is_none());
        // The likelihood's readings less a base of 0.1 kWh an hour.
        let l = m.likelihood(0, 1, 8760, &vec![0.1; 8760]).unwrap();
        assert_eq!(l.readings().len(), 2);
        assert!((l.readings()[0].total - (300.0 - 72.0)).abs() < 1e-9);
    }

    /// Four bills fitted and one held out; two draws 20 % apart: each bill's interval spans
    /// both draws' totals and their noise, the shares count the bills inside, and an interval
    /// of a meter that never reads below zero starts at zero at the lowest.
    #[test]
    fn each_bill_gets_an_interval_from_the_draws_and_their_own_residuals() {
        let mut m = meter_of(
            "start,end,quantity\n2021-01-01,2021-01-30,720\n2021-01-31,2021-03-01,740\n\
             2021-03-02,2021-03-31,690\n2021-04-01,2021-04-30,0\n2021-05-01,2021-05-30,730\n",
        );
        let held: Vec<bool> = (0..8760).map(|t| t >= 120 * 24).collect();
        m.hold_out(&held);
        let draws = [vec![1.0; 8760], vec![1.2; 8760]];
        let p = m
            .predictive("heating_kwh", &draws, ErrorModelSetting::Auto)
            .unwrap();
        assert_eq!(p.bills.len(), 5);
        assert_eq!(p.bills[4].held_out as u8 + p.bills[0].held_out as u8, 1);
        for b in &p.bills {
            let q = b.quantiles;
            assert!(q.windows(2).all(|w| w[0] <= w[1]), "{b:?}");
            assert!(q[0] >= 0.0, "{b:?}");
        }
        // 30 days at 1 and 1.2 kWh an hour: 720 and 864 kWh, the median between them.
        let q = p.bills[0].quantiles;
        assert!(
            q[0] < 720.0 && 864.0 < q[4] && 720.0 < q[2] && q[2] < 864.0,
            "{q:?}"
        );
        // The April bill of 0 lies inside the 90 % interval only through its lower bound 0.
        let april = &p.bills[3];
        assert_eq!(april.measured_kwh, 0.0);
        assert!(april.quantiles[0] == 0.0, "{april:?}");
        // Shares are of the 4 fitted bills and the 1 held out.
        assert!(p
            .in_sample
            .iter()
            .all(|s| (0.0..=1.0).contains(s) && (s * 4.0).fract() == 0.0));
        assert!(p.held_out.is_some());
        assert!(
            p.sentence()
                .contains("of the calibration period's 4 bills; the 1 held-out bills"),
            "{}",
            p.sentence()
        );
    }
}

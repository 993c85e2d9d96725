//! The building's schedule as hourly inputs (issue 66): a surrogate folded from the building
//! family's pretrained network reads the schedule's value hour by hour, and that value is a
//! calibrated parameter for the hours its schedule interval covers. The trainer
//! (`pretrain.schedule_table`) writes the table into `surrogate.json` (`schedule_inputs`); the
//! runtime builds the same columns from it ([`ScheduleInputs::fill`]) after the weather and
//! time features, and the graphs form the parameter's part themselves (`q = m . (width * p)`,
//! `ScheduledSurrogate` in `python/bemcal_train/model.py`). Pure: no I/O.

use serde::{Deserialize, Serialize};

/// Hours of a day.
const HOURS: usize = 24;

/// The columns before the indicators: off-day flag, occupied flag, the fixed interval's value.
pub const LEADING_COLUMNS: [&str; 3] = ["off_day", "occupied", "schedule_fixed"];

/// One kind of day's hours (hour of day `t mod 24`, hour beginning).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DaySchedule {
    /// Per hour: the calibrated schedule parameter covering it, as an index into
    /// [`ScheduleInputs::params`], or -1 where the interval is fixed.
    pub interval: Vec<i64>,
    /// Per hour: the fixed interval's value (0 where the interval is calibrated).
    pub fixed: Vec<f64>,
    /// Per hour: 1 where the building is occupied, else 0.
    pub occupied: Vec<u8>,
}

/// `surrogate.json`'s `schedule_inputs`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ScheduleInputs {
    /// The calibrated schedule parameters, by their position among the surrogate's
    /// parameters: one indicator column each, in this order.
    pub params: Vec<usize>,
    /// Working days (day type code 0).
    pub working: DaySchedule,
    /// Days off (any other day type: weekends, holidays).
    pub off: DaySchedule,
}

impl ScheduleInputs {
    /// Hourly columns these inputs add: [`LEADING_COLUMNS`] and one indicator per parameter.
    pub fn n_columns(&self) -> usize {
        LEADING_COLUMNS.len() + self.params.len()
    }

    /// Consistency with a surrogate of `n_params` parameters; the message names the field.
    pub fn validate(&self, n_params: usize) -> Result<(), String> {
        if let Some(p) = self.params.iter().find(|&&p| p >= n_params) {
            return Err(format!(
                "schedule_inputs.params: {p} is not one of the {n_params} parameters"
            ));
        }
        for (kind, day) in [("working", &self.working), ("off", &self.off)] {
            if day.interval.len() != HOURS
                || day.fixed.len() != HOURS
                || day.occupied.len() != HOURS
            {
                return Err(format!(
                    "schedule_inputs.{kind}: interval, fixed and occupied need {HOURS} values each"
                ));
            }
            if let Some(i) = day
                .interval
                .iter()
                .find(|&&i| i < -1 || i >= self.params.len() as i64)
            {
                return Err(format!(
                    "schedule_inputs.{kind}.interval: {i} is neither -1 nor one of the {} parameters",
                    self.params.len()
                ));
            }
            if day.fixed.iter().any(|v| !v.is_finite()) || day.occupied.iter().any(|&o| o > 1) {
                return Err(format!(
                    "schedule_inputs.{kind}: fixed values must be finite and occupied 0 or 1"
                ));
            }
        }
        Ok(())
    }

    /// Writes hour `t`'s columns into `out` ([`ScheduleInputs::n_columns`] of them) for a day
    /// of type `day_type` (0: working). Identical to the trainer's `data.schedule_columns`.
    pub fn fill(&self, t: usize, day_type: f64, out: &mut [f32]) {
        let off = day_type != 0.0;
        let day = if off { &self.off } else { &self.working };
        let h = t % HOURS;
        out.fill(0.0);
        out[0] = if off { 1.0 } else { 0.0 };
        out[1] = f32::from(day.occupied[h]);
        match usize::try_from(day.interval[h]) {
            Ok(k) => out[LEADING_COLUMNS.len() + k] = 1.0,
            Err(_) => out[2] = day.fixed[h] as f32,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn day(interval: i64, fixed: f64) -> DaySchedule {
        DaySchedule {
            interval: vec![interval; HOURS],
            fixed: vec![fixed; HOURS],
            occupied: (0..HOURS).map(|h| u8::from((8..17).contains(&h))).collect(),
        }
    }

    #[test]
    fn an_hour_reads_its_days_interval() {
        let mut working = day(1, 0.0);
        working.interval[3] = 0;
        let mut off = day(-1, 0.3);
        off.occupied = vec![0; HOURS];
        let s = ScheduleInputs {
            params: vec![4, 7],
            working,
            off,
        };
        s.validate(8).unwrap();
        let mut out = vec![9.0; s.n_columns()];
        s.fill(24 + 3, 0.0, &mut out);
        assert_eq!(out, [0.0, 0.0, 0.0, 1.0, 0.0]);
        s.fill(10, 0.0, &mut out);
        assert_eq!(out, [0.0, 1.0, 0.0, 0.0, 1.0]);
        s.fill(10, 2.0, &mut out);
        assert_eq!(out, [1.0, 0.0, 0.3, 0.0, 0.0]);
        assert!(s.validate(5).unwrap_err().contains("7 is not one of the 5"));
        let mut short = s.clone();
        short.off.fixed.pop();
        assert!(short
            .validate(8)
            .unwrap_err()
            .contains("schedule_inputs.off"));
    }
}

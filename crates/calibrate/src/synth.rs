//! Synthetic measurements for demonstrations and tests: EnergyPlus at "true" parameters the
//! sampler never sees, plus measurement noise and a gap, and optionally a known model-form
//! error (an hour-of-day x season pattern) that a calibration's discrepancy term must carry.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

use bemcal_energyplus::HourlyOutputs;
use bemcal_weather::grid::GridYear;
use chrono::{Datelike, Timelike};

/// Noise and gap of synthetic measurements.
#[derive(Debug, Clone, PartialEq)]
pub struct SynthOptions {
    /// Multiplicative noise sd (fraction of the hourly value).
    pub relative_noise: f64,
    /// Additive noise sd as a fraction of the output's annual mean.
    pub absolute_noise: f64,
    /// Missing hours `[start, end)` (hour of year).
    pub gap: Option<(usize, usize)>,
    /// Seed of the noise's random generator.
    pub seed: u64,
    /// A known structured model-form error added to one meter before the noise.
    pub bias: Option<InjectedBias>,
}

/// A known model-form error on one meter: `amplitude` x the meter's annual mean x
/// [`bias_shape`] of each hour, added before the noise, so that the meters are "EnergyPlus plus
/// something the model cannot represent" with the something known (issue 71's test case).
#[derive(Debug, Clone, PartialEq)]
pub struct InjectedBias {
    /// Index of the meter in the outputs.
    pub meter: usize,
    /// Size of the pattern as a fraction of the meter's annual mean.
    pub amplitude: f64,
    /// The pattern's shape per hour slot, [`bias_shape`] at each slot's time.
    pub shape: Vec<f64>,
}

impl InjectedBias {
    /// The hour-of-day x season pattern on meter `meter` of a `hours`-slot year.
    pub fn hour_season(meter: usize, amplitude: f64, year: GridYear, hours: usize) -> Self {
        let shape = (0..hours)
            .map(|t| {
                let time = year.slot_time(t);
                bias_shape(time.hour(), time.month())
            })
            .collect();
        InjectedBias {
            meter,
            amplitude,
            shape,
        }
    }
}

/// The injected pattern's shape: 1 in working hours (9-17 h) and 0.3 otherwise, times 0.5 in
/// winter (December-February), 1.5 in summer (June-August) and 1 in spring and autumn.
pub fn bias_shape(hour: u32, month: u32) -> f64 {
    let by_hour = if (9..=17).contains(&hour) { 1.0 } else { 0.3 };
    let by_season = match month {
        12 | 1 | 2 => 0.5,
        6..=8 => 1.5,
        _ => 1.0,
    };
    by_hour * by_season
}

impl Default for SynthOptions {
    fn default() -> Self {
        SynthOptions {
            relative_noise: 0.05,
            absolute_noise: 0.02,
            // 15 July to 15 August, like the reference's missing month.
            gap: Some((195 * 24, 226 * 24)),
            seed: 42,
            bias: None,
        }
    }
}

/// Noisy copies of the outputs, NaN in the gap, never negative.
pub fn measurements(truth: &HourlyOutputs, o: &SynthOptions) -> HourlyOutputs {
    let mut rng = ChaCha8Rng::seed_from_u64(o.seed);
    let std = Normal::new(0.0, 1.0).expect("unit normal");
    let series = truth
        .series
        .iter()
        .enumerate()
        .map(|(j, s)| {
            let mean = s.iter().sum::<f64>() / s.len().max(1) as f64;
            let bias = o.bias.as_ref().filter(|b| b.meter == j);
            s.iter()
                .enumerate()
                .map(|(t, v)| {
                    let v = v + bias.map_or(0.0, |b| b.amplitude * mean * b.shape[t]);
                    if o.gap.is_some_and(|(a, b)| (a..b).contains(&t)) {
                        return f64::NAN;
                    }
                    let e1: f64 = std.sample(&mut rng);
                    let e2: f64 = std.sample(&mut rng);
                    let _ = rng.random::<u8>();
                    (v * (1.0 + o.relative_noise * e1) + o.absolute_noise * mean * e2).max(0.0)
                })
                .collect()
        })
        .collect();
    HourlyOutputs {
        names: truth.names.clone(),
        series,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn flat(hours: usize) -> HourlyOutputs {
        HourlyOutputs {
            names: vec!["heating_kwh".into(), "electricity_kwh".into()],
            series: vec![vec![1.0; hours], vec![2.0; hours]],
        }
    }

    #[test]
    fn the_injected_bias_is_the_pattern_on_its_meter_only() {
        let year = GridYear::calendar(2021);
        let o = SynthOptions {
            relative_noise: 0.0,
            absolute_noise: 0.0,
            gap: None,
            seed: 1,
            bias: Some(InjectedBias::hour_season(1, 0.2, year, 8760)),
        };
        let m = measurements(&flat(8760), &o);
        assert!(m.series[0].iter().all(|v| *v == 1.0));
        // 10:00 on 15 July (summer, working hours) and 03:00 on 15 January (winter, night).
        let at = |day: usize, hour: usize| m.series[1][day * 24 + hour];
        assert!((at(195, 10) - (2.0 + 0.2 * 2.0 * 1.5)).abs() < 1e-12);
        assert!((at(14, 3) - (2.0 + 0.2 * 2.0 * 0.3 * 0.5)).abs() < 1e-12);
    }
}

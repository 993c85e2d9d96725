//! Synthetic measurements for demonstrations and tests: EnergyPlus at "true" parameters the
//! sampler never sees, plus measurement noise and a gap.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

use bemcal_energyplus::HourlyOutputs;

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
}

impl Default for SynthOptions {
    fn default() -> Self {
        SynthOptions {
            relative_noise: 0.05,
            absolute_noise: 0.02,
            // 15 July to 15 August, like the reference's missing month.
            gap: Some((195 * 24, 226 * 24)),
            seed: 42,
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
        .map(|s| {
            let mean = s.iter().sum::<f64>() / s.len().max(1) as f64;
            s.iter()
                .enumerate()
                .map(|(t, v)| {
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

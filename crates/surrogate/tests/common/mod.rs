//! Shared synthetic data for the surrogate tests.
#![allow(dead_code)]

use bemcal_surrogate::{ParamSpec, TrainingSet};
use bemcal_weather::{DayType, HourlyFeatures};
use ndarray::{Array2, Array3};

/// A year of smooth synthetic weather (seasonal + daily temperature cycle, sun by day,
/// weekends every 7th and 1st day).
pub fn synthetic_weather(n: usize) -> HourlyFeatures {
    let tau = std::f64::consts::TAU;
    let mut f = HourlyFeatures {
        dry_bulb_c: vec![],
        rel_humidity_pct: vec![],
        wind_speed_m_s: vec![],
        global_horizontal_wh_m2: vec![],
        day_type: vec![],
    };
    for t in 0..n {
        let h = (t % 24) as f64;
        let day = t / 24;
        f.dry_bulb_c.push(
            10.0 - 12.0 * (tau * t as f64 / 8760.0).cos() + 5.0 * (tau * (h - 9.0) / 24.0).sin(),
        );
        f.rel_humidity_pct
            .push(60.0 + 20.0 * (tau * h / 24.0).cos());
        f.wind_speed_m_s
            .push(3.0 + 2.0 * (tau * day as f64 / 5.0).sin());
        f.global_horizontal_wh_m2
            .push((600.0 * (tau * (h - 6.0) / 24.0).sin()).max(0.0));
        f.day_type.push(match day % 7 {
            0 | 6 => DayType::Weekend,
            _ => DayType::Weekday,
        });
    }
    f
}

/// `n_points` design points of three parameters and a physical-looking response: heating and
/// cooling proportional to a U-value and degree-hours, electricity from a lighting power density
/// scaled by occupancy (weekday daytime).
pub fn synthetic_set(n_points: usize, weather: &HourlyFeatures) -> TrainingSet {
    let params = vec![
        ParamSpec::new("u_wall", 0.2, 2.0, 0.6),
        ParamSpec::new("lpd_w_m2", 4.0, 14.0, 9.0),
        ParamSpec::new("setpoint_heat_c", 18.0, 22.0, 20.0),
    ];
    let n = weather.len();
    let mut points = Array2::zeros((n_points, 3));
    for i in 0..n_points {
        let u = (i as f64 + 0.5) / n_points as f64;
        let v = ((i * 7 % n_points) as f64 + 0.5) / n_points as f64;
        let w = ((i * 3 % n_points) as f64 + 0.5) / n_points as f64;
        for (j, x) in [u, v, w].into_iter().enumerate() {
            points[[i, j]] = params[j].min + x * (params[j].max - params[j].min);
        }
    }
    let mut out = Array3::zeros((n_points, n, 3));
    for i in 0..n_points {
        let (u, lpd, sp) = (points[[i, 0]], points[[i, 1]], points[[i, 2]]);
        for t in 0..n {
            let prev = weather.dry_bulb_c[t.saturating_sub(1)];
            let temp = 0.7 * weather.dry_bulb_c[t] + 0.3 * prev;
            let h = t % 24;
            let occupied = weather.day_type[t] == DayType::Weekday && (8..18).contains(&h);
            let sun = weather.global_horizontal_wh_m2[t] / 1000.0;
            out[[i, t, 0]] = (u * 2.0 * (sp - temp) - 3.0 * sun).max(0.0);
            out[[i, t, 1]] = (u * 1.5 * (temp - 24.0) + 4.0 * sun).max(0.0);
            out[[i, t, 2]] = lpd * if occupied { 1.0 } else { 0.2 } + 2.0;
        }
    }
    TrainingSet::new(
        params,
        points,
        weather,
        vec![
            "heating_kwh".into(),
            "cooling_kwh".into(),
            "electricity_kwh".into(),
        ],
        out,
        42,
    )
    .expect("valid synthetic set")
}

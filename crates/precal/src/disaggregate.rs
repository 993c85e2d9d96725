//! Base-load disaggregation (reference section 2.2.1).
//!
//! * **Heating**: the base (domestic hot water) is estimated in the non-heating season as an
//!   hour-of-week profile (median per hour of week, Monday 00:00 = 0); space heating = total -
//!   base, floored at 0. The non-heating season is detected as the months whose mean outdoor dry
//!   bulb is at or above a balance point (default 15 C) and whose mean heating is at most 20 % of
//!   the largest monthly mean; a month list overrides it. The profile's peak gives the hot water
//!   peak flow: `flow [m3/s] = P [W] / (rho c dT)` with rho = 1000 kg/m3, c = 4186 J/(kg K) and
//!   the stated temperature rise (default 45 K: 10 C mains to 55 C supply).
//! * **Cooling**: a constant base (labs, mechanical rooms) = a low quantile (default 10 %) of
//!   cooling in the cold months (mean outdoor dry bulb below 10 C; the three coldest months if
//!   none), subtracted and floored at 0.
//! * **Electricity**: a `data_center` sub-meter gives a constant base (its median); otherwise the
//!   base is a low quantile (default 5 %) of night-time (00:00-05:00) electricity. The variable
//!   part is total - base, floored at 0.
//!
//! Every estimate is returned with a `method` string for the reports.

use serde::{Deserialize, Serialize};

use crate::meters::{slot_month, GridYear};
use crate::stats::{mean, median, quantile};
use chrono::Datelike;

/// Water density used for the hot water flow conversion, kg/m3.
pub const WATER_DENSITY: f64 = 1000.0;
/// Water specific heat, J/(kg K).
pub const WATER_CP: f64 = 4186.0;

/// Options of the disaggregation.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct DisaggregationOptions {
    /// Balance point for the non-heating season, C (monthly mean outdoor dry bulb).
    pub balance_point_c: f64,
    /// Months (1..=12) of the non-heating season; overrides detection.
    pub non_heating_months: Option<Vec<u32>>,
    /// Months counted as heating season for the cooling base; overrides detection.
    pub heating_months: Option<Vec<u32>>,
    /// Cold-month threshold for the cooling base, C.
    pub cold_month_c: f64,
    /// Quantile of winter cooling taken as the cooling base.
    pub cooling_base_quantile: f64,
    /// Quantile of night-time electricity taken as the base without a data center meter.
    pub night_base_quantile: f64,
    /// Domestic hot water temperature rise, K.
    pub dhw_delta_t_k: f64,
}

impl Default for DisaggregationOptions {
    fn default() -> Self {
        DisaggregationOptions {
            balance_point_c: 15.0,
            non_heating_months: None,
            heating_months: None,
            cold_month_c: 10.0,
            cooling_base_quantile: 0.1,
            night_base_quantile: 0.05,
            dhw_delta_t_k: 45.0,
        }
    }
}

/// An estimated quantity and how it was obtained.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Estimate {
    /// Identifier, e.g. `heating_base_peak_kw`.
    pub name: String,
    /// The value.
    pub value: f64,
    /// Its unit.
    pub unit: String,
    /// How it was estimated.
    pub method: String,
}

/// A derived hourly series (kWh per hour, 8,760 slots).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DerivedSeries {
    /// Column name, e.g. `space_heating`.
    pub name: String,
    /// Values, NaN where the source is missing.
    pub values: Vec<f64>,
    /// How it was derived.
    pub method: String,
}

/// Results of the disaggregation.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct Disaggregation {
    /// Scalar estimates (bases, peak flow, ...).
    pub estimates: Vec<Estimate>,
    /// Derived series.
    pub series: Vec<DerivedSeries>,
    /// Months (1..=12) used as the non-heating season.
    pub non_heating_months: Vec<u32>,
    /// Months used as the heating season (cooling base).
    pub heating_months: Vec<u32>,
    /// Heating base hour-of-week profile (168 values, Monday 00:00 first), kWh per hour.
    pub heating_base_profile: Option<Vec<f64>>,
}

impl Disaggregation {
    /// The estimate called `name`.
    pub fn estimate(&self, name: &str) -> Option<&Estimate> {
        self.estimates.iter().find(|e| e.name == name)
    }

    /// The derived series called `name`.
    pub fn get(&self, name: &str) -> Option<&DerivedSeries> {
        self.series.iter().find(|s| s.name == name)
    }
}

/// Monthly means (January first) of an 8,760-slot series, ignoring NaN.
pub fn monthly_means(values: &[f64]) -> [f64; 12] {
    let mut s = [0.0; 12];
    let mut n = [0usize; 12];
    for (t, &v) in values.iter().enumerate() {
        if v.is_finite() {
            let m = slot_month(t) as usize - 1;
            s[m] += v;
            n[m] += 1;
        }
    }
    std::array::from_fn(|m| {
        if n[m] == 0 {
            f64::NAN
        } else {
            s[m] / n[m] as f64
        }
    })
}

/// Non-heating months: mean outdoor dry bulb >= `balance_c` and mean heating <= 20 % of the
/// largest monthly mean (months without heating data count as low).
pub fn detect_non_heating_months(
    outdoor: &[f64; 12],
    heating: &[f64; 12],
    balance_c: f64,
) -> Vec<u32> {
    let peak = heating
        .iter()
        .copied()
        .filter(|v| v.is_finite())
        .fold(0.0, f64::max);
    (0..12)
        .filter(|&m| outdoor[m] >= balance_c && (heating[m].is_nan() || heating[m] <= 0.2 * peak))
        .map(|m| m as u32 + 1)
        .collect()
}

/// Cold months: mean outdoor dry bulb below `cold_c`, or the three coldest months if none.
pub fn detect_cold_months(outdoor: &[f64; 12], cold_c: f64) -> Vec<u32> {
    let mut m: Vec<u32> = (0..12)
        .filter(|&m| outdoor[m] < cold_c)
        .map(|m| m as u32 + 1)
        .collect();
    if m.is_empty() {
        let mut idx: Vec<usize> = (0..12).collect();
        idx.sort_by(|&a, &b| outdoor[a].total_cmp(&outdoor[b]));
        m = idx[..3].iter().map(|&i| i as u32 + 1).collect();
        m.sort();
    }
    m
}

/// Hour of week (Monday 00:00 = 0 .. Sunday 23:00 = 167) of slot `t` in `year`.
pub fn hour_of_week(year: GridYear, t: usize) -> usize {
    let wd = year.day_date(t / 24).weekday().num_days_from_monday() as usize;
    wd * 24 + t % 24
}

/// Median per hour of week over the slots in `months`; hours of week without data take the
/// median of all selected values. `None` if no value is selected.
pub fn hour_of_week_profile(values: &[f64], year: GridYear, months: &[u32]) -> Option<Vec<f64>> {
    let mut buckets: Vec<Vec<f64>> = vec![Vec::new(); 168];
    for (t, &v) in values.iter().enumerate() {
        if v.is_finite() && months.contains(&slot_month(t)) {
            buckets[hour_of_week(year, t)].push(v);
        }
    }
    let all: Vec<f64> = buckets.iter().flatten().copied().collect();
    if all.is_empty() {
        return None;
    }
    let fill = median(&all);
    Some(
        buckets
            .iter()
            .map(|b| if b.is_empty() { fill } else { median(b) })
            .collect(),
    )
}

/// Hot water peak volume flow (m3/s) delivering `peak_kw` with a temperature rise `delta_t_k`.
pub fn hot_water_peak_flow_m3s(peak_kw: f64, delta_t_k: f64) -> f64 {
    peak_kw * 1000.0 / (WATER_DENSITY * WATER_CP * delta_t_k)
}

fn months_str(m: &[u32]) -> String {
    m.iter().map(u32::to_string).collect::<Vec<_>>().join(",")
}

fn subtract_floor(total: &[f64], base: impl Fn(usize) -> f64) -> Vec<f64> {
    total
        .iter()
        .enumerate()
        .map(|(t, &v)| {
            if v.is_finite() {
                (v - base(t)).max(0.0)
            } else {
                f64::NAN
            }
        })
        .collect()
}

/// Heating: base profile from the non-heating season, space heating = total - base (>= 0).
pub fn disaggregate_heating(
    heating: &[f64],
    outdoor_c: &[f64],
    year: GridYear,
    opts: &DisaggregationOptions,
    out: &mut Disaggregation,
) {
    let outdoor_m = monthly_means(outdoor_c);
    let heat_m = monthly_means(heating);
    let (months, how) = match &opts.non_heating_months {
        Some(m) => (m.clone(), "months given in the options".to_string()),
        None => (
            detect_non_heating_months(&outdoor_m, &heat_m, opts.balance_point_c),
            format!(
                "months with mean outdoor dry bulb >= {} C and mean heating <= 20 % of the largest monthly mean",
                opts.balance_point_c
            ),
        ),
    };
    out.non_heating_months = months.clone();
    let Some(profile) = hour_of_week_profile(heating, year, &months) else {
        out.estimates.push(Estimate {
            name: "heating_base_mean_kw".into(),
            value: f64::NAN,
            unit: "kW".into(),
            method: format!(
                "no heating data in the non-heating season (months [{}]): base not estimated",
                months_str(&months)
            ),
        });
        return;
    };
    let method = format!(
        "median per hour of week of heating in the non-heating season, months [{}] ({how})",
        months_str(&months)
    );
    let peak = profile.iter().copied().fold(0.0, f64::max);
    out.estimates.push(Estimate {
        name: "heating_base_mean_kw".into(),
        value: mean(&profile),
        unit: "kW".into(),
        method: method.clone(),
    });
    out.estimates.push(Estimate {
        name: "heating_base_peak_kw".into(),
        value: peak,
        unit: "kW".into(),
        method: format!("maximum of the hour-of-week base profile ({method})"),
    });
    out.estimates.push(Estimate {
        name: "hot_water_peak_flow_m3s".into(),
        value: hot_water_peak_flow_m3s(peak, opts.dhw_delta_t_k),
        unit: "m3/s".into(),
        method: format!(
            "heating base peak / (rho c dT), rho = {WATER_DENSITY} kg/m3, c = {WATER_CP} J/(kg K), dT = {} K",
            opts.dhw_delta_t_k
        ),
    });
    let base: Vec<f64> = (0..heating.len())
        .map(|t| profile[hour_of_week(year, t)])
        .collect();
    out.series.push(DerivedSeries {
        name: "heating_base".into(),
        values: base.clone(),
        method: method.clone(),
    });
    out.series.push(DerivedSeries {
        name: "space_heating".into(),
        values: subtract_floor(heating, |t| base[t]),
        method: "heating - heating_base, floored at 0".into(),
    });
    out.heating_base_profile = Some(profile);
}

/// Cooling: constant base = low quantile of cooling in the cold months; space cooling = total -
/// base (>= 0).
pub fn disaggregate_cooling(
    cooling: &[f64],
    outdoor_c: &[f64],
    opts: &DisaggregationOptions,
    out: &mut Disaggregation,
) {
    let outdoor_m = monthly_means(outdoor_c);
    let (months, how) = match &opts.heating_months {
        Some(m) => (m.clone(), "months given in the options".to_string()),
        None => (
            detect_cold_months(&outdoor_m, opts.cold_month_c),
            format!(
                "months with mean outdoor dry bulb < {} C",
                opts.cold_month_c
            ),
        ),
    };
    out.heating_months = months.clone();
    let winter: Vec<f64> = cooling
        .iter()
        .enumerate()
        .filter(|&(t, _)| months.contains(&slot_month(t)))
        .map(|(_, &v)| v)
        .collect();
    let base = quantile(&winter, opts.cooling_base_quantile);
    let base = if base.is_finite() { base.max(0.0) } else { 0.0 };
    let method = format!(
        "{:.0} % quantile of hourly cooling in the heating season, months [{}] ({how})",
        opts.cooling_base_quantile * 100.0,
        months_str(&months)
    );
    out.estimates.push(Estimate {
        name: "cooling_base_kw".into(),
        value: base,
        unit: "kW".into(),
        method: method.clone(),
    });
    out.series.push(DerivedSeries {
        name: "space_cooling".into(),
        values: subtract_floor(cooling, |_| base),
        method: format!("cooling - {base:.3} kW constant base, floored at 0"),
    });
}

/// Electricity: constant base from a data center sub-meter (its median) or a low quantile of
/// night-time electricity; variable part = total - base (>= 0). Returns the base (kW).
pub fn disaggregate_electricity(
    electricity: Option<&[f64]>,
    data_center: Option<&[f64]>,
    opts: &DisaggregationOptions,
    out: &mut Disaggregation,
) -> f64 {
    let (base, method) = match (data_center, electricity) {
        (Some(dc), _) => (
            median(dc),
            "median of the data_center sub-meter (a near-constant base)".to_string(),
        ),
        (None, Some(e)) => {
            let night: Vec<f64> = e
                .iter()
                .enumerate()
                .filter(|&(t, _)| t % 24 < 5)
                .map(|(_, &v)| v)
                .collect();
            (
                quantile(&night, opts.night_base_quantile),
                format!(
                    "{:.0} % quantile of electricity at 00:00-05:00 (no data center sub-meter)",
                    opts.night_base_quantile * 100.0
                ),
            )
        }
        (None, None) => return 0.0,
    };
    let base = if base.is_finite() { base.max(0.0) } else { 0.0 };
    out.estimates.push(Estimate {
        name: "electricity_base_kw".into(),
        value: base,
        unit: "kW".into(),
        method: method.clone(),
    });
    if let Some(dc) = data_center {
        let (q05, q95) = (quantile(dc, 0.05), quantile(dc, 0.95));
        out.estimates.push(Estimate {
            name: "data_center_spread_kw".into(),
            value: q95 - q05,
            unit: "kW".into(),
            method: "95 % - 5 % quantile of the data_center sub-meter (how constant the base is)"
                .into(),
        });
    }
    if let Some(e) = electricity {
        out.series.push(DerivedSeries {
            name: "electricity_variable".into(),
            values: subtract_floor(e, |_| base),
            method: format!("electricity - {base:.3} kW constant base ({method}), floored at 0"),
        });
    }
    base
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn flow_conversion() {
        // 10 kW with 45 K: 10000 / (1000 * 4186 * 45) m3/s.
        let f = hot_water_peak_flow_m3s(10.0, 45.0);
        assert!((f - 5.3087e-5).abs() < 1e-8, "{f}");
    }

    #[test]
    fn synthetic_heating_cooling_electricity() {
        let year = 2011;
        // Outdoor: cold Jan-Apr and Oct-Dec, warm May-Sep.
        let outdoor: Vec<f64> = (0..8760)
            .map(|t| {
                if (5..=9).contains(&slot_month(t)) {
                    20.0
                } else {
                    0.0
                }
            })
            .collect();
        // DHW base 10 kW during 06-18, 2 kW otherwise; space heating 100 kW in cold months.
        let heating: Vec<f64> = (0..8760)
            .map(|t| {
                let dhw = if (6..18).contains(&(t % 24)) {
                    10.0
                } else {
                    2.0
                };
                let sh = if (5..=9).contains(&slot_month(t)) {
                    0.0
                } else {
                    100.0
                };
                dhw + sh
            })
            .collect();
        let opts = DisaggregationOptions::default();
        let mut d = Disaggregation::default();
        disaggregate_heating(&heating, &outdoor, year.into(), &opts, &mut d);
        assert_eq!(d.non_heating_months, vec![5, 6, 7, 8, 9]);
        assert_eq!(d.estimate("heating_base_peak_kw").unwrap().value, 10.0);
        let sh = &d.get("space_heating").unwrap().values;
        assert_eq!(sh[10], 100.0);
        assert_eq!(sh[4000], 0.0);
        let cooling: Vec<f64> = (0..8760).map(|t| 5.0 + (t % 3) as f64).collect();
        disaggregate_cooling(&cooling, &outdoor, &opts, &mut d);
        assert_eq!(d.estimate("cooling_base_kw").unwrap().value, 5.0);
        let e: Vec<f64> = (0..8760).map(|t| 50.0 + (t % 24) as f64).collect();
        let b = disaggregate_electricity(Some(&e), None, &opts, &mut d);
        assert!((50.0..51.0).contains(&b), "{b}");
    }
}

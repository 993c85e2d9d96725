//! The case at an index: a building spec, its climate and its parameters' values. Pure: the
//! manifest and the index decide everything, so a rerun, a larger corpus or another machine
//! draws the same case.
//!
//! Building `b` draws its spec and climate from ChaCha8 stream `2 b` of the manifest's seed;
//! its point `p` draws the parameters from stream `2 b + 1` of the seed plus `p`. Parameters are
//! uniform over each default prior's support widened by `widen` of its range on each side,
//! clamped to [`physical_bounds`], redrawn until the model's constraints hold.

use bemcal_energyplus::building::{default_weekday_bounds, default_weekend_bounds};
use bemcal_energyplus::{BuildingSpec, Model, ParameterValues};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::manifest::Manifest;

/// How many times a parameter draw is repeated to meet the model's constraints.
const CONSTRAINT_TRIES: usize = 1000;

/// One building-year of the corpus.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Case {
    /// The case's index in the manifest's sequence.
    pub index: usize,
    /// The building it belongs to (`index / points_per_building`).
    pub building: usize,
    /// Its point within the building.
    pub point: usize,
    /// The climate's name.
    pub climate: String,
    /// The generated building.
    pub spec: BuildingSpec,
    /// Every parameter of the building, by name.
    pub values: ParameterValues,
    /// Each parameter's population range `[low, high]` the value was drawn from.
    pub ranges: std::collections::BTreeMap<String, [f64; 2]>,
}

impl Case {
    /// The case's key: its content and the simulation's revision (16 hex digits).
    pub fn key(&self) -> String {
        use sha2::Digest;
        let json = serde_json::to_vec(&(
            bemcal_energyplus::SIMULATION_REVISION,
            &self.climate,
            &self.spec,
            &self.values,
        ))
        .expect("a case serialises");
        hex::encode(&sha2::Sha256::digest(json)[..8])
    }
}

/// The case at `index`.
pub fn case(manifest: &Manifest, index: usize) -> Case {
    let building = index / manifest.points_per_building;
    let point = index % manifest.points_per_building;
    let mut rng = ChaCha8Rng::seed_from_u64(manifest.seed);
    rng.set_stream(2 * building as u64);
    let (spec, climate) = building_spec(manifest, building, &mut rng);
    let mut rng = ChaCha8Rng::seed_from_u64(manifest.seed.wrapping_add(point as u64));
    rng.set_stream(2 * building as u64 + 1);
    let (values, ranges) = parameter_values(&spec, manifest.widen, &mut rng);
    Case {
        index,
        building,
        point,
        climate,
        spec,
        values,
        ranges,
    }
}

/// A building spec and its climate, drawn over the manifest's spec space.
fn building_spec(m: &Manifest, building: usize, rng: &mut ChaCha8Rng) -> (BuildingSpec, String) {
    let s = &m.spec;
    let uniform = |rng: &mut ChaCha8Rng, r: [f64; 2]| r[0] + (r[1] - r[0]) * rng.random::<f64>();
    let pick = |rng: &mut ChaCha8Rng, n: usize| rng.random_range(0..n);
    let storeys = rng.random_range(s.storeys[0]..=s.storeys[1]);
    let length = uniform(rng, s.length_m);
    let width = (length / uniform(rng, s.aspect)).max(3.0);
    let floor_to_floor = uniform(rng, s.floor_to_floor_m);
    let window_to_wall = uniform(rng, s.window_to_wall);
    let mut zoning = s.zoning[pick(rng, s.zoning.len())];
    let heating_source = s.heating_source[pick(rng, s.heating_source.len())];
    let hvac = s.hvac[pick(rng, s.hvac.len())];
    let start = rng.random_range(s.occupied_start[0]..=s.occupied_start[1]);
    let end = rng.random_range(s.occupied_end[0]..=s.occupied_end[1]);
    let weekday = merged(&default_weekday_bounds(), s.merge_boundaries, rng);
    let weekend = merged(&default_weekend_bounds(), s.merge_boundaries, rng);
    let climate = m.climates[pick(rng, m.climates.len())].name.clone();
    let perimeter_depth = 4.57;
    if 2.0 * perimeter_depth + 1.0 > length.min(width) {
        zoning = bemcal_energyplus::building::Zoning::OnePerFloor;
    }
    let round = |x: f64, per_unit: f64| (x * per_unit).round() / per_unit;
    let spec = BuildingSpec {
        name: format!("corpus-{building:05}"),
        storeys,
        footprint_m: [round(length, 10.0), round(width, 10.0)],
        floor_to_floor_m: round(floor_to_floor, 100.0),
        zoning,
        perimeter_depth_m: perimeter_depth,
        window_to_wall: round(window_to_wall, 1000.0),
        heating_source,
        timesteps_per_hour: m.timesteps_per_hour,
        occupied_hours: [start, end],
        weekday_boundaries: weekday,
        weekend_boundaries: weekend,
        hvac,
        year: m.year.into(),
        holidays: m.holidays.clone(),
        ..BuildingSpec::default()
    };
    (spec, climate)
}

/// `bounds` (ending at 24) with each interior boundary dropped with chance `p`.
fn merged(bounds: &[u32], p: f64, rng: &mut ChaCha8Rng) -> Vec<u32> {
    let last = bounds.len() - 1;
    bounds
        .iter()
        .enumerate()
        .filter(|&(i, _)| i == last || rng.random::<f64>() >= p)
        .map(|(_, &b)| b)
        .collect()
}

/// Bounds no population draw crosses, by parameter name: fractions in (0, 1], SHGC a glazing
/// can have, positive conductivities and densities.
pub fn physical_bounds(name: &str, prior_min: f64) -> (f64, f64) {
    if name.starts_with("schedule_") {
        return (0.02, 1.0);
    }
    match name {
        "shgc" => (0.1, 0.9),
        "chilled_water_supply_temp" => (2.0, 12.0),
        _ if prior_min >= 0.0 => (0.5 * prior_min, f64::INFINITY),
        _ => (f64::NEG_INFINITY, f64::INFINITY),
    }
}

/// Every parameter of `spec`, drawn from its population range; the ranges beside.
fn parameter_values(
    spec: &BuildingSpec,
    widen: f64,
    rng: &mut ChaCha8Rng,
) -> (
    ParameterValues,
    std::collections::BTreeMap<String, [f64; 2]>,
) {
    let model = Model::generated(spec.clone());
    let ranges: std::collections::BTreeMap<String, [f64; 2]> = model
        .parameters()
        .iter()
        .map(|d| {
            let (lo, hi) = physical_bounds(&d.name, d.prior.min);
            let w = widen * (d.prior.max - d.prior.min);
            let range = [(d.prior.min - w).max(lo), (d.prior.max + w).min(hi)];
            (d.name.clone(), range)
        })
        .collect();
    let mut values = ParameterValues::new();
    for _ in 0..CONSTRAINT_TRIES {
        values = ranges
            .iter()
            .map(|(n, r)| (n.clone(), r[0] + (r[1] - r[0]) * rng.random::<f64>()))
            .collect();
        if model.values(&values).is_ok() {
            break;
        }
    }
    (values, ranges)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn manifest() -> Manifest {
        Manifest::parse(
            r#"
name = "t"
seed = 7
cases = 10
points_per_building = 2
[spec]
storeys = [1, 3]
length_m = [15.0, 40.0]
aspect = [1.0, 2.0]
floor_to_floor_m = [3.0, 4.0]
window_to_wall = [0.2, 0.5]
zoning = ["one_per_floor", "perimeter_core"]
heating_source = ["boiler", "district"]
hvac = ["vav_reheat", "doas_fan_coil"]
occupied_start = [6, 8]
occupied_end = [17, 20]
merge_boundaries = 0.3
[[climates]]
name = "a"
weather = "a.epw"
[[climates]]
name = "b"
weather = "b.epw"
"#,
            std::path::Path::new("m.toml"),
        )
        .unwrap()
    }

    #[test]
    fn a_case_is_its_index() {
        let m = manifest();
        assert_eq!(case(&m, 3), case(&m, 3));
        assert_eq!(case(&m, 3).key(), case(&m, 3).key());
        assert_ne!(case(&m, 3).key(), case(&m, 4).key());
    }

    #[test]
    fn points_of_a_building_share_its_spec_not_its_values() {
        let m = manifest();
        let (a, b) = (case(&m, 4), case(&m, 5));
        assert_eq!((a.building, a.point, b.building, b.point), (2, 0, 2, 1));
        assert_eq!(a.spec, b.spec);
        assert_eq!(a.climate, b.climate);
        assert_ne!(a.values, b.values);
    }

    #[test]
    fn cases_are_valid_buildings_inside_their_ranges() {
        let m = manifest();
        for i in 0..40 {
            let c = case(&m, i);
            c.spec.validate().unwrap();
            let model = Model::generated(c.spec.clone());
            model.values(&c.values).unwrap();
            assert_eq!(c.values.len(), model.parameters().len());
            for (n, v) in &c.values {
                let r = c.ranges[n];
                assert!(r[0] <= *v && *v <= r[1], "{n} = {v} outside {r:?}");
            }
        }
    }

    #[test]
    fn population_ranges_widen_the_prior_within_physical_bounds() {
        let m = manifest();
        let c = case(&m, 0);
        // equipment: prior 10..25, widened by 0.25 x 15 on each side.
        assert_eq!(c.ranges["equipment_power_density"], [6.25, 28.75]);
        let s = c
            .ranges
            .iter()
            .find(|(n, _)| n.starts_with("schedule_"))
            .unwrap()
            .1;
        assert!(s[0] >= 0.02 && s[1] <= 1.0);
    }
}

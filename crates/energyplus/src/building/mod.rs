//! A parametric office/laboratory building written as EnergyPlus 25.2 input.
//!
//! Users rarely have a detailed model of each building; a portfolio needs one per building. A
//! [`BuildingSpec`] (a short TOML file) describes the massing, zoning, glazing and HVAC; bemcal
//! writes the IDF itself: rectangular storeys, one zone per floor or perimeter + core zones with
//! matched interzone surfaces, a VAV system with hot-water reheat split over two air-handling
//! units (or dedicated outdoor-air systems with fan coils, [`HvacSystem`]; HVACTemplate
//! objects, expanded before the run), chilled water from a district plant,
//! hot water from a boiler or district heating, and a stand-alone domestic hot water heater.
//!
//! Every calibration parameter of the reference study (its Tables 1-2) is exposed by name with
//! the reference's triangular prior as default ([`BuildingSpec::parameters`]).

use serde::{Deserialize, Serialize};

use bemcal_weather::grid::GridYear;
use bemcal_weather::{Calendar, Holidays};

use crate::idf::{num, Idf};
use crate::params::{Constraint, ParameterDef, ParameterValues, TriangularPrior};
use crate::Error;

mod geometry;
mod hvac;

pub use hvac::HvacSystem;

/// Maximum warm-up days (`Building`). EnergyPlus's default of 25 is too few for heavy
/// constructions at some points of the priors (a 3-storey 50 x 30 m building's top floor still
/// failed the loads tolerance after 25 days); days past convergence are never run, so this
/// only costs where it is needed.
pub const MAX_WARMUP_DAYS: u32 = 50;

/// Design conditions at which HVAC is sized, fixed whatever the sampled operating values: the
/// thermostat on the sizing days, the cooling coils' design supply air (the preheat coil's 2 K
/// below it) and the chilled-water loop's design temperature. Equipment is then sized once for
/// the building and its loads and operated at the sampled set-points. Sizing at the sampled
/// values made design points fail (coil-UA calculation at low cooling set-points) and made the
/// set-points act through equipment size instead of operation. The occupied set-points'
/// prior modes, and ASHRAE's usual 12.8 C supply air from 6.7 C chilled water.
pub const DESIGN_COOLING_SETPOINT_C: f64 = 24.0;
/// See [`DESIGN_COOLING_SETPOINT_C`].
pub const DESIGN_HEATING_SETPOINT_C: f64 = 21.0;
/// See [`DESIGN_COOLING_SETPOINT_C`].
pub const DESIGN_SUPPLY_AIR_C: f64 = 12.8;
/// See [`DESIGN_COOLING_SETPOINT_C`].
pub const DESIGN_CHILLED_WATER_C: f64 = 6.7;

/// Zoning of each storey.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum Zoning {
    /// One thermal zone per floor.
    OnePerFloor,
    /// Four perimeter zones and a core zone per floor.
    PerimeterCore,
}

/// Where space heating hot water comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum HeatingSource {
    /// Natural-gas hot-water boiler in the building (the reference building has four).
    Boiler,
    /// District heating hot water.
    District,
}

/// The building description.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct BuildingSpec {
    /// The building's name (the IDF's `Building` object).
    #[serde(default = "default_name")]
    pub name: String,
    /// Storeys above ground.
    #[serde(default = "default_storeys")]
    pub storeys: u32,
    /// Footprint length (east-west, x) and width (north-south, y), m.
    #[serde(default = "default_footprint")]
    pub footprint_m: [f64; 2],
    /// Height of a storey, floor to floor, m.
    #[serde(default = "default_floor_height")]
    pub floor_to_floor_m: f64,
    /// One zone per floor, or perimeter and core zones.
    #[serde(default = "default_zoning")]
    pub zoning: Zoning,
    /// Depth of the perimeter zones, m (with perimeter and core zoning).
    #[serde(default = "default_perimeter_depth")]
    pub perimeter_depth_m: f64,
    /// Window-to-wall ratio of every facade, 0..1.
    #[serde(default = "default_wwr")]
    pub window_to_wall: f64,
    /// Where the hot water comes from.
    #[serde(default = "default_heating")]
    pub heating_source: HeatingSource,
    /// Simulation time steps per hour (EnergyPlus `Timestep`).
    #[serde(default = "default_timesteps")]
    pub timesteps_per_hour: u32,
    /// The shortest HVAC time step, in minutes (EnergyPlus `ConvergenceLimits`, Minimum System
    /// Timestep). Unset: EnergyPlus's own rule, the HVAC step ratcheting down to 1 minute inside
    /// a zone time step while the system is far from converged. `0` holds it at the zone time
    /// step: fewer HVAC iterations for a coarser HVAC solution (the small model at one zone
    /// step per hour: an annual run 1.4 s against 2.5 s, its annual meters within 0.3 %).
    /// Left out of the serialised spec when unset, so that earlier specs serialise as they did.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub minimum_system_timestep_minutes: Option<u32>,
    /// Occupied period on weekdays, [start hour, end hour): set-points and outdoor air switch
    /// between their occupied and unoccupied values at these hours.
    #[serde(default = "default_occupied")]
    pub occupied_hours: [u32; 2],
    /// Hour (1..=24) at which each weekday schedule interval ends; the last must be 24.
    #[serde(default = "default_weekday_bounds")]
    pub weekday_boundaries: Vec<u32>,
    /// Hour (1..=24) at which each weekend/holiday schedule interval ends; the last must be 24.
    #[serde(default = "default_weekend_bounds")]
    pub weekend_boundaries: Vec<u32>,
    /// Hour (1..=24) at which each partial day's schedule interval ends (pre-calibration's
    /// `priors.toml` gives them where the meters show partial days); the last must be 24. Only
    /// a calendar with partial days (`partial` in `day_types_file`) uses them: those days run
    /// their own interval fractions ([`partial_param`]) and the weekday's occupied hours.
    /// Unset with partial days: the weekday's default intervals.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub partial_boundaries: Vec<u32>,
    /// One supply-air temperature parameter per AHU instead of one shared by both.
    #[serde(default)]
    pub separate_ahu_supply_air: bool,
    /// The HVAC system: `vav_reheat` (the default) or `doas_fan_coil`. Left out of the
    /// serialised spec at its default, so that earlier specs serialise as they did.
    #[serde(default, skip_serializing_if = "HvacSystem::is_default")]
    pub hvac: HvacSystem,
    /// Sensible effectiveness of the dedicated outdoor-air system's heat recovery (0..0.95;
    /// 0, the default, for none). Only with `hvac = "doas_fan_coil"`.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub heat_recovery_effectiveness: f64,
    /// A differential dry-bulb economizer on the VAV air-handling units: outdoor air beyond the
    /// minimum whenever it is cooler than the return air and cooling is wanted (free cooling,
    /// which in a dry climate carries most of an efficient building's cooling). Off by default
    /// (the reference building has none). Only with `hvac = "vav_reheat"`.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub economizer: bool,
    /// The year simulated: a calendar year (`2021`) or twelve months from another month
    /// (`"2017-04"`: 1 April 2017 to 31 March 2018, the run period across the year end), which
    /// sets the weekdays and holidays of each date; it must be the meters' year.
    #[serde(default = "crate::calendar::default_year")]
    pub year: GridYear,
    /// Holidays run on the weekend schedule (`RunPeriodControl:SpecialDays`); the same
    /// calendar gives the surrogate its day types.
    #[serde(default)]
    pub holidays: Holidays,
    /// A file of holiday dates (`bemcal_weather::read_holiday_list`), relative to the spec;
    /// its dates replace `holidays`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub holidays_file: Option<std::path::PathBuf>,
    /// The day-type calendar the meters show (pre-calibration's `calendar.csv`: date and
    /// label), relative to the spec: each listed date runs the schedule of its label instead of
    /// the weekday/weekend rule (a school's breaks, a Friday-Saturday weekend, a lab open on
    /// Saturdays). Read into `observed_day_types`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub day_types_file: Option<std::path::PathBuf>,
    /// The dates `day_types_file` lists and their day types.
    #[serde(skip)]
    pub observed_day_types: std::collections::BTreeMap<chrono::NaiveDate, bemcal_weather::DayType>,
    /// Overrides of default priors, by parameter name.
    #[serde(default)]
    pub priors: std::collections::BTreeMap<String, TriangularPrior>,
}

fn is_zero(x: &f64) -> bool {
    *x == 0.0
}

fn default_name() -> String {
    "bemcal-office".into()
}
fn default_storeys() -> u32 {
    4
}
fn default_footprint() -> [f64; 2] {
    // 4 x 71.5 x 40 = 11,440 m2, the reference building's ~11,437 m2.
    [71.5, 40.0]
}
fn default_floor_height() -> f64 {
    3.96
}
fn default_zoning() -> Zoning {
    Zoning::PerimeterCore
}
fn default_perimeter_depth() -> f64 {
    4.57
}
fn default_wwr() -> f64 {
    0.33
}
fn default_heating() -> HeatingSource {
    HeatingSource::Boiler
}
fn default_timesteps() -> u32 {
    4
}
fn default_occupied() -> [u32; 2] {
    [7, 19]
}
/// Default weekday intervals: 12, as in the reference.
pub fn default_weekday_bounds() -> Vec<u32> {
    vec![6, 7, 8, 9, 11, 13, 15, 17, 18, 19, 21, 24]
}
/// Default weekend intervals: 10, as in the reference.
pub fn default_weekend_bounds() -> Vec<u32> {
    vec![6, 8, 10, 12, 14, 16, 18, 20, 22, 24]
}

/// Reference Table 2 schedule priors (weekdays, 12 intervals).
const WEEKDAY_PRIORS: [(f64, f64, f64); 12] = [
    (0.1, 0.2, 0.3),
    (0.1, 0.35, 0.6),
    (0.4, 0.5, 0.6),
    (0.4, 0.55, 0.7),
    (0.5, 0.65, 0.8),
    (0.5, 0.7, 0.9),
    (0.5, 0.65, 0.8),
    (0.4, 0.55, 0.7),
    (0.3, 0.45, 0.6),
    (0.3, 0.4, 0.5),
    (0.2, 0.3, 0.4),
    (0.1, 0.2, 0.3),
];
/// Reference Table 2 schedule priors (weekends, 10 intervals).
const WEEKEND_PRIORS: [(f64, f64, f64); 10] = [
    (0.1, 0.15, 0.2),
    (0.1, 0.25, 0.4),
    (0.2, 0.35, 0.5),
    (0.2, 0.35, 0.5),
    (0.3, 0.45, 0.6),
    (0.3, 0.45, 0.6),
    (0.2, 0.35, 0.5),
    (0.1, 0.25, 0.4),
    (0.1, 0.25, 0.4),
    (0.1, 0.2, 0.3),
];

/// Floor area of the reference building (Crocker Science Center), m2.
pub const REFERENCE_FLOOR_AREA_M2: f64 = 11_437.0;

/// Effective thickness of the glazing layer that turns the reference's "window glass
/// conductivity" (0.01-0.02 W/m-K) into a glazing U-factor: U = 1 / (R_films + t / k).
pub const GLASS_EQUIVALENT_THICKNESS_M: f64 = 0.005;
/// Interior + exterior film resistance used in that mapping, m2-K/W.
pub const GLASS_FILM_RESISTANCE: f64 = 0.17;

/// Glazing U-factor (W/m2-K) for an equivalent glass-layer conductivity (W/m-K).
pub fn glazing_u_factor(glass_conductivity: f64) -> f64 {
    1.0 / (GLASS_FILM_RESISTANCE + GLASS_EQUIVALENT_THICKNESS_M / glass_conductivity)
}

impl Default for BuildingSpec {
    fn default() -> Self {
        toml::from_str("").expect("all fields have defaults")
    }
}

struct P {
    name: &'static str,
    unit: &'static str,
    description: &'static str,
    prior: (f64, f64, f64),
}

const ENGINEERING: [P; 16] = [
    P { name: "wall_insulation_conductivity", unit: "W/m-K", description: "conductivity of the wall insulation layer", prior: (0.03, 0.04, 0.05) },
    P { name: "roof_insulation_conductivity", unit: "W/m-K", description: "conductivity of the roof insulation layer", prior: (0.08, 0.09, 0.10) },
    P { name: "window_glass_conductivity", unit: "W/m-K", description: "equivalent glass conductivity, mapped to the glazing U-factor (5 mm layer + 0.17 m2-K/W films)", prior: (0.01, 0.015, 0.02) },
    P { name: "shgc", unit: "-", description: "window solar heat gain coefficient", prior: (0.3, 0.5, 0.8) },
    P { name: "equipment_power_density", unit: "W/m2", description: "electric equipment power per floor area", prior: (10.0, 17.5, 25.0) },
    P { name: "lighting_power_density", unit: "W/m2", description: "lighting power per floor area", prior: (5.0, 10.0, 15.0) },
    P { name: "people_area_per_person", unit: "m2/person", description: "floor area per person", prior: (5.0, 10.0, 15.0) },
    P { name: "cooling_setpoint_occupied", unit: "C", description: "cooling set-point at occupied hours", prior: (20.0, 24.0, 26.0) },
    P { name: "cooling_setpoint_unoccupied", unit: "C", description: "cooling set-point at unoccupied hours", prior: (24.0, 26.0, 28.0) },
    P { name: "heating_setpoint_occupied", unit: "C", description: "heating set-point at occupied hours", prior: (18.0, 21.0, 24.0) },
    P { name: "heating_setpoint_unoccupied", unit: "C", description: "heating set-point at unoccupied hours", prior: (12.0, 18.0, 20.0) },
    P { name: "chilled_water_supply_temp", unit: "C", description: "chilled water supply temperature", prior: (3.0, 6.0, 9.0) },
    P { name: "supply_air_temp", unit: "C", description: "supply air temperature of each AHU", prior: (10.0, 14.0, 18.0) },
    P { name: "outdoor_air_ach_occupied", unit: "1/h", description: "outdoor air at occupied hours", prior: (0.8, 1.1, 1.4) },
    P { name: "outdoor_air_ach_unoccupied", unit: "1/h", description: "outdoor air at unoccupied hours", prior: (0.4, 0.595, 0.79) },
    P { name: "hot_water_peak_flow", unit: "m3/s", description: "domestic hot water peak flow", prior: (0.0, 0.0015, 0.003) },
];

/// Name of the n-th (1-based) weekday schedule interval fraction.
pub fn weekday_param(n: usize) -> String {
    format!("schedule_weekday_{n:02}")
}
/// Name of the n-th (1-based) weekend schedule interval fraction.
pub fn weekend_param(n: usize) -> String {
    format!("schedule_weekend_{n:02}")
}
/// Name of the n-th (1-based) partial day's schedule interval fraction.
pub fn partial_param(n: usize) -> String {
    format!("schedule_partial_{n:02}")
}

/// The default prior of a partial day's interval `i` (0-based) on the weekday's default
/// intervals: from 0.1 to the weekday's maximum, its mode halfway between the weekday's and a
/// quiet day's 0.15 (a partial day lies between a working day and a day off).
fn default_partial_prior(i: usize) -> (f64, f64, f64) {
    let (_, mode, max) = WEEKDAY_PRIORS.get(i).copied().unwrap_or((0.1, 0.4, 0.8));
    (0.1, 0.5 * (mode + 0.15), max)
}

impl BuildingSpec {
    /// Parses and validates a spec from TOML text.
    pub fn from_toml(text: &str, path: &std::path::Path) -> Result<BuildingSpec, Error> {
        let mut spec: BuildingSpec = crate::parse_toml(text, path)?;
        let (holidays, observed) = crate::calendar::read_calendar_files(
            text,
            path,
            spec.holidays_file.as_ref(),
            spec.day_types_file.as_ref(),
        )?;
        if let Some(h) = holidays {
            spec.holidays = h;
        }
        spec.observed_day_types = observed;
        spec.check_fields().map_err(|(key, message)| Error::Input {
            path: path.to_path_buf(),
            line: crate::toml_line(text, &key.iter().map(String::as_str).collect::<Vec<_>>()),
            message,
        })?;
        Ok(spec)
    }

    /// The spec with a retrofit measure's edits of its fields (`occupied_hours = [8, 18]`,
    /// `economizer = true`), each a field of [`BuildingSpec::MEASURE_FIELDS`] in the spec
    /// file's own form, checked as a spec file's fields are. Refused: other fields (the
    /// building's geometry, calendar and simulation settings are not what a retrofit changes),
    /// a value of the wrong form, and edits that leave the spec as it was.
    pub fn edited(
        &self,
        edits: &std::collections::BTreeMap<String, serde_json::Value>,
    ) -> Result<BuildingSpec, String> {
        let mut value = serde_json::to_value(self).map_err(|e| e.to_string())?;
        let fields = value
            .as_object_mut()
            .ok_or("a building spec serialises to a table")?;
        for (key, v) in edits {
            if !Self::MEASURE_FIELDS.contains(&key.as_str()) {
                return Err(format!(
                    "building.{}: not a field a measure may edit (the building's geometry, \
                     calendar and simulation settings stay the calibration's); it may edit {}",
                    bemcal_excerpt::excerpt(key, 40),
                    Self::MEASURE_FIELDS.join(", ")
                ));
            }
            fields.insert(key.clone(), v.clone());
        }
        let mut spec: BuildingSpec = serde_json::from_value(value)
            .map_err(|e| format!("building: {}", bemcal_excerpt::shorten(&e.to_string())))?;
        spec.observed_day_types = self.observed_day_types.clone();
        spec.validate().map_err(|e| format!("building: {e}"))?;
        if spec == *self {
            return Err("building: the edits leave the building as it is".into());
        }
        Ok(spec)
    }

    /// The fields a retrofit measure may edit ([`BuildingSpec::edited`]): operation and
    /// systems, and the windows.
    pub const MEASURE_FIELDS: [&'static str; 5] = [
        "occupied_hours",
        "window_to_wall",
        "hvac",
        "heat_recovery_effectiveness",
        "economizer",
    ];

    /// Checks geometry, schedule boundaries and prior overrides.
    pub fn validate(&self) -> Result<(), String> {
        self.check_fields().map_err(|(_, message)| message)
    }

    /// [`BuildingSpec::validate`], with the TOML key of the field at fault (`["footprint_m"]`,
    /// `["priors", "shgc"]`) so that a spec file's message can name its line.
    fn check_fields(&self) -> Result<(), (Vec<String>, String)> {
        self.check_geometry()?;
        self.check_systems()?;
        self.check_schedules()?;
        self.check_priors()
    }

    /// Storeys, footprint, heights, perimeter depth and windows.
    fn check_geometry(&self) -> Result<(), (Vec<String>, String)> {
        let at = |key: &str, message: String| (vec![key.to_string()], message);
        if self.storeys == 0 || self.storeys > 60 {
            return Err(at(
                "storeys",
                format!("storeys = {}, expected 1..=60", self.storeys),
            ));
        }
        let [l, w] = self.footprint_m;
        // Finite and bounded: an infinite footprint passed ">= 3 m" and made an infinite floor
        // area, which the hot water prior (scaled by floor area) then reported as its own fault.
        if !((3.0..=1000.0).contains(&l) && (3.0..=1000.0).contains(&w)) {
            return Err(at(
                "footprint_m",
                format!("footprint_m = [{l:?}, {w:?}], expected two finite lengths of 3..1000 m"),
            ));
        }
        if !(2.4..=10.0).contains(&self.floor_to_floor_m) {
            return Err(at(
                "floor_to_floor_m",
                format!(
                    "floor_to_floor_m = {:?}, expected 2.4..10 m",
                    self.floor_to_floor_m
                ),
            ));
        }
        if !(self.perimeter_depth_m.is_finite() && self.perimeter_depth_m > 0.0) {
            return Err(at(
                "perimeter_depth_m",
                format!(
                    "perimeter_depth_m = {:?}, expected a finite depth > 0 m",
                    self.perimeter_depth_m
                ),
            ));
        }
        if self.zoning == Zoning::PerimeterCore && 2.0 * self.perimeter_depth_m + 1.0 > l.min(w) {
            return Err(at(
                "perimeter_depth_m",
                format!(
                    "perimeter_depth_m = {} leaves no core in a {l} x {w} m footprint",
                    self.perimeter_depth_m
                ),
            ));
        }
        if !(0.01..=0.9).contains(&self.window_to_wall) {
            return Err(at(
                "window_to_wall",
                format!(
                    "window_to_wall = {:?}, expected 0.01..0.9",
                    self.window_to_wall
                ),
            ));
        }
        Ok(())
    }

    /// The time step and what the HVAC system can have.
    fn check_systems(&self) -> Result<(), (Vec<String>, String)> {
        let at = |key: &str, message: String| (vec![key.to_string()], message);
        if ![1, 2, 3, 4, 5, 6, 10, 12, 15, 20, 30, 60].contains(&self.timesteps_per_hour) {
            return Err(at(
                "timesteps_per_hour",
                format!(
                    "timesteps_per_hour = {}, expected a divisor of 60",
                    self.timesteps_per_hour
                ),
            ));
        }
        if let Some(minutes) = self.minimum_system_timestep_minutes {
            if minutes > 60 {
                return Err(at(
                    "minimum_system_timestep_minutes",
                    format!(
                        "minimum_system_timestep_minutes = {minutes}, expected 0..60 (0: the zone time step)"
                    ),
                ));
            }
        }
        let hr = self.heat_recovery_effectiveness;
        if !(0.0..=0.95).contains(&hr) {
            return Err(at(
                "heat_recovery_effectiveness",
                format!("heat_recovery_effectiveness = {hr:?}, expected 0..0.95"),
            ));
        }
        if hr > 0.0 && self.hvac != HvacSystem::DoasFanCoil {
            return Err(at(
                "heat_recovery_effectiveness",
                format!(
                    "heat_recovery_effectiveness = {hr} needs hvac = \"doas_fan_coil\" (the generated VAV system has no heat recovery)"
                ),
            ));
        }
        if self.economizer && self.hvac != HvacSystem::VavReheat {
            return Err(at(
                "economizer",
                "economizer = true needs hvac = \"vav_reheat\" (fan coils have no outdoor-air mixing)".into(),
            ));
        }
        Ok(())
    }

    /// Occupied hours, the year and the schedules' interval boundaries.
    fn check_schedules(&self) -> Result<(), (Vec<String>, String)> {
        let at = |key: &str, message: String| (vec![key.to_string()], message);
        let [a, b] = self.occupied_hours;
        if !(a < b && b <= 24) {
            return Err(at(
                "occupied_hours",
                format!("occupied_hours = [{a}, {b}], expected start < end <= 24"),
            ));
        }
        if !(1900..=2100).contains(&self.year.first_year()) {
            return Err(at(
                "year",
                format!("year = {}, expected 1900..=2100", self.year),
            ));
        }
        for (what, bounds) in [
            ("weekday_boundaries", &self.weekday_boundaries),
            ("weekend_boundaries", &self.weekend_boundaries),
        ] {
            check_boundaries(bounds).map_err(|m| at(what, format!("{what}: {m}")))?;
        }
        if !self.partial_boundaries.is_empty() {
            check_boundaries(&self.partial_boundaries)
                .map_err(|m| at("partial_boundaries", format!("partial_boundaries: {m}")))?;
        }
        Ok(())
    }

    /// Every prior override names a parameter of this building and is a valid triangle.
    fn check_priors(&self) -> Result<(), (Vec<String>, String)> {
        let names: Vec<String> = self.parameters().into_iter().map(|d| d.name).collect();
        for (name, p) in &self.priors {
            let at = |m: String| (vec!["priors".to_string(), name.clone()], m);
            if !names.contains(name) {
                let why = self
                    .absent(name)
                    .map_or(String::new(), |r| format!(" ({r})"));
                return Err(at(format!("priors.{name}: unknown parameter{why}")));
            }
            TriangularPrior::new(p.min, p.mode, p.max)
                .map_err(|m| at(format!("priors.{name}: {m}")))?;
        }
        Ok(())
    }

    /// Why this building has no parameter `name` where another building would: its HVAC
    /// system has no such setting, or its calendar no partial days for a partial day's
    /// interval. None for a name no building has.
    pub fn absent(&self, name: &str) -> Option<String> {
        if let Some((_, reason)) = self.hvac.omitted().iter().find(|(n, _)| *n == name) {
            return Some(reason.to_string());
        }
        (name.starts_with("schedule_partial_") && !self.has_partial_days()).then(|| {
            "a partial day's schedule interval: the model's calendar has no partial days; \
             day_types_file labels them, as pre-calibration's calendar.csv does"
                .to_string()
        })
    }

    /// True where the calendar has partial days (`partial` in `day_types_file`).
    pub fn has_partial_days(&self) -> bool {
        self.observed_day_types
            .values()
            .any(|t| *t == bemcal_weather::DayType::Partial)
    }

    /// The partial days' schedule intervals: none without partial days, else
    /// `partial_boundaries` or the weekday's defaults.
    pub fn partial_intervals(&self) -> Vec<u32> {
        match (self.has_partial_days(), self.partial_boundaries.is_empty()) {
            (false, _) => vec![],
            (true, true) => default_weekday_bounds(),
            (true, false) => self.partial_boundaries.clone(),
        }
    }

    /// Total conditioned floor area, m2.
    pub fn floor_area_m2(&self) -> f64 {
        self.footprint_m[0] * self.footprint_m[1] * self.storeys as f64
    }

    /// All calibration parameters with their priors (defaults from the reference's Table 2,
    /// overridden by `priors`).
    pub fn parameters(&self) -> Vec<ParameterDef> {
        let mut out = Vec::new();
        for p in &ENGINEERING {
            if self.hvac.omitted().iter().any(|(n, _)| *n == p.name) {
                continue;
            }
            if p.name == "supply_air_temp" && self.separate_ahu_supply_air {
                for ahu in 1..=2 {
                    out.push(def(
                        &format!("supply_air_temp_ahu{ahu}"),
                        p.unit,
                        &format!("supply air temperature of AHU {ahu}"),
                        p.prior,
                    ));
                }
                continue;
            }
            out.push(def(p.name, p.unit, p.description, p.prior));
        }
        for (i, _) in self.weekday_boundaries.iter().enumerate() {
            let prior = WEEKDAY_PRIORS.get(i).copied().unwrap_or((0.1, 0.4, 0.8));
            let d = format!("weekday schedule fraction, interval {}", i + 1);
            out.push(def(&weekday_param(i + 1), "-", &d, prior));
        }
        for (i, _) in self.weekend_boundaries.iter().enumerate() {
            let prior = WEEKEND_PRIORS.get(i).copied().unwrap_or((0.1, 0.25, 0.5));
            let d = format!("weekend/holiday schedule fraction, interval {}", i + 1);
            out.push(def(&weekend_param(i + 1), "-", &d, prior));
        }
        for (i, _) in self.partial_intervals().iter().enumerate() {
            let d = format!("partial day schedule fraction, interval {}", i + 1);
            out.push(def(
                &partial_param(i + 1),
                "-",
                &d,
                default_partial_prior(i),
            ));
        }
        // The reference's hot water prior belongs to its 11,437 m2 building: scale by floor area.
        let scale = self.floor_area_m2() / REFERENCE_FLOOR_AREA_M2;
        for d in &mut out {
            if d.name == "hot_water_peak_flow" {
                d.prior.mode *= scale;
                d.prior.max *= scale;
            }
            if let Some(p) = self.priors.get(&d.name) {
                d.prior = *p;
            }
        }
        out
    }

    /// Physical constraints between parameters (checked before any EnergyPlus run).
    pub fn constraints(&self) -> Vec<Constraint> {
        let mut c = vec![
            Constraint {
                lower: "heating_setpoint_occupied".into(),
                upper: "cooling_setpoint_occupied".into(),
                margin: 0.0,
                reason: "a heating set-point above the cooling set-point is fatal in EnergyPlus (DualSetPointWithDeadband)".into(),
            },
            Constraint {
                lower: "heating_setpoint_unoccupied".into(),
                upper: "cooling_setpoint_unoccupied".into(),
                margin: 0.0,
                reason: "a heating set-point above the cooling set-point is fatal in EnergyPlus (DualSetPointWithDeadband)".into(),
            },
        ];
        let sat: Vec<String> = if self.separate_ahu_supply_air {
            vec!["supply_air_temp_ahu1".into(), "supply_air_temp_ahu2".into()]
        } else {
            vec!["supply_air_temp".into()]
        };
        for s in sat {
            c.push(Constraint {
                lower: "chilled_water_supply_temp".into(),
                upper: s,
                margin: 3.0,
                reason:
                    "supply air below chilled water + 3 K cannot be reached by the cooling coil"
                        .into(),
            });
        }
        c
    }

    /// Number of air-handling units: two, as in the reference building, unless there is a
    /// single zone.
    pub fn ahu_count(&self) -> usize {
        if self.zone_names().len() == 1 {
            1
        } else {
            2
        }
    }

    /// The AHU (1 or 2) serving zone `i` of [`BuildingSpec::zone_names`]: the lower half of the
    /// storeys on AHU 1, the upper half on AHU 2; one storey alternates zones.
    fn ahu_of_zone(&self, i: usize) -> usize {
        if self.ahu_count() == 1 {
            return 1;
        }
        if self.storeys == 1 {
            return 1 + i % 2;
        }
        let per_floor = self.zone_names().len() / self.storeys as usize;
        if i / per_floor < (self.storeys as usize).div_ceil(2) {
            1
        } else {
            2
        }
    }

    /// The calendar the model simulates (year and holidays).
    pub fn calendar(&self) -> Calendar {
        Calendar {
            observed: self.observed_day_types.clone(),
            ..Calendar::new(self.year, self.holidays.clone())
        }
    }

    /// Zone names, floor by floor.
    pub fn zone_names(&self) -> Vec<String> {
        let mut z = Vec::new();
        for f in 1..=self.storeys {
            match self.zoning {
                Zoning::OnePerFloor => z.push(format!("F{f}")),
                Zoning::PerimeterCore => {
                    for side in ["South", "East", "North", "West", "Core"] {
                        z.push(format!("F{f}_{side}"));
                    }
                }
            }
        }
        z
    }

    /// Writes the model's IDF for a complete set of parameter values (see
    /// [`crate::params::complete_values`]); constraints must already hold.
    pub fn to_idf(&self, v: &ParameterValues) -> Result<Idf, Error> {
        let mut m = Idf::new();
        self.add_simulation_control(&mut m);
        self.add_sizing_periods(&mut m);
        crate::calendar::add_run_period(&mut m, &self.calendar());
        m.add(
            "Site:GroundTemperature:BuildingSurface",
            &["18"; 12].map(String::from),
        );
        self.add_schedules(&mut m, v)?;
        self.add_setpoint_schedules(&mut m, v)?;
        self.add_constructions(&mut m, v)?;
        self.add_geometry(&mut m);
        self.add_internal_gains(&mut m, v)?;
        self.add_air_systems(&mut m, v)?;
        self.add_plant(&mut m);
        self.add_domestic_hot_water(&mut m, v)?;
        self.add_outputs(&mut m);
        Ok(m)
    }

    /// The simulation's settings: IDF version, what is simulated, the `Building` object, time
    /// steps and geometry rules.
    fn add_simulation_control(&self, m: &mut Idf) {
        m.add("Version", &["25.2"]);
        m.add(
            "SimulationControl",
            &["Yes", "Yes", "Yes", "No", "Yes", "No", "1"],
        );
        m.add(
            "Building",
            &[
                &self.name,
                "0",
                "City",
                "0.04",
                "0.4",
                "FullInteriorAndExterior",
                &MAX_WARMUP_DAYS.to_string(),
                "6",
            ],
        );
        m.add("Timestep", &[self.timesteps_per_hour.to_string()]);
        if let Some(minutes) = self.minimum_system_timestep_minutes {
            m.add("ConvergenceLimits", &[minutes.to_string()]);
        }
        m.add(
            "GlobalGeometryRules",
            &["UpperLeftCorner", "Counterclockwise", "Relative"],
        );
    }

    /// The sizing periods (`SizingPeriod:WeatherFileConditionType`) and sizing factors.
    fn add_sizing_periods(&self, m: &mut Idf) {
        // Sizing from the weather file itself (no .ddy needed), on days of the design-day
        // types: there the thermostat holds its fixed design set-points (see
        // `DESIGN_COOLING_SETPOINT_C`), so equipment is sized once for the building and its
        // loads, and the sampled set-points only operate it.
        m.add(
            "SizingPeriod:WeatherFileConditionType",
            &[
                "Summer Extreme",
                "SummerExtreme",
                "SummerDesignDay",
                "No",
                "No",
            ],
        );
        m.add(
            "SizingPeriod:WeatherFileConditionType",
            &[
                "Winter Extreme",
                "WinterExtreme",
                "WinterDesignDay",
                "No",
                "No",
            ],
        );
        m.add("Sizing:Parameters", &["1.2", "1.2"]);
    }

    /// Schedule type limits, the constant `Always On` and `Activity` schedules, and the
    /// `Occupancy` schedule from the weekday and weekend interval fractions.
    fn add_schedules(&self, m: &mut Idf, v: &ParameterValues) -> Result<(), Error> {
        m.add("ScheduleTypeLimits", &["Fraction", "0", "1", "Continuous"]);
        m.add(
            "ScheduleTypeLimits",
            &["Temperature", "-60", "200", "Continuous"],
        );
        m.add("ScheduleTypeLimits", &["Any Number"]);
        constant(m, "Always On", "Fraction", 1.0);
        constant(m, "Activity", "Any Number", 120.0);
        let wd: Vec<f64> = (1..=self.weekday_boundaries.len())
            .map(|i| value(v, &weekday_param(i)))
            .collect::<Result<_, _>>()?;
        let we: Vec<f64> = (1..=self.weekend_boundaries.len())
            .map(|i| value(v, &weekend_param(i)))
            .collect::<Result<_, _>>()?;
        let partial = self.partial_intervals();
        let pd: Vec<f64> = (1..=partial.len())
            .map(|i| value(v, &partial_param(i)))
            .collect::<Result<_, _>>()?;
        interval_schedule(
            m,
            "Occupancy",
            (&self.weekday_boundaries, &wd),
            (&self.weekend_boundaries, &we),
            (&partial, &pd),
        );
        Ok(())
    }

    /// The control schedules: heating and cooling set-points, outdoor-air fraction, the plant's
    /// chilled- and hot-water set-points, each AHU's supply air and preheat temperatures, and the
    /// domestic hot water's set-point, mains and ambient temperatures.
    fn add_setpoint_schedules(&self, m: &mut Idf, v: &ParameterValues) -> Result<(), Error> {
        self.occupied_schedule(
            m,
            "Heating Setpoint",
            "Temperature",
            value(v, "heating_setpoint_occupied")?,
            value(v, "heating_setpoint_unoccupied")?,
            Some(DESIGN_HEATING_SETPOINT_C),
        );
        self.occupied_schedule(
            m,
            "Cooling Setpoint",
            "Temperature",
            value(v, "cooling_setpoint_occupied")?,
            value(v, "cooling_setpoint_unoccupied")?,
            Some(DESIGN_COOLING_SETPOINT_C),
        );
        let oa_occ = value(v, "outdoor_air_ach_occupied")?;
        let oa_unocc = match self.hvac {
            HvacSystem::VavReheat => value(v, "outdoor_air_ach_unoccupied")?,
            HvacSystem::DoasFanCoil => 0.0,
        };
        let oa_frac = if oa_occ > 0.0 {
            (oa_unocc / oa_occ).min(1.0)
        } else {
            0.0
        };
        self.occupied_schedule(m, "Outdoor Air Fraction", "Fraction", 1.0, oa_frac, None);
        if self.hvac == HvacSystem::DoasFanCoil {
            // The DOAS runs at occupied hours (and on the sizing days).
            self.occupied_schedule(m, "DOAS Availability", "Fraction", 1.0, 0.0, Some(1.0));
        }
        let chw = value(v, "chilled_water_supply_temp")?;
        constant(m, "CHW Setpoint", "Temperature", chw);
        constant(m, "HW Setpoint", "Temperature", 80.0);
        let sat = |ahu: usize| -> Result<f64, Error> {
            if self.separate_ahu_supply_air {
                value(v, &format!("supply_air_temp_ahu{ahu}"))
            } else {
                value(v, "supply_air_temp")
            }
        };
        for ahu in 1..=2 {
            let s = sat(ahu)?;
            constant(m, &format!("AHU{ahu} Supply Air"), "Temperature", s);
            constant(
                m,
                &format!("AHU{ahu} Preheat"),
                "Temperature",
                (s - 2.0).min(10.0),
            );
        }
        constant(m, "DHW Setpoint", "Temperature", 60.0);
        constant(m, "DHW Mains", "Temperature", 12.0);
        constant(m, "DHW Ambient", "Temperature", 21.0);
        Ok(())
    }

    /// `Schedule:Compact` switching between an occupied and an unoccupied value at the spec's
    /// `occupied_hours` on weekdays; with a `design` value the sizing days hold it all day
    /// instead of following the weekday pattern.
    fn occupied_schedule(
        &self,
        m: &mut Idf,
        name: &str,
        limits: &str,
        occ: f64,
        unocc: f64,
        design: Option<f64>,
    ) {
        let [o0, o1] = self.occupied_hours;
        let mut f: Vec<String> = vec![name.into(), limits.into(), "Through: 12/31".into()];
        // Partial days (CustomDay2) keep the weekday's occupied hours.
        let working = match self.has_partial_days() {
            true => "Weekdays CustomDay1 CustomDay2",
            false => "Weekdays CustomDay1",
        };
        match design {
            Some(d) => {
                f.push("For: SummerDesignDay WinterDesignDay".into());
                f.push("Until: 24:00".into());
                f.push(num(d));
                f.push(format!("For: {working}"));
            }
            None => f.push(format!("For: {working} SummerDesignDay WinterDesignDay")),
        }
        if o0 > 0 {
            f.push(format!("Until: {o0:02}:00"));
            f.push(num(unocc));
        }
        f.push(format!("Until: {o1:02}:00"));
        f.push(num(occ));
        if o1 < 24 {
            f.push("Until: 24:00".into());
            f.push(num(unocc));
        }
        f.push("For: AllOtherDays".into());
        f.push("Until: 24:00".into());
        f.push(num(unocc));
        m.add("Schedule:Compact", &f);
    }

    /// Materials and constructions: walls, roof, floors and ceilings, interior walls and the
    /// window's simple glazing system, from the sampled conductivities and SHGC.
    fn add_constructions(&self, m: &mut Idf, v: &ParameterValues) -> Result<(), Error> {
        let k_wall = value(v, "wall_insulation_conductivity")?;
        let k_roof = value(v, "roof_insulation_conductivity")?;
        let k_glass = value(v, "window_glass_conductivity")?;
        if k_wall <= 0.0 || k_roof <= 0.0 || k_glass <= 0.0 {
            return Err(Error::Parameter {
                name: "insulation / glass conductivity".into(),
                message: "conductivities must be > 0".into(),
            });
        }
        let mat = |m: &mut Idf, n: &str, t: f64, k: f64, rho: f64, cp: f64| {
            m.add(
                "Material",
                &[
                    n.into(),
                    "MediumRough".into(),
                    num(t),
                    num(k),
                    num(rho),
                    num(cp),
                ],
            );
        };
        mat(m, "Brick", 0.1016, 0.89, 1920.0, 790.0);
        mat(m, "Wall Insulation", 0.0794, k_wall, 43.0, 1210.0);
        mat(m, "Gypsum", 0.0127, 0.16, 784.9, 830.0);
        mat(m, "Roof Membrane", 0.0095, 0.16, 1121.3, 1460.0);
        mat(m, "Roof Insulation", 0.2, k_roof, 265.0, 836.8);
        mat(m, "Metal Deck", 0.0015, 45.0, 7680.0, 418.0);
        mat(m, "Concrete Slab", 0.1016, 1.95, 2240.0, 900.0);
        mat(m, "Carpet", 0.0127, 0.06, 288.0, 1380.0);
        m.add(
            "Construction",
            &["Exterior Wall", "Brick", "Wall Insulation", "Gypsum"],
        );
        m.add(
            "Construction",
            &["Roof", "Roof Membrane", "Roof Insulation", "Metal Deck"],
        );
        m.add("Construction", &["Ground Floor", "Concrete Slab", "Carpet"]);
        m.add(
            "Construction",
            &["Interior Floor", "Concrete Slab", "Carpet"],
        );
        m.add(
            "Construction",
            &["Interior Ceiling", "Carpet", "Concrete Slab"],
        );
        m.add("Construction", &["Interior Wall", "Gypsum", "Gypsum"]);
        let shgc = value(v, "shgc")?;
        if !(0.0 < shgc && shgc < 1.0) {
            return Err(Error::Parameter {
                name: "shgc".into(),
                message: format!("{shgc} is outside (0, 1)"),
            });
        }
        m.add(
            "WindowMaterial:SimpleGlazingSystem",
            &[
                "Glazing".into(),
                num(glazing_u_factor(k_glass)),
                num(shgc),
                "0.6".into(),
            ],
        );
        m.add("Construction", &["Window", "Glazing"]);
        Ok(())
    }

    /// Internal gains (people, lights, equipment over the `All Zones` list) and infiltration.
    fn add_internal_gains(&self, m: &mut Idf, v: &ParameterValues) -> Result<(), Error> {
        m.add(
            "ZoneList",
            &std::iter::once("All Zones".to_string())
                .chain(self.zone_names())
                .collect::<Vec<_>>(),
        );
        let people = value(v, "people_area_per_person")?;
        if people <= 0.0 {
            return Err(Error::Parameter {
                name: "people_area_per_person".into(),
                message: "must be > 0".into(),
            });
        }
        m.add(
            "People",
            &[
                "People",
                "All Zones",
                "Occupancy",
                "Area/Person",
                "",
                "",
                &num(people),
                "0.3",
                "AUTOCALCULATE",
                "Activity",
            ],
        );
        m.add(
            "Lights",
            &[
                "Lights".to_string(),
                "All Zones".into(),
                "Occupancy".into(),
                "Watts/Area".into(),
                "".into(),
                num(value(v, "lighting_power_density")?),
                "".into(),
                "0".into(),
                "0.7".into(),
                "0.2".into(),
                "1".into(),
            ],
        );
        m.add(
            "ElectricEquipment",
            &[
                "Equipment".to_string(),
                "All Zones".into(),
                "Occupancy".into(),
                "Watts/Area".into(),
                "".into(),
                num(value(v, "equipment_power_density")?),
                "".into(),
                "0".into(),
                "0.5".into(),
                "0".into(),
            ],
        );
        m.add(
            "ZoneInfiltration:DesignFlowRate",
            &[
                "Infiltration",
                "All Zones",
                "Always On",
                "AirChanges/Hour",
                "",
                "",
                "",
                "0.2",
                "1",
                "0",
                "0",
                "0",
            ],
        );
        Ok(())
    }

    /// Outputs: the reported meters, hourly, and which output files EnergyPlus writes.
    fn add_outputs(&self, m: &mut Idf) {
        // Outputs: EnergyPlus writes its own hourly meter CSV (no ReadVarsESO).
        for meter in REPORTED_METERS {
            m.add("Output:Meter", &[meter, "Hourly"]);
        }
        let mut files = vec!["Yes", "Yes", "Yes"];
        files.resize(33, "No");
        files[3] = "Yes"; // EIO, small and useful for sizing checks
        m.add("OutputControl:Files", &files);
    }
}

/// Meters every generated model reports hourly.
pub const REPORTED_METERS: [&str; 7] = [
    "Electricity:Facility",
    "InteriorLights:Electricity",
    "InteriorEquipment:Electricity",
    "DistrictCooling:Facility",
    "NaturalGas:Facility",
    "DistrictHeatingWater:Facility",
    "Fans:Electricity",
];

fn def(name: &str, unit: &str, description: &str, p: (f64, f64, f64)) -> ParameterDef {
    ParameterDef {
        name: name.into(),
        unit: unit.into(),
        description: description.into(),
        prior: TriangularPrior {
            min: p.0,
            mode: p.1,
            max: p.2,
        },
    }
}

fn check_boundaries(b: &[u32]) -> Result<(), String> {
    if b.is_empty() {
        return Err("no intervals".into());
    }
    if b.last() != Some(&24) {
        return Err(format!("the last boundary is {:?}, expected 24", b.last()));
    }
    if b[0] == 0 || b.windows(2).any(|w| w[0] >= w[1]) {
        return Err(format!(
            "{b:?}: expected strictly increasing hours in 1..=24"
        ));
    }
    Ok(())
}

/// The value of parameter `name`, or an error naming it as missing.
fn value(v: &ParameterValues, name: &str) -> Result<f64, Error> {
    v.get(name).copied().ok_or_else(|| Error::Parameter {
        name: name.into(),
        message: "missing value".into(),
    })
}

fn constant(m: &mut Idf, name: &str, limits: &str, value: f64) {
    m.add(
        "Schedule:Constant",
        &[name.to_string(), limits.into(), num(value)],
    );
}

/// `Schedule:Compact` with one value per interval: weekdays (and design days), partial days
/// (`CustomDay2`, where there are intervals) and weekends/holidays.
fn interval_schedule(
    m: &mut Idf,
    name: &str,
    weekday: (&[u32], &[f64]),
    weekend: (&[u32], &[f64]),
    partial: (&[u32], &[f64]),
) {
    let mut f: Vec<String> = vec![name.into(), "Fraction".into(), "Through: 12/31".into()];
    let days = [
        (
            "Weekdays CustomDay1 SummerDesignDay WinterDesignDay",
            weekday,
        ),
        ("CustomDay2", partial),
        ("AllOtherDays", weekend),
    ];
    // A day kind without intervals (partial days where the calendar has none) has no block.
    for (kind, (hours, values)) in days.into_iter().filter(|(_, d)| !d.0.is_empty()) {
        f.push(format!("For: {kind}"));
        for (h, v) in hours.iter().zip(values) {
            f.push(format!("Until: {h:02}:00"));
            f.push(num(*v));
        }
    }
    m.add("Schedule:Compact", &f);
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::params::complete_values;

    #[test]
    fn default_spec_is_reference_building() {
        let s = BuildingSpec::default();
        assert!((s.floor_area_m2() - 11437.0).abs() < 50.0);
        let p = s.parameters();
        assert_eq!(p.len(), 38, "16 engineering + 12 weekday + 10 weekend");
        assert_eq!(s.zone_names().len(), 20);
    }

    /// A retrofit measure's building edits: operation and systems change, the parameters and
    /// outputs stay (so that a posterior draw carries over); geometry, a value of the wrong
    /// form, an edit to the same value and a change of the parameters are refused.
    #[test]
    fn a_measure_edits_the_building_it_may() {
        let spec = BuildingSpec::from_toml(
            "storeys = 1\nfootprint_m = [20.0, 15.0]\nzoning = \"one_per_floor\"\n",
            std::path::Path::new("m.toml"),
        )
        .unwrap();
        let model = crate::Model::generated(spec.clone());
        let edits = |text: &str| -> std::collections::BTreeMap<String, serde_json::Value> {
            toml::from_str(text).unwrap()
        };
        let edited = model
            .with_building_edits(&edits("economizer = true\noccupied_hours = [8, 18]"))
            .unwrap();
        let e = edited.spec().unwrap();
        assert!(e.economizer && e.occupied_hours == [8, 18]);
        assert_eq!(edited.parameters(), model.parameters());
        let v = complete_values(model.parameters(), &Default::default()).unwrap();
        let idf = e.to_idf(&v).unwrap();
        let ahus: Vec<_> = idf.of_class("HVACTemplate:System:VAV").collect();
        assert!(!ahus.is_empty() && ahus.iter().all(|o| o.fields[28] == "DifferentialDryBulb"));
        let err = |text: &str| model.with_building_edits(&edits(text)).unwrap_err();
        let e = err("storeys = 2");
        assert!(
            e.contains("building.storeys: not a field a measure may edit"),
            "{e}"
        );
        let e = err("economizer = \"yes\"");
        assert!(e.starts_with("building: ") && e.contains("boolean"), "{e}");
        let e = err("window_to_wall = 1.5");
        assert!(e.starts_with("building: ") && e.contains("window"), "{e}");
        let e = err("occupied_hours = [7, 19]");
        assert!(e.contains("leave the building as it is"), "{e}");
        let e = err("hvac = \"doas_fan_coil\"");
        assert!(e.contains("change the model's parameters"), "{e}");
    }

    /// `minimum_system_timestep_minutes` writes `ConvergenceLimits` only when set, and is
    /// checked against EnergyPlus's range.
    #[test]
    fn minimum_system_timestep_is_convergence_limits() {
        let limits = |text: &str| -> Vec<Vec<String>> {
            let s = BuildingSpec::from_toml(text, std::path::Path::new("m.toml")).unwrap();
            let v = complete_values(&s.parameters(), &Default::default()).unwrap();
            let idf = s.to_idf(&v).unwrap();
            idf.of_class("ConvergenceLimits")
                .map(|o| o.fields.clone())
                .collect()
        };
        let small = "storeys = 1\nfootprint_m = [20.0, 15.0]\n";
        assert!(limits(small).is_empty());
        let held = limits(&format!("{small}minimum_system_timestep_minutes = 0\n"));
        assert_eq!(held, vec![vec!["0".to_string()]]);
        let e = BuildingSpec::from_toml(
            &format!("{small}minimum_system_timestep_minutes = 90\n"),
            std::path::Path::new("m.toml"),
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("expected 0..60"), "{e}");
        // Unset, the spec serialises as before the field existed.
        let spec = BuildingSpec::default();
        assert!(!toml::to_string(&spec)
            .unwrap()
            .contains("minimum_system_timestep"));
    }

    /// The model's holidays (`RunPeriodControl:SpecialDays`) follow the spec's calendar: the UK
    /// table, or a file of dates beside the spec.
    #[test]
    fn special_days_follow_the_spec_holidays() {
        let special = |s: &BuildingSpec| -> Vec<String> {
            let v = complete_values(&s.parameters(), &Default::default()).unwrap();
            let idf = s.to_idf(&v).unwrap();
            idf.of_class("RunPeriodControl:SpecialDays")
                .map(|o| o.fields[1].clone())
                .collect()
        };
        let uk = BuildingSpec::from_toml(
            "storeys = 1\nfootprint_m = [20.0, 15.0]\nyear = 2017\nholidays = \"uk\"\n",
            std::path::Path::new("m.toml"),
        )
        .unwrap();
        assert_eq!(
            special(&uk),
            ["1/2", "4/14", "4/17", "5/1", "5/29", "8/28", "12/25", "12/26"]
        );
        let dir = std::env::temp_dir().join(format!("bemcal-spec-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(
            dir.join("breaks.csv"),
            "date,name\n2017-10-23,half term\n2017-10-27,\n",
        )
        .unwrap();
        let text = "storeys = 1\nfootprint_m = [20.0, 15.0]\nyear = 2017\nholidays_file = \"breaks.csv\"\n";
        let listed = BuildingSpec::from_toml(text, &dir.join("m.toml")).unwrap();
        assert_eq!(special(&listed), ["10/23", "10/27"]);
        assert_eq!(
            listed.calendar().day_type(10, 23),
            Some(bemcal_weather::DayType::Holiday)
        );
        std::fs::write(dir.join("breaks.csv"), "2017-13-01\n").unwrap();
        let e = BuildingSpec::from_toml(text, &dir.join("m.toml"))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("holidays_file") && e.contains("breaks.csv:1:"),
            "{e}"
        );
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// The run period's first and last dates and weekday, and its special days, of a spec.
    fn run_period(s: &BuildingSpec) -> (Vec<String>, Vec<(String, String)>) {
        let v = complete_values(&s.parameters(), &Default::default()).unwrap();
        let idf = s.to_idf(&v).unwrap();
        let rp = idf.of_class("RunPeriod").next().unwrap().fields[1..8].to_vec();
        let special = idf
            .of_class("RunPeriodControl:SpecialDays")
            .map(|o| (o.fields[1].clone(), o.fields[3].clone()))
            .collect();
        (rp, special)
    }

    #[test]
    fn partial_days_run_their_own_intervals_on_custom_day_2() {
        // Saturdays of 2021 labelled partial (a half-day): the spec gains a partial day's
        // intervals (the weekday's defaults, or its own boundaries), the Saturdays become
        // CustomDay2 and the occupancy schedule has a CustomDay2 block; the set-points keep the
        // weekday's occupied hours on them.
        let mut s = BuildingSpec {
            year: 2021.into(),
            holidays: bemcal_weather::Holidays::None,
            ..Default::default()
        };
        let names = |s: &BuildingSpec| -> Vec<String> {
            s.parameters()
                .into_iter()
                .map(|d| d.name)
                .filter(|n| n.starts_with("schedule_partial_"))
                .collect()
        };
        assert!(names(&s).is_empty() && !s.has_partial_days());
        let saturdays = (0..52).map(|w| {
            chrono::NaiveDate::from_ymd_opt(2021, 1, 2).unwrap() + chrono::Duration::weeks(w)
        });
        s.observed_day_types = saturdays
            .map(|d| (d, bemcal_weather::DayType::Partial))
            .collect();
        assert_eq!(names(&s).len(), default_weekday_bounds().len());
        s.partial_boundaries = vec![8, 13, 24];
        assert_eq!(
            names(&s),
            [
                "schedule_partial_01",
                "schedule_partial_02",
                "schedule_partial_03"
            ]
        );
        let (_, special) = run_period(&s);
        assert_eq!(special.len(), 52);
        assert!(
            special.iter().all(|(_, kind)| kind == "CustomDay2"),
            "{special:?}"
        );
        assert_eq!(special[0].0, "1/2");
        let mut v = complete_values(&s.parameters(), &Default::default()).unwrap();
        v.insert("schedule_partial_02".into(), 0.42);
        let idf = s.to_idf(&v).unwrap();
        let schedule = |name: &str| {
            idf.of_class("Schedule:Compact")
                .find(|o| o.fields[0] == name)
                .unwrap()
                .fields
                .join(",")
        };
        assert!(
            schedule("Occupancy").contains("For: CustomDay2,Until: 08:00,")
                && schedule("Occupancy").contains("Until: 13:00,0.42,Until: 24:00"),
            "{}",
            schedule("Occupancy")
        );
        assert!(
            schedule("Heating Setpoint").contains("For: Weekdays CustomDay1 CustomDay2,"),
            "{}",
            schedule("Heating Setpoint")
        );
        // Boundaries that do not end at 24 are refused, named.
        s.partial_boundaries = vec![8, 13];
        let e = s.validate().unwrap_err();
        assert!(e.contains("partial_boundaries"), "{e}");
    }

    #[test]
    fn a_year_from_april_runs_across_the_year_end_from_its_weekday() {
        let s = BuildingSpec {
            year: "2021-04".parse().unwrap(),
            holidays: bemcal_weather::Holidays::None,
            ..Default::default()
        };
        let (rp, special) = run_period(&s);
        assert_eq!(rp, ["4", "1", "2021", "3", "31", "2022", "Thursday"]);
        assert!(special.is_empty(), "{special:?}");
        let s = BuildingSpec {
            year: 2021.into(),
            ..Default::default()
        };
        assert_eq!(
            run_period(&s).0,
            ["1", "1", "2021", "12", "31", "2021", "Friday"]
        );
    }

    #[test]
    fn after_a_leap_day_the_real_weekdays_are_kept() {
        // EnergyPlus simulates 2020 without 29 February and counts weekdays on: from 1 March it
        // is one day behind. Real Sundays (its Saturdays) need nothing; real Mondays (its
        // Sundays) run the weekday schedule; real Saturdays (its Fridays) the weekend one.
        let s = BuildingSpec {
            year: 2020.into(),
            holidays: bemcal_weather::Holidays::None,
            ..Default::default()
        };
        let (rp, special) = run_period(&s);
        assert_eq!(rp[6], "Wednesday");
        let kind = |md: &str| {
            special
                .iter()
                .find(|(d, _)| d == md)
                .map(|(_, k)| k.as_str())
        };
        assert_eq!(kind("2/28"), None); // a Friday, as EnergyPlus counts too
        assert_eq!(kind("3/1"), None); // Sunday: EnergyPlus's Saturday
        assert_eq!(kind("3/2"), Some("CustomDay1")); // Monday: EnergyPlus's Sunday
        assert_eq!(kind("3/7"), Some("Holiday")); // Saturday: EnergyPlus's Friday
        assert_eq!(kind("12/31"), None); // Thursday: EnergyPlus's Wednesday
        assert_eq!(special.len(), 44 + 43, "{special:?}"); // the real Mondays and Saturdays from 2 March
                                                           // A year without a leap day needs no special day at all.
        let s = BuildingSpec {
            year: 2021.into(),
            holidays: bemcal_weather::Holidays::None,
            ..Default::default()
        };
        assert!(run_period(&s).1.is_empty());
    }

    #[test]
    fn idf_has_matched_interzone_surfaces() {
        let s = BuildingSpec::default();
        let v = complete_values(&s.parameters(), &Default::default()).unwrap();
        let idf = s.to_idf(&v).unwrap();
        let surfaces: Vec<_> = idf.of_class("BuildingSurface:Detailed").collect();
        for srf in &surfaces {
            if srf.fields[5] == "Surface" {
                let twin = surfaces
                    .iter()
                    .find(|o| o.fields[0] == srf.fields[6])
                    .unwrap_or_else(|| panic!("{} has no twin {}", srf.fields[0], srf.fields[6]));
                assert_eq!(twin.fields[6], srf.fields[0]);
            }
        }
        assert_eq!(idf.of_class("HVACTemplate:Zone:VAV").count(), 20);
        assert_eq!(idf.of_class("HVACTemplate:System:VAV").count(), 2);
    }

    #[test]
    fn the_air_system_follows_the_spec() {
        let v = crate::params::complete_values(
            &BuildingSpec::default().parameters(),
            &ParameterValues::new(),
        )
        .unwrap();
        let vav = BuildingSpec::default().to_idf(&v).unwrap();
        assert_eq!(vav.of_class("HVACTemplate:Zone:FanCoil").count(), 0);
        let ahu = vav.of_class("HVACTemplate:System:VAV").next().unwrap();
        assert_eq!(ahu.fields[28], "NoEconomizer");
        let spec = |text: &str| BuildingSpec::from_toml(text, std::path::Path::new("b.toml"));
        let econ = spec("economizer = true\n").unwrap().to_idf(&v).unwrap();
        let ahu = econ.of_class("HVACTemplate:System:VAV").next().unwrap();
        assert_eq!(ahu.fields[28], "DifferentialDryBulb");
        let doas = spec("hvac = \"doas_fan_coil\"\nheat_recovery_effectiveness = 0.7\n")
            .unwrap()
            .to_idf(&v)
            .unwrap();
        assert_eq!(doas.of_class("HVACTemplate:System:VAV").count(), 0);
        assert_eq!(doas.of_class("HVACTemplate:Zone:VAV").count(), 0);
        let coils: Vec<_> = doas.of_class("HVACTemplate:Zone:FanCoil").collect();
        assert_eq!(coils.len(), 20);
        assert_eq!(coils[0].fields[20], "AHU1");
        assert_eq!(coils[19].fields[20], "AHU2");
        assert_eq!(coils[0].fields[31], "None");
        let names: Vec<String> = spec("hvac = \"doas_fan_coil\"\n")
            .unwrap()
            .parameters()
            .into_iter()
            .map(|d| d.name)
            .collect();
        assert!(!names.contains(&"outdoor_air_ach_unoccupied".to_string()));
        assert!(names.contains(&"outdoor_air_ach_occupied".to_string()));
        let units: Vec<_> = doas
            .of_class("HVACTemplate:System:DedicatedOutdoorAir")
            .collect();
        assert_eq!(units.len(), 2);
        assert_eq!(units[1].fields[13], "AHU2 Supply Air");
        assert_eq!(units[1].fields[25], "AHU2 Preheat");
        assert_eq!(units[1].fields[32..34], ["Sensible", "0.7"]);
        // Options that the system does not have are refused, naming the key.
        let e = spec("heat_recovery_effectiveness = 0.6\n").unwrap_err();
        assert!(
            e.to_string().contains("needs hvac = \"doas_fan_coil\""),
            "{e}"
        );
        let e = spec("hvac = \"doas_fan_coil\"\neconomizer = true\n").unwrap_err();
        assert!(e.to_string().contains("b.toml:2"), "{e}");
        let e = spec(
            "hvac = \"doas_fan_coil\"\n[priors]\n\
             outdoor_air_ach_unoccupied = { min = 0.1, mode = 0.2, max = 0.3 }\n",
        )
        .unwrap_err();
        assert!(
            e.to_string()
                .contains("its DOAS runs at occupied hours only"),
            "{e}"
        );
        let e = spec("hvac = \"radiant\"\n").unwrap_err();
        assert!(e.to_string().contains("b.toml:1"), "{e}");
        // The default system is left out of the serialised spec (simulation cache keys).
        let text = toml::to_string(&BuildingSpec::default()).unwrap();
        assert!(
            !text.contains("hvac") && !text.contains("economizer"),
            "{text}"
        );
    }

    #[test]
    fn bad_spec_is_a_clear_error() {
        let e =
            BuildingSpec::from_toml("storeys = 0\n", std::path::Path::new("b.toml")).unwrap_err();
        assert!(e.to_string().contains("storeys = 0"), "{e}");
        let e =
            BuildingSpec::from_toml("storys = 2\n", std::path::Path::new("b.toml")).unwrap_err();
        assert!(e.to_string().contains("b.toml:1"), "{e}");
        let e = BuildingSpec::from_toml(
            "weekday_boundaries = [6, 12, 20]\n",
            std::path::Path::new("b.toml"),
        )
        .unwrap_err();
        assert!(e.to_string().contains("expected 24"), "{e}");
    }

    #[test]
    fn non_finite_or_unphysical_geometry_is_refused_naming_the_field_and_line() {
        let load = |text: &str| {
            BuildingSpec::from_toml(text, std::path::Path::new("model.toml"))
                .map(|_| ())
                .map_err(|e| e.to_string())
        };
        let head = "name = \"box\"\nstoreys = 1\n";
        for (field, value, message) in [
            (
                "footprint_m",
                "[inf, 15]",
                "footprint_m = [inf, 15.0], expected two finite lengths of 3..1000 m",
            ),
            (
                "footprint_m",
                "[20, nan]",
                "footprint_m = [20.0, NaN], expected two finite lengths of 3..1000 m",
            ),
            (
                "footprint_m",
                "[1e300, 15]",
                "footprint_m = [1e300, 15.0], expected two finite lengths of 3..1000 m",
            ),
            (
                "floor_to_floor_m",
                "inf",
                "floor_to_floor_m = inf, expected 2.4..10 m",
            ),
            (
                "perimeter_depth_m",
                "-inf",
                "perimeter_depth_m = -inf, expected a finite depth > 0 m",
            ),
            (
                "perimeter_depth_m",
                "-2.0",
                "perimeter_depth_m = -2.0, expected a finite depth > 0 m",
            ),
            (
                "window_to_wall",
                "nan",
                "window_to_wall = NaN, expected 0.01..0.9",
            ),
            (
                "window_to_wall",
                "1.5",
                "window_to_wall = 1.5, expected 0.01..0.9",
            ),
            ("year", "20210", "year = 20210, expected 1900..=2100"),
        ] {
            let e = load(&format!("{head}{field} = {value}\n")).unwrap_err();
            assert_eq!(e, format!("model.toml:3: {message}"), "{field} = {value}");
        }
        let e = load(&format!(
            "{head}\n[priors]\nshgc = {{ min = 0.3, mode = inf, max = 0.8 }}\n"
        ))
        .unwrap_err();
        assert_eq!(
            e,
            "model.toml:5: priors.shgc: prior (0.3, inf, 0.8) is not finite"
        );
        // A spec whose fields are all defaults has nothing to point at.
        load(head).unwrap();
        // The one-zone box with a sensible perimeter depth it does not use still loads.
        load(&format!(
            "{head}zoning = \"one_per_floor\"\nfootprint_m = [20, 15]\n"
        ))
        .unwrap();
    }
}

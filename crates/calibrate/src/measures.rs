//! Retrofit measures (`[[measures]]` in a project) and the records of their savings in
//! `summary.json` (`savings`): the settings, the one rule that applies a measure to a draw's
//! parameter values, and the checks that refuse a measure naming nothing or changing nothing.
//! The simulations are [`crate::savings`]'s; the statistics are [`bemcal_stats::savings`]'.
//!
//! ```toml
//! [[measures]]
//! name = "LED lighting"
//! scale = { lighting_power_density = 0.6 }     # x 0.6 of each draw's value
//! [[measures]]
//! name = "cooling set-point +1 K"
//! offset = { cooling_setpoint_occupied = 1.0 }
//! [[measures]]
//! name = "new glazing"
//! set = { window_glass_conductivity = 0.01, shgc = 0.35 }
//! [[measures]]
//! name = "air-side economizer"
//! building = { economizer = true }             # a generated building's spec fields
//! [[measures]]
//! name = "low-pressure ductwork"                 # fields of the IDF each draw simulates
//! idf = [{ class = "HVACTemplate:System:VAV", field = "Supply Fan Delta Pressure", edit = "scale", value = 0.7 }]
//! ```

use std::collections::BTreeMap;

use bemcal_energyplus::idd::Idd;
use bemcal_energyplus::model::IdfEdit;
use bemcal_energyplus::params::ParameterValues;
use bemcal_stats::savings::Spread;
use serde::{Deserialize, Serialize};

/// A retrofit measure: named edits of the model's parameters, applied to every posterior draw.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Measure {
    /// The measure's name (unique in the project; its runs' folder is named after it).
    pub name: String,
    /// Parameters set to a value (the parameter's unit), whatever the draw's.
    #[serde(default)]
    pub set: BTreeMap<String, f64>,
    /// Parameters multiplied by a factor (>= 0) of each draw's value.
    #[serde(default)]
    pub scale: BTreeMap<String, f64>,
    /// Parameters shifted by an amount (the parameter's unit) from each draw's value.
    #[serde(default)]
    pub offset: BTreeMap<String, f64>,
    /// Fields of a generated building's spec, in the model file's form (`occupied_hours =
    /// [8, 18]`, `economizer = true`; [`bemcal_energyplus::BuildingSpec::MEASURE_FIELDS`]),
    /// the same in every draw. EnergyPlus simulates such a measure: the surrogate never saw
    /// the building otherwise.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    #[schemars(with = "BTreeMap<String, serde_json::Value>")]
    pub building: BTreeMap<String, serde_json::Value>,
    /// Fields of the IDF each draw simulates (your own IDF's objects, or a generated
    /// building's), the same in every draw, applied after the draw's parameters
    /// ([`bemcal_energyplus::Model::with_idf_edits`]): what a measure changes that no parameter
    /// reaches. EnergyPlus simulates such a measure.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub idf: Vec<IdfEdit>,
}

/// How a measure edits one parameter.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Edit {
    /// To this value.
    Set(f64),
    /// Times this factor.
    Scale(f64),
    /// Plus this amount.
    Offset(f64),
}

impl Edit {
    /// An IDF edit's amount as the same kind of edit.
    pub fn of(e: &IdfEdit) -> Edit {
        use bemcal_energyplus::model::Edit as Field;
        match e.edit {
            Field::Set => Edit::Set(e.value),
            Field::Scale => Edit::Scale(e.value),
            Field::Offset => Edit::Offset(e.value),
        }
    }

    /// The amount checked, for `who` (the measure) editing `name`: finite, a factor 0 or
    /// more, and not the identity (a factor 1, an amount 0).
    fn check(self, who: &str, name: &str) -> Result<(), String> {
        let (amount, identity, what) = match self {
            Edit::Set(v) => (v, false, "value"),
            Edit::Scale(f) => (f, f == 1.0, "factor"),
            Edit::Offset(d) => (d, d == 0.0, "amount"),
        };
        if !amount.is_finite() {
            return Err(format!("{who}: {name}'s {what} {amount} is not finite"));
        }
        if let Edit::Scale(f) = self {
            if f < 0.0 {
                return Err(format!("{who}: {name} x {f}: a factor must be 0 or more"));
            }
        }
        if identity {
            return Err(format!(
                "{who} changes nothing: {name}'s {what} {amount} leaves it as it is"
            ));
        }
        Ok(())
    }

    /// The parameter's value after the edit.
    pub fn apply(self, value: f64) -> f64 {
        match self {
            Edit::Set(v) => v,
            Edit::Scale(f) => value * f,
            Edit::Offset(d) => value + d,
        }
    }
}

impl Measure {
    /// Its edits, parameter by parameter (in name order: set, scale, offset).
    pub fn edits(&self) -> Vec<(&str, Edit)> {
        let set = self.set.iter().map(|(n, v)| (n.as_str(), Edit::Set(*v)));
        let scale = self
            .scale
            .iter()
            .map(|(n, v)| (n.as_str(), Edit::Scale(*v)));
        let offset = self
            .offset
            .iter()
            .map(|(n, v)| (n.as_str(), Edit::Offset(*v)));
        set.chain(scale).chain(offset).collect()
    }

    /// A draw's parameter values with the measure applied.
    pub fn apply(&self, values: &ParameterValues) -> ParameterValues {
        let mut v = values.clone();
        for (name, edit) in self.edits() {
            let now = v.get(name).copied().unwrap_or(f64::NAN);
            v.insert(name.to_string(), edit.apply(now));
        }
        v
    }

    /// The edits as a reader says them: `lighting_power_density x 0.6`, `economizer = true`.
    pub fn describe(&self) -> Vec<String> {
        let building = (self.building.iter().map(|(n, v)| format!("{n} = {v}")))
            .chain(self.idf.iter().map(IdfEdit::describe));
        self.edits()
            .into_iter()
            .map(|(n, e)| match e {
                Edit::Set(v) => format!("{n} = {v}"),
                Edit::Scale(f) => format!("{n} x {f}"),
                Edit::Offset(d) => format!("{n} {d:+}"),
            })
            .chain(building)
            .collect()
    }

    /// True where it edits the model itself (its building or its IDF), not only the
    /// parameters' values: the surrogate never saw such a model, and a run's values alone do
    /// not say what it simulated.
    pub fn edits_model(&self) -> bool {
        !self.building.is_empty() || !self.idf.is_empty()
    }

    /// The model its runs simulate: the calibration's, with the measure's building edits
    /// ([`bemcal_energyplus::Model::with_building_edits`]) and then its IDF edits
    /// ([`bemcal_energyplus::Model::with_idf_edits`]) where it has any.
    pub fn model(
        &self,
        model: &bemcal_energyplus::Model,
        idd: &Idd,
    ) -> Result<bemcal_energyplus::Model, String> {
        let who = format!("measure '{}'", bemcal_excerpt::excerpt(&self.name, 60));
        let mut m = model.clone();
        if !self.building.is_empty() {
            m = m
                .with_building_edits(&self.building)
                .map_err(|e| format!("{who}: {e}"))?;
        }
        if !self.idf.is_empty() {
            m = m
                .with_idf_edits(&self.idf, idd)
                .map_err(|e| format!("{who}: {e}"))?;
        }
        Ok(m)
    }

    /// What its edits of the model are, as text: the key of the runs it simulates beside their
    /// values (the building edits' JSON, `{}` where there are none, then the IDF edits' where
    /// there are any).
    pub fn model_edits_key(&self) -> String {
        let mut text = serde_json::to_string(&self.building).unwrap_or_default();
        if !self.idf.is_empty() {
            text.push('\n');
            text.push_str(&serde_json::to_string(&self.idf).unwrap_or_default());
        }
        text
    }

    /// The folder of its runs under `savings/<weather>/`: [`Measure::folder`], and for a
    /// measure that edits the model a key of those edits ([`Measure::model_edits_key`]),
    /// since a run is reloaded by its parameter values alone and the same values then
    /// simulate another building.
    pub fn runs_folder(&self) -> String {
        if !self.edits_model() {
            return self.folder();
        }
        use sha2::Digest;
        let text = self.model_edits_key();
        let digest = sha2::Sha256::digest(text.as_bytes());
        let key: String = digest[..4].iter().map(|b| format!("{b:02x}")).collect();
        format!("{}-{key}", self.folder())
    }

    /// The folder of its runs under `savings/`: the name in lower case, runs of other
    /// characters than letters and digits as one `-`.
    pub fn folder(&self) -> String {
        let mut s = String::new();
        for c in self.name.trim().chars().flat_map(char::to_lowercase) {
            if c.is_ascii_alphanumeric() {
                s.push(c);
            } else if !s.ends_with('-') {
                s.push('-');
            }
        }
        s.trim_matches('-').to_string()
    }

    /// Checks that need no model: a name, at least one edit, finite amounts, no parameter
    /// edited twice, no edit that is the identity.
    pub fn check(&self) -> Result<(), String> {
        let who = format!("measure '{}'", bemcal_excerpt::excerpt(&self.name, 60));
        if self.folder().is_empty() {
            return Err(format!(
                "{who}: needs a name with a letter or digit (its runs' folder is named after it)"
            ));
        }
        let edits = self.edits();
        if edits.is_empty() && !self.edits_model() {
            return Err(format!(
                "{who} names nothing: give set = {{ NAME = VALUE }}, scale = {{ NAME = FACTOR }} \
                 or offset = {{ NAME = AMOUNT }} of parameters, building = {{ FIELD = VALUE }}, \
                 or idf = [{{ class = ..., object = ..., field = ..., edit = ..., value = ... }}]"
            ));
        }
        let mut seen = std::collections::BTreeSet::new();
        for (name, edit) in edits {
            if !seen.insert(name) {
                return Err(format!(
                    "{who} edits {name} twice (in two of set, scale and offset): give one"
                ));
            }
            edit.check(&who, name)?;
        }
        for e in &self.idf {
            let name = format!("idf edit '{}'", bemcal_excerpt::excerpt(&e.describe(), 120));
            Edit::of(e).check(&who, &name)?;
        }
        Ok(())
    }

    /// Checks against the model and the calibration: every parameter named is the model's, a
    /// `set` of a parameter the calibration held fixed differs from its value, and the
    /// building edits apply ([`Measure::model`]). Returns the notes a reader needs: the
    /// parameters the measure edits that the calibration did not calibrate (their value is the
    /// same in every draw, as the calibration held it) and the building edits.
    pub fn check_model(
        &self,
        model: &bemcal_energyplus::Model,
        idd: &Idd,
        calibrated: &[String],
        fixed: &ParameterValues,
    ) -> Result<Vec<String>, String> {
        let who = format!("measure '{}'", bemcal_excerpt::excerpt(&self.name, 60));
        let mut notes = vec![];
        if self.edits_model() {
            self.model(model, idd)?;
        }
        if !self.idf.is_empty() {
            let objects: Vec<String> = (self.idf.iter())
                .map(|e| format!("{} {}", e.class, e.object))
                .collect();
            notes.push(format!(
                "it edits the IDF ({}), the same in every draw: its interval carries the \
                 calibrated parameters' uncertainty under the edited model, none of the edit's own",
                bemcal_excerpt::shorten(&objects.join(", "))
            ));
        }
        if !self.building.is_empty() {
            let fields: Vec<&str> = self.building.keys().map(String::as_str).collect();
            notes.push(format!(
                "it edits the building ({}), the same in every draw: its interval carries the \
                 calibrated parameters' uncertainty under the edited building, none of the \
                 edit's own",
                fields.join(", ")
            ));
        }
        for (name, edit) in self.edits() {
            if !model.parameters().iter().any(|p| p.name == name) {
                let known: Vec<&str> = model.parameters().iter().map(|p| p.name.as_str()).collect();
                return Err(format!(
                    "{who}: the model has no parameter '{}'; it has: {}",
                    bemcal_excerpt::excerpt(name, 60),
                    bemcal_excerpt::shorten(&known.join(", "))
                ));
            }
            if calibrated.iter().any(|c| c == name) {
                continue;
            }
            let held = fixed.get(name).copied().unwrap_or(f64::NAN);
            if let Edit::Set(v) = edit {
                if v == held {
                    return Err(format!(
                        "{who} changes nothing: {name} = {v} is the value the calibration held it at"
                    ));
                }
            }
            notes.push(format!(
                "{name} was not calibrated: every draw has it at {held}, so this measure's \
                 interval carries no uncertainty of it"
            ));
        }
        Ok(notes)
    }
}

/// What would narrow the interval of a saving that a parameter's posterior spread drives: the
/// measurement that observes that parameter apart from the others on the same meter.
pub fn what_would_narrow(parameter: &str) -> &'static str {
    let p = parameter.to_ascii_lowercase();
    let has = |words: &[&str]| words.iter().any(|w| p.contains(w));
    if has(&["lighting"]) {
        "a lighting sub-meter (or a lighting survey with logged hours)"
    } else if has(&["equipment", "plug"]) {
        "a plug-load sub-meter (or a night-time base-load test)"
    } else if has(&["setpoint", "set_point"]) {
        "trend logs of the zone temperatures and set-points from the building automation system"
    } else if has(&["outdoor_air", "ach", "infiltration", "ventilation"]) {
        "an outdoor-air flow measurement (or a CO2 trend of occupied hours)"
    } else if has(&[
        "insulation",
        "conductivity",
        "u_value",
        "shgc",
        "window",
        "glazing",
    ]) {
        "a longer heating and cooling season record, or a co-heating or thermography test"
    } else if has(&["schedule"]) {
        "a sub-meter of the end use the schedule drives, or occupancy counts"
    } else if has(&["hot_water"]) {
        "a water heater's gas or hot-water flow meter"
    } else {
        "a sub-meter of the end use it drives, or a longer record"
    }
}

/// The weather a saving is simulated under.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum SavingsWeather {
    /// The calibration's own: the metered year's where the project has `[measured_weather]`.
    Calibration,
    /// The site's typical year (the project's `weather` under `[measured_weather]`):
    /// weather-normalised savings.
    Typical,
}

impl SavingsWeather {
    /// Its name in `summary.json` and folders.
    pub fn as_str(self) -> &'static str {
        match self {
            SavingsWeather::Calibration => "calibration",
            SavingsWeather::Typical => "typical",
        }
    }
}

/// What simulated a measure's savings.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum SavingsMethod {
    /// EnergyPlus at every posterior draw, with and without the measure.
    Energyplus,
    /// The surrogate at many posterior draws, corrected onto EnergyPlus at a few (the metered
    /// outputs under the calibration's weather; the others by EnergyPlus alone).
    SurrogateCorrected,
}

/// `summary.json`'s `savings`: every measure's savings over posterior draws.
#[derive(Debug, Clone, Serialize, Deserialize, schemars::JsonSchema)]
pub struct SavingsReport {
    /// The posterior draws simulated (evenly spaced over the chains' draws, from
    /// `draws_with_surrogate_error.csv` where the surrogate's error was carried, else
    /// `draws.csv`).
    pub draws: usize,
    /// Where the draws came from.
    pub draws_file: String,
    /// How the model's errors enter the savings.
    pub notes: Vec<String>,
    /// Pairs of parameters tied in the posterior whose split was drawn again from their priors
    /// at each draw (`bemcal savings --split priors`, the default); left out where none.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub split_redrawn: Vec<RedrawnSplit>,
    /// One per measure, in the project's order.
    pub measures: Vec<MeasureSavings>,
}

/// One measure's savings.
#[derive(Debug, Clone, Serialize, Deserialize, schemars::JsonSchema)]
pub struct MeasureSavings {
    /// The measure's name.
    pub measure: String,
    /// Its edits (`lighting_power_density x 0.6`).
    pub edits: Vec<String>,
    /// What simulated it.
    pub method: SavingsMethod,
    /// Why that method.
    pub method_note: String,
    /// The posterior draws the surrogate simulated (0: EnergyPlus alone).
    #[serde(default)]
    pub surrogate_draws: usize,
    /// Parameters the measure takes outside their prior's support at some draw (the
    /// surrogate's training range).
    pub beyond_prior: Vec<String>,
    /// What its edits leave out of the interval: the parameters it edits that the calibration
    /// did not calibrate, and its building edits.
    pub notes: Vec<String>,
    /// Draws whose simulation with or without the measure failed, with the reason (left out).
    pub failed: Vec<String>,
    /// Per weather and output.
    pub outputs: Vec<OutputSavings>,
}

/// A measure's savings on one output under one weather.
#[derive(Debug, Clone, Serialize, Deserialize, schemars::JsonSchema)]
pub struct OutputSavings {
    /// The model output (and its meter).
    pub output: String,
    /// The weather simulated.
    pub weather: SavingsWeather,
    /// Draws with both simulations.
    pub n: usize,
    /// The annual energy without the measure: median over the draws, kWh.
    #[serde(deserialize_with = "bemcal_stats::nan::null_as_nan")]
    #[schemars(with = "bemcal_stats::nan::NumberOrNull")]
    pub baseline_kwh: f64,
    /// The annual saving, kWh (positive: the measure saves).
    pub savings_kwh: Spread,
    /// The annual saving in percent of each draw's own baseline.
    pub savings_percent: Spread,
    /// The annual saving at the calibration's estimate (EnergyPlus), kWh; NaN where it failed.
    #[serde(deserialize_with = "bemcal_stats::nan::null_as_nan")]
    #[schemars(with = "bemcal_stats::nan::NumberOrNull")]
    pub at_estimate_kwh: f64,
    /// Monthly savings, kWh, January to December.
    pub monthly_kwh: Vec<Spread>,
    /// The parameters whose posterior spread drives the interval, largest share first (those
    /// explaining 10 % or more of the savings' variance).
    pub drivers: Vec<Driver>,
    /// Why this saving may not be trusted as it stands (no meter, not fitted, Guideline 14
    /// missed at the estimate), or none.
    #[serde(default)]
    pub warning: Option<String>,
    /// With the surrogate: the line from its annual savings to EnergyPlus's at EnergyPlus's
    /// draws, through which its draws were corrected.
    #[serde(default)]
    pub correction: Option<bemcal_stats::savings::Correction>,
}

/// A parameter whose posterior spread drives a saving's interval.
#[derive(Debug, Clone, Serialize, Deserialize, schemars::JsonSchema)]
pub struct Driver {
    /// The calibrated parameter.
    pub parameter: String,
    /// The share of the savings' variance over the draws it explains alone (squared
    /// correlation).
    #[serde(deserialize_with = "bemcal_stats::nan::null_as_nan")]
    #[schemars(with = "bemcal_stats::nan::NumberOrNull")]
    pub share: f64,
    /// Its posterior 90 % interval's width over its prior's (near 1: the meters did not
    /// identify it).
    #[serde(deserialize_with = "bemcal_stats::nan::null_as_nan")]
    #[schemars(with = "bemcal_stats::nan::NumberOrNull")]
    pub width_ratio: f64,
    /// The measurement that would narrow it.
    pub would_narrow: String,
    /// Parameters strongly correlated with it in the posterior
    /// (`PosteriorSummary::correlated_pairs`): the meters constrain a combination of them.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub moves_with: Vec<Partner>,
}

/// A pair of parameters tied in the posterior, and the line along which each draw's split
/// between them was drawn again from their priors.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct RedrawnSplit {
    /// The first parameter.
    pub a: String,
    /// The second.
    pub b: String,
    /// Their Pearson correlation over the posterior draws.
    #[serde(deserialize_with = "bemcal_stats::nan::null_as_nan")]
    #[schemars(with = "bemcal_stats::nan::NumberOrNull")]
    pub correlation: f64,
    /// The line's unit direction in (a, b), the parameters' own units: the major axis of
    /// their posterior draws.
    pub direction: [f64; 2],
}

/// A parameter a driver moves with in the posterior.
#[derive(Debug, Clone, Serialize, Deserialize, schemars::JsonSchema)]
pub struct Partner {
    /// The other calibrated parameter.
    pub parameter: String,
    /// Their Pearson correlation over the posterior draws.
    #[serde(deserialize_with = "bemcal_stats::nan::null_as_nan")]
    #[schemars(with = "bemcal_stats::nan::NumberOrNull")]
    pub correlation: f64,
}

#[cfg(test)]
mod tests {
    use super::*;

    fn measure(text: &str) -> Measure {
        toml::from_str(text).unwrap()
    }

    #[test]
    fn a_measure_edits_each_draw_as_it_says() {
        let m = measure(
            "name = \"LED + setback\"\nscale = { lpd = 0.6 }\noffset = { csp = 1.0 }\nset = { shgc = 0.35 }",
        );
        m.check().unwrap();
        let v: ParameterValues = [("lpd", 10.0), ("csp", 24.0), ("shgc", 0.5), ("x", 1.0)]
            .into_iter()
            .map(|(n, v)| (n.to_string(), v))
            .collect();
        let after = m.apply(&v);
        assert_eq!(after["lpd"], 6.0);
        assert_eq!(after["csp"], 25.0);
        assert_eq!(after["shgc"], 0.35);
        assert_eq!(after["x"], 1.0);
        assert_eq!(m.folder(), "led-setback");
        assert_eq!(m.describe(), ["shgc = 0.35", "lpd x 0.6", "csp +1"]);
    }

    #[test]
    fn a_measure_naming_nothing_or_changing_nothing_is_refused() {
        let e = measure("name = \"empty\"").check().unwrap_err();
        assert!(e.contains("measure 'empty' names nothing"), "{e}");
        let e = measure("name = \"x\"\nscale = { lpd = 1.0 }")
            .check()
            .unwrap_err();
        assert!(e.contains("changes nothing") && e.contains("lpd"), "{e}");
        let e = measure("name = \"x\"\noffset = { csp = 0.0 }")
            .check()
            .unwrap_err();
        assert!(e.contains("changes nothing"), "{e}");
        let e = measure("name = \"x\"\nscale = { lpd = 0.5 }\noffset = { lpd = 1.0 }")
            .check()
            .unwrap_err();
        assert!(e.contains("edits lpd twice"), "{e}");
        let e = measure("name = \"--\"\nscale = { lpd = 0.5 }")
            .check()
            .unwrap_err();
        assert!(e.contains("needs a name"), "{e}");
        let e = measure("name = \"x\"\nscale = { lpd = -1.0 }")
            .check()
            .unwrap_err();
        assert!(e.contains("0 or more"), "{e}");
        assert!(toml::from_str::<Measure>("name = \"x\"\nmultiply = { lpd = 2.0 }").is_err());
    }

    #[test]
    fn a_building_measure_names_its_edits_and_keys_its_runs_by_them() {
        let m = measure("name = \"Economizer\"\nbuilding = { economizer = true }");
        m.check().unwrap();
        assert_eq!(m.describe(), ["economizer = true"]);
        let other = measure("name = \"Economizer\"\nbuilding = { occupied_hours = [8, 18] }");
        assert!(m.runs_folder().starts_with("economizer-"));
        assert_ne!(m.runs_folder(), other.runs_folder());
        let v: ParameterValues = [("lpd".to_string(), 10.0)].into_iter().collect();
        assert_eq!(m.apply(&v), v);
        let plain = measure("name = \"LED\"\nscale = { lpd = 0.6 }");
        assert_eq!(plain.runs_folder(), "led");
    }

    #[test]
    fn an_idf_measure_names_its_edits_and_keys_its_runs_by_them() {
        let m = measure(
            "name = \"Fans\"\nidf = [{ class = \"Fan:VariableVolume\", field = \"Pressure Rise\", \
             edit = \"scale\", value = 0.7 }]",
        );
        m.check().unwrap();
        assert!(m.edits_model());
        assert_eq!(m.describe(), ["Fan:VariableVolume Pressure Rise x 0.7"]);
        let economizer = measure("name = \"Fans\"\nbuilding = { economizer = true }");
        // A building edit's key is its JSON, as before IDF edits existed (cached runs keep it).
        assert_eq!(economizer.model_edits_key(), r#"{"economizer":true}"#);
        assert!(m.runs_folder().starts_with("fans-"));
        assert_ne!(m.runs_folder(), economizer.runs_folder());
        let e = measure(
            "name = \"x\"\nidf = [{ class = \"Lights\", field = \"Watts per Floor Area\", \
             edit = \"scale\", value = 1.0 }]",
        )
        .check()
        .unwrap_err();
        assert!(e.contains("changes nothing") && e.contains("Lights"), "{e}");
    }

    #[test]
    fn what_would_narrow_names_a_measurement_of_the_end_use() {
        assert!(what_would_narrow("lighting_power_density").contains("lighting sub-meter"));
        assert!(what_would_narrow("cooling_setpoint_occupied").contains("set-points"));
        assert!(what_would_narrow("outdoor_air_ach_occupied").contains("outdoor-air"));
    }
}

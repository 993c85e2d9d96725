//! What gets calibrated: a generated building or a user's IDF with a parameter map.
//!
//! A model file is TOML. Without an `[idf]` table it is a [`BuildingSpec`]. With one, it names a
//! user's IDF and maps each calibration parameter to fields of objects in it:
//!
//! ```toml
//! year = 2017                       # the meters' year (default 2021); bemcal writes the
//! holidays = "us_federal"            # run period and special days (see crate::calendar)
//!
//! [idf]
//! path = "my_building.idf"          # relative to the model file
//!
//! [[parameter]]
//! name = "lighting_power_density"
//! unit = "W/m2"
//! prior = { min = 5.0, mode = 10.0, max = 15.0 }
//! targets = [{ class = "Lights", object = "*", field = "Watts per Floor Area" }]
//!
//! [[output]]
//! name = "electricity_kwh"
//! meters = ["Electricity:Facility"]
//!
//! [[constraint]]                    # optional: lower + margin <= upper
//! lower = "heating_setpoint"
//! upper = "cooling_setpoint"
//! margin = 0.0
//! reason = "heating above cooling set-point is fatal"
//! ```

use std::path::{Path, PathBuf};

use bemcal_weather::grid::GridYear;
use bemcal_weather::{Calendar, Holidays};
use serde::{Deserialize, Serialize};

use crate::building::{BuildingSpec, HeatingSource};
use crate::idd::Idd;
use crate::idf::{num, Idf};
use crate::meters::OutputSpec;
use crate::params::{complete_values, Constraint, ParameterDef, ParameterValues, TriangularPrior};
use crate::{io_err, Error};

/// One field a parameter sets: in every object of `class` whose name matches `object` (a name,
/// `*` for all, or a pattern with `*` wildcards such as `Office*`, case-insensitive).
///
/// `edit` says how the parameter's value enters the field: `set` (the default: the field is
/// the value), `scale` (the field of the user's IDF times the value: `Lights` of every zone
/// scaled by one multiplier) or `offset` (the field plus the value: set-points moved by a few
/// degrees). With `scale` or `offset`, `field = "*"` edits every numeric field of the object
/// (the values of a `Schedule:Compact`, leaving its `Through:`/`For:`/`Until:` fields).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct FieldTarget {
    /// The objects' class.
    pub class: String,
    /// Their name, `*`, or a pattern with `*` wildcards.
    pub object: String,
    /// The field's name as the IDD spells it, or `*` (every numeric field, with `scale` or
    /// `offset`).
    pub field: String,
    /// How the value enters the field.
    #[serde(default)]
    pub edit: Edit,
}

/// How a parameter's value enters a field ([`FieldTarget`]).
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, schemars::JsonSchema,
)]
#[serde(rename_all = "snake_case")]
pub enum Edit {
    /// The field becomes the value.
    #[default]
    Set,
    /// The field of the user's IDF is multiplied by the value.
    Scale,
    /// The value is added to the field of the user's IDF.
    Offset,
}

/// A retrofit measure's edit of fields of the IDF a draw simulates ([`Model::with_idf_edits`]):
/// the objects and field as a [`FieldTarget`] names them, and the value the edit takes, the
/// same in every draw. Relative edits (`scale`, `offset`) start from the field as the draw's
/// parameters left it.
///
/// ```toml
/// idf = [{ class = "HVACTemplate:System:VAV", object = "*", field = "Supply Fan Delta Pressure", edit = "scale", value = 0.7 }]
/// ```
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct IdfEdit {
    /// The objects' class.
    pub class: String,
    /// Their name, `*` (the default), or a pattern with `*` wildcards.
    #[serde(default = "every_object")]
    pub object: String,
    /// The field's name as the IDD spells it, or `*` (every numeric field, with `scale` or
    /// `offset`).
    pub field: String,
    /// How the value enters the field (`set`, the default; `scale`; `offset`).
    #[serde(default)]
    pub edit: Edit,
    /// The value, factor or amount.
    pub value: f64,
}

fn every_object() -> String {
    "*".into()
}

impl IdfEdit {
    /// The objects and field it edits.
    pub fn target(&self) -> FieldTarget {
        FieldTarget {
            class: self.class.clone(),
            object: self.object.clone(),
            field: self.field.clone(),
            edit: self.edit,
        }
    }

    /// As a reader says it: `HVACTemplate:System:VAV Supply Fan Delta Pressure x 0.7` (the
    /// object named where it is not `*`).
    pub fn describe(&self) -> String {
        let what = match self.object.as_str() {
            "*" => format!("{} {}", self.class, self.field),
            object => format!("{} {object} {}", self.class, self.field),
        };
        match self.edit {
            Edit::Set => format!("{what} = {}", self.value),
            Edit::Scale => format!("{what} x {}", self.value),
            Edit::Offset => format!("{what} {:+}", self.value),
        }
    }
}

impl FieldTarget {
    /// True when `name` matches `object` (`*` wildcards, case-insensitive).
    fn matches(&self, name: Option<&str>) -> bool {
        let Some(name) = name else {
            return self.object == "*";
        };
        glob_match(
            &self.object.to_ascii_lowercase(),
            &name.to_ascii_lowercase(),
        )
    }

    /// The field positions this target edits in `o` (IDD `index`, or every numeric field for
    /// `field = "*"`).
    fn positions(&self, o: &crate::idf::IdfObject, index: Option<usize>) -> Vec<usize> {
        match index {
            Some(i) => vec![i],
            None => (1..o.fields.len())
                .filter(|&i| o.fields[i].trim().parse::<f64>().is_ok())
                .collect(),
        }
    }
}

/// `*`-wildcard match of a whole string.
fn glob_match(pattern: &str, s: &str) -> bool {
    let parts: Vec<&str> = pattern.split('*').collect();
    if parts.len() == 1 {
        return pattern == s;
    }
    let (first, last) = (parts[0], parts[parts.len() - 1]);
    if !s.starts_with(first) || !s[first.len()..].ends_with(last) {
        return false;
    }
    let mut rest = &s[first.len()..s.len() - last.len()];
    for part in &parts[1..parts.len() - 1] {
        match rest.find(part) {
            Some(k) => rest = &rest[k + part.len()..],
            None => return false,
        }
    }
    true
}

/// A parameter of a user IDF and the fields it sets.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct MappedParameter {
    /// The parameter's name.
    pub name: String,
    /// Its unit, for listings.
    #[serde(default)]
    pub unit: String,
    /// What it is, for listings.
    #[serde(default)]
    pub description: String,
    /// Its triangular prior.
    pub prior: TriangularPrior,
    /// The fields it sets.
    pub targets: Vec<FieldTarget>,
}

/// The `[idf]` form of a model file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ParameterMap {
    /// The year simulated, as a building spec's `year`: a calendar year (`2017`) or twelve
    /// months from another month (`"2017-04"`); it must be the meters' year. bemcal writes the
    /// IDF's run period for it ([`crate::calendar`]).
    #[serde(default = "crate::calendar::default_year")]
    pub year: GridYear,
    /// Holidays run on the weekend schedule, as a building spec's `holidays`; they replace the
    /// IDF's own `RunPeriodControl:SpecialDays`.
    #[serde(default)]
    pub holidays: Holidays,
    /// A file of holiday dates, relative to the model file; its dates replace `holidays`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub holidays_file: Option<PathBuf>,
    /// The day-type calendar the meters show (pre-calibration's `calendar.csv`), relative to
    /// the model file: the surrogate's day types on the listed dates. (The IDF's schedules are
    /// the user's: they are not rewritten for these dates.)
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub day_types_file: Option<PathBuf>,
    /// The user's IDF (`[idf] path`).
    pub idf: IdfRef,
    /// `[[parameter]]`: the calibration parameters and the fields they set.
    #[serde(rename = "parameter", default)]
    pub parameters: Vec<MappedParameter>,
    /// `[[output]]`: the outputs compared with meters.
    #[serde(rename = "output", default)]
    pub outputs: Vec<OutputSpec>,
    /// `[[constraint]]`: physical constraints between parameters.
    #[serde(rename = "constraint", default)]
    pub constraints: Vec<Constraint>,
}

/// Where the user's IDF is.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct IdfRef {
    /// The IDF file, relative to the model file.
    pub path: PathBuf,
}

#[derive(Debug, Clone)]
enum Source {
    Generated(BuildingSpec),
    Mapped {
        idf: Idf,
        map: ParameterMap,
        calendar: Calendar,
    },
}

/// A calibratable model.
#[derive(Debug, Clone)]
pub struct Model {
    source: Source,
    parameters: Vec<ParameterDef>,
    constraints: Vec<Constraint>,
    outputs: Vec<OutputSpec>,
    /// A retrofit measure's edits of the IDF, applied after the parameters
    /// ([`Model::with_idf_edits`]); none for a calibration's model.
    idf_edits: Vec<IdfEdit>,
    /// Where it was loaded from (for messages).
    pub path: PathBuf,
}

impl Model {
    /// A generated building.
    pub fn generated(spec: BuildingSpec) -> Model {
        let outputs = generated_outputs(&spec);
        Model {
            parameters: spec.parameters(),
            constraints: spec.constraints(),
            outputs,
            source: Source::Generated(spec),
            idf_edits: vec![],
            path: PathBuf::from("<generated>"),
        }
    }

    /// Loads a model file (building spec or IDF + parameter map). `idd` is needed to check the
    /// field names of a parameter map.
    pub fn load(path: &Path, idd: &Idd) -> Result<Model, Error> {
        let text = std::fs::read_to_string(path).map_err(io_err(path))?;
        Model::from_toml(&text, path, idd)
    }

    /// The files a model file names, as written (relative to the model file's folder): an
    /// `[idf]` map's IDF, and either form's `holidays_file` and `day_types_file` — what
    /// [`Model::from_toml`] reads besides the model file itself.
    pub fn named_files(text: &str, path: &Path) -> Result<Vec<PathBuf>, Error> {
        let value: toml::Table = crate::parse_toml(text, path)?;
        if value.contains_key("idf") {
            let map: ParameterMap = crate::parse_toml(text, path)?;
            return Ok(std::iter::once(map.idf.path)
                .chain(map.holidays_file)
                .chain(map.day_types_file)
                .collect());
        }
        let spec: BuildingSpec = crate::parse_toml(text, path)?;
        Ok(spec
            .holidays_file
            .into_iter()
            .chain(spec.day_types_file)
            .collect())
    }

    /// Parses a model file's text (`path` locates relative files and names errors).
    pub fn from_toml(text: &str, path: &Path, idd: &Idd) -> Result<Model, Error> {
        let value: toml::Table = crate::parse_toml(text, path)?;
        if !value.contains_key("idf") {
            let spec = BuildingSpec::from_toml(text, path)?;
            let mut m = Model::generated(spec);
            m.path = path.into();
            return Ok(m);
        }
        let map: ParameterMap = crate::parse_toml(text, path)?;
        let calendar = map_calendar(&map, text, path)?;
        let idf_path = path.parent().unwrap_or(Path::new(".")).join(&map.idf.path);
        let idf_text = std::fs::read_to_string(&idf_path).map_err(io_err(&idf_path))?;
        let idf = Idf::parse(&idf_text, &idf_path)?;
        crate::screen::screen(&idf, idd, &idf_path)?;
        let err = |message: String| Error::Input {
            path: path.into(),
            line: 0,
            message,
        };
        if map.outputs.is_empty() {
            return Err(err(
                "no [[output]]: name at least one output and its meters".into(),
            ));
        }
        for p in &map.parameters {
            check_parameter(p, &idf, &idf_path, idd).map_err(err)?;
        }
        let parameters = map
            .parameters
            .iter()
            .map(|p| ParameterDef {
                name: p.name.clone(),
                unit: p.unit.clone(),
                description: p.description.clone(),
                prior: p.prior,
            })
            .collect();
        Ok(Model {
            parameters,
            constraints: map.constraints.clone(),
            outputs: map.outputs.clone(),
            source: Source::Mapped { idf, map, calendar },
            idf_edits: vec![],
            path: path.into(),
        })
    }

    /// The calibration parameters, in the model's order.
    pub fn parameters(&self) -> &[ParameterDef] {
        &self.parameters
    }

    /// Replaces the prior of a parameter (e.g. from pre-calibration).
    pub fn set_prior(&mut self, name: &str, prior: TriangularPrior) -> Result<(), Error> {
        let Some(i) = self.parameters.iter().position(|p| p.name == name) else {
            let why = self.spec().and_then(|s| s.absent(name));
            return Err(Error::Parameter {
                name: name.into(),
                message: why.map_or("unknown parameter".into(), |w| {
                    format!("unknown parameter ({w})")
                }),
            });
        };
        self.parameters[i].prior = prior;
        Ok(())
    }

    /// Constraints between parameters.
    pub fn constraints(&self) -> &[Constraint] {
        &self.constraints
    }

    /// The calibration outputs and their meters.
    pub fn outputs(&self) -> &[OutputSpec] {
        &self.outputs
    }

    /// The same model with a retrofit measure's edits of its building spec
    /// ([`BuildingSpec::edited`]): the parameters, their priors and the outputs stay the
    /// calibration's, so that a posterior draw's values mean the same in both. Refused for an
    /// own IDF (its measures edit the `[idf]` map's parameters) and where the edit would
    /// change the parameters or the outputs (another HVAC system's, say).
    pub fn with_building_edits(
        &self,
        edits: &std::collections::BTreeMap<String, serde_json::Value>,
    ) -> Result<Model, String> {
        let Source::Generated(spec) = &self.source else {
            return Err(
                "building: an own IDF's building is its IDF; edit its objects \
                        through the [idf] map's parameters (set, scale, offset)"
                    .into(),
            );
        };
        let edited = Model::generated(spec.edited(edits)?);
        let names =
            |m: &Model| -> Vec<String> { m.parameters.iter().map(|p| p.name.clone()).collect() };
        if names(&edited) != names(self) {
            let (now, then) = (names(self), names(&edited));
            let lost: Vec<&str> = now
                .iter()
                .filter(|n| !then.contains(n))
                .map(String::as_str)
                .collect();
            let new: Vec<&str> = then
                .iter()
                .filter(|n| !now.contains(n))
                .map(String::as_str)
                .collect();
            return Err(format!(
                "building: the edits change the model's parameters (without: {}; new: {}), \
                 so a posterior draw would not carry over",
                bemcal_excerpt::shorten(&lost.join(", ")),
                bemcal_excerpt::shorten(&new.join(", "))
            ));
        }
        if edited.outputs != self.outputs {
            return Err(
                "building: the edits change the model's outputs (their meters), \
                        so savings could not be compared output by output"
                    .into(),
            );
        }
        Ok(Model {
            source: edited.source,
            parameters: self.parameters.clone(),
            constraints: self.constraints.clone(),
            outputs: self.outputs.clone(),
            idf_edits: self.idf_edits.clone(),
            path: self.path.clone(),
        })
    }

    /// The building spec, for a generated model.
    pub fn spec(&self) -> Option<&BuildingSpec> {
        match &self.source {
            Source::Generated(s) => Some(s),
            Source::Mapped { .. } => None,
        }
    }

    /// The calendar the model simulates: its year, holidays and observed day types (the
    /// surrogate's day types come from it, and EnergyPlus runs its dates).
    pub fn calendar(&self) -> Calendar {
        match &self.source {
            Source::Generated(s) => s.calendar(),
            Source::Mapped { calendar, .. } => calendar.clone(),
        }
    }

    /// The calendar of a model file's text, either form, without loading its IDF or
    /// checking its parameter map against EnergyPlus's IDD (for commands that only need the
    /// dates, such as `bemcal predict`).
    pub fn calendar_from_toml(text: &str, path: &Path) -> Result<Calendar, Error> {
        let value: toml::Table = crate::parse_toml(text, path)?;
        if value.contains_key("idf") {
            let map: ParameterMap = crate::parse_toml(text, path)?;
            return map_calendar(&map, text, path);
        }
        Ok(BuildingSpec::from_toml(text, path)?.calendar())
    }

    /// Complete, checked values: unknown names rejected, missing ones at the prior mode,
    /// constraints enforced.
    pub fn values(&self, given: &ParameterValues) -> Result<ParameterValues, Error> {
        let v = complete_values(&self.parameters, given)?;
        for c in &self.constraints {
            c.check(&v)?;
        }
        Ok(v)
    }

    /// The IDF for a set of parameter values (see [`Model::values`]), with a measure's IDF
    /// edits where the model has any ([`Model::with_idf_edits`]).
    pub fn instantiate(&self, given: &ParameterValues, idd: &Idd) -> Result<Idf, Error> {
        let v = self.values(given)?;
        let mut out = match &self.source {
            Source::Generated(spec) => spec.to_idf(&v)?,
            Source::Mapped { idf, map, calendar } => {
                let mut out = idf.clone();
                for p in &map.parameters {
                    for t in &p.targets {
                        // Relative edits start from the user's IDF, so edits never compound.
                        edit_fields(&mut out, idf, t, v[&p.name], idd);
                    }
                }
                // After the edits, which pair each object with the user's by position.
                crate::calendar::set_run_period(&mut out, calendar);
                out
            }
        };
        if !self.idf_edits.is_empty() {
            let drawn = out.clone();
            for e in &self.idf_edits {
                edit_fields(&mut out, &drawn, &e.target(), e.value, idd);
            }
        }
        Ok(out)
    }

    /// The same model with a retrofit measure's edits of the IDF each draw simulates, applied
    /// after the parameters (a relative edit starts from the field as the draw left it): the
    /// parameters, their priors and the outputs stay the calibration's. Each edit is checked
    /// against the IDF at the priors' modes (its class, field and objects, a number in every
    /// field a relative edit takes, a value a `set` can write) and refused where it changes
    /// nothing there; the message names the edit.
    pub fn with_idf_edits(&self, edits: &[IdfEdit], idd: &Idd) -> Result<Model, String> {
        let at_modes = self
            .instantiate(&ParameterValues::new(), idd)
            .map_err(|e| format!("the model at its priors' modes: {e}"))?;
        let mut taken: Vec<(Vec<(usize, usize)>, String)> = vec![];
        for e in edits {
            let who = format!("idf edit '{}'", bemcal_excerpt::excerpt(&e.describe(), 120));
            if !e.value.is_finite() || (e.edit == Edit::Scale && e.value < 0.0) {
                return Err(format!(
                    "{who}: the value must be finite (a factor 0 or more)"
                ));
            }
            if is_setting(&e.class) {
                return Err(format!(
                    "{who}: {} objects are the simulation's settings (its period, time step, \
                     outputs, site), not a measure's",
                    e.class
                ));
            }
            check_target(&e.target(), &at_modes, idd, "the IDF each draw simulates")
                .map_err(|m| format!("{who}: {m}"))?;
            let fields = edited_fields(&at_modes, &e.target(), idd);
            if let Some((_, other)) = taken
                .iter()
                .find(|(f, _)| f.iter().any(|x| fields.contains(x)))
            {
                return Err(format!(
                    "{who} edits a field '{other}' edits too: give each field one edit"
                ));
            }
            if let Some(p) = self.parameter_on(&fields, &at_modes, idd) {
                return Err(format!(
                    "{who} edits a field parameter {p} sets in every draw: edit the parameter \
                     instead (set, scale or offset = {{ {p} = ... }})"
                ));
            }
            let mut edited = at_modes.clone();
            edit_fields(&mut edited, &at_modes, &e.target(), e.value, idd);
            let number = |idf: &Idf, (o, i): (usize, usize)| {
                let text = idf.objects[o].fields.get(i).map_or("", |f| f.trim());
                text.parse::<f64>().map_err(|_| text.to_string())
            };
            if fields
                .iter()
                .all(|&x| number(&edited, x) == number(&at_modes, x))
            {
                return Err(format!(
                    "{who} changes nothing: the fields already hold what it writes"
                ));
            }
            taken.push((fields, e.describe()));
        }
        let mut model = self.clone();
        model.idf_edits.extend(edits.iter().cloned());
        Ok(model)
    }

    /// The mapped parameter whose targets take one of `fields` (object, field positions in
    /// `idf`, the IDF at the priors' modes, objects by position as in the user's IDF); None
    /// for a generated building, whose parameters are its spec's.
    fn parameter_on(&self, fields: &[(usize, usize)], idf: &Idf, idd: &Idd) -> Option<String> {
        let Source::Mapped { map, .. } = &self.source else {
            return None;
        };
        (map.parameters.iter())
            .find(|p| {
                (p.targets.iter()).any(|t| {
                    edited_fields(idf, t, idd)
                        .iter()
                        .any(|x| fields.contains(x))
                })
            })
            .map(|p| p.name.clone())
    }
}

/// Whether `class` holds the simulation's settings (its period, time step, outputs, site),
/// which the calibration fixes and a measure's IDF edit may not touch.
fn is_setting(class: &str) -> bool {
    let c = class.to_ascii_lowercase();
    [
        "version",
        "simulationcontrol",
        "timestep",
        "building",
        "convergencelimits",
        "site:location",
    ]
    .contains(&c.as_str())
        || ["runperiod", "sizingperiod", "output"]
            .iter()
            .any(|p| c.starts_with(p))
}

/// The (object, field) positions `t` edits in `idf`.
fn edited_fields(idf: &Idf, t: &FieldTarget, idd: &Idd) -> Vec<(usize, usize)> {
    let index = (t.field != "*")
        .then(|| idd.field_index(&t.class, &t.field))
        .flatten();
    if t.field != "*" && index.is_none() {
        return vec![];
    }
    (idf.objects.iter().enumerate())
        .filter(|(_, o)| o.class.eq_ignore_ascii_case(&t.class) && t.matches(o.name()))
        .flat_map(|(k, o)| t.positions(o, index).into_iter().map(move |i| (k, i)))
        .collect()
}

/// Writes `value` into the fields `t` names in `out` (objects paired with `original` by
/// position): set, or `original`'s number scaled or offset. The one rule of an edit, for the
/// parameters' targets and a measure's edits alike.
fn edit_fields(out: &mut Idf, original: &Idf, t: &FieldTarget, value: f64, idd: &Idd) {
    let index = (t.field != "*").then(|| {
        idd.field_index(&t.class, &t.field)
            .expect("checked at load")
    });
    for (o, original) in out
        .objects
        .iter_mut()
        .zip(&original.objects)
        .filter(|(o, _)| o.class.eq_ignore_ascii_case(&t.class) && t.matches(o.name()))
    {
        for i in t.positions(original, index) {
            if o.fields.len() <= i {
                o.fields.resize(i + 1, String::new());
            }
            let base = || {
                original.fields[i]
                    .trim()
                    .parse::<f64>()
                    .expect("checked at load")
            };
            o.fields[i] = match t.edit {
                Edit::Set => num(value),
                Edit::Scale => num(base() * value),
                Edit::Offset => num(base() + value),
            };
        }
    }
}

/// Checks one mapped parameter against the IDF and the IDD: its prior, and each target's class,
/// field and objects (relative edits need a number in every matched field); the message
/// names what is wrong and what exists.
fn check_parameter(
    p: &MappedParameter,
    idf: &Idf,
    idf_path: &Path,
    idd: &Idd,
) -> Result<(), String> {
    TriangularPrior::new(p.prior.min, p.prior.mode, p.prior.max)
        .map_err(|m| format!("parameter {}: {m}", p.name))?;
    if p.targets.is_empty() {
        return Err(format!("parameter {}: no targets", p.name));
    }
    for t in &p.targets {
        check_target(t, idf, idd, &idf_path.display().to_string())
            .map_err(|m| format!("parameter {}: {m}", p.name))?;
    }
    Ok(())
}

/// Checks one target against an IDF (`idf_name` names it in the message) and the IDD: the
/// class and field, at least one object, and a number in every field a relative edit takes.
fn check_target(t: &FieldTarget, idf: &Idf, idd: &Idd, idf_name: &str) -> Result<(), String> {
    if t.field == "*" && t.edit == Edit::Set {
        return Err("field = \"*\" needs edit = \"scale\" or \"offset\"".into());
    }
    if t.field != "*" && idd.field_index(&t.class, &t.field).is_none() {
        let known = idd.fields(&t.class).map(|f| f.join(", "));
        return Err(format!(
            "class '{}' has no field '{}'{}",
            t.class,
            t.field,
            known
                .map(|k| format!(" (fields: {})", bemcal_excerpt::shorten(&k)))
                .unwrap_or_else(|| " (unknown class)".into())
        ));
    }
    let index = (t.field != "*")
        .then(|| idd.field_index(&t.class, &t.field))
        .flatten();
    let matched: Vec<_> = idf
        .of_class(&t.class)
        .filter(|o| t.matches(o.name()))
        .collect();
    if t.edit != Edit::Set {
        for o in &matched {
            let positions = t.positions(o, index);
            let bad = positions.iter().find(|&&i| {
                o.fields
                    .get(i)
                    .is_none_or(|f| f.trim().parse::<f64>().is_err())
            });
            if positions.is_empty() || bad.is_some() {
                return Err(format!(
                    "edit = \"{:?}\" needs a number in {} '{}' field '{}' (found '{}')",
                    t.edit,
                    t.class,
                    o.name().unwrap_or(""),
                    t.field,
                    bad.and_then(|&i| o.fields.get(i))
                        .map_or("", |f| f.as_str())
                ));
            }
        }
    }
    if matched.is_empty() {
        return Err(format!(
            "{idf_name} has no object {} of class {}",
            t.object, t.class
        ));
    }
    Ok(())
}

/// The calendar of an `[idf]` model file: its year, holidays (or `holidays_file`) and
/// `day_types_file`.
fn map_calendar(map: &ParameterMap, text: &str, path: &Path) -> Result<Calendar, Error> {
    let (holidays, observed) = crate::calendar::read_calendar_files(
        text,
        path,
        map.holidays_file.as_ref(),
        map.day_types_file.as_ref(),
    )?;
    Ok(Calendar {
        observed,
        ..Calendar::new(map.year, holidays.unwrap_or_else(|| map.holidays.clone()))
    })
}

/// The outputs of a generated building: heating (boiler gas or district hot water, domestic hot
/// water included), cooling (district chilled water), electricity, and the lighting and equipment
/// sub-meters.
pub fn generated_outputs(spec: &BuildingSpec) -> Vec<OutputSpec> {
    let heating = match spec.heating_source {
        HeatingSource::Boiler => "NaturalGas:Facility",
        HeatingSource::District => "DistrictHeatingWater:Facility",
    };
    vec![
        OutputSpec::new("heating_kwh", &[heating]),
        OutputSpec::new("cooling_kwh", &["DistrictCooling:Facility"]),
        OutputSpec::new("electricity_kwh", &["Electricity:Facility"]),
        OutputSpec::new("lighting_kwh", &["InteriorLights:Electricity"]),
        OutputSpec::new("equipment_kwh", &["InteriorEquipment:Electricity"]),
    ]
}

// Only for the schema; `Model::from_toml` reads the files.
/// A bemcal model file: a generated building's spec, or your own IDF with the map of its
/// parameters (`[idf]`).
#[derive(schemars::JsonSchema)]
#[serde(untagged)]
#[allow(dead_code)]
enum ModelFile {
    /// A generated building.
    Generated(crate::building::BuildingSpec),
    /// Your own IDF and the map of its parameters.
    Mapped(ParameterMap),
}

/// The JSON Schema of a model file (editors complete and check TOML files against it, for
/// example through taplo's `#:schema` directive).
pub fn model_file_schema() -> schemars::Schema {
    let mut s = schemars::schema_for!(ModelFile);
    s.insert("title".into(), "bemcal model file".into());
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An own IDF of two `Lights` and a map scaling the office's, in a fresh folder.
    fn mapped() -> (Model, Idd) {
        let idd = Idd::parse(
            "Lights,\n  A1 , \\field Name\n  N1 ; \\field Watts per Floor Area\n\
             RunPeriod,\n  A1 , \\field Name\n  N1 ; \\field Begin Month\n",
        );
        let dir = std::env::temp_dir().join(format!("bemcal-model-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(
            dir.join("b.idf"),
            "Lights, Office Lights, 10;\nLights, Core Lights, 8;\n",
        )
        .unwrap();
        let text = r#"
[idf]
path = "b.idf"
[[parameter]]
name = "lighting_scale"
prior = { min = 0.5, mode = 1.0, max = 1.5 }
targets = [{ class = "Lights", object = "Office*", field = "Watts per Floor Area", edit = "scale" }]
[[output]]
name = "electricity_kwh"
meters = ["Electricity:Facility"]
"#;
        let model = Model::from_toml(text, &dir.join("model.toml"), &idd).unwrap();
        (model, idd)
    }

    fn lights(idf: &Idf) -> Vec<String> {
        idf.of_class("Lights")
            .map(|o| o.fields[1].clone())
            .collect()
    }

    fn edit(object: &str, field: &str, edit: Edit, value: f64) -> IdfEdit {
        IdfEdit {
            class: "Lights".into(),
            object: object.into(),
            field: field.into(),
            edit,
            value,
        }
    }

    const FIELD: &str = "Watts per Floor Area";

    #[test]
    fn idf_edits_apply_to_the_fields_no_parameter_sets() {
        let (model, idd) = mapped();
        let led = model
            .with_idf_edits(&[edit("Core*", FIELD, Edit::Scale, 0.6)], &idd)
            .unwrap();
        let draw = ParameterValues::from([("lighting_scale".to_string(), 1.2)]);
        assert_eq!(
            lights(&model.instantiate(&draw, &idd).unwrap()),
            ["12.0", "8"]
        );
        // The office's lights as the draw sets them; the core's x 0.6.
        assert_eq!(
            lights(&led.instantiate(&draw, &idd).unwrap()),
            ["12.0", "4.8"]
        );
        assert_eq!(led.parameters(), model.parameters());
        let set = model
            .with_idf_edits(&[edit("Core Lights", FIELD, Edit::Set, 5.0)], &idd)
            .unwrap();
        assert_eq!(
            lights(&set.instantiate(&draw, &idd).unwrap()),
            ["12.0", "5.0"]
        );
        assert_eq!(
            edit("*", FIELD, Edit::Scale, 0.6).describe(),
            "Lights Watts per Floor Area x 0.6"
        );
    }

    #[test]
    fn idf_edits_that_name_nothing_or_change_nothing_are_refused() {
        let (model, idd) = mapped();
        let errs = |e: &[IdfEdit]| model.with_idf_edits(e, &idd).unwrap_err();
        let err = |e: IdfEdit| errs(&[e]);
        assert!(err(edit("*", "Watts", Edit::Set, 5.0)).contains("has no field 'Watts'"));
        assert!(err(edit("Lobby*", FIELD, Edit::Set, 5.0))
            .contains("the IDF each draw simulates has no object Lobby* of class Lights"));
        // The core's lights hold 8 W/m2 (written "8"): a set to 8.0 changes nothing.
        assert!(err(edit("Core Lights", FIELD, Edit::Set, 8.0)).contains("changes nothing"));
        assert!(err(edit("*", "*", Edit::Set, 1.0)).contains("needs edit = \"scale\""));
        assert!(err(edit("Core*", FIELD, Edit::Scale, -1.0)).contains("a factor 0 or more"));
        // The map's parameter scales the office's lights: an edit of that field is the
        // parameter's to make.
        let e = err(edit("*", FIELD, Edit::Set, 5.0));
        assert!(
            e.contains("parameter lighting_scale sets in every draw"),
            "{e}"
        );
        // Two edits of one field, and the simulation's settings, are refused.
        let core = |v| edit("Core*", FIELD, Edit::Scale, v);
        assert!(errs(&[core(0.5), core(0.6)]).contains("give each field one edit"));
        let mut period = edit("*", "Begin Month", Edit::Set, 2.0);
        period.class = "RunPeriod".into();
        assert!(err(period).contains("the simulation's settings"));
    }
}

//! What gets calibrated: a generated building or a user's IDF with a parameter map.
//!
//! A model file is TOML. Without an `[idf]` table it is a [`BuildingSpec`]. With one, it names a
//! user's IDF and maps each calibration parameter to fields of objects in it:
//!
//! ```toml
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

use serde::{Deserialize, Serialize};

use crate::building::{BuildingSpec, HeatingSource};
use crate::idd::Idd;
use crate::idf::{num, Idf};
use crate::meters::OutputSpec;
use crate::params::{complete_values, Constraint, ParameterDef, ParameterValues, TriangularPrior};
use crate::{io_err, Error};

/// One field a parameter sets: in every object of `class` named `object` (or all with `*`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FieldTarget {
    pub class: String,
    pub object: String,
    pub field: String,
}

/// A parameter of a user IDF and the fields it sets.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MappedParameter {
    pub name: String,
    #[serde(default)]
    pub unit: String,
    #[serde(default)]
    pub description: String,
    pub prior: TriangularPrior,
    pub targets: Vec<FieldTarget>,
}

/// The `[idf]` form of a model file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ParameterMap {
    pub idf: IdfRef,
    #[serde(rename = "parameter", default)]
    pub parameters: Vec<MappedParameter>,
    #[serde(rename = "output", default)]
    pub outputs: Vec<OutputSpec>,
    #[serde(rename = "constraint", default)]
    pub constraints: Vec<Constraint>,
}

/// Where the user's IDF is.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct IdfRef {
    pub path: PathBuf,
}

#[derive(Debug, Clone)]
enum Source {
    Generated(BuildingSpec),
    Mapped { idf: Idf, map: ParameterMap },
}

/// A calibratable model.
#[derive(Debug, Clone)]
pub struct Model {
    source: Source,
    parameters: Vec<ParameterDef>,
    constraints: Vec<Constraint>,
    outputs: Vec<OutputSpec>,
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
            path: PathBuf::from("<generated>"),
        }
    }

    /// Loads a model file (building spec or IDF + parameter map). `idd` is needed to check the
    /// field names of a parameter map.
    pub fn load(path: &Path, idd: &Idd) -> Result<Model, Error> {
        let text = std::fs::read_to_string(path).map_err(io_err(path))?;
        Model::from_toml(&text, path, idd)
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
        let idf_path = path.parent().unwrap_or(Path::new(".")).join(&map.idf.path);
        let idf_text = std::fs::read_to_string(&idf_path).map_err(io_err(&idf_path))?;
        let idf = Idf::parse(&idf_text, &idf_path)?;
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
            TriangularPrior::new(p.prior.min, p.prior.mode, p.prior.max)
                .map_err(|m| err(format!("parameter {}: {m}", p.name)))?;
            if p.targets.is_empty() {
                return Err(err(format!("parameter {}: no targets", p.name)));
            }
            for t in &p.targets {
                if idd.field_index(&t.class, &t.field).is_none() {
                    let known = idd.fields(&t.class).map(|f| f.join(", "));
                    return Err(err(format!(
                        "parameter {}: class '{}' has no field '{}'{}",
                        p.name,
                        t.class,
                        t.field,
                        known
                            .map(|k| format!(" (fields: {k})"))
                            .unwrap_or_else(|| " (unknown class)".into())
                    )));
                }
                let n = idf
                    .of_class(&t.class)
                    .filter(|o| {
                        t.object == "*"
                            || o.name().is_some_and(|n| n.eq_ignore_ascii_case(&t.object))
                    })
                    .count();
                if n == 0 {
                    return Err(err(format!(
                        "parameter {}: {} has no object {} of class {}",
                        p.name,
                        idf_path.display(),
                        t.object,
                        t.class
                    )));
                }
            }
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
            source: Source::Mapped { idf, map },
            path: path.into(),
        })
    }

    /// The calibration parameters, in the model's order.
    pub fn parameters(&self) -> &[ParameterDef] {
        &self.parameters
    }

    /// Replaces the prior of a parameter (e.g. from pre-calibration).
    pub fn set_prior(&mut self, name: &str, prior: TriangularPrior) -> Result<(), Error> {
        let p = self
            .parameters
            .iter_mut()
            .find(|p| p.name == name)
            .ok_or_else(|| Error::Parameter {
                name: name.into(),
                message: "unknown parameter".into(),
            })?;
        p.prior = prior;
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

    /// The building spec, for a generated model.
    pub fn spec(&self) -> Option<&BuildingSpec> {
        match &self.source {
            Source::Generated(s) => Some(s),
            Source::Mapped { .. } => None,
        }
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

    /// The IDF for a set of parameter values (see [`Model::values`]).
    pub fn instantiate(&self, given: &ParameterValues, idd: &Idd) -> Result<Idf, Error> {
        let v = self.values(given)?;
        match &self.source {
            Source::Generated(spec) => spec.to_idf(&v),
            Source::Mapped { idf, map } => {
                let mut out = idf.clone();
                for p in &map.parameters {
                    let value = num(v[&p.name]);
                    for t in &p.targets {
                        let i = idd
                            .field_index(&t.class, &t.field)
                            .expect("checked at load");
                        for o in out.objects.iter_mut().filter(|o| {
                            o.class.eq_ignore_ascii_case(&t.class)
                                && (t.object == "*"
                                    || o.name().is_some_and(|n| n.eq_ignore_ascii_case(&t.object)))
                        }) {
                            if o.fields.len() <= i {
                                o.fields.resize(i + 1, String::new());
                            }
                            o.fields[i] = value.clone();
                        }
                    }
                }
                Ok(out)
            }
        }
    }
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

//! What a meters file is and how to read it: the roles, units and conventions of its columns
//! ([`MeterColumn`]) and the file's settings ([`MeterSpec`], the project's `[meters]` table).

use std::fmt;
use std::path::PathBuf;
use std::str::FromStr;

use serde::{Deserialize, Serialize};

use super::DEFAULT_TIMESTAMP_FORMAT;

/// What a meter measures.
#[derive(Debug, Clone, PartialEq, Eq, Hash, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(from = "String", into = "String")]
pub enum MeterRole {
    /// Total heating (space heating + domestic hot water).
    Heating,
    /// Total cooling.
    Cooling,
    /// Total (whole-building) electricity.
    Electricity,
    /// A named sub-meter, e.g. `lighting`, `plug_loads`, `data_center`, `mechanical`.
    Submeter(String),
}

impl MeterRole {
    /// The role's name as written in files (`heating`, `cooling`, `electricity`, or the
    /// sub-meter's name).
    pub fn name(&self) -> &str {
        match self {
            MeterRole::Heating => "heating",
            MeterRole::Cooling => "cooling",
            MeterRole::Electricity => "electricity",
            MeterRole::Submeter(s) => s,
        }
    }
}

impl From<String> for MeterRole {
    fn from(s: String) -> MeterRole {
        match s.trim().to_ascii_lowercase().as_str() {
            "heating" => MeterRole::Heating,
            "cooling" => MeterRole::Cooling,
            "electricity" => MeterRole::Electricity,
            other => MeterRole::Submeter(other.replace([' ', '-'], "_")),
        }
    }
}

impl From<MeterRole> for String {
    fn from(r: MeterRole) -> String {
        r.name().to_string()
    }
}

impl fmt::Display for MeterRole {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// Unit of a meter column. Power units are means over the hour.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(try_from = "String", into = "String")]
pub enum EnergyUnit {
    /// Watt (hourly mean).
    W,
    /// Kilowatt (hourly mean): numerically kWh per hour.
    #[default]
    KW,
    /// Megawatt (hourly mean).
    MW,
    /// Watt-hour.
    Wh,
    /// Kilowatt-hour.
    KWh,
    /// Megawatt-hour.
    MWh,
    /// US therm (105.5 MJ = 29.3071 kWh).
    Therm,
    /// Thousand Btu (0.293071 kWh).
    KBtu,
    /// Million Btu (293.071 kWh).
    MMBtu,
    /// Megajoule (0.277778 kWh).
    MJ,
    /// Gigajoule (277.778 kWh).
    GJ,
    /// Ton of refrigeration (hourly mean; 3.51685 kW).
    Ton,
    /// Ton-hour of refrigeration (3.51685 kWh).
    TonHour,
}

impl EnergyUnit {
    /// True for power units (a reading is a mean rate), false for energy units (a reading is
    /// the energy of its interval).
    pub fn is_power(self) -> bool {
        matches!(
            self,
            EnergyUnit::W | EnergyUnit::KW | EnergyUnit::MW | EnergyUnit::Ton
        )
    }

    /// Factor converting one hour's value in this unit to kWh.
    pub fn to_kwh(self) -> f64 {
        match self {
            EnergyUnit::W | EnergyUnit::Wh => 1e-3,
            EnergyUnit::KW | EnergyUnit::KWh => 1.0,
            EnergyUnit::MW | EnergyUnit::MWh => 1e3,
            EnergyUnit::Therm => 29.307_107,
            EnergyUnit::KBtu => 0.293_071_07,
            EnergyUnit::MMBtu => 293.071_07,
            EnergyUnit::MJ => 1.0 / 3.6,
            EnergyUnit::GJ => 1000.0 / 3.6,
            EnergyUnit::Ton | EnergyUnit::TonHour => 3.516_853,
        }
    }

    /// The unit's canonical spelling.
    pub fn as_str(self) -> &'static str {
        match self {
            EnergyUnit::W => "W",
            EnergyUnit::KW => "kW",
            EnergyUnit::MW => "MW",
            EnergyUnit::Wh => "Wh",
            EnergyUnit::KWh => "kWh",
            EnergyUnit::MWh => "MWh",
            EnergyUnit::Therm => "therm",
            EnergyUnit::KBtu => "kBtu",
            EnergyUnit::MMBtu => "MMBtu",
            EnergyUnit::MJ => "MJ",
            EnergyUnit::GJ => "GJ",
            EnergyUnit::Ton => "ton",
            EnergyUnit::TonHour => "ton_h",
        }
    }
}

impl FromStr for EnergyUnit {
    type Err = String;
    fn from_str(s: &str) -> Result<EnergyUnit, String> {
        let k = s.trim().to_ascii_lowercase().replace([' ', '-', '_'], "");
        Ok(match k.as_str() {
            "w" => EnergyUnit::W,
            "kw" => EnergyUnit::KW,
            "mw" => EnergyUnit::MW,
            "wh" => EnergyUnit::Wh,
            "kwh" => EnergyUnit::KWh,
            "mwh" => EnergyUnit::MWh,
            "therm" | "therms" | "thm" => EnergyUnit::Therm,
            "kbtu" => EnergyUnit::KBtu,
            "mmbtu" => EnergyUnit::MMBtu,
            "mj" => EnergyUnit::MJ,
            "gj" => EnergyUnit::GJ,
            "ton" | "tons" | "tr" => EnergyUnit::Ton,
            "tonh" | "tonhour" | "tonhours" | "trh" => EnergyUnit::TonHour,
            _ => {
                return Err(format!(
                    "unknown unit '{s}' (known: W, kW, MW, Wh, kWh, MWh, therm, kBtu, MMBtu, MJ, GJ, ton, ton_h)"
                ))
            }
        })
    }
}

impl TryFrom<String> for EnergyUnit {
    type Error = String;
    fn try_from(s: String) -> Result<EnergyUnit, String> {
        s.parse()
    }
}

impl From<EnergyUnit> for String {
    fn from(u: EnergyUnit) -> String {
        u.as_str().to_string()
    }
}

impl schemars::JsonSchema for EnergyUnit {
    fn schema_name() -> std::borrow::Cow<'static, str> {
        "EnergyUnit".into()
    }

    fn json_schema(_: &mut schemars::SchemaGenerator) -> schemars::Schema {
        schemars::json_schema!({
            "description": "Unit of the values (power units are means over the hour): W, kW, MW, Wh, kWh, MWh, therm, kBtu, MMBtu, MJ, GJ, ton, ton_h; read in any case, spaces, '-' and '_' ignored (also therms, thm, tons, tr, ton-hour, trh).",
            "type": "string",
            "examples": ["kW", "kWh", "W", "Wh", "MW", "MWh", "therm", "kBtu", "MMBtu", "MJ", "GJ", "ton", "ton_h"]
        })
    }
}

/// Whether a timestamp marks the start or the end of its hour.
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, schemars::JsonSchema,
)]
#[serde(rename_all = "snake_case")]
pub enum HourConvention {
    /// Detect (see the module docs).
    #[default]
    Auto,
    /// `05:00` = the hour 05:00-06:00.
    HourBeginning,
    /// `05:00` = the hour 04:00-05:00.
    HourEnding,
}

/// How the file's clock relates to local standard time.
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, schemars::JsonSchema,
)]
#[serde(rename_all = "snake_case")]
pub enum DstHandling {
    /// Detect from the spring skip / autumn repeat (see the module docs).
    #[default]
    Auto,
    /// Local standard time all year.
    None,
    /// Local clock time following US daylight saving rules (2007 onwards).
    Us,
}

/// What to do when two rows fall into the same hour slot (other than a DST repeat).
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, schemars::JsonSchema,
)]
#[serde(rename_all = "snake_case")]
pub enum DuplicatePolicy {
    /// Reject the file, naming both lines.
    #[default]
    Error,
    /// Keep the first row.
    First,
    /// Keep the last row.
    Last,
    /// Average the rows (e.g. repeated readings of an hourly mean).
    Mean,
    /// Sum the rows (e.g. sub-hourly energy readings).
    Sum,
}

/// What to do with a negative reading.
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, schemars::JsonSchema,
)]
#[serde(rename_all = "snake_case")]
pub enum NegativePolicy {
    /// Reject the file, naming line and column.
    #[default]
    Error,
    /// Treat as missing (NaN).
    Missing,
    /// Set to zero.
    Zero,
    /// Keep (e.g. a net meter).
    Keep,
}

/// One meter column of the CSV.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct MeterColumn {
    /// Column header in the CSV (matched after trimming, case-sensitive first, then
    /// case-insensitive).
    pub column: String,
    /// What the column measures.
    pub role: MeterRole,
    /// Unit of the values (default kW, hourly mean).
    #[serde(default)]
    pub unit: EnergyUnit,
    /// Periods whose readings this meter got wrong (an outage that reads zero, a test, a
    /// logger fault): their hours become missing for this meter alone, with a note, so that
    /// neither pre-calibration nor the calibration fits them. Written like `[validation]
    /// holdout`: `"2011-03-04..2011-03-31"`, `"mar"`, or a list.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub exclude: Option<bemcal_weather::period::Holdout>,
    /// Whether the calibration fits this meter (default true). `fit = false`: the meter is
    /// read, compared with the model in validation and model form, and reported, but the
    /// likelihood leaves it out: for a meter the model cannot reach (a system it does not
    /// have) that would otherwise pull every parameter to its bounds. Pre-calibration reads
    /// it as any other.
    #[serde(default = "fitted", skip_serializing_if = "is_fitted")]
    pub fit: bool,
}

fn fitted() -> bool {
    true
}

fn is_fitted(fit: &bool) -> bool {
    *fit
}

/// How to read a meters CSV. Sits in the project file as `[meters]`:
///
/// ```toml
/// [meters]
/// file = "rsfmeasureddata2011.csv"
/// timestamp_column = "Date and Time"
/// timestamp_format = "%m/%d/%Y %H:%M"
/// convention = "hour_ending"
/// dst = "none"
/// [[meters.columns]]
/// column = "Total Heating (kW)"
/// role = "heating"
/// unit = "kW"
/// ```
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct MeterSpec {
    /// The CSV file (relative paths are relative to the project file). Optional when given on
    /// the command line.
    #[serde(default)]
    pub file: Option<PathBuf>,
    /// Timestamp column; default: the first header containing "time" or "date".
    #[serde(default)]
    pub timestamp_column: Option<String>,
    /// chrono format string, `iso8601`, or `auto` (the default: ISO 8601, else
    /// `%m/%d/%Y %H:%M`).
    #[serde(default = "default_format")]
    pub timestamp_format: String,
    /// Hour-beginning or hour-ending stamps.
    #[serde(default)]
    pub convention: HourConvention,
    /// Daylight saving handling.
    #[serde(default)]
    pub dst: DstHandling,
    /// The IANA time zone the file's clock follows (e.g. `Europe/Berlin`,
    /// `Australia/Sydney`): its daylight saving rules (any country, either hemisphere) move
    /// readings back to local standard time, the zone's standard offset. With it, `dst` stays
    /// `auto`; stamps that carry a UTC offset are taken as they are.
    #[serde(default)]
    pub time_zone: Option<String>,
    /// Two rows in one hour slot.
    #[serde(default)]
    pub duplicates: DuplicatePolicy,
    /// Negative readings.
    #[serde(default)]
    pub negative: NegativePolicy,
    /// Hours a value must repeat to count as a flat run in the quality summary (default 24).
    #[serde(default = "default_flat")]
    pub flat_run_hours: usize,
    /// The meter columns; empty = detect from the headers ([`detect_columns`](super::detect_columns)).
    #[serde(default)]
    pub columns: Vec<MeterColumn>,
    /// Meters read as utility bills, one file each ([`super::bills`]): the calibration fits
    /// each bill's total; a role read as bills has no column.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub bills: Vec<super::bills::BillSpec>,
}

fn default_format() -> String {
    DEFAULT_TIMESTAMP_FORMAT.to_string()
}

fn default_flat() -> usize {
    24
}

impl Default for MeterSpec {
    fn default() -> MeterSpec {
        MeterSpec {
            file: None,
            timestamp_column: None,
            timestamp_format: default_format(),
            convention: HourConvention::Auto,
            dst: DstHandling::Auto,
            time_zone: None,
            duplicates: DuplicatePolicy::Error,
            negative: NegativePolicy::Error,
            flat_run_hours: default_flat(),
            columns: Vec::new(),
            bills: Vec::new(),
        }
    }
}

//! NaN in JSON records (`summary.json` and what it holds): JSON has no NaN and serde_json
//! writes it as `null` (a statistic that could not be computed: the R-hat of a constant chain,
//! the CV-RMSE of a meter that reads zero), so every number field of those records reads
//! `null` back as NaN and a record round-trips:
//!
//! ```ignore
//! #[serde(deserialize_with = "bemcal_stats::nan::null_as_nan")]
//! #[schemars(with = "bemcal_stats::nan::NumberOrNull")]
//! pub rhat: f64,
//! ```
//!
//! (`schemars(with)` makes the field's JSON Schema say `number` or `null`, still required.)

use std::borrow::Cow;

use serde::{Deserialize, Deserializer};

/// Reads a number, or `null` as NaN.
pub fn null_as_nan<'de, D: Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
    Ok(Option::<f64>::deserialize(d)?.unwrap_or(f64::NAN))
}

/// The JSON Schema of an `f64` field read by [`null_as_nan`]: a number, or `null` for NaN.
/// Unlike `Option<f64>`'s it leaves the field required.
pub struct NumberOrNull;

impl schemars::JsonSchema for NumberOrNull {
    fn inline_schema() -> bool {
        true
    }

    fn schema_name() -> Cow<'static, str> {
        "NumberOrNull".into()
    }

    fn json_schema(_: &mut schemars::SchemaGenerator) -> schemars::Schema {
        schemars::json_schema!({"type": ["number", "null"], "format": "double"})
    }
}

/// Reads a pair of numbers (an interval's ends), each `null` as NaN.
pub fn null_as_nan_pair<'de, D: Deserializer<'de>>(d: D) -> Result<[f64; 2], D::Error> {
    let [a, b] = <[Option<f64>; 2]>::deserialize(d)?;
    Ok([a.unwrap_or(f64::NAN), b.unwrap_or(f64::NAN)])
}

/// The JSON Schema of a `[f64; 2]` field read by [`null_as_nan_pair`].
pub struct PairOfNumberOrNull;

impl schemars::JsonSchema for PairOfNumberOrNull {
    fn inline_schema() -> bool {
        true
    }

    fn schema_name() -> Cow<'static, str> {
        "PairOfNumberOrNull".into()
    }

    fn json_schema(_: &mut schemars::SchemaGenerator) -> schemars::Schema {
        schemars::json_schema!({
            "type": "array",
            "items": {"type": ["number", "null"], "format": "double"},
            "minItems": 2,
            "maxItems": 2
        })
    }
}

#[cfg(test)]
mod tests {
    #[derive(serde::Serialize, serde::Deserialize)]
    struct R {
        #[serde(deserialize_with = "super::null_as_nan")]
        x: f64,
    }

    #[test]
    fn nan_is_written_as_null_and_read_back() {
        let text = serde_json::to_string(&R { x: f64::NAN }).unwrap();
        assert_eq!(text, r#"{"x":null}"#);
        assert!(serde_json::from_str::<R>(&text).unwrap().x.is_nan());
        assert_eq!(serde_json::from_str::<R>(r#"{"x":2.5}"#).unwrap().x, 2.5);
        let e = serde_json::from_str::<R>("{}").err().unwrap().to_string();
        assert!(e.contains("missing field `x`"), "{e}");
    }

    #[derive(serde::Serialize, serde::Deserialize)]
    struct P {
        #[serde(deserialize_with = "super::null_as_nan_pair")]
        x: [f64; 2],
    }

    #[test]
    fn an_interval_with_a_nan_end_round_trips() {
        let text = serde_json::to_string(&P { x: [1.0, f64::NAN] }).unwrap();
        assert_eq!(text, r#"{"x":[1.0,null]}"#);
        let back = serde_json::from_str::<P>(&text).unwrap().x;
        assert_eq!(back[0], 1.0);
        assert!(back[1].is_nan());
    }
}

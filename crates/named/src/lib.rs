//! Named values in `summary.json`: a list of `(name, value)` in the calibration's order is
//! written as a JSON object keyed by name (`{"heating_kwh": 0.31, ...}`, in that order), the
//! form pandas, `jq` and a dict read as they are; it reads back from that object or from the
//! `[[name, value], ...]` pairs that summaries before issue 22 wrote. Used with
//! `#[serde(with = "bemcal_named")]` (the writer, `bemcal-calibrate`) and by every reader
//! (the report, the portfolio, `simulate --values`).
#![deny(missing_docs)]

use std::fmt;
use std::marker::PhantomData;

use serde::de::{Deserialize, Deserializer, MapAccess, SeqAccess, Visitor};
use serde::ser::{Serialize, Serializer};

/// Writes `[(name, value)]` as an object keyed by name, in order.
pub fn serialize<S: Serializer, T: Serialize>(
    values: &[(String, T)],
    s: S,
) -> Result<S::Ok, S::Error> {
    s.collect_map(values.iter().map(|(k, v)| (k, v)))
}

/// Reads an object keyed by name, or a list of `[name, value]` pairs, in document order.
pub fn deserialize<'de, D: Deserializer<'de>, T: Deserialize<'de>>(
    d: D,
) -> Result<Vec<(String, T)>, D::Error> {
    d.deserialize_any(Named(PhantomData))
}

struct Named<T>(PhantomData<T>);

impl<'de, T: Deserialize<'de>> Visitor<'de> for Named<T> {
    type Value = Vec<(String, T)>;

    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        f.write_str("an object keyed by name, or a list of [name, value] pairs")
    }

    fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<Self::Value, A::Error> {
        let mut out = Vec::with_capacity(map.size_hint().unwrap_or(0));
        while let Some(entry) = map.next_entry()? {
            out.push(entry);
        }
        Ok(out)
    }

    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Self::Value, A::Error> {
        let mut out = Vec::with_capacity(seq.size_hint().unwrap_or(0));
        while let Some(pair) = seq.next_element()? {
            out.push(pair);
        }
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    #[derive(serde::Serialize, serde::Deserialize, PartialEq, Debug)]
    struct S {
        #[serde(with = "crate")]
        v: Vec<(String, f64)>,
    }

    #[test]
    fn written_as_an_object_in_order_and_read_from_either_form() {
        let s = S {
            v: vec![("b".into(), 1.5), ("a".into(), -2.0)],
        };
        let text = serde_json::to_string(&s).unwrap();
        assert_eq!(text, r#"{"v":{"b":1.5,"a":-2.0}}"#);
        assert_eq!(serde_json::from_str::<S>(&text).unwrap(), s);
        let old: S = serde_json::from_str(r#"{"v":[["b",1.5],["a",-2.0]]}"#).unwrap();
        assert_eq!(old, s);
        assert!(serde_json::from_str::<S>(r#"{"v":3}"#).is_err());
    }
}

//! Deserialisers that refuse what serde's defaults accept silently in a results file: a sample
//! token given twice in one JSON object (serde keeps the last) and a `confidence_level` that is
//! `null` (an `Option` reads it as absent, which ground truth means, and scores it 1.0).

use std::fmt;
use std::marker::PhantomData;

use indexmap::IndexMap;
use serde::de::{Deserialize, Deserializer, Error, MapAccess, Visitor};

/// A JSON object into a map in the file's key order, refusing a key given twice.
///
/// # Errors
/// The repeated key named, or the values' own errors.
pub fn unique_keys<'de, D, V>(d: D) -> Result<IndexMap<String, V>, D::Error>
where
    D: Deserializer<'de>,
    V: Deserialize<'de>,
{
    struct Unique<V>(PhantomData<V>);
    impl<'de, V: Deserialize<'de>> Visitor<'de> for Unique<V> {
        type Value = IndexMap<String, V>;
        fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
            f.write_str("an object keyed by sample token")
        }
        fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<Self::Value, A::Error> {
            let mut out = IndexMap::new();
            while let Some((key, value)) = map.next_entry::<String, V>()? {
                if out.contains_key(&key) {
                    return Err(A::Error::custom(format!(
                        "sample_token {key:?} appears more than once"
                    )));
                }
                out.insert(key, value);
            }
            Ok(out)
        }
    }
    d.deserialize_map(Unique(PhantomData))
}

/// A number that may be absent (`#[serde(default)]` gives `None`) but not `null`.
///
/// # Errors
/// `null`, or anything but a number.
pub fn number_if_present<'de, D: Deserializer<'de>>(d: D) -> Result<Option<f64>, D::Error> {
    match Option::<f64>::deserialize(d)? {
        Some(v) => Ok(Some(v)),
        None => Err(D::Error::custom(
            "confidence_level is null: a score is a number (absent only in ground truth)",
        )),
    }
}

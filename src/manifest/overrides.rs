//! `--set KEY=VALUE` overrides, applied to the JSON form of a manifest.
//!
//! The manifest (defaults filled in) is serialized to a `serde_json::Value`, so every valid
//! key is present and an unknown key is found at once. VALUE is read as a YAML scalar
//! (number, bool, string, null). Setting the tag of a tagged section (`fluid.model`,
//! `scene.kind`) to a different variant replaces the whole section by that variant's
//! defaults (or by the bare tag when the variant has required fields, which later
//! overrides then fill in).

use std::collections::BTreeSet;

use serde_json::{Map, Value};

use super::error::{ManifestError, Result};
use super::types::{Fluid, SceneSection};

/// Sections that are internally tagged enums: (path, tag key).
pub const TAGGED_SECTIONS: &[(&str, &str)] = &[("fluid", "model"), ("scene", "kind")];

/// What the overrides touched, for provenance of later validation errors.
#[derive(Debug, Default, Clone)]
pub struct Touched {
    /// Dotted paths set by an override.
    pub set: BTreeSet<String>,
    /// Sections replaced because their tag changed: nothing below them comes from the file.
    pub reset: BTreeSet<String>,
    /// Sections reset to a bare tag: any key may be added below them.
    open: BTreeSet<String>,
}

impl Touched {
    /// The value at `path` came from an override.
    pub fn is_set(&self, path: &str) -> bool {
        self.set.contains(path)
    }
    /// The value at `path` lies below a section whose variant an override replaced.
    pub fn is_reset(&self, path: &str) -> bool {
        self.reset.iter().any(|r| is_below(path, r))
    }
}

fn err(key: &str, message: impl Into<String>) -> ManifestError {
    ManifestError::Override {
        key: key.to_string(),
        message: message.into(),
    }
}

/// Split `KEY=VALUE`.
pub fn split(raw: &str) -> Result<(&str, &str)> {
    let Some((key, value)) = raw.split_once('=') else {
        return Err(err(
            raw,
            "malformed override: expected KEY=VALUE, e.g. --set time.end_s=0.5",
        ));
    };
    if key.is_empty() {
        return Err(err(raw, "malformed override: empty KEY in KEY=VALUE"));
    }
    if key.split('.').any(str::is_empty) {
        return Err(err(
            key,
            "malformed key: expected dotted field names such as time.end_s",
        ));
    }
    Ok((key, value))
}

/// Read VALUE as a YAML scalar.
fn parse_scalar(key: &str, raw: &str) -> Result<Value> {
    if raw.trim().is_empty() {
        return Err(err(
            key,
            "empty value (write null, or quote an empty string as '')",
        ));
    }
    let value: Value = serde_saphyr::from_str(raw).map_err(|e| {
        let msg = super::saphyr_message(&e);
        err(key, format!("cannot read value {raw:?}: {msg}"))
    })?;
    match value {
        Value::Array(_) | Value::Object(_) => Err(err(
            key,
            format!("value {raw:?} is not a scalar (expected a number, bool, string or null)"),
        )),
        Value::Number(n) if n.as_f64().is_some_and(|x| !x.is_finite()) => {
            Err(err(key, format!("value {raw:?} is not a finite number")))
        }
        v => Ok(v),
    }
}

fn keys_of(map: &Map<String, Value>) -> String {
    map.keys().cloned().collect::<Vec<_>>().join(", ")
}

/// Apply one `KEY=VALUE` override to `root`.
pub fn apply<S: SceneSection>(root: &mut Value, raw: &str, touched: &mut Touched) -> Result<()> {
    let (key, raw_value) = split(raw)?;
    let mut new = parse_scalar(key, raw_value)?;
    let segs: Vec<&str> = key.split('.').collect();

    let mut node = &mut *root;
    let mut here = String::new(); // dotted path of `node`
    let mut reset = None;
    for (i, seg) in segs.iter().enumerate() {
        let last = i + 1 == segs.len();
        let at = if here.is_empty() {
            "the top level".to_string()
        } else {
            format!("`{here}`")
        };
        if node.is_array() {
            // A list item, by its index (`boundaries.inlets.0.volume_m3`).
            let Value::Array(items) = node else {
                unreachable!("checked above")
            };
            let n = items.len();
            let Some(index) = seg.parse::<usize>().ok().filter(|&k| k < n) else {
                let allowed = match n {
                    0 => "it is empty, so no item can be set (add the item in the manifest)"
                        .to_string(),
                    1 => format!("`{seg}` is not an index; the only one is 0"),
                    _ => format!("`{seg}` is not an index 0 to {}", n - 1),
                };
                let size = if n == 1 {
                    "1 item".to_string()
                } else {
                    format!("{n} items")
                };
                return Err(err(key, format!("`{here}` is a list of {size}: {allowed}")));
            };
            let child_path = format!("{here}.{seg}");
            if last {
                if items[index].is_object() || items[index].is_array() {
                    return Err(err(
                        key,
                        format!(
                            "`{child_path}` is a section, not a value; set one of its keys instead"
                        ),
                    ));
                }
                items[index] = new;
                touched.set.insert(child_path);
                return Ok(());
            }
            node = &mut items[index];
            here = child_path;
            continue;
        }
        let Value::Object(map) = node else {
            return Err(err(
                key,
                format!("`{here}` is a value, not a section: it has no key `{seg}`"),
            ));
        };
        if !map.contains_key(*seg) {
            if last && touched.open.contains(&here) {
                map.insert((*seg).to_string(), Value::Null);
            } else {
                return Err(err(
                    key,
                    format!("unknown key `{seg}` in {at}; valid keys: {}", keys_of(map)),
                ));
            }
        }
        let child_path = if here.is_empty() {
            (*seg).to_string()
        } else {
            format!("{here}.{seg}")
        };
        if last {
            let slot = map.get_mut(*seg).expect("checked above");
            if let Value::Object(section) = slot {
                return Err(err(
                    key,
                    format!(
                        "`{child_path}` is a section, not a value; set one of its keys instead: {}",
                        keys_of(section)
                    ),
                ));
            }
            // A plain scalar such as 2024 or true written for a string field means the text.
            if slot.is_string() && (new.is_number() || new.is_boolean()) {
                new = Value::String(raw_value.trim().to_string());
            }
            let tag_of = TAGGED_SECTIONS
                .iter()
                .find(|(section, tag)| *section == here && tag == seg);
            if tag_of.is_some() && *slot != new {
                let Value::String(variant) = &new else {
                    return Err(err(key, format!("expected a variant name, got {new}")));
                };
                let defaults = variant_defaults::<S>(&here, seg, variant);
                if defaults.as_object().is_some_and(|m| m.len() == 1) {
                    touched.open.insert(here.clone());
                }
                touched.reset.insert(here.clone());
                touched.set.retain(|p| !is_below(p, &here));
                touched.set.insert(child_path);
                reset = Some((here, defaults));
                break;
            }
            *slot = new;
            touched.set.insert(child_path);
            return Ok(());
        }
        node = map.get_mut(*seg).expect("checked above");
        here = child_path;
    }
    let (section, defaults) = reset.expect("the loop returns unless a section is reset");
    let pointer = format!("/{}", section.replace('.', "/"));
    *root.pointer_mut(&pointer).expect("the section exists") = defaults;
    Ok(())
}

/// `path` lies strictly below `section`.
fn is_below(path: &str, section: &str) -> bool {
    path.len() > section.len()
        && path.starts_with(section)
        && path[section.len()..].starts_with('.')
}

/// The serialized defaults of variant `variant` of the tagged section at `section`, or just
/// `{tag: variant}` when the variant has required fields (or is unknown: the error comes when
/// the manifest is rebuilt, naming the valid variants).
fn variant_defaults<S: SceneSection>(section: &str, tag: &str, variant: &str) -> Value {
    let mut bare = Map::new();
    bare.insert(tag.to_string(), Value::String(variant.to_string()));
    let bare = Value::Object(bare);
    let full = match section {
        "fluid" => serde_json::from_value::<Fluid>(bare.clone())
            .ok()
            .and_then(|f| serde_json::to_value(f).ok()),
        "scene" => serde_json::from_value::<S>(bare.clone())
            .ok()
            .and_then(|s| serde_json::to_value(s).ok()),
        _ => None,
    };
    full.unwrap_or(bare)
}

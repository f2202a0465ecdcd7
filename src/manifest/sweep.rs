//! Parameter sweeps: a top-level `sweep:` section mapping dotted keys to lists of scalars.
//!
//! ```yaml
//! sweep:
//!   fluid.yield_stress_pa: [50, 100, 150, 200, 250]
//!   fluid.stress_gradient_term: [true, false]
//! ```
//!
//! Semantics:
//! - The points are the Cartesian product of the lists, keys in the order written, the
//!   **last key varying fastest** (like nested loops written top to bottom), values in the
//!   order written. The order is part of the sweep hash.
//! - Only the points are resolved and validated (the manifest without the sweep need not be
//!   valid by itself, e.g. a placeholder value that every point overrides).
//! - Each point is resolved exactly as the manifest without its `sweep` section plus one
//!   `--set KEY=VALUE` per swept key (after the command-line `--set`s): the same validation,
//!   the same canonical form and experiment hash. [`super::from_str`] ignores the `sweep`
//!   section (it blanks it out, keeping every other line and column), so the recorded
//!   manifest source plus the recorded overrides of a point reproduce its hash.
//! - A key that is both swept and `--set` on the command line is pinned by the `--set`: the
//!   axis is dropped (so replaying a point's recorded overrides runs just that point).
//! - The sweep hash is the SHA-256 of the canonical JSON
//!   `{"axes":[[KEY,[VALUE,...]],...],"points":[HASH,...]}` where VALUEs are the resolved
//!   values (as in the points' canonical forms) and HASHes the points' experiment hashes.
//!   It names the sweep's output folder.

use std::path::Path;

use serde::Deserialize;
use serde::de::{IgnoredAny, MapAccess, Visitor};
use serde_json::Value;

use super::error::{ManifestError, Result};
use super::locate::{Pos, SourceMap};
use super::{Resolved, SceneSection, canonical, from_str};

/// The top-level key of the sweep section.
pub const SWEEP_KEY: &str = "sweep";

/// Refuse sweeps larger than this many points (a typo guard).
pub const MAX_POINTS: usize = 10_000;

/// What a manifest file describes: one run, or a sweep of runs.
#[derive(Debug, Clone, PartialEq)]
pub enum Plan<S> {
    Single(Box<Resolved<S>>),
    Sweep(Sweep<S>),
}

/// One swept key and its values.
#[derive(Debug, Clone, PartialEq)]
pub struct Axis {
    /// Dotted manifest key, e.g. `fluid.yield_stress_pa`.
    pub key: String,
    /// The values as written (YAML scalars read as JSON values).
    pub values: Vec<Value>,
}

/// One point of a sweep.
#[derive(Debug, Clone, PartialEq)]
pub struct Point<S> {
    /// `(key, value text)` per axis, in axis order; the value text is what `--set` gets.
    pub assignments: Vec<(String, String)>,
    /// The point resolved (its `overrides` are the command-line ones, then the assignments).
    pub resolved: Resolved<S>,
}

impl<S> Point<S> {
    /// `key=value key=value ...`
    pub fn label(&self) -> String {
        self.assignments
            .iter()
            .map(|(k, v)| format!("{k}={v}"))
            .collect::<Vec<_>>()
            .join(" ")
    }
}

/// An expanded sweep.
#[derive(Debug, Clone, PartialEq)]
pub struct Sweep<S> {
    /// The manifest's `name` (of the first point; `name` itself may be swept).
    pub name: String,
    /// Axes in expansion order (swept keys pinned by `--set` removed).
    pub axes: Vec<Axis>,
    /// Points in expansion order (last axis fastest).
    pub points: Vec<Point<S>>,
    /// Canonical JSON of the sweep (see the module docs).
    pub canonical: String,
    /// Lowercase hex SHA-256 of `canonical`.
    pub hash_hex: String,
}

impl<S> Sweep<S> {
    /// First 12 hex digits of the sweep hash.
    pub fn short_hash(&self) -> &str {
        super::canonical::short_hash(&self.hash_hex)
    }
    /// Folder name of the sweep's runs: `<name>-sweep-<first 12 hex of the sweep hash>`.
    pub fn folder_name(&self) -> String {
        format!("{}-sweep-{}", self.name, self.short_hash())
    }
}

/// Read the manifest at `path`: a [`Plan::Single`] when it has no `sweep` section (exactly
/// [`super::load`]), else the expanded [`Plan::Sweep`].
pub fn load_plan<S: SceneSection>(path: &Path, overrides: &[String]) -> Result<Plan<S>> {
    let text = std::fs::read_to_string(path).map_err(|source| ManifestError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    plan_from_str(&text, &path.display().to_string(), overrides)
}

/// Like [`load_plan`], from text.
pub fn plan_from_str<S: SceneSection>(
    text: &str,
    source_name: &str,
    overrides: &[String],
) -> Result<Plan<S>> {
    let map = SourceMap::build(text);
    let single = || from_str(text, source_name, overrides).map(|r| Plan::Single(Box::new(r)));
    let Some(entry) = map.entries.get(SWEEP_KEY) else {
        return single();
    };
    let sweep_pos = entry.key.0;
    let doc: Top = match serde_saphyr::from_str(text) {
        Ok(doc) => doc,
        // Syntax errors come from the plain loader, with its locations.
        Err(e) => {
            single()?;
            return Err(ManifestError::Syntax {
                source_name: source_name.to_string(),
                line: Some(sweep_pos.line),
                column: Some(sweep_pos.column),
                field: Some(SWEEP_KEY.to_string()),
                message: super::saphyr_message(&e),
            });
        }
    };
    // Not a top-level `sweep` key after all (e.g. nested in a list).
    let Some(raw) = doc.sweep else {
        return single();
    };
    let invalid = |field: &str, pos: Option<Pos>, message: String| ManifestError::Invalid {
        source_name: source_name.to_string(),
        field: field.to_string(),
        line: pos.map(|p| p.line),
        column: pos.map(|p| p.column),
        message,
    };
    let Some(Ordered(entries)) = raw.ordered else {
        let got = match raw.value {
            Value::Array(_) => "a list",
            Value::Null => "nothing",
            _ => "a scalar",
        };
        return Err(invalid(
            SWEEP_KEY,
            map.value_pos(SWEEP_KEY),
            format!("expected a mapping of dotted keys to lists of values, got {got}"),
        ));
    };
    if entries.is_empty() {
        return Err(invalid(
            SWEEP_KEY,
            map.value_pos(SWEEP_KEY),
            "empty sweep: give at least one key with a list of values".into(),
        ));
    }

    let pinned: Vec<&str> = overrides
        .iter()
        .filter_map(|o| o.split_once('=').map(|(k, _)| k))
        .collect();
    let mut axes = Vec::new();
    for (key, value) in entries {
        let field = format!("{SWEEP_KEY}.{key}");
        let key_pos = map.entries.get(&field).map(|e| e.key.0);
        let value_pos = map.value_pos(&field);
        if key.is_empty() || key.split('.').any(str::is_empty) {
            return Err(invalid(
                &field,
                key_pos,
                "malformed key: expected dotted field names such as fluid.yield_stress_pa".into(),
            ));
        }
        let Value::Array(values) = value else {
            return Err(invalid(
                &field,
                value_pos,
                format!("expected a list of values, e.g. {key}: [1, 2, 3]"),
            ));
        };
        if values.is_empty() {
            return Err(invalid(
                &field,
                value_pos,
                "empty list: give at least one value".into(),
            ));
        }
        for (i, v) in values.iter().enumerate() {
            if matches!(v, Value::Array(_) | Value::Object(_)) {
                let item = format!("{field}.{i}");
                return Err(invalid(
                    &item,
                    map.value_pos(&item).or(value_pos),
                    "not a scalar (expected a number, bool, string or null)".into(),
                ));
            }
        }
        if pinned.contains(&key.as_str()) {
            continue;
        }
        axes.push(Axis { key, values });
    }

    let total = axes
        .iter()
        .try_fold(1usize, |n, a| n.checked_mul(a.values.len()))
        .filter(|n| *n <= MAX_POINTS);
    let Some(total) = total else {
        return Err(invalid(
            SWEEP_KEY,
            Some(sweep_pos),
            format!("the sweep has more than {MAX_POINTS} points"),
        ));
    };

    let mut points = Vec::with_capacity(total);
    for index in 0..total {
        // Mixed radix, last axis fastest.
        let mut rest = index;
        let mut picks = vec![0usize; axes.len()];
        for (a, axis) in axes.iter().enumerate().rev() {
            picks[a] = rest % axis.values.len();
            rest /= axis.values.len();
        }
        let assignments: Vec<(String, String)> = axes
            .iter()
            .zip(&picks)
            .map(|(axis, &i)| (axis.key.clone(), value_text(&axis.values[i])))
            .collect();
        let mut sets = overrides.to_vec();
        sets.extend(assignments.iter().map(|(k, v)| format!("{k}={v}")));
        let resolved = from_str(text, source_name, &sets).map_err(|e| {
            let at = |k: &str| {
                let axis = axes.iter().position(|a| a.key == k)?;
                let item = format!("{SWEEP_KEY}.{k}.{}", picks[axis]);
                let pos = map.value_pos(&item);
                Some((item, pos))
            };
            relocate(e, source_name, &at)
        })?;
        points.push(Point {
            assignments,
            resolved,
        });
    }

    // Resolved axis values, read back from the first point that has each value.
    let resolved_axes: Vec<Value> = axes
        .iter()
        .enumerate()
        .map(|(a, axis)| {
            let stride: usize = axes[a + 1..].iter().map(|x| x.values.len()).product();
            let values: Vec<Value> = (0..axis.values.len())
                .map(|i| {
                    let canonical: Value =
                        serde_json::from_str(&points[i * stride].resolved.canonical)
                            .expect("canonical text is JSON");
                    lookup(&canonical, &axis.key)
                        .cloned()
                        .unwrap_or(Value::Null)
                })
                .collect();
            Value::Array(vec![Value::String(axis.key.clone()), Value::Array(values)])
        })
        .collect();
    let mut obj = serde_json::Map::new();
    obj.insert("axes".into(), Value::Array(resolved_axes));
    obj.insert(
        "points".into(),
        Value::Array(
            points
                .iter()
                .map(|p| Value::String(p.resolved.hash_hex.clone()))
                .collect(),
        ),
    );
    let canonical = serde_json::to_string(&Value::Object(obj)).expect("JSON serializes");
    let hash_hex = canonical::sha256_hex(&canonical);
    Ok(Plan::Sweep(Sweep {
        // Never empty: every axis has a value (no axes at all: one point).
        name: points[0].resolved.manifest.name.clone(),
        axes,
        points,
        canonical,
        hash_hex,
    }))
}

/// The value at dotted `path` of a JSON object.
pub fn lookup<'a>(root: &'a Value, path: &str) -> Option<&'a Value> {
    path.split('.').try_fold(root, |node, seg| node.get(seg))
}

/// The `--set` text of a scalar: JSON text, which reads back as the same YAML scalar.
fn value_text(v: &Value) -> String {
    serde_json::to_string(v).expect("JSON serializes")
}

/// Swept key -> (field path of the point's value in the sweep section, its location).
type Locator<'a> = dyn Fn(&str) -> Option<(String, Option<Pos>)> + 'a;

/// An error of resolving a point, about a swept key, located at the value in the sweep
/// section instead of "--set KEY".
fn relocate(e: ManifestError, source_name: &str, at: &Locator) -> ManifestError {
    match e {
        ManifestError::Override { key, message } => match at(&key) {
            Some((item, pos)) => ManifestError::Invalid {
                source_name: source_name.to_string(),
                field: item,
                line: pos.map(|p| p.line),
                column: pos.map(|p| p.column),
                message,
            },
            None => ManifestError::Override { key, message },
        },
        ManifestError::Invalid {
            source_name: s,
            field,
            line: None,
            column,
            message,
        } if message.ends_with(" (from --set)") => match at(&field) {
            Some((item, pos)) => ManifestError::Invalid {
                source_name: s,
                field: item,
                line: pos.map(|p| p.line),
                column: pos.map(|p| p.column),
                message: format!("{} (from sweep)", message.trim_end_matches(" (from --set)")),
            },
            None => ManifestError::Invalid {
                source_name: s,
                field,
                line: None,
                column,
                message,
            },
        },
        e => e,
    }
}

/// Replace the top-level `sweep` entry of `text` by spaces (newlines kept), so that every
/// other value keeps its line and column; in a flow mapping, the comma after the entry goes
/// too. Returns `text` unchanged when there is none.
pub(crate) fn strip(text: &str) -> std::borrow::Cow<'_, str> {
    let map = SourceMap::build(text);
    let Some(entry) = map.entries.get(SWEEP_KEY) else {
        return text.into();
    };
    let (start, end) = (entry.key.0, entry.value.1);
    let mut out = String::with_capacity(text.len());
    let (mut line, mut column) = (1usize, 1usize);
    let mut looking_for_comma = true;
    for c in text.chars() {
        let here = Pos { line, column };
        let blank = if c == '\n' || c == '\r' {
            false
        } else if start <= here && here < end {
            true
        } else if here >= end && looking_for_comma && !c.is_whitespace() {
            looking_for_comma = false;
            c == ','
        } else {
            false
        };
        out.push(if blank { ' ' } else { c });
        if c == '\n' {
            line += 1;
            column = 1;
        } else {
            column += 1;
        }
    }
    out.into()
}

/// The top level of a manifest as far as sweeps care: the `sweep` value.
#[derive(Default)]
struct Top {
    sweep: Option<MaybeOrdered>,
}

/// A mapping with its entries in the order written.
#[derive(Debug, Default)]
struct Ordered(Vec<(String, Value)>);

impl<'de> Deserialize<'de> for Top {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> std::result::Result<Self, D::Error> {
        struct V;
        impl<'de> Visitor<'de> for V {
            type Value = Top;
            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                f.write_str("a manifest mapping")
            }
            fn visit_map<A: MapAccess<'de>>(self, mut m: A) -> std::result::Result<Top, A::Error> {
                let mut top = Top::default();
                while let Some(k) = m.next_key::<String>()? {
                    if k == SWEEP_KEY {
                        top.sweep = Some(m.next_value()?);
                    } else {
                        m.next_value::<IgnoredAny>()?;
                    }
                }
                Ok(top)
            }
        }
        d.deserialize_map(V)
    }
}

/// Any value; a mapping also keeps its key order.
struct MaybeOrdered {
    value: Value,
    ordered: Option<Ordered>,
}

impl<'de> Deserialize<'de> for MaybeOrdered {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> std::result::Result<Self, D::Error> {
        struct V;
        impl<'de> Visitor<'de> for V {
            type Value = MaybeOrdered;
            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                f.write_str("a mapping of dotted keys to lists of values")
            }
            fn visit_map<A: MapAccess<'de>>(
                self,
                mut m: A,
            ) -> std::result::Result<MaybeOrdered, A::Error> {
                let mut entries = Vec::new();
                while let Some(k) = m.next_key::<String>()? {
                    entries.push((k, m.next_value::<Value>()?));
                }
                let value = Value::Object(entries.iter().cloned().collect());
                Ok(MaybeOrdered {
                    value,
                    ordered: Some(Ordered(entries)),
                })
            }
            fn visit_seq<A: serde::de::SeqAccess<'de>>(
                self,
                mut s: A,
            ) -> std::result::Result<MaybeOrdered, A::Error> {
                let mut items = Vec::new();
                while let Some(v) = s.next_element::<Value>()? {
                    items.push(v);
                }
                Ok(MaybeOrdered {
                    value: Value::Array(items),
                    ordered: None,
                })
            }
            fn visit_bool<E>(self, v: bool) -> std::result::Result<MaybeOrdered, E> {
                Ok(scalar(Value::Bool(v)))
            }
            fn visit_i64<E>(self, v: i64) -> std::result::Result<MaybeOrdered, E> {
                Ok(scalar(v.into()))
            }
            fn visit_u64<E>(self, v: u64) -> std::result::Result<MaybeOrdered, E> {
                Ok(scalar(v.into()))
            }
            fn visit_f64<E>(self, v: f64) -> std::result::Result<MaybeOrdered, E> {
                Ok(scalar(v.into()))
            }
            fn visit_str<E>(self, v: &str) -> std::result::Result<MaybeOrdered, E> {
                Ok(scalar(Value::String(v.to_string())))
            }
            fn visit_unit<E>(self) -> std::result::Result<MaybeOrdered, E> {
                Ok(scalar(Value::Null))
            }
            fn visit_none<E>(self) -> std::result::Result<MaybeOrdered, E> {
                Ok(scalar(Value::Null))
            }
        }
        d.deserialize_any(V)
    }
}

fn scalar(value: Value) -> MaybeOrdered {
    MaybeOrdered {
        value,
        ordered: None,
    }
}

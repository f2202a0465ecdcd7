//! Experiment manifests: typed YAML, validation, `--set` overrides, canonical form and hash.
//!
//! Pipeline of [`from_str`] / [`load`]:
//! 0. a top-level `sweep` section is blanked out ([`sweep`] expands it; [`sweep::load_plan`]
//!    is the entry point for files that may carry one);
//! 1. the YAML text is deserialized into a typed [`Manifest`] by serde-saphyr (unknown
//!    fields, missing fields, wrong types and YAML syntax errors come back as
//!    [`ManifestError::Syntax`] with line, column and, where it can be found, the field path);
//! 2. the manifest (defaults filled in) becomes a `serde_json::Value`; each override is
//!    applied to it in order ([`ManifestError::Override`] on unknown keys and bad values);
//! 3. `mps.preset` is resolved into the fields it names (see [`preset`] for which setting
//!    wins where);
//! 4. `-0.0` is normalised and the value is turned back into a typed [`Manifest`];
//! 5. every field is validated ([`ManifestError::Invalid`], located in the source when the
//!    value was written there);
//! 6. the canonical text and its SHA-256 are computed (see [`canonical`]).

pub mod boundaries;
pub mod canonical;
pub mod checker;
mod error;
pub mod locate;
mod overrides;
pub mod preset;
pub mod shape;
pub mod sweep;
mod types;
pub mod validate;

use std::collections::BTreeSet;
use std::path::Path;

pub use error::{ManifestError, Result};
pub use preset::{PRESET_REVISION, PresetName, recorded_revision};
pub use types::{
    Fluid, Manifest, Mps, Output, PpePreconditioner, PpeSource, PressureSchemeName, SceneSection,
    Stop, Time,
};

use locate::{Pos, SourceMap};
use overrides::Touched;

/// A manifest loaded, overridden, validated and hashed.
#[derive(Debug, Clone, PartialEq)]
pub struct Resolved<S> {
    /// The fully resolved manifest.
    pub manifest: Manifest<S>,
    /// The manifest file text as written.
    pub source_text: String,
    /// The `--set KEY=VALUE` strings applied, in order.
    pub overrides: Vec<String>,
    /// Canonical JSON text of the resolved manifest.
    pub canonical: String,
    /// Lowercase hex SHA-256 of `canonical` (64 characters).
    pub hash_hex: String,
    /// The preset the manifest was resolved under where neither its file nor an override
    /// named one ([`default_preset`] for a new run; a file's recorded one when it is taken
    /// back up).
    pub default_preset: Option<PresetName>,
    /// What the presets set ([`PRESET_REVISION`] for a new run; a file's recorded one when
    /// it is taken back up).
    pub preset_revision: u32,
}

/// The preset a new run's manifest takes, by its dimension, where neither its file nor an
/// override names one (with the precedence of a preset written in the file: the file's
/// fields win; `mps.preset: null` or `standard` opts out). `quiet` in 2D, where it meets
/// every figure of issue 31 (docs/validation.md, "Holding still"); none in 3D, where its
/// thin layers stay stirred under the rigid state and the coarse slumps run short (README,
/// "Holding still"). A file records the default it was resolved under (metadata
/// `manifest.default_preset`, written only when there is one) and its source is resolved
/// under that one again when it is taken back up ([`from_str_under`]), so files keep
/// verifying when this changes; a stored canonical form, which holds every field, is
/// resolved under none ([`from_canonical`]).
pub fn default_preset(dimension: u64) -> Option<PresetName> {
    (dimension == 2).then_some(PresetName::Quiet)
}

impl<S> Resolved<S> {
    /// The first 12 hex digits of the hash (for file names).
    pub fn short_hash(&self) -> &str {
        canonical::short_hash(&self.hash_hex)
    }
}

/// Read the manifest at `path`, apply `overrides` (`KEY=VALUE`), validate and hash it.
/// Errors name the file as `path` was given.
pub fn load<S: SceneSection>(path: &Path, overrides: &[String]) -> Result<Resolved<S>> {
    let text = std::fs::read_to_string(path).map_err(|source| ManifestError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    from_str(&text, &path.display().to_string(), overrides)
}

/// Like [`load`], from text; `source_name` is used in error messages.
/// A top-level `sweep` section is ignored here (blanked out, see [`sweep`]); `source_text`
/// keeps it.
pub fn from_str<S: SceneSection>(
    text: &str,
    source_name: &str,
    overrides: &[String],
) -> Result<Resolved<S>> {
    resolve_with(
        text,
        source_name,
        overrides,
        default_preset,
        PRESET_REVISION,
    )
}

/// A canonical form (stored in a run file or written by `runner expand`), with `overrides`:
/// resolved under no default preset, since it holds every field that differs from the
/// behaviour before the presets.
pub fn from_canonical<S: SceneSection>(
    text: &str,
    source_name: &str,
    overrides: &[String],
) -> Result<Resolved<S>> {
    resolve_with(text, source_name, overrides, |_| None, PRESET_REVISION)
}

/// Like [`from_str`], under `default_preset` where neither the file nor an override names a
/// preset.
pub fn from_str_under<S: SceneSection>(
    text: &str,
    source_name: &str,
    overrides: &[String],
    default_preset: Option<PresetName>,
) -> Result<Resolved<S>> {
    from_str_as_of(
        text,
        source_name,
        overrides,
        default_preset,
        PRESET_REVISION,
    )
}

/// Like [`from_str_under`], with the presets as they were at `revision` (a run file's
/// recorded one).
pub fn from_str_as_of<S: SceneSection>(
    text: &str,
    source_name: &str,
    overrides: &[String],
    default_preset: Option<PresetName>,
    revision: u32,
) -> Result<Resolved<S>> {
    resolve_with(text, source_name, overrides, |_| default_preset, revision)
}

/// The pipeline, with the default preset given by the manifest's dimension (after the
/// overrides).
fn resolve_with<S: SceneSection>(
    text: &str,
    source_name: &str,
    overrides: &[String],
    default_for: impl Fn(u64) -> Option<PresetName>,
    preset_revision: u32,
) -> Result<Resolved<S>> {
    let full_text = text;
    let text: &str = &sweep::strip(full_text);
    let parsed: Manifest<S> = serde_saphyr::from_str_with_options(text, yaml_options())
        .map_err(|e| syntax_error::<S>(&e, source_name, text))?;

    // JSON has no NaN or infinity: catch them before the manifest becomes JSON.
    let map = SourceMap::build(text);
    if let Some(issue) = validate::check(&parsed).into_iter().find(|i| i.non_finite) {
        let pos = map.written_pos(&issue.field);
        return Err(ManifestError::Invalid {
            source_name: source_name.to_string(),
            field: issue.field,
            line: pos.map(|p| p.line),
            column: pos.map(|p| p.column),
            message: issue.message,
        });
    }

    let mut value = serde_json::to_value(&parsed).expect("a manifest always serializes to JSON");
    let mut touched = Touched::default();
    for raw in overrides {
        overrides::apply::<S>(&mut value, raw, &mut touched)?;
    }
    let default_preset = default_for(value["dimension"].as_u64().unwrap_or(2));
    let preset_filled =
        preset::resolve(&mut value, &map, &touched, default_preset, preset_revision)?;
    canonical::normalise_negative_zero(&mut value);
    let manifest = rebuild(&value, overrides)?;

    // An issue the default preset caused (a field it set, or named in the message) comes after
    // the user's own: `--set dimension=2` on a 3D-only scene is told so first.
    let mut issues = validate::check(&manifest);
    if preset_filled.by_default.is_some() {
        issues.sort_by_key(|i| preset_paths_in(i, &preset_filled).next().is_some());
    }
    if let Some(issue) = issues.into_iter().next() {
        let (pos, origin) = if touched.is_set(&issue.field) {
            (None, " (from --set)")
        } else if preset_filled.paths.contains(&issue.field) {
            let origin = match preset_filled.by_default {
                Some(_) => " (from the default mps.preset)",
                None => " (from mps.preset)",
            };
            (None, origin)
        } else if touched.is_reset(&issue.field) {
            (None, " (default)")
        } else {
            match map.written_pos(&issue.field) {
                Some(p) => (Some(p), ""),
                None => (None, " (default)"),
            }
        };
        let note = preset_note(&issue, &preset_filled);
        return Err(ManifestError::Invalid {
            source_name: source_name.to_string(),
            field: issue.field,
            line: pos.map(|p| p.line),
            column: pos.map(|p| p.column),
            message: format!("{}{origin}{note}", issue.message),
        });
    }

    let canonical = canonical::canonical_text(&manifest);
    let hash_hex = canonical::sha256_hex(&canonical);
    Ok(Resolved {
        manifest,
        source_text: full_text.to_string(),
        overrides: overrides.to_vec(),
        canonical,
        hash_hex,
        default_preset,
        preset_revision,
    })
}

/// The fields the preset set that `issue` is about or names in its message.
fn preset_paths_in<'a>(
    issue: &'a checker::Issue,
    filled: &'a preset::Filled,
) -> impl Iterator<Item = &'a str> {
    filled
        .paths
        .iter()
        .map(String::as_str)
        .filter(|p| *p == issue.field || issue.message.contains(p))
}

/// Names the preset's fields that a validation message mentions but the user did not write,
/// and, for a default preset, how to opt out.
fn preset_note(issue: &checker::Issue, filled: &preset::Filled) -> String {
    let named: Vec<&str> = preset_paths_in(issue, filled)
        .filter(|p| *p != issue.field)
        .collect();
    if named.is_empty() {
        String::new()
    } else {
        match filled.by_default {
            Some(p) => format!(
                "; {} set by the default mps.preset `{}` of this dimension (write `mps.preset: standard` to keep the standard scheme)",
                named.join(", "),
                p.name()
            ),
            None => format!("; {} set by mps.preset", named.join(", ")),
        }
    }
}

/// serde-saphyr options: the defaults (duplicate keys rejected, alias/size budget on), with
/// snippets off since our errors carry their own location.
fn yaml_options() -> serde_saphyr::Options {
    let mut options = serde_saphyr::Options::default();
    options.with_snippet = false;
    options
}

/// Turn the (overridden) JSON value back into a typed manifest. The value goes through
/// pretty JSON text and serde-saphyr, so that a type error has a location, which gives its
/// field path, which names the override responsible.
fn rebuild<S: SceneSection>(
    value: &serde_json::Value,
    overrides: &[String],
) -> Result<Manifest<S>> {
    let text = serde_json::to_string_pretty(value).expect("a JSON value always serializes");
    serde_saphyr::from_str_with_options(&text, yaml_options()).map_err(|e| {
        let Described { field, message, .. } = describe::<S>(&e, &SourceMap::build(&text));
        let keys: Vec<&str> = overrides
            .iter()
            .filter_map(|o| overrides::split(o).ok().map(|(k, _)| k))
            .collect();
        let related = |k: &&&str| {
            field.as_deref().is_some_and(|f| {
                let k: &str = k;
                f == k
                    || f.starts_with(&format!("{k}."))
                    || k.starts_with(&format!("{f}."))
                    || parent(k) == parent(f)
            })
        };
        let key = keys
            .iter()
            .rev()
            .find(|k| Some(**k) == field.as_deref())
            .or_else(|| keys.iter().rev().find(related))
            .map(|k| k.to_string())
            .or(field.clone())
            .unwrap_or_else(|| "?".to_string());
        let message = match &field {
            Some(f) if *f != key => format!("{f}: {message}"),
            _ => message,
        };
        ManifestError::Override { key, message }
    })
}

fn parent(path: &str) -> &str {
    path.rfind('.').map_or("", |i| &path[..i])
}

/// A serde-saphyr error as `ManifestError::Syntax`.
pub fn syntax_error<S: SceneSection>(
    e: &serde_saphyr::Error,
    source_name: &str,
    text: &str,
) -> ManifestError {
    let map = SourceMap::build(text);
    let d = describe::<S>(e, &map);
    ManifestError::Syntax {
        source_name: source_name.to_string(),
        line: d.pos.map(|p| p.line),
        column: d.pos.map(|p| p.column),
        field: d.field,
        message: d.message,
    }
}

/// The error itself, without snippet or alias wrappers.
fn inner(e: &serde_saphyr::Error) -> &serde_saphyr::Error {
    let mut e = e.without_snippet();
    while let serde_saphyr::Error::AliasError { error, .. } = e {
        e = error.without_snippet();
    }
    e
}

/// Every field path of the manifest schema (sections included).
fn schema_paths<S: SceneSection>() -> BTreeSet<String> {
    fn collect(v: &serde_json::Value, prefix: &str, out: &mut BTreeSet<String>) {
        if let serde_json::Value::Object(map) = v {
            for (k, child) in map {
                let path = join(prefix, k);
                collect(child, &path, out);
                out.insert(path);
            }
        }
    }
    let mut out = BTreeSet::new();
    for m in types::samples::<S>() {
        collect(&serde_json::to_value(m).expect("serializes"), "", &mut out);
    }
    out
}

fn join(prefix: &str, seg: &str) -> String {
    if prefix.is_empty() {
        seg.to_string()
    } else {
        format!("{prefix}.{seg}")
    }
}

/// `path`, then its ancestors up to the root `""`.
fn ancestors(path: &str) -> impl Iterator<Item = &str> {
    std::iter::successors(Some(path), |p| (!p.is_empty()).then(|| parent(p)))
}

/// What an error is about: field path, location and message.
struct Described {
    field: Option<String>,
    pos: Option<Pos>,
    message: String,
}

/// Field path (found from the error's location: serde-saphyr reports a struct's missing
/// field at its last key, and errors inside internally tagged enums at the enum's key),
/// location and message of a serde-saphyr error.
fn describe<S: SceneSection>(e: &serde_saphyr::Error, map: &SourceMap) -> Described {
    use serde_saphyr::Error as E;
    let e = inner(e);
    let mut pos = e.location().filter(|l| l.line() > 0).map(|l| Pos {
        line: l.line() as usize,
        column: l.column() as usize,
    });
    let at: Option<String> = pos.and_then(|p| map.path_at(p)).map(str::to_string);
    let list = |v: &[&str]| {
        v.iter()
            .map(|s| format!("`{s}`"))
            .collect::<Vec<_>>()
            .join(", ")
    };
    let in_section = |path: &str| {
        let section = parent(path);
        if section.is_empty() {
            String::new()
        } else {
            format!(" in `{section}`")
        }
    };
    let (field, message) = match e {
        E::SerdeUnknownField {
            field, expected, ..
        } => {
            let k = at.clone().unwrap_or_default();
            let path = if k.rsplit('.').next() == Some(field.as_str()) {
                k
            } else if let Some((p, entry)) = ancestors(&k)
                .map(|s| join(s, field))
                .find_map(|p| map.entries.get(&p).map(|e| (p, e)))
            {
                pos = Some(entry.key.0);
                p
            } else {
                join(&k, field)
            };
            let message = format!(
                "unknown field `{field}`{}, expected one of {}",
                in_section(&path),
                list(expected)
            );
            (Some(path), message)
        }
        E::SerdeMissingField { field, .. } => {
            let k = at.clone().unwrap_or_default();
            let schema = schema_paths::<S>();
            let path = ancestors(&k)
                .map(|s| join(s, field))
                .find(|p| schema.contains(p))
                .unwrap_or_else(|| field.to_string());
            // Point at the section that lacks the field (its key), or at the first key of
            // the document for a top-level field.
            let section = parent(&path);
            pos = if section.is_empty() {
                map.entries
                    .iter()
                    .filter(|(p, _)| !p.contains('.'))
                    .map(|(_, e)| e.key.0)
                    .min()
                    .or(pos)
            } else {
                map.entries.get(section).map(|e| e.key.0).or(pos)
            };
            let message = format!("missing required field `{field}`{}", in_section(&path));
            (Some(path), message)
        }
        E::SerdeUnknownVariant {
            variant, expected, ..
        } => {
            // Reported at the tag's key: point at its value.
            if let Some(entry) = at.as_deref().and_then(|p| map.entries.get(p))
                && entry.scalar.is_some()
            {
                pos = Some(entry.value.0);
            }
            (
                at,
                format!(
                    "unknown variant `{variant}`, expected one of {}",
                    list(expected)
                ),
            )
        }
        E::SerdeInvalidType { unexpected, .. } | E::SerdeInvalidValue { unexpected, .. } => {
            // Inside an internally tagged enum the location is the enum's key: look for the
            // offending scalar below it.
            let mut field = at;
            if let (Some(k), Some(text)) = (&field, quoted(unexpected)) {
                let below: Vec<(&String, &locate::Entry)> = map
                    .entries
                    .iter()
                    .filter(|(p, e)| {
                        p.starts_with(&format!("{k}.")) && e.scalar.as_deref() == Some(text)
                    })
                    .collect();
                if let [(p, entry)] = below[..] {
                    pos = Some(entry.value.0);
                    field = Some(p.clone());
                }
            }
            (field, saphyr_message(e))
        }
        E::InvalidScalar { ty, .. } => {
            let text = at
                .as_deref()
                .and_then(|p| map.entries.get(p))
                .and_then(|e| e.scalar.as_deref());
            // serde-saphyr names the Rust type ("u64", "floating point"); say what to write.
            let wanted = match *ty {
                "u8" | "u16" | "u32" | "u64" | "u128" | "usize" => {
                    format!("a whole number >= 0 (fits {ty})")
                }
                "i8" | "i16" | "i32" | "i64" | "i128" | "isize" => {
                    format!("a whole number (fits {ty})")
                }
                "floating point" | "f32" | "f64" => "a number".to_string(),
                "bool" => "true or false".to_string(),
                other => format!("a value of type {other}"),
            };
            let message = match text {
                Some(t) => format!("expected {wanted}, got {t:?}"),
                None => format!("expected {wanted}"),
            };
            (at, message)
        }
        _ => {
            let mut message = saphyr_message(e);
            // serde-saphyr's words for a list or mapping where one value belongs.
            let not_scalar = at
                .as_deref()
                .and_then(|p| map.entries.get(p))
                .is_some_and(|entry| entry.scalar.is_none());
            if message.contains("expected string scalar") && not_scalar {
                message =
                    "expected a single value (a number, string or bool), got a list or a mapping"
                        .to_string();
            }
            (at, message)
        }
    };
    Described {
        field,
        pos,
        message,
    }
}

/// The text between the first pair of `"` or backticks in serde's "unexpected" phrase,
/// e.g. `string "abc"` -> `abc`.
fn quoted(s: &str) -> Option<&str> {
    let i = s.find(['"', '`'])?;
    let q = s[i..].chars().next()?;
    let rest = &s[i + 1..];
    let j = rest.find(q)?;
    Some(&rest[..j])
}

/// The message of a serde-saphyr error without location, control characters escaped.
pub(crate) fn saphyr_message(e: &serde_saphyr::Error) -> String {
    use serde_saphyr::MessageFormatter;
    let msg = serde_saphyr::UserMessageFormatter.format_message(inner(e));
    msg.chars()
        .flat_map(|c| {
            if c.is_control() {
                c.escape_default().collect::<Vec<_>>()
            } else {
                vec![c]
            }
        })
        .collect()
}

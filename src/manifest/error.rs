//! Errors of manifest loading, override application and validation.

use std::fmt;
use std::path::PathBuf;

/// Result alias of this module.
pub type Result<T, E = ManifestError> = std::result::Result<T, E>;

/// Why a manifest could not be loaded.
///
/// Display formats (line and column are 1-based, columns count characters):
/// - `Io`: `PATH: cannot read manifest: CAUSE`
/// - `Syntax`: `SOURCE:LINE:COLUMN: FIELD: MESSAGE` (the `LINE:COLUMN` and `FIELD: ` parts
///   are left out when unknown)
/// - `Invalid`: `SOURCE:LINE:COLUMN: FIELD: MESSAGE`; when the value did not come from the
///   file, `SOURCE: FIELD: MESSAGE (from --set)` or `... (default)`
/// - `Override`: `--set KEY: MESSAGE`
#[derive(Debug, thiserror::Error)]
pub enum ManifestError {
    /// The manifest file could not be read.
    #[error("{}: cannot read manifest: {source}", path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },

    /// The YAML is malformed or does not fit the manifest's shape: syntax error, unknown
    /// field, missing field, wrong type, unknown variant, duplicate key, budget exceeded.
    #[error("{}", DisplayLocated { source_name, line: *line, column: *column, field: field.as_deref(), message })]
    Syntax {
        source_name: String,
        /// 1-based line, when known.
        line: Option<usize>,
        /// 1-based column (characters), when known.
        column: Option<usize>,
        /// Dotted path of the offending field, when it could be determined.
        field: Option<String>,
        message: String,
    },

    /// A value is out of its allowed range or inconsistent with another value.
    #[error("{}", DisplayLocated { source_name, line: *line, column: *column, field: Some(field), message })]
    Invalid {
        source_name: String,
        /// Dotted path of the field, e.g. `time.courant`.
        field: String,
        /// 1-based line of the value in the source; `None` when the value came from an
        /// override or a default (the message then says which).
        line: Option<usize>,
        column: Option<usize>,
        message: String,
    },

    /// A `--set KEY=VALUE` override could not be applied.
    #[error("--set {key}: {message}")]
    Override { key: String, message: String },
}

impl ManifestError {
    /// The dotted field path the error is about, when known.
    pub fn field(&self) -> Option<&str> {
        match self {
            ManifestError::Io { .. } => None,
            ManifestError::Syntax { field, .. } => field.as_deref(),
            ManifestError::Invalid { field, .. } => Some(field),
            ManifestError::Override { key, .. } => Some(key),
        }
    }

    /// `(line, column)` in the manifest source, when known.
    pub fn location(&self) -> Option<(usize, usize)> {
        match self {
            ManifestError::Syntax {
                line: Some(l),
                column: Some(c),
                ..
            }
            | ManifestError::Invalid {
                line: Some(l),
                column: Some(c),
                ..
            } => Some((*l, *c)),
            _ => None,
        }
    }
}

struct DisplayLocated<'a> {
    source_name: &'a str,
    line: Option<usize>,
    column: Option<usize>,
    field: Option<&'a str>,
    message: &'a str,
}

impl fmt::Display for DisplayLocated<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.source_name)?;
        match (self.line, self.column) {
            (Some(l), Some(c)) => write!(f, ":{l}:{c}")?,
            (Some(l), None) => write!(f, ":{l}")?,
            _ => {}
        }
        f.write_str(": ")?;
        if let Some(field) = self.field.filter(|s| !s.is_empty()) {
            write!(f, "{field}: ")?;
        }
        f.write_str(self.message)
    }
}

//! The suite file of `runner bench --suite` (e.g. `benchmarks/suite.yaml`): read, checked and
//! resolved before anything runs, so that a typo costs an error message, not a long run that
//! ends in a refused case. Errors are manifest errors (the same `FILE:LINE:COLUMN: FIELD:
//! MESSAGE` form, exit 2).

use mps_runner::experiment::{self, SceneSpec};
use mps_runner::manifest::ManifestError;
use mps_runner::manifest::locate::SourceMap;
use mps_runner::manifest::sweep::Plan;
use serde::Deserialize;
use std::path::{Component, Path, PathBuf};

/// The file as written. Every field has a default so that a missing one is reported by
/// [`check`] at the entry that lacks it (serde's own message would point at the document).
#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct SuiteFile {
    #[serde(default)]
    cases: Vec<CaseSpec>,
    #[serde(default)]
    scaling: Option<ScalingSpec>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct CaseSpec {
    #[serde(default)]
    name: String,
    #[serde(default)]
    manifest: String,
    #[serde(default)]
    set: Vec<String>,
    #[serde(default)]
    quick_set: Vec<String>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct ScalingSpec {
    #[serde(default)]
    manifest: String,
    #[serde(default)]
    set: Vec<String>,
    #[serde(default)]
    quick_set: Vec<String>,
    #[serde(default)]
    spacings_m: Vec<f64>,
}

/// One case, resolved: the manifest path as the child is given it, and the `--set`s for this
/// run (`set`, then `quick_set` with `--quick`).
#[derive(Debug, Clone)]
pub struct Case {
    pub name: String,
    pub manifest: PathBuf,
    pub sets: Vec<String>,
    /// `Some(points)` for a sweep manifest (run as a sweep, not by `runner bench`).
    pub sweep_points: Option<usize>,
}

/// The scaling series: one `runner bench` per spacing (`--set spacing_m=S` last).
#[derive(Debug, Clone)]
pub struct Scaling {
    pub manifest: PathBuf,
    pub sets: Vec<String>,
    pub spacings_m: Vec<f64>,
}

#[derive(Debug, Clone)]
pub struct Suite {
    pub cases: Vec<Case>,
    pub scaling: Option<Scaling>,
}

/// Reads, checks and resolves the suite at `path`. Manifest paths are relative to the suite
/// file's folder (as a calibration's `base`); each case's manifest is loaded with its
/// `--set`s, so an unknown key or a bad value is refused here, naming the suite entry.
pub fn load(path: &Path, quick: bool) -> Result<Suite, ManifestError> {
    let source = path.display().to_string();
    let text = std::fs::read_to_string(path).map_err(|e| ManifestError::Syntax {
        source_name: source.clone(),
        line: None,
        column: None,
        field: None,
        message: format!("cannot read the suite file: {e}"),
    })?;
    let file: SuiteFile = serde_saphyr::from_str(&text)
        .map_err(|e| mps_runner::manifest::syntax_error::<SceneSpec>(&e, &source, &text))?;
    let checker = Checker {
        source,
        map: SourceMap::build(&text),
        folder: path.parent().unwrap_or(Path::new("")).to_path_buf(),
    };
    checker.suite(file, quick)
}

/// Turns a field path into a located error.
struct Checker {
    source: String,
    map: SourceMap,
    folder: PathBuf,
}

impl Checker {
    /// `field` located at its value, or at the nearest entry above it that is written (a
    /// missing field is reported at the case that lacks it).
    fn bad(&self, field: &str, message: String) -> ManifestError {
        let mut at = field;
        let pos = loop {
            if let Some(p) = self.map.written_pos(at) {
                break Some(p);
            }
            match at.rfind('.') {
                Some(i) => at = &at[..i],
                None => break None,
            }
        };
        ManifestError::Invalid {
            source_name: self.source.clone(),
            field: field.to_string(),
            line: pos.map(|p| p.line),
            column: pos.map(|p| p.column),
            message,
        }
    }

    fn suite(&self, file: SuiteFile, quick: bool) -> Result<Suite, ManifestError> {
        if file.cases.is_empty() && file.scaling.is_none() {
            return Err(self.bad(
                "cases",
                "the suite names no case and no scaling series: nothing to run".into(),
            ));
        }
        let mut cases: Vec<Case> = Vec::new();
        for (i, spec) in file.cases.into_iter().enumerate() {
            let case = self.case(i, spec, quick)?;
            if cases.iter().any(|c| c.name == case.name) {
                return Err(self.bad(
                    &format!("cases.{i}.name"),
                    format!(
                        "{} is the name of an earlier case: names must differ",
                        case.name
                    ),
                ));
            }
            cases.push(case);
        }
        let scaling = match file.scaling {
            Some(s) => Some(self.scaling(s, quick)?),
            None => None,
        };
        Ok(Suite { cases, scaling })
    }

    fn case(&self, i: usize, spec: CaseSpec, quick: bool) -> Result<Case, ManifestError> {
        let at = format!("cases.{i}");
        if spec.name.trim().is_empty() {
            return Err(self.bad(&format!("{at}.name"), "must give the case a name".into()));
        }
        let manifest = self.manifest_path(&at, &spec.manifest)?;
        let sets = self.sets(&at, &spec.set, &spec.quick_set, quick)?;
        let plan =
            experiment::load_plan(&manifest, &sets).map_err(|e| self.load_error(&at, quick, e))?;
        let sweep_points = match plan {
            Plan::Single(_) => None,
            Plan::Sweep(s) => Some(s.points.len()),
        };
        Ok(Case {
            name: spec.name,
            manifest,
            sets,
            sweep_points,
        })
    }

    fn scaling(&self, spec: ScalingSpec, quick: bool) -> Result<Scaling, ManifestError> {
        let at = "scaling";
        let manifest = self.manifest_path(at, &spec.manifest)?;
        let sets = self.sets(at, &spec.set, &spec.quick_set, quick)?;
        if spec.spacings_m.is_empty() {
            return Err(self.bad(
                "scaling.spacings_m",
                "must list the spacings to run, e.g. [0.01, 0.005]".into(),
            ));
        }
        for (k, s) in spec.spacings_m.iter().enumerate() {
            let field = format!("scaling.spacings_m.{k}");
            if !(s.is_finite() && *s > 0.0) {
                return Err(self.bad(&field, format!("must be a spacing > 0 (m), got {s}")));
            }
            // Each spacing is loaded: a scene too fine or too coarse for it is refused here.
            let with = [sets.clone(), vec![format!("spacing_m={s}")]].concat();
            match experiment::load_plan(&manifest, &with) {
                Ok(Plan::Single(_)) => {}
                Ok(Plan::Sweep(_)) => {
                    return Err(self.bad(
                        "scaling.manifest",
                        "is a sweep: the scaling series runs `runner bench`, which takes one experiment".into(),
                    ));
                }
                Err(e) => return Err(self.bad(&field, format!("{e}"))),
            }
        }
        Ok(Scaling {
            manifest,
            sets,
            spacings_m: spec.spacings_m,
        })
    }

    /// The manifest path relative to the suite's folder, `..` taken out where it follows a
    /// folder name, so that the commands shown read as a user would type them.
    fn manifest_path(&self, at: &str, written: &str) -> Result<PathBuf, ManifestError> {
        let field = format!("{at}.manifest");
        if written.trim().is_empty() {
            return Err(self.bad(&field, "must name the experiment manifest to run".into()));
        }
        let path = tidy(&self.folder.join(written));
        if !path.is_file() {
            return Err(self.bad(
                &field,
                format!(
                    "{} is not a file (manifest paths are relative to the suite file's folder)",
                    path.display()
                ),
            ));
        }
        Ok(path)
    }

    /// `set` (and `quick_set` with `--quick`), each checked to be `KEY=VALUE`.
    fn sets(
        &self,
        at: &str,
        set: &[String],
        quick_set: &[String],
        quick: bool,
    ) -> Result<Vec<String>, ManifestError> {
        for (list, items) in [("set", set), ("quick_set", quick_set)] {
            if let Some(k) = items.iter().position(|s| !s.contains('=')) {
                return Err(self.bad(
                    &format!("{at}.{list}.{k}"),
                    format!("must be KEY=VALUE, got {:?}", items[k]),
                ));
            }
        }
        let mut sets = set.to_vec();
        if quick {
            sets.extend_from_slice(quick_set);
        }
        Ok(sets)
    }

    /// A manifest that does not load with the case's `--set`s: reported at the `set` or
    /// `quick_set` entry that sets the field the error names (the last one: it applies),
    /// else at the manifest.
    fn load_error(&self, at: &str, quick: bool, e: ManifestError) -> ManifestError {
        let entry = e.field().and_then(|field| {
            let prefix = format!("{field}=");
            let lists = [format!("{at}.set."), format!("{at}.quick_set.")];
            let lists = if quick { &lists[..] } else { &lists[..1] };
            self.map
                .entries
                .iter()
                .filter(|(p, _)| lists.iter().any(|l| p.starts_with(l.as_str())))
                .filter(|(_, entry)| {
                    entry
                        .scalar
                        .as_deref()
                        .is_some_and(|s| s.starts_with(&prefix))
                })
                .map(|(p, _)| p)
                .max_by_key(|p| (p.contains("quick_set"), index_of(p)))
                .cloned()
        });
        let field = entry.unwrap_or_else(|| format!("{at}.manifest"));
        self.bad(&field, format!("{e}"))
    }
}

/// The list index at the end of a field path (`cases.0.set.3` -> 3).
fn index_of(path: &str) -> usize {
    path.rsplit('.')
        .next()
        .and_then(|s| s.parse().ok())
        .unwrap_or(0)
}

/// `a/b/../c` -> `a/c`: a lexical tidy-up of the joined path (a `..` after a folder name
/// cancels it; leading `..` are kept).
fn tidy(path: &Path) -> PathBuf {
    let mut out: Vec<Component> = Vec::new();
    for c in path.components() {
        match c {
            Component::CurDir => {}
            Component::ParentDir if matches!(out.last(), Some(Component::Normal(_))) => {
                out.pop();
            }
            _ => out.push(c),
        }
    }
    if out.is_empty() {
        PathBuf::from(".")
    } else {
        out.iter().collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tidy_cancels_folder_then_parent() {
        assert_eq!(
            tidy(Path::new("benchmarks/../experiments/a.yaml")),
            PathBuf::from("experiments/a.yaml")
        );
        assert_eq!(
            tidy(Path::new("../x/./a.yaml")),
            PathBuf::from("../x/a.yaml")
        );
        assert_eq!(
            tidy(Path::new("/r/b/../a.yaml")),
            PathBuf::from("/r/a.yaml")
        );
    }
}

//! The commands that read a manifest and run nothing: `runner hash` (the experiment hash)
//! and `runner expand` (one canonical manifest per sweep point).

use crate::cli::{ExpandArgs, HashArgs};
use crate::error::{CliError, Done, Result};
use mps_runner::experiment;
use mps_runner::manifest::sweep::Plan;
use std::path::PathBuf;

/// `runner hash`: the experiment's (or the sweep's) hash, after its canonical form with
/// `--canonical`.
pub fn hash(args: HashArgs) -> Result {
    let (canonical, hash_hex) = match experiment::load_plan(&args.manifest, &args.set)? {
        Plan::Single(resolved) => (resolved.canonical, resolved.hash_hex),
        Plan::Sweep(s) => (s.canonical, s.hash_hex),
    };
    if args.canonical {
        println!("{canonical}");
    }
    println!("{hash_hex}");
    Ok(Done::Success)
}

/// `runner expand`: one canonical manifest per sweep point, as
/// `OUT/<name>-<first 12 hex of its hash>.yaml`; prints their paths.
pub fn expand(args: ExpandArgs) -> Result {
    let path = &args.manifest;
    let s = match experiment::load_plan(path, &args.set)? {
        Plan::Sweep(s) => s,
        Plan::Single(_) => {
            return Err(CliError::BadInput(format!(
                "{} has no sweep: section: it is one experiment already",
                path.display()
            )));
        }
    };
    let dir = args
        .out
        .unwrap_or_else(|| PathBuf::from("manifests").join(s.folder_name()));
    std::fs::create_dir_all(&dir)
        .map_err(|e| CliError::Internal(format!("cannot create {}: {e}", dir.display())))?;
    let n = s.points.len();
    for (k, point) in s.points.iter().enumerate() {
        let r = &point.resolved;
        let file = dir.join(format!("{}-{}.yaml", r.manifest.name, r.short_hash()));
        // JSON is YAML: the canonical form, under a comment naming the point, with
        // `mps.preset: null` written out, so that it resolves to the same experiment under
        // any default preset (`manifest::default_preset`; the key is not part of the hash).
        let mut value = serde_json::from_str::<serde_json::Value>(&r.canonical)
            .expect("the canonical form is JSON");
        value["mps"]["preset"] = serde_json::Value::Null;
        let pretty = serde_json::to_string_pretty(&value).expect("JSON serializes");
        let text = format!(
            "# Point {}/{n} of sweep {} ({}): {}\n# experiment hash {}\n{pretty}\n",
            k + 1,
            s.hash_hex,
            path.display(),
            point.label(),
            r.hash_hex
        );
        std::fs::write(&file, text)
            .map_err(|e| CliError::Internal(format!("cannot write {}: {e}", file.display())))?;
        println!("{}", file.display());
    }
    Ok(Done::Success)
}

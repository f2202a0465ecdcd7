//! `mps.preset`: one switch for a whole set of scheme fields.
//!
//! A preset names values for a fixed list of fields (which ones depend on the dimension and
//! on whether the fluid has a yield stress). It is resolved before validation and then
//! dropped: the resolved manifest holds the fields themselves, so a run under a preset has
//! the canonical form and hash of the same run with those fields written out, and files
//! written under a preset verify like any other.
//!
//! Precedence, strongest first: a field set by `--set`; a preset set by `--set`; a field
//! written in the file; a preset written in the file; the field's default. So a file may
//! adjust one field of its preset, and `--set mps.preset=...` on a file switches the whole
//! set whatever the file wrote.
//!
//! What a preset sets changes only with a new [`PRESET_REVISION`]; a run file records the
//! revision its source was resolved under, and is taken back up under that one.

use std::collections::BTreeSet;

use serde::{Deserialize, Serialize};
use serde_json::{Value, json};

use super::error::{ManifestError, Result};
use super::locate::SourceMap;
use super::overrides::Touched;
use super::types::Mps;

/// The presets (see [`Mps::preset`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PresetName {
    /// Every field of the quiet set back at its default: the standard scheme and the
    /// regularised law.
    Standard,
    /// The quiet core (docs/validation.md, "Holding still"): the incremental scheme with its
    /// stabilisers; in 2D the pressure regularisation and compressibility; for a fluid with
    /// a yield stress the rigid state by the augmented Lagrangian, with the corrected
    /// first-shell strain rate and no slip at the walls' surface.
    Quiet,
}

impl PresetName {
    /// The manifest's spelling.
    pub fn name(self) -> &'static str {
        match self {
            Self::Standard => "standard",
            Self::Quiet => "quiet",
        }
    }
}

/// The presets' current revision, recorded in every run file (`manifest.preset_revision`; a
/// file without it was written under revision 1):
/// 1. as first landed;
/// 2. `quiet` with a yield stress also sets `mps.wall_face_normals: true`: the one plane
///    fitted to a particle's wall neighbours tilts when the particle is not above a wall
///    particle, and its no-slip factor then grips the bottom row 5-17 % too hard, which kept
///    yielded layers thinner than about a spacing rigid (docs/validation.md, "The wall's
///    grip").
/// 3. `quiet` in 2D also sets `mps.ppe_preconditioner: multigrid` with
///    `mps.multigrid_over_correction: 1.5`: under Jacobi the 2D default's pressure solve
///    needs iterations in proportion to the particles across the domain and failed at a
///    million particles (2000 iterations at the first step); the shipped 2D experiments that
///    name a preconditioner name these (docs/performance.md, "The 2D default's solver").
/// 4. `quiet` in 2D also sets `time.acoustic_courant: 40`: under the fixed `time.dt_max_s` the
///    compressibility's damping falls as l0^2 at the start, and the 2D dam break at 0.35 mm
///    (a million particles) blew up at its sixth step; 40 binds only below 2.5 mm for water
///    and below about 1.6 mm for concrete, so nothing coarser changes (docs/performance.md,
///    "The 2D default's solver").
/// 5. `quiet` in 3D with a yield stress also sets `mps.increment_regularisation: 5` with
///    `mps.regularisation_radius: 1.45`: without a stabiliser that grows with compression,
///    deep disordered 3D material boils under the quiet set (a rock bed after its pour at 3.7
///    J, a deep layer at rest at 0.06 J; with it 1.6e-2 J and 1.6e-10 J), where the 2D set's
///    pressure regularisation brakes thin 3D layers. Water gets none: it stirs the still 3D
///    tank (docs/validation.md, "The quiet 3D yield set takes the increment's
///    regularisation").
/// 6. `quiet` in 3D with a yield stress also sets `mps.yield_penalty_local: true`,
///    `mps.yield_anderson_depth: 5` and `mps.yield_max_iterations: 200`: how the yield solve
///    iterates, not what it solves (the same minimiser); the quiet 3D set spent three
///    quarters of a run there, and these take 0.64 times its time a step (docs/validation.md,
///    "The quiet 3D yield set takes local penalties and Anderson acceleration").
pub const PRESET_REVISION: u32 = 6;

/// The revision a run file records (`manifest.preset_revision`, `None` where absent): 1 for a
/// file from before revisions; an error for one this build does not know.
pub fn recorded_revision(text: Option<&str>) -> std::result::Result<u32, String> {
    let Some(text) = text else {
        return Ok(1);
    };
    text.parse::<u32>()
        .ok()
        .filter(|r| (1..=PRESET_REVISION).contains(r))
        .ok_or_else(|| {
            format!(
                "unknown preset_revision {text:?} (this build knows 1 to {PRESET_REVISION}; written by a newer build?)"
            )
        })
}

/// Who a preset's values are for.
#[derive(Debug, Clone, Copy)]
struct Target {
    dimension: u64,
    yield_stress: bool,
}

/// The quiet set's fields and values for `target`, as dotted paths. Measured in
/// docs/validation.md: the tanks at rest and the dam break (2D and 3D water), the heap, the
/// inclined layer and the slump (the yield sets).
fn quiet_values(target: Target, revision: u32) -> Vec<(&'static str, Value)> {
    let mut v = vec![
        ("mps.pressure_scheme", json!("incremental")),
        ("mps.pair_stabilisation", json!(0.8)),
        ("mps.wall_support", json!(0.95)),
        ("mps.surface_depth", json!(0.5)),
        ("mps.corrected_strain_rate", json!(true)),
    ];
    if target.dimension == 2 {
        // In 3D the first shell of radius 1.5 lets its rows slide (validation refuses it
        // there); the 3D tank is at rest without it.
        v.push(("mps.pressure_regularisation", json!(1.0)));
        // Damps the increment's two-step mode (the rodding at 2.5 mm).
        v.push(("mps.compressibility_1_pa", json!(1.0e-7)));
        if revision >= 3 {
            // In 3D Jacobi is the faster of the two (docs/manifest.md, the field's row).
            v.extend(
                SOLVER_CHOICES
                    .iter()
                    .copied()
                    .zip([json!("multigrid"), json!(1.5)]),
            );
        }
        if revision >= 4 {
            // Keeps the compressibility's share of the increment's diagonal, (l0 / (c dt))^2,
            // at 2.5 mm's at any finer spacing.
            v.push(("time.acoustic_courant", json!(40.0)));
        }
    }
    if target.yield_stress {
        v.extend([
            // The yield solve takes the stress from the multiplier, not from eq. 8's term.
            ("fluid.stress_gradient_term", json!(false)),
            ("mps.wall_surface_no_slip", json!(true)),
            ("mps.strain_rate_radius", json!(1.5)),
            ("mps.yield_penalty_pa_s", json!(1000.0)),
            ("mps.yield_penalty_adaptive", json!(true)),
            ("mps.yield_velocity_fraction", json!(0.1)),
        ]);
        if revision >= 2 {
            v.push(("mps.wall_face_normals", json!(true)));
        }
        if target.dimension == 3 {
            if revision >= 5 {
                // Calms deep disordered 3D material (it acts on a positive increment only);
                // 1.45 keeps the first shell's shear stiffness positive in 3D. Not for water:
                // the still 3D tank grows a mode under it, 0.6 m/s by 2 s (docs/validation.md).
                v.push(("mps.regularisation_radius", json!(1.45)));
                v.push(("mps.increment_regularisation", json!(5.0)));
            }
            if revision >= 6 {
                // Each row's penalty at the law's secant viscosity, and Anderson acceleration
                // with the room it needs to converge: in 2D neither pays (the heap takes as
                // many CG iterations; Anderson slows the 5 mm collapse).
                v.push(("mps.yield_penalty_local", json!(true)));
                v.push(("mps.yield_anderson_depth", json!(5)));
                v.push(("mps.yield_max_iterations", json!(200)));
            }
        }
    }
    v
}

/// The fields of the quiet set that choose how a system is solved, not what is solved (the
/// same solution to the solver's tolerance). `standard` leaves them to the file: the
/// standard scheme with a file's multigrid stays multigrid.
const SOLVER_CHOICES: [&str; 2] = ["mps.ppe_preconditioner", "mps.multigrid_over_correction"];

/// Every scheme field the quiet set may touch (for any dimension; the fluid's own field only
/// for a fluid that has it), at its default; not the solver choices.
fn standard_values(target: Target, revision: u32) -> Vec<(&'static str, Value)> {
    let defaults = serde_json::to_value(Mps::default()).expect("Mps serializes");
    // The paths of either dimension, each once (2D's first, in their order); the quiet
    // values themselves are not needed.
    let mut paths: Vec<&'static str> = Vec::new();
    for dimension in [2, 3] {
        let target = Target {
            dimension,
            yield_stress: true,
        };
        for (path, _) in quiet_values(target, revision) {
            if !paths.contains(&path) {
                paths.push(path);
            }
        }
    }
    paths
        .into_iter()
        .filter(|path| !SOLVER_CHOICES.contains(path))
        .filter_map(|path| match path.split_once('.') {
            Some(("mps", key)) => Some((path, defaults[key].clone())),
            // The only time field: no acoustic bound by default.
            Some(("time", _)) => Some((path, Value::Null)),
            // The only fluid field: eq. 8's term, on by default.
            _ => target.yield_stress.then_some((path, json!(true))),
        })
        .collect()
}

/// The values of `preset` at `revision` for the manifest `root` (its dimension and fluid as
/// they stand).
fn values(preset: PresetName, root: &Value, revision: u32) -> Vec<(&'static str, Value)> {
    let target = Target {
        dimension: root["dimension"].as_u64().unwrap_or(2),
        yield_stress: matches!(
            root["fluid"]["model"].as_str(),
            Some("bingham" | "bi_viscosity")
        ),
    };
    match preset {
        PresetName::Standard => standard_values(target, revision),
        PresetName::Quiet => quiet_values(target, revision),
    }
}

/// What [`resolve`] filled in.
#[derive(Debug, Default)]
pub struct Filled {
    /// The paths the preset set.
    pub paths: BTreeSet<String>,
    /// The default preset, where it applied (neither the file nor an override named one).
    pub by_default: Option<PresetName>,
}

/// Resolves `mps.preset` in `root` (the manifest after its overrides) and sets it to null.
/// `map` locates what the file wrote, `touched` what the overrides set; `default` applies,
/// as if written in the file, where neither names a preset (null written or set names
/// none). `revision`: what the presets set ([`PRESET_REVISION`] for a new run).
pub fn resolve(
    root: &mut Value,
    map: &SourceMap,
    touched: &Touched,
    default: Option<PresetName>,
    revision: u32,
) -> Result<Filled> {
    let raw = root["mps"]["preset"].take();
    let named = touched.is_set("mps.preset") || map.written_pos("mps.preset").is_some();
    let mut filled = Filled::default();
    let preset: PresetName = match (raw.is_null(), named, default) {
        (false, _, _) => {
            serde_json::from_value(raw.clone()).map_err(|_| ManifestError::Override {
                key: "mps.preset".to_string(),
                message: format!("unknown preset {raw}; expected `standard` or `quiet`"),
            })?
        }
        (true, false, Some(preset)) => {
            filled.by_default = Some(preset);
            preset
        }
        (true, _, _) => return Ok(filled),
    };
    let from_set = touched.is_set("mps.preset");
    for (path, value) in values(preset, root, revision) {
        let written = map.written_pos(path).is_some() && !touched.is_reset(path);
        if touched.is_set(path) || (!from_set && written) {
            continue;
        }
        let (section, key) = path.split_once('.').expect("dotted path");
        root[section][key] = value;
        filled.paths.insert(path.to_string());
    }
    Ok(filled)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every scheme field of the quiet set is set back by `standard`; the solver choices are
    /// left to the file.
    #[test]
    fn the_standard_preset_names_every_field_the_quiet_one_may_set() {
        for dimension in [2, 3] {
            for yield_stress in [false, true] {
                let t = Target {
                    dimension,
                    yield_stress,
                };
                for revision in 1..=PRESET_REVISION {
                    let standard: BTreeSet<_> = standard_values(t, revision)
                        .into_iter()
                        .map(|p| p.0)
                        .collect();
                    for (path, value) in quiet_values(t, revision) {
                        if SOLVER_CHOICES.contains(&path) {
                            assert!(!standard.contains(path), "{path}");
                            assert!(dimension == 2 && revision >= 3, "{path}");
                            continue;
                        }
                        assert!(standard.contains(path), "{path}");
                        let back = standard_values(t, revision)
                            .into_iter()
                            .find(|p| p.0 == path)
                            .unwrap()
                            .1;
                        assert_ne!(back, value, "{path}: the quiet value is the default");
                    }
                }
            }
        }
    }
}

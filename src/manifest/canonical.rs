//! Canonical text of a resolved manifest and its SHA-256.
//!
//! Canonical form: compact JSON (no whitespace) of the fully resolved manifest, object keys
//! sorted (serde_json's default `Map` is a `BTreeMap`: the `preserve_order` feature must stay
//! off, which a test checks), `f64` fields always written as floats in serde_json's shortest
//! round-trip form, `-0.0` written as `0.0`, integers as integers. Settings added after the
//! format was first used are left out while they are at their original behaviour
//! (`mps.ppe_preconditioner: jacobi`, `mps.multigrid_over_correction` at 1 or under Jacobi,
//! `mps.pressure_scheme: standard` with
//! `mps.compression_relaxation`, `mps.pair_stabilisation`, `mps.wall_support` and
//! `mps.pressure_regularisation` and `mps.increment_regularisation` (with
//! `mps.regularisation_radius`), `mps.deep_surface_threshold` (with `mps.deep_surface_head`),
//! `mps.surface_depth`,
//! `mps.pressure_smoothing_time_s` and
//! `mps.particle_shifting` (with `mps.particle_shifting_limit`) at 0 (and under the standard
//! scheme), `mps.pressure_floor_pa` at 0, `mps.yield_penalty_pa_s` at 0 (with
//! `mps.yield_max_iterations` and `mps.yield_tolerance_1_s`), `mps.yield_velocity_fraction` and
//! `mps.yield_anderson_depth` at 0, `mps.yield_penalty_local`, `mps.yield_velocity_relative`, `mps.corrected_strain_rate`, `mps.wall_surface_no_slip`, `mps.wall_face_normals`, `mps.wall_curvature`, `mps.quadratic_strain_rate`
//! `mps.exact_projection`, `mps.conservative_gradient`, `mps.adjoint_projection` and `mps.periodic_hydrostatic` (also under the standard scheme) false, `stop.rest_*` without
//! `stop.rest_metric`, null `mps.wall_collision_*`, `mps.strain_rate_radius`,
//! `mps.viscous_laplacian_radius`, `time.dt_min_s`, `time.acoustic_courant`, `stop.max_ghost_particles` and the rod's,
//! the cone's and the bodies' slip lengths, the inclined layer's width and the side walls' slip length (inclined layer, tank), an empty `boundaries` section), so every
//! experiment keeps the hash it had before they existed and files written then still verify. JSON is YAML, so the canonical text loads back through
//! [`super::from_str`] to the same manifest and hash.

use serde_json::Value;
use sha2::{Digest, Sha256};

use super::types::{Manifest, PpePreconditioner, PressureSchemeName, SceneSection};

/// Replace every `-0.0` in `value` by `0.0`.
pub fn normalise_negative_zero(value: &mut Value) {
    match value {
        // -0.0 == 0.0, so this rewrites both zeros as +0.0.
        Value::Number(n) if n.is_f64() && n.as_f64() == Some(0.0) => {
            *n = serde_json::Number::from_f64(0.0).expect("0.0 is finite");
        }
        Value::Array(items) => items.iter_mut().for_each(normalise_negative_zero),
        Value::Object(map) => map.values_mut().for_each(normalise_negative_zero),
        _ => {}
    }
}

/// The canonical JSON text of `manifest`.
pub fn canonical_text<S: SceneSection>(manifest: &Manifest<S>) -> String {
    let mut value = serde_json::to_value(manifest).expect("a manifest always serializes to JSON");
    normalise_negative_zero(&mut value);
    // A preset is resolved into its fields before the manifest is typed (`preset::resolve`);
    // the key itself never reaches the canonical form.
    if let Some(mps) = value.get_mut("mps").and_then(Value::as_object_mut) {
        mps.remove("preset");
    }
    if manifest.mps.ppe_preconditioner == PpePreconditioner::Jacobi
        && let Some(mps) = value.get_mut("mps").and_then(Value::as_object_mut)
    {
        mps.remove("ppe_preconditioner");
    }
    // Plain aggregation (1), or a factor Jacobi never reads: the behaviour before the field.
    if (manifest.mps.multigrid_over_correction == 1.0
        || manifest.mps.ppe_preconditioner == PpePreconditioner::Jacobi)
        && let Some(mps) = value.get_mut("mps").and_then(Value::as_object_mut)
    {
        mps.remove("multigrid_over_correction");
    }
    // The f64 smoother (the behaviour before the field), or a choice Jacobi never reads.
    if (!manifest.mps.multigrid_single_precision
        || manifest.mps.ppe_preconditioner == PpePreconditioner::Jacobi)
        && let Some(mps) = value.get_mut("mps").and_then(Value::as_object_mut)
    {
        mps.remove("multigrid_single_precision");
    }
    if manifest.mps.pressure_scheme == PressureSchemeName::Standard
        && let Some(mps) = value.get_mut("mps").and_then(Value::as_object_mut)
    {
        // The standard scheme does not read the incremental scheme's relaxation.
        mps.remove("pressure_scheme");
        mps.remove("compression_relaxation");
    }
    if let Some(mps) = value.get_mut("mps").and_then(Value::as_object_mut) {
        // Off (0) is the behaviour before the fields existed; the standard scheme reads
        // none of them.
        for (key, v) in [
            ("pair_stabilisation", manifest.mps.pair_stabilisation),
            ("wall_support", manifest.mps.wall_support),
            (
                "pressure_regularisation",
                manifest.mps.pressure_regularisation,
            ),
            (
                "increment_regularisation",
                manifest.mps.increment_regularisation,
            ),
            (
                "deep_surface_threshold",
                manifest.mps.deep_surface_threshold,
            ),
            ("surface_depth", manifest.mps.surface_depth),
            ("particle_shifting", manifest.mps.particle_shifting),
            (
                "pressure_smoothing_time_s",
                manifest.mps.pressure_smoothing_time_s,
            ),
        ] {
            if v == 0.0 || manifest.mps.pressure_scheme == PressureSchemeName::Standard {
                mps.remove(key);
            }
        }
        // 0 is the clip of negative pressure before the field existed (both schemes read it).
        if manifest.mps.pressure_floor_pa == 0.0 {
            mps.remove("pressure_floor_pa");
        }
        // 0 is the yield solve's velocity steps at the viscous tolerance, as before the field.
        if manifest.mps.yield_velocity_fraction == 0.0 {
            mps.remove("yield_velocity_fraction");
        }
        // 0 is the plain iterations, as before the field.
        if manifest.mps.yield_anderson_depth == 0 {
            mps.remove("yield_anderson_depth");
        }
        // The radius is read only with a regularisation on, the limit only with shifting.
        if !mps.contains_key("pressure_regularisation")
            && !mps.contains_key("increment_regularisation")
        {
            mps.remove("regularisation_radius");
        }
        if !mps.contains_key("particle_shifting") {
            mps.remove("particle_shifting_limit");
        }
        if !mps.contains_key("deep_surface_threshold") {
            mps.remove("deep_surface_head");
        }
        // The regularised law (penalty 0) is the behaviour before the yield solve existed.
        if manifest.mps.yield_penalty_pa_s == 0.0 {
            for key in [
                "yield_penalty_pa_s",
                "yield_max_iterations",
                "yield_tolerance_1_s",
                "yield_penalty_adaptive",
                "yield_penalty_local",
                "yield_velocity_relative",
                "yield_consistent_divergence",
                "yield_volumetric_limit",
            ] {
                mps.remove(key);
            }
        }
        // The switches: off (false) is the behaviour before they existed; the exact projection
        // is read by the incremental scheme only.
        let incremental = manifest.mps.pressure_scheme != PressureSchemeName::Standard;
        for (key, on) in [
            ("corrected_strain_rate", manifest.mps.corrected_strain_rate),
            ("wall_surface_no_slip", manifest.mps.wall_surface_no_slip),
            ("wall_face_normals", manifest.mps.wall_face_normals),
            ("wall_curvature", manifest.mps.wall_curvature),
            ("quadratic_strain_rate", manifest.mps.quadratic_strain_rate),
            (
                "yield_penalty_adaptive",
                manifest.mps.yield_penalty_adaptive,
            ),
            ("yield_penalty_local", manifest.mps.yield_penalty_local),
            (
                "yield_velocity_relative",
                manifest.mps.yield_velocity_relative,
            ),
            (
                "yield_consistent_divergence",
                manifest.mps.yield_consistent_divergence,
            ),
            (
                "conservative_gradient",
                manifest.mps.conservative_gradient && incremental,
            ),
            (
                "exact_projection",
                manifest.mps.exact_projection && incremental,
            ),
            (
                "adjoint_projection",
                manifest.mps.adjoint_projection && incremental,
            ),
            (
                "periodic_hydrostatic",
                manifest.mps.periodic_hydrostatic && incremental,
            ),
        ] {
            if !on {
                mps.remove(key);
            }
        }
    }
    for (section, key) in [
        ("mps", "wall_collision_distance"),
        ("mps", "wall_collision_second_pass"),
        ("mps", "strain_rate_radius"),
        ("mps", "viscous_laplacian_radius"),
        ("mps", "yield_volumetric_limit"),
        ("mps", "solid_wall_layers"),
        ("time", "dt_min_s"),
        ("time", "acoustic_courant"),
        ("stop", "max_ghost_particles"),
        ("scene", "rod_slip_length_m"),
        ("scene", "cone_slip_length_m"),
        ("scene", "width_m"),
        ("scene", "side_slip_length_m"),
        ("scene", "floor_slip_length_m"),
        ("scene", "disorder"),
        ("scene", "disorder_seed"),
    ] {
        // null = the rule that held before these fields existed.
        if let Some(map) = value.get_mut(section).and_then(Value::as_object_mut)
            && map.get(key).is_some_and(Value::is_null)
        {
            map.remove(key);
        }
    }
    // The whole slump and L-B box are the scenes as they were before the quarter and the
    // half existed.
    if let Some(scene) = value.get_mut("scene").and_then(Value::as_object_mut) {
        for key in ["quarter_domain", "half_domain"] {
            if scene.get(key) == Some(&Value::Bool(false)) {
                scene.remove(key);
            }
        }
    }
    // A body without a slip length carries its velocity as walls did before the field.
    if let Some(bodies) = value
        .pointer_mut("/boundaries/bodies")
        .and_then(Value::as_array_mut)
    {
        for body in bodies.iter_mut().filter_map(Value::as_object_mut) {
            if body.get("slip_length_m").is_some_and(Value::is_null) {
                body.remove("slip_length_m");
            }
        }
    }
    if manifest.boundaries.is_empty()
        && let Some(top) = value.as_object_mut()
    {
        top.remove("boundaries");
    }
    if manifest.stop.rest_metric.is_none()
        && let Some(stop) = value.get_mut("stop").and_then(Value::as_object_mut)
    {
        // Without a rest metric these have no effect on the run.
        for key in ["rest_metric", "rest_metric_change", "rest_after_s"] {
            stop.remove(key);
        }
    }
    serde_json::to_string(&value).expect("a JSON value always serializes")
}

/// The first 12 hex digits of a hash, as file and folder names carry it (all of a shorter
/// one, and never half a character of a damaged one read from a file).
pub fn short_hash(hash_hex: &str) -> &str {
    hash_hex.get(..12).unwrap_or(hash_hex)
}

/// Lowercase hex SHA-256 of the UTF-8 bytes of `text`.
pub fn sha256_hex(text: &str) -> String {
    hex::encode(Sha256::digest(text.as_bytes()))
}

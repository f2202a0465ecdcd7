//! Manifest loading, validation, overrides, canonical form and hash.

use std::path::Path;

use crate::common;

use mps_runner::experiment;
use mps_runner::experiment::dam_break::DamBreak;
use mps_runner::experiment::{Resolved, SceneSpec};
use mps_runner::manifest::{self, Fluid, ManifestError};

/// A manifest with every field written out (values as in experiments/dam_break_2d.yaml).
const FULL: &str = "\
# a full manifest
name: full_example
dimension: 2
spacing_m: 0.01
gravity_m_s2: 9.81
time:
  end_s: 1.0
  dt_max_s: 1.0e-3
  courant: 0.2
fluid:
  model: newtonian
  density_kg_m3: 1000.0
  viscosity_pa_s: 1.0e-3
mps:
  number_density_radius: 2.1
  laplacian_radius: 3.1
  surface_threshold: 0.97
  relaxation_coefficient: 0.2
  compressibility_1_pa: 0.45e-9
  collision_distance: 0.5
  collision_restitution: 0.2
  ppe_tolerance: 1.0e-6
  ppe_max_iterations: 2000
  wall_layers: 1
  dummy_layers: 2
scene:
  kind: dam_break
  tank_width_m: 1.0
  tank_height_m: 0.6
  tank_depth_m: 0.1
  column_width_m: 0.25
  column_height_m: 0.5
output:
  checkpoint_interval_s: 0.1
  cloud_interval_s: 0.02
  diagnostics_interval_s: 0.005
stop:
  max_steps: 10000000
  max_speed_m_s: 100.0
";

/// The same experiment with only the required fields.
const MINIMAL: &str = "\
name: full_example
dimension: 2
spacing_m: 0.01
time:
  end_s: 1
fluid:
  model: newtonian
  density_kg_m3: 1000
  viscosity_pa_s: 0.001
scene:
  kind: dam_break
";

fn ok(text: &str) -> Resolved {
    ok_with(text, &[])
}

/// These tests of parsing, overrides, validation and hashing read a manifest as it was read
/// before the 2D default preset (`from_str_under(.., None)`), so that FULL, which writes
/// every default out, stays MINIMAL's experiment; the default's own tests use
/// `experiment::from_str`.
fn ok_with(text: &str, overrides: &[&str]) -> Resolved {
    let overrides: Vec<String> = overrides.iter().map(|s| s.to_string()).collect();
    match manifest::from_str_under(text, "exp.yaml", &overrides, None) {
        Ok(r) => r,
        Err(e) => panic!("expected success, got: {e}"),
    }
}

fn err(text: &str) -> ManifestError {
    err_with(text, &[])
}

fn err_with(text: &str, overrides: &[&str]) -> ManifestError {
    let overrides: Vec<String> = overrides.iter().map(|s| s.to_string()).collect();
    match manifest::from_str_under::<SceneSpec>(text, "exp.yaml", &overrides, None) {
        Ok(r) => panic!("expected an error, got a manifest: {}", r.canonical),
        Err(e) => e,
    }
}

/// Replace exactly one occurrence of `from`.
fn edit(text: &str, from: &str, to: &str) -> String {
    assert_eq!(text.matches(from).count(), 1, "{from:?} must occur once");
    text.replacen(from, to, 1)
}

/// 1-based (line, column) of the first occurrence of `needle` in `text`, plus `offset` chars.
fn pos_of(text: &str, needle: &str, offset: usize) -> (usize, usize) {
    let i = text.find(needle).expect("needle present");
    let line = text[..i].matches('\n').count() + 1;
    let col = text[..i].rfind('\n').map_or(i, |nl| i - nl - 1) + 1 + offset;
    (line, col)
}

// ---------------------------------------------------------------- parsing and round trip

#[test]
fn full_manifest_parses_and_defaults_are_filled() {
    let r = ok(FULL);
    let m = &r.manifest;
    assert_eq!(m.name, "full_example");
    assert_eq!(m.dimension, 2);
    assert_eq!(m.spacing_m, 0.01);
    assert_eq!(m.fluid.model_name(), "newtonian");
    assert_eq!(m.scene_kind(), "dam_break");
    assert_eq!(
        m.fluid,
        Fluid::Newtonian {
            density_kg_m3: 1000.0,
            viscosity_pa_s: 1.0e-3
        }
    );
    assert_eq!(m.mps.compressibility_1_pa, 0.45e-9);
    assert_eq!(r.source_text, FULL);
    assert!(r.overrides.is_empty());

    let min = ok(MINIMAL);
    let d = &min.manifest;
    assert_eq!(d.gravity_m_s2, 9.81);
    assert_eq!(d.time.dt_max_s, 1.0e-3);
    assert_eq!(d.time.courant, 0.2);
    // The documented defaults (docs/manifest.md table), written out rather than compared with the
    // library's own Default.
    assert_eq!(d.mps.source_term, manifest::PpeSource::NumberDensity);
    assert_eq!(
        d.mps.ppe_preconditioner,
        manifest::PpePreconditioner::Jacobi
    );
    assert_eq!(d.mps.wall_collision_distance, None);
    assert_eq!(d.mps.wall_collision_second_pass, None);
    assert_eq!(d.mps.surface_threshold, 0.97);
    assert_eq!(d.mps.relaxation_coefficient, 0.2);
    assert_eq!(d.mps.collision_distance, 0.5);
    assert_eq!(d.mps.ppe_tolerance, 1e-6);
    assert_eq!(d.mps.wall_layers, 1);
    assert_eq!(d.mps.number_density_radius, 2.1);
    assert_eq!(d.mps.laplacian_radius, 3.1);
    assert_eq!(d.mps.ppe_max_iterations, 2000);
    assert_eq!(d.mps.dummy_layers, 2);
    assert_eq!(
        d.scene,
        SceneSpec::DamBreak(DamBreak {
            tank_width_m: 1.0,
            tank_height_m: 0.6,
            tank_depth_m: 0.1,
            column_width_m: 0.25,
            column_height_m: 0.5,
            side_slip_length_m: None,
        })
    );
    assert_eq!(d.output.checkpoint_interval_s, 0.1);
    assert_eq!(d.output.diagnostics_interval_s, 0.005);
    assert_eq!(d.output.cloud_interval_s, 0.02);
    assert_eq!(d.stop.max_steps, 10_000_000);
    assert_eq!(d.stop.max_speed_m_s, 100.0);
    // Writing every default out is the same experiment.
    assert_eq!(d, m);
}

#[test]
fn hash_format() {
    let r = ok(FULL);
    // The hash is the SHA-256 of the canonical text, computed here without the library's
    // hashing code.
    use sha2::Digest;
    assert_eq!(
        r.hash_hex,
        hex::encode(sha2::Sha256::digest(r.canonical.as_bytes()))
    );
    assert_eq!(
        manifest::canonical::sha256_hex(""),
        "e3b0c44298fc1c149afbf4c8996fb92427ae41e4649b934ca495991b7852b855"
    );
}

#[test]
fn canonical_form_is_compact_sorted_json() {
    let r = ok(FULL);
    let c = &r.canonical;
    assert!(!c.contains(' ') && !c.contains('\n'), "{c}");
    assert!(c.starts_with(r#"{"dimension":2,"fluid":{"density_kg_m3":1000.0,"model":"newtonian","viscosity_pa_s":0.001},"gravity_m_s2":9.81,"mps":{"#), "{c}");
    // floats stay floats, integers stay integers
    assert!(c.contains(r#""tank_width_m":1.0"#), "{c}");
    assert!(c.contains(r#""ppe_max_iterations":2000,"#), "{c}");
    assert!(c.contains(r#""compressibility_1_pa":4.5e-10"#), "{c}");
    // Keys are sorted because serde_json's map is ordered (its `preserve_order` feature is
    // off): keys inserted out of order come out sorted.
    assert_eq!(
        serde_json::to_string(&serde_json::json!({"b": 1, "a": {"d": 2, "c": 3}})).unwrap(),
        r#"{"a":{"c":3,"d":2},"b":1}"#
    );
    let top: Vec<&str> = c
        .match_indices(r#""name""#)
        .map(|(i, _)| &c[i..i + 6])
        .collect();
    assert_eq!(top.len(), 1);
    assert!(c.find(r#""dimension""#) < c.find(r#""name""#));
}

#[test]
fn canonical_text_round_trips() {
    for text in [
        FULL,
        MINIMAL,
        // values that serde_json writes in exponent form, also inside the tagged sections
        &edit(MINIMAL, "viscosity_pa_s: 0.001", "viscosity_pa_s: 1.0e-7"),
        &edit(MINIMAL, "density_kg_m3: 1000", "density_kg_m3: 1.5e21"),
    ] {
        let r = ok(text);
        let again = ok(&r.canonical);
        assert_eq!(again.manifest, r.manifest);
        assert_eq!(again.canonical, r.canonical);
        assert_eq!(again.hash_hex, r.hash_hex);
    }
    // with overrides applied, the canonical text holds them
    let r = ok_with(MINIMAL, &["spacing_m=0.02", "scene.tank_width_m=2"]);
    let again = ok(&r.canonical);
    assert_eq!(again.manifest, r.manifest);
    assert_eq!(again.hash_hex, r.hash_hex);
}

#[test]
fn example_files_parse() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    // Under the standard scheme: the file leaves the compressibility to the 2D default preset.
    let standard = ["mps.preset=standard".to_string()];
    let d = experiment::load(&root.join("experiments/dam_break_2d.yaml"), &standard).unwrap();
    let m = &d.manifest;
    assert_eq!(m.name, "dam_break_2d");
    assert_eq!(m.dimension, 2);
    assert_eq!(m.spacing_m, 0.01);
    assert_eq!(m.time.end_s, 1.0);
    assert_eq!(m.fluid.density_kg_m3(), 1000.0);
    assert_eq!(m.output.checkpoint_interval_s, 0.1);
    assert_eq!(m.output.cloud_interval_s, 0.02);
    assert_eq!(m.output.diagnostics_interval_s, 0.005);
    // Its values are FULL's (defaults written out), except for the name and the multigrid
    // preconditioner with its over-correction (the default stays Jacobi, which earlier files
    // used).
    let full = ok(&edit(
        &edit(FULL, "name: full_example", "name: dam_break_2d"),
        "  ppe_tolerance:",
        "  ppe_preconditioner: multigrid\n  multigrid_over_correction: 1.5\n  ppe_tolerance:",
    ));
    assert_eq!(d.manifest, full.manifest);
    assert_eq!(d.hash_hex, full.hash_hex);

    let s = experiment::load(&root.join("experiments/smoke_2d.yaml"), &[]).unwrap();
    let m = &s.manifest;
    assert_eq!(m.name, "smoke_2d");
    assert_eq!(m.spacing_m, 0.025);
    assert_eq!(m.time.end_s, 0.1);
    assert_eq!(m.output.checkpoint_interval_s, 0.02);
    let SceneSpec::DamBreak(DamBreak {
        tank_width_m,
        tank_height_m,
        column_width_m,
        column_height_m,
        ..
    }) = m.scene
    else {
        panic!("smoke_2d is a dam break")
    };
    assert_eq!(
        (tank_width_m, tank_height_m, column_width_m, column_height_m),
        (0.5, 0.4, 0.15, 0.3)
    );
    assert_ne!(s.hash_hex, d.hash_hex);
}

// ---------------------------------------------------------------- hash invariance

#[test]
fn hash_ignores_presentation_and_defaults() {
    let base = ok(MINIMAL).hash_hex;
    let variants = [
        // comments and blank lines
        format!("# comment\n\n{}", edit(MINIMAL, "dimension: 2", "dimension: 2   # 2D")),
        // key order, top level and nested
        "scene:\n  kind: dam_break\nfluid:\n  viscosity_pa_s: 0.001\n  density_kg_m3: 1000\n  model: newtonian\ntime:\n  end_s: 1\nspacing_m: 0.01\ndimension: 2\nname: full_example\n".to_string(),
        // number spellings
        edit(MINIMAL, "end_s: 1", "end_s: 1.0"),
        edit(MINIMAL, "end_s: 1", "end_s: 1.00"),
        edit(MINIMAL, "end_s: 1", "end_s: 1e0"),
        edit(MINIMAL, "spacing_m: 0.01", "spacing_m: 1.0e-2"),
        edit(MINIMAL, "density_kg_m3: 1000", "density_kg_m3: 1000.000"),
        // flow style, quoting
        edit(MINIMAL, "time:\n  end_s: 1\n", "time: {end_s: 1}\n"),
        edit(MINIMAL, "name: full_example", "name: \"full_example\""),
        // explicit defaults
        edit(MINIMAL, "spacing_m: 0.01\n", "spacing_m: 0.01\ngravity_m_s2: 9.81\nmps:\n  laplacian_radius: 3.1\nstop: {}\n"),
        edit(MINIMAL, "  kind: dam_break\n", "  kind: dam_break\n  tank_width_m: 1\n  column_height_m: 0.5\n"),
        edit(MINIMAL, "  end_s: 1\n", "  end_s: 1\n  courant: 0.2\n  dt_max_s: 0.001\n"),
        FULL.to_string(),
    ];
    for v in &variants {
        assert_eq!(ok(v).hash_hex, base, "different hash for:\n{v}");
    }
    // An override that sets the value already there changes nothing either.
    assert_eq!(ok_with(MINIMAL, &["time.courant=0.2"]).hash_hex, base);
    assert_eq!(ok_with(MINIMAL, &["fluid.model=newtonian"]).hash_hex, base);
    // The multigrid over-correction at plain aggregation (1), or under Jacobi, which never
    // reads it, is the experiment before the field existed; under multigrid it is part of it.
    assert_eq!(
        ok_with(MINIMAL, &["mps.multigrid_over_correction=1"]).hash_hex,
        base
    );
    assert_eq!(
        ok_with(MINIMAL, &["mps.multigrid_over_correction=1.5"]).hash_hex,
        base
    );
    let multigrid = ok_with(MINIMAL, &["mps.ppe_preconditioner=multigrid"]).hash_hex;
    assert_ne!(
        ok_with(
            MINIMAL,
            &[
                "mps.ppe_preconditioner=multigrid",
                "mps.multigrid_over_correction=1.5"
            ]
        )
        .hash_hex,
        multigrid
    );
}

#[test]
fn negative_zero_is_normalised() {
    let pos = ok(&edit(
        MINIMAL,
        "spacing_m: 0.01\n",
        "spacing_m: 0.01\ngravity_m_s2: 0.0\n",
    ));
    let neg = ok(&edit(
        MINIMAL,
        "spacing_m: 0.01\n",
        "spacing_m: 0.01\ngravity_m_s2: -0.0\n",
    ));
    assert_eq!(pos.hash_hex, neg.hash_hex);
    assert!(neg.canonical.contains(r#""gravity_m_s2":0.0"#));
    assert!(neg.manifest.gravity_m_s2.is_sign_positive());
    let over = ok_with(MINIMAL, &["gravity_m_s2=-0.0"]);
    assert_eq!(over.hash_hex, pos.hash_hex);
}

// ---------------------------------------------------------------- hash sensitivity

#[test]
fn hash_changes_with_every_value() {
    let base = ok(FULL);
    let mut seen = vec![base.hash_hex.clone()];
    for (from, to) in [
        ("spacing_m: 0.01", "spacing_m: 0.011"),
        ("name: full_example", "name: full_example2"),
        ("dimension: 2", "dimension: 3"),
        ("gravity_m_s2: 9.81", "gravity_m_s2: 9.8"),
        ("end_s: 1.0", "end_s: 1.5"),
        ("courant: 0.2", "courant: 0.25"),
        ("density_kg_m3: 1000.0", "density_kg_m3: 998.2"),
        ("viscosity_pa_s: 1.0e-3", "viscosity_pa_s: 1.002e-3"),
        ("laplacian_radius: 3.1", "laplacian_radius: 4.0"),
        (
            "compressibility_1_pa: 0.45e-9",
            "compressibility_1_pa: 0.46e-9",
        ),
        ("ppe_max_iterations: 2000", "ppe_max_iterations: 2001"),
        ("dummy_layers: 2", "dummy_layers: 3"),
        ("tank_width_m: 1.0", "tank_width_m: 1.2"),
        ("column_height_m: 0.5", "column_height_m: 0.4"),
        ("tank_depth_m: 0.1", "tank_depth_m: 0.2"),
        ("cloud_interval_s: 0.02", "cloud_interval_s: 0.01"),
        ("max_steps: 10000000", "max_steps: 10000001"),
        ("max_speed_m_s: 100.0", "max_speed_m_s: 50.0"),
    ] {
        let h = ok(&edit(FULL, from, to)).hash_hex;
        assert!(!seen.contains(&h), "hash did not change for {to}");
        seen.push(h);
    }
    // The solids' wall layers: null is the rule before the field (the hash of a manifest
    // without it), a number changes the experiment.
    let null = ok(&edit(
        FULL,
        "dummy_layers: 2",
        "dummy_layers: 2\n  solid_wall_layers: null",
    ));
    assert_eq!(null.hash_hex, base.hash_hex);
    let two = ok(&edit(
        FULL,
        "dummy_layers: 2",
        "dummy_layers: 2\n  solid_wall_layers: 2",
    ));
    assert!(!seen.contains(&two.hash_hex));
    // the smallest change of a float shows
    let next = f64::from_bits(0.01f64.to_bits() + 1);
    let h = ok(&edit(
        FULL,
        "spacing_m: 0.01",
        &format!("spacing_m: {next:?}"),
    ))
    .hash_hex;
    assert_ne!(h, base.hash_hex);
}

#[test]
fn override_equals_writing_the_value() {
    let written = ok(&edit(MINIMAL, "spacing_m: 0.01", "spacing_m: 0.02"));
    let over = ok_with(MINIMAL, &["spacing_m=0.02"]);
    assert_eq!(over.manifest.spacing_m, 0.02);
    assert_eq!(over.hash_hex, written.hash_hex);
    assert_ne!(over.hash_hex, ok(MINIMAL).hash_hex);
    assert_eq!(over.overrides, vec!["spacing_m=0.02".to_string()]);
    assert_eq!(over.source_text, MINIMAL);

    // nested, integer for a float field, later overrides win
    let written = ok(&edit(
        &edit(MINIMAL, "  end_s: 1\n", "  end_s: 2.5\n"),
        "  kind: dam_break\n",
        "  kind: dam_break\n  column_width_m: 0.3\n",
    ));
    let over = ok_with(
        MINIMAL,
        &["time.end_s=3", "scene.column_width_m=0.3", "time.end_s=2.5"],
    );
    assert_eq!(over.hash_hex, written.hash_hex);

    // integers, strings, a plain number for a string field
    let over = ok_with(MINIMAL, &["mps.wall_layers=2", "name=2024"]);
    assert_eq!(over.manifest.mps.wall_layers, 2);
    assert_eq!(over.manifest.name, "2024");
    let written = ok(&edit(MINIMAL, "name: full_example", "name: '2024'"));
    assert_eq!(written.manifest.name, "2024");

    // an override can repair an invalid file value
    let fixed = ok_with(
        &edit(MINIMAL, "spacing_m: 0.01", "spacing_m: -1"),
        &["spacing_m=0.01"],
    );
    assert_eq!(fixed.hash_hex, ok(MINIMAL).hash_hex);
}

// ---------------------------------------------------------------- errors

fn assert_syntax(e: &ManifestError, field: &str, at: Option<(usize, usize)>, needles: &[&str]) {
    let ManifestError::Syntax {
        field: f,
        line,
        column,
        source_name,
        message,
    } = e
    else {
        panic!("expected a Syntax error, got {e:?}");
    };
    assert_eq!(source_name, "exp.yaml");
    assert_eq!(f.as_deref(), Some(field), "{e}");
    if let Some((l, c)) = at {
        assert_eq!((*line, *column), (Some(l), Some(c)), "{e}");
    }
    for n in needles {
        assert!(message.contains(n), "{n:?} not in {e}");
    }
}

fn assert_invalid(e: &ManifestError, field: &str, at: Option<(usize, usize)>, needles: &[&str]) {
    let ManifestError::Invalid {
        field: f,
        line,
        column,
        message,
        ..
    } = e
    else {
        panic!("expected an Invalid error, got {e:?}");
    };
    assert_eq!(f, field, "{e}");
    assert_eq!((*line, *column), (at.map(|a| a.0), at.map(|a| a.1)), "{e}");
    for n in needles {
        assert!(message.contains(n), "{n:?} not in {e}");
    }
}

fn assert_override(e: &ManifestError, key: &str, needles: &[&str]) {
    let ManifestError::Override { key: k, message } = e else {
        panic!("expected an Override error, got {e:?}");
    };
    assert_eq!(k, key, "{e}");
    for n in needles {
        assert!(message.contains(n), "{n:?} not in {e}");
    }
}

#[test]
fn unknown_field_is_named_and_located() {
    let text = edit(MINIMAL, "spacing_m: 0.01", "spcing_m: 0.01");
    let e = err(&text);
    assert_syntax(
        &e,
        "spcing_m",
        Some(pos_of(&text, "spcing_m", 0)),
        &["unknown field `spcing_m`", "spacing_m"],
    );
    assert_eq!(
        e.to_string().split(": ").take(2).collect::<Vec<_>>(),
        ["exp.yaml:3:1", "spcing_m"]
    );

    let text = edit(MINIMAL, "  end_s: 1\n", "  end_s: 1\n  ends: 2\n");
    assert_syntax(
        &err(&text),
        "time.ends",
        Some(pos_of(&text, "ends:", 0)),
        &["unknown field `ends`", "in `time`"],
    );

    // inside the internally tagged sections too
    let text = edit(
        MINIMAL,
        "  kind: dam_break\n",
        "  kind: dam_break\n  tank_widht_m: 1\n",
    );
    assert_syntax(
        &err(&text),
        "scene.tank_widht_m",
        Some(pos_of(&text, "tank_widht_m", 0)),
        &["tank_width_m"],
    );
    let text = edit(
        MINIMAL,
        "  model: newtonian\n",
        "  model: newtonian\n  yield_stress_pa: 50\n",
    );
    assert_syntax(
        &err(&text),
        "fluid.yield_stress_pa",
        Some(pos_of(&text, "yield_stress_pa", 0)),
        &["unknown field"],
    );
}

#[test]
fn missing_required_field() {
    let e = err(&edit(MINIMAL, "  end_s: 1\n", "  courant: 0.3\n"));
    assert_syntax(
        &e,
        "time.end_s",
        Some((4, 1)),
        &["missing required field `end_s`", "in `time`"],
    );
    let e = err(&edit(MINIMAL, "spacing_m: 0.01\n", ""));
    assert_syntax(
        &e,
        "spacing_m",
        Some((1, 1)),
        &["missing required field `spacing_m`"],
    );
    let e = err(&edit(MINIMAL, "  density_kg_m3: 1000\n", ""));
    assert_syntax(
        &e,
        "fluid.density_kg_m3",
        Some((6, 1)),
        &["`density_kg_m3`", "in `fluid`"],
    );
    let e = err(&edit(MINIMAL, "scene:\n  kind: dam_break\n", ""));
    assert_syntax(&e, "scene", None, &["missing required field `scene`"]);
    let e = err(&edit(MINIMAL, "  kind: dam_break\n", "  tank_width_m: 1\n"));
    assert!(e.to_string().contains("kind"), "{e}");
}

#[test]
fn wrong_type() {
    let text = edit(MINIMAL, "spacing_m: 0.01", "spacing_m: ten");
    assert_syntax(
        &err(&text),
        "spacing_m",
        Some(pos_of(&text, "ten", 0)),
        &["ten"],
    );
    let text = edit(MINIMAL, "dimension: 2", "dimension: 2.5");
    assert_syntax(&err(&text), "dimension", Some(pos_of(&text, "2.5", 0)), &[]);
    let text = edit(MINIMAL, "density_kg_m3: 1000", "density_kg_m3: heavy");
    assert_syntax(
        &err(&text),
        "fluid.density_kg_m3",
        Some(pos_of(&text, "heavy", 0)),
        &["heavy", "f64"],
    );
    let text = edit(MINIMAL, "time:\n  end_s: 1\n", "time: 1\n");
    assert_syntax(&err(&text), "time", Some(pos_of(&text, "time: 1", 6)), &[]);
    let text = edit(MINIMAL, "model: newtonian", "model: herschel_bulkley");
    assert_syntax(
        &err(&text),
        "fluid.model",
        Some(pos_of(&text, "herschel_bulkley", 0)),
        &["unknown variant `herschel_bulkley`", "newtonian"],
    );
}

#[test]
fn invalid_values_are_named_and_located() {
    let text = edit(MINIMAL, "  end_s: 1\n", "  end_s: 1\n  courant: 1.5\n");
    let e = err(&text);
    assert_invalid(&e, "time.courant", Some((6, 12)), &["(0, 1]", "1.5"]);
    assert_eq!(
        e.to_string(),
        "exp.yaml:6:12: time.courant: must be in (0, 1], got 1.5"
    );
    assert_eq!(e.location(), Some((6, 12)));
    assert_eq!(e.field(), Some("time.courant"));

    let text = edit(MINIMAL, "dimension: 2", "dimension: 4");
    assert_invalid(&err(&text), "dimension", Some((2, 12)), &["2 or 3", "4"]);
    let text = edit(MINIMAL, "spacing_m: 0.01", "spacing_m: -1");
    assert_invalid(&err(&text), "spacing_m", Some((3, 12)), &["> 0"]);
    let text = edit(MINIMAL, "density_kg_m3: 1000", "density_kg_m3: 0");
    assert_invalid(
        &err(&text),
        "fluid.density_kg_m3",
        Some(pos_of(&text, "0\n", 0)),
        &["> 0"],
    );

    for bad in [
        "a/b",
        "'with space'",
        "'..'",
        "\"\"",
        "caf\u{e9}",
        &"x".repeat(65),
    ] {
        let text = edit(MINIMAL, "name: full_example", &format!("name: {bad}"));
        assert_invalid(&err(&text), "name", Some((1, 7)), &[]);
    }
    ok(&edit(
        MINIMAL,
        "name: full_example",
        &format!("name: {}", "x".repeat(64)),
    ));
    ok(&edit(MINIMAL, "name: full_example", "name: A-z_0.9"));

    // cross-field checks
    let text = edit(
        MINIMAL,
        "  kind: dam_break\n",
        "  kind: dam_break\n  column_width_m: 1.5\n",
    );
    assert_invalid(
        &err(&text),
        "scene.column_width_m",
        Some(pos_of(&text, "1.5", 0)),
        &["tank_width_m"],
    );
    let text = edit(MINIMAL, "spacing_m: 0.01", "spacing_m: 0.3");
    assert_invalid(
        &err(&text),
        "scene.column_width_m",
        None,
        &["2 * spacing_m", "(default)"],
    );
    let text = edit(
        MINIMAL,
        "spacing_m: 0.01\n",
        "spacing_m: 0.01\nmps:\n  laplacian_radius: 2.0\n",
    );
    assert_invalid(
        &err(&text),
        "mps.laplacian_radius",
        Some(pos_of(&text, "2.0", 0)),
        &["number_density_radius"],
    );
    let text = edit(
        MINIMAL,
        "spacing_m: 0.01\n",
        "spacing_m: 0.01\nmps: {wall_layers: 1, dummy_layers: 1}\n",
    );
    assert_invalid(
        &err(&text),
        "mps.dummy_layers",
        Some(pos_of(&text, "1}", 0)),
        &["wall_layers"],
    );
    let text = edit(
        MINIMAL,
        "spacing_m: 0.01\n",
        "spacing_m: 0.01\nmps: {wall_layers: 0}\n",
    );
    assert_invalid(
        &err(&text),
        "mps.wall_layers",
        Some(pos_of(&text, "0}", 0)),
        &[">= 1"],
    );
    // The solids' wall layers: at least one, and with the dummies deep enough for the
    // Laplacian (3.1 spacings: 3 layers), named apart from the container's.
    let text = edit(
        MINIMAL,
        "spacing_m: 0.01\n",
        "spacing_m: 0.01\nmps: {solid_wall_layers: 0}\n",
    );
    assert_invalid(
        &err(&text),
        "mps.solid_wall_layers",
        Some(pos_of(&text, "0}", 0)),
        &[">= 1"],
    );
    let text = edit(
        MINIMAL,
        "spacing_m: 0.01\n",
        "spacing_m: 0.01\nmps: {wall_layers: 2, dummy_layers: 1, solid_wall_layers: 1}\n",
    );
    assert_invalid(
        &err(&text),
        "mps.solid_wall_layers",
        Some(pos_of(&text, "1}", 0)),
        &["1 + 1 = 2"],
    );
    // Unwritten, the field is `wall_layers` and is not blamed for it (every issue listed).
    let fields = |m: &manifest::Manifest<_>| -> Vec<String> {
        manifest::validate::check(m)
            .into_iter()
            .map(|i| i.field)
            .collect()
    };
    let mut m = ok(MINIMAL).manifest;
    m.mps.wall_layers = 11;
    assert_eq!(fields(&m), ["mps.wall_layers"]);
    m.mps.solid_wall_layers = Some(11);
    assert_eq!(fields(&m), ["mps.wall_layers", "mps.solid_wall_layers"]);

    // The pressure regularisation: its radius between the first and the second shell, and in
    // 3D between sqrt(2) and 1.478 (its first shell's rows slide apart above; 1.5, the
    // default, is refused there).
    let e = err_with(
        MINIMAL,
        &[
            "mps.pressure_scheme=incremental",
            "mps.pressure_regularisation=1",
            "mps.regularisation_radius=2.5",
        ],
    );
    assert_invalid(&e, "mps.regularisation_radius", None, &["(1, 2)", "2.5"]);
    let e = err_with(
        MINIMAL,
        &[
            "dimension=3",
            "mps.pressure_scheme=incremental",
            "mps.pressure_regularisation=1",
        ],
    );
    assert_invalid(
        &e,
        "mps.regularisation_radius",
        None,
        &["(sqrt(2), 1.477)", "3D", "1.5 (default)"],
    );
    for radius in ["1.4", "1.48"] {
        let e = err_with(
            MINIMAL,
            &[
                "dimension=3",
                "mps.pressure_scheme=incremental",
                "mps.pressure_regularisation=1",
                &format!("mps.regularisation_radius={radius}"),
            ],
        );
        assert_invalid(&e, "mps.regularisation_radius", None, &[radius]);
    }
    ok_with(
        MINIMAL,
        &[
            "dimension=3",
            "mps.pressure_scheme=incremental",
            "mps.pressure_regularisation=1",
            "mps.regularisation_radius=1.45",
        ],
    );
    // Off, the 3D radius is not read.
    ok_with(MINIMAL, &["dimension=3", "mps.pressure_scheme=incremental"]);
    // The increment's regularisation: in [0, 100] and under the same radius rule in 3D.
    let e = err_with(
        MINIMAL,
        &[
            "mps.pressure_scheme=incremental",
            "mps.increment_regularisation=101",
        ],
    );
    assert_invalid(&e, "mps.increment_regularisation", None, &["101"]);
    let e = err_with(
        MINIMAL,
        &[
            "dimension=3",
            "mps.pressure_scheme=incremental",
            "mps.increment_regularisation=5",
        ],
    );
    assert_invalid(
        &e,
        "mps.regularisation_radius",
        None,
        &["(sqrt(2), 1.477)", "3D"],
    );
    // Off, either is no part of the experiment: the hash is the one without the fields (the
    // radius with them).
    let plain = ok_with(MINIMAL, &["mps.pressure_scheme=incremental"]);
    for field in ["pressure_regularisation", "increment_regularisation"] {
        let off = ok_with(
            MINIMAL,
            &[
                "mps.pressure_scheme=incremental",
                &format!("mps.{field}=0"),
                "mps.regularisation_radius=1.7",
            ],
        );
        assert_eq!(plain.hash_hex, off.hash_hex, "{field}");
        let on = ok_with(
            MINIMAL,
            &["mps.pressure_scheme=incremental", &format!("mps.{field}=1")],
        );
        assert_ne!(plain.hash_hex, on.hash_hex, "{field}");
    }
    // The deep surface rule: below the surface threshold, its head positive, and off (0) no
    // part of the experiment, its head with it.
    fn incremental<'a>(sets: &[&'a str]) -> Vec<&'a str> {
        [&["mps.pressure_scheme=incremental"], sets].concat()
    }
    let e = err_with(MINIMAL, &incremental(&["mps.deep_surface_threshold=0.97"]));
    assert_invalid(
        &e,
        "mps.deep_surface_threshold",
        None,
        &["below mps.surface_threshold (0.97)", "0.97"],
    );
    let e = err_with(
        MINIMAL,
        &incremental(&["mps.deep_surface_threshold=0.9", "mps.deep_surface_head=0"]),
    );
    assert_invalid(&e, "mps.deep_surface_head", None, &["0"]);
    let hash = |sets: &[&str]| ok_with(MINIMAL, &incremental(sets)).hash_hex;
    let off = hash(&["mps.deep_surface_threshold=0", "mps.deep_surface_head=5"]);
    assert_eq!(plain.hash_hex, off);
    let on = hash(&["mps.deep_surface_threshold=0.9"]);
    assert_ne!(plain.hash_hex, on);
    assert_ne!(
        on,
        hash(&["mps.deep_surface_threshold=0.9", "mps.deep_surface_head=5"])
    );
    // surface_depth, corrected_strain_rate and wall_surface_no_slip likewise.
    let off = ok_with(
        MINIMAL,
        &[
            "mps.pressure_scheme=incremental",
            "mps.surface_depth=0",
            "mps.corrected_strain_rate=false",
            "mps.wall_surface_no_slip=false",
            "mps.wall_face_normals=false",
            "mps.wall_curvature=false",
            "mps.quadratic_strain_rate=false",
            "mps.exact_projection=false",
            "mps.conservative_gradient=false",
            "mps.adjoint_projection=false",
            "mps.periodic_hydrostatic=false",
            "mps.particle_shifting=0",
            "mps.particle_shifting_limit=0.2",
            "mps.pressure_floor_pa=0",
            "mps.pressure_smoothing_time_s=0",
        ],
    );
    assert_eq!(plain.hash_hex, off.hash_hex);
    for on in [
        "mps.pressure_floor_pa=-101325",
        "mps.surface_depth=0.5",
        "mps.corrected_strain_rate=true",
        "mps.wall_surface_no_slip=true",
        "mps.quadratic_strain_rate=true",
        "mps.exact_projection=true",
        "mps.conservative_gradient=true",
        "mps.adjoint_projection=true",
        "mps.periodic_hydrostatic=true",
        "mps.pressure_smoothing_time_s=0.01",
    ] {
        let on = ok_with(MINIMAL, &["mps.pressure_scheme=incremental", on]);
        assert_ne!(plain.hash_hex, on.hash_hex);
    }
    // Each wall particle's own face is part of the experiment, and places the surface's no-slip.
    let surface = ["mps.wall_surface_no_slip=true"];
    let faces = [
        "mps.wall_surface_no_slip=true",
        "mps.wall_face_normals=true",
    ];
    assert_ne!(
        ok_with(MINIMAL, &surface).hash_hex,
        ok_with(MINIMAL, &faces).hash_hex
    );
    // The walls' curvature needs both, and is part of the experiment.
    let curvature = [
        "mps.wall_surface_no_slip=true",
        "mps.wall_face_normals=true",
        "mps.wall_curvature=true",
    ];
    assert_ne!(
        ok_with(MINIMAL, &faces).hash_hex,
        ok_with(MINIMAL, &curvature).hash_hex
    );
    let e = err_with(
        MINIMAL,
        &["mps.wall_surface_no_slip=true", "mps.wall_curvature=true"],
    );
    assert_invalid(&e, "mps.wall_curvature", None, &["wall_face_normals"]);
    let e = err_with(MINIMAL, &["mps.conservative_gradient=true"]);
    assert_invalid(&e, "mps.conservative_gradient", None, &["incremental"]);
    let e = err_with(MINIMAL, &["mps.adjoint_projection=true"]);
    assert_invalid(&e, "mps.adjoint_projection", None, &["incremental"]);
    let e = err_with(MINIMAL, &["mps.periodic_hydrostatic=true"]);
    assert_invalid(&e, "mps.periodic_hydrostatic", None, &["incremental"]);
    let e = err_with(
        MINIMAL,
        &[
            "mps.pressure_scheme=incremental",
            "mps.adjoint_projection=true",
            "mps.exact_projection=true",
        ],
    );
    assert_invalid(&e, "mps.adjoint_projection", None, &["exact_projection"]);
    let e = err_with(MINIMAL, &["mps.wall_face_normals=true"]);
    assert_invalid(&e, "mps.wall_face_normals", None, &["wall_surface_no_slip"]);
    let e = err_with(MINIMAL, &["mps.surface_depth=1.5"]);
    assert_invalid(&e, "mps.surface_depth", None, &["[0, 1]", "1.5"]);
    let e = err_with(MINIMAL, &["mps.pressure_floor_pa=-2e5"]);
    assert_invalid(
        &e,
        "mps.pressure_floor_pa",
        None,
        &["[-101325, 0]", "-200000"],
    );
    let e = err_with(MINIMAL, &["mps.pressure_floor_pa=10"]);
    assert_invalid(&e, "mps.pressure_floor_pa", None, &["[-101325, 0]", "10"]);
    // The floor is read by the standard scheme too.
    let plain_standard = ok_with(MINIMAL, &[]);
    let standard_floor = ok_with(MINIMAL, &["mps.pressure_floor_pa=-1000"]);
    assert_ne!(plain_standard.hash_hex, standard_floor.hash_hex);
    // The shifting's limit is part of the experiment once shifting is on.
    let shifting = [
        "mps.pressure_scheme=incremental",
        "mps.particle_shifting=40",
    ];
    let shifted = ok_with(MINIMAL, &shifting);
    let limited = ok_with(
        MINIMAL,
        &[&shifting[..], &["mps.particle_shifting_limit=0.1"]].concat(),
    );
    assert_ne!(shifted.hash_hex, limited.hash_hex);
    // The standard scheme does not read the smoothing: the same experiment.
    assert_eq!(
        plain_standard.hash_hex,
        ok_with(MINIMAL, &["mps.pressure_smoothing_time_s=0.01"]).hash_hex
    );
    let e = err_with(MINIMAL, &["mps.pressure_smoothing_time_s=-0.01"]);
    assert_invalid(
        &e,
        "mps.pressure_smoothing_time_s",
        None,
        &["[0, 1000]", "-0.01"],
    );
    let e = err_with(MINIMAL, &["mps.particle_shifting=-1"]);
    assert_invalid(&e, "mps.particle_shifting", None, &["[0, 1000]", "-1"]);
    let e = err_with(MINIMAL, &["mps.particle_shifting_limit=0"]);
    assert_invalid(&e, "mps.particle_shifting_limit", None, &["(0, 0.5]", "0"]);
    // Two estimates of the strain rate: one at a time.
    let e = err_with(
        MINIMAL,
        &[
            "mps.corrected_strain_rate=true",
            "mps.quadratic_strain_rate=true",
        ],
    );
    assert_invalid(&e, "mps.quadratic_strain_rate", None, &["set one of them"]);
    // The strain rate's and the viscous Laplacian's radii: beyond the nearest neighbours,
    // within the neighbour lists; unset, no part of the experiment.
    for key in ["strain_rate_radius", "viscous_laplacian_radius"] {
        let field = format!("mps.{key}");
        let e = err_with(MINIMAL, &[&format!("{field}=1")]);
        assert_invalid(&e, &field, None, &["(1, 5]", "1"]);
        let e = err_with(MINIMAL, &[&format!("{field}=3.5")]);
        assert_invalid(&e, &field, None, &["mps.laplacian_radius (3.1)", "3.5"]);
        let shell = ok_with(MINIMAL, &[&format!("{field}=1.5")]);
        assert_ne!(ok_with(MINIMAL, &[]).hash_hex, shell.hash_hex);
        assert!(shell.canonical.contains(&format!(r#""{key}":1.5"#)));
        assert!(!ok_with(MINIMAL, &[]).canonical.contains(key));
    }
    // The adaptive penalty's switch, off, is no part of the experiment either.
    assert_eq!(
        ok_with(MINIMAL, &["mps.yield_penalty_adaptive=false"]).hash_hex,
        ok_with(MINIMAL, &[]).hash_hex
    );
    // Nor is the consistent divergence's switch, off; on, it is.
    assert_eq!(
        ok_with(MINIMAL, &["mps.yield_consistent_divergence=false"]).hash_hex,
        ok_with(MINIMAL, &[]).hash_hex
    );
    // Nor are exact velocity steps in the yield solve (the inexact ones' fraction at 0).
    let yield_solve = [
        "mps.yield_penalty_pa_s=1000",
        "mps.wall_surface_no_slip=true",
        "fluid.stress_gradient_term=false",
    ];
    let heap = std::fs::read_to_string(common::experiment("column_collapse_2d.yaml")).unwrap();
    let exact = ok_with(&heap, &yield_solve);
    let mut sets = yield_solve.to_vec();
    sets.push("mps.yield_velocity_fraction=0");
    sets.push("mps.yield_anderson_depth=0");
    sets.push("mps.yield_velocity_relative=false");
    assert_eq!(ok_with(&heap, &sets).hash_hex, exact.hash_hex);
    // Inexact steps, then the consistent divergence, on top: each changes the hash and is
    // named in the canonical form.
    for (set, named) in [
        (
            "mps.yield_velocity_fraction=0.1",
            r#""yield_velocity_fraction":0.1"#,
        ),
        (
            "mps.yield_velocity_relative=true",
            r#""yield_velocity_relative":true"#,
        ),
        (
            "mps.yield_consistent_divergence=true",
            r#""yield_consistent_divergence":true"#,
        ),
        ("mps.yield_anderson_depth=5", r#""yield_anderson_depth":5"#),
        (
            "mps.yield_volumetric_limit=1",
            r#""yield_volumetric_limit":1"#,
        ),
    ] {
        let before = ok_with(&heap, &sets).hash_hex;
        sets.push(set);
        let after = ok_with(&heap, &sets);
        assert_ne!(after.hash_hex, before, "{set}");
        assert!(
            after.canonical.contains(named),
            "{set}: {}",
            after.canonical
        );
    }

    // The volumetric limit: null is the whole tensor's limit, as before (no part of the
    // experiment); a factor is in [0, 1e6] and needs the yield solve.
    assert_eq!(
        ok_with(
            &heap,
            &[&yield_solve[..], &["mps.yield_volumetric_limit=null"]].concat()
        )
        .hash_hex,
        exact.hash_hex
    );
    let e = err_with(
        &heap,
        &[&yield_solve[..], &["mps.yield_volumetric_limit=-1"]].concat(),
    );
    assert_invalid(
        &e,
        "mps.yield_volumetric_limit",
        None,
        &["[0, 1000000]", "-1"],
    );
    // The relative floor scales the inexact steps' floor: without a fraction it has none.
    let e = err_with(
        &heap,
        &[&yield_solve[..], &["mps.yield_velocity_relative=true"]].concat(),
    );
    assert_invalid(
        &e,
        "mps.yield_velocity_relative",
        None,
        &["mps.yield_velocity_fraction > 0"],
    );
    let e = err_with(MINIMAL, &["mps.yield_volumetric_limit=1"]);
    assert_invalid(
        &e,
        "mps.yield_volumetric_limit",
        None,
        &["needs mps.yield_penalty_pa_s > 0"],
    );

    // from an override: no line, says so
    let e = err_with(MINIMAL, &["time.courant=1.5"]);
    assert_invalid(&e, "time.courant", None, &["(from --set)"]);
    assert_eq!(
        e.to_string(),
        "exp.yaml: time.courant: must be in (0, 1], got 1.5 (from --set)"
    );
}

#[test]
fn non_finite_values_are_rejected() {
    for bad in [".nan", ".inf", "-.inf", ".NaN"] {
        let text = edit(MINIMAL, "spacing_m: 0.01", &format!("spacing_m: {bad}"));
        assert_invalid(&err(&text), "spacing_m", Some((3, 12)), &["finite"]);
        let text = edit(
            MINIMAL,
            "spacing_m: 0.01\n",
            &format!("spacing_m: 0.01\nmps:\n  ppe_tolerance: {bad}\n"),
        );
        assert_invalid(&err(&text), "mps.ppe_tolerance", Some((5, 18)), &["finite"]);
        // inside a tagged section the YAML layer rejects it
        let text = edit(
            MINIMAL,
            "viscosity_pa_s: 0.001",
            &format!("viscosity_pa_s: {bad}"),
        );
        let e = err(&text);
        assert_eq!(e.field(), Some("fluid.viscosity_pa_s"), "{e}");
        assert_eq!(e.location(), Some(pos_of(&text, bad, 0)), "{e}");
        assert!(e.to_string().contains("finite"), "{e}");
        // and in an override
        let e = err_with(MINIMAL, &[&format!("time.end_s={bad}")]);
        assert_override(&e, "time.end_s", &["finite"]);
    }
    let text = edit(MINIMAL, "spacing_m: 0.01", "spacing_m: 1e999");
    assert!(matches!(
        err(&text),
        ManifestError::Invalid { .. } | ManifestError::Syntax { .. }
    ));
}

#[test]
fn override_errors() {
    let e = err_with(MINIMAL, &["time.endd_s=1"]);
    assert_override(
        &e,
        "time.endd_s",
        &["endd_s", "end_s", "courant", "dt_max_s"],
    );
    assert!(e.to_string().starts_with("--set time.endd_s: "), "{e}");
    assert_override(&err_with(MINIMAL, &["nope=1"]), "nope", &["spacing_m"]);
    assert_override(
        &err_with(MINIMAL, &["spacing_m.x=1"]),
        "spacing_m.x",
        &["not a section"],
    );
    assert_override(&err_with(MINIMAL, &["time=1"]), "time", &["section"]);

    // malformed
    assert_override(&err_with(MINIMAL, &["foo"]), "foo", &["KEY=VALUE"]);
    assert_override(&err_with(MINIMAL, &["=1"]), "=1", &["KEY"]);
    assert_override(&err_with(MINIMAL, &["time..end_s=1"]), "time..end_s", &[]);
    assert_override(
        &err_with(MINIMAL, &["time.end_s="]),
        "time.end_s",
        &["empty"],
    );
    assert_override(
        &err_with(MINIMAL, &["time.end_s=[1, 2]"]),
        "time.end_s",
        &["scalar"],
    );

    // wrong type
    assert_override(
        &err_with(MINIMAL, &["time.end_s=abc"]),
        "time.end_s",
        &["abc"],
    );
    assert_override(
        &err_with(MINIMAL, &["dimension=2.5"]),
        "dimension",
        &["2.5"],
    );
    assert_override(
        &err_with(MINIMAL, &["mps.wall_layers=-1"]),
        "mps.wall_layers",
        &[],
    );
    assert_override(
        &err_with(MINIMAL, &["fluid.density_kg_m3=true"]),
        "fluid.density_kg_m3",
        &[],
    );
    assert_override(
        &err_with(MINIMAL, &["fluid.model=herschel_bulkley"]),
        "fluid.model",
        &["herschel_bulkley", "newtonian"],
    );

    // the first failing override is reported, the others are not applied silently
    let e = err_with(MINIMAL, &["time.end_s=2", "time.bogus=1"]);
    assert_override(&e, "time.bogus", &[]);
}

#[test]
fn yaml_errors() {
    let e = err("name: [unclosed\n");
    assert!(
        matches!(e, ManifestError::Syntax { line: Some(_), .. }),
        "{e:?}"
    );
    let e = err(&format!("{MINIMAL}name: again\n"));
    assert_syntax(&e, "name", Some((12, 1)), &["duplicate"]);
    let e = err("");
    assert!(matches!(e, ManifestError::Syntax { .. }), "{e:?}");
    let e = err(&format!("{MINIMAL}---\n{MINIMAL}"));
    assert!(matches!(e, ManifestError::Syntax { .. }), "{e:?}");

    // an alias bomb hits serde-saphyr's budget
    let mut bomb = String::from("a: &a [x, x, x, x, x, x, x, x, x, x]\n");
    for i in 1..12 {
        let prev = (b'a' + i - 1) as char;
        let cur = (b'a' + i) as char;
        bomb.push_str(&format!(
            "{cur}: &{cur} [*{prev}, *{prev}, *{prev}, *{prev}, *{prev}, *{prev}, *{prev}, *{prev}, *{prev}, *{prev}]\n"
        ));
    }
    bomb.push_str(MINIMAL);
    assert!(matches!(err(&bomb), ManifestError::Syntax { .. }));
}

#[test]
fn io_error_names_the_path() {
    let e = experiment::load(Path::new("/nonexistent/exp.yaml"), &[]).unwrap_err();
    assert!(matches!(e, ManifestError::Io { .. }));
    assert!(e.to_string().starts_with("/nonexistent/exp.yaml: "), "{e}");
}

#[test]
fn load_names_the_file_in_errors() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("bad.yaml");
    std::fs::write(
        &path,
        edit(MINIMAL, "  end_s: 1\n", "  end_s: 1\n  courant: 1.5\n"),
    )
    .unwrap();
    let e = experiment::load(&path, &[]).unwrap_err();
    assert_eq!(
        e.to_string(),
        format!(
            "{}:6:12: time.courant: must be in (0, 1], got 1.5",
            path.display()
        )
    );
}

#[test]
fn aliases_and_flow_style_are_located() {
    let text = "{name: t, dimension: 2, spacing_m: 0.01, time: {end_s: 1, courant: 2}, fluid: {model: newtonian, density_kg_m3: 1, viscosity_pa_s: 0}, scene: {kind: dam_break}}";
    assert_invalid(&err(text), "time.courant", Some(pos_of(text, "2}", 0)), &[]);
    // a value reached through an alias is located at the anchored value
    let text = edit(MINIMAL, "spacing_m: 0.01\n", "spacing_m: &s 0.01\n");
    let text = edit(
        &text,
        "  kind: dam_break\n",
        "  kind: dam_break\n  column_width_m: *s\n",
    );
    assert_invalid(
        &err(&text),
        "scene.column_width_m",
        Some(pos_of(&text, "*s", 0)),
        &["2 * spacing_m"],
    );
}

#[test]
fn variant_can_be_selected_by_override() {
    // same variant: the section's other values stay
    let r = ok_with(MINIMAL, &["scene.kind=dam_break", "scene.tank_width_m=2"]);
    let SceneSpec::DamBreak(DamBreak { tank_width_m, .. }) = r.manifest.scene else {
        panic!("a dam break")
    };
    assert_eq!(tank_width_m, 2.0);
    // an unknown variant is an error naming the valid ones
    let e = err_with(MINIMAL, &["scene.kind=v_funnel", "scene.gate_height_m=0.1"]);
    assert_override(&e, "scene.kind", &["v_funnel", "dam_break", "lb_box"]);
}

#[test]
fn rest_metric_must_be_a_metric_of_the_experiment() {
    let e = err_with(MINIMAL, &["stop.rest_metric=spread_radius_mean_m"]);
    assert_invalid(
        &e,
        "stop.rest_metric",
        None,
        &["spread_radius_mean_m", "not a metric", "front_position_m"],
    );
    let r = ok_with(MINIMAL, &["stop.rest_metric=front_position_m"]);
    assert_eq!(
        r.manifest.stop.rest_metric.as_deref(),
        Some("front_position_m")
    );
    let e = err_with(MINIMAL, &["stop.rest_metric_change=0"]);
    assert_invalid(&e, "stop.rest_metric_change", None, &["0"]);
}

#[test]
fn metric_names_are_the_metrics_each_experiment_reports() {
    // The names validation accepts for stop.rest_metric are exactly the keys measured, for
    // every shipped experiment (a sweep by its first point).
    let mut checked = 0;
    let mut files = 0;
    for entry in std::fs::read_dir(common::root().join("experiments")).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_none_or(|e| e != "yaml") {
            continue;
        }
        files += 1;
        let r = match mps_runner::experiment::load_plan(&path, &[]) {
            Ok(mps_runner::experiment::Plan::Single(r)) => *r,
            Ok(mps_runner::experiment::Plan::Sweep(s)) => s.points[0].resolved.clone(),
            Err(e) => panic!("{}: {e}", path.display()),
        };
        checked += 1;
        let m = &r.manifest;
        let measured: Vec<String> = if m.dimension == 2 {
            let scene = mps_runner::experiment::build_scene::<2>(m);
            mps_runner::experiment::experiment_metrics(m, &scene.particles, 0.0)
                .into_keys()
                .collect()
        } else {
            let scene = mps_runner::experiment::build_scene::<3>(m);
            mps_runner::experiment::experiment_metrics(m, &scene.particles, 0.0)
                .into_keys()
                .collect()
        };
        assert_eq!(
            mps_runner::experiment::metric_names(m),
            measured,
            "{}",
            path.display()
        );
    }
    assert!(
        files >= 8 && checked == files,
        "{checked} of {files} checked"
    );
}

#[test]
fn experiment_hashes_stay_what_they_were() {
    // `runner verify` re-canonicalises a file's stored manifest and checks its hash: a change
    // of the canonical form (a new key written for every manifest) would make every file
    // written before it unverifiable. smoke_2d's hash as of the first release of the format,
    // with the PPE tolerance of that time (the default became 1e-6 by the error budget in
    // docs/performance.md; a changed default is a new experiment, not a new form).
    // With the standard scheme, as before the 2D default preset.
    let pinned = [
        "mps.ppe_tolerance=1e-9".to_string(),
        "mps.preset=standard".to_string(),
    ];
    let r = experiment::load(&common::experiment("smoke_2d.yaml"), &pinned).unwrap();
    assert_eq!(
        r.hash_hex,
        "e549f3f34509373b7baaa9c1ed88d53c111b9c220bbecc9e585706f7f4de0a13"
    );
    assert!(!r.canonical.contains("rest_"), "{}", r.canonical);
    // With a rest metric the rest settings are part of the experiment.
    let sets = ["stop.rest_metric=front_position_m".to_string()];
    let r = experiment::load(&common::experiment("smoke_2d.yaml"), &sets).unwrap();
    assert!(
        r.canonical.contains("\"rest_after_s\":0.5"),
        "{}",
        r.canonical
    );
    assert!(
        r.canonical.contains("\"rest_metric_change\":0.001"),
        "{}",
        r.canonical
    );
}

#[test]
fn a_list_where_a_number_belongs_is_named_as_such() {
    let text = "name: x\ndimension: 2\nspacing_m: [1, 2]\ntime: {end_s: 1}\nfluid: {model: newtonian, density_kg_m3: 1000, viscosity_pa_s: 0.001}\nscene: {kind: dam_break}\n";
    let e = experiment::from_str(text, "exp.yaml", &[])
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("exp.yaml:3:12: spacing_m: expected a single value (a number, string or bool), got a list or a mapping"),
        "{e}"
    );
}

#[test]
fn slip_lengths_of_the_rod_and_the_cone_are_part_of_the_experiment_only_when_set() {
    for (file, field) in [
        ("rodding_2d.yaml", "scene.rod_slip_length_m"),
        ("slump_3d.yaml", "scene.cone_slip_length_m"),
    ] {
        let key = field.trim_start_matches("scene.");
        let path = common::experiment(file);
        // (The shipped rodding sets its rod's slip length: null takes it out.)
        let plain = experiment::load(&path, &[format!("{field}=null")]).unwrap();
        // Absent: the canonical form (and so every hash and file written before) is unchanged.
        assert!(!plain.canonical.contains(key), "{}", plain.canonical);
        let set = experiment::load(&path, &[format!("{field}=0.002")]).unwrap();
        assert!(set.canonical.contains(&format!("\"{key}\":0.002")));
        assert_ne!(plain.hash_hex, set.hash_hex);
        let e = experiment::load(&path, &[format!("{field}=-0.001")])
            .unwrap_err()
            .to_string();
        assert!(e.contains(field) && e.contains("-0.001"), "{e}");
    }
}

#[test]
fn the_quarter_slump_is_part_of_the_experiment_only_when_set() {
    let path = common::experiment("slump_3d.yaml");
    let whole = experiment::load(&path, &[]).unwrap();
    let explicit = experiment::load(&path, &["scene.quarter_domain=false".to_string()]).unwrap();
    // False is the whole slump as before the field: the canonical form and hash are unchanged.
    assert!(
        !whole.canonical.contains("quarter_domain"),
        "{}",
        whole.canonical
    );
    assert_eq!(whole.hash_hex, explicit.hash_hex);
    let quarter = experiment::load(&path, &["scene.quarter_domain=true".to_string()]).unwrap();
    assert!(quarter.canonical.contains("\"quarter_domain\":true"));
    assert_ne!(whole.hash_hex, quarter.hash_hex);
}

// ---------------------------------------------------------------- mps.preset

/// The quiet set as the docs measure it (docs/validation.md, "Holding still"), written out
/// field by field: every scheme, every dimension.
const QUIET_ALL: [&str; 5] = [
    "mps.pressure_scheme=incremental",
    "mps.pair_stabilisation=0.8",
    "mps.wall_support=0.95",
    "mps.surface_depth=0.5",
    "mps.corrected_strain_rate=true",
];
/// What the quiet set adds in 2D (the multigrid PPE since preset revision 3).
const QUIET_2D_ONLY: [&str; 5] = [
    "mps.pressure_regularisation=1",
    "mps.compressibility_1_pa=1e-7",
    "mps.ppe_preconditioner=multigrid",
    "mps.multigrid_over_correction=1.5",
    "time.acoustic_courant=40",
];
/// What it adds for a fluid with a yield stress: the rigid state by the augmented Lagrangian
/// (the walls' own faces since preset revision 2).
const QUIET_YIELD: [&str; 7] = [
    "fluid.stress_gradient_term=false",
    "mps.wall_surface_no_slip=true",
    "mps.strain_rate_radius=1.5",
    "mps.yield_penalty_pa_s=1000",
    "mps.yield_penalty_adaptive=true",
    "mps.yield_velocity_fraction=0.1",
    "mps.wall_face_normals=true",
];

/// What it adds for a fluid with a yield stress in 3D since preset revision 5 ...
const QUIET_3D_YIELD_REVISION_5: [&str; 2] = [
    "mps.regularisation_radius=1.45",
    "mps.increment_regularisation=5",
];

/// ... and since revision 6.
const QUIET_3D_YIELD_REVISION_6: [&str; 3] = [
    "mps.yield_penalty_local=true",
    "mps.yield_anderson_depth=5",
    "mps.yield_max_iterations=200",
];

/// Preset revision 2 adds the walls' own faces to the quiet yield set. Revision 1, under which
/// older files are taken back up, has none; water gets none at any revision.
#[test]
fn the_quiet_yield_set_takes_the_walls_faces_from_revision_2() {
    use mps_runner::experiment::SceneSpec;
    use mps_runner::manifest::PRESET_REVISION;
    const { assert!(PRESET_REVISION >= 2) };
    let at =
        |sets: &[&str], revision: u32| as_of("inclined_layer.yaml", sets, revision).manifest.mps;
    assert!(at(&[], 2).wall_face_normals);
    assert!(!at(&[], 1).wall_face_normals);
    let text = std::fs::read_to_string(common::experiment("inclined_layer.yaml")).unwrap();
    let r = manifest::from_str::<SceneSpec>(&text, "x", &[]).unwrap();
    assert!(r.manifest.mps.wall_face_normals);
    let water = load_exp("tank_at_rest.yaml", &["mps.preset=quiet"]).manifest;
    assert!(!water.mps.wall_face_normals);
}

/// Preset revision 3 gives the 2D quiet set the multigrid PPE with the over-correction 1.5;
/// revision 2 left the solver at Jacobi, and 3D keeps Jacobi (faster there). A file's own
/// solver fields beat the preset written or defaulted; `standard` leaves them alone.
#[test]
fn the_2d_quiet_set_takes_the_multigrid_pressure_solve_from_revision_3() {
    use mps_runner::manifest::{PRESET_REVISION, PpePreconditioner};
    const { assert!(PRESET_REVISION >= 3) };
    let at = |file: &str, sets: &[&str], revision: u32| as_of(file, sets, revision).manifest.mps;
    let heap = at("column_collapse_2d.yaml", &[], 3);
    assert_eq!(heap.ppe_preconditioner, PpePreconditioner::Multigrid);
    assert_eq!(heap.multigrid_over_correction, 1.5);
    let before = at("column_collapse_2d.yaml", &[], 2);
    assert_eq!(before.ppe_preconditioner, PpePreconditioner::Jacobi);
    assert_eq!(before.multigrid_over_correction, 1.0);
    let slump = at("slump_3d.yaml", &["mps.preset=quiet"], 3);
    assert_eq!(slump.ppe_preconditioner, PpePreconditioner::Jacobi);
    // The inclined layer writes plain aggregation: it keeps it under the default.
    let layer = at("inclined_layer.yaml", &[], 3);
    assert_eq!(layer.ppe_preconditioner, PpePreconditioner::Multigrid);
    assert_eq!(layer.multigrid_over_correction, 1.0);
    // `standard` sets the scheme back, not the solver: the dam break keeps its multigrid,
    // the heap its default Jacobi.
    let dam = load_exp("dam_break_2d.yaml", &["mps.preset=standard"])
        .manifest
        .mps;
    assert_eq!(dam.ppe_preconditioner, PpePreconditioner::Multigrid);
    assert_eq!(dam.multigrid_over_correction, 1.5);
    let standard = load_exp("column_collapse_2d.yaml", &["mps.preset=standard"])
        .manifest
        .mps;
    assert_eq!(standard.ppe_preconditioner, PpePreconditioner::Jacobi);
    // Jacobi set on a revision-3 run gives revision 2's experiment (same hash): the field
    // changed nothing else.
    let hash =
        |sets: &[&str], revision: u32| as_of("column_collapse_2d.yaml", sets, revision).hash_hex;
    assert_eq!(hash(&["mps.ppe_preconditioner=jacobi"], 3), hash(&[], 2));
    assert_ne!(hash(&[], 3), hash(&[], 2));
}

/// `time.acoustic_courant` is left out of the canonical form while null (the rule before
/// it), bounds the largest step by A l0 sqrt(rho kappa), and needs a compressibility.
#[test]
fn the_acoustic_step_bound_is_a_field_of_its_own() {
    // Revision 3: the 2D default without the bound.
    let plain = as_of("smoke_2d.yaml", &[], 3);
    assert!(!plain.canonical.contains("acoustic_courant"));
    assert_eq!(plain.manifest.largest_step_s(), 1e-3);
    let bounded = as_of("smoke_2d.yaml", &["time.acoustic_courant=40"], 3);
    assert_ne!(plain.hash_hex, bounded.hash_hex);
    // 40 * 0.025 m * sqrt(1000 kg/m3 * 1e-7 1/Pa) = 0.01 s: dt_max (1 ms) is the smaller.
    assert_eq!(bounded.manifest.largest_step_s(), 1e-3);
    let fine = as_of(
        "smoke_2d.yaml",
        &["time.acoustic_courant=40", "spacing_m=0.0005"],
        3,
    );
    assert!((fine.manifest.largest_step_s() - 2e-4).abs() < 1e-15);
    let sets = vec![
        "time.acoustic_courant=40".to_string(),
        "mps.compressibility_1_pa=0".to_string(),
    ];
    let e = experiment::load(&common::experiment("smoke_2d.yaml"), &sets).unwrap_err();
    assert!(e.to_string().contains("time.acoustic_courant"), "{e}");
}

/// Preset revision 4 gives the 2D quiet set `time.acoustic_courant: 40` (water and
/// concrete), not revision 3 and not 3D; `standard` takes it back to none, a file's or an
/// override's value wins, and with it set to null a revision-4 run is revision 3's
/// experiment (same hash). Under the default a compressibility of 0 is refused naming the
/// preset's bound and how to drop it.
#[test]
fn the_2d_quiet_set_takes_the_acoustic_step_bound_from_revision_4() {
    use mps_runner::manifest::PRESET_REVISION;
    const { assert!(PRESET_REVISION >= 4) };
    let courant = |file: &str, sets: &[&str], revision: u32| {
        as_of(file, sets, revision).manifest.time.acoustic_courant
    };
    for file in [
        "smoke_2d.yaml",
        "column_collapse_2d.yaml",
        "dam_break_2d.yaml",
    ] {
        assert_eq!(courant(file, &[], 4), Some(40.0), "{file}");
        assert_eq!(courant(file, &[], 3), None, "{file}");
        assert_eq!(courant(file, &["mps.preset=standard"], 4), None, "{file}");
        assert_eq!(
            courant(file, &["time.acoustic_courant=20"], 4),
            Some(20.0),
            "{file}"
        );
    }
    assert_eq!(courant("slump_3d.yaml", &["mps.preset=quiet"], 4), None);
    // The shipped 2D defaults are coarse enough that the bound does not bind (2.5 mm water
    // is the first spacing where it does, with equality).
    let heap = as_of("column_collapse_2d.yaml", &[], 4).manifest;
    assert_eq!(heap.largest_step_s(), heap.time.dt_max_s);
    let water = as_of("dam_break_2d.yaml", &["spacing_m=0.0025"], 4).manifest;
    assert_eq!(water.largest_step_s(), 1e-3);
    let fine = as_of("dam_break_2d.yaml", &["spacing_m=0.00035"], 4).manifest;
    assert!((fine.largest_step_s() - 1.4e-4).abs() < 1e-15);
    let hash = |sets: &[&str], revision: u32| as_of("smoke_2d.yaml", sets, revision).hash_hex;
    assert_eq!(hash(&["time.acoustic_courant=null"], 4), hash(&[], 3));
    assert_ne!(hash(&[], 4), hash(&[], 3));
    let e = experiment::load(
        &common::experiment("smoke_2d.yaml"),
        &["mps.compressibility_1_pa=0".to_string()],
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("time.acoustic_courant"), "{e}");
    assert!(e.contains("time.acoustic_courant: null"), "{e}");
    let off = [
        "mps.compressibility_1_pa=0".to_string(),
        "time.acoustic_courant=null".to_string(),
    ];
    assert!(experiment::load(&common::experiment("smoke_2d.yaml"), &off).is_ok());
}

/// Preset revision 5 gives the quiet 3D yield set the increment's regularisation (beta 5 at
/// the 3D radius 1.45); revision 4 has none, 2D and water none at any revision. A revision-5
/// run is revision 4's with the two fields written out (same hash), `standard` takes them
/// back, and a file's own value wins.
#[test]
fn the_3d_quiet_yield_set_takes_the_increments_regularisation_from_revision_5() {
    use mps_runner::manifest::PRESET_REVISION;
    const { assert!(PRESET_REVISION >= 5) };
    let now = quiet_slump_as_of(&[], 5).manifest.mps;
    assert_eq!(now.increment_regularisation, 5.0);
    assert_eq!(now.regularisation_radius, 1.45);
    let before = quiet_slump_as_of(&[], 4).manifest.mps;
    assert_eq!(before.increment_regularisation, 0.0);
    assert_eq!(before.regularisation_radius, 1.5);
    assert_eq!(
        quiet_slump_as_of(&[], 5).hash_hex,
        quiet_slump_as_of(&QUIET_3D_YIELD_REVISION_5, 4).hash_hex
    );
    assert_ne!(
        quiet_slump_as_of(&[], 5).hash_hex,
        quiet_slump_as_of(&[], 4).hash_hex
    );
    assert_eq!(
        quiet_slump_as_of(&["mps.increment_regularisation=2"], 5)
            .manifest
            .mps
            .increment_regularisation,
        2.0
    );
    let standard = load_exp("slump_3d.yaml", &["mps.preset=standard"])
        .manifest
        .mps;
    assert_eq!(standard.increment_regularisation, 0.0);
    assert_eq!(standard.regularisation_radius, 1.5);
    let water_3d = as_of(
        "tank_at_rest.yaml",
        &[
            "dimension=3",
            "scene.tank_width_m=0.3",
            "scene.fill_height_m=0.2",
            "mps.preset=quiet",
        ],
        5,
    )
    .manifest
    .mps;
    assert_eq!(water_3d.increment_regularisation, 0.0);
    let heap_2d = as_of("column_collapse_2d.yaml", &[], 5).manifest.mps;
    assert_eq!(heap_2d.increment_regularisation, 0.0);
    assert_eq!(heap_2d.regularisation_radius, 1.5);
}

/// Preset revision 6 gives the quiet 3D yield set local penalties and Anderson acceleration
/// with its 200-iteration cap; revision 5 has none, 2D none at any revision. A revision-6 run
/// is revision 5's with the three fields written out (same hash), `standard` takes them back,
/// and a file's own value wins.
#[test]
fn the_3d_quiet_yield_set_takes_local_penalties_and_anderson_from_revision_6() {
    use mps_runner::manifest::PRESET_REVISION;
    const { assert!(PRESET_REVISION >= 6) };
    let now = quiet_slump_as_of(&[], 6).manifest.mps;
    assert!(now.yield_penalty_local);
    assert_eq!(now.yield_anderson_depth, 5);
    assert_eq!(now.yield_max_iterations, 200);
    let before = quiet_slump_as_of(&[], 5).manifest.mps;
    assert!(!before.yield_penalty_local);
    assert_eq!(before.yield_anderson_depth, 0);
    assert_eq!(before.yield_max_iterations, 50);
    assert_eq!(
        quiet_slump_as_of(&[], 6).hash_hex,
        quiet_slump_as_of(&QUIET_3D_YIELD_REVISION_6, 5).hash_hex
    );
    assert_ne!(
        quiet_slump_as_of(&[], 6).hash_hex,
        quiet_slump_as_of(&[], 5).hash_hex
    );
    let own = quiet_slump_as_of(&["mps.yield_anderson_depth=2"], 6)
        .manifest
        .mps;
    assert_eq!(own.yield_anderson_depth, 2);
    assert!(own.yield_penalty_local);
    let standard = load_exp("slump_3d.yaml", &["mps.preset=standard"])
        .manifest
        .mps;
    assert!(!standard.yield_penalty_local);
    assert_eq!(standard.yield_anderson_depth, 0);
    assert_eq!(standard.yield_max_iterations, 50);
    let heap_2d = as_of("column_collapse_2d.yaml", &[], 6).manifest.mps;
    assert!(!heap_2d.yield_penalty_local);
    assert_eq!(heap_2d.yield_anderson_depth, 0);
    assert_eq!(heap_2d.yield_max_iterations, 50);
}

/// The shipped slump under `mps.preset=quiet` with `sets`, as preset `revision` resolved it.
fn quiet_slump_as_of(sets: &[&str], revision: u32) -> Resolved {
    as_of(
        "slump_3d.yaml",
        &[&["mps.preset=quiet"], sets].concat(),
        revision,
    )
}

/// A shipped experiment with `sets`, resolved under the default `quiet` as preset
/// `revision` resolved it.
fn as_of(file: &str, sets: &[&str], revision: u32) -> Resolved {
    use mps_runner::manifest::PresetName;
    let text = std::fs::read_to_string(common::experiment(file)).unwrap();
    let sets: Vec<String> = sets.iter().map(|s| s.to_string()).collect();
    manifest::from_str_as_of::<SceneSpec>(&text, "x", &sets, Some(PresetName::Quiet), revision)
        .unwrap()
}

fn load_exp(file: &str, sets: &[&str]) -> Resolved {
    let sets: Vec<String> = sets.iter().map(|s| s.to_string()).collect();
    experiment::load(&common::experiment(file), &sets).unwrap_or_else(|e| panic!("{file}: {e}"))
}

#[test]
fn the_quiet_preset_is_its_fields_written_out() {
    let yield_2d = [&QUIET_ALL[..], &QUIET_2D_ONLY, &QUIET_YIELD].concat();
    let yield_3d = [
        &QUIET_ALL[..],
        &QUIET_YIELD,
        &QUIET_3D_YIELD_REVISION_5,
        &QUIET_3D_YIELD_REVISION_6,
    ]
    .concat();
    let water_2d = [&QUIET_ALL[..], &QUIET_2D_ONLY].concat();
    let water_3d = [
        "dimension=3",
        "scene.tank_width_m=0.3",
        "scene.fill_height_m=0.2",
    ];
    for (file, dims, fields) in [
        ("column_collapse_2d.yaml", &[][..], &yield_2d[..]),
        ("inclined_layer.yaml", &[], &yield_2d),
        ("slump_3d.yaml", &[], &yield_3d),
        ("tank_at_rest.yaml", &[], &water_2d),
        ("tank_at_rest.yaml", &water_3d, &QUIET_ALL),
    ] {
        let by_hand = load_exp(file, &[dims, fields].concat());
        let preset = load_exp(file, &[dims, &["mps.preset=quiet"]].concat());
        // The same experiment, so the same canonical form and hash: a file written under the
        // preset verifies like one written with the fields.
        assert_eq!(preset.canonical, by_hand.canonical, "{file} {dims:?}");
        assert_eq!(preset.hash_hex, by_hand.hash_hex);
        assert!(!preset.canonical.contains("preset"), "{}", preset.canonical);
        // The experiment that names no preset (in 2D the default is quiet).
        let plain = load_exp(file, &[dims, &["mps.preset=null"]].concat());
        assert_ne!(
            plain.hash_hex, preset.hash_hex,
            "{file}: the preset changed nothing"
        );
        // `standard` takes every field back to its default: the experiment without the set
        // (the shipped files write no field of it, or its default).
        let back = load_exp(file, &[dims, fields, &["mps.preset=standard"]].concat());
        assert_eq!(
            back.hash_hex, by_hand.hash_hex,
            "a field set by --set beats the preset"
        );
        let standard = load_exp(file, &[dims, &["mps.preset=standard"]].concat());
        assert_eq!(standard.hash_hex, plain.hash_hex, "{file} {dims:?}");
    }
    // Water gets no yield settings (the validation refuses them without a yield stress).
    let water = load_exp("tank_at_rest.yaml", &["mps.preset=quiet"]).manifest;
    assert_eq!(water.mps.yield_penalty_pa_s, 0.0);
    assert!(!water.mps.wall_surface_no_slip);
}

#[test]
fn a_field_beats_the_preset_written_beside_it_and_a_preset_set_later_beats_the_file() {
    let text = edit(
        FULL,
        "mps:\n",
        "mps:\n  preset: quiet\n  pair_stabilisation: 0.7\n",
    );
    let r = ok(&text);
    assert_eq!(r.manifest.mps.pair_stabilisation, 0.7);
    assert_eq!(r.manifest.mps.wall_support, 0.95);
    assert_eq!(
        r.manifest.mps.pressure_scheme,
        manifest::PressureSchemeName::Incremental
    );
    // FULL writes the compressibility (0.45e-9): the file's preset leaves it alone.
    assert_eq!(r.manifest.mps.compressibility_1_pa, 0.45e-9);
    // The same preset set by --set switches the file's fields too, but not a --set field.
    let r = ok_with(FULL, &["mps.pair_stabilisation=0.7", "mps.preset=quiet"]);
    assert_eq!(r.manifest.mps.pair_stabilisation, 0.7);
    assert_eq!(r.manifest.mps.compressibility_1_pa, 1e-7);
    // A preset set by --set over the file's preset wins on every field the file wrote.
    let r = ok_with(&text, &["mps.preset=standard"]);
    assert_eq!(r.manifest.mps.pair_stabilisation, 0.0);
    assert_eq!(
        r.manifest.mps.pressure_scheme,
        manifest::PressureSchemeName::Standard
    );
    assert_eq!(r.hash_hex, ok(FULL).hash_hex);
    // Null is no preset.
    assert_eq!(
        ok_with(FULL, &["mps.preset=null"]).hash_hex,
        ok(FULL).hash_hex
    );
}

#[test]
fn a_bad_preset_is_named_and_a_clash_says_what_the_preset_set() {
    let text = edit(FULL, "mps:\n", "mps:\n  preset: quite\n");
    let e = err(&text);
    assert_syntax(
        &e,
        "mps.preset",
        Some(pos_of(&text, "quite", 0)),
        &["quite", "standard", "quiet"],
    );
    let e = err_with(FULL, &["mps.preset=loud"]);
    assert_override(&e, "mps.preset", &["loud", "`standard` or `quiet`"]);
    // A Bingham file that keeps eq. 8's term on against the preset's yield solve: the error is
    // at the user's line and names what the preset set.
    let l_flow = std::fs::read_to_string(common::experiment("l_flow_2d.yaml")).unwrap();
    let text = edit(&l_flow, "  preset: standard\n", "  preset: quiet\n");
    let e = err(&text);
    assert_invalid(
        &e,
        "fluid.stress_gradient_term",
        Some(pos_of(&text, "stress_gradient_term: true", 22)),
        &["mps.yield_penalty_pa_s set by mps.preset"],
    );
    // Under the 2D default (the file's `preset: standard` taken out) the error says that the
    // default set it, and how to opt out.
    let text = edit(&l_flow, "mps:\n  preset: standard\n", "");
    let e = experiment::from_str(&text, "exp.yaml", &[]).unwrap_err();
    assert_invalid(
        &e,
        "fluid.stress_gradient_term",
        Some(pos_of(&text, "stress_gradient_term: true", 22)),
        &[
            "mps.yield_penalty_pa_s set by the default mps.preset `quiet` of this dimension",
            "write `mps.preset: standard`",
        ],
    );
}

#[test]
fn a_default_preset_applies_as_if_written_in_the_file_and_never_to_a_canonical_form() {
    use mps_runner::experiment::SceneSpec;
    use mps_runner::manifest::PresetName;
    let under = |text: &str, sets: &[&str], default: Option<PresetName>| {
        let sets: Vec<String> = sets.iter().map(|s| s.to_string()).collect();
        manifest::from_str_under::<SceneSpec>(text, "exp.yaml", &sets, default).unwrap()
    };
    let quiet = |text: &str, sets: &[&str]| under(text, sets, Some(PresetName::Quiet));
    let none = |text: &str, sets: &[&str]| under(text, sets, None);
    let new_run = |text: &str, sets: &[&str]| {
        let sets: Vec<String> = sets.iter().map(|s| s.to_string()).collect();
        experiment::from_str(text, "exp.yaml", &sets).unwrap()
    };
    // The default: quiet in 2D, none in 3D; `from_str` takes it by the dimension the
    // overrides leave.
    assert_eq!(manifest::default_preset(2), Some(PresetName::Quiet));
    assert_eq!(manifest::default_preset(3), None);
    let r = new_run(FULL, &[]);
    assert_eq!(r.default_preset, Some(PresetName::Quiet));
    assert_eq!(r.hash_hex, quiet(FULL, &[]).hash_hex);
    let written = new_run(&edit(FULL, "mps:\n", "mps:\n  preset: quiet\n"), &[]);
    assert_eq!(
        r.hash_hex, written.hash_hex,
        "the file's fields win, as over a file's preset"
    );
    assert_eq!(r.manifest.mps.compressibility_1_pa, 0.45e-9);
    assert_ne!(r.hash_hex, none(FULL, &[]).hash_hex);
    let in_3d = new_run(FULL, &["dimension=3"]);
    assert_eq!(in_3d.default_preset, None);
    assert_eq!(in_3d.hash_hex, none(FULL, &["dimension=3"]).hash_hex);
    // A preset named, null included, in the file or by --set, replaces the default.
    assert_eq!(
        quiet(FULL, &["mps.preset=null"]).hash_hex,
        none(FULL, &[]).hash_hex
    );
    let opt_out = edit(FULL, "mps:\n", "mps:\n  preset: null\n");
    assert_eq!(quiet(&opt_out, &[]).hash_hex, none(FULL, &[]).hash_hex);
    assert_eq!(
        quiet(FULL, &["mps.preset=standard"]).hash_hex,
        none(FULL, &[]).hash_hex
    );
    // A canonical form holds every field: resolved under no default, whatever the default.
    let standard = none(FULL, &[]);
    let back = manifest::from_canonical::<SceneSpec>(&standard.canonical, "c", &[]).unwrap();
    assert_eq!(back.hash_hex, standard.hash_hex);
    let back = manifest::from_canonical::<SceneSpec>(&r.canonical, "c", &[]).unwrap();
    assert_eq!(back.hash_hex, r.hash_hex);
    // (Under the default the standard run's canonical form would become another experiment,
    // which is why stored forms are never read that way.)
    assert_ne!(
        new_run(&standard.canonical, &[]).hash_hex,
        standard.hash_hex
    );
}

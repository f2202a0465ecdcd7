//! Rock-filled concrete (issue 30; docs/rockfill.md): the rock bed (no overlap, every rock
//! carried, the same bed bit for bit), the void metrics on made-up states, and a 2D pour that
//! fills its bed at a low yield stress without losing a particle.
use crate::common;
use mps_runner::experiment::rockfill::Rockfill;
use mps_runner::experiment::{Fill, SceneSpec, build_scene, experiment_metrics};
use mps_runner::mps::{ParticleKind, Particles, Vector};
use mps_runner::record::read_run;

fn spec(m: &mps_runner::experiment::Manifest) -> &Rockfill {
    match &m.scene {
        SceneSpec::Rockfill(r) => r,
        other => panic!("not a rock fill: {other:?}"),
    }
}

/// The bed of `m` checked (`Bed::check`) and deposited twice the same; its rock count and the
/// porosity its scene's metrics report.
fn checked_bed<const D: usize>(m: &mps_runner::experiment::Manifest, name: &str) -> (usize, f64) {
    let d = spec(m).deposition::<D>();
    let bed = d.deposit();
    bed.check(&d).unwrap_or_else(|e| panic!("{name}: {e}"));
    assert_eq!(bed, d.deposit(), "{name}: the same bed twice");
    let scene = build_scene::<D>(m);
    let metrics = experiment_metrics(m, &scene.particles, 0.0);
    (bed.rocks.len(), metrics["bed_porosity"])
}

#[test]
fn the_shipped_beds_rest_without_overlap_and_repeat_bit_for_bit() {
    for (name, dimension) in [("rockfill_3d.yaml", 3), ("rockfill_2d.yaml", 2)] {
        let m = common::resolve(name, &[]).manifest;
        let (rocks, porosity) = if dimension == 3 {
            checked_bed::<3>(&m, name)
        } else {
            checked_bed::<2>(&m, name)
        };
        // The laboratory block: 80-120 mm rocks in a 0.4 m form, so walls and the rough top
        // loosen the packing beyond the bulk's 0.42 (bed.rs, a bed of one size).
        let expected = if dimension == 3 {
            (0.42, 0.60)
        } else {
            (0.5, 0.8)
        };
        assert!(
            porosity > expected.0 && porosity < expected.1 && rocks > 10,
            "{name}: porosity {porosity}, {rocks} rocks"
        );
    }
    // Another seed: another bed.
    let a = common::resolve("rockfill_3d.yaml", &[]).manifest;
    let b = common::resolve("rockfill_3d.yaml", &["scene.bed.seed=2"]).manifest;
    assert_ne!(spec(&a).deposit::<3>().rocks, spec(&b).deposit::<3>().rocks);
}

/// The 2D scene at `spacing_m` with fluid particles put at `points`.
fn with_fluid(
    sets: &[&str],
    points: impl Fn(&Vector<2>) -> bool,
) -> (mps_runner::experiment::Manifest, Particles<2>) {
    let m = common::resolve("rockfill_2d.yaml", sets).manifest;
    let mut p = build_scene::<2>(&m).particles;
    let r = spec(&m);
    let l0 = m.spacing_m;
    let bed = r.deposit::<2>();
    let (nx, nz) = (
        (r.form_length_m / l0).round() as i64,
        (r.bed.height_m / l0).ceil() as i64 + 4,
    );
    for k in 0..nz {
        for i in 0..nx {
            let x = Vector::<2>::new((i as f64 + 0.5) * l0, (k as f64 + 0.5) * l0);
            let in_rock = bed
                .rocks
                .iter()
                .any(|rock| (x - rock.centre_m).norm() < rock.radius_m);
            if !in_rock && points(&x) {
                p.push(x, ParticleKind::Fluid);
            }
        }
    }
    (m, p)
}

#[test]
fn the_void_metrics_count_what_they_should() {
    // Fluid on every void cell of the bed and above it: full, no pockets.
    let (m, p) = with_fluid(&[], |_| true);
    let metrics = experiment_metrics(&m, &p, 0.0);
    assert_eq!(metrics["filled_fraction"], 1.0, "{metrics:?}");
    for k in 1..=4 {
        assert_eq!(metrics[&format!("filled_fraction_layer_{k:02}")], 1.0);
    }
    assert_eq!(metrics["pocket_count"], 0.0);
    let r = spec(&m);
    let height = (r.bed.height_m / m.spacing_m).ceil() * m.spacing_m + 4.0 * m.spacing_m;
    assert!(
        (metrics["surface_height_mean_m"] - height).abs() < 1e-12,
        "{metrics:?}"
    );
    // Only the lowest layer: a quarter of the zone's rows full, the rest empty and open above.
    let quarter = 0.25 * r.bed.height_m;
    let (m, p) = with_fluid(&[], |x| x[1] < quarter);
    let metrics = experiment_metrics(&m, &p, 0.0);
    assert_eq!(metrics["filled_fraction_layer_01"], 1.0);
    assert_eq!(metrics["filled_fraction_layer_02"], 0.0);
    assert_eq!(
        metrics["pocket_count"], 0.0,
        "void open to the top is no pocket"
    );
    // A hole of radius 4 spacings in the fluid, away from the rocks: one pocket whose cells
    // lie farther than a spacing from the fluid, centred on the hole.
    let bed = r.deposit::<2>();
    let l0 = m.spacing_m;
    let centre = (0..360)
        .flat_map(|i| {
            (0..160)
                .map(move |k| Vector::<2>::new(0.02 + 0.001 * i as f64, 0.02 + 0.001 * k as f64))
        })
        .find(|c| {
            bed.rocks
                .iter()
                .all(|rock| (c - rock.centre_m).norm() > rock.radius_m + 6.0 * l0)
        })
        .expect("a clearing in the bed");
    let hole = 4.0 * l0;
    let (m, p) = with_fluid(&[], |x| (x - centre).norm() > hole);
    let metrics = experiment_metrics(&m, &p, 0.0);
    assert_eq!(metrics["pocket_count"], 1.0, "{metrics:?}");
    let pocket = metrics["largest_pocket_m3"];
    // The cells more than l0 from the fluid: those within about 3 l0 of the centre.
    let expected = std::f64::consts::PI * (hole - l0) * (hole - l0);
    assert!(
        (pocket - expected).abs() < 0.5 * expected,
        "{pocket} against {expected}"
    );
    assert!(
        (metrics["largest_pocket_x_m"] - centre[0]).abs() < l0,
        "{metrics:?}"
    );
    assert!(
        (metrics["largest_pocket_z_m"] - centre[1]).abs() < l0,
        "{metrics:?}"
    );
    assert_eq!(
        metrics["pocket_volume_far_from_contacts_m3"], pocket,
        "no contact near it"
    );
    assert!(metrics["filled_fraction"] < 1.0);
}

/// The covering sweep's two ends at 10 mm (`rockfill_cover_sweep.yaml`, docs/rockfill.md
/// "The covering sweep"): the 2D bed and its concrete poured at the left end, 7 cm above the
/// bed. At 20 Pa the pour runs out and fills the bed; at 350 Pa the heap under the inlet
/// rises to it, the pour stalls and the far end stays empty (measured at 10 mm: 0.987 filled
/// against 0.462, half the volume poured).
#[test]
fn a_stiff_concrete_poured_at_one_end_stalls_and_leaves_the_bed_partly_empty() {
    let dir = tempfile::tempdir().unwrap();
    let pour = |tau_pa: &str| {
        let tau = format!("fluid.yield_stress_pa={tau_pa}");
        let sets = [
            "spacing_m=0.01",
            "scene.pours.0.centre_m.0=0.03",
            "time.end_s=10",
            &tau,
        ];
        let resolved = common::resolve("rockfill_2d.yaml", &sets);
        let volume = spec(&resolved.manifest).pours[0].volume_m3;
        let metrics = common::run_completed(&resolved, dir.path(), 2)
            .summary
            .metrics;
        // Nothing left the domain, so the fluid in the form is what the inlet let in.
        assert_eq!(metrics["ghost_particle_count"], 0.0, "{metrics:?}");
        let poured = metrics["poured_volume_m3"];
        (metrics["filled_fraction"], poured / volume)
    };
    let (soft_fill, soft_poured) = pour("20");
    let (stiff_fill, stiff_poured) = pour("350");
    assert!(
        (soft_poured - 1.0).abs() < 1e-9,
        "20 Pa pours all of it: {soft_poured}"
    );
    assert!(soft_fill >= 0.95, "20 Pa fills the bed: {soft_fill}");
    // A yield stress the flow ignored would pour and fill as the soft one does.
    assert!(
        stiff_poured < 0.75,
        "350 Pa heaps up to the inlet: {stiff_poured} of it poured"
    );
    assert!(
        stiff_fill < 0.7,
        "350 Pa leaves the far end empty: {stiff_fill}"
    );
}

#[test]
fn a_low_yield_stress_fills_the_2d_bed_and_loses_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let resolved = common::resolve("rockfill_2d.yaml", &["time.end_s=8"]);
    let m = &resolved.manifest;
    let r = spec(m);
    let l0 = m.spacing_m;
    let result = common::run_completed(&resolved, dir.path(), 2);
    let metrics = &result.summary.metrics;
    let poured = (r.pours[0].volume_m3 / (l0 * l0)).round();
    assert_eq!(metrics["fluid_particle_count"], poured, "{metrics:?}");
    assert_eq!(metrics["ghost_particle_count"], 0.0);
    // 20 Pa, concrete for the void and a 2 cm cover: the void fills (issue 30, item 3), and
    // no pocket is left away from the contacts.
    assert!(metrics["filled_fraction"] >= 0.95, "{metrics:?}");
    assert_eq!(
        metrics["pocket_volume_far_from_contacts_m3"], 0.0,
        "{metrics:?}"
    );
    assert!(metrics.contains_key("time_to_fill_s"), "{metrics:?}");
    // The bed is in the file: the rocks' centres and radii, exactly.
    let bed = r.deposit::<2>();
    let run = read_run(&result.path).unwrap();
    let record = &run.metadata["rock_bed"];
    // Every number of the JSON arrays, parsed exactly (std's parser rounds correctly;
    // serde_json's default float parser may miss by an ulp).
    let numbers = |text: &str| -> Vec<f64> {
        text.split(['[', ']', ','])
            .filter(|t| !t.trim().is_empty())
            .map(|t| t.trim().parse().unwrap())
            .collect()
    };
    let radii: Vec<f64> = bed.rocks.iter().map(|k| k.radius_m).collect();
    let centres: Vec<f64> = bed
        .rocks
        .iter()
        .flat_map(|k| k.centre_m.iter().copied())
        .collect();
    assert_eq!(numbers(&record["radii_m"]), radii);
    assert_eq!(numbers(&record["centres_m"]), centres);
    // The report's section of the last checkpoint: the bed zone's cells that are not rock
    // are concrete, as the filled fraction says (at least 95 %).
    let maps = mps_runner::report::cell_maps(&run).unwrap();
    assert_eq!(maps.len(), 1);
    let map = &maps[0];
    let rows = (r.bed.height_m / l0).round() as usize;
    let zone = &map.cells[..rows * map.columns];
    let rock = zone.iter().filter(|&&c| c == Fill::Rock).count();
    let concrete = zone.iter().filter(|&&c| c == Fill::Concrete).count();
    assert!(
        concrete as f64 >= 0.95 * (zone.len() - rock) as f64 && rock > 0,
        "{concrete} concrete, {rock} rock of {} cells",
        zone.len()
    );
    // No fluid inside a rock (deeper than half a spacing below its surface: the wall layer's
    // centres lie from 0 to l0 inside it) or outside the form, at any checkpoint.
    for s in &run.states {
        for i in 0..s.kind.len() {
            if s.kind[i] != 0 {
                continue;
            }
            let x = Vector::<2>::new(s.position_m[2 * i], s.position_m[2 * i + 1]);
            for rock in &bed.rocks {
                let depth = rock.radius_m - (x - rock.centre_m).norm();
                assert!(
                    depth < 0.5 * l0,
                    "fluid {i} at {x} inside a rock by {depth}, t = {}",
                    s.time_s
                );
            }
            assert!(
                x[0] > 0.0 && x[0] < r.form_length_m && x[1] > 0.0,
                "fluid {i} at {x} out of the form"
            );
        }
    }
}

/// The shipped 3D rock fill at 20 mm, poured for 2 s: every particle the inlet let in is in the
/// form, and none gets into a rock (issue 30, item 2). A sphere's shell of one wall layer has
/// gaps wider than a flat wall's (`tests/shapes.rs`); the manifest's two layers close them.
/// Measured at commit 4f20330 to 3 s: with two layers (`mps.solid_wall_layers: 2`) the deepest
/// concrete particle sits 0.68 l0 inside a rock's nominal surface (in the lattice staircase;
/// the same with every wall doubled); with one (`mps.solid_wall_layers=1`) 1.46 l0 at 0.5 s
/// and 2.66 l0 at 3 s, 67 particles past 0.5 l0, and this test fails. The form holds it too (a particle pressed 0.09 l0 into the floor's face, short of its wall
/// particles' centres).
#[test]
fn the_3d_rocks_keep_the_concrete_out() {
    let dir = tempfile::tempdir().unwrap();
    let resolved = common::resolve("rockfill_3d.yaml", &["spacing_m=0.02", "time.end_s=2"]);
    let m = &resolved.manifest;
    let r = spec(m);
    let l0 = m.spacing_m;
    let result = common::run_completed(&resolved, dir.path(), 2);
    let metrics = &result.summary.metrics;
    assert_eq!(metrics["ghost_particle_count"], 0.0, "{metrics:?}");
    let poured = metrics["poured_volume_m3"] / (l0 * l0 * l0);
    assert!(poured > 500.0, "{metrics:?}");
    assert_eq!(
        metrics["fluid_particle_count"],
        poured.round(),
        "{metrics:?}"
    );
    let bed = r.deposit::<3>();
    let run = read_run(&result.path).unwrap();
    assert!(run.states.len() >= 4, "{} checkpoints", run.states.len());
    // The form's first wall layer has its centres l0/2 behind its inner faces.
    let (lo, hi) = (
        -0.5 * l0,
        [r.form_length_m + 0.5 * l0, r.form_width_m + 0.5 * l0],
    );
    for s in &run.states {
        let mut deepest = f64::NEG_INFINITY;
        for i in (0..s.kind.len()).filter(|&i| s.kind[i] == 0) {
            let x = Vector::<3>::from_fn(|a, _| s.position_m[3 * i + a]);
            for rock in &bed.rocks {
                deepest = deepest.max(rock.radius_m - (x - rock.centre_m).norm());
            }
            assert!(
                (0..2).all(|a| x[a] > lo && x[a] < hi[a]) && x[2] > lo,
                "fluid {i} at {x} out of the form"
            );
        }
        assert!(
            deepest < l0,
            "concrete {deepest} m inside a rock at t = {} s (a spacing is {l0} m)",
            s.time_s
        );
    }
}

#[test]
fn bad_rockfill_sections_are_refused_naming_the_field() {
    let text = std::fs::read_to_string(common::experiment("rockfill_2d.yaml")).unwrap();
    let dir = tempfile::tempdir().unwrap();
    // `edit` replaces text in the shipped manifest, `sets` are --set overrides.
    let refused = |edit: (&str, &str), sets: &[&str], field: &str| {
        assert!(text.contains(edit.0), "{edit:?}");
        let path = dir.path().join("m.yaml");
        std::fs::write(&path, text.replace(edit.0, edit.1)).unwrap();
        let sets: Vec<String> = sets.iter().map(|s| s.to_string()).collect();
        let e = mps_runner::experiment::load(&path, &sets).expect_err("refused");
        let message = e.to_string();
        assert!(message.contains(field), "{edit:?} {sets:?}: {message}");
    };
    let none = ("", "");
    let gap = "    gap_m: 0.02";
    refused(
        (gap, &format!("    diameter_range_m: [0.04, 0.06]\n{gap}")),
        &[],
        "scene.bed.sizes",
    );
    refused(
        none,
        &["scene.bed.sizes.0.volume_fraction=0.6"],
        "scene.bed.sizes",
    );
    refused(
        none,
        &["scene.pours.0.centre_m.1=0.15"],
        "scene.pours.0.centre_m.1",
    );
    refused(
        none,
        &["scene.pours.0.centre_m.0=0.39"],
        "scene.pours.0.centre_m.0",
    );
    refused(none, &["spacing_m=0.025"], "scene.bed");
    // Rocks of 3 mm in the 0.4 x 0.2 m bed: about 7000, more than the bed may hold.
    refused(
        (
            "diameter_m: 0.04, volume_fraction: 0.5",
            "diameter_m: 0.003, volume_fraction: 0.5",
        ),
        &["spacing_m=0.001", "scene.bed.gap_m=0"],
        "more than 4096",
    );
    refused(none, &["scene.layers=0"], "scene.layers");
    refused(none, &["scene.bed.height_m=0.5"], "scene.bed.height_m");
    refused(none, &["scene.bed.misses=0"], "scene.bed.misses");
}

/// `tools/critical_slope.py` (docs/rockfill.md, "Where the drain stops"): its fit of the
/// slit law gives back the threshold, gain and creep floor of made-up front speeds
/// (`--self-test`). Needs MPS_PYTHON, which tools/test.sh sets.
#[test]
#[ignore = "needs the Python venv; tools/test.sh runs it"]
fn the_critical_slope_fit_recovers_a_known_threshold() {
    let out = std::process::Command::new(common::python())
        .arg(common::root().join("tools/critical_slope.py"))
        .arg("--self-test")
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success() && text.contains("self-test: ok"),
        "{text}{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

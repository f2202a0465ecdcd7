//! Inlets (src/mps/inlet.rs): the cross-section lattice, pouring round(V / l0^D) particles
//! into a small walled box in 2D and 3D, and a run restored from a mid-pour checkpoint
//! continuing bit for bit.
use crate::core_setup;
use core_setup::{advance, config, position_bits, through_checkpoint, walled_box};
use mps_runner::checkpoint::{solver_from_message, to_message};
use mps_runner::mps::{Inlet, ParticleKind, Solver, Vector};

fn inlet<const D: usize>(centre_m: Vector<D>, radius_m: f64, volume_m3: f64) -> Inlet<D> {
    Inlet {
        centre_m,
        direction: Vector::<D>::from_fn(|a, _| if a == D - 1 { -1.0 } else { 0.0 }),
        radius_m,
        speed_m_s: 0.5,
        volume_m3,
        start_s: 0.01,
        tag: 4,
        // 0.9 l0 at the spacing every test here uses (20 mm).
        clearance_m: 0.9 * 0.02,
    }
}

#[test]
fn cross_sections_are_cell_centred_lattices() {
    let l0 = 0.02;
    let down = inlet::<3>(Vector::<3>::new(0.12, 0.12, 0.25), 0.05, 0.0);
    let points = down.cross_section_m(l0);
    assert_eq!(points.len(), 16);
    assert_eq!(
        down.plane_axes(),
        vec![
            Vector::<3>::new(1.0, 0.0, 0.0),
            Vector::<3>::new(0.0, 1.0, 0.0)
        ]
    );
    for x in &points {
        assert_eq!(x[2], 0.25);
        // u, v in units of l0: round-off of order 1e-14.
        let (u, v) = ((x[0] - 0.12) / l0, (x[1] - 0.12) / l0);
        assert!((u - u.round() - 0.5).abs() < 1e-9 || (u - u.round() + 0.5).abs() < 1e-9);
        assert!((v - v.round() - 0.5).abs() < 1e-9 || (v - v.round() + 0.5).abs() < 1e-9);
    }
    // The four centre points come first (at +-l0/2; round-off of order 1e-17 m).
    for x in &points[..4] {
        assert!(((x[0] - 0.12).abs() - 0.01).abs() < 1e-12);
        assert!(((x[1] - 0.12).abs() - 0.01).abs() < 1e-12);
    }
    let segment = inlet::<2>(Vector::<2>::new(0.15, 0.25), 0.05, 0.0);
    let points = segment.cross_section_m(l0);
    // u = +-0.01, +-0.03, +-0.05 (the ends of the segment count).
    assert_eq!(points.len(), 6);
    assert!((points[0][0] - 0.14).abs() < 1e-12 && (points[1][0] - 0.16).abs() < 1e-12);
    // A slanted inlet: every point in the plane, within the radius, l0 from its nearest (an
    // orthonormal basis built from (1, -2, -2)/3: round-off of order 1e-16 m).
    let mut slanted = down.clone();
    slanted.direction = Vector::<3>::new(1.0, -2.0, -2.0) / 3.0;
    let points = slanted.cross_section_m(l0);
    assert_eq!(points.len(), 16);
    for x in &points {
        let r = x - slanted.centre_m;
        assert!(r.dot(&slanted.direction).abs() < 1e-12);
        assert!(r.norm() <= 0.05 + 1e-12);
        let nearest = points
            .iter()
            .filter(|y| *y != x)
            .map(|y| (x - y).norm())
            .fold(f64::INFINITY, f64::min);
        assert!((nearest - l0).abs() < 1e-12);
    }
    assert_eq!(slanted.validate(l0), Ok(()));
    let mut narrow = slanted.clone();
    narrow.volume_m3 = 1e-3;
    narrow.radius_m = 0.01;
    assert!(narrow.validate(l0).is_err());
}

/// A box with a shallow pool and an inlet pouring `volume_m3` downwards from near its top;
/// the run goes on until `end_s`. Checks the count, the volume, the tags, and that a copy
/// restored from the first checkpoint taken mid-pour ends bit for bit where the run does.
fn pours<const D: usize>(cells: [i64; D], l0: f64, inlet: Inlet<D>, end_s: f64, count: u64) {
    let (p, lo, hi) = walled_box::<D>(l0, cells, 2);
    let initial = p.fluid_count();
    let initial_len = p.len();
    let mut c = config::<D>(l0, lo, hi);
    let total = inlet.total_count(l0);
    let per_layer = inlet.cross_section_m(l0).len() as u64;
    assert!(
        total > 2 * per_layer && !total.is_multiple_of(per_layer),
        "test needs a partial layer"
    );
    // The count derived by hand in the caller (round(V / l0^D)).
    assert_eq!(total, count);
    c.inlets = vec![inlet];
    let mut solver = Solver::new(c.clone(), p);
    let mut restored: Option<Solver<D>> = None;
    while advance(&mut solver, end_s) {
        let emitted = solver.inlet_emitted[0];
        assert!(emitted <= total);
        assert_eq!(solver.particles.len() as u64, initial_len as u64 + emitted);
        if let Some(r) = restored.as_mut() {
            assert!(advance(r, end_s));
        } else if emitted > per_layer && emitted < total {
            // Mid-pour: the inlet's progress goes through the checkpoint.
            let msg = to_message(0, &solver, 0.0);
            assert_eq!(msg.extra_scalars, vec![emitted as f64]);
            assert_eq!(msg.tag.len(), solver.particles.len());
            restored = Some(through_checkpoint(&solver, c.clone()));
        }
    }
    assert_eq!(solver.inlet_emitted[0], total, "the inlet did not finish");
    let p = &solver.particles;
    assert_eq!(p.count(ParticleKind::Ghost), 0);
    assert_eq!(p.fluid_count() as u64, initial as u64 + total);
    let poured = (initial_len..p.len())
        .filter(|&i| p.tag[i] == 4 && p.kind[i] == ParticleKind::Fluid)
        .count();
    assert_eq!(poured as u64, total);
    assert!(p.tag[..initial_len].iter().all(|&t| t == 0));
    let r = restored.expect("a mid-pour checkpoint");
    assert_eq!(r.inlet_emitted, solver.inlet_emitted);
    assert_eq!(r.step, solver.step);
    assert!(
        position_bits(&r.particles) == position_bits(&solver.particles),
        "{D}D: the restored run ends elsewhere"
    );
    assert_eq!(r.particles, solver.particles);
}

#[test]
fn inlet_pours_its_volume_and_stops_2d() {
    // Half-width 0.05 m at l0 = 0.02: 6 points a layer; 14.2 l0^2 -> 14 particles.
    let l0 = 0.02;
    let volume = 14.2 * l0 * l0;
    pours::<2>(
        [12, 16],
        l0,
        inlet::<2>(Vector::<2>::new(0.12, 0.26), 0.05, volume),
        0.4,
        14,
    );
    // 14.7 l0^2 rounds up: 15 particles (a floor would give 14).
    pours::<2>(
        [12, 16],
        l0,
        inlet::<2>(Vector::<2>::new(0.12, 0.26), 0.05, 14.7 * l0 * l0),
        0.4,
        15,
    );
}

#[test]
fn inlet_pours_its_volume_and_stops_3d() {
    // Radius 0.05 m at l0 = 0.02: 16 points a layer; 56.25 l0^3 -> 56 particles.
    let l0 = 0.02;
    let volume = 56.25 * l0 * l0 * l0;
    pours::<3>(
        [12, 12, 16],
        l0,
        inlet::<3>(Vector::<3>::new(0.12, 0.12, 0.26), 0.05, volume),
        0.35,
        56,
    );
}

#[test]
fn restoring_needs_the_inlets_progress() {
    let l0 = 0.02;
    let (p, lo, hi) = walled_box::<2>(l0, [8, 8], 2);
    let mut c = config::<2>(l0, lo, hi);
    c.inlets = vec![inlet::<2>(
        Vector::<2>::new(0.08, 0.14),
        0.03,
        6.0 * l0 * l0,
    )];
    let solver = Solver::new(c.clone(), p);
    let mut msg = to_message(0, &solver, 0.0);
    assert_eq!(msg.extra_scalars, vec![0.0]);
    assert!(solver_from_message::<2>(c.clone(), &msg).is_ok());
    msg.extra_scalars = vec![];
    assert!(solver_from_message::<2>(c.clone(), &msg).is_err());
    msg.extra_scalars = vec![2.5];
    assert!(solver_from_message::<2>(c.clone(), &msg).is_err());
    msg.extra_scalars = vec![7.0];
    assert!(solver_from_message::<2>(c, &msg).is_err());
}

#[test]
fn a_blocked_inlet_waits() {
    // The opening lies inside a pool at rest: fluid sits on its lattice points.
    let l0 = 0.02;
    let (p, lo, hi) = walled_box::<2>(l0, [8, 8], 4);
    let count = p.len();
    let mut c = config::<2>(l0, lo, hi);
    let mut blocked = inlet::<2>(Vector::<2>::new(0.08, 0.03), 0.03, 6.0 * l0 * l0);
    blocked.start_s = 0.0;
    c.inlets = vec![blocked];
    let mut solver = Solver::new(c, p);
    while advance(&mut solver, 0.05) {}
    assert_eq!(solver.inlet_emitted, vec![0]);
    assert_eq!(solver.particles.len(), count);
}

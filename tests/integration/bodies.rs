//! Rigid bodies on time-pure paths (src/mps/body.rs): the path arithmetic, a body driven
//! through a small walled box in 2D and 3D (down, hold, up; with and without repeat), and a
//! run restored from a mid-run checkpoint continuing bit for bit.
use crate::core_setup;
use core_setup::{advance, config, position_bits, through_checkpoint, walled_box};
use mps_runner::mps::{ParticleKind, Path, RigidBody, Solver, Vector};

/// The slump cone's lift as the solver computed it before `Path` (offset and speed on the
/// last axis), for the bit-identity check.
fn old_lift(start_s: f64, speed: f64, travel: f64, t: f64) -> (f64, f64) {
    let offset = |t: f64| ((t - start_s) * speed).clamp(0.0, travel);
    let v = if t >= start_s && offset(t) < travel {
        speed
    } else {
        0.0
    };
    (offset(t), v)
}

#[test]
fn lift_reproduces_the_old_moving_wall_bit_for_bit() {
    let (start, speed, travel) = (0.05, 0.2, 0.05);
    let path = Path::<3>::lift(
        start,
        Vector::<3>::new(0.0, 0.0, speed),
        Vector::<3>::new(0.0, 0.0, travel),
    );
    let mut t = 0.0;
    let mut k = 0;
    while t < 0.6 {
        let (offset, v) = old_lift(start, speed, travel, t);
        let o = path.offset_m(t);
        let w = path.velocity_m_s(t);
        assert_eq!(o[2].to_bits(), offset.to_bits(), "offset at t = {t}");
        assert_eq!(w[2].to_bits(), v.to_bits(), "velocity at t = {t}");
        for a in 0..2 {
            assert_eq!(o[a].to_bits(), 0.0f64.to_bits());
            assert_eq!(w[a].to_bits(), 0.0f64.to_bits());
        }
        // Uneven steps, as the CFL condition gives.
        t += 1e-4 * (1.0 + (k % 7) as f64 / 3.0);
        k += 1;
    }
    assert_eq!(path.offset_m(1.0)[2], travel);
}

#[test]
fn keyframe_paths_hold_and_repeat() {
    let times = [1.0, 2.0, 4.0];
    let offsets = [
        Vector::<2>::new(0.0, 0.0),
        Vector::<2>::new(0.0, -1.0),
        Vector::<2>::new(2.0, -1.0),
    ];
    let hold = Path::from_keyframes(&times, &offsets, None).unwrap();
    // Offsets of order 1 m interpolated linearly: round-off of order 1e-16 m.
    let close = |a: Vector<2>, b: Vector<2>| (a - b).norm() < 1e-12;
    assert!(close(hold.offset_m(0.5), offsets[0]));
    assert_eq!(hold.velocity_m_s(0.5), Vector::<2>::zeros());
    assert!(close(hold.offset_m(1.5), Vector::<2>::new(0.0, -0.5)));
    assert_eq!(hold.velocity_m_s(1.5), Vector::<2>::new(0.0, -1.0));
    // Keyframes are met exactly.
    assert_eq!(hold.offset_m(2.0), offsets[1]);
    assert!(close(hold.offset_m(3.0), Vector::<2>::new(1.0, -1.0)));
    assert_eq!(hold.velocity_m_s(3.0), Vector::<2>::new(1.0, 0.0));
    assert_eq!(hold.offset_m(4.0), offsets[2]);
    assert_eq!(hold.offset_m(10.0), offsets[2]);
    assert_eq!(hold.velocity_m_s(10.0), Vector::<2>::zeros());

    let repeat = Path::from_keyframes(&times, &offsets, Some(5.0)).unwrap();
    // Held between the last keyframe (4) and the next period (6), then over again.
    assert_eq!(repeat.offset_m(5.5), offsets[2]);
    assert_eq!(repeat.velocity_m_s(5.5), Vector::<2>::zeros());
    assert!(close(repeat.offset_m(6.5), Vector::<2>::new(0.0, -0.5)));
    assert_eq!(repeat.velocity_m_s(6.5), Vector::<2>::new(0.0, -1.0));
    assert!(close(repeat.offset_m(13.0), Vector::<2>::new(1.0, -1.0)));

    assert!(Path::from_keyframes(&[1.0, 1.0], &offsets[..2], None).is_err());
    assert!(Path::from_keyframes(&times, &offsets[..2], None).is_err());
    assert!(Path::from_keyframes(&times, &offsets, Some(2.5)).is_err());
    assert!(Path::<2>::from_keyframes(&[], &[], None).is_err());
    let rest = Path::from_keyframes(&[0.0], &offsets[2..], Some(1.0)).unwrap();
    assert_eq!(rest.offset_m(7.3), offsets[2]);
    assert_eq!(rest.velocity_m_s(7.3), Vector::<2>::zeros());
}

/// A walled box with some fluid and a plate (one wall row, two dummy rows above it) above
/// the fluid that the path moves: returns the solver and the plate's initial positions.
fn scene<const D: usize>(path: Path<D>) -> (Solver<D>, Vec<Vector<D>>) {
    let l0 = if D == 2 { 0.02 } else { 0.025 };
    let cells: [i64; D] = std::array::from_fn(|a| {
        if a == D - 1 {
            12
        } else {
            8 + 4 * (3 - D as i64)
        }
    });
    let (mut p, lo, hi) = walled_box::<D>(l0, cells, 3);
    let first = p.len();
    for row in 0..3 {
        let kind = if row == 0 {
            ParticleKind::Wall
        } else {
            ParticleKind::Dummy
        };
        let lo_idx: [i64; D] = std::array::from_fn(|a| {
            if a == D - 1 {
                7 + row
            } else {
                cells[a] / 2 - 1
            }
        });
        let hi_idx: [i64; D] = std::array::from_fn(|a| {
            if a == D - 1 {
                8 + row
            } else {
                cells[a] / 2 + 1
            }
        });
        mps_runner::experiment::geometry::lattice::for_each_index(lo_idx, hi_idx, |idx| {
            p.push(
                mps_runner::experiment::geometry::lattice::centre(idx, l0),
                kind,
            )
        });
    }
    let end = p.len();
    let initial = p.position_m[first..end].to_vec();
    let mut c = config::<D>(l0, lo, hi);
    c.bodies = vec![RigidBody {
        first,
        end,
        path,
        slip_length_m: None,
    }];
    (Solver::new(c, p), initial)
}

/// Down 0.1 m into the fluid's surface, hold, up and sideways; `repeat` closes the loop.
fn keyframe_path<const D: usize>(repeat: bool) -> Path<D> {
    let along = |a: usize, x: f64| Vector::<D>::from_fn(|b, _| if a == b { x } else { 0.0 });
    let down = along(D - 1, -0.1);
    let last = if repeat {
        Vector::<D>::zeros()
    } else {
        along(0, 0.05) + along(D - 1, 0.02)
    };
    Path::from_keyframes(
        &[0.02, 0.1, 0.15, 0.23],
        &[Vector::<D>::zeros(), down, down, last],
        repeat.then_some(0.25),
    )
    .unwrap()
}

/// Steps to `end_s`, checking after every step that each plate particle is at its initial
/// position plus the path offset (to 1e-9 m) and carries the path velocity of the step's
/// start time; a copy restored from a checkpoint at `end_s / 2` runs alongside and must end
/// bit for bit where the uninterrupted run does.
fn follows_path<const D: usize>(repeat: bool, end_s: f64) {
    let (mut solver, initial) = scene::<D>(keyframe_path(repeat));
    let body = solver.config.bodies[0].clone();
    let mut restored: Option<Solver<D>> = None;
    let mut lowest = 0.0f64;
    let mut moved_steps = 0;
    let check = |s: &Solver<D>, t0: f64| {
        for (k, i) in (body.first..body.end).enumerate() {
            let want = initial[k] + body.path.offset_m(s.time_s);
            let err = (s.particles.position_m[i] - want).norm();
            // Positions add offset(t + dt) - offset(t) over a few hundred steps: round-off
            // of order 1e-14 m; moving by v dt instead would overshoot a keyframe by v dt_max.
            assert!(
                err < 1e-9,
                "{D}D step {}: particle {i} off its path by {err:e} m",
                s.step
            );
            assert_eq!(
                s.particles.velocity_m_s[i],
                body.path.velocity_m_s(t0),
                "{D}D step {}: particle {i}",
                s.step
            );
        }
    };
    loop {
        let t0 = solver.time_s;
        if !advance(&mut solver, end_s) {
            break;
        }
        check(&solver, t0);
        // Read off the particles, not the path: the body really went down and moved.
        let shift = solver.particles.position_m[body.first][D - 1] - initial[0][D - 1];
        lowest = lowest.min(shift);
        if solver.particles.velocity_m_s[body.first].norm() > 0.0 {
            moved_steps += 1;
        }
        if let Some(r) = restored.as_mut() {
            let t0 = r.time_s;
            assert!(advance(r, end_s));
            check(r, t0);
        } else if solver.time_s >= 0.5 * end_s {
            restored = Some(through_checkpoint(&solver, solver.config.clone()));
        }
    }
    // The path's bottom is 0.1 m down, reached to the round-off above.
    assert!(
        (lowest + 0.1).abs() < 1e-9,
        "the path was not followed to its bottom: {lowest}"
    );
    assert!(moved_steps > 10);
    let r = restored.expect("a restored copy");
    assert_eq!(r.step, solver.step);
    assert_eq!(r.time_s.to_bits(), solver.time_s.to_bits());
    assert!(
        position_bits(&r.particles) == position_bits(&solver.particles),
        "{D}D: the restored run ends elsewhere"
    );
    assert!(solver.particles.fluid_count() > 0);
}

#[test]
fn body_follows_keyframes_and_holds_2d() {
    follows_path::<2>(false, 0.35);
}

#[test]
fn body_follows_repeating_keyframes_2d() {
    follows_path::<2>(true, 0.6);
}

#[test]
fn body_follows_keyframes_and_holds_3d() {
    follows_path::<3>(false, 0.3);
}

#[test]
fn body_follows_repeating_keyframes_3d() {
    follows_path::<3>(true, 0.55);
}

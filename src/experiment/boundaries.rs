//! The manifest's `boundaries:` section made into particles and core pieces, on top of any
//! test's scene: tag regions over the initial fluid, obstacles and rigid bodies filled with
//! wall and dummy layers (initial fluid inside them left out), and inlets.
use super::geometry::shapes::{Shape, fill_walls};
use super::{Manifest, Scene};
use crate::manifest::boundaries::{Body, Boundaries, Inlet as InletSpec};
use crate::manifest::validate::Checker;
use crate::mps::{Inlet, ParticleKind, Particles, Path, RigidBody, Vector};
use std::collections::BTreeSet;

/// The domain box of the test's own scene (before the section is added).
pub struct Domain<'a, const D: usize> {
    pub min_m: &'a Vector<D>,
    pub max_m: &'a Vector<D>,
}

fn vector<const D: usize>(v: &[f64]) -> Vector<D> {
    Vector::<D>::from_fn(|a, _| v[a])
}

/// The core's inlet for a manifest inlet.
pub fn inlet<const D: usize>(spec: &InletSpec, spacing_m: f64) -> Inlet<D> {
    // Scaled by its largest component first, so that no length under- or overflows.
    let direction = vector::<D>(&spec.direction);
    let largest = direction.amax();
    Inlet {
        centre_m: vector(&spec.centre_m),
        direction: (direction / largest).normalize(),
        radius_m: 0.5 * spec.diameter_m,
        speed_m_s: spec.speed_m_s,
        volume_m3: spec.volume_m3,
        start_s: spec.start_s,
        tag: spec.tag,
        clearance_m: spec.clearance * spacing_m,
    }
}

/// The body's path: its keyframes' offsets, linear in between.
pub fn path<const D: usize>(body: &Body) -> Result<Path<D>, String> {
    let times: Vec<f64> = body.keyframes.iter().map(|k| k.time_s).collect();
    let offsets: Vec<Vector<D>> = body.keyframes.iter().map(|k| vector(&k.offset_m)).collect();
    Path::from_keyframes(&times, &offsets, body.repeat_s)
}

/// Checks that need the test's scene and the core, once the manifest passed every other
/// check: every solid (a body at each of its keyframes) and every inlet lies inside the
/// domain box (so no input can make the lattice scans or the neighbour grid grow without
/// bound), a body moves at most `time.courant` spacings per `time.dt_max_s` (its speed is
/// not in the CFL step), an inlet's opening holds a lattice point, a path is one the core
/// accepts.
pub fn check<const D: usize>(m: &Manifest, domain: Domain<'_, D>, c: &mut Checker) {
    let b = &m.boundaries;
    let l0 = m.spacing_m;
    let inside = |lo: Vector<D>, hi: Vector<D>| {
        (0..D).all(|a| lo[a] >= domain.min_m[a] && hi[a] <= domain.max_m[a])
    };
    let describe = format!(
        "must lie inside the domain box {:?} to {:?} m (the test's scene and its surroundings)",
        domain.min_m.as_slice(),
        domain.max_m.as_slice()
    );
    let bounds = |s: &Shape<D>| {
        s.cell_bounds(l0).map(|(lo, hi)| {
            (
                Vector::<D>::from_fn(|a, _| lo[a] as f64 * l0),
                Vector::<D>::from_fn(|a, _| hi[a] as f64 * l0),
            )
        })
    };
    for (i, spec) in b.obstacles.iter().enumerate() {
        if bounds(&Shape::from_spec(spec)).is_none_or(|(lo, hi)| !inside(lo, hi)) {
            c.fail(&format!("boundaries.obstacles.{i}"), describe.clone());
        }
    }
    for (i, body) in b.bodies.iter().enumerate() {
        let at = format!("boundaries.bodies.{i}");
        let shape = Shape::<D>::from_spec(&body.shape);
        for (k, key) in body.keyframes.iter().enumerate() {
            let moved = shape.translated(&vector(&key.offset_m));
            if bounds(&moved).is_none_or(|(lo, hi)| !inside(lo, hi)) {
                c.fail(
                    &format!("{at}.keyframes.{k}.offset_m"),
                    format!("puts the body outside the domain: it {describe}"),
                );
            }
            if k > 0 {
                let before = &body.keyframes[k - 1];
                let step_m = (vector::<D>(&key.offset_m) - vector::<D>(&before.offset_m)).norm();
                let speed = step_m / (key.time_s - before.time_s);
                let limit = m.time.courant * l0 / m.time.dt_max_s;
                if speed > limit {
                    c.fail(
                        &format!("{at}.keyframes.{k}"),
                        format!(
                            "the body moves at {speed:.4} m/s from keyframe {} to {k}, faster than time.courant * spacing_m / time.dt_max_s = {limit:.4} m/s (a step would carry it past the fluid): slow it down or lower time.dt_max_s",
                            k - 1
                        ),
                    );
                }
            }
        }
        if let Err(message) = path::<D>(body) {
            c.fail(&format!("{at}.keyframes"), message);
        }
    }
    for (i, spec) in b.inlets.iter().enumerate() {
        let at = format!("boundaries.inlets.{i}");
        let core = inlet::<D>(spec, l0);
        let r = Vector::<D>::repeat(core.radius_m);
        if !inside(core.centre_m - r, core.centre_m + r) {
            c.fail(&at, describe.clone());
        } else if let Err(message) = core.validate(l0) {
            c.fail(&at, message);
        }
    }
}

/// The tags in use: those of the tag regions and inlets, and 0, or none when the section
/// tags nothing (each gets the metric `fluid_count_tag_<k>`).
pub fn tags_in_use(b: &Boundaries) -> BTreeSet<u16> {
    let mut tags: BTreeSet<u16> = b
        .tags
        .iter()
        .map(|t| t.tag)
        .chain(b.inlets.iter().map(|i| i.tag))
        .collect();
    if !tags.is_empty() {
        tags.insert(0);
    }
    tags
}

/// Adds the section's pieces to `scene` (nothing for an empty section, so every scene
/// without one keeps its particles and bits).
pub fn apply<const D: usize>(m: &Manifest, scene: &mut Scene<D>) {
    let (b, spacing_m) = (&m.boundaries, m.spacing_m);
    if b.is_empty() {
        return;
    }
    let (walls, dummies) = (m.mps.wall_layers_of_solids(), m.mps.dummy_layers);
    let p = &mut scene.particles;

    // Tags of the initial fluid: later regions win.
    let regions: Vec<(u16, Shape<D>)> = b
        .tags
        .iter()
        .map(|t| (t.tag, Shape::from_spec(&t.region)))
        .collect();
    for i in 0..p.len() {
        if p.kind[i] != ParticleKind::Fluid {
            continue;
        }
        for (tag, region) in &regions {
            if region.depth_m(&p.position_m[i]) > 0.0 {
                p.tag[i] = *tag;
            }
        }
    }

    // Solids: obstacles where they stand, bodies where their path puts them at t = 0.
    let paths: Vec<Path<D>> = b
        .bodies
        .iter()
        .map(|body| path(body).expect("checked by the manifest"))
        .collect();
    let obstacles: Vec<Shape<D>> = b.obstacles.iter().map(Shape::from_spec).collect();
    let bodies: Vec<Shape<D>> = b
        .bodies
        .iter()
        .zip(&paths)
        .map(|(body, path)| Shape::from_spec(&body.shape).translated(&path.offset_m(0.0)))
        .collect();

    // Initial fluid inside a solid (or within half a spacing of its surface) is left out.
    let inside = |x: &Vector<D>| {
        obstacles
            .iter()
            .chain(&bodies)
            .any(|s| s.depth_m(x) > -0.5 * spacing_m)
    };
    let keep: Vec<bool> = (0..p.len())
        .map(|i| p.kind[i] != ParticleKind::Fluid || !inside(&p.position_m[i]))
        .collect();
    if keep.contains(&false) {
        retain(p, &keep, &mut scene.bodies);
    }

    // Cells that already hold a wall or dummy particle (the test's walls, earlier solids)
    // are not filled twice.
    let mut taken = taken_cells(p);
    for solid in &obstacles {
        fill_solid(p, solid, spacing_m, walls, dummies, &mut taken);
    }
    for ((solid, path), spec) in bodies.iter().zip(paths).zip(&b.bodies) {
        let first = p.len();
        fill_solid(p, solid, spacing_m, walls, dummies, &mut taken);
        scene.bodies.push(RigidBody {
            first,
            end: p.len(),
            path,
            slip_length_m: spec.slip_length_m,
        });
    }
    scene
        .inlets
        .extend(b.inlets.iter().map(|spec| inlet::<D>(spec, spacing_m)));
}

/// The bits of a position (lattice cell centres are computed the same way everywhere, so
/// equal cells give equal bits).
fn key<const D: usize>(x: &Vector<D>) -> Vec<u64> {
    x.iter().map(|v| v.to_bits()).collect()
}

/// The cells that hold a wall or dummy particle of `p` (see [`fill_solid`]).
pub fn taken_cells<const D: usize>(p: &Particles<D>) -> BTreeSet<Vec<u64>> {
    (0..p.len())
        .filter(|&i| p.kind[i] != ParticleKind::Fluid)
        .map(|i| key(&p.position_m[i]))
        .collect()
}

/// Fills `solid` with wall and dummy layers, leaving out cells in `taken` (and adding the
/// new ones to it).
pub fn fill_solid<const D: usize>(
    p: &mut Particles<D>,
    solid: &Shape<D>,
    spacing_m: f64,
    walls: u32,
    dummies: u32,
    taken: &mut BTreeSet<Vec<u64>>,
) {
    let Some(scan) = solid.cell_bounds(spacing_m) else {
        return;
    };
    let mut filled = Particles::<D>::default();
    fill_walls(&mut filled, solid, scan, spacing_m, walls, dummies);
    for i in 0..filled.len() {
        if taken.insert(key(&filled.position_m[i])) {
            p.push(filled.position_m[i], filled.kind[i]);
        }
    }
}

/// Keeps the particles marked in `keep` (in order) and moves the bodies' index ranges with
/// them (bodies are wall particles: never removed).
fn retain<const D: usize>(p: &mut Particles<D>, keep: &[bool], bodies: &mut [RigidBody<D>]) {
    let mut new_index = Vec::with_capacity(keep.len() + 1);
    let mut next = 0;
    for &k in keep {
        new_index.push(next);
        next += usize::from(k);
    }
    new_index.push(next);
    for body in bodies.iter_mut() {
        body.first = new_index[body.first];
        body.end = new_index[body.end];
    }
    let mut out = Particles::<D>::default();
    for i in (0..p.len()).filter(|&i| keep[i]) {
        out.push_tagged(p.position_m[i], p.kind[i], p.tag[i]);
        let last = out.len() - 1;
        out.velocity_m_s[last] = p.velocity_m_s[i];
        out.pressure_pa[last] = p.pressure_pa[i];
    }
    *p = out;
}

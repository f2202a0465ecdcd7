//! The manifest's `boundaries:` section made into particles and core pieces, on top of any
//! test's scene: tag regions over the initial fluid, obstacles and rigid bodies filled with
//! wall and dummy layers (initial fluid inside them left out), and inlets.
use super::geometry::shapes::{Shape, fill_walls};
use super::{Manifest, Scene};
use crate::manifest::boundaries::{Body, Boundaries, Inlet as InletSpec};
use crate::manifest::validate::Checker;
use crate::mps::{Inlet, ParticleKind, Particles, Path, RigidBody, Vector};
use std::collections::BTreeSet;

fn vector<const D: usize>(v: &[f64]) -> Vector<D> {
    Vector::<D>::from_fn(|a, _| v[a])
}

/// The core's inlet for a manifest inlet (direction normalised by the core).
pub fn inlet<const D: usize>(spec: &InletSpec) -> Inlet<D> {
    Inlet {
        centre_m: vector(&spec.centre_m),
        direction: vector::<D>(&spec.direction).normalize(),
        radius_m: 0.5 * spec.diameter_m,
        speed_m_s: spec.speed_m_s,
        volume_m3: spec.volume_m3,
        start_s: spec.start_s,
        tag: spec.tag,
    }
}

/// The body's path: its keyframes' offsets, linear in between.
pub fn path<const D: usize>(body: &Body) -> Result<Path<D>, String> {
    let times: Vec<f64> = body.keyframes.iter().map(|k| k.time_s).collect();
    let offsets: Vec<Vector<D>> = body.keyframes.iter().map(|k| vector(&k.offset_m)).collect();
    Path::from_keyframes(&times, &offsets, body.repeat_s)
}

/// Checks that need the spacing and the core (after the section's own checks passed): an
/// inlet's opening must hold a lattice point, a path must be one the core accepts.
pub fn check(m: &Manifest, c: &mut Checker) {
    let b = &m.boundaries;
    if b.is_empty()
        || !super::spacing_ok(m)
        || !matches!(m.dimension, 2 | 3)
        || !crate::manifest::boundaries::check(b, m.dimension as usize).is_empty()
    {
        return;
    }
    let l0 = m.spacing_m;
    for (i, spec) in b.inlets.iter().enumerate() {
        let result = match m.dimension {
            3 => inlet::<3>(spec).validate(l0),
            _ => inlet::<2>(spec).validate(l0),
        };
        if let Err(message) = result {
            c.fail(&format!("boundaries.inlets.{i}"), message);
        }
    }
    for (i, body) in b.bodies.iter().enumerate() {
        let result = match m.dimension {
            3 => path::<3>(body).map(drop),
            _ => path::<2>(body).map(drop),
        };
        if let Err(message) = result {
            c.fail(&format!("boundaries.bodies.{i}.keyframes"), message);
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
    let (walls, dummies) = (m.mps.wall_layers, m.mps.dummy_layers);
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

    for solid in &obstacles {
        fill(p, solid, spacing_m, walls, dummies);
    }
    for (solid, path) in bodies.iter().zip(paths) {
        let first = p.len();
        fill(p, solid, spacing_m, walls, dummies);
        scene.bodies.push(RigidBody {
            first,
            end: p.len(),
            path,
        });
    }
    scene
        .inlets
        .extend(b.inlets.iter().map(|spec| inlet::<D>(spec)));
}

fn fill<const D: usize>(
    p: &mut Particles<D>,
    solid: &Shape<D>,
    spacing_m: f64,
    walls: u32,
    dummies: u32,
) {
    if let Some(scan) = solid.cell_bounds(spacing_m) {
        fill_walls(p, solid, scan, spacing_m, walls, dummies);
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

//! Solid shapes (from a manifest's [`ShapeSpec`]) and the wall and dummy particle layers that
//! fill them on the lattice.
//!
//! A shape is measured by a signed depth: positive inside the solid (how far below its
//! surface a point lies), negative outside. A lattice cell whose centre lies at depth d > 0
//! is in layer ceil(d / l0): layers 1..=wall_layers hold wall particles, the next
//! dummy_layers dummies, deeper cells nothing.
use super::lattice::{CellBox, centre, for_each_index};
use crate::manifest::shape::ShapeSpec;
use crate::mps::{ParticleKind, Particles, Vector};

/// A solid in D dimensions (see [`Shape::depth_m`] for how each is measured).
#[derive(Debug, Clone, PartialEq)]
pub enum Shape<const D: usize> {
    /// Axis-aligned box.
    Box { min_m: Vector<D>, max_m: Vector<D> },
    /// Ball (disc in 2D).
    Sphere { centre_m: Vector<D>, radius_m: f64 },
    /// Axis-aligned frustum; a cylinder is one with equal radii. `axis` is 0, 1 or 2.
    Frustum {
        base_centre_m: Vector<D>,
        axis: usize,
        bottom_radius_m: f64,
        top_radius_m: f64,
        height_m: f64,
    },
    /// Points in any of the shapes.
    Union(Vec<Shape<D>>),
    /// Points of `from` in none of `remove`.
    Difference {
        from: std::boxed::Box<Shape<D>>,
        remove: Vec<Shape<D>>,
    },
}

fn point<const D: usize>(v: &[f64]) -> Vector<D> {
    assert_eq!(v.len(), D, "a shape's point must have {D} components");
    Vector::<D>::from_fn(|a, _| v[a])
}

/// Cells lo..hi (hi exclusive) of every cell that overlaps the metric box [lo_m, hi_m].
fn cells_covering<const D: usize>(
    lo_m: &Vector<D>,
    hi_m: &Vector<D>,
    spacing_m: f64,
) -> CellBox<D> {
    (
        std::array::from_fn(|a| (lo_m[a] / spacing_m).floor() as i64),
        std::array::from_fn(|a| (hi_m[a] / spacing_m).ceil() as i64),
    )
}

impl<const D: usize> Shape<D> {
    /// The shape a manifest describes. The spec must pass
    /// [`crate::manifest::shape::check`] for dimension D (panics on a point without D
    /// components or an axis beyond D).
    pub fn from_spec(spec: &ShapeSpec) -> Shape<D> {
        match spec {
            ShapeSpec::Box { min_m, max_m } => Shape::Box {
                min_m: point(min_m),
                max_m: point(max_m),
            },
            ShapeSpec::Sphere { centre_m, radius_m } => Shape::Sphere {
                centre_m: point(centre_m),
                radius_m: *radius_m,
            },
            ShapeSpec::Cylinder {
                base_centre_m,
                axis,
                radius_m,
                height_m,
            } => Shape::frustum(
                point(base_centre_m),
                axis.index(),
                *radius_m,
                *radius_m,
                *height_m,
            ),
            ShapeSpec::Frustum {
                base_centre_m,
                axis,
                bottom_radius_m,
                top_radius_m,
                height_m,
            } => Shape::frustum(
                point(base_centre_m),
                axis.index(),
                *bottom_radius_m,
                *top_radius_m,
                *height_m,
            ),
            ShapeSpec::Union { of } => Shape::Union(of.iter().map(Shape::from_spec).collect()),
            ShapeSpec::Difference { from, remove } => Shape::Difference {
                from: std::boxed::Box::new(Shape::from_spec(from)),
                remove: remove.iter().map(Shape::from_spec).collect(),
            },
        }
    }

    fn frustum(base: Vector<D>, axis: usize, bottom: f64, top: f64, height: f64) -> Shape<D> {
        assert!(axis < D, "a shape's axis must be one of the {D} axes");
        Shape::Frustum {
            base_centre_m: base,
            axis,
            bottom_radius_m: bottom,
            top_radius_m: top,
            height_m: height,
        }
    }

    /// The same shape moved by `by_m`.
    pub fn translated(&self, by_m: &Vector<D>) -> Shape<D> {
        match self {
            Shape::Box { min_m, max_m } => Shape::Box {
                min_m: min_m + by_m,
                max_m: max_m + by_m,
            },
            Shape::Sphere { centre_m, radius_m } => Shape::Sphere {
                centre_m: centre_m + by_m,
                radius_m: *radius_m,
            },
            Shape::Frustum {
                base_centre_m,
                axis,
                bottom_radius_m,
                top_radius_m,
                height_m,
            } => Shape::Frustum {
                base_centre_m: base_centre_m + by_m,
                axis: *axis,
                bottom_radius_m: *bottom_radius_m,
                top_radius_m: *top_radius_m,
                height_m: *height_m,
            },
            Shape::Union(of) => Shape::Union(of.iter().map(|s| s.translated(by_m)).collect()),
            Shape::Difference { from, remove } => Shape::Difference {
                from: std::boxed::Box::new(from.translated(by_m)),
                remove: remove.iter().map(|s| s.translated(by_m)).collect(),
            },
        }
    }

    /// Signed depth of `x` below the surface, metres: > 0 inside, < 0 outside.
    pub fn depth_m(&self, x: &Vector<D>) -> f64 {
        match self {
            // Chebyshev (L-infinity): min over axes of the signed distances to both faces,
            // which outside is -(largest excess), as container.rs counts wall layers.
            Shape::Box { min_m, max_m } => (0..D)
                .map(|a| (x[a] - min_m[a]).min(max_m[a] - x[a]))
                .fold(f64::INFINITY, f64::min),
            // Euclidean: radius minus distance from the centre.
            Shape::Sphere { centre_m, radius_m } => radius_m - (x - centre_m).norm(),
            // min of the radial depth R(h) - r (r measured perpendicular to the axis, as
            // slump.rs measures its cone shell; R linear in h, held at the end radius beyond
            // an end) and the axial depth to the nearer end cap: outside, -(larger excess).
            Shape::Frustum {
                base_centre_m,
                axis,
                bottom_radius_m,
                top_radius_m,
                height_m,
            } => {
                let a = *axis;
                let h = x[a] - base_centre_m[a];
                let axial = h.min(height_m - h);
                let t = h.clamp(0.0, *height_m) / height_m;
                let radius = bottom_radius_m + (top_radius_m - bottom_radius_m) * t;
                let r = if D == 2 {
                    (x[1 - a] - base_centre_m[1 - a]).abs()
                } else {
                    (0..D)
                        .filter(|&b| b != a)
                        .map(|b| (x[b] - base_centre_m[b]) * (x[b] - base_centre_m[b]))
                        .sum::<f64>()
                        .sqrt()
                };
                (radius - r).min(axial)
            }
            // Union: the deepest of the parts.
            Shape::Union(parts) => parts
                .iter()
                .map(|s| s.depth_m(x))
                .fold(f64::NEG_INFINITY, f64::max),
            // Difference A - B: min(depth_A, -depth_B), B the union of the removed shapes.
            Shape::Difference { from, remove } => remove
                .iter()
                .map(|s| -s.depth_m(x))
                .fold(from.depth_m(x), f64::min),
        }
    }

    /// A box of lattice cells (spacing `spacing_m`) holding every cell whose centre lies in
    /// the shape; `None` for an unbounded shape (every shape so far is bounded).
    pub fn cell_bounds(&self, spacing_m: f64) -> Option<CellBox<D>> {
        match self {
            Shape::Box { min_m, max_m } => Some(cells_covering(min_m, max_m, spacing_m)),
            Shape::Sphere { centre_m, radius_m } => {
                let r = Vector::<D>::repeat(*radius_m);
                Some(cells_covering(&(centre_m - r), &(centre_m + r), spacing_m))
            }
            Shape::Frustum {
                base_centre_m,
                axis,
                bottom_radius_m,
                top_radius_m,
                height_m,
            } => {
                let r = bottom_radius_m.max(*top_radius_m);
                let lo = Vector::<D>::from_fn(|b, _| {
                    base_centre_m[b] - if b == *axis { 0.0 } else { r }
                });
                let hi = Vector::<D>::from_fn(|b, _| {
                    base_centre_m[b] + if b == *axis { *height_m } else { r }
                });
                Some(cells_covering(&lo, &hi, spacing_m))
            }
            Shape::Union(parts) => {
                let mut hull: Option<CellBox<D>> = None;
                for s in parts {
                    let (lo, hi) = s.cell_bounds(spacing_m)?;
                    hull = Some(match hull {
                        None => (lo, hi),
                        Some((l, h)) => (
                            std::array::from_fn(|a| l[a].min(lo[a])),
                            std::array::from_fn(|a| h[a].max(hi[a])),
                        ),
                    });
                }
                hull
            }
            Shape::Difference { from, .. } => from.cell_bounds(spacing_m),
        }
    }
}

/// Fills the solid with wall and dummy particles: visits the cells of `scan` (lo..hi, hi
/// exclusive) in the order of [`for_each_index`]; a cell whose centre x lies at depth d > 0
/// is in layer ceil(d / spacing_m) and gets a wall particle for layers 1..=wall_layers, a
/// dummy for the next `dummy_layers`, nothing deeper.
pub fn fill_walls<const D: usize>(
    particles: &mut Particles<D>,
    solid: &Shape<D>,
    scan: CellBox<D>,
    spacing_m: f64,
    wall_layers: u32,
    dummy_layers: u32,
) {
    let walls = f64::from(wall_layers);
    let all = walls + f64::from(dummy_layers);
    for_each_index(scan.0, scan.1, |idx| {
        let x = centre(idx, spacing_m);
        let depth = solid.depth_m(&x);
        if depth <= 0.0 || depth.is_nan() {
            return;
        }
        let layer = (depth / spacing_m).ceil();
        if layer <= walls {
            particles.push(x, ParticleKind::Wall);
        } else if layer <= all {
            particles.push(x, ParticleKind::Dummy);
        }
    });
}

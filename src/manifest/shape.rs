//! Solid shapes as the manifest describes them: boxes, spheres, cylinders and frustums, and
//! their unions and differences (the geometry module of the tests, `src/experiment/geometry/shapes.rs`, fills them).
//!
//! Every shape is a mapping tagged by `kind`; lengths are in metres and points have one
//! component per spatial dimension (x, y in 2D; x, y, z in 3D):
//!
//! ```yaml
//! kind: box
//! min_m: [0.0, 0.0]
//! max_m: [1.0, 0.6]
//! ```
//!
//! Because a shape is read ahead untyped (to find its `kind`), YAML's `.nan` and `.inf`
//! inside one are refused when the YAML is read; [`check`] still refuses non-finite numbers
//! in shapes that reach it another way.
//!
//! Field paths in [`check`]'s issues name list items by their index as a dotted segment
//! (`of.1.radius_m`, `min_m.0`), as the manifest's source map does.

use serde::{Deserialize, Serialize};

/// Deepest nesting of unions and differences that [`check`] accepts (a plain shape is 1).
pub const MAX_DEPTH: usize = 16;

/// A coordinate axis: `x`, `y` or `z`.
///
/// Inside a shape (a mapping tagged by `kind`, which serde reads ahead untyped) an unquoted
/// `y` arrives as YAML 1.1's boolean `true`; it is read as the y axis (so are `yes`, `on`
/// and `true`, the other spellings of that boolean), `false` is refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Axis {
    X,
    Y,
    Z,
}

impl<'de> Deserialize<'de> for Axis {
    fn deserialize<De: serde::Deserializer<'de>>(deserializer: De) -> Result<Axis, De::Error> {
        struct AxisVisitor;
        impl serde::de::Visitor<'_> for AxisVisitor {
            type Value = Axis;
            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                f.write_str("an axis: x, y or z")
            }
            fn visit_str<E: serde::de::Error>(self, v: &str) -> Result<Axis, E> {
                match v {
                    "x" => Ok(Axis::X),
                    "y" => Ok(Axis::Y),
                    "z" => Ok(Axis::Z),
                    _ => Err(E::unknown_variant(v, &["x", "y", "z"])),
                }
            }
            fn visit_bool<E: serde::de::Error>(self, v: bool) -> Result<Axis, E> {
                if v {
                    Ok(Axis::Y)
                } else {
                    Err(E::invalid_value(serde::de::Unexpected::Bool(v), &self))
                }
            }
        }
        deserializer.deserialize_any(AxisVisitor)
    }
}

impl Axis {
    /// 0 for x, 1 for y, 2 for z.
    pub fn index(self) -> usize {
        match self {
            Axis::X => 0,
            Axis::Y => 1,
            Axis::Z => 2,
        }
    }
}

/// A solid, tagged by the `kind` key.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum ShapeSpec {
    /// Axis-aligned box from `min_m` to `max_m` (a rectangle in 2D).
    Box {
        /// Lowest corner, metres.
        min_m: Vec<f64>,
        /// Highest corner, metres.
        max_m: Vec<f64>,
    },
    /// Ball (a disc in 2D).
    Sphere {
        /// Centre, metres.
        centre_m: Vec<f64>,
        /// Radius, metres.
        radius_m: f64,
    },
    /// Axis-aligned circular cylinder; in 2D a rectangle (the radial distance is the other
    /// coordinate's distance from the axis).
    Cylinder {
        /// Centre of the bottom end (the end at the lower `axis` coordinate), metres.
        base_centre_m: Vec<f64>,
        /// Direction of the axis (bottom to top = increasing coordinate).
        axis: Axis,
        /// Radius, metres.
        radius_m: f64,
        /// Length along the axis, metres.
        height_m: f64,
    },
    /// Axis-aligned truncated cone, radius linear from `bottom_radius_m` at the base to
    /// `top_radius_m` one height further along `axis`; in 2D a trapezoid.
    Frustum {
        /// Centre of the bottom end (the end at the lower `axis` coordinate), metres.
        base_centre_m: Vec<f64>,
        /// Direction of the axis (bottom to top = increasing coordinate).
        axis: Axis,
        /// Radius at the base, metres.
        bottom_radius_m: f64,
        /// Radius at the top, metres.
        top_radius_m: f64,
        /// Length along the axis, metres.
        height_m: f64,
    },
    /// Every point in at least one of the shapes.
    Union {
        /// The shapes (at least one).
        of: Vec<ShapeSpec>,
    },
    /// The points of `from` that are in none of `remove`.
    Difference {
        /// The shape to cut from.
        from: Box<ShapeSpec>,
        /// The shapes cut away (at least one).
        remove: Vec<ShapeSpec>,
    },
}

impl ShapeSpec {
    /// The `kind` tag, e.g. `"box"`.
    pub fn kind_name(&self) -> &'static str {
        match self {
            ShapeSpec::Box { .. } => "box",
            ShapeSpec::Sphere { .. } => "sphere",
            ShapeSpec::Cylinder { .. } => "cylinder",
            ShapeSpec::Frustum { .. } => "frustum",
            ShapeSpec::Union { .. } => "union",
            ShapeSpec::Difference { .. } => "difference",
        }
    }
}

/// Every problem of `spec` in a `dimension`-dimensional scene, as (dotted field path,
/// message), in field order; `field` is the path of `spec` itself (e.g. `bodies.0.shape`).
/// Checks: points have `dimension` components, every number is finite, radii and heights
/// are > 0, a box's min < max on every axis, no z axis in 2D, unions and differences list at
/// least one shape, and nesting is at most [`MAX_DEPTH`] deep (deeper shapes are not
/// looked into).
pub fn check(spec: &ShapeSpec, dimension: usize, field: &str) -> Vec<(String, String)> {
    let mut issues = Vec::new();
    check_at(spec, dimension, field, 1, &mut issues);
    issues
}

fn join(prefix: &str, seg: &str) -> String {
    if prefix.is_empty() {
        seg.to_string()
    } else {
        format!("{prefix}.{seg}")
    }
}

/// Short number formatting: `1` not `1.0`.
fn fmt_num(x: f64) -> String {
    if x == x.trunc() && x.abs() < 1e15 {
        format!("{}", x as i64)
    } else {
        format!("{x:?}")
    }
}

/// A point: `dimension` finite components. Returns whether it passed.
fn point(issues: &mut Vec<(String, String)>, field: &str, v: &[f64], dimension: usize) -> bool {
    let mut ok = true;
    if v.len() != dimension {
        issues.push((
            field.to_string(),
            format!(
                "must have {dimension} components (one per axis, dimension {dimension}), got {}",
                v.len()
            ),
        ));
        ok = false;
    }
    for (i, x) in v.iter().enumerate() {
        if !x.is_finite() {
            issues.push((
                join(field, &i.to_string()),
                format!("must be a finite number, got {x:?}"),
            ));
            ok = false;
        }
    }
    ok
}

/// A finite number > 0. Returns whether it passed.
fn positive(issues: &mut Vec<(String, String)>, field: &str, x: f64) -> bool {
    if !x.is_finite() {
        issues.push((
            field.to_string(),
            format!("must be a finite number, got {x:?}"),
        ));
        false
    } else if x <= 0.0 {
        issues.push((
            field.to_string(),
            format!("must be > 0, got {}", fmt_num(x)),
        ));
        false
    } else {
        true
    }
}

fn axis_ok(issues: &mut Vec<(String, String)>, field: &str, axis: Axis, dimension: usize) {
    if axis.index() >= dimension {
        issues.push((
            field.to_string(),
            format!("must be x or y in {dimension}D, got z"),
        ));
    }
}

fn check_at(
    spec: &ShapeSpec,
    dimension: usize,
    field: &str,
    depth: usize,
    issues: &mut Vec<(String, String)>,
) {
    if depth > MAX_DEPTH {
        issues.push((
            field.to_string(),
            format!("shapes may be nested at most {MAX_DEPTH} deep"),
        ));
        return;
    }
    let at = |seg: &str| join(field, seg);
    match spec {
        ShapeSpec::Box { min_m, max_m } => {
            let lo_ok = point(issues, &at("min_m"), min_m, dimension);
            let hi_ok = point(issues, &at("max_m"), max_m, dimension);
            if lo_ok && hi_ok {
                for (a, (lo, hi)) in min_m.iter().zip(max_m).enumerate() {
                    if hi <= lo {
                        issues.push((
                            join(&at("max_m"), &a.to_string()),
                            format!(
                                "must be > min_m.{a} ({}), got {}",
                                fmt_num(*lo),
                                fmt_num(*hi)
                            ),
                        ));
                    }
                }
            }
        }
        ShapeSpec::Sphere { centre_m, radius_m } => {
            point(issues, &at("centre_m"), centre_m, dimension);
            positive(issues, &at("radius_m"), *radius_m);
        }
        ShapeSpec::Cylinder {
            base_centre_m,
            axis,
            radius_m,
            height_m,
        } => {
            point(issues, &at("base_centre_m"), base_centre_m, dimension);
            axis_ok(issues, &at("axis"), *axis, dimension);
            positive(issues, &at("radius_m"), *radius_m);
            positive(issues, &at("height_m"), *height_m);
        }
        ShapeSpec::Frustum {
            base_centre_m,
            axis,
            bottom_radius_m,
            top_radius_m,
            height_m,
        } => {
            point(issues, &at("base_centre_m"), base_centre_m, dimension);
            axis_ok(issues, &at("axis"), *axis, dimension);
            positive(issues, &at("bottom_radius_m"), *bottom_radius_m);
            positive(issues, &at("top_radius_m"), *top_radius_m);
            positive(issues, &at("height_m"), *height_m);
        }
        ShapeSpec::Union { of } => {
            if of.is_empty() {
                issues.push((at("of"), "must list at least one shape".to_string()));
            }
            for (i, s) in of.iter().enumerate() {
                check_at(
                    s,
                    dimension,
                    &join(&at("of"), &i.to_string()),
                    depth + 1,
                    issues,
                );
            }
        }
        ShapeSpec::Difference { from, remove } => {
            check_at(from, dimension, &at("from"), depth + 1, issues);
            if remove.is_empty() {
                issues.push((at("remove"), "must list at least one shape".to_string()));
            }
            for (i, s) in remove.iter().enumerate() {
                check_at(
                    s,
                    dimension,
                    &join(&at("remove"), &i.to_string()),
                    depth + 1,
                    issues,
                );
            }
        }
    }
}

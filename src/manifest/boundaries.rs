//! The `boundaries:` section: pieces any test can add to its scene: static obstacles, rigid
//! bodies moving on keyframe paths, inlets that pour fluid during the run, and tags that mark
//! initial fluid by region. Empty by default; an empty section is left out of the canonical
//! form, so manifests without it keep their hashes.
use serde::{Deserialize, Serialize};

use super::shape::{self, ShapeSpec};

/// Most items in each list of the section (a typo guard: each item costs a scan of the
/// lattice).
pub const MAX_ITEMS: usize = 256;
/// Most keyframes of one path.
pub const MAX_KEYFRAMES: usize = 10_000;

#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Boundaries {
    /// Static solids filled with wall and dummy layers (e.g. rocks). Initial fluid inside one
    /// is left out.
    pub obstacles: Vec<ShapeSpec>,
    /// Rigid solids of wall and dummy layers that move on keyframe paths (e.g. a rod).
    pub bodies: Vec<Body>,
    /// Openings through which fluid enters during the run.
    pub inlets: Vec<Inlet>,
    /// Tags of the initial fluid inside regions (later rules win); 0 elsewhere.
    pub tags: Vec<TagRegion>,
}

impl Boundaries {
    pub fn is_empty(&self) -> bool {
        self == &Boundaries::default()
    }
}

/// A rigid body: a solid whose wall particles follow a piecewise-linear path.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Body {
    /// The solid at its initial position (offset 0).
    pub shape: ShapeSpec,
    /// Offsets of the body from its initial position at given times; linear in between; the
    /// body holds its first offset before the first time and its last after the last time.
    pub keyframes: Vec<Keyframe>,
    /// Period after which the path starts again from its first keyframe (>= the time the
    /// keyframes span; the last offset is held in the gap). null = no repeat.
    #[serde(default)]
    pub repeat_s: Option<f64>,
    /// Navier slip length of the body's surface, metres (0: no slip at the surface; large:
    /// free slip). Absent: its particles carry the body's velocity, as every wall does.
    #[serde(default)]
    pub slip_length_m: Option<f64>,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Keyframe {
    /// Simulated time, seconds.
    pub time_s: f64,
    /// Offset from the initial position, metres (one component per axis).
    pub offset_m: Vec<f64>,
}

/// A disc (3D) or segment (2D) through which fluid enters at a set velocity.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Inlet {
    /// Centre of the opening, metres.
    pub centre_m: Vec<f64>,
    /// Direction of the inflow (need not be of unit length; it is normalised).
    pub direction: Vec<f64>,
    /// Diameter of the disc (3D) or length of the segment (2D), metres.
    pub diameter_m: f64,
    /// Inflow speed, m/s.
    pub speed_m_s: f64,
    /// Volume to pour, m^3 (m^2 per metre of depth in 2D).
    pub volume_m3: f64,
    /// Time the pour starts, seconds.
    #[serde(default)]
    pub start_s: f64,
    /// Tag of the poured particles.
    #[serde(default)]
    pub tag: u16,
    /// A due layer enters only once no fluid is closer than this to its points (units of
    /// spacing): the layer before has moved on. Below 1 so that a layer that entered up to a
    /// step late does not hold the next one back; it bounds how densely layers can pack.
    #[serde(default = "default_clearance")]
    pub clearance: f64,
}

fn default_clearance() -> f64 {
    0.9
}

/// Initial fluid inside `region` gets `tag`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TagRegion {
    pub tag: u16,
    pub region: ShapeSpec,
}

/// Every problem of the section, as (field path, message), in field order.
pub fn check(b: &Boundaries, dimension: usize) -> Vec<(String, String)> {
    let mut out = Vec::new();
    let d = dimension;
    for (list, len) in [
        ("boundaries.obstacles", b.obstacles.len()),
        ("boundaries.bodies", b.bodies.len()),
        ("boundaries.inlets", b.inlets.len()),
        ("boundaries.tags", b.tags.len()),
    ] {
        if len > MAX_ITEMS {
            out.push((
                list.to_string(),
                format!("at most {MAX_ITEMS} items, got {len}"),
            ));
        }
    }
    for (i, s) in b.obstacles.iter().enumerate() {
        out.extend(shape::check(s, d, &format!("boundaries.obstacles.{i}")));
    }
    for (i, body) in b.bodies.iter().enumerate() {
        let at = format!("boundaries.bodies.{i}");
        out.extend(shape::check(&body.shape, d, &format!("{at}.shape")));
        check_path(body, d, &at, &mut out);
    }
    for (i, inlet) in b.inlets.iter().enumerate() {
        check_inlet(inlet, d, &format!("boundaries.inlets.{i}"), &mut out);
    }
    for (i, t) in b.tags.iter().enumerate() {
        out.extend(shape::check(
            &t.region,
            d,
            &format!("boundaries.tags.{i}.region"),
        ));
    }
    out
}

fn finite_vector(v: &[f64], d: usize, field: &str, out: &mut Vec<(String, String)>) -> bool {
    if v.len() != d {
        out.push((
            field.to_string(),
            format!("must have {d} components (one per axis), got {}", v.len()),
        ));
        return false;
    }
    if let Some(k) = v.iter().position(|x| !x.is_finite()) {
        out.push((
            format!("{field}.{k}"),
            format!("must be a finite number, got {:?}", v[k]),
        ));
        return false;
    }
    true
}

fn check_path(body: &Body, d: usize, at: &str, out: &mut Vec<(String, String)>) {
    let k = &body.keyframes;
    if k.is_empty() || k.len() > MAX_KEYFRAMES {
        out.push((
            format!("{at}.keyframes"),
            format!("must list 1 to {MAX_KEYFRAMES} keyframes, got {}", k.len()),
        ));
        return;
    }
    for (j, f) in k.iter().enumerate() {
        let field = format!("{at}.keyframes.{j}");
        if !f.time_s.is_finite() || f.time_s < 0.0 {
            out.push((
                format!("{field}.time_s"),
                format!("must be a finite number >= 0, got {:?}", f.time_s),
            ));
        } else if j > 0 && f.time_s <= k[j - 1].time_s {
            out.push((
                format!("{field}.time_s"),
                format!(
                    "keyframe times must increase strictly, got {:?} after {:?}",
                    f.time_s,
                    k[j - 1].time_s
                ),
            ));
        }
        finite_vector(&f.offset_m, d, &format!("{field}.offset_m"), out);
    }
    if let Some(period) = body.repeat_s {
        let span = k[k.len() - 1].time_s - k[0].time_s;
        if !period.is_finite() || period <= 0.0 || period < span {
            out.push((
                format!("{at}.repeat_s"),
                format!(
                    "must be a finite number > 0 and >= the keyframes' span ({span:?} s), got {period:?}"
                ),
            ));
        }
    }
    if let Some(b) = body.slip_length_m
        && !(b.is_finite() && b >= 0.0)
    {
        out.push((
            format!("{at}.slip_length_m"),
            format!("must be a finite number >= 0 (metres), got {b:?}"),
        ));
    }
}

fn check_inlet(inlet: &Inlet, d: usize, at: &str, out: &mut Vec<(String, String)>) {
    finite_vector(&inlet.centre_m, d, &format!("{at}.centre_m"), out);
    if finite_vector(&inlet.direction, d, &format!("{at}.direction"), out)
        && inlet.direction.iter().all(|x| *x == 0.0)
    {
        out.push((
            format!("{at}.direction"),
            "must not be the zero vector".to_string(),
        ));
    }
    for (name, x, min) in [
        ("diameter_m", inlet.diameter_m, 0.0),
        ("speed_m_s", inlet.speed_m_s, 0.0),
        ("volume_m3", inlet.volume_m3, 0.0),
    ] {
        if !(x.is_finite() && x > min) {
            out.push((format!("{at}.{name}"), format!("must be > 0, got {x:?}")));
        }
    }
    if !(inlet.clearance.is_finite() && inlet.clearance >= 0.5 && inlet.clearance <= 1.0) {
        out.push((
            format!("{at}.clearance"),
            format!(
                "must be in [0.5, 1] (units of spacing), got {:?}",
                inlet.clearance
            ),
        ));
    }
    if !(inlet.start_s.is_finite() && inlet.start_s >= 0.0) {
        out.push((
            format!("{at}.start_s"),
            format!("must be >= 0, got {:?}", inlet.start_s),
        ));
    }
}

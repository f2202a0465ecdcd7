//! L-B box, 3D (seed 004, section 3): concrete poured through a circular inlet at the top of
//! a vertical part flows into a horizontal part that holds glass spheres standing in for
//! rocks (rock-filled concrete). Without spheres the box is an L-box, whose free surface at
//! rest has a closed form (Nguyen, Roussel & Coussot 2006).
//!
//! Geometry (docs/validation.md, *The L-B box*): x along the box from the inner back wall of the
//! vertical part, y across it (inner width `width_m`), z up from the floor. The vertical part
//! is x in [0, vertical_width_m], walls up to `vertical_height_m`, open on top; the
//! horizontal part runs on to x = vertical_width_m + channel_length_m under a lid at
//! `channel_height_m`. Lengths are snapped to whole lattice cells, as in the L-flow box.
//! The spheres are static solids of wall and dummy layers; the inlet is a disc in the plane
//! z = `inlet_height_m` pouring downwards.
mod profile;

use super::boundaries::{fill_solid, taken_cells};
use super::geometry::container::{CellBox, add_walls, l_box_parts};
use super::geometry::lattice::cells;
use super::geometry::shapes::Shape;
use super::{Experiment, Manifest, Scene, SurfaceProfile, yield_stress_pa};
use crate::manifest::validate::{Checker, POSITIVE, fmt_num};
use crate::mps::grid::MirrorPlanes;
use crate::mps::particles::cell_volume;
use crate::mps::{Inlet, ParticleKind, Particles, Vector};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// Most spheres (each costs a scan of its cells).
pub const MAX_SPHERES: usize = 256;

/// `scene: {kind: lb_box}`, 3D only. Defaults: docs/validation.md, *The L-B box*.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LbBox {
    /// Inner length (x) of the vertical part, in metres.
    pub vertical_width_m: f64,
    /// Wall height of the vertical part (open above), in metres.
    pub vertical_height_m: f64,
    /// Length of the horizontal part beyond the vertical part, in metres.
    pub channel_length_m: f64,
    /// Inner height of the horizontal part (under its lid), in metres.
    pub channel_height_m: f64,
    /// Inner width (y) of the whole box, in metres: the W of the closed form.
    pub width_m: f64,
    /// Diameter of the circular inlet, in metres.
    pub inlet_diameter_m: f64,
    /// x of the inlet's centre (its y is the box's middle), in metres.
    pub inlet_x_m: f64,
    /// Height of the inlet's plane above the floor, in metres.
    pub inlet_height_m: f64,
    /// Speed of the concrete through the inlet (downwards), m/s.
    pub inlet_speed_m_s: f64,
    /// Volume poured through the inlet, m^3.
    pub pour_volume_m3: f64,
    /// Diameter of the spheres (rocks), in metres.
    pub sphere_diameter_m: f64,
    /// Centres of the spheres [x, y, z], in metres; none: an L-box.
    pub sphere_centres_m: Vec<Vec<f64>>,
    /// Height above the floor up to which `filling_rate` measures the void around the
    /// spheres, in metres.
    pub filling_height_m: f64,
    /// Simulate the half y >= W/2 beside a mirror symmetry plane through the box's middle
    /// (the inlet's axis; the spheres must be symmetric about it); metrics are those of the
    /// whole box.
    pub half_domain: bool,
}

impl Default for LbBox {
    fn default() -> Self {
        // Four spheres on the floor in a row along the middle of the horizontal part, 200 mm
        // apart, the first 50 mm past the vertical part: the rock zone (x 0.25-1.45 m) spans
        // the concrete's reach down to 20 Pa, so concrete that gets further stays among them.
        let sphere = |x: f64| vec![x, 0.1, 0.075];
        Self {
            vertical_width_m: 0.2,
            vertical_height_m: 0.5,
            channel_length_m: 1.4,
            channel_height_m: 0.25,
            width_m: 0.2,
            inlet_diameter_m: 0.06,
            inlet_x_m: 0.1,
            inlet_height_m: 0.45,
            inlet_speed_m_s: 1.0,
            pour_volume_m3: 0.013,
            sphere_diameter_m: 0.15,
            sphere_centres_m: vec![sphere(0.325), sphere(0.675), sphere(1.025), sphere(1.375)],
            filling_height_m: 0.15,
            half_domain: false,
        }
    }
}

/// The surface heights reported as metrics, at these shares of the filling distance past
/// the vertical part.
const SURFACE_SHARES: [(&str, f64); 3] = [("x25", 0.25), ("x50", 0.5), ("x75", 0.75)];

impl Experiment for LbBox {
    fn flow_measures(&self) -> &'static [&'static str] {
        &["filling_distance_m", "filling_rate"]
    }

    fn surface_profile(
        &self,
        m: &Manifest,
        particles: &Particles<3>,
        time_s: f64,
        title: &str,
    ) -> Option<Result<SurfaceProfile, String>> {
        Some(self.profile(m, particles, time_s).map(|p| p.figure(title)))
    }
    fn check(&self, m: &Manifest, c: &mut Checker) {
        super::require_3d(m, c, "lb_box", "a circular inlet, spheres");
        let dims = [
            ("scene.vertical_width_m", self.vertical_width_m),
            ("scene.vertical_height_m", self.vertical_height_m),
            ("scene.channel_length_m", self.channel_length_m),
            ("scene.channel_height_m", self.channel_height_m),
            ("scene.width_m", self.width_m),
        ];
        let mut ok = true;
        for (field, x) in dims {
            ok &= c.real(field, x, POSITIVE);
        }
        for (field, x) in [
            ("scene.inlet_diameter_m", self.inlet_diameter_m),
            ("scene.inlet_x_m", self.inlet_x_m),
            ("scene.inlet_height_m", self.inlet_height_m),
            ("scene.inlet_speed_m_s", self.inlet_speed_m_s),
            ("scene.pour_volume_m3", self.pour_volume_m3),
            ("scene.sphere_diameter_m", self.sphere_diameter_m),
            ("scene.filling_height_m", self.filling_height_m),
        ] {
            ok &= c.real(field, x, POSITIVE);
        }
        if self.sphere_centres_m.len() > MAX_SPHERES {
            c.fail(
                "scene.sphere_centres_m",
                format!(
                    "at most {MAX_SPHERES} spheres, got {}",
                    self.sphere_centres_m.len()
                ),
            );
            ok = false;
        }
        for (k, centre) in self.sphere_centres_m.iter().enumerate() {
            let at = format!("scene.sphere_centres_m.{k}");
            if centre.len() != 3 {
                c.fail(
                    &at,
                    format!("must be [x, y, z] (3 numbers), got {} numbers", centre.len()),
                );
                ok = false;
                continue;
            }
            for (a, &x) in centre.iter().enumerate() {
                ok &= c.real(&format!("{at}.{a}"), x, crate::manifest::validate::NON_NEGATIVE);
            }
        }
        if !ok {
            return;
        }
        let at_most = |c: &mut Checker, field: &str, x: f64, limit: f64, what: &str| {
            if x > limit {
                c.fail(
                    field,
                    format!("must be <= {what} ({}), got {}", fmt_num(limit), fmt_num(x)),
                );
            }
        };
        at_most(
            c,
            "scene.channel_height_m",
            self.channel_height_m,
            self.vertical_height_m,
            "scene.vertical_height_m",
        );
        at_most(
            c,
            "scene.inlet_height_m",
            self.inlet_height_m,
            self.vertical_height_m,
            "scene.vertical_height_m",
        );
        at_most(
            c,
            "scene.filling_height_m",
            self.filling_height_m,
            self.channel_height_m,
            "scene.channel_height_m",
        );
        let r_in = 0.5 * self.inlet_diameter_m;
        if self.inlet_x_m - r_in < 0.0 || self.inlet_x_m + r_in > self.vertical_width_m {
            c.fail(
                "scene.inlet_x_m",
                format!(
                    "the inlet (x {} +- {} m) must lie over the vertical part, x in [0, {}]",
                    fmt_num(self.inlet_x_m),
                    fmt_num(r_in),
                    fmt_num(self.vertical_width_m)
                ),
            );
        }
        at_most(
            c,
            "scene.inlet_diameter_m",
            self.inlet_diameter_m,
            self.width_m,
            "scene.width_m",
        );
        if self.inlet_height_m <= self.channel_height_m {
            c.fail(
                "scene.inlet_height_m",
                format!(
                    "must be > scene.channel_height_m ({}): the inlet pours into the vertical part above the horizontal part, got {}",
                    fmt_num(self.channel_height_m),
                    fmt_num(self.inlet_height_m)
                ),
            );
        }
        let r = 0.5 * self.sphere_diameter_m;
        let length = self.vertical_width_m + self.channel_length_m;
        for (k, s) in self.sphere_centres_m.iter().enumerate() {
            let inside = s[0] - r >= 0.0
                && s[0] + r <= length
                && s[1] - r >= 0.0
                && s[1] + r <= self.width_m
                && s[2] - r >= 0.0
                && s[2] + r <= self.channel_height_m;
            if !inside {
                c.fail(
                    &format!("scene.sphere_centres_m.{k}"),
                    format!(
                        "a sphere of diameter {} m at {s:?} must lie inside the box below its lid: x in [0, {}], y in [0, {}], z in [0, {}]",
                        fmt_num(self.sphere_diameter_m),
                        fmt_num(length),
                        fmt_num(self.width_m),
                        fmt_num(self.channel_height_m)
                    ),
                );
            }
        }
        super::refuse_planes_without_images(m, c, "scene.half_domain", self.half_domain);
        if super::spacing_ok(m) {
            c.lattice_lengths(&dims, m.spacing_m);
            if self.half_domain {
                self.check_half_domain(m.spacing_m, c);
            }
            if c.is_clean()
                && let Err(message) = self.inlet::<3>(m.spacing_m).validate(m.spacing_m)
            {
                c.fail("scene.inlet_diameter_m", message);
            }
        }
    }

    fn build<const D: usize>(&self, m: &Manifest) -> Scene<D> {
        assert!(D == 3, "the L-B box is 3D");
        let l0 = m.spacing_m;
        let (vertical_part, channel) = self.parts::<D>(l0);
        let mut particles = Particles::<D>::default();
        add_walls(
            &mut particles,
            &[vertical_part, channel],
            vertical_part.1[D - 1],
            l0,
            m.mps.wall_layers,
            m.mps.dummy_layers,
        );
        let mut taken = taken_cells(&particles);
        for sphere in self.spheres::<D>() {
            fill_solid(
                &mut particles,
                &sphere,
                l0,
                m.mps.wall_layers_of_solids(),
                m.mps.dummy_layers,
                &mut taken,
            );
        }
        let mut symmetry = MirrorPlanes::default();
        if self.half_domain {
            // The whole box is built, then cut at the plane: what stays is the whole's half
            // y > W/2, and the mirror images stand for the rest.
            let plane_m = self.mirror_plane_m(l0);
            particles.retain(|x| x[1] > plane_m);
            symmetry = MirrorPlanes {
                axes: 0b010,
                position_m: [0.0, plane_m, 0.0],
            };
        }
        let (domain_min_m, domain_max_m) = self.domain::<D>(m);
        Scene {
            particles,
            domain_min_m,
            domain_max_m,
            bodies: Vec::new(),
            inlets: vec![self.inlet(l0)],
            gravity_tilt_rad: 0.0,
            periodic_x: None,
            symmetry,
        }
    }

    fn domain<const D: usize>(&self, m: &Manifest) -> (Vector<D>, Vector<D>) {
        let (vertical_part, channel) = self.parts::<D>(m.spacing_m);
        super::l_flow::domain::<D>(vertical_part, channel, m.spacing_m)
    }

    fn metric_names(&self, m: &Manifest) -> Vec<&'static str> {
        let mut names = vec![
            "poured_volume_m3",
            "filling_distance_m",
            "surface_height_x25_m",
            "surface_height_x50_m",
            "surface_height_x75_m",
        ];
        if !self.sphere_centres_m.is_empty() {
            names.push("filling_rate");
        } else if yield_stress_pa(&m.fluid) > 0.0 {
            names.extend([
                "closed_form_filling_distance_m",
                "closed_form_height_x25_m",
                "closed_form_height_x50_m",
                "closed_form_height_x75_m",
            ]);
        }
        names
    }

    /// docs/validation.md, *The L-B box*: poured volume, filling distance, filling rate, surface
    /// heights and (no spheres) the L-box closed forms.
    fn metrics<const D: usize>(
        &self,
        m: &Manifest,
        particles: &Particles<D>,
        _time_s: f64,
        out: &mut BTreeMap<String, f64>,
    ) {
        let l0 = m.spacing_m;
        let g = self.lattice(l0);
        let volume_m3 = self.copies() * particles.fluid_count() as f64 * cell_volume(l0, D);
        out.insert("poured_volume_m3".into(), volume_m3);
        let front_m = super::front_position_m(particles, l0);
        let distance_m = super::front_past_m(particles, g.gate_x_m, l0);
        out.insert("filling_distance_m".into(), distance_m);
        let stations = SURFACE_SHARES.map(|(name, share)| (name, g.gate_x_m + share * distance_m));
        for (name, x) in stations {
            out.insert(
                format!("surface_height_{name}_m"),
                surface_height_m(particles, l0, x),
            );
        }
        if !self.sphere_centres_m.is_empty() {
            out.insert("filling_rate".into(), self.filling_rate(particles, l0));
            return;
        }
        let tau = yield_stress_pa(&m.fluid);
        if tau <= 0.0 {
            return;
        }
        let k_m = tau / (m.fluid.density_kg_m3() * m.gravity_m_s2);
        let heap_m = heap_length_m(k_m, g.width_m, volume_m3);
        out.insert(
            "closed_form_filling_distance_m".into(),
            (heap_m - g.gate_x_m).max(0.0),
        );
        for (name, x) in stations {
            out.insert(
                format!("closed_form_height_{name}_m"),
                closed_form_height_m(k_m, g.width_m, front_m - x),
            );
        }
    }

    fn trend_metric(&self) -> &'static str {
        "filling_distance_m"
    }
}

/// The box's lengths as the lattice makes them (whole cells).
#[derive(Debug, Clone, Copy)]
pub struct Lattice {
    /// x of the end of the vertical part (where the horizontal part begins).
    pub gate_x_m: f64,
    /// Inner width W.
    pub width_m: f64,
}

impl LbBox {
    pub fn lattice(&self, spacing_m: f64) -> Lattice {
        let n = |x: f64| cells(x, spacing_m) as f64 * spacing_m;
        Lattice {
            gate_x_m: n(self.vertical_width_m),
            width_m: n(self.width_m),
        }
    }

    /// The mirror plane y = W/2 of `half_domain` must be a cell face of the lattice (W an
    /// even number of spacings) and every sphere must be its own mirror image or have one.
    fn check_half_domain(&self, spacing_m: f64, c: &mut Checker) {
        let n = cells(self.width_m, spacing_m);
        if n % 2 != 0 {
            c.fail(
                "scene.half_domain",
                format!(
                    "needs scene.width_m to be an even number of spacings (the mirror plane y = W/2 on a cell face), got {n} spacings of {} m",
                    fmt_num(spacing_m)
                ),
            );
            return;
        }
        let plane_m = self.mirror_plane_m(spacing_m);
        // A nanometre: far below a spacing, far above the round-off of a written centre.
        let same = |a: f64, b: f64| (a - b).abs() <= 1e-9;
        for (k, s) in self.sphere_centres_m.iter().enumerate() {
            let mirror_y = 2.0 * plane_m - s[1];
            let mirrored = same(s[1], plane_m)
                || self.sphere_centres_m.iter().any(|t| {
                    same(t[0], s[0]) && same(t[1], mirror_y) && same(t[2], s[2])
                });
            if !mirrored {
                c.fail(
                    &format!("scene.sphere_centres_m.{k}"),
                    format!(
                        "with scene.half_domain the spheres must be symmetric about y = {} m (half the lattice's width): centred on it, or with a twin at y = {}",
                        fmt_num(plane_m),
                        fmt_num(mirror_y)
                    ),
                );
            }
        }
    }

    /// y of the mirror plane of `half_domain`: half the lattice's width.
    pub fn mirror_plane_m(&self, spacing_m: f64) -> f64 {
        0.5 * self.lattice(spacing_m).width_m
    }

    /// How many copies of the simulated part the whole box holds (2 for `half_domain`):
    /// counts of concrete are multiplied by it.
    pub fn copies(&self) -> f64 {
        if self.half_domain { 2.0 } else { 1.0 }
    }

    fn parts<const D: usize>(
        &self,
        spacing_m: f64,
    ) -> (CellBox<D>, CellBox<D>) {
        l_box_parts::<D>(
            self.vertical_width_m,
            self.vertical_height_m,
            self.channel_length_m,
            self.channel_height_m,
            self.width_m,
            spacing_m,
        )
    }

    fn spheres<const D: usize>(&self) -> Vec<Shape<D>> {
        self.sphere_centres_m
            .iter()
            .map(|c| Shape::Sphere {
                centre_m: Vector::<D>::from_fn(|a, _| c[a]),
                radius_m: 0.5 * self.sphere_diameter_m,
            })
            .collect()
    }

    /// The inlet: a disc at (inlet_x_m, W/2, inlet_height_m) pouring downwards.
    pub fn inlet<const D: usize>(&self, spacing_m: f64) -> Inlet<D> {
        let w = self.lattice(spacing_m).width_m;
        Inlet {
            centre_m: Vector::<D>::from_fn(|a, _| match a {
                0 => self.inlet_x_m,
                1 => 0.5 * w,
                _ => self.inlet_height_m,
            }),
            direction: Vector::<D>::from_fn(|a, _| if a == D - 1 { -1.0 } else { 0.0 }),
            radius_m: 0.5 * self.inlet_diameter_m,
            speed_m_s: self.inlet_speed_m_s,
            // The half beside the mirror plane pours half (the solver keeps the points of
            // the opening on the domain's side).
            volume_m3: self.pour_volume_m3 / self.copies(),
            start_s: 0.0,
            tag: 0,
            clearance_m: 0.9 * spacing_m,
        }
    }

    /// The rock zone: x from the first sphere's front to the last one's back, the whole
    /// width, z from the floor to `filling_height_m`; `None` without spheres.
    pub fn rock_zone_m(&self, spacing_m: f64) -> Option<([f64; 3], [f64; 3])> {
        let r = 0.5 * self.sphere_diameter_m;
        let xs = self.sphere_centres_m.iter().map(|c| c[0]);
        let lo = xs.clone().fold(f64::INFINITY, f64::min) - r;
        let hi = xs.fold(f64::NEG_INFINITY, f64::max) + r;
        (lo < hi).then(|| {
            (
                [lo, 0.0, 0.0],
                [hi, self.lattice(spacing_m).width_m, self.filling_height_m],
            )
        })
    }

    /// Void volume of the rock zone: its box less the parts of the spheres below
    /// `filling_height_m` (each sphere lies inside the box's width and length by validation,
    /// so only the cut at that height matters: a cap of height t holds pi t^2 (3r - t)/3).
    pub fn void_volume_m3(&self, spacing_m: f64) -> f64 {
        let Some((lo, hi)) = self.rock_zone_m(spacing_m) else {
            return 0.0;
        };
        let r = 0.5 * self.sphere_diameter_m;
        let solid: f64 = self
            .sphere_centres_m
            .iter()
            .map(|c| {
                let t = (self.filling_height_m - (c[2] - r)).clamp(0.0, 2.0 * r);
                std::f64::consts::PI * t * t * (3.0 * r - t) / 3.0
            })
            .sum();
        (hi[0] - lo[0]) * (hi[1] - lo[1]) * (hi[2] - lo[2]) - solid
    }

    /// Filling rate: the volume of the concrete in the rock zone (l0^3 for each fluid
    /// particle whose centre lies in it) over the zone's void volume. A full zone gives 1 up
    /// to the method's density fluctuation (a few %).
    pub fn filling_rate<const D: usize>(&self, particles: &Particles<D>, spacing_m: f64) -> f64 {
        let Some((lo, hi)) = self.rock_zone_m(spacing_m) else {
            return 0.0;
        };
        let inside = (0..particles.len())
            .filter(|&i| {
                let x = &particles.position_m[i];
                particles.kind[i] == ParticleKind::Fluid
                    && (0..D).all(|a| x[a] >= lo[a] && x[a] <= hi[a])
            })
            .count();
        self.copies() * inside as f64 * cell_volume(spacing_m, D) / self.void_volume_m3(spacing_m)
    }
}

/// Height of the free surface at `x_m`: the highest fluid particle centre within l0/2 of x
/// (across the whole width), plus l0/2; 0 where there is none.
pub fn surface_height_m<const D: usize>(
    particles: &Particles<D>,
    spacing_m: f64,
    x_m: f64,
) -> f64 {
    let mut top = f64::NEG_INFINITY;
    for i in 0..particles.len() {
        let x = &particles.position_m[i];
        if particles.kind[i] == ParticleKind::Fluid && (x[0] - x_m).abs() < 0.5 * spacing_m {
            top = top.max(x[D - 1]);
        }
    }
    if top.is_finite() {
        top + 0.5 * spacing_m
    } else {
        0.0
    }
}

/// L-box at rest (Nguyen, Roussel & Coussot 2006): distance back from the front at which the
/// surface stands h high, x(h) = (W/(2k)) [h - (W/2) ln(1 + 2h/W)], k = tau_0/(rho g).
pub fn closed_form_distance_m(k_m: f64, width_m: f64, h_m: f64) -> f64 {
    let w = width_m;
    w / (2.0 * k_m) * (h_m - 0.5 * w * libm::log1p(2.0 * h_m / w))
}

/// The inverse of [`closed_form_distance_m`]: the height h(d) at distance d back from the
/// front (0 for d <= 0), by bisection (x(h) increases strictly).
pub fn closed_form_height_m(k_m: f64, width_m: f64, d_m: f64) -> f64 {
    if d_m <= 0.0 {
        return 0.0;
    }
    // h >= sqrt(2 k d) (the 2D heap: side walls only make it steeper) to start from.
    solve_increasing(
        |h| closed_form_distance_m(k_m, width_m, h),
        d_m,
        (2.0 * k_m * d_m).sqrt(),
    )
}

/// The h >= 0 where the increasing f (f(0) = 0) reaches `target`: an upper bound by doubling
/// `start`, then bisection to the last bit; a fixed sequence of operations, so the same bits
/// everywhere.
fn solve_increasing(f: impl Fn(f64) -> f64, target: f64, start: f64) -> f64 {
    let mut hi = start.max(f64::MIN_POSITIVE);
    while f(hi) < target && hi < f64::MAX / 4.0 {
        hi *= 2.0;
    }
    let mut lo = 0.0;
    for _ in 0..2100 {
        let mid = 0.5 * (lo + hi);
        if mid <= lo || mid >= hi {
            break;
        }
        if f(mid) < target {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}

/// Cross-section area A(H) = integral of h dx of that surface from the front back to where it
/// stands H high: (W/(8k)) [u^2/2 - 2 W u + W^2 ln u] from u = W to W + 2H.
pub fn closed_form_area_m2(k_m: f64, width_m: f64, h_m: f64) -> f64 {
    let w = width_m;
    let u = w + 2.0 * h_m;
    let bracket = 0.5 * (u * u - w * w) - 2.0 * w * (u - w) + w * w * libm::log1p(2.0 * h_m / w);
    w / (8.0 * k_m) * bracket
}

/// Length of a heap of volume V at rest against the back wall of an L-box of width W (the
/// closed form's front, measured from the back wall): the height H at the wall solves
/// W A(H) = V (bisection), then L = x(H).
pub fn heap_length_m(k_m: f64, width_m: f64, volume_m3: f64) -> f64 {
    if volume_m3 <= 0.0 {
        return 0.0;
    }
    let area = volume_m3 / width_m;
    // From the height of the heap without side walls, A = H^3/(3k).
    let start = libm::cbrt(3.0 * k_m * area);
    let h = solve_increasing(|h| closed_form_area_m2(k_m, width_m, h), area, start);
    closed_form_distance_m(k_m, width_m, h)
}

pub use profile::{LbProfile, ProfilePoint};

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn closed_form_inverts_and_matches_the_thin_heap() {
        let (k, w) = (42.4 / (2337.0 * 9.81), 0.2);
        for d in [0.01, 0.1, 0.5, 1.2] {
            let h = closed_form_height_m(k, w, d);
            let back = closed_form_distance_m(k, w, h);
            assert!((back - d).abs() < 1e-12 * d.max(1.0), "d {d} h {h} back {back}");
        }
        // Thin layers see no side walls: h -> sqrt(2 k d), x -> h^2/(2k), A -> H^3/(3k).
        let h = 1e-4;
        let x = closed_form_distance_m(k, w, h);
        assert!((x / (h * h / (2.0 * k)) - 1.0).abs() < 1e-3);
        let a = closed_form_area_m2(k, w, h);
        assert!((a / (h * h * h / (3.0 * k)) - 1.0).abs() < 1e-3);
        // A(H) is the integral of h over x: trapezoids in h.
        let big_h = 0.09;
        let n = 20_000;
        let mut area = 0.0;
        for i in 0..n {
            let (h0, h1) = (
                big_h * i as f64 / n as f64,
                big_h * (i + 1) as f64 / n as f64,
            );
            let dx = closed_form_distance_m(k, w, h1) - closed_form_distance_m(k, w, h0);
            area += 0.5 * (h0 + h1) * dx;
        }
        let exact = closed_form_area_m2(k, w, big_h);
        assert!((area / exact - 1.0).abs() < 1e-6, "{area} vs {exact}");
        // The seed's 13 L at 42.4 Pa in a 200 mm box: about 1.2 m.
        let l = heap_length_m(k, w, 0.013);
        assert!(l > 1.1 && l < 1.35, "{l}");
        let big = heap_length_m(k, w, 0.026);
        assert!(big > l);
    }

    /// The half's counts stand for the whole's: a state in the half and the same state with
    /// its mirror image give the same filling rate.
    #[test]
    fn half_domain_counts_its_mirror() {
        let l0 = 0.01;
        let half = LbBox {
            half_domain: true,
            ..LbBox::default()
        };
        let plane_m = half.mirror_plane_m(l0);
        assert_eq!(plane_m, 0.1);
        let mut one_side = Particles::<3>::default();
        let mut both = Particles::<3>::default();
        for k in 0..37 {
            let x = Vector::<3>::new(0.26 + 0.01 * k as f64, 0.105 + 0.002 * k as f64, 0.01);
            one_side.push(x, ParticleKind::Fluid);
            both.push(x, ParticleKind::Fluid);
            both.push(Vector::<3>::new(x[0], 2.0 * plane_m - x[1], x[2]), ParticleKind::Fluid);
        }
        let whole = LbBox::default();
        let (h, w) = (half.filling_rate(&one_side, l0), whole.filling_rate(&both, l0));
        assert!(h > 0.0 && (h - w).abs() <= 1e-15 * w, "half {h}, whole {w}");
        assert!((whole.filling_rate(&one_side, l0) - 0.5 * w).abs() <= 1e-15 * w);
    }

    #[test]
    fn void_volume_of_the_default_rock_zone() {
        let b = LbBox::default();
        let r = 0.075_f64;
        let sphere = 4.0 / 3.0 * std::f64::consts::PI * r * r * r;
        // Spheres on the floor up to their tops: zone 1.2 x 0.2 x 0.15 m less 4 spheres.
        let expected = 1.2 * 0.2 * 0.15 - 4.0 * sphere;
        assert!((b.void_volume_m3(0.01) - expected).abs() < 1e-12);
    }
}

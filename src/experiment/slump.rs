//! Slump-flow test, 3D (seed 004; EN 12350-8): a frustum-shaped cone standing on a square
//! no-slip plate is filled with concrete and lifted; the concrete spreads into a pancake.
//!
//! Geometry: the plate's top surface is z = 0 and the cone's axis is x = y = 0 (a lattice
//! cell corner, so the particle arrangement is symmetric under the quarter turns). Particles
//! sit at cell centres (k + 1/2) l0.
//! - Fluid: every cell centre strictly inside the frustum, z in (0, cone height), radius
//!   R(z) from the bottom radius at z = 0 to the top radius at the cone height.
//! - Plate: `wall_layers` wall and `dummy_layers` dummy layers under the whole square plate
//!   (side `plate_size_m`), no rim: fluid that runs off the edge falls and becomes a ghost when
//!   it leaves the domain box.
//! - Cone: the cells whose horizontal distance r from the axis lies in
//!   [R(z), R(z) + wall_layers l0) are wall particles, those in the next `dummy_layers` l0
//!   dummies (z from 0 to the cone height; the cone is open at the top and bottom). Built
//!   last, so the cone is one index range, which the solver lifts.
use super::geometry::lattice::{cells, centre, for_each_index};
use super::{Curve, Experiment, Manifest, Scene, SurfaceProfile, yield_stress_pa};
use crate::manifest::validate::{Checker, NON_NEGATIVE, POSITIVE, fmt_num};
use crate::mps::grid::MirrorPlanes;
use crate::mps::particles::cell_volume;
use crate::mps::{ParticleKind, Particles, Path, RigidBody, Vector};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// `scene: {kind: slump}`, 3D only (seed 004; EN 12350-8): a frustum cone (open at both
/// ends) standing on a square no-slip plate, filled with concrete and lifted. The plate's top
/// is z = 0, the cone's axis x = y = 0.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Slump {
    /// Inner height of the cone, in metres.
    pub cone_height_m: f64,
    /// Inner diameter at the bottom (on the plate), in metres.
    pub cone_bottom_diameter_m: f64,
    /// Inner diameter at the top, in metres.
    pub cone_top_diameter_m: f64,
    /// Side of the square plate, in metres.
    pub plate_size_m: f64,
    /// Lift speed of the cone, m/s; 0 = no cone (removed at once at t = 0).
    pub lift_speed_m_s: f64,
    /// Simulated time at which the lift starts, in seconds (the concrete rests in the cone
    /// before).
    pub lift_start_s: f64,
    /// How far the cone is lifted, in metres; it then stays there, clear of the concrete.
    pub lift_height_m: f64,
    /// Navier slip length of the cone's steel, in metres (0: no slip at its surface; large:
    /// free slip). Absent: the cone's particles carry its velocity, as every wall does.
    pub cone_slip_length_m: Option<f64>,
    /// Simulate one quarter (x >= 0, y >= 0) between two mirror symmetry planes through the
    /// axis (free-slip planes of symmetry); metrics are those of the whole slump.
    pub quarter_domain: bool,
}

impl Default for Slump {
    fn default() -> Self {
        Self {
            cone_height_m: 0.3,
            cone_bottom_diameter_m: 0.2,
            cone_top_diameter_m: 0.1,
            plate_size_m: 0.9,
            lift_speed_m_s: 0.2,
            lift_start_s: 0.0,
            lift_height_m: 0.4,
            cone_slip_length_m: None,
            quarter_domain: false,
        }
    }
}

impl Experiment for Slump {
    fn flow_measures(&self) -> &'static [&'static str] {
        &["spread_radius_mean_m", "spread_radius_min_m", "spread_radius_max_m", "spread_diameter_m"]
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
        super::require_3d(m, c, "slump", "an axisymmetric cone");
        let dims = [
            ("scene.cone_height_m", self.cone_height_m),
            ("scene.cone_bottom_diameter_m", self.cone_bottom_diameter_m),
            ("scene.cone_top_diameter_m", self.cone_top_diameter_m),
            ("scene.plate_size_m", self.plate_size_m),
        ];
        let mut all_ok = true;
        for (field, x) in dims {
            all_ok &= c.real(field, x, POSITIVE);
        }
        c.real("scene.lift_speed_m_s", self.lift_speed_m_s, NON_NEGATIVE);
        if let Some(b) = self.cone_slip_length_m {
            c.real("scene.cone_slip_length_m", b, NON_NEGATIVE);
        }
        c.real("scene.lift_start_s", self.lift_start_s, NON_NEGATIVE);
        super::refuse_planes_without_images(m, c, "scene.quarter_domain", self.quarter_domain);
        c.real("scene.lift_height_m", self.lift_height_m, POSITIVE);
        if all_ok {
            let widest = self.cone_bottom_diameter_m.max(self.cone_top_diameter_m);
            if self.plate_size_m <= widest {
                c.fail(
                    "scene.plate_size_m",
                    format!(
                        "must be > the cone's widest diameter ({}), got {}",
                        fmt_num(widest),
                        fmt_num(self.plate_size_m)
                    ),
                );
            }
            if super::spacing_ok(m) {
                c.lattice_lengths(&dims, m.spacing_m);
            }
        }
    }

    fn build<const D: usize>(&self, m: &Manifest) -> Scene<D> {
        build::<D>(
            self,
            m.spacing_m,
            m.mps.wall_layers,
            m.mps.dummy_layers,
            self.lift_speed_m_s > 0.0,
        )
    }

    fn domain<const D: usize>(&self, m: &Manifest) -> (Vector<D>, Vector<D>) {
        domain::<D>(self, m.spacing_m)
    }

    /// Roussel & Coussot's radius is the mean spread radius's closed form.
    fn measured_for(&self, closed: &str) -> Option<&'static str> {
        (closed == "closed_form_radius_m").then_some("spread_radius_mean_m")
    }

    fn metric_names(&self, m: &Manifest) -> Vec<&'static str> {
        let mut names = vec![
            "spread_radius_mean_m",
            "spread_radius_min_m",
            "spread_radius_max_m",
            "spread_diameter_m",
            "centre_height_m",
        ];
        if yield_stress_pa(&m.fluid) > 0.0 {
            names.extend([
                "fluid_on_plate_count",
                "closed_form_radius_m",
                "surface_height_r25_m",
                "closed_form_height_r25_m",
                "surface_height_r50_m",
                "closed_form_height_r50_m",
                "surface_height_r75_m",
                "closed_form_height_r75_m",
            ]);
        }
        names
    }

    /// Spread radius over the octants, the height at the centre, and the Roussel & Coussot
    /// closed forms for the fluid's volume (docs/manifest.md).
    fn metrics<const D: usize>(
        &self,
        m: &Manifest,
        particles: &Particles<D>,
        _time_s: f64,
        out: &mut BTreeMap<String, f64>,
    ) {
        let l0 = m.spacing_m;
        // Fluid lifted above the cone's height (stuck to its wall) is not part of the pancake.
        let z_max = self.cone_height_m;
        let (radii, on_plate) = self.spread_and_count(particles, l0);
        let mean = radii.iter().sum::<f64>() / radii.len() as f64;
        let min = radii.iter().copied().fold(f64::INFINITY, f64::min);
        let max = radii.iter().copied().fold(0.0, f64::max);
        out.insert("spread_radius_mean_m".into(), mean);
        out.insert("spread_radius_min_m".into(), min);
        out.insert("spread_radius_max_m".into(), max);
        out.insert("spread_diameter_m".into(), 2.0 * mean);
        out.insert(
            "centre_height_m".into(),
            surface_height_m(particles, l0, 0.0, 1.5 * l0, z_max),
        );
        let tau = yield_stress_pa(&m.fluid);
        if tau > 0.0 {
            let (rho, g) = (m.fluid.density_kg_m3(), m.gravity_m_s2);
            out.insert("fluid_on_plate_count".into(), on_plate as f64);
            let volume = on_plate as f64 * cell_volume(l0, D);
            let radius = closed_form_radius_m(rho, g, volume, tau);
            out.insert("closed_form_radius_m".into(), radius);
            // The surface at rest at a quarter, half and three quarters of the measured mean
            // radius, against h(r) = sqrt(2 tau_0 (R - r)/(rho g)) with R the measured radius.
            for (name, share) in [("r25", 0.25), ("r50", 0.5), ("r75", 0.75)] {
                let r = share * mean;
                out.insert(
                    format!("surface_height_{name}_m"),
                    surface_height_m(particles, l0, r, l0, z_max),
                );
                out.insert(
                    format!("closed_form_height_{name}_m"),
                    closed_form_height_m(rho, g, tau, mean, r),
                );
            }
        }
    }

    fn trend_metric(&self) -> &'static str {
        "spread_diameter_m"
    }

    /// t500 (EN 12350-8, EFNARC): the time from the start of the lift until the spread
    /// diameter reaches 500 mm.
    fn crossings(&self, _m: &Manifest) -> Vec<super::Crossing> {
        vec![super::Crossing {
            name: "t500_s",
            metric: "spread_diameter_m",
            threshold: 0.5,
            since_s: self.lift_start_s,
        }]
    }

    /// The pancake law inverted for the cone's volume: tau_0 = 225 rho g V^2 / (128 pi^2 R^5).
    fn yield_stress_guess_pa(&self, m: &Manifest, metric: &str, value: f64) -> Option<f64> {
        let radius_m = match metric {
            "spread_diameter_m" => 0.5 * value,
            "spread_radius_mean_m" => value,
            _ => return None,
        };
        let v = self.cone_volume_m3();
        let pi2 = std::f64::consts::PI * std::f64::consts::PI;
        let r5 = libm::pow(radius_m, 5.0);
        Some(225.0 * m.fluid.density_kg_m3() * m.gravity_m_s2 * v * v / (128.0 * pi2 * r5))
    }
}

/// One radius of a slump-flow surface profile (m).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ProfilePoint {
    pub r_m: f64,
    /// Height of the highest concrete particle within l0/2 of r, plus l0/2.
    pub measured_m: f64,
    /// Roussel & Coussot h(r) with the run's measured radius.
    pub closed_form_m: f64,
}

/// The surface at rest of a slump-flow run against the closed form: measured mean spread
/// radius, closed-form radius for the concrete's volume, and h(r) every spacing from the axis
/// to the measured radius (where a particle centre lies within l0/2 of r).
#[derive(Debug, Clone, PartialEq)]
pub struct SlumpProfile {
    pub time_s: f64,
    pub spacing_m: f64,
    pub density_kg_m3: f64,
    pub gravity_m_s2: f64,
    pub yield_stress_pa: f64,
    pub radius_m: f64,
    pub closed_form_radius_m: f64,
    pub points: Vec<ProfilePoint>,
}

impl Slump {
    /// The surface profile of a state at `time_s` (the figure of `runner profile`); an error
    /// names what is missing.
    pub fn profile(
        &self,
        m: &Manifest,
        particles: &Particles<3>,
        time_s: f64,
    ) -> Result<SlumpProfile, String> {
        let tau = yield_stress_pa(&m.fluid);
        if tau <= 0.0 {
            return Err(
                "the closed form needs a yield stress (fluid.model bingham or bi_viscosity)".into(),
            );
        }
        let (l0, rho, g) = (m.spacing_m, m.fluid.density_kg_m3(), m.gravity_m_s2);
        let z_max = self.cone_height_m;
        let (radii, count) = self.spread_and_count(particles, l0);
        let radius_m = radii.iter().sum::<f64>() / radii.len() as f64;
        let volume = count as f64 * cell_volume(l0, 3);
        let closed_form_radius_m = closed_form_radius_m(rho, g, volume, tau);
        let points = (0..)
            .map(|k| k as f64 * l0)
            .take_while(|&r| r <= radius_m)
            .map(|r| ProfilePoint {
                r_m: r,
                measured_m: surface_height_m(particles, l0, r, 0.5 * l0, z_max),
                closed_form_m: closed_form_height_m(rho, g, tau, radius_m, r),
            })
            // A band that holds no particle centre has no surface to report (at r = 0 on an
            // unmoved lattice the nearest centres lie 0.71 l0 from the axis).
            .filter(|q| q.measured_m > 0.0)
            .collect();
        Ok(SlumpProfile {
            time_s,
            spacing_m: l0,
            density_kg_m3: rho,
            gravity_m_s2: g,
            yield_stress_pa: tau,
            radius_m,
            closed_form_radius_m,
            points,
        })
    }
}

impl SlumpProfile {
    /// The table and the figure's curves: the surface, and h(r) for the measured radius and
    /// for the closed-form radius.
    pub fn figure(&self, title: &str) -> SurfaceProfile {
        let (rho, g, tau) = (self.density_kg_m3, self.gravity_m_s2, self.yield_stress_pa);
        let mut table = format!(
            "{title} at t = {:.3} s (spacing {} m): spread radius {:.4} m (diameter {:.1} mm), closed form {:.4} m ({:+.1} %)\n",
            self.time_s,
            self.spacing_m,
            self.radius_m,
            2000.0 * self.radius_m,
            self.closed_form_radius_m,
            100.0 * (self.radius_m / self.closed_form_radius_m - 1.0)
        );
        table += "r_m       h_measured_m  h_closed_form_m  difference_m\n";
        for q in &self.points {
            table += &format!(
                "{:<9.4} {:<13.4} {:<16.4} {:+.4}\n",
                q.r_m,
                q.measured_m,
                q.closed_form_m,
                q.measured_m - q.closed_form_m
            );
        }
        let fine = |radius: f64| -> Vec<(f64, f64)> {
            (0..=200)
                .map(|k| radius * f64::from(k) / 200.0)
                .map(|r| (r, closed_form_height_m(rho, g, tau, radius, r)))
                .collect()
        };
        SurfaceProfile {
            table,
            x_label: "r [m]",
            spacing_m: self.spacing_m,
            time_s: self.time_s,
            surface: Curve {
                label: "MPS surface (top particle + l0/2)".into(),
                points: self.points.iter().map(|q| (q.r_m, q.measured_m)).collect(),
            },
            closed_at_measured: Some(Curve {
                label: format!("h(r), measured R = {:.3} m", self.radius_m),
                points: fine(self.radius_m),
            }),
            closed_for_volume: Some(Curve {
                label: format!("h(r), closed-form R = {:.3} m", self.closed_form_radius_m),
                points: fine(self.closed_form_radius_m),
            }),
        }
    }
}

impl Slump {
    /// The spread radius of each sector the simulated part covers (see [`spread_radii_m`]:
    /// for a quarter the two octants of the first quadrant, else all eight) and the count of
    /// concrete particles on the plate of the whole slump (four times the quarter's).
    pub fn spread_and_count<const D: usize>(
        &self,
        particles: &Particles<D>,
        spacing_m: f64,
    ) -> (Vec<f64>, usize) {
        let z_max = self.cone_height_m;
        let radii = spread_radii_m(particles, spacing_m, z_max);
        let count = (0..particles.len())
            .filter(|&i| on_plate(particles, i, z_max))
            .count();
        if self.quarter_domain {
            (radii[..2].to_vec(), 4 * count)
        } else {
            (radii.to_vec(), count)
        }
    }

    /// Inner radius of the cone at height z (linear from bottom to top).
    pub fn radius_at_m(&self, z_m: f64) -> f64 {
        let (rb, rt) = (
            0.5 * self.cone_bottom_diameter_m,
            0.5 * self.cone_top_diameter_m,
        );
        rb + (rt - rb) * (z_m / self.cone_height_m)
    }
    /// Volume of the frustum: pi h (R^2 + R r + r^2) / 3.
    pub fn cone_volume_m3(&self) -> f64 {
        let (rb, rt) = (
            0.5 * self.cone_bottom_diameter_m,
            0.5 * self.cone_top_diameter_m,
        );
        std::f64::consts::PI * self.cone_height_m * (rb * rb + rb * rt + rt * rt) / 3.0
    }
}

/// Fluid beyond half a plate past the edge, or that fell well below it, is a ghost.
fn domain<const D: usize>(p: &Slump, l0: f64) -> (Vector<D>, Vector<D>) {
    let side = cells(0.5 * p.plate_size_m, l0) as f64 * l0;
    let top = 2.0 * p.cone_height_m + 1.0;
    (
        Vector::<D>::from_fn(|a, _| if a == D - 1 { -0.5 } else { -2.0 * side }),
        Vector::<D>::from_fn(|a, _| if a == D - 1 { top } else { 2.0 * side }),
    )
}

/// Builds the slump scene (3D only: the manifest rejects `dimension: 2`); the cone, if any,
/// is a rigid body lifted along z from `lift_start_s` at `lift_speed_m_s` by
/// `lift_height_m`, then held.
pub fn build<const D: usize>(
    p: &Slump,
    spacing_m: f64,
    wall_layers: u32,
    dummy_layers: u32,
    with_cone: bool,
) -> Scene<D> {
    assert!(D == 3, "the slump scene is 3D");
    let l0 = spacing_m;
    let layers = i64::from(wall_layers + dummy_layers);
    let height = cells(p.cone_height_m, l0);
    let half_plate = cells(0.5 * p.plate_size_m, l0);
    let rb = 0.5 * p.cone_bottom_diameter_m.max(p.cone_top_diameter_m);
    let reach = (rb / l0).ceil() as i64 + layers + 1;
    let horizontal_r2 = |x: &Vector<D>| x[0] * x[0] + x[1] * x[1];
    let mut particles = Particles::<D>::default();
    // A quarter: the cells with x, y > 0 (the axis is a cell corner, so the mirror images of
    // these cells across x = 0 and y = 0 are the lattice's other cells).
    let start = |reach: i64| if p.quarter_domain { 0 } else { -reach };

    // Fluid inside the frustum.
    let lo: [i64; D] = std::array::from_fn(|a| if a == D - 1 { 0 } else { start(reach) });
    let hi: [i64; D] = std::array::from_fn(|a| if a == D - 1 { height } else { reach });
    for_each_index(lo, hi, |idx| {
        let x = centre(idx, l0);
        let r = p.radius_at_m(x[D - 1]);
        if horizontal_r2(&x) < r * r {
            particles.push(x, ParticleKind::Fluid);
        }
    });

    // Plate: wall layers right under z = 0, then dummies.
    let plate_lo: [i64; D] =
        std::array::from_fn(|a| if a == D - 1 { -layers } else { start(half_plate) });
    let plate_hi: [i64; D] = std::array::from_fn(|a| if a == D - 1 { 0 } else { half_plate });
    for_each_index(plate_lo, plate_hi, |idx| {
        let kind = if idx[D - 1] >= -i64::from(wall_layers) {
            ParticleKind::Wall
        } else {
            ParticleKind::Dummy
        };
        particles.push(centre(idx, l0), kind);
    });

    // Cone shell, last: the solver moves this index range.
    let first = particles.len();
    if with_cone {
        for_each_index(lo, hi, |idx| {
            let x = centre(idx, l0);
            let r = p.radius_at_m(x[D - 1]);
            let r2 = horizontal_r2(&x);
            let wall_r = r + f64::from(wall_layers) * l0;
            let outer_r = r + layers as f64 * l0;
            if r2 < r * r || r2 >= outer_r * outer_r {
                return;
            }
            let kind = if r2 < wall_r * wall_r {
                ParticleKind::Wall
            } else {
                ParticleKind::Dummy
            };
            particles.push(x, kind);
        });
    }
    let end = particles.len();

    let (domain_min_m, domain_max_m) = domain::<D>(p, l0);
    Scene {
        particles,
        domain_min_m,
        domain_max_m,
        bodies: (end > first)
            .then(|| {
                let along_z =
                    |x: f64| Vector::<D>::from_fn(|a, _| if a == D - 1 { x } else { 0.0 });
                RigidBody {
                    first,
                    end,
                    path: Path::lift(
                        p.lift_start_s,
                        along_z(p.lift_speed_m_s),
                        along_z(p.lift_height_m),
                    ),
                    slip_length_m: p.cone_slip_length_m,
                }
            })
            .into_iter()
            .collect(),
        inlets: Vec::new(),
        gravity_tilt_rad: 0.0,
        periodic_x: None,
        symmetry: if p.quarter_domain {
            MirrorPlanes {
                axes: 0b011,
                position_m: [0.0; 3],
            }
        } else {
            MirrorPlanes::default()
        },
    }
}

/// Number of angular sectors of the spread radius (octants: decided by signs and |x| vs |y|,
/// exact, no trigonometry).
pub const SECTORS: usize = 8;

/// Octant of a horizontal direction (x, y), 0..8.
fn sector(x: f64, y: f64) -> usize {
    usize::from(x < 0.0) * 4 + usize::from(y < 0.0) * 2 + usize::from(x.abs() < y.abs())
}

/// Whether fluid particle i counts as the concrete on the plate: at most `z_max_m` high
/// (the cone height: a few particles stick to the cone's wall and are lifted with it).
pub fn on_plate<const D: usize>(particles: &Particles<D>, i: usize, z_max_m: f64) -> bool {
    particles.kind[i] == ParticleKind::Fluid && particles.position_m[i][D - 1] <= z_max_m
}

/// Spread radius per sector: the horizontal distance from the axis of the furthest fluid
/// particle on the plate in that sector plus l0/2 (its far edge), 0 for an empty sector.
pub fn spread_radii_m<const D: usize>(
    particles: &Particles<D>,
    spacing_m: f64,
    z_max_m: f64,
) -> [f64; SECTORS] {
    let mut r2_max = [f64::NEG_INFINITY; SECTORS];
    for i in 0..particles.len() {
        if !on_plate(particles, i, z_max_m) {
            continue;
        }
        let x = particles.position_m[i];
        let s = sector(x[0], x[1]);
        r2_max[s] = r2_max[s].max(x[0] * x[0] + x[1] * x[1]);
    }
    r2_max.map(|r2| {
        if r2.is_finite() {
            r2.sqrt() + 0.5 * spacing_m
        } else {
            0.0
        }
    })
}

/// Height of the fluid surface at horizontal distance `r_m` from the axis: the highest fluid
/// particle on the plate whose distance lies within `band_m` of `r_m`, plus l0/2 (0 when there
/// is none).
pub fn surface_height_m<const D: usize>(
    particles: &Particles<D>,
    spacing_m: f64,
    r_m: f64,
    band_m: f64,
    z_max_m: f64,
) -> f64 {
    let mut top = f64::NEG_INFINITY;
    for i in 0..particles.len() {
        if !on_plate(particles, i, z_max_m) {
            continue;
        }
        let x = particles.position_m[i];
        let r = (x[0] * x[0] + x[1] * x[1]).sqrt();
        if (r - r_m).abs() < band_m {
            top = top.max(x[D - 1]);
        }
    }
    if top.is_finite() {
        top + 0.5 * spacing_m
    } else {
        0.0
    }
}

/// Roussel & Coussot (2005), thin "pancake" regime: final radius of a yield-stress fluid of
/// volume V spread on a plane, R = (225 rho g V^2 / (128 pi^2 tau_0))^(1/5).
/// libm's `pow`, not std's (which calls the platform's): the summary records this value and
/// `runner verify` compares it bit for bit. Files written before `run.math` was recorded
/// used std `powf`; see [`crate::experiment::PLATFORM_POW_METRICS`].
pub fn closed_form_radius_m(
    density_kg_m3: f64,
    gravity_m_s2: f64,
    volume_m3: f64,
    yield_stress_pa: f64,
) -> f64 {
    let pi2 = std::f64::consts::PI * std::f64::consts::PI;
    libm::pow(
        225.0 * density_kg_m3 * gravity_m_s2 * volume_m3 * volume_m3
            / (128.0 * pi2 * yield_stress_pa),
        0.2,
    )
}

/// The surface at rest of that pancake, h(r) = sqrt(2 tau_0 (R - r) / (rho g)) (0 beyond R).
pub fn closed_form_height_m(
    density_kg_m3: f64,
    gravity_m_s2: f64,
    yield_stress_pa: f64,
    radius_m: f64,
    r_m: f64,
) -> f64 {
    (2.0 * yield_stress_pa * (radius_m - r_m).max(0.0) / (density_kg_m3 * gravity_m_s2)).sqrt()
}

//! The free surface of an L-B box state along the box against the L-box closed form: the
//! table and figure of `runner profile`.

use super::{LbBox, closed_form_height_m, heap_length_m, surface_height_m};
use crate::experiment::{Curve, Manifest, SurfaceProfile, front_position_m, yield_stress_pa};
use crate::mps::Particles;
use crate::mps::particles::cell_volume;

/// One station of an L-box surface profile.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ProfilePoint {
    /// Distance back from the front, metres.
    pub d_m: f64,
    /// x of the station, metres.
    pub x_m: f64,
    /// Top particle within l0/2 of x, plus l0/2.
    pub measured_m: f64,
    /// h(d) of the closed form (no spheres and a yield stress; else NaN).
    pub closed_form_m: f64,
}

/// The free surface of an L-B box state along the box: every spacing from the front back to
/// the back wall.
#[derive(Debug, Clone, PartialEq)]
pub struct LbProfile {
    pub time_s: f64,
    pub spacing_m: f64,
    pub width_m: f64,
    /// tau_0/(rho g), metres.
    pub k_m: f64,
    pub front_m: f64,
    pub gate_x_m: f64,
    /// Closed-form heap length from the back wall for the fluid's volume (NaN with spheres).
    pub closed_form_front_m: f64,
    pub points: Vec<ProfilePoint>,
}

impl LbBox {
    /// The surface profile of a state (the figure and table of `runner profile`).
    pub fn profile(
        &self,
        m: &Manifest,
        particles: &Particles<3>,
        time_s: f64,
    ) -> Result<LbProfile, String> {
        let tau = yield_stress_pa(&m.fluid);
        let l0 = m.spacing_m;
        if particles.fluid_count() == 0 {
            return Err("the state holds no concrete yet".into());
        }
        let g = self.lattice(l0);
        let k_m = tau / (m.fluid.density_kg_m3() * m.gravity_m_s2);
        let closed = tau > 0.0 && self.sphere_centres_m.is_empty();
        let front_m = front_position_m(particles, l0);
        let volume = self.copies() * particles.fluid_count() as f64 * cell_volume(l0, 3);
        let closed_form_front_m = if closed {
            heap_length_m(k_m, g.width_m, volume)
        } else {
            f64::NAN
        };
        // Stations at the lattice's cell centres (l0/2, 3 l0/2, ...) up to the front.
        let points = (0..)
            .map(|k| (k as f64 + 0.5) * l0)
            .take_while(|&x| x < front_m)
            .map(|x| ProfilePoint {
                d_m: front_m - x,
                x_m: x,
                measured_m: surface_height_m(particles, l0, x),
                closed_form_m: if closed {
                    closed_form_height_m(k_m, g.width_m, front_m - x)
                } else {
                    f64::NAN
                },
            })
            .filter(|q| q.measured_m > 0.0)
            .collect();
        Ok(LbProfile {
            time_s,
            spacing_m: l0,
            width_m: g.width_m,
            k_m,
            front_m,
            gate_x_m: g.gate_x_m,
            closed_form_front_m,
            points,
        })
    }
}

impl LbProfile {
    /// The table and the figure's curves: the surface h(x) along the box, and the L-box
    /// closed form (no spheres) for the measured front and for the fluid's volume.
    pub fn figure(&self, title: &str) -> SurfaceProfile {
        let closed = self.closed_form_front_m.is_finite();
        let mut table = format!(
            "{title} at t = {:.3} s (spacing {} m, W = {} m, k = tau_0/(rho g) = {:.3} mm): front at x = {:.4} m, filling distance {:.4} m",
            self.time_s,
            self.spacing_m,
            self.width_m,
            1000.0 * self.k_m,
            self.front_m,
            self.front_m - self.gate_x_m
        );
        if closed {
            table += &format!(
                "; closed form for this volume {:.4} m ({:+.1} %)",
                self.closed_form_front_m - self.gate_x_m,
                100.0
                    * ((self.front_m - self.gate_x_m) / (self.closed_form_front_m - self.gate_x_m)
                        - 1.0)
            );
        }
        table += "\nx_m       d_m       h_measured_m  h_closed_form_m  difference_m\n";
        for q in &self.points {
            table += &format!(
                "{:<9.4} {:<9.4} {:<13.4} {:<16.4} {:+.4}\n",
                q.x_m,
                q.d_m,
                q.measured_m,
                q.closed_form_m,
                q.measured_m - q.closed_form_m
            );
        }
        let fine = |front: f64| -> Vec<(f64, f64)> {
            (0..=400)
                .map(|k| front * f64::from(k) / 400.0)
                .map(|x| (x, closed_form_height_m(self.k_m, self.width_m, front - x)))
                .collect()
        };
        SurfaceProfile {
            table,
            x_label: "x from the back wall [m]",
            spacing_m: self.spacing_m,
            time_s: self.time_s,
            surface: Curve {
                label: "MPS surface (top particle + l0/2)".into(),
                points: self.points.iter().map(|q| (q.x_m, q.measured_m)).collect(),
            },
            closed_at_measured: closed.then(|| Curve {
                label: format!("L-box closed form, measured front x = {:.3} m", self.front_m),
                points: fine(self.front_m),
            }),
            closed_for_volume: closed.then(|| Curve {
                label: format!(
                    "L-box closed form for the volume, front x = {:.3} m",
                    self.closed_form_front_m
                ),
                points: fine(self.closed_form_front_m),
            }),
        }
    }
}


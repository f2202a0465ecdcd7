//! Inlets: fluid particles that enter through a disc (3D) or a segment (2D).
//!
//! An inlet pours a fixed number of particles, layer by layer, onto a fixed lattice of the
//! cross-section. Its only state is how many particles it has poured so far (kept by the
//! solver and recorded in the checkpoint); everything else follows from the configuration.
//! Only `+ - * /`, `sqrt` and comparisons are used (docs/design.md section 6).
use super::grid::MirrorPlanes;
use super::particles::{Vector, cell_volume};

/// An opening through which fluid enters at a constant speed.
///
/// The cross-section is the plane through `centre_m` normal to `direction`; its particle
/// positions are the lattice points of spacing l0 in that plane within `radius_m` of the
/// centre (see [`Inlet::cross_section_m`]). Layer k is due at `start_s + k l0 / speed_m_s`:
/// at the start of the first step at or after that time the solver appends the layer's
/// particles (fluid, velocity `speed_m_s * direction`, pressure 0, tag `tag`) at the end of
/// the particle arrays, unless a fluid particle lies within 0.5 l0 of one of its positions
/// (a blocked inlet waits, then catches up one layer per step). Emitted particles start on the
/// plane itself. It pours `round(volume_m3 / l0^D)` particles in all (the last layer holds
/// the first points of the lattice order, the rest of a full layer), then stops. Beside
/// mirror symmetry planes the solver keeps only the section's points on the domain's side,
/// and fluid's mirror images block the opening as the fluid does.
#[derive(Debug, Clone, PartialEq)]
pub struct Inlet<const D: usize> {
    pub centre_m: Vector<D>,
    /// Direction of the inflow (normalised by the solver; axis-aligned directions give an
    /// exactly axis-aligned lattice).
    pub direction: Vector<D>,
    /// Radius of the disc in 3D, half-width of the segment in 2D.
    pub radius_m: f64,
    /// Speed of the entering fluid (> 0).
    pub speed_m_s: f64,
    /// Volume to pour: round(volume_m3 / l0^D) particles (m^3; m^2 per metre of depth in 2D).
    pub volume_m3: f64,
    /// When the first layer is due.
    pub start_s: f64,
    /// Tag of the poured particles (layer, material, origin).
    pub tag: u16,
    /// A due layer enters only when no fluid particle is closer than this to any of its
    /// points (the layer before it has moved on, the opening is not blocked).
    pub clearance_m: f64,
}

impl<const D: usize> Inlet<D> {
    /// Checks that the inlet can pour: finite values, a non-zero direction, a positive speed,
    /// a non-negative volume and a cross-section that holds at least one lattice point.
    pub fn validate(&self, spacing_m: f64) -> Result<(), String> {
        let finite = self
            .centre_m
            .iter()
            .chain(self.direction.iter())
            .all(|x| x.is_finite())
            && [self.radius_m, self.speed_m_s, self.volume_m3, self.start_s]
                .iter()
                .all(|x| x.is_finite());
        if !finite {
            return Err("inlet values must be finite".into());
        }
        if self.direction.norm() == 0.0 {
            return Err("inlet direction must not be zero".into());
        }
        if self.speed_m_s <= 0.0 {
            return Err(format!(
                "inlet speed {} m/s must be positive",
                self.speed_m_s
            ));
        }
        if self.volume_m3 < 0.0 {
            return Err(format!(
                "inlet volume {} must not be negative",
                self.volume_m3
            ));
        }
        if self.total_count(spacing_m) > 0 && self.cross_section_m(spacing_m).is_empty() {
            return Err(format!(
                "inlet radius {} m holds no lattice point at spacing {spacing_m} m (it needs at least half a spacing{})",
                self.radius_m,
                if D == 3 { " times sqrt 2" } else { "" }
            ));
        }
        Ok(())
    }

    /// Number of particles the inlet pours in all: round(volume / l0^D).
    pub fn total_count(&self, spacing_m: f64) -> u64 {
        let n = (self.volume_m3 / cell_volume(spacing_m, D)).round();
        if n > 0.0 { n as u64 } else { 0 }
    }

    /// Time at which layer `layer` (0-based) is due: start + k l0 / speed.
    pub fn layer_due_s(&self, layer: u64, spacing_m: f64) -> f64 {
        self.start_s + layer as f64 * spacing_m / self.speed_m_s
    }

    /// Unit inflow direction.
    pub fn unit_direction(&self) -> Vector<D> {
        self.direction / self.direction.norm()
    }

    /// The in-plane axes e_1 .. e_{D-1}: let k be the axis where |direction| is largest (the
    /// first of equals); the other coordinate axes, in increasing order, are made orthogonal
    /// to the direction and to each other (Gram-Schmidt) and normalised. For an axis-aligned
    /// direction they are exactly the other coordinate axes.
    pub fn plane_axes(&self) -> Vec<Vector<D>> {
        let n = self.unit_direction();
        let mut k = 0;
        for a in 1..D {
            if n[a].abs() > n[k].abs() {
                k = a;
            }
        }
        let mut axes: Vec<Vector<D>> = Vec::with_capacity(D - 1);
        for a in (0..D).filter(|&a| a != k) {
            let mut e = Vector::<D>::zeros();
            e[a] = 1.0;
            let mut v = e - n * n.dot(&e);
            for b in &axes {
                v -= *b * b.dot(&e);
            }
            axes.push(v / v.norm());
        }
        axes
    }

    /// The cross-section's points that the inlet pours beside mirror symmetry planes: those
    /// on the domain's side of every plane (all of them without planes), in their order. An
    /// opening that straddles a plane pours its part; the images stand for the rest.
    pub fn cross_section_beside_m(&self, spacing_m: f64, planes: &MirrorPlanes) -> Vec<Vector<D>> {
        let mut section = self.cross_section_m(spacing_m);
        section.retain(|x| planes.beside(x));
        section
    }

    /// Positions of the cross-section's lattice points, in their fixed order. In-plane
    /// coordinates (u_1, .., u_{D-1}) = ((i_1 + 1/2) l0, ..): the points sit like cell centres
    /// around `centre_m` (which lies on a cell corner). Kept: sum u^2 <= radius^2. Ordered by
    /// distance from the centre (exactly, on the integers sum (2 i + 1)^2), then by i_{D-1},
    /// .., i_1, so that a partial last layer fills the middle of the opening first.
    /// Position = centre + sum u_a e_a with the axes of [`Inlet::plane_axes`].
    pub fn cross_section_m(&self, spacing_m: f64) -> Vec<Vector<D>> {
        let axes = self.plane_axes();
        let m = (self.radius_m / spacing_m).ceil().max(0.0) as i64 + 1;
        let r2 = self.radius_m * self.radius_m;
        // (distance key, indices last-axis first, position)
        let mut points: Vec<(i64, Vec<i64>, Vector<D>)> = Vec::new();
        let dims = D - 1;
        let mut idx = vec![-m; dims];
        loop {
            let u: Vec<f64> = idx.iter().map(|&i| (i as f64 + 0.5) * spacing_m).collect();
            let u2 = u.iter().fold(0.0, |s, x| s + x * x);
            if u2 <= r2 {
                let key = idx.iter().map(|&i| (2 * i + 1) * (2 * i + 1)).sum::<i64>();
                let mut x = self.centre_m;
                for (e, ua) in axes.iter().zip(&u) {
                    x += *e * *ua;
                }
                points.push((key, idx.iter().rev().copied().collect(), x));
            }
            // Next index tuple (first index fastest).
            let mut a = 0;
            loop {
                if a == dims {
                    points.sort_by(|p, q| (p.0, &p.1).cmp(&(q.0, &q.1)));
                    return points.into_iter().map(|p| p.2).collect();
                }
                idx[a] += 1;
                if idx[a] < m {
                    break;
                }
                idx[a] = -m;
                a += 1;
            }
        }
    }
}

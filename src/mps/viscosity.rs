//! Viscous stage of the step: strain rate, effective viscosity, the optional stress-gradient
//! term of seed 000 eq. 8, and the implicit viscous predictor solved by CG.
use super::grid::{KernelPairs, Neighbours, entry_index};
use super::kernel::{RefValues, weight};
use super::operators::{MIN_DET_RATIO, gradient_correction, weighted_neighbours};
use super::particles::{ParticleKind, Particles, Vector};
use super::pressure::{Preconditioner, SolveReport, solve_pcg_many};
use super::reduce::PARTICLES_PER_TASK;
use super::rheology::Rheology;
use super::sparse::CsrMatrix;
use super::yield_solve::{StrainOperator, Tensor, YieldSolve};
use nalgebra::SMatrix;
use rayon::prelude::*;

/// Settings of the viscous stage.
#[derive(Debug, Clone, PartialEq)]
pub struct ViscousSettings {
    pub rheology: Rheology,
    pub density_kg_m3: f64,
    /// Seed 000 eq. 8 stress-gradient term (as the divergence form, see [`predict_velocity`]).
    pub stress_gradient_term: bool,
    pub tolerance: f64,
    pub max_iterations: u32,
    /// How the strain rate's velocity gradient is estimated (see [`velocity_gradient`]).
    pub gradient: StrainRateGradient,
    /// Where the no-slip condition holds: `None` at the wall and dummy particles (they carry
    /// their own velocity); `Some(s)` at the walls' surface, s in front of the nearest wall
    /// particle (half a spacing on a lattice), see [`WallFrame`].
    pub wall_surface_m: Option<f64>,
    /// Rigid bodies whose walls have Navier slip (empty: every wall as above).
    pub slip_walls: Vec<SlipWall>,
    /// Bingham's law with a rigid state, by the augmented Lagrangian of
    /// [`super::yield_solve`], instead of the regularised viscosity (`None`). Read for a
    /// Bingham fluid without the divergence form only.
    pub yield_solve: Option<YieldSolve>,
    /// `Some(l0)`, the lattice spacing: the no-slip walls' ghost velocities continue the
    /// fluid's parabola instead of the line through the wall and i (see
    /// [`wall_half_curvature`]); with `wall_surface_m` and the walls' faces only, lagged a
    /// step. l0 sets the least span of neighbours the fit trusts.
    pub wall_curvature: Option<f64>,
}

/// A rigid body's walls with Navier slip, u_s = b du_t/dn at the body's surface (steel in fresh
/// concrete slips; a no-slip rod drags a column of concrete out of the form, issue "Rodding").
/// The surface lies `surface_m` in front of the body's outer particles (half a spacing on its
/// lattice). A wall or dummy neighbour j of fluid particle i, d_j behind that surface with i
/// d_i in front of it, carries u_w + (u_i - u_w)(b - d_j)/(b + d_i): the linear profile
/// through i with that slip. Its pair term (u_j - u_i) becomes (1 + d_j/d_i) d_i/(d_i + b)
/// (u_w - u_i): b = 0 is no slip at the surface ([`WallFrame::factor`]), a large b free slip.
/// The factor acts on the whole relative velocity: the normal part is the pressure's to stop.
#[derive(Debug, Clone, PartialEq)]
pub struct SlipWall {
    /// The body's particles.
    pub particles: std::ops::Range<usize>,
    /// Slip length b >= 0, in metres.
    pub slip_length_m: f64,
    /// Distance of the body's surface in front of its outer particles, in metres.
    pub surface_m: f64,
}

/// The slip wall that particle j belongs to, if any.
#[inline]
fn slip_wall_of(slip_walls: &[SlipWall], j: usize) -> Option<&SlipWall> {
    slip_walls.iter().find(|w| w.particles.contains(&j))
}

/// How the walls meet the fluid in the velocity gradient and the viscous term: where the
/// no-slip condition holds, which bodies slip, and each wall particle's own face.
#[derive(Debug, Clone, Copy)]
pub struct Walls<'a, const D: usize> {
    /// [`ViscousSettings::wall_surface_m`].
    pub surface_m: Option<f64>,
    /// [`ViscousSettings::slip_walls`].
    pub slip: &'a [SlipWall],
    /// Each wall particle's own face for the no-slip walls (`mps.wall_face_normals`; `None`:
    /// one frame fitted per fluid particle, [`WallFrame`]).
    pub faces: Option<&'a WallFaces<D>>,
}

impl<'a, const D: usize> Walls<'a, D> {
    /// The settings' walls, with `faces` if built.
    pub fn of(settings: &'a ViscousSettings, faces: Option<&'a WallFaces<D>>) -> Self {
        Self {
            surface_m: settings.wall_surface_m,
            slip: &settings.slip_walls,
            faces,
        }
    }

    /// Walls that carry their own velocity (no frame, no slip, no faces).
    pub fn own_velocity() -> Self {
        Self {
            surface_m: None,
            slip: &[],
            faces: None,
        }
    }
}

/// The walls a fluid particle's pair terms see: the no-slip frame (`Walls::surface_m`) of the
/// walls that do not slip, and the frame of the slip walls.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Frames<'a, const D: usize> {
    no_slip: Option<WallFrame<D>>,
    slip: Option<WallFrame<D>>,
    slip_walls: &'a [SlipWall],
    // Each wall particle's own face for the no-slip walls (`mps.wall_face_normals`).
    faces: Option<&'a WallFaces<D>>,
}

impl<'a, const D: usize> Frames<'a, D> {
    pub(crate) fn of(
        p: &Particles<D>,
        nb: &Neighbours,
        i: usize,
        radius_m: f64,
        walls: &Walls<'a, D>,
    ) -> Self {
        let slip_walls = walls.slip;
        let plain = |j: usize| slip_wall_of(slip_walls, j).is_none();
        let no_slip = walls
            .surface_m
            .and_then(|s| WallFrame::of(p, nb, i, radius_m, s, plain));
        let slip = slip_walls.first().and_then(|w| {
            WallFrame::of(p, nb, i, radius_m, w.surface_m, |j| {
                slip_wall_of(slip_walls, j).is_some()
            })
        });
        Self {
            no_slip,
            slip,
            slip_walls,
            faces: walls.faces.filter(|_| walls.surface_m.is_some()),
        }
    }

    /// The slip wall that particle j belongs to, if any.
    #[inline]
    fn slip_wall(&self, j: usize) -> Option<&SlipWall> {
        slip_wall_of(self.slip_walls, j)
    }

    /// The factor of wall or dummy neighbour entry `e`'s pair term (u_j - u_i) at
    /// displacement r_ij (1 for a wall that carries its own velocity).
    #[inline]
    pub(crate) fn factor(&self, e: u32, r_ij: &Vector<D>) -> f64 {
        self.factor_and_face(e, r_ij).0
    }

    /// [`Self::factor`], with the face of a wall that does not slip (depth d_j behind it,
    /// i's gap d_i in front) where the factor came from one.
    #[inline]
    pub(crate) fn factor_and_face(&self, e: u32, r_ij: &Vector<D>) -> (f64, Option<(f64, f64)>) {
        let slip_wall = self.slip_wall(entry_index(e));
        if let Some(wall) = slip_wall
            && let Some(f) = &self.slip
        {
            return (
                f.factor(r_ij) * f.gap_m / (f.gap_m + wall.slip_length_m),
                None,
            );
        }
        if let Some((_, depth_m, gap_m)) = self.faces.and_then(|faces| faces.face_of(e, r_ij)) {
            let face = slip_wall.is_none().then_some((depth_m, gap_m));
            return (WallFaces::<D>::factor(depth_m, gap_m), face);
        }
        (self.no_slip.as_ref().map_or(1.0, |f| f.factor(r_ij)), None)
    }
}

/// Each wall or dummy particle's own face, for the no-slip extrapolation of [`WallFrame`]
/// pair by pair: [`WallFrame`] fits one plane to all of a fluid particle's wall neighbours,
/// which near an edge (a floor under a side wall) tilts it between the two faces and puts
/// the surface a quarter spacing away, so that a pair term within two or three spacings of
/// the edge came out up to six times its value (3D, Laplacian radius 3.1). Here a wall
/// particle's outward normal is the direction away from the non-fluid particles around it
/// (a first-layer particle of a flat wall: the wall's normal; of an edge: the diagonal), its
/// face `surface_m` in front of it; a dummy, or an edge's wall particle solid on all sides,
/// takes the face of its nearest wall particle that has one.
/// Then d_i is i's own distance to the face of each wall neighbour.
#[derive(Debug, Clone, PartialEq)]
pub struct WallFaces<const D: usize> {
    // Per particle (`None`: no face, the fitted frame is used).
    face: Vec<Option<Face<D>>>,
    // d_i is kept at least this (as `WallFrame`'s gap).
    min_gap_m: f64,
}

/// A wall particle's face: its outward unit normal and its depth behind the face, in metres.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Face<const D: usize> {
    normal: Vector<D>,
    depth_m: f64,
}

impl<const D: usize> WallFaces<D> {
    /// Faces from `nb`, which must list the wall particles' neighbours (the solver's lists
    /// do), over `radius_m`; `surface_m` in front of the first layer.
    pub fn build(p: &Particles<D>, nb: &Neighbours, radius_m: f64, surface_m: f64) -> Self {
        let solid = |j: usize| matches!(p.kind[j], ParticleKind::Wall | ParticleKind::Dummy);
        // Only walls with fluid in reach are read (most of a form's walls are not).
        let wet = |i: usize| {
            p.kind[i] == ParticleKind::Wall
                && nb
                    .of(i)
                    .iter()
                    .any(|&e| p.kind[entry_index(e)] == ParticleKind::Fluid)
        };
        let mut face: Vec<Option<Face<D>>> = (0..p.len())
            .into_par_iter()
            .with_min_len(PARTICLES_PER_TASK)
            .map(|i| {
                if !wet(i) {
                    return None;
                }
                let mut away = Vector::<D>::zeros();
                let mut total = 0.0;
                for &e in nb.of(i) {
                    let j = entry_index(e);
                    if !solid(j) || Neighbours::is_own_image(e, i) {
                        continue;
                    }
                    let r = nb.displacement(&p.position_m, i, e);
                    let w = weight(r.norm(), radius_m);
                    away -= r * w;
                    total += w * r.norm();
                }
                // Solid on all sides (or a shell one particle thick): no face.
                (away.norm() >= FACE_ASYMMETRY * total).then(|| Face {
                    normal: away / away.norm(),
                    depth_m: surface_m,
                })
            })
            .collect();
        // A dummy, or a wall particle without a face (a concave edge's), takes the face of
        // its nearest wall particle that has one (ties: the lowest index).
        // (normal, displacement from that wall particle) per particle.
        let mut nearest: Vec<Option<(Vector<D>, Vector<D>)>> = vec![None; p.len()];
        for (i, own) in face.iter().enumerate() {
            let Some(own) = own else { continue };
            for &e in nb.of(i) {
                let j = entry_index(e);
                if !solid(j) || face[j].is_some() || Neighbours::plane_bits(e) != 0 {
                    continue;
                }
                // The displacement, not the positions' difference: across a periodic boundary.
                let r = nb.displacement(&p.position_m, i, e);
                if nearest[j].is_none_or(|(_, near)| r.norm() < near.norm()) {
                    nearest[j] = Some((own.normal, r));
                }
            }
        }
        for (face, nearest) in face.iter_mut().zip(nearest) {
            if let Some((normal, r)) = nearest {
                *face = Some(Face {
                    normal,
                    depth_m: surface_m - r.dot(&normal),
                });
            }
        }
        Self {
            face,
            min_gap_m: 0.5 * surface_m,
        }
    }

    /// 1 + d_j/d_i for wall or dummy entry `e` at displacement r_ij from fluid particle i, with
    /// d_i i's distance to j's face; `None` where j has no face.
    #[inline]
    pub fn factor_of(&self, e: u32, r_ij: &Vector<D>) -> Option<f64> {
        self.face_of(e, r_ij)
            .map(|(_, depth_m, gap_m)| Self::factor(depth_m, gap_m))
    }

    /// 1 + d_j/d_i.
    #[inline]
    fn factor(depth_m: f64, gap_m: f64) -> f64 {
        1.0 + depth_m / gap_m
    }

    /// Wall or dummy entry `e`'s face as seen from fluid particle i at displacement r_ij: its
    /// outward normal (reflected for a mirror image), j's depth d_j behind it and i's
    /// distance d_i in front of it; `None` where j has no face.
    #[inline]
    pub fn face_of(&self, e: u32, r_ij: &Vector<D>) -> Option<(Vector<D>, f64, f64)> {
        let face = self.face.get(entry_index(e))?.as_ref()?;
        let n = Neighbours::reflected(e, face.normal);
        let gap_m = ((-r_ij).dot(&n) - face.depth_m).max(self.min_gap_m);
        Some((n, face.depth_m, gap_m))
    }
}

/// The radius over which a wall particle's normal is taken, in spacings: its face-adjacent
/// lattice neighbours only. Walls are built on the lattice, so this is exact on a flat face
/// and on the rows next to an edge, where a wider radius (1.5, 2.1) takes in the other
/// face's particles and tilts the normal (factors off by up to 19 and 39 % there).
pub const FACE_RADIUS_SPACINGS: f64 = 1.1;

/// A wall particle has a face when the weighted pull of its solid neighbours is at least
/// this share of its largest possible value (a first-layer particle of a flat wall: one of
/// its five face-adjacent solid neighbours in 3D uncancelled, 0.2).
const FACE_ASYMMETRY: f64 = 0.1;

/// The velocity gradient model of the strain rate.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StrainRateGradient {
    /// The MPS gradient model normalised by d/n0 (seed 000 eqs. 12-13).
    Plain,
    /// Normalised by the corrective matrix: exact for a linear field on any stencil.
    Corrected,
    /// A weighted least-squares fit of a quadratic field: exact for a quadratic one, so that a
    /// sheared zone one or two spacings thick (a parabolic profile) is not read as the secant
    /// slope over the stencil.
    Quadratic,
}

/// The walls seen from fluid particle i, for a no-slip condition at the walls' surface:
/// the unit normal into the walls and i's distance to their surface. A wall or dummy
/// neighbour j at distance d_j beyond the surface then carries the linear extrapolation
/// u_w + (u_w - u_i) d_j/d_i of i's velocity through the surface (Morris, Fox & Zhu 1997,
/// with the surface found from the neighbours, so any wall shape works), i.e. its pair term
/// (u_j - u_i) becomes (1 + d_j/d_i)(u_w - u_i).
#[derive(Debug, Clone, Copy)]
pub struct WallFrame<const D: usize> {
    normal: Vector<D>,
    gap_m: f64,
}

impl<const D: usize> WallFrame<D> {
    /// The frame of fluid particle i from its non-fluid neighbours within `radius_m` that
    /// `counts` accepts (normal:
    /// their weighted mean direction; surface: `surface_m` in front of the nearest one along
    /// it). `None` without wall neighbours. The gap is at least half `surface_m`, so that a
    /// particle pushed against a wall keeps a bounded coupling.
    pub fn of(
        p: &Particles<D>,
        nb: &Neighbours,
        i: usize,
        radius_m: f64,
        surface_m: f64,
        counts: impl Fn(usize) -> bool,
    ) -> Option<Self> {
        let wall = |j: usize| p.kind[j] != ParticleKind::Fluid && counts(j);
        let mut sum = Vector::<D>::zeros();
        for &e in nb.of(i) {
            let j = entry_index(e);
            if wall(j) {
                let r = nb.displacement(&p.position_m, i, e);
                sum += r * weight(r.norm(), radius_m);
            }
        }
        let length = sum.norm();
        if length == 0.0 {
            return None;
        }
        let normal = sum / length;
        let mut nearest = f64::INFINITY;
        for &e in nb.of(i) {
            let j = entry_index(e);
            if wall(j) {
                let r = nb.displacement(&p.position_m, i, e);
                if weight(r.norm(), radius_m) > 0.0 {
                    nearest = nearest.min(r.dot(&normal));
                }
            }
        }
        Some(Self {
            normal,
            gap_m: (nearest - surface_m).max(0.5 * surface_m),
        })
    }

    /// The point of the walls' surface nearest to i, relative to i.
    pub fn surface_point(&self) -> Vector<D> {
        self.normal * self.gap_m
    }

    /// 1 + d_j/d_i for a wall or dummy neighbour at displacement r_ij (1 for one in front of
    /// the surface).
    pub fn factor(&self, r_ij: &Vector<D>) -> f64 {
        1.0 + ((r_ij.dot(&self.normal) - self.gap_m) / self.gap_m).max(0.0)
    }
}

/// Result of the viscous stage.
#[derive(Debug, Clone)]
pub struct ViscousStage<const D: usize> {
    /// Predicted velocity u* of every particle (walls keep theirs).
    pub velocity_m_s: Vec<Vector<D>>,
    /// Strain-rate invariant Pi = 2 e:e per particle (0 for non-fluid).
    pub strain_invariant: Vec<f64>,
    /// Worst CG report over the velocity components (iterations summed).
    pub solve: SolveReport,
    /// With the yield solve, the yield part of each particle's stress (its multiplier, in Pa;
    /// zero for non-fluid), carried to the next step; empty without it.
    pub yield_stress_pa: Vec<Tensor<D>>,
    /// With the yield solve's adaptive penalty, the penalty the next step starts from (Pa s);
    /// 0 otherwise.
    pub yield_penalty_pa_s: f64,
    /// The yield solve's iterations in this step; 0 without it.
    pub yield_iterations: u32,
}

/// Velocity gradient G_ab = d u_a / d x_b at fluid particle i by the gradient model (eq. 3,
/// applied to each velocity component as in seed 000 eqs. 12-13); walls and dummies carry
/// their own velocity, which makes the floor no-slip at their centres, or with
/// `walls.surface_m` i's velocity extrapolated through the walls' surface ([`WallFrame`]).
/// - `Corrected`: the sum is normalised by the corrective matrix M_i^-1 (Khayyer & Gotoh
///   2011) instead of d/n0, which makes it exact for a linear velocity field on a truncated
///   stencil (the free surface: the plain model gives a flat surface's top row half the shear
///   rate); the uncorrected d/n0 where M_i is ill-conditioned (a splash).
/// - `Quadratic`: see [`quadratic_gradient`]; the corrected model where the fit is
///   ill-conditioned.
pub fn velocity_gradient<const D: usize>(
    p: &Particles<D>,
    nb: &Neighbours,
    refs: &RefValues,
    i: usize,
    model: StrainRateGradient,
    walls: &Walls<'_, D>,
) -> SMatrix<f64, D, D> {
    let frames = Frames::of(p, nb, i, refs.radius_strain_m, walls);
    if model == StrainRateGradient::Quadratic
        && let Some(g) = quadratic_gradient(p, nb, refs, i, &frames)
    {
        return g;
    }
    let corrected = model != StrainRateGradient::Plain;
    let ui = p.velocity_m_s[i];
    let mut g = SMatrix::<f64, D, D>::zeros();
    let mut m = SMatrix::<f64, D, D>::zeros();
    for (e, r, r2, w) in weighted_neighbours(&p.position_m, nb, i, refs.radius_strain_m) {
        let j = entry_index(e);
        let du = if p.kind[j] == ParticleKind::Fluid {
            nb.reflect(e, p.velocity_m_s[j]) - ui
        } else {
            (nb.reflect(e, p.velocity_m_s[j]) - ui) * frames.factor(e, &r)
        };
        g += du * (r.transpose() * (w / r2));
        if corrected {
            m += r * r.transpose() * (w / r2);
        }
    }
    if corrected {
        g * gradient_correction(&m, refs.n0_strain, MIN_DET_RATIO)
    } else {
        g * (D as f64 / refs.n0_strain)
    }
}

/// Unknowns of the quadratic fit: D first derivatives and D (D + 1) / 2 second ones; sized
/// for 3D (a 2D fit pads the rest with identity rows).
const FIT: usize = 9;

/// The weighted least-squares fit u_j - u_i = G r_ij + (1/2) r_ij^T H r_ij over i's
/// neighbours (weights w(r_ij), lengths in units of the strain rate's radius for
/// conditioning), the gradient G of least-squares MPS to second order (Tamai & Koshizuka
/// 2014). Wall and dummy neighbours take part with their own velocity, unless `frame` is given:
/// then they are replaced by one point on the walls' surface carrying the nearest wall's
/// velocity (no slip there), weighted as the heaviest neighbour, so that a layer sheared next
/// to a wall is fitted by the parabola through the wall. `None` where the fit is
/// ill-conditioned (too few neighbours spread in too few directions).
fn quadratic_gradient<const D: usize>(
    p: &Particles<D>,
    nb: &Neighbours,
    refs: &RefValues,
    i: usize,
    frames: &Frames<'_, D>,
) -> Option<SMatrix<f64, D, D>> {
    let frame = frames.no_slip.as_ref();
    let scale = refs.radius_strain_m;
    let unknowns = D + D * (D + 1) / 2;
    let ui = p.velocity_m_s[i];
    let mut normal = SMatrix::<f64, FIT, FIT>::zeros();
    let mut rhs = SMatrix::<f64, FIT, D>::zeros();
    let mut add = |r: &Vector<D>, du: &Vector<D>, w: f64| {
        let s = r / scale;
        let mut row = [0.0; FIT];
        row[..D].copy_from_slice(s.as_slice());
        let mut k = D;
        for a in 0..D {
            for b in a..D {
                row[k] = if a == b {
                    0.5 * s[a] * s[a]
                } else {
                    s[a] * s[b]
                };
                k += 1;
            }
        }
        for x in 0..unknowns {
            for y in 0..unknowns {
                normal[(x, y)] += w * row[x] * row[y];
            }
            for c in 0..D {
                rhs[(x, c)] += w * row[x] * du[c];
            }
        }
    };
    let mut heaviest = 0.0f64;
    let mut wall_velocity = None;
    let mut nearest_wall = f64::INFINITY;
    for &e in nb.of(i) {
        let j = entry_index(e);
        let r = nb.displacement(&p.position_m, i, e);
        let d = r.norm();
        let w = weight(d, refs.radius_strain_m);
        if w == 0.0 {
            continue;
        }
        if p.kind[j] != ParticleKind::Fluid && frames.slip_wall(j).is_some() {
            // A slip wall enters with the velocity of its slip profile.
            heaviest = heaviest.max(w);
            add(
                &r,
                &((nb.reflect(e, p.velocity_m_s[j]) - ui) * frames.factor(e, &r)),
                w,
            );
            continue;
        }
        if frame.is_some() && p.kind[j] != ParticleKind::Fluid {
            if d < nearest_wall {
                nearest_wall = d;
                wall_velocity = Some(nb.reflect(e, p.velocity_m_s[j]));
            }
            continue;
        }
        heaviest = heaviest.max(w);
        add(&r, &(nb.reflect(e, p.velocity_m_s[j]) - ui), w);
    }
    if let (Some(f), Some(u_w)) = (frame, wall_velocity) {
        add(&f.surface_point(), &(u_w - ui), heaviest.max(1.0));
    }
    for k in unknowns..FIT {
        normal[(k, k)] = 1.0;
    }
    // Ill-conditioned when a pivot of the factorisation is tiny against the largest diagonal
    // entry: a fit that would guess a curvature from neighbours on one line.
    let largest = (0..unknowns).fold(0.0f64, |m, k| m.max(normal[(k, k)]));
    let cholesky = normal.cholesky()?;
    let l = cholesky.l_dirty();
    // (A NaN pivot compares as not greater: refused too.)
    let weak = |k: usize| {
        (l[(k, k)] * l[(k, k)]).partial_cmp(&(MIN_FIT_CONDITION * largest))
            != Some(std::cmp::Ordering::Greater)
    };
    if (0..unknowns).any(weak) {
        return None;
    }
    let solution = cholesky.solve(&rhs);
    let mut g = SMatrix::<f64, D, D>::zeros();
    for c in 0..D {
        for b in 0..D {
            g[(c, b)] = solution[(b, c)] / scale;
        }
    }
    Some(g)
}

/// Smallest squared pivot of the quadratic fit, relative to its largest diagonal entry,
/// accepted (see [`quadratic_gradient`]).
const MIN_FIT_CONDITION: f64 = 1e-6;

/// Pi = 2 e_ij e_ij with e = (G + G^T)/2 (seed 000 eqs. 9-11, full tensor contraction).
pub fn strain_invariant<const D: usize>(g: &SMatrix<f64, D, D>) -> f64 {
    let e = (g + g.transpose()) * 0.5;
    2.0 * e.component_mul(&e).sum()
}

/// What the viscous stage takes from outside the particles: the body force, and what the
/// step carries from the last one.
#[derive(Debug, Clone, Copy)]
pub struct Loads<'a, const D: usize> {
    pub body_force_m_s2: Vector<D>,
    /// The incremental scheme's -grad(p^n)/rho per particle (`None` under the standard one).
    pub pressure_accel_m_s2: Option<&'a [Vector<D>]>,
    /// The yield solve's multiplier per particle from the last step (empty: none yet).
    pub yield_stress_pa: &'a [Tensor<D>],
    /// The yield solve's adaptive penalty from the last step (0: none yet, start from the
    /// settings' penalty).
    pub yield_penalty_pa_s: f64,
    /// Each wall particle's own face for the no-slip extrapolation (`None`: one frame fitted
    /// per fluid particle, [`WallFrame`]).
    pub wall_faces: Option<&'a WallFaces<D>>,
}

impl<const D: usize> Loads<'_, D> {
    /// A body force alone.
    pub fn body_force(body_force_m_s2: Vector<D>) -> Self {
        Loads {
            body_force_m_s2,
            pressure_accel_m_s2: None,
            yield_stress_pa: &[],
            yield_penalty_pa_s: 0.0,
            wall_faces: None,
        }
    }
}

/// Half the curvature b of each fluid particle's velocity along the normal of its nearest
/// no-slip wall face (zero where it has none, `mps.wall_curvature`): the parabola
/// u(s) = u_w + (u_i - u_w) s / d_i + b s (s - d_i) through the no-slip surface (s = 0, the
/// wall's velocity u_w) and i (s = d_i) that best fits, weighted by the kernel, i's fluid
/// neighbours at their distances s_k = d_i + r_ik . n (one least-squares unknown per
/// component; neighbours as far from the wall as i do not enter it). The linear mirror
/// -u_i d_j / d_i is exact for a linear profile only: on a parabola (a body force, a
/// pressure gradient along the wall) the row over the wall reads the wall's shear as
/// u_i / d_i and runs fast by (u''/2) d_i^2, and every velocity above carries that
/// (docs/validation.md, "The walls' curvature"). The ghost of wall neighbour j then gains
/// b d_j (d_j + d_i), the parabola's value at -d_j less the line's. From u^n: exact in a
/// steady flow, zero at rest.
///
/// b is left 0 unless the fit's denominator sum w (s (s - d_i))^2 reaches that of one
/// neighbour a spacing l0 further out, w(l0) (l0 (d_i + l0))^2, as every particle over a
/// filled wall has: a particle whose neighbours lie about as far from the wall as itself (a
/// stray one in a lifted cone) has a denominator near 0 and an unbounded b (the 8 mm slump
/// blew up on one).
fn wall_half_curvature<const D: usize>(
    p: &Particles<D>,
    nb: &Neighbours,
    radius_m: f64,
    spacing_m: f64,
    walls: &Walls<D>,
    faces: &WallFaces<D>,
) -> Vec<Vector<D>> {
    let least_weight = weight(spacing_m, radius_m);
    (0..p.len())
        .into_par_iter()
        .with_min_len(PARTICLES_PER_TASK)
        .map(|i| {
            if p.kind[i] != ParticleKind::Fluid {
                return Vector::<D>::zeros();
            }
            // The nearest no-slip wall neighbour with a face.
            let mut nearest: Option<(f64, Vector<D>, f64, Vector<D>)> = None;
            for &e in nb.of(i) {
                let j = entry_index(e);
                if p.kind[j] == ParticleKind::Fluid || slip_wall_of(walls.slip, j).is_some() {
                    continue;
                }
                let r = nb.displacement(&p.position_m, i, e);
                let distance = r.norm();
                if distance > radius_m || nearest.is_some_and(|(d, ..)| distance >= d) {
                    continue;
                }
                if let Some((normal, _, gap_m)) = faces.face_of(e, &r) {
                    nearest = Some((distance, normal, gap_m, nb.reflect(e, p.velocity_m_s[j])));
                }
            }
            let Some((_, normal, gap_m, wall_velocity)) = nearest else {
                return Vector::<D>::zeros();
            };
            let own = p.velocity_m_s[i] - wall_velocity;
            let mut numerator = Vector::<D>::zeros();
            let mut denominator = 0.0;
            for &e in nb.of(i) {
                let k = entry_index(e);
                if p.kind[k] != ParticleKind::Fluid || Neighbours::is_own_image(e, i) || k == i {
                    continue;
                }
                let r = nb.displacement(&p.position_m, i, e);
                let w = weight(r.norm(), radius_m);
                if w == 0.0 {
                    continue;
                }
                let s = gap_m + r.dot(&normal);
                let basis = s * (s - gap_m);
                let u = nb.reflect(e, p.velocity_m_s[k]) - wall_velocity - own * (s / gap_m);
                numerator += u * (w * basis);
                denominator += w * basis * basis;
            }
            let least_span = spacing_m * (gap_m + spacing_m);
            if denominator > 0.0 && denominator >= least_weight * least_span * least_span {
                numerator / denominator
            } else {
                Vector::<D>::zeros()
            }
        })
        .collect()
}

/// Implicit viscous predictor: u* solves u* - dt V(u*) = u^n + dt f, with f the body force
/// plus, for the incremental pressure scheme, the acceleration -grad(p^n)/rho of the pressure
/// carried from the last step (`loads.pressure_accel_m_s2`, per particle). The viscosity is
/// taken from the strain rate of u^n (with the yield solve: see [`super::yield_solve`]). Two
/// forms of the viscous term V:
/// - without the eq. 8 term: nu_i <lap u>_i (seed 000 eq. 8 without its fourth term). Each
///   row is divided by dt nu_i, which makes the matrix symmetric positive definite:
///   (1/(dt nu_i) + sum_j a_ij) u_i - sum_j a_ij u_j = rhs_i / (dt nu_i);
/// - with it: the divergence form div(mu grad u)/rho = (mu lap u + grad(mu) . grad u)/rho,
///   2d/(lambda n0 rho) sum_j mu_ij (u_j - u_i) w_ij with the harmonic mean mu_ij, which is
///   symmetric as it stands. It equals eq. 8's (eta + Lambda) lap u + 2 e . grad(Lambda) in
///   unidirectional shear (the L-flow channel, Poiseuille); the part from grad(u)^T, zero
///   there, is left out. Written explicitly as in the seed, the term is unstable at viscosity
///   ratios of 1000 (its rate 2 dLambda / (rho l0^2) far exceeds 1/dt).
///
/// a_ij = 2d/(lambda n0) w_ij; wall and dummy velocities are known and go to the right side.
pub fn predict_velocity<const D: usize>(
    p: &Particles<D>,
    pairs: &KernelPairs,
    refs: &RefValues,
    settings: &ViscousSettings,
    loads: Loads<D>,
    dt_s: f64,
) -> ViscousStage<D> {
    let Loads {
        body_force_m_s2,
        pressure_accel_m_s2,
        yield_stress_pa: carried_stress_pa,
        yield_penalty_pa_s: carried_penalty_pa_s,
        wall_faces,
    } = loads;
    let walls = Walls::of(settings, wall_faces);
    let rho = settings.density_kg_m3;
    let n = p.len();
    let is_fluid = |i: usize| p.kind[i] == ParticleKind::Fluid;
    let divergence_form = settings.stress_gradient_term;
    // The yield solve: (mu_p, tau_y, settings); the plastic viscosity alone in the matrix.
    let yield_solve = match (settings.yield_solve, settings.rheology) {
        (
            Some(solve),
            Rheology::Bingham {
                plastic_viscosity_pa_s,
                yield_stress_pa,
                ..
            },
        ) if !divergence_form && plastic_viscosity_pa_s > 0.0 => {
            Some((plastic_viscosity_pa_s, yield_stress_pa, solve))
        }
        _ => None,
    };
    let strain: Vec<f64> = (0..n)
        .into_par_iter()
        .with_min_len(PARTICLES_PER_TASK)
        .with_max_len(PARTICLES_PER_TASK)
        .map(|i| {
            if is_fluid(i) && yield_solve.is_none() {
                strain_invariant(&velocity_gradient(
                    p,
                    &pairs.near,
                    refs,
                    i,
                    settings.gradient,
                    &walls,
                ))
            } else {
                0.0
            }
        })
        .collect();
    let rheology = settings.rheology;
    let mu: Vec<f64> = strain
        .par_iter()
        .with_min_len(PARTICLES_PER_TASK)
        .map(|&s| match yield_solve {
            Some((plastic, _, _)) => plastic,
            None => rheology.viscosity_pa_s(s),
        })
        .collect();
    let rhs: Vec<Vector<D>> = (0..n)
        .into_par_iter()
        .with_min_len(PARTICLES_PER_TASK)
        .map(|i| {
            if is_fluid(i) {
                let force = match pressure_accel_m_s2 {
                    Some(a) => body_force_m_s2 + a[i],
                    None => body_force_m_s2,
                };
                p.velocity_m_s[i] + force * dt_s
            } else {
                p.velocity_m_s[i]
            }
        })
        .collect();
    let rows: Vec<usize> = (0..n)
        .filter(|&i| is_fluid(i) && (divergence_form || mu[i] > 0.0))
        .collect();
    let mut velocity = rhs.clone();
    let mut solve = SolveReport {
        iterations: 0,
        relative_residual: 0.0,
        converged: true,
    };
    if rows.is_empty() || mu.iter().all(|&m| m == 0.0) {
        return ViscousStage {
            velocity_m_s: velocity,
            strain_invariant: strain,
            solve,
            yield_stress_pa: Vec::new(),
            yield_penalty_pa_s: 0.0,
            yield_iterations: 0,
        };
    }
    let mut row_of = vec![u32::MAX; n];
    for (k, &i) in rows.iter().enumerate() {
        row_of[i] = k as u32;
    }
    let coef = 2.0 * D as f64 / (refs.lambda_visc_m2 * refs.n0_visc);
    // The viscous Laplacian's radius may be shorter than the pressure's
    // (`mps.viscous_laplacian_radius`): then the near pairs hold all its neighbours.
    let radius_visc_m = refs.radius_visc_m;
    let nb = if radius_visc_m != refs.radius_lap_m && radius_visc_m <= refs.radius_n_m {
        &pairs.near
    } else {
        &pairs.lap
    };
    // The walls' curvature: only where the no-slip surface and the faces are there.
    let curvature = match (settings.wall_curvature, walls.surface_m, wall_faces) {
        (Some(spacing_m), Some(_), Some(faces)) => Some(wall_half_curvature(
            p,
            nb,
            radius_visc_m,
            spacing_m,
            &walls,
            faces,
        )),
        _ => None,
    };
    // Row i: (s_i + sum_j c_ij) u_i - sum_fluid c_ij u_j = s_i rhs_i + sum_walls c_ij u_j.
    // A mirror image carries its source's velocity with the plane's normal component
    // negated, so with symmetry planes each component has its own matrix: an image's column
    // enters with that sign (its plane bits ride in the column's top bits, see
    // `CsrMatrix::component_diagonal`), and i's own image, u_i' - u_i = (sign - 1) u_i, on
    // the diagonal only.
    let (matrix, extra) = CsrMatrix::assemble(rows.len(), |k, columns, values| {
        let i = rows[k];
        let scale = if divergence_form {
            1.0
        } else {
            rho / (dt_s * mu[i])
        };
        let mut diag = scale;
        let mut boundary = Vector::<D>::zeros();
        let mut own_image = Vector::<D>::zeros();
        let frames = Frames::of(p, nb, i, radius_visc_m, &walls);
        for &e in nb.of(i) {
            let j = entry_index(e);
            let r = nb.displacement(&p.position_m, i, e);
            let mut a = coef * weight(r.norm(), radius_visc_m);
            if a == 0.0 {
                continue;
            }
            if !is_fluid(j) {
                let (factor, face) = frames.factor_and_face(e, &r);
                // The ghost's part beyond the line: b_i d_j (d_j + d_i), a known term (u^n).
                if let (Some(b), Some((depth_m, gap_m))) = (&curvature, face) {
                    let c_line = if divergence_form {
                        a * mu[i] * dt_s / rho
                    } else {
                        a
                    };
                    boundary += b[i] * (c_line * depth_m * (depth_m + gap_m));
                }
                a *= factor;
            }
            let c = if divergence_form {
                let mu_ij = if is_fluid(j) {
                    harmonic_mean(mu[i], mu[j])
                } else {
                    mu[i]
                };
                a * mu_ij * dt_s / rho
            } else {
                a
            };
            if Neighbours::is_own_image(e, i) {
                // 2c on the diagonal of each component the image negates.
                own_image += nb.reflect(e, Vector::<D>::repeat(-c)).add_scalar(c);
                continue;
            }
            diag += c;
            if row_of[j] != u32::MAX {
                columns.push(row_of[j] | Neighbours::plane_bits(e));
                values.push(-c);
            } else {
                boundary += nb.reflect(e, p.velocity_m_s[j]) * c;
            }
        }
        (diag, (scale, boundary, own_image))
    });
    // Start from the current velocity: close to the answer, and part of the state.
    let mut x: Vec<[f64; D]> = rows
        .iter()
        .map(|&i| std::array::from_fn(|axis| p.velocity_m_s[i][axis]))
        .collect();
    let b: Vec<[f64; D]> = rows
        .iter()
        .zip(&extra)
        .map(|(&i, (scale, boundary, _))| {
            std::array::from_fn(|axis| rhs[i][axis] * scale + boundary[axis])
        })
        .collect();
    // All velocity components in one run of side-by-side solves (one matrix pass per
    // product); with symmetry planes each component has its own signs and diagonal.
    let matrix = if nb.mirror.is_empty() {
        matrix
    } else {
        matrix.with_component_diagonals(|k| {
            std::array::from_fn(|m| if m < D { extra[k].2[m] } else { 0.0 })
        })
    };
    if let Some((plastic, yield_stress_pa, yield_settings)) = yield_solve {
        let op = StrainOperator::build(
            p,
            &pairs.near,
            refs,
            &rows,
            &row_of,
            &walls,
            yield_settings.consistent_divergence,
        );
        let carried = rows
            .iter()
            .map(|&i| {
                carried_stress_pa
                    .get(i)
                    .copied()
                    .unwrap_or_else(Tensor::zeros)
            })
            .collect();
        let outcome = super::yield_solve::solve(
            &op,
            &matrix,
            &b,
            &mut x,
            carried,
            carried_penalty_pa_s,
            plastic,
            yield_stress_pa,
            &yield_settings,
            rho / dt_s,
            settings.tolerance,
            settings.max_iterations,
        );
        let mut strain = vec![0.0; n];
        let mut stress = vec![Tensor::<D>::zeros(); n];
        for (k, &i) in rows.iter().enumerate() {
            velocity[i] = Vector::<D>::from(x[k]);
            // Pi of the law's strain rate (0 where rigid).
            strain[i] = super::yield_solve::strain_invariant(
                &outcome.strain_rate[k],
                yield_settings.volumetric_limit,
            );
            stress[i] = outcome.stress_pa[k];
        }
        return ViscousStage {
            velocity_m_s: velocity,
            strain_invariant: strain,
            solve: outcome.solve,
            yield_stress_pa: stress,
            yield_penalty_pa_s: outcome.penalty_pa_s,
            yield_iterations: outcome.iterations,
        };
    }
    let reports = solve_pcg_many(
        &matrix,
        &b,
        &mut x,
        settings.tolerance,
        settings.max_iterations,
        Preconditioner::Jacobi,
    );
    for report in reports {
        solve.iterations += report.iterations;
        // As f64::max, but a NaN (a non-finite system) is kept rather than dropped.
        if report.relative_residual.is_nan() || report.relative_residual > solve.relative_residual {
            solve.relative_residual = report.relative_residual;
        }
        solve.converged &= report.converged;
    }
    for (k, &i) in rows.iter().enumerate() {
        for axis in 0..D {
            velocity[i][axis] = x[k][axis];
        }
    }
    ViscousStage {
        velocity_m_s: velocity,
        strain_invariant: strain,
        solve,
        yield_stress_pa: Vec::new(),
        yield_penalty_pa_s: 0.0,
        yield_iterations: 0,
    }
}

/// 2 a b / (a + b): the pair viscosity of the divergence form (dominated by the smaller one,
/// as for conductances in series); 0 when both are 0.
#[inline]
fn harmonic_mean(a: f64, b: f64) -> f64 {
    if a + b > 0.0 {
        2.0 * a * b / (a + b)
    } else {
        0.0
    }
}

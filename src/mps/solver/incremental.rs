//! The incremental pressure scheme ([`PressureScheme::Incremental`]): a fluid at rest under
//! hydrostatic pressure is a fixed point of the step, on any arrangement of the particles.
//!
//! The standard scheme solves for the whole pressure each step from the compression of the
//! predicted positions. Its rest state is no equilibrium: the gradient (p_j - p_min form) gives
//! a flat surface's top row half the support it needs, pressureless dummies leave a few per
//! cent of g at the walls, and the surface truncates the Laplacian's stencil, so the PPE's
//! answer is not hydrostatic near the surface (docs/validation.md, "Holding still").
//! Here instead (a pressure-correction projection, van Kan 1986, with MPS operators):
//! - the pressure p^n is carried from the last step and its force enters the prediction:
//!   u* = u^n + dt (viscous + g - grad(p^n)/rho);
//! - the PPE gives the increment: -lap(dp) = -(rho/dt) div(u*) + gamma_c rho/dt^2
//!   max(n* - n0, 0)/n0, dp = -p^n on the free surface (so that p^(n+1) = 0 there), and a
//!   zero normal derivative at walls (their velocity enters through div(u*), the
//!   uncorrected MPS divergence: only each pair's radial relative velocity counts, so shear
//!   along a no-slip wall makes no source, which the corrected one made at a dam-break toe);
//! - u^(n+1) = u* - (dt/rho) grad(dp), p^(n+1) = max(p^n + dp, 0).
//!
//! Gradients are first-order consistent (corrective matrix, difference form, Khayyer & Gotoh
//! 2011), and wall and dummy neighbours j of fluid particle i carry the pressure
//! p_i + rho g . r_ij (Neumann-consistent: hydrostatic along the wall normal; Adami et al.
//! 2012 in SPH), so a linear hydrostatic field has the exact gradient rho g at every fluid
//! particle. At rest with p^n hydrostatic, u* = 0, the source is zero, dp = 0 and nothing
//! moves, whatever the Laplacian's truncation: the Laplacian only sets how fast a
//! disturbance is projected out, not where the rest state lies.
//!
//! Two stabilisers for violent flows, both idle at rest (docs/validation.md, "Holding still"): wall
//! support (`wall_support_m`: walls that fluid comes closer to become unknowns of the
//! increment, and that fluid's carried gradient sees them no lower than itself) and pair
//! stabilisation (`pair_stabilisation_m`, in `solver.rs`).
use super::conservative::row_gradient;
use super::{PARTICLES_PER_TASK, ParticleKind, PressureScheme, SolveReport, Solver, StepError};
use crate::mps::grid::entry_index;
use crate::mps::kernel::weight;
use crate::mps::operators::{
    MIN_DET_RATIO, corrected_gradient, divergence, gradient_correction, inward_sum, moment_matrix,
    shell_repulsion, smoothing_sums,
};
use crate::mps::particles::Vector;
use crate::mps::pressure::solve_bicgstab;
use crate::mps::reduce::map_particles;
use nalgebra::SMatrix;
use rayon::prelude::*;
use std::cell::OnceCell;
use std::time::Instant;

impl<const D: usize> Solver<D> {
    /// Corrective matrix of every fluid particle at the current positions (identity-scaled
    /// fallback elsewhere; non-fluid entries are unused).
    fn gradient_corrections(&self) -> Vec<SMatrix<f64, D, D>> {
        let p = &self.particles;
        let nb = &self.pairs.near;
        let refs = self.refs;
        (0..p.len())
            .into_par_iter()
            .with_min_len(PARTICLES_PER_TASK)
            .with_max_len(PARTICLES_PER_TASK)
            .map(|i| {
                if p.kind[i] == ParticleKind::Fluid {
                    let m = moment_matrix(&p.position_m, nb, i, refs.radius_n_m);
                    gradient_correction(&m, refs.n0, MIN_DET_RATIO)
                } else {
                    SMatrix::<f64, D, D>::zeros()
                }
            })
            .collect()
    }

    /// -grad(p^n)/rho at every fluid particle (zero elsewhere), at the current positions: the
    /// carried pressure's force in the prediction. Wall and dummy neighbours carry
    /// p_i + rho g . r_ij.
    pub(super) fn carried_pressure_acceleration(&self) -> Vec<Vector<D>> {
        debug_assert_eq!(self.config.pressure_scheme, PressureScheme::Incremental);
        let corrections = self.gradient_corrections();
        let conservative = self
            .config
            .conservative_gradient
            .then(|| self.conservative_gradient_rows(&corrections, &self.number_density()));
        let p = &self.particles;
        let nb = &self.pairs.near;
        let rho = self.config.density_kg_m3;
        let rho_g = self.hydrostatic_gravity() * rho;
        map_particles(p.len(), |i| {
            if p.kind[i] != ParticleKind::Fluid {
                return Vector::<D>::zeros();
            }
            let pi = p.pressure_pa[i];
            // Only particles with a wall or dummy neighbour need the reference.
            let wall_base = OnceCell::new();
            let wall_base = || {
                *wall_base.get_or_init(|| {
                    let base =
                        wall_reference(p, nb, self.refs.radius_n_m, i, &p.pressure_pa, rho_g) - pi;
                    // Driven into a wall, i must not see it lower than itself: the mean of
                    // its neighbours would pull a particle with a pressure peak into it.
                    if self.pressed_against_wall(i) {
                        base.max(0.0)
                    } else {
                        base
                    }
                })
            };
            let g = corrected_gradient(
                &p.position_m,
                nb,
                i,
                self.refs.radius_n_m,
                &corrections[i],
                |j, r| {
                    if p.kind[j] != ParticleKind::Fluid {
                        wall_base() + rho_g.dot(r)
                    } else if conservative.is_some() {
                        0.0
                    } else {
                        p.pressure_pa[j] - pi
                    }
                },
            );
            let g = match &conservative {
                Some(rows) => g + row_gradient(&rows[i], &p.pressure_pa),
                None => g,
            };
            (g + self.regularisation(i, pi)) * (-1.0 / rho)
        })
    }

    /// Step (8) of the incremental scheme at the predicted positions: n*, free
    /// surface, the PPE for the increment dp, the correction with grad(dp) and the new
    /// carried pressure. Returns the PPE report and the count of surface particles.
    pub(super) fn incremental_projection(
        &mut self,
        dt_s: f64,
    ) -> Result<(SolveReport, usize), StepError> {
        let pressure_started = Instant::now();
        let c = &self.config;
        let refs = self.refs;
        let rho = c.density_kg_m3;
        let number_density = self.number_density();
        let corrections = self.gradient_corrections();
        let p = &self.particles;
        let is_fluid = |i: usize| p.kind[i] == ParticleKind::Fluid;
        // Fluid below the threshold is on the surface: its increment is known, p_s - p^n (so
        // that p^(n+1) = p_s, 0 unless `surface_depth_m` is on). The other fluid particles
        // are the unknowns. Walls have none: the increment's normal derivative is zero there
        // (measured: with walls as unknowns, as in the standard scheme, the tank at rest
        // diverges within 3 s at dt/2).
        let threshold = c.surface_threshold * refs.n0;
        // Deeper than `deep_surface_pressure_pa` (by the carried pressure) only a clearly
        // loose particle is on the surface: one that just dips under the threshold there
        // would flicker to the surface's pressure and back (`mps.deep_surface_threshold`).
        let deep_threshold = c.deep_surface_threshold * refs.n0;
        let surface: Vec<bool> = (0..p.len())
            .map(|i| {
                is_fluid(i)
                    && number_density[i] < threshold
                    && (deep_threshold == 0.0
                        || p.pressure_pa[i] <= c.deep_surface_pressure_pa
                        || number_density[i] < deep_threshold)
            })
            .collect();
        let surface_count = surface.iter().filter(|&&s| s).count();
        let surface_value = self.surface_pressure(&surface);
        let surface_on = c.surface_depth_m > 0.0;
        // Wall support: walls that a fluid particle has come closer to than
        // `wall_support_m` are unknowns too (their own divergence as the source), so the
        // increment can push back on fluid driven into them.
        let support = self.supporting_walls();
        let mut unknown_of = vec![u32::MAX; p.len()];
        let mut rows = Vec::new();
        for i in 0..p.len() {
            if (is_fluid(i) && !surface[i]) || support[i] {
                unknown_of[i] = rows.len() as u32;
                rows.push(i);
            }
        }
        // Exact projection: -D G with the correction's own gradient (`exact.rs`). Adjoint
        // projection: G^T G with the same rows, the carried gradient's conservative ones under
        // `conservative_gradient` (the projection then pushes as the prediction does).
        let adjoint = c.adjoint_projection;
        let gradient = (c.exact_projection || adjoint).then(|| {
            let conservative = (adjoint && c.conservative_gradient)
                .then(|| self.conservative_gradient_rows(&corrections, &number_density));
            self.gradient_rows(&corrections, &support, conservative.as_ref())
        });
        // -lap(dp) over fluid neighbours and supporting walls: any other wall's increment
        // mirrors the particle's, so its term vanishes.
        // The known increments: p_s - p^n on the surface (-p^n as it stands when the surface
        // holds 0: the same bits as before the option).
        let known: Vec<f64> = (0..p.len())
            .map(|j| {
                if surface_on {
                    surface_value[j] - p.pressure_pa[j]
                } else {
                    -p.pressure_pa[j]
                }
            })
            .collect();
        // The adjoint projection's matrix comes with its divergence, -G^T u* per row.
        let (matrix, known, adjoint_divergence) = match &gradient {
            Some(gradient) if adjoint => {
                let (matrix, known, transposed) =
                    self.adjoint_ppe(dt_s, &rows, &unknown_of, gradient, &known);
                (matrix, known, Some(transposed))
            }
            Some(gradient) => {
                let (matrix, known) = self.exact_ppe(dt_s, &rows, &unknown_of, gradient, &known);
                (matrix, known, None)
            }
            None => {
                let (matrix, known) = self.assemble_ppe(
                    dt_s,
                    &rows,
                    &unknown_of,
                    |j| is_fluid(j) || support[j],
                    |j| known[j],
                );
                (matrix, known, None)
            }
        };
        // Source: -(rho/dt) div(u*), walls at their own velocity (no penetration; only the
        // radial relative velocity of each pair counts, so shear along a no-slip wall makes
        // none), plus the relaxed compression term at fluid rows.
        let compression_scale = c.compression_relaxation * rho / (dt_s * dt_s);
        let source_of = |i: usize, div: f64| {
            let s = -rho / dt_s * div;
            if is_fluid(i) {
                s + compression_scale * ((number_density[i] - refs.n0).max(0.0) / refs.n0)
            } else {
                s
            }
        };
        let near = &self.pairs.near;
        let source: Vec<f64> = match adjoint_divergence {
            Some(transposed) => rows
                .iter()
                .zip(&transposed)
                .map(|(&i, &g_t_u)| source_of(i, -g_t_u))
                .collect(),
            None => rows
                .par_iter()
                .with_min_len(PARTICLES_PER_TASK)
                .with_max_len(PARTICLES_PER_TASK)
                .map(|&i| {
                    let ui = p.velocity_m_s[i];
                    let div = divergence(&p.position_m, near, i, refs.radius_n_m, refs.n0, |e| {
                        near.reflect(e, p.velocity_m_s[entry_index(e)]) - ui
                    });
                    source_of(i, div)
                })
                .collect(),
        };
        let rhs: Vec<f64> = source.iter().zip(&known).map(|(s, k)| s + k).collect();
        // The increment is small once the carried pressure has settled: start from zero.
        let mut solution = vec![0.0; rows.len()];
        let solve_started = Instant::now();
        let ppe = if gradient.is_some() && !adjoint {
            solve_bicgstab(
                &matrix,
                &rhs,
                &mut solution,
                c.ppe_tolerance,
                c.ppe_max_iterations,
            )
        } else {
            self.solve_ppe_system(&matrix, &rhs, &mut solution, &rows)
        };
        let solve_s = solve_started.elapsed().as_secs_f64();
        self.timing.pressure_solve_s += solve_s;
        self.timing.ppe_iterations += u64::from(ppe.iterations);
        self.check_pressure_solve(&ppe)?;

        // New carried pressure and the increment actually applied (after the clip at
        // `pressure_floor_pa`).
        let p = &self.particles;
        // Walls carry no pressure of their own (the carried gradient mirrors the fluid's); a
        // supporting wall's increment acts in this correction only.
        let new_pressure: Vec<f64> = (0..p.len())
            .map(|i| match unknown_of[i] {
                u32::MAX => surface_value[i],
                _ if !is_fluid(i) => 0.0,
                k => (p.pressure_pa[i] + solution[k as usize]).max(self.config.pressure_floor_pa),
            })
            .collect();
        let increment: Vec<f64> = (0..p.len())
            .map(|i| {
                if is_fluid(i) {
                    new_pressure[i] - p.pressure_pa[i]
                } else if support[i] {
                    solution[unknown_of[i] as usize]
                } else {
                    0.0
                }
            })
            .collect();
        // Pressure smoothing: interior fluid moves a share dt/T of the way toward the
        // kernel-weighted mean of its fluid neighbours' pressures carried back to it along
        // the local gradient G_i (p_j - G_i . r_ij, G_i the corrected gradient over the same
        // fluid neighbours; rho g where they do not span every direction): exact for any
        // linear pressure on any stencil, it removes the particle-scale noise that the
        // increment leaves where u* has no divergence. After the increment is taken, so the
        // velocity correction stays unsmoothed.
        let new_pressure = if c.pressure_smoothing_time_s > 0.0 {
            let share = (dt_s / c.pressure_smoothing_time_s).min(1.0);
            let rho_g = self.hydrostatic_gravity() * rho;
            map_particles(p.len(), |i| {
                let pi = new_pressure[i];
                if !is_fluid(i) || unknown_of[i] == u32::MAX {
                    return pi;
                }
                let (excess, weights) = smoothing_sums(
                    &p.position_m,
                    near,
                    i,
                    refs.radius_n_m,
                    refs.n0,
                    |j| is_fluid(j).then(|| new_pressure[j]),
                    rho_g,
                );
                if weights > 0.0 {
                    (pi + share * excess / weights).max(self.config.pressure_floor_pa)
                } else {
                    pi
                }
            })
        } else {
            new_pressure
        };
        let scale = -dt_s / rho;
        // The increment's regularisation at interior fluid particle i (zero when off).
        let regularised = |i: usize, g: Vector<D>| {
            if c.increment_regularisation > 0.0 && unknown_of[i] != u32::MAX {
                g + self.increment_regularisation(i, increment[i])
            } else {
                g
            }
        };
        let dv: Vec<Vector<D>> = (0..p.len())
            .into_par_iter()
            .with_min_len(PARTICLES_PER_TASK)
            .with_max_len(PARTICLES_PER_TASK)
            .map(|i| {
                if !is_fluid(i) {
                    return Vector::<D>::zeros();
                }
                if let Some(gradient) = &gradient {
                    let g = gradient[i]
                        .iter()
                        .fold(Vector::<D>::zeros(), |g, &(k, coef)| {
                            g + coef * increment[k as usize]
                        });
                    return regularised(i, g) * scale;
                }
                let di = increment[i];
                let wall_base = OnceCell::new();
                let wall_base = || {
                    *wall_base.get_or_init(|| {
                        wall_reference(
                            p,
                            near,
                            refs.radius_n_m,
                            i,
                            &increment,
                            Vector::<D>::zeros(),
                        ) - di
                    })
                };
                let g = corrected_gradient(
                    &p.position_m,
                    near,
                    i,
                    refs.radius_n_m,
                    &corrections[i],
                    |j, _| match p.kind[j] {
                        ParticleKind::Fluid => increment[j] - di,
                        _ if support[j] => increment[j] - di,
                        _ => wall_base(),
                    },
                );
                regularised(i, g) * scale
            })
            .collect();
        self.timing.pressure_assembly_s += pressure_started.elapsed().as_secs_f64() - solve_s;
        let p = &mut self.particles;
        p.pressure_pa = new_pressure;
        super::per_particle(&mut p.velocity_m_s, &mut p.position_m, |i, v, x| {
            *v += dv[i];
            *x += dv[i] * dt_s;
        });
        Ok((ppe, surface_count))
    }
}

/// The value that walls and dummies near fluid particle i mirror: the weighted mean over i's
/// fluid neighbours (i excluded) of v_f + rho_g . (r_i - r_f), their value carried
/// hydrostatically to i. Exact for a hydrostatic field; using it instead of v_i keeps the
/// walls from echoing i's own deviation (an odd-even pressure mode, which the consistent
/// gradient does not see in the interior, would otherwise push on the wall rows). Falls back to
/// v_i without fluid neighbours.
fn wall_reference<const D: usize>(
    p: &crate::mps::particles::Particles<D>,
    nb: &crate::mps::grid::Neighbours,
    radius_m: f64,
    i: usize,
    values: &[f64],
    rho_g: Vector<D>,
) -> f64 {
    let mut sum = 0.0;
    let mut weights = 0.0;
    for &e in nb.of(i) {
        let j = entry_index(e);
        if p.kind[j] != ParticleKind::Fluid {
            continue;
        }
        let r = nb.displacement(&p.position_m, i, e);
        let w = weight(r.norm(), radius_m);
        if w > 0.0 {
            sum += w * (values[j] - rho_g.dot(&r));
            weights += w;
        }
    }
    if weights > 0.0 {
        sum / weights
    } else {
        values[i]
    }
}

impl<const D: usize> Solver<D> {
    /// The pressure regularisation's pseudo-gradient at fluid particle i (zero when off or
    /// p_i <= 0): beta p_i (d/n0) sum_j r_ij w_s(r_ij)/r_ij^2 over every neighbour (fluid,
    /// wall, dummy) within the regularisation radius, w_s the MPS weight of that radius. Its
    /// force pushes i away from whichever neighbour is closer than the others, with a
    /// stiffness that grows with the pressure, as the p_j - p_min term of the standard scheme
    /// does; but it sums to zero over a complete first shell, so a lattice at rest feels
    /// nothing. The consistent gradient alone leaves modes that it does not see (a column
    /// pair moving apart in alternate rows) free, and the walls' terms of the divergence drive
    /// them: measured, a 6 x 60 column of water at 10 mm blows up within 0.6 s without it.
    fn regularisation(&self, i: usize, pi: f64) -> Vector<D> {
        let beta = self.config.pressure_regularisation;
        if beta <= 0.0 {
            return Vector::<D>::zeros();
        }
        // Measured from a flat surface's value, so that the surface row (incomplete shell)
        // feels none of it.
        let pi =
            pi - self.config.density_kg_m3 * self.gravity().norm() * self.config.surface_depth_m;
        if pi <= 0.0 {
            return Vector::<D>::zeros();
        }
        self.shell_pseudo_gradient(i, beta * pi)
    }

    /// beta x (d/n0) sum_j r_ij w_s(r_ij)/r_ij^2 over i's neighbours within the
    /// regularisation radius, for `scaled` = beta x: both regularisations' force.
    fn shell_pseudo_gradient(&self, i: usize, scaled: f64) -> Vector<D> {
        let radius = self.config.regularisation_radius_m;
        shell_repulsion(&self.particles.position_m, &self.pairs.near, i, radius)
            * (scaled * D as f64 / self.refs.n0)
    }

    /// The increment's regularisation at fluid particle i (zero for dp_i <= 0): the pressure
    /// regularisation's pseudo-gradient with the step's increment dp_i in place of p_i,
    /// beta dp_i (d/n0) sum_j r_ij w_s(r_ij)/r_ij^2 over the neighbours within the
    /// regularisation radius. A compressing rearrangement raises dp_i, and the repulsion
    /// pushes i off its closest neighbours while it lasts; at rest dp = 0 on any arrangement,
    /// so unlike the carried pressure's regularisation it holds no stiffness in proportion
    /// to the depth, which a thin layer feels as a friction (docs/validation.md, "The
    /// increment's regularisation").
    fn increment_regularisation(&self, i: usize, dp_pa: f64) -> Vector<D> {
        if dp_pa <= 0.0 {
            return Vector::<D>::zeros();
        }
        self.shell_pseudo_gradient(i, self.config.increment_regularisation * dp_pa)
    }

    /// The pressure each free-surface particle holds (0 elsewhere): rho |g| surface_depth_m
    /// max(-n . g/|g|, 0), the hydrostatic pressure of that depth of fluid beyond its centre
    /// along its outward normal n. n is minus the kernel-weighted mean direction to its
    /// neighbours (fluid, and walls and dummies except those standing above it: a tank's
    /// sides above the fill would tilt the normal of the surface particles next to them).
    /// All zeros when `surface_depth_m` is 0.
    fn surface_pressure(&self, surface: &[bool]) -> Vec<f64> {
        let p = &self.particles;
        let depth = self.config.surface_depth_m;
        let g = self.gravity();
        let g_norm = g.norm();
        if depth <= 0.0 || g_norm == 0.0 {
            return vec![0.0; p.len()];
        }
        let down = g / g_norm;
        let nb = &self.pairs.near;
        let scale = self.config.density_kg_m3 * g_norm * depth;
        // "Above": more than a quarter spacing higher than i.
        let above_m = 0.25 * self.config.spacing_m;
        map_particles(p.len(), |i| {
            if !surface[i] {
                return 0.0;
            }
            let inward = inward_sum(&p.position_m, nb, i, self.refs.radius_n_m, |j, r| {
                p.kind[j] == ParticleKind::Fluid || -r.dot(&down) <= above_m
            });
            let length = inward.norm();
            if length == 0.0 {
                return 0.0;
            }
            // -n . g/|g| with n = -inward/|inward|.
            scale * (inward / length).dot(&down).max(0.0)
        })
    }

    /// Whether particle i has a neighbour of `kind` closer than `wall_support_m` (false when
    /// wall support is off): the one test behind both parts of wall support.
    fn wall_contact(&self, i: usize, kind: ParticleKind) -> bool {
        let reach = self.config.wall_support_m;
        let p = &self.particles;
        let nb = &self.pairs.near;
        reach > 0.0
            && nb.of(i).iter().any(|&j| {
                p.kind[entry_index(j)] == kind
                    && nb.displacement(&p.position_m, i, j).norm() < reach
            })
    }

    /// Whether fluid particle i has a wall particle closer than `wall_support_m`.
    fn pressed_against_wall(&self, i: usize) -> bool {
        self.wall_contact(i, ParticleKind::Wall)
    }

    /// The wall particles (not dummies) with a fluid particle closer than `wall_support_m`:
    /// the supporting walls of this step's increment.
    fn supporting_walls(&self) -> Vec<bool> {
        let p = &self.particles;
        if self.config.wall_support_m <= 0.0 {
            return vec![false; p.len()];
        }
        (0..p.len())
            .into_par_iter()
            .with_min_len(PARTICLES_PER_TASK)
            .with_max_len(PARTICLES_PER_TASK)
            .map(|i| {
                p.kind[i] == ParticleKind::Wall
                    && !self.pairs.lap.of(i).is_empty()
                    && self.wall_contact(i, ParticleKind::Fluid)
            })
            .collect()
    }
}

//! MPS weight function and the reference values n0 and lambda (Koshizuka & Oka 1996).

/// Weight w(r) = re/r - 1 for 0 < r < re, else 0 (seed 000, used by eqs. 3 and 4).
#[inline]
pub fn weight(distance_m: f64, radius_m: f64) -> f64 {
    if distance_m > 0.0 && distance_m < radius_m {
        radius_m / distance_m - 1.0
    } else {
        0.0
    }
}

/// Reference values of an interior particle on a full, regular lattice of spacing l0.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RefValues {
    /// Effective radius for number density and gradient (m).
    pub radius_n_m: f64,
    /// Effective radius for the Laplacian (m).
    pub radius_lap_m: f64,
    /// n0: number density with `radius_n_m`.
    pub n0: f64,
    /// n0 with `radius_lap_m` (normalises the Laplacian, eq. 4).
    pub n0_lap: f64,
    /// lambda = sum w r^2 / sum w with `radius_lap_m` (m^2).
    pub lambda_m2: f64,
    /// Effective radius of the strain rate's velocity gradient (m); `radius_n_m` unless set
    /// by [`RefValues::with_strain_radius`].
    pub radius_strain_m: f64,
    /// n0 with `radius_strain_m`.
    pub n0_strain: f64,
    /// Effective radius of the viscous stage's Laplacian (m); `radius_lap_m` unless set by
    /// [`RefValues::with_viscous_radius`].
    pub radius_visc_m: f64,
    /// n0 with `radius_visc_m`.
    pub n0_visc: f64,
    /// lambda with `radius_visc_m` (m^2).
    pub lambda_visc_m2: f64,
}

impl RefValues {
    /// Sums over the lattice points j != 0 of a D-dimensional square/cubic lattice.
    pub fn on_lattice<const D: usize>(spacing_m: f64, radius_n_m: f64, radius_lap_m: f64) -> Self {
        let (n0, _) = lattice_sums::<D>(spacing_m, radius_n_m);
        let (n0_lap, wr2) = lattice_sums::<D>(spacing_m, radius_lap_m);
        RefValues {
            radius_n_m,
            radius_lap_m,
            n0,
            n0_lap,
            lambda_m2: wr2 / n0_lap,
            radius_strain_m: radius_n_m,
            n0_strain: n0,
            radius_visc_m: radius_lap_m,
            n0_visc: n0_lap,
            lambda_visc_m2: wr2 / n0_lap,
        }
    }

    /// The same values with the strain rate's gradient over `radius_strain_m` (its n0 from
    /// the same lattice sum).
    pub fn with_strain_radius<const D: usize>(self, spacing_m: f64, radius_strain_m: f64) -> Self {
        if radius_strain_m == self.radius_n_m {
            return self;
        }
        let (n0_strain, _) = lattice_sums::<D>(spacing_m, radius_strain_m);
        Self {
            radius_strain_m,
            n0_strain,
            ..self
        }
    }

    /// The same values with the viscous stage's Laplacian over `radius_visc_m` (its n0 and
    /// lambda from the same lattice sums as the pressure's).
    pub fn with_viscous_radius<const D: usize>(self, spacing_m: f64, radius_visc_m: f64) -> Self {
        if radius_visc_m == self.radius_lap_m {
            return self;
        }
        let (n0_visc, wr2) = lattice_sums::<D>(spacing_m, radius_visc_m);
        Self {
            radius_visc_m,
            n0_visc,
            lambda_visc_m2: wr2 / n0_visc,
            ..self
        }
    }
}

/// (sum w, sum w r^2) of the weight over `radius_m` at the lattice points j != 0. The points
/// are walked in lexicographic order of their coordinates, the same for any reach, and the
/// points beyond the radius add exact zeros: the sums (and their rounding) never change.
fn lattice_sums<const D: usize>(spacing_m: f64, radius_m: f64) -> (f64, f64) {
    let reach = (radius_m / spacing_m).ceil() as i64 + 1;
    let side = (2 * reach + 1) as usize;
    let mut n0 = 0.0;
    let mut wr2 = 0.0;
    for flat in 0..side.pow(D as u32) {
        let mut rest = flat;
        let mut r2 = 0.0;
        for _ in 0..D {
            let k = (rest % side) as i64 - reach;
            rest /= side;
            let x = k as f64 * spacing_m;
            r2 += x * x;
        }
        if r2 == 0.0 {
            continue;
        }
        let w = weight(r2.sqrt(), radius_m);
        n0 += w;
        wr2 += w * r2;
    }
    (n0, wr2)
}

/// Shear stiffness of the first-shell repulsion sum_j r_ij w(r_ij)/r_ij^2 (the pressure
/// regularisation's force per unit of its prefactor, positions in spacings) on a square or
/// cubic lattice whose rows slide alternately along a lattice axis: the restoring force on a
/// particle per unit of its displacement. Each neighbour's bond is a central repulsion
/// phi(r) = w(r)/r; along it the stiffness is -phi'(r), across it -phi(r)/r, negative because
/// the bond is compressed at rest. The face neighbours above and below give -2 (re - 1), the
/// four in-plane diagonals re/sqrt(2), in 3D the four out-of-plane diagonals 2 - sqrt(2) re:
/// K_2D = 2 - (2 - 1/sqrt(2)) re, K_3D = 4 - (2 + 1/sqrt(2)) re once the diagonals are inside
/// the radius (re > sqrt(2)); -2 (re - 1) for 1 < re <= sqrt(2). Negative K lets the mode
/// grow. Valid up to the next shell: re < 2 in 2D, re < sqrt(3) (the cube's corners) in 3D.
pub fn first_shell_shear_stiffness(dimension: usize, radius_spacings: f64) -> f64 {
    let re = radius_spacings;
    if re <= std::f64::consts::SQRT_2 {
        return -2.0 * (re - 1.0).max(0.0);
    }
    let in_plane = 2.0 - (2.0 - std::f64::consts::FRAC_1_SQRT_2) * re;
    if dimension == 3 {
        in_plane + 2.0 - std::f64::consts::SQRT_2 * re
    } else {
        in_plane
    }
}

/// The largest radius (spacings) at which [`first_shell_shear_stiffness`] is positive:
/// 2 / (2 - 1/sqrt(2)) = 1.547 in 2D, 4 / (2 + 1/sqrt(2)) = 1.478 in 3D. The stable radii
/// lie between sqrt(2) and this.
pub fn first_shell_radius_limit(dimension: usize) -> f64 {
    if dimension == 3 {
        4.0 / (2.0 + std::f64::consts::FRAC_1_SQRT_2)
    } else {
        2.0 / (2.0 - std::f64::consts::FRAC_1_SQRT_2)
    }
}

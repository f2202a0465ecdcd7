//! Constitutive laws: effective viscosity from the strain-rate invariant.
//!
//! Pi = 2 e_ij e_ij (seed 000 eq. 9) with e the strain-rate tensor; sqrt(Pi) is the
//! equivalent shear rate (it equals du/dy in simple shear).

/// The viscosity law of the fluid.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Rheology {
    /// mu constant.
    Newtonian { viscosity_pa_s: f64 },
    /// Regularised Bingham fluid. Seed 000 eqs. 6-7: mu = eta + tau_y / sqrt(Pi) while flowing,
    /// eta + tau_y / sqrt(Pi_c) when Pi <= Pi_c (non-flowing). Seed 004's bi-viscosity model is
    /// the same law written with the rigid viscosity mu_r = eta + tau_y / sqrt(Pi_c), i.e.
    /// gamma_c = sqrt(Pi_c) = tau_y / (mu_r - eta); the manifest accepts either form.
    Bingham {
        plastic_viscosity_pa_s: f64,
        yield_stress_pa: f64,
        /// sqrt(Pi_c): the equivalent shear rate below which the fluid is non-flowing (1/s).
        critical_shear_rate_1_s: f64,
    },
}

impl Rheology {
    /// Seed 000 parameters: Pi_c = (2 pi_c)^2, so sqrt(Pi_c) = 2 pi_c.
    pub fn seed000(
        plastic_viscosity_pa_s: f64,
        yield_stress_pa: f64,
        critical_strain_rate_1_s: f64,
    ) -> Self {
        Rheology::Bingham {
            plastic_viscosity_pa_s,
            yield_stress_pa,
            critical_shear_rate_1_s: 2.0 * critical_strain_rate_1_s,
        }
    }

    /// Seed 004 bi-viscosity parameters: gamma_c = tau_0 / (mu_r - mu_p).
    pub fn bi_viscosity(
        plastic_viscosity_pa_s: f64,
        yield_stress_pa: f64,
        rigid_viscosity_pa_s: f64,
    ) -> Self {
        Rheology::Bingham {
            plastic_viscosity_pa_s,
            yield_stress_pa,
            critical_shear_rate_1_s: yield_stress_pa
                / (rigid_viscosity_pa_s - plastic_viscosity_pa_s),
        }
    }

    /// Whether a particle with invariant `pi` flows (always true for a Newtonian fluid).
    #[inline]
    pub fn is_flowing(&self, pi: f64) -> bool {
        match *self {
            Rheology::Newtonian { .. } => true,
            Rheology::Bingham {
                critical_shear_rate_1_s: c,
                ..
            } => pi > c * c,
        }
    }

    /// Yield part of the viscosity, Lambda = tau_y / sqrt(max(Pi, Pi_c)) (seed 000 eq. 8).
    #[inline]
    pub fn yield_viscosity_pa_s(&self, pi: f64) -> f64 {
        match *self {
            Rheology::Newtonian { .. } => 0.0,
            Rheology::Bingham {
                yield_stress_pa,
                critical_shear_rate_1_s: c,
                ..
            } => {
                if pi > c * c {
                    yield_stress_pa / pi.sqrt()
                } else {
                    yield_stress_pa / c
                }
            }
        }
    }

    /// Effective viscosity eta + Lambda (Pa s).
    #[inline]
    pub fn viscosity_pa_s(&self, pi: f64) -> f64 {
        match *self {
            Rheology::Newtonian { viscosity_pa_s } => viscosity_pa_s,
            Rheology::Bingham {
                plastic_viscosity_pa_s,
                ..
            } => plastic_viscosity_pa_s + self.yield_viscosity_pa_s(pi),
        }
    }

    /// Largest viscosity the law can give (the non-flowing one for Bingham).
    pub fn max_viscosity_pa_s(&self) -> f64 {
        self.viscosity_pa_s(0.0)
    }
}

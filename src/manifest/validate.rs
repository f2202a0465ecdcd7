//! Range and consistency checks of a deserialized manifest.
//!
//! Checks run in field order; the first failure is reported. Every `f64` is checked to be
//! finite (YAML `.nan` / `.inf` reach typed `f64` fields unchanged).

pub use super::checker::{Checker, Issue, NON_NEGATIVE, POSITIVE, Range, between, fmt_num};
use super::types::{Fluid, Manifest, PressureSchemeName, SceneSection};
use crate::mps::kernel::first_shell_radius_limit;

/// Most outputs of each kind (checkpoints, clouds, diagnostics rows) a run may ask for.
pub const MAX_OUTPUTS: f64 = 1e7;
/// Most wall (and most dummy) layers.
pub const MAX_LAYERS: u32 = 10;

/// All issues of `m`, in field order.
pub fn check<S: SceneSection>(m: &Manifest<S>) -> Vec<Issue> {
    let mut c = Checker::new();

    // name
    let n = m.name.chars().count();
    if n == 0 || n > 64 {
        c.fail(
            "name",
            format!("must be 1 to 64 characters long, got {n} characters"),
        );
    } else if let Some(bad) = m
        .name
        .chars()
        .find(|ch| !(ch.is_ascii_alphanumeric() || matches!(ch, '_' | '.' | '-')))
    {
        c.fail(
            "name",
            format!(
                "may contain only letters A-Z a-z, digits, '_', '.' and '-' (it becomes a file name), found {bad:?}"
            ),
        );
    } else if m.name == "." || m.name == ".." {
        c.fail("name", format!("must not be {:?}", m.name));
    }

    if m.dimension != 2 && m.dimension != 3 {
        c.fail("dimension", format!("must be 2 or 3, got {}", m.dimension));
    }
    c.real("spacing_m", m.spacing_m, POSITIVE);
    c.real("gravity_m_s2", m.gravity_m_s2, NON_NEGATIVE);

    // time
    c.real("time.end_s", m.time.end_s, POSITIVE);
    c.real("time.dt_max_s", m.time.dt_max_s, POSITIVE);
    c.real(
        "time.courant",
        m.time.courant,
        between(0.0, false, 1.0, true),
    );
    if let Some(dt_min_s) = m.time.dt_min_s
        && c.real("time.dt_min_s", dt_min_s, POSITIVE)
        && dt_min_s > m.time.dt_max_s
    {
        c.fail(
            "time.dt_min_s",
            format!(
                "must be <= time.dt_max_s = {}, got {}",
                fmt_num(m.time.dt_max_s),
                fmt_num(dt_min_s)
            ),
        );
    }

    if let Some(a) = m.time.acoustic_courant
        && c.real("time.acoustic_courant", a, POSITIVE)
        && m.mps.compressibility_1_pa <= 0.0
    {
        c.fail(
            "time.acoustic_courant",
            "needs mps.compressibility_1_pa > 0 (the sound speed it counts in); without one, set \
             time.acoustic_courant: null"
                .to_string(),
        );
    }

    // fluid
    match &m.fluid {
        Fluid::Newtonian {
            density_kg_m3,
            viscosity_pa_s,
        } => {
            c.real("fluid.density_kg_m3", *density_kg_m3, POSITIVE);
            c.real("fluid.viscosity_pa_s", *viscosity_pa_s, NON_NEGATIVE);
        }
        Fluid::Bingham {
            density_kg_m3,
            plastic_viscosity_pa_s,
            yield_stress_pa,
            critical_strain_rate_1_s,
            ..
        } => {
            c.real("fluid.density_kg_m3", *density_kg_m3, POSITIVE);
            c.real(
                "fluid.plastic_viscosity_pa_s",
                *plastic_viscosity_pa_s,
                NON_NEGATIVE,
            );
            c.real("fluid.yield_stress_pa", *yield_stress_pa, NON_NEGATIVE);
            c.real(
                "fluid.critical_strain_rate_1_s",
                *critical_strain_rate_1_s,
                POSITIVE,
            );
            if *plastic_viscosity_pa_s == 0.0 && *yield_stress_pa == 0.0 {
                c.fail(
                    "fluid.plastic_viscosity_pa_s",
                    "must be > 0 when fluid.yield_stress_pa is 0".to_string(),
                );
            }
        }
        Fluid::BiViscosity {
            density_kg_m3,
            plastic_viscosity_pa_s,
            yield_stress_pa,
            rigid_viscosity_pa_s,
            ..
        } => {
            c.real("fluid.density_kg_m3", *density_kg_m3, POSITIVE);
            let mu_p_ok = c.real(
                "fluid.plastic_viscosity_pa_s",
                *plastic_viscosity_pa_s,
                NON_NEGATIVE,
            );
            c.real("fluid.yield_stress_pa", *yield_stress_pa, POSITIVE);
            if c.real(
                "fluid.rigid_viscosity_pa_s",
                *rigid_viscosity_pa_s,
                POSITIVE,
            ) && mu_p_ok
                && rigid_viscosity_pa_s <= plastic_viscosity_pa_s
            {
                c.fail(
                    "fluid.rigid_viscosity_pa_s",
                    format!(
                        "must be > fluid.plastic_viscosity_pa_s ({}), got {}",
                        fmt_num(*plastic_viscosity_pa_s),
                        fmt_num(*rigid_viscosity_pa_s)
                    ),
                );
            }
        }
    }

    // mps
    let p = &m.mps;
    let nd_ok = c.real(
        "mps.number_density_radius",
        p.number_density_radius,
        between(1.0, false, 5.0, true),
    );
    let lap_ok = c.real(
        "mps.laplacian_radius",
        p.laplacian_radius,
        between(1.0, false, 5.0, true),
    );
    if nd_ok && lap_ok && p.laplacian_radius < p.number_density_radius {
        c.fail(
            "mps.laplacian_radius",
            format!(
                "must be >= mps.number_density_radius ({}), got {}",
                fmt_num(p.number_density_radius),
                fmt_num(p.laplacian_radius)
            ),
        );
    }
    // The neighbour lists reach the Laplacian's radius (>= the number density's).
    for (field, radius) in [
        ("mps.strain_rate_radius", p.strain_rate_radius),
        ("mps.viscous_laplacian_radius", p.viscous_laplacian_radius),
    ] {
        if let Some(r) = radius
            && c.real(field, r, between(1.0, false, 5.0, true))
            && lap_ok
            && r > p.laplacian_radius
        {
            c.fail(
                field,
                format!(
                    "must be <= mps.laplacian_radius ({}), got {}",
                    fmt_num(p.laplacian_radius),
                    fmt_num(r)
                ),
            );
        }
    }
    c.real(
        "mps.surface_threshold",
        p.surface_threshold,
        between(0.0, false, 1.0, false),
    );
    c.real(
        "mps.relaxation_coefficient",
        p.relaxation_coefficient,
        between(0.0, false, 1.0, true),
    );
    c.real(
        "mps.compression_relaxation",
        p.compression_relaxation,
        between(0.0, true, 1.0, true),
    );
    c.real(
        "mps.compressibility_1_pa",
        p.compressibility_1_pa,
        NON_NEGATIVE,
    );
    c.real(
        "mps.pair_stabilisation",
        p.pair_stabilisation,
        between(0.0, true, 1.0, false),
    );
    c.real(
        "mps.wall_support",
        p.wall_support,
        between(0.0, true, 1.0, false),
    );
    c.real(
        "mps.pressure_regularisation",
        p.pressure_regularisation,
        between(0.0, true, 10.0, true),
    );
    c.real(
        "mps.increment_regularisation",
        p.increment_regularisation,
        between(0.0, true, 100.0, true),
    );
    if c.real(
        "mps.deep_surface_threshold",
        p.deep_surface_threshold,
        between(0.0, true, 1.0, false),
    ) && p.deep_surface_threshold >= p.surface_threshold
    {
        c.fail(
            "mps.deep_surface_threshold",
            format!(
                "must lie below mps.surface_threshold ({}), the rule it narrows at depth; got {}",
                fmt_num(p.surface_threshold),
                fmt_num(p.deep_surface_threshold)
            ),
        );
    }
    c.real(
        "mps.deep_surface_head",
        p.deep_surface_head,
        between(0.0, false, 1000.0, true),
    );
    let reg_ok = c.real(
        "mps.regularisation_radius",
        p.regularisation_radius,
        between(1.0, false, 2.0, false),
    );
    c.real(
        "mps.pressure_smoothing_time_s",
        p.pressure_smoothing_time_s,
        between(0.0, true, 1000.0, true),
    );
    c.real(
        "mps.multigrid_over_correction",
        p.multigrid_over_correction,
        between(0.0, false, 2.0, false),
    );
    c.real(
        "mps.surface_depth",
        p.surface_depth,
        between(0.0, true, 1.0, true),
    );
    c.real(
        "mps.pressure_floor_pa",
        p.pressure_floor_pa,
        between(-101_325.0, true, 0.0, true),
    );
    c.real(
        "mps.particle_shifting",
        p.particle_shifting,
        between(0.0, true, 1000.0, true),
    );
    c.real(
        "mps.particle_shifting_limit",
        p.particle_shifting_limit,
        between(0.0, false, 0.5, true),
    );
    // The regularisation's first shell resists a shear of its rows only for radii between
    // sqrt(2) and first_shell_radius_limit (docs/validation.md, "The regularisation in 3D"):
    // the 3D default 1.5 lies above 1.478, and a 3D tank at rest grows to 0.7 m/s with it.
    // 2D keeps its (1, 2) range, so that files written before still load.
    let limit = first_shell_radius_limit(3);
    if m.dimension == 3
        && (p.pressure_regularisation > 0.0 || p.increment_regularisation > 0.0)
        && reg_ok
        && (p.regularisation_radius <= std::f64::consts::SQRT_2 || p.regularisation_radius >= limit)
    {
        c.fail(
            "mps.regularisation_radius",
            format!(
                "must lie in (sqrt(2), {}) with mps.pressure_regularisation or mps.increment_regularisation in 3D, where the first shell's rows slide apart outside it (1.45 recommended); got {}",
                fmt_num((limit * 1e3).floor() / 1e3),
                fmt_num(p.regularisation_radius)
            ),
        );
    }
    if c.real(
        "mps.yield_penalty_pa_s",
        p.yield_penalty_pa_s,
        between(0.0, true, 1e12, true),
    ) && p.yield_penalty_pa_s > 0.0
    {
        c.real("mps.yield_tolerance_1_s", p.yield_tolerance_1_s, POSITIVE);
        c.real(
            "mps.yield_velocity_fraction",
            p.yield_velocity_fraction,
            between(0.0, true, 1.0, false),
        );
        if p.yield_anderson_depth > 20 {
            c.fail(
                "mps.yield_anderson_depth",
                format!("must be <= 20, got {}", p.yield_anderson_depth),
            );
        }
        if c.int_at_least("mps.yield_max_iterations", p.yield_max_iterations.into(), 1)
            && p.yield_max_iterations > 10_000
        {
            c.fail(
                "mps.yield_max_iterations",
                format!("must be <= 10000, got {}", p.yield_max_iterations),
            );
        }
        let (plastic, stress_gradient_term) = match m.fluid {
            Fluid::Newtonian { .. } => (None, false),
            Fluid::Bingham {
                plastic_viscosity_pa_s,
                stress_gradient_term,
                ..
            }
            | Fluid::BiViscosity {
                plastic_viscosity_pa_s,
                stress_gradient_term,
                ..
            } => (Some(plastic_viscosity_pa_s), stress_gradient_term),
        };
        match plastic {
            None => c.fail(
                "mps.yield_penalty_pa_s",
                "needs a yield-stress fluid (fluid.model bingham or bi_viscosity)".to_string(),
            ),
            Some(mu) if mu <= 0.0 => c.fail(
                "mps.yield_penalty_pa_s",
                "needs fluid.plastic_viscosity_pa_s > 0".to_string(),
            ),
            _ => {}
        }
        if stress_gradient_term {
            c.fail(
                "fluid.stress_gradient_term",
                "must be false with mps.yield_penalty_pa_s > 0 (the yield solve's stress is already a divergence)"
                    .to_string(),
            );
        }
        // Measured: without it the Bingham Poiseuille plug is 6 % fast, the yield term and
        // the Laplacian putting no-slip at different places (tests/integration/bingham.rs).
        if !p.wall_surface_no_slip {
            c.fail(
                "mps.wall_surface_no_slip",
                "must be true with mps.yield_penalty_pa_s > 0 (the yield term and the viscous term then hold no-slip at the same surface)"
                    .to_string(),
            );
        }
    }
    if p.wall_face_normals && !p.wall_surface_no_slip {
        c.fail(
            "mps.wall_face_normals",
            "needs mps.wall_surface_no_slip: true (it places that no-slip surface)".to_string(),
        );
    }
    if p.yield_velocity_relative && p.yield_velocity_fraction == 0.0 {
        c.fail(
            "mps.yield_velocity_relative",
            "needs mps.yield_velocity_fraction > 0 (the fraction whose floor it scales)"
                .to_string(),
        );
    }
    if p.yield_penalty_adaptive && p.yield_penalty_pa_s == 0.0 {
        c.fail(
            "mps.yield_penalty_adaptive",
            "needs mps.yield_penalty_pa_s > 0 (the penalty it starts from)".to_string(),
        );
    }
    if p.conservative_gradient && p.pressure_scheme == PressureSchemeName::Standard {
        c.fail(
            "mps.conservative_gradient",
            "needs mps.pressure_scheme: incremental (it changes the carried pressure's gradient)"
                .to_string(),
        );
    }
    if p.wall_curvature && !(p.wall_surface_no_slip && p.wall_face_normals) {
        c.fail(
            "mps.wall_curvature",
            "needs mps.wall_surface_no_slip and mps.wall_face_normals (the ghost's parabola \
             starts at the no-slip surface, along the wall's own face)"
                .to_string(),
        );
    }
    if p.periodic_hydrostatic && p.pressure_scheme == PressureSchemeName::Standard {
        c.fail(
            "mps.periodic_hydrostatic",
            "needs mps.pressure_scheme: incremental (the standard scheme's walls carry no \
             hydrostatic pressure)"
                .to_string(),
        );
    }
    if p.adjoint_projection && p.pressure_scheme == PressureSchemeName::Standard {
        c.fail(
            "mps.adjoint_projection",
            "needs mps.pressure_scheme: incremental (it changes the increment's equation)"
                .to_string(),
        );
    }
    if p.adjoint_projection && p.exact_projection {
        c.fail(
            "mps.adjoint_projection",
            "cannot be combined with mps.exact_projection (each builds the increment's equation)"
                .to_string(),
        );
    }
    let volumetric_set = p.yield_volumetric_limit.is_some_and(|limit| {
        c.real(
            "mps.yield_volumetric_limit",
            limit,
            between(0.0, true, 1e6, true),
        )
    });
    // Fields that act only inside the yield solve, and what each does there.
    for (field, set, role) in [
        (
            "mps.yield_consistent_divergence",
            p.yield_consistent_divergence,
            "it corrects the yield solve's operator",
        ),
        (
            "mps.yield_volumetric_limit",
            volumetric_set,
            "it sets the yield solve's law",
        ),
        (
            "mps.yield_velocity_fraction",
            p.yield_velocity_fraction != 0.0,
            "it sets how far the yield solve's velocity steps go",
        ),
        (
            "mps.yield_anderson_depth",
            p.yield_anderson_depth != 0,
            "it accelerates the yield solve",
        ),
        (
            "mps.yield_penalty_local",
            p.yield_penalty_local,
            "it sets the yield solve's penalty per row",
        ),
    ] {
        if set && p.yield_penalty_pa_s == 0.0 {
            c.fail(field, format!("needs mps.yield_penalty_pa_s > 0 ({role})"));
        }
    }
    if p.quadratic_strain_rate && p.corrected_strain_rate {
        c.fail(
            "mps.quadratic_strain_rate",
            "and mps.corrected_strain_rate are two estimates of the strain rate: set one of them"
                .to_string(),
        );
    }
    // The regularisation sums over the number-density neighbour lists.
    if nd_ok && reg_ok && p.regularisation_radius > p.number_density_radius {
        c.fail(
            "mps.regularisation_radius",
            format!(
                "must be <= mps.number_density_radius ({}), got {}",
                fmt_num(p.number_density_radius),
                fmt_num(p.regularisation_radius)
            ),
        );
    }
    c.real(
        "mps.collision_distance",
        p.collision_distance,
        between(0.0, true, 1.0, false),
    );
    if let Some(d) = p.wall_collision_distance {
        c.real(
            "mps.wall_collision_distance",
            d,
            between(0.0, true, 1.0, false),
        );
    }
    c.real(
        "mps.collision_restitution",
        p.collision_restitution,
        between(0.0, true, 1.0, true),
    );
    c.real(
        "mps.ppe_tolerance",
        p.ppe_tolerance,
        between(0.0, false, 1e-2, true),
    );
    c.int_at_least("mps.ppe_max_iterations", p.ppe_max_iterations.into(), 1);
    c.real(
        "mps.viscosity_tolerance",
        p.viscosity_tolerance,
        between(0.0, false, 1e-2, true),
    );
    c.int_at_least(
        "mps.viscosity_max_iterations",
        p.viscosity_max_iterations.into(),
        1,
    );
    let walls_ok = c.int_at_least("mps.wall_layers", p.wall_layers.into(), 1);
    // More layers than the Laplacian reaches (4 at most) only add particles; the bound keeps
    // every build, the size estimate's coarse ones included, to the scene's own size (1e5
    // layers aborted allocating them).
    let solid_ok = p
        .solid_wall_layers
        .is_none_or(|n| c.int_at_least("mps.solid_wall_layers", n.into(), 1));
    for (field, layers) in [
        ("mps.wall_layers", p.wall_layers),
        ("mps.dummy_layers", p.dummy_layers),
        ("mps.solid_wall_layers", p.solid_wall_layers.unwrap_or(0)),
    ] {
        if layers > MAX_LAYERS {
            c.fail(field, format!("must be <= {MAX_LAYERS}, got {layers}"));
        }
    }
    if walls_ok && lap_ok {
        // A fluid particle one spacing away from the wall must see wall or dummy particles
        // at every distance k * spacing_m < laplacian_radius * spacing_m, k = 1, 2, ...
        let needed = p.laplacian_radius.ceil() - 1.0;
        let have = u64::from(p.wall_layers) + u64::from(p.dummy_layers);
        if (have as f64) < needed {
            c.fail(
                "mps.dummy_layers",
                format!(
                    "mps.wall_layers + mps.dummy_layers must be >= ceil(mps.laplacian_radius) - 1 = {}, got {} + {} = {have}",
                    fmt_num(needed),
                    p.wall_layers,
                    p.dummy_layers
                ),
            );
        }
        // Checked only where written: null is `wall_layers`, checked above.
        if let Some(n) = p.solid_wall_layers
            && solid_ok
        {
            let solid = u64::from(n) + u64::from(p.dummy_layers);
            if (solid as f64) < needed {
                c.fail(
                    "mps.solid_wall_layers",
                    format!(
                        "mps.solid_wall_layers + mps.dummy_layers must be >= ceil(mps.laplacian_radius) - 1 = {}, got {n} + {} = {solid}",
                        fmt_num(needed),
                        p.dummy_layers
                    ),
                );
            }
        }
    }

    // scene: the test module's own checks
    m.scene.check(m, &mut c);

    // boundaries
    for (field, message) in super::boundaries::check(&m.boundaries, m.dimension as usize) {
        c.fail(&field, message);
    }

    // output
    let o = &m.output;
    // At most MAX_OUTPUTS of each stream: a smaller interval would only write the same
    // step again and again (and 1e-300 s would never end).
    for (field, interval) in [
        ("output.checkpoint_interval_s", o.checkpoint_interval_s),
        ("output.cloud_interval_s", o.cloud_interval_s),
        ("output.diagnostics_interval_s", o.diagnostics_interval_s),
    ] {
        if c.real(field, interval, POSITIVE)
            && m.time.end_s.is_finite()
            && interval * MAX_OUTPUTS < m.time.end_s
        {
            c.fail(
                field,
                format!(
                    "must be >= time.end_s / {MAX_OUTPUTS:e} = {} (at most {MAX_OUTPUTS:e} outputs of each kind), got {}",
                    fmt_num(m.time.end_s / MAX_OUTPUTS),
                    fmt_num(interval)
                ),
            );
        } else if interval < m.dt_min_s() * (1.0 - 1e-9) {
            // Only one output per step is ever written: a smaller interval is a typo. (The
            // bound is shown to 4 digits, so the slack keeps an interval equal to it allowed.)
            let bound: f64 = format!("{:.4e}", m.dt_min_s()).parse().unwrap_or(0.0);
            c.fail(
                field,
                format!(
                    "must be >= the smallest time step {} s (time.dt_min_s; when null, the CFL step at stop.max_speed_m_s, at most time.dt_max_s), got {}",
                    fmt_num(bound),
                    fmt_num(interval)
                ),
            );
        }
    }

    // stop
    c.int_at_least("stop.max_steps", m.stop.max_steps, 1);
    c.real("stop.max_speed_m_s", m.stop.max_speed_m_s, POSITIVE);
    c.real(
        "stop.non_flowing_after_s",
        m.stop.non_flowing_after_s,
        NON_NEGATIVE,
    );
    c.real("stop.rest_after_s", m.stop.rest_after_s, NON_NEGATIVE);
    c.real(
        "stop.rest_metric_change",
        m.stop.rest_metric_change,
        POSITIVE,
    );
    if let Some(name) = &m.stop.rest_metric {
        let names = m.scene.metric_names(m);
        if !names.contains(name) {
            c.fail(
                "stop.rest_metric",
                format!(
                    "`{name}` is not a metric of this experiment (it has: {})",
                    names.join(", ")
                ),
            );
        }
    }
    if let Some(share) = m.stop.non_flowing_fraction
        && c.real(
            "stop.non_flowing_fraction",
            share,
            between(0.0, false, 1.0, true),
        )
        && matches!(m.fluid, Fluid::Newtonian { .. })
    {
        c.fail(
                "stop.non_flowing_fraction",
                "needs a yield-stress fluid (fluid.model bingham or bi_viscosity); a Newtonian fluid always flows".to_string(),
            );
    }

    c.into_issues()
}

//! The workability tests, one module each. A test owns its manifest `scene:` section (the
//! struct), its validation, its particle set, its declared metrics and closed forms, its
//! default trend axis and its report figures; the [`Experiment`] trait names these hooks and
//! the compiler checks that every test has them.
//!
//! Data flows one way: manifest (parse, check, hash) -> test module (scene, metrics) -> MPS
//! core -> recorder. The only place that lists the tests is the `experiments!` invocation
//! below, which also declares their modules: adding a test is one module plus one line there
//! (docs/tests.md, "How to add a test").
pub mod boundaries;
pub mod geometry;
pub mod profile;
pub mod staged;

pub use profile::{CellMap, Curve, Fill, SurfaceProfile};
pub use staged::{StagedFigure, StagedFigures};

/// Summary metrics that builds before `run.math` (see [`crate::record::MATH`]) computed with
/// the platform's `pow` (std `powf`): in files without that entry they may differ from this
/// build's libm value in the last bit, which `runner verify` reports as a note.
pub const PLATFORM_POW_METRICS: &[&str] = &["closed_form_radius_m"];

use crate::manifest::validate::Checker;
use crate::manifest::{self, Fluid, SceneSection};
use crate::mps::{self, Inlet, ParticleKind, Particles, RigidBody, Vector};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::Path;

/// A manifest whose `scene:` is one of our tests.
pub type Manifest = manifest::Manifest<SceneSpec>;
/// A loaded, checked and hashed manifest of one of our tests.
pub type Resolved = manifest::Resolved<SceneSpec>;
/// A manifest file: one run or a sweep.
pub type Plan = manifest::sweep::Plan<SceneSpec>;
/// An expanded sweep of runs.
pub type Sweep = manifest::sweep::Sweep<SceneSpec>;

/// Particles of an experiment plus the box fluid particles must stay in.
#[derive(Debug, Clone)]
pub struct Scene<const D: usize> {
    pub particles: Particles<D>,
    pub domain_min_m: Vector<D>,
    pub domain_max_m: Vector<D>,
    /// Rigid bodies of wall particles on time-pure paths (the slump cone, rods).
    pub bodies: Vec<RigidBody<D>>,
    /// Inlets that add fluid during the run.
    pub inlets: Vec<Inlet<D>>,
    /// Gravity turned from -vertical towards +x by this angle (the inclined layer); 0 else.
    pub gravity_tilt_rad: f64,
    /// A periodic x axis (the inclined layer); None else.
    pub periodic_x: Option<mps::PeriodicX>,
    /// Mirror symmetry planes (a quarter of the slump); none else.
    pub symmetry: mps::grid::MirrorPlanes,
}

/// What makes a test that test. Each method gets the whole manifest (spacing, fluid, MPS
/// layers) besides the test's own section `self`.
pub trait Experiment {
    /// Checks of the section (fields `scene.*`) and of the manifest's fit to the test.
    fn check(&self, m: &Manifest, c: &mut Checker);
    /// The particle set at t = 0, its moving bodies and its inlets.
    fn build<const D: usize>(&self, m: &Manifest) -> Scene<D>;
    /// The scene's domain box (`Scene::domain_min_m`, `domain_max_m`) without building its
    /// particles: validation and the size estimate need it before a scene of unknown size
    /// may be built.
    fn domain<const D: usize>(&self, m: &Manifest) -> (Vector<D>, Vector<D>);
    /// Names of the metrics [`Experiment::metrics`] adds for `m` (besides
    /// `front_position_m`, which every test reports).
    fn metric_names(&self, m: &Manifest) -> Vec<&'static str>;
    /// The test's metrics and closed forms at the current state, reached at `time_s`.
    fn metrics<const D: usize>(
        &self,
        m: &Manifest,
        particles: &Particles<D>,
        time_s: f64,
        out: &mut BTreeMap<String, f64>,
    );
    /// The summary metric that `runner verify --trend` follows by default.
    fn trend_metric(&self) -> &'static str;
    /// Times at which a metric first reaches a threshold (e.g. the slump's t500), found by
    /// the time loop at the diagnostics times and recorded in the summary.
    fn crossings(&self, _m: &Manifest) -> Vec<Crossing> {
        Vec::new()
    }
    /// Maxima of a metric over the diagnostics rows from a time on (e.g. the tank's speed
    /// after settling), recorded in the summary.
    fn extremes(&self, _m: &Manifest) -> Vec<Extreme> {
        Vec::new()
    }
    /// The yield stress (Pa) that a closed form of the test gives for `value` of `metric`,
    /// where it has one: the first guess of `runner calibrate`.
    fn yield_stress_guess_pa(&self, _m: &Manifest, _metric: &str, _value: f64) -> Option<f64> {
        None
    }
    /// The summary metrics that are flow measures (a spread, a front, a filling distance or
    /// rate): they fall as the concrete stiffens. With the test's crossings (flow times, which
    /// rise) they tell `runner calibrate` which way to step ([`SceneSpec::stiffening_response`]).
    fn flow_measures(&self) -> &'static [&'static str] {
        &[]
    }
    /// The measured metric a closed-form metric `closed` (`closed_form_*`) stands beside,
    /// where its name does not say it (see [`closed_form_pairs`]).
    fn measured_for(&self, _closed: &str) -> Option<&'static str> {
        None
    }
    /// Sections of a state as cells (the rock fill's concrete, rock and empty void), drawn
    /// by the report; none for most tests.
    fn cell_maps<const D: usize>(&self, _m: &Manifest, _particles: &Particles<D>) -> Vec<CellMap> {
        Vec::new()
    }
    /// Metadata records that describe the scene in the run file (the rock bed's rocks), as
    /// (record name, entries); none for most tests. Derived from the manifest alone, so a
    /// resumed file writes the same.
    fn file_records(&self, _m: &Manifest) -> Vec<FileRecord> {
        Vec::new()
    }
    /// The test's figures drawn once per stage (the rodding's strokes), `None` for a test
    /// that does not go in stages.
    fn staged_figures(&self) -> Option<StagedFigures> {
        None
    }
    /// The free surface of a 3D state at `time_s` against the test's closed form (the figure
    /// and table of `runner profile` and of the report), headed by `title`; `None` for a
    /// test without one, an error naming what is missing.
    fn surface_profile(
        &self,
        _m: &Manifest,
        _particles: &Particles<3>,
        _time_s: f64,
        _title: &str,
    ) -> Option<Result<SurfaceProfile, String>> {
        None
    }
}

/// How a summary metric responds when the concrete stiffens
/// ([`SceneSpec::stiffening_response`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Response {
    /// A flow measure (a spread, a filling distance or rate): falls as the yield stress or
    /// the plastic viscosity rises.
    FlowMeasure,
    /// A flow time (t500, t200): rises as either rises, in proportion to the plastic
    /// viscosity (the viscous time scale mu_p / (rho g H)).
    FlowTime,
}

/// Declares the tests: their modules, the [`SceneSpec`] enum (one variant per `scene.kind`)
/// and the one `match` that dispatches on it.
macro_rules! experiments {
    ($d:tt $($variant:ident($module:ident :: $section:ident) = $kind:literal,)*) => {
        $(pub mod $module;)*

        /// The manifest's `scene:` section, tagged by `kind`; each variant's struct belongs
        /// to its test module.
        #[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
        #[serde(tag = "kind")]
        pub enum SceneSpec {
            $(#[serde(rename = $kind)] $variant($module::$section),)*
        }

        /// Runs `$body` with `$e` bound to the test of `$spec`.
        macro_rules! with_experiment {
            ($d spec:expr, $d e:ident => $d body:expr) => {
                match $d spec {
                    $(SceneSpec::$variant($d e) => $d body,)*
                }
            };
        }

        impl SceneSpec {
            /// The `kind` tag, e.g. `"dam_break"`.
            pub fn kind_name(&self) -> &'static str {
                match self {
                    $(SceneSpec::$variant(_) => $kind,)*
                }
            }
            /// Every test with its default section.
            pub fn all_defaults() -> Vec<SceneSpec> {
                vec![$(SceneSpec::$variant($module::$section::default()),)*]
            }
        }
    };
}

experiments! {$
    DamBreak(dam_break::DamBreak) = "dam_break",
    ColumnCollapse(column_collapse::ColumnCollapse) = "column_collapse",
    LFlow(l_flow::LFlow) = "l_flow",
    Slump(slump::Slump) = "slump",
    Rodding(rodding::Rodding) = "rodding",
    LbBox(lb_box::LbBox) = "lb_box",
    TankAtRest(tank_at_rest::TankAtRest) = "tank_at_rest",
    InclinedLayer(inclined_layer::InclinedLayer) = "inclined_layer",
    Rockfill(rockfill::Rockfill) = "rockfill",
}

impl SceneSection for SceneSpec {
    fn kind_name(&self) -> &'static str {
        SceneSpec::kind_name(self)
    }
    fn check(&self, m: &Manifest, c: &mut Checker) {
        with_experiment!(self, e => e.check(m, c));
        // The boundaries section is checked against the test's scene, which is built only
        // from a manifest that passed everything else.
        if m.boundaries.is_empty()
            || !c.is_clean()
            || !crate::manifest::boundaries::check(&m.boundaries, m.dimension as usize).is_empty()
        {
            return;
        }
        match m.dimension {
            2 => check_boundaries::<2>(self, m, c),
            3 => check_boundaries::<3>(self, m, c),
            _ => {}
        }
    }
    fn metric_names(&self, m: &Manifest) -> Vec<String> {
        metric_names(m)
    }
    fn samples() -> Vec<Self> {
        Self::all_defaults()
    }
}

fn check_boundaries<const D: usize>(spec: &SceneSpec, m: &Manifest, c: &mut Checker) {
    // The box alone: building the scene here allocated every particle of a run not yet
    // checked for size (a 10 um pour aborted in validation).
    let (min_m, max_m) = with_experiment!(spec, e => e.domain::<D>(m));
    let domain = boundaries::Domain {
        min_m: &min_m,
        max_m: &max_m,
    };
    boundaries::check(m, domain, c);
}

impl SceneSpec {
    /// The summary metric `runner verify --trend` follows by default for this test.
    pub fn trend_metric(&self) -> &'static str {
        with_experiment!(self, e => e.trend_metric())
    }
    /// How summary metric `metric` responds when the concrete stiffens (a higher yield stress
    /// or plastic viscosity), where the test says: one of its flow measures falls, one of its
    /// crossings (the time a flow measure reaches a threshold) rises.
    pub fn stiffening_response(&self, m: &Manifest, metric: &str) -> Option<Response> {
        with_experiment!(self, e => {
            if e.flow_measures().contains(&metric) {
                Some(Response::FlowMeasure)
            } else if e.crossings(m).iter().any(|c| c.name == metric) {
                Some(Response::FlowTime)
            } else {
                None
            }
        })
    }
    /// See [`Experiment::surface_profile`].
    pub fn surface_profile(
        &self,
        m: &Manifest,
        particles: &Particles<3>,
        time_s: f64,
        title: &str,
    ) -> Option<Result<SurfaceProfile, String>> {
        with_experiment!(self, e => e.surface_profile(m, particles, time_s, title))
    }

    /// See [`Experiment::cell_maps`].
    pub fn cell_maps<const D: usize>(
        &self,
        m: &Manifest,
        particles: &Particles<D>,
    ) -> Vec<CellMap> {
        with_experiment!(self, e => e.cell_maps(m, particles))
    }

    /// The test's figures drawn once per stage, if it goes in stages.
    pub fn staged_figures(&self) -> Option<StagedFigures> {
        with_experiment!(self, e => e.staged_figures())
    }
}

/// Reads, overrides, checks and hashes the manifest at `path`.
/// A summary metric `name` = the time, counted from `since_s`, at which `metric` first
/// reaches `threshold`: linear interpolation between the two diagnostics rows around the
/// crossing (so it is known to better than `output.diagnostics_interval_s`). Left out of the
/// summary when the run never reaches it.
#[derive(Debug, Clone, PartialEq)]
pub struct Crossing {
    pub name: &'static str,
    pub metric: &'static str,
    pub threshold: f64,
    pub since_s: f64,
}

/// Each closed-form metric of `m`'s test with the measured metric it stands beside: for
/// `closed_form_X` the test's own choice ([`Experiment::measured_for`]), else `X`, else
/// `surface_X`, where the test reports one; `None` for a closed form with no measured twin
/// (the inclined layer's critical depth).
pub fn closed_form_pairs(m: &Manifest) -> Vec<(String, Option<String>)> {
    let names = metric_names(m);
    names
        .iter()
        .filter_map(|closed| {
            let x = closed.strip_prefix("closed_form_")?;
            let own = with_experiment!(&m.scene, e => e.measured_for(closed)).map(str::to_string);
            let measured = own
                .into_iter()
                .chain([x.to_string(), format!("surface_{x}")])
                .find(|n| names.contains(n));
            Some((closed.clone(), measured))
        })
        .collect()
}

/// A metadata record of a run file: its name and its (key, value) entries.
pub type FileRecord = (&'static str, Vec<(&'static str, String)>);

/// See [`Experiment::file_records`].
pub fn file_records(m: &Manifest) -> Vec<FileRecord> {
    with_experiment!(&m.scene, e => e.file_records(m))
}

/// See [`Experiment::crossings`].
pub fn crossings(m: &Manifest) -> Vec<Crossing> {
    with_experiment!(&m.scene, e => e.crossings(m))
}

/// A summary metric `name` = the largest value of `metric` over the diagnostics rows at
/// times >= `since_s` (sampled at `output.diagnostics_interval_s`). Left out of the summary
/// when no row is that late.
#[derive(Debug, Clone, PartialEq)]
pub struct Extreme {
    pub name: &'static str,
    pub metric: &'static str,
    pub since_s: f64,
}

/// See [`Experiment::extremes`].
pub fn extremes(m: &Manifest) -> Vec<Extreme> {
    with_experiment!(&m.scene, e => e.extremes(m))
}

/// Names of the summary metrics that [`RowTracker`] adds for `m`: crossings and extremes.
pub fn row_metric_names(m: &Manifest) -> Vec<String> {
    crossings(m)
        .iter()
        .map(|c| c.name)
        .chain(extremes(m).iter().map(|e| e.name))
        .map(str::to_string)
        .collect()
}

/// Summary metrics that builds before them did not record: a file without one is not a
/// mismatch for `runner verify`, which says so in a note.
pub const LATER_METRICS: &[&str] = &["t500_s", "t200_s", "t400_s", "non_flowing_fraction"];

/// The first crossing of each [`Crossing`] and the running maximum of each [`Extreme`], fed
/// with the diagnostics rows in time order.
#[derive(Debug, Clone, Default)]
pub struct RowTracker {
    crossings: Vec<Crossing>,
    extremes: Vec<Extreme>,
    /// The previous row's time and the value of each crossing's metric there.
    previous: Option<(f64, Vec<Option<f64>>)>,
    found: BTreeMap<String, f64>,
}

impl RowTracker {
    pub fn new(m: &Manifest) -> Self {
        Self {
            crossings: crossings(m),
            extremes: extremes(m),
            ..Self::default()
        }
    }
    pub fn is_empty(&self) -> bool {
        self.crossings.is_empty() && self.extremes.is_empty()
    }
    /// One diagnostics row: its time and a lookup of its experiment metrics.
    pub fn row(&mut self, time_s: f64, metric: impl Fn(&str) -> Option<f64>) {
        for e in &self.extremes {
            if time_s < e.since_s {
                continue;
            }
            if let Some(v) = metric(e.metric) {
                let best = self.found.entry(e.name.to_string()).or_insert(v);
                *best = best.max(v);
            }
        }
        let values: Vec<Option<f64>> = self.crossings.iter().map(|c| metric(c.metric)).collect();
        for (k, c) in self.crossings.iter().enumerate() {
            if self.found.contains_key(c.name) || time_s < c.since_s {
                continue;
            }
            let Some(v) = values[k] else {
                continue;
            };
            if v < c.threshold {
                continue;
            }
            // Interpolated from the previous row when it was below and after since_s.
            let t = match &self.previous {
                Some((t0, v0)) if *t0 >= c.since_s => match v0[k] {
                    Some(v0) if v0 < c.threshold && v > v0 => {
                        t0 + (c.threshold - v0) / (v - v0) * (time_s - t0)
                    }
                    _ => time_s,
                },
                _ => time_s,
            };
            self.found.insert(c.name.to_string(), t - c.since_s);
        }
        self.previous = Some((time_s, values));
    }
    pub fn found(&self) -> &BTreeMap<String, f64> {
        &self.found
    }
}

/// See [`Experiment::yield_stress_guess_pa`].
pub fn yield_stress_guess_pa(m: &Manifest, metric: &str, value: f64) -> Option<f64> {
    with_experiment!(&m.scene, e => e.yield_stress_guess_pa(m, metric, value))
}

pub fn load(path: &Path, overrides: &[String]) -> manifest::Result<Resolved> {
    manifest::load(path, overrides)
}

/// Like [`load`], from text (`source_name` names it in errors).
pub fn from_str(text: &str, source_name: &str, overrides: &[String]) -> manifest::Result<Resolved> {
    manifest::from_str(text, source_name, overrides)
}

/// Reads a manifest file that may hold a sweep.
pub fn load_plan(path: &Path, overrides: &[String]) -> manifest::Result<Plan> {
    manifest::sweep::load_plan(path, overrides)
}

/// Like [`load_plan`], from text.
pub fn plan_from_str(
    text: &str,
    source_name: &str,
    overrides: &[String],
) -> manifest::Result<Plan> {
    manifest::sweep::plan_from_str(text, source_name, overrides)
}

/// The particle set a manifest describes.
pub fn build_scene<const D: usize>(m: &Manifest) -> Scene<D> {
    let mut scene = with_experiment!(&m.scene, e => e.build::<D>(m));
    boundaries::apply(m, &mut scene);
    scene
}

/// About how many particles the run of `m` will hold (its scene plus what its inlets pour),
/// without building it at its spacing: the scene is built at spacings f l0 and 2 f l0, f the
/// smallest power of sqrt 2 whose scene holds at most 20 000 particles, and the two counts
/// fitted as a volume and a surface term, n = X (f l0 / h)^D + Y (f l0 / h)^(D-1) (fluid
/// fills volumes, walls are layers on surfaces), then taken at h = l0. A scene of up to
/// 20 000 particles is counted exactly. The cost is that of two scenes of that size.
pub fn estimate_particles(m: &Manifest) -> f64 {
    let d = m.dimension as usize;
    let count = |factor: f64| -> f64 {
        let mut coarse = m.clone();
        coarse.spacing_m = m.spacing_m * factor;
        // Inlets pour later; a coarse build needs none of them.
        coarse.boundaries.inlets.clear();
        match m.dimension {
            3 => build_scene::<3>(&coarse).particles.len() as f64,
            _ => build_scene::<2>(&coarse).particles.len() as f64,
        }
    };
    let factor = |j: u32| f64::from(1u32 << (j / 2)) * if j % 2 == 1 { 2f64.sqrt() } else { 1.0 };
    // Start so coarse that any scene is a handful of cells, then refine.
    let mut j = 40;
    let (mut n, mut coarser) = (count(factor(j)), 0.0);
    while j > 0 && n < 20_000.0 {
        j -= 1;
        if j + 2 <= 40 {
            coarser = count(factor(j + 2));
        }
        n = count(factor(j));
    }
    let scene = if j == 0 {
        n
    } else {
        // n = X + Y at f, coarser = X / 2^D + Y / 2^(D-1) at 2 f.
        let half = cell_volume_of(2.0, d - 1);
        let x = (2.0 * (n - half * coarser)).max(0.0);
        let y = (n - x).max(0.0);
        let f = factor(j);
        x * cell_volume_of(f, d) + y * cell_volume_of(f, d - 1)
    };
    let poured: f64 = m
        .boundaries
        .inlets
        .iter()
        .map(|i| i.volume_m3 / mps::particles::cell_volume(m.spacing_m, m.dimension as usize))
        .sum();
    scene + poured
}

fn cell_volume_of(length: f64, dimension: usize) -> f64 {
    mps::particles::cell_volume(length, dimension)
}

/// Metrics of the experiment at the current state (documented in docs/file-format.md): the front
/// position, which every test reports, and the test's own.
pub fn experiment_metrics<const D: usize>(
    m: &Manifest,
    particles: &Particles<D>,
    time_s: f64,
) -> BTreeMap<String, f64> {
    let mut out = BTreeMap::new();
    out.insert(
        "front_position_m".to_string(),
        front_position_m(particles, m.spacing_m),
    );
    with_experiment!(&m.scene, e => e.metrics(m, particles, time_s, &mut out));
    let tags = boundaries::tags_in_use(&m.boundaries);
    if !tags.is_empty() {
        let mut counts = vec![0usize; usize::from(*tags.last().expect("not empty")) + 1];
        for i in 0..particles.len() {
            if particles.kind[i] == ParticleKind::Fluid {
                let t = usize::from(particles.tag[i]);
                if t < counts.len() {
                    counts[t] += 1;
                }
            }
        }
        for t in tags {
            out.insert(tag_metric(t), counts[usize::from(t)] as f64);
        }
    }
    out
}

/// The metric counting the fluid particles of tag `tag`.
fn tag_metric(tag: u16) -> String {
    format!("fluid_count_tag_{tag}")
}

/// Names of the metrics [`experiment_metrics`] gives for this manifest, sorted.
pub fn metric_names(m: &Manifest) -> Vec<String> {
    let mut names: Vec<String> = with_experiment!(&m.scene, e => e.metric_names(m))
        .into_iter()
        .map(str::to_string)
        .collect();
    names.push("front_position_m".to_string());
    names.extend(
        boundaries::tags_in_use(&m.boundaries)
            .into_iter()
            .map(tag_metric),
    );
    names.sort();
    names.dedup();
    names
}

/// Front position: distance from the wall at x = 0 to the far edge of the furthest fluid
/// particle (its centre plus half a spacing, so a column of width a starts at exactly a).
pub fn front_position_m<const D: usize>(particles: &Particles<D>, spacing_m: f64) -> f64 {
    let mut front = f64::NEG_INFINITY;
    for i in 0..particles.len() {
        if particles.kind[i] == ParticleKind::Fluid {
            front = front.max(particles.position_m[i][0]);
        }
    }
    front + 0.5 * spacing_m
}

/// How far the front ([`front_position_m`]) lies past `x_m` (0 when it does not, or when
/// there is no fluid): the L-flow value and the L-B box's filling distance.
pub fn front_past_m<const D: usize>(particles: &Particles<D>, x_m: f64, spacing_m: f64) -> f64 {
    (front_position_m(particles, spacing_m) - x_m).max(0.0)
}

/// Yield stress of the fluid (0 for a Newtonian one).
pub fn yield_stress_pa(fluid: &Fluid) -> f64 {
    match *fluid {
        Fluid::Newtonian { .. } => 0.0,
        Fluid::Bingham {
            yield_stress_pa, ..
        }
        | Fluid::BiViscosity {
            yield_stress_pa, ..
        } => yield_stress_pa,
    }
}

/// Fails `dimension` unless the manifest is 3D: `kind` names the test, `why` says why.
pub fn require_3d(m: &Manifest, c: &mut Checker, kind: &str, why: &str) {
    if m.dimension != 3 {
        c.fail(
            "dimension",
            format!(
                "scene.kind {kind} is a 3D test ({why}): dimension must be 3, got {}",
                m.dimension
            ),
        );
    }
}

/// Fails `field` (a scene's switch to mirror symmetry planes, when on) if the manifest asks
/// for the exact or the adjoint projection, whose gradient rows have no mirror images.
pub fn refuse_planes_without_images(m: &Manifest, c: &mut Checker, field: &str, on: bool) {
    if on && m.mps.pressure_scheme != crate::manifest::PressureSchemeName::Standard {
        for (set, name) in [
            (m.mps.exact_projection, "mps.exact_projection"),
            (m.mps.adjoint_projection, "mps.adjoint_projection"),
        ] {
            if set {
                c.fail(
                    field,
                    format!(
                        "is not available with {name} (its gradient rows have no mirror images)"
                    ),
                );
            }
        }
    }
}

/// Checks an optional field that only a 3D scene takes: absent is fine; in 2D it fails
/// naming `field` (`no_2d` says what a 2D scene lacks); in 3D its value must be in `range`.
pub fn check_3d_only(
    m: &Manifest,
    c: &mut Checker,
    field: &str,
    value: Option<f64>,
    range: crate::manifest::validate::Range,
    no_2d: &str,
) -> bool {
    match (m.dimension, value) {
        (_, None) => true,
        (3, Some(v)) => c.real(field, v, range),
        (_, Some(_)) => {
            c.fail(field, format!("is for dimension 3 only ({no_2d})"));
            false
        }
    }
}

/// Side walls at rest whose surface slips (Navier slip length `slip_length_m`; see
/// `mps::viscosity::SlipWall`): the particles `first..end` as one body that never moves.
pub fn slipping_walls<const D: usize>(
    first: usize,
    end: usize,
    slip_length_m: f64,
) -> RigidBody<D> {
    RigidBody {
        first,
        end,
        path: mps::Path::lift(0.0, Vector::<D>::zeros(), Vector::<D>::zeros()),
        slip_length_m: Some(slip_length_m),
    }
}

/// Whether the manifest's spacing passed its own check (scene checks that compare lengths
/// with it skip otherwise).
pub fn spacing_ok(m: &Manifest) -> bool {
    m.spacing_m.is_finite() && m.spacing_m > 0.0
}

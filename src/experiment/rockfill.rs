//! Rock-filled concrete (seed 004's purpose; docs/rockfill.md): a rectangular form holds a bed
//! of rocks (spheres; discs in 2D) deposited by gravity from a seeded generator
//! ([`bed`]), and concrete poured from one or more inlets above it flows down through the
//! voids. The metrics map how well the void fills: the filled fraction (overall and in
//! horizontal layers), the pockets that no concrete reached, the free surface's height and how
//! far the concrete got along the floor.
//!
//! Geometry: x along the form (inner length `form_length_m`), in 3D y across it
//! (`form_width_m`), the last axis up from the floor; walls up to `form_height_m`, open above.
//! The bed is deposited in the form's nominal size, so that it is the same at every spacing;
//! the walls are snapped to whole lattice cells. Rocks are static solids of wall and dummy
//! layers.
pub mod bed;

use super::boundaries::{fill_solid, taken_cells};
use super::geometry::container::{CellBox, add_walls};
use super::geometry::lattice::cells;
use super::geometry::shapes::Shape;
use super::{CellMap, Crossing, Experiment, Fill, Manifest, Scene};
use crate::manifest::validate::{Checker, NON_NEGATIVE, POSITIVE, between, fmt_num};
use crate::mps::grid::MirrorPlanes;
use crate::mps::particles::cell_volume;
use crate::mps::{Inlet, ParticleKind, Particles, Vector};
use bed::{Bed, Deposition, Sizes};
use serde::{Deserialize, Serialize};
use std::any::Any;
use std::collections::BTreeMap;
use std::sync::{Arc, Mutex};

/// Most rocks in a bed (each is a scan of its cells and a term in every deposition step).
pub const MAX_ROCKS: usize = 4096;
/// Most size classes and most pours.
pub const MAX_CLASSES: usize = 16;
pub const MAX_POURS: usize = 16;
/// Most horizontal layers of the filled fraction.
pub const MAX_LAYERS: u32 = 20;
/// The layers' metric names, bottom up.
const LAYER_NAMES: [&str; MAX_LAYERS as usize] = [
    "filled_fraction_layer_01",
    "filled_fraction_layer_02",
    "filled_fraction_layer_03",
    "filled_fraction_layer_04",
    "filled_fraction_layer_05",
    "filled_fraction_layer_06",
    "filled_fraction_layer_07",
    "filled_fraction_layer_08",
    "filled_fraction_layer_09",
    "filled_fraction_layer_10",
    "filled_fraction_layer_11",
    "filled_fraction_layer_12",
    "filled_fraction_layer_13",
    "filled_fraction_layer_14",
    "filled_fraction_layer_15",
    "filled_fraction_layer_16",
    "filled_fraction_layer_17",
    "filled_fraction_layer_18",
    "filled_fraction_layer_19",
    "filled_fraction_layer_20",
];

/// `scene: {kind: rockfill}`. Defaults: a 0.4 m laboratory block of 80-120 mm rocks poured
/// from one central inlet (docs/rockfill.md).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Rockfill {
    /// Inner length (x) of the form, in metres.
    pub form_length_m: f64,
    /// Inner width (y) of the form, in metres (3D only).
    pub form_width_m: f64,
    /// Height of the form's walls (open above), in metres.
    pub form_height_m: f64,
    /// The rock bed.
    pub bed: RockBed,
    /// Inlets above the bed, pouring straight down.
    pub pours: Vec<Pour>,
    /// Horizontal layers of equal height between the floor and the bed's height, each with
    /// its own filled fraction.
    pub layers: u32,
    /// `time_to_fill_s` is the time at which `filled_fraction` first reaches this.
    pub fill_threshold: f64,
    /// The deposited bed, built once per run.
    #[serde(skip)]
    bed_cache: Cache,
    /// The metrics' voxel grid, built once per run.
    #[serde(skip)]
    prepared: Cache,
}

/// `scene.bed`: rocks deposited by gravity (docs/rockfill.md, "The rock bed").
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RockBed {
    /// Seed of the generator that draws the rocks' sizes and drop positions.
    pub seed: u64,
    /// A rock is kept only if its top lies at or below this height, in metres.
    pub height_m: f64,
    /// Size classes by share of the rock volume (or leave empty and give
    /// `diameter_range_m`).
    pub sizes: Vec<RockSize>,
    /// [min, max] diameters, drawn uniformly (or leave empty and give `sizes`).
    pub diameter_range_m: Vec<f64>,
    /// Clearance between rocks, half of it at the walls and the floor, in metres; in 2D the
    /// voids between touching discs are closed, so a 2D bed needs one.
    pub gap_m: f64,
    /// Drops in a row whose rock ends above `height_m` (or does not come to rest) that end
    /// the deposition.
    pub misses: u32,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RockSize {
    pub diameter_m: f64,
    /// Share of the rock volume in this class; the shares add up to 1.
    pub volume_fraction: f64,
}

/// `scene.pours[k]`: a disc (segment in 2D) pouring straight down.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Pour {
    /// Centre of the opening [x, (y,) z], in metres.
    pub centre_m: Vec<f64>,
    /// Diameter of the disc (length of the segment in 2D), in metres.
    pub diameter_m: f64,
    /// Speed of the concrete through it, m/s.
    pub speed_m_s: f64,
    /// Volume poured, m^3 (m^2 per metre of depth in 2D).
    pub volume_m3: f64,
    /// When it starts, s.
    #[serde(default)]
    pub start_s: f64,
}

/// A `bed:` section that names neither sizes nor a range is refused (the scene's default
/// bed, when `bed:` is left out, has the range [0.08, 0.12] m).
impl Default for RockBed {
    fn default() -> Self {
        Self {
            seed: 1,
            height_m: 0.4,
            sizes: Vec::new(),
            diameter_range_m: Vec::new(),
            gap_m: 0.0,
            misses: 200,
        }
    }
}

impl Default for Rockfill {
    fn default() -> Self {
        Self {
            form_length_m: 0.4,
            form_width_m: 0.4,
            form_height_m: 0.5,
            bed: RockBed {
                diameter_range_m: vec![0.08, 0.12],
                ..RockBed::default()
            },
            pours: vec![Pour {
                centre_m: vec![0.2, 0.2, 0.46],
                diameter_m: 0.08,
                speed_m_s: 1.0,
                volume_m3: 0.036,
                start_s: 0.0,
            }],
            layers: 4,
            fill_threshold: 0.95,
            bed_cache: Cache::default(),
            prepared: Cache::default(),
        }
    }
}

impl Experiment for Rockfill {
    fn flow_measures(&self) -> &'static [&'static str] {
        &["filled_fraction", "floor_reach_m"]
    }

    fn check(&self, m: &Manifest, c: &mut Checker) {
        let d = m.dimension as usize;
        let mut dims = vec![
            ("scene.form_length_m", self.form_length_m),
            ("scene.form_height_m", self.form_height_m),
        ];
        if d == 3 {
            dims.insert(1, ("scene.form_width_m", self.form_width_m));
        }
        let mut ok = true;
        for &(field, x) in &dims {
            ok &= c.real(field, x, POSITIVE);
        }
        ok &= c.real("scene.bed.height_m", self.bed.height_m, POSITIVE);
        ok &= c.real("scene.bed.gap_m", self.bed.gap_m, NON_NEGATIVE);
        ok &= c.real("scene.fill_threshold", self.fill_threshold, between(0.0, false, 1.0, true));
        if self.layers == 0 || self.layers > MAX_LAYERS {
            c.fail(
                "scene.layers",
                format!("must be 1 to {MAX_LAYERS}, got {}", self.layers),
            );
        }
        if self.bed.misses == 0 || self.bed.misses > 100_000 {
            c.fail(
                "scene.bed.misses",
                format!("must be 1 to 100000, got {}", self.bed.misses),
            );
        }
        ok &= self.check_sizes(c);
        ok &= self.check_pours(d, c);
        if !ok {
            return;
        }
        if self.bed.height_m > self.form_height_m {
            c.fail(
                "scene.bed.height_m",
                format!(
                    "must be <= scene.form_height_m ({}), got {}",
                    fmt_num(self.form_height_m),
                    fmt_num(self.bed.height_m)
                ),
            );
        }
        let sizes = self.sizes();
        let largest = sizes.largest_m() + self.bed.gap_m;
        for &(field, x) in &dims[..d - 1] {
            if largest > x {
                c.fail(
                    field,
                    format!(
                        "must hold the largest rock with its clearance ({} m), got {}",
                        fmt_num(largest),
                        fmt_num(x)
                    ),
                );
            }
        }
        // A typo guard against a bed of millions of rocks: the form's volume over the
        // smallest rock's at a packing of 0.64 (random close packing).
        let smallest = self.smallest_diameter_m() + self.bed.gap_m;
        let footprint: f64 = dims[..d - 1].iter().map(|f| f.1).product();
        let rocks = 0.64 * footprint * self.bed.height_m / rock_volume(smallest, d);
        if rocks > MAX_ROCKS as f64 {
            c.fail(
                "scene.bed",
                format!(
                    "the form could hold about {} rocks of the smallest size, more than {MAX_ROCKS}",
                    rocks.round()
                ),
            );
        }
        for (k, pour) in self.pours.iter().enumerate() {
            let r = 0.5 * pour.diameter_m;
            let z = pour.centre_m[d - 1];
            if z <= self.bed.height_m || z > self.form_height_m {
                c.fail(
                    &format!("scene.pours.{k}.centre_m.{}", d - 1),
                    format!(
                        "the pour must lie above the bed and within the form: height in ({}, {}], got {}",
                        fmt_num(self.bed.height_m),
                        fmt_num(self.form_height_m),
                        fmt_num(z)
                    ),
                );
            }
            for (a, &(_, length)) in dims[..d - 1].iter().enumerate() {
                let x = pour.centre_m[a];
                if x - r < 0.0 || x + r > length {
                    c.fail(
                        &format!("scene.pours.{k}.centre_m.{a}"),
                        format!(
                            "the opening ({} +- {} m) must lie over the form, [0, {}]",
                            fmt_num(x),
                            fmt_num(r),
                            fmt_num(length)
                        ),
                    );
                }
            }
        }
        if super::spacing_ok(m) {
            c.lattice_lengths(&dims, m.spacing_m);
            if self.smallest_diameter_m() < 2.0 * m.spacing_m {
                c.fail(
                    "scene.bed",
                    format!(
                        "the smallest rock ({} m) must be at least two spacings across (spacing_m = {})",
                        fmt_num(self.smallest_diameter_m()),
                        fmt_num(m.spacing_m)
                    ),
                );
            }
            if c.is_clean() {
                if d == 3 {
                    self.check_inlets::<3>(m.spacing_m, c);
                } else {
                    self.check_inlets::<2>(m.spacing_m, c);
                }
            }
        }
    }

    fn build<const D: usize>(&self, m: &Manifest) -> Scene<D> {
        let l0 = m.spacing_m;
        let interior = self.interior::<D>(l0);
        let mut particles = Particles::<D>::default();
        add_walls(
            &mut particles,
            &[interior],
            interior.1[D - 1],
            l0,
            m.mps.wall_layers,
            m.mps.dummy_layers,
        );
        let mut taken = taken_cells(&particles);
        for rock in &self.deposit::<D>().rocks {
            let sphere = Shape::Sphere {
                centre_m: rock.centre_m,
                radius_m: rock.radius_m,
            };
            fill_solid(
                &mut particles,
                &sphere,
                l0,
                m.mps.wall_layers_of_solids(),
                m.mps.dummy_layers,
                &mut taken,
            );
        }
        let (domain_min_m, domain_max_m) = self.domain::<D>(m);
        Scene {
            particles,
            domain_min_m,
            domain_max_m,
            bodies: Vec::new(),
            inlets: self.inlets(l0),
            gravity_tilt_rad: 0.0,
            periodic_x: None,
            symmetry: MirrorPlanes::default(),
        }
    }

    /// One form size beyond the form on every side; above, to the highest pour too.
    fn domain<const D: usize>(&self, m: &Manifest) -> (Vector<D>, Vector<D>) {
        let interior = self.interior::<D>(m.spacing_m);
        let top = self
            .pours
            .iter()
            .filter_map(|p| p.centre_m.get(D - 1).copied())
            .fold(self.form_height_m, f64::max);
        let size = Vector::<D>::from_fn(|a, _| {
            let x = interior.1[a] as f64 * m.spacing_m;
            if a == D - 1 { x.max(top) } else { x }
        });
        (-size, size * 2.0)
    }

    fn metric_names(&self, m: &Manifest) -> Vec<&'static str> {
        let mut names = vec![
            "poured_volume_m3",
            "filled_fraction",
            "bed_porosity",
            "rock_count",
            "pocket_count",
            "pocket_volume_m3",
            "pocket_volume_far_from_contacts_m3",
            "largest_pocket_m3",
            "largest_pocket_x_m",
        ];
        if m.dimension == 3 {
            names.push("largest_pocket_y_m");
        }
        names.extend([
            "largest_pocket_z_m",
            "surface_height_min_m",
            "surface_height_mean_m",
            "surface_height_max_m",
            "floor_reach_m",
            "surface_slope",
            "closed_form_surface_slope",
        ]);
        names.extend(LAYER_NAMES.iter().take(self.layers.min(MAX_LAYERS) as usize));
        names
    }

    fn metrics<const D: usize>(
        &self,
        m: &Manifest,
        particles: &Particles<D>,
        _time_s: f64,
        out: &mut BTreeMap<String, f64>,
    ) {
        let prepared = self.prepared::<D>(m.spacing_m);
        prepared.measure(particles, out);
        // The slope at which a yield-stress material stands in the bed: the yield stress
        // over the weight per wetted area, rho g R_h, with the bed's hydraulic radius (void
        // over wetted surface: R_h = phi d / (6 (1 - phi)) for spheres of Sauter diameter d,
        // phi d / (4 (1 - phi)) for discs); the reasoning of the L-box law (issue 30 item 4).
        let tau_pa = super::yield_stress_pa(&m.fluid);
        let r_h = prepared.hydraulic_radius_m();
        let closed = if r_h > 0.0 {
            tau_pa / (m.fluid.density_kg_m3() * m.gravity_m_s2 * r_h)
        } else {
            0.0
        };
        out.insert("closed_form_surface_slope".into(), closed);
    }

    fn trend_metric(&self) -> &'static str {
        "filled_fraction"
    }

    /// A vertical section through the first pour's axis and, in 3D, a plan view at half the
    /// bed's height: concrete, rock and empty cells over the whole form.
    fn cell_maps<const D: usize>(&self, m: &Manifest, particles: &Particles<D>) -> Vec<CellMap> {
        let l0 = m.spacing_m;
        let bed = self.deposit::<D>();
        let interior = self.interior::<D>(l0);
        let n: [usize; D] = std::array::from_fn(|a| interior.1[a] as usize);
        let pour = &self.pours[0].centre_m;
        let at = |a: usize, x: f64| ((x / l0).floor().max(0.0) as usize).min(n[a] - 1);
        let mut maps = Vec::new();
        if D == 2 {
            maps.push(section(particles, &bed, l0, [0, 1], None, n, "vertical section"));
        } else {
            let y = at(1, pour[1]);
            let title = format!("vertical section at y = {:.3} m", (y as f64 + 0.5) * l0);
            maps.push(section(particles, &bed, l0, [0, 2], Some((1, y)), n, &title));
            let z = at(D - 1, 0.5 * self.bed.height_m);
            let title = format!("plan view at z = {:.3} m", (z as f64 + 0.5) * l0);
            maps.push(section(particles, &bed, l0, [0, 1], Some((2, z)), n, &title));
        }
        maps
    }

    /// `rock_bed`: the deposited rocks (centres and radii in metres, JSON arrays in full
    /// precision), with the seed, the drops and the porosity of the bed zone.
    fn file_records(&self, m: &Manifest) -> Vec<super::FileRecord> {
        let (centres, radii, drops) = if m.dimension == 3 {
            bed_json(&self.deposit::<3>())
        } else {
            bed_json(&self.deposit::<2>())
        };
        let porosity = if m.dimension == 3 {
            self.porosity::<3>()
        } else {
            self.porosity::<2>()
        };
        vec![(
            "rock_bed",
            vec![
                ("seed", self.bed.seed.to_string()),
                ("drops", drops.to_string()),
                ("porosity", format!("{porosity:?}")),
                ("centres_m", centres),
                ("radii_m", radii),
            ],
        )]
    }

    fn crossings(&self, _m: &Manifest) -> Vec<Crossing> {
        vec![Crossing {
            name: "time_to_fill_s",
            metric: "filled_fraction",
            threshold: self.fill_threshold,
            since_s: 0.0,
        }]
    }
}

/// The rocks' centres and radii as JSON arrays (shortest round-trip decimals: exact), and
/// the number of drops.
fn bed_json<const D: usize>(bed: &Bed<D>) -> (String, String, u64) {
    let centres: Vec<Vec<f64>> = bed.rocks.iter().map(|r| r.centre_m.iter().copied().collect()).collect();
    let radii: Vec<f64> = bed.rocks.iter().map(|r| r.radius_m).collect();
    (
        serde_json::to_string(&centres).expect("numbers serialize"),
        serde_json::to_string(&radii).expect("numbers serialize"),
        bed.drops,
    )
}

/// A rock's volume (area in 2D) for diameter d.
fn rock_volume(d: f64, dimension: usize) -> f64 {
    let r = 0.5 * d;
    if dimension == 3 {
        4.0 / 3.0 * std::f64::consts::PI * r * r * r
    } else {
        std::f64::consts::PI * r * r
    }
}

impl Rockfill {
    fn check_sizes(&self, c: &mut Checker) -> bool {
        let b = &self.bed;
        match (b.sizes.is_empty(), b.diameter_range_m.is_empty()) {
            (true, true) | (false, false) => {
                c.fail(
                    "scene.bed.sizes",
                    "give either scene.bed.sizes (classes by volume) or scene.bed.diameter_range_m ([min, max]), not both or neither".into(),
                );
                false
            }
            (true, false) => {
                let r = &b.diameter_range_m;
                if r.len() != 2 {
                    c.fail(
                        "scene.bed.diameter_range_m",
                        format!("must be [min, max] (2 numbers), got {} numbers", r.len()),
                    );
                    return false;
                }
                let ok = c.real("scene.bed.diameter_range_m.0", r[0], POSITIVE)
                    & c.real("scene.bed.diameter_range_m.1", r[1], POSITIVE);
                if ok && r[1] < r[0] {
                    c.fail(
                        "scene.bed.diameter_range_m.1",
                        format!("must be >= the minimum ({}), got {}", fmt_num(r[0]), fmt_num(r[1])),
                    );
                    return false;
                }
                ok
            }
            (false, true) => {
                if b.sizes.len() > MAX_CLASSES {
                    c.fail(
                        "scene.bed.sizes",
                        format!("at most {MAX_CLASSES} classes, got {}", b.sizes.len()),
                    );
                    return false;
                }
                let mut ok = true;
                for (k, s) in b.sizes.iter().enumerate() {
                    ok &= c.real(&format!("scene.bed.sizes.{k}.diameter_m"), s.diameter_m, POSITIVE);
                    ok &= c.real(
                        &format!("scene.bed.sizes.{k}.volume_fraction"),
                        s.volume_fraction,
                        between(0.0, false, 1.0, true),
                    );
                }
                let total: f64 = b.sizes.iter().map(|s| s.volume_fraction).sum();
                if ok && (total - 1.0).abs() > 1e-6 {
                    c.fail(
                        "scene.bed.sizes",
                        format!("the volume fractions must add up to 1, got {}", fmt_num(total)),
                    );
                    ok = false;
                }
                ok
            }
        }
    }

    /// Each pour's opening must hold a lattice point at the spacing.
    fn check_inlets<const D: usize>(&self, spacing_m: f64, c: &mut Checker) {
        for (k, inlet) in self.inlets::<D>(spacing_m).iter().enumerate() {
            if let Err(message) = inlet.validate(spacing_m) {
                c.fail(&format!("scene.pours.{k}.diameter_m"), message);
            }
        }
    }

    fn check_pours(&self, d: usize, c: &mut Checker) -> bool {
        if self.pours.is_empty() || self.pours.len() > MAX_POURS {
            c.fail(
                "scene.pours",
                format!("must list 1 to {MAX_POURS} pours, got {}", self.pours.len()),
            );
            return false;
        }
        let mut ok = true;
        for (k, p) in self.pours.iter().enumerate() {
            let at = format!("scene.pours.{k}");
            if p.centre_m.len() != d {
                c.fail(
                    &format!("{at}.centre_m"),
                    format!("must have {d} numbers (dimension {d}), got {}", p.centre_m.len()),
                );
                ok = false;
            } else {
                for (a, &x) in p.centre_m.iter().enumerate() {
                    ok &= c.real(&format!("{at}.centre_m.{a}"), x, NON_NEGATIVE);
                }
            }
            ok &= c.real(&format!("{at}.diameter_m"), p.diameter_m, POSITIVE);
            ok &= c.real(&format!("{at}.speed_m_s"), p.speed_m_s, POSITIVE);
            ok &= c.real(&format!("{at}.volume_m3"), p.volume_m3, POSITIVE);
            ok &= c.real(&format!("{at}.start_s"), p.start_s, NON_NEGATIVE);
        }
        ok
    }

    /// The size distribution as the generator takes it (validated first).
    pub fn sizes(&self) -> Sizes {
        if self.bed.sizes.is_empty() {
            Sizes::Range(self.bed.diameter_range_m[0], self.bed.diameter_range_m[1])
        } else {
            Sizes::Classes(
                self.bed
                    .sizes
                    .iter()
                    .map(|s| (s.diameter_m, s.volume_fraction))
                    .collect(),
            )
        }
    }

    fn smallest_diameter_m(&self) -> f64 {
        if self.bed.sizes.is_empty() {
            self.bed.diameter_range_m.first().copied().unwrap_or(0.0)
        } else {
            self.bed
                .sizes
                .iter()
                .map(|s| s.diameter_m)
                .fold(f64::INFINITY, f64::min)
        }
    }

    /// The deposition of this bed in the form's nominal size.
    pub fn deposition<const D: usize>(&self) -> Deposition<D> {
        Deposition {
            form_m: Vector::<D>::from_fn(|a, _| match a {
                0 => self.form_length_m,
                a if a == D - 1 => self.form_height_m,
                _ => self.form_width_m,
            }),
            height_m: self.bed.height_m,
            gap_m: self.bed.gap_m,
            sizes: self.sizes(),
            seed: self.bed.seed,
            misses: self.bed.misses,
            max_rocks: MAX_ROCKS,
        }
    }

    /// The bed (deposited once per run: it depends on the scene only, not on the spacing).
    pub fn deposit<const D: usize>(&self) -> Arc<Bed<D>> {
        let deposition = self.deposition::<D>();
        self.bed_cache.get_or(deposition.clone(), || deposition.deposit())
    }

    /// Porosity of the bed zone (the form's nominal footprint up to the bed's height): one
    /// less the rocks' volume over the zone's (every rock lies wholly inside it).
    pub fn porosity<const D: usize>(&self) -> f64 {
        let form = self.deposition::<D>().form_m;
        let zone: f64 = (0..D - 1).map(|a| form[a]).product::<f64>() * self.bed.height_m;
        let solid: f64 = self
            .deposit::<D>()
            .rocks
            .iter()
            .map(|r| rock_volume(2.0 * r.radius_m, D))
            .sum();
        1.0 - solid / zone
    }

    /// The form's inside as lattice cells.
    fn interior<const D: usize>(&self, spacing_m: f64) -> CellBox<D> {
        let n = |x: f64| cells(x, spacing_m);
        (
            [0; D],
            std::array::from_fn(|a| match a {
                0 => n(self.form_length_m),
                a if a == D - 1 => n(self.form_height_m),
                _ => n(self.form_width_m),
            }),
        )
    }

    /// The pours as inlets pouring straight down.
    pub fn inlets<const D: usize>(&self, spacing_m: f64) -> Vec<Inlet<D>> {
        self.pours
            .iter()
            .filter(|p| p.centre_m.len() == D)
            .map(|p| Inlet {
                centre_m: Vector::<D>::from_fn(|a, _| p.centre_m[a]),
                direction: Vector::<D>::from_fn(|a, _| if a == D - 1 { -1.0 } else { 0.0 }),
                radius_m: 0.5 * p.diameter_m,
                speed_m_s: p.speed_m_s,
                volume_m3: p.volume_m3,
                start_s: p.start_s,
                tag: 0,
                clearance_m: 0.9 * spacing_m,
            })
            .collect()
    }

    /// The voxel grid of this scene at `spacing_m`, built once per run. It depends on the
    /// whole scene (the bed, the layers, the pours), so the whole scene is its key.
    fn prepared<const D: usize>(&self, spacing_m: f64) -> Arc<Voxels<D>> {
        let key = (spacing_m, self.clone());
        self.prepared.get_or(key, || Voxels::<D>::new(self, spacing_m))
    }
}

/// A per-run cache of one value built from a key (the bed, the voxel grid); empty in every
/// copy, ignored by comparisons, never serialised. The key (what the value is built from)
/// is kept beside it, so a scene changed in place never reads a stale value.
#[derive(Default)]
struct Cache(Mutex<Option<Arc<dyn Any + Send + Sync>>>);

impl Cache {
    /// The value built from `key`, built by `make` on the first call (or after `key` changed).
    fn get_or<K, T>(&self, key: K, make: impl FnOnce() -> T) -> Arc<T>
    where
        K: PartialEq + Send + Sync + 'static,
        T: Send + Sync + 'static,
    {
        let mut slot = self.0.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(any) = slot.as_ref()
            && let Some((k, v)) = any.downcast_ref::<(K, Arc<T>)>()
            && *k == key
        {
            return Arc::clone(v);
        }
        let v = Arc::new(make());
        *slot = Some(Arc::new((key, Arc::clone(&v))));
        v
    }
}

impl Clone for Cache {
    fn clone(&self) -> Self {
        Self::default()
    }
}
impl PartialEq for Cache {
    fn eq(&self, _: &Self) -> bool {
        true
    }
}
impl std::fmt::Debug for Cache {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("Cache")
    }
}

/// The bed zone (the form's footprint from the floor up to the bed's height, rounded up to
/// whole cells) as voxels of one spacing, and what the metrics need of the bed.
struct Voxels<const D: usize> {
    spacing_m: f64,
    /// Voxels along each axis (the last: rows of the bed zone).
    n: [usize; D],
    /// Columns of the whole form's footprint (for the surface heights).
    columns: usize,
    /// Whether a voxel's centre lies outside every rock (void).
    void: Vec<bool>,
    /// Void voxels in each layer, and the first row of each layer (and one past the last).
    layer_void: Vec<usize>,
    layer_rows: Vec<usize>,
    /// Whether a voxel's centre lies within 2 l0 of a point where two rocks, or a rock and
    /// a wall or the floor, touch (across the gap).
    near_contact: Vec<bool>,
    porosity: f64,
    rocks: usize,
    /// The rocks' volume over their surface, times 2D (6 for spheres, 4 for discs): the
    /// Sauter mean diameter sum d^3 / sum d^2 (sum d^2 / sum d for discs).
    surface_diameter_m: f64,
    /// x of the first pour's centre.
    pour_x_m: f64,
}

impl<const D: usize> Voxels<D> {
    fn new(scene: &Rockfill, spacing_m: f64) -> Self {
        let bed = scene.deposit::<D>();
        let form = scene.deposition::<D>().form_m;
        let interior = scene.interior::<D>(spacing_m);
        let rows = ((scene.bed.height_m / spacing_m).ceil() as usize).max(1);
        let n: [usize; D] = std::array::from_fn(|a| {
            if a == D - 1 { rows } else { interior.1[a] as usize }
        });
        let columns: usize = n[..D - 1].iter().product();
        let total = columns * rows;
        let mut void = vec![true; total];
        for (v, slot) in void.iter_mut().enumerate() {
            let x = voxel_centre(v, &n, spacing_m);
            *slot = bed
                .rocks
                .iter()
                .all(|r| (x - r.centre_m).norm_squared() > r.radius_m * r.radius_m);
        }
        let contacts = contacts(&bed, &form, scene.bed.gap_m);
        let near_contact = (0..total)
            .map(|v| {
                let x = voxel_centre(v, &n, spacing_m);
                contacts
                    .iter()
                    .any(|p| (p - x).norm_squared() <= 4.0 * spacing_m * spacing_m)
            })
            .collect();
        let layers = scene.layers.clamp(1, MAX_LAYERS) as usize;
        let layer_rows: Vec<usize> = (0..=layers).map(|k| k * rows / layers).collect();
        let layer_void = (0..layers)
            .map(|k| {
                void[layer_rows[k] * columns..layer_rows[k + 1] * columns]
                    .iter()
                    .filter(|&&v| v)
                    .count()
            })
            .collect();
        Self {
            spacing_m,
            n,
            columns,
            void,
            layer_void,
            layer_rows,
            near_contact,
            porosity: scene.porosity::<D>(),
            surface_diameter_m: {
                let moment = |k: usize| -> f64 {
                    bed.rocks
                        .iter()
                        .map(|r| (0..k).fold(1.0, |v, _| v * 2.0 * r.radius_m))
                        .sum()
                };
                if bed.rocks.is_empty() { 0.0 } else { moment(D) / moment(D - 1) }
            },
            rocks: bed.rocks.len(),
            pour_x_m: scene.pours.first().map_or(0.0, |p| p.centre_m[0]),
        }
    }

    /// The bed's hydraulic radius, void over wetted surface: phi d / (2 D (1 - phi)).
    fn hydraulic_radius_m(&self) -> f64 {
        if self.rocks == 0 || self.porosity >= 1.0 {
            return 0.0;
        }
        self.porosity * self.surface_diameter_m / (2.0 * D as f64 * (1.0 - self.porosity))
    }

    /// Index of the voxel of the form's footprint holding x (any height), if inside it.
    fn column(&self, x: &Vector<D>) -> Option<usize> {
        let mut index = 0;
        for a in (0..D - 1).rev() {
            let k = (x[a] / self.spacing_m).floor();
            if k < 0.0 || k >= self.n[a] as f64 {
                return None;
            }
            index = index * self.n[a] + k as usize;
        }
        Some(index)
    }

    fn measure(&self, particles: &Particles<D>, out: &mut BTreeMap<String, f64>) {
        let l0 = self.spacing_m;
        let rows = self.n[D - 1];
        let cell = cell_volume(l0, D);
        let layers = self.layer_void.len();
        let mut in_layer = vec![0usize; layers];
        let mut reached = vec![false; self.void.len()];
        let mut top = vec![f64::NEG_INFINITY; self.columns];
        let mut reach: f64 = 0.0;
        let mut fluid = 0usize;
        for i in 0..particles.len() {
            if particles.kind[i] != ParticleKind::Fluid {
                continue;
            }
            fluid += 1;
            let x = particles.position_m[i];
            if x[D - 1] < 2.0 * l0 {
                reach = reach.max((x[0] - self.pour_x_m).abs());
            }
            let Some(column) = self.column(&x) else {
                continue;
            };
            top[column] = top[column].max(x[D - 1]);
            let row = (x[D - 1] / l0).floor();
            if row >= 0.0 && (row as usize) < rows {
                let row = row as usize;
                let layer = self.layer_rows.partition_point(|&r| r <= row) - 1;
                in_layer[layer] += 1;
            }
            self.mark_reached(&x, &mut reached);
        }
        let void_total: usize = self.layer_void.iter().sum();
        let filled: usize = in_layer.iter().sum();
        let fraction = |count: usize, void: usize| {
            if void == 0 { 1.0 } else { count as f64 / void as f64 }
        };
        out.insert("poured_volume_m3".into(), fluid as f64 * cell);
        out.insert("filled_fraction".into(), fraction(filled, void_total));
        for (k, name) in LAYER_NAMES.iter().take(layers).enumerate() {
            out.insert((*name).into(), fraction(in_layer[k], self.layer_void[k]));
        }
        out.insert("bed_porosity".into(), self.porosity);
        out.insert("rock_count".into(), self.rocks as f64);
        self.pockets(&reached, out);
        let heights: Vec<f64> = top
            .iter()
            .map(|&z| if z.is_finite() { z + 0.5 * l0 } else { 0.0 })
            .collect();
        let (lo, hi) = heights
            .iter()
            .fold((f64::INFINITY, 0.0f64), |(lo, hi), &h| (lo.min(h), hi.max(h)));
        out.insert("surface_height_min_m".into(), lo);
        out.insert(
            "surface_height_mean_m".into(),
            heights.iter().sum::<f64>() / heights.len() as f64,
        );
        out.insert("surface_height_max_m".into(), hi);
        out.insert("floor_reach_m".into(), reach);
        out.insert("surface_slope".into(), self.surface_slope(&heights));
    }

    /// How fast the surface falls with the distance along x from the first pour: the
    /// least-squares slope of the columns' surface heights against |x - x_pour|, over the
    /// columns whose surface lies inside the bed zone (concrete there, below the zone's top),
    /// negated (positive: falling away from the pour); NaN (no slope inside the bed) with
    /// fewer than three such columns, e.g. when the concrete covers the bed.
    fn surface_slope(&self, heights: &[f64]) -> f64 {
        let l0 = self.spacing_m;
        let zone_top = self.n[D - 1] as f64 * l0;
        let (mut n, mut sx, mut sy, mut sxx, mut sxy) = (0.0, 0.0, 0.0, 0.0, 0.0);
        for (column, &h) in heights.iter().enumerate() {
            if h <= 0.0 || h >= zone_top {
                continue;
            }
            let x = ((column % self.n[0]) as f64 + 0.5) * l0;
            let d = (x - self.pour_x_m).abs();
            n += 1.0;
            sx += d;
            sy += h;
            sxx += d * d;
            sxy += d * h;
        }
        let spread = n * sxx - sx * sx;
        if n < 3.0 || spread <= 0.0 {
            return f64::NAN;
        }
        -(n * sxy - sx * sy) / spread
    }

    /// Marks the voxels whose centres lie within one spacing of the fluid particle at x.
    fn mark_reached(&self, x: &Vector<D>, reached: &mut [bool]) {
        let l0 = self.spacing_m;
        let base: [i64; D] = std::array::from_fn(|a| (x[a] / l0).floor() as i64);
        let mut offset = [-1i64; D];
        loop {
            let mut index = 0usize;
            let mut inside = true;
            for a in (0..D).rev() {
                let k = base[a] + offset[a];
                if k < 0 || k >= self.n[a] as i64 {
                    inside = false;
                    break;
                }
                index = index * self.n[a] + k as usize;
            }
            if inside {
                let c = voxel_centre(index, &self.n, l0);
                if (c - x).norm_squared() <= l0 * l0 {
                    reached[index] = true;
                }
            }
            let mut a = 0;
            loop {
                offset[a] += 1;
                if offset[a] <= 1 {
                    break;
                }
                offset[a] = -1;
                a += 1;
                if a == D {
                    return;
                }
            }
        }
    }

    /// Pockets: connected regions (through voxel faces) of void that no concrete reached and
    /// that do not reach the bed zone's top row (void open to the top is not yet covered, not
    /// trapped).
    fn pockets(&self, reached: &[bool], out: &mut BTreeMap<String, f64>) {
        let l0 = self.spacing_m;
        let cell = cell_volume(l0, D);
        let rows = self.n[D - 1];
        let empty = |v: usize| self.void[v] && !reached[v];
        let mut seen = vec![false; self.void.len()];
        let mut stack = Vec::new();
        let (mut count, mut volume, mut far) = (0usize, 0usize, 0usize);
        let mut largest: (usize, Vector<D>) = (0, Vector::<D>::zeros());
        let strides: [usize; D] = std::array::from_fn(|a| self.n[..a].iter().product());
        for start in 0..self.void.len() {
            if seen[start] || !empty(start) {
                continue;
            }
            seen[start] = true;
            stack.push(start);
            let (mut size, mut open, mut far_here) = (0usize, false, 0usize);
            let mut sum = Vector::<D>::zeros();
            while let Some(v) = stack.pop() {
                size += 1;
                let c = voxel_centre(v, &self.n, l0);
                sum += c;
                if (v / strides[D - 1]) % rows == rows - 1 {
                    open = true;
                }
                far_here += usize::from(!self.near_contact[v]);
                for a in 0..D {
                    let k = (v / strides[a]) % self.n[a];
                    if k > 0 && !seen[v - strides[a]] && empty(v - strides[a]) {
                        seen[v - strides[a]] = true;
                        stack.push(v - strides[a]);
                    }
                    if k + 1 < self.n[a] && !seen[v + strides[a]] && empty(v + strides[a]) {
                        seen[v + strides[a]] = true;
                        stack.push(v + strides[a]);
                    }
                }
            }
            if open {
                continue;
            }
            count += 1;
            volume += size;
            far += far_here;
            if size > largest.0 {
                largest = (size, sum / size as f64);
            }
        }
        out.insert("pocket_count".into(), count as f64);
        out.insert("pocket_volume_m3".into(), volume as f64 * cell);
        out.insert("pocket_volume_far_from_contacts_m3".into(), far as f64 * cell);
        out.insert("largest_pocket_m3".into(), largest.0 as f64 * cell);
        let axes: &[(&str, usize)] = if D == 3 {
            &[("x", 0), ("y", 1), ("z", 2)]
        } else {
            &[("x", 0), ("z", 1)]
        };
        for &(name, a) in axes {
            let at = if largest.0 > 0 { largest.1[a] } else { 0.0 };
            out.insert(format!("largest_pocket_{name}_m"), at);
        }
    }
}

/// The cells of the plane spanned by `axes` (at cell `fixed` of the remaining axis in 3D)
/// over the form's n cells: rock where the centre lies in a rock, concrete where a fluid
/// particle lies within a spacing of it, empty else.
fn section<const D: usize>(
    particles: &Particles<D>,
    bed: &Bed<D>,
    l0: f64,
    axes: [usize; 2],
    fixed: Option<(usize, usize)>,
    n: [usize; D],
    title: &str,
) -> CellMap {
    let (columns, rows) = (n[axes[0]], n[axes[1]]);
    let centre = |i: usize, j: usize| {
        let mut x = Vector::<D>::zeros();
        x[axes[0]] = (i as f64 + 0.5) * l0;
        x[axes[1]] = (j as f64 + 0.5) * l0;
        if let Some((a, k)) = fixed {
            x[a] = (k as f64 + 0.5) * l0;
        }
        x
    };
    let mut cells = vec![Fill::Empty; columns * rows];
    for i in 0..particles.len() {
        if particles.kind[i] != ParticleKind::Fluid {
            continue;
        }
        let x = particles.position_m[i];
        if let Some((a, k)) = fixed
            && ((k as f64 + 0.5) * l0 - x[a]).abs() > l0
        {
            continue;
        }
        let ci = (x[axes[0]] / l0).floor() as i64;
        let cj = (x[axes[1]] / l0).floor() as i64;
        for dj in -1..=1 {
            for di in -1..=1 {
                let (ii, jj) = (ci + di, cj + dj);
                if ii < 0 || jj < 0 || ii >= columns as i64 || jj >= rows as i64 {
                    continue;
                }
                let (ii, jj) = (ii as usize, jj as usize);
                if (centre(ii, jj) - x).norm_squared() <= l0 * l0 {
                    cells[jj * columns + ii] = Fill::Concrete;
                }
            }
        }
    }
    for j in 0..rows {
        for i in 0..columns {
            let c = centre(i, j);
            if bed
                .rocks
                .iter()
                .any(|r| (c - r.centre_m).norm_squared() < r.radius_m * r.radius_m)
            {
                cells[j * columns + i] = Fill::Rock;
            }
        }
    }
    let name = |a: usize| match a {
        0 => "x [m]",
        1 => "y [m]",
        _ => "z [m]",
    };
    CellMap {
        title: title.to_string(),
        x_label: name(axes[0]),
        y_label: name(axes[1]),
        origin_m: (0.0, 0.0),
        cell_m: l0,
        columns,
        rows,
        cells,
    }
}

/// Centre of voxel v (first axis fastest) of a grid of n voxels from the origin.
fn voxel_centre<const D: usize>(v: usize, n: &[usize; D], spacing_m: f64) -> Vector<D> {
    let mut rest = v;
    Vector::<D>::from_fn(|a, _| {
        let k = rest % n[a];
        rest /= n[a];
        (k as f64 + 0.5) * spacing_m
    })
}

/// Contact points of the bed: between touching rocks (across the gap: the middle of it), and
/// of rocks with the floor and the walls.
fn contacts<const D: usize>(bed: &Bed<D>, form: &Vector<D>, gap_m: f64) -> Vec<Vector<D>> {
    // A nanometre, as the bed's test of overlap.
    let touching = 1e-9;
    let mut points = Vec::new();
    for (i, a) in bed.rocks.iter().enumerate() {
        for b in &bed.rocks[..i] {
            let d = b.centre_m - a.centre_m;
            let dist = d.norm();
            if dist <= a.radius_m + b.radius_m + gap_m + touching {
                let along = a.radius_m + 0.5 * (dist - a.radius_m - b.radius_m);
                points.push(a.centre_m + d * (along / dist));
            }
        }
        for axis in 0..D {
            let clearance = 0.5 * gap_m + touching;
            let low = a.centre_m[axis] - a.radius_m;
            let mut at = a.centre_m;
            if low <= clearance {
                at[axis] = 0.0;
                points.push(at);
            }
            if axis < D - 1 && form[axis] - a.centre_m[axis] - a.radius_m <= clearance {
                at[axis] = form[axis];
                points.push(at);
            }
        }
    }
    points
}

//! Rodding (mixing) test, seed 000 section 5 and Fig. 5 (2D): concrete fills a form in three
//! layers whose particles carry a layer tag for the whole run; a rod (a rigid body of wall
//! particles on a keyframe path) is pushed down into the concrete and pulled out, stroke after
//! stroke, at positions across the form. The metrics say how far the layers have mixed: for
//! each height band of the concrete, the share of its particles that came from each layer.
use super::geometry::container::add_walls;
use super::geometry::lattice::{cells, centre, for_each_index};
use super::geometry::shapes::{Shape, fill_walls};
use super::{Experiment, Manifest, Scene, StagedFigure, StagedFigures};
use crate::manifest::validate::{Checker, NON_NEGATIVE, POSITIVE, fmt_num};
use crate::mps::{ParticleKind, Particles, Path, RigidBody, Vector};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// Layer tags, from the floor up (tag 0 is never used by this test).
pub const LAYER_TAGS: [u16; 3] = [1, 2, 3];
/// Names of the layers and of the height bands, from the floor up.
pub const LAYERS: [&str; 3] = ["bottom", "middle", "top"];

/// `scene: {kind: rodding}`. The form's inner lower-left corner is the origin; x across the
/// form, y up.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Rodding {
    /// Inner width of the form, in metres.
    pub form_width_m: f64,
    /// Inner height of the form's walls, in metres.
    pub form_height_m: f64,
    /// Height of the concrete at t = 0 (three layers of a third each), in metres.
    pub fill_height_m: f64,
    /// Width of the rod, in metres.
    pub rod_width_m: f64,
    /// Length of the rod, in metres.
    pub rod_length_m: f64,
    /// Where the rod's axis goes down, from the form's left inner wall, in metres: stroke k
    /// uses entry k modulo the list's length.
    pub stroke_positions_m: Vec<f64>,
    /// Number of strokes (down and up).
    pub strokes: u32,
    /// Height of the rod's tip above the floor at the bottom of a stroke, in metres.
    pub stroke_bottom_m: f64,
    /// Height of the rod's tip above `fill_height_m` between strokes, in metres.
    pub rod_clearance_m: f64,
    /// Speed of the rod, down, up and across, in m/s.
    pub rod_speed_m_s: f64,
    /// When the first stroke starts, in seconds (the concrete settles before).
    pub start_s: f64,
    /// Navier slip length of the rod's steel, in metres (0: no slip at its surface; large:
    /// free slip). Absent: the rod's particles carry its velocity, as every wall does.
    pub rod_slip_length_m: Option<f64>,
}

impl Default for Rodding {
    fn default() -> Self {
        Self {
            form_width_m: 0.15,
            form_height_m: 0.4,
            fill_height_m: 0.3,
            rod_width_m: 0.016,
            rod_length_m: 0.4,
            stroke_positions_m: vec![0.0375, 0.075, 0.1125],
            strokes: 12,
            stroke_bottom_m: 0.02,
            rod_clearance_m: 0.02,
            rod_speed_m_s: 0.25,
            start_s: 0.2,
            rod_slip_length_m: None,
        }
    }
}

/// SHARE_NAMES[band][layer]: the metric of the share of band `band` (bottom, middle, top)
/// that came from layer `layer`.
pub const SHARE_NAMES: [[&str; 3]; 3] = [
    [
        "band_bottom_from_bottom_share",
        "band_bottom_from_middle_share",
        "band_bottom_from_top_share",
    ],
    [
        "band_middle_from_bottom_share",
        "band_middle_from_middle_share",
        "band_middle_from_top_share",
    ],
    [
        "band_top_from_bottom_share",
        "band_top_from_middle_share",
        "band_top_from_top_share",
    ],
];

impl Rodding {
    /// Height of the rod's tip between strokes.
    fn tip_up_m(&self) -> f64 {
        self.fill_height_m + self.rod_clearance_m
    }

    /// Keyframes of the rod's tip centre (x, height): it waits above the first position until
    /// `start_s`, then each stroke goes down to `stroke_bottom_m` and back up, and the rod
    /// moves across to the next position, all at `rod_speed_m_s`. Also the end time of each
    /// stroke (when the tip is back up).
    fn keyframes(&self) -> (Vec<f64>, Vec<[f64; 2]>, Vec<f64>) {
        let up = self.tip_up_m();
        let travel_s = (up - self.stroke_bottom_m) / self.rod_speed_m_s;
        let position = |k: usize| self.stroke_positions_m[k % self.stroke_positions_m.len()];
        let mut t = self.start_s;
        let mut times = vec![t];
        let mut points = vec![[position(0), up]];
        let mut stroke_ends = Vec::new();
        for k in 0..self.strokes as usize {
            let x = position(k);
            if k > 0 {
                let across_m = (x - position(k - 1)).abs();
                if across_m > 0.0 {
                    t += across_m / self.rod_speed_m_s;
                    times.push(t);
                    points.push([x, up]);
                }
            }
            t += travel_s;
            times.push(t);
            points.push([x, self.stroke_bottom_m]);
            t += travel_s;
            times.push(t);
            points.push([x, up]);
            stroke_ends.push(t);
        }
        (times, points, stroke_ends)
    }

    /// Strokes finished by `time_s`.
    pub fn strokes_done(&self, time_s: f64) -> usize {
        let (_, _, ends) = self.keyframes();
        ends.iter().filter(|&&end| end <= time_s).count()
    }

    /// When the last stroke ends (the rod is back up).
    pub fn last_stroke_end_s(&self) -> f64 {
        let (_, _, ends) = self.keyframes();
        ends.last().copied().unwrap_or(self.start_s)
    }
}

impl Experiment for Rodding {
    fn check(&self, m: &Manifest, c: &mut Checker) {
        if m.dimension != 2 {
            c.fail(
                "dimension",
                format!(
                    "scene.kind rodding is the 2D test of seed 000: dimension must be 2, got {}",
                    m.dimension
                ),
            );
        }
        let dims = [
            ("scene.form_width_m", self.form_width_m),
            ("scene.form_height_m", self.form_height_m),
            ("scene.fill_height_m", self.fill_height_m),
            ("scene.rod_width_m", self.rod_width_m),
            ("scene.rod_length_m", self.rod_length_m),
            ("scene.stroke_bottom_m", self.stroke_bottom_m),
            ("scene.rod_clearance_m", self.rod_clearance_m),
            ("scene.rod_speed_m_s", self.rod_speed_m_s),
        ];
        let mut ok = true;
        for (field, x) in dims {
            ok &= c.real(field, x, POSITIVE);
        }
        ok &= c.real("scene.start_s", self.start_s, NON_NEGATIVE);
        if let Some(b) = self.rod_slip_length_m {
            ok &= c.real("scene.rod_slip_length_m", b, NON_NEGATIVE);
        }
        ok &= c.int_at_least("scene.strokes", u64::from(self.strokes), 1);
        if self.stroke_positions_m.is_empty() {
            c.fail(
                "scene.stroke_positions_m",
                "needs at least one position".into(),
            );
            ok = false;
        }
        if self.stroke_positions_m.len() > 1000 || self.strokes > 10_000 {
            c.fail(
                "scene.strokes",
                "at most 10000 strokes over at most 1000 positions".into(),
            );
            ok = false;
        }
        for (k, &x) in self.stroke_positions_m.iter().enumerate() {
            ok &= c.real(&format!("scene.stroke_positions_m.{k}"), x, POSITIVE);
        }
        if !ok || !super::spacing_ok(m) {
            return;
        }
        let l0 = m.spacing_m;
        if self.fill_height_m > self.form_height_m {
            c.fail(
                "scene.fill_height_m",
                format!(
                    "must be <= scene.form_height_m ({}), got {}",
                    fmt_num(self.form_height_m),
                    fmt_num(self.fill_height_m)
                ),
            );
        }
        if self.stroke_bottom_m < l0 || self.stroke_bottom_m >= self.fill_height_m {
            c.fail(
                "scene.stroke_bottom_m",
                format!(
                    "the rod's lowest tip must stay at least one spacing ({}) above the floor and below scene.fill_height_m ({}), got {}",
                    fmt_num(l0),
                    fmt_num(self.fill_height_m),
                    fmt_num(self.stroke_bottom_m)
                ),
            );
        }
        // The rod goes down inside the form: its sides at least one spacing from the walls.
        let half = 0.5 * self.rod_width_m;
        for (k, &x) in self.stroke_positions_m.iter().enumerate() {
            if x - half < l0 || x + half > self.form_width_m - l0 {
                c.fail(
                    &format!("scene.stroke_positions_m.{k}"),
                    format!(
                        "the rod ({} wide) must stay one spacing inside the form's walls: between {} and {}, got {}",
                        fmt_num(self.rod_width_m),
                        fmt_num(l0 + half),
                        fmt_num(self.form_width_m - l0 - half),
                        fmt_num(x)
                    ),
                );
            }
        }
        if self.rod_length_m < self.tip_up_m() - self.stroke_bottom_m {
            c.fail(
                "scene.rod_length_m",
                format!(
                    "must be at least the stroke ({} m), so the rod's top never enters the concrete, got {}",
                    fmt_num(self.tip_up_m() - self.stroke_bottom_m),
                    fmt_num(self.rod_length_m)
                ),
            );
        }
        // A step may carry the rod at most courant l0 (as for boundaries.bodies).
        let limit = m.time.courant * l0 / m.time.dt_max_s;
        if self.rod_speed_m_s > limit {
            c.fail(
                "scene.rod_speed_m_s",
                format!(
                    "must be <= time.courant * spacing_m / time.dt_max_s = {limit:.4} m/s (a step would carry the rod past the fluid), got {}",
                    fmt_num(self.rod_speed_m_s)
                ),
            );
        }
        c.lattice_lengths(
            &[
                ("scene.form_width_m", self.form_width_m),
                ("scene.form_height_m", self.form_height_m),
                ("scene.fill_height_m", self.fill_height_m),
                ("scene.rod_width_m", self.rod_width_m),
                ("scene.rod_length_m", self.rod_length_m),
            ],
            l0,
        );
        // Once all else holds, the path the scene builds must be one the core accepts: a
        // start far beyond the strokes' durations (1e308 s) leaves keyframe times that no
        // longer increase.
        if c.is_clean() {
            let (times, points, _) = self.keyframes();
            let offsets: Vec<Vector<2>> = points
                .iter()
                .map(|p| Vector::<2>::new(p[0] - points[0][0], p[1] - points[0][1]))
                .collect();
            if let Err(message) = Path::from_keyframes(&times, &offsets, None) {
                c.fail(
                    "scene.start_s",
                    format!("the rod's path cannot be built from these values: {message}"),
                );
            }
        }
    }

    fn build<const D: usize>(&self, m: &Manifest) -> Scene<D> {
        let l0 = m.spacing_m;
        let form: [i64; D] = std::array::from_fn(|a| {
            if a == D - 1 {
                cells(self.form_height_m, l0)
            } else {
                cells(self.form_width_m, l0)
            }
        });
        let fill: [i64; D] = std::array::from_fn(|a| {
            if a == D - 1 {
                cells(self.fill_height_m, l0)
            } else {
                form[a]
            }
        });
        // Three layers of equal height in cell rows (the top one takes a remainder).
        let rows = fill[D - 1];
        let mut particles = Particles::<D>::default();
        for_each_index([0; D], fill, |idx| {
            let layer = ((idx[D - 1] * 3) / rows).clamp(0, 2) as usize;
            particles.push_tagged(centre(idx, l0), ParticleKind::Fluid, LAYER_TAGS[layer]);
        });
        add_walls(
            &mut particles,
            &[([0; D], form)],
            form[D - 1],
            l0,
            m.mps.wall_layers,
            m.mps.dummy_layers,
        );
        // The rod: a box whose tip centre follows the keyframes (offsets from t = 0).
        let (times, points, _) = self.keyframes();
        let start = points[0];
        let half = 0.5 * self.rod_width_m;
        let solid = Shape::<D>::Box {
            min_m: Vector::<D>::from_fn(|a, _| [start[0] - half, start[1]][a.min(1)]),
            max_m: Vector::<D>::from_fn(|a, _| {
                [start[0] + half, start[1] + self.rod_length_m][a.min(1)]
            }),
        };
        let offsets: Vec<Vector<D>> = points
            .iter()
            .map(|p| Vector::<D>::from_fn(|a, _| p[a.min(1)] - start[a.min(1)]))
            .collect();
        let path = Path::from_keyframes(&times, &offsets, None).expect("checked keyframes");
        let first = particles.len();
        if let Some(scan) = solid.cell_bounds(l0) {
            fill_walls(
                &mut particles,
                &solid,
                scan,
                l0,
                m.mps.wall_layers_of_solids(),
                m.mps.dummy_layers,
            );
        }
        let bodies = vec![RigidBody {
            first,
            end: particles.len(),
            path,
            slip_length_m: self.rod_slip_length_m,
        }];
        let (domain_min_m, domain_max_m) = self.domain::<D>(m);
        Scene {
            particles,
            domain_min_m,
            domain_max_m,
            bodies,
            inlets: Vec::new(),
            gravity_tilt_rad: 0.0,
            periodic_x: None,
            symmetry: Default::default(),
        }
    }

    /// Room above the form for the rod; fluid beyond one form size is a ghost.
    fn domain<const D: usize>(&self, _m: &Manifest) -> (Vector<D>, Vector<D>) {
        let top_m = (self.tip_up_m() + self.rod_length_m).max(self.form_height_m);
        let min = Vector::<D>::from_fn(|a, _| {
            -if a == D - 1 {
                self.form_height_m
            } else {
                self.form_width_m
            }
        });
        let max = Vector::<D>::from_fn(|a, _| {
            if a == D - 1 {
                2.0 * top_m
            } else {
                2.0 * self.form_width_m
            }
        });
        (min, max)
    }

    fn metric_names(&self, _m: &Manifest) -> Vec<&'static str> {
        let mut names = vec!["strokes_done", "mixing_index", "fluid_on_rod_count"];
        names.extend(SHARE_NAMES.iter().flatten());
        names
    }

    fn metrics<const D: usize>(
        &self,
        _m: &Manifest,
        particles: &Particles<D>,
        time_s: f64,
        out: &mut BTreeMap<String, f64>,
    ) {
        let (shares, in_form) = band_shares(particles, self.tip_up_m());
        let on_rod = particles.fluid_count() - in_form;
        out.insert("fluid_on_rod_count".into(), on_rod as f64);
        for (band, row) in shares.iter().enumerate() {
            for (layer, share) in row.iter().enumerate() {
                out.insert(SHARE_NAMES[band][layer].into(), *share);
            }
        }
        out.insert("mixing_index".into(), mixing_index(&shares));
        out.insert("strokes_done".into(), self.strokes_done(time_s) as f64);
    }

    fn trend_metric(&self) -> &'static str {
        "mixing_index"
    }

    /// Seed 000 Fig. 5 as ours: each band's share of each layer after every stroke (a
    /// complete mix is a third each), the mixing index, and the concrete above the form's
    /// fill (what rode up with the rod) per stroke.
    fn staged_figures(&self) -> Option<StagedFigures> {
        let figures = LAYERS
            .iter()
            .enumerate()
            .rev()
            .map(|(band, name)| StagedFigure {
                title: format!("{name} band: share of each layer"),
                y_label: "share of the band's particles",
                curves: LAYERS
                    .iter()
                    .enumerate()
                    .map(|(layer, from)| (SHARE_NAMES[band][layer], format!("from the {from} layer")))
                    .collect(),
                reference: Some((1.0 / 3.0, "a third (complete mix)".into())),
            })
            .chain(std::iter::once(StagedFigure {
                title: "mixing index".into(),
                y_label: "mixing index (0 layers intact, 1 complete mix)",
                curves: vec![("mixing_index", "mixing index".into())],
                reference: None,
            }))
            .collect();
        let mut table = vec!["mixing_index", "fluid_on_rod_count"];
        table.extend(SHARE_NAMES.iter().flatten());
        Some(StagedFigures {
            stage_metric: "strokes_done",
            stage_label: "strokes done",
            figures,
            table,
        })
    }
}

/// shares[band][layer]: the fluid particles at most `max_height_m` high (the concrete in the
/// form; above it, fluid clings to the rod) ranked by height (ties by x, then index) and cut
/// into three bands of equal count, bottom to top; in each, the share from each layer. Bands
/// by rank, not by fixed heights, so that a surface that moves does not empty a band. Also
/// the number of fluid particles in those bands.
pub fn band_shares<const D: usize>(
    p: &Particles<D>,
    max_height_m: f64,
) -> ([[f64; 3]; 3], usize) {
    let up = D - 1;
    let mut fluid: Vec<usize> = (0..p.len())
        .filter(|&i| p.kind[i] == ParticleKind::Fluid && p.position_m[i][up] <= max_height_m)
        .collect();
    fluid.sort_by(|&i, &j| {
        let (a, b) = (&p.position_m[i], &p.position_m[j]);
        a[up]
            .total_cmp(&b[up])
            .then(a[0].total_cmp(&b[0]))
            .then(i.cmp(&j))
    });
    let n = fluid.len();
    let mut counts = [[0usize; 3]; 3];
    let mut sizes = [0usize; 3];
    for (rank, &i) in fluid.iter().enumerate() {
        let band = (rank * 3) / n.max(1);
        sizes[band] += 1;
        if let Some(layer) = LAYER_TAGS.iter().position(|&t| t == p.tag[i]) {
            counts[band][layer] += 1;
        }
    }
    let shares = std::array::from_fn(|band| {
        std::array::from_fn(|layer| {
            if sizes[band] == 0 {
                0.0
            } else {
                counts[band][layer] as f64 / sizes[band] as f64
            }
        })
    });
    (shares, n)
}

/// 1 - sqrt(S / S0), S = sum over bands and layers of (share - 1/3)^2 and S0 = 2 its value
/// for intact layers (each band all of its own layer): 0 = layers intact, 1 = every band a
/// third of each layer.
pub fn mixing_index(shares: &[[f64; 3]; 3]) -> f64 {
    let mut s = 0.0;
    for row in shares {
        for &share in row {
            let d = share - 1.0 / 3.0;
            s += d * d;
        }
    }
    1.0 - (s / 2.0).sqrt()
}

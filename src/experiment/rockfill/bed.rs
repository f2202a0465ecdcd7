//! Rock beds by sequential gravity deposition (docs/rockfill.md, "The rock bed").
//!
//! Rocks (spheres; discs in 2D) are dropped one at a time into a rectangular form: the floor
//! at height 0, side walls at 0 and at the form's length (and width), open above. Each rock
//! falls straight down from above the bed at a horizontal position drawn from a seeded
//! generator, then rolls over the rocks already placed (which stay fixed) along the path of
//! steepest descent until it rests: on the floor, or on supports (rocks and walls) whose
//! contact forces balance its weight without pulling (Visscher & Bolsterli 1972, Nature
//! 239:504; Jodrey & Tory 1979, Simulation 32:1). A rock that comes to rest with its top above
//! the bed's height is taken away again (a miss); the bed is complete after `misses` misses in
//! a row.
//!
//! Every move is exact: between events the centre moves on a line or a circle (free fall;
//! rolling on one rock; in 3D, rolling in the groove of two supports), and each event (a new
//! contact, a support that would pull, the lowest point of the circle) is the root of
//! A + B cos(phi) + C sin(phi) or of a quadratic, solved in closed form. Only `+ - * /`,
//! `sqrt` and `libm`'s `acos` and `atan2` are used, so the same seed gives the same bed bit
//! for bit on every machine (DESIGN.md section 6).
pub use crate::rng::SplitMix64;
use crate::mps::Vector;
use std::f64::consts::PI;

/// Most events (contacts, releases) in one rock's descent before it counts as stuck (a miss).
const MAX_EVENTS: usize = 256;
/// Contact forces below this (in units of the rock's weight) count as zero.
const FORCE_TOLERANCE: f64 = 1e-12;
/// Relative tolerance of a contact (distance against the sum of the radii).
const CONTACT_TOLERANCE: f64 = 1e-12;

/// How rock diameters are drawn.
#[derive(Debug, Clone, PartialEq)]
pub enum Sizes {
    /// Classes (diameter in metres, share of the rock volume): a class is drawn with a
    /// probability proportional to its share over its rock's volume (d^3; d^2 in 2D).
    Classes(Vec<(f64, f64)>),
    /// Diameters uniform in [min, max] metres.
    Range(f64, f64),
}

impl Sizes {
    /// One diameter (one number from `rng`).
    fn draw(&self, rng: &mut SplitMix64, dimension: usize) -> f64 {
        let u = rng.unit();
        match self {
            Sizes::Range(lo, hi) => lo + u * (hi - lo),
            Sizes::Classes(classes) => {
                let weight = |&(d, share): &(f64, f64)| {
                    share / (0..dimension).fold(1.0, |v, _| v * d)
                };
                let total: f64 = classes.iter().map(weight).sum();
                let mut left = u * total;
                for class in classes {
                    left -= weight(class);
                    if left < 0.0 {
                        return class.0;
                    }
                }
                classes[classes.len() - 1].0
            }
        }
    }
    /// The largest diameter.
    pub fn largest_m(&self) -> f64 {
        match self {
            Sizes::Range(_, hi) => *hi,
            Sizes::Classes(c) => c.iter().map(|c| c.0).fold(0.0, f64::max),
        }
    }
}

/// What a bed is deposited from.
#[derive(Debug, Clone, PartialEq)]
pub struct Deposition<const D: usize> {
    /// Inner size of the form (the last axis: its height, unused: the form is open above).
    pub form_m: Vector<D>,
    /// A rock is kept only if its top lies at or below this height.
    pub height_m: f64,
    /// Clearance between rocks (half of it at the walls and the floor): 0 for touching
    /// rocks; in 2D discs need one for the voids to connect.
    pub gap_m: f64,
    pub sizes: Sizes,
    pub seed: u64,
    /// Misses in a row that end the deposition.
    pub misses: u32,
    /// Most rocks.
    pub max_rocks: usize,
}

/// What a rock rests on (or touches).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Support {
    Floor,
    /// A side wall: the wall at 0 (`high` false) or at the form's size along `axis`.
    Wall {
        axis: usize,
        high: bool,
    },
    /// An earlier rock, by index.
    Rock(usize),
}

#[derive(Debug, Clone, PartialEq)]
pub struct Rock<const D: usize> {
    pub centre_m: Vector<D>,
    pub radius_m: f64,
    /// What it came to rest on.
    pub supports: Vec<Support>,
}

#[derive(Debug, Clone, PartialEq)]
pub struct Bed<const D: usize> {
    pub rocks: Vec<Rock<D>>,
    /// Rocks dropped, kept or not.
    pub drops: u64,
    /// Drops whose descent did not end within the event limit (counted as misses).
    pub stuck: u64,
}

/// A move along a line or a circle: p(s) = origin + radius (cos s e1 + sin s e2) on a circle.
#[derive(Debug, Clone, Copy)]
enum Path<const D: usize> {
    /// Straight down: p(t) = start - t e_z.
    Fall { start: Vector<D> },
    Circle {
        origin: Vector<D>,
        radius: f64,
        e1: Vector<D>,
        e2: Vector<D>,
    },
}

/// f(s) = a + b cos s + c sin s.
#[derive(Debug, Clone, Copy)]
struct Trig {
    a: f64,
    b: f64,
    c: f64,
}

impl Trig {
    /// The first s in [0, end] at which f goes from >= 0 to < 0 (s = 0 when f(0) is within
    /// `tolerance` of 0 and falling), or None.
    fn first_descent(&self, end: f64, tolerance: f64) -> Option<f64> {
        let m = (self.b * self.b + self.c * self.c).sqrt();
        let f0 = self.a + self.b;
        // Touching now: a contact only if approaching (a support just let go, whose
        // derivative is zero up to round-off, is not met again at once).
        if f0 <= tolerance && self.c < -tolerance {
            return Some(0.0);
        }
        if m <= self.a.abs() || m == 0.0 {
            return None;
        }
        // f = a + m cos(s - beta); it falls through 0 at s - beta = alpha = acos(-a / m).
        let beta = libm::atan2(self.c, self.b);
        let alpha = libm::acos((-self.a / m).clamp(-1.0, 1.0));
        let mut s = beta + alpha;
        while s < 0.0 {
            s += 2.0 * PI;
        }
        while s >= 2.0 * PI {
            s -= 2.0 * PI;
        }
        (s <= end).then_some(s)
    }
}

impl<const D: usize> Deposition<D> {
    /// Deposits the bed.
    pub fn deposit(&self) -> Bed<D> {
        let mut rng = SplitMix64::new(self.seed);
        let mut bed = Bed {
            rocks: Vec::new(),
            drops: 0,
            stuck: 0,
        };
        let mut misses = 0;
        let half_gap = 0.5 * self.gap_m;
        while misses < self.misses && bed.rocks.len() < self.max_rocks {
            bed.drops += 1;
            let r = 0.5 * self.sizes.draw(&mut rng, D);
            // Every radius grows by half the gap: touching grown rocks leave the gap between
            // the rocks themselves, and half of it at the walls and the floor.
            let grown = r + half_gap;
            let top = bed
                .rocks
                .iter()
                .map(|k| k.centre_m[D - 1] + k.radius_m + half_gap)
                .fold(0.0, f64::max);
            let start = Vector::<D>::from_fn(|a, _| {
                if a == D - 1 {
                    top + 2.0 * grown
                } else {
                    grown + rng.unit() * (self.form_m[a] - 2.0 * grown)
                }
            });
            match self.settle(&bed.rocks, grown, start) {
                Some((centre, supports)) if centre[D - 1] + r <= self.height_m => {
                    bed.rocks.push(Rock {
                        centre_m: centre,
                        radius_m: r,
                        supports,
                    });
                    misses = 0;
                }
                Some(_) => misses += 1,
                None => {
                    bed.stuck += 1;
                    misses += 1;
                }
            }
        }
        bed
    }

    /// Constraint value at p, >= 0 where allowed: for a rock the squared distance less the
    /// squared contact distance, for a wall or the floor the distance from the plane that the
    /// centre may reach.
    fn value(&self, rocks: &[Rock<D>], r: f64, s: Support, p: &Vector<D>) -> f64 {
        match s {
            Support::Floor => p[D - 1] - r,
            Support::Wall { axis, high: false } => p[axis] - r,
            Support::Wall { axis, high: true } => self.form_m[axis] - r - p[axis],
            Support::Rock(k) => {
                let reach = r + rocks[k].radius_m + self.gap_m * 0.5;
                (p - rocks[k].centre_m).norm_squared() - reach * reach
            }
        }
    }

    /// Unit normal of a support at p, pointing to the side the centre may be on.
    fn normal(&self, rocks: &[Rock<D>], s: Support, p: &Vector<D>) -> Vector<D> {
        let unit = |axis: usize, sign: f64| Vector::<D>::from_fn(|a, _| if a == axis { sign } else { 0.0 });
        match s {
            Support::Floor => unit(D - 1, 1.0),
            Support::Wall { axis, high } => unit(axis, if high { -1.0 } else { 1.0 }),
            Support::Rock(k) => (p - rocks[k].centre_m).normalize(),
        }
    }

    /// Every support the centre could meet: the floor, the side walls, the rocks.
    fn candidates(&self, rocks: &[Rock<D>]) -> impl Iterator<Item = Support> {
        std::iter::once(Support::Floor)
            .chain((0..D - 1).flat_map(|axis| {
                [false, true].map(|high| Support::Wall { axis, high })
            }))
            .chain((0..rocks.len()).map(Support::Rock))
    }

    /// Contact forces of the active supports (per unit weight) for the rock at p: the
    /// least-squares balance of its weight, mu solving (N^T N) mu = N^T e_z. None when the
    /// normals are dependent.
    fn forces(&self, rocks: &[Rock<D>], active: &[Support], p: &Vector<D>) -> Option<Vec<f64>> {
        let normals: Vec<Vector<D>> = active.iter().map(|&s| self.normal(rocks, s, p)).collect();
        let k = normals.len();
        if k == 0 {
            return Some(Vec::new());
        }
        let gram = nalgebra::DMatrix::from_fn(k, k, |i, j| normals[i].dot(&normals[j]));
        let rhs = nalgebra::DVector::from_fn(k, |i, _| normals[i][D - 1]);
        let inverse = gram.try_inverse()?;
        let mu = &inverse * rhs;
        Some(mu.iter().copied().collect())
    }

    /// Settles a rock of (grown) radius r dropped at `start`: its resting centre and its
    /// supports, or None if it did not come to rest within [`MAX_EVENTS`] events.
    fn settle(&self, rocks: &[Rock<D>], r: f64, start: Vector<D>) -> Option<(Vector<D>, Vec<Support>)> {
        let mut p = start;
        let mut active: Vec<Support> = Vec::new();
        let down = Vector::<D>::from_fn(|a, _| if a == D - 1 { -1.0 } else { 0.0 });
        for _ in 0..MAX_EVENTS {
            if active.contains(&Support::Floor) {
                return Some((p, vec![Support::Floor]));
            }
            // Supports that would pull are let go, the most pulling first.
            let mu = loop {
                let mu = self.forces(rocks, &active, &p)?;
                let (worst, least) = mu
                    .iter()
                    .enumerate()
                    .fold((usize::MAX, -FORCE_TOLERANCE), |best, (i, &m)| {
                        if m < best.1 { (i, m) } else { best }
                    });
                if worst == usize::MAX || least >= -FORCE_TOLERANCE {
                    break mu;
                }
                active.remove(worst);
            };
            // Steepest descent within the active supports: the weight less what they carry.
            let mut descent = down;
            for (&s, m) in active.iter().zip(&mu) {
                descent += self.normal(rocks, s, &p) * *m;
            }
            if active.len() >= D || descent.norm() <= FORCE_TOLERANCE {
                return Some((p, active));
            }
            let path = self.path(rocks, &active, &p, &descent)?;
            let (event, next) = self.next_event(rocks, r, &active, &path)?;
            p = next;
            match event {
                Event::Contact(s) => active.push(s),
                Event::Release(i) => {
                    active.remove(i);
                }
                Event::Lowest => return Some((p, active)),
            }
        }
        None
    }

    /// The path of steepest descent from p with the active supports holding the rock.
    fn path(&self, rocks: &[Rock<D>], active: &[Support], p: &Vector<D>, descent: &Vector<D>) -> Option<Path<D>> {
        let held: Vec<usize> = active
            .iter()
            .filter_map(|s| match s {
                Support::Rock(k) => Some(*k),
                _ => None,
            })
            .collect();
        let wall = active.iter().find_map(|s| match s {
            Support::Wall { axis, high } => Some((*axis, *high)),
            _ => None,
        });
        let origin = match (held.as_slice(), wall) {
            // Walls alone carry nothing: the rock falls along them.
            ([], _) => return Some(Path::Fall { start: *p }),
            // Rolling on one rock: a great circle about its centre.
            ([k], None) => rocks[*k].centre_m,
            // On a rock and along a wall: the circle where the rock's sphere meets the plane.
            ([k], Some((axis, _))) => {
                let mut o = rocks[*k].centre_m;
                o[axis] = p[axis];
                o
            }
            // In the groove of two rocks: the circle about the line through their centres.
            ([j, k], _) => {
                let (cj, ck) = (rocks[*j].centre_m, rocks[*k].centre_m);
                let axis = (ck - cj).normalize();
                cj + axis * (p - cj).dot(&axis)
            }
            _ => return None,
        };
        let radius = (p - origin).norm();
        if radius == 0.0 {
            return None;
        }
        Some(Path::Circle {
            origin,
            radius,
            e1: (p - origin) / radius,
            e2: descent.normalize(),
        })
    }

    /// The first event along `path`, and the centre there.
    fn next_event(&self, rocks: &[Rock<D>], r: f64, active: &[Support], path: &Path<D>) -> Option<(Event, Vector<D>)> {
        match *path {
            Path::Fall { start } => {
                let mut best: Option<(f64, Support)> = None;
                for s in self.candidates(rocks).filter(|s| !active.contains(s)) {
                    let t = match s {
                        Support::Floor => Some((start[D - 1] - r).max(0.0)),
                        Support::Wall { .. } => None,
                        Support::Rock(k) => {
                            // |start - t e_z - c|^2 = reach^2: t^2 - 2 h t + q = 0.
                            let q = self.value(rocks, r, s, &start);
                            let h = start[D - 1] - rocks[k].centre_m[D - 1];
                            let reach = r + rocks[k].radius_m + 0.5 * self.gap_m;
                            if q <= CONTACT_TOLERANCE * reach * reach {
                                // Touching: met only if falling onto it (not a rock just
                                // left at its equator).
                                (h > CONTACT_TOLERANCE.sqrt() * reach).then_some(0.0)
                            } else if h > 0.0 && h * h > q {
                                Some(h - (h * h - q).sqrt())
                            } else {
                                None
                            }
                        }
                    };
                    if let Some(t) = t
                        && best.is_none_or(|b| t < b.0)
                    {
                        best = Some((t, s));
                    }
                }
                let (t, s) = best?;
                let mut p = start;
                p[D - 1] -= t;
                Some((Event::Contact(s), p))
            }
            Path::Circle {
                origin,
                radius,
                e1,
                e2,
            } => {
                let at = |s: f64| origin + (e1 * libm::cos(s) + e2 * libm::sin(s)) * radius;
                // The lowest point: height o_z + radius (e1_z cos s + e2_z sin s) is least at
                // s = atan2(-e2_z, -e1_z), in (0, pi) since the path starts downwards.
                let mut end = libm::atan2(-e2[D - 1], -e1[D - 1]);
                if end < 0.0 {
                    end += 2.0 * PI;
                }
                let mut best: (f64, Event) = (end, Event::Lowest);
                let consider = |s: Option<f64>, e: Event, best: &mut (f64, Event)| {
                    if let Some(s) = s
                        && s < best.0
                    {
                        *best = (s, e);
                    }
                };
                for s in self.candidates(rocks).filter(|s| !active.contains(s)) {
                    let (f, tolerance) = match s {
                        Support::Rock(k) => {
                            let d = origin - rocks[k].centre_m;
                            let reach = r + rocks[k].radius_m + 0.5 * self.gap_m;
                            (
                                Trig {
                                    a: d.norm_squared() + radius * radius - reach * reach,
                                    b: 2.0 * radius * e1.dot(&d),
                                    c: 2.0 * radius * e2.dot(&d),
                                },
                                CONTACT_TOLERANCE * reach * reach,
                            )
                        }
                        Support::Floor | Support::Wall { .. } => {
                            let n = self.normal(rocks, s, &origin);
                            (
                                Trig {
                                    a: self.value(rocks, r, s, &origin),
                                    b: radius * n.dot(&e1),
                                    c: radius * n.dot(&e2),
                                },
                                CONTACT_TOLERANCE * r,
                            )
                        }
                    };
                    consider(f.first_descent(best.0, tolerance), Event::Contact(s), &mut best);
                }
                // The active supports' forces along the circle: N(s)^T e_z is linear in
                // (cos s, sin s) and N^T N is constant on it (fixed contact distances and a
                // fixed plane), so each force is a + b cos s + c sin s.
                let gram_inverse = {
                    let p0 = at(0.0);
                    let normals: Vec<Vector<D>> = active.iter().map(|&s| self.normal(rocks, s, &p0)).collect();
                    let k = normals.len();
                    nalgebra::DMatrix::from_fn(k, k, |i, j| normals[i].dot(&normals[j])).try_inverse()?
                };
                let lifts: Vec<Trig> = active
                    .iter()
                    .map(|&s| match s {
                        Support::Rock(k) => {
                            let reach = r + rocks[k].radius_m + 0.5 * self.gap_m;
                            Trig {
                                a: (origin[D - 1] - rocks[k].centre_m[D - 1]) / reach,
                                b: radius * e1[D - 1] / reach,
                                c: radius * e2[D - 1] / reach,
                            }
                        }
                        _ => Trig { a: 0.0, b: 0.0, c: 0.0 },
                    })
                    .collect();
                for i in 0..active.len() {
                    let mut f = Trig { a: 0.0, b: 0.0, c: 0.0 };
                    for (j, lift) in lifts.iter().enumerate() {
                        let g = gram_inverse[(i, j)];
                        f.a += g * lift.a;
                        f.b += g * lift.b;
                        f.c += g * lift.c;
                    }
                    consider(f.first_descent(best.0, FORCE_TOLERANCE), Event::Release(i), &mut best);
                }
                Some((best.1, at(best.0)))
            }
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum Event {
    Contact(Support),
    /// The active support at this index would pull from here on.
    Release(usize),
    Lowest,
}

impl<const D: usize> Bed<D> {
    /// Checks the bed as a user would measure it, from the rocks alone: no two rocks closer
    /// than their radii and the gap less a nanometre, each inside the form (half the gap from
    /// its walls and floor) with its top at or below the bed's height, and each resting on
    /// the floor or on contacts (to a nanometre) of which at most D carry its weight with
    /// forces >= 0 (later rocks rest on it and carry nothing).
    pub fn check(&self, d: &Deposition<D>) -> Result<(), String> {
        let tol = 1e-9;
        let g = d.gap_m;
        let up = Vector::<D>::from_fn(|b, _| if b == D - 1 { 1.0 } else { 0.0 });
        for (i, a) in self.rocks.iter().enumerate() {
            let mut normals: Vec<Vector<D>> = Vec::new();
            for (j, b) in self.rocks[..i].iter().enumerate() {
                let dist = (a.centre_m - b.centre_m).norm();
                let contact = a.radius_m + b.radius_m + g;
                if dist < contact - tol {
                    return Err(format!("rocks {j} and {i} overlap by {} m", contact - dist));
                }
                if dist <= contact + tol {
                    normals.push((a.centre_m - b.centre_m) / dist);
                }
            }
            for axis in 0..D {
                let low = a.centre_m[axis] - a.radius_m - 0.5 * g;
                let high = d.form_m[axis] - a.centre_m[axis] - a.radius_m - 0.5 * g;
                if low < -tol || (axis < D - 1 && high < -tol) {
                    return Err(format!("rock {i} at {:?} is outside the form along axis {axis}", a.centre_m.as_slice()));
                }
                if low <= tol {
                    normals.push(Vector::<D>::from_fn(|b, _| if b == axis { 1.0 } else { 0.0 }));
                }
                if axis < D - 1 && high <= tol {
                    normals.push(Vector::<D>::from_fn(|b, _| if b == axis { -1.0 } else { 0.0 }));
                }
            }
            if a.centre_m[D - 1] + a.radius_m > d.height_m + tol {
                return Err(format!("rock {i} reaches above the bed's height"));
            }
            let k = normals.len();
            let carried = (1u32..(1 << k.min(16))).filter(|s| s.count_ones() as usize <= D).any(|set| {
                let chosen: Vec<&Vector<D>> = (0..k).filter(|j| set >> j & 1 == 1).map(|j| &normals[j]).collect();
                let n = nalgebra::DMatrix::from_fn(D, chosen.len(), |r, c| chosen[c][r]);
                let Some(inverse) = (n.transpose() * &n).try_inverse() else {
                    return false;
                };
                let rhs = nalgebra::DVector::from_fn(D, |r, _| up[r]);
                let mu = inverse * n.transpose() * &rhs;
                (&n * &mu - rhs).norm() < 1e-7 && mu.iter().all(|&m| m >= -1e-9)
            });
            if !carried {
                return Err(format!(
                    "rock {i} at {:?} rests on nothing that carries it ({k} contacts)",
                    a.centre_m.as_slice()
                ));
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rock<const D: usize>(centre: [f64; D], radius_m: f64) -> Rock<D> {
        Rock {
            centre_m: Vector::<D>::from_fn(|a, _| centre[a]),
            radius_m,
            supports: Vec::new(),
        }
    }

    fn form<const D: usize>(size: f64) -> Deposition<D> {
        Deposition {
            form_m: Vector::<D>::repeat(size),
            height_m: size,
            gap_m: 0.0,
            sizes: Sizes::Range(2.0, 2.0),
            seed: 7,
            misses: 50,
            max_rocks: MAX_ROCKS_TEST,
        }
    }
    const MAX_ROCKS_TEST: usize = 2000;

    #[test]
    fn trig_roots() {
        // f = 1 - 2 cos s is negative for |s| < pi/3: from s = 0 on it falls through 0 at
        // s = 5 pi / 3.
        let f = Trig { a: 1.0, b: -2.0, c: 0.0 };
        let s = f.first_descent(2.0 * PI, 1e-12).unwrap();
        assert!((s - 5.0 * PI / 3.0).abs() < 1e-12, "{s}");
        assert_eq!(f.first_descent(5.0, 1e-12), None);
        // Always positive: no root.
        assert_eq!(Trig { a: 3.0, b: 1.0, c: 1.0 }.first_descent(7.0, 1e-12), None);
        // Touching and falling now.
        assert_eq!(Trig { a: -1.0, b: 1.0, c: -0.5 }.first_descent(1.0, 1e-12), Some(0.0));
    }

    #[test]
    fn a_disc_rolls_into_the_groove_of_two() {
        let d = form::<2>(10.0);
        let rocks = [rock([1.0, 1.0], 1.0), rock([3.0, 1.0], 1.0)];
        let (p, supports) = d.settle(&rocks, 1.0, Vector::<2>::new(2.3, 9.0)).unwrap();
        assert!((p[0] - 2.0).abs() < 1e-12 && (p[1] - (1.0 + 3f64.sqrt())).abs() < 1e-12, "{p}");
        assert_eq!(supports.len(), 2);
        // Dropped beside one rock only: it rolls off it onto the floor.
        let (p, supports) = d.settle(&rocks[1..], 1.0, Vector::<2>::new(3.5, 9.0)).unwrap();
        assert_eq!(supports, vec![Support::Floor]);
        assert!((p[0] - 5.0).abs() < 1e-12 && (p[1] - 1.0).abs() < 1e-12, "{p}");
    }

    #[test]
    fn a_sphere_rests_in_the_pocket_of_three() {
        let d = form::<3>(10.0);
        let h = 3f64.sqrt();
        let rocks = [
            rock([3.0, 3.0, 1.0], 1.0),
            rock([5.0, 3.0, 1.0], 1.0),
            rock([4.0, 3.0 + h, 1.0], 1.0),
        ];
        let centroid = [4.0, 3.0 + h / 3.0];
        // Dropped off-centre onto the first rock: it rolls over one, along the groove of two
        // and into the pocket.
        let (p, supports) = d
            .settle(&rocks, 1.0, Vector::<3>::new(3.4, 3.2, 9.0))
            .unwrap();
        assert_eq!(supports.len(), 3, "{supports:?}");
        let z = 1.0 + (4.0 - 4.0 / 3.0f64).sqrt();
        assert!(
            (p[0] - centroid[0]).abs() < 1e-9 && (p[1] - centroid[1]).abs() < 1e-9 && (p[2] - z).abs() < 1e-9,
            "{p}"
        );
        // Against a wall: a rock on the floor at the wall, another dropped beside them rests
        // on the rock and the wall only if its weight presses it to the wall; here it rolls
        // away from the wall onto the floor.
        let rocks = [rock([1.0, 5.0, 1.0], 1.0)];
        let (p, supports) = d.settle(&rocks, 1.0, Vector::<3>::new(1.5, 5.2, 9.0)).unwrap();
        assert_eq!(supports, vec![Support::Floor], "{p}");
    }

    #[test]
    fn a_bed_of_one_size_packs_without_overlap_and_rests() {
        // A form ten rocks wide, filled 6 rocks deep.
        let d = Deposition::<3> {
            form_m: Vector::<3>::new(1.0, 1.0, 1.0),
            height_m: 0.6,
            gap_m: 0.0,
            sizes: Sizes::Range(0.1, 0.1),
            seed: 2026,
            misses: 200,
            max_rocks: 4096,
        };
        let bed = d.deposit();
        bed.check(&d).unwrap();
        assert_eq!(bed, d.deposit(), "the same seed gives the same bed");
        // Porosity of the core, away from the walls, the floor and the rough top: one rock
        // diameter in from every side (samples on a grid of 5 mm).
        let (lo, hi) = ([0.1, 0.1, 0.1], [0.9, 0.9, 0.45]);
        let step = 0.005;
        let (mut inside, mut all) = (0usize, 0usize);
        let mut rocks: Vec<&Rock<3>> = bed.rocks.iter().collect();
        rocks.sort_by(|a, b| a.centre_m[2].total_cmp(&b.centre_m[2]));
        let zs: Vec<f64> = rocks.iter().map(|r| r.centre_m[2]).collect();
        let count = |a: f64, b: f64| ((b - a) / step).round() as usize;
        for i in 0..count(lo[0], hi[0]) {
            for j in 0..count(lo[1], hi[1]) {
                for k in 0..count(lo[2], hi[2]) {
                    let x = Vector::<3>::new(
                        lo[0] + (i as f64 + 0.5) * step,
                        lo[1] + (j as f64 + 0.5) * step,
                        lo[2] + (k as f64 + 0.5) * step,
                    );
                    let from = zs.partition_point(|&z| z < x[2] - 0.05);
                    let to = zs.partition_point(|&z| z <= x[2] + 0.05);
                    all += 1;
                    inside += usize::from(rocks[from..to].iter().any(|r| (x - r.centre_m).norm_squared() < r.radius_m * r.radius_m));
                }
            }
        }
        let porosity = 1.0 - inside as f64 / all as f64;
        // Sequential deposition of one size packs to about 0.58 (porosity 0.42; Visscher &
        // Bolsterli 1972 found 0.582); 0.40-0.48 is what the issue asks of a bed of one size.
        assert!((0.40..=0.48).contains(&porosity), "core porosity {porosity}, {} rocks", bed.rocks.len());
        assert_eq!(bed.stuck, 0, "{} of {} drops stuck", bed.stuck, bed.drops);
    }

    #[test]
    fn a_2d_bed_keeps_its_gap() {
        let d = Deposition::<2> {
            form_m: Vector::<2>::new(0.4, 0.3),
            height_m: 0.2,
            gap_m: 0.01,
            sizes: Sizes::Classes(vec![(0.04, 0.5), (0.06, 0.5)]),
            seed: 3,
            misses: 200,
            max_rocks: 4096,
        };
        let bed = d.deposit();
        bed.check(&d).unwrap();
        assert!(bed.rocks.len() > 10, "{}", bed.rocks.len());
        let other = Deposition { seed: 4, ..d.clone() }.deposit();
        assert_ne!(bed.rocks, other.rocks, "another seed, another bed");
    }
}

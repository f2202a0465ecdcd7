//! Rigid bodies that move on time-pure paths (the slump cone, a rod, a gate).
//!
//! A body is a range of wall and dummy particles whose displacement from their initial
//! positions is a pure function of the simulated time ([`Path::offset_m`]). Nothing about
//! the motion is state: a checkpoint (positions and time) is all that a resumed run or a
//! replay needs. While moving, the body's particles carry the path velocity, so the implicit
//! viscous stage sees a moving no-slip wall.
//!
//! Only `+ - * /`, comparisons and the exact f64 remainder are used (docs/design.md section 6).
use super::particles::Vector;

/// One piece of a [`Path`]: from `start_s` on the offset moves from `start_offset_m` at
/// `velocity_m_s` until, on each axis separately, it has travelled to `end_offset_m`; then
/// that axis holds. Velocity and travel (`end_offset_m - start_offset_m`) must have the same
/// sign on each axis (a velocity pointing away from the end never moves the body).
#[derive(Debug, Clone, PartialEq)]
pub struct Segment<const D: usize> {
    pub start_s: f64,
    /// Offset at `start_s`, relative to the body's initial position.
    pub start_offset_m: Vector<D>,
    pub velocity_m_s: Vector<D>,
    /// Offset at which each axis stops.
    pub end_offset_m: Vector<D>,
}

/// Piecewise-linear motion: offset (m) of a body from its initial position as a function of
/// time. The segment that acts at time t is the last one whose `start_s <= t`; before the
/// first segment the offset is the first segment's start offset. With `repeat_s = Some(T)`
/// the whole path repeats with period T counted from the first segment's start: the offset
/// at t is the offset at `start + (t - start) % T` (f64 `%` is exact).
#[derive(Debug, Clone, PartialEq)]
pub struct Path<const D: usize> {
    /// In increasing `start_s`.
    pub segments: Vec<Segment<D>>,
    pub repeat_s: Option<f64>,
}

/// Where segment `s` has taken axis `a` at time `t_s >= s.start_s`, and whether the axis is
/// still moving: d = (t - start) v, clamped to the interval between 0 and the travel
/// T = end - start (whichever order). At the end the end offset itself is returned, so
/// consecutive keyframe segments meet exactly.
fn axis_offset<const D: usize>(s: &Segment<D>, a: usize, t_s: f64) -> (f64, bool) {
    let (start, end) = (s.start_offset_m[a], s.end_offset_m[a]);
    let travel = end - start;
    let d = (t_s - s.start_s) * s.velocity_m_s[a];
    if travel > 0.0 {
        if d >= travel {
            (end, false)
        } else if d < 0.0 {
            (start, true)
        } else {
            (start + d, true)
        }
    } else if travel < 0.0 {
        if d <= travel {
            (end, false)
        } else if d > 0.0 {
            (start, true)
        } else {
            (start + d, true)
        }
    } else {
        (start, false)
    }
}

impl<const D: usize> Path<D> {
    /// One segment from `start_s`: move at `velocity_m_s` until `travel_m` is covered on
    /// each axis, then stay (the slump cone's lift: velocity and travel along the last axis
    /// only). On an axis the offset is exactly `clamp((t - start) v, 0, travel)`.
    pub fn lift(start_s: f64, velocity_m_s: Vector<D>, travel_m: Vector<D>) -> Self {
        Self {
            segments: vec![Segment {
                start_s,
                start_offset_m: Vector::<D>::zeros(),
                velocity_m_s,
                end_offset_m: travel_m,
            }],
            repeat_s: None,
        }
    }

    /// The path through `offsets_m[k]` at `times_s[k]`, linear in between: segment k runs
    /// from keyframe k to k + 1 at velocity (o_{k+1} - o_k) / (t_{k+1} - t_k). Before the
    /// first keyframe the body is at the first offset; after the last one it holds the last
    /// offset, or, with `repeat_s = Some(T)`, the path starts over every T seconds from the
    /// first keyframe (T >= last time - first time; between the last keyframe and the next
    /// period the body holds the last offset; at each new period it jumps to the first
    /// offset, so a closed loop ends where it starts). A single keyframe is a body at rest at
    /// that offset.
    pub fn from_keyframes(
        times_s: &[f64],
        offsets_m: &[Vector<D>],
        repeat_s: Option<f64>,
    ) -> Result<Self, String> {
        if times_s.is_empty() || times_s.len() != offsets_m.len() {
            return Err(format!(
                "a path needs as many offsets as times, and at least one ({} times, {} offsets)",
                times_s.len(),
                offsets_m.len()
            ));
        }
        if !times_s.iter().all(|t| t.is_finite())
            || !offsets_m.iter().all(|o| o.iter().all(|x| x.is_finite()))
        {
            return Err("path keyframe times and offsets must be finite".into());
        }
        if let Some(k) = (1..times_s.len()).find(|&k| times_s[k] <= times_s[k - 1]) {
            return Err(format!(
                "path keyframe times must increase strictly: {} s follows {} s",
                times_s[k],
                times_s[k - 1]
            ));
        }
        let span_s = times_s[times_s.len() - 1] - times_s[0];
        if let Some(period) = repeat_s
            && !(period.is_finite() && period > 0.0 && period >= span_s)
        {
            return Err(format!(
                "path repeat period {period} s must be positive and at least the keyframes' span {span_s} s"
            ));
        }
        let segments = if times_s.len() == 1 {
            vec![Segment {
                start_s: times_s[0],
                start_offset_m: offsets_m[0],
                velocity_m_s: Vector::<D>::zeros(),
                end_offset_m: offsets_m[0],
            }]
        } else {
            (0..times_s.len() - 1)
                .map(|k| Segment {
                    start_s: times_s[k],
                    start_offset_m: offsets_m[k],
                    velocity_m_s: (offsets_m[k + 1] - offsets_m[k]) / (times_s[k + 1] - times_s[k]),
                    end_offset_m: offsets_m[k + 1],
                })
                .collect()
        };
        Ok(Self { segments, repeat_s })
    }

    /// The segment acting at `t_s` (after folding by the period), if any has started.
    fn active(&self, t_s: f64) -> Option<(&Segment<D>, f64)> {
        let first = self.segments.first()?;
        let t = match self.repeat_s {
            Some(period) if t_s >= first.start_s => first.start_s + (t_s - first.start_s) % period,
            _ => t_s,
        };
        self.segments
            .iter()
            .rev()
            .find(|s| s.start_s <= t)
            .map(|s| (s, t))
    }

    /// Offset from the initial position at time `t_s` (m).
    pub fn offset_m(&self, t_s: f64) -> Vector<D> {
        match self.active(t_s) {
            Some((s, t)) => Vector::<D>::from_fn(|a, _| axis_offset(s, a, t).0),
            None => self
                .segments
                .first()
                .map_or_else(Vector::<D>::zeros, |s| s.start_offset_m),
        }
    }

    /// Velocity during the step that starts at `t_s` (m/s): the acting segment's velocity on
    /// each axis that has not yet reached its end offset, 0 on the others, before the first
    /// segment and for an empty path.
    pub fn velocity_m_s(&self, t_s: f64) -> Vector<D> {
        match self.active(t_s) {
            Some((s, t)) => Vector::<D>::from_fn(|a, _| {
                if axis_offset(s, a, t).1 {
                    s.velocity_m_s[a]
                } else {
                    0.0
                }
            }),
            None => Vector::<D>::zeros(),
        }
    }
}

/// Wall and dummy particles `first..end` that move rigidly along `path` (ranges of
/// different bodies must not overlap). Each step sets their velocity to the path velocity
/// at the step's start time t and, after the predictor, moves them by
/// `offset(t + dt) - offset(t)`: so their positions stay the initial ones plus the path
/// offset (up to the round-off of the sums), and the solver needs no memory of the motion.
#[derive(Debug, Clone, PartialEq)]
pub struct RigidBody<const D: usize> {
    pub first: usize,
    pub end: usize,
    pub path: Path<D>,
    /// Navier slip length of the body's surface, in metres (see
    /// [`crate::mps::viscosity::SlipWall`]); None: its particles carry the path velocity as
    /// every wall does.
    pub slip_length_m: Option<f64>,
}

//! One stage's search: bracketing the measured value, then narrowing the bracket.

use super::record::{Evaluation, Fit, Stage};
use super::runs::Runs;
use super::{CalibrateError, Pair, Plan, Response};
use std::collections::BTreeMap;

/// The fitted values that stiffen the concrete: for these the test's
/// [`crate::experiment::SceneSpec::stiffening_response`] gives the direction of the search.
const STIFFENING_VALUES: &[&str] = &["fluid.yield_stress_pa", "fluid.plastic_viscosity_pa_s"];

/// A parameter value rounded to 4 significant digits: runs get tidy manifests, and a value
/// met again is the same run (reused, not rerun).
pub fn round4(x: f64) -> f64 {
    format!("{x:.3e}")
        .parse()
        .expect("a formatted number parses")
}

/// Where a stage's search starts: the current value; for a time metric after an earlier
/// stage, scaled by measured / simulated at that stage's best run (t ~ mu_p, the viscous time
/// scale mu_p / (rho g H)).
pub(super) fn stage_start(pair: &Pair, current: &BTreeMap<String, f64>, fit: &Fit) -> f64 {
    let value = current[&pair.parameter];
    let last_best = fit.stages.last().and_then(|s| {
        let (p, _) = s.best?;
        s.evaluations
            .iter()
            .find(|e| e.values[&s.parameter] == p)
            .and_then(|e| e.metrics.get(&pair.metric).copied())
    });
    match last_best {
        Some(t) if pair.response == Some(Response::FlowTime) && t.is_finite() && t > 0.0 => {
            round4((value * pair.measured / t).clamp(pair.bounds[0], pair.bounds[1]))
        }
        _ => value,
    }
}

/// Both runs of the stage's bracket meet every measured metric within its tolerance.
pub(super) fn bracket_runs_meet_all(plan: &Plan, stage: &Stage) -> bool {
    let Some(b) = stage.bracket else {
        return false;
    };
    b.iter().all(|(p, _)| {
        stage
            .evaluations
            .iter()
            .find(|e| e.values[&stage.parameter] == *p)
            .is_some_and(|e| {
                plan.pairs.iter().all(|q| {
                    e.metrics
                        .get(&q.metric)
                        .is_some_and(|m| (m - q.measured).abs() <= q.tolerance)
                })
            })
    })
}

/// Bracket in parameter order: (parameter, metric) of the adjacent runs whose metrics lie on
/// either side of the target.
fn bracket_of(points: &[(f64, f64)], target: f64) -> Option<[(f64, f64); 2]> {
    let mut sorted: Vec<(f64, f64)> = points.iter().copied().filter(|p| p.1.is_finite()).collect();
    sorted.sort_by(|a, b| a.0.total_cmp(&b.0));
    sorted
        .windows(2)
        .find(|w| (w[0].1 - target) * (w[1].1 - target) <= 0.0)
        .map(|w| [w[0], w[1]])
}

/// The secant estimate in log-log space inside the bracket (geometric midpoint if the two
/// metrics are equal or not positive).
fn secant(b: [(f64, f64); 2], target: f64) -> f64 {
    let [(p0, m0), (p1, m1)] = b;
    if m0 > 0.0 && m1 > 0.0 && m0 != m1 {
        let (lp0, lp1) = (libm::log(p0), libm::log(p1));
        let (lm0, lm1, lt) = (libm::log(m0), libm::log(m1), libm::log(target));
        let s = lp0 + (lt - lm0) * (lp1 - lp0) / (lm1 - lm0);
        libm::exp(s.clamp(lp0.min(lp1), lp0.max(lp1)))
    } else {
        libm::sqrt(p0 * p1)
    }
}

/// One stage: fits `pair.parameter` from `pair.metric` with `stage.held` fixed, in at most
/// `budget` runs.
pub(super) fn search(
    runs: &Runs,
    pair: &Pair,
    start: f64,
    budget: usize,
    stage: &mut Stage,
    on_run: &dyn Fn(&Stage, &Evaluation),
) -> Result<(), CalibrateError> {
    let [lo, hi] = pair.bounds;
    let n = runs.plan.calibration.points_per_round as usize;
    let target = pair.measured;
    let clamp = |p: f64| round4(p.clamp(lo, hi));
    let mut round = 0u32;
    // Round 0: points around the start, a factor 1.3 apart.
    let mut next: Vec<f64> = (0..n)
        .map(|i| clamp(start * libm::pow(1.3, i as f64 - (n as f64 - 1.0) / 2.0)))
        .collect();
    loop {
        next.dedup();
        let done: Vec<f64> = stage
            .evaluations
            .iter()
            .map(|e| e.values[&pair.parameter])
            .collect();
        next.retain(|p| !done.contains(p));
        next.truncate(budget.saturating_sub(stage.evaluations.len()));
        if next.is_empty() {
            break;
        }
        for e in runs.round(&stage.held, pair, &next, round)? {
            stage.evaluations.push(e);
            on_run(stage, stage.evaluations.last().expect("just pushed"));
        }
        round += 1;
        let points: Vec<(f64, f64)> = stage
            .evaluations
            .iter()
            .map(|e| (e.values[&pair.parameter], e.metrics[&pair.metric]))
            .collect();
        stage.best = points
            .iter()
            .copied()
            .filter(|p| p.1.is_finite())
            .min_by(|a, b| (a.1 - target).abs().total_cmp(&(b.1 - target).abs()));
        stage.bracket = bracket_of(&points, target);
        stage.fitted = stage
            .bracket
            .map(|b| secant(b, target))
            .or(stage.best.map(|b| b.0));
        let within = stage
            .best
            .is_some_and(|b| (b.1 - target).abs() <= pair.tolerance);
        // Done when the runs on both sides of the measured value are within the tolerance of
        // it: every value in the bracket then gives it within the tolerance (for a monotone
        // response), so the bracket is the fit's uncertainty.
        let tight = stage.bracket.is_some_and(|b| {
            (b[0].1 - target).abs() <= pair.tolerance && (b[1].1 - target).abs() <= pair.tolerance
        });
        if tight {
            stage.converged = true;
            return Ok(());
        }
        if stage.evaluations.len() >= budget {
            break;
        }
        next = match stage.bracket {
            Some(b) => narrowing_points(b, target, n),
            None => widening_points(pair, &points, n, if within { 1.1 } else { 2.0 })?,
        };
    }
    Err(CalibrateError::NotConverged(stage.evaluations.len() as u32))
}

/// Inside the bracket: the secant estimate, then bisections of the larger remaining part.
fn narrowing_points(b: [(f64, f64); 2], target: f64, n: usize) -> Vec<f64> {
    let mut cuts = vec![b[0].0, round4(secant(b, target)), b[1].0];
    while cuts.len() < n + 2 {
        let (i, _) =
            cuts.windows(2)
                .map(|w| w[1] / w[0])
                .enumerate()
                .fold(
                    (0, 0.0),
                    |best, (i, r)| if r > best.1 { (i, r) } else { best },
                );
        let mid = round4(libm::sqrt(cuts[i] * cuts[i + 1]));
        if mid <= cuts[i] || mid >= cuts[i + 1] {
            break;
        }
        cuts.insert(i + 1, mid);
    }
    cuts[1..cuts.len() - 1].to_vec()
}

/// No bracket yet: every run is on one side of the measured value. Step beyond the run
/// nearest the value, by powers of `factor` (2; 1.1 once a run is within the tolerance), in
/// the direction the response points to.
fn widening_points(
    pair: &Pair,
    points: &[(f64, f64)],
    n: usize,
    factor: f64,
) -> Result<Vec<f64>, CalibrateError> {
    let [lo, hi] = pair.bounds;
    let mut ok: Vec<(f64, f64)> = points.iter().copied().filter(|p| p.1.is_finite()).collect();
    if ok.is_empty() {
        return Err(CalibrateError::AllRunsFailed);
    }
    ok.sort_by(|a, b| a.0.total_cmp(&b.0));
    let (first, last) = (ok[0], ok[ok.len() - 1]);
    // For a stiffening value (the yield stress, the plastic viscosity) the test says which way
    // its metric goes. Runs a little apart can disagree (at 16 mm the slump spread scatters by
    // about a spacing: 0.648 m at 37 Pa, 0.657 m at 48 Pa), so they decide only for other
    // values or metrics, and only when they differ by more than the tolerance; else a metric
    // is taken to be a flow measure, which falls.
    let stiffening = STIFFENING_VALUES.contains(&pair.parameter.as_str());
    let falling = match pair.response {
        Some(r) if stiffening || (last.1 - first.1).abs() <= pair.tolerance => {
            r == Response::FlowMeasure
        }
        None if (last.1 - first.1).abs() <= pair.tolerance => true,
        _ => last.1 < first.1,
    };
    let below = first.1 < pair.measured; // every metric is below the target
    let go_down = below == falling;
    let (from, bound) = if go_down { (first, lo) } else { (last, hi) };
    if from.0 == bound {
        return Err(CalibrateError::OutOfBounds(format!(
            "the measured {} = {} is outside what fit.{} in [{lo}, {hi}] gives: at {} the run gives {}",
            pair.metric, pair.measured, pair.parameter, from.0, from.1
        )));
    }
    Ok((1..=n)
        .map(|k| {
            let f = libm::pow(factor, k as f64);
            round4(if go_down { from.0 / f } else { from.0 * f }.clamp(lo, hi))
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn narrowing_takes_the_secant_then_bisects_the_larger_part() {
        // R ~ tau^(-1/5): the log-log secant through two exact points hits the target.
        let law = |t: f64| libm::pow(t, -0.2);
        let b = [(20.0, law(20.0)), (80.0, law(80.0))];
        let s = secant(b, law(50.0));
        assert!((s - 50.0).abs() < 1e-9, "{s}");
        let pts = narrowing_points(b, law(50.0), 2);
        assert_eq!(pts.len(), 2);
        assert_eq!(pts[1], 50.0);
        // The larger part in log terms is [20, 50]: its geometric midpoint 31.62.
        assert_eq!(pts[0], round4(libm::sqrt(20.0 * 50.0)));
    }

    #[test]
    fn the_bracket_is_the_adjacent_pair_around_the_target() {
        let pts = [(10.0, 0.8), (40.0, 0.6), (20.0, 0.7), (80.0, 0.5)];
        assert_eq!(bracket_of(&pts, 0.65), Some([(20.0, 0.7), (40.0, 0.6)]));
        assert_eq!(bracket_of(&pts, 0.9), None);
    }

    #[test]
    fn rounding_keeps_four_significant_digits() {
        assert_eq!(round4(47.26789), 47.27);
        assert_eq!(round4(0.0123456), 0.01235);
    }
}

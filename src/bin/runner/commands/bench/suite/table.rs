//! The suite's Markdown: a header line, the case table and the scaling table. Cells are text
//! made here; numbers are written plainly (no `k`/`M` suffixes) so that the tables can be
//! read back by a script or a test.

use super::child::BenchReport;

/// One row of the case table.
#[derive(Debug, Clone)]
pub struct CaseRow {
    pub name: String,
    pub command: String,
    pub particles: String,
    pub steps: String,
    pub wall_s: String,
    pub rate: String,
    pub time_to_result_s: String,
    pub outcome: String,
    pub stages: String,
    pub peak_mib: String,
}

/// One row of the scaling table; `report` is `None` when the run gave no report.
#[derive(Debug, Clone)]
pub struct ScalePoint {
    pub spacing_m: f64,
    pub report: Option<BenchReport>,
    pub peak_kib: Option<u64>,
    /// `completed`, or why not.
    pub outcome: String,
}

pub const NA: &str = "n/a";

pub fn case_table(rows: &[CaseRow]) -> String {
    let mut out = String::from(
        "| case | command | particles | steps | wall s | particle-steps/s | time to result s | outcome | largest stages | peak MiB |\n\
         |---|---|---:|---:|---:|---:|---:|---|---|---:|\n",
    );
    for r in rows {
        let cells = [
            r.name.clone(),
            format!("`{}`", r.command),
            r.particles.clone(),
            r.steps.clone(),
            r.wall_s.clone(),
            r.rate.clone(),
            r.time_to_result_s.clone(),
            r.outcome.clone(),
            r.stages.clone(),
            r.peak_mib.clone(),
        ];
        out += &row(&cells);
    }
    out
}

/// The scaling table, then the least-squares line of peak memory against particles (the
/// ratio in the table also holds the process's fixed memory, which dominates small runs).
pub fn scaling_table(command: &str, points: &[ScalePoint]) -> String {
    let mut out = format!(
        "Scaling: `{command}` for each spacing\n\n\
         | spacing m | particles | steps | wall s | particle-steps/s | peak MiB | KiB per particle | outcome |\n\
         |---:|---:|---:|---:|---:|---:|---:|---|\n"
    );
    for p in points {
        out += &row(&scale_cells(p));
    }
    if let Some((slope, fixed)) = memory_line(points) {
        out += &format!(
            "\nPeak memory against particles (least squares): {slope:.2} KiB per particle + {:.1} MiB\n",
            fixed / 1024.0
        );
    }
    out
}

fn scale_cells(p: &ScalePoint) -> Vec<String> {
    let spacing = p.spacing_m.to_string();
    let Some(r) = &p.report else {
        let mut cells = vec![spacing];
        cells.extend(std::iter::repeat_n(NA.to_string(), 6));
        cells.push(p.outcome.clone());
        return cells;
    };
    vec![
        spacing,
        r.particles.to_string(),
        r.steps.to_string(),
        format!("{:.3}", r.wall_s),
        format!("{:.0}", r.particle_steps_per_s),
        mib(p.peak_kib),
        p.peak_kib
            .filter(|_| r.particles > 0.0)
            .map_or(NA.into(), |k| format!("{:.2}", k as f64 / r.particles)),
        p.outcome.clone(),
    ]
}

/// Slope (KiB per particle) and intercept (KiB) of peak memory against particles, over the
/// points that have both; `None` for fewer than two distinct sizes.
fn memory_line(points: &[ScalePoint]) -> Option<(f64, f64)> {
    let xy: Vec<(f64, f64)> = points
        .iter()
        .filter_map(|p| Some((p.report.as_ref()?.particles, p.peak_kib? as f64)))
        .collect();
    let n = xy.len() as f64;
    let (mx, my) = (
        xy.iter().map(|p| p.0).sum::<f64>() / n,
        xy.iter().map(|p| p.1).sum::<f64>() / n,
    );
    let sxx: f64 = xy.iter().map(|p| (p.0 - mx) * (p.0 - mx)).sum();
    let sxy: f64 = xy.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum();
    (xy.len() >= 2 && sxx > 0.0).then(|| (sxy / sxx, my - sxy / sxx * mx))
}

/// Peak memory in MiB, one decimal.
pub fn mib(kib: Option<u64>) -> String {
    kib.map_or(NA.into(), |k| format!("{:.1}", k as f64 / 1024.0))
}

/// The three largest stages by share, short names: `PPE solve 50.1 % (13.7 it/step), ...`
/// (the iteration counts kept: they say why a solve is slow).
pub fn largest_stages(stages: &[(String, f64)]) -> String {
    let mut sorted: Vec<&(String, f64)> = stages.iter().collect();
    sorted.sort_by(|a, b| b.1.total_cmp(&a.1));
    let parts: Vec<String> = sorted
        .iter()
        .take(3)
        .map(|(name, share)| {
            let (short, detail) = match name.split_once(" (") {
                Some((s, d)) => (s, d.trim_end_matches(')')),
                None => (name.as_str(), ""),
            };
            let its = detail.rsplit(", ").next().unwrap_or("");
            match its.strip_prefix("CG ").filter(|t| t.ends_with("it/step")) {
                Some(its) => format!("{short} {share:.1} % ({its})"),
                None => format!("{short} {share:.1} %"),
            }
        })
        .collect();
    if parts.is_empty() {
        NA.into()
    } else {
        parts.join(", ")
    }
}

fn row(cells: &[String]) -> String {
    let escaped: Vec<String> = cells.iter().map(|c| c.replace('|', "\\|")).collect();
    format!("| {} |\n", escaped.join(" | "))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn largest_stages_keep_iteration_counts() {
        let stages = vec![
            ("kernel pairs (lists cut to radii)".to_string(), 16.0),
            ("PPE solve (CG 13.7 it/step)".to_string(), 50.0),
            (
                "viscosity (strain, assembly, CG 2.9 it/step)".to_string(),
                11.0,
            ),
            ("recording and output".to_string(), 1.0),
        ];
        assert_eq!(
            largest_stages(&stages),
            "PPE solve 50.0 % (13.7 it/step), kernel pairs 16.0 %, viscosity 11.0 % (2.9 it/step)"
        );
    }

    #[test]
    fn memory_line_through_two_points() {
        let point = |particles: f64, kib| ScalePoint {
            spacing_m: 0.01,
            report: Some(BenchReport {
                particles,
                steps: 1.0,
                outcome: "completed".into(),
                wall_s: 1.0,
                particle_steps_per_s: 1.0,
                stages: vec![],
            }),
            peak_kib: Some(kib),
            outcome: "completed".into(),
        };
        let (slope, fixed) = memory_line(&[point(1000.0, 12_000), point(3000.0, 16_000)]).unwrap();
        assert!((slope - 2.0).abs() < 1e-12 && (fixed - 10_000.0).abs() < 1e-9);
    }
}

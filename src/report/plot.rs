//! SVG charts with `plotters` (SVG backend: text as `<text>` elements, no font needed).
//!
//! Element conventions the tests rely on: every data series of a line plot is one
//! `<polyline>` with `stroke-width="2"` (axes and ticks are 1 wide); sweep plots mark each data point with one `<circle>`; snapshot particles are
//! `<circle>`s; legend swatches are `<rect>`s.

use std::path::Path;

use plotters::prelude::*;

use super::cloud::Frame;
use super::{ReportError, Result};
use crate::experiment::{CellMap, Fill};

/// One line of a chart: the tests' profile curves are drawn as they are.
pub use crate::experiment::Curve as Series;

/// Distinct colours for series and categories (Tableau 10).
pub const PALETTE: [RGBColor; 10] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(188, 189, 34),
    RGBColor(23, 190, 207),
    RGBColor(127, 127, 127),
];

/// Wall particles.
pub const WALL_GREY: RGBColor = RGBColor(170, 170, 170);

fn write_err(path: &Path) -> impl Fn(String) -> ReportError + '_ {
    move |message| ReportError::Write {
        path: path.to_path_buf(),
        message,
    }
}

/// `[lo, hi]` padded by 5 % (or by 1 around a single value).
fn padded(lo: f64, hi: f64) -> (f64, f64) {
    if !(lo.is_finite() && hi.is_finite()) {
        return (0.0, 1.0);
    }
    let span = hi - lo;
    if span <= 0.0 {
        let d = if lo == 0.0 { 1.0 } else { lo.abs() * 0.1 };
        (lo - d, hi + d)
    } else {
        (lo - 0.05 * span, hi + 0.05 * span)
    }
}

fn bounds(points: impl Iterator<Item = (f64, f64)>) -> ((f64, f64), (f64, f64)) {
    let (mut x0, mut x1, mut y0, mut y1) = (
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
    );
    for (x, y) in points.filter(|(x, y)| x.is_finite() && y.is_finite()) {
        x0 = x0.min(x);
        x1 = x1.max(x);
        y0 = y0.min(y);
        y1 = y1.max(y);
    }
    (padded(x0, x1), padded(y0, y1))
}

/// Chart layouts: caption font size, margin, and the x and y label areas, in pixels.
const LINE_LAYOUT: [u32; 4] = [22, 15, 50, 80];
/// Drawings to scale (snapshots, cell maps).
const SCALED_LAYOUT: [u32; 4] = [20, 10, 45, 70];

type Chart<'a, DB> = ChartContext<
    'a,
    DB,
    Cartesian2d<plotters::coord::types::RangedCoordf64, plotters::coord::types::RangedCoordf64>,
>;

/// A chart on `root` over [x0, x1] x [y0, y1] with its caption and labelled axes (no grid).
fn chart<'a, DB: DrawingBackend>(
    root: &'a DrawingArea<DB, plotters::coord::Shift>,
    title: &str,
    layout: [u32; 4],
    (x0, x1): (f64, f64),
    (y0, y1): (f64, f64),
    (x_label, y_label): (&str, &str),
) -> std::result::Result<Chart<'a, DB>, DrawingAreaErrorKind<DB::ErrorType>> {
    let mut chart = ChartBuilder::on(root)
        .caption(title, ("sans-serif", layout[0]))
        .margin(layout[1])
        .x_label_area_size(layout[2])
        .y_label_area_size(layout[3])
        .build_cartesian_2d(x0..x1, y0..y1)?;
    chart
        .configure_mesh()
        .x_desc(x_label)
        .y_desc(y_label)
        .light_line_style(WHITE.mix(0.0))
        .draw()?;
    Ok(chart)
}

/// Width of the plot area of a drawing to scale `width` pixels wide, and the drawing's
/// height for [x0, x1] x [y0, y1] (the plot 150 to 1400 pixels high).
fn scaled_size(width: u32, (x0, x1): (f64, f64), (y0, y1): (f64, f64)) -> (f64, u32) {
    let plot_w = f64::from(width - 120);
    let plot_h = (plot_w * (y1 - y0) / (x1 - x0)).clamp(150.0, 1400.0);
    (plot_w, plot_h as u32 + 110)
}

/// A line chart: one `<polyline>` per series (plus one `<circle>` per point when `markers`),
/// a legend when there is more than one series or `markers` is on.
pub fn line_plot(
    path: &Path,
    title: &str,
    x_label: &str,
    y_label: &str,
    series: &[Series],
    markers: bool,
) -> Result<()> {
    let err = write_err(path);
    let e = |x: &dyn std::fmt::Display| err(x.to_string());
    let ((x0, x1), (y0, y1)) = bounds(series.iter().flat_map(|s| s.points.iter().copied()));
    let root = SVGBackend::new(path, (900, 600)).into_drawing_area();
    root.fill(&WHITE).map_err(|x| e(&x))?;
    let mut chart = chart(
        &root,
        title,
        LINE_LAYOUT,
        (x0, x1),
        (y0, y1),
        (x_label, y_label),
    )
    .map_err(|x| e(&x))?;
    for (i, s) in series.iter().enumerate() {
        let color = PALETTE[i % PALETTE.len()];
        let drawn = chart
            .draw_series(LineSeries::new(
                // A metric undefined at some points (NaN) is drawn where it is defined.
                s.points
                    .iter()
                    .copied()
                    .filter(|(x, y)| x.is_finite() && y.is_finite()),
                color.stroke_width(2),
            ))
            .map_err(|x| e(&x))?;
        drawn
            .label(s.label.clone())
            .legend(move |(x, y)| Rectangle::new([(x, y - 5), (x + 14, y + 5)], color.filled()));
        if markers {
            chart
                .draw_series(
                    s.points
                        .iter()
                        .filter(|(x, y)| x.is_finite() && y.is_finite())
                        .map(|&p| Circle::new(p, 4, color.filled())),
                )
                .map_err(|x| e(&x))?;
        }
    }
    if markers || series.len() > 1 {
        draw_legend(&mut chart).map_err(|x| e(&x))?;
    }
    root.present().map_err(|x| e(&x))?;
    Ok(())
}

/// The legend of the labelled series, top right on a translucent white box (every figure).
fn draw_legend<'a, DB: DrawingBackend + 'a, CT: CoordTranslate>(
    chart: &mut ChartContext<'a, DB, CT>,
) -> std::result::Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .position(SeriesLabelPosition::UpperRight)
        .draw()
}

/// How a field is coloured: categories (a few small integers) or a ramp over `[lo, hi]`.
#[derive(Debug, Clone, PartialEq)]
pub enum Coloring {
    Categorical(Vec<i64>),
    Ramp(f64, f64),
}

/// Categorical when every value is an integer and there are at most 10 distinct ones.
pub fn coloring(values: &[f32]) -> Coloring {
    let mut cats: Vec<i64> = Vec::new();
    for v in values {
        if v.fract() != 0.0 || !v.is_finite() {
            cats.clear();
            break;
        }
        let c = *v as i64;
        if !cats.contains(&c) {
            cats.push(c);
            if cats.len() > 10 {
                cats.clear();
                break;
            }
        }
    }
    if !cats.is_empty() {
        cats.sort();
        return Coloring::Categorical(cats);
    }
    // The ramp spans the 1st to 99th percentile, so that a few outliers (a splash, particles
    // stuck to a lifted cone) do not wash out the rest; values beyond are clamped.
    let mut finite: Vec<f64> = values
        .iter()
        .filter(|v| v.is_finite())
        .map(|v| f64::from(*v))
        .collect();
    if finite.is_empty() {
        return Coloring::Ramp(0.0, 1.0);
    }
    finite.sort_by(f64::total_cmp);
    let at = |q: f64| finite[((finite.len() - 1) as f64 * q).round() as usize];
    Coloring::Ramp(at(0.01), at(0.99))
}

/// Blue (0) to red (1).
pub fn ramp(t: f64) -> RGBColor {
    let t = if t.is_finite() {
        t.clamp(0.0, 1.0)
    } else {
        0.0
    };
    let (r, g, b) = HSLColor(0.66 * (1.0 - t), 0.85, 0.5).rgb();
    RGBColor(r, g, b)
}

/// Which plane a snapshot shows.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum View {
    /// x-y with walls (2D runs).
    Plane,
    /// x-z with walls (3D runs from the side).
    Side,
    /// x-y of the fluid alone, walls left out (3D runs from above; a plate would hide all).
    Top,
}

/// Particles of the last frame as dots, equal axis scales (see [`View`]). Walls (`kind` 1
/// or 2) are grey; the others are coloured by `field`. One `<circle>` per particle.
pub fn snapshot_plot(
    path: &Path,
    title: &str,
    frame: &Frame,
    field: &str,
    view: View,
) -> Result<()> {
    let err = write_err(path);
    let e = |x: &dyn std::fmt::Display| err(x.to_string());
    let side_view = view == View::Side;
    let vertical = if side_view { &frame.z } else { &frame.y };
    let pts: Vec<(f64, f64)> = frame
        .x
        .iter()
        .zip(vertical)
        .map(|(x, y)| (f64::from(*x), f64::from(*y)))
        .collect();
    let kind = frame.fields.get("kind");
    let is_wall = |i: usize| kind.is_some_and(|k| k[i] == 1.0 || k[i] == 2.0);
    let shown = |i: usize| view != View::Top || !is_wall(i);
    let ((x0, x1), (y0, y1)) = bounds((0..pts.len()).filter(|&i| shown(i)).map(|i| pts[i]));
    let width = 1000u32;
    let (plot_w, height) = scaled_size(width, (x0, x1), (y0, y1));

    let values = &frame.fields[field];
    let colored: Vec<f32> = (0..pts.len())
        .filter(|&i| shown(i) && (!is_wall(i) || field == "kind"))
        .map(|i| values[i])
        .collect();
    let coloring = coloring(&colored);

    // A ramp gets a colour bar in a strip on the right.
    let bar_w = if matches!(coloring, Coloring::Ramp(..)) {
        150
    } else {
        0
    };
    let full = SVGBackend::new(path, (width + bar_w, height)).into_drawing_area();
    full.fill(&WHITE).map_err(|x| e(&x))?;
    let (root, bar) = full.split_horizontally(width);
    if let Coloring::Ramp(lo, hi) = coloring {
        colour_bar(&bar, field, lo, hi, height).map_err(|x| e(&x))?;
    }
    let mut chart = chart(
        &root,
        title,
        SCALED_LAYOUT,
        (x0, x1),
        (y0, y1),
        ("x [m]", if side_view { "z [m]" } else { "y [m]" }),
    )
    .map_err(|x| e(&x))?;
    let color_of = |v: f32| -> RGBColor {
        match &coloring {
            Coloring::Categorical(cats) => {
                let i = cats.iter().position(|c| *c as f32 == v).unwrap_or(0);
                PALETTE[i % PALETTE.len()]
            }
            Coloring::Ramp(lo, hi) => ramp((f64::from(v) - lo) / (hi - lo).max(f64::MIN_POSITIVE)),
        }
    };
    let radius = ((plot_w / (x1 - x0)) * 0.004).clamp(1.0, 4.0) as i32;
    let walls: Vec<usize> = (0..pts.len())
        .filter(|&i| shown(i) && is_wall(i) && field != "kind")
        .collect();
    if !walls.is_empty() {
        chart
            .draw_series(
                walls
                    .iter()
                    .map(|&i| Circle::new(pts[i], radius, WALL_GREY.filled())),
            )
            .map_err(|x| e(&x))?
            .label("wall")
            .legend(|(x, y)| Rectangle::new([(x, y - 5), (x + 12, y + 5)], WALL_GREY.filled()));
    }
    let mut others: Vec<usize> = (0..pts.len())
        .filter(|&i| shown(i) && (!is_wall(i) || field == "kind"))
        .collect();
    if view == View::Top {
        // Seen from above: the highest particles are drawn last, on top.
        others.sort_by(|&a, &b| frame.z[a].total_cmp(&frame.z[b]));
    }
    match &coloring {
        Coloring::Categorical(cats) => {
            for (ci, cat) in cats.iter().enumerate() {
                let color = PALETTE[ci % PALETTE.len()];
                let label = category_label(field, *cat);
                chart
                    .draw_series(
                        others
                            .iter()
                            .filter(|&&i| values[i] == *cat as f32)
                            .map(|&i| Circle::new(pts[i], radius, color.filled())),
                    )
                    .map_err(|x| e(&x))?
                    .label(label)
                    .legend(move |(x, y)| {
                        Rectangle::new([(x, y - 5), (x + 12, y + 5)], color.filled())
                    });
            }
        }
        Coloring::Ramp(..) => {
            chart
                .draw_series(
                    others
                        .iter()
                        .map(|&i| Circle::new(pts[i], radius, color_of(values[i]).filled())),
                )
                .map_err(|x| e(&x))?;
        }
    }
    // A ramp of fluid only (the view from above) has no labelled series: no empty legend box.
    if !walls.is_empty() || matches!(coloring, Coloring::Categorical(_)) {
        draw_legend(&mut chart).map_err(|x| e(&x))?;
    }
    full.present().map_err(|x| e(&x))?;
    Ok(())
}

/// A vertical colour bar for the ramp over `[lo, hi]` (1st to 99th percentile; values beyond
/// are drawn in the end colours): the field and its unit on top, five ticks.
fn colour_bar<DB: DrawingBackend>(
    area: &DrawingArea<DB, plotters::coord::Shift>,
    field: &str,
    lo: f64,
    hi: f64,
    height: u32,
) -> std::result::Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    let (top, bottom) = (70i32, height as i32 - 60);
    let (x0, x1) = (15i32, 40i32);
    let steps = 100;
    let span = f64::from(bottom - top);
    for k in 0..steps {
        let t0 = f64::from(k) / f64::from(steps);
        let y_hi = bottom - (t0 * span) as i32;
        let y_lo = bottom - ((t0 + 1.0 / f64::from(steps)) * span) as i32;
        area.draw(&Rectangle::new([(x0, y_lo), (x1, y_hi)], ramp(t0).filled()))?;
    }
    area.draw(&Rectangle::new(
        [(x0, top), (x1, bottom)],
        BLACK.stroke_width(1),
    ))?;
    let unit = super::unit_of(field).map_or(String::new(), |u| format!(" [{u}]"));
    area.draw(&Text::new(
        format!("{field}{unit}"),
        (2, top - 40),
        ("sans-serif", 14),
    ))?;
    area.draw(&Text::new(
        "1st-99th percentile",
        (2, top - 22),
        ("sans-serif", 11),
    ))?;
    for k in 0..=4 {
        let t = f64::from(k) / 4.0;
        let y = bottom - (t * span) as i32;
        area.draw(&PathElement::new(vec![(x1, y), (x1 + 5, y)], BLACK))?;
        area.draw(&Text::new(
            tick_label(lo + t * (hi - lo), lo.abs().max(hi.abs())),
            (x1 + 8, y - 6),
            ("sans-serif", 12),
        ))?;
    }
    Ok(())
}

/// A colour-bar tick: four decimals where they tell the ticks apart, else scientific (a
/// tank at rest colours speeds of 1e-5 m/s, which four decimals printed as five zeros).
fn tick_label(value: f64, magnitude: f64) -> String {
    if magnitude == 0.0 || (1e-2..1e5).contains(&magnitude) {
        format!("{value:.4}")
    } else {
        format!("{value:.2e}")
    }
}

/// Legend text of category `value` of `field`.
fn category_label(field: &str, value: i64) -> String {
    match (field, value) {
        ("kind", 0) => "fluid".into(),
        ("kind", 1) => "wall".into(),
        ("kind", 2) => "dummy".into(),
        ("kind", 3) => "ghost".into(),
        ("kind", 4) => "inlet".into(),
        ("flowing", 0) => "not flowing".into(),
        ("flowing", 1) => "flowing".into(),
        (f, v) => format!("{f} = {v}"),
    }
}

/// Colours of the cells of a [`CellMap`]: concrete blue, rock grey, empty orange.
fn fill_colour(fill: Fill) -> RGBColor {
    match fill {
        Fill::Concrete => PALETTE[0],
        Fill::Rock => WALL_GREY,
        Fill::Empty => RGBColor(253, 208, 162),
    }
}

/// A section as square cells (one `<rect>` each), to scale, with a legend of the three fills.
pub fn cell_map(path: &Path, title: &str, map: &CellMap) -> Result<()> {
    let err = write_err(path);
    let e = |x: &dyn std::fmt::Display| err(x.to_string());
    let (x0, y0) = map.origin_m;
    let (x1, y1) = (
        x0 + map.columns as f64 * map.cell_m,
        y0 + map.rows as f64 * map.cell_m,
    );
    let width = 900u32;
    let (_, height) = scaled_size(width, (x0, x1), (y0, y1));
    let root = SVGBackend::new(path, (width, height)).into_drawing_area();
    root.fill(&WHITE).map_err(|x| e(&x))?;
    let mut chart = chart(
        &root,
        title,
        SCALED_LAYOUT,
        (x0, x1),
        (y0, y1),
        (map.x_label, map.y_label),
    )
    .map_err(|x| e(&x))?;
    for (fill, label) in [
        (Fill::Concrete, "concrete"),
        (Fill::Rock, "rock"),
        (Fill::Empty, "empty (void not reached, air)"),
    ] {
        let colour = fill_colour(fill);
        let cells = (0..map.cells.len())
            .filter(|&k| map.cells[k] == fill)
            .map(|k| {
                let (i, j) = (k % map.columns, k / map.columns);
                let lo = (x0 + i as f64 * map.cell_m, y0 + j as f64 * map.cell_m);
                let hi = (lo.0 + map.cell_m, lo.1 + map.cell_m);
                Rectangle::new([lo, hi], colour.filled())
            });
        chart
            .draw_series(cells)
            .map_err(|x| e(&x))?
            .label(label)
            .legend(move |(x, y)| Rectangle::new([(x, y - 5), (x + 12, y + 5)], colour.filled()));
    }
    draw_legend(&mut chart).map_err(|x| e(&x))?;
    root.present().map_err(|x| e(&x))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::tick_label;

    #[test]
    fn colour_bar_ticks_tell_small_values_apart() {
        assert_eq!(tick_label(0.5, 1.0), "0.5000");
        assert_eq!(tick_label(0.0, 0.0), "0.0000");
        // Speeds of a tank at rest: distinct labels, not 0.0000 each.
        assert_eq!(tick_label(2.3e-5, 4.6e-5), "2.30e-5");
        assert_eq!(tick_label(0.0, 4.6e-5), "0.00e0");
        assert_eq!(tick_label(2.5e6, 5e6), "2.50e6");
    }
}

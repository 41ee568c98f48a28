//! PNG figures for `eval --plots DIR` (plotters, bitmap backend, system TrueType fonts).
//!
//! [`predicted_vs_true`]: one panel per strategy with the identity line. [`fields`]: the
//! pneumatic gain g and offset b over the calibrated region. [`localization_map`]: per true
//! location, the mean detected centroid and its error. [`conductivity`]: one image (blue =
//! conductivity decrease) with ROI outlines, centroids (x) and true centres (o).
//! Coordinates in mm (CONTRACTS.md §1, y up); forces in N.

use super::metrics::Evaluator;
use crate::correct::calibration::Calibration;
use crate::segment::Contact;
use crate::segment::grid::ImageGrid;
use plotters::prelude::*;
use std::path::Path;

/// A figure could not be drawn or written.
#[derive(Debug, thiserror::Error)]
#[error("{path}: cannot draw plot: {message}")]
pub struct PlotError {
    /// The output file.
    pub path: String,
    /// What plotters reported.
    pub message: String,
}

fn err(path: &Path) -> impl Fn(&dyn std::fmt::Display) -> PlotError + '_ {
    move |e| PlotError { path: path.display().to_string(), message: e.to_string() }
}

/// Blue (t = 0) -> white (0.5) -> red (1).
fn diverging(t: f64) -> RGBColor {
    let t = if t.is_finite() { t.clamp(0.0, 1.0) } else { 0.5 };
    let lerp = |a: u8, b: u8, s: f64| (a as f64 + (b as f64 - a as f64) * s).round() as u8;
    if t < 0.5 {
        let s = t / 0.5;
        RGBColor(lerp(33, 255, s), lerp(102, 255, s), lerp(172, 255, s))
    } else {
        let s = (t - 0.5) / 0.5;
        RGBColor(lerp(255, 178, s), lerp(255, 24, s), lerp(255, 43, s))
    }
}

/// Dark blue (0) -> yellow (1), for magnitudes.
fn sequential(t: f64) -> RGBColor {
    let t = if t.is_finite() { t.clamp(0.0, 1.0) } else { 0.0 };
    let lerp = |a: f64, b: f64| (a + (b - a) * t).round() as u8;
    RGBColor(lerp(68.0, 253.0), lerp(1.0, 231.0), lerp(84.0, 37.0))
}

/// Predicted vs true force, one panel per strategy, identity line dashed.
pub fn predicted_vs_true(path: &Path, eval: &Evaluator) -> Result<(), PlotError> {
    let e = err(path);
    let n = eval.names.len().max(1);
    let cols = n.min(3);
    let rows = n.div_ceil(cols);
    let root = BitMapBackend::new(path, (360 * cols as u32, 340 * rows as u32)).into_drawing_area();
    root.fill(&WHITE).map_err(|x| e(&x))?;
    let fmax = eval
        .records
        .iter()
        .flat_map(|r| r.forces_n.iter().copied().chain([r.truth.force_n]))
        .filter(|v| v.is_finite())
        .fold(1.0_f64, f64::max)
        * 1.05;
    for (s, area) in root.split_evenly((rows, cols)).iter().enumerate().take(eval.names.len()) {
        let mut chart = ChartBuilder::on(area)
            .caption(&eval.labels[s], ("sans-serif", 16))
            .margin(8)
            .x_label_area_size(32)
            .y_label_area_size(40)
            .build_cartesian_2d(0.0..fmax, 0.0..fmax)
            .map_err(|x| e(&x))?;
        // plotters' own tick labels, but in scientific notation where the plain form runs long
        // (truth in the wrong unit: ticks of hundreds of digits drawn over each other).
        let tick = |v: &f64| {
            plotters::data::float::FloatPrettyPrinter { allow_scientific: true, min_decimal: 1, max_decimal: 5 }
                .print(*v)
        };
        chart
            .configure_mesh()
            .x_desc("true force [N]")
            .y_desc("predicted [N]")
            .x_label_formatter(&tick)
            .y_label_formatter(&tick)
            .draw()
            .map_err(|x| e(&x))?;
        chart
            .draw_series(DashedLineSeries::new([(0.0, 0.0), (fmax, fmax)], 6, 4, BLACK.stroke_width(1)))
            .map_err(|x| e(&x))?;
        chart
            .draw_series(
                eval.records.iter().map(|r| Circle::new((r.truth.force_n, r.forces_n[s]), 2, RED.mix(0.6).filled())),
            )
            .map_err(|x| e(&x))?;
    }
    root.present().map_err(|x| e(&x))
}

/// Heatmap of `value(u, v)` over the region, in mm, with its own colour range.
fn heatmap(
    area: &DrawingArea<BitMapBackend, plotters::coord::Shift>,
    cal: &Calibration,
    title: &str,
    value: impl Fn(f64, f64) -> f64,
) -> Result<(), String> {
    let r = cal.region;
    const N: usize = 48;
    let vals: Vec<f64> = (0..N * N)
        .map(|k| value(-1.0 + 2.0 * ((k % N) as f64 + 0.5) / N as f64, -1.0 + 2.0 * ((k / N) as f64 + 0.5) / N as f64))
        .collect();
    let (lo, hi) = vals.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| (a.min(v), b.max(v)));
    let span = if hi > lo { hi - lo } else { 1.0 };
    let caption = format!("{title}: {lo:.3} (dark) .. {hi:.3} (light)");
    let mut chart = ChartBuilder::on(area)
        .caption(caption, ("sans-serif", 15))
        .margin(8)
        .x_label_area_size(32)
        .y_label_area_size(40)
        .build_cartesian_2d(r.x_min_mm..r.x_max_mm, r.y_min_mm..r.y_max_mm)
        .map_err(|x| x.to_string())?;
    chart.configure_mesh().x_desc("x [mm]").y_desc("y [mm]").draw().map_err(|x| x.to_string())?;
    let (dx, dy) = ((r.x_max_mm - r.x_min_mm) / N as f64, (r.y_max_mm - r.y_min_mm) / N as f64);
    chart
        .draw_series((0..N * N).map(|k| {
            let (x0, y0) = (r.x_min_mm + (k % N) as f64 * dx, r.y_min_mm + (k / N) as f64 * dy);
            Rectangle::new([(x0, y0), (x0 + dx, y0 + dy)], sequential((vals[k] - lo) / span).filled())
        }))
        .map_err(|x| x.to_string())?;
    Ok(())
}

/// The pneumatic location-aware gain g(x, y) and offset b(x, y) side by side.
pub fn fields(path: &Path, cal: &Calibration) -> Result<(), PlotError> {
    let e = err(path);
    let root = BitMapBackend::new(path, (900, 420)).into_drawing_area();
    root.fill(&WHITE).map_err(|x| e(&x))?;
    let halves = root.split_evenly((1, 2));
    let la = cal.pneumatic.locaware;
    heatmap(&halves[0], cal, "gain g", |u, v| la.gain.at(u, v)).map_err(|x| e(&x))?;
    heatmap(&halves[1], cal, "offset b [N]", |u, v| la.offset.at(u, v)).map_err(|x| e(&x))?;
    root.present().map_err(|x| e(&x))
}

/// Per true location: mean localization error (colour, dark = small) and a line to the mean
/// detected centroid; the sensor outline is `extent_mm` = (x_min, x_max, y_min, y_max).
pub fn localization_map(path: &Path, eval: &Evaluator, extent_mm: (f64, f64, f64, f64)) -> Result<(), PlotError> {
    let e = err(path);
    // (true x, true y, sum detected x, sum detected y, sum error, count)
    let mut locs: Vec<(f64, f64, f64, f64, f64, f64)> = Vec::new();
    for r in eval.records.iter().filter(|r| r.truth_in_frame == 1) {
        let i = match locs.iter().position(|l| (l.0 - r.truth.x_mm).hypot(l.1 - r.truth.y_mm) < 1.0) {
            Some(i) => i,
            None => {
                locs.push((r.truth.x_mm, r.truth.y_mm, 0.0, 0.0, 0.0, 0.0));
                locs.len() - 1
            }
        };
        let l = &mut locs[i];
        l.2 += r.detected_mm.0;
        l.3 += r.detected_mm.1;
        l.4 += r.dist_mm;
        l.5 += 1.0;
    }
    let emax = locs.iter().map(|l| l.4 / l.5).fold(1e-9, f64::max);
    let root = BitMapBackend::new(path, (560, 560)).into_drawing_area();
    root.fill(&WHITE).map_err(|x| e(&x))?;
    let (x0, x1, y0, y1) = extent_mm;
    let mut chart = ChartBuilder::on(&root)
        .caption(format!("localization error (dark 0 .. light {emax:.1} mm)"), ("sans-serif", 16))
        .margin(10)
        .x_label_area_size(32)
        .y_label_area_size(40)
        .build_cartesian_2d(x0..x1, y0..y1)
        .map_err(|x| e(&x))?;
    chart.configure_mesh().x_desc("x [mm]").y_desc("y [mm]").draw().map_err(|x| e(&x))?;
    for l in &locs {
        let det = (l.2 / l.5, l.3 / l.5);
        chart.draw_series(LineSeries::new([(l.0, l.1), det], BLACK.stroke_width(1))).map_err(|x| e(&x))?;
        chart.draw_series([Circle::new((l.0, l.1), 6, sequential(l.4 / l.5 / emax).filled())]).map_err(|x| e(&x))?;
    }
    root.present().map_err(|x| e(&x))
}

/// A conductivity-change image with ROI outlines (black), centroids (x) and true centres (o).
/// `labels` is [`crate::Segmenter::labels`] of the same frame (may be empty: no outlines); only
/// the regions of `contacts` (by [`Contact::label`]) are outlined.
pub fn conductivity(
    path: &Path,
    image: &[f64],
    grid: &ImageGrid,
    labels: &[u32],
    contacts: &[Contact],
    truth_mm: &[(f64, f64)],
) -> Result<(), PlotError> {
    let e = err(path);
    let vmax = image.iter().filter(|v| v.is_finite()).fold(1e-12_f64, |m, v| m.max(v.abs()));
    let root = BitMapBackend::new(path, (560, 560)).into_drawing_area();
    root.fill(&WHITE).map_err(|x| e(&x))?;
    let mut chart = ChartBuilder::on(&root)
        .caption(format!("conductivity change (blue = decrease, |max| {vmax:.3})"), ("sans-serif", 16))
        .margin(10)
        .x_label_area_size(32)
        .y_label_area_size(40)
        .build_cartesian_2d(grid.x_min_mm..grid.x_max_mm, grid.y_min_mm..grid.y_max_mm)
        .map_err(|x| e(&x))?;
    chart.configure_mesh().x_desc("x [mm]").y_desc("y [mm]").draw().map_err(|x| e(&x))?;
    let (dx, dy) = (grid.dx_mm(), grid.dy_mm());
    let cell = |p: usize| {
        let (c, r) = (p % grid.width, p / grid.width);
        let (x0, y0) = (grid.x_min_mm + c as f64 * dx, grid.y_min_mm + r as f64 * dy);
        [(x0, y0), (x0 + dx, y0 + dy)]
    };
    chart
        .draw_series((0..grid.len()).map(|p| Rectangle::new(cell(p), diverging(0.5 + 0.5 * image[p] / vmax).filled())))
        .map_err(|x| e(&x))?;
    if labels.len() == grid.len() {
        // Only the regions that are contacts: a sidelobe the crosstalk pass removed, or a region
        // beyond `max_contacts`, keeps its label but was not evaluated.
        let kept = |l: u32| contacts.iter().any(|k| k.label == l);
        let boundary = |p: usize| {
            let (c, r) = (p % grid.width, p / grid.width);
            let l = labels[p];
            l != 0
                && kept(l)
                && (c == 0
                    || r == 0
                    || c + 1 == grid.width
                    || r + 1 == grid.height
                    || labels[p - 1] != l
                    || labels[p + 1] != l
                    || labels[p - grid.width] != l
                    || labels[p + grid.width] != l)
        };
        chart
            .draw_series((0..grid.len()).filter(|&p| boundary(p)).map(|p| Rectangle::new(cell(p), BLACK.filled())))
            .map_err(|x| e(&x))?;
    }
    chart
        .draw_series(contacts.iter().map(|c| Cross::new((c.x_mm, c.y_mm), 6, GREEN.stroke_width(3))))
        .map_err(|x| e(&x))?;
    chart
        .draw_series(truth_mm.iter().map(|&(x, y)| Circle::new((x, y), 7, BLACK.stroke_width(2))))
        .map_err(|x| e(&x))?;
    root.present().map_err(|x| e(&x))
}

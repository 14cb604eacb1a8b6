//! Charts as PNG: speed against accuracy (log time axis, one labelled point per method) and
//! metric-versus-level lines (robustness sweeps). Drawn with plotters into an RGB buffer
//! with an embedded font, so they look the same on every machine.

use std::path::Path;
use std::sync::Once;

use anyhow::{anyhow, ensure, Result};
use plotters::coord::types::RangedCoordf64;
use plotters::element::DashedPathElement;
use plotters::prelude::*;

use crate::util::write_bytes_atomic;

pub const CHART_SIZE: (u32, u32) = (960, 640);

pub(crate) fn register_fonts() {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| {
        // The bytes are a valid TTF shipped by the dejavu crate.
        let _ = plotters::style::register_font(
            "sans-serif",
            FontStyle::Normal,
            dejavu::sans::regular(),
        );
        let _ = plotters::style::register_font("sans-serif", FontStyle::Bold, dejavu::sans::bold());
    });
}

fn save_png(path: &Path, buf: Vec<u8>, (w, h): (u32, u32)) -> Result<()> {
    let img = image::RgbImage::from_raw(w, h, buf).ok_or_else(|| anyhow!("chart buffer size"))?;
    let mut png = Vec::new();
    img.write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)?;
    write_bytes_atomic(path, &png)
}

fn plot_err<E: std::fmt::Debug>(e: E) -> anyhow::Error {
    anyhow!("drawing chart: {e:?}")
}

type Canvas<'a> = DrawingArea<BitMapBackend<'a>, plotters::coord::Shift>;

/// A chart's caption size, where it fits.
const CAPTION_SIZE: f64 = 28.0;

/// Pixels around a chart, the caption's included.
const CHART_MARGIN: u32 = 20;

/// The font size up to `largest` at which `text` spans at most `width` pixels on `area` (a
/// long title, a panel's method name): smaller, not cut at the edges.
pub(crate) fn fitting_size<DB: DrawingBackend>(
    area: &DrawingArea<DB, plotters::coord::Shift>,
    text: &str,
    largest: f64,
    width: u32,
) -> f64 {
    let mut size = largest;
    while size > 8.0 {
        match area.estimate_text_size(text, &("sans-serif", size).into_text_style(area)) {
            Ok((w, _)) if w > width => size -= 1.0,
            _ => break,
        }
    }
    size
}

/// A caption's font: [`CAPTION_SIZE`], or smaller where the title would not fit between
/// the margins.
fn caption_font(root: &Canvas, title: &str) -> (&'static str, f64) {
    let width = root.dim_in_pixel().0 - 2 * CHART_MARGIN;
    ("sans-serif", fitting_size(root, title, CAPTION_SIZE, width))
}

/// Draws on a white CHART_SIZE canvas and saves it as PNG.
fn draw_png(path: &Path, draw: impl FnOnce(&Canvas) -> Result<()>) -> Result<()> {
    register_fonts();
    let (w, h) = CHART_SIZE;
    let mut buf = vec![255u8; (w * h * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(plot_err)?;
        draw(&root)?;
        root.present().map_err(plot_err)?;
    }
    save_png(path, buf, (w, h))
}

/// One method's point on the speed/accuracy chart.
pub struct SpeedPoint<'a> {
    pub label: &'a str,
    pub seconds: f64,
    pub score: f64,
}

/// Radius in pixels of a point's dot in the speed chart.
const DOT_RADIUS: i32 = 7;

/// Scatter of `score` (y, 0..1) against wall time (x, log scale), each point labelled.
pub fn speed_vs_accuracy(
    path: &Path,
    title: &str,
    y_label: &str,
    points: &[SpeedPoint],
) -> Result<()> {
    ensure!(!points.is_empty(), "no points to chart");
    ensure!(
        points
            .iter()
            .all(|p| p.seconds > 0.0 && p.seconds.is_finite() && p.score.is_finite()),
        "non-finite chart data"
    );
    draw_png(path, |root| {
        let tmin = points
            .iter()
            .map(|p| p.seconds)
            .fold(f64::INFINITY, f64::min);
        let tmax = points.iter().map(|p| p.seconds).fold(0.0, f64::max);
        // Room on the right for the slowest point's label (drawn rightwards from it).
        let (x0, x1) = (tmin / 2.0, tmax * 6.0);
        let mut chart = ChartBuilder::on(root)
            .caption(title, caption_font(root, title))
            .margin(CHART_MARGIN)
            .x_label_area_size(55)
            .y_label_area_size(70)
            .build_cartesian_2d((x0..x1).log_scale(), 0.0f64..1.0f64)
            .map_err(plot_err)?;
        chart
            .configure_mesh()
            .x_desc("wall time (s, log scale)")
            .y_desc(y_label)
            .axis_desc_style(("sans-serif", 20))
            .label_style(("sans-serif", 16))
            .draw()
            .map_err(plot_err)?;
        // Labels placed so far: (left, top, right) in pixels; every point's dot, which no
        // other point's label may cover.
        let mut placed: Vec<(i32, i32, i32)> = Vec::new();
        let dots: Vec<(i32, i32)> = (points.iter())
            .map(|p| chart.backend_coord(&(p.seconds, p.score)))
            .collect();
        for (i, p) in points.iter().enumerate() {
            let color = Palette99::pick(i).to_rgba();
            chart
                .draw_series(std::iter::once(Circle::new(
                    (p.seconds, p.score),
                    DOT_RADIUS,
                    color.filled(),
                )))
                .map_err(plot_err)?
                .label(format!("{} ({:.3}, {:.2} s)", p.label, p.score, p.seconds))
                .legend(move |(x, y)| Circle::new((x, y), 6, color.filled()));
            let others: Vec<(i32, i32)> = (dots.iter().enumerate())
                .filter(|&(j, _)| j != i)
                .map(|(_, &d)| d)
                .collect();
            let y = label_height(&chart, &placed, &others, p);
            let (px, py) = chart.backend_coord(&(p.seconds, y));
            placed.push((px, py, px + label_width(p.label)));
            // A label moved off its dot's line keeps to it by a leader, and takes its colour.
            if (y - p.score).abs() > 0.06 {
                let leader = [(p.seconds, p.score), (p.seconds, y)];
                (chart.draw_series(std::iter::once(PathElement::new(leader, color))))
                    .map_err(plot_err)?;
            }
            let font = ("sans-serif", 16).into_font().color(&color);
            chart
                .draw_series(std::iter::once(Text::new(
                    p.label.to_string(),
                    (p.seconds, y),
                    font,
                )))
                .map_err(plot_err)?;
        }
        draw_legend(&mut chart, SeriesLabelPosition::LowerRight)
    })
}

/// The series legend both charts draw, at `position`.
fn draw_legend<'a, DB: DrawingBackend + 'a, CT: plotters::coord::CoordTranslate>(
    chart: &mut ChartContext<'a, DB, CT>,
    position: SeriesLabelPosition,
) -> Result<()> {
    chart
        .configure_series_labels()
        .position(position)
        .background_style(WHITE.mix(0.9))
        .border_style(BLACK)
        .label_font(("sans-serif", 16))
        .draw()
        .map_err(plot_err)?;
    Ok(())
}

/// Pixel width of a label in the 16-pixel font (about half the height per character).
fn label_width(label: &str) -> i32 {
    label.chars().count() as i32 * 9
}

/// A height for `p`'s label near its point, alternately above and below and further out,
/// where it overprints no label placed before (labels are drawn rightwards from the point).
fn label_height<DB: DrawingBackend>(
    chart: &ChartContext<DB, Cartesian2d<LogCoord<f64>, RangedCoordf64>>,
    placed: &[(i32, i32, i32)],
    dots: &[(i32, i32)],
    p: &SpeedPoint,
) -> f64 {
    const LINE: f64 = 0.045;
    let candidates = (1..12).flat_map(|k| {
        let d = LINE * (k as f64) - 0.015;
        [p.score + d, p.score - d - 0.02]
    });
    let free = |y: f64| {
        let (x, top) = chart.backend_coord(&(p.seconds, y));
        let right = x + label_width(p.label);
        let r = DOT_RADIUS;
        let clear_of_dot = |&(dx, dy): &(i32, i32)| {
            dx + r <= x || dx - r >= right || dy + r <= top || dy - r >= top + 16
        };
        (placed.iter()).all(|&(l, t, r)| right <= l || x >= r || (top - t).abs() >= 18)
            && dots.iter().all(clear_of_dot)
    };
    candidates
        .filter(|y| (0.02..=0.97).contains(y))
        .find(|&y| free(y))
        .unwrap_or((p.score + 0.03).min(0.97))
}

/// One line of a metric-versus-level chart.
pub struct Line<'a> {
    pub label: &'a str,
    /// (level, value) pairs in level order.
    pub points: Vec<(f64, f64)>,
    /// (min, max) per point: the spread over several runs, drawn as a shaded band around the
    /// line; empty: no band.
    pub band: Vec<(f64, f64)>,
}

/// A reference line (a bound or a baseline the methods are read against), drawn in a
/// dash of its own ([`REFERENCE_DASHES`]).
pub struct Reference<'a> {
    pub label: &'a str,
    pub points: Vec<(f64, f64)>,
}

/// Lines of `y_label` (0..1) against `x_label`, one per method, each with its min-max band
/// where it has one, and dashed reference lines drawn over them.
pub fn lines(
    path: &Path,
    title: &str,
    x_label: &str,
    y_label: &str,
    series: &[Line],
    references: &[Reference],
) -> Result<()> {
    check_line_data(series, references)?;
    let all = || {
        series
            .iter()
            .flat_map(|s| s.points.iter())
            .chain(references.iter().flat_map(|r| r.points.iter()))
    };
    draw_png(path, |root| {
        let xmin = all().map(|p| p.0).fold(f64::INFINITY, f64::min);
        let xmax = all().map(|p| p.0).fold(f64::NEG_INFINITY, f64::max);
        let pad = ((xmax - xmin) * 0.05).max(1e-3);
        let mut chart = ChartBuilder::on(root)
            .caption(title, caption_font(root, title))
            .margin(CHART_MARGIN)
            .x_label_area_size(55)
            .y_label_area_size(70)
            .build_cartesian_2d((xmin - pad)..(xmax + pad), 0.0f64..1.0f64)
            .map_err(plot_err)?;
        chart
            .configure_mesh()
            .x_desc(x_label)
            .y_desc(y_label)
            .axis_desc_style(("sans-serif", 20))
            .label_style(("sans-serif", 16))
            .draw()
            .map_err(plot_err)?;
        // Bands first, so that no band hides a line.
        for (i, s) in series.iter().enumerate() {
            draw_band(&mut chart, s, Palette99::pick(i).to_rgba())?;
        }
        for (i, s) in series.iter().enumerate() {
            let color = Palette99::pick(i).to_rgba();
            chart
                .draw_series(LineSeries::new(
                    s.points.iter().copied(),
                    color.stroke_width(3),
                ))
                .map_err(plot_err)?
                .label(s.label)
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(3))
                });
            chart
                .draw_series(s.points.iter().map(|&p| Circle::new(p, 5, color.filled())))
                .map_err(plot_err)?;
        }
        for (i, r) in references.iter().enumerate() {
            let dash = REFERENCE_DASHES[i % REFERENCE_DASHES.len()];
            let color = RGBColor(dash.grey, dash.grey, dash.grey).to_rgba();
            let style = color.stroke_width(2);
            let (size, gap) = dash.on_chart;
            chart
                .draw_series(DashedLineSeries::new(
                    r.points.iter().copied(),
                    size,
                    gap,
                    style,
                ))
                .map_err(plot_err)?
                .label(r.label)
                .legend(move |(x, y)| {
                    let (size, gap) = dash.in_legend;
                    DashedPathElement::new(vec![(x, y), (x + 20, y)], size, gap, style)
                });
        }
        draw_legend(&mut chart, SeriesLabelPosition::LowerLeft)
    })
}

/// How a reference line is drawn: dark, apart from the methods' palette, and each in its
/// own dash (an oracle bound and a clean-label line in two greys of one dash read as one).
#[derive(Clone, Copy)]
struct Dash {
    grey: u8,
    /// (dash, gap) in pixels along the chart's line and in the legend's 20-pixel sample.
    on_chart: (i32, i32),
    in_legend: (i32, i32),
}

/// The references' dashes, in order: long dashes in black, then dots in grey.
const REFERENCE_DASHES: [Dash; 2] = [
    Dash {
        grey: 0,
        on_chart: (12, 8),
        in_legend: (7, 4),
    },
    Dash {
        grey: 90,
        on_chart: (3, 5),
        in_legend: (2, 3),
    },
];

/// Refuses chart data that would draw nothing or garbage: no points, non-finite values, or
/// a band without one (min, max) per point.
fn check_line_data(series: &[Line], references: &[Reference]) -> Result<()> {
    ensure!(
        series.iter().any(|s| !s.points.is_empty()),
        "no points to chart"
    );
    let points = series
        .iter()
        .flat_map(|s| s.points.iter())
        .chain(references.iter().flat_map(|r| r.points.iter()));
    let bands = series.iter().flat_map(|s| s.band.iter());
    ensure!(
        points.clone().all(|(x, y)| x.is_finite() && y.is_finite())
            && bands
                .clone()
                .all(|(lo, hi)| lo.is_finite() && hi.is_finite()),
        "non-finite chart data"
    );
    ensure!(
        series
            .iter()
            .all(|s| s.band.is_empty() || s.band.len() == s.points.len()),
        "a band needs one (min, max) per point"
    );
    Ok(())
}

/// The shaded min-max band of one line (nothing when it has none).
fn draw_band<DB: DrawingBackend>(
    chart: &mut ChartContext<DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>,
    line: &Line,
    color: RGBAColor,
) -> Result<()> {
    if line.band.is_empty() {
        return Ok(());
    }
    let upper = line.points.iter().zip(&line.band).map(|(p, b)| (p.0, b.1));
    let lower = line.points.iter().zip(&line.band).map(|(p, b)| (p.0, b.0));
    let outline: Vec<(f64, f64)> = upper.chain(lower.rev()).collect();
    chart
        .draw_series(std::iter::once(Polygon::new(
            outline,
            color.mix(0.18).filled(),
        )))
        .map_err(plot_err)?;
    Ok(())
}

//! Error-against-time plots on log-log axes, for the studies that draw them
//! (`compare`, `exchange_curves`): panels side by side, one line per series.

use std::path::Path;

use plotters::prelude::*;

/// One panel: a metric of every series against time.
pub struct Panel {
    /// Above the panel.
    pub title: String,
    /// The metric, on the vertical axis.
    pub y_desc: &'static str,
    /// Each series' label and points `(seconds, value)`, in time order.
    pub lines: Vec<(String, Vec<(f64, f64)>)>,
}

/// Draws `panels` side by side into the PNG `out` (600 pixels wide each),
/// labels in the TrueType `font`. Values that a log axis cannot show (zero,
/// negative, not finite) are left out.
pub fn plot(panels: &[Panel], font: &Path, out: &Path) -> Result<(), Box<dyn std::error::Error>> {
    let bytes: &'static [u8] = Box::leak(std::fs::read(font)?.into_boxed_slice());
    plotters::style::register_font("sans-serif", FontStyle::Normal, bytes)
        .map_err(|_| "not a TrueType font")?;
    let root = BitMapBackend::new(out, (600 * panels.len() as u32, 500)).into_drawing_area();
    root.fill(&WHITE)?;
    let colors = [
        BLACK,
        RED,
        GREEN,
        BLUE,
        MAGENTA,
        CYAN,
        RGBColor(255, 140, 0),
    ];
    for (area, panel) in root.split_evenly((1, panels.len())).iter().zip(panels) {
        let lines: Vec<Vec<(f64, f64)>> = panel
            .lines
            .iter()
            .map(|(_, points)| {
                let shown = |&&(t, v): &&(f64, f64)| t > 0.0 && v > 0.0 && v.is_finite();
                points.iter().filter(shown).copied().collect()
            })
            .collect();
        let all = || lines.iter().flatten();
        let range = |values: Vec<f64>| {
            values
                .into_iter()
                .fold((f64::INFINITY, 0.0f64), |(lo, hi), v| {
                    (lo.min(v), hi.max(v))
                })
        };
        let (t_lo, t_hi) = range(all().map(|p| p.0).collect());
        let (lo, hi) = range(all().map(|p| p.1).collect());
        if lo > hi {
            return Err(format!("no positive {} to plot", panel.y_desc).into());
        }
        let (x_range, y_range) = ((t_lo * 0.8, t_hi * 1.25), (lo * 0.7, hi * 1.4));
        let mut chart = ChartBuilder::on(area)
            .caption(&panel.title, ("sans-serif", 20))
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(70)
            .build_cartesian_2d(
                (x_range.0..x_range.1)
                    .log_scale()
                    .with_key_points(log_ticks(x_range.0, x_range.1)),
                (y_range.0..y_range.1)
                    .log_scale()
                    .with_key_points(log_ticks(y_range.0, y_range.1)),
            )?;
        chart
            .configure_mesh()
            .x_desc("seconds")
            .y_desc(panel.y_desc)
            .x_label_formatter(&|v| tick_label(*v))
            .y_label_formatter(&|v| tick_label(*v))
            .label_style(("sans-serif", 13))
            .draw()?;
        for ((label, _), (points, color)) in panel.lines.iter().zip(lines.iter().zip(colors)) {
            chart
                .draw_series(LineSeries::new(points.clone(), color.stroke_width(2)))?
                .label(label)
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(2))
                });
            chart.draw_series(points.iter().map(|&p| Circle::new(p, 4, color.filled())))?;
        }
        let legend = legend_position(&lines, x_range, y_range);
        chart
            .configure_series_labels()
            .position(legend)
            .label_font(("sans-serif", 13))
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .draw()?;
    }
    root.present()?;
    Ok(())
}

/// Labelled values of a log axis over `lo..hi`: 1, 2 and 5 times the powers
/// of ten inside it; every digit times them where that gives fewer than 3,
/// the powers of ten alone where it gives more than 8 (plotters labels only
/// powers of ten, so a range within one decade would have no labels).
fn log_ticks(lo: f64, hi: f64) -> Vec<f64> {
    let decades = lo.log10().floor() as i32..=hi.log10().ceil() as i32;
    let within = |mantissas: &[f64]| -> Vec<f64> {
        decades
            .clone()
            .flat_map(|e| mantissas.iter().map(move |m| m * 10f64.powi(e)))
            .filter(|v| (lo..=hi).contains(v))
            .collect()
    };
    match within(&[1.0, 2.0, 5.0]) {
        few if few.len() < 3 => within(&[1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0]),
        many if many.len() > 8 => within(&[1.0]),
        ticks => ticks,
    }
}

/// A [`log_ticks`] value (one significant digit) as text: `0.05`, `20`,
/// `2e-7`.
fn tick_label(v: f64) -> String {
    if v != 0.0 && v.abs() < 1e-3 {
        return format!("{v:.0e}");
    }
    let decimals = (-v.abs().log10().floor()).max(0.0) as usize;
    format!("{v:.decimals$}")
}

/// Where the legend hides the least of `lines` (points on log-log axes over
/// `x` and `y`): the upper right unless another corner or edge of the plot
/// has fewer line samples under a legend-sized box (a quarter of the width
/// and of the height).
fn legend_position(lines: &[Vec<(f64, f64)>], x: (f64, f64), y: (f64, f64)) -> SeriesLabelPosition {
    use SeriesLabelPosition::*;
    let unit = |v: f64, (lo, hi): (f64, f64)| (v / lo).ln() / (hi / lo).ln();
    let samples: Vec<(f64, f64)> = lines
        .iter()
        .flat_map(|line| line.windows(2))
        .flat_map(|pair| {
            let (a, b) = (
                (unit(pair[0].0, x), unit(pair[0].1, y)),
                (unit(pair[1].0, x), unit(pair[1].1, y)),
            );
            (0..=32).map(move |i| {
                let f = i as f64 / 32.0;
                (a.0 + f * (b.0 - a.0), a.1 + f * (b.1 - a.1))
            })
        })
        .collect();
    let (w, h) = (0.25, 0.25);
    let span = |at: f64, size: f64| (at * (1.0 - size), at * (1.0 - size) + size);
    [
        (UpperRight, 1.0, 1.0),
        (UpperLeft, 0.0, 1.0),
        (LowerLeft, 0.0, 0.0),
        (LowerRight, 1.0, 0.0),
        (MiddleRight, 1.0, 0.5),
        (MiddleLeft, 0.0, 0.5),
        (UpperMiddle, 0.5, 1.0),
        (LowerMiddle, 0.5, 0.0),
    ]
    .into_iter()
    .map(|(position, cx, cy)| {
        let ((x0, x1), (y0, y1)) = (span(cx, w), span(cy, h));
        let covered = samples
            .iter()
            .filter(|(sx, sy)| (x0..=x1).contains(sx) && (y0..=y1).contains(sy))
            .count();
        (covered, position)
    })
    .min_by_key(|(covered, _)| *covered)
    .map_or(UpperRight, |(_, position)| position)
}

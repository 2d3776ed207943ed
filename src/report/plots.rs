//! SVG charts of a run, drawn with plotters' SVG backend (no system fonts needed: plotters is
//! built without its `ttf` feature, so text is written as SVG `<text>` and sized by estimate).
//!
//! - `speeds.svg`: expected and actual speed over time, the action sent to the robot, and the
//!   augmented actions marked (as the paper's figures) by reason, capped ones apart;
//! - `p1.svg`: P1's margin `Ldist − Bdist` over time, each step coloured by its status;
//! - `p3.svg`: P3's spikes and dropouts per scan;
//! - `mse.svg`: the running MSE between expected and actual speed.

use super::series::Picked;
use plotters::coord::Shift;
use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;
use std::ops::Range;

/// One rendered chart.
#[derive(Debug, Clone)]
pub struct Plot {
    pub file_name: &'static str,
    pub title: &'static str,
    pub svg: String,
}

/// File names and titles of the charts, in page order.
pub const FILES: [(&str, &str); 4] = [
    ("speeds.svg", "Expected and actual speed, augmented actions"),
    ("p1.svg", "P1 braking distance: margin and status"),
    ("p3.svg", "P3 lidar: spikes and dropouts per scan"),
    ("mse.svg", "Running mean squared error of the speed"),
];

const SIZE: (u32, u32) = (960, 420);
const EXPECTED: RGBColor = RGBColor(31, 119, 180);
const ACTUAL: RGBColor = RGBColor(214, 39, 40);
const ACTION: RGBColor = RGBColor(44, 160, 44);
const AUGMENTED: RGBColor = RGBColor(0, 0, 0);
const UNKNOWN: RGBColor = RGBColor(150, 150, 150);
const DROPOUT: RGBColor = RGBColor(255, 127, 14);

/// All charts of [`FILES`], in that order.
pub fn render_all(picked: &Picked) -> Result<Vec<Plot>, String> {
    let mut plots = Vec::new();
    for (file_name, title) in FILES {
        let svg = match file_name {
            "speeds.svg" => render(title, |root| speeds(root, picked, title)),
            "p1.svg" => render(title, |root| p1(root, picked, title)),
            "p3.svg" => render(title, |root| p3(root, picked, title)),
            _ => render(title, |root| mse(root, picked, title)),
        }?;
        plots.push(Plot {
            file_name,
            title,
            svg,
        });
    }
    Ok(plots)
}

type Root<'a> = DrawingArea<SVGBackend<'a>, Shift>;
type DrawResult = Result<(), Box<dyn std::error::Error + 'static>>;

fn render(title: &str, draw: impl FnOnce(&Root<'_>) -> DrawResult) -> Result<String, String> {
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, SIZE).into_drawing_area();
        root.fill(&WHITE)
            .map_err(|e| format!("plot {title:?}: {e}"))?;
        draw(&root).map_err(|e| format!("plot {title:?}: {e}"))?;
        root.present().map_err(|e| format!("plot {title:?}: {e}"))?;
    }
    Ok(svg)
}

/// A range covering `values` with a little room, never empty.
fn span(values: impl Iterator<Item = f64>, floor_zero: bool) -> Range<f64> {
    let (mut lo, mut hi) = values
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
            (lo.min(v), hi.max(v))
        });
    if !lo.is_finite() {
        return 0.0..1.0;
    }
    if floor_zero {
        lo = lo.min(0.0);
    }
    if hi - lo < 1e-9 {
        hi = lo + 1.0;
    }
    let pad = (hi - lo) * 0.05;
    (if floor_zero && lo >= 0.0 {
        lo
    } else {
        lo - pad
    })..(hi + pad)
}

fn time_span(picked: &Picked) -> Range<f64> {
    let times = picked
        .expected_speed
        .points
        .iter()
        .chain(&picked.actual_speed.points)
        .chain(&picked.p1_margin.points)
        .chain(&picked.p3_spikes.points)
        .map(|(t, _)| *t);
    let r = span(times, true);
    0.0..r.end
}

fn legend(color: RGBColor) -> impl Fn((i32, i32)) -> PathElement<(i32, i32)> {
    move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(2))
}

type Chart<'a, 'b> = ChartContext<'a, SVGBackend<'b>, Cartesian2d<RangedCoordf64, RangedCoordf64>>;

/// A titled chart over the run's time span with the y range `ys`, axes labelled.
fn chart<'a, 'b>(
    root: &'a Root<'b>,
    picked: &Picked,
    title: &str,
    ys: Range<f64>,
    y_desc: &str,
    y_label_width: u32,
) -> Result<Chart<'a, 'b>, Box<dyn std::error::Error + 'static>> {
    let mut chart = ChartBuilder::on(root)
        .caption(title, ("sans-serif", 20))
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(y_label_width)
        .build_cartesian_2d(time_span(picked), ys)?;
    chart
        .configure_mesh()
        .x_desc("time [s]")
        .y_desc(y_desc)
        .draw()?;
    Ok(chart)
}

/// A labelled line through `points`.
fn line(
    chart: &mut Chart<'_, '_>,
    points: &[(f64, f64)],
    color: RGBColor,
    width: u32,
    label: &str,
) -> DrawResult {
    chart
        .draw_series(LineSeries::new(
            points.iter().copied(),
            color.stroke_width(width),
        ))?
        .label(label)
        .legend(legend(color));
    Ok(())
}

/// The legend box, drawn last.
fn legend_box<'a, 'b: 'a>(chart: &mut Chart<'a, 'b>) -> DrawResult {
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()?;
    Ok(())
}

/// Augmented actions of one kind: legend label, colour, (time, speed sent).
type MarkGroup = (&'static str, RGBColor, Vec<(f64, f64)>);

fn speeds(root: &Root<'_>, picked: &Picked, title: &str) -> DrawResult {
    let ys = picked
        .expected_speed
        .points
        .iter()
        .chain(&picked.actual_speed.points)
        .chain(&picked.action_speed.points)
        .map(|(_, v)| *v);
    let mut chart = chart(root, picked, title, span(ys, true), "speed [m/s]", 64)?;
    line(
        &mut chart,
        &picked.expected_speed.points,
        EXPECTED,
        2,
        "expected speed",
    )?;
    line(
        &mut chart,
        &picked.actual_speed.points,
        ACTUAL,
        2,
        "actual speed",
    )?;
    line(
        &mut chart,
        &picked.action_speed.points,
        ACTION,
        1,
        "action speed",
    )?;
    // Mark each augmented action at the speed sent (a step's action and flag share its time),
    // by why: P2's correction, P1's safe speed, both, or the cap while P1 was `unknown`.
    let reason_at = |t: f64| {
        picked
            .reason
            .points
            .iter()
            .find(|(tr, _)| *tr == t)
            .map(|(_, r)| r.as_str())
    };
    let unknown_at = |t: f64| {
        picked
            .action_p1_status
            .points
            .iter()
            .any(|(ts, s)| *ts == t && s == "unknown")
    };
    let mut groups: Vec<MarkGroup> = vec![
        ("augmented action", AUGMENTED, Vec::new()),
        ("augmented: p2", AUGMENTED, Vec::new()),
        ("augmented: p1", ACTUAL, Vec::new()),
        ("augmented: p1,p2", DROPOUT, Vec::new()),
        ("capped: P1 unknown", UNKNOWN, Vec::new()),
    ];
    for (t, _) in picked.augmented.points.iter().filter(|(_, a)| *a) {
        let Some(v) = picked
            .action_speed
            .points
            .iter()
            .find(|(ta, _)| ta == t)
            .map(|(_, v)| *v)
        else {
            continue;
        };
        let g = match reason_at(*t) {
            None => 0,
            Some(r) if r.split(',').any(|p| p == "p1") && unknown_at(*t) => 4,
            Some("p2") => 1,
            Some("p1") => 2,
            Some(_) => 3,
        };
        groups[g].2.push((*t, v));
    }
    for (label, color, marks) in groups {
        if marks.is_empty() {
            continue;
        }
        chart
            .draw_series(
                marks
                    .into_iter()
                    .map(move |p| TriangleMarker::new(p, 5, color.filled())),
            )?
            .label(label)
            .legend(move |(x, y)| TriangleMarker::new((x + 10, y), 5, color.filled()));
    }
    legend_box(&mut chart)
}

fn status_color(status: &str) -> RGBColor {
    match status {
        "ok" => ACTION,
        "violated" => ACTUAL,
        _ => UNKNOWN,
    }
}

fn p1(root: &Root<'_>, picked: &Picked, title: &str) -> DrawResult {
    let ys = picked.p1_margin.points.iter().map(|(_, v)| *v);
    let ys = span(ys.chain([0.0]), false);
    let mut chart = chart(root, picked, title, ys, "margin Ldist - Bdist [m]", 64)?;
    let end = time_span(picked).end;
    chart.draw_series(LineSeries::new(
        vec![(0.0, 0.0), (end, 0.0)],
        BLACK.mix(0.5),
    ))?;
    line(&mut chart, &picked.p1_margin.points, EXPECTED, 2, "margin")?;
    // Status at each step: on the margin curve where there is one, else on the zero line.
    for status in ["ok", "violated", "unknown"] {
        let color = status_color(status);
        let points: Vec<(f64, f64)> = picked
            .p1_status
            .points
            .iter()
            .filter(|(_, s)| s == status)
            .map(|(t, _)| {
                let y = picked
                    .p1_margin
                    .points
                    .iter()
                    .find(|(tm, _)| tm == t)
                    .map_or(0.0, |(_, m)| *m);
                (*t, y)
            })
            .collect();
        chart
            .draw_series(
                points
                    .into_iter()
                    .map(|p| Circle::new(p, 3, color.filled())),
            )?
            .label(format!("status {status}"))
            .legend(move |(x, y)| Circle::new((x + 10, y), 3, color.filled()));
    }
    legend_box(&mut chart)
}

fn p3(root: &Root<'_>, picked: &Picked, title: &str) -> DrawResult {
    let ys = picked
        .p3_spikes
        .points
        .iter()
        .chain(&picked.p3_dropouts.points)
        .map(|(_, v)| *v);
    let mut chart = chart(root, picked, title, span(ys, true), "beams per scan", 64)?;
    for (series, color, label) in [
        (&picked.p3_spikes, ACTUAL, "spikes"),
        (&picked.p3_dropouts, DROPOUT, "dropouts"),
    ] {
        line(&mut chart, &series.points, color, 1, label)?;
        chart.draw_series(
            series
                .points
                .iter()
                .map(|p| Circle::new(*p, 2, color.filled())),
        )?;
    }
    legend_box(&mut chart)
}

fn mse(root: &Root<'_>, picked: &Picked, title: &str) -> DrawResult {
    let ys = picked
        .speed_mse
        .points
        .iter()
        .chain(&picked.running_mse.points)
        .map(|(_, v)| *v);
    let mut chart = chart(
        root,
        picked,
        title,
        span(ys, true),
        "speed_mse [(m/s)^2]",
        80,
    )?;
    line(
        &mut chart,
        &picked.speed_mse.points,
        EXPECTED,
        2,
        "speed_mse (spec)",
    )?;
    let label = "MSE of the telemetry (report)";
    line(&mut chart, &picked.running_mse.points, ACTUAL, 1, label)?;
    legend_box(&mut chart)
}

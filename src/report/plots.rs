//! SVG charts of a run, drawn with plotters' SVG backend (no system fonts needed: plotters is
//! built without its `ttf` feature, so text is written as SVG `<text>` and sized by estimate).
//!
//! - `speeds.svg`: expected and actual speed over time, the action sent to the robot, and the
//!   augmented actions marked (as the paper's figures) by reason, capped ones apart;
//! - `p1.svg`: P1's margin `Ldist − Bdist` over time, each step coloured by its status;
//! - `p3.svg`: P3's spikes and dropouts per scan;
//! - `mse.svg`: the running MSE between expected and actual speed;
//! - `outputs.svg`: any spec's numeric outputs over time, one panel each, drawn by their shape
//!   ([`numeric_kind`]): a single event as a mark, integers and other counts as steps held until
//!   the next event, other numbers as a line through marks;
//! - `verdicts.svg`: any spec's verdicts (Bool and text outputs) on a timeline, one row each
//!   ([`is_event`]): a verdict with values as bands of colour, each value held until the next,
//!   an output with one value only (an event such as a `Unit` alert or a command) as marks.
//!
//! The robot's charts are drawn only when the run has their data; the robot's silent periods
//! (`robot_silent`) are shaded on them. Legends sit right of the plotting area, never on the data.

use super::outputs::{Output, Outputs};
use super::series::Picked;
use super::text::short;
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
pub const FILES: [(&str, &str); 6] = [
    ("speeds.svg", "Expected and actual speed, augmented actions"),
    ("p1.svg", "P1 braking distance: margin and status"),
    ("p3.svg", "P3 lidar: spikes and dropouts per scan"),
    ("mse.svg", "Running mean squared error of the speed"),
    ("outputs.svg", "The spec's numeric outputs"),
    ("verdicts.svg", "The spec's verdicts and events over time"),
];

const SIZE: (u32, u32) = (960, 420);
/// Room right of the plotting area for the legend.
const LEGEND_W: u32 = 200;
/// Most panels in `outputs.svg` and lines in `verdicts.svg`.
pub const MOST: usize = 12;
const EXPECTED: RGBColor = RGBColor(31, 119, 180);
const ACTUAL: RGBColor = RGBColor(214, 39, 40);
const ACTION: RGBColor = RGBColor(44, 160, 44);
const AUGMENTED: RGBColor = RGBColor(0, 0, 0);
const UNKNOWN: RGBColor = RGBColor(150, 150, 150);
const DROPOUT: RGBColor = RGBColor(255, 127, 14);
const SILENT: RGBColor = RGBColor(148, 103, 189);
/// Twelve colours told apart (Tableau 10, then black and olive), one per line of a chart with
/// at most [`MOST`] lines.
const PALETTE: [RGBColor; 12] = [
    EXPECTED,
    ACTUAL,
    ACTION,
    DROPOUT,
    SILENT,
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(127, 127, 127),
    RGBColor(188, 189, 34),
    RGBColor(23, 190, 207),
    AUGMENTED,
    RGBColor(128, 128, 0),
];

/// The charts this run has data for, in [`FILES`] order.
pub fn render_all(picked: &Picked, outputs: &Outputs) -> Result<Vec<Plot>, PlotError> {
    let has_speeds = !(picked.expected_speed.is_empty()
        && picked.actual_speed.is_empty()
        && picked.action_speed.is_empty());
    let has_p1 = !(picked.p1_status.is_empty() && picked.p1_margin.is_empty());
    let has_p3 = !(picked.p3_spikes.is_empty() && picked.p3_dropouts.is_empty());
    let has_mse = !(picked.speed_mse.is_empty() && picked.running_mse.is_empty());
    let mut plots = Vec::new();
    for (file_name, title) in FILES {
        let svg = match file_name {
            "speeds.svg" if has_speeds => render(title, SIZE, |root| speeds(root, picked, title)),
            "p1.svg" if has_p1 => render(title, SIZE, |root| p1(root, picked, title)),
            "p3.svg" if has_p3 => render(title, SIZE, |root| p3(root, picked, title)),
            "mse.svg" if has_mse => render(title, SIZE, |root| mse(root, picked, title)),
            "outputs.svg" if !outputs.numeric.is_empty() => {
                let panels = outputs.numeric.len().min(MOST) as u32;
                let size = (SIZE.0, 60 + 150 * panels);
                render(title, size, |root| numeric(root, picked, outputs, title))
            }
            "verdicts.svg" if !outputs.verdicts.is_empty() => {
                let rows = outputs.verdicts.len().min(MOST) as u32;
                let size = (SIZE.0, SIZE.1.max(120 + 40 * rows));
                render(title, size, |root| verdicts(root, picked, outputs, title))
            }
            _ => continue,
        }?;
        plots.push(Plot {
            file_name,
            title,
            svg,
        });
    }
    Ok(plots)
}

/// A chart plotters could not draw: its title and plotters' text.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("plot {title:?}: {error}")]
pub struct PlotError {
    /// The chart's title.
    pub title: String,
    /// What plotters said.
    pub error: String,
}

type Root<'a> = DrawingArea<SVGBackend<'a>, Shift>;
type DrawResult = Result<(), Box<dyn std::error::Error + 'static>>;

fn render(
    title: &str,
    size: (u32, u32),
    draw: impl FnOnce(&Root<'_>) -> DrawResult,
) -> Result<String, PlotError> {
    let failed = |e: &dyn std::fmt::Display| PlotError {
        title: title.to_string(),
        error: e.to_string(),
    };
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, size).into_drawing_area();
        root.fill(&WHITE).map_err(|e| failed(&e))?;
        draw(&root).map_err(|e| failed(&e))?;
        root.present().map_err(|e| failed(&e))?;
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
        .chain(&picked.action_speed.points)
        .chain(&picked.speed_mse.points)
        .map(|(t, _)| *t)
        .chain(picked.end_t);
    let r = span(times, true);
    0.0..r.end
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
        .margin_right(LEGEND_W)
        .x_label_area_size(40)
        .y_label_area_size(y_label_width)
        .build_cartesian_2d(time_span(picked), ys)?;
    chart
        .configure_mesh()
        .x_desc("time [s]")
        .y_desc(y_desc)
        .x_label_formatter(&|v| short(*v))
        .y_label_formatter(&|v| short(*v))
        .draw()?;
    Ok(chart)
}

/// Shade the robot's silent periods (`robot_silent`) over the whole height of `ys`.
fn silent_periods(
    chart: &mut Chart<'_, '_>,
    legend: &mut Legend,
    picked: &Picked,
    ys: &Range<f64>,
) -> DrawResult {
    let Some(silence) = &picked.silence else {
        return Ok(());
    };
    if silence.periods.is_empty() {
        return Ok(());
    }
    let (lo, hi) = (ys.start, ys.end);
    chart.draw_series(
        silence
            .periods
            .iter()
            .map(|(a, b)| Rectangle::new([(*a, lo), (*b, hi)], SILENT.mix(0.2).filled())),
    )?;
    legend.push(("robot silent".to_string(), Mark::Band(SILENT)));
    Ok(())
}

/// A labelled line through `points`.
fn line(
    chart: &mut Chart<'_, '_>,
    legend: &mut Legend,
    points: &[(f64, f64)],
    color: RGBColor,
    width: u32,
    label: &str,
) -> DrawResult {
    chart.draw_series(LineSeries::new(
        points.iter().copied(),
        color.stroke_width(width),
    ))?;
    legend.push((label.to_string(), Mark::Line(color, width)));
    Ok(())
}

/// How a legend entry is drawn.
#[derive(Clone, Copy)]
enum Mark {
    Line(RGBColor, u32),
    Triangle(RGBColor),
    Circle(RGBColor),
    Band(RGBColor),
}

/// A chart's legend entries, in drawing order.
type Legend = Vec<(String, Mark)>;

/// The legend box, drawn last on `area` (a whole chart's area, in pixels) in the room right of
/// the plotting area that [`chart`] keeps free ([`LEGEND_W`]), so it never covers the data.
fn legend_box(area: &Root<'_>, legend: &Legend, top: i32) -> DrawResult {
    if legend.is_empty() {
        return Ok(());
    }
    let (width, _) = area.dim_in_pixel();
    let x0 = width as i32 - LEGEND_W as i32 + 4;
    let row = 18;
    let h = row * legend.len() as i32 + 8;
    let w = LEGEND_W as i32 - 12;
    area.draw(&Rectangle::new(
        [(x0, top), (x0 + w, top + h)],
        WHITE.filled(),
    ))?;
    area.draw(&Rectangle::new([(x0, top), (x0 + w, top + h)], BLACK))?;
    for (i, (label, mark)) in legend.iter().enumerate() {
        let y = top + 4 + row * i as i32 + row / 2;
        let (x, m) = (x0 + 6, x0 + 16);
        match *mark {
            Mark::Line(c, width) => area.draw(&PathElement::new(
                vec![(x, y), (x + 20, y)],
                c.stroke_width(width),
            ))?,
            Mark::Triangle(c) => area.draw(&TriangleMarker::new((m, y), 5, c.filled()))?,
            Mark::Circle(c) => area.draw(&Circle::new((m, y), 3, c.filled()))?,
            Mark::Band(c) => area.draw(&Rectangle::new(
                [(x, y - 5), (x + 20, y + 5)],
                c.mix(0.4).filled(),
            ))?,
        }
        let text = if label.chars().count() > 24 {
            format!("{}…", label.chars().take(23).collect::<String>())
        } else {
            label.clone()
        };
        area.draw(&Text::new(
            text,
            (x0 + 32, y - 6),
            ("sans-serif", 12).into_font(),
        ))?;
    }
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
    let ys = span(ys, true);
    let mut legend = Legend::new();
    let mut chart = chart(root, picked, title, ys.clone(), "speed [m/s]", 64)?;
    silent_periods(&mut chart, &mut legend, picked, &ys)?;
    line(
        &mut chart,
        &mut legend,
        &picked.expected_speed.points,
        EXPECTED,
        2,
        "expected speed",
    )?;
    line(
        &mut chart,
        &mut legend,
        &picked.actual_speed.points,
        ACTUAL,
        2,
        "actual speed",
    )?;
    line(
        &mut chart,
        &mut legend,
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
        chart.draw_series(
            marks
                .into_iter()
                .map(move |p| TriangleMarker::new(p, 5, color.filled())),
        )?;
        legend.push((label.to_string(), Mark::Triangle(color)));
    }
    drop(chart);
    legend_box(root, &legend, 40)
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
    let mut legend = Legend::new();
    let mut chart = chart(
        root,
        picked,
        title,
        ys.clone(),
        "margin Ldist - Bdist [m]",
        64,
    )?;
    silent_periods(&mut chart, &mut legend, picked, &ys)?;
    let end = time_span(picked).end;
    chart.draw_series(LineSeries::new(
        vec![(0.0, 0.0), (end, 0.0)],
        BLACK.mix(0.5),
    ))?;
    line(
        &mut chart,
        &mut legend,
        &picked.p1_margin.points,
        EXPECTED,
        2,
        "margin",
    )?;
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
        chart.draw_series(
            points
                .into_iter()
                .map(|p| Circle::new(p, 3, color.filled())),
        )?;
        legend.push((format!("status {status}"), Mark::Circle(color)));
    }
    drop(chart);
    legend_box(root, &legend, 40)
}

fn p3(root: &Root<'_>, picked: &Picked, title: &str) -> DrawResult {
    let ys = picked
        .p3_spikes
        .points
        .iter()
        .chain(&picked.p3_dropouts.points)
        .map(|(_, v)| *v);
    let ys = span(ys, true);
    let mut legend = Legend::new();
    let mut chart = chart(root, picked, title, ys.clone(), "beams per scan", 64)?;
    silent_periods(&mut chart, &mut legend, picked, &ys)?;
    for (series, color, label) in [
        (&picked.p3_spikes, ACTUAL, "spikes"),
        (&picked.p3_dropouts, DROPOUT, "dropouts"),
    ] {
        line(&mut chart, &mut legend, &series.points, color, 1, label)?;
        chart.draw_series(
            series
                .points
                .iter()
                .map(|p| Circle::new(*p, 2, color.filled())),
        )?;
    }
    drop(chart);
    legend_box(root, &legend, 40)
}

fn mse(root: &Root<'_>, picked: &Picked, title: &str) -> DrawResult {
    let ys = picked
        .speed_mse
        .points
        .iter()
        .chain(&picked.running_mse.points)
        .map(|(_, v)| *v);
    let mut legend = Legend::new();
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
        &mut legend,
        &picked.speed_mse.points,
        EXPECTED,
        2,
        "speed_mse (spec)",
    )?;
    let label = "MSE of the telemetry (report)";
    line(
        &mut chart,
        &mut legend,
        &picked.running_mse.points,
        ACTUAL,
        1,
        label,
    )?;
    drop(chart);
    legend_box(root, &legend, 40)
}

/// Any spec's numeric outputs: one panel each (at most [`MOST`]), over the run's time span.
fn numeric(root: &Root<'_>, picked: &Picked, outputs: &Outputs, title: &str) -> DrawResult {
    let root = root.titled(title, ("sans-serif", 20))?;
    let shown: Vec<_> = outputs.numeric.iter().take(MOST).collect();
    let areas = root.split_evenly((shown.len().max(1), 1));
    for (i, (area, output)) in areas.iter().zip(shown).enumerate() {
        let ys = span(output.points.iter().map(|(_, v)| *v), false);
        let mut legend = Legend::new();
        let mut chart = ChartBuilder::on(area)
            .margin(8)
            .margin_right(LEGEND_W)
            .x_label_area_size(30)
            .y_label_area_size(70)
            .build_cartesian_2d(time_span(picked), ys.clone())?;
        chart
            .configure_mesh()
            .x_desc("time [s]")
            .x_label_formatter(&|v| short(*v))
            .y_label_formatter(&|v| short(*v))
            .draw()?;
        silent_periods(&mut chart, &mut legend, picked, &ys)?;
        let color = PALETTE[i % PALETTE.len()];
        let end = time_span(picked).end;
        let radius = if output.points.len() <= 30 { 4 } else { 2 };
        match numeric_kind(output) {
            STEPS => {
                line(
                    &mut chart,
                    &mut legend,
                    &held(&output.points, end),
                    color,
                    2,
                    &output.name,
                )?;
            }
            LINE => {
                line(
                    &mut chart,
                    &mut legend,
                    &output.points,
                    color,
                    2,
                    &output.name,
                )?;
            }
            _ => legend.push((output.name.clone(), Mark::Circle(color))),
        }
        chart.draw_series(
            output
                .points
                .iter()
                .map(|p| Circle::new(*p, radius, color.filled())),
        )?;
        drop(chart);
        legend_box(area, &legend, 8)?;
    }
    Ok(())
}

/// How `numeric` draws an output: a single event as a mark.
pub const MARK: &str = "mark (a single event)";
/// Integers and other counts (whole numbers that never fall) as steps.
pub const STEPS: &str = "steps (held until the next event)";
/// Other numbers as a line through marks.
pub const LINE: &str = "line";

/// The shape of a numeric output, as `numeric` draws it: [`MARK`], [`STEPS`] or [`LINE`].
pub fn numeric_kind(o: &Output<f64>) -> &'static str {
    let whole = o.points.iter().all(|(_, v)| v.fract() == 0.0);
    let rising = o.points.windows(2).all(|w| w[0].1 <= w[1].1);
    if o.points.len() <= 1 {
        MARK
    } else if o.ints || (whole && rising) {
        STEPS
    } else {
        LINE
    }
}

/// Whether a verdict is drawn as marks: it has one value only (an event that happens, such as
/// a `Unit` alert `true` or a command), so a band of colour would say nothing.
pub fn is_event<T: PartialEq>(o: &Output<T>) -> bool {
    o.points
        .iter()
        .all(|(_, v)| Some(v) == o.points.first().map(|(_, f)| f))
}

/// `points` as steps: each value held until the next point, the last until `end`.
fn held(points: &[(f64, f64)], end: f64) -> Vec<(f64, f64)> {
    let mut out = Vec::with_capacity(points.len() * 2 + 1);
    for (i, (t, v)) in points.iter().enumerate() {
        if i > 0 {
            out.push((*t, points[i - 1].1));
        }
        out.push((*t, *v));
    }
    if let Some((t, v)) = points.last() {
        out.push((end.max(*t), *v));
    }
    out
}

/// The colour of a verdict's value: `true` red, `false` green, others in order of appearance.
fn value_color(value: &str, others: &mut Vec<String>) -> RGBColor {
    // The palette without the two colours `true` and `false` have.
    let palette = || PALETTE.iter().filter(|c| **c != ACTUAL && **c != ACTION);
    match value {
        "true" => ACTUAL,
        "false" => ACTION,
        _ => {
            let i = others.iter().position(|v| v == value).unwrap_or_else(|| {
                others.push(value.to_string());
                others.len() - 1
            });
            palette()
                .nth(i % palette().count())
                .copied()
                .unwrap_or(EXPECTED)
        }
    }
}

/// Any spec's verdicts on a timeline (at most [`MOST`] rows, the first on top): a verdict's
/// values as bands, each held until its next value (the last to the run's end); an output with
/// one value as marks at its events.
fn verdicts(root: &Root<'_>, picked: &Picked, outputs: &Outputs, title: &str) -> DrawResult {
    let rows: Vec<&Output<String>> = outputs.verdicts.iter().take(MOST).collect();
    let n = rows.len();
    let names: Vec<String> = rows
        .iter()
        .map(|o| {
            if o.name.chars().count() > 30 {
                format!("{}…", o.name.chars().take(29).collect::<String>())
            } else {
                o.name.clone()
            }
        })
        .collect();
    let widest = names.iter().map(|s| s.chars().count()).max().unwrap_or(0) as u32;
    let y_of = |i: usize| (n - 1 - i) as f64;
    let label = |v: &f64| {
        let i = v.round();
        if (v - i).abs() > 1e-6 || i < 0.0 || i as usize >= n {
            return String::new();
        }
        names.get(n - 1 - i as usize).cloned().unwrap_or_default()
    };
    let ys = -0.5..(n as f64 - 0.5);
    let span = time_span(picked);
    let end = span.end;
    let mut chart = ChartBuilder::on(root)
        .caption(title, ("sans-serif", 20))
        .margin(12)
        .margin_right(LEGEND_W)
        .x_label_area_size(40)
        .y_label_area_size((widest * 7 + 16).clamp(40, 230))
        .build_cartesian_2d(span, ys.clone())?;
    chart
        .configure_mesh()
        .disable_y_mesh()
        .y_labels(n.max(1))
        .x_desc("time [s]")
        .x_label_formatter(&|v| short(*v))
        .y_label_formatter(&label)
        .draw()?;
    let mut legend = Legend::new();
    silent_periods(&mut chart, &mut legend, picked, &ys)?;
    let mut others = Vec::new();
    for (i, o) in rows.iter().enumerate() {
        let y = y_of(i);
        if is_event(o) {
            let value = o.points.first().map_or("", |(_, v)| v.as_str());
            let color = value_color(value, &mut others);
            chart.draw_series(
                o.points
                    .iter()
                    .map(|(t, _)| TriangleMarker::new((*t, y), 7, color.filled())),
            )?;
            let entry = (format!("{value} (event)"), Mark::Triangle(color));
            if !legend.iter().any(|(l, _)| *l == entry.0) {
                legend.push(entry);
            }
            continue;
        }
        let mut bands: Vec<(f64, f64, &str)> = Vec::new();
        for (k, (t, v)) in o.points.iter().enumerate() {
            let to = o.points.get(k + 1).map_or(end.max(*t), |(u, _)| *u);
            match bands.last_mut() {
                Some(last) if last.2 == v.as_str() => last.1 = to,
                _ => bands.push((*t, to, v.as_str())),
            }
        }
        for (from, to, value) in bands {
            let color = value_color(value, &mut others);
            chart.draw_series([Rectangle::new(
                [(from, y - 0.3), (to, y + 0.3)],
                color.mix(0.7).filled(),
            )])?;
            // The change itself, visible even when the band is too short to see.
            chart.draw_series([PathElement::new(
                vec![(from, y - 0.38), (from, y + 0.38)],
                color.stroke_width(2),
            )])?;
            if !legend.iter().any(|(l, _)| l == value) {
                legend.push((value.to_string(), Mark::Band(color)));
            }
        }
    }
    legend.truncate(MOST);
    drop(chart);
    legend_box(root, &legend, 40)
}

//! The report page: a well-formed (XML-parsable) HTML5 document with the summary table, the MSE
//! and violation counts, and the SVG plots. Every number in the table also carries its full
//! precision in a `data-value` attribute, for tools and tests.

use super::data::Run;
use super::outputs::{Output, Outputs};
use super::stats::Summary;
use super::text::short;

/// Escape text for HTML/XML content and attribute values.
pub fn escape(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    for c in text.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&#39;"),
            c if c.is_control() && c != '\n' && c != '\t' => out.push('\u{FFFD}'),
            c => out.push(c),
        }
    }
    out
}

fn number_row(id: &str, label: &str, value: Option<f64>, shown: String) -> String {
    let data = value.map_or_else(String::new, |v| format!(" data-value=\"{v:e}\""));
    format!(
        "<tr><th scope=\"row\">{}</th><td id=\"{id}\"{data}>{}</td></tr>\n",
        escape(label),
        escape(&shown)
    )
}

fn count_row(id: &str, label: &str, count: usize, of: Option<usize>) -> String {
    let shown = match of {
        Some(total) => format!("{count} of {total}"),
        None => count.to_string(),
    };
    number_row(id, label, Some(count as f64), shown)
}

fn fmt_opt(value: Option<f64>) -> String {
    value.map_or_else(|| "no data".to_string(), |v| format!("{v:.6e}"))
}

/// The whole page. `plots` are `(file name, title)` of the SVGs next to the page.
pub fn page(
    source_name: &str,
    s: &Summary,
    plots: &[(&str, &str)],
    run: &Run,
    outputs: &Outputs,
) -> String {
    let mut out = String::new();
    out.push_str("<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\"/>\n");
    out.push_str(&format!(
        "<title>tessla-telegraf report: {}</title>\n",
        escape(source_name)
    ));
    out.push_str(
        "<style>body{font-family:sans-serif;max-width:1000px;margin:auto}\
         table{border-collapse:collapse}th,td{border:1px solid #999;padding:4px 8px;text-align:left}\
         img{max-width:100%}</style>\n</head>\n<body>\n",
    );
    out.push_str(&format!(
        "<h1>Run report</h1>\n<p>Source: <code>{}</code>; <span id=\"steps\" data-value=\"{}\">{} steps</span>, {} records over {} s{}.</p>\n",
        escape(source_name),
        s.steps,
        s.steps,
        s.records,
        short(s.duration_s),
        if s.skipped > 0 {
            format!(", {} lines skipped (not line protocol)", s.skipped)
        } else {
            String::new()
        }
    ));
    if s.status_lines + s.ahead > 0 {
        out.push_str(&format!(
            "<p id=\"left-out\">Left out of the run's clock and counts: {} status lines \
             (<code>tessla_spec</code>, stamped with the wall clock) and {} records stamped \
             ahead of the clock (refused by <code>run</code>, passed through).</p>\n",
            s.status_lines, s.ahead
        ));
    }
    let measurements = {
        let mut names: Vec<&str> = run.records.iter().map(|r| r.measurement.as_str()).collect();
        names.sort_unstable();
        names.dedup();
        names.join(", ")
    };
    out.push_str(&format!("<p>Measurements: {}</p>\n", escape(&measurements)));

    outputs_table(&mut out, outputs);
    if !s.splits.is_empty() {
        out.push_str("<h2>Per instance</h2>\n<table id=\"splits\">\n");
        for (key, values) in &s.splits {
            for (value, n) in values {
                out.push_str(&count_row(
                    &format!("split-{key}-{value}"),
                    &format!("{key} = {value}: steps"),
                    *n,
                    None,
                ));
            }
        }
        out.push_str("</table>\n");
    }
    if s.mse.is_some() || s.spec_mse.is_some() {
        out.push_str("<h2>Mean squared error</h2>\n<table id=\"mse\">\n");
        out.push_str(&number_row(
            "mse-telemetry",
            &format!(
                "MSE expected vs actual speed, from the telemetry ({} pairs) [(m/s)²]",
                s.mse_pairs
            ),
            s.mse,
            fmt_opt(s.mse),
        ));
        out.push_str(&number_row(
            "mse-spec",
            "speed_mse reported by the spec at the end [(m/s)²]",
            s.spec_mse,
            fmt_opt(s.spec_mse),
        ));
        out.push_str("</table>\n");
    }

    if let Some(silence) = &s.silence {
        out.push_str("<h2>Robot silent</h2>\n<table id=\"silence\">\n");
        out.push_str(&count_row(
            "silent-periods",
            "Periods without the robot's messages (robot_silent)",
            silence.periods.len(),
            None,
        ));
        out.push_str(&number_row(
            "silent-total",
            "Time without the robot's messages [s]",
            Some(silence.total()),
            super::text::short(silence.total()),
        ));
        out.push_str("</table>\n");
    }
    if !s.verdicts.is_empty() {
        out.push_str("<h2>Verdicts</h2>\n<table id=\"verdicts\">\n");
        for (name, counts) in &s.verdicts {
            for (value, n) in counts {
                out.push_str(&count_row(
                    &format!("verdict-{name}-{value}"),
                    &format!("{name} = {value}: steps"),
                    *n,
                    None,
                ));
            }
        }
        out.push_str("</table>\n");
    }
    if s.robot {
        robot_rows(&mut out, s);
    }
    out.push_str("<h2>Plots</h2>\n");
    for (file, title) in plots {
        out.push_str(&format!(
            "<figure><img src=\"{}\" alt=\"{}\"/><figcaption>{}</figcaption></figure>\n",
            escape(file),
            escape(title),
            escape(title)
        ));
    }
    out.push_str("</body>\n</html>\n");
    out
}

/// Every output of the spec: its kind (as plotted), its events, its last value.
fn outputs_table(out: &mut String, outputs: &Outputs) {
    if outputs.numeric.is_empty() && outputs.verdicts.is_empty() {
        out.push_str("<p id=\"no-outputs\">The run has no outputs of a spec.</p>\n");
        return;
    }
    out.push_str(
        "<h2>Outputs</h2>\n<table id=\"outputs\">\n<tr><th>output</th><th>shown as</th>\
         <th>events</th><th>last value</th></tr>\n",
    );
    let row = |out: &mut String, name: &str, kind: &str, n: usize, last: String| {
        out.push_str(&format!(
            "<tr id=\"output-{}\"><th scope=\"row\">{}</th><td>{kind}</td>\
             <td data-value=\"{n}\">{n}</td><td>{}</td></tr>\n",
            escape(name),
            escape(name),
            escape(&last)
        ));
    };
    for o in &outputs.numeric {
        let last = o.points.last().map_or_else(String::new, |(_, v)| short(*v));
        row(
            out,
            &o.name,
            super::plots::numeric_kind(o),
            o.points.len(),
            last,
        );
    }
    for o in &outputs.verdicts {
        let last = o.points.last().map_or_else(String::new, |(_, v)| v.clone());
        row(out, &o.name, verdict_kind(o), o.points.len(), last);
    }
    out.push_str("</table>\n");
}

fn verdict_kind(o: &Output<String>) -> &'static str {
    if super::plots::is_event(o) {
        "marks (one value: events)"
    } else {
        "timeline (values over time)"
    }
}

/// The robot spec's violation counts.
fn robot_rows(out: &mut String, s: &Summary) {
    out.push_str("<h2>Violations</h2>\n<table id=\"violations\">\n");
    out.push_str(&count_row(
        "p1-violated",
        "P1 braking distance: steps violated",
        s.p1_violated,
        Some(s.p1_violated + s.p1_unknown + s.p1_ok),
    ));
    out.push_str(&count_row(
        "p1-unknown",
        "P1 braking distance: steps unknown (sector blinded)",
        s.p1_unknown,
        Some(s.p1_violated + s.p1_unknown + s.p1_ok),
    ));
    out.push_str(&count_row(
        "p2-violated",
        "P2 tolerance: steps violated",
        s.p2_violations,
        Some(s.p2_steps),
    ));
    out.push_str(&count_row(
        "augmented",
        "Augmented actions",
        s.augmented_actions,
        Some(s.actions),
    ));
    for (reason, n) in &s.reasons {
        out.push_str(&count_row(
            &format!("reason-{}", reason.replace(',', "-")),
            &format!("Augmented actions, reason {reason}"),
            *n,
            Some(s.augmented_actions),
        ));
    }
    out.push_str(&count_row(
        "capped",
        "Actions capped at unknown_speed_cap (reason p1 while P1 unknown)",
        s.capped_actions,
        Some(s.augmented_actions),
    ));
    out.push_str(&count_row(
        "p3-scans-with-spikes",
        "P3 lidar: scans with spikes",
        s.p3_scans_with_spikes,
        Some(s.p3_scans),
    ));
    out.push_str(&number_row(
        "p3-spikes",
        "P3 lidar: spikes in all scans",
        Some(s.p3_spikes),
        super::text::short(s.p3_spikes),
    ));
    out.push_str(&number_row(
        "p3-dropouts",
        "P3 lidar: dropouts in all scans",
        Some(s.p3_dropouts),
        super::text::short(s.p3_dropouts),
    ));
    out.push_str("</table>\n");
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn escapes_markup() {
        assert_eq!(escape("a<b & \"c\"'"), "a&lt;b &amp; &quot;c&quot;&#39;");
    }
}

//! Reading the shipped dashboards (telegraf/dashboards/) in tests: their queries, the
//! measurement/field/tag names each query uses, and an independent evaluation of the InfluxQL
//! panel queries over a set of line-protocol points (what InfluxDB should answer).

use influxdb_line_protocol::{FieldValue, parse_lines, split_lines};
use serde_json::Value;
use std::collections::{BTreeMap, BTreeSet};
use std::path::PathBuf;

pub fn dashboards_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("telegraf/dashboards")
}

/// The dashboard file `name` of `telegraf/dashboards`, parsed.
pub fn read_json(name: &str) -> Value {
    let path = dashboards_dir().join(name);
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    serde_json::from_str(&text).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// The robot dashboard and the dashboard for any spec.
pub const ROBOT: &str = "grafana-influxql.json";
pub const ANY_SPEC: &str = "grafana-influxql-any-spec.json";

/// A panel of a Grafana dashboard: its title, the InfluxQL query of each target, and the field
/// types it drops (`filterFields` transformations excluding `byType`).
#[derive(Debug, Clone)]
pub struct Panel {
    pub title: String,
    pub queries: Vec<String>,
    pub drops: Vec<String>,
}

/// The panels of an InfluxQL dashboard.
pub fn influxql_panels(file: &str) -> Vec<Panel> {
    let dash = read_json(file);
    let mut out = Vec::new();
    for panel in dash["panels"].as_array().expect("panels") {
        // A row only groups the panels below it: it has no query.
        if panel["type"] == "row" {
            continue;
        }
        let drops = panel["transformations"]
            .as_array()
            .map(|ts| {
                ts.iter()
                    .filter(|t| t["id"] == "filterFields")
                    .filter(|t| t["options"]["exclude"]["id"] == "byType")
                    .filter_map(|t| t["options"]["exclude"]["options"].as_str())
                    .map(str::to_string)
                    .collect()
            })
            .unwrap_or_default();
        out.push(Panel {
            title: panel["title"].as_str().unwrap_or("?").to_string(),
            queries: panel["targets"]
                .as_array()
                .expect("targets")
                .iter()
                .map(|t| t["query"].as_str().expect("query").to_string())
                .collect(),
            drops,
        });
    }
    out
}

/// `(name, query)` of every template variable of a dashboard.
pub fn variables(file: &str) -> Vec<(String, String)> {
    let dash = read_json(file);
    dash["templating"]["list"]
        .as_array()
        .expect("templating.list")
        .iter()
        .map(|v| {
            (
                v["name"].as_str().expect("name").to_string(),
                v["query"].as_str().expect("query").to_string(),
            )
        })
        .collect()
}

/// The measurement of the fleet level's outputs (`--fleet-spec`, docs/fleet.md): one series for
/// the whole fleet, with no robot tag and no spec version.
pub const FLEET_MEASUREMENT: &str = "tessla_fleet";

/// Whether an InfluxQL or Flux query reads the fleet level's outputs.
pub fn is_fleet(query: &str) -> bool {
    query.contains(&format!("FROM \"{FLEET_MEASUREMENT}\""))
        || query.contains(&format!("r._measurement == \"{FLEET_MEASUREMENT}\""))
}

/// The titles of the robot dashboard's rows.
pub fn row_titles(file: &str) -> Vec<String> {
    read_json(file)["panels"]
        .as_array()
        .expect("panels")
        .iter()
        .filter(|p| p["type"] == "row")
        .filter_map(|p| p["title"].as_str().map(str::to_string))
        .collect()
}

/// `(panel title, query)` of every InfluxQL target of the robot dashboard.
pub fn influxql_queries() -> Vec<(String, String)> {
    influxql_panels(ROBOT)
        .into_iter()
        .flat_map(|p| p.queries.into_iter().map(move |q| (p.title.clone(), q)))
        .collect()
}

/// The robot and spec-version selection every robot-dashboard query carries: which robot (the
/// tag --instance-by names: `topic` or `robot`) and which spec version, one series each.
pub const ROBOT_FILTER: &str =
    "(\"topic\" =~ /^${robot:regex}$/ OR \"robot\" =~ /^${robot:regex}$/) AND ";
pub const VERSION_FILTER: &str = "\"spec_version\" =~ /^${spec_version:regex}$/ AND ";
pub const BY_INSTANCE: &str = "\"topic\", \"robot\", \"spec_version\"";

/// The query without its robot and version selection (absent tags match it: `.*` matches the
/// empty value), or `None` when it lacks one.
pub fn without_selection(query: &str) -> Option<String> {
    if !query.contains(ROBOT_FILTER) {
        return None;
    }
    let q = query.replace(ROBOT_FILTER, "").replace(VERSION_FILTER, "");
    let q = q
        .replace(&format!(", {BY_INSTANCE}"), "")
        .replace(&format!(" GROUP BY {BY_INSTANCE}"), "")
        .replace(" GROUP BY \"topic\", \"robot\"", "");
    Some(q)
}

/// What a user picked for a variable.
#[derive(Debug, Clone)]
pub enum Pick {
    /// "All": the variable's custom all value `.*`, not escaped.
    All,
    /// One or more values.
    Values(Vec<String>),
    /// A single-valued variable's value.
    Raw(String),
}

/// Grafana's `regex` format: each value regex-escaped (slashes too, for `/.../` literals), several
/// joined as `(a|b)`.
fn regex_format(values: &[String]) -> String {
    let escaped: Vec<String> = values
        .iter()
        .map(|v| {
            let mut out = String::new();
            for c in v.chars() {
                if "\\^$*+?.()|[]{}/".contains(c) {
                    out.push('\\');
                }
                out.push(c);
            }
            out
        })
        .collect();
    match escaped.as_slice() {
        [one] => one.clone(),
        _ => format!("({})", escaped.join("|")),
    }
}

/// The query as Grafana sends it: `${name:regex}` / `${name:raw}` / `$name` replaced by the
/// pick, `$timeFilter` by the range in ns, `$__interval` by `interval`.
pub fn fill(
    query: &str,
    picks: &BTreeMap<String, Pick>,
    range: (i64, i64),
    interval: &str,
) -> String {
    let mut q = query
        .replace(
            "$timeFilter",
            &format!("time >= {} AND time <= {}", range.0, range.1),
        )
        .replace("$__interval", interval);
    for (name, pick) in picks {
        let value = match pick {
            Pick::All => ".*".to_string(),
            Pick::Values(v) => regex_format(v),
            Pick::Raw(v) => v.clone(),
        };
        let raw = match pick {
            Pick::Raw(v) => v.clone(),
            Pick::Values(v) => v.join(","),
            Pick::All => ".*".to_string(),
        };
        q = q
            .replace(&format!("${{{name}:regex}}"), &value)
            .replace(&format!("${{{name}:raw}}"), &raw);
    }
    assert!(!q.contains("${"), "a variable left unfilled: {q}");
    q
}

/// `(chart name, query)` of every Flux query of the InfluxDB 2 template's robot dashboard.
pub fn flux_queries() -> Vec<(String, String)> {
    flux_dashboard_queries("tessla-robot-monitors")
}

/// Every query of the InfluxDB 2 template's dashboard for any spec.
pub fn flux_any_spec_queries() -> Vec<(String, String)> {
    flux_dashboard_queries("tessla-any-spec")
}

/// Every (chart, query) of the template's dashboard named `name`.
fn flux_dashboard_queries(name: &str) -> Vec<(String, String)> {
    let template = read_json("influxdb2-template.json");
    let mut out = Vec::new();
    for resource in template.as_array().expect("a template is an array") {
        if resource["kind"] != "Dashboard" || resource["metadata"]["name"] != name {
            continue;
        }
        for chart in resource["spec"]["charts"].as_array().expect("charts") {
            let name = chart["name"].as_str().unwrap_or("?").to_string();
            for q in chart["queries"].as_array().expect("queries") {
                out.push((
                    name.clone(),
                    q["query"].as_str().expect("query").to_string(),
                ));
            }
        }
    }
    out
}

/// The names one query uses.
#[derive(Debug, Default, Clone, PartialEq)]
pub struct Refs {
    pub measurements: BTreeSet<String>,
    /// Fields selected (InfluxQL SELECT, Flux `r._field == ...`).
    pub fields: BTreeSet<String>,
    /// Names compared in conditions: tags, or fields after a Flux pivot.
    pub keys: BTreeSet<String>,
}

/// Double-quoted identifiers of an InfluxQL fragment (`"name"`).
fn quoted_identifiers(text: &str) -> Vec<String> {
    text.split('"')
        .skip(1)
        .step_by(2)
        .map(str::to_string)
        .collect()
}

/// Names used by an InfluxQL `SELECT ... FROM "m" WHERE ... [GROUP BY ...]`.
pub fn influxql_refs(query: &str) -> Refs {
    let stripped = without_selection(query);
    let query = stripped.as_deref().unwrap_or(query);
    let upper = query.to_uppercase();
    let from = upper.find(" FROM ").expect("FROM");
    let where_at = upper.find(" WHERE ").unwrap_or(query.len());
    let group_at = upper.find(" GROUP BY ").unwrap_or(query.len());
    let select = query.get(..from).unwrap();
    let mut refs = Refs::default();
    // In the SELECT clause, an identifier after AS is an alias, not a field.
    let mut pieces = select.split('"');
    let mut previous = pieces.next().unwrap_or("");
    let mut inside = true;
    for piece in pieces {
        if inside && !previous.trim_end().to_uppercase().ends_with("AS") {
            refs.fields.insert(piece.to_string());
        }
        if !inside {
            previous = piece;
        }
        inside = !inside;
    }
    let from_clause = query.get(from + 6..where_at.min(group_at)).unwrap();
    refs.measurements.extend(quoted_identifiers(from_clause));
    if where_at < query.len() {
        let clause = query.get(where_at..group_at.max(where_at)).unwrap();
        refs.keys.extend(quoted_identifiers(clause));
    }
    if group_at < query.len() {
        refs.keys
            .extend(quoted_identifiers(query.get(group_at..).unwrap()));
    }
    refs
}

/// Names used by a Flux query: `r._measurement == "m"`, `r._field == "f"`, and any other
/// `r.name` / `r["name"]` (a tag, or a field after `pivot`).
pub fn flux_refs(query: &str) -> Refs {
    let mut refs = Refs::default();
    let normalized = query.replace("r[\"", "r.").replace("\"]", "");
    let mut rest = normalized.as_str();
    while let Some(at) = rest.find("r.") {
        let before_ok = at == 0
            || !rest[..at]
                .chars()
                .last()
                .is_some_and(|c| c.is_alphanumeric() || c == '_');
        rest = &rest[at + 2..];
        if !before_ok {
            continue;
        }
        let name: String = rest
            .chars()
            .take_while(|c| c.is_alphanumeric() || *c == '_')
            .collect();
        let after = rest[name.len()..].trim_start();
        // A comparison with a dashboard variable (`r.robot == v.robot`) selects, it names
        // nothing the spec must write.
        if after
            .strip_prefix("==")
            .is_some_and(|s| s.trim_start().starts_with("v."))
        {
            continue;
        }
        let literal = after
            .strip_prefix("==")
            .map(str::trim_start)
            .and_then(|s| s.strip_prefix('"'))
            .and_then(|s| s.split('"').next());
        match (name.as_str(), literal) {
            ("_measurement", Some(m)) => {
                refs.measurements.insert(m.to_string());
            }
            ("_field", Some(f)) => {
                refs.fields.insert(f.to_string());
            }
            ("_value" | "_time" | "_start" | "_stop" | "_measurement" | "_field", _) => {}
            (other, _) if !other.is_empty() => {
                refs.keys.insert(other.to_string());
            }
            _ => {}
        }
    }
    // Columns kept by name after a pivot are fields too.
    for (i, _) in query.match_indices("keep(columns: [") {
        let list = &query[i + 15..];
        let list = &list[..list.find(']').unwrap_or(0)];
        for name in quoted_identifiers(list) {
            if !name.starts_with('_') {
                refs.keys.insert(name);
            }
        }
    }
    refs
}

/// What a stream of line protocol contains: per measurement, its field and tag keys.
#[derive(Debug, Default, Clone)]
pub struct Emitted {
    pub fields: BTreeMap<String, BTreeSet<String>>,
    pub tags: BTreeMap<String, BTreeSet<String>>,
}

impl Emitted {
    pub fn from_lines(text: &str) -> Emitted {
        let mut e = Emitted::default();
        for p in points(text) {
            e.fields
                .entry(p.measurement.clone())
                .or_default()
                .extend(p.fields.keys().cloned());
            e.tags
                .entry(p.measurement.clone())
                .or_default()
                .extend(p.tags.keys().cloned());
        }
        e
    }

    /// Every name of `refs` that this output does not have, explained.
    pub fn missing(&self, refs: &Refs) -> Vec<String> {
        let mut missing = Vec::new();
        for m in &refs.measurements {
            let Some(fields) = self.fields.get(m) else {
                missing.push(format!("measurement {m:?}"));
                continue;
            };
            let tags = self.tags.get(m).cloned().unwrap_or_default();
            for f in &refs.fields {
                if !fields.contains(f) {
                    missing.push(format!("field {f:?} of {m:?}"));
                }
            }
            for k in &refs.keys {
                if !fields.contains(k) && !tags.contains(k) {
                    missing.push(format!("tag or field {k:?} of {m:?}"));
                }
            }
        }
        missing
    }
}

/// A point as InfluxDB stores it.
#[derive(Debug, Clone, PartialEq)]
pub struct Point {
    pub measurement: String,
    pub tags: BTreeMap<String, String>,
    pub fields: BTreeMap<String, Lit>,
    pub time: i64,
}

/// A field value.
#[derive(Debug, Clone, PartialEq)]
pub enum Lit {
    Num(f64),
    Bool(bool),
    Str(String),
}

/// Measurement, sorted tags and time: what identifies a point in InfluxDB.
type SeriesAt = (String, Vec<(String, String)>, i64);

/// The points of `text`, merged as InfluxDB merges them: same measurement, tags and time make
/// one point, later fields overwriting earlier ones. Sorted by series then time.
pub fn points(text: &str) -> Vec<Point> {
    let mut merged: BTreeMap<SeriesAt, BTreeMap<String, Lit>> = BTreeMap::new();
    for chunk in split_lines(text) {
        for line in parse_lines(chunk) {
            let line = line.unwrap_or_else(|e| panic!("not line protocol ({e}): {chunk}"));
            let tags: Vec<(String, String)> = line
                .series
                .tag_set
                .iter()
                .flatten()
                .map(|(k, v)| (k.to_string(), v.to_string()))
                .collect::<BTreeMap<_, _>>()
                .into_iter()
                .collect();
            let key = (
                line.series.measurement.to_string(),
                tags,
                line.timestamp.expect("our output has timestamps"),
            );
            let fields = merged.entry(key).or_default();
            for (k, v) in &line.field_set {
                let lit = match v {
                    FieldValue::I64(i) => Lit::Num(*i as f64),
                    FieldValue::U64(u) => Lit::Num(*u as f64),
                    FieldValue::F64(f) => Lit::Num(*f),
                    FieldValue::Boolean(b) => Lit::Bool(*b),
                    FieldValue::String(s) => Lit::Str(s.to_string()),
                };
                fields.insert(k.to_string(), lit);
            }
        }
    }
    merged
        .into_iter()
        .map(|((measurement, tags, time), fields)| Point {
            measurement,
            tags: tags.into_iter().collect(),
            fields,
            time,
        })
        .collect()
}

/// What an InfluxQL panel query should return over `points`, worked out without InfluxDB:
/// the number of rows of a raw query, or the value of a single `count`/`sum` aggregate (summed
/// over all intervals for `GROUP BY time(...)`). Handles the dashboards' forms only: one
/// measurement, conditions `"key" = 'text'` / `"key" = true|false` joined by AND.
#[derive(Debug, Clone, PartialEq)]
pub enum Expected {
    Rows(usize),
    Aggregate(f64),
}

pub fn expected_answer(query: &str, points: &[Point]) -> Expected {
    let refs = influxql_refs(query);
    let measurement = refs
        .measurements
        .iter()
        .next()
        .expect("one measurement")
        .clone();
    let upper = query.to_uppercase();
    let where_clause = upper
        .find(" WHERE ")
        .map(|w| {
            let end = upper.find(" GROUP BY ").unwrap_or(query.len());
            &query[w + 7..end]
        })
        .unwrap_or("");
    let conditions: Vec<(String, Lit)> = where_clause
        .split(" AND ")
        .filter(|c| c.contains('='))
        .map(|c| {
            let (key, value) = c.split_once('=').unwrap();
            let key = key.trim().trim_matches('"').to_string();
            let value = value.trim();
            let lit = match value {
                "true" => Lit::Bool(true),
                "false" => Lit::Bool(false),
                v => Lit::Str(v.trim_matches('\'').to_string()),
            };
            (key, lit)
        })
        .collect();
    let matching = points.iter().filter(|p| {
        p.measurement == measurement
            && conditions.iter().all(|(k, v)| match v {
                Lit::Str(s) => p.tags.get(k) == Some(s) || p.fields.get(k) == Some(v),
                other => p.fields.get(k) == Some(other),
            })
    });
    let select = &query[..upper.find(" FROM ").unwrap()];
    let select_upper = select.to_uppercase();
    let field = refs.fields.iter().next().expect("a field").clone();
    if select_upper.contains("COUNT(") {
        Expected::Aggregate(matching.filter(|p| p.fields.contains_key(&field)).count() as f64)
    } else if select_upper.contains("SUM(") {
        Expected::Aggregate(
            matching
                .filter_map(|p| match p.fields.get(&field) {
                    Some(Lit::Num(n)) => Some(*n),
                    _ => None,
                })
                .sum(),
        )
    } else {
        Expected::Rows(
            matching
                .filter(|p| refs.fields.iter().any(|f| p.fields.contains_key(f)))
                .count(),
        )
    }
}

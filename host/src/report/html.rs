//! The HTML page: header, result table, figures, health events and the generic tables of
//! everything else the report holds, with the JSON itself embedded (inert, not executed).

use std::fmt::Write;

use serde_json::Value;

use super::data::{self, History, Kind};
use super::figures;
use super::svg::escape;

/// An image to embed: caption and PNG bytes.
pub struct Image<'a> {
    /// Caption under it.
    pub caption: String,
    /// PNG file content.
    pub png: &'a [u8],
}

const STYLE: &str = "body{font-family:sans-serif;max-width:920px;margin:1em auto;color:#222}\
table{border-collapse:collapse;margin:.5em 0}td,th{border:1px solid #ccc;padding:2px 8px;\
text-align:right;font-size:13px}th{background:#f4f4f4}td.k{text-align:left}\
.ok{color:#2a7a2a}.bad{color:#b00}svg.figure{display:block;margin:.5em 0}\
img.overlay{max-width:100%}section{margin-top:1.5em}";

/// Arrays drawn as figures or too long for a table; they stay in the embedded JSON.
/// (`sensors`: the monitor's per-sensor series, drawn by its timeline.)
const NOT_TABULATED: [&str; 6] = [
    "history",
    "scans",
    "excitation",
    "sample",
    "mi_slices",
    "sensors",
];
/// Longest array shown as a table.
const MAX_TABLE_ROWS: usize = 200;

/// Renders the page of `report` (the pipeline's JSON report) with `images` and `figures`
/// embedded.
pub fn page(report: &Value, images: &[Image<'_>], figures: &[super::SvgFigure]) -> String {
    let kind = Kind::of(report);
    let history = History::read(report);
    let file_tables = report
        .get(super::result_file::KEY)
        .map(super::result_file::tables);
    let rows = match &file_tables {
        Some(tables) => tables.first().map(|t| t.rows.clone()).unwrap_or_default(),
        None => data::result_rows(report, history.as_ref()),
    };
    let mut out = String::new();
    let _ = write!(
        out,
        "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">\
         <title>msreg: {0}</title><style>{STYLE}</style></head><body><h1>msreg: {0}</h1>",
        escape(kind.title())
    );
    status(&mut out, report, "status");
    match &file_tables {
        Some(tables) => result_file_tables(&mut out, tables, history.is_some()),
        None => result_table(&mut out, kind.transform(), "result", &rows),
    }
    if kind == Kind::Joint {
        joint_sensors(&mut out, report, file_tables.is_none());
    }
    let mut section = |title: &str, body: Option<String>| {
        if let Some(body) = body {
            let _ = write!(out, "<section><h2>{}</h2>{body}</section>", escape(title));
        }
    };
    if let Some(h) = &history {
        section(
            "Convergence (estimate and 3-sigma band)",
            figures::convergence(h, ""),
        );
        section("NIS over time", figures::nis(report, h, ""));
    }
    let residuals = data::residuals(report, kind, history.as_ref());
    section("Residual histograms", figures::histograms(&residuals));
    section("Excitation per DoF", figures::excitation(report));
    section(
        "Observability: final 1-sigma per DoF",
        figures::sigmas(&rows),
    );
    section("Reprojection of one image", figures::reprojection(report));
    section(
        "MI slices through the estimate (Fig. 7.8 / 7.9)",
        super::slices::mi_slices(report),
    );
    section(
        "Top view: keyframes, cameras and their 3-sigma ellipses",
        super::topview::top_view(report),
    );
    for f in figures {
        let body = format!(
            "<figure id=\"{}\">{}<figcaption>{}</figcaption></figure>",
            escape(&f.id),
            f.svg,
            escape(&f.caption)
        );
        section(&f.caption, Some(body));
    }
    section("Overlays", overlays(images));
    section("Health events", events(report, history.is_some()));
    section("Details", Some(details(report)));
    embed_json(&mut out, report);
    out.push_str("</body></html>\n");
    out
}

/// The converged / NOT converged line with its reasons, as element `id`.
fn status(out: &mut String, report: &Value, id: &str) {
    let Some(converged) = report.get("converged").and_then(Value::as_bool) else {
        return;
    };
    let (class, text) = if converged {
        ("ok", "converged")
    } else {
        ("bad", "NOT converged")
    };
    let _ = write!(
        out,
        "<p id=\"{}\" class=\"{class}\"><b>{text}</b>",
        escape(id)
    );
    for key in ["reasons", "reason"] {
        for r in strings(report.get(key)) {
            let _ = write!(out, "<br>{}", escape(&r));
        }
    }
    out.push_str("</p>");
}

fn strings(v: Option<&Value>) -> Vec<String> {
    match v {
        Some(Value::String(s)) => vec![s.clone()],
        Some(Value::Array(a)) => a.iter().map(scalar_text).collect(),
        _ => Vec::new(),
    }
}

/// The joint filter's two sensors, each with its status, result, convergence and NIS
/// (element ids suffixed `-cam0` / `-lidar0`).
/// `with_results`: also each sensor's result table from its last history point (reports
/// without the result file).
fn joint_sensors(out: &mut String, report: &Value, with_results: bool) {
    for (key, scope, transform) in [
        ("camera", "-cam0", "cam0: T_imu_cam"),
        ("lidar", "-lidar0", "lidar0: T_imu_lidar"),
    ] {
        let Some(sensor) = report.get(key) else {
            continue;
        };
        let Some(h) = History::read(sensor) else {
            continue;
        };
        status(out, sensor, &format!("status{scope}"));
        if with_results {
            result_table(
                out,
                transform,
                &format!("result{scope}"),
                &data::result_rows(sensor, Some(&h)),
            );
        }
        for (title, body) in [
            ("convergence", figures::convergence(&h, scope)),
            ("NIS over time", figures::nis(sensor, &h, scope)),
        ] {
            if let Some(body) = body {
                let _ = write!(
                    out,
                    "<section><h2>{transform}: {title}</h2>{body}</section>"
                );
            }
        }
    }
}

fn result_table(out: &mut String, transform: &str, id: &str, rows: &[data::ResultRow]) {
    if rows.is_empty() {
        return;
    }
    let _ = write!(
        out,
        "<section><h2>Result: {}</h2><table id=\"{}\"><tr><th>DoF</th><th>value</th>\
         <th>1-sigma</th><th>3-sigma</th><th>unit</th></tr>",
        escape(transform),
        escape(id)
    );
    for (name, value, sigma, unit) in rows {
        let _ = write!(
            out,
            "<tr><td class=\"k\">{name}</td><td>{value:.4}</td><td>{sigma:.4}</td>\
             <td>{:.4}</td><td class=\"k\">{unit}</td></tr>",
            3.0 * sigma
        );
    }
    out.push_str(
        "</table><p>Rotation as a rotation vector; its sigmas are those of the filter's \
         rotation perturbation.</p></section>",
    );
}

/// The result file's transforms (section `result`), one table each (`result-pose0-T_imu_pose`),
/// with a `held` column; `filtered`: the run has a filter history, whose last state the
/// convergence figures show.
fn result_file_tables(
    out: &mut String,
    tables: &[super::result_file::ResultTable],
    filtered: bool,
) {
    out.push_str("<section id=\"result\"><h2>Result (the numbers of the result file)</h2>");
    for t in tables {
        let _ = write!(
            out,
            "<h3>{}</h3><table id=\"{}\"><tr><th>DoF</th><th>value</th><th>1-sigma</th>\
             <th>3-sigma</th><th>unit</th><th>status</th></tr>",
            escape(&t.label),
            escape(&t.id)
        );
        for (name, value, sigma, unit) in &t.rows {
            let held = if t.is_held(name) {
                "held at its prior"
            } else {
                ""
            };
            let _ = write!(
                out,
                "<tr><td class=\"k\">{name}</td><td>{value:.4}</td><td>{}</td><td>{}</td>\
                 <td class=\"k\">{unit}</td><td class=\"k\">{held}</td></tr>",
                number(*sigma),
                number(3.0 * sigma)
            );
        }
        out.push_str("</table>");
    }
    out.push_str(
        "<p>Rotation as the rotation vector of each transform as the file stores it; \
         translation in mm, time shift in ms (the file gives no sigma for it: -). A DoF \
         marked held is at its prior: the data did not determine it.",
    );
    if filtered {
        out.push_str(
            " The convergence figures show the filter's state; where the pipeline replaced \
             part of it (see the reasons above), this table is the result.",
        );
    }
    out.push_str("</p></section>");
}

/// A table cell's number, `-` for NaN.
fn number(v: f64) -> String {
    if v.is_finite() {
        format!("{v:.4}")
    } else {
        "-".to_string()
    }
}

fn overlays(images: &[Image<'_>]) -> Option<String> {
    use base64::Engine as _;
    if images.is_empty() {
        return None;
    }
    let mut out = String::new();
    for (i, image) in images.iter().enumerate() {
        let encoded = base64::engine::general_purpose::STANDARD.encode(image.png);
        let _ = write!(
            out,
            "<figure><img id=\"overlay-{i}\" class=\"overlay\" alt=\"{0}\" \
             src=\"data:image/png;base64,{encoded}\"><figcaption>{0}</figcaption></figure>",
            escape(&image.caption)
        );
    }
    Some(out)
}

fn events(report: &Value, filter: bool) -> Option<String> {
    let mut out = String::new();
    if let Some(rows) = report.get("events").and_then(Value::as_array) {
        if rows.is_empty() {
            out.push_str(
                "<p id=\"events\">No health event (no step in the extrinsic detected).</p>",
            );
        } else {
            table(&mut out, "events", rows);
        }
    } else if filter {
        out.push_str("<p id=\"events\">The report carries no health events.</p>");
    }
    for key in ["poses_skipped", "scans_skipped"] {
        let list = strings(report.get(key));
        if !list.is_empty() {
            let _ = write!(out, "<p>{key}: {}</p><ul>", list.len());
            for s in list.iter().take(MAX_TABLE_ROWS) {
                let _ = write!(out, "<li>{}</li>", escape(s));
            }
            out.push_str("</ul>");
        }
    }
    (!out.is_empty()).then_some(out)
}

/// Every scalar field (one level of nesting flattened) and every short array of objects.
fn details(report: &Value) -> String {
    let mut out = String::from("<table id=\"summary\"><tr><th>field</th><th>value</th></tr>");
    if let Some(map) = report.as_object() {
        for (key, value) in map {
            summary_rows(&mut out, key, value);
        }
    }
    out.push_str("</table>");
    let Some(map) = report.as_object() else {
        return out;
    };
    for (key, value) in map {
        let Some(rows) = value.as_array() else {
            continue;
        };
        let rows_of_fields = rows.first().is_some_and(|r| r.is_object() || r.is_array());
        if key == "events" || NOT_TABULATED.contains(&key.as_str()) || !rows_of_fields {
            continue;
        }
        let _ = write!(out, "<h3>{} ({} rows)</h3>", escape(key), rows.len());
        if rows.len() <= MAX_TABLE_ROWS {
            table(&mut out, key, rows);
        } else {
            out.push_str("<p>Too many rows for a table: see the embedded JSON.</p>");
        }
    }
    out
}

fn summary_rows(out: &mut String, key: &str, value: &Value) {
    match value {
        Value::Object(inner) => {
            for (k, v) in inner {
                if !v.is_object() && !v.is_array() {
                    summary_rows(out, &format!("{key}.{k}"), v);
                }
            }
        }
        Value::Array(a) if a.len() <= 7 && a.iter().all(|v| !v.is_object()) => {
            let text: Vec<String> = a.iter().map(scalar_text).collect();
            let _ = write!(
                out,
                "<tr><td class=\"k\">{}</td><td class=\"k\">{}</td></tr>",
                escape(key),
                escape(&text.join(", "))
            );
        }
        Value::Array(_) => {}
        v => {
            let _ = write!(
                out,
                "<tr><td class=\"k\">{}</td><td class=\"k\">{}</td></tr>",
                escape(key),
                escape(&scalar_text(v))
            );
        }
    }
}

fn scalar_text(v: &Value) -> String {
    match v {
        Value::Null => "NaN / none".into(),
        Value::String(s) => s.clone(),
        Value::Number(n) => match n.as_f64() {
            Some(f) if n.is_f64() => format!("{f:.6}"),
            _ => n.to_string(),
        },
        Value::Array(a) => {
            let parts: Vec<String> = a.iter().map(scalar_text).collect();
            format!("[{}]", parts.join(", "))
        }
        other => other.to_string(),
    }
}

/// A table of objects (one column per scalar field of the first row) or of arrays (one
/// column per element).
fn table(out: &mut String, id: &str, rows: &[Value]) {
    if rows.first().is_some_and(Value::is_array) {
        let _ = write!(out, "<table id=\"{}\">", escape(id));
        for row in rows.iter().take(MAX_TABLE_ROWS) {
            out.push_str("<tr>");
            for cell in row.as_array().into_iter().flatten() {
                let _ = write!(out, "<td>{}</td>", escape(&scalar_text(cell)));
            }
            out.push_str("</tr>");
        }
        out.push_str("</table>");
        return;
    }
    let columns: Vec<&String> = rows
        .first()
        .and_then(Value::as_object)
        .map(|m| {
            m.iter()
                .filter(|(_, v)| !v.is_object())
                .map(|(k, _)| k)
                .collect()
        })
        .unwrap_or_default();
    let _ = write!(out, "<table id=\"{}\"><tr>", escape(id));
    for c in &columns {
        let _ = write!(out, "<th>{}</th>", escape(c));
    }
    out.push_str("</tr>");
    for row in rows.iter().take(MAX_TABLE_ROWS) {
        out.push_str("<tr>");
        for c in &columns {
            let cell = row.get(c.as_str()).map(scalar_text).unwrap_or_default();
            let _ = write!(out, "<td>{}</td>", escape(&cell));
        }
        out.push_str("</tr>");
    }
    out.push_str("</table>");
}

/// The report's JSON, inert (`type="application/json"` is never executed); `<` is escaped
/// so no string in it can close the element.
fn embed_json(out: &mut String, report: &Value) {
    let json = serde_json::to_string(report)
        .unwrap_or_default()
        .replace('<', "\\u003c");
    let _ = write!(
        out,
        "<script type=\"application/json\" id=\"report-json\">{json}</script>"
    );
}

//! The monitor's timeline plot as a self-contained SVG (no font or library needed): per
//! sensor, the NIS / dof of every update with its gate and the windowed NIS, alarms as
//! vertical lines; then the per-DoF excitation of the observability run over time; then each
//! sensor's extrinsic estimate against the calibration of record (rotation and translation
//! per axis, with the filter's 3-sigma band); then the observability table and the alarms in
//! words.

use std::fmt::Write;
use std::path::Path;

use super::{EstimatePoint, MonitorReport, SensorReport};

const WIDTH: f64 = 1200.0;
const PANEL_H: f64 = 190.0;
const LEFT: f64 = 70.0;
const RIGHT: f64 = 20.0;
const DOF_NAMES: [&str; 7] = [
    "rot x", "rot y", "rot z", "trans x", "trans y", "trans z", "t_d",
];
const DOF_COLOURS: [&str; 7] = [
    "#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#17becf",
];

/// Why the plot could not be written.
#[derive(Debug, thiserror::Error)]
#[error("{path}: {source}")]
pub struct TimelineError {
    /// The output file.
    pub path: String,
    /// The I/O error.
    pub source: std::io::Error,
}

/// Horizontal and vertical mapping of one panel.
struct Panel {
    top: f64,
    t1: f64,
    y0: f64,
    y1: f64,
}

impl Panel {
    fn x(&self, t: f64) -> f64 {
        LEFT + (t / self.t1).clamp(0.0, 1.0) * (WIDTH - LEFT - RIGHT)
    }

    fn y(&self, v: f64) -> f64 {
        let f = ((v - self.y0) / (self.y1 - self.y0)).clamp(0.0, 1.0);
        self.top + PANEL_H - 25.0 - f * (PANEL_H - 50.0)
    }

    fn frame(&self, out: &mut String, title: &str, unit: &str) {
        let (b, t) = (self.y(self.y0), self.y(self.y1));
        let _ = write!(
            out,
            "<rect x='{LEFT}' y='{t:.1}' width='{:.1}' height='{:.1}' fill='none' stroke='#888'/>\
             <text x='{LEFT}' y='{:.1}' font-size='14'>{title}</text>\
             <text x='5' y='{:.1}' font-size='11'>{:.2}</text><text x='5' y='{:.1}' font-size='11'>{:.2}</text>\
             <text x='5' y='{:.1}' font-size='11'>{unit}</text>",
            WIDTH - LEFT - RIGHT,
            b - t,
            t - 6.0,
            b,
            self.y0,
            t + 10.0,
            self.y1,
            (b + t) / 2.0
        );
        for k in 0..=6 {
            let tt = self.t1 * k as f64 / 6.0;
            let _ = write!(
                out,
                "<text x='{:.1}' y='{:.1}' font-size='11' text-anchor='middle'>{tt:.0} s</text>",
                self.x(tt),
                b + 14.0
            );
        }
    }

    fn polyline(&self, out: &mut String, points: impl Iterator<Item = (f64, f64)>, colour: &str) {
        let pts: Vec<String> = points
            .map(|(t, v)| format!("{:.1},{:.1}", self.x(t), self.y(v)))
            .collect();
        let _ = write!(
            out,
            "<polyline fill='none' stroke='{colour}' stroke-width='1.2' points='{}'/>",
            pts.join(" ")
        );
    }
}

fn nis_panel(out: &mut String, r: &MonitorReport, s: &SensorReport, top: f64) {
    let gate = s.nis.iter().map(|p| p.gate_per_dof).fold(0.0, f64::max);
    let p = Panel {
        top,
        t1: r.duration_s.max(1e-6),
        y0: 0.0,
        y1: (2.0 * gate).max(1.0),
    };
    p.frame(
        out,
        &format!(
            "{}: NIS/dof per update (grey), windowed (blue), gate (dashed), alarms (red)",
            s.name
        ),
        "NIS/dof",
    );
    for q in &s.nis {
        let colour = if q.accepted { "#999" } else { "#f0a" };
        let _ = write!(
            out,
            "<circle cx='{:.1}' cy='{:.1}' r='1.3' fill='{colour}'/>",
            p.x(q.t_s),
            p.y(q.nis_per_dof)
        );
    }
    p.polyline(
        out,
        s.nis.iter().map(|q| (q.t_s, q.window_nis_per_dof)),
        "#1f77b4",
    );
    let _ = write!(
        out,
        "<line x1='{LEFT}' x2='{:.1}' y1='{y:.1}' y2='{y:.1}' stroke='#444' stroke-dasharray='5,4'/>",
        WIDTH - RIGHT,
        y = p.y(gate)
    );
    for a in r.alarms.iter().filter(|a| a.sensor == s.name) {
        let x = p.x(a.t_s);
        let _ = write!(
            out,
            "<line x1='{x:.1}' x2='{x:.1}' y1='{:.1}' y2='{:.1}' stroke='red' stroke-width='2'/>\
             <text x='{:.1}' y='{:.1}' font-size='11' fill='red'>{} {:.1} s</text>",
            p.y(p.y1),
            p.y(p.y0),
            x + 3.0,
            p.y(p.y1) + 12.0,
            a.kind,
            a.t_s
        );
    }
}

fn excitation_panel(out: &mut String, r: &MonitorReport, s: &SensorReport, top: f64) {
    let p = Panel {
        top,
        t1: r.duration_s.max(1e-6),
        y0: 0.0,
        y1: 1.0,
    };
    p.frame(
        out,
        &format!(
            "{}: per-DoF excitation 1 - sigma/prior (observability run)",
            s.name
        ),
        "excit.",
    );
    for k in 0..7 {
        p.polyline(
            out,
            s.excitation.iter().map(|e| (e.t_s, e.excitation[k])),
            DOF_COLOURS[k],
        );
        let _ = write!(
            out,
            "<text x='{:.1}' y='{:.1}' font-size='11' fill='{}'>{}</text>",
            LEFT + 8.0 + 70.0 * k as f64,
            p.y(1.0) + 14.0,
            DOF_COLOURS[k],
            DOF_NAMES[k]
        );
    }
}

/// One axis of an estimate panel: value and 1-sigma.
type AxisOf = fn(&EstimatePoint, usize) -> (f64, f64);

/// Rotation (deg) or translation (mm) of `s`'s estimate minus the record, per axis, each
/// with its 3-sigma band, the record as the zero line, alarms as vertical lines.
fn estimate_panel(out: &mut String, r: &MonitorReport, s: &SensorReport, top: f64, rotation: bool) {
    let (what, unit, of): (&str, &str, AxisOf) = if rotation {
        ("rotation", "deg", |e, k| {
            (e.rotation_deg[k], e.sigma_rotation_deg[k])
        })
    } else {
        ("translation", "mm", |e, k| {
            (e.translation_mm[k], e.sigma_translation_mm[k])
        })
    };
    // The scale: the largest |estimate| and 3 sigma after the first second (the start's
    // prior sigmas would flatten the rest).
    let late = s.estimates.iter().filter(|e| e.t_s > 1.0);
    let span = late
        .flat_map(|e| (0..3).map(move |k| of(e, k)))
        .fold(0.0, |m: f64, (v, sd)| m.max(v.abs() + 3.0 * sd))
        .max(if rotation { 0.1 } else { 1.0 });
    let p = Panel {
        top,
        t1: r.duration_s.max(1e-6),
        y0: -span,
        y1: span,
    };
    p.frame(
        out,
        &format!(
            "{}: {what} estimate minus the calibration of record (0), per axis, 3-sigma band",
            s.name
        ),
        unit,
    );
    let zero = p.y(0.0);
    let _ = write!(
        out,
        "<line x1='{LEFT}' x2='{:.1}' y1='{zero:.1}' y2='{zero:.1}' stroke='#000' stroke-dasharray='2,3'/>",
        WIDTH - RIGHT
    );
    for k in 0..3 {
        let colour = DOF_COLOURS[k + if rotation { 0 } else { 3 }];
        let upper = s.estimates.iter().map(|e| {
            let (v, sd) = of(e, k);
            format!("{:.1},{:.1}", p.x(e.t_s), p.y(v + 3.0 * sd))
        });
        let lower = s.estimates.iter().rev().map(|e| {
            let (v, sd) = of(e, k);
            format!("{:.1},{:.1}", p.x(e.t_s), p.y(v - 3.0 * sd))
        });
        let band: Vec<String> = upper.chain(lower).collect();
        let _ = write!(
            out,
            "<polygon fill='{colour}' fill-opacity='0.15' stroke='none' points='{}'/>",
            band.join(" ")
        );
        p.polyline(out, s.estimates.iter().map(|e| (e.t_s, of(e, k).0)), colour);
        let _ = write!(
            out,
            "<text x='{:.1}' y='{:.1}' font-size='11' fill='{colour}'>{what} {}</text>",
            LEFT + 8.0 + 110.0 * k as f64,
            p.y(span) + 14.0,
            ["x", "y", "z"][k]
        );
    }
    for a in r.alarms.iter().filter(|a| a.sensor == s.name) {
        let x = p.x(a.t_s);
        let _ = write!(
            out,
            "<line x1='{x:.1}' x2='{x:.1}' y1='{:.1}' y2='{:.1}' stroke='red' stroke-width='1.5'/>",
            p.y(p.y1),
            p.y(p.y0)
        );
    }
}

fn escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}

/// The SVG text of the timeline.
pub fn timeline_svg(r: &MonitorReport) -> String {
    let words = r.unobservable_words();
    let verdict = r.verdict().lines(&super::VerdictWords::default());
    let lines = 3 + r.alarms.len().max(1) + words.len() + verdict.len();
    let panels = 4.0 * r.sensors.len() as f64;
    let height = panels * PANEL_H + 40.0 + 16.0 * lines as f64;
    let mut out = format!(
        "<svg xmlns='http://www.w3.org/2000/svg' width='{WIDTH}' height='{height:.0}' \
         font-family='sans-serif'><rect width='100%' height='100%' fill='white'/>"
    );
    let n = r.sensors.len();
    let top = |panel: usize| 10.0 + PANEL_H * panel as f64;
    for (k, s) in r.sensors.iter().enumerate() {
        nis_panel(&mut out, r, s, top(k));
        excitation_panel(&mut out, r, s, top(n + k));
        estimate_panel(&mut out, r, s, top(2 * n + 2 * k), true);
        estimate_panel(&mut out, r, s, top(2 * n + 2 * k + 1), false);
    }
    let mut y = panels * PANEL_H + 30.0;
    let mut text = |out: &mut String, s: &str, colour: &str| {
        let _ = write!(
            out,
            "<text x='10' y='{y:.0}' font-size='13' fill='{colour}'>{}</text>",
            escape(s)
        );
        y += 16.0;
    };
    text(&mut out, "Verdict:", "black");
    for v in &verdict {
        let colour = if v.starts_with("OK") { "black" } else { "red" };
        text(&mut out, &format!("  {v}"), colour);
    }
    text(&mut out, "Alarms:", "black");
    if r.alarms.is_empty() {
        text(&mut out, "  none", "black");
    }
    for a in &r.alarms {
        let s = format!(
            "  {:.2} s  {}  {}  (statistic {:.1})",
            a.t_s, a.sensor, a.kind, a.statistic
        );
        text(&mut out, &s, "red");
    }
    text(&mut out, "Not observed by this drive:", "black");
    for w in &words {
        text(&mut out, &format!("  {w}"), "black");
    }
    out.push_str("</svg>\n");
    out
}

/// Writes the timeline to `path` (SVG).
pub fn write_timeline_svg(path: &Path, r: &MonitorReport) -> Result<(), TimelineError> {
    std::fs::write(path, timeline_svg(r)).map_err(|source| TimelineError {
        path: path.display().to_string(),
        source,
    })
}

//! The infrastructure calibration's top view (`fig-infra-topview`) from the report's
//! `top_view`: the robot's keyframes, each camera with the footprint of its view on the
//! robot's plane and its optical axis, its 3-sigma horizontal ellipse, and the true
//! position after the rigid alignment when the report has it. Ellipses and truth offsets
//! are millimetres on a plot of tens of metres, so both are magnified by one stated factor
//! about the estimated position (a true position inside its ellipse is consistent).

use serde_json::Value;

use super::data::{num, nums};
use super::svg::{self, range_of, Panel};

const TRAJECTORY: &str = "#1f77b4";
const CAMERA: &str = "#d62728";
const FOOTPRINT: &str = "rgba(255,127,14,0.05)";
const FOOTPRINT_EDGE: &str = "rgba(255,127,14,0.40)";
const ELLIPSE: &str = "#9467bd";
const TRUTH: &str = "#2ca02c";
/// Margin around the trajectory and the cameras, m.
const MARGIN_M: f64 = 3.0;
/// Largest magnified 3-sigma semi-axis, m (on the plot).
const ELLIPSE_TARGET_M: f64 = 1.5;

/// One camera as the figure reads it.
struct Cam {
    id: String,
    position: [f64; 2],
    axis: [f64; 2],
    footprint: Vec<(f64, f64)>,
    covariance: [f64; 3],
    truth: Option<[f64; 2]>,
}

fn pairs(v: Option<&Value>) -> Vec<(f64, f64)> {
    v.and_then(Value::as_array)
        .map(|a| a.iter().map(|p| (num(p.get(0)), num(p.get(1)))).collect())
        .unwrap_or_default()
}

fn cameras(view: &Value) -> Vec<Cam> {
    let Some(rows) = view.get("cameras").and_then(Value::as_array) else {
        return Vec::new();
    };
    rows.iter()
        .map(|c| {
            let p: [f64; 3] = nums(c.get("position_m"));
            let cov = c.get("covariance_xy_m2");
            let (row0, row1): ([f64; 2], [f64; 2]) = (
                nums(cov.and_then(|m| m.get(0))),
                nums(cov.and_then(|m| m.get(1))),
            );
            let truth = c.get("truth_m").filter(|t| t.is_array()).map(|t| {
                let t: [f64; 3] = nums(Some(t));
                [t[0], t[1]]
            });
            Cam {
                id: c.get("id").and_then(Value::as_str).unwrap_or("").into(),
                position: [p[0], p[1]],
                axis: nums(c.get("axis_xy_m")),
                footprint: pairs(c.get("footprint_xy_m")),
                covariance: [row0[0], row0[1], row1[1]],
                truth,
            }
        })
        .collect()
}

/// Semi-axes (3 sigma, m) and the angle of the first of a 2 x 2 covariance `[xx, xy, yy]`.
fn ellipse([xx, xy, yy]: [f64; 3]) -> (f64, f64, f64) {
    let mean = 0.5 * (xx + yy);
    let diff = (0.25 * (xx - yy) * (xx - yy) + xy * xy).sqrt();
    let (l1, l2) = ((mean + diff).max(0.0), (mean - diff).max(0.0));
    let angle = 0.5 * (2.0 * xy).atan2(xx - yy);
    (3.0 * l1.sqrt(), 3.0 * l2.sqrt(), angle)
}

/// The largest 1-2-5 magnification that keeps the largest 3-sigma semi-axis within
/// `ELLIPSE_TARGET_M` (at least 1).
fn magnification(cams: &[Cam]) -> f64 {
    let largest = cams
        .iter()
        .map(|c| ellipse(c.covariance).0)
        .filter(|a| a.is_finite())
        .fold(0.0, f64::max);
    if largest <= 0.0 {
        return 1.0;
    }
    let raw = ELLIPSE_TARGET_M / largest;
    let decade = 10f64.powf(raw.log10().floor());
    let nice = [5.0, 2.0, 1.0]
        .iter()
        .map(|m| m * decade)
        .find(|m| *m <= raw)
        .unwrap_or(decade);
    nice.max(1.0)
}

/// The figure, or `None` when the report has no top view with a trajectory.
pub fn top_view(report: &Value) -> Option<String> {
    let view = report.get("top_view")?;
    let trajectory = pairs(view.get("trajectory_xy_m"));
    let cams = cameras(view);
    let xs = trajectory
        .iter()
        .map(|p| p.0)
        .chain(cams.iter().map(|c| c.position[0]));
    let ys = trajectory
        .iter()
        .map(|p| p.1)
        .chain(cams.iter().map(|c| c.position[1]));
    let (x, y) = (range_of(xs)?, range_of(ys)?);
    let pad = |(lo, hi): (f64, f64)| (lo - MARGIN_M, hi + MARGIN_M);
    let panel = Panel::equal_aspect((0.0, 0.0), 880.0, 760.0, pad(x), pad(y));
    let scale = magnification(&cams);
    let mut out = String::new();
    let height = panel.height + 18.0;
    svg::open(&mut out, "fig-infra-topview", 880.0, height, "top view");
    panel.open_clip(&mut out, "clip-infra-topview");
    for c in &cams {
        panel.polygon(&mut out, &c.footprint, FOOTPRINT, FOOTPRINT_EDGE);
    }
    panel.line(&mut out, &trajectory, TRAJECTORY, 1.4);
    if let (Some(first), Some(last)) = (trajectory.first(), trajectory.last()) {
        panel.dots(&mut out, &[*first], TRAJECTORY, 4.0);
        panel.text(&mut out, *first, "start", "end");
        panel.dots(&mut out, &[*last], TRAJECTORY, 2.5);
    }
    for c in &cams {
        draw_camera(&mut out, &panel, c, scale);
    }
    out.push_str("</g>");
    panel.axes(
        &mut out,
        &format!(
            "top view, VO frame (m): 3-sigma ellipses and truth offsets magnified x{}",
            svg::label(scale)
        ),
        "x, m",
    );
    let entries = [
        (TRAJECTORY, "keyframes"),
        (CAMERA, "camera, optical axis"),
        (FOOTPRINT_EDGE, "view on the robot's plane"),
        (ELLIPSE, "3 sigma"),
        (TRUTH, "truth (aligned)"),
    ];
    let shown = if cams.iter().any(|c| c.truth.is_some()) {
        &entries[..]
    } else {
        &entries[..4]
    };
    svg::legend(&mut out, 870.0, height - 4.0, shown);
    out.push_str("</svg>");
    Some(out)
}

fn draw_camera(out: &mut String, panel: &Panel, c: &Cam, scale: f64) {
    let at = (c.position[0], c.position[1]);
    panel.line(out, &[at, (c.axis[0], c.axis[1])], CAMERA, 1.0);
    let (a, b, angle) = ellipse(c.covariance);
    let (sin, cos) = angle.sin_cos();
    let ring: Vec<(f64, f64)> = (0..=48)
        .map(|k| {
            let t = k as f64 / 48.0 * std::f64::consts::TAU;
            let (u, v) = (scale * a * t.cos(), scale * b * t.sin());
            (at.0 + cos * u - sin * v, at.1 + sin * u + cos * v)
        })
        .collect();
    panel.line(out, &ring, ELLIPSE, 1.2);
    if let Some(t) = c.truth {
        let shown = (at.0 + scale * (t[0] - at.0), at.1 + scale * (t[1] - at.1));
        panel.line(out, &[at, shown], TRUTH, 1.0);
        panel.dots(out, &[shown], TRUTH, 2.2);
    }
    panel.dots(out, &[at], CAMERA, 2.8);
    panel.text(out, (at.0 + 0.6, at.1 + 0.6), &c.id, "start");
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ellipse_axes_are_three_sigma_along_the_eigenvectors() {
        // sigma 2 along 30 deg, 1 across
        let (s, c) = 30f64.to_radians().sin_cos();
        let (l1, l2) = (4.0, 1.0);
        let cov = [
            l1 * c * c + l2 * s * s,
            (l1 - l2) * s * c,
            l1 * s * s + l2 * c * c,
        ];
        let (a, b, angle) = ellipse(cov);
        assert!((a - 6.0).abs() < 1e-12 && (b - 3.0).abs() < 1e-12);
        assert!((angle - 30f64.to_radians()).abs() < 1e-12);
    }
}

//! The report's figures as inline SVG: convergence with 3-sigma bands, NIS against its
//! chi-square bounds, residual histograms, per-DoF excitation and sigmas, and the
//! reprojection of one image's corners. Each returns `None` when the report lacks its data.

use msreg_estimator::chi2::{self, Confidence};
use serde_json::Value;

use super::data::{num, update_dofs, History, Residuals, ResultRow, DOF};
use super::svg::{self, range_of, Panel};

const BLUE: &str = "#1f77b4";
const RED: &str = "#d62728";
const GREY: &str = "#777";
const BAND: &str = "rgba(31,119,180,0.22)";

/// Estimate after each update with its +-3 sigma band, one panel per DoF
/// (`fig-convergence`, then `scope`: element ids stay unique when a page shows several
/// filters).
pub fn convergence(h: &History, scope: &str) -> Option<String> {
    let (w, ph) = (440.0, 170.0);
    let mut out = String::new();
    svg::open(
        &mut out,
        &format!("fig-convergence{scope}"),
        2.0 * w,
        4.0 * ph,
        "convergence",
    );
    for (i, (name, unit)) in DOF.iter().enumerate() {
        let panel = convergence_panel(h, i, (w * (i % 2) as f64, ph * (i / 2) as f64), (w, ph))?;
        let (lo, hi) = band(&h.value[i], &h.sigma[i]);
        panel.open_clip(&mut out, &format!("clip-conv{scope}-{i}"));
        panel.band(&mut out, &h.t, &lo, &hi, BAND);
        let points: Vec<(f64, f64)> = h.t.iter().copied().zip(h.value[i].clone()).collect();
        panel.line(&mut out, &points, BLUE, 1.5);
        out.push_str("</g>");
        panel.axes(&mut out, &format!("{name} ({unit})"), "time, s");
    }
    svg::legend(
        &mut out,
        2.0 * w - 10.0,
        4.0 * ph - 20.0,
        &[(BLUE, "estimate"), (BAND, "+-3 sigma")],
    );
    out.push_str("</svg>");
    Some(out)
}

fn band(value: &[f64], sigma: &[f64]) -> (Vec<f64>, Vec<f64>) {
    let lo = value.iter().zip(sigma).map(|(v, s)| v - 3.0 * s).collect();
    let hi = value.iter().zip(sigma).map(|(v, s)| v + 3.0 * s).collect();
    (lo, hi)
}

/// The panel of DoF `i`: y covers the band from a tenth into the history on (the prior's
/// early width would flatten the rest; the clip keeps it inside the frame).
fn convergence_panel(
    h: &History,
    i: usize,
    (x0, y0): (f64, f64),
    (width, height): (f64, f64),
) -> Option<Panel> {
    let skip = h.t.len() / 10;
    let (lo, hi) = band(&h.value[i][skip..], &h.sigma[i][skip..]);
    let y = range_of(lo.into_iter().chain(hi)).or_else(|| range_of(h.value[i].clone()))?;
    let x = range_of(h.t.clone())?;
    Some(Panel {
        x0,
        y0,
        width,
        height,
        x,
        y,
    })
}

/// NIS per DoF of every update (log scale) with the two-sided 99 % chi-square bounds of its
/// DoF (`fig-nis`, then `scope`); health events as vertical lines.
pub fn nis(report: &Value, h: &History, scope: &str) -> Option<String> {
    let dofs = update_dofs(report, h);
    let log = |v: f64| v.max(1e-12).log10();
    let scaled: Vec<f64> = h
        .nis
        .iter()
        .zip(&dofs)
        .map(|(n, d)| log(n / *d as f64))
        .collect();
    let bound = |d: usize, upper: bool| {
        let q: f64 = if upper {
            chi2::quantile(d, Confidence::P995)
        } else {
            chi2::lower_quantile(d, Confidence::P995)
        };
        log(q / d.max(1) as f64)
    };
    let upper: Vec<f64> = dofs.iter().map(|&d| bound(d, true)).collect();
    let lower: Vec<f64> = dofs.iter().map(|&d| bound(d, false)).collect();
    let (lo, hi) = range_of(scaled.iter().chain(&upper).chain(&lower).copied())?;
    // Decades from below the lowest to above the highest, at most 1e4 times the upper bound.
    let y = ((lo - 0.1).floor(), (hi + 0.1).ceil().min(4.0));
    let panel = Panel {
        x0: 0.0,
        y0: 0.0,
        width: 880.0,
        height: 260.0,
        x: range_of(h.t.clone())?,
        y,
    };
    let mut out = String::new();
    svg::open(
        &mut out,
        &format!("fig-nis{scope}"),
        880.0,
        260.0,
        "NIS over time",
    );
    panel.open_clip(&mut out, &format!("clip-nis{scope}"));
    for t in super::data::column(report, "events", "t_s") {
        panel.line(&mut out, &[(t, y.0), (t, y.1)], "#f0a000", 1.5);
    }
    let pts = |keep: bool| -> Vec<(f64, f64)> {
        (0..h.t.len())
            .filter(|&k| h.accepted[k] == keep)
            .map(|k| (h.t[k], scaled[k].min(y.1 - 0.01)))
            .collect()
    };
    panel.dots(&mut out, &pts(true), BLUE, 1.8);
    panel.dots(&mut out, &pts(false), RED, 2.2);
    let xy = |v: &[f64]| -> Vec<(f64, f64)> { h.t.iter().copied().zip(v.to_vec()).collect() };
    panel.line(&mut out, &xy(&upper), GREY, 1.2);
    panel.line(&mut out, &xy(&lower), GREY, 1.2);
    panel.line(
        &mut out,
        &[(panel.x.0, 0.0), (panel.x.1, 0.0)],
        "#2ca02c",
        1.0,
    );
    out.push_str("</g>");
    panel.axes_log_y(&mut out, "NIS / dof (log scale)", "time, s");
    svg::legend(
        &mut out,
        870.0,
        15.0,
        &[
            (BLUE, "accepted"),
            (RED, "rejected"),
            (GREY, "chi2 0.5 % / 99.5 %"),
            ("#f0a000", "health event"),
        ],
    );
    out.push_str("</svg>");
    Some(out)
}

/// One histogram per residual series (`fig-residuals`), two per row.
pub fn histograms(series: &[Residuals]) -> Option<String> {
    if series.is_empty() {
        return None;
    }
    let (w, ph) = (440.0, 200.0);
    let rows = series.len().div_ceil(2);
    let mut out = String::new();
    svg::open(
        &mut out,
        "fig-residuals",
        2.0 * w,
        ph * rows as f64,
        "residual histograms",
    );
    for (i, (title, x_title, values)) in series.iter().enumerate() {
        let origin = (w * (i % 2) as f64, ph * (i / 2) as f64);
        histogram(&mut out, origin, (w, ph), (title, x_title), values);
    }
    out.push_str("</svg>");
    Some(out)
}

fn histogram(
    out: &mut String,
    (x0, y0): (f64, f64),
    (width, height): (f64, f64),
    (title, x_title): (&str, &str),
    values: &[f64],
) {
    let Some((lo, hi)) = range_of(values.iter().copied()) else {
        return;
    };
    let bins = ((values.len() as f64).sqrt().round() as usize).clamp(5, 40);
    let step = (hi - lo) / bins as f64;
    let mut counts = vec![0usize; bins];
    for v in values {
        let b = (((v - lo) / step) as usize).min(bins - 1);
        counts[b] += 1;
    }
    let peak = counts.iter().copied().max().unwrap_or(1) as f64;
    let panel = Panel {
        x0,
        y0,
        width,
        height,
        x: (lo, hi),
        y: (0.0, peak * 1.1),
    };
    for (b, c) in counts.iter().enumerate() {
        let left = lo + b as f64 * step;
        panel.bar(out, (left, left + step), *c as f64, BLUE);
    }
    let n = values.len();
    let median = {
        let mut s = values.to_vec();
        s.sort_by(f64::total_cmp);
        s[n / 2]
    };
    panel.axes(
        out,
        title,
        &format!("{x_title}; n = {n}, median {}", svg::label(median)),
    );
}

/// Excitation per filter DoF, `1 - sigma/prior` (`fig-excitation`).
pub fn excitation(report: &Value) -> Option<String> {
    let values: Vec<f64> = report
        .get("excitation")?
        .as_array()?
        .iter()
        .map(|v| num(Some(v)))
        .collect();
    if values.is_empty() {
        return None;
    }
    let panel = Panel {
        x0: 0.0,
        y0: 0.0,
        width: 440.0,
        height: 220.0,
        x: (0.0, values.len() as f64),
        y: (0.0, 1.0),
    };
    let mut out = String::new();
    svg::open(
        &mut out,
        "fig-excitation",
        440.0,
        220.0,
        "excitation per DoF",
    );
    for (i, v) in values.iter().enumerate() {
        let colour = if *v >= 0.9 { BLUE } else { RED };
        panel.bar(
            &mut out,
            (i as f64 + 0.15, i as f64 + 0.85),
            v.max(0.0),
            colour,
        );
        let name = DOF.get(i).map_or("?", |d| d.0);
        panel.text(&mut out, (i as f64 + 0.5, 0.03), name, "middle");
    }
    panel.axes_categorical(&mut out, "excitation: 1 - sigma / prior sigma", "DoF");
    out.push_str("</svg>");
    Some(out)
}

/// Final 1-sigma per DoF, rotation and translation panels (`fig-sigmas`): what the data
/// pinned down and what it left open.
pub fn sigmas(rows: &[ResultRow]) -> Option<String> {
    if rows.len() < 6 {
        return None;
    }
    let mut out = String::new();
    svg::open(
        &mut out,
        "fig-sigmas",
        880.0,
        220.0,
        "final 1-sigma per DoF",
    );
    for (p, (unit, chunk)) in [("deg", &rows[0..3]), ("mm", &rows[3..6])]
        .into_iter()
        .enumerate()
    {
        let top = chunk.iter().map(|r| r.2).fold(0.0, f64::max);
        let top = if top.is_finite() && top > 0.0 {
            top * 1.15
        } else {
            1.0
        };
        let panel = Panel {
            x0: 440.0 * p as f64,
            y0: 0.0,
            width: 440.0,
            height: 220.0,
            x: (0.0, 3.0),
            y: (0.0, top),
        };
        for (i, row) in chunk.iter().enumerate() {
            panel.bar(&mut out, (i as f64 + 0.2, i as f64 + 0.8), row.2, BLUE);
            panel.text(&mut out, (i as f64 + 0.5, top * 0.02), row.0, "middle");
        }
        panel.axes_categorical(&mut out, &format!("final 1-sigma, {unit}"), "DoF");
    }
    out.push_str("</svg>");
    Some(out)
}

/// One image's detected corners and their reprojection under the final estimate, the error
/// vectors magnified (`fig-reprojection`).
pub fn reprojection(report: &Value) -> Option<String> {
    let sample = report.get("sample")?;
    let read = |k: &str| -> Vec<(f64, f64)> {
        sample
            .get(k)
            .and_then(Value::as_array)
            .map_or(Vec::new(), |a| {
                a.iter().map(|p| (num(p.get(0)), num(p.get(1)))).collect()
            })
    };
    let (detected, reprojected) = (read("detected"), read("reprojected"));
    if detected.is_empty() || detected.len() != reprojected.len() {
        return None;
    }
    let mean_error = detected
        .iter()
        .zip(&reprojected)
        .map(|(d, r)| (d.0 - r.0).hypot(d.1 - r.1))
        .sum::<f64>()
        / detected.len() as f64;
    let gain = (15.0 / mean_error.max(1e-6)).min(1e4).round().max(1.0);
    let x = range_of(detected.iter().map(|p| p.0))?;
    let y = range_of(detected.iter().map(|p| -p.1))?;
    let pad = |(lo, hi): (f64, f64)| (lo - 0.08 * (hi - lo), hi + 0.08 * (hi - lo));
    let panel = Panel {
        x0: 0.0,
        y0: 0.0,
        width: 640.0,
        height: 480.0,
        x: pad(x),
        y: pad(y),
    };
    let mut out = String::new();
    svg::open(
        &mut out,
        "fig-reprojection",
        640.0,
        480.0,
        "reprojection of one image",
    );
    for (d, r) in detected.iter().zip(&reprojected) {
        let tip = (d.0 + gain * (r.0 - d.0), -(d.1 + gain * (r.1 - d.1)));
        panel.line(&mut out, &[(d.0, -d.1), tip], RED, 1.0);
    }
    let flipped: Vec<(f64, f64)> = detected.iter().map(|p| (p.0, -p.1)).collect();
    panel.dots(&mut out, &flipped, BLUE, 2.5);
    panel.axes(
        &mut out,
        &format!(
            "detected corners (blue), error to the reprojection x{gain} (red); mean {:.3} px",
            mean_error
        ),
        "u, px (v down, axis shows -v)",
    );
    out.push_str("</svg>");
    Some(out)
}

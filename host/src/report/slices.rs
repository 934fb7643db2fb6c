//! The MI slices of `calibrate prior-map` (dissertation Fig. 7.8 / 7.9) as one inline SVG
//! (`fig-mi-slices`): per DoF, the smoothed MI along that DoF through the estimate, the
//! parabola of the refinement's curvature (where the sigmas come from) and the slice's
//! peak. A slice that peaks away from the estimate, or a parabola much narrower or wider
//! than the curve, shows at a glance where the reported sigma is not to be trusted.

use serde_json::Value;

use super::data::num;
use super::svg::{self, range_of, Panel};

const BLUE: &str = "#1f77b4";
const RED: &str = "#d62728";
const GREY: &str = "#777";

/// One slice as the report carries it (`mi_slices[k]`).
struct Slice {
    dof: String,
    unit: String,
    offsets: Vec<f64>,
    mi: Vec<f64>,
    quadratic: Vec<f64>,
    peak: f64,
}

impl Slice {
    fn read(v: &Value) -> Option<Slice> {
        let array = |key: &str| -> Option<Vec<f64>> {
            Some(
                v.get(key)?
                    .as_array()?
                    .iter()
                    .map(|x| num(Some(x)))
                    .collect(),
            )
        };
        let text = |key: &str| v.get(key).and_then(Value::as_str).unwrap_or("?").to_owned();
        let slice = Slice {
            dof: text("dof"),
            unit: text("unit"),
            offsets: array("offsets")?,
            mi: array("mi")?,
            quadratic: array("quadratic").unwrap_or_default(),
            peak: num(v.get("peak_offset")),
        };
        (slice.offsets.len() == slice.mi.len() && slice.offsets.len() >= 2).then_some(slice)
    }
}

/// The six MI slices in a 3 x 2 grid of panels; `None` when the report has none.
pub fn mi_slices(report: &Value) -> Option<String> {
    let slices: Vec<Slice> = report
        .get("mi_slices")?
        .as_array()?
        .iter()
        .filter_map(Slice::read)
        .collect();
    if slices.is_empty() {
        return None;
    }
    let (w, ph) = (440.0, 180.0);
    let rows = slices.len().div_ceil(2);
    let mut out = String::new();
    svg::open(
        &mut out,
        "fig-mi-slices",
        2.0 * w,
        rows as f64 * ph + 24.0,
        "MI slices through the estimate",
    );
    for (i, s) in slices.iter().enumerate() {
        let origin = (w * (i % 2) as f64, ph * (i / 2) as f64);
        if let Some(panel) = slice_panel(s, origin, (w, ph)) {
            draw(&mut out, &panel, s, i);
        }
    }
    svg::legend(
        &mut out,
        2.0 * w - 10.0,
        rows as f64 * ph + 16.0,
        &[
            (BLUE, "smoothed MI"),
            (GREY, "refinement's curvature"),
            (RED, "slice peak"),
        ],
    );
    out.push_str("</svg>");
    Some(out)
}

/// x over the offsets; y over the MI curve with a margin (the parabola is clipped, so
/// its far tails do not flatten the curve).
fn slice_panel(s: &Slice, (x0, y0): (f64, f64), (width, height): (f64, f64)) -> Option<Panel> {
    let x = range_of(s.offsets.iter().copied())?;
    let (lo, hi) = range_of(s.mi.iter().copied())?;
    let margin = 0.15 * (hi - lo).max(1e-9);
    Some(Panel {
        x0,
        y0,
        width,
        height,
        x,
        y: (lo - margin, hi + margin),
    })
}

fn draw(out: &mut String, panel: &Panel, s: &Slice, i: usize) {
    panel.open_clip(out, &format!("clip-mi-slice-{i}"));
    if s.quadratic.len() == s.offsets.len() {
        let parabola: Vec<(f64, f64)> = s
            .offsets
            .iter()
            .copied()
            .zip(s.quadratic.iter().copied())
            .collect();
        panel.line(out, &parabola, GREY, 1.2);
    }
    let curve: Vec<(f64, f64)> = s
        .offsets
        .iter()
        .copied()
        .zip(s.mi.iter().copied())
        .collect();
    panel.line(out, &curve, BLUE, 1.6);
    if s.peak.is_finite() {
        panel.line(out, &[(s.peak, panel.y.0), (s.peak, panel.y.1)], RED, 1.0);
    }
    out.push_str("</g>");
    panel.axes(
        out,
        &format!("{} (MI, nats)", s.dof),
        &format!("offset from the estimate, {}", s.unit),
    );
}

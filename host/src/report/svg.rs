//! Inline SVG primitives for the HTML report: a panel with linear axes, lines, bands,
//! markers and bars. Pure string building; no script, no external resource.

use std::fmt::Write;

/// Width of the plot area's left margin (tick labels), px.
const LEFT: f64 = 58.0;
/// Bottom margin (tick labels and axis title), px.
const BOTTOM: f64 = 34.0;
/// Top margin (panel title), px.
const TOP: f64 = 22.0;
/// Right margin, px.
const RIGHT: f64 = 12.0;

/// Escapes text for HTML/SVG content and attribute values.
pub fn escape(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&#39;"),
            c => out.push(c),
        }
    }
    out
}

/// A finite `[lo, hi]` range with `hi > lo` (widened around a single value).
pub fn range_of<I: IntoIterator<Item = f64>>(values: I) -> Option<(f64, f64)> {
    let (lo, hi) = values
        .into_iter()
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
            (lo.min(v), hi.max(v))
        });
    if lo > hi {
        return None;
    }
    let pad = if hi > lo {
        0.0
    } else {
        lo.abs().max(1e-9) * 0.1
    };
    Some((lo - pad, hi + pad))
}

/// "Nice" tick positions (steps of 1, 2 or 5 times a power of ten) covering `[lo, hi]`.
pub fn ticks(lo: f64, hi: f64, target: usize) -> Vec<f64> {
    let span = hi - lo;
    if !(span.is_finite() && span > 0.0) {
        return vec![lo];
    }
    let raw = span / target.max(1) as f64;
    let magnitude = 10f64.powf(raw.log10().floor());
    let step = [1.0, 2.0, 5.0, 10.0]
        .iter()
        .map(|m| m * magnitude)
        .find(|s| *s >= raw)
        .unwrap_or(10.0 * magnitude);
    let first = (lo / step).ceil() as i64;
    let last = (hi / step).floor() as i64;
    (first..=last).map(|i| i as f64 * step).collect()
}

/// Formats a tick label compactly.
pub fn label(v: f64) -> String {
    let a = v.abs();
    if a == 0.0 {
        "0".into()
    } else if !(1e-3..1e5).contains(&a) {
        format!("{v:.1e}")
    } else {
        let s = format!("{v:.4}");
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    }
}

/// One panel: a rectangle of the SVG with data ranges mapped onto its plot area.
#[derive(Clone, Copy, Debug)]
pub struct Panel {
    /// Left edge of the panel in the SVG, px.
    pub x0: f64,
    /// Top edge of the panel in the SVG, px.
    pub y0: f64,
    /// Panel width, px.
    pub width: f64,
    /// Panel height, px.
    pub height: f64,
    /// Data range along x.
    pub x: (f64, f64),
    /// Data range along y.
    pub y: (f64, f64),
}

impl Panel {
    /// Pixel x of data `x`.
    pub fn px(&self, x: f64) -> f64 {
        let (lo, hi) = self.x;
        self.x0 + LEFT + (x - lo) / (hi - lo) * (self.width - LEFT - RIGHT)
    }

    /// Pixel y of data `y` (up is larger).
    pub fn py(&self, y: f64) -> f64 {
        let (lo, hi) = self.y;
        self.y0 + self.height - BOTTOM - (y - lo) / (hi - lo) * (self.height - TOP - BOTTOM)
    }

    fn plot_area(&self) -> (f64, f64, f64, f64) {
        (
            self.x0 + LEFT,
            self.y0 + TOP,
            self.width - LEFT - RIGHT,
            self.height - TOP - BOTTOM,
        )
    }

    /// A panel at `(x0, y0)`, `width` wide, whose data ranges cover `x` and `y` at one
    /// scale on both axes (a map): as tall as that makes it, at most `max_height` (the x
    /// range then widens).
    pub fn equal_aspect(
        (x0, y0): (f64, f64),
        width: f64,
        max_height: f64,
        x: (f64, f64),
        y: (f64, f64),
    ) -> Panel {
        let (plot_w, max_plot_h) = (width - LEFT - RIGHT, max_height - TOP - BOTTOM);
        let px_per_unit = (plot_w / (x.1 - x.0)).min(max_plot_h / (y.1 - y.0));
        let half_x = 0.5 * plot_w / px_per_unit;
        let mid_x = 0.5 * (x.0 + x.1);
        Panel {
            x0,
            y0,
            width,
            height: (y.1 - y.0) * px_per_unit + TOP + BOTTOM,
            x: (mid_x - half_x, mid_x + half_x),
            y,
        }
    }

    /// Opens a group clipped to the plot area; `clip_id` must be unique in the page.
    pub fn open_clip(&self, out: &mut String, clip_id: &str) {
        let (x, y, w, h) = self.plot_area();
        let _ = write!(
            out,
            r#"<clipPath id="{clip_id}"><rect x="{x:.1}" y="{y:.1}" width="{w:.1}" height="{h:.1}"/></clipPath><g clip-path="url(#{clip_id})">"#
        );
    }

    /// The frame, ticks, tick labels, title and x-axis title.
    pub fn axes(&self, out: &mut String, title: &str, x_title: &str) {
        self.frame(out, title, x_title, (true, false));
    }

    /// [`Panel::axes`] for a panel whose y is `log10` of the quantity: decade ticks
    /// labelled with the quantity.
    pub fn axes_log_y(&self, out: &mut String, title: &str, x_title: &str) {
        self.frame(out, title, x_title, (true, true));
    }

    /// [`Panel::axes`] without x ticks (categories labelled by the caller).
    pub fn axes_categorical(&self, out: &mut String, title: &str, x_title: &str) {
        self.frame(out, title, x_title, (false, false));
    }

    fn frame(&self, out: &mut String, title: &str, x_title: &str, (x_ticks, y_log): (bool, bool)) {
        let (x, y, w, h) = self.plot_area();
        let _ = write!(
            out,
            r##"<rect class="frame" x="{x:.1}" y="{y:.1}" width="{w:.1}" height="{h:.1}" fill="none" stroke="#888"/>"##
        );
        let x_tick_values = if x_ticks {
            ticks(self.x.0, self.x.1, 5)
        } else {
            Vec::new()
        };
        for t in x_tick_values {
            let px = self.px(t);
            let _ = write!(
                out,
                r##"<line x1="{px:.1}" y1="{:.1}" x2="{px:.1}" y2="{:.1}" stroke="#888"/><text x="{px:.1}" y="{:.1}" text-anchor="middle" font-size="10">{}</text>"##,
                y + h,
                y + h + 4.0,
                y + h + 14.0,
                label(t)
            );
        }
        let y_ticks: Vec<f64> = if y_log {
            (self.y.0.ceil() as i64..=self.y.1.floor() as i64)
                .map(|d| d as f64)
                .collect()
        } else {
            ticks(self.y.0, self.y.1, 4)
        };
        for t in y_ticks {
            let py = self.py(t);
            let _ = write!(
                out,
                r##"<line x1="{:.1}" y1="{py:.1}" x2="{x:.1}" y2="{py:.1}" stroke="#888"/><line x1="{x:.1}" y1="{py:.1}" x2="{:.1}" y2="{py:.1}" stroke="#eee"/><text x="{:.1}" y="{:.1}" text-anchor="end" font-size="10">{}</text>"##,
                x - 4.0,
                x + w,
                x - 6.0,
                py + 3.5,
                label(if y_log { 10f64.powf(t) } else { t })
            );
        }
        let _ = write!(
            out,
            r#"<text x="{x:.1}" y="{:.1}" font-size="12" font-weight="bold">{}</text><text x="{:.1}" y="{:.1}" text-anchor="middle" font-size="10">{}</text>"#,
            self.y0 + 15.0,
            escape(title),
            x + w / 2.0,
            y + h + 28.0,
            escape(x_title)
        );
    }

    /// The `points` attribute of the finite points, in pixels (empty when none).
    fn points_attr<'a, I: IntoIterator<Item = (&'a f64, &'a f64)>>(&self, points: I) -> String {
        let mut d = String::new();
        for (&x, &y) in points
            .into_iter()
            .filter(|(x, y)| x.is_finite() && y.is_finite())
        {
            let _ = write!(d, "{:.1},{:.1} ", self.px(x), self.py(y));
        }
        d.trim_end().to_string()
    }

    /// A polyline through the finite points.
    pub fn line(&self, out: &mut String, points: &[(f64, f64)], stroke: &str, width: f64) {
        let d = self.points_attr(points.iter().map(|(x, y)| (x, y)));
        if !d.is_empty() {
            let _ = write!(
                out,
                r#"<polyline points="{d}" fill="none" stroke="{stroke}" stroke-width="{width}"/>"#
            );
        }
    }

    /// A filled band between `lower` and `upper` at the same x.
    pub fn band(&self, out: &mut String, xs: &[f64], lower: &[f64], upper: &[f64], fill: &str) {
        let d = self.points_attr(xs.iter().zip(upper).chain(xs.iter().zip(lower).rev()));
        if !d.is_empty() {
            let _ = write!(
                out,
                r#"<polygon class="band" points="{d}" fill="{fill}" stroke="none"/>"#
            );
        }
    }

    /// A closed polygon through the finite points.
    pub fn polygon(&self, out: &mut String, points: &[(f64, f64)], fill: &str, stroke: &str) {
        let d = self.points_attr(points.iter().map(|(x, y)| (x, y)));
        if !d.is_empty() {
            let _ = write!(
                out,
                r#"<polygon points="{d}" fill="{fill}" stroke="{stroke}" stroke-width="0.8"/>"#
            );
        }
    }

    /// Small circles at the points.
    pub fn dots(&self, out: &mut String, points: &[(f64, f64)], fill: &str, radius: f64) {
        for &(x, y) in points
            .iter()
            .filter(|(x, y)| x.is_finite() && y.is_finite())
        {
            let _ = write!(
                out,
                r#"<circle cx="{:.1}" cy="{:.1}" r="{radius}" fill="{fill}"/>"#,
                self.px(x),
                self.py(y)
            );
        }
    }

    /// A vertical bar from y = 0 (or the range floor) to `y` over `[x_lo, x_hi]`.
    pub fn bar(&self, out: &mut String, (x_lo, x_hi): (f64, f64), y: f64, fill: &str) {
        let base = self.py(0f64.max(self.y.0));
        let top = self.py(y.min(self.y.1));
        let (l, r) = (self.px(x_lo), self.px(x_hi));
        let _ = write!(
            out,
            r#"<rect class="bar" x="{:.1}" y="{:.1}" width="{:.1}" height="{:.1}" fill="{fill}"/>"#,
            l.min(r),
            top.min(base),
            (r - l).abs(),
            (base - top).abs()
        );
    }

    /// Text at data coordinates.
    pub fn text(&self, out: &mut String, (x, y): (f64, f64), text: &str, anchor: &str) {
        let _ = write!(
            out,
            r#"<text x="{:.1}" y="{:.1}" text-anchor="{anchor}" font-size="10">{}</text>"#,
            self.px(x),
            self.py(y),
            escape(text)
        );
    }
}

/// Opens an `<svg>` element of the given id and size.
pub fn open(out: &mut String, id: &str, width: f64, height: f64, caption: &str) {
    let _ = write!(
        out,
        r#"<svg id="{id}" class="figure" xmlns="http://www.w3.org/2000/svg" width="{width:.0}" height="{height:.0}" viewBox="0 0 {width:.0} {height:.0}" role="img" aria-label="{}">"#,
        escape(caption)
    );
}

/// Legend entries (colour, text) in one row at the panel's top right.
pub fn legend(out: &mut String, x_right: f64, y: f64, entries: &[(&str, &str)]) {
    let mut x = x_right;
    for (colour, text) in entries.iter().rev() {
        x -= 8.0 + 6.0 * text.len() as f64;
        let _ = write!(
            out,
            r#"<rect x="{:.1}" y="{:.1}" width="8" height="8" fill="{colour}"/><text x="{:.1}" y="{:.1}" font-size="10">{}</text>"#,
            x - 11.0,
            y - 8.0,
            x,
            y,
            escape(text)
        );
        x -= 16.0;
    }
}

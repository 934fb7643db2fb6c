//! Printable calibration targets (`msreg target`): an SVG at exact physical size (width and
//! height in millimetres, a viewBox in millimetres, so one user unit is one millimetre on
//! paper), with a quiet white border around the pattern and a caption with its parameters.
//!
//! - Checkerboard (Kalibr): `rows x cols` inner corners, so `(rows + 1) x (cols + 1)`
//!   squares; the square at the top-left of the sheet is black, which is the detector's id
//!   rule (the square between corners 0, 1, cols, cols + 1 is dark; docs/checkerboard.md).
//!   Target x runs down the sheet (rows, `rowSpacingMeters`), y to the right (columns,
//!   `colSpacingMeters`), corner 0 at the top-left inner corner.
//! - AprilGrid (Kalibr): `tagCols x tagRows` tag36h11 tags of side `tagSize`, `tagSpacing`
//!   of it apart, drawn as [`crate::vision::aprilgrid::pattern`] describes (2-bit black
//!   border, 6 x 6 data bits, black squares in every gap at the tag corners); tag 0 at the
//!   lower-left, target x right and y up the sheet. Each tag is one path (its outline and
//!   its white bits as holes, even-odd fill), so no seam shows between neighbouring cells.
//!
//! A page size puts the pattern in the middle of an A4 / A3 / Letter sheet (portrait, or
//! landscape when only that fits) and fails when it does not fit; `Auto` makes the sheet the
//! pattern plus its border and caption. PDF is not written: see docs/target.md.

use std::fmt::Write as _;

use crate::camera_yaml::{AprilGridTarget, CheckerboardTarget};
use crate::vision::aprilgrid::tag36h11_code;

/// Height reserved below the pattern for the caption, mm.
const CAPTION_MM: f64 = 9.0;
/// Caption font size, mm.
const FONT_MM: f64 = 3.2;

/// A target to print.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum PrintTarget {
    /// A Kalibr checkerboard.
    Checkerboard(CheckerboardTarget),
    /// A Kalibr AprilGrid.
    AprilGrid(AprilGridTarget),
}

/// The sheet.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Page {
    /// 210 x 297 mm.
    A4,
    /// 297 x 420 mm.
    A3,
    /// 8.5 x 11 in (215.9 x 279.4 mm).
    Letter,
    /// The pattern, its border and the caption.
    Auto,
}

impl Page {
    /// Portrait width and height, mm (`None` for [`Page::Auto`]).
    pub fn size_mm(self) -> Option<[f64; 2]> {
        match self {
            Page::A4 => Some([210.0, 297.0]),
            Page::A3 => Some([297.0, 420.0]),
            Page::Letter => Some([215.9, 279.4]),
            Page::Auto => None,
        }
    }
}

/// Why a target cannot be drawn.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum TargetSvgError {
    /// A size or count is out of range.
    #[error("invalid target: {0}")]
    Invalid(String),
    /// The pattern with its border does not fit the page.
    #[error(
        "the target needs {needed_mm:.1} x {needed_mm_h:.1} mm with its border and caption, \
         more than the {page:?} page in either orientation (use a larger --page or auto)"
    )]
    DoesNotFit {
        /// Width needed, mm.
        needed_mm: f64,
        /// Height needed, mm.
        needed_mm_h: f64,
        /// The page.
        page: Page,
    },
}

/// A drawn target.
#[derive(Clone, Debug, PartialEq)]
pub struct TargetSheet {
    /// The SVG document.
    pub svg: String,
    /// Sheet width, mm.
    pub width_mm: f64,
    /// Sheet height, mm.
    pub height_mm: f64,
}

/// The black shapes of a pattern, in mm from the pattern's top-left: rectangles
/// `[x, y, w, h]` and tags (outline square `[x, y, side]` with white cells as holes).
struct Ink {
    size_mm: [f64; 2],
    rects: Vec<[f64; 4]>,
    tags: Vec<([f64; 3], Vec<[f64; 4]>)>,
    caption: String,
}

fn checkerboard_ink(t: &CheckerboardTarget) -> Result<Ink, TargetSvgError> {
    if t.rows < 3 || t.cols < 3 || !(t.row_spacing_m > 0.0 && t.col_spacing_m > 0.0) {
        return Err(TargetSvgError::Invalid(
            "a checkerboard needs at least 3 x 3 inner corners and positive squares".into(),
        ));
    }
    let (sh, sw) = (t.row_spacing_m * 1e3, t.col_spacing_m * 1e3);
    let mut rects = Vec::new();
    for i in 0..=t.rows {
        for j in 0..=t.cols {
            if (i + j) % 2 == 0 {
                rects.push([j as f64 * sw, i as f64 * sh, sw, sh]);
            }
        }
    }
    let square = if (sw - sh).abs() <= f64::EPSILON * sw.abs().max(sh.abs()) {
        format!("squares {} mm", fmt(sw))
    } else {
        format!("squares {} mm wide, {} mm high", fmt(sw), fmt(sh))
    };
    Ok(Ink {
        size_mm: [(t.cols + 1) as f64 * sw, (t.rows + 1) as f64 * sh],
        rects,
        tags: Vec::new(),
        caption: format!(
            "Kalibr checkerboard: targetRows {} x targetCols {} inner corners, {square}. \
             Print at 100 %.",
            t.rows, t.cols
        ),
    })
}

fn aprilgrid_ink(t: &AprilGridTarget) -> Result<Ink, TargetSvgError> {
    if t.tag_cols < 1
        || t.tag_rows < 1
        || t.tag_cols * t.tag_rows > 587
        || !(t.tag_size_m > 0.0 && t.tag_spacing > 0.0 && t.tag_spacing.is_finite())
    {
        return Err(TargetSvgError::Invalid(
            "an aprilgrid needs 1 to 587 tags, a positive tag size and spacing".into(),
        ));
    }
    let s = t.tag_size_m * 1e3;
    let gap = s * t.tag_spacing;
    let pitch = s + gap;
    let (cols, rows) = (t.tag_cols, t.tag_rows);
    let size_mm = [cols as f64 * pitch + gap, rows as f64 * pitch + gap];
    // Sheet y of the target-frame y (up): the pattern's bottom edge is at size_mm[1].
    let sheet_y = |y: f64| size_mm[1] - gap - y;
    let mut rects = Vec::new();
    for i in 0..=rows {
        for j in 0..=cols {
            let (x, y) = (j as f64 * pitch, sheet_y(i as f64 * pitch - gap));
            rects.push([x, y - gap, gap, gap]);
        }
    }
    let bit = s / 10.0;
    let mut tags = Vec::new();
    for id in 0..cols * rows {
        let (col, row) = ((id % cols) as f64, (id / cols) as f64);
        let (x0, top) = (gap + col * pitch, sheet_y(row * pitch + s));
        let code = tag36h11_code(id).unwrap_or(0);
        let mut holes = Vec::new();
        for r in 0..6 {
            for c in 0..6 {
                if (code >> (35 - (6 * r + c))) & 1 == 1 {
                    let (x, y) = (x0 + (c + 2) as f64 * bit, top + (r + 2) as f64 * bit);
                    holes.push([x, y, bit, bit]);
                }
            }
        }
        tags.push(([x0, top, s], holes));
    }
    Ok(Ink {
        size_mm,
        rects,
        tags,
        caption: format!(
            "Kalibr aprilgrid (tag36h11, tags 0-{}): tagCols {cols} x tagRows {rows}, tagSize {} \
             mm, tagSpacing {} ({} mm gaps). Print at 100 %.",
            cols * rows - 1,
            fmt(s),
            fmt(t.tag_spacing),
            fmt(gap)
        ),
    })
}

/// Shortest exact decimal of `x` (mm).
fn fmt(x: f64) -> String {
    let s = format!("{x}");
    if s == "-0" {
        "0".into()
    } else {
        s
    }
}

/// The sheet size and the pattern's top-left on it, mm.
fn layout(ink: &Ink, border_mm: f64, page: Page) -> Result<([f64; 2], [f64; 2]), TargetSvgError> {
    let need = [
        ink.size_mm[0] + 2.0 * border_mm,
        ink.size_mm[1] + 2.0 * border_mm + CAPTION_MM,
    ];
    let Some([pw, ph]) = page.size_mm() else {
        return Ok((need, [border_mm, border_mm]));
    };
    let sheet = [[pw, ph], [ph, pw]]
        .into_iter()
        .find(|s| need[0] <= s[0] && need[1] <= s[1])
        .ok_or(TargetSvgError::DoesNotFit {
            needed_mm: need[0],
            needed_mm_h: need[1],
            page,
        })?;
    let origin = [
        0.5 * (sheet[0] - ink.size_mm[0]),
        0.5 * (sheet[1] - CAPTION_MM - ink.size_mm[1]),
    ];
    Ok((sheet, origin))
}

/// Draws `target` on `page` with a white border of `border_mm` around the pattern.
pub fn target_svg(
    target: &PrintTarget,
    page: Page,
    border_mm: f64,
) -> Result<TargetSheet, TargetSvgError> {
    if !(border_mm.is_finite() && border_mm >= 0.0) {
        return Err(TargetSvgError::Invalid("the border must be >= 0 mm".into()));
    }
    let ink = match target {
        PrintTarget::Checkerboard(t) => checkerboard_ink(t)?,
        PrintTarget::AprilGrid(t) => aprilgrid_ink(t)?,
    };
    let ([w, h], [ox, oy]) = layout(&ink, border_mm, page)?;
    let mut svg = String::new();
    // Writing to a String cannot fail.
    let _ = write!(
        svg,
        "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n\
         <svg xmlns=\"http://www.w3.org/2000/svg\" version=\"1.1\" width=\"{w}mm\" \
         height=\"{h}mm\" viewBox=\"0 0 {w} {h}\">\n\
         <rect id=\"paper\" x=\"0\" y=\"0\" width=\"{w}\" height=\"{h}\" fill=\"#ffffff\"/>\n\
         <g id=\"pattern\" fill=\"#000000\" stroke=\"none\">\n",
        w = fmt(w),
        h = fmt(h)
    );
    for [x, y, rw, rh] in &ink.rects {
        let _ = writeln!(
            svg,
            "<rect x=\"{}\" y=\"{}\" width=\"{}\" height=\"{}\"/>",
            fmt(ox + x),
            fmt(oy + y),
            fmt(*rw),
            fmt(*rh)
        );
    }
    for ([x, y, s], holes) in &ink.tags {
        let mut d = square_path(ox + x, oy + y, *s, *s);
        for [hx, hy, hw, hh] in holes {
            d.push(' ');
            d.push_str(&square_path(ox + hx, oy + hy, *hw, *hh));
        }
        let _ = writeln!(svg, "<path fill-rule=\"evenodd\" d=\"{d}\"/>");
    }
    let _ = write!(
        svg,
        "</g>\n<text x=\"{}\" y=\"{}\" font-family=\"sans-serif\" font-size=\"{FONT_MM}\" \
         fill=\"#000000\">{}</text>\n</svg>\n",
        fmt(ox),
        fmt(oy + ink.size_mm[1] + border_mm + FONT_MM + 1.0),
        ink.caption
    );
    Ok(TargetSheet {
        svg,
        width_mm: w,
        height_mm: h,
    })
}

/// An axis-aligned rectangle as an absolute path: `M x y H x+w V y+h H x Z`.
fn square_path(x: f64, y: f64, w: f64, h: f64) -> String {
    format!(
        "M{} {}H{}V{}H{}Z",
        fmt(x),
        fmt(y),
        fmt(x + w),
        fmt(y + h),
        fmt(x)
    )
}

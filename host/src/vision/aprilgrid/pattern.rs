//! The printed AprilGrid as Kalibr's `kalibr_create_target_pdf` draws it (aslam_cv's
//! `createTargetPDF.py`), for the renderer: target frame x right, y up on the sheet, z out of
//! the printed face. Tag `i` (column `i % tag_cols`, row `i / tag_cols`) has its lower-left
//! corner at `(column, row) * tag_size * (1 + tag_spacing)`. A tag of side `s` is 10 bits of
//! `s / 10`: a 2-bit black border around 6 x 6 data bits; the data cell in row `r` from the
//! top and column `c` from the left shows bit `35 - (6 r + c)` of the tag36h11 code, black
//! where the bit is 0. Black squares of side `tag_spacing * s` fill the gaps at every tag
//! corner, so each tag corner is a saddle point (Kalibr: "symmetric corners").

use super::tag36h11_code;
use crate::camera_yaml::AprilGridTarget;
use crate::vision::render::{Class, PrintedTarget};

/// Bits across a tag: 6 data bits and a 2-bit black border on each side.
const TAG_BITS: f64 = 10.0;

/// An AprilGrid on a white sheet.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AprilGridPattern {
    /// The grid (Kalibr `target.yaml`).
    pub target: AprilGridTarget,
    /// White margin around the outer corner squares, metres.
    pub margin_m: f64,
}

impl AprilGridPattern {
    /// Side of the corner squares (the gap between tags), metres.
    fn gap(&self) -> f64 {
        self.target.tag_size_m * self.target.tag_spacing
    }

    /// Distance between neighbouring tags' lower-left corners, metres.
    fn pitch(&self) -> f64 {
        self.target.tag_size_m + self.gap()
    }

    /// The class of point `(u, v)` (metres from the lower-left corner) of tag `id`.
    fn tag_class(&self, id: usize, u: f64, v: f64) -> Class {
        let bit = self.target.tag_size_m / TAG_BITS;
        let (bx, by) = ((u / bit).floor() as i64, (v / bit).floor() as i64);
        if !(2..8).contains(&bx) || !(2..8).contains(&by) {
            return Class::Dark;
        }
        let (row_from_top, col) = (7 - by, bx - 2);
        let index = 35 - (6 * row_from_top + col);
        match tag36h11_code(id) {
            Some(code) if (code >> index) & 1 == 1 => Class::Light,
            _ => Class::Dark,
        }
    }
}

impl PrintedTarget for AprilGridPattern {
    fn class(&self, x: f64, y: f64) -> Class {
        let [x0, x1, y0, y1] = self.outline();
        if !(x >= x0 && x < x1 && y >= y0 && y < y1) {
            return Class::Background;
        }
        let (pitch, s) = (self.pitch(), self.target.tag_size_m);
        let (col, row) = ((x / pitch).floor(), (y / pitch).floor());
        let (u, v) = (x - col * pitch, y - row * pitch);
        let (cols, rows) = (self.target.tag_cols as f64, self.target.tag_rows as f64);
        let in_tag_x = u < s && (0.0..cols).contains(&col);
        let in_tag_y = v < s && (0.0..rows).contains(&row);
        let in_gap_x = u >= s && (-1.0..cols).contains(&col);
        let in_gap_y = v >= s && (-1.0..rows).contains(&row);
        if in_tag_x && in_tag_y {
            let id = row as usize * self.target.tag_cols + col as usize;
            self.tag_class(id, u, v)
        } else if in_gap_x && in_gap_y {
            Class::Dark
        } else {
            Class::Light
        }
    }

    fn outline(&self) -> [f64; 4] {
        let (q, m, p) = (self.gap(), self.margin_m, self.pitch());
        [
            -q - m,
            self.target.tag_cols as f64 * p + m,
            -q - m,
            self.target.tag_rows as f64 * p + m,
        ]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid() -> AprilGridPattern {
        AprilGridPattern {
            target: AprilGridTarget {
                tag_cols: 2,
                tag_rows: 2,
                tag_size_m: 0.1,
                tag_spacing: 0.3,
            },
            margin_m: 0.02,
        }
    }

    #[test]
    fn borders_corner_squares_and_paper_are_where_kalibr_draws_them() {
        let g = grid();
        // Black border of tag 0, just inside its lower-left corner.
        assert_eq!(g.class(0.005, 0.005), Class::Dark);
        // Corner squares: outer lower-left, between the four tags, outer upper-right.
        assert_eq!(g.class(-0.015, -0.015), Class::Dark);
        assert_eq!(g.class(0.115, 0.115), Class::Dark);
        assert_eq!(g.class(0.245, 0.245), Class::Dark);
        // Gap between tags 0 and 1 beside the tags (paper), margin, and off the sheet.
        assert_eq!(g.class(0.115, 0.05), Class::Light);
        assert_eq!(g.class(-0.035, 0.05), Class::Light);
        assert_eq!(g.class(-0.06, 0.05), Class::Background);
    }

    #[test]
    fn data_bits_follow_the_code_msb_at_the_top_left() {
        let g = grid();
        let code = tag36h11_code(3).unwrap();
        let (x0, y0) = (g.pitch(), g.pitch());
        let bit = 0.01;
        for r in 0..6 {
            for c in 0..6 {
                let (u, v) = ((c as f64 + 2.5) * bit, (7.0 - r as f64 + 0.5) * bit);
                let white = (code >> (35 - (6 * r + c))) & 1 == 1;
                let expected = if white { Class::Light } else { Class::Dark };
                assert_eq!(g.class(x0 + u, y0 + v), expected, "row {r} col {c}");
            }
        }
    }
}

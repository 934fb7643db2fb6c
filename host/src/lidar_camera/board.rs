//! The plain rectangular board of `target.yaml` (`target_type: board`): origin at its
//! centre, x along `width_m`, y along `height_m`, z towards the viewer (CONVENTIONS.md).

use nalgebra::Vector3;

/// A plain rectangle of known size.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Board {
    /// Extent along target x, m.
    pub width_m: f64,
    /// Extent along target y, m.
    pub height_m: f64,
}

impl Board {
    /// Corners in the target frame, counter-clockwise seen from +z:
    /// `(-w/2, -h/2), (w/2, -h/2), (w/2, h/2), (-w/2, h/2)`. Edge `j` runs from corner `j`
    /// to corner `j + 1 (mod 4)`.
    pub fn corners(&self) -> [Vector3<f64>; 4] {
        let (x, y) = (0.5 * self.width_m, 0.5 * self.height_m);
        [
            Vector3::new(-x, -y, 0.0),
            Vector3::new(x, -y, 0.0),
            Vector3::new(x, y, 0.0),
            Vector3::new(-x, y, 0.0),
        ]
    }

    /// True when `(x, y)` of the board plane is on the board.
    pub fn contains(&self, x: f64, y: f64) -> bool {
        x.abs() <= 0.5 * self.width_m && y.abs() <= 0.5 * self.height_m
    }

    /// Length of the diagonal, m.
    pub fn diagonal(&self) -> f64 {
        self.width_m.hypot(self.height_m)
    }
}

//! Scenes of solid axis-aligned boxes and the ray caster through them: the rooms of the
//! LiDAR-IMU simulator ([`super::Environment`]) and, with [`BoxWorld::scan`] (a still
//! spinning-LiDAR scan, no motion, no noise model beyond an optional deterministic range
//! jitter), the scenes of the NDT tests and benchmarks.

use nalgebra::{Isometry3, Vector3};

/// A scene of solid axis-aligned boxes (walls are thin boxes).
#[derive(Debug, Clone, PartialEq)]
pub struct BoxWorld {
    /// `(min corner, max corner)` of each box, m.
    pub boxes: Vec<(Vector3<f64>, Vector3<f64>)>,
}

fn slab(min: [f64; 3], max: [f64; 3]) -> (Vector3<f64>, Vector3<f64>) {
    (Vector3::from(min), Vector3::from(max))
}

impl BoxWorld {
    /// A 20 x 12 x 4 m room (floor at z = 0) with boxes and pillars: well
    /// constrained in all 6 DoF.
    pub fn indoor() -> Self {
        let w = 0.2;
        Self {
            boxes: vec![
                slab([-10.0, -6.0, -w], [10.0, 6.0, 0.0]),
                slab([-10.0, -6.0, 4.0], [10.0, 6.0, 4.0 + w]),
                slab([-10.0 - w, -6.0, 0.0], [-10.0, 6.0, 4.0]),
                slab([10.0, -6.0, 0.0], [10.0 + w, 6.0, 4.0]),
                slab([-10.0, -6.0 - w, 0.0], [10.0, -6.0, 4.0]),
                slab([-10.0, 6.0, 0.0], [10.0, 6.0 + w, 4.0]),
                slab([2.5, 1.5, 0.0], [3.7, 3.0, 1.0]),
                slab([-4.5, -3.5, 0.0], [-2.5, -2.6, 2.0]),
                slab([0.8, -2.3, 0.0], [1.2, -1.9, 4.0]),
                slab([-6.3, 2.7, 0.0], [-5.7, 3.3, 4.0]),
                slab([5.0, -4.0, 0.0], [6.5, -3.0, 1.4]),
                slab([-1.0, 3.8, 0.0], [0.5, 6.0, 2.2]),
            ],
        }
    }

    /// A 200 m corridor: two parallel walls 3 m apart along x and a floor,
    /// nothing else (translation along x is unobservable).
    pub fn corridor() -> Self {
        Self {
            boxes: vec![
                slab([-100.0, -1.5, -0.2], [100.0, 1.5, 0.0]),
                slab([-100.0, -1.7, 0.0], [100.0, -1.5, 3.0]),
                slab([-100.0, 1.5, 0.0], [100.0, 1.7, 3.0]),
            ],
        }
    }

    /// Range along the unit ray `origin + s dir` to the first box surface.
    pub fn cast(&self, origin: &Vector3<f64>, dir: &Vector3<f64>) -> Option<f64> {
        self.first_hit(origin, dir).map(|(range, _, _)| range)
    }

    /// First hit along the unit ray `origin + s dir` (`s > 0`): range, index of the box and
    /// the axis of the surface normal (slab method; the first box wins a tie).
    pub fn first_hit(
        &self,
        origin: &Vector3<f64>,
        dir: &Vector3<f64>,
    ) -> Option<(f64, usize, usize)> {
        let mut best: Option<(f64, usize, usize)> = None;
        for (index, (lo, hi)) in self.boxes.iter().enumerate() {
            let mut enter = f64::NEG_INFINITY;
            let mut exit = f64::INFINITY;
            let mut axis = 0;
            for k in 0..3 {
                let inv = 1.0 / dir[k];
                let (a, b) = ((lo[k] - origin[k]) * inv, (hi[k] - origin[k]) * inv);
                let near = a.min(b);
                if near > enter {
                    enter = near;
                    axis = k;
                }
                exit = exit.min(a.max(b));
            }
            if enter <= exit && enter > 0.0 && best.is_none_or(|(r, _, _)| enter < r) {
                best = Some((enter, index, axis));
            }
        }
        best
    }

    /// A spinning-LiDAR scan from `t_world_sensor`: `rings` beams spread
    /// uniformly over +-22.5 deg elevation (Ouster OS1), `columns` azimuths,
    /// returns beyond `max_range` dropped; points in the sensor frame, each
    /// range perturbed by a deterministic pseudo-random `+-jitter_m`.
    pub fn scan(
        &self,
        t_world_sensor: &Isometry3<f64>,
        rings: usize,
        columns: usize,
        max_range: f64,
        jitter_m: f64,
    ) -> Vec<Vector3<f64>> {
        let origin = t_world_sensor.translation.vector;
        let mut out = Vec::with_capacity(rings * columns);
        let mut state = 0x2545_F491_4F6C_DD1Du64;
        for c in 0..columns {
            let az = std::f64::consts::TAU * c as f64 / columns as f64;
            for r in 0..rings {
                let el = (-22.5 + 45.0 * r as f64 / (rings.max(2) - 1) as f64).to_radians();
                let dir_s = Vector3::new(el.cos() * az.cos(), el.cos() * az.sin(), el.sin());
                let dir_w = t_world_sensor.rotation * dir_s;
                state ^= state << 13;
                state ^= state >> 7;
                state ^= state << 17;
                let u = (state >> 11) as f64 / (1u64 << 53) as f64;
                if let Some(range) = self.cast(&origin, &dir_w).filter(|&s| s <= max_range) {
                    out.push(dir_s * (range + jitter_m * (2.0 * u - 1.0)));
                }
            }
        }
        out
    }
}

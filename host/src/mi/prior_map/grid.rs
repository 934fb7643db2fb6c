//! The score of the prior-map grid: hard-binned MI of the map points against the blurred
//! fisheye image at `T_world_cam = grid_pose(start, [x, y, z, yaw])`, the same score as
//! [`MiScene::hard_serial`] in single precision. The per-point work is precomputed (the
//! points relative to the start position in f32, their value bins, the camera in f32, the
//! equalised and blurred image in 16 bits: quantisation 1.5e-5 of the range, far below a
//! bin), and candidates are scored in groups, the points in chunks of image rows: each
//! chunk's part of the image is read once from memory for the whole group instead of once
//! per candidate (the image is larger than the L2 cache; docs/benchmarks.md).

use msreg_estimator::camera::Camera;
use nalgebra::{Isometry3, Matrix3, UnitQuaternion, Vector3};
use rayon::prelude::*;

use crate::mi::histogram::score_of;
use crate::mi::scene::{equalize, MiScene};
use crate::vision::GrayImage;

/// Candidates scored together.
const GROUP: usize = 16;
/// Points per chunk (consecutive in the image order of `points_in_view`).
const CHUNK: usize = 256;

/// Precomputed grid problem.
#[derive(Clone, Debug)]
pub struct GridScorer {
    /// Points minus the start position (W axes).
    points: Vec<Vector3<f32>>,
    /// Hard bin of each point's value.
    point_bins: Vec<u16>,
    /// The image in units of 1/65535, row-major.
    image: Vec<u16>,
    width: usize,
    height: usize,
    camera: Camera<f32>,
    bins: usize,
    min_depth: f32,
    start: Isometry3<f64>,
}

impl GridScorer {
    /// The points and values of `scene` against `image` blurred by `blur_px`, for poses
    /// around `start` (`T_world_cam`).
    pub fn new(scene: &MiScene, image: &GrayImage, blur_px: f64, start: &Isometry3<f64>) -> Self {
        let blurred = equalize(image).gaussian_blur(blur_px);
        let bins = scene.bins.max(2);
        let origin = start.translation.vector;
        Self {
            points: scene.points.iter().map(|p| (p - origin).cast()).collect(),
            point_bins: scene.values.iter().map(|&a| bin_of(a, bins)).collect(),
            width: blurred.width(),
            height: blurred.height(),
            image: blurred
                .data()
                .iter()
                .map(|v| (v.clamp(0.0, 1.0) * 65535.0).round() as u16)
                .collect(),
            camera: scene.camera.cast(),
            bins,
            min_depth: scene.min_depth as f32,
            start: *start,
        }
    }

    /// Hard-binned MI (nats) at grid parameters `v = [x, y, z, yaw]` (m, rad):
    /// `T_world_cam` = translation `start + (x, y, z)`, rotation `Rz(yaw) * start`.
    pub fn score(&self, v: &[f64]) -> f64 {
        self.score_group(std::slice::from_ref(&v.to_vec()))[0]
    }

    /// [`Self::score`] of every candidate, in parallel over groups of candidates.
    pub fn score_all(&self, candidates: &[Vec<f64>]) -> Vec<f64> {
        candidates
            .par_chunks(GROUP)
            .flat_map_iter(|group| self.score_group(group))
            .collect()
    }

    /// `(R_cam_world - as f32, translation offset)` of grid parameters `v`.
    fn transform(&self, v: &[f64]) -> (Matrix3<f32>, Vector3<f32>) {
        let rotation =
            UnitQuaternion::from_axis_angle(&Vector3::z_axis(), v[3]) * self.start.rotation;
        let r = rotation
            .to_rotation_matrix()
            .into_inner()
            .transpose()
            .cast();
        (r, Vector3::new(v[0], v[1], v[2]).cast())
    }

    /// Scores of a few candidates, the points in chunks, every candidate per chunk.
    fn score_group(&self, group: &[Vec<f64>]) -> Vec<f64> {
        let poses: Vec<_> = group.iter().map(|v| self.transform(v)).collect();
        let bins = self.bins;
        let mut counts = vec![0u32; group.len() * bins * bins];
        let mut n = vec![0usize; group.len()];
        for (pts, point_bins) in self.points.chunks(CHUNK).zip(self.point_bins.chunks(CHUNK)) {
            for (k, (r, d)) in poses.iter().enumerate() {
                let hist = &mut counts[k * bins * bins..(k + 1) * bins * bins];
                for (p, &a) in pts.iter().zip(point_bins) {
                    if let Some(b) = self.value_at(&(r * (p - d))) {
                        hist[usize::from(a) * bins + usize::from(bin_of(b, bins))] += 1;
                        n[k] += 1;
                    }
                }
            }
        }
        counts
            .chunks(bins * bins)
            .zip(n)
            .map(|(c, n)| {
                let joint: Vec<f64> = c.iter().map(|&x| f64::from(x)).collect();
                score_of(&joint, bins, n).mi
            })
            .collect()
    }

    /// Image value where the camera-frame point `pc` projects; `None` when it is closer
    /// than the minimum depth, does not project or its 2 x 2 neighbourhood is off the
    /// image.
    #[inline]
    fn value_at(&self, pc: &Vector3<f32>) -> Option<f32> {
        if pc.z < self.min_depth {
            return None;
        }
        let q = self.camera.project(pc)?;
        let (u, v) = (q.pixel.x, q.pixel.y);
        if !(u >= 0.0 && v >= 0.0) {
            return None;
        }
        let (x0, y0) = (u as usize, v as usize);
        if x0 + 1 >= self.width || y0 + 1 >= self.height {
            return None;
        }
        let (fx, fy) = (u - x0 as f32, v - y0 as f32);
        let i = y0 * self.width + x0;
        let at = |j: usize| f32::from(self.image[j]);
        let (a, b) = (at(i), at(i + 1));
        let (c, d) = (at(i + self.width), at(i + self.width + 1));
        let top = a + (b - a) * fx;
        let bottom = c + (d - c) * fx;
        Some((top + (bottom - top) * fy) * (1.0 / 65535.0))
    }
}

/// Hard bin of a value in [0, 1] (as [`MiScene::hard_serial`]).
#[inline]
fn bin_of(x: f32, bins: usize) -> u16 {
    ((x.clamp(0.0, 1.0) * bins as f32) as usize).min(bins - 1) as u16
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mi::prior_map::grid_pose;
    use crate::mi::synthetic::synthetic_ground;

    /// The f32 score equals the generic f64 one (`MiScene::hard_serial`) on the same poses,
    /// and scoring in a group changes nothing.
    #[test]
    fn matches_the_generic_hard_mi() {
        let g = synthetic_ground(5, 20_000);
        let scene = MiScene::new(g.points.clone(), &g.intensities, &g.image, g.camera, 4.0);
        let start = g.t_world_cam;
        let scorer = GridScorer::new(&scene, &g.image, 4.0, &start);
        let poses = [
            [0.0, 0.0, 0.0, 0.0],
            [0.3, -0.2, 0.1, 0.02],
            [-0.5, 0.4, -0.3, -0.035],
        ];
        let all = scorer.score_all(&poses.map(|v| v.to_vec()));
        for (v, grouped) in poses.iter().zip(all) {
            let fast = scorer.score(v);
            assert_eq!(fast.to_bits(), grouped.to_bits(), "{v:?}");
            let generic = scene.hard_serial(&grid_pose(&start, v).inverse());
            assert!(fast > 0.01, "{v:?}: {fast}");
            assert!(
                (fast - generic).abs() < 1e-3 * generic,
                "{v:?}: {fast} vs {generic}"
            );
        }
    }
}

//! The data of the report's top view (`top_view` in the JSON report; drawn by
//! `report::topview`): the robot's keyframe positions, each camera's position, the
//! footprint of its field of view on the robot's plane and its horizontal position
//! covariance, and, when ground truth is at hand, the true camera positions after one rigid
//! alignment onto the estimate. Everything in the metric VO frame (`frame: vo`), whose
//! z is F0's optical axis: up, since F looks at the ceiling.

use std::collections::BTreeMap;

use msreg_estimator::camera::Camera;
use nalgebra::{Isometry3, Matrix6, Vector2, Vector3};
use serde::Serialize;

use super::align::rigid;
use super::io::{pose_of_rows, InfraError, InfraResultFile};

/// Pixels sampled along each image side for the footprint.
const SIDE_SAMPLES: usize = 8;
/// Footprint rays that do not meet the plane within this horizontal range stop there, m.
const MAX_RANGE_M: f64 = 8.0;

/// A solved camera as [`TopView::new`] takes it: id, intrinsics, `T_vo_C` and its
/// `[theta, p]` covariance.
pub type SolvedCamera<'a> = (String, &'a Camera<f64>, Isometry3<f64>, Matrix6<f64>);

/// One camera in the top view.
#[derive(Clone, Debug, Serialize)]
pub struct TopViewCamera {
    /// Id.
    pub id: String,
    /// Estimated position `[x, y, z]`, m.
    pub position_m: [f64; 3],
    /// Where the optical axis meets the robot's plane (or `MAX_RANGE_M` along its
    /// horizontal direction), `[x, y]`, m.
    pub axis_xy_m: [f64; 2],
    /// The image border's rays on the robot's plane (clipped at `MAX_RANGE_M`), `[x, y]`, m.
    pub footprint_xy_m: Vec<[f64; 2]>,
    /// Covariance of `[x, y]`, m^2 (row-major 2 x 2).
    pub covariance_xy_m2: [[f64; 2]; 2],
    /// The true position after the rigid alignment of all true positions onto the
    /// estimated ones, `[x, y, z]`, m (when ground truth was given).
    pub truth_m: Option<[f64; 3]>,
}

/// The top view.
#[derive(Clone, Debug, Serialize)]
pub struct TopView {
    /// Height of the robot's plane (mean keyframe z), m.
    pub plane_z_m: f64,
    /// Keyframe positions `[x, y]`, m, in time order.
    pub trajectory_xy_m: Vec<[f64; 2]>,
    /// Solved cameras.
    pub cameras: Vec<TopViewCamera>,
}

impl TopView {
    /// The view of `keyframes` (`T_vo_F` per keyframe) and the solved `cameras`
    /// (`T_vo_C`, its intrinsics, its `[theta, p]` covariance).
    pub fn new(keyframes: &[Isometry3<f64>], cameras: &[SolvedCamera<'_>]) -> TopView {
        let n = keyframes.len().max(1) as f64;
        let plane_z_m = keyframes.iter().map(|k| k.translation.z).sum::<f64>() / n;
        let trajectory_xy_m = keyframes
            .iter()
            .map(|k| [k.translation.x, k.translation.y])
            .collect();
        let cameras = cameras
            .iter()
            .map(|(id, camera, pose, cov)| TopViewCamera {
                id: id.clone(),
                position_m: pose.translation.vector.into(),
                axis_xy_m: on_plane(pose, &Vector3::z(), plane_z_m),
                footprint_xy_m: border(camera)
                    .iter()
                    .filter_map(|px| camera.unproject(px))
                    .map(|ray| on_plane(pose, &ray, plane_z_m))
                    .collect(),
                covariance_xy_m2: [[cov[(3, 3)], cov[(3, 4)]], [cov[(4, 3)], cov[(4, 4)]]],
                truth_m: None,
            })
            .collect();
        TopView {
            plane_z_m,
            trajectory_xy_m,
            cameras,
        }
    }

    /// Adds the true camera positions of `truth` (ground-truth `infra.yaml`, any frame),
    /// moved by the least-squares rigid transform of the true positions onto the estimated
    /// ones (cameras in both); the one rigid alignment the evaluation uses.
    pub fn add_truth(&mut self, truth: &InfraResultFile) -> Result<(), InfraError> {
        let here = std::path::Path::new("groundtruth/infra.yaml");
        let mut true_pos = BTreeMap::new();
        for (id, c) in &truth.infra.cameras {
            true_pos.insert(
                id.clone(),
                pose_of_rows(here, &c.t_world_cam)?.translation.vector,
            );
        }
        let (mut est, mut tru) = (Vec::new(), Vec::new());
        for c in &self.cameras {
            if let Some(t) = true_pos.get(&c.id) {
                est.push(Vector3::from(c.position_m));
                tru.push(*t);
            }
        }
        if tru.len() < 3 {
            return Ok(());
        }
        let align = rigid(&tru, &est);
        for c in &mut self.cameras {
            c.truth_m = true_pos
                .get(&c.id)
                .map(|t| (align * nalgebra::Point3::from(*t)).coords.into());
        }
        Ok(())
    }
}

/// Pixels along the image border, clockwise from the top-left corner.
fn border(camera: &Camera<f64>) -> Vec<Vector2<f64>> {
    let (w, h) = (camera.resolution.0 as f64, camera.resolution.1 as f64);
    let corners = [(0.0, 0.0), (w, 0.0), (w, h), (0.0, h)];
    let mut out = Vec::with_capacity(4 * SIDE_SAMPLES);
    for k in 0..4 {
        let (a, b) = (corners[k], corners[(k + 1) % 4]);
        for s in 0..SIDE_SAMPLES {
            let f = s as f64 / SIDE_SAMPLES as f64;
            out.push(Vector2::new(a.0 + f * (b.0 - a.0), a.1 + f * (b.1 - a.1)));
        }
    }
    out
}

/// Where the ray `ray` (camera frame) of the camera at `pose` meets the plane
/// `z = plane_z`; rays that meet it beyond `MAX_RANGE_M` horizontally, or not at all,
/// stop at that range along their horizontal direction.
fn on_plane(pose: &Isometry3<f64>, ray: &Vector3<f64>, plane_z: f64) -> [f64; 2] {
    let c = pose.translation.vector;
    let d = pose.rotation * ray;
    let horizontal = Vector2::new(d.x, d.y);
    let reach = horizontal.norm();
    let t = (plane_z - c.z) / d.z;
    let at = if d.z < 0.0 && t * reach <= MAX_RANGE_M {
        Vector2::new(c.x, c.y) + t * horizontal
    } else if reach > 0.0 {
        Vector2::new(c.x, c.y) + horizontal * (MAX_RANGE_M / reach)
    } else {
        Vector2::new(c.x, c.y)
    };
    [at.x, at.y]
}

#[cfg(test)]
mod tests {
    use super::*;
    use msreg_estimator::camera::{Distortion, Intrinsics, Projection};
    use nalgebra::{Translation3, UnitQuaternion};

    #[test]
    fn a_camera_looking_straight_down_sees_a_square_about_its_foot() {
        // Given a 90 deg pinhole (f = w / 2) 3 m above the plane z = 0, looking down
        let k = Intrinsics {
            fu: 400.0,
            fv: 400.0,
            cu: 400.0,
            cv: 400.0,
        };
        let camera = Camera::new(Projection::Pinhole, k, Distortion::None, (800, 800)).unwrap();
        let down = UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI);
        let pose = Isometry3::from_parts(Translation3::new(1.0, 2.0, 3.0), down);
        let keyframes = [Isometry3::translation(0.0, 0.0, 0.0)];
        let cov = Matrix6::from_diagonal_element(1e-6);
        let view = TopView::new(&keyframes, &[("c".into(), &camera, pose, cov)]);
        let c = &view.cameras[0];
        // Then the axis meets the plane below it and the corners 3 m out on each axis
        assert!((c.axis_xy_m[0] - 1.0).abs() < 1e-9 && (c.axis_xy_m[1] - 2.0).abs() < 1e-9);
        assert_eq!(c.footprint_xy_m.len(), 4 * SIDE_SAMPLES);
        for p in &c.footprint_xy_m {
            let (dx, dy) = ((p[0] - 1.0).abs(), (p[1] - 2.0).abs());
            assert!(
                (dx.max(dy) - 3.0).abs() < 1e-6,
                "on the square's border: {p:?}"
            );
        }
        assert_eq!(c.covariance_xy_m2, [[1e-6, 0.0], [0.0, 1e-6]]);
    }

    #[test]
    fn a_ray_above_the_horizon_stops_at_the_range() {
        let pose = Isometry3::translation(0.0, 0.0, 3.0);
        let p = on_plane(&pose, &Vector3::new(1.0, 0.0, 0.1), 0.0);
        assert!((p[0] - MAX_RANGE_M).abs() < 1e-12 && p[1].abs() < 1e-12);
    }
}

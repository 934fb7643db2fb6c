//! Mean line reprojection error (MLRE, dissertation section 2.7.3): LiDAR edge points
//! projected into the image with an estimated `T_cam_lidar`, perpendicular distance to the
//! detected image edge line, in pixels. Independent of both cost functions (neither
//! minimises an image distance). Distances are measured in the undistorted pinhole image
//! (`K` of the camera), where the edges are straight lines.

use msreg_estimator::camera::Camera;
use msreg_estimator::Pose;
use nalgebra::Vector3;

/// Pixel distances of LiDAR points from the image line whose back-projected plane has
/// unit normal `plane_normal` (camera frame); points behind the camera are skipped.
pub fn line_distances_px(
    camera: &Camera<f64>,
    t_cam_lidar: &Pose<f64>,
    plane_normal: &Vector3<f64>,
    points_lidar: &[Vector3<f64>],
) -> Vec<f64> {
    let i = camera.intrinsics();
    // The line in pinhole pixels: n0 (u - cu)/fu + n1 (v - cv)/fv + n2 = 0.
    let (a, b) = (plane_normal.x / i.fu, plane_normal.y / i.fv);
    let c = plane_normal.z - a * i.cu - b * i.cv;
    let norm = a.hypot(b);
    if norm < 1e-15 {
        return Vec::new();
    }
    points_lidar
        .iter()
        .filter_map(|p| {
            let q = t_cam_lidar.transform_point(p);
            (q.z > 1e-6).then(|| {
                let (u, v) = (i.fu * q.x / q.z + i.cu, i.fv * q.y / q.z + i.cv);
                (a * u + b * v + c).abs() / norm
            })
        })
        .collect()
}

/// Mean of all distances (0 for none).
pub fn mean(values: &[f64]) -> f64 {
    if values.is_empty() {
        0.0
    } else {
        values.iter().sum::<f64>() / values.len() as f64
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use msreg_estimator::camera::{Distortion, Intrinsics, Projection};

    #[test]
    fn distance_of_a_point_off_a_vertical_line() {
        let cam = Camera::new(
            Projection::Pinhole,
            Intrinsics {
                fu: 500.0,
                fv: 400.0,
                cu: 320.0,
                cv: 240.0,
            },
            Distortion::None,
            (640, 480),
        )
        .unwrap();
        // The plane x = 0 images as the column u = cu; a point at x/z = 0.01 is 5 px off.
        let d = line_distances_px(
            &cam,
            &Pose::identity(),
            &Vector3::x(),
            &[Vector3::new(0.02, 0.3, 2.0), Vector3::new(0.0, 0.0, -1.0)],
        );
        assert_eq!(d.len(), 1);
        assert!((d[0] - 5.0).abs() < 1e-9);
    }
}

//! The crossing check on a synthetic road: a ring LiDAR 1.8 m above a plane with painted
//! lines in its reflectivity, and a pinhole image ray-cast from the same geometry (its own
//! brightness and noise). From a rotation error, the alignment must return to the truth.

use msreg_estimator::camera::{Camera, Distortion, Intrinsics, Projection};
use nalgebra::{Isometry3, Matrix3, Rotation3, Translation3, UnitQuaternion, Vector2, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

use super::{align_rotation, MarkingOptions};
use crate::mi::scene::PoseParam;
use crate::pointcloud::{Point, PointCloud};
use crate::vision::GrayImage;

const GROUND_Z: f64 = -1.8;

/// Painted lines along x: solid at y = -1.75 and 5.25, dashed (3 m of 6 m) at y = 1.75;
/// 0.15 m wide.
fn painted(x: f64, y: f64) -> bool {
    let on = |c: f64| (y - c).abs() < 0.075;
    on(-1.75) || on(5.25) || (on(1.75) && x.rem_euclid(6.0) < 3.0)
}

fn camera() -> Camera<f64> {
    let i = Intrinsics {
        fu: 1000.0,
        fv: 1000.0,
        cu: 639.5,
        cv: 359.5,
    };
    Camera::new(Projection::Pinhole, i, Distortion::None, (1280, 720))
        .unwrap_or_else(|_| unreachable!("valid constants"))
}

fn truth() -> Isometry3<f64> {
    // camera x = -lidar y, camera y = -lidar z, camera z = lidar x; slightly tilted.
    let axes = Rotation3::from_matrix_unchecked(Matrix3::new(
        0.0, -1.0, 0.0, 0.0, 0.0, -1.0, 1.0, 0.0, 0.0,
    ));
    let tilt = Rotation3::from_scaled_axis(Vector3::new(0.01, 0.02, -0.015));
    Isometry3::from_parts(
        Translation3::new(0.03, -0.4, -0.09),
        UnitQuaternion::from_rotation_matrix(&(axes * tilt)),
    )
}

fn scan(rng: &mut ChaCha8Rng) -> PointCloud {
    let mut points = Vec::new();
    for ring in 0..30u16 {
        let elev = (-24.0 + 0.7 * f64::from(ring)).to_radians();
        for k in 0..600 {
            let az = (-45.0 + 0.15 * f64::from(k)).to_radians();
            let d = Vector3::new(elev.cos() * az.cos(), elev.cos() * az.sin(), elev.sin());
            let p = d * (GROUND_Z / d.z);
            let base = if painted(p.x, p.y) { 90.0 } else { 30.0 };
            points.push(Point {
                xyz: p,
                intensity: base + rng.gen_range(-5.0..5.0),
                t_ns: 0,
                ring,
            });
        }
    }
    PointCloud::new(points)
}

fn render(camera: &Camera<f64>, t_cam_lidar: &Isometry3<f64>, rng: &mut ChaCha8Rng) -> GrayImage {
    let (w, h) = (1280usize, 720usize);
    let noise = Normal::new(0.0, 3.0).unwrap_or_else(|_| unreachable!("positive sigma"));
    let t_lidar_cam = t_cam_lidar.inverse();
    let origin = t_lidar_cam.translation.vector;
    let data = (0..w * h)
        .map(|i| {
            let px = Vector2::new((i % w) as f64, (i / w) as f64);
            let value = camera
                .unproject(&px)
                .map(|b| t_lidar_cam.rotation * b)
                .filter(|d| d.z < -1e-3)
                .map_or(160.0, |d| {
                    let g = origin + d * ((GROUND_Z - origin.z) / d.z);
                    if painted(g.x, g.y) {
                        210.0
                    } else {
                        70.0
                    }
                });
            (value + noise.sample(rng)) as f32
        })
        .collect();
    GrayImage::from_vec(w, h, data).unwrap_or_else(|| GrayImage::new(w, h, 0.0))
}

#[test]
fn rotation_error_is_recovered_from_the_marking_crossings() {
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let camera = camera();
    let truth = truth();
    let cloud = scan(&mut rng);
    let image = render(&camera, &truth, &mut rng);
    let error = Vector3::new(0.1f64, -0.3, 0.15).map(f64::to_radians);
    let start = PoseParam::CamFromSource.retract(
        &truth,
        &nalgebra::Vector6::new(error.x, error.y, error.z, 0.0, 0.0, 0.0),
    );
    let a = align_rotation(
        &cloud,
        &image,
        &camera,
        &start,
        &MarkingOptions::default(),
        3,
    )
    .expect("enough crossings");
    let left = (truth.rotation.inverse() * a.t_cam_lidar.rotation).scaled_axis();
    println!(
        "start residual median {:.1} px ({} crossings); final {:.2} px, scatter {:.2} px \
         ({} crossings); remaining error {:?} deg, sigma {:?} deg",
        a.first.median_residual_px,
        a.first.crossings,
        a.last.median_residual_px,
        a.last.robust_sigma_px,
        a.last.crossings,
        left.map(f64::to_degrees).as_slice(),
        a.last.sigma_rad.map(f64::to_degrees).as_slice()
    );
    assert!(a.first.median_residual_px.abs() > 2.0, "{:?}", a.first);
    assert!(a.last.median_residual_px.abs() < 0.5, "{:?}", a.last);
    for k in 0..3 {
        assert!(
            left[k].abs() < 3.0 * a.last.sigma_rad[k],
            "axis {k}: {} deg vs sigma {} deg",
            left[k].to_degrees(),
            a.last.sigma_rad[k].to_degrees()
        );
    }
    assert!(left.norm().to_degrees() < 0.05, "{left:?}");
}

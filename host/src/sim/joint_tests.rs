//! The joint simulator against geometry it does not share with the estimator: the board is in
//! both views, and the estimator's board-plane model, fed with the ray-cast board points
//! deskewed by the true motion, is zero at the truth up to the range noise (chi-square).

use super::*;
use msreg_estimator::update::board_plane::{self, BoardPlane};
use msreg_estimator::Pose;

fn short(seed: u64) -> JointSimConfig {
    let mut config = JointSimConfig::default();
    config.camera.seed = seed;
    config.camera.duration_s = 8.0;
    config.lidar.rings = 32;
    config.lidar.columns = 512;
    config.lidar.time_offset_s = 0.007;
    config
}

fn pose(t: &Isometry3<f64>) -> Pose<f64> {
    Pose::new(t.rotation, t.translation.vector)
}

/// The points of scan `k` that truly lie on the board, in L at the scan stamp's IMU time
/// (deskewed with the true motion), and the cosine of each one's incidence angle.
fn board_points(sim: &JointSim, k: usize) -> (Vec<Vector3<f64>>, Vec<f64>) {
    let lidar = &sim.lidar;
    let t_ref = lidar.seconds(lidar.scan_stamps[k]) + lidar.config.lidar.time_offset_s;
    let t_g_ref = lidar.t_g_l(t_ref);
    let t_t_g = sim.camera.t_g_target.inverse();
    let (w, h) = board_size(&sim.camera.config.board);
    let b = &sim.camera.config.board;
    let centre = Vector3::new(
        (b.rows - 1) as f64 * b.row_spacing_m / 2.0,
        (b.cols - 1) as f64 * b.col_spacing_m / 2.0,
        0.0,
    );
    let normal = sim.camera.t_g_target.rotation * Vector3::z();
    let mut points = Vec::new();
    let mut cosines = Vec::new();
    for p in &lidar.scan(k).points {
        let t_g_l = lidar.t_g_l(t_ref + f64::from(p.t_ns) * 1e-9);
        let in_g = t_g_l * nalgebra::Point3::from(p.xyz);
        let on_board = (t_t_g * in_g).coords - centre;
        if on_board.z.abs() < 0.1 && on_board.x.abs() < w / 2.0 && on_board.y.abs() < h / 2.0 {
            let ray = (in_g.coords - t_g_l.translation.vector).normalize();
            cosines.push(ray.dot(&normal).abs());
            points.push((t_g_ref.inverse() * in_g).coords);
        }
    }
    (points, cosines)
}

#[test]
fn both_sensors_see_the_board() -> Result<(), SimError> {
    for seed in 0..3 {
        let sim = simulate_joint(&short(seed))?;
        let frames = sim.camera.frame_stamps.len();
        let in_view = (0..frames)
            .filter(|&k| sim.camera.full_board_in_view(k))
            .count();
        let scans = sim.lidar.scan_stamps.len();
        let seen = (0..scans)
            .step_by(4)
            .map(|k| board_points(&sim, k).0.len())
            .collect::<Vec<_>>();
        println!("seed {seed}: board in {in_view}/{frames} images; board points {seen:?}");
        assert!(in_view as f64 >= 0.9 * frames as f64, "seed {seed}");
        assert!(seen.iter().all(|&n| n >= 100), "seed {seed}: {seen:?}");
    }
    Ok(())
}

/// The board-plane residual of the estimator at the true state, over scans of three seeds:
/// its NIS (3 dof per scan, noise the range noise along the normal) sums inside the 99 %
/// chi-square band.
#[test]
fn the_board_plane_model_is_zero_at_the_truth_up_to_the_range_noise() -> Result<(), SimError> {
    let (mut nis, mut dof, mut bias, mut planes) = (0.0, 0, 0.0, 0);
    for seed in 0..3 {
        let sim = simulate_joint(&short(seed))?;
        let lidar = &sim.lidar;
        let sigma_range = lidar.config.lidar.range_noise_m;
        for k in (5..lidar.scan_stamps.len()).step_by(7) {
            let (points, cosines) = board_points(&sim, k);
            let rms_cos =
                (cosines.iter().map(|c| c * c).sum::<f64>() / cosines.len() as f64).sqrt();
            let plane = BoardPlane::from_points(0, &points, sigma_range * rms_cos)
                .expect("the board is a plane");
            let t = lidar.seconds(lidar.scan_stamps[k]) + lidar.config.lidar.time_offset_s;
            let h = board_plane::predict(
                &pose(&sim.camera.trajectory.isometry(t)),
                &pose(&lidar.t_imu_lidar),
                &pose(&sim.camera.t_g_target),
                &plane,
            );
            nis += h.norm_squared() / (plane.sigma * plane.sigma);
            dof += 3;
            bias += h[0] / f64::from(plane.count).sqrt();
            planes += 1;
        }
    }
    // Two-sided 99 % band of chi-square(dof) (Wilson-Hilferty).
    let band = |z: f64| {
        let d = dof as f64;
        d * (1.0 - 2.0 / (9.0 * d) + z * (2.0 / (9.0 * d)).sqrt()).powi(3)
    };
    println!(
        "board-plane NIS {nis:.1} over {dof} dof; mean distance row {:.3} mm",
        bias / f64::from(planes) * 1e3
    );
    assert!(
        (band(-2.576)..=band(2.576)).contains(&nis),
        "NIS {nis} over {dof} dof"
    );
    Ok(())
}

#[test]
fn the_result_file_has_all_three_sections() -> Result<(), SimError> {
    let sim = simulate_joint(&short(1))?;
    let truth = sim.extrinsics();
    let (cam, lidar, cl) = (
        truth.cam0.expect("cam0"),
        truth.lidar0.expect("lidar0"),
        truth.cam0_lidar0.expect("cam0_lidar0"),
    );
    let chained = cam.transform * lidar.transform;
    assert!(
        (chained.to_homogeneous() - cl.transform.to_homogeneous())
            .abs()
            .max()
            < 1e-12
    );
    assert!((lidar.timeshift_s - 0.007).abs() < 1e-15);
    // The LiDAR's z axis points up in the camera frame (-y_C) within the jitter.
    let up_in_camera = cl.transform.rotation * Vector3::z();
    assert!(up_in_camera.dot(&-Vector3::y()) > 0.99, "{up_in_camera}");
    Ok(())
}

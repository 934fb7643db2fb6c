//! The pose-IMU calibration on a real recording: EuRoC MAV `imu_april` (real ADIS16448 at
//! 200 Hz, 1416 images of an AprilGrid at 20 Hz, no standstill; `../shared/data/README.md`)
//! with cam0's per-frame PnP pose as the pose sensor (MoCal's odometry,
//! `calibrate::pnp_odometry`), judged against EuRoC's published Kalibr calibration, beside a
//! plain batch baseline on the same increments: the gyro integrated between poses, the
//! rotation by Kabsch on the rotation vectors alternated with a constant gyro bias
//! (`gyro_bias::hand_eye_with_gyro_bias`).
//!
//! Measured (docs/pose-imu.md): the batch baseline 0.304 deg from Kalibr; the filter before
//! the fix (its health monitor reacting to eight false "steps") 0.282 deg / 33.1 mm, and
//! 1.11 deg / 0.68 deg with the translation / rotation noise scaled by 3 / 2; after it
//! 0.255 deg / 10.8 mm, and 0.227-0.255 deg, 8.3-10.8 mm over the noise scalings. Kalibr
//! itself and Basalt's calibration of this recording differ by 0.34 deg / 8.0 mm
//! (cli/tests/euroc_camera_imu_real.rs), so millimetres and hundredths of a degree below
//! that are not judged here; the comparison with the batch on the same data is.

// A test crate: its helpers may panic on bad fixtures.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use msreg_host::calibrate::driver::nominal_period_ns;
use msreg_host::calibrate::driver::report::{PoseImuCalibration, PoseImuOptions};
use msreg_host::calibrate::pnp_odometry::pnp_odometry;
use msreg_host::calibrate::pose_imu::model_error::model_error;
use msreg_host::calibrate::pose_imu::{calibrate, PoseImuInput};
use msreg_host::calibrate::{gyro_bias, init};
use msreg_host::camera_yaml::read_camera_yaml;
use msreg_host::dataset::{read_imu_csv, ImuNoiseYaml, PoseRecord};
use nalgebra::{Isometry3, UnitQuaternion};

#[path = "support/euroc.rs"]
mod euroc;

use euroc::{corner_frames, kalibr_t_imu_cam, SET};

struct Real {
    imu: Vec<msreg_host::dataset::ImuRecord>,
    noise: ImuNoiseYaml,
    odometry: Vec<PoseRecord>,
    pose_noise: msreg_host::dataset::PoseSensorYaml,
    kalibr: Isometry3<f64>,
}

/// The recording with its PnP odometry; `None` (a `SKIP:` line, a panic under CI) when absent.
fn load() -> Option<Real> {
    let dir = msreg_host::shared_data::dir_or_skip(SET)?;
    let camera = read_camera_yaml(&dir.join("cam0/camera.yaml")).unwrap();
    let (odometry, pose_noise) = pnp_odometry(&camera, &corner_frames(&dir));
    Some(Real {
        imu: read_imu_csv(dir.join("imu0/data.csv")).unwrap(),
        noise: ImuNoiseYaml::read(dir.join("imu0/imu.yaml")).unwrap(),
        odometry,
        pose_noise,
        kalibr: kalibr_t_imu_cam(&dir),
    })
}

/// Rotation (deg) and translation (mm) of `t_imu_cam` from Kalibr's.
fn error(estimate: &Isometry3<f64>, kalibr: &Isometry3<f64>) -> (f64, f64) {
    (
        estimate.rotation.angle_to(&kalibr.rotation).to_degrees(),
        (estimate.translation.vector - kalibr.translation.vector).norm() * 1e3,
    )
}

/// The batch baseline: rotation and constant gyro bias from the PnP rotation increments.
fn batch_rotation(real: &Real) -> UnitQuaternion<f64> {
    let period = nominal_period_ns(&real.odometry);
    let increments = init::pose_increments(&real.odometry, period * 3 / 2);
    let (rotation, _) = gyro_bias::hand_eye_with_gyro_bias(&real.imu, &increments, 10);
    rotation.unwrap().rotation
}

/// The pose-IMU pipeline on the real odometry with its noise scaled.
fn run(real: &Real, scale_r: f64, scale_t: f64) -> PoseImuCalibration {
    let mut noise = real.pose_noise.clone();
    noise.rotation_noise_rad *= scale_r;
    noise.translation_noise_m *= scale_t;
    let input = PoseImuInput {
        imu: &real.imu,
        imu_noise: &real.noise,
        poses: &real.odometry,
        pose_noise: &noise,
    };
    calibrate::<f64>(&input, &PoseImuOptions::default(), &mut |_| {}).unwrap()
}

#[test]
fn real_pnp_pose_imu_is_never_worse_than_the_batch_baseline() {
    let Some(real) = &load() else {
        return;
    };
    let (batch_deg, _) = error(
        &Isometry3::from_parts(Default::default(), batch_rotation(real)),
        &real.kalibr,
    );
    let c = run(real, 1.0, 1.0);
    let (rot_deg, trans_mm) = error(&c.t_imu_sensor, &real.kalibr);
    let sigma = c.covariance.diagonal().map(f64::sqrt);
    let sigma_rot_deg = sigma.fixed_rows::<3>(0).map(f64::to_degrees);
    let sigma_trans_mm = sigma.fixed_rows::<3>(3) * 1e3;
    println!(
        "{} PnP poses (increment noise {:.4} rad, {:.2} mm); batch {batch_deg:.3} deg; \
         EKF {rot_deg:.3} deg / {trans_mm:.1} mm (sigma rot {:.3?} deg, trans {:.1?} mm), \
         t_d {:.3} ms, NIS/dof {:.2}, accepted {}, rejected {}, events {}",
        real.odometry.len(),
        real.pose_noise.rotation_noise_rad,
        real.pose_noise.translation_noise_m * 1e3,
        sigma_rot_deg.as_slice(),
        sigma_trans_mm.as_slice(),
        c.time_offset_s * 1e3,
        c.report.mean_nis_per_dof,
        c.report.updates_accepted,
        c.report.updates_rejected,
        c.report.events.len()
    );
    assert!(c.report.converged, "{:?}", c.report.reasons);
    // Measured 0.255 deg against the batch's 0.304 deg (before the fix 0.282).
    assert!(rot_deg <= batch_deg, "{rot_deg} deg, batch {batch_deg} deg");
    // Measured 10.8 mm (before the fix 33.1 mm); Kalibr and Basalt differ by 8 mm.
    assert!(trans_mm < 25.0, "{trans_mm} mm");
    // Measured -0.06 ms (RepErrCal on the same recording: -0.011 ms).
    assert!(c.time_offset_s.abs() < 0.5e-3, "{} s", c.time_offset_s);
    // Measured 0.048-0.060 deg and 1.0-1.2 mm: the filter's sigma, against which the
    // error from Kalibr is 4-5 (rotation) and 9 (translation) sigma; the reference's own
    // spread (0.34 deg / 8 mm to Basalt) is larger, so this is not judged as NEES here.
    assert!(
        sigma_rot_deg.iter().all(|s| *s > 0.02 && *s < 0.15),
        "{sigma_rot_deg}"
    );
    assert!(
        sigma_trans_mm.iter().all(|s| *s > 0.3 && *s < 4.0),
        "{sigma_trans_mm}"
    );
    // Measured 2.99: real PnP increments scatter sqrt(3) times MoCal's median noise
    // (heavy-tailed: fast motion); 117 of 1412 gated out.
    assert!((1.0..4.5).contains(&c.report.mean_nis_per_dof));
    assert!(
        c.report.updates_rejected < 300,
        "{}",
        c.report.updates_rejected
    );
    // The eight steps the health monitor reacted to were refuted (docs/pose-imu.md).
    assert!(c.report.events.is_empty(), "{:?}", c.report.events.len());
}

/// Before the fix the end depended on the stated odometry noise through the false steps
/// (0.28, 1.11 and 0.68 deg at noise x1, translation x3, rotation x2); held constant the
/// extrinsic ends within 0.03 deg whatever the noise, and never worse than the batch.
#[test]
fn real_pnp_pose_imu_does_not_depend_on_the_stated_noise() {
    let Some(real) = &load() else {
        return;
    };
    let (batch_deg, _) = error(
        &Isometry3::from_parts(Default::default(), batch_rotation(real)),
        &real.kalibr,
    );
    let runs = [(1.0, 1.0), (1.0, 3.0), (2.0, 1.0), (1.0, 1e3)];
    let ends: Vec<(f64, f64)> = runs
        .iter()
        .map(|&(r, t)| error(&run(real, r, t).t_imu_sensor, &real.kalibr))
        .collect();
    for ((r, t), (deg, mm)) in runs.iter().zip(&ends) {
        println!("noise x{r} rotation, x{t} translation: {deg:.3} deg / {mm:.1} mm");
    }
    let (lo, hi) = ends.iter().fold((f64::MAX, 0f64), |(lo, hi), (d, _)| {
        (lo.min(*d), hi.max(*d))
    });
    // Measured 0.227-0.255 deg (spread 0.028 deg), batch 0.304 deg.
    assert!(hi - lo < 0.08, "{lo}..{hi} deg");
    assert!(hi <= batch_deg, "{hi} deg, batch {batch_deg} deg");
    // With the translation path on (not x1000): measured 8.3-10.8 mm.
    for (deg, mm) in &ends[..3] {
        assert!(*mm < 25.0, "{deg} deg / {mm} mm");
    }
}

/// Covariances that hold (issue 34, item 2): the two halves of the recording, each with the
/// model error of its time blocks (`pose_imu::model_error`), agree within 3 combined written
/// sigma per axis; the whole run's written sigma is printed against Kalibr.
#[test]
#[ignore = "real-data acceptance: three pose-IMU runs with their time blocks"]
fn real_pnp_pose_imu_halves_agree_within_the_written_sigma() {
    let Some(real) = &load() else {
        return;
    };
    let (first, last) = (real.imu[0].stamp_ns, real.imu.last().unwrap().stamp_ns);
    let middle = first + (last - first) / 2;
    let written = |(from, to): (u64, u64)| {
        let imu: Vec<_> = real
            .imu
            .iter()
            .filter(|r| (from..to).contains(&r.stamp_ns))
            .cloned()
            .collect();
        let poses: Vec<_> = real
            .odometry
            .iter()
            .filter(|p| (from..to).contains(&p.stamp_ns))
            .cloned()
            .collect();
        let input = PoseImuInput {
            imu: &imu,
            imu_noise: &real.noise,
            poses: &poses,
            pose_noise: &real.pose_noise,
        };
        let options = PoseImuOptions::default();
        let c = calibrate::<f64>(&input, &options, &mut |_| {}).unwrap();
        let (cov, report) = model_error::<f64>(&input, &options, &c);
        println!(
            "[{:.0}, {:.0}] s: ratio {:.1?}, blocks {}/{}, filter sigma rot {:.3?} deg trans \
             {:.2?} mm, written rot {:.3?} deg trans {:.2?} mm; skipped {:?}",
            (from - first) as f64 * 1e-9,
            (to.min(last) - first) as f64 * 1e-9,
            report.variance_ratio,
            report.blocks_used,
            report.blocks,
            report.filter_sigma_rot_deg,
            report.filter_sigma_trans_m.map(|v| v * 1e3),
            report.sigma_rot_deg,
            report.sigma_trans_m.map(|v| v * 1e3),
            report.skipped
        );
        (c, cov)
    };
    let started = std::time::Instant::now();
    let (full, full_cov) = written((first, last + 1));
    let (a, a_cov) = written((first, middle));
    let (b, b_cov) = written((middle, last + 1));
    println!("three runs: {:.1} s", started.elapsed().as_secs_f64());
    let diff = |x: &Isometry3<f64>, y: &Isometry3<f64>| {
        let r = (y.rotation.inverse() * x.rotation).scaled_axis();
        let p = x.translation.vector - y.translation.vector;
        nalgebra::Vector6::new(r.x, r.y, r.z, p.x, p.y, p.z)
    };
    let e = diff(&b.t_imu_sensor, &a.t_imu_sensor);
    let z: Vec<f64> = (0..6)
        .map(|i| e[i].abs() / (a_cov[(i, i)] + b_cov[(i, i)]).sqrt())
        .collect();
    let z_filter: Vec<f64> = (0..6)
        .map(|i| e[i].abs() / (a.covariance[(i, i)] + b.covariance[(i, i)]).sqrt())
        .collect();
    println!(
        "halves differ by {:.3} deg / {:.1} mm: z {z:.2?} (filter's sigma: {z_filter:.2?})",
        e.fixed_rows::<3>(0).norm().to_degrees(),
        e.fixed_rows::<3>(3).norm() * 1e3
    );
    let k = diff(&full.t_imu_sensor, &real.kalibr);
    let z_kalibr: Vec<f64> = (0..6)
        .map(|i| k[i].abs() / full_cov[(i, i)].sqrt())
        .collect();
    println!("whole run vs Kalibr: z {z_kalibr:.1?}");
    assert!(z.iter().all(|z| *z <= 3.0), "{z:?}");
}

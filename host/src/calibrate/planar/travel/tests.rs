//! The direction-of-travel yaw on simulated car drives ([`crate::sim::drive`], the pose-IMU
//! simulator: a random mounting, 6-D odometry with 0.2 deg / 5 mm per 10 Hz increment, and
//! the gyro bias starting at zero).

use super::*;
use crate::calibrate::init;
use crate::calibrate::planar::detect;
use crate::sim::{self, SimConfig, SimDataset};

fn drive(seed: u64) -> SimDataset {
    let mut c = SimConfig {
        seed,
        duration_s: 120.0,
        ..SimConfig::default()
    };
    c.trajectory.motion = sim::MotionKind::Drive(sim::DriveConfig::default());
    c.pose.time_offset_s = (((7 * seed) % 41) as f64 - 20.0) * 1e-3;
    sim::simulate_pose_imu(&c).expect("valid simulation")
}

/// (error, error about the axis, sigma, side ratio), deg, deg, deg, 1.
fn fit(seed: u64) -> (f64, f64, f64, f64) {
    let data = drive(seed);
    let increments = init::pose_increments(&data.pose, 150_000_000);
    let pairs = init::rotation_pairs(&data.imu, increments.iter().copied(), &Vector3::zeros());
    let motion = detect(&pairs).expect("planar");
    let t = travel_yaw(&data.imu, &data.pose, &Vector3::zeros(), &motion).expect("a fit");
    let rest = data.t_imu_pose.rotation * t.rotation.inverse();
    let error = rest.angle().to_degrees();
    let about = rest.scaled_axis().dot(&motion.axis_imu).to_degrees();
    println!(
        "seed {seed}: error {error:.3} deg, about the axis {about:+.3} deg, sigma {:.3} deg, side {:.4}, windows {}",
        t.heading.sigma_rad.to_degrees(),
        t.travel.side_ratio,
        t.heading.windows
    );
    (
        error,
        about,
        t.heading.sigma_rad.to_degrees(),
        t.travel.side_ratio,
    )
}

/// Seeds 41-50 (the constants were fixed before any drive was run; seeds 1-40 were measured
/// while building it: worst 1.94 deg in all, 1.93 deg about the axis at 3.2 sigma, sideways
/// share 0.011-0.022). Each error about the axis inside the 99.73 % bound of Student's t with
/// 22 dof (the jackknife's 23 windows), the whole rotation within 3x the worst of seeds 1-40
/// (what matters of a start: the filter's 10 deg prior), the pooled NEES below the 95 % band's
/// top. (Seeds 41-50 measured 0.58 deg at worst, and a pooled NEES of 2.8, under the band's
/// bottom 3.2: the jackknife's sigma, from 23 windows, errs wide here; a wide start is safe.) The scan this replaces started 4 deg off at the
/// median of seeds 1-40 and 21 deg at worst.
#[test]
fn the_direction_of_travel_gives_the_rotation_about_the_axis() {
    let seeds: Vec<u64> = (41..=50).collect();
    let fits: Vec<_> = seeds.iter().map(|&s| fit(s)).collect();
    let mut nees = 0.0;
    for (seed, (error, about, sigma, side)) in seeds.iter().zip(&fits) {
        assert!(*error < 5.8, "seed {seed}: {error} deg");
        assert!(
            about.abs() < 3.38 * sigma,
            "seed {seed}: {about} vs sigma {sigma}"
        );
        assert!(*side < 0.066, "seed {seed}: sideways share {side}");
        nees += (about / sigma).powi(2);
    }
    println!("yaw NEES {nees:.1} over {} fits", seeds.len());
    assert!(nees < 20.5, "{nees}");
}

/// A base that translates without turning to face its motion (holonomic, or a hand-held
/// rig) has no single direction of travel in its own frame: no fit.
#[test]
fn sideways_motion_has_no_direction_of_travel() {
    let poses: Vec<PoseRecord> = (0..200u64)
        .map(|k| {
            let t = k as f64 * 0.1;
            let p = Vector3::new(5.0 * (0.3 * t).sin(), 5.0 * (0.3 * t).cos(), 0.0);
            let q = UnitQuaternion::from_euler_angles(0.0, 0.0, 0.05 * t);
            PoseRecord::from_isometry(
                k * 100_000_000,
                &nalgebra::Isometry3::from_parts(p.into(), q),
            )
        })
        .collect();
    let travel = direction_of_travel(&poses).expect("moving increments");
    assert!(travel.side_ratio > 0.5, "{}", travel.side_ratio);
}

//! The car-like drive: exact derivatives against finite differences, and the ranges the
//! scenario promises (speed 3-15 m/s, yaw rate <= ~0.5 rad/s, roll / pitch within ~2 deg).

use nalgebra::Vector3;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use super::{gravity_in_g, DriveConfig, MotionKind, Trajectory, TrajectoryConfig};

fn drive(seed: u64) -> Trajectory {
    drive_of(DriveConfig::default(), seed)
}

fn drive_of(drive: DriveConfig, seed: u64) -> Trajectory {
    let config = TrajectoryConfig {
        motion: MotionKind::Drive(drive),
        ..TrajectoryConfig::default()
    };
    Trajectory::random(&config, &mut ChaCha8Rng::seed_from_u64(seed))
}

const TIMES: [f64; 6] = [0.0, 0.7, 3.3, 11.1, 27.4, 58.9];

#[test]
fn drive_derivatives_match_finite_differences() {
    let h = 1e-4;
    for seed in 0..4 {
        let traj = drive(seed);
        for t in TIMES {
            let (r_minus, p_minus) = traj.pose(t - h);
            let (r, p) = traj.pose(t);
            let (r_plus, p_plus) = traj.pose(t + h);
            let v_fd = (p_plus - p_minus) / (2.0 * h);
            assert!((v_fd - traj.velocity(t)).norm() < 1e-6, "seed {seed} t {t}");
            let a_fd = (traj.velocity(t + h) - traj.velocity(t - h)) / (2.0 * h);
            assert!(
                (a_fd - traj.acceleration(t)).norm() < 1e-5,
                "seed {seed} t {t}"
            );
            let omega_fd = (r_minus.inverse() * r_plus).scaled_axis() / (2.0 * h);
            let omega = traj.body_rate(t);
            assert!(
                (omega_fd - omega).norm() < 1e-7,
                "seed {seed} t {t}: {omega_fd} vs {omega}"
            );
            let a2 = (p_plus - 2.0 * p + p_minus) / (h * h);
            let f_fd = r.inverse_transform_vector(&(a2 - gravity_in_g()));
            assert!(
                (f_fd - traj.specific_force(t)).norm() < 1e-3,
                "seed {seed} t {t}"
            );
        }
    }
}

#[test]
fn drive_stays_on_the_plane_within_car_like_ranges() {
    for seed in 0..5 {
        let traj = drive(seed);
        let (mut min_speed, mut max_speed) = (f64::INFINITY, 0.0_f64);
        let (mut max_yaw_rate, mut max_tilt, mut max_side) = (0.0_f64, 0.0_f64, 0.0_f64);
        let z0 = traj.pose(0.0).1.z;
        for k in 0..12_000 {
            let t = 0.01 * f64::from(k);
            let (r, p) = traj.pose(t);
            assert!((p.z - z0).abs() < 1e-12);
            let v = traj.velocity(t);
            min_speed = min_speed.min(v.norm());
            max_speed = max_speed.max(v.norm());
            let (roll, pitch, _) = r.euler_angles();
            max_tilt = max_tilt.max(roll.abs()).max(pitch.abs());
            max_yaw_rate = max_yaw_rate.max((r * traj.body_rate(t)).z.abs());
            // No side slip: the velocity in the vehicle frame points forward (up to the tilt).
            let v_body = r.inverse_transform_vector(&v);
            max_side = max_side.max(v_body.y.abs() / v.norm());
        }
        eprintln!(
            "seed {seed}: speed {min_speed:.1}-{max_speed:.1} m/s, yaw rate {max_yaw_rate:.2} \
             rad/s, tilt {:.2} deg, side {max_side:.1e}",
            max_tilt.to_degrees()
        );
        assert!(min_speed > 3.0 && max_speed < 15.0);
        assert!((0.2..0.6).contains(&max_yaw_rate), "{max_yaw_rate}");
        assert!((0.5..2.5).contains(&max_tilt.to_degrees()), "{max_tilt}");
        assert!(max_side < 0.05, "{max_side}");
    }
}

#[test]
fn drive_turns_mostly_about_the_vertical() {
    let traj = drive(3);
    let (mut yaw, mut other) = (0.0, 0.0);
    for k in 0..6000 {
        let w: Vector3<f64> = traj.body_rate(0.01 * f64::from(k));
        yaw += w.z * w.z;
        other += w.x * w.x + w.y * w.y;
    }
    assert!(other < 0.05 * yaw, "{other} vs {yaw}");
}

/// The calibration figure-eight stays within what a car can do in a parking lot: a turning
/// radius of 5 m or more, at most 3 m/s^2 sideways, and turns about twice as fast as the
/// default drive's (rms yaw rate).
#[test]
fn figure_eight_turns_like_a_car_in_a_parking_lot() {
    for seed in 0..5 {
        let traj = drive_of(DriveConfig::figure_eight(), seed);
        let (mut min_radius, mut max_lateral, mut max_tilt) = (f64::INFINITY, 0.0_f64, 0.0_f64);
        let (mut min_speed, mut max_speed, mut yaw_sq) = (f64::INFINITY, 0.0_f64, 0.0);
        let n = 6_000;
        for k in 0..n {
            let t = 0.01 * f64::from(k);
            let (r, _) = traj.pose(t);
            let v = traj.velocity(t);
            let yaw_rate = (r * traj.body_rate(t)).z;
            min_speed = min_speed.min(v.norm());
            max_speed = max_speed.max(v.norm());
            min_radius = min_radius.min(v.norm() / yaw_rate.abs());
            max_lateral = max_lateral.max(v.norm() * yaw_rate.abs());
            let (roll, pitch, _) = r.euler_angles();
            max_tilt = max_tilt.max(roll.abs()).max(pitch.abs());
            yaw_sq += yaw_rate * yaw_rate;
        }
        let rms = (yaw_sq / f64::from(n)).sqrt();
        eprintln!(
            "seed {seed}: speed {min_speed:.1}-{max_speed:.1} m/s, radius >= {min_radius:.1} m, \
             lateral <= {max_lateral:.2} m/s^2, tilt {:.2} deg, yaw rate rms {rms:.2} rad/s",
            max_tilt.to_degrees()
        );
        assert!(min_speed > 3.5 && max_speed < 8.0);
        assert!(min_radius > 5.0, "{min_radius}");
        assert!(max_lateral < 3.0, "{max_lateral}");
        assert!(max_tilt.to_degrees() < 2.0, "{max_tilt}");
        assert!((0.35..0.55).contains(&rms), "{rms}");
    }
}

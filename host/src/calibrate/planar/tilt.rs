//! The tilt of the mounting from gravity, for planar motion recorded against level 2-D
//! odometry (wheel odometry whose `z`, roll and pitch are always zero: REP-105's `odom`
//! frame, `z` up).
//!
//! When the odometry's rotation cannot be trusted (a skid-steer base slips in every turn),
//! the yaw of the mounting has no source, but its roll and pitch still do: the pose
//! sensor's `z` axis is vertical, so the mean specific force over the drive, read in the
//! IMU frame, is `g R_I_S e_z`. What limits it is the vehicle's own tilt (the terrain under
//! it, its accelerations), which a 2-D odometry calls level: it averages out over the drive
//! only if the ground is level on average. The spread of the tilt over windows of
//! [`TILT_WINDOW_S`] measures it, and the accelerometer bias, which planar motion cannot
//! separate from a tilt (both stay fixed in the IMU frame under rotation about `z`), adds
//! its prior.

use nalgebra::{UnitQuaternion, Vector3};

use crate::dataset::{ImuRecord, PoseRecord};

/// Length of the windows whose tilt spread sets the sigma, s: long enough that a ground
/// vehicle's own accelerations average down (2 m/s of speed change over 10 s is 0.2 m/s^2,
/// 1.2 deg), short enough for several windows in a minute.
pub const TILT_WINDOW_S: f64 = 10.0;
/// Fewest windows for a spread.
const MIN_WINDOWS: usize = 3;
/// Largest height change (m) and roll/pitch (rad, as the quaternion's x/y parts) of a pose
/// in level 2-D odometry: exact zeros in the Jackal's, above any rounding.
const LEVEL_TOLERANCE: f64 = 1e-6;

/// Roll and pitch of `R_I_S` (ZYX Euler angles, yaw zero) from gravity.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GravityTilt {
    /// Roll of `R_I_S`, rad.
    pub roll_rad: f64,
    /// Pitch of `R_I_S`, rad.
    pub pitch_rad: f64,
    /// 1-sigma of the roll and of the pitch, rad.
    pub sigma_rad: [f64; 2],
    /// Sample standard deviation of the roll and pitch over the windows, rad.
    pub spread_rad: [f64; 2],
    /// Windows of [`TILT_WINDOW_S`] used.
    pub windows: usize,
}

impl GravityTilt {
    /// `R_I_S` with this roll and pitch and zero yaw.
    pub fn rotation(&self) -> UnitQuaternion<f64> {
        UnitQuaternion::from_euler_angles(self.roll_rad, self.pitch_rad, 0.0)
    }
}

/// True when every pose lies in the first one's horizontal plane with its `z` axis vertical
/// (2-D odometry).
pub fn is_level(poses: &[PoseRecord]) -> bool {
    let Some(first) = poses.first() else {
        return false;
    };
    poses.iter().all(|p| {
        (p.position.z - first.position.z).abs() <= LEVEL_TOLERANCE
            && p.rotation.i.abs() <= LEVEL_TOLERANCE
            && p.rotation.j.abs() <= LEVEL_TOLERANCE
    })
}

/// Roll and pitch of `R_I_S` such that `R_I_S e_z` points along the specific force `f`.
fn roll_pitch(f: &Vector3<f64>) -> (f64, f64) {
    // R = Ry(pitch) Rx(roll): R e_z = (cos r sin p, -sin r, cos r cos p).
    let roll = (-f.y).atan2(f.x.hypot(f.z));
    let pitch = f.x.atan2(f.z);
    (roll, pitch)
}

/// The tilt from the mean specific force of `imu` over the whole record, with its sigma from
/// the spread over windows of [`TILT_WINDOW_S`] and `accel_bias_sigma` (m/s^2, the prior of
/// the accelerometer bias); `None` with fewer than three windows.
pub fn gravity_tilt(imu: &[ImuRecord], accel_bias_sigma: f64) -> Option<GravityTilt> {
    let (first, last) = (imu.first()?, imu.last()?);
    let span_s = (last.stamp_ns - first.stamp_ns) as f64 * 1e-9;
    let windows = (span_s / TILT_WINDOW_S).floor() as usize;
    if windows < MIN_WINDOWS {
        return None;
    }
    let mut sums = vec![(Vector3::zeros(), 0usize); windows];
    for r in imu {
        let k = ((r.stamp_ns - first.stamp_ns) as f64 * 1e-9 / TILT_WINDOW_S) as usize;
        if let Some(s) = sums.get_mut(k) {
            s.0 += r.accel;
            s.1 += 1;
        }
    }
    let mean: Vector3<f64> = imu.iter().map(|r| r.accel).sum::<Vector3<f64>>() / imu.len() as f64;
    let (roll, pitch) = roll_pitch(&mean);
    let per_window: Vec<(f64, f64)> = sums
        .iter()
        .filter(|s| s.1 > 0)
        .map(|s| roll_pitch(&(s.0 / s.1 as f64)))
        .collect();
    let n = per_window.len();
    if n < MIN_WINDOWS {
        return None;
    }
    let spread = |f: fn(&(f64, f64)) -> f64| {
        let m = per_window.iter().map(f).sum::<f64>() / n as f64;
        (per_window.iter().map(|w| (f(w) - m).powi(2)).sum::<f64>() / (n - 1) as f64).sqrt()
    };
    let spread_rad = [spread(|w| w.0), spread(|w| w.1)];
    let bias_tilt = accel_bias_sigma / mean.norm();
    let sigma_rad = spread_rad.map(|s| (s * s / n as f64 + bias_tilt * bias_tilt).sqrt());
    Some(GravityTilt {
        roll_rad: roll,
        pitch_rad: pitch,
        sigma_rad,
        spread_rad,
        windows: n,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Translation3;

    /// 60 s at 50 Hz of a vehicle whose IMU is mounted at `R_I_S` = `truth` (roll, pitch, yaw): it
    /// yaws at a varying rate and rocks about its own level (+-3 deg, zero mean), so the
    /// specific force is gravity seen through the rocking and the mounting.
    fn drive(truth: (f64, f64, f64)) -> Vec<ImuRecord> {
        let r_i_s = UnitQuaternion::from_euler_angles(truth.0, truth.1, truth.2);
        (0..=3000)
            .map(|k| {
                let t = k as f64 * 0.02;
                let rock = UnitQuaternion::from_euler_angles(
                    3f64.to_radians() * (0.7 * t).sin(),
                    3f64.to_radians() * (0.45 * t + 1.0).sin(),
                    0.4 * t.sin(),
                );
                let f_s = rock.inverse() * Vector3::new(0.0, 0.0, 9.81);
                ImuRecord {
                    stamp_ns: k * 20_000_000,
                    gyro: Vector3::zeros(),
                    accel: r_i_s * f_s,
                }
            })
            .collect()
    }

    #[test]
    fn tilt_of_the_mounting_is_recovered_inside_its_sigma() {
        let truth = (1.5f64.to_radians(), -0.8f64.to_radians(), 0.3);
        // The roll and pitch of R_I_S at zero yaw that put its z axis where the mounting's is.
        let r_i_s = UnitQuaternion::from_euler_angles(truth.0, truth.1, truth.2);
        let up = r_i_s * Vector3::z();
        let (roll, pitch) = roll_pitch(&up);
        let tilt = gravity_tilt(&drive(truth), 0.05).expect("six windows");
        assert_eq!(tilt.windows, 6);
        for (k, (estimate, truth)) in [(tilt.roll_rad, roll), (tilt.pitch_rad, pitch)]
            .into_iter()
            .enumerate()
        {
            assert!(
                (estimate - truth).abs() < 3.0 * tilt.sigma_rad[k],
                "axis {k}: {estimate} vs {truth}, sigma {}",
                tilt.sigma_rad[k]
            );
            // The rocking's spread over 10 s windows (about 1 deg) sets the sigma.
            assert!(
                tilt.spread_rad[k] > 0.2f64.to_radians(),
                "{:?}",
                tilt.spread_rad
            );
        }
        // The rotation of a roll and pitch puts the z axis where they were read from.
        let exact = GravityTilt {
            roll_rad: roll,
            pitch_rad: pitch,
            ..tilt
        };
        assert!((exact.rotation() * Vector3::z() - up).norm() < 1e-12);
        assert!(exact.rotation().euler_angles().2.abs() < 1e-12, "zero yaw");
        assert!(
            gravity_tilt(&drive(truth)[..1000], 0.05).is_none(),
            "20 s: 2 windows"
        );
    }

    #[test]
    fn level_odometry_is_recognised() {
        let pose = |z: f64, q: UnitQuaternion<f64>| PoseRecord {
            stamp_ns: 0,
            position: Translation3::new(1.0, 2.0, z).vector,
            rotation: q,
        };
        let yawed = UnitQuaternion::from_euler_angles(0.0, 0.0, 2.0);
        assert!(is_level(&[
            pose(0.0, yawed),
            pose(0.0, UnitQuaternion::identity())
        ]));
        assert!(!is_level(&[pose(0.0, yawed), pose(0.01, yawed)]));
        let rolled = UnitQuaternion::from_euler_angles(0.01, 0.0, 2.0);
        assert!(!is_level(&[pose(0.0, yawed), pose(0.0, rolled)]));
        assert!(!is_level(&[]));
    }
}

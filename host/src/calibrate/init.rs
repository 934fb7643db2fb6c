//! Initialisation before the filter runs: standstill detection at the start of a recording
//! (gravity direction, gyro bias) and the hand-eye rotation from gyro-integrated and
//! sensor rotation increments (eq. 3.2-3.5).

use msreg_estimator::hand_eye::{HandEye, HandEyeError};
use msreg_estimator::lie;
use nalgebra::{UnitQuaternion, Vector3};

use crate::dataset::{ImuRecord, PoseRecord};

/// The stationary start of a recording.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Standstill {
    /// Stamp of the last sample still at rest, ns.
    pub until_ns: u64,
    /// Number of samples at rest.
    pub samples: usize,
    /// Mean accelerometer reading (gravity direction).
    pub accel_mean: Vector3<f64>,
    /// Mean gyro reading (gyro bias).
    pub gyro_mean: Vector3<f64>,
}

/// Odometry noise sigmas (accumulated over the standstill's increments) the pose sensor may
/// move while the IMU is said to be at rest.
const STILL_SIGMAS: f64 = 4.0;

impl Standstill {
    /// The last sensor stamp surely taken at rest: a measurement stamped `t_S` was taken at
    /// IMU time `t_S + t_d`, and the time offset is within 3 sigma of its prior (mean zero,
    /// `time_offset_sigma_s`).
    pub fn surely_at_rest_until_ns(&self, time_offset_sigma_s: f64) -> u64 {
        let margin_ns = (3.0 * time_offset_sigma_s.abs() * 1e9) as u64;
        self.until_ns.saturating_sub(margin_ns)
    }

    /// True when the pose sensor agrees with this standstill: an IMU moving at constant
    /// velocity without turning reads exactly as at rest (a car cruising straight when the
    /// recording starts: drive seeds 16 and 230), so the odometry must not move over it by
    /// more than its increment noise `sigma_t` allows. Without poses inside the standstill
    /// the IMU decides.
    pub fn odometry_agrees(&self, poses: &[PoseRecord], sigma_t: f64) -> bool {
        let Some(first) = poses.first() else {
            return true;
        };
        let within = poses.iter().take_while(|p| p.stamp_ns <= self.until_ns);
        let (count, moved) = within.fold((0usize, 0f64), |(n, m), p| {
            (n + 1, m.max((p.position - first.position).norm()))
        });
        let increments = count.saturating_sub(1).max(1) as f64;
        moved <= STILL_SIGMAS * sigma_t * increments.sqrt()
    }
}

/// Largest deviation of a gyro sample from the first 0.1 s mean still counted as rest, rad/s.
const REST_GYRO: f64 = 0.03;
/// Largest deviation of an accelerometer sample from the first 0.1 s mean at rest, m/s^2.
const REST_ACCEL: f64 = 0.3;

/// Finds the stationary start: samples until the gyro or accelerometer leaves a band around
/// the first 0.1 s mean; `None` when it lasts less than `min_duration_s`.
pub fn detect_standstill(imu: &[ImuRecord], min_duration_s: f64) -> Option<Standstill> {
    let first = imu.first()?;
    let head: Vec<&ImuRecord> = imu
        .iter()
        .take_while(|r| r.stamp_ns - first.stamp_ns <= 100_000_000)
        .collect();
    let n = head.len() as f64;
    let g0 = head.iter().map(|r| r.gyro).sum::<Vector3<f64>>() / n;
    let a0 = head.iter().map(|r| r.accel).sum::<Vector3<f64>>() / n;
    let still = imu
        .iter()
        .take_while(|r| (r.gyro - g0).amax() < REST_GYRO && (r.accel - a0).amax() < REST_ACCEL)
        .count();
    // Leave a margin: the last samples before motion may already move slightly.
    let samples = still.saturating_sub(still / 10);
    let last = imu.get(samples.checked_sub(1)?)?;
    if (last.stamp_ns - first.stamp_ns) as f64 * 1e-9 < min_duration_s {
        return None;
    }
    let rest = &imu[..samples];
    let m = samples as f64;
    Some(Standstill {
        until_ns: last.stamp_ns,
        samples,
        accel_mean: rest.iter().map(|r| r.accel).sum::<Vector3<f64>>() / m,
        gyro_mean: rest.iter().map(|r| r.gyro).sum::<Vector3<f64>>() / m,
    })
}

/// The gyro between two stamps as pieces `(mean rate, dt)`: the readings are instantaneous
/// and linear between stamps, so each piece between consecutive stamps (or the interval's
/// ends) integrates the mean of its end readings, as the filter does. `None` when the
/// stamps are outside the IMU data.
pub fn gyro_pieces(
    imu: &[ImuRecord],
    from_ns: u64,
    to_ns: u64,
) -> Option<Vec<(Vector3<f64>, f64)>> {
    if imu.is_empty() || from_ns < imu[0].stamp_ns || to_ns <= from_ns {
        return None;
    }
    let last = imu.last()?;
    if to_ns > last.stamp_ns {
        return None;
    }
    // The interval [t_k, t_{k+1}] that holds `from_ns`.
    let start = imu
        .partition_point(|r| r.stamp_ns <= from_ns)
        .checked_sub(1)?;
    let rate_at = |k: usize, t: u64| {
        let a = &imu[k];
        let Some(b) = imu.get(k + 1) else {
            return a.gyro;
        };
        let f = (t.saturating_sub(a.stamp_ns)) as f64 / (b.stamp_ns - a.stamp_ns) as f64;
        a.gyro + (b.gyro - a.gyro) * f.clamp(0.0, 1.0)
    };
    let mut pieces = Vec::new();
    let mut t = from_ns;
    for k in start..imu.len().saturating_sub(1) {
        let end = imu[k + 1].stamp_ns.min(to_ns);
        if end > t {
            let dt = (end - t) as f64 * 1e-9;
            pieces.push(((rate_at(k, t) + rate_at(k, end)) * 0.5, dt));
            t = end;
        }
        if t >= to_ns {
            break;
        }
    }
    Some(pieces)
}

/// The rotation of the IMU between two stamps from its gyro ([`gyro_pieces`]), minus
/// `gyro_bias`. `None` when the stamps are outside the IMU data.
pub fn integrate_gyro(
    imu: &[ImuRecord],
    from_ns: u64,
    to_ns: u64,
    gyro_bias: &Vector3<f64>,
) -> Option<UnitQuaternion<f64>> {
    let pieces = gyro_pieces(imu, from_ns, to_ns)?;
    Some(
        pieces
            .iter()
            .fold(UnitQuaternion::identity(), |q, (rate, dt)| {
                q * lie::exp(&((rate - gyro_bias) * *dt))
            }),
    )
}

/// Result of the hand-eye rotation initialisation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RotationInit {
    /// `R_I_S`.
    pub rotation: UnitQuaternion<f64>,
    /// Pairs used.
    pub pairs: usize,
    /// Second / first eigenvalue of the sensor rotation scatter.
    pub axis_ratio: f64,
}

/// A rotation increment of a sensor, `(from_ns, to_ns, R_Sfrom_Sto)`, stamps on the IMU clock.
pub type RotationIncrement = (u64, u64, UnitQuaternion<f64>);

/// The rotation increments between consecutive odometry poses; intervals longer than
/// `max_interval_ns` (odometry gaps) are left out.
pub fn pose_increments(poses: &[PoseRecord], max_interval_ns: u64) -> Vec<RotationIncrement> {
    poses
        .windows(2)
        .filter_map(|pair| {
            let (a, b) = (&pair[0], &pair[1]);
            (b.stamp_ns - a.stamp_ns <= max_interval_ns)
                .then(|| (a.stamp_ns, b.stamp_ns, a.rotation.inverse() * b.rotation))
        })
        .collect()
}

/// Hand-eye rotation from consecutive odometry poses and the gyro over the same intervals.
/// Intervals longer than `max_interval_ns` (odometry gaps) are skipped.
pub fn hand_eye_rotation(
    imu: &[ImuRecord],
    poses: &[PoseRecord],
    gyro_bias: &Vector3<f64>,
    max_interval_ns: u64,
) -> Result<RotationInit, HandEyeError<f64>> {
    let increments = pose_increments(poses, max_interval_ns);
    hand_eye_from_pairs(rotation_pairs(imu, increments, gyro_bias), 10)
}

/// Pairs each sensor rotation increment `(from_ns, to_ns, R_Sfrom_Sto)` (stamps on the IMU
/// clock) with the gyro-integrated IMU rotation over the same interval, as rotation vectors
/// `(r_I, r_S)`; increments outside the IMU data are left out.
pub fn rotation_pairs(
    imu: &[ImuRecord],
    increments: impl IntoIterator<Item = (u64, u64, UnitQuaternion<f64>)>,
    gyro_bias: &Vector3<f64>,
) -> Vec<(Vector3<f64>, Vector3<f64>)> {
    increments
        .into_iter()
        .filter_map(|(from, to, q_sensor)| {
            let q_imu = integrate_gyro(imu, from, to, gyro_bias)?;
            Some((lie::log(&q_imu), lie::log(&q_sensor)))
        })
        .collect()
}

/// Total rotation of the sensor over total rotation of the gyro across `pairs` (rotation
/// vectors `(r_I, r_S)` of the same intervals): 1 for a rigid pair whatever the extrinsic.
/// Far from 1 the two disagree on how much the body turned: a gyro in the wrong unit, or
/// odometry whose rotation slips (skid-steer wheel odometry); `None` without rotation.
pub fn rotation_scale(pairs: &[(Vector3<f64>, Vector3<f64>)]) -> Option<f64> {
    let gyro: f64 = pairs.iter().map(|(ri, _)| ri.norm()).sum();
    let sensor: f64 = pairs.iter().map(|(_, rs)| rs.norm()).sum();
    (gyro > 0.0).then(|| sensor / gyro)
}

/// The closed-form hand-eye rotation (eq. 3.3-3.5) of rotation-vector pairs `(r_I, r_S)`,
/// with its degeneracy check (fewer than `min_pairs` pairs or rotation about one axis only).
pub fn hand_eye_from_pairs(
    pairs: impl IntoIterator<Item = (Vector3<f64>, Vector3<f64>)>,
    min_pairs: usize,
) -> Result<RotationInit, HandEyeError<f64>> {
    let mut he = HandEye::<f64>::default();
    for (r_imu, r_sensor) in pairs {
        he.add(&r_imu, &r_sensor);
    }
    let rotation = he.solve(min_pairs)?;
    Ok(RotationInit {
        rotation,
        pairs: he.pairs(),
        axis_ratio: he.axis_ratio(),
    })
}

#[cfg(test)]
mod rotation_scale_tests {
    use super::*;

    #[test]
    fn rotation_scale_is_one_for_a_rigid_pair_and_57_for_degrees() {
        let r = UnitQuaternion::from_euler_angles(0.3, -1.0, 2.0);
        let pairs: Vec<_> = (0..50)
            .map(|k| {
                let rs = Vector3::new((k as f64).sin(), 0.3, (0.7 * k as f64).cos()) * 0.05;
                (r * rs, rs)
            })
            .collect();
        assert!((rotation_scale(&pairs).expect("turns") - 1.0).abs() < 1e-12);
        let degrees: Vec<_> = pairs
            .iter()
            .map(|(ri, rs)| (ri * 180.0 / std::f64::consts::PI, *rs))
            .collect();
        let scale = rotation_scale(&degrees).expect("turns");
        assert!((scale * 180.0 / std::f64::consts::PI - 1.0).abs() < 1e-12);
        assert_eq!(rotation_scale(&[]), None);
    }
}

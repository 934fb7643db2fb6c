//! The rotation about the axis from the direction of travel, for a vehicle that moves along
//! its own forward axis (no side slip: a car, a wheeled robot).
//!
//! Such a vehicle's velocity keeps one direction in every frame fixed to it. In the pose
//! sensor's frame that direction, `d_S`, is read off the odometry's own increments (each
//! increment's translation in the frame at its start, [`direction_of_travel`]); in the
//! IMU's frame it is `u`, which [`heading::nonholonomic_yaw`] fits to the IMU alone, window
//! by window, from the speed along `d_S` (speed changes inform `u` along itself, turns
//! across it). The rotation about the axis is then the one that takes `alignment d_S` onto
//! `u` ([`travel_yaw`]).
//!
//! Unlike the scan of [`super::fit_yaw`], this never rotates the IMU's accelerations by the
//! odometry's absolute orientation. That orientation drifts (0.2 deg per 10 Hz increment is
//! 2.4 deg in 15 s), and a drifting tilt leaks gravity into the horizontal accelerations
//! the scan compares: its start was 4 deg off at the median of simulated drives 1-40, 21 deg
//! at worst, and three of the forty did not converge from it (docs/planar.md). Here the
//! odometry's rotation enters only within one increment, and the IMU's attitude only within
//! one 5 s window of the gyro.
//!
//! Assumed: the lever arm's velocity `w x p` is small against the speed (it shows as a
//! sideways share of the increments, [`MAX_SIDE_RATIO`]), and the two clocks agree to a few
//! tens of ms (an offset lags the speed behind the IMU's accelerations).

use nalgebra::{Matrix3, UnitQuaternion, Vector3};

use super::heading::{self, HeadingFit};
use super::{main_axis, rotation_between, PlanarMotion};
use crate::dataset::{ImuRecord, PoseRecord};

/// Largest rms sideways over rms forward displacement of the increments for a vehicle that
/// moves along its forward axis. A car's lever arm gives `w |p| / speed`, about 1-2 % on the
/// simulated drives; a holonomic base or a hand-held rig moves sideways far more.
pub const MAX_SIDE_RATIO: f64 = 0.1;

/// Fewest increments that moved for a direction of travel.
const MIN_MOVING_INCREMENTS: usize = 50;

/// Increments slower than this are not used for the direction (at rest, or creeping), m/s.
const MIN_SPEED_M_S: f64 = 0.3;

/// An increment longer than this many times the median pose interval spans a gap (its
/// chord cuts across the turns) and is not used.
const MAX_INTERVAL_RATIO: f64 = 1.5;

/// The span of the recording both fits use, from its first pose, s: the 120 s drives they
/// were checked on (23 windows of the IMU-side fit); it also bounds their memory.
const TRAVEL_SPAN_S: f64 = 120.0;

/// The direction a vehicle moves in, in the pose sensor's frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Travel {
    /// Unit direction of travel `d_S` (forward: the way most increments go).
    pub forward_sensor: Vector3<f64>,
    /// Rms sideways over rms forward displacement of the increments (vertical motion
    /// counts as sideways).
    pub side_ratio: f64,
    /// Increments used.
    pub increments: usize,
}

/// The direction of travel from the odometry's increments: the main axis of their
/// translations, each in the sensor's frame at the increment's start. Increments across a
/// gap ([`MAX_INTERVAL_RATIO`]) or slower than [`MIN_SPEED_M_S`] are left out; `None` with
/// fewer than [`MIN_MOVING_INCREMENTS`] left.
pub fn direction_of_travel(poses: &[PoseRecord]) -> Option<Travel> {
    let mut intervals: Vec<u64> = poses
        .windows(2)
        .map(|w| w[1].stamp_ns.saturating_sub(w[0].stamp_ns))
        .collect();
    intervals.sort_unstable();
    let median_ns = *intervals.get(intervals.len() / 2)? as f64;
    let steps: Vec<Vector3<f64>> = poses
        .windows(2)
        .filter_map(|w| {
            let dt_ns = w[1].stamp_ns.saturating_sub(w[0].stamp_ns) as f64;
            let t = w[0].rotation.inverse() * (w[1].position - w[0].position);
            let moving = t.norm() >= MIN_SPEED_M_S * dt_ns * 1e-9;
            (dt_ns > 0.0 && dt_ns <= MAX_INTERVAL_RATIO * median_ns && moving).then_some(t)
        })
        .collect();
    if steps.len() < MIN_MOVING_INCREMENTS {
        return None;
    }
    let scatter: Matrix3<f64> = steps.iter().map(|t| t * t.transpose()).sum();
    let (_, mut forward) = main_axis(&scatter)?;
    if steps.iter().map(|t| t.dot(&forward)).sum::<f64>() < 0.0 {
        forward = -forward;
    }
    let along: f64 = steps.iter().map(|t| t.dot(&forward).powi(2)).sum();
    let side = (scatter.trace() - along).max(0.0);
    Some(Travel {
        forward_sensor: forward,
        side_ratio: (side / along).sqrt(),
        increments: steps.len(),
    })
}

/// The rotation about the axis from the direction of travel.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TravelYaw {
    /// `R_I_S`: the alignment turned about the IMU axis so that it takes `d_S` onto `u`.
    pub rotation: UnitQuaternion<f64>,
    /// The angle about `axis_imu` added to the alignment, rad.
    pub angle_rad: f64,
    /// The direction of travel it used.
    pub travel: Travel,
    /// The IMU-side fit (its `sigma_rad`, the jackknife over its windows, is the angle's).
    pub heading: HeadingFit,
}

/// The rotation about `motion.axis_imu` that takes the direction of travel in the sensor
/// frame onto the one the IMU sees (module docs), starting from `gyro_bias`. `None` when the
/// odometry does not move along one direction ([`MAX_SIDE_RATIO`]) or the IMU-side fit finds
/// no answer.
pub fn travel_yaw(
    imu: &[ImuRecord],
    poses: &[PoseRecord],
    gyro_bias: &Vector3<f64>,
    motion: &PlanarMotion,
) -> Option<TravelYaw> {
    let (imu, poses) = first_span(imu, poses)?;
    let travel = direction_of_travel(poses)?;
    if travel.side_ratio > MAX_SIDE_RATIO {
        return None;
    }
    // A frame whose `z` is the axis: both angles are measured in its x-y plane.
    let vertical = rotation_between(&Vector3::z(), &motion.axis_imu);
    let fit = heading::nonholonomic_yaw(imu, poses, &travel.forward_sensor, gyro_bias, &vertical)?;
    let mapped = motion.alignment * travel.forward_sensor;
    let angle = heading::wrap(fit.yaw_rad - heading::yaw_of(&mapped, &vertical));
    Some(TravelYaw {
        rotation: UnitQuaternion::from_scaled_axis(motion.axis_imu * angle) * motion.alignment,
        angle_rad: angle,
        travel,
        heading: fit,
    })
}

/// The IMU samples and poses of the first [`TRAVEL_SPAN_S`] from the first pose.
fn first_span<'a>(
    imu: &'a [ImuRecord],
    poses: &'a [PoseRecord],
) -> Option<(&'a [ImuRecord], &'a [PoseRecord])> {
    let end = poses.first()?.stamp_ns + (TRAVEL_SPAN_S * 1e9) as u64;
    let poses = &poses[..poses.partition_point(|p| p.stamp_ns <= end)];
    let imu = &imu[..imu.partition_point(|r| r.stamp_ns <= end + 1_000_000_000)];
    Some((imu, poses))
}

#[cfg(test)]
mod tests;

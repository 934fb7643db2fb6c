//! The firmware's feed seam: the link session (`firmware/src/session.rs`, `on_imu`) turns
//! each IMU sample into `msreg_estimator::ImuSample<f32>` and calls `Filter::propagate`
//! with it. This is the same conversion for a sample read from the ICM-42688-P.

use msreg_estimator::na::Vector3;
use msreg_estimator::ImuSample;

use crate::Sample;

/// The estimator's IMU sample (IMU time = the driver's data-ready stamp, ns; angular rate,
/// rad/s; specific force, m/s^2; both in the IMU's axes).
pub fn imu_sample(s: &Sample) -> ImuSample<f32> {
    ImuSample {
        stamp_ns: s.stamp_ns,
        gyro: Vector3::from(s.gyro),
        accel: Vector3::from(s.accel),
    }
}

//! Random but realistic ground-truth poses: the sensor mounting `T_imu_pose`
//! (sensor roughly upside down relative to the IMU, arbitrary heading, within
//! 30 cm) and an arbitrary odometry origin.

use std::f64::consts::PI;

use nalgebra::{Isometry3, Translation3, UnitQuaternion};
use rand::Rng;
use rand_distr::StandardNormal;

/// `T_imu_pose`: roll 180 deg + N(0, 5 deg), pitch N(0, 5 deg), yaw uniform;
/// each translation component uniform in [-0.3, 0.3] m.
pub fn random_mounting(rng: &mut impl Rng) -> Isometry3<f64> {
    let sigma = 5.0_f64.to_radians();
    let roll = PI + sigma * rng.sample::<f64, _>(StandardNormal);
    let pitch = sigma * rng.sample::<f64, _>(StandardNormal);
    let yaw = rng.gen_range(-PI..PI);
    let translation = Translation3::new(
        rng.gen_range(-0.3..=0.3),
        rng.gen_range(-0.3..=0.3),
        rng.gen_range(-0.3..=0.3),
    );
    Isometry3::from_parts(
        translation,
        UnitQuaternion::from_euler_angles(roll, pitch, yaw),
    )
}

/// An arbitrary pose: any orientation, each coordinate within +-10 m.
pub fn random_pose(rng: &mut impl Rng) -> Isometry3<f64> {
    let angles = [0; 3].map(|_| rng.gen_range(-PI..PI));
    let translation = Translation3::new(
        rng.gen_range(-10.0..10.0),
        rng.gen_range(-10.0..10.0),
        rng.gen_range(-10.0..10.0),
    );
    Isometry3::from_parts(
        translation,
        UnitQuaternion::from_euler_angles(angles[0], angles[1], angles[2]),
    )
}

//! Conversions between the host's f64 nalgebra types and the estimator's generic scalars.

use msreg_estimator::{ImuNoise, ImuSample, Pose, Scalar};
use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion, Vector3};

use crate::dataset::{ImuNoiseYaml, ImuRecord};

/// f64 vector -> scalar `T`.
pub fn vec3<T: Scalar>(v: &Vector3<f64>) -> Vector3<T> {
    Vector3::new(T::lit(v.x), T::lit(v.y), T::lit(v.z))
}

/// Scalar `T` vector -> f64.
pub fn vec3_f64<T: Scalar>(v: &Vector3<T>) -> Vector3<f64> {
    Vector3::new(v.x.to_f64(), v.y.to_f64(), v.z.to_f64())
}

/// f64 isometry -> estimator pose in `T`.
pub fn pose<T: Scalar>(iso: &Isometry3<f64>) -> Pose<T> {
    let q = iso.rotation.quaternion();
    Pose::new(
        UnitQuaternion::new_normalize(Quaternion::new(
            T::lit(q.w),
            T::lit(q.i),
            T::lit(q.j),
            T::lit(q.k),
        )),
        vec3(&iso.translation.vector),
    )
}

/// Estimator pose in `T` -> f64 isometry.
pub fn isometry<T: Scalar>(p: &Pose<T>) -> Isometry3<f64> {
    let q = p.rotation.quaternion();
    Isometry3::from_parts(
        Translation3::from(vec3_f64(&p.translation)),
        UnitQuaternion::new_normalize(Quaternion::new(
            q.w.to_f64(),
            q.i.to_f64(),
            q.j.to_f64(),
            q.k.to_f64(),
        )),
    )
}

/// A dataset IMU record as an estimator sample.
pub fn imu_sample<T: Scalar>(r: &ImuRecord) -> ImuSample<T> {
    ImuSample {
        stamp_ns: r.stamp_ns,
        gyro: vec3(&r.gyro),
        accel: vec3(&r.accel),
    }
}

/// Kalibr `imu.yaml` noise as the estimator's noise model.
pub fn imu_noise<T: Scalar>(y: &ImuNoiseYaml) -> ImuNoise<T> {
    ImuNoise {
        gyro_noise_density: T::lit(y.gyroscope_noise_density),
        accel_noise_density: T::lit(y.accelerometer_noise_density),
        gyro_random_walk: T::lit(y.gyroscope_random_walk),
        accel_random_walk: T::lit(y.accelerometer_random_walk),
    }
}

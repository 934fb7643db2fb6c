//! Garbage in, typed error out: whatever the filter is fed, it never panics, and an input
//! it rejects leaves its state exactly as it was.

use msreg_estimator::na::{UnitQuaternion, Vector3};
use msreg_estimator::{
    Error, FilterConfig, ImuNoise, ImuSample, InitialState, Pose, PoseImuEkf, RelativePose,
    SensorId, SOLE_SENSOR,
};

use proptest::prelude::*;

const START_NS: u64 = 1_700_000_000_000_000_000;

/// A filter that has run for 1 s at rest with a few relative-pose updates.
fn warmed_up() -> PoseImuEkf<f64> {
    let config = FilterConfig::new(ImuNoise::vn300());
    let init = InitialState::<f64, 1>::at_rest(Vector3::new(0.0, 0.0, 9.81))
        .expect("gravity")
        .with_extrinsic(SOLE_SENSOR, Pose::identity(), 0.05, 0.2)
        .with_time_offset(SOLE_SENSOR, 0.0, 0.01);
    let mut ekf = PoseImuEkf::new(&config, &init).expect("valid prior");
    for k in 0..=400u64 {
        let s = ImuSample {
            stamp_ns: START_NS + k * 2_500_000,
            gyro: Vector3::zeros(),
            accel: Vector3::new(0.0, 0.0, 9.81),
        };
        ekf.propagate(&s).expect("valid sample");
        if k == 40 {
            ekf.anchor(SOLE_SENSOR, s.stamp_ns).expect("anchor");
        }
        if k > 40 && k % 40 == 0 {
            let m = RelativePose::with_sigmas(
                s.stamp_ns - 100_000_000,
                s.stamp_ns,
                Pose::identity(),
                0.0035,
                0.005,
            );
            ekf.update_relative_pose(SOLE_SENSOR, &m)
                .expect("valid update");
        }
    }
    ekf
}

/// Everything observable of the filter, for before/after comparisons.
fn snapshot(ekf: &PoseImuEkf<f64>) -> String {
    format!(
        "{} {:?} {:?} {:?}",
        ekf.time_ns(),
        ekf.imu(),
        ekf.sensor(SOLE_SENSOR),
        ekf.covariance()
    )
}

fn garbage_f64() -> impl Strategy<Value = f64> {
    prop_oneof![
        Just(f64::NAN),
        Just(f64::INFINITY),
        Just(f64::NEG_INFINITY),
        Just(1e300),
        Just(-1e300),
        any::<f64>(),
        -1e6..1e6f64,
    ]
}

fn vec3() -> impl Strategy<Value = Vector3<f64>> {
    (garbage_f64(), garbage_f64(), garbage_f64()).prop_map(|(x, y, z)| Vector3::new(x, y, z))
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(500))]

    #[test]
    fn garbage_imu_never_panics_and_errors_leave_state(
        gyro in vec3(), accel in vec3(), dt in prop_oneof![Just(0u64), 0..200_000_000u64], back in any::<bool>()
    ) {
        let mut ekf = warmed_up();
        let before = snapshot(&ekf);
        let t = ekf.time_ns();
        let stamp = if back { t.saturating_sub(dt) } else { t.saturating_add(dt) };
        let result = ekf.propagate(&ImuSample { stamp_ns: stamp, gyro, accel });
        if result.is_err() {
            prop_assert_eq!(before, snapshot(&ekf));
        } else {
            // Accepted input keeps the state finite.
            prop_assert!(ekf.imu().is_finite());
        }
    }

    #[test]
    fn garbage_relative_pose_never_panics_and_errors_leave_state(
        axis in vec3(), trans in vec3(), sigma_r in garbage_f64(), sigma_t in garbage_f64(),
        from_offset in 0..400_000_000u64, len in 0..300_000_000u64, sensor in 0usize..3
    ) {
        let mut ekf = warmed_up();
        let before = snapshot(&ekf);
        let anchor = ekf.time_ns();
        let from = anchor.saturating_sub(from_offset);
        let rotation = UnitQuaternion::from_scaled_axis(if axis.iter().all(|x| x.is_finite()) { axis } else { Vector3::zeros() });
        let m = RelativePose::with_sigmas(from, from + len, Pose::new(rotation, trans), sigma_r, sigma_t);
        // Sensors 1 and 2 are ids of a wider layout: typed errors, state untouched.
        let sensor = SensorId::new::<3>(sensor).expect("sensor of the wider layout");
        match ekf.update_relative_pose(sensor, &m) {
            Err(_) => prop_assert_eq!(before, snapshot(&ekf)),
            Ok(report) => {
                prop_assert!(report.nis.is_finite());
                prop_assert!(ekf.sensor(SOLE_SENSOR).is_some_and(|s| s.extrinsic.is_finite()));
            }
        }
    }
}

#[test]
fn time_going_backwards_is_a_typed_error() {
    let mut ekf = warmed_up();
    let before = snapshot(&ekf);
    let err = ekf
        .propagate(&ImuSample {
            stamp_ns: ekf.time_ns() - 1,
            gyro: Vector3::zeros(),
            accel: Vector3::new(0.0, 0.0, 9.81),
        })
        .unwrap_err();
    assert!(matches!(err, Error::TimeWentBackwards { .. }));
    assert_eq!(before, snapshot(&ekf));
}

#[test]
fn imu_gap_is_a_typed_error() {
    let mut ekf = warmed_up();
    let err = ekf
        .propagate(&ImuSample {
            stamp_ns: ekf.time_ns() + 1_000_000_000,
            gyro: Vector3::zeros(),
            accel: Vector3::new(0.0, 0.0, 9.81),
        })
        .unwrap_err();
    assert!(matches!(err, Error::ImuGap { .. }));
}

#[test]
fn measurement_older_than_the_window_is_a_typed_error() {
    let mut ekf = warmed_up();
    let before = snapshot(&ekf);
    let t = ekf.time_ns();
    let m = RelativePose::with_sigmas(t - 900_000_000, t, Pose::identity(), 0.0035, 0.005);
    assert_eq!(
        ekf.update_relative_pose(SOLE_SENSOR, &m).unwrap_err(),
        Error::OlderThanWindow
    );
    assert_eq!(before, snapshot(&ekf));
}

#[test]
fn unknown_sensor_is_a_typed_error() {
    let mut ekf = warmed_up();
    assert_eq!(
        ekf.anchor(SensorId::at::<5, 6>(), ekf.time_ns())
            .unwrap_err(),
        Error::UnknownSensor
    );
}

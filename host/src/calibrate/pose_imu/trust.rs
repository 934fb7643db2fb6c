//! When the pose sensor's rotation is not the body's (it turns more or less than the gyro):
//! the reason, and what of the result can still be trusted.

use msreg_estimator::InitialState;
use nalgebra::{Isometry3, Matrix6, Vector3, Vector6};

use super::super::driver::report::PoseImuCalibration;
use super::super::init;
use super::super::observability::DofObservability;
use super::super::planar::{self, heading, tilt};
use crate::dataset::{ImuRecord, PoseRecord};

/// Refuses the result (not converged) because the pose sensor's rotation disagrees with the
/// gyro's (`problem`, from [`rotation_scale_problem`]). Under `planar` motion against level
/// 2-D odometry the rotation of the mounting is still measured ([`tilt_only`]: the tilt
/// from gravity, the yaw from the wheel speed and the non-holonomic constraint, starting
/// from `gyro_bias`); otherwise every rotation row is marked `not trusted`.
pub(super) fn refuse_rotation(
    calibration: &mut PoseImuCalibration,
    problem: &str,
    (planar, gyro_bias): (bool, &Vector3<f64>),
    (imu, poses): (&[ImuRecord], &[PoseRecord]),
) {
    let level = planar && tilt::is_level(poses);
    match level
        .then(|| tilt::gravity_tilt(imu, accel_bias_prior_sigma()))
        .flatten()
    {
        Some(t) => {
            let forward = Vector3::x();
            let yaw = heading::nonholonomic_yaw(imu, poses, &forward, gyro_bias, &t.rotation());
            tilt_only(calibration, (&t, yaw.as_ref()), problem);
        }
        None => {
            distrust_rotation(&mut calibration.report.observability);
            calibration.report.reasons.insert(0, problem.to_string());
        }
    }
    calibration.report.converged = false;
}

/// The accelerometer bias prior of the filter (the estimator's default), m/s^2.
fn accel_bias_prior_sigma() -> f64 {
    InitialState::<f64, 1>::at_rest(Vector3::new(0.0, 0.0, 9.81))
        .map_or(0.05, |s| s.sigma_accel_bias)
}

/// Why a DoF the pose sensor's rotation shaped is not trusted.
const TILT_ONLY_REASON: &str = "the pose sensor's rotation disagrees with the gyro's";

/// The honest result when the pose sensor's rotation is not the body's but the motion is
/// planar against level 2-D odometry: roll and pitch of `R_I_S` from gravity
/// ([`tilt::gravity_tilt`]), the yaw about the vertical from the wheel speed and the
/// non-holonomic constraint ([`heading::nonholonomic_yaw`]) when it is found, else at the
/// prior of an unknown yaw; what the filter took from the odometry's rotation (the lever arm
/// across the axis through `w x p`, the time offset, and without a heading fit the yaw) back
/// at its prior, marked `not trusted`, and the reasons naming each.
fn tilt_only(
    calibration: &mut PoseImuCalibration,
    (tilt, yaw): (&tilt::GravityTilt, Option<&heading::HeadingFit>),
    problem: &str,
) {
    let report = &mut calibration.report;
    let prior = |dof: &str| {
        report
            .observability
            .iter()
            .find(|r| r.dof == dof)
            .map_or(0.0, |r| r.prior_sigma)
    };
    let (sigma_t, sigma_td_s) = (prior("translation x"), prior("time offset") * 1e-3);
    let [sr, sp] = tilt.sigma_rad;
    let sy = yaw.map_or(planar::UNKNOWN_YAW_SIGMA_RAD, |h| h.sigma_rad);
    calibration.t_imu_sensor = Isometry3::from_parts(
        Default::default(),
        yaw.map_or(tilt.rotation(), |h| h.rotation(&tilt.rotation())),
    );
    calibration.covariance = Matrix6::from_diagonal(&Vector6::new(
        sr * sr,
        sp * sp,
        sy * sy,
        sigma_t * sigma_t,
        sigma_t * sigma_t,
        sigma_t * sigma_t,
    ));
    calibration.time_offset_s = 0.0;
    calibration.time_offset_sigma_s = sigma_td_s;
    let from_gravity = format!(
        "from gravity against the level 2-D odometry frame (spread over {} windows of {} s: \
         roll {:.2} deg, pitch {:.2} deg)",
        tilt.windows,
        tilt::TILT_WINDOW_S,
        tilt.spread_rad[0].to_degrees(),
        tilt.spread_rad[1].to_degrees()
    );
    let from_wheels = yaw.map(|h| {
        format!(
            "from the wheel speed along the base's forward axis and the non-holonomic \
             constraint (jackknife over {} windows of {} s; IMU speed {:.3}x the wheels')",
            h.windows,
            heading::HEADING_WINDOW_S,
            h.speed_scale()
        )
    });
    tilt_only_rows(
        &mut report.observability,
        [sr, sp, sy],
        (&from_gravity, from_wheels.as_deref()),
    );
    report
        .reasons
        .retain(|r| !r.starts_with("rotation about") && !r.starts_with("translation along"));
    let tilt_words = format!(
        "roll {:.2} deg and pitch {:.2} deg (sigma {:.2}, {:.2} deg) {from_gravity}",
        tilt.roll_rad.to_degrees(),
        tilt.pitch_rad.to_degrees(),
        sr.to_degrees(),
        sp.to_degrees()
    );
    let reason = match (yaw, &from_wheels) {
        (Some(h), Some(wheels)) => format!(
            "the lever arm across the axis and the time offset are not trusted: {problem}; \
             the rotation is reported: {tilt_words}, yaw {:.2} deg (sigma {:.2} deg) {wheels}",
            h.yaw_rad.to_degrees(),
            sy.to_degrees()
        ),
        _ => format!(
            "rotation z (the yaw of the mounting about the planar axis), the lever arm across \
             the axis and the time offset are not trusted: {problem}; only {tilt_words} are \
             reported"
        ),
    };
    report.reasons.insert(0, reason);
    report.planar = format!(
        "{}; roll {:.2} deg, pitch {:.2} deg of the mounting {from_gravity}{}",
        report.planar,
        tilt.roll_rad.to_degrees(),
        tilt.pitch_rad.to_degrees(),
        yaw.map_or(String::new(), |h| format!(
            "; yaw {:.2} deg {}",
            h.yaw_rad.to_degrees(),
            from_wheels.as_deref().unwrap_or_default()
        ))
    );
}

/// The observability rows of [`tilt_only`]: roll and pitch observed `from_gravity`, the yaw
/// observed `from_wheels` or at the prior of an unknown yaw and `not trusted`, the lever arm
/// across the axis and the time offset at their priors, `not trusted`; sigmas in rad.
fn tilt_only_rows(
    rows: &mut [DofObservability],
    [sr, sp, sy]: [f64; 3],
    (from_gravity, from_wheels): (&str, Option<&str>),
) {
    let unknown = planar::UNKNOWN_YAW_SIGMA_RAD.to_degrees();
    for row in rows.iter_mut() {
        let (sigma, prior, status, reason) = match row.dof.as_str() {
            "rotation x" => (
                sr.to_degrees(),
                row.prior_sigma,
                "observed",
                from_gravity.into(),
            ),
            "rotation y" => (
                sp.to_degrees(),
                row.prior_sigma,
                "observed",
                from_gravity.into(),
            ),
            "rotation z" => match from_wheels {
                Some(wheels) => (sy.to_degrees(), unknown, "observed", wheels.into()),
                None => (
                    unknown,
                    unknown,
                    "not trusted",
                    format!("{TILT_ONLY_REASON}; held at the prior of an unknown yaw"),
                ),
            },
            "translation x" | "translation y" | "time offset" => (
                row.prior_sigma,
                row.prior_sigma,
                "not trusted",
                format!("{TILT_ONLY_REASON}; held at its prior"),
            ),
            _ => continue,
        };
        (row.sigma, row.prior_sigma, row.status, row.reason) = (sigma, prior, status, reason);
    }
}

/// Marks the rotation rows `not trusted`: when the pose sensor and the gyro disagree on
/// how much the body turned, the filter's rotation sigmas measure agreement with a wrong
/// input, not accuracy, and must not read as `observed`.
fn distrust_rotation(rows: &mut [DofObservability]) {
    for row in rows.iter_mut().filter(|r| r.dof.starts_with("rotation")) {
        row.status = "not trusted";
        row.reason = TILT_ONLY_REASON.into();
    }
}

/// Largest factor by which the pose sensor's and the gyro's total rotation may differ: a few
/// percent is noise and slip; a gyro in deg/s reads 57x, skid-steer wheel odometry
/// several times the true turn.
const MAX_ROTATION_SCALE: f64 = 1.25;

/// The reason to distrust the result when the pose sensor and the gyro disagree on how much
/// the body turned (see [`init::rotation_scale`]).
pub(super) fn rotation_scale_problem(pairs: &[planar::RotationPair]) -> Option<String> {
    let scale = init::rotation_scale(pairs)?;
    (!(1.0 / MAX_ROTATION_SCALE..=MAX_ROTATION_SCALE).contains(&scale)).then(|| {
        format!(
            "pose0 turns {scale:.2}x as much as the gyro over the same intervals: the odometry's \
             rotation is not the body's (wheel slip of a skid-steer base, or a unit error in \
             pose0 or imu0)"
        )
    })
}

#[cfg(test)]
mod tests {
    //! The pose-IMU pipeline on a slipping robot (here, not beside the heading fit in
    //! `planar`, which must not import the pipeline above it).
    use crate::calibrate::driver::report::PoseImuOptions;
    use crate::calibrate::pose_imu::{calibrate, PoseImuInput};
    use crate::dataset::PoseSensorYaml;
    use crate::sim::wheel::{simulate_wheel_drive, small_robot_drive, WheelDriveConfig};
    use nalgebra::{UnitQuaternion, Vector3};

    /// The mounting's tilt in the heading fit's tests (roll, pitch, rad).
    const MOUNT_TILT: (f64, f64) = (0.026, -0.017);

    /// Through the pose-IMU pipeline (seed 21, which chose nothing): a small skid-steer robot
    /// whose odometry turns 4x the gyro has its odometry's rotation refused (not converged),
    /// and the rotation is reported from gravity and the wheel speed, inside 3 sigma of the
    /// mounting's, the yaw row `observed`, the lever arm and time offset `not trusted`.
    #[test]
    fn the_pose_imu_pipeline_reports_the_rotation_of_a_slipping_robot() {
        let yaw = 5f64.to_radians();
        let tilt0 = UnitQuaternion::from_euler_angles(MOUNT_TILT.0, MOUNT_TILT.1, 0.0);
        let sim = simulate_wheel_drive(&WheelDriveConfig {
            seed: 21,
            drive: small_robot_drive(),
            r_i_b: tilt0 * UnitQuaternion::from_euler_angles(0.0, 0.0, yaw),
            yaw_rate_scale: 4.0,
            ..WheelDriveConfig::default()
        });
        let pose_noise = PoseSensorYaml {
            rotation_noise_rad: 0.002,
            translation_noise_m: 0.005,
            rate_hz: Some(50.0),
        };
        let input = PoseImuInput {
            imu: &sim.imu,
            imu_noise: &sim.imu_noise,
            poses: &sim.poses,
            pose_noise: &pose_noise,
        };
        let cal = calibrate::<f64>(&input, &PoseImuOptions::default(), &mut |_| {}).expect("runs");
        assert!(!cal.report.converged);
        let row = |dof: &str| {
            cal.report
                .observability
                .iter()
                .find(|r| r.dof == dof)
                .map(|r| r.status)
                .expect("row")
        };
        assert_eq!(row("rotation z"), "observed");
        assert_eq!(row("translation x"), "not trusted");
        assert_eq!(row("time offset"), "not trusted");
        // The error in the sensor frame (the covariance's: right perturbation of R_I_S).
        let error = (cal.t_imu_sensor.rotation.inverse() * sim.r_i_s).scaled_axis();
        let sigma = cal.covariance.diagonal().map(f64::sqrt);
        println!(
            "pipeline: error {:.3?} deg, sigma {:.3?} deg",
            error.map(f64::to_degrees),
            sigma.fixed_rows::<3>(0).map(f64::to_degrees)
        );
        for k in 0..3 {
            assert!(
                error[k].abs() < 3.0 * sigma[k],
                "axis {k}: {error}, {sigma}"
            );
        }
        assert_eq!(cal.t_imu_sensor.translation.vector, Vector3::zeros());
    }
}

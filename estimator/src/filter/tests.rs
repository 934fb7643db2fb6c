//! Filter-level tests: clone Jacobians, covariance health through updates.

use super::*;
use crate::lie::log;
use crate::lie::Pose;
use crate::propagate::{ImuNoise, ImuSample};
use crate::state::{InitialState, Layout};
use crate::testing::assert_mat_close;
use crate::RelativePose;
use nalgebra::{SMatrix, Vector3};
use nalgebra::{SVector, UnitQuaternion};

pub(super) const T0: u64 = 1_700_000_000_000_000_000;

/// A filter spinning and accelerating with the given time-offset prior.
fn moving_filter(time_offset: f64) -> PoseImuEkf<f64> {
    moving_filter_from(
        InitialState::<f64, 1>::at_rest(Vector3::new(0.0, 0.0, 9.81))
            .expect("gravity")
            .with_time_offset(SOLE_SENSOR, time_offset, 0.01),
    )
}

/// A filter from `init`, spinning and accelerating.
fn moving_filter_from(mut init: InitialState<f64, 1>) -> PoseImuEkf<f64> {
    init.imu.velocity = Vector3::new(0.7, -0.3, 0.2);
    init.imu.rotation = UnitQuaternion::from_euler_angles(0.3, -0.2, 1.0);
    let mut config = FilterConfig::new(ImuNoise::vn300());
    config.health = config.health.with_jump_detector();
    let mut ekf = PoseImuEkf::new(&config, &init).expect("prior");
    for k in 0..=96u64 {
        ekf.propagate(&ImuSample {
            stamp_ns: T0 + k * 2_500_000,
            gyro: Vector3::new(1.2, -0.8, 0.5),
            accel: Vector3::new(0.5, 1.0, 9.0),
        })
        .expect("sample");
    }
    look_ahead(&mut ekf);
    ekf
}

/// One more (constant) reading 20 ms on: the filter stands at `T0 + 240 ms` and can reach
/// any measurement up to `T0 + 260 ms`.
fn look_ahead<const S: usize, const C: usize, const N: usize, const F: usize>(
    ekf: &mut Ekf<f64, S, C, N, F>,
) {
    ekf.propagate(&ImuSample {
        stamp_ns: T0 + 260_000_000,
        gyro: Vector3::new(1.2, -0.8, 0.5),
        accel: Vector3::new(0.5, 1.0, 9.0),
    })
    .expect("look-ahead sample");
    assert_eq!(ekf.time_ns(), T0 + 240_000_000);
}

#[test]
fn clone_time_offset_jacobian_matches_central_differences() {
    // Given a moving IMU and a measurement stamped between two IMU samples
    let stamp = T0 + 240_000_000 + 1_234_567;
    let td = 0.004;
    let h = 1e-4;
    // When the pose is cloned at stamp + t_d for t_d +- h
    let clone_pose = |td: f64| {
        let mut ekf = moving_filter(td);
        ekf.anchor(SOLE_SENSOR, stamp).expect("anchor");
        ekf.imu().pose()
    };
    let (plus, minus) = (clone_pose(td + h), clone_pose(td - h));
    let mut numeric = SVector::<f64, 6>::zeros();
    numeric
        .fixed_rows_mut::<3>(0)
        .copy_from(&(log(&(minus.rotation.inverse() * plus.rotation)) / (2.0 * h)));
    numeric
        .fixed_rows_mut::<3>(3)
        .copy_from(&((plus.translation - minus.translation) / (2.0 * h)));
    // Then the clone's covariance with t_d is d(clone)/d(t_d) * var(t_d)
    let mut ekf = moving_filter(td);
    ekf.anchor(SOLE_SENSOR, stamp).expect("anchor");
    let c = Layout::<1, 2>::clone_orientation(0).idx;
    let t = Layout::<1, 2>::time_offset(SOLE_SENSOR).idx;
    let var = ekf.covariance()[(t, t)];
    let analytic = ekf.covariance().fixed_view::<6, 1>(c, t).clone_owned() / var;
    // The midpoint integrator's position is consistent with its velocity to O(|w| |a| dt^2)
    // (~1e-4 m/s here), which bounds the agreement.
    assert_mat_close(&analytic, &numeric, 2e-4);
}

#[test]
fn slightly_late_measurement_is_fused_at_the_filter_time_and_a_late_one_is_refused() {
    // Given a filter at T0 + 240 ms (t_d = 0)
    let mut ekf = moving_filter(0.0);
    let now = T0 + 240_000_000;
    // When a measurement's IMU time is 0.6 ms behind (a t_d update moved it there)
    ekf.anchor(SOLE_SENSOR, now - 600_000)
        .expect("within max_late_ns");
    // Then it is cloned at the filter time
    assert_eq!(ekf.time_ns(), now);
    // And one 1.5 ms behind is time going backwards, the state untouched
    let mut late = moving_filter(0.0);
    let before = late.covariance();
    assert!(matches!(
        late.anchor(SOLE_SENSOR, now - 1_500_000),
        Err(Error::TimeWentBackwards { .. })
    ));
    assert_eq!(late.covariance(), before);
}

/// Feeds the constant spinning reading at 400 Hz until a measurement at `stamp` is due.
fn spin_until_due(ekf: &mut PoseImuEkf<f64>, stamp: u64) {
    while !ekf.is_due(SOLE_SENSOR, stamp) {
        ekf.propagate(&ImuSample {
            stamp_ns: ekf.imu_horizon_ns().expect("imu") + 2_500_000,
            gyro: Vector3::new(1.2, -0.8, 0.5),
            accel: Vector3::new(0.5, 1.0, 9.0),
        })
        .expect("sample");
    }
}

#[test]
fn covariance_stays_symmetric_and_positive_through_updates() {
    let mut ekf = moving_filter(0.0);
    let t = ekf.time_ns();
    ekf.anchor(SOLE_SENSOR, t).expect("anchor");
    for k in 1..=20u64 {
        let stamp = t + k * 100_000_000;
        spin_until_due(&mut ekf, stamp);
        let m = RelativePose::with_sigmas(stamp - 100_000_000, stamp, Pose::identity(), 0.5, 0.5);
        ekf.update_relative_pose(SOLE_SENSOR, &m).expect("update");
    }
    let p = ekf.covariance();
    assert_mat_close(
        &(p - p.transpose()),
        &SMatrix::<f64, 34, 34>::zeros(),
        1e-12,
    );
    let eig = p.symmetric_eigenvalues();
    assert!(
        eig.min() > -1e-12 * eig.max(),
        "negative eigenvalue {} (largest {})",
        eig.min(),
        eig.max()
    );
}

#[test]
fn relative_pose_failing_after_propagation_and_cloning_takes_both_back() {
    // Given an anchored filter and a measurement whose noise is not positive definite
    // (valid diagonal, so it is found only at the Cholesky of S, after the filter
    // propagated to its end stamp and cloned the IMU pose there)
    let mut ekf = moving_filter(0.0);
    let t = ekf.time_ns();
    ekf.anchor(SOLE_SENSOR, t).expect("anchor");
    let stamp = t + 15_000_000;
    let mut bad = RelativePose::with_sigmas(t, stamp, Pose::identity(), 1e-4, 1e-4);
    bad.covariance[(0, 1)] = 1.0;
    bad.covariance[(1, 0)] = 1.0;
    let before = ekf.clone();
    // When it is fused
    let result = ekf.update_relative_pose(SOLE_SENSOR, &bad);
    // Then it is a typed error and nothing moved: time, state, covariance, clones
    assert_eq!(result, Err(Error::SingularInnovation));
    assert_eq!(ekf.time_ns(), before.time_ns());
    assert_eq!(ekf.imu(), before.imu());
    assert_eq!(ekf.covariance(), before.covariance());
    assert_eq!(ekf.clones, before.clones);
    assert_eq!(ekf.anchors, before.anchors);
    // and the same measurement with valid noise gives bit for bit what it gives on the copy.
    let good = RelativePose::with_sigmas(t, stamp, Pose::identity(), 0.05, 0.05);
    let mut copy = before.clone();
    assert_eq!(
        ekf.update_relative_pose(SOLE_SENSOR, &good),
        copy.update_relative_pose(SOLE_SENSOR, &good)
    );
    assert_eq!(ekf.covariance(), copy.covariance());
    assert_eq!(ekf.imu(), copy.imu());
}

#[test]
fn zero_velocity_belongs_to_no_sensor_and_needs_the_stream_period() {
    // Given a filter at rest with one IMU sample: no period yet, so no zero-velocity update
    let init = InitialState::<f64, 1>::at_rest(Vector3::new(0.0, 0.0, 9.81)).expect("gravity");
    let mut ekf = PoseImuEkf::new(&FilterConfig::new(ImuNoise::vn300()), &init).expect("prior");
    let at_rest = |stamp_ns| ImuSample {
        stamp_ns,
        gyro: Vector3::zeros(),
        accel: Vector3::new(0.0, 0.0, 9.81),
    };
    ekf.propagate(&at_rest(T0)).expect("sample");
    assert_eq!(ekf.imu_period_ns(), None);
    assert_eq!(ekf.update_zero_velocity(), Err(Error::NotInitialized));
    // When a second sample 5 ms on gives the stream its period and the update runs
    ekf.propagate(&at_rest(T0 + 5_000_000)).expect("sample");
    assert_eq!(ekf.imu_period_ns(), Some(5_000_000));
    let report = ekf.update_zero_velocity().expect("update");
    // Then it is accepted, booked on no sensor, and sensor 0's health saw nothing
    assert!(report.accepted);
    assert_eq!(report.sensor, None);
    assert_eq!(report.dof, 9);
    let health = ekf.health().sensor(SOLE_SENSOR).expect("sensor 0");
    assert_eq!((health.accepted, health.rejected), (0, 0));
}

#[test]
fn held_translation_axis_keeps_its_prior_through_relative_pose_updates() {
    // Given a moving filter holding the lever arm along a tilted axis
    let mut ekf = moving_filter(0.0);
    assert_eq!(
        ekf.hold_translation_axis(SensorId::at::<1, 2>(), Some(Vector3::z())),
        Err(Error::UnknownSensor)
    );
    assert_eq!(
        ekf.hold_translation_axis(SOLE_SENSOR, Some(Vector3::zeros())),
        Err(Error::InvalidConfig)
    );
    assert_eq!(
        ekf.hold_translation_axis(SOLE_SENSOR, Some(Vector3::new(f64::NAN, 0.0, 1.0))),
        Err(Error::NonFinite)
    );
    let axis = Vector3::new(0.1, -0.2, 1.0).normalize();
    ekf.hold_translation_axis(SOLE_SENSOR, Some(axis * 3.0))
        .expect("hold");
    assert!((ekf.held_translation_axis(SOLE_SENSOR).expect("held") - axis).norm() < 1e-15);
    let b = Layout::<1, 2>::extrinsic_translation(SOLE_SENSOR).idx;
    let along = |ekf: &PoseImuEkf<f64>| {
        let p = ekf.covariance().fixed_view::<3, 3>(b, b).clone_owned();
        (
            (axis.transpose() * p * axis)[0],
            axis.dot(&ekf.extrinsic(SOLE_SENSOR).translation),
        )
    };
    let (var0, value0) = along(&ekf);
    let sigma_before = ekf.extrinsic_sigma(SOLE_SENSOR).1;
    // When relative poses near the motion the filter predicts, but not on it, are fused
    let t = ekf.time_ns();
    ekf.anchor(SOLE_SENSOR, t).expect("anchor");
    let mut from = ekf.imu().pose();
    for k in 1..=6u64 {
        let stamp = t + k * 100_000_000;
        spin_until_due(&mut ekf, stamp);
        let mut probe = ekf.clone();
        probe.anchor(SOLE_SENSOR, stamp).expect("probe");
        let to = probe.imu().pose();
        let e = ekf.extrinsic(SOLE_SENSOR);
        let predicted = e
            .inverse()
            .compose(&from.inverse().compose(&to))
            .compose(&e);
        let delta = predicted.boxplus(
            &Vector3::new(0.01, 0.0, -0.01),
            &Vector3::new(0.01, -0.02, 0.03),
        );
        let m = RelativePose::with_sigmas(stamp - 100_000_000, stamp, delta, 0.01, 0.02);
        let report = ekf.update_relative_pose(SOLE_SENSOR, &m).expect("update");
        assert!(report.accepted, "update {k}: NIS {}", report.nis);
        from = to;
    }
    // Then the held component keeps its value and variance, and the others learn
    let (var1, value1) = along(&ekf);
    assert!((var1 - var0).abs() < 1e-9 * var0, "{var0} -> {var1}");
    assert!((value1 - value0).abs() < 1e-12, "{value0} -> {value1}");
    let after = ekf.extrinsic_sigma(SOLE_SENSOR).1;
    assert!(after.y < 0.8 * sigma_before.y, "{sigma_before} -> {after}");
}

/// Up to 32 update reports.
type Reports = heapless::Vec<crate::update::UpdateReport<f64>, 32>;

/// A spinning filter (as `moving_filter`) whose extrinsic has converged: its step detectors
/// are armed from the start.
fn converged_moving_filter() -> PoseImuEkf<f64> {
    moving_filter_from(
        InitialState::<f64, 1>::at_rest(Vector3::new(0.0, 0.0, 9.81))
            .expect("gravity")
            .with_extrinsic(SOLE_SENSOR, Pose::identity(), 1e-3, 1e-3),
    )
}

/// Feeds 10 Hz relative poses of the motion the filter predicts, with pose `k` of the
/// odometry seen through the mounting `R_I_S Exp(turn(k))` (a knock: from some `k` on; an
/// odometry glitch: at one `k`); the reports.
fn increments(turn: impl Fn(u64) -> Vector3<f64>, count: u64) -> Reports {
    let mut ekf = converged_moving_filter();
    let t = ekf.time_ns();
    ekf.anchor(SOLE_SENSOR, t).expect("anchor");
    let mut from = ekf.imu().pose();
    let e = ekf.extrinsic(SOLE_SENSOR);
    let mount = |k: u64| e.boxplus(&turn(k), &Vector3::zeros());
    (1..=count)
        .map(|k| {
            let stamp = t + k * 100_000_000;
            spin_until_due(&mut ekf, stamp);
            let mut probe = ekf.clone();
            probe.anchor(SOLE_SENSOR, stamp).expect("probe");
            let to = probe.imu().pose();
            let delta = mount(k - 1)
                .inverse()
                .compose(&from.inverse().compose(&to))
                .compose(&mount(k));
            let m = RelativePose::with_sigmas(stamp - 100_000_000, stamp, delta, 2e-3, 0.01);
            from = to;
            ekf.update_relative_pose(SOLE_SENSOR, &m).expect("update")
        })
        .collect()
}

/// 1 deg about a tilted axis: 8.7 sigma of one increment's 2 mrad.
fn one_degree() -> Vector3<f64> {
    Vector3::new(0.3, -1.0, 0.5).normalize() * 1f64.to_radians()
}

#[test]
fn a_knock_inside_one_increment_holds_the_sensor_out_until_the_increments_after_it_decide() {
    // Given exact increments, then a 2 deg knock inside the fourth (the increments after it
    // see it only through `H_R`, the conjugation by their 0.15 rad rotations; measured:
    // the fourth after it decides, against the 9.2 of 99.99 %)
    let knock = one_degree() * 2.0;
    let reports = increments(|k| if k >= 4 { knock } else { Vector3::zeros() }, 30);
    let accepted: heapless::Vec<bool, 32> = reports.iter().map(|r| r.accepted).collect();
    // Then the gate refuses it, the increments after it are tested but not fused, and the
    // first one whose test decides raises the step with the knock as its estimate
    assert_eq!(&accepted[..4], &[true, true, true, false], "{accepted:?}");
    let fired = reports
        .iter()
        .position(|r| r.event.is_some())
        .unwrap_or_else(|| panic!("the knock must be confirmed: {accepted:?}"));
    assert!(
        (5..12).contains(&fired),
        "confirmed at increment {}",
        fired + 1
    );
    assert!(accepted[4..=fired].iter().all(|a| !a), "{accepted:?}");
    let Some(crate::HealthEvent::RotationStep { step, .. }) = reports[fired].event else {
        panic!("{:?}", reports[fired].event);
    };
    assert!(
        (step - knock).norm() < 0.05 * knock.norm(),
        "{step:?} vs {knock:?}"
    );
}

#[test]
fn a_glitch_of_one_odometry_pose_holds_the_sensor_out_only_until_refuted() {
    // Given exact increments but the fourth odometry pose 1 deg off (the two increments
    // around it both carry it)
    let glitch = one_degree();
    let reports = increments(|k| if k == 4 { glitch } else { Vector3::zeros() }, 16);
    let accepted: heapless::Vec<bool, 32> = reports.iter().map(|r| r.accepted).collect();
    // Then no step is raised, and the increments after it are fused again once refuted
    assert!(reports.iter().all(|r| r.event.is_none()), "{accepted:?}");
    assert_eq!(
        &accepted[..5],
        &[true, true, true, false, false],
        "{accepted:?}"
    );
    assert!(accepted[10..].iter().all(|a| *a), "{accepted:?}");
}

// ----- reprojection update ---------------------------------------------------------------

pub(super) mod reprojection {
    use super::*;
    use crate::camera::{radtan::RadTan, Camera, Distortion, Intrinsics, Projection};
    use crate::filter::CameraImuEkf;
    use crate::update::reprojection::{CornerObservation, CornerSet};
    use crate::update::{UpdateKind, UpdateReport};
    use crate::Error;
    use nalgebra::Vector2;

    /// The image stamp the tests use: between two IMU samples, after the last fed one.
    pub(in crate::filter) const STAMP: u64 = T0 + 240_000_000 + 1_234_567;

    /// The EuRoC-like pinhole-radtan camera of the reprojection tests.
    pub(in crate::filter) fn camera() -> Camera<f64> {
        Camera::new(
            Projection::Pinhole,
            Intrinsics {
                fu: 460.0,
                fv: 458.0,
                cu: 367.0,
                cv: 248.0,
            },
            Distortion::RadTan(RadTan {
                k1: -0.28,
                k2: 0.07,
                p1: 2e-4,
                p2: 2e-5,
                k3: 0.0,
            }),
            (752, 480),
        )
        .expect("camera")
    }

    fn extrinsic() -> Pose<f64> {
        Pose::new(
            UnitQuaternion::from_euler_angles(-1.5, 0.03, -1.6),
            Vector3::new(0.06, -0.02, 0.01),
        )
    }

    /// A 6 x 5 board of 5 cm squares.
    fn board() -> impl Iterator<Item = Vector3<f64>> {
        (0..30).map(|k| Vector3::new(f64::from(k % 6) * 0.05, f64::from(k / 6) * 0.05, 0.0))
    }

    /// The moving IMU of `moving_filter` as a camera-IMU filter, with the target placed
    /// 0.8 m in front of the camera at the image's IMU time.
    fn camera_filter(time_offset: f64) -> CameraImuEkf<f64> {
        let mut init = InitialState::<f64, 1>::at_rest(Vector3::new(0.0, 0.0, 9.81))
            .expect("gravity")
            .with_extrinsic(SOLE_SENSOR, extrinsic(), 0.02, 0.02)
            .with_time_offset(SOLE_SENSOR, time_offset, 0.01);
        init.imu.velocity = Vector3::new(0.7, -0.3, 0.2);
        init.imu.rotation = UnitQuaternion::from_euler_angles(0.3, -0.2, 1.0);
        let mut ekf =
            CameraImuEkf::new(&FilterConfig::new(ImuNoise::vn300()), &init).expect("prior");
        for k in 0..=96u64 {
            ekf.propagate(&ImuSample {
                stamp_ns: T0 + k * 2_500_000,
                gyro: Vector3::new(1.2, -0.8, 0.5),
                accel: Vector3::new(0.5, 1.0, 9.0),
            })
            .expect("sample");
        }
        look_ahead(&mut ekf);
        // The target is placed from the pose 4 ms after the stamp whatever `time_offset` is,
        // so that different offsets see the same static target.
        let mut at_image = ekf.clone();
        at_image.advance_to(STAMP + 4_000_000).expect("advance");
        let target_in_camera = Pose::new(
            UnitQuaternion::from_euler_angles(0.2, -0.3, 0.1),
            Vector3::new(-0.12, -0.1, 0.8),
        );
        let target = at_image
            .imu()
            .pose()
            .compose(&extrinsic())
            .compose(&target_in_camera);
        ekf.init_frame(TARGET_FRAME, target, 0.05, 0.05)
            .expect("frame");
        ekf
    }

    /// Where the filter predicts the corner `p` at the image's IMU time.
    fn predicted(ekf: &CameraImuEkf<f64>, p: &Vector3<f64>) -> Vector2<f64> {
        let mut at_image = ekf.clone();
        // After an update the filter already stands at the image's (then) IMU time.
        let t = at_image
            .imu_time(SOLE_SENSOR, STAMP)
            .expect("sensor")
            .max(at_image.time_ns());
        at_image.advance_to(t).expect("advance");
        let p_c = crate::update::reprojection::point_in_camera(
            &at_image.imu().pose(),
            &at_image.extrinsic(SOLE_SENSOR),
            &at_image.frame(TARGET_FRAME).expect("frame"),
            p,
        );
        camera().project(&p_c).expect("in view").pixel
    }

    /// Fuses `obs` as the image stamped `STAMP` with 0.5 px corners.
    fn fuse(ekf: &mut CameraImuEkf<f64>, obs: &[CornerObservation<f64>]) -> UpdateReport<f64> {
        let meas = CornerSet {
            stamp_ns: STAMP,
            corners: obs,
            pixel_sigma: 0.5,
        };
        ekf.update_reprojection(SOLE_SENSOR, TARGET_FRAME, &camera(), &meas)
            .expect("update")
    }

    fn observations(ekf: &CameraImuEkf<f64>, offset_px: f64) -> [CornerObservation<f64>; 30] {
        let mut out = [CornerObservation {
            point_in_target: Vector3::zeros(),
            pixel: Vector2::zeros(),
        }; 30];
        for (o, p) in out.iter_mut().zip(board()) {
            *o = CornerObservation {
                point_in_target: p,
                pixel: predicted(ekf, &p) + Vector2::new(offset_px, -0.5 * offset_px),
            };
        }
        out
    }

    #[test]
    fn jacobian_matches_central_differences_over_the_whole_state() {
        // Given a moving filter with a target in view, standing at the image's IMU time
        let td = 0.004;
        let corner = Vector3::new(0.15, 0.05, 0.0);
        let mut at_image = camera_filter(td);
        at_image
            .advance_to(at_image.imu_time(SOLE_SENSOR, STAMP).expect("sensor"))
            .expect("advance");
        // When every error-state direction is perturbed there
        let h = 1e-6;
        let mut numeric = SMatrix::<f64, 2, 28>::zeros();
        for i in 0..28 {
            let shifted = |sign: f64| {
                let mut e = at_image.clone();
                let mut dx = SVector::<f64, 28>::zeros();
                dx[i] = sign * h;
                e.apply_correction(&dx).expect("finite");
                predicted(&e, &corner)
            };
            numeric.set_column(i, &((shifted(1.0) - shifted(-1.0)) / (2.0 * h)));
        }
        // and the time offset through the propagation to a later or earlier IMU time
        let h_td = 1e-5;
        let td_column = (predicted(&camera_filter(td + h_td), &corner)
            - predicted(&camera_filter(td - h_td), &corner))
            / (2.0 * h_td);
        numeric.set_column(Layout::<1, 0>::time_offset(SOLE_SENSOR).idx, &td_column);
        // Then the analytic Jacobian the update uses agrees
        let lin = crate::update::reprojection::linearize(
            &camera(),
            &at_image.imu().pose(),
            &at_image.extrinsic(SOLE_SENSOR),
            &at_image.frame(TARGET_FRAME).expect("frame"),
            &corner,
            &Vector2::zeros(),
        )
        .expect("in view");
        let gyro = at_image.imu_now.expect("imu").gyro;
        let analytic: SMatrix<f64, 2, 28> = at_image
            .reprojection_jacobian(SOLE_SENSOR, TARGET_FRAME, &lin, &gyro)
            .to_dense();
        // Pixels per unit error are O(500); the time-offset column carries the midpoint
        // integrator's O(|w| |a| dt^2) velocity inconsistency, as in the clone test.
        assert_mat_close(&(analytic / 1000.0), &(numeric / 1000.0), 2e-4);
    }

    #[test]
    fn consistent_corners_are_fused_and_shrink_the_extrinsic() {
        let mut ekf = camera_filter(0.0);
        let obs = observations(&ekf, 0.3);
        let before = ekf.extrinsic_sigma(SOLE_SENSOR);
        let report = fuse(&mut ekf, &obs);
        assert_eq!(report.kind, UpdateKind::Reprojection);
        assert_eq!(report.dof, 60);
        assert!(report.accepted, "nis {} > {}", report.nis, report.threshold);
        let after = ekf.extrinsic_sigma(SOLE_SENSOR);
        assert!(after.0.norm() < before.0.norm() && after.1.norm() < before.1.norm());
        // The corners now reproject closer to where they were seen.
        let residual: f64 = obs
            .iter()
            .map(|o| (o.pixel - predicted(&ekf, &o.point_in_target)).norm())
            .sum::<f64>()
            / 30.0;
        assert!(residual < 0.2, "mean residual {residual} px");
    }

    #[test]
    fn corners_fused_one_by_one_equal_the_batch_update_of_the_stacked_image() {
        // Given a filter at the image's IMU time and corners 3 px off its prediction
        let mut ekf = camera_filter(0.0);
        let obs = observations(&ekf, 3.0);
        let mut prior = ekf.clone();
        prior
            .advance_to(prior.imu_time(SOLE_SENSOR, STAMP).expect("sensor"))
            .expect("advance");
        let p0 = prior.covariance();
        let gyro = prior.imu_now.expect("imu").gyro;
        // When the textbook batch update is formed from all 60 rows, linearised at the prior
        let mut h = SMatrix::<f64, 60, 28>::zeros();
        let mut r = SVector::<f64, 60>::zeros();
        for (k, o) in obs.iter().enumerate() {
            let lin = crate::update::reprojection::linearize(
                &camera(),
                &prior.imu().pose(),
                &prior.extrinsic(SOLE_SENSOR),
                &prior.frame(TARGET_FRAME).expect("frame"),
                &o.point_in_target,
                &o.pixel,
            )
            .expect("in view");
            let rows: SMatrix<f64, 2, 28> = prior
                .reprojection_jacobian(SOLE_SENSOR, TARGET_FRAME, &lin, &gyro)
                .to_dense();
            h.fixed_view_mut::<2, 28>(2 * k, 0).copy_from(&rows);
            r.fixed_rows_mut::<2>(2 * k).copy_from(&lin.residual);
        }
        let s = h * p0 * h.transpose() + SMatrix::<f64, 60, 60>::identity() * 0.25;
        let s_inv = s.try_inverse().expect("S invertible");
        let k = p0 * h.transpose() * s_inv;
        let dx = k * r;
        let p_batch = (SMatrix::<f64, 28, 28>::identity() - k * h) * p0;
        // Then the corner-by-corner update gives the same covariance, correction and NIS
        let report = fuse(&mut ekf, &obs);
        assert!(report.accepted);
        assert!((report.nis - r.dot(&(s_inv * r))).abs() < 1e-8 * report.nis);
        let scale = p0.amax();
        assert!((ekf.covariance() - p_batch).amax() < 1e-9 * scale);
        let e = Layout::<1, 0>::extrinsic_rotation(SOLE_SENSOR).idx;
        let expected = prior.extrinsic(SOLE_SENSOR).boxplus(
            &dx.fixed_rows::<3>(e).into_owned(),
            &dx.fixed_rows::<3>(e + 3).into_owned(),
        );
        let got = ekf.extrinsic(SOLE_SENSOR);
        assert!(log(&(got.rotation.inverse() * expected.rotation)).norm() < 1e-10);
        assert!((got.translation - expected.translation).norm() < 1e-10);
        // (the prior's correction is not small: the test would see a relinearised update)
        assert!(
            dx.fixed_rows::<3>(e).norm() > 1e-3,
            "{}",
            dx.fixed_rows::<3>(e).norm()
        );
    }

    #[test]
    fn an_outlying_corner_is_dropped_and_the_rest_of_the_image_fused() {
        let mut ekf = camera_filter(0.0);
        let mut obs = observations(&ekf, 0.3);
        // 300 px: far outside that corner's own predicted spread (~50 px).
        obs[7].pixel.x += 300.0;
        let report = fuse(&mut ekf, &obs);
        assert!(report.accepted, "nis {} > {}", report.nis, report.threshold);
        assert_eq!(report.dof, 58);
        let residual = |k: usize| (obs[k].pixel - predicted(&ekf, &obs[k].point_in_target)).norm();
        assert!(
            residual(6) < 0.5 && residual(8) < 0.5,
            "{} {}",
            residual(6),
            residual(8)
        );
        assert!(residual(7) > 250.0);
    }

    #[test]
    fn outlying_image_is_gated_and_leaves_the_estimate() {
        let mut ekf = camera_filter(0.0);
        // Every corner 45 px off, alternately one way and the other: each alone is inside
        // its prior (the target's 5 cm are ~50 px), the image as a whole fits no state. (A
        // common 45 px shift is not an outlier: a small target rotation inside its prior
        // explains it, and the batch update accepts it.)
        let mut obs = observations(&ekf, 40.0);
        for o in obs.iter_mut().skip(1).step_by(2) {
            o.pixel -= Vector2::new(80.0, -40.0);
        }
        let before = ekf.clone();
        let report = fuse(&mut ekf, &obs);
        assert!(!report.accepted);
        assert_eq!(ekf.imu(), before.imu());
        assert_eq!(ekf.extrinsic(SOLE_SENSOR), before.extrinsic(SOLE_SENSOR));
        assert_eq!(ekf.frame(TARGET_FRAME), before.frame(TARGET_FRAME));
        assert_eq!(ekf.covariance(), before.covariance());
    }

    #[test]
    fn bad_corner_sets_are_typed_errors_with_the_state_untouched() {
        let ekf = camera_filter(0.0);
        let obs = observations(&ekf, 0.0);
        let mut nan = obs;
        nan[3].pixel.x = f64::NAN;
        /// Sensor, frame, corners, pixel sigma, stamp, expected error.
        type Case<'a> = (usize, usize, &'a [CornerObservation<f64>], f64, u64, Error);
        let cases: [Case; 6] = [
            (1, 0, &obs, 0.5, STAMP, Error::UnknownSensor),
            (0, 1, &obs, 0.5, STAMP, Error::UnknownFrame),
            (0, 0, &[], 0.5, STAMP, Error::EmptyMeasurement),
            (0, 0, &nan, 0.5, STAMP, Error::NonFinite),
            (0, 0, &obs, 0.0, STAMP, Error::InvalidConfig),
            (
                0,
                0,
                &obs,
                0.5,
                T0,
                Error::TimeWentBackwards {
                    filter_ns: T0 + 240_000_000,
                    stamp_ns: T0,
                },
            ),
        ];
        for (s, f, corners, sigma, stamp, expected) in cases {
            // Ids of a wider layout than the filter's: they can still reach it.
            let s = SensorId::new::<2>(s).expect("sensor of the wider layout");
            let f = FrameId::new::<2>(f).expect("frame of the wider layout");
            let mut e = ekf.clone();
            let meas = CornerSet {
                stamp_ns: stamp,
                corners,
                pixel_sigma: sigma,
            };
            assert_eq!(e.update_reprojection(s, f, &camera(), &meas), Err(expected));
            assert_eq!(e.covariance(), ekf.covariance());
            assert_eq!(e.imu(), ekf.imu());
        }
        // A target not yet initialised.
        let mut fresh = CameraImuEkf::new(
            &FilterConfig::new(ImuNoise::vn300()),
            &InitialState::at_rest(Vector3::new(0.0, 0.0, 9.81)).expect("gravity"),
        )
        .expect("prior");
        let meas = CornerSet {
            stamp_ns: STAMP,
            corners: &obs,
            pixel_sigma: 0.5,
        };
        assert_eq!(
            fresh.update_reprojection(SOLE_SENSOR, TARGET_FRAME, &camera(), &meas),
            Err(Error::FrameNotInitialized)
        );
    }
}

/// Two seconds of a changing 400 Hz signal (up to 2.2 rad/s) with a 10 Hz relative pose a
/// little off the prediction, in the filter `config` gives: the final IMU state, extrinsic
/// and covariance.
fn series_run<T: Scalar>(rotations: Rotations) -> (ImuState<T>, Pose<T>, SMatrix<T, 34, 34>) {
    let mut config = FilterConfig::new(ImuNoise::<T>::vn300());
    config.rotations = rotations;
    let init = InitialState::<T, 1>::at_rest(Vector3::new(T::zero(), T::zero(), T::lit(9.81)))
        .expect("gravity")
        .with_extrinsic(SOLE_SENSOR, Pose::identity(), T::lit(0.05), T::lit(0.05));
    let mut ekf = PoseImuEkf::<T>::new(&config, &init).expect("prior");
    let sample = |k: u64| {
        let t = k as f64 * 0.0025;
        let v = |a: f64, f: f64| T::lit(a * (f * t).sin());
        ImuSample {
            stamp_ns: T0 + k * 2_500_000,
            gyro: Vector3::new(v(1.5, 3.0), v(-1.2, 2.3), v(0.8, 4.1)),
            accel: Vector3::new(v(2.0, 1.7), v(1.5, 2.9), T::lit(9.81) + v(1.0, 3.7)),
        }
    };
    ekf.propagate(&sample(0)).expect("first");
    ekf.propagate(&sample(1)).expect("second");
    ekf.anchor(SOLE_SENSOR, T0).expect("anchor");
    let mut from = ekf.imu().pose();
    for k in 2..=801u64 {
        ekf.propagate(&sample(k)).expect("sample");
        let stamp = T0 + (k - 1) * 2_500_000;
        if (k - 1) % 40 == 0 && ekf.is_due(SOLE_SENSOR, stamp) {
            let mut probe = ekf.clone();
            probe.anchor(SOLE_SENSOR, stamp).expect("probe");
            let to = probe.imu().pose();
            let off = Pose::new(
                crate::lie::exp(&Vector3::new(T::lit(2e-3), T::lit(-1e-3), T::lit(1.5e-3))),
                Vector3::new(T::lit(4e-3), T::lit(-2e-3), T::lit(3e-3)),
            );
            let delta = from.inverse().compose(&to).compose(&off);
            let m = RelativePose::with_sigmas(
                stamp - 100_000_000,
                stamp,
                delta,
                T::lit(2e-3),
                T::lit(0.01),
            );
            ekf.update_relative_pose(SOLE_SENSOR, &m).expect("update");
            from = to;
        }
    }
    (*ekf.imu(), ekf.extrinsic(SOLE_SENSOR), ekf.covariance())
}

/// The largest difference between two runs, relative to the larger magnitude of each
/// compared quantity (rotations by their angle).
fn series_difference<T: Scalar>(
    a: &(ImuState<T>, Pose<T>, SMatrix<T, 34, 34>),
    b: &(ImuState<T>, Pose<T>, SMatrix<T, 34, 34>),
) -> [f64; 4] {
    let rel = |x: &[T], y: &[T]| {
        let scale = x
            .iter()
            .chain(y)
            .fold(0.0f64, |m, v| m.max(v.to_f64().abs()));
        x.iter()
            .zip(y)
            .fold(0.0f64, |m, (p, q)| m.max((p.to_f64() - q.to_f64()).abs()))
            / scale
    };
    let pos = rel(a.0.position.as_slice(), b.0.position.as_slice());
    let rot = a.0.rotation.angle_to(&b.0.rotation).to_f64()
        + a.1.rotation.angle_to(&b.1.rotation).to_f64();
    let lever = rel(a.1.translation.as_slice(), b.1.translation.as_slice());
    // The diagonal: covariances span 1e-12..1 across blocks, so entry by entry.
    let cov = (0..34).fold(0.0f64, |m, i| {
        let (p, q) = (a.2[(i, i)].to_f64(), b.2[(i, i)].to_f64());
        m.max((p - q).abs() / p.abs().max(q.abs()))
    });
    [pos, rot, lever, cov]
}

#[test]
fn series_rotations_change_the_filter_by_rounding_only() {
    let f64_diff = series_difference(
        &series_run::<f64>(Rotations::Trigonometric),
        &series_run::<f64>(Rotations::Series),
    );
    // f32 with the series against the f64 reference, beside f32 with libm against it: the
    // series add nothing to what single precision itself costs.
    let reference = series_run::<f64>(Rotations::Trigonometric);
    let widen = |r: (ImuState<f32>, Pose<f32>, SMatrix<f32, 34, 34>)| {
        (
            ImuState {
                rotation: r.0.rotation.cast(),
                position: r.0.position.cast(),
                velocity: r.0.velocity.cast(),
                gyro_bias: r.0.gyro_bias.cast(),
                accel_bias: r.0.accel_bias.cast(),
            },
            Pose::new(r.1.rotation.cast(), r.1.translation.cast()),
            r.2.cast::<f64>(),
        )
    };
    let f32_series = series_difference(&reference, &widen(series_run::<f32>(Rotations::Series)));
    let f32_trig = series_difference(
        &reference,
        &widen(series_run::<f32>(Rotations::Trigonometric)),
    );
    assert!(f64_diff.iter().all(|d| *d < 1.5e-13), "{f64_diff:?}");
    for (s, t) in f32_series.iter().zip(&f32_trig) {
        assert!(*s < 3.0 * t.max(1e-6), "{f32_series:?} vs {f32_trig:?}");
    }
}

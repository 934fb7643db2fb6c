//! Tests of [`Ekf::init_frame_relative`]: Jacobians against central differences, the
//! covariance it writes against the dense `A P A^T + B R B^T`, the time-offset column against
//! a re-run at `t_d +- h`, every error leaving the filter unchanged, f32 against f64.

use super::frame_relative::compose_frame;
use super::*;
use crate::lie::{log, Pose};
use crate::propagate::{ImuNoise, ImuSample};
use crate::state::{InitialState, Layout};
use crate::testing::{assert_mat_close, central_diff};
use nalgebra::{SMatrix, SVector, UnitQuaternion, Vector3};

const T0: u64 = 1_700_000_000_000_000_000;
/// The image stamp (sensor clock), between two IMU samples.
pub(super) const STAMP: u64 = T0 + 240_000_000 + 1_234_567;

pub(super) fn extrinsic<T: Scalar>() -> Pose<T> {
    Pose::new(
        UnitQuaternion::from_euler_angles(T::lit(-1.5), T::lit(0.03), T::lit(-1.6)),
        Vector3::new(T::lit(0.06), T::lit(-0.02), T::lit(0.01)),
    )
}

pub(super) fn target_in_sensor<T: Scalar>() -> Pose<T> {
    Pose::new(
        UnitQuaternion::from_euler_angles(T::lit(0.2), T::lit(-0.3), T::lit(0.1)),
        Vector3::new(T::lit(-0.12), T::lit(-0.1), T::lit(0.8)),
    )
}

/// A PnP-like covariance: correlated rotation and translation.
pub(super) fn measurement_cov<T: Scalar>() -> SMatrix<T, 6, 6> {
    let a = SMatrix::<f64, 6, 6>::from_fn(|r, c| ((r * 5 + c * 3) % 7) as f64 * 1e-3);
    let m = a * a.transpose() + SMatrix::<f64, 6, 6>::identity() * 1e-5;
    m.map(T::lit)
}

/// Places the camera filter's target from the PnP-like [`target_in_sensor`] with
/// [`measurement_cov`] at [`STAMP`], as the pipeline does.
pub(super) fn place_target<T: Scalar>(ekf: &mut CameraImuEkf<T>) -> Result<(), Error> {
    ekf.init_frame_relative(
        TARGET_FRAME,
        SOLE_SENSOR,
        STAMP,
        &target_in_sensor(),
        &measurement_cov(),
    )
}

/// A spinning, accelerating camera-IMU filter standing at `T0 + 240 ms`, reach to 260 ms.
pub(super) fn camera_filter<T: Scalar>(time_offset: f64) -> CameraImuEkf<T> {
    let mut init = InitialState::<T, 1>::at_rest(Vector3::new(T::zero(), T::zero(), T::lit(9.81)))
        .expect("gravity")
        .with_extrinsic(SOLE_SENSOR, extrinsic(), T::lit(0.02), T::lit(0.02))
        .with_time_offset(SOLE_SENSOR, T::lit(time_offset), T::lit(0.01));
    init.imu.velocity = Vector3::new(T::lit(0.7), T::lit(-0.3), T::lit(0.2));
    init.imu.rotation = UnitQuaternion::from_euler_angles(T::lit(0.3), T::lit(-0.2), T::lit(1.0));
    let config = FilterConfig::new(ImuNoise::vn300());
    let mut ekf = CameraImuEkf::new(&config, &init).expect("prior");
    let stamps = (0..=96u64)
        .map(|k| T0 + k * 2_500_000)
        .chain([T0 + 260_000_000]);
    for (k, stamp_ns) in stamps.enumerate() {
        let k = T::lit(k as f64);
        ekf.propagate(&ImuSample {
            stamp_ns,
            gyro: Vector3::new(T::lit(1.2), T::lit(-0.8), T::lit(0.5) + k * T::lit(0.01)),
            accel: Vector3::new(T::lit(0.5), T::lit(1.0), T::lit(9.0)),
        })
        .expect("sample");
    }
    ekf
}

#[test]
fn compose_frame_jacobians_match_central_differences() {
    let t_g_i = Pose::new(
        UnitQuaternion::from_euler_angles(0.3, -0.2, 1.0),
        Vector3::new(0.4, -1.0, 0.3),
    );
    let (t_i_s, t_s_f) = (extrinsic::<f64>(), target_in_sensor::<f64>());
    let jac = compose_frame(&t_g_i, &t_i_s, &t_s_f);
    let error = |p: &Pose<f64>| {
        let mut e = SVector::<f64, 6>::zeros();
        e.fixed_rows_mut::<3>(0)
            .copy_from(&log(&(jac.pose.rotation.inverse() * p.rotation)));
        e.fixed_rows_mut::<3>(3)
            .copy_from(&(p.translation - jac.pose.translation));
        e
    };
    let v = |d: &SVector<f64, 3>| Vector3::new(d[0], d[1], d[2]);
    let rot = |p: &Pose<f64>, d: SVector<f64, 3>| p.boxplus(&v(&d), &Vector3::zeros());
    let pos = |p: &Pose<f64>, d: SVector<f64, 3>| p.boxplus(&Vector3::zeros(), &v(&d));
    let blocks: [SMatrix<f64, 6, 3>; 4] = [
        central_diff(|d| error(&compose_frame(&rot(&t_g_i, d), &t_i_s, &t_s_f).pose)),
        central_diff(|d| error(&compose_frame(&pos(&t_g_i, d), &t_i_s, &t_s_f).pose)),
        central_diff(|d| error(&compose_frame(&t_g_i, &rot(&t_i_s, d), &t_s_f).pose)),
        central_diff(|d| error(&compose_frame(&t_g_i, &pos(&t_i_s, d), &t_s_f).pose)),
    ];
    for (analytic, numeric) in jac.state.iter().zip(blocks.iter()) {
        assert_mat_close(analytic, numeric, 1e-8);
    }
    let numeric: SMatrix<f64, 6, 6> = central_diff(|d: SVector<f64, 6>| {
        let m = t_s_f.boxplus(
            &Vector3::new(d[0], d[1], d[2]),
            &Vector3::new(d[3], d[4], d[5]),
        );
        error(&compose_frame(&t_g_i, &t_i_s, &m).pose)
    });
    assert_mat_close(&jac.measurement, &numeric, 1e-8);
}

/// The dense form: the new covariance is `A P A^T + B R B^T` with `A` the identity whose
/// frame rows are the frame's Jacobian (and whose frame columns are zero: the old frame is
/// dropped), `B` the measurement Jacobian in the frame rows.
#[test]
fn frame_covariance_is_the_dense_linear_transform_of_the_state() {
    let mut before = camera_filter::<f64>(0.004);
    let t = before.imu_time(SOLE_SENSOR, STAMP).expect("sensor");
    before.advance_to(t).expect("advance");
    let p = before.covariance();
    let mut ekf = camera_filter::<f64>(0.004);
    place_target(&mut ekf).expect("frame");
    let jac = compose_frame(
        &before.imu().pose(),
        &before.extrinsic(SOLE_SENSOR),
        &target_in_sensor(),
    );
    let w = before.imu_now.expect("reading").gyro - before.imu().gyro_bias;
    let fr = Layout::<1, 0>::frame_orientation(TARGET_FRAME).idx;
    let mut a = SMatrix::<f64, 28, 28>::identity();
    a.fixed_view_mut::<6, 6>(fr, fr).fill(0.0);
    let cols = [
        0,
        3,
        Layout::<1, 0>::extrinsic_rotation(SOLE_SENSOR).idx,
        Layout::<1, 0>::extrinsic_translation(SOLE_SENSOR).idx,
    ];
    for (c, b) in cols.iter().zip(jac.state.iter()) {
        a.fixed_view_mut::<6, 3>(fr, *c).copy_from(b);
    }
    let td = Layout::<1, 0>::time_offset(SOLE_SENSOR).idx;
    let j_td = jac.state[0] * w + jac.state[1] * before.imu().velocity;
    a.fixed_view_mut::<6, 1>(fr, td).copy_from(&j_td);
    let mut b = SMatrix::<f64, 28, 6>::zeros();
    b.fixed_view_mut::<6, 6>(fr, 0).copy_from(&jac.measurement);
    let dense = a * p * a.transpose() + b * measurement_cov::<f64>() * b.transpose();
    assert_mat_close(&ekf.covariance(), &dense, 1e-12);
    assert_eq!(ekf.frame(TARGET_FRAME), Some(jac.pose));
    assert!(ekf.covariance().cholesky().is_some());
}

/// The frame's correlation with `t_d`: the pose it is placed at moves with `t_d` by
/// `[w; v]` through the IMU pose, checked by re-running at `t_d +- h`.
#[test]
fn frame_time_offset_column_matches_central_differences() {
    let (td, h) = (0.004, 1e-4);
    let frame_at = |td: f64| {
        let mut ekf = camera_filter::<f64>(td);
        place_target(&mut ekf).expect("frame");
        ekf.frame(TARGET_FRAME).expect("frame")
    };
    let (plus, minus) = (frame_at(td + h), frame_at(td - h));
    let mut numeric = SVector::<f64, 6>::zeros();
    numeric
        .fixed_rows_mut::<3>(0)
        .copy_from(&(log(&(minus.rotation.inverse() * plus.rotation)) / (2.0 * h)));
    numeric
        .fixed_rows_mut::<3>(3)
        .copy_from(&((plus.translation - minus.translation) / (2.0 * h)));
    let mut ekf = camera_filter::<f64>(td);
    place_target(&mut ekf).expect("frame");
    let t = Layout::<1, 0>::time_offset(SOLE_SENSOR).idx;
    let fr = Layout::<1, 0>::frame_orientation(TARGET_FRAME).idx;
    let cov = ekf.covariance();
    let analytic = cov.fixed_view::<6, 1>(fr, t).clone_owned() / cov[(t, t)];
    // As for the clones: the integrator's position agrees with its velocity to
    // O(|w| |a| dt^2), which bounds the agreement.
    assert_mat_close(&analytic, &numeric, 2e-4);
}

/// Frame, sensor (indices into a layout twice as wide as the filter's: ids made for a larger
/// layout still reach it), stamp, measurement, its covariance and the error expected.
type Case = (usize, usize, u64, Pose<f64>, SMatrix<f64, 6, 6>, Error);

#[test]
fn every_error_leaves_the_filter_unchanged() {
    let good = measurement_cov::<f64>();
    let mut asym = good;
    asym[(0, 1)] += 1e-3;
    let mut indefinite = good;
    indefinite[(2, 2)] = -1e-3;
    let mut nan = good;
    nan[(4, 4)] = f64::NAN;
    let far = Pose::new(
        UnitQuaternion::identity(),
        Vector3::new(f64::INFINITY, 0.0, 0.0),
    );
    let cases: [Case; 7] = [
        (1, 0, STAMP, target_in_sensor(), good, Error::UnknownFrame),
        (0, 1, STAMP, target_in_sensor(), good, Error::UnknownSensor),
        (0, 0, STAMP, far, good, Error::NonFinite),
        (0, 0, STAMP, target_in_sensor(), nan, Error::NonFinite),
        (0, 0, STAMP, target_in_sensor(), asym, Error::InvalidConfig),
        (
            0,
            0,
            STAMP,
            target_in_sensor(),
            indefinite,
            Error::InvalidConfig,
        ),
        (
            0,
            0,
            T0 + 300_000_000,
            target_in_sensor(),
            good,
            Error::NotYetDue {
                imu_time_ns: T0 + 304_000_000,
                horizon_ns: T0 + 260_000_000,
            },
        ),
    ];
    for (f, s, stamp, pose, cov, expected) in cases {
        let f = FrameId::new::<2>(f).expect("frame of the wider layout");
        let s = SensorId::new::<2>(s).expect("sensor of the wider layout");
        let mut ekf = camera_filter::<f64>(0.004);
        let (p, x, time) = (ekf.covariance(), *ekf.imu(), ekf.time_ns());
        assert_eq!(
            ekf.init_frame_relative(f, s, stamp, &pose, &cov),
            Err(expected)
        );
        assert_eq!(ekf.covariance(), p);
        assert_eq!(*ekf.imu(), x);
        assert_eq!(ekf.time_ns(), time);
        assert_eq!(ekf.frame(TARGET_FRAME), None);
    }
}

#[test]
fn f32_agrees_with_f64() {
    let mut wide = camera_filter::<f64>(0.004);
    let mut narrow = camera_filter::<f32>(0.004);
    place_target(&mut wide).expect("f64");
    place_target(&mut narrow).expect("f32");
    let (a, b) = (
        wide.frame(TARGET_FRAME).expect("f64"),
        narrow.frame(TARGET_FRAME).expect("f32"),
    );
    let rotation = b.rotation.cast::<f64>().inverse() * a.rotation;
    assert!(rotation.angle() < 1e-5, "{}", rotation.angle());
    assert!((b.translation.cast::<f64>() - a.translation).norm() < 1e-5);
    let (pa, pb) = (
        wide.frame_covariance(TARGET_FRAME),
        narrow.frame_covariance(TARGET_FRAME).cast::<f64>(),
    );
    assert!(
        (pa - pb).amax() < 1e-5 * pa.amax(),
        "{}",
        (pa - pb).amax() / pa.amax()
    );
}

// The Student-t reweighting of a relative pose (`HealthConfig::odometry_dof`, fuse.rs), here
// for want of a test file of the relative-pose update's own.

/// A spinning pose-IMU filter with the given Student-t dof, anchored at `T0 + 240 ms` and
/// propagated until an increment ending 50 ms later is due; that stamp.
fn anchored_filter(odometry_dof: f64) -> (PoseImuEkf<f64>, u64) {
    let mut init = InitialState::<f64, 1>::at_rest(Vector3::new(0.0, 0.0, 9.81)).expect("gravity");
    init.imu.velocity = Vector3::new(0.7, -0.3, 0.2);
    let mut config = FilterConfig::new(ImuNoise::vn300());
    config.health.odometry_dof = odometry_dof;
    let mut ekf = PoseImuEkf::new(&config, &init).expect("prior");
    let sample = |k: u64| ImuSample {
        stamp_ns: T0 + k * 2_500_000,
        gyro: Vector3::new(1.2, -0.8, 0.5),
        accel: Vector3::new(0.5, 1.0, 9.0),
    };
    for k in 0..=104u64 {
        ekf.propagate(&sample(k)).expect("sample");
    }
    let anchor = ekf.time_ns();
    ekf.anchor(SOLE_SENSOR, anchor).expect("anchor");
    let stamp = anchor + 50_000_000;
    let mut k = 105;
    while !ekf.is_due(SOLE_SENSOR, stamp) {
        ekf.propagate(&sample(k)).expect("sample");
        k += 1;
    }
    (ekf, stamp)
}

/// The identity increment (the filter spins at ~1.5 rad/s: a ~4 deg residual) over
/// `[stamp - 50 ms, stamp]` with covariance `cov`, fused in a fresh filter of `dof`.
fn fused_increment(
    dof: f64,
    cov: &SMatrix<f64, 6, 6>,
) -> (PoseImuEkf<f64>, crate::UpdateReport<f64>) {
    let (mut ekf, stamp) = anchored_filter(dof);
    let m = crate::RelativePose {
        stamp_from_ns: stamp - 50_000_000,
        stamp_to_ns: stamp,
        delta: Pose::identity(),
        covariance: *cov,
    };
    let report = ekf.update_relative_pose(SOLE_SENSOR, &m).expect("update");
    (ekf, report)
}

#[test]
fn an_outlying_increment_is_fused_at_its_student_t_weight() {
    // A noise that puts the increment's NIS between its dof (6) and the gate (22.5).
    let cov = SMatrix::<f64, 6, 6>::identity() * 0.03f64.powi(2);
    let (gaussian, g) = fused_increment(f64::INFINITY, &cov);
    assert!(g.nis > 6.0 && g.accepted, "premise: {}", g.nis);
    let (robust, r) = fused_increment(4.0, &cov);
    // The gate and the report keep the stated noise.
    assert_eq!(
        (r.nis, r.accepted, r.threshold),
        (g.nis, g.accepted, g.threshold)
    );
    // The state and covariance are a Gaussian update's at the noise divided by the weight.
    let w = crate::update::relative_pose::student_t_weight(g.nis, 6, 4.0);
    let (weighted, _) = fused_increment(f64::INFINITY, &(cov / w));
    assert_mat_close(&robust.covariance(), &weighted.covariance(), 1e-12);
    let angle = |e: &PoseImuEkf<f64>| e.extrinsic(SOLE_SENSOR).rotation;
    assert!(angle(&robust).angle_to(&angle(&weighted)) < 1e-12);
    // ... and not the unweighted update's: less information gained.
    let trace = |e: &PoseImuEkf<f64>| e.covariance().trace();
    assert!(trace(&robust) > trace(&gaussian) + 1e-9);
    // An inlier (NIS below 6) is fused as by the Gaussian filter.
    let wide = SMatrix::<f64, 6, 6>::identity() * 0.2f64.powi(2);
    let (g, _) = fused_increment(f64::INFINITY, &wide);
    let (r, report) = fused_increment(4.0, &wide);
    assert!(report.nis < 6.0, "premise: {}", report.nis);
    assert_eq!(g.covariance(), r.covariance());
}

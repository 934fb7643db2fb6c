//! The joint layout (issue 12 item 3, issue 13): IMU, LiDAR (sensor 0), camera (sensor 1),
//! four clones and the board as static frame 0, `JointEkf`, N = 59. The board-plane update
//! over the whole state, its coupling of the two extrinsics through the target, typed errors
//! with the state untouched, and f32 against f64.

use super::tests::T0;
use super::*;
use crate::camera::{Camera, Distortion, Intrinsics, Projection};
use crate::lie::Pose;
use crate::propagate::{ImuNoise, ImuSample};
use crate::state::{InitialState, Layout};
use crate::testing::assert_mat_close;
use crate::update::board_plane::{self, BoardPlane};
use crate::update::reprojection::{CornerObservation, CornerSet};
use crate::update::UpdateKind;
use nalgebra::{SMatrix, SVector, UnitQuaternion, Vector2, Vector3};

use super::{JOINT_CAMERA as CAMERA, JOINT_LIDAR as LIDAR};
/// The scan / image stamp: between two IMU samples, after the last fed one.
const STAMP: u64 = T0 + 240_000_000 + 1_234_567;
const N: usize = 59;

fn lidar_mount<T: Scalar>() -> Pose<T> {
    Pose::new(
        UnitQuaternion::from_euler_angles(T::lit(0.02), T::lit(-0.03), T::lit(0.4)),
        Vector3::new(T::lit(0.1), T::lit(0.05), T::lit(0.2)),
    )
}

fn camera_mount<T: Scalar>() -> Pose<T> {
    Pose::new(
        UnitQuaternion::from_euler_angles(T::lit(-1.5), T::lit(0.03), T::lit(-1.6)),
        Vector3::new(T::lit(0.06), T::lit(-0.02), T::lit(0.01)),
    )
}

fn camera<T: Scalar>() -> Camera<T> {
    let intrinsics = Intrinsics {
        fu: T::lit(460.0),
        fv: T::lit(458.0),
        cu: T::lit(367.0),
        cv: T::lit(248.0),
    };
    Camera::new(
        Projection::Pinhole,
        intrinsics,
        Distortion::None,
        (752, 480),
    )
    .expect("camera")
}

/// The spinning, accelerating IMU of the filter tests as a joint filter, with the board
/// 1.2 m in front of the camera at the scan's IMU time (placed from the pose 4 ms after
/// the stamp whatever the LiDAR's `time_offset`, so that offsets see the same board).
pub(super) fn joint_filter<T: Scalar>(lidar_time_offset: T) -> JointEkf<T> {
    let mut init = InitialState::<T, 2>::at_rest(Vector3::new(T::zero(), T::zero(), T::lit(9.81)))
        .expect("gravity")
        .with_extrinsic(LIDAR, lidar_mount(), T::lit(0.02), T::lit(0.03))
        .with_time_offset(LIDAR, lidar_time_offset, T::lit(0.01))
        .with_extrinsic(CAMERA, camera_mount(), T::lit(0.02), T::lit(0.03));
    init.imu.velocity = Vector3::new(T::lit(0.7), T::lit(-0.3), T::lit(0.2));
    init.imu.rotation = UnitQuaternion::from_euler_angles(T::lit(0.3), T::lit(-0.2), T::lit(1.0));
    let mut ekf = JointEkf::new(&FilterConfig::new(ImuNoise::vn300()), &init).expect("prior");
    let sample = |k: u64| ImuSample {
        stamp_ns: T0 + k * 2_500_000,
        gyro: Vector3::new(T::lit(1.2), T::lit(-0.8), T::lit(0.5)),
        accel: Vector3::new(T::lit(0.5), T::lit(1.0), T::lit(9.0)),
    };
    for k in 0..=96u64 {
        ekf.propagate(&sample(k)).expect("sample");
    }
    ekf.propagate(&sample(104)).expect("look-ahead sample");
    let mut at_image = ekf.clone();
    at_image.advance_to(STAMP + 4_000_000).expect("advance");
    let board_in_camera = Pose::new(
        UnitQuaternion::from_euler_angles(T::lit(0.2), T::lit(-0.3), T::lit(0.1)),
        Vector3::new(T::lit(-0.3), T::lit(-0.2), T::lit(1.2)),
    );
    let board = at_image
        .imu()
        .pose()
        .compose(&camera_mount())
        .compose(&board_in_camera);
    ekf.init_frame(TARGET_FRAME, board, T::lit(0.05), T::lit(0.05))
        .expect("frame");
    ekf
}

/// The filter moved to the measurement's IMU time (where an update would linearise).
fn at_measurement<T: Scalar>(ekf: &JointEkf<T>, s: SensorId) -> JointEkf<T> {
    let mut e = ekf.clone();
    let t = e.imu_time(s, STAMP).expect("sensor").max(e.time_ns());
    e.advance_to(t).expect("advance");
    e
}

/// A 0.6 x 0.45 m patch of the board seen by the LiDAR at the filter's estimate, every point
/// moved along the board normal by `offset_m`.
fn plane_seen<T: Scalar>(ekf: &JointEkf<T>, offset_m: f64) -> BoardPlane<T> {
    let e = at_measurement(ekf, LIDAR);
    let t_l_t = e
        .imu()
        .pose()
        .compose(&e.extrinsic(LIDAR))
        .inverse()
        .compose(&e.frame(TARGET_FRAME).expect("frame"));
    let points: [Vector3<T>; 70] = core::array::from_fn(|i| {
        let (a, b) = (T::lit((i % 10) as f64), T::lit((i / 10) as f64));
        t_l_t.transform_point(&Vector3::new(
            a * T::lit(0.066),
            b * T::lit(0.075),
            T::lit(offset_m),
        ))
    });
    BoardPlane::from_points(STAMP, &points, T::lit(0.01)).expect("plane")
}

fn predicted_plane(ekf: &JointEkf<f64>, plane: &BoardPlane<f64>) -> Vector3<f64> {
    let e = at_measurement(ekf, LIDAR);
    board_plane::predict(
        &e.imu().pose(),
        &e.extrinsic(LIDAR),
        &e.frame(TARGET_FRAME).expect("frame"),
        plane,
    )
}

#[test]
fn layout_is_59_states_with_the_target_last() {
    assert_eq!(Layout::<2, 4>::dim_with_frames(1), N);
    assert_eq!(Layout::<2, 4>::frame_orientation(TARGET_FRAME).idx, 53);
    let ekf = joint_filter(0.0f64);
    assert_eq!(ekf.covariance().nrows(), N);
}

#[test]
fn board_plane_jacobian_matches_central_differences_over_the_whole_state() {
    // Given the joint filter at the scan's IMU time and the board as the LiDAR saw it
    let td = 0.004;
    let ekf = joint_filter(td);
    let plane = plane_seen(&ekf, 0.02);
    let at_scan = at_measurement(&ekf, LIDAR);
    // When every error-state direction is perturbed
    let h = 1e-6;
    let mut numeric = SMatrix::<f64, 3, N>::zeros();
    for i in 0..N {
        let shifted = |sign: f64| {
            let mut e = at_scan.clone();
            let mut dx = SVector::<f64, N>::zeros();
            dx[i] = sign * h;
            e.apply_correction(&dx).expect("finite");
            predicted_plane(&e, &plane)
        };
        numeric.set_column(i, &((shifted(1.0) - shifted(-1.0)) / (2.0 * h)));
    }
    // and the LiDAR time offset through the propagation to another IMU time
    let h_td = 1e-5;
    let td_column = (predicted_plane(&joint_filter(td + h_td), &plane)
        - predicted_plane(&joint_filter(td - h_td), &plane))
        / (2.0 * h_td);
    numeric.set_column(Layout::<2, 4>::time_offset(LIDAR).idx, &td_column);
    // Then the analytic Jacobian the update uses agrees (the camera's blocks are zero)
    let lin = board_plane::linearize(
        &at_scan.imu().pose(),
        &at_scan.extrinsic(LIDAR),
        &at_scan.frame(TARGET_FRAME).expect("frame"),
        &plane,
    );
    let gyro = at_scan.imu_now.expect("imu").gyro;
    let analytic: SMatrix<f64, 3, N> = at_scan
        .board_plane_jacobian(LIDAR, TARGET_FRAME, &lin, &gyro)
        .to_dense();
    // The rows are whitened by sqrt(K) and sqrt(lambda) (O(10)); the time-offset column
    // carries the midpoint integrator's O(|w| |a| dt^2) velocity inconsistency.
    assert_mat_close(&(analytic / 10.0), &(numeric / 10.0), 2e-4);
}

/// The corners of a 6 x 5 board of 5 cm squares where the filter predicts them.
fn corners_seen(ekf: &JointEkf<f64>) -> [CornerObservation<f64>; 30] {
    let e = at_measurement(ekf, CAMERA);
    core::array::from_fn(|k| {
        let p = Vector3::new((k % 6) as f64 * 0.05, (k / 6) as f64 * 0.05, 0.0);
        let p_c = crate::update::reprojection::point_in_camera(
            &e.imu().pose(),
            &e.extrinsic(CAMERA),
            &e.frame(TARGET_FRAME).expect("frame"),
            &p,
        );
        let pixel = camera::<f64>().project(&p_c).expect("in view").pixel;
        CornerObservation {
            point_in_target: p,
            pixel: pixel + Vector2::new(0.2, -0.1),
        }
    })
}

#[test]
fn corners_then_a_plane_couple_the_lidar_and_camera_extrinsics() {
    // Given the joint filter: LiDAR and camera extrinsics start uncorrelated
    let mut ekf = joint_filter(0.0f64);
    let lidar_t = Layout::<2, 4>::extrinsic_translation(LIDAR).idx;
    let camera_t = Layout::<2, 4>::extrinsic_translation(CAMERA).idx;
    let cross = |e: &JointEkf<f64>| {
        e.covariance()
            .fixed_view::<3, 3>(lidar_t, camera_t)
            .abs()
            .max()
    };
    assert!(cross(&ekf) < 1e-300);
    // When the camera sees the board's corners and the LiDAR its plane, 1 cm off
    let obs = corners_seen(&ekf);
    let corners = CornerSet {
        stamp_ns: STAMP,
        corners: &obs,
        pixel_sigma: 0.5,
    };
    let report = ekf
        .update_reprojection(CAMERA, TARGET_FRAME, &camera(), &corners)
        .expect("corners");
    assert!(report.accepted);
    let plane = plane_seen(&ekf, 0.01);
    let (before, before_t) = ekf.extrinsic_sigma(LIDAR);
    let report = ekf
        .update_board_plane(LIDAR, TARGET_FRAME, &plane)
        .expect("plane");
    // Then the plane is fused, the residual shrinks, the LiDAR's translation along the
    // board normal tightens, and the two extrinsics are now correlated through the board
    assert_eq!(report.kind, UpdateKind::BoardPlane);
    assert_eq!((report.sensor, report.dof), (Some(LIDAR), 3));
    assert!(report.accepted, "nis {}", report.nis);
    let before_residual = (0.01f64 * (70.0f64).sqrt()).abs();
    assert!(predicted_plane(&ekf, &plane).norm() < 0.2 * before_residual);
    let (after, after_t) = ekf.extrinsic_sigma(LIDAR);
    assert!(after.norm() < before.norm() && after_t.norm() < before_t.norm());
    assert!(cross(&ekf) > 1e-8, "cross-covariance {}", cross(&ekf));
}

#[test]
fn outlying_and_bad_planes_leave_the_state_untouched() {
    let ekf = joint_filter(0.0f64);
    // A board 30 cm off is gated: recorded, not fused.
    let mut gated = ekf.clone();
    let report = gated
        .update_board_plane(LIDAR, TARGET_FRAME, &plane_seen(&ekf, 0.3))
        .expect("plane");
    assert!(!report.accepted);
    // (The filter stands at the scan's IMU time: propagation is not undone.)
    assert_eq!(gated.imu(), at_measurement(&ekf, LIDAR).imu());
    assert_eq!(gated.extrinsic(LIDAR), ekf.extrinsic(LIDAR));
    assert_eq!(gated.frame(TARGET_FRAME), ekf.frame(TARGET_FRAME));
    // Typed errors, each with the state (and the filter time) unchanged.
    let good = plane_seen(&ekf, 0.0);
    let mut nan = good;
    nan.centroid.y = f64::NAN;
    let mut early = good;
    early.stamp_ns = T0;
    let mut beyond = good;
    beyond.stamp_ns = T0 + 1_000_000_000;
    let cases = [
        (2, 0, good, Error::UnknownSensor),
        (0, 1, good, Error::UnknownFrame),
        (0, 0, nan, Error::NonFinite),
        (
            0,
            0,
            early,
            Error::TimeWentBackwards {
                filter_ns: T0 + 240_000_000,
                stamp_ns: T0,
            },
        ),
        (
            0,
            0,
            beyond,
            Error::NotYetDue {
                imu_time_ns: T0 + 1_000_000_000,
                horizon_ns: T0 + 260_000_000,
            },
        ),
    ];
    for (s, f, plane, expected) in cases {
        // Ids of a wider layout than the joint filter's: they can still reach it.
        let s = SensorId::new::<3>(s).expect("sensor of the wider layout");
        let f = FrameId::new::<2>(f).expect("frame of the wider layout");
        let mut e = ekf.clone();
        assert_eq!(e.update_board_plane(s, f, &plane), Err(expected));
        assert_eq!(e.covariance(), ekf.covariance());
        assert_eq!((e.imu(), e.time_ns()), (ekf.imu(), ekf.time_ns()));
    }
}

#[test]
fn f32_follows_f64_through_a_joint_sequence() {
    // The same corners-then-plane sequence in both precisions.
    fn run<T: Scalar>() -> (Pose<T>, Pose<T>, T) {
        let mut ekf = joint_filter(T::lit(0.002));
        let obs64 = corners_seen(&joint_filter(0.002f64));
        let obs: [CornerObservation<T>; 30] = core::array::from_fn(|k| CornerObservation {
            point_in_target: obs64[k].point_in_target.map(T::lit),
            pixel: obs64[k].pixel.map(T::lit),
        });
        let corners = CornerSet {
            stamp_ns: STAMP,
            corners: &obs,
            pixel_sigma: T::lit(0.5),
        };
        ekf.update_reprojection(CAMERA, TARGET_FRAME, &camera(), &corners)
            .expect("corners");
        let plane = plane_seen(&ekf, 0.01);
        ekf.update_board_plane(LIDAR, TARGET_FRAME, &plane)
            .expect("plane");
        (
            ekf.extrinsic(LIDAR),
            ekf.extrinsic(CAMERA),
            ekf.time_offset(LIDAR),
        )
    }
    let (l64, c64, td64) = run::<f64>();
    let (l32, c32, td32) = run::<f32>();
    let close = |a: &Pose<f64>, b: &Pose<f32>| {
        let b = Pose::new(b.rotation.cast::<f64>(), b.translation.cast::<f64>());
        (
            a.rotation.angle_to(&b.rotation),
            (a.translation - b.translation).norm(),
        )
    };
    for (rot, trans) in [close(&l64, &l32), close(&c64, &c32)] {
        assert!(rot < 1e-5 && trans < 1e-5, "{rot} rad, {trans} m");
    }
    assert!((td64 - f64::from(td32)).abs() < 1e-6);
}

/// The corners of [`corners_seen`] with a deterministic per-corner disturbance of about
/// `px` pixels (so the image is not explained exactly by any state).
fn corners_disturbed<T: Scalar>(ekf: &JointEkf<f64>, px: f64) -> [CornerObservation<T>; 30] {
    let seen = corners_seen(ekf);
    core::array::from_fn(|k| {
        let d = Vector2::new((k as f64 * 1.7).sin(), (k as f64 * 2.3).cos()) * px;
        CornerObservation {
            point_in_target: seen[k].point_in_target.map(T::lit),
            pixel: (seen[k].pixel + d).map(T::lit),
        }
    })
}

/// The textbook update of the image's stacked rows (all 30 corners, 60 x 19 Jacobian, one
/// linearisation point) in f64: the filter after it and its NIS.
fn stacked_update(ekf: &JointEkf<f64>, obs: &[CornerObservation<f64>; 30]) -> (JointEkf<f64>, f64) {
    let mut e = at_measurement(ekf, CAMERA);
    e.flush_transition();
    let gyro = e.imu_now.expect("imu").gyro;
    let mut values = SMatrix::<f64, 60, 19>::zeros();
    let mut residual = SVector::<f64, 60>::zeros();
    let mut columns = [0; 19];
    for (k, corner) in obs.iter().enumerate() {
        let lin = crate::update::reprojection::linearize(
            &camera(),
            &e.imu().pose(),
            &e.extrinsic(CAMERA),
            &e.frame(TARGET_FRAME).expect("frame"),
            &corner.point_in_target,
            &corner.pixel,
        )
        .expect("in view");
        let h = e.reprojection_jacobian(CAMERA, TARGET_FRAME, &lin, &gyro);
        columns = h.columns;
        values.fixed_rows_mut::<2>(2 * k).copy_from(&h.values);
        residual.fixed_rows_mut::<2>(2 * k).copy_from(&lin.residual);
    }
    let meas = crate::update::Measurement {
        residual,
        jacobian: crate::update::SparseJacobian { columns, values },
        noise: SMatrix::<f64, 60, 60>::identity() * 0.25,
    };
    let gain = crate::update::Gain::compute(&e.cov, &meas, f64::INFINITY, &[]).expect("gain");
    e.correct(&gain).expect("correct");
    (e, gain.nis)
}

#[test]
fn compressed_image_update_equals_the_stacked_update() {
    // Given the joint filter and an image of 30 corners, each disturbed by ~0.4 px
    let ekf = joint_filter(0.001f64);
    let obs = corners_disturbed::<f64>(&ekf, 0.4);
    // When it is fused compressed (60 rows folded into 19) and, for reference, stacked
    let mut compressed = ekf.clone();
    let corners = CornerSet {
        stamp_ns: STAMP,
        corners: &obs,
        pixel_sigma: 0.5,
    };
    let report = compressed
        .update_reprojection(CAMERA, TARGET_FRAME, &camera(), &corners)
        .expect("corners");
    let (stacked, nis) = stacked_update(&ekf, &obs);
    // Then NIS, dof, state and covariance agree to rounding
    assert!(report.accepted);
    assert_eq!(report.dof, 60);
    assert!(
        (report.nis - nis).abs() < 1e-9 * nis,
        "{} vs {nis}",
        report.nis
    );
    let p = stacked.covariance();
    let dp = (compressed.covariance() - p).amax() / p.amax();
    assert!(
        dp < 1e-12,
        "covariance differs by {dp:e} of its largest entry"
    );
    for s in [LIDAR, CAMERA] {
        let (a, b) = (compressed.extrinsic(s), stacked.extrinsic(s));
        assert!(a.rotation.angle_to(&b.rotation) < 1e-13);
        assert!((a.translation - b.translation).norm() < 1e-13);
        assert!((compressed.time_offset(s) - stacked.time_offset(s)).abs() < 1e-15);
    }
    let (a, b) = (
        compressed.frame(TARGET_FRAME).expect("f"),
        stacked.frame(TARGET_FRAME).expect("f"),
    );
    assert!(a.rotation.angle_to(&b.rotation) < 1e-13);
    assert!((a.translation - b.translation).norm() < 1e-13);
    assert!((compressed.imu().position - stacked.imu().position).norm() < 1e-13);
}

#[test]
fn compressed_image_update_in_f32_follows_the_stacked_f64_one() {
    let ekf = joint_filter(0.001f64);
    let obs64 = corners_disturbed::<f64>(&ekf, 0.4);
    let (stacked, nis) = stacked_update(&ekf, &obs64);
    let mut e32 = joint_filter(0.001f32);
    let obs = corners_disturbed::<f32>(&ekf, 0.4);
    let corners = CornerSet {
        stamp_ns: STAMP,
        corners: &obs,
        pixel_sigma: 0.5,
    };
    let report = e32
        .update_reprojection(CAMERA, TARGET_FRAME, &camera(), &corners)
        .expect("corners");
    assert!(
        (f64::from(report.nis) - nis).abs() < 1e-3 * nis,
        "{} vs {nis}",
        report.nis
    );
    let (a, b) = (e32.extrinsic(CAMERA), stacked.extrinsic(CAMERA));
    let b32 = Pose::new(b.rotation.cast::<f32>(), b.translation.cast::<f32>());
    assert!(a.rotation.angle_to(&b32.rotation) < 1e-5);
    assert!((a.translation - b32.translation).norm() < 1e-5);
    // Relative to each variance (the empty clone slots' are zero in both).
    let (p32, p64) = (e32.covariance(), stacked.covariance());
    let mut worst = 0.0f64;
    for i in 0..N {
        let (a, b) = (f64::from(p32[(i, i)]), p64[(i, i)]);
        let rel = if b == 0.0 { a.abs() } else { (a - b).abs() / b };
        worst = worst.max(rel);
    }
    assert!(worst < 5e-5, "worst relative variance difference {worst:e}");
}

//! Tests of [`Ekf::fix_gauge`]: the gauge directions against a finite global yaw and
//! translation of every pose in the state, the fixed directions' zero variance, the
//! gauge-invariant blocks kept exactly, every error leaving the filter unchanged, f32
//! against f64.

use super::frame_relative_tests::{camera_filter, place_target, STAMP};
use super::joint_tests::joint_filter;
use super::*;
use crate::lie::{exp, log, Pose};
use crate::state::{CloneState, Layout};
use crate::testing::{assert_mat_close, central_diff};
use nalgebra::{SMatrix, SVector, UnitQuaternion, Vector3, Vector4};

/// `x` with every pose moved by `Exp(yaw z)` and then translated by `t` in G.
fn moved<const S: usize, const C: usize, const N: usize, const F: usize>(
    ekf: &Ekf<f64, S, C, N, F>,
    g: &Vector4<f64>,
) -> Ekf<f64, S, C, N, F> {
    let turn = exp(&(Vector3::z() * g[0]));
    let t = Vector3::new(g[1], g[2], g[3]);
    let pose = |p: &Pose<f64>| Pose::new(turn * p.rotation, turn * p.translation + t);
    let mut out = ekf.clone();
    out.imu.rotation = turn * ekf.imu.rotation;
    out.imu.position = turn * ekf.imu.position + t;
    out.imu.velocity = turn * ekf.imu.velocity;
    for c in out.clones.iter_mut().flatten() {
        c.pose = pose(&c.pose);
    }
    for f in out.frames.iter_mut().flatten() {
        *f = pose(f);
    }
    out
}

/// The error state `a - b` (right perturbations, additive positions and velocity).
fn difference<const S: usize, const C: usize, const N: usize, const F: usize>(
    a: &Ekf<f64, S, C, N, F>,
    b: &Ekf<f64, S, C, N, F>,
) -> SVector<f64, N> {
    let mut d = SVector::<f64, N>::zeros();
    d.fixed_rows_mut::<15>(0)
        .copy_from(&crate::propagate::boxminus(&a.imu, &b.imu));
    let mut pose = |o: usize, x: &Pose<f64>, y: &Pose<f64>| {
        d.fixed_rows_mut::<3>(o)
            .copy_from(&log(&(y.rotation.inverse() * x.rotation)));
        d.fixed_rows_mut::<3>(o + 3)
            .copy_from(&(x.translation - y.translation));
    };
    for c in 0..C {
        if let (Some(x), Some(y)) = (a.clones[c], b.clones[c]) {
            pose(Layout::<S, C>::clone_orientation(c).idx, &x.pose, &y.pose);
        }
    }
    for f in FrameId::all::<F>() {
        if let (Some(x), Some(y)) = (a.frames[f.index()], b.frames[f.index()]) {
            pose(Layout::<S, C>::frame_orientation(f).idx, &x, &y);
        }
    }
    d
}

/// The joint filter with both a clone and the board: every kind of pose the gauge moves.
fn joint_with_clone() -> JointEkf<f64> {
    let mut ekf = joint_filter::<f64>(0.004);
    ekf.clones[1] = Some(CloneState {
        pose: Pose::new(
            UnitQuaternion::from_euler_angles(0.1, 0.2, -0.7),
            Vector3::new(1.5, -2.0, 0.4),
        ),
        stamp_ns: STAMP,
        sensor: SOLE_SENSOR,
        yaw_direction: [Vector3::zeros(); 2],
    });
    ekf
}

#[test]
fn gauge_directions_match_a_finite_yaw_and_translation_of_every_pose() {
    let ekf = joint_with_clone();
    let numeric = central_diff::<59, 4>(|g| difference(&moved(&ekf, &g), &ekf));
    assert_mat_close(&ekf.gauge_directions(), &numeric, 1e-6);
    let ekf = camera_filter::<f64>(0.003);
    let numeric = central_diff::<28, 4>(|g| difference(&moved(&ekf, &g), &ekf));
    assert_mat_close(&ekf.gauge_directions(), &numeric, 1e-6);
}

/// The camera filter with its target placed from a PnP-like measurement (correlated with
/// the IMU pose, the extrinsic and the time offset, as the pipeline does it).
fn placed() -> CameraImuEkf<f64> {
    let mut ekf = camera_filter::<f64>(0.003);
    place_target(&mut ekf).expect("frame");
    ekf
}

/// The covariance of gauge-invariant quantities: the IMU pose and velocity in the target
/// frame, the extrinsic, the time offset and the biases (`J V = 0` for all of them).
fn invariant_covariance(ekf: &CameraImuEkf<f64>) -> SMatrix<f64, 22, 22> {
    let relative = |x: &CameraImuEkf<f64>| {
        let t_f_i = x.frames[0].expect("frame").inverse().compose(&x.imu.pose());
        let v_f = x.frames[0].expect("frame").rotation.inverse() * x.imu.velocity;
        (t_f_i, v_f)
    };
    let (p0, v0) = relative(ekf);
    let jac = central_diff::<22, 28>(|dx| {
        let mut x = ekf.clone();
        x.apply_correction(&dx).expect("finite");
        let (p, v) = relative(&x);
        let mut out = SVector::<f64, 22>::zeros();
        out.fixed_rows_mut::<3>(0)
            .copy_from(&log(&(p0.rotation.inverse() * p.rotation)));
        out.fixed_rows_mut::<3>(3)
            .copy_from(&(p.translation - p0.translation));
        out.fixed_rows_mut::<3>(6).copy_from(&(v - v0));
        out.fixed_rows_mut::<13>(9)
            .copy_from(&dx.fixed_rows::<13>(9));
        out
    });
    jac * ekf.covariance() * jac.transpose()
}

#[test]
fn fixing_the_gauge_zeroes_the_frame_yaw_and_position_and_keeps_every_invariant() {
    let mut ekf = placed();
    let before = ekf.covariance();
    let invariant_before = invariant_covariance(&ekf);
    ekf.fix_gauge(TARGET_FRAME).expect("fixed");
    let after = ekf.covariance();
    let frame = ekf.frame(TARGET_FRAME).expect("frame");
    let yaw = frame.rotation.to_rotation_matrix().into_inner().transpose() * Vector3::z();
    let o = Layout::<1, 0>::frame_orientation(TARGET_FRAME).idx;
    let p = Layout::<1, 0>::frame_position(TARGET_FRAME).idx;
    let scale = before.amax();
    let yaw_row = yaw.transpose() * after.fixed_view::<3, 28>(o, 0);
    assert!(yaw_row.amax() < 1e-12 * scale, "yaw row {yaw_row}");
    let position_rows = after.fixed_view::<3, 28>(p, 0);
    assert!(position_rows.amax() < 1e-12 * scale, "{position_rows}");
    // Biases, extrinsic and time offset: not moved by the gauge, kept bit for bit.
    let fixed = 9..28 - 6;
    for i in fixed.clone() {
        for j in fixed.clone() {
            assert_eq!(
                after[(i, j)].to_bits(),
                before[(i, j)].to_bits(),
                "({i}, {j})"
            );
        }
    }
    assert_mat_close(&invariant_covariance(&ekf), &invariant_before, 1e-7);
    // The frame's roll and pitch keep a positive variance; P stays positive semi-definite.
    let eigen = after.symmetric_eigenvalues();
    assert!(eigen.min() > -1e-12 * scale, "{eigen}");
    let roll_pitch = after.fixed_view::<3, 3>(o, o);
    assert!(roll_pitch.trace() > 1e-3 * before.fixed_view::<3, 3>(o, o).trace());
}

#[test]
fn the_fixed_gauge_survives_propagation() {
    let mut ekf = placed();
    ekf.fix_gauge(TARGET_FRAME).expect("fixed");
    let horizon = ekf.imu_horizon_ns().expect("samples");
    ekf.advance_to(horizon).expect("advance");
    let p = Layout::<1, 0>::frame_position(TARGET_FRAME).idx;
    let rows = ekf.covariance().fixed_view::<3, 28>(p, 0).amax();
    assert!(rows < 1e-12 * ekf.covariance().amax(), "{rows}");
}

#[test]
fn errors_leave_the_filter_unchanged() {
    let mut ekf = camera_filter::<f64>(0.003);
    let before = ekf.covariance();
    assert_eq!(ekf.fix_gauge(TARGET_FRAME), Err(Error::FrameNotInitialized));
    assert_eq!(
        ekf.fix_gauge(FrameId::at::<1, 2>()),
        Err(Error::UnknownFrame)
    );
    assert_eq!(ekf.covariance(), before);
}

#[test]
fn f32_follows_f64() {
    let mut wide = placed();
    let mut narrow = camera_filter::<f32>(0.003);
    place_target(&mut narrow).expect("frame");
    wide.fix_gauge(TARGET_FRAME).expect("f64");
    narrow.fix_gauge(TARGET_FRAME).expect("f32");
    let (a, b) = (wide.covariance(), narrow.covariance().map(f64::from));
    assert!((a - b).amax() < 1e-5 * a.amax(), "{}", (a - b).amax());
}

//! The unobservable rotation about gravity, kept unobservable (observability-constrained
//! EKF, Hesch et al. 2014, for the yaw; the global position needs nothing).
//!
//! Relative poses and zero-velocity updates see neither the IMU's global position nor its
//! rotation about gravity: turning the IMU pose, its velocity and every clone about `e_z`
//! changes no prediction. In the error state (right perturbation on rotations) that turn is
//! the direction `n` with orientation `R^T e_z`, position `e_z x p`, velocity `e_z x v`,
//! and the same orientation and position parts on each clone.
//!
//! An EKF evaluates `n` at whatever the estimate is. Each relative-pose Jacobian annihilates
//! `n` at the clones' current estimates, and each IMU transition maps `n` at its start onto
//! `n` at its end. But the update between two steps moves the estimate, so the `n` the next
//! transition starts from is not the one the previous transition ended on, and the chain
//! `H_k Phi_(k-1) ... Phi_1 n_1` no longer vanishes: the filter gains information about the
//! yaw about gravity that nothing measured (docs/planar.md measures a 6.4x gain on a drive).
//!
//! The constraint keeps one chain: `n` as it was propagated, never re-evaluated after an
//! update. Every transition is changed minimally (Frobenius norm, on its orientation
//! columns) so that it maps the chain's `n` onto the orientation and velocity parts of `n`
//! at the propagated estimate (its position part follows the transition: see
//! [`constrain_transition`]), and each clone keeps the chain's orientation and position
//! parts from the moment it was cloned.
//! A relative-pose Jacobian is projected (again minimally, on its own columns) so that it
//! annihilates the chain's `n` and still every global translation.
//!
//! Only for layouts without static frames: a target frame in the state turns with
//! everything else, and its part of `n` is not tracked here (`Ekf::new` refuses the
//! combination). Zero-velocity updates are not projected: at rest `e_z x v` is zero and
//! their Jacobian annihilates `n` already.

use crate::propagate::BLOCKS;
use crate::scalar::Scalar;
use crate::state::ImuState;
use nalgebra::{Matrix3, SMatrix, Vector3};

/// The IMU part of the yaw direction: orientation, position and velocity rows.
pub(crate) type YawDirection<T> = [Vector3<T>; 3];

/// The yaw direction's IMU part at the estimate `x`.
pub(crate) fn yaw_direction<T: Scalar>(x: &ImuState<T>) -> YawDirection<T> {
    let e_z = Vector3::z();
    [
        x.rotation.inverse_transform_vector(&e_z),
        e_z.cross(&x.position),
        e_z.cross(&x.velocity),
    ]
}

/// Changes the orientation columns of `phi`'s orientation and velocity rows by the least
/// Frobenius norm that makes `phi` map the chain's direction `from` onto `to` (the direction
/// at the propagated estimate) in those rows, and returns the chain's next direction: `to`'s
/// orientation and velocity, and the position `phi` maps `from`'s onto.
///
/// The position row is left as it is: a global translation is unobservable too, so the
/// chain's position part only has to be right up to a common shift, and what matters (the
/// clones' positions relative to each other) is exactly what the transition integrates. An
/// update's jump of the position, often decimetres early in a run, would otherwise enter one
/// transition as a huge orientation-to-position coupling. The other blocks stay, so the
/// transition keeps the structure `propagate::transition_mul` relies on; `from` has no bias
/// part, so the process noise (formed on the bias columns) is unaffected.
pub(crate) fn constrain_transition<T: Scalar>(
    phi: &mut SMatrix<T, 15, 15>,
    from: &YawDirection<T>,
    to: &YawDirection<T>,
) -> YawDirection<T> {
    let (o, p, v, _, _) = BLOCKS;
    let u = from[0];
    let uu = u.norm_squared();
    if uu > T::zero() {
        // What the orientation block must produce, the other columns' share taken off
        // (orientation row: nothing else; velocity: `I u_v`).
        for (row, target) in [(o, to[0]), (v, to[2] - from[2])] {
            let a: Matrix3<T> = phi.fixed_view::<3, 3>(row, o).clone_owned();
            let miss = a * u - target;
            phi.fixed_view_mut::<3, 3>(row, o)
                .copy_from(&(a - miss * (u.transpose() / uu)));
        }
    }
    let position =
        phi.fixed_view::<3, 3>(p, o) * from[0] + from[1] + phi.fixed_view::<3, 3>(p, v) * from[2];
    [to[0], position, to[2]]
}

/// Projects a relative pose's clone Jacobians (`[orientation, position]` columns of the
/// clone the segment starts at and of the one it ends at) so that they annihilate the
/// chain's yaw direction (`from_n`, `to_n`: each clone's orientation and position parts)
/// and every global translation, by the least change of those columns.
pub(crate) fn constrain_relative_jacobian<T: Scalar>(
    h_from: &mut SMatrix<T, 6, 6>,
    h_to: &mut SMatrix<T, 6, 6>,
    from_n: &[Vector3<T>; 2],
    to_n: &[Vector3<T>; 2],
) {
    // The yaw direction made orthogonal to the three translations (position parts equal
    // on both clones), which the Jacobians annihilate exactly at any estimate.
    let mean = (from_n[1] + to_n[1]) * T::lit(0.5);
    let stack = |n: &[Vector3<T>; 2]| {
        let mut out = nalgebra::SVector::<T, 6>::zeros();
        out.fixed_rows_mut::<3>(0).copy_from(&n[0]);
        out.fixed_rows_mut::<3>(3).copy_from(&(n[1] - mean));
        out
    };
    let (a, b) = (stack(from_n), stack(to_n));
    let nn = a.norm_squared() + b.norm_squared();
    if nn <= T::zero() {
        return;
    }
    let miss = *h_from * a + *h_to * b;
    *h_from -= miss * (a.transpose() / nn);
    *h_to -= miss * (b.transpose() / nn);
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lie::Pose;
    use crate::propagate::{step, ImuInterval, ImuNoise};
    use crate::testing::assert_mat_close;
    use crate::update::relative_pose;
    use nalgebra::{SVector, UnitQuaternion};

    fn moving_state() -> ImuState<f64> {
        ImuState {
            rotation: UnitQuaternion::from_euler_angles(0.05, -0.03, 1.2),
            position: Vector3::new(12.0, -4.0, 0.3),
            velocity: Vector3::new(8.0, 3.0, 0.1),
            gyro_bias: Vector3::new(1e-3, -2e-3, 5e-4),
            accel_bias: Vector3::new(0.02, -0.01, 0.03),
        }
    }

    fn stacked(n: &YawDirection<f64>) -> SVector<f64, 15> {
        let mut out = SVector::<f64, 15>::zeros();
        for (k, part) in n.iter().enumerate() {
            out.fixed_rows_mut::<3>(3 * k).copy_from(part);
        }
        out
    }

    /// One 10 ms step of a turning, accelerating IMU.
    fn turning_step() -> ImuInterval<f64> {
        ImuInterval::constant(
            Vector3::new(0.1, -0.05, 0.4),
            Vector3::new(1.0, 0.5, 9.9),
            0.01,
        )
    }

    /// The unconstrained transition already maps the yaw direction at its start onto the one
    /// at its end (the turn about gravity commutes with the IMU kinematics), so the
    /// constraint changes nothing along a propagated chain and acts only where an update
    /// moved the estimate.
    #[test]
    fn a_transition_maps_the_yaw_direction_at_its_start_to_its_end() {
        let x = moving_state();
        let interval = turning_step();
        let s = step(&x, &interval, &ImuNoise::vn300());
        let (from, to) = (yaw_direction(&x), yaw_direction(&s.state));
        let mapped = s.transition * stacked(&from);
        assert_mat_close(&mapped, &stacked(&to), 1e-9);
        let mut phi = s.transition;
        let next = constrain_transition(&mut phi, &from, &to);
        assert_mat_close(&phi, &s.transition, 1e-9);
        assert_mat_close(&stacked(&next), &stacked(&to), 1e-9);
    }

    /// From an estimate an update has moved (chain at the state before the update), the
    /// constrained transition maps the chain onto its next value, which has the propagated
    /// estimate's orientation and velocity parts, and changes only the orientation columns
    /// of the orientation and velocity rows.
    #[test]
    fn the_constrained_transition_maps_the_chain_and_keeps_its_structure() {
        let before = moving_state();
        let mut after = before;
        after.rotation = before.rotation * UnitQuaternion::from_euler_angles(0.01, -0.02, 0.03);
        after.velocity += Vector3::new(0.3, -0.2, 0.05);
        after.position += Vector3::new(0.1, 0.2, -0.1);
        let interval = turning_step();
        let s = step(&after, &interval, &ImuNoise::vn300());
        let (from, to) = (yaw_direction(&before), yaw_direction(&s.state));
        let mut phi = s.transition;
        let next = constrain_transition(&mut phi, &from, &to);
        assert_mat_close(&(phi * stacked(&from)), &stacked(&next), 1e-12);
        assert_mat_close(&next[0], &to[0], 1e-12);
        assert_mat_close(&next[2], &to[2], 1e-12);
        let changed = phi - s.transition;
        for (r, c) in (0..15).flat_map(|r| (0..15).map(move |c| (r, c))) {
            if (3..6).contains(&r) || r >= 9 || c >= 3 {
                assert!(changed[(r, c)] == 0.0, "entry ({r}, {c}) changed");
            }
        }
    }

    fn pose(roll: f64, yaw: f64, p: [f64; 3]) -> Pose<f64> {
        Pose::new(
            UnitQuaternion::from_euler_angles(roll, 0.02, yaw),
            Vector3::from(p),
        )
    }

    fn clone_direction(t: &Pose<f64>) -> [Vector3<f64>; 2] {
        let e_z = Vector3::z();
        [
            t.rotation.inverse_transform_vector(&e_z),
            e_z.cross(&t.translation),
        ]
    }

    /// At the clones' own estimates the projection is a no-op (a relative pose cannot see
    /// the turn); at chain values from before an update it annihilates the chain's
    /// direction while every global translation stays unseen.
    #[test]
    fn the_projected_relative_jacobian_annihilates_the_chain_and_the_translations() {
        let (from, to) = (
            pose(0.01, 0.3, [5.0, 1.0, 0.2]),
            pose(-0.02, 0.45, [5.8, 1.4, 0.21]),
        );
        let extrinsic = pose(0.5, -1.0, [0.3, 0.1, 0.8]);
        let measured = from.inverse().compose(&to);
        let lin = relative_pose::linearize(
            &from,
            &to,
            &extrinsic,
            &extrinsic.inverse().compose(&measured).compose(&extrinsic),
        );
        let (mut h_from, mut h_to) = (lin.clone_from, lin.clone_to);
        constrain_relative_jacobian(
            &mut h_from,
            &mut h_to,
            &clone_direction(&from),
            &clone_direction(&to),
        );
        assert_mat_close(&h_from, &lin.clone_from, 1e-12);
        assert_mat_close(&h_to, &lin.clone_to, 1e-12);

        let moved = pose(0.012, 0.31, [5.1, 0.9, 0.2]);
        let chain = [clone_direction(&moved), clone_direction(&to)];
        constrain_relative_jacobian(&mut h_from, &mut h_to, &chain[0], &chain[1]);
        let stack = |n: &[Vector3<f64>; 2]| {
            SVector::<f64, 6>::from_iterator(n[0].iter().chain(n[1].iter()).copied())
        };
        let seen = h_from * stack(&chain[0]) + h_to * stack(&chain[1]);
        assert!(seen.norm() < 1e-12, "chain direction seen: {seen}");
        for i in 0..3 {
            let mut shift = SVector::<f64, 6>::zeros();
            shift[3 + i] = 1.0;
            let seen = h_from * shift + h_to * shift;
            assert!(seen.norm() < 1e-12, "translation {i} seen: {seen}");
        }
    }

    /// The yaw direction over the whole state: the IMU part and each clone's.
    fn full_direction(
        ekf: &crate::PoseImuEkf<f64>,
        imu_part: &YawDirection<f64>,
        clone_part: impl Fn(&crate::state::CloneState<f64>) -> [Vector3<f64>; 2],
    ) -> SVector<f64, 34> {
        use crate::state::{imu, Layout};
        let mut n = SVector::<f64, 34>::zeros();
        let mut put = |idx: usize, v: &Vector3<f64>| n.fixed_rows_mut::<3>(idx).copy_from(v);
        put(imu::ORIENTATION.idx, &imu_part[0]);
        put(imu::POSITION.idx, &imu_part[1]);
        put(imu::VELOCITY.idx, &imu_part[2]);
        for (slot, c) in ekf.clones.iter().enumerate() {
            if let Some(c) = c {
                let [o, p] = clone_part(c);
                put(Layout::<1, 2>::clone_orientation(slot).idx, &o);
                put(Layout::<1, 2>::clone_orientation(slot).idx + 3, &p);
            }
        }
        n
    }

    /// Information along `n`: `n^T P^+ n` (a fresh clone makes `P` singular).
    fn information(ekf: &crate::PoseImuEkf<f64>, n: &SVector<f64, 34>) -> f64 {
        let pinv = ekf.covariance().pseudo_inverse(1e-12).expect("svd");
        (n.transpose() * pinv * n)[0]
    }

    /// A spinning, accelerating filter fed relative poses it does not predict (identity),
    /// so that every update moves the estimate: the information along the yaw about gravity
    /// grows when the direction is re-evaluated at each estimate, and never grows along the
    /// constrained chain.
    fn information_history(constrain: bool) -> ([f64; 20], f64) {
        use crate::filter::SOLE_SENSOR;
        use crate::propagate::ImuSample;
        use crate::{FilterConfig, InitialState, PoseImuEkf, RelativePose};
        const T0: u64 = 1_700_000_000_000_000_000;
        let mut init =
            InitialState::<f64, 1>::at_rest(Vector3::new(0.0, 0.0, 9.81)).expect("gravity");
        init.imu.velocity = Vector3::new(0.7, -0.3, 0.2);
        init.imu.rotation = UnitQuaternion::from_euler_angles(0.3, -0.2, 1.0);
        // A yaw known to 0.5 rad and a velocity to 0.5 m/s, so that what the updates add
        // is not hidden under the prior's information.
        init.sigma_orientation = 0.5;
        init.sigma_velocity = 0.5;
        let config = FilterConfig {
            constrain_yaw: constrain,
            ..FilterConfig::new(ImuNoise::vn300())
        };
        let mut ekf = PoseImuEkf::new(&config, &init).expect("prior");
        let feed = |ekf: &mut PoseImuEkf<f64>, stamp: u64| {
            while !ekf.is_due(SOLE_SENSOR, stamp) {
                let next = ekf.imu_horizon_ns().map_or(T0, |h| h + 2_500_000);
                let sample = ImuSample {
                    stamp_ns: next,
                    gyro: Vector3::new(1.2, -0.8, 0.5),
                    accel: Vector3::new(0.5, 1.0, 9.0),
                };
                ekf.propagate(&sample).expect("sample");
            }
        };
        feed(&mut ekf, T0 + 100_000_000);
        ekf.anchor(SOLE_SENSOR, T0 + 100_000_000).expect("anchor");
        let mut info = [0.0; 20];
        let mut largest_rise = 0.0f64;
        let mut before = None;
        for (k, slot) in info.iter_mut().enumerate() {
            let stamp = T0 + (k as u64 + 2) * 100_000_000;
            feed(&mut ekf, stamp);
            let m =
                RelativePose::with_sigmas(stamp - 100_000_000, stamp, Pose::identity(), 0.5, 0.5);
            ekf.update_relative_pose(SOLE_SENSOR, &m).expect("update");
            let n = if constrain {
                full_direction(&ekf, &ekf.yaw_chain, |c| c.yaw_direction)
            } else {
                full_direction(&ekf, &yaw_direction(&ekf.imu), |c| clone_direction(&c.pose))
            };
            *slot = information(&ekf, &n);
            if let Some(b) = before {
                largest_rise = largest_rise.max(*slot / b);
            }
            before = Some(*slot);
        }
        (info, largest_rise)
    }

    #[test]
    fn the_constrained_filter_gains_no_information_about_the_yaw_about_gravity() {
        let (free, free_rise) = information_history(false);
        let (chain, chain_rise) = information_history(true);
        // Measured: 6.5 -> 7.8e5 in 20 updates (a yaw sigma of 0.39 rad claimed down to
        // 1.1 mrad) against 6.320 -> 6.320, falling by the process noise.
        assert!(free[19] > 1e3 * free[0], "unconstrained: {free:?}");
        assert!(free_rise > 1.0);
        assert!(chain_rise <= 1.0 + 1e-9, "constrained: {chain:?}");
    }

    /// A static frame turns with the yaw and its part of the direction is not tracked:
    /// such a layout refuses the constraint with a typed error.
    #[test]
    fn a_layout_with_static_frames_refuses_the_constraint() {
        use crate::{CameraImuEkf, Error, FilterConfig, InitialState};
        let init = InitialState::<f64, 1>::at_rest(Vector3::new(0.0, 0.0, 9.81)).expect("gravity");
        let config = FilterConfig {
            constrain_yaw: true,
            ..FilterConfig::new(ImuNoise::vn300())
        };
        assert!(matches!(
            CameraImuEkf::new(&config, &init),
            Err(Error::InvalidConfig)
        ));
        assert!(crate::PoseImuEkf::new(&config, &init).is_ok());
    }
}

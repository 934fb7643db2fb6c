//! IMU propagation (dissertation eq. 3.8-3.17, OpenVINS-style discrete model).
//!
//! An IMU sample is the angular rate and specific force at its stamp, an instantaneous
//! reading, as EuRoC, Kalibr and OpenVINS take it. Between samples the signal is the quadratic
//! through the last three ([`ImuSignal`]; the straight line at the start and around gaps), and
//! a step over `[t_a, t_b]` takes that signal's exact mean and its readings at both ends
//! ([`ImuInterval`]). Orientation integrates the mean rate, `R' = R Exp(w dt)`, plus the
//! coning term; velocity and position integrate the mean specific force rotated by the
//! mid-interval orientation `R Exp(w dt / 2)`, plus the sculling term and the double
//! integral's correction for a force that changes within the interval (holding `R` at the
//! interval start, as eq. 3.9 writes it, leaves a systematic error of `|a| |w| dt / 2` that a
//! 400 Hz, 2 rad/s excitation turns into a spurious 0.02 m/s^2 accelerometer bias). Holding
//! one sample over the whole interval instead would delay the signal by half a period, and
//! every time offset estimated against it by `dt / 2` (1.25 ms at 400 Hz). Against the
//! simulator's exact motion at 200 Hz (hand-held, up to 2.7 rad/s), the mean of two samples
//! alone drifts 4.3e-5 rad RMS and 0.31 mm at worst in one second; this step, 7.5e-7 rad and
//! 0.011 mm (`cargo run --release -p msreg --example propagation_error`).
//!
//! IMUs whose driver outputs interval means (integrating IMUs) are re-stamped to their
//! interval's midpoint by the dataset reader (`sample_timing` in `imu0/imu.yaml`), which
//! makes them instantaneous readings to second order.
//!
//! The error-state transition `Phi` and the discrete noise `Q_d = G Q G^T` follow from the
//! right perturbation `R = R_hat Exp(dtheta)`; both are checked against central differences.

use core::ops::AddAssign;

use crate::lie::{exp, skew};
use crate::scalar::Scalar;
use crate::state::{imu, ImuState};
use nalgebra::{Matrix3, SMatrix, UnitQuaternion, Vector3};

mod series;
mod signal;
pub use series::{Rotations, SERIES_MAX_ANGLE};
pub use signal::{ImuInterval, ImuSignal};

/// Standard gravity, m/s^2; gravity in G is `(0, 0, -GRAVITY)`.
pub const GRAVITY: f64 = 9.81;

/// First indices of the IMU blocks: orientation, position, velocity, gyro bias, accel bias.
pub(crate) const BLOCKS: (usize, usize, usize, usize, usize) = (
    imu::ORIENTATION.idx,
    imu::POSITION.idx,
    imu::VELOCITY.idx,
    imu::GYRO_BIAS.idx,
    imu::ACCEL_BIAS.idx,
);

/// One IMU reading.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ImuSample<T: Scalar> {
    /// IMU time, ns.
    pub stamp_ns: u64,
    /// Angular rate, rad/s, IMU frame.
    pub gyro: Vector3<T>,
    /// Specific force, m/s^2, IMU frame.
    pub accel: Vector3<T>,
}

impl<T: Scalar> ImuSample<T> {
    /// Rejects NaN/Inf and values beyond any real IMU's range (1000 rad/s, 1000 m/s^2).
    pub fn validate(&self) -> Result<(), crate::Error> {
        let finite = self
            .gyro
            .iter()
            .chain(self.accel.iter())
            .all(|x| x.is_finite());
        if !finite {
            return Err(crate::Error::NonFinite);
        }
        if self.gyro.amax() > T::lit(1e3) || self.accel.amax() > T::lit(1e3) {
            return Err(crate::Error::OutOfRange);
        }
        Ok(())
    }
}

/// Continuous-time IMU noise in Kalibr's `imu.yaml` units.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ImuNoise<T: Scalar> {
    /// Gyroscope white noise density, rad/s/sqrt(Hz).
    pub gyro_noise_density: T,
    /// Accelerometer white noise density, m/s^2/sqrt(Hz).
    pub accel_noise_density: T,
    /// Gyroscope bias random walk, rad/s^2/sqrt(Hz).
    pub gyro_random_walk: T,
    /// Accelerometer bias random walk, m/s^3/sqrt(Hz).
    pub accel_random_walk: T,
}

impl<T: Scalar> ImuNoise<T> {
    /// VectorNav VN-300-class figures (datasheet noise densities, Kalibr-style walks).
    pub fn vn300() -> Self {
        Self {
            gyro_noise_density: T::lit(6.1e-5),
            accel_noise_density: T::lit(1.4e-3),
            gyro_random_walk: T::lit(4.0e-6),
            accel_random_walk: T::lit(8.0e-5),
        }
    }

    /// True when all densities are finite and positive.
    pub fn is_valid(&self) -> bool {
        [
            self.gyro_noise_density,
            self.accel_noise_density,
            self.gyro_random_walk,
            self.accel_random_walk,
        ]
        .iter()
        .all(|x| x.is_finite() && *x > T::zero())
    }
}

/// The result of one propagation step: new nominal state, transition and noise of the
/// 15-dim IMU error state.
#[derive(Clone, Debug)]
pub struct ImuStep<T: Scalar> {
    /// Propagated nominal IMU state.
    pub state: ImuState<T>,
    /// Error-state transition `Phi`.
    pub transition: SMatrix<T, 15, 15>,
    /// Discrete process noise `Q_d`.
    pub noise: SMatrix<T, 15, 15>,
}

/// Propagates the IMU state over one interval of the signal (see [`ImuSignal::interval`]).
///
/// The mean reading drives the step as described in the module doc; on top of it, the
/// second-order terms of a signal that changes within the interval: coning
/// (`dt^2 / 12 w_a x w_b` in the rotation vector), sculling (`R_a dt^2 / 12 (w_a x da - dw x a_a)`
/// in the velocity) and the position's double integral of a force that changes linearly
/// (`dt^2 / 12 (f_a - f_b)`). They vanish for a constant reading. `Phi` includes their
/// derivatives (central-difference tests below); `Q` treats each reading's white noise as
/// a bias error held over the interval, entering through `Phi`'s bias columns.
pub fn step<T: Scalar>(
    x: &ImuState<T>,
    signal: &ImuInterval<T>,
    noise: &ImuNoise<T>,
) -> ImuStep<T> {
    step_with(x, signal, noise, Rotations::Trigonometric)
}

/// [`step`] with the rotation functions evaluated as `rotations` says (the same step;
/// [`Rotations::Series`] differs from the reference by rounding only).
pub fn step_with<T: Scalar>(
    x: &ImuState<T>,
    signal: &ImuInterval<T>,
    noise: &ImuNoise<T>,
    rotations: Rotations,
) -> ImuStep<T> {
    let k = Kinematics::new(x, signal, rotations);
    let half = T::lit(0.5);
    let dt = signal.dt;
    let g = Vector3::new(T::zero(), T::zero(), -T::lit(GRAVITY));
    let acc_g = k.r_mid * k.a + g + k.r_a * k.sculling * k.twelfth / dt;
    let force_change = k.r_a * k.a_a - k.r_b * k.a_b;
    let state = ImuState {
        rotation: crate::lie::renormalize(x.rotation * k.dq),
        position: x.position
            + x.velocity * dt
            + acc_g * (half * dt * dt)
            + force_change * k.twelfth,
        velocity: x.velocity + acc_g * dt,
        gyro_bias: x.gyro_bias,
        accel_bias: x.accel_bias,
    };
    let phi = transition(&k, dt, rotations);
    ImuStep {
        state,
        transition: phi,
        noise: process_noise(&phi, dt, noise),
    }
}

/// The bias-corrected readings of one step and the rotations they produce.
struct Kinematics<T: Scalar> {
    /// Mean rate and specific force.
    w: Vector3<T>,
    a: Vector3<T>,
    /// Readings at the interval's ends.
    w_a: Vector3<T>,
    w_b: Vector3<T>,
    a_a: Vector3<T>,
    a_b: Vector3<T>,
    /// Rotation vector of the step (mean rate plus coning) and its derivative by the gyro bias.
    theta: Vector3<T>,
    d_theta_d_bg: Matrix3<T>,
    dq: UnitQuaternion<T>,
    dq_half: UnitQuaternion<T>,
    r_a: Matrix3<T>,
    r_mid: Matrix3<T>,
    r_b: Matrix3<T>,
    /// `w_a x da - dw x a_a` (body frame at the start; times `dt^2 / 12` and `R_a`: the
    /// velocity's sculling term).
    sculling: Vector3<T>,
    twelfth: T,
}

impl<T: Scalar> Kinematics<T> {
    fn new(x: &ImuState<T>, signal: &ImuInterval<T>, rotations: Rotations) -> Self {
        let dt = signal.dt;
        let twelfth = dt * dt / T::lit(12.0);
        let (w_a, a_a) = (signal.start.0 - x.gyro_bias, signal.start.1 - x.accel_bias);
        let (w_b, a_b) = (signal.end.0 - x.gyro_bias, signal.end.1 - x.accel_bias);
        let w = signal.gyro_mean - x.gyro_bias;
        let theta = w * dt + w_a.cross(&w_b) * twelfth;
        let dq = rotations.exp(&theta);
        let dq_half = rotations.exp(&(w * (dt * T::lit(0.5))));
        let r_a = x.rotation.to_rotation_matrix().into_inner();
        Self {
            w,
            a: signal.accel_mean - x.accel_bias,
            w_a,
            w_b,
            a_a,
            a_b,
            theta,
            d_theta_d_bg: skew(&(w_b - w_a)) * twelfth - Matrix3::identity() * dt,
            dq,
            dq_half,
            r_a,
            r_mid: r_a * dq_half.to_rotation_matrix().into_inner(),
            r_b: r_a * dq.to_rotation_matrix().into_inner(),
            sculling: w_a.cross(&(a_b - a_a)) - (w_b - w_a).cross(&a_a),
            twelfth,
        }
    }
}

/// The error-state transition of [`step`], with the right perturbation `R = R_hat Exp(dtheta)`.
fn transition<T: Scalar>(k: &Kinematics<T>, dt: T, rotations: Rotations) -> SMatrix<T, 15, 15> {
    let half = T::lit(0.5);
    // The rotated mean specific force R_mid a.
    let ra_x = k.r_mid * skew(&k.a);
    let e_half_t = k.dq_half.to_rotation_matrix().into_inner().transpose();
    let d_force_d_theta = -(ra_x * e_half_t);
    let d_force_d_bg = ra_x * rotations.right_jacobian(&(k.w * (dt * half))) * (dt * half);
    let d_force_d_ba = -k.r_mid;
    // The sculling velocity R_a s dt^2 / 12.
    let d_scull_d_theta = -(k.r_a * skew(&k.sculling)) * k.twelfth;
    let d_scull_d_bg = k.r_a * skew(&(k.a_b - k.a_a)) * k.twelfth;
    let d_scull_d_ba = k.r_a * skew(&(k.w_b - k.w_a)) * k.twelfth;
    // The double integral's correction (R_a a_a - R_b a_b) dt^2 / 12.
    let rb_ab_x = k.r_b * skew(&k.a_b);
    let d_change_d_theta = (k.r_a * (skew(&(k.dq * k.a_b)) - skew(&k.a_a))) * k.twelfth;
    let d_rot_d_bg = rotations.right_jacobian(&k.theta) * k.d_theta_d_bg;
    let d_change_d_bg = rb_ab_x * d_rot_d_bg * k.twelfth;
    let d_change_d_ba = (k.r_b - k.r_a) * k.twelfth;

    let mut phi = SMatrix::<T, 15, 15>::identity();
    let (o, p, v, bg, ba) = BLOCKS;
    let half_dt = half * dt;
    set3(
        &mut phi,
        o,
        o,
        &k.dq.to_rotation_matrix().into_inner().transpose(),
    );
    set3(&mut phi, o, bg, &d_rot_d_bg);
    let v_o = d_force_d_theta * dt + d_scull_d_theta;
    let v_bg = d_force_d_bg * dt + d_scull_d_bg;
    let v_ba = d_force_d_ba * dt + d_scull_d_ba;
    set3(&mut phi, p, o, &(v_o * half_dt + d_change_d_theta));
    set3(&mut phi, p, v, &(Matrix3::identity() * dt));
    set3(&mut phi, p, bg, &(v_bg * half_dt + d_change_d_bg));
    set3(&mut phi, p, ba, &(v_ba * half_dt + d_change_d_ba));
    set3(&mut phi, v, o, &v_o);
    set3(&mut phi, v, bg, &v_bg);
    set3(&mut phi, v, ba, &v_ba);
    phi
}

/// `Q_d = G Q_c G^T` of one step with transition `phi`.
fn process_noise<T: Scalar>(
    phi: &SMatrix<T, 15, 15>,
    dt: T,
    noise: &ImuNoise<T>,
) -> SMatrix<T, 15, 15> {
    let (o, p, _, bg, ba) = BLOCKS;
    // White noise enters exactly like a bias error; bias walks add on the bias blocks. The
    // gyro noise reaches the orientation, position and velocity rows (the first 9), the
    // accelerometer noise position and velocity, so `Q` is formed on those blocks only.
    const _: () = assert!(BLOCKS.0 == 0 && BLOCKS.1 == 3 && BLOCKS.2 == 6);
    let g_gyro = phi.fixed_view::<9, 3>(o, bg).clone_owned();
    let g_accel = phi.fixed_view::<6, 3>(p, ba).clone_owned();
    let var_g = noise.gyro_noise_density * noise.gyro_noise_density / dt;
    let var_a = noise.accel_noise_density * noise.accel_noise_density / dt;
    let mut q = SMatrix::<T, 15, 15>::zeros();
    q.fixed_view_mut::<9, 9>(o, o)
        .copy_from(&(g_gyro * g_gyro.transpose() * var_g));
    let mut q_pv = q.fixed_view_mut::<6, 6>(p, p);
    q_pv += g_accel * g_accel.transpose() * var_a;
    let walk_g = noise.gyro_random_walk * noise.gyro_random_walk * dt;
    let walk_a = noise.accel_random_walk * noise.accel_random_walk * dt;
    for i in 0..3 {
        q[(bg + i, bg + i)] += walk_g;
        q[(ba + i, ba + i)] += walk_a;
    }
    q
}

/// `Phi * m` for a transition with the structure every product of IMU steps keeps: the
/// orientation row depends on orientation and gyro bias only, position and velocity carry
/// identity on themselves, the biases are constant. Nine 3x3 products per column instead of
/// twenty-five (the covariance propagation's hot path, on the microcontroller above all).
pub fn transition_mul<T: Scalar, const K: usize>(
    phi: &SMatrix<T, 15, 15>,
    m: &SMatrix<T, 15, K>,
) -> SMatrix<T, 15, K> {
    let (o, p, v, bg, ba) = BLOCKS;
    let b = |r: usize, c: usize| phi.fixed_view::<3, 3>(r, c);
    let rows = |r: usize| m.fixed_view::<3, K>(r, 0);
    let mut out = SMatrix::<T, 15, K>::zeros();
    out.fixed_view_mut::<3, K>(o, 0)
        .copy_from(&(b(o, o) * rows(o) + b(o, bg) * rows(bg)));
    out.fixed_view_mut::<3, K>(p, 0).copy_from(
        &(b(p, o) * rows(o)
            + rows(p)
            + b(p, v) * rows(v)
            + b(p, bg) * rows(bg)
            + b(p, ba) * rows(ba)),
    );
    out.fixed_view_mut::<3, K>(v, 0)
        .copy_from(&(b(v, o) * rows(o) + rows(v) + b(v, bg) * rows(bg) + b(v, ba) * rows(ba)));
    out.fixed_view_mut::<3, K>(bg, 0).copy_from(&rows(bg));
    out.fixed_view_mut::<3, K>(ba, 0).copy_from(&rows(ba));
    out
}

/// `Phi P Phi^T + Q` for a symmetric `P` (the IMU block of the covariance) and a symmetric
/// `Q`, with `Phi`'s block structure as in [`transition_mul`]. `A = Phi P` is formed whole;
/// of `Phi A^T` only the block-lower triangle (513 multiply-adds instead of 1,215), which is
/// then mirrored: the result is exactly symmetric without an averaging pass.
pub fn covariance_step<T: Scalar>(
    phi: &SMatrix<T, 15, 15>,
    p: &SMatrix<T, 15, 15>,
    q: &SMatrix<T, 15, 15>,
) -> SMatrix<T, 15, 15> {
    let (o, pp, v, bg, ba) = BLOCKS;
    let a = transition_mul(phi, p);
    let b = |r: usize, c: usize| phi.fixed_view::<3, 3>(r, c);
    let mut out = *q;
    let row_o = b(o, o) * at::<T, 3>(&a, o) + b(o, bg) * at::<T, 3>(&a, bg);
    let row_p = b(pp, o) * at::<T, 6>(&a, o)
        + at::<T, 6>(&a, pp)
        + b(pp, v) * at::<T, 6>(&a, v)
        + b(pp, bg) * at::<T, 6>(&a, bg)
        + b(pp, ba) * at::<T, 6>(&a, ba);
    let row_v = b(v, o) * at::<T, 9>(&a, o)
        + at::<T, 9>(&a, v)
        + b(v, bg) * at::<T, 9>(&a, bg)
        + b(v, ba) * at::<T, 9>(&a, ba);
    out.fixed_view_mut::<3, 3>(o, 0).add_assign(&row_o);
    out.fixed_view_mut::<3, 6>(pp, 0).add_assign(&row_p);
    out.fixed_view_mut::<3, 9>(v, 0).add_assign(&row_v);
    out.fixed_view_mut::<3, 12>(bg, 0)
        .add_assign(&at::<T, 12>(&a, bg));
    out.fixed_view_mut::<3, 15>(ba, 0)
        .add_assign(&at::<T, 15>(&a, ba));
    for i in 0..15 {
        for j in i + 1..15 {
            out[(i, j)] = out[(j, i)];
        }
    }
    out
}

/// Block column `k` of `a` over its first `N` rows, transposed: rows `k..k+3` of `a^T`
/// over its first `N` columns.
fn at<T: Scalar, const N: usize>(a: &SMatrix<T, 15, 15>, k: usize) -> SMatrix<T, 3, N> {
    a.fixed_view::<N, 3>(0, k).transpose()
}

/// `Phi A` for `A` a product of transitions (e.g. the pending transition of
/// `Ekf::flush_transition`): the same block pattern as `Phi` (orientation rows touch only
/// orientation and gyro bias, velocity rows not the position, bias rows identity), which is
/// closed under products, so only its 10 non-trivial 3x3 block products are formed (270
/// multiply-adds instead of [`transition_mul`]'s 1,215). Same sums in the same order as
/// [`transition_mul`], less the terms that are exact zeros.
pub fn transition_compose<T: Scalar>(
    phi: &SMatrix<T, 15, 15>,
    a: &SMatrix<T, 15, 15>,
) -> SMatrix<T, 15, 15> {
    let (o, p, v, bg, ba) = BLOCKS;
    let f = |r: usize, c: usize| phi.fixed_view::<3, 3>(r, c).clone_owned();
    let x = |r: usize, c: usize| a.fixed_view::<3, 3>(r, c).clone_owned();
    let mut out = SMatrix::<T, 15, 15>::zeros();
    let mut put = |r: usize, c: usize, m: Matrix3<T>| {
        out.fixed_view_mut::<3, 3>(r, c).copy_from(&m);
    };
    put(o, o, f(o, o) * x(o, o));
    put(o, bg, f(o, o) * x(o, bg) + f(o, bg));
    put(p, o, f(p, o) * x(o, o) + x(p, o) + f(p, v) * x(v, o));
    put(p, p, x(p, p));
    put(p, v, x(p, v) + f(p, v) * x(v, v));
    put(
        p,
        bg,
        f(p, o) * x(o, bg) + x(p, bg) + f(p, v) * x(v, bg) + f(p, bg),
    );
    put(p, ba, x(p, ba) + f(p, v) * x(v, ba) + f(p, ba));
    put(v, o, f(v, o) * x(o, o) + x(v, o));
    put(v, v, x(v, v));
    put(v, bg, f(v, o) * x(o, bg) + x(v, bg) + f(v, bg));
    put(v, ba, x(v, ba) + f(v, ba));
    put(bg, bg, x(bg, bg));
    put(ba, ba, x(ba, ba));
    out
}

/// True when every value is finite, in one multiply-add per value and no branch:
/// `x * 0` is zero for a finite `x` and NaN for an infinite or NaN one, and a sum of zeros
/// never overflows, so the sum is zero exactly when every value is finite (the same answer
/// as `is_finite` on each; `Iterator::all` over it cost ~20 M4F instructions per value).
pub(crate) fn all_finite<T: Scalar>(values: &[T]) -> bool {
    let mut acc = T::zero();
    for &x in values {
        acc += x * T::zero();
    }
    acc == T::zero()
}

fn set3<T: Scalar>(m: &mut SMatrix<T, 15, 15>, row: usize, col: usize, block: &Matrix3<T>) {
    m.fixed_view_mut::<3, 3>(row, col).copy_from(block);
}

/// Applies an error-state correction to an IMU state (right perturbation on rotation).
pub fn boxplus<T: Scalar>(x: &ImuState<T>, dx: &nalgebra::SVector<T, 15>) -> ImuState<T> {
    let d = |b: crate::state::Block| Vector3::new(dx[b.idx], dx[b.idx + 1], dx[b.idx + 2]);
    ImuState {
        rotation: crate::lie::renormalize(x.rotation * exp(&d(imu::ORIENTATION))),
        position: x.position + d(imu::POSITION),
        velocity: x.velocity + d(imu::VELOCITY),
        gyro_bias: x.gyro_bias + d(imu::GYRO_BIAS),
        accel_bias: x.accel_bias + d(imu::ACCEL_BIAS),
    }
}

/// The error between two IMU states, `a - b` in the filter's error convention.
pub fn boxminus<T: Scalar>(a: &ImuState<T>, b: &ImuState<T>) -> nalgebra::SVector<T, 15> {
    let mut dx = nalgebra::SVector::<T, 15>::zeros();
    let dtheta = crate::lie::log(&(b.rotation.inverse() * a.rotation));
    dx.fixed_rows_mut::<3>(imu::ORIENTATION.idx)
        .copy_from(&dtheta);
    dx.fixed_rows_mut::<3>(imu::POSITION.idx)
        .copy_from(&(a.position - b.position));
    dx.fixed_rows_mut::<3>(imu::VELOCITY.idx)
        .copy_from(&(a.velocity - b.velocity));
    dx.fixed_rows_mut::<3>(imu::GYRO_BIAS.idx)
        .copy_from(&(a.gyro_bias - b.gyro_bias));
    dx.fixed_rows_mut::<3>(imu::ACCEL_BIAS.idx)
        .copy_from(&(a.accel_bias - b.accel_bias));
    dx
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::{assert_mat_close, central_diff};
    use nalgebra::{SVector, UnitQuaternion};

    fn moving_state() -> ImuState<f64> {
        ImuState {
            rotation: UnitQuaternion::from_euler_angles(2.9, -0.3, 1.2),
            position: Vector3::new(0.3, -1.0, 2.0),
            velocity: Vector3::new(0.5, -0.2, 0.1),
            gyro_bias: Vector3::new(1e-3, -2e-3, 5e-4),
            accel_bias: Vector3::new(0.02, -0.01, 0.03),
        }
    }

    #[test]
    fn transition_matches_central_differences() {
        let x = moving_state();
        let gyro = Vector3::new(1.5, -2.0, 0.7);
        let accel = Vector3::new(1.0, 3.0, 9.0);
        let noise = ImuNoise::vn300();
        // A long step makes every second-order term visible.
        let dt = 0.05;
        let nominal = step(&x, &ImuInterval::constant(gyro, accel, dt), &noise).state;
        let numeric = central_diff::<15, 15>(|d: SVector<f64, 15>| {
            let next = step(
                &boxplus(&x, &d),
                &ImuInterval::constant(gyro, accel, dt),
                &noise,
            )
            .state;
            boxminus(&next, &nominal)
        });
        let analytic = step(&x, &ImuInterval::constant(gyro, accel, dt), &noise).transition;
        assert_mat_close(&analytic, &numeric, 1e-6);
    }

    #[test]
    fn transition_of_a_changing_signal_matches_central_differences() {
        let x = moving_state();
        // Rate and force change within the step, as fast as 2.7 rad/s hand-held motion at
        // 20 Hz would: coning, sculling and the force change are all non-zero.
        let signal = ImuInterval {
            dt: 0.05,
            gyro_mean: Vector3::new(1.5, -2.0, 0.7),
            accel_mean: Vector3::new(1.0, 3.0, 9.0),
            start: (Vector3::new(1.0, -2.5, 1.0), Vector3::new(-1.0, 4.0, 8.0)),
            end: (Vector3::new(2.0, -1.5, 0.3), Vector3::new(3.0, 2.0, 10.0)),
        };
        let noise = ImuNoise::vn300();
        let nominal = step(&x, &signal, &noise).state;
        let numeric = central_diff::<15, 15>(|d: SVector<f64, 15>| {
            boxminus(&step(&boxplus(&x, &d), &signal, &noise).state, &nominal)
        });
        assert_mat_close(&step(&x, &signal, &noise).transition, &numeric, 1e-6);
    }

    #[test]
    fn transition_with_series_rotations_matches_central_differences() {
        // A 400 Hz step of a fast turn: every angle inside the series' range.
        let x = moving_state();
        let signal = ImuInterval {
            dt: 0.0025,
            gyro_mean: Vector3::new(6.5, -9.0, 4.7),
            accel_mean: Vector3::new(1.0, 3.0, 9.0),
            start: (Vector3::new(6.0, -9.5, 5.0), Vector3::new(-1.0, 4.0, 8.0)),
            end: (Vector3::new(7.0, -8.5, 4.3), Vector3::new(3.0, 2.0, 10.0)),
        };
        let noise = ImuNoise::vn300();
        let run = |x: &ImuState<f64>| step_with(x, &signal, &noise, Rotations::Series);
        let nominal = run(&x).state;
        let numeric = central_diff::<15, 15>(|d: SVector<f64, 15>| {
            boxminus(&run(&boxplus(&x, &d)).state, &nominal)
        });
        assert_mat_close(&run(&x).transition, &numeric, 1e-6);
        let reference = step(&x, &signal, &noise);
        assert_mat_close(&run(&x).transition, &reference.transition, 1e-15);
        assert!(boxminus(&nominal, &reference.state).amax() < 1e-15);
    }

    #[test]
    fn covariance_step_equals_the_dense_product() {
        let noise = ImuNoise::<f64>::vn300();
        let x = moving_state();
        let signal = ImuInterval::linear(
            (Vector3::new(0.3, -1.2, 2.1), Vector3::new(0.4, 9.9, -1.3)),
            (Vector3::new(0.5, -1.0, 2.4), Vector3::new(0.1, 9.6, -1.0)),
            0.0025,
        );
        let step = step(&x, &signal, &noise);
        // A symmetric positive definite P with every entry non-zero.
        let l = SMatrix::<f64, 15, 15>::from_fn(|i, j| {
            if j <= i {
                1.0 + 0.1 * ((i * 7 + j * 3) % 11) as f64
            } else {
                0.0
            }
        });
        let p = l * l.transpose();
        let phi = step.transition;
        let dense = phi * p * phi.transpose() + step.noise;
        let structured = covariance_step(&phi, &p, &step.noise);
        assert_mat_close(&structured, &dense, 1e-13);
        assert_eq!(structured, structured.transpose());
    }

    #[test]
    fn structured_product_equals_dense_product_for_chained_steps() {
        let noise = ImuNoise::vn300();
        let mut x = moving_state();
        let mut acc = SMatrix::<f64, 15, 15>::identity();
        for k in 0..5 {
            let s = step(
                &x,
                &ImuInterval::constant(
                    Vector3::new(1.0, -0.5, 0.2 * k as f64),
                    Vector3::new(0.3, 2.0, 9.0),
                    0.01,
                ),
                &noise,
            );
            let dense = s.transition * acc;
            let composed = transition_compose(&s.transition, &acc);
            acc = transition_mul(&s.transition, &acc);
            assert_mat_close(&acc, &dense, 1e-14);
            // The block-pattern product skips exact zeros only: the same numbers.
            assert_mat_close(&composed, &acc, 1e-15);
            assert_eq!(composed, acc, "step {k}");
            x = s.state;
        }
        let m = SMatrix::<f64, 15, 4>::from_fn(|r, c| (r * 7 + c) as f64 * 0.1);
        assert_mat_close(&transition_mul(&acc, &m), &(acc * m), 1e-13);
    }

    #[test]
    fn all_finite_answers_as_is_finite_on_each_value() {
        let big = [f64::MAX, -f64::MAX, f64::MAX, 1e308, -0.0, 0.0];
        assert!(all_finite(&big), "finite values whose sum overflows");
        for bad in [f64::INFINITY, f64::NEG_INFINITY, f64::NAN] {
            for at in 0..big.len() {
                let mut v = big;
                v[at] = bad;
                assert!(!all_finite(&v), "{bad} at {at}");
            }
        }
        assert!(all_finite::<f32>(&[]));
        assert!(!all_finite(&[1.0f32, f32::NAN]));
        assert!(all_finite(&[f32::MAX, f32::MAX]));
    }

    #[test]
    fn noise_is_symmetric_and_positive() {
        let x = moving_state();
        let s = step(
            &x,
            &ImuInterval::constant(Vector3::new(1.0, 0.5, 0.0), Vector3::z(), 0.0025),
            &ImuNoise::vn300(),
        );
        assert_mat_close(&s.noise, &s.noise.transpose(), 1e-18);
        assert!((0..15).all(|i| s.noise[(i, i)] > 0.0));
        // The block-wise Q is the dense G Q_c G^T: white noise enters like the bias columns
        // of Phi (without their identity), the walks on the bias diagonal.
        let n = ImuNoise::<f64>::vn300();
        let (dt, bg, ba) = (0.0025, imu::GYRO_BIAS.idx, imu::ACCEL_BIAS.idx);
        let mut g = SMatrix::<f64, 15, 12>::zeros();
        g.fixed_view_mut::<15, 3>(0, 0)
            .copy_from(&s.transition.fixed_view::<15, 3>(0, bg));
        g.fixed_view_mut::<15, 3>(0, 3)
            .copy_from(&s.transition.fixed_view::<15, 3>(0, ba));
        g.fixed_view_mut::<3, 3>(bg, 0).fill(0.0);
        g.fixed_view_mut::<3, 3>(ba, 3).fill(0.0);
        g.fixed_view_mut::<3, 3>(bg, 6).fill_diagonal(1.0);
        g.fixed_view_mut::<3, 3>(ba, 9).fill_diagonal(1.0);
        let mut q_c = SMatrix::<f64, 12, 12>::zeros();
        let var = [
            n.gyro_noise_density.powi(2) / dt,
            n.accel_noise_density.powi(2) / dt,
            n.gyro_random_walk.powi(2) * dt,
            n.accel_random_walk.powi(2) * dt,
        ];
        for i in 0..12 {
            q_c[(i, i)] = var[i / 3];
        }
        let dense = g * q_c * g.transpose();
        assert!(
            (s.noise - dense).amax() < 1e-15 * dense.amax(),
            "{}",
            (s.noise - dense).amax()
        );
    }

    #[test]
    fn stationary_imu_stays_put() {
        let mut x = moving_state();
        x.velocity = Vector3::zeros();
        x.gyro_bias = Vector3::zeros();
        x.accel_bias = Vector3::zeros();
        let accel = x.rotation.inverse() * Vector3::new(0.0, 0.0, GRAVITY);
        let mut s = x;
        for _ in 0..400 {
            s = step(
                &s,
                &ImuInterval::constant(Vector3::zeros(), accel, 0.0025),
                &ImuNoise::vn300(),
            )
            .state;
        }
        assert!((s.position - x.position).norm() < 1e-12);
        assert!(s.velocity.norm() < 1e-12);
    }
}

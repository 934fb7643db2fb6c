//! IMU propagation (dissertation eq. 3.8-3.17, OpenVINS-style discrete model).
//!
//! An IMU sample is the angular rate and specific force at its stamp, an instantaneous
//! reading, as EuRoC, Kalibr and OpenVINS take it. Between two samples the signal is their
//! linear interpolation ([`ImuSample::lerp`] gives a reading between samples), and
//! [`step_linear`] integrates that signal to fourth order: orientation with the linear rate
//! and its coning term, velocity and position by Simpson's rule over the orientations at the
//! start, middle and end of the step (what RK4 on the interpolated samples does here, as in
//! OpenVINS). The earlier scheme, the mean of the two readings with the mid-interval
//! orientation `R Exp(w_mean dt / 2)`, missed `dw/dt dt^2 / 8` of that orientation: a
//! specific-force error `|a| |dw/dt| dt^2 / 8` (2.5e-4 m/s^2 at 200 Hz and 8 rad/s^2);
//! propagation alone, worst 50 ms window 1.72 -> 1.17 sigma at 200 Hz, but the camera-IMU
//! NEES cells did not improve (docs/estimator.md). Holding one sample over
//! the whole interval instead would delay the signal by half a period, and every time offset
//! estimated against it by `dt / 2` (1.25 ms at 400 Hz).
//!
//! IMUs whose driver outputs interval means (integrating IMUs) are re-stamped to their
//! interval's midpoint by the dataset reader (`sample_timing` in `imu0/imu.yaml`), which
//! makes them instantaneous readings to second order.
//!
//! The error-state transition `Phi` and the discrete noise `Q_d = G Q G^T` follow from the
//! right perturbation `R = R_hat Exp(dtheta)`; both are checked against central differences.

use crate::lie::{exp, right_jacobian, skew};
use crate::scalar::Scalar;
use crate::state::{imu, ImuState};
use nalgebra::{Matrix3, SMatrix, Vector3};

/// Standard gravity, m/s^2; gravity in G is `(0, 0, -GRAVITY)`.
pub const GRAVITY: f64 = 9.81;

/// First indices of the IMU blocks: orientation, position, velocity, gyro bias, accel bias.
const BLOCKS: (usize, usize, usize, usize, usize) = (
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

    /// The reading at `t_ns` on the straight line from `self` to the later sample `next`
    /// (`t_ns` clamped to their stamps; `next` itself at its stamp, bit for bit).
    pub fn lerp(&self, next: &Self, t_ns: u64) -> Self {
        if t_ns >= next.stamp_ns || next.stamp_ns <= self.stamp_ns {
            return *next;
        }
        if t_ns <= self.stamp_ns {
            return *self;
        }
        let span = (next.stamp_ns - self.stamp_ns) as f64;
        let f = T::lit((t_ns - self.stamp_ns) as f64 / span);
        Self {
            stamp_ns: t_ns,
            gyro: self.gyro + (next.gyro - self.gyro) * f,
            accel: self.accel + (next.accel - self.accel) * f,
        }
    }

    /// The mean of two readings: the held value of the step between them.
    pub fn mean(&self, other: &Self) -> (Vector3<T>, Vector3<T>) {
        let half = T::lit(0.5);
        (
            (self.gyro + other.gyro) * half,
            (self.accel + other.accel) * half,
        )
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

/// Propagates the IMU state over `dt` seconds holding one reading `(gyro, accel)` (the
/// constant signal: [`step_linear`] with equal readings at both ends).
pub fn step<T: Scalar>(
    x: &ImuState<T>,
    gyro: &Vector3<T>,
    accel: &Vector3<T>,
    dt: T,
    noise: &ImuNoise<T>,
) -> ImuStep<T> {
    let held = ImuSample {
        stamp_ns: 0,
        gyro: *gyro,
        accel: *accel,
    };
    step_linear(x, &held, &held, dt, noise)
}

/// Rotation vector from the start of a step to `tau` (`dt / 2` or `dt`) under the bias-free
/// rate `u0 -> u1` linear over `dt`, to third order (the coning term `c u0 x u1`), and its
/// Jacobian w.r.t. the gyro bias.
fn rotation_to<T: Scalar>(
    u0: &Vector3<T>,
    u1: &Vector3<T>,
    dt: T,
    mid: bool,
) -> (Vector3<T>, Matrix3<T>) {
    let (w0, w1, tau, c) = if mid {
        // Over [0, dt/2]: the rate ends at (u0 + u1) / 2.
        (
            T::lit(0.375),
            T::lit(0.125),
            dt * T::lit(0.5),
            dt * dt / T::lit(96.0),
        )
    } else {
        (T::lit(0.5), T::lit(0.5), dt, dt * dt / T::lit(12.0))
    };
    let theta = (u0 * w0 + u1 * w1) * dt + u0.cross(u1) * c;
    let d_bg = Matrix3::identity() * (-tau) + (skew(u1) - skew(u0)) * c;
    (theta, d_bg)
}

/// Propagates the IMU state over `dt` seconds from reading `start` to reading `end`, the
/// signal linear in between (the readings' stamps are not used). Orientation integrates the
/// linear rate to third order (with its coning term); the rotated specific force is
/// integrated by Simpson's rule over the start, mid-interval and end orientations, which is
/// what RK4 on the linearly interpolated samples does for this linear system.
pub fn step_linear<T: Scalar>(
    x: &ImuState<T>,
    start: &ImuSample<T>,
    end: &ImuSample<T>,
    dt: T,
    noise: &ImuNoise<T>,
) -> ImuStep<T> {
    let (half, sixth) = (T::lit(0.5), T::lit(1.0 / 6.0));
    let (u0, u1) = (start.gyro - x.gyro_bias, end.gyro - x.gyro_bias);
    let a = [
        start.accel - x.accel_bias,
        (start.accel + end.accel) * half - x.accel_bias,
        end.accel - x.accel_bias,
    ];
    let g = Vector3::new(T::zero(), T::zero(), -T::lit(GRAVITY));
    let (theta_mid, d_mid) = rotation_to(&u0, &u1, dt, true);
    let (theta_end, d_end) = rotation_to(&u0, &u1, dt, false);
    let r0 = x.rotation.to_rotation_matrix().into_inner();
    let e = [
        Matrix3::identity(),
        exp(&theta_mid).to_rotation_matrix().into_inner(),
        exp(&theta_end).to_rotation_matrix().into_inner(),
    ];
    let f = |k: usize| r0 * e[k] * a[k];
    let (f0, fm, f1) = (f(0), f(1), f(2));
    let dv = (f0 + fm * T::lit(4.0) + f1) * (dt * sixth);
    let dp = (f0 + fm * T::lit(2.0)) * (dt * dt * sixth);

    let state = ImuState {
        rotation: crate::lie::renormalize(x.rotation * exp(&theta_end)),
        position: x.position + x.velocity * dt + dp + g * (half * dt * dt),
        velocity: x.velocity + dv + g * dt,
        gyro_bias: x.gyro_bias,
        accel_bias: x.accel_bias,
    };

    // Sensitivities of each rotated specific force `R0 E_k a_k` to the errors.
    let jr = [
        Matrix3::zeros(),
        right_jacobian(&theta_mid) * d_mid,
        right_jacobian(&theta_end) * d_end,
    ];
    let d_theta = |k: usize| -(r0 * e[k] * skew(&a[k]) * e[k].transpose());
    let d_bg = |k: usize| -(r0 * e[k] * skew(&a[k]) * jr[k]);
    let d_ba = |k: usize| -(r0 * e[k]);
    let simpson_v =
        |d: &dyn Fn(usize) -> Matrix3<T>| (d(0) + d(1) * T::lit(4.0) + d(2)) * (dt * sixth);
    let simpson_p =
        |d: &dyn Fn(usize) -> Matrix3<T>| (d(0) + d(1) * T::lit(2.0)) * (dt * dt * sixth);

    let mut phi = SMatrix::<T, 15, 15>::identity();
    let (o, p, v, bg, ba) = BLOCKS;
    set3(&mut phi, o, o, &e[2].transpose());
    set3(&mut phi, o, bg, &jr[2]);
    set3(&mut phi, p, o, &simpson_p(&d_theta));
    set3(&mut phi, p, v, &(Matrix3::identity() * dt));
    set3(&mut phi, p, bg, &simpson_p(&d_bg));
    set3(&mut phi, p, ba, &simpson_p(&d_ba));
    set3(&mut phi, v, o, &simpson_v(&d_theta));
    set3(&mut phi, v, bg, &simpson_v(&d_bg));
    set3(&mut phi, v, ba, &simpson_v(&d_ba));

    ImuStep {
        state,
        noise: discrete_noise(&phi, dt, noise),
        transition: phi,
    }
}

/// `Q_d = G Q G^T`: white noise enters exactly like a bias error held over the step, bias
/// walks add on the bias blocks. The gyro noise reaches the orientation, position and
/// velocity rows (the first 9), the accelerometer noise position and velocity, so `Q` is
/// formed on those blocks only.
fn discrete_noise<T: Scalar>(
    phi: &SMatrix<T, 15, 15>,
    dt: T,
    noise: &ImuNoise<T>,
) -> SMatrix<T, 15, 15> {
    let (o, p, _, bg, ba) = BLOCKS;
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
        let nominal = step(&x, &gyro, &accel, dt, &noise).state;
        let numeric = central_diff::<15, 15>(|d: SVector<f64, 15>| {
            let next = step(&boxplus(&x, &d), &gyro, &accel, dt, &noise).state;
            boxminus(&next, &nominal)
        });
        let analytic = step(&x, &gyro, &accel, dt, &noise).transition;
        assert_mat_close(&analytic, &numeric, 1e-6);
    }

    /// The interpolating step: different readings at both ends, a long step.
    #[test]
    fn linear_step_transition_matches_central_differences() {
        let x = moving_state();
        let reading = |gyro: [f64; 3], accel: [f64; 3]| ImuSample {
            stamp_ns: 0,
            gyro: Vector3::from(gyro),
            accel: Vector3::from(accel),
        };
        let a = reading([1.5, -2.0, 0.7], [1.0, 3.0, 9.0]);
        let b = reading([0.4, -1.1, 2.2], [-2.0, 4.0, 8.0]);
        let (dt, noise) = (0.05, ImuNoise::vn300());
        let nominal = step_linear(&x, &a, &b, dt, &noise).state;
        let numeric = central_diff::<15, 15>(|d: SVector<f64, 15>| {
            boxminus(
                &step_linear(&boxplus(&x, &d), &a, &b, dt, &noise).state,
                &nominal,
            )
        });
        assert_mat_close(
            &step_linear(&x, &a, &b, dt, &noise).transition,
            &numeric,
            1e-6,
        );
    }

    /// Against a fine integration of the linearly interpolated signal: the step's error is
    /// fourth order in `dt` (halving `dt` divides it by ~16), the mean-reading scheme's was
    /// third (its mid-interval orientation `Exp(w_mean dt / 2)` misses `dw/dt dt^2 / 8`).
    #[test]
    fn linear_step_converges_at_fourth_order() {
        let x = moving_state();
        let reading = |t: f64| ImuSample {
            stamp_ns: 0,
            gyro: Vector3::new(1.5, -2.0, 0.7) + Vector3::new(-20.0, 18.0, 30.0) * t,
            accel: Vector3::new(1.0, 3.0, 9.0) + Vector3::new(-60.0, 20.0, -20.0) * t,
        };
        let noise = ImuNoise::vn300();
        let fine = |dt: f64| {
            let n = 4000;
            let h = dt / n as f64;
            (0..n).fold(x, |s, k| {
                let (t0, t1) = (k as f64 * h, (k + 1) as f64 * h);
                step_linear(&s, &reading(t0), &reading(t1), h, &noise).state
            })
        };
        let error = |dt: f64| {
            let coarse = step_linear(&x, &reading(0.0), &reading(dt), dt, &noise).state;
            boxminus(&coarse, &fine(dt)).fixed_rows::<9>(0).norm()
        };
        let (e1, e2) = (error(0.01), error(0.005));
        assert!(e1 / e2 > 12.0, "{e1:e} / {e2:e}");
    }

    #[test]
    fn structured_product_equals_dense_product_for_chained_steps() {
        let noise = ImuNoise::vn300();
        let mut x = moving_state();
        let mut acc = SMatrix::<f64, 15, 15>::identity();
        for k in 0..5 {
            let s = step(
                &x,
                &Vector3::new(1.0, -0.5, 0.2 * k as f64),
                &Vector3::new(0.3, 2.0, 9.0),
                0.01,
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
    fn noise_is_symmetric_and_positive() {
        let x = moving_state();
        let s = step(
            &x,
            &Vector3::new(1.0, 0.5, 0.0),
            &Vector3::z(),
            0.0025,
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
            s = step(&s, &Vector3::zeros(), &accel, 0.0025, &ImuNoise::vn300()).state;
        }
        assert!((s.position - x.position).norm() < 1e-12);
        assert!(s.velocity.norm() < 1e-12);
    }
}

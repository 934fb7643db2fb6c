//! The yaw of the mounting from the wheel speed and the non-holonomic constraint, for a
//! ground vehicle whose odometry's rotation cannot be trusted (a skid-steer base slips in
//! every turn) but whose speed along its forward axis can.
//!
//! A wheeled base moves along its own forward axis only (no sideways or vertical
//! velocity), so the IMU's velocity, in the IMU frame, is `v_I = u s`: the wheel speed `s`
//! along `u = R_I_S e_x` (the lever arm's `w x p` neglected). `e_x` is the base's forward
//! axis in the odometry's body frame; any other known direction of travel can take its
//! place (the `forward` argument; `planar::travel` passes the one the odometry moves along). Over an interval `[a, b]` the
//! IMU's specific force, rotated into the IMU frame at `a` with the gyro alone and
//! integrated (`dv_ab`), is then
//!
//! `dv_ab = R_ab u s_b - u s_a + (b - a) R_aT g_T - int_a^b R_at dt b_a`,
//!
//! with `R_ab` the gyro's rotation from `b` to `a`, `g_T` the specific force of gravity in
//! the IMU frame at the start `T` of the interval's window of [`HEADING_WINDOW_S`] (the
//! vehicle's tilt over terrain, which a 2-D odometry calls level, followed inside the window
//! by the gyro) and `b_a` the accelerometer bias. The unknowns common to the drive are `u`,
//! `b_a` across the vertical (along it, it is one with every `g_T`) and a correction of the
//! gyro bias (Gauss-Newton, its columns by finite differences of the strapdown: a bias of
//! 1e-3 rad/s turns gravity enough in a window to move the yaw by up to 10 sigma, measured
//! on the simulated seeds 1-5); one `g_T` per window is eliminated window by window (a Schur
//! complement). The speed changes inform `u` along itself and the turns (the velocity
//! turning with the gyro: the centripetal `s w_z` sideways) across it; the odometry's own
//! rotation is never used. The angle of `u` about the sensor's `z` (vertical, from the tilt
//! by gravity) is the yaw of `R_I_S`, and the sigma is the delete-one-window jackknife over
//! the windows, which measures what the residuals actually do (slip sideways in turns,
//! terrain, time offset) instead of assuming white noise. `|u|` is the IMU's speed over the
//! wheels' (their scale; attenuated by noisy wheel speeds, so only reported).
//!
//! Assumed: the lever arm's velocity `w x p` is small against the speed (a few cm at a
//! few deg/s against tenths of m/s); the IMU and odometry stamps share a clock (on the
//! Jackal the fit prefers its odometry 100-200 ms later: docs/planar.md).

use nalgebra::{Matrix3, SMatrix, SVector, UnitQuaternion, Vector3};
use std::f64::consts::PI;

use crate::dataset::{ImuRecord, PoseRecord};

/// Length of each window with its own gravity, s: a few speed changes and turns of a
/// ground vehicle, short enough that its tilt and the gyro's drift stay put (fixed
/// beforehand and checked on the simulated seeds 201-240, not those the tests use).
pub const HEADING_WINDOW_S: f64 = 5.0;
/// Length of each interval of the velocity equations, s.
const NODE_S: f64 = 0.5;
/// Span over which the wheel speed at a node is averaged, s.
const SPEED_SPAN_S: f64 = 0.2;
/// Fewest windows for a jackknife sigma.
const MIN_WINDOWS: usize = 4;

/// The yaw of `R_I_S` from the non-holonomic fit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HeadingFit {
    /// Angle of `u` about `tilt`'s `z` from its `x`, rad. With `forward = x` (a wheel
    /// odometry) it is the yaw of `R_I_S = R_tilt Rz(yaw)`.
    pub yaw_rad: f64,
    /// 1-sigma of the yaw (jackknife over the windows), rad.
    pub sigma_rad: f64,
    /// The forward axis in the IMU frame, `u` (its norm: the speed scale).
    pub forward_imu: Vector3<f64>,
    /// The gyro bias refined by the fit, rad/s.
    pub gyro_bias: Vector3<f64>,
    /// Windows used.
    pub windows: usize,
}

impl HeadingFit {
    /// `R_I_S = R_tilt Rz(yaw)`, for a fit with `forward = x` (otherwise the rotation that
    /// takes `x`, not the direction of travel, onto `u`).
    pub fn rotation(&self, tilt: &UnitQuaternion<f64>) -> UnitQuaternion<f64> {
        tilt * UnitQuaternion::from_euler_angles(0.0, 0.0, self.yaw_rad)
    }

    /// IMU speed / wheel speed, `|u|`.
    pub fn speed_scale(&self) -> f64 {
        self.forward_imu.norm()
    }
}

/// Bias-corrected attitude `R_0(t)` (IMU at `t` to IMU at the first sample), the specific
/// force rotated into the first sample's frame and integrated, `V(t)`, and the attitude
/// integrated, `W(t) = int R_0 dt` (for a constant accelerometer bias), at every IMU sample.
struct Strapdown<'a> {
    imu: &'a [ImuRecord],
    rotation: Vec<UnitQuaternion<f64>>,
    velocity: Vec<Vector3<f64>>,
    attitude_integral: Vec<Matrix3<f64>>,
}

impl<'a> Strapdown<'a> {
    fn new(imu: &'a [ImuRecord], gyro_bias: &Vector3<f64>) -> Self {
        let mut rotation = vec![UnitQuaternion::identity()];
        let mut velocity = vec![Vector3::zeros()];
        let mut attitude_integral = vec![Matrix3::zeros()];
        for pair in imu.windows(2) {
            let dt = (pair[1].stamp_ns - pair[0].stamp_ns) as f64 * 1e-9;
            let k = rotation.len() - 1;
            let (r0, v0, w0) = (rotation[k], velocity[k], attitude_integral[k]);
            let w = 0.5 * (pair[0].gyro + pair[1].gyro) - gyro_bias;
            let r1 = r0 * UnitQuaternion::from_scaled_axis(w * dt);
            velocity.push(v0 + 0.5 * dt * (r0 * pair[0].accel + r1 * pair[1].accel));
            let (m0, m1) = (r0.to_rotation_matrix(), r1.to_rotation_matrix());
            attitude_integral.push(w0 + 0.5 * dt * (m0.matrix() + m1.matrix()));
            rotation.push(r1);
        }
        Self {
            imu,
            rotation,
            velocity,
            attitude_integral,
        }
    }

    /// `(R_0(t), V(t), W(t))` interpolated between the samples around `t_ns`.
    fn at(&self, t_ns: u64) -> Option<(UnitQuaternion<f64>, Vector3<f64>, Matrix3<f64>)> {
        let k = self.imu.partition_point(|r| r.stamp_ns <= t_ns);
        let (lo, hi) = (self.imu.get(k.checked_sub(1)?)?, self.imu.get(k)?);
        let alpha = (t_ns - lo.stamp_ns) as f64 / (hi.stamp_ns - lo.stamp_ns) as f64;
        let r = self.rotation[k - 1].slerp(&self.rotation[k], alpha);
        let v = self.velocity[k - 1].lerp(&self.velocity[k], alpha);
        let (w0, w1) = (self.attitude_integral[k - 1], self.attitude_integral[k]);
        let w = w0 + (w1 - w0) * alpha;
        Some((r, v, w))
    }
}

/// Speed along `forward` (the base's forward axis in the odometry's body frame: `x` for a
/// wheel odometry) at `t_ns`: the odometry's displacement in its own body frame over the
/// pose intervals whose midpoints lie within [`SPEED_SPAN_S`] of it, over their duration.
fn wheel_speed(poses: &[PoseRecord], forward: &Vector3<f64>, t_ns: u64) -> Option<f64> {
    let half = (0.5 * SPEED_SPAN_S * 1e9) as u64;
    let (from, to) = (t_ns.saturating_sub(half), t_ns + half);
    let start = poses
        .partition_point(|p| p.stamp_ns < from)
        .saturating_sub(1);
    let (mut path, mut time) = (0.0, 0.0);
    for pair in poses[start..].windows(2) {
        let mid = pair[0].stamp_ns / 2 + pair[1].stamp_ns / 2;
        if mid > to {
            break;
        }
        if mid >= from {
            let body = pair[0].rotation.inverse() * (pair[1].position - pair[0].position);
            path += body.dot(forward);
            time += (pair[1].stamp_ns - pair[0].stamp_ns) as f64 * 1e-9;
        }
    }
    (time > 0.5 * SPEED_SPAN_S).then(|| path / time)
}

/// The unknowns common to the drive: `u` (3), the horizontal accelerometer bias in the
/// tilt frame (2), the gyro bias correction (3).
const GLOBAL: usize = 8;
type Global = SVector<f64, GLOBAL>;
type GlobalMatrix = SMatrix<f64, GLOBAL, GLOBAL>;
type Design = SMatrix<f64, 3, GLOBAL>;

/// An interval `[a, b]` of a window starting at `start` with the wheel speeds at its ends.
#[derive(Clone, Copy)]
struct Interval {
    start: u64,
    a: u64,
    b: u64,
    s_a: f64,
    s_b: f64,
}

/// The intervals of the window starting at `start` (those with speeds along `forward` at
/// both ends).
fn intervals(poses: &[PoseRecord], forward: &Vector3<f64>, start: u64) -> Vec<Interval> {
    let steps = (HEADING_WINDOW_S / NODE_S).round() as u64;
    let node_ns = (NODE_S * 1e9) as u64;
    (0..steps)
        .filter_map(|j| {
            let (a, b) = (start + j * node_ns, start + (j + 1) * node_ns);
            let (s_a, s_b) = (
                wheel_speed(poses, forward, a)?,
                wheel_speed(poses, forward, b)?,
            );
            Some(Interval {
                start,
                a,
                b,
                s_a,
                s_b,
            })
        })
        .collect()
}

/// The measured `dv_ab` and the designs of `(u, c)` (the bias's horizontal part `c`, across
/// `level`'s columns) and of `g_T`, with `strap`.
fn terms(
    strap: &Strapdown<'_>,
    iv: &Interval,
    level: &SMatrix<f64, 3, 2>,
) -> Option<(Vector3<f64>, SMatrix<f64, 3, 5>, Matrix3<f64>)> {
    let ((r_0t, _, _), (r_0a, v_a, w_a), (r_0b, v_b, w_b)) =
        (strap.at(iv.start)?, strap.at(iv.a)?, strap.at(iv.b)?);
    let r_a0 = r_0a.inverse().to_rotation_matrix().into_inner();
    let y = r_a0 * (v_b - v_a);
    let a_u = r_a0 * r_0b.to_rotation_matrix().matrix() * iv.s_b - Matrix3::identity() * iv.s_a;
    let mut design = SMatrix::<f64, 3, 5>::zeros();
    design.fixed_view_mut::<3, 3>(0, 0).copy_from(&a_u);
    design
        .fixed_view_mut::<3, 2>(0, 3)
        .copy_from(&(r_a0 * (w_b - w_a) * level));
    let a_g = r_a0 * r_0t.to_rotation_matrix().matrix() * ((iv.b - iv.a) as f64 * 1e-9);
    Some((y, design, a_g))
}

/// One window's normal equations with its gravity eliminated (a Schur complement), and
/// what back-substitutes it.
#[derive(Clone, Copy)]
struct Reduced {
    n: GlobalMatrix,
    b: Global,
    ngx: SMatrix<f64, 3, GLOBAL>,
    ngg_inv: Matrix3<f64>,
    bg: Vector3<f64>,
}

impl Reduced {
    fn gravity(&self, x: &Global) -> Vector3<f64> {
        self.ngg_inv * (self.bg - self.ngx * x)
    }
}

/// The global unknowns at a linearisation point: `(u, c)` and the gyro bias.
struct Point {
    uc: SVector<f64, 5>,
    gyro_bias: Vector3<f64>,
}

/// A window's equations linearised at `point` (its gravity `g`): `y = [A_uc, -J_b] x + A_g g`
/// with `J_b` the residual's derivative in the gyro bias by finite differences.
fn reduce(
    straps: &[Strapdown<'_>; 4],
    window: &[Interval],
    level: &SMatrix<f64, 3, 2>,
    lin: Option<(&Point, Vector3<f64>)>,
) -> Option<Reduced> {
    let (mut nxx, mut nxg, mut ngg) = (GlobalMatrix::zeros(), Design::zeros(), Matrix3::zeros());
    let (mut bx, mut bg) = (Global::zeros(), Vector3::zeros());
    for iv in window {
        let (y, a_uc, a_g) = terms(&straps[0], iv, level)?;
        let mut design = Design::zeros();
        design.fixed_view_mut::<3, 5>(0, 0).copy_from(&a_uc);
        if let Some((point, g)) = lin {
            let residual =
                |s: &Strapdown<'_>| terms(s, iv, level).map(|(y, d, ag)| y - d * point.uc - ag * g);
            let r0 = residual(&straps[0])?;
            for i in 0..3 {
                let column = (residual(&straps[i + 1])? - r0) / BIAS_STEP;
                design
                    .fixed_view_mut::<3, 1>(0, 5 + i)
                    .copy_from(&(-column));
            }
        }
        nxx += design.transpose() * design;
        nxg += a_g.transpose() * design;
        ngg += a_g.transpose() * a_g;
        bx += design.transpose() * y;
        bg += a_g.transpose() * y;
    }
    let ngg_inv = (window.len() >= 3).then(|| ngg.try_inverse()).flatten()?;
    Some(Reduced {
        n: nxx - nxg.transpose() * ngg_inv * nxg,
        b: bx - nxg.transpose() * ngg_inv * bg,
        ngx: nxg,
        ngg_inv,
        bg,
    })
}

/// Finite-difference step of the gyro bias, rad/s.
const BIAS_STEP: f64 = 1e-5;
/// Gauss-Newton steps of the gyro bias.
const ITERATIONS: usize = 3;

fn strapdowns<'a>(imu: &'a [ImuRecord], bias: &Vector3<f64>) -> [Strapdown<'a>; 4] {
    let step = |i: usize| bias + Vector3::ith(i, BIAS_STEP);
    [
        Strapdown::new(imu, bias),
        Strapdown::new(imu, &step(0)),
        Strapdown::new(imu, &step(1)),
        Strapdown::new(imu, &step(2)),
    ]
}

/// Rotation about the vertical of `R_I_S = R_tilt Rz(yaw)` whose forward axis is `u`:
/// `R_tilt` (roll and pitch at zero yaw, from gravity) keeps the sensor's `z` where gravity
/// puts it, and the yaw turns about that `z`, so `R_tilt^T u` is `(cos, sin, 0) yaw`.
pub(crate) fn yaw_of(u: &Vector3<f64>, tilt: &UnitQuaternion<f64>) -> f64 {
    let level = tilt.inverse() * u;
    level.y.atan2(level.x)
}

/// `angle` wrapped into `[-pi, pi)`.
pub(crate) fn wrap(angle: f64) -> f64 {
    (angle + PI).rem_euclid(2.0 * PI) - PI
}

/// Solves the summed reduced equations (the gyro-bias columns fixed at zero when `fixed`).
fn solve(n: &GlobalMatrix, b: &Global, fixed: bool) -> Option<Global> {
    let mut n = *n;
    if fixed {
        for i in 5..GLOBAL {
            n[(i, i)] += 1.0;
        }
    }
    n.try_inverse().map(|inv| inv * b)
}

/// The yaw of `R_I_S` (see the module docs) from `imu` (starting gyro bias `gyro_bias`,
/// refined) and the odometry `poses` whose body moves along `forward` (`x` for a wheel
/// odometry), at the roll and pitch of `tilt` (`R_I_S` at zero yaw, for `forward = x`; in
/// general `yaw_rad` is the angle of `u` about `tilt`'s `z` from its `x`); `None` with fewer
/// than [`MIN_WINDOWS`] windows or when the drive neither accelerates nor turns.
pub fn nonholonomic_yaw(
    imu: &[ImuRecord],
    poses: &[PoseRecord],
    forward: &Vector3<f64>,
    gyro_bias: &Vector3<f64>,
    tilt: &UnitQuaternion<f64>,
) -> Option<HeadingFit> {
    let (first, last) = (
        imu.first()?.stamp_ns.max(poses.first()?.stamp_ns),
        imu.last()?.stamp_ns.min(poses.last()?.stamp_ns),
    );
    let window_ns = (HEADING_WINDOW_S * 1e9) as u64;
    let windows: Vec<Vec<Interval>> = (0..)
        .map(|k| first + 1 + k * window_ns)
        .take_while(|start| start + window_ns < last)
        .map(|start| intervals(poses, forward, start))
        .filter(|w| w.len() >= 3)
        .collect();
    if windows.len() < MIN_WINDOWS {
        return None;
    }
    let level_rot = tilt.to_rotation_matrix();
    let level: SMatrix<f64, 3, 2> = level_rot.matrix().fixed_columns::<2>(0).into();
    let mut point = Point {
        uc: SVector::zeros(),
        gyro_bias: *gyro_bias,
    };
    let mut lin: Option<Vec<Vector3<f64>>> = None;
    let mut reduced = Vec::new();
    for _ in 0..=ITERATIONS {
        let straps = strapdowns(imu, &point.gyro_bias);
        reduced = windows
            .iter()
            .enumerate()
            .map(|(k, w)| reduce(&straps, w, &level, lin.as_ref().map(|g| (&point, g[k]))))
            .collect::<Option<Vec<_>>>()?;
        let (n, b) = sum(&reduced, None);
        let x = solve(&n, &b, lin.is_none())?;
        lin = Some(reduced.iter().map(|r| r.gravity(&x)).collect());
        point.uc = x.fixed_rows::<5>(0).into();
        point.gyro_bias += x.fixed_rows::<3>(5);
    }
    let u: Vector3<f64> = point.uc.fixed_rows::<3>(0).into();
    let yaw = yaw_of(&u, tilt);
    let leave_one_out: Vec<f64> = (0..reduced.len())
        .map(|k| {
            let (n, b) = sum(&reduced, Some(k));
            let x = solve(&n, &b, false)?;
            Some(wrap(yaw_of(&x.fixed_rows::<3>(0).into(), tilt) - yaw))
        })
        .collect::<Option<_>>()?;
    let k = leave_one_out.len() as f64;
    let mean = leave_one_out.iter().sum::<f64>() / k;
    let variance = (k - 1.0) / k
        * leave_one_out
            .iter()
            .map(|d| (d - mean).powi(2))
            .sum::<f64>();
    let sigma = variance.sqrt();
    (sigma.is_finite() && sigma > 0.0).then_some(HeadingFit {
        yaw_rad: yaw,
        sigma_rad: sigma,
        forward_imu: u,
        gyro_bias: point.gyro_bias,
        windows: windows.len(),
    })
}

/// The reduced equations summed over the windows, leaving out window `skip`.
fn sum(reduced: &[Reduced], skip: Option<usize>) -> (GlobalMatrix, Global) {
    reduced
        .iter()
        .enumerate()
        .filter(|(k, _)| Some(*k) != skip)
        .fold((GlobalMatrix::zeros(), Global::zeros()), |acc, (_, r)| {
            (acc.0 + r.n, acc.1 + r.b)
        })
}

#[cfg(test)]
mod tests;

//! The gyroscope bias from motion, for recordings that do not start at rest: the bias that
//! makes the integrated gyro agree with the sensor's rotation increments, seen through the
//! hand-eye rotation (VINS-Mono's `solveGyroscopeBias`, here with the full SO(3)
//! Jacobians and alternated with the hand-eye rotation, which the bias also skews).
//!
//! Real MEMS gyros carry turn-on biases of several deg/s: the EuRoC ADIS16448 recording
//! `imu_april` reads 0.077 rad/s about z. A filter that starts from zero bias with a
//! 2e-3 rad/s prior sigma is 38 sigma off and diverges; a standstill measures the bias
//! directly, and without one this module does.

use msreg_estimator::hand_eye::HandEyeError;
use msreg_estimator::lie;
use nalgebra::{Matrix3, UnitQuaternion, Vector3};

use super::init::{self, gyro_pieces, RotationIncrement, RotationInit};
use crate::dataset::ImuRecord;

/// The gyroscope bias estimated from motion.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GyroBiasEstimate {
    /// Bias, rad/s, IMU axes (reading = rate + bias).
    pub bias: Vector3<f64>,
    /// 1-sigma per axis from the fit's residual scatter, rad/s.
    pub sigma: Vector3<f64>,
    /// Increments used (after the outlier cut).
    pub pairs: usize,
}

/// Fewest increments for a bias fit (3 unknowns, every increment gives 3 equations; more
/// keeps the residual-scatter sigma meaningful).
const MIN_PAIRS: usize = 10;
/// Gauss-Newton iterations per bias fit; the problem is nearly linear (two suffice).
const ITERATIONS: usize = 3;
/// Hand-eye / bias alternations: the bias moves the hand-eye pairs by `b dt`, the rotation
/// moves the bias residuals; three rounds leave both unchanged to 1e-9 in the tests.
const ALTERNATIONS: usize = 3;
/// Increments whose residual exceeds this many times the median are cut as outliers.
const OUTLIER_FACTOR: f64 = 5.0;
/// Residual below which an increment is never an outlier, rad.
const MIN_OUTLIER_THRESHOLD_RAD: f64 = 0.01;

/// One increment prepared for the fit: the gyro pieces over it and the sensor's rotation in
/// IMU axes (`R_I_S R_Sa_Sb R_I_S^T`).
struct Increment {
    pieces: Vec<(Vector3<f64>, f64)>,
    measured: UnitQuaternion<f64>,
}

/// The residual `log(R_gyro(b)^T R_measured)` of one increment and its Jacobian with
/// respect to the bias `b`.
///
/// With `R_gyro(b) = prod_k Exp((w_k - b) dt_k)`, a bias step `d` gives
/// `R_gyro(b + d) = R_gyro(b) Exp(A d)`, `A = -sum_k R_(k+1..n)^T Jr(phi_k) dt_k`, so the
/// residual's Jacobian is `-Jl^-1(r) A` with `Jl^-1(r) = Jr^-1(-r)`.
fn residual(increment: &Increment, bias: &Vector3<f64>) -> (Vector3<f64>, Matrix3<f64>) {
    let mut a = Matrix3::zeros();
    // Accumulated from the last piece backwards: `after` = R_(k+1..n).
    let mut after = UnitQuaternion::identity();
    for (rate, dt) in increment.pieces.iter().rev() {
        let phi = (rate - bias) * *dt;
        let r_after = after.to_rotation_matrix();
        a -= r_after.matrix().transpose() * lie::right_jacobian(&phi) * *dt;
        after = lie::exp(&phi) * after;
    }
    let r = lie::log(&(after.inverse() * increment.measured));
    (r, -lie::right_jacobian_inv(&(-r)) * a)
}

/// Gauss-Newton on the bias from `start`, over `increments`; the estimate with its sigmas
/// and the residual norms at the end. `None` when the normal equations are singular.
fn fit(increments: &[&Increment], start: &Vector3<f64>) -> Option<(GyroBiasEstimate, Vec<f64>)> {
    let mut bias = *start;
    let mut normal = Matrix3::zeros();
    for _ in 0..ITERATIONS {
        let mut rhs = Vector3::zeros();
        normal = Matrix3::zeros();
        for inc in increments {
            let (r, j) = residual(inc, &bias);
            normal += j.transpose() * j;
            rhs += j.transpose() * r;
        }
        bias -= normal.try_inverse()? * rhs;
    }
    let norms: Vec<f64> = increments
        .iter()
        .map(|inc| residual(inc, &bias).0.norm())
        .collect();
    let dof = (3 * increments.len()).saturating_sub(3).max(1) as f64;
    let variance = norms.iter().map(|e| e * e).sum::<f64>() / dof;
    let covariance = normal.try_inverse()? * variance;
    let estimate = GyroBiasEstimate {
        bias,
        sigma: covariance.diagonal().map(|v| v.max(0.0).sqrt()),
        pairs: increments.len(),
    };
    estimate
        .bias
        .iter()
        .all(|v| v.is_finite())
        .then_some((estimate, norms))
}

/// The gyro bias that best explains the rotation `increments` of a sensor at `R_I_S` =
/// `r_i_s`, starting from `start`: a fit, an outlier cut at 5x the median residual, a refit.
/// `None` with fewer than 10 usable increments or a singular fit.
pub fn estimate_gyro_bias(
    imu: &[ImuRecord],
    increments: &[RotationIncrement],
    r_i_s: &UnitQuaternion<f64>,
    start: &Vector3<f64>,
) -> Option<GyroBiasEstimate> {
    let prepared: Vec<Increment> = increments
        .iter()
        .filter_map(|(from, to, q_sensor)| {
            Some(Increment {
                pieces: gyro_pieces(imu, *from, *to)?,
                measured: r_i_s * q_sensor * r_i_s.inverse(),
            })
        })
        .collect();
    if prepared.len() < MIN_PAIRS {
        return None;
    }
    let all: Vec<&Increment> = prepared.iter().collect();
    let (first, norms) = fit(&all, start)?;
    let mut sorted = norms.clone();
    sorted.sort_by(f64::total_cmp);
    let threshold = (OUTLIER_FACTOR * sorted[sorted.len() / 2]).max(MIN_OUTLIER_THRESHOLD_RAD);
    let kept: Vec<&Increment> = all
        .iter()
        .zip(&norms)
        .filter(|(_, e)| **e <= threshold)
        .map(|(inc, _)| *inc)
        .collect();
    if kept.len() < MIN_PAIRS {
        return None;
    }
    fit(&kept, &first.bias).map(|(estimate, _)| estimate)
}

/// The hand-eye rotation and the gyro bias together, for a recording without a standstill:
/// hand-eye at zero bias, then alternately the bias at the current rotation and the
/// hand-eye at the current bias. The bias is `None` when no fit was possible (the hand-eye
/// result then stands at zero bias).
pub fn hand_eye_with_gyro_bias(
    imu: &[ImuRecord],
    increments: &[RotationIncrement],
    min_pairs: usize,
) -> (
    Result<RotationInit, HandEyeError<f64>>,
    Option<GyroBiasEstimate>,
) {
    let hand_eye = |bias: &Vector3<f64>| {
        init::hand_eye_from_pairs(
            init::rotation_pairs(imu, increments.iter().copied(), bias),
            min_pairs,
        )
    };
    let mut rotation = hand_eye(&Vector3::zeros());
    let mut estimate = None;
    for _ in 0..ALTERNATIONS {
        let Ok(current) = &rotation else {
            break;
        };
        let start = estimate.map_or_else(Vector3::zeros, |e: GyroBiasEstimate| e.bias);
        let Some(next) = estimate_gyro_bias(imu, increments, &current.rotation, &start) else {
            break;
        };
        estimate = Some(next);
        rotation = hand_eye(&next.bias);
    }
    (rotation, estimate)
}

#[cfg(test)]
mod tests;

//! VO scale `s` and the marker offset `T_F_M` from motion (eq. 6.7-6.9): the relative
//! motion of `F` between two marker detections of one camera (VO, interpolated, translation
//! times `s`) and that of `M` (from the two marker PnP poses) satisfy `A X = X B`,
//! `X = T_F_M`. The two are solved alternately: `s` in closed form with `X` fixed (eq.
//! 6.8), then `X` by Gauss-Newton with `s` fixed (eq. 6.9, Cauchy IRLS), a few rounds.
//!
//! Observability: rotation about one axis only (planar driving) leaves the rotation of `X`
//! about that axis to the translations and the translation of `X` along it unobservable.
//! [`MotionSolution::degeneracy`] reports the eigen-directions of the X step's normal
//! matrix whose information is below 1e-4 of the largest.

use nalgebra::{Isometry3, Matrix6, SMatrix, Translation3, UnitQuaternion, Vector3, Vector6};
use serde::Serialize;

use crate::solve::Loss;

/// One pair: `A = T_Fi_Fj` (translation in VO units), `B = T_Mi_Mj` (metric).
#[derive(Clone, Copy, Debug)]
pub struct MotionPair {
    /// Relative motion of F (VO units).
    pub a: Isometry3<f64>,
    /// Relative motion of M (m).
    pub b: Isometry3<f64>,
}

/// A weakly observed direction of `T_F_M`.
#[derive(Clone, Debug, Serialize)]
pub struct WeakDirection {
    /// `[d_theta, d_p]` unit direction.
    pub direction: [f64; 6],
    /// Its information relative to the best-determined direction.
    pub relative_information: f64,
}

/// Result of the alternation.
#[derive(Clone, Debug, Serialize)]
pub struct MotionSolution {
    /// Metres per VO unit.
    pub scale: f64,
    /// `T_F_M`, row-major.
    pub t_f_m: [[f64; 4]; 4],
    /// Weakly observed directions (empty: fully observable).
    pub degeneracy: Vec<WeakDirection>,
    /// Pairs used.
    pub pairs: usize,
    /// Rounds of the alternation.
    pub rounds: usize,
    /// RMS rotation residual (deg) and translation residual (m) at the solution.
    pub rms_rot_deg: f64,
    /// See `rms_rot_deg`.
    pub rms_trans_m: f64,
}

fn scaled(a: &Isometry3<f64>, s: f64) -> Isometry3<f64> {
    Isometry3::from_parts(Translation3::from(a.translation.vector * s), a.rotation)
}

/// `A X (-) X B` (eq. 6.7): rotation vector and translation of `(X B)^-1 A X`.
pub fn residual(p: &MotionPair, s: f64, x: &Isometry3<f64>) -> Vector6<f64> {
    let d = (x * p.b).inverse() * scaled(&p.a, s) * x;
    let r = d.rotation.scaled_axis();
    Vector6::new(
        r.x,
        r.y,
        r.z,
        d.translation.x,
        d.translation.y,
        d.translation.z,
    )
}

fn boxplus(x: &Isometry3<f64>, d: &Vector6<f64>) -> Isometry3<f64> {
    let q = x.rotation * UnitQuaternion::from_scaled_axis(Vector3::new(d[0], d[1], d[2]));
    Isometry3::from_parts(
        Translation3::from(x.translation.vector + Vector3::new(d[3], d[4], d[5])),
        q,
    )
}

/// Cauchy scale of the whitened residual (rotation weighted 1 rad ~ 1 m / `ROT_WEIGHT`).
const CAUCHY: f64 = 3.0;
/// Metres per radian used to put rotation and translation residuals on one scale.
const ROT_WEIGHT: f64 = 0.5;
/// Expected residual scale (m): rotation residuals times ROT_WEIGHT, translations.
const SIGMA: f64 = 0.02;

fn whiten(r: &Vector6<f64>) -> Vector6<f64> {
    let mut w = *r / SIGMA;
    for k in 0..3 {
        w[k] *= ROT_WEIGHT;
    }
    w
}

/// Closed-form `s` with `X` fixed: the translation part of eq. 6.7 is linear in `s`.
fn solve_scale(pairs: &[MotionPair], x: &Isometry3<f64>) -> f64 {
    let (mut num, mut den) = (0.0, 0.0);
    for p in pairs {
        // R_A t_X + s t_A = R_X t_B + t_X  =>  s t_A = R_X t_B + t_X - R_A t_X.
        let ta = p.a.translation.vector;
        let rhs = x.rotation * p.b.translation.vector + x.translation.vector
            - p.a.rotation * x.translation.vector;
        let w = Loss::Cauchy(CAUCHY).weight((ta * 1.0 - rhs).norm_squared() / (SIGMA * SIGMA));
        num += w * ta.dot(&rhs);
        den += w * ta.norm_squared();
    }
    if den > 0.0 {
        num / den
    } else {
        1.0
    }
}

/// Normal matrix and gradient of the X step (numeric Jacobian, central differences).
fn normal_equations(
    pairs: &[MotionPair],
    s: f64,
    x: &Isometry3<f64>,
) -> (Matrix6<f64>, Vector6<f64>, f64) {
    let (mut h, mut g, mut cost) = (Matrix6::zeros(), Vector6::zeros(), 0.0);
    let loss = Loss::Cauchy(CAUCHY);
    for p in pairs {
        let r = whiten(&residual(p, s, x));
        let mut j = SMatrix::<f64, 6, 6>::zeros();
        for k in 0..6 {
            let mut d = Vector6::zeros();
            d[k] = 1e-6;
            let plus = whiten(&residual(p, s, &boxplus(x, &d)));
            let minus = whiten(&residual(p, s, &boxplus(x, &-d)));
            j.set_column(k, &((plus - minus) / 2e-6));
        }
        let sq = r.norm_squared();
        let w = loss.weight(sq);
        cost += loss.rho(sq);
        h += w * j.transpose() * j;
        g += w * j.transpose() * r;
    }
    (h, g, cost)
}

fn solve_x(pairs: &[MotionPair], s: f64, start: Isometry3<f64>) -> (Isometry3<f64>, f64) {
    let mut x = start;
    let (mut h, mut g, mut cost) = normal_equations(pairs, s, &x);
    let mut lambda = 1e-3;
    for _ in 0..50 {
        let mut damped = h;
        for k in 0..6 {
            damped[(k, k)] += lambda * h[(k, k)].max(1e-9);
        }
        let Some(step) = damped.cholesky().map(|c| c.solve(&-g)) else {
            break;
        };
        let candidate = boxplus(&x, &step);
        let (h2, g2, c2) = normal_equations(pairs, s, &candidate);
        if c2 < cost {
            let done = (cost - c2) < 1e-10 * cost || step.norm() < 1e-10;
            (x, h, g, cost, lambda) = (candidate, h2, g2, c2, (lambda * 0.3).max(1e-9));
            if done {
                break;
            }
        } else {
            lambda *= 10.0;
            if lambda > 1e8 {
                break;
            }
        }
    }
    (x, cost)
}

/// Starting rotations: the mean rotation axis of B turned onto that of A, then 8 angles
/// about it (the planar case leaves that angle to the translations).
fn starts(pairs: &[MotionPair]) -> Vec<Isometry3<f64>> {
    let axis = |q: &UnitQuaternion<f64>, r: &UnitQuaternion<f64>| {
        let (a, b) = (q.scaled_axis(), r.scaled_axis());
        if a.dot(&b) < 0.0 {
            (a, -b)
        } else {
            (a, b)
        }
    };
    let (mut sa, mut sb) = (Vector3::zeros(), Vector3::zeros());
    for p in pairs {
        let (a, b) = axis(&p.a.rotation, &p.b.rotation);
        let sign = if a.z < 0.0 { -1.0 } else { 1.0 };
        sa += a * sign;
        sb += b * sign;
    }
    let align = UnitQuaternion::rotation_between(&sb, &sa).unwrap_or_else(UnitQuaternion::identity);
    let n = sa.try_normalize(1e-12).unwrap_or_else(Vector3::z);
    (0..8)
        .map(|k| {
            let spin =
                UnitQuaternion::from_scaled_axis(n * (k as f64 * std::f64::consts::FRAC_PI_4));
            Isometry3::from_parts(Translation3::identity(), spin * align)
        })
        .collect()
}

/// Solves eq. 6.7-6.9 by alternation from the starts; `None` with fewer than 3 pairs.
pub fn solve(pairs: &[MotionPair]) -> Option<MotionSolution> {
    if pairs.len() < 3 {
        return None;
    }
    let mut best: Option<(Isometry3<f64>, f64, f64, usize)> = None;
    for start in starts(pairs) {
        let (mut x, mut s, mut cost) = (start, solve_scale(pairs, &start), f64::INFINITY);
        let mut rounds = 0;
        for _ in 0..20 {
            rounds += 1;
            let (x2, c2) = solve_x(pairs, s, x);
            x = x2;
            s = solve_scale(pairs, &x);
            let converged = (cost - c2).abs() < 1e-9 * c2.max(1e-12);
            cost = c2;
            if converged {
                break;
            }
        }
        if best.as_ref().is_none_or(|b| cost < b.2) {
            best = Some((x, s, cost, rounds));
        }
    }
    let (x, s, _, rounds) = best?;
    Some(summarise(pairs, x, s, rounds))
}

fn summarise(pairs: &[MotionPair], x: Isometry3<f64>, s: f64, rounds: usize) -> MotionSolution {
    let (h, _, _) = normal_equations(pairs, s, &x);
    let eig = h.symmetric_eigen();
    let max = eig.eigenvalues.max().max(1e-300);
    let degeneracy = (0..6)
        .filter(|&k| eig.eigenvalues[k] < 1e-4 * max)
        .map(|k| {
            let v = eig.eigenvectors.column(k);
            WeakDirection {
                direction: std::array::from_fn(|i| v[i]),
                relative_information: eig.eigenvalues[k] / max,
            }
        })
        .collect();
    let n = pairs.len() as f64;
    let (mut rr, mut rt) = (0.0, 0.0);
    for p in pairs {
        let r = residual(p, s, &x);
        rr += r.fixed_rows::<3>(0).norm_squared();
        rt += r.fixed_rows::<3>(3).norm_squared();
    }
    MotionSolution {
        scale: s,
        t_f_m: super::io::matrix_rows(&x),
        degeneracy,
        pairs: pairs.len(),
        rounds,
        rms_rot_deg: (rr / n).sqrt().to_degrees(),
        rms_trans_m: (rt / n).sqrt(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn recovers_scale_and_offset_from_exact_pairs() {
        let x = Isometry3::from_parts(
            Translation3::new(-0.3, 0.05, 0.08),
            UnitQuaternion::from_euler_angles(0.03, -0.02, 1.3),
        );
        let s = 2.7;
        let pairs: Vec<MotionPair> = (0..40)
            .map(|i| {
                let f = i as f64;
                let a_metric = Isometry3::from_parts(
                    Translation3::new(0.8 + 0.1 * f.sin(), 0.3 * (f * 0.7).cos(), 0.01 * f.cos()),
                    UnitQuaternion::from_euler_angles(
                        0.03 * (f * 1.3).sin(),
                        0.03 * (f * 0.9).cos(),
                        0.4 * (f * 0.5).sin(),
                    ),
                );
                let b = x.inverse() * a_metric * x;
                MotionPair {
                    a: scaled(&a_metric, 1.0 / s),
                    b,
                }
            })
            .collect();
        let sol = solve(&pairs).expect("solvable");
        assert!((sol.scale - s).abs() < 1e-6 * s, "{}", sol.scale);
        let est =
            super::super::io::pose_of_rows(std::path::Path::new("-"), &sol.t_f_m).expect("pose");
        assert!((est.translation.vector - x.translation.vector).norm() < 1e-5);
        assert!(est.rotation.angle_to(&x.rotation) < 1e-6);
    }
}

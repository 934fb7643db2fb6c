//! Second IMU against the first (`imuN.T_imu0_imu`, `timeshift_imu_imu0`), batch.
//!
//! Conventions: `p_imu0 = R * p_imuN + r` (`T_imu0_imu`), and a sample of imuN stamped
//! `t_N` was taken at imu0 time `t_N + timeshift`.
//!
//! Stages: (1) time offset from the cross-correlation of the angular-rate magnitudes
//! (grid of imu0 periods, then a fine grid and a parabolic fit); (2) rotation, combined
//! gyro bias and time offset by Gauss-Newton on `w0(t_N + ts) = R w_N + c` (Kabsch start);
//! (3) lever arm and combined accelerometer bias by linear least squares on
//! `R f_N = f0 + alpha x r + w x (w x r) + d` with `alpha` a central difference of imu0's
//! gyro. Covariances come from the data: the block sandwich of [`COVARIANCE_BLOCK_S`]-long
//! time blocks (the residuals of neighbouring rows share samples, so they are not white).

mod rig;

use nalgebra::{Matrix3, Rotation3, SMatrix, SVector, UnitQuaternion, Vector3};
use thiserror::Error;

pub use rig::{
    calibrate_rig, series, ImuPairOutcome, ImuRigCalibration, ImuRigError, LEVER_HELD_SIGMA_M,
};

/// One IMU's samples, time-ordered (s, rad/s, m/s^2).
#[derive(Debug, Clone, Default)]
pub struct ImuSeries {
    /// Stamps in the IMU's own clock (s).
    pub t: Vec<f64>,
    /// Gyro readings (rad/s).
    pub gyro: Vec<Vector3<f64>>,
    /// Accelerometer readings (m/s^2).
    pub accel: Vec<Vector3<f64>>,
}

/// Why the calibration could not run.
#[derive(Debug, Error, PartialEq)]
pub enum ImuImuError {
    /// Fewer samples than the method needs.
    #[error("{which}: {got} samples, need at least {need}")]
    TooFewSamples {
        /// Which series.
        which: &'static str,
        /// Samples present.
        got: usize,
        /// Samples needed.
        need: usize,
    },
    /// Stamps not strictly increasing or lengths differ.
    #[error("{which}: stamps not strictly increasing or series lengths differ (index {index})")]
    BadSeries {
        /// Which series.
        which: &'static str,
        /// First bad sample.
        index: usize,
    },
    /// Too little rotation to align the gyros.
    #[error("rotation not observable: smallest angular-rate spread {spread:.4} rad/s < {min}")]
    NoRotation {
        /// Smallest singular value of the rate spread (rad/s).
        spread: f64,
        /// Threshold (rad/s).
        min: f64,
    },
    /// The normal equations are singular.
    #[error("singular normal equations in {stage}")]
    Singular {
        /// Stage that failed.
        stage: &'static str,
    },
}

/// The estimate and its 1-sigma uncertainties.
#[derive(Debug, Clone)]
pub struct ImuImuEstimate {
    /// `R_imu0_imuN`.
    pub rotation: UnitQuaternion<f64>,
    /// Lever arm: imuN's origin in imu0 (m).
    pub translation: Vector3<f64>,
    /// `timeshift_imu_imu0` (s).
    pub timeshift_s: f64,
    /// Combined gyro bias `c = b0 - R bN` (rad/s).
    pub gyro_bias_diff: Vector3<f64>,
    /// Combined accelerometer bias `d` (m/s^2).
    pub accel_bias_diff: Vector3<f64>,
    /// 1-sigma of the rotation error (rad, tangent at the estimate).
    pub sigma_rotation: Vector3<f64>,
    /// 1-sigma of the lever arm (m).
    pub sigma_translation: Vector3<f64>,
    /// 1-sigma of the time offset (s).
    pub sigma_timeshift_s: f64,
    /// Covariance of (rotation, time) from the gyro stage.
    pub cov_rot_time: SMatrix<f64, 4, 4>,
    /// Covariance of the lever arm.
    pub cov_translation: Matrix3<f64>,
    /// Singular values of the centred angular-rate spread (rad/s), the rotation excitation.
    pub rate_spread: Vector3<f64>,
}

/// Tuning of the search.
#[derive(Debug, Clone, Copy)]
pub struct ImuImuOptions {
    /// Largest |time offset| searched (s).
    pub max_offset_s: f64,
    /// Smallest angular-rate spread (rad/s) for the rotation to count as observable.
    pub min_rate_spread: f64,
}

impl Default for ImuImuOptions {
    fn default() -> Self {
        Self {
            max_offset_s: 0.2,
            min_rate_spread: 0.05,
        }
    }
}

fn check(which: &'static str, s: &ImuSeries) -> Result<(), ImuImuError> {
    if s.t.len() < 50 {
        return Err(ImuImuError::TooFewSamples {
            which,
            got: s.t.len(),
            need: 50,
        });
    }
    if s.gyro.len() != s.t.len() || s.accel.len() != s.t.len() {
        return Err(ImuImuError::BadSeries {
            which,
            index: s.t.len().min(s.gyro.len()),
        });
    }
    match s.t.windows(2).position(|w| {
        w[1].partial_cmp(&w[0]) != Some(std::cmp::Ordering::Greater) || !w[1].is_finite()
    }) {
        Some(i) => Err(ImuImuError::BadSeries {
            which,
            index: i + 1,
        }),
        None => Ok(()),
    }
}

/// Cubic (Catmull-Rom) interpolation of `v` at `t`, linear in the first and last interval;
/// `None` outside the stamps. Linear interpolation would shrink a signal of frequency `f`
/// sampled every `dt` by about `(2 pi f dt)^2 / 12` on average, a scale error that biases
/// the rotation and the lever arm (3e-4 at 2 Hz and 200 Hz, 0.2 mm on a 30 cm lever).
fn interp(t: &[f64], v: &[Vector3<f64>], x: f64) -> Option<Vector3<f64>> {
    if x < t[0] || x > t[t.len() - 1] {
        return None;
    }
    let i = t.partition_point(|&s| s <= x).clamp(1, t.len() - 1);
    let a = (x - t[i - 1]) / (t[i] - t[i - 1]);
    if i < 2 || i + 1 >= t.len() {
        return Some(v[i - 1] * (1.0 - a) + v[i] * a);
    }
    // Tangents from the neighbours' central differences, scaled to this interval.
    let dt = t[i] - t[i - 1];
    let m0 = (v[i] - v[i - 2]) * (dt / (t[i] - t[i - 2]));
    let m1 = (v[i + 1] - v[i - 1]) * (dt / (t[i + 1] - t[i - 1]));
    let (a2, a3) = (a * a, a * a * a);
    Some(
        v[i - 1] * (2.0 * a3 - 3.0 * a2 + 1.0)
            + m0 * (a3 - 2.0 * a2 + a)
            + v[i] * (-2.0 * a3 + 3.0 * a2)
            + m1 * (a3 - a2),
    )
}

/// Normalised correlation of the rate magnitudes at offset `ts`.
fn correlation(s0: &ImuSeries, sn: &ImuSeries, ts: f64) -> f64 {
    let pairs: Vec<(f64, f64)> =
        sn.t.iter()
            .zip(&sn.gyro)
            .filter_map(|(&t, w)| interp(&s0.t, &s0.gyro, t + ts).map(|w0| (w0.norm(), w.norm())))
            .collect();
    if pairs.len() < 10 {
        return f64::NEG_INFINITY;
    }
    let n = pairs.len() as f64;
    let (ma, mb) = pairs
        .iter()
        .fold((0.0, 0.0), |(a, b), p| (a + p.0 / n, b + p.1 / n));
    let (mut sab, mut saa, mut sbb) = (0.0, 0.0, 0.0);
    for (a, b) in &pairs {
        sab += (a - ma) * (b - mb);
        saa += (a - ma) * (a - ma);
        sbb += (b - mb) * (b - mb);
    }
    sab / (saa * sbb).sqrt().max(1e-300)
}

/// Best of `ts0 + k * step`, |k| <= n, refined by a parabola through the peak.
fn grid_peak(s0: &ImuSeries, sn: &ImuSeries, ts0: f64, step: f64, n: i64) -> f64 {
    let c: Vec<f64> = (-n..=n)
        .map(|k| correlation(s0, sn, ts0 + k as f64 * step))
        .collect();
    let best = (0..c.len()).fold(0, |b, i| if c[i] > c[b] { i } else { b });
    let mut ts = ts0 + (best as i64 - n) as f64 * step;
    if best > 0 && best + 1 < c.len() {
        let (a, b, d) = (c[best - 1], c[best], c[best + 1]);
        let den = a - 2.0 * b + d;
        if den < 0.0 {
            ts += 0.5 * step * (a - d) / den;
        }
    }
    ts
}

/// Stage 1: time offset from the rate-magnitude cross-correlation.
pub fn coarse_timeshift(s0: &ImuSeries, sn: &ImuSeries, max_offset_s: f64) -> f64 {
    let dt0 = (s0.t[s0.t.len() - 1] - s0.t[0]) / (s0.t.len() - 1) as f64;
    let n = (max_offset_s / dt0).ceil() as i64;
    let coarse = grid_peak(s0, sn, 0.0, dt0, n);
    grid_peak(s0, sn, coarse, dt0 / 20.0, 20)
}

/// Kabsch: `R` minimising sum |a_k - R b_k|^2 over centred pairs, plus the spread of `a`.
fn kabsch(pairs: &[(Vector3<f64>, Vector3<f64>)]) -> (Rotation3<f64>, Vector3<f64>) {
    let n = pairs.len() as f64;
    let ma = pairs.iter().map(|p| p.0).sum::<Vector3<f64>>() / n;
    let mb = pairs.iter().map(|p| p.1).sum::<Vector3<f64>>() / n;
    let mut h = Matrix3::zeros();
    let mut saa = Matrix3::zeros();
    for (a, b) in pairs {
        h += (a - ma) * (b - mb).transpose();
        saa += (a - ma) * (a - ma).transpose();
    }
    let svd = h.svd(true, true);
    let (u, vt) = (svd.u.unwrap_or_default(), svd.v_t.unwrap_or_default());
    let s = Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, (u * vt).determinant().signum()));
    let spread = (saa / n).symmetric_eigenvalues().map(|e| e.max(0.0).sqrt());
    (Rotation3::from_matrix_unchecked(u * s * vt), spread)
}

/// Gyro residuals `w0(t_N + ts) - R w_N - c` with the Jacobian rows (dtheta, dc, dts).
fn gyro_rows(
    s0: &ImuSeries,
    sn: &ImuSeries,
    r: &Rotation3<f64>,
    c: &Vector3<f64>,
    ts: f64,
) -> Vec<Row<7>> {
    let h = 1e-3;
    let mut rows = Vec::with_capacity(sn.t.len());
    for (&t, w) in sn.t.iter().zip(&sn.gyro) {
        let (Some(w0), Some(wp), Some(wm)) = (
            interp(&s0.t, &s0.gyro, t + ts),
            interp(&s0.t, &s0.gyro, t + ts + h),
            interp(&s0.t, &s0.gyro, t + ts - h),
        ) else {
            continue;
        };
        let mut j = SMatrix::<f64, 3, 7>::zeros();
        j.fixed_view_mut::<3, 3>(0, 0)
            .copy_from(&(r.matrix() * w.cross_matrix()));
        j.fixed_view_mut::<3, 3>(0, 3)
            .copy_from(&(-Matrix3::identity()));
        j.fixed_view_mut::<3, 1>(0, 6)
            .copy_from(&((wp - wm) / (2.0 * h)));
        rows.push((t, w0 - r * w - c, j));
    }
    rows
}

/// One residual row: its stamp (imuN clock, s), the residual and its Jacobian.
type Row<const N: usize> = (f64, Vector3<f64>, SMatrix<f64, 3, N>);

/// Normal equations of stacked rows: (J^T J, J^T e).
type Normal<const N: usize> = (SMatrix<f64, N, N>, SVector<f64, N>);

/// Length of the time blocks of the covariance (s): five times the longest span a residual
/// shares samples over (the 20 ms central difference of the angular acceleration in the
/// lever-arm rows; the gyro rows share less, one imu0 interval).
pub const COVARIANCE_BLOCK_S: f64 = 0.1;

/// Stage 2's estimate: rotation, combined gyro bias, time offset, their covariance, and the
/// angular-rate spread.
type GyroFit = (
    Rotation3<f64>,
    Vector3<f64>,
    f64,
    SMatrix<f64, 7, 7>,
    Vector3<f64>,
);

/// Stage 3's estimate: lever arm, accelerometer-bias difference, lever-arm covariance.
type LeverFit = (Vector3<f64>, Vector3<f64>, Matrix3<f64>);

fn normal<const N: usize>(rows: &[Row<N>]) -> Normal<N> {
    let mut a = SMatrix::<f64, N, N>::zeros();
    let mut b = SVector::<f64, N>::zeros();
    for (_, e, j) in rows {
        a += j.transpose() * j;
        b += j.transpose() * e;
    }
    (a, b)
}

/// Covariance of the least-squares solution from the data (`A^-1 B A^-1`, the block
/// sandwich): `B` sums the outer products of each time block's gradient `sum J^T e`, so
/// residuals correlated within a block (a shared interpolated sample, a shared finite
/// difference, bias drift within the block) and a misjudged noise level are both in it;
/// a plain `A^-1 sigma^2` assumes white residuals and was 1.5x overconfident in NEES here.
fn sandwich<const N: usize>(
    rows: &[Row<N>],
    stage: &'static str,
) -> Result<SMatrix<f64, N, N>, ImuImuError> {
    let (a, _) = normal(rows);
    let inv = a.try_inverse().ok_or(ImuImuError::Singular { stage })?;
    let mut b = SMatrix::<f64, N, N>::zeros();
    let mut g = SVector::<f64, N>::zeros();
    let mut block = None;
    for (t, e, j) in rows {
        let k = (t / COVARIANCE_BLOCK_S).floor() as i64;
        if block.is_some_and(|b| b != k) {
            b += g * g.transpose();
            g.fill(0.0);
        }
        block = Some(k);
        g += j.transpose() * e;
    }
    b += g * g.transpose();
    Ok(inv * b * inv)
}

/// Stage 2: rotation, combined gyro bias and time offset (Gauss-Newton, Kabsch start).
fn gyro_stage(
    s0: &ImuSeries,
    sn: &ImuSeries,
    ts0: f64,
    opts: &ImuImuOptions,
) -> Result<GyroFit, ImuImuError> {
    let pairs: Vec<_> =
        sn.t.iter()
            .zip(&sn.gyro)
            .filter_map(|(&t, w)| interp(&s0.t, &s0.gyro, t + ts0).map(|w0| (w0, *w)))
            .collect();
    let (mut r, spread) = kabsch(&pairs);
    if spread.min() < opts.min_rate_spread {
        return Err(ImuImuError::NoRotation {
            spread: spread.min(),
            min: opts.min_rate_spread,
        });
    }
    let n = pairs.len() as f64;
    let mut c = pairs.iter().map(|p| p.0 - r * p.1).sum::<Vector3<f64>>() / n;
    let mut ts = ts0;
    for _ in 0..8 {
        let (a, b) = normal(&gyro_rows(s0, sn, &r, &c, ts));
        let dx = a
            .cholesky()
            .ok_or(ImuImuError::Singular { stage: "gyro" })?
            .solve(&(-b));
        r *= Rotation3::new(Vector3::new(dx[0], dx[1], dx[2]));
        c += Vector3::new(dx[3], dx[4], dx[5]);
        ts += dx[6];
        if dx.norm() < 1e-12 {
            break;
        }
    }
    let cov = sandwich(&gyro_rows(s0, sn, &r, &c, ts), "gyro covariance")?;
    Ok((r, c, ts, cov, spread))
}

/// Accelerometer rows for the lever arm: `R f_N - f0 = (alpha^ + w^ w^) r + d`.
fn accel_rows(
    s0: &ImuSeries,
    sn: &ImuSeries,
    r: &Rotation3<f64>,
    c: &Vector3<f64>,
    ts: f64,
) -> Vec<Row<6>> {
    let h = 0.01;
    let mut rows = Vec::with_capacity(sn.t.len());
    for ((&t, f), wn) in sn.t.iter().zip(&sn.accel).zip(&sn.gyro) {
        let x = t + ts;
        let (Some(f0), Some(wp), Some(wm)) = (
            interp(&s0.t, &s0.accel, x),
            interp(&s0.t, &s0.gyro, x + h),
            interp(&s0.t, &s0.gyro, x - h),
        ) else {
            continue;
        };
        let w = r * wn + c;
        let alpha = (wp - wm) / (2.0 * h);
        let mut j = SMatrix::<f64, 3, 6>::zeros();
        let wx = w.cross_matrix();
        j.fixed_view_mut::<3, 3>(0, 0)
            .copy_from(&(alpha.cross_matrix() + wx * wx));
        j.fixed_view_mut::<3, 3>(0, 3)
            .copy_from(&Matrix3::identity());
        rows.push((t, r * f - f0, j));
    }
    rows
}

/// The linear least-squares solution `(lever, d)` of the accelerometer rows at `(r, c, ts)`.
fn lever_solve(
    s0: &ImuSeries,
    sn: &ImuSeries,
    r: &Rotation3<f64>,
    c: &Vector3<f64>,
    ts: f64,
) -> Result<(Vec<Row<6>>, SVector<f64, 6>), ImuImuError> {
    let rows = accel_rows(s0, sn, r, c, ts);
    let (a, b) = normal(&rows);
    let x = a
        .cholesky()
        .ok_or(ImuImuError::Singular { stage: "lever arm" })?
        .solve(&b);
    Ok((rows, x))
}

/// Stage 3: lever arm and combined accelerometer bias, linear least squares. The
/// covariance is the block sandwich of its own rows plus what the stage-2 uncertainty of
/// `(rotation, c, ts)` (`cov_gyro`) does to the solution (a two-step estimator: the
/// sensitivity `d x / d p` by central differences of the solve, `F cov_gyro F^T`).
fn lever_stage(
    s0: &ImuSeries,
    sn: &ImuSeries,
    gyro: (&Rotation3<f64>, &Vector3<f64>, f64),
    cov_gyro: &SMatrix<f64, 7, 7>,
) -> Result<LeverFit, ImuImuError> {
    let (r, c, ts) = gyro;
    let (rows, x) = lever_solve(s0, sn, r, c, ts)?;
    let residuals: Vec<Row<6>> = rows.iter().map(|(t, e, j)| (*t, e - j * x, *j)).collect();
    let own = sandwich(&residuals, "lever covariance")?;
    let mut f = SMatrix::<f64, 6, 7>::zeros();
    let h = 1e-6;
    for k in 0..7 {
        let solve_at = |sign: f64| {
            let mut d = SVector::<f64, 7>::zeros();
            d[k] = sign * h;
            let rp = r * Rotation3::new(Vector3::new(d[0], d[1], d[2]));
            let cp = c + Vector3::new(d[3], d[4], d[5]);
            lever_solve(s0, sn, &rp, &cp, ts + d[6]).map(|(_, x)| x)
        };
        f.set_column(k, &((solve_at(1.0)? - solve_at(-1.0)?) / (2.0 * h)));
    }
    let cov = own + f * cov_gyro * f.transpose();
    Ok((
        Vector3::new(x[0], x[1], x[2]),
        Vector3::new(x[3], x[4], x[5]),
        cov.fixed_view::<3, 3>(0, 0).into(),
    ))
}

/// Calibrates imuN (`sn`) against imu0 (`s0`).
pub fn calibrate(
    s0: &ImuSeries,
    sn: &ImuSeries,
    opts: &ImuImuOptions,
) -> Result<ImuImuEstimate, ImuImuError> {
    check("imu0", s0)?;
    check("imuN", sn)?;
    let ts0 = coarse_timeshift(s0, sn, opts.max_offset_s);
    let (r, c, ts, cov7, spread) = gyro_stage(s0, sn, ts0, opts)?;
    let (lever, d, cov_t) = lever_stage(s0, sn, (&r, &c, ts), &cov7)?;
    let mut cov4 = SMatrix::<f64, 4, 4>::zeros();
    for (i, p) in [0usize, 1, 2, 6].iter().enumerate() {
        for (k, q) in [0usize, 1, 2, 6].iter().enumerate() {
            cov4[(i, k)] = cov7[(*p, *q)];
        }
    }
    Ok(ImuImuEstimate {
        rotation: UnitQuaternion::from_rotation_matrix(&r),
        translation: lever,
        timeshift_s: ts,
        gyro_bias_diff: c,
        accel_bias_diff: d,
        sigma_rotation: Vector3::new(cov7[(0, 0)], cov7[(1, 1)], cov7[(2, 2)]).map(f64::sqrt),
        sigma_translation: cov_t.diagonal().map(f64::sqrt),
        sigma_timeshift_s: cov7[(6, 6)].sqrt(),
        cov_rot_time: cov4,
        cov_translation: cov_t,
        rate_spread: spread,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn wiggly_series(rate: f64, shift: f64) -> ImuSeries {
        let mut s = ImuSeries::default();
        for k in 0..(4.0 * rate) as usize {
            let t = k as f64 / rate;
            let x = t + shift;
            s.t.push(t);
            s.gyro.push(Vector3::new(
                (1.3 * x).sin(),
                0.7 * (2.1 * x).cos(),
                0.4 * (0.9 * x).sin() + 0.2,
            ));
            s.accel.push(Vector3::new(0.1 * x.sin(), 0.0, 9.81));
        }
        s
    }

    /// The gyro rows' Jacobian (rotation on the right, combined bias, time offset) against
    /// central differences of the residual.
    #[test]
    fn gyro_jacobian_matches_finite_differences() {
        let (s0, sn) = (wiggly_series(400.0, 0.0), wiggly_series(250.0, 0.013));
        let r = Rotation3::new(Vector3::new(0.3, -0.2, 1.1));
        let c = Vector3::new(0.01, -0.02, 0.005);
        let ts = 0.01;
        let rows = gyro_rows(&s0, &sn, &r, &c, ts);
        let h = 1e-6;
        let mut worst = [0.0f64; 2];
        let plus = |d: &SVector<f64, 7>| {
            let rp = r * Rotation3::new(Vector3::new(d[0], d[1], d[2]));
            let cp = c + Vector3::new(d[3], d[4], d[5]);
            gyro_rows(&s0, &sn, &rp, &cp, ts + d[6])
        };
        for i in 0..7 {
            let mut d = SVector::<f64, 7>::zeros();
            d[i] = h;
            let (p, m) = (plus(&d), plus(&(-d)));
            assert_eq!((p.len(), m.len()), (rows.len(), rows.len()));
            for ((row, rp), rm) in rows.iter().zip(&p).zip(&m).skip(100).step_by(97) {
                let fd = (rp.1 - rm.1) / (2.0 * h);
                let an = row.2.column(i);
                let w = &mut worst[usize::from(i == 6)];
                *w = w.max((fd - an).norm());
            }
        }
        // Rotation and bias columns are exact up to the differencing error (~1e-9).
        assert!(worst[0] < 1e-6, "rotation/bias columns off by {}", worst[0]);
        // The time column is a +-1 ms central difference of the linearly interpolated gyro,
        // the finite difference the slope of one 2.5 ms segment: they differ by at most
        // |d2w/dt2| * 2.5 ms = 3.1 rad/s^3 * 2.5 ms ~ 8e-3 rad/s per s here.
        assert!(worst[1] < 1e-2, "time column off by {}", worst[1]);
    }
}

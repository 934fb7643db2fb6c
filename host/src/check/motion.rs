//! Motion checks: each sensor's clock offset from the cross-correlation of its angular
//! rate (from pose or PnP increments) with the gyro's, and the excitation per IMU axis.
//!
//! The magnitude of the angular rate does not depend on the mounting, so the offset is
//! found before anything is calibrated (as Kalibr's and OpenVINS's initialisers do).

use nalgebra::{Isometry3, Matrix3, UnitQuaternion, Vector3};
use rayon::prelude::*;

use super::sensors::{CameraData, SensorData};
use super::Finding;
use crate::calibrate::camera_imu::pnp_of;
use crate::calibrate::convert;
use crate::dataset::ImuRecord;

/// Fewest corners for a PnP pose the checks use.
pub const MIN_PNP_CORNERS: usize = 8;
/// Widest offset searched, s (and at most a quarter of the shared time).
pub const MAX_SEARCH_S: f64 = 2.0;
/// Coarse search step, s.
const COARSE_STEP_S: f64 = 0.005;
/// Fine search step around the coarse peak, s.
const FINE_STEP_S: f64 = 0.0002;
/// A peak correlation below this is no answer.
pub const MIN_CORRELATION: f64 = 0.5;
/// Fewest increments correlated.
const MIN_INCREMENTS: usize = 20;
/// Least rms rate per axis the recording guide asks for, deg/s (0.1 rad/s).
pub const MIN_RMS_RATE_DEG_S: f64 = 5.7;
/// Least second / first eigenvalue of the rate scatter (the rotation initialisation's).
pub const MIN_SECOND_AXIS_RATIO: f64 = 0.02;

/// A sensor pose at a stamp (`T_odom_S`, or the camera in the target `T_T_C`).
#[derive(Debug, Clone, Copy)]
pub struct StampedPose {
    /// Sensor stamp, ns.
    pub stamp_ns: u64,
    /// The pose.
    pub pose: Isometry3<f64>,
}

/// The gyro as a function of IMU time: samples and their running integral.
pub struct Gyro<'a> {
    /// The samples.
    pub imu: &'a [ImuRecord],
    /// Sample times, s after the first.
    pub t: Vec<f64>,
    /// `integral of w dt` up to each sample (trapezoid), rad.
    integral: Vec<Vector3<f64>>,
}

impl<'a> Gyro<'a> {
    /// Over the IMU samples (at least two).
    pub fn new(imu: &'a [ImuRecord]) -> Self {
        let t: Vec<f64> = imu
            .iter()
            .map(|r| since(imu[0].stamp_ns, r.stamp_ns))
            .collect();
        let mut integral = vec![Vector3::zeros(); imu.len()];
        for i in 1..imu.len() {
            integral[i] =
                integral[i - 1] + (imu[i].gyro + imu[i - 1].gyro) * 0.5 * (t[i] - t[i - 1]);
        }
        Self { imu, t, integral }
    }

    /// Seconds of `stamp_ns` after the first IMU sample.
    pub fn time_of(&self, stamp_ns: u64) -> f64 {
        since(self.imu[0].stamp_ns, stamp_ns)
    }

    /// The integral at `t`, `None` outside the samples.
    fn integral_at(&self, t: f64) -> Option<Vector3<f64>> {
        if t < 0.0 || t > *self.t.last()? {
            return None;
        }
        let i = self
            .t
            .partition_point(|&x| x <= t)
            .clamp(1, self.t.len() - 1);
        let f = (t - self.t[i - 1]) / (self.t[i] - self.t[i - 1]);
        Some(self.integral[i - 1] + (self.integral[i] - self.integral[i - 1]) * f)
    }

    /// The mean rate over `[a, b]`, rad/s.
    pub fn mean_rate(&self, a: f64, b: f64) -> Option<Vector3<f64>> {
        Some((self.integral_at(b)? - self.integral_at(a)?) / (b - a))
    }
}

/// `b - a` in seconds.
fn since(a_ns: u64, b_ns: u64) -> f64 {
    (i128::from(b_ns) - i128::from(a_ns)) as f64 * 1e-9
}

/// PnP pose of the camera in the target for every image with enough corners.
pub fn camera_poses(camera: &CameraData) -> Vec<StampedPose> {
    camera
        .frames
        .par_iter()
        .filter(|f| f.corners.len() >= MIN_PNP_CORNERS)
        .filter_map(|f| {
            let pnp = pnp_of(&camera.camera, f).ok()?;
            Some(StampedPose {
                stamp_ns: f.stamp_ns,
                pose: convert::isometry(&pnp.t_cam_target).inverse(),
            })
        })
        .collect()
}

/// The pose0 records as poses.
pub fn pose0_poses(data: &SensorData) -> Vec<StampedPose> {
    data.pose0.as_deref().map_or_else(Vec::new, |records| {
        records
            .iter()
            .map(|r| StampedPose {
                stamp_ns: r.stamp_ns,
                pose: Isometry3::from_parts(r.position.into(), r.rotation),
            })
            .collect()
    })
}

/// One increment: its interval in IMU seconds (before the offset) and the body rotation
/// vector over it.
#[derive(Debug, Clone, Copy)]
pub struct Increment {
    /// Start, s (IMU time axis, sensor clock).
    pub a: f64,
    /// End, s.
    pub b: f64,
    /// `Log(R_a^T R_b)`, rad, in the sensor frame.
    pub rotation: Vector3<f64>,
}

/// Increments between consecutive poses no more than 3 median intervals apart.
pub fn increments(gyro: &Gyro, poses: &[StampedPose]) -> Vec<Increment> {
    let mut dts: Vec<u64> = poses
        .windows(2)
        .map(|w| w[1].stamp_ns - w[0].stamp_ns)
        .collect();
    dts.sort_unstable();
    let Some(&median) = dts.get(dts.len() / 2) else {
        return Vec::new();
    };
    poses
        .windows(2)
        .filter(|w| w[1].stamp_ns - w[0].stamp_ns <= 3 * median)
        .map(|w| Increment {
            a: gyro.time_of(w[0].stamp_ns),
            b: gyro.time_of(w[1].stamp_ns),
            rotation: (w[0].pose.rotation.inverse() * w[1].pose.rotation).scaled_axis(),
        })
        .collect()
}

/// Pearson correlation of `|rotation| / dt` with the gyro's mean rate over the shifted
/// intervals, and the number of increments inside the IMU's span.
fn correlation(gyro: &Gyro, incs: &[Increment], shift: f64) -> (f64, usize) {
    let pairs: Vec<(f64, f64)> = incs
        .iter()
        .filter_map(|inc| {
            let g = gyro.mean_rate(inc.a + shift, inc.b + shift)?;
            Some((inc.rotation.norm() / (inc.b - inc.a), g.norm()))
        })
        .collect();
    let n = pairs.len() as f64;
    if pairs.len() < MIN_INCREMENTS {
        return (0.0, pairs.len());
    }
    let (mx, my) = pairs
        .iter()
        .fold((0.0, 0.0), |(x, y), p| (x + p.0 / n, y + p.1 / n));
    let (mut sxy, mut sxx, mut syy) = (0.0, 0.0, 0.0);
    for (x, y) in &pairs {
        sxy += (x - mx) * (y - my);
        sxx += (x - mx) * (x - mx);
        syy += (y - my) * (y - my);
    }
    let r = if sxx > 0.0 && syy > 0.0 {
        sxy / (sxx * syy).sqrt()
    } else {
        0.0
    };
    (r, pairs.len())
}

/// The best shift on a grid `centre +- half` with `step`: (shift, correlation, increments).
fn search(gyro: &Gyro, incs: &[Increment], centre: f64, half: f64, step: f64) -> (f64, f64, usize) {
    let n = (half / step).round() as i64;
    (-n..=n)
        .into_par_iter()
        .map(|i| {
            let shift = centre + i as f64 * step;
            let (r, used) = correlation(gyro, incs, shift);
            (shift, r, used)
        })
        .reduce(
            || (0.0, f64::NEG_INFINITY, 0),
            |a, b| if b.1 > a.1 { b } else { a },
        )
}

/// The offset of one sensor: a finding, and the offset when the peak is clear.
pub fn time_offset(stream: &str, gyro: &Gyro, poses: &[StampedPose]) -> (Finding, Option<f64>) {
    let incs = increments(gyro, poses);
    let span = incs.last().map_or(0.0, |l| l.b) - incs.first().map_or(0.0, |f| f.a);
    let half = MAX_SEARCH_S.min(0.25 * span).max(COARSE_STEP_S);
    let (coarse, _, _) = search(gyro, &incs, 0.0, half, COARSE_STEP_S);
    let (shift, peak, used) = search(gyro, &incs, coarse, COARSE_STEP_S, FINE_STEP_S);
    if peak < MIN_CORRELATION || used < MIN_INCREMENTS {
        let finding = Finding::TimeOffsetUnclear {
            stream: stream.to_string(),
            correlation: peak.max(0.0),
        };
        return (finding, None);
    }
    let finding = Finding::TimeOffset {
        stream: stream.to_string(),
        offset_s: shift,
        correlation: peak,
        correlation_at_zero: correlation(gyro, &incs, 0.0).0,
        increments: used,
    };
    (finding, Some(shift))
}

/// The excitation per IMU axis over the IMU samples.
pub fn excitation(imu: &[ImuRecord]) -> Option<Finding> {
    if imu.len() < 2 {
        return None;
    }
    let mut angle = Vector3::zeros();
    let mut square = Vector3::zeros();
    let mut scatter = Matrix3::zeros();
    let mut total = 0.0;
    for w in imu.windows(2) {
        let dt = since(w[0].stamp_ns, w[1].stamp_ns);
        let rate = w[0].gyro;
        angle += rate.abs() * dt;
        square += rate.component_mul(&rate) * dt;
        scatter += rate * rate.transpose() * dt;
        total += dt;
    }
    let mut eigen: Vec<f64> = scatter.symmetric_eigenvalues().iter().copied().collect();
    eigen.sort_by(|a, b| b.total_cmp(a));
    let ratio = if eigen[0] > 0.0 {
        eigen[1] / eigen[0]
    } else {
        0.0
    };
    let rms = (square / total).map(f64::sqrt).map(f64::to_degrees);
    let low = rms.min() < MIN_RMS_RATE_DEG_S || ratio < MIN_SECOND_AXIS_RATIO;
    Some(Finding::Excitation {
        angle_deg: angle.map(f64::to_degrees).into(),
        rms_deg_s: rms.into(),
        second_axis_ratio: ratio,
        low,
    })
}

/// The rotation `R_C_I` that best maps the gyro's mean rates onto the sensor's increment
/// rates (Kabsch), given the offset.
pub fn rotation_sensor_imu(
    gyro: &Gyro,
    incs: &[Increment],
    offset: f64,
) -> Option<UnitQuaternion<f64>> {
    let mut h = Matrix3::zeros();
    let mut used = 0;
    for inc in incs {
        if let Some(g) = gyro.mean_rate(inc.a + offset, inc.b + offset) {
            h += g * (inc.rotation / (inc.b - inc.a)).transpose();
            used += 1;
        }
    }
    if used < MIN_INCREMENTS {
        return None;
    }
    let svd = h.svd(true, true);
    let (u, v_t) = (svd.u?, svd.v_t?);
    let mut d = Matrix3::identity();
    if (v_t.transpose() * u.transpose()).determinant() < 0.0 {
        d[(2, 2)] = -1.0;
    }
    let r = v_t.transpose() * d * u.transpose();
    Some(UnitQuaternion::from_matrix(&r))
}

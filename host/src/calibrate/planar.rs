//! Planar motion: a vehicle driving on the ground turns about one axis (its vertical) only.
//!
//! What that leaves observable, and how each part is found here (dissertation ch. 3.5 notes
//! the degeneracy; VINS-on-wheels and LI-Init treat it alike):
//! - The hand-eye rotation (eq. 3.3-3.5) fixes only the alignment of the two rotation axes
//!   (two of three DoF): rotation increments about one axis say nothing about the rotation
//!   about it. [`detect`] finds the axis in both frames and that alignment.
//! - The rotation about the axis ("yaw" of the extrinsic) shows in the translation. For a
//!   vehicle that moves along its own forward axis, [`travel::travel_yaw`] takes the
//!   direction of travel in the sensor's frame onto the one the IMU sees. Otherwise the IMU's
//!   accelerations, rotated into the odometry frame, must integrate to the odometry's
//!   translations: [`fit_yaw`] scans it with the dynamic initialisation's linear alignment
//!   ([`super::dynamic_init`]) as the cost.
//! - The lever arm perpendicular to the axis shows through the yaw rate (`w x p`); the
//!   component along the axis (the height, for a level IMU) moves every pose of the drive
//!   alike and is not observable. The filter holds it at its prior (a Schmidt direction,
//!   `Ekf::hold_translation_axis`) instead of fitting it to suspension motion and model
//!   error, and the result says so.

use std::f64::consts::PI;

use msreg_estimator::{InitialState, Scalar};
use nalgebra::{Matrix3, SymmetricEigen, UnitQuaternion, Vector3};

use super::convert;
use super::dynamic_init::{self, DynamicInitError, DynamicInitInput, DynamicInitOptions, Window};
use super::gyro_bias::{self, GyroBiasEstimate};
use super::init::{self, RotationIncrement, RotationInit};
use crate::dataset::{ImuRecord, PoseRecord};

pub mod heading;
pub mod tilt;
pub mod travel;

/// Largest second / first eigenvalue of the IMU rotation scatter treated as planar motion:
/// the rms rate about every other axis is under a third (`sqrt 0.1`) of the rate about the
/// main one. Hand-held calibration motion excites the second axis well above it; a car's
/// suspension roll and pitch (a few deg/s against tens of deg/s of yaw rate) stay below.
pub const PLANAR_AXIS_RATIO: f64 = 0.1;

/// A rotation increment of the IMU and of the sensor over the same interval, as rotation
/// vectors `(r_I, r_S)`.
pub type RotationPair = (Vector3<f64>, Vector3<f64>);

/// Prior 1-sigma of the rotation about the axis when nothing tells it (no yaw fit, or an
/// odometry whose rotation is not the body's), rad: a quarter turn.
pub const UNKNOWN_YAW_SIGMA_RAD: f64 = 0.5 * PI;

/// Fewest rotation increments to call the motion planar.
const MIN_PAIRS: usize = 20;

/// Rotation about one axis only.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlanarMotion {
    /// Unit rotation axis in the IMU frame.
    pub axis_imu: Vector3<f64>,
    /// The same axis in the sensor frame (sign-consistent with `axis_imu`).
    pub axis_sensor: Vector3<f64>,
    /// Second / first eigenvalue of the IMU rotation scatter.
    pub axis_ratio: f64,
    /// The shortest rotation `R_I_S` taking `axis_sensor` to `axis_imu`: right up to a
    /// rotation about `axis_imu`.
    pub alignment: UnitQuaternion<f64>,
    /// Rotation increments used.
    pub pairs: usize,
}

/// Planar motion from rotation-increment pairs `(r_I, r_S)` (rotation vectors of the IMU and
/// the sensor over the same intervals, [`super::init::rotation_pairs`]); `None` when the
/// motion turns about more than one axis or there are too few pairs.
pub fn detect(pairs: &[RotationPair]) -> Option<PlanarMotion> {
    if pairs.len() < MIN_PAIRS {
        return None;
    }
    let scatter = |f: fn(&RotationPair) -> Vector3<f64>| {
        pairs
            .iter()
            .map(|p| {
                let r = f(p);
                r * r.transpose()
            })
            .sum::<Matrix3<f64>>()
    };
    let (ratio, axis_imu) = main_axis(&scatter(|p| p.0))?;
    if ratio >= PLANAR_AXIS_RATIO {
        return None;
    }
    let (_, mut axis_sensor) = main_axis(&scatter(|p| p.1))?;
    let agreement: f64 = pairs
        .iter()
        .map(|(ri, rs)| ri.dot(&axis_imu) * rs.dot(&axis_sensor))
        .sum();
    if agreement < 0.0 {
        axis_sensor = -axis_sensor;
    }
    let alignment = rotation_between(&axis_sensor, &axis_imu);
    Some(PlanarMotion {
        axis_imu,
        axis_sensor,
        axis_ratio: ratio,
        alignment,
        pairs: pairs.len(),
    })
}

/// The shortest rotation taking unit `from` onto unit `to` (a half turn about an axis
/// across them when they are opposite).
fn rotation_between(from: &Vector3<f64>, to: &Vector3<f64>) -> UnitQuaternion<f64> {
    UnitQuaternion::rotation_between(from, to)
        .unwrap_or_else(|| UnitQuaternion::from_scaled_axis(orthogonal_unit(to) * PI))
}

/// (second / first eigenvalue, unit eigenvector of the first) of a scatter matrix.
fn main_axis(scatter: &Matrix3<f64>) -> Option<(f64, Vector3<f64>)> {
    let eig = SymmetricEigen::new(*scatter);
    let mut order = [0usize, 1, 2];
    order.sort_by(|&a, &b| eig.eigenvalues[b].total_cmp(&eig.eigenvalues[a]));
    let first = eig.eigenvalues[order[0]];
    if first.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
        return None;
    }
    let axis = eig.eigenvectors.column(order[0]).normalize();
    Some((eig.eigenvalues[order[1]].max(0.0) / first, axis))
}

/// A unit vector orthogonal to `v`.
fn orthogonal_unit(v: &Vector3<f64>) -> Vector3<f64> {
    let helper = if v.x.abs() < 0.9 {
        Vector3::x()
    } else {
        Vector3::y()
    };
    v.cross(&helper).normalize()
}

/// The rotation about the axis found from the translations.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct YawFit {
    /// `R_I_S`: the alignment turned by the best angle about the IMU axis.
    pub rotation: UnitQuaternion<f64>,
    /// The angle about `axis_imu` added to the alignment, rad.
    pub angle_rad: f64,
    /// 1-sigma of the angle, rad.
    pub sigma_rad: f64,
    /// How it was found.
    pub method: YawMethod,
}

/// How the rotation about the axis was found.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum YawMethod {
    /// From the direction of travel ([`travel::travel_yaw`]); the sigma is the heading fit's
    /// jackknife over its windows.
    Travel {
        /// Rms sideways over rms forward displacement of the odometry's increments.
        side_ratio: f64,
        /// Windows of the IMU-side fit.
        windows: usize,
    },
    /// From the scan of the alignment cost ([`fit_yaw`]); the sigma is the cost's curvature.
    Scan {
        /// Median cost over the scan / best cost: about 1 when the translations do not tell
        /// the angle (no acceleration or turn in the window).
        contrast: f64,
    },
}

impl From<travel::TravelYaw> for YawFit {
    fn from(t: travel::TravelYaw) -> Self {
        Self {
            rotation: t.rotation,
            angle_rad: t.angle_rad,
            sigma_rad: t.heading.sigma_rad,
            method: YawMethod::Travel {
                side_ratio: t.travel.side_ratio,
                windows: t.heading.windows,
            },
        }
    }
}

/// Why the angle about the axis could not be found.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum YawFitError {
    /// The alignment window could not be built or solved.
    #[error("{0}")]
    Alignment(#[from] DynamicInitError),
    /// The cost barely changes with the angle: the window neither accelerates nor turns.
    #[error(
        "the translations do not determine the rotation about the axis (contrast {contrast:.2})"
    )]
    Flat {
        /// Median / best cost of the scan.
        contrast: f64,
    },
}

/// Angles tried by the scan before the refinement.
const SCAN_STEPS: usize = 24;
/// A scan whose median cost is less than this many times the best is flat.
const MIN_CONTRAST: f64 = 3.0;
/// Golden-section steps of the refinement (the bracket shrinks by 0.618 each).
const REFINE_STEPS: usize = 20;

/// The rotation about `planar.axis_imu` that makes the IMU's accelerations agree with the
/// odometry's translations best: a scan over the full turn, then a golden-section search
/// around the best angle. `input.r_i_s` is ignored (the alignment is used).
pub fn fit_yaw(
    input: &DynamicInitInput<'_>,
    options: &DynamicInitOptions,
    planar: &PlanarMotion,
) -> Result<YawFit, YawFitError> {
    let window = Window::new(input, options)?;
    let rotation_at =
        |angle: f64| UnitQuaternion::from_scaled_axis(planar.axis_imu * angle) * planar.alignment;
    // An angle at which the alignment fails (e.g. gravity far from 9.81) costs infinity.
    let cost = |angle: f64| -> (f64, f64) {
        let r = rotation_at(angle).to_rotation_matrix().into_inner();
        match dynamic_init::align(&window, &r, options, false) {
            Ok(aligned) => {
                let s = &aligned.solution;
                (s.ssr.iter().sum(), s.redundancy.iter().sum())
            }
            Err(_) => (f64::INFINITY, 0.0),
        }
    };
    let step = 2.0 * PI / SCAN_STEPS as f64;
    let scan: Vec<(f64, f64)> = (0..SCAN_STEPS)
        .map(|k| -PI + k as f64 * step)
        .map(|angle| (angle, cost(angle).0))
        .collect();
    let (best, best_cost) = scan
        .iter()
        .copied()
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .unwrap_or((0.0, f64::INFINITY));
    let mut costs: Vec<f64> = scan.iter().map(|s| s.1).collect();
    costs.sort_by(f64::total_cmp);
    let contrast = costs[costs.len() / 2] / best_cost.max(f64::MIN_POSITIVE);
    if !best_cost.is_finite() || contrast.is_nan() || contrast < MIN_CONTRAST {
        return Err(YawFitError::Flat { contrast });
    }
    let angle = golden_section(|a| cost(a).0, best - step, best + step);
    Ok(YawFit {
        rotation: rotation_at(angle),
        angle_rad: angle,
        sigma_rad: curvature_sigma(&cost, angle),
        method: YawMethod::Scan { contrast },
    })
}

/// Minimum of a unimodal `f` on `[lo, hi]` (golden-section search, `REFINE_STEPS` steps).
pub(crate) fn golden_section(f: impl Fn(f64) -> f64, mut lo: f64, mut hi: f64) -> f64 {
    let ratio = (5f64.sqrt() - 1.0) / 2.0;
    let (mut a, mut b) = (hi - ratio * (hi - lo), lo + ratio * (hi - lo));
    let (mut fa, mut fb) = (f(a), f(b));
    for _ in 0..REFINE_STEPS {
        if fa < fb {
            hi = b;
            (b, fb) = (a, fa);
            a = hi - ratio * (hi - lo);
            fa = f(a);
        } else {
            lo = a;
            (a, fa) = (b, fb);
            b = lo + ratio * (hi - lo);
            fb = f(b);
        }
    }
    0.5 * (lo + hi)
}

/// 1-sigma of the angle at the minimum: the cost is a sum of squared residuals over the
/// noise the alignment assumed, so `sigma^2 = 2 s^2 / cost''` with `s^2 = cost / redundancy`
/// the residual variance factor.
fn curvature_sigma(cost: &impl Fn(f64) -> (f64, f64), angle: f64) -> f64 {
    let h = 0.2f64.to_radians();
    let (c0, redundancy) = cost(angle);
    let (cp, cm) = (cost(angle + h).0, cost(angle - h).0);
    let second = ((cp - 2.0 * c0 + cm) / (h * h)).max(f64::MIN_POSITIVE);
    let variance_factor = (c0 / redundancy.max(1.0)).max(1.0);
    (2.0 * variance_factor / second).sqrt()
}

/// The planar start of an IMU pipeline: the motion, the gyro bias refitted along the axis
/// alignment (without a standstill), and the rotation about the axis.
#[derive(Debug, Clone, PartialEq)]
pub struct PlanarStart {
    /// The axis in both frames.
    pub motion: PlanarMotion,
    /// The gyro bias fitted through the alignment, when there was no standstill.
    pub gyro_bias: Option<GyroBiasEstimate>,
    /// The rotation about the axis, or why the translations did not tell it.
    pub yaw: Result<YawFit, YawFitError>,
}

/// The window the yaw scan aligns over, s: longer than the dynamic initialisation's, since
/// a vehicle accelerates and turns less often than a hand-held rig.
const YAW_WINDOW_S: f64 = 15.0;
/// Smallest prior 1-sigma of the rotation after a yaw fit, deg: the scan's curvature sigma
/// ignores the drift of the odometry's absolute orientation over the window, and its
/// errors on the simulated drives reach 21 deg (docs/planar.md). The direction of travel
/// is within 2 deg there, and keeps the same floor: a wide prior costs it nothing.
const MIN_YAW_PRIOR_SIGMA_DEG: f64 = 10.0;
/// Shortest pose interval of the yaw scan, s: 0.2 s keeps the alignment small (75
/// intervals over the window) while each interval still integrates a measurable turn.
const YAW_MIN_INTERVAL_S: f64 = 0.2;

impl PlanarStart {
    /// `R_I_S` to start the filter from: the yaw fit, else the bare alignment.
    pub fn rotation(&self) -> UnitQuaternion<f64> {
        self.yaw
            .as_ref()
            .map_or(self.motion.alignment, |y| y.rotation)
    }

    /// Prior 1-sigma of the extrinsic rotation (isotropic): `default`, widened to three
    /// sigma of the yaw fit and at least [`MIN_YAW_PRIOR_SIGMA_DEG`]; a quarter turn when
    /// the yaw is unknown.
    pub fn rotation_sigma(&self, default: f64) -> f64 {
        self.yaw.as_ref().map_or(UNKNOWN_YAW_SIGMA_RAD, |y| {
            default
                .max(3.0 * y.sigma_rad)
                .max(MIN_YAW_PRIOR_SIGMA_DEG.to_radians())
        })
    }

    /// The rotation initialisation the pipelines start from.
    pub fn rotation_init(&self) -> RotationInit {
        RotationInit {
            rotation: self.rotation(),
            pairs: self.motion.pairs,
            axis_ratio: self.motion.axis_ratio,
        }
    }

    /// The prior with the lever arm's component along the axis at its prior mean (zero):
    /// a moving start's alignment guesses it from suspension motion, which the filter will
    /// not correct (it holds that direction).
    pub fn with_lever_arm_prior<T: Scalar>(
        &self,
        mut initial: InitialState<T, 1>,
    ) -> InitialState<T, 1> {
        let axis = convert::vec3::<T>(&self.motion.axis_imu);
        let t = &mut initial.sensors[0].state.extrinsic.translation;
        *t -= axis * axis.dot(t);
        initial
    }

    /// The report's words for the start.
    pub fn describe(&self) -> String {
        let a = self.motion.axis_imu;
        let yaw = match &self.yaw {
            Ok(y) => {
                let how = match y.method {
                    YawMethod::Travel {
                        side_ratio,
                        windows,
                    } => format!(
                        "the direction of travel (sideways share {side_ratio:.3}, {windows} windows)"
                    ),
                    YawMethod::Scan { contrast } => {
                        format!("the translations (scan contrast {contrast:.1})")
                    }
                };
                format!(
                    "rotation about it from {how}: {:.2} deg from the axis alignment (sigma {:.3} deg)",
                    y.angle_rad.to_degrees(),
                    y.sigma_rad.to_degrees(),
                )
            }
            Err(e) => format!("rotation about it unknown ({e}): started wide open"),
        };
        format!(
            "planar motion: rotation about [{:.3}, {:.3}, {:.3}] (IMU frame) only, axis ratio {:.4}; {yaw}",
            a.x, a.y, a.z, self.motion.axis_ratio
        )
    }
}

/// Detects planar motion in `pairs` (the rotation `increments` integrated at gyro bias
/// `bias`: the standstill's mean or a motion fit) and, when it is, fits what the planar case
/// needs (see the module docs). Without a standstill the bias is refitted through the
/// yaw-fitted rotation, which planar motion leaves well defined where the full hand-eye
/// rotation is not, and the axis and yaw are found again with it.
pub fn planar_start(
    (imu, poses): (&[ImuRecord], &[PoseRecord]),
    (increments, pairs): (&[RotationIncrement], &[RotationPair]),
    (bias, at_rest): (Vector3<f64>, bool),
    accel_noise_density: f64,
) -> Option<PlanarStart> {
    let mut motion = detect(pairs)?;
    let options = DynamicInitOptions {
        window_s: YAW_WINDOW_S,
        min_interval_s: YAW_MIN_INTERVAL_S,
        accel_noise_density,
        ..DynamicInitOptions::default()
    };
    let yaw_at = |motion: &PlanarMotion, gyro_bias: Vector3<f64>| {
        if let Some(t) = travel::travel_yaw(imu, poses, &gyro_bias, motion) {
            return Ok(YawFit::from(t));
        }
        let input = DynamicInitInput {
            imu,
            poses,
            r_i_s: motion.alignment,
            gyro_bias,
            time_offset_s: 0.0,
        };
        fit_yaw(&input, &options, motion)
    };
    let mut yaw = yaw_at(&motion, bias);
    let mut fitted = None;
    if !at_rest {
        // The bias seen through the whole rotation (the bare alignment would turn the
        // small rotations across the axis the wrong way), then the axis and yaw again.
        let rotation = yaw.as_ref().map_or(motion.alignment, |y| y.rotation);
        if let Some(fit) = gyro_bias::estimate_gyro_bias(imu, increments, &rotation, &bias) {
            let pairs = init::rotation_pairs(imu, increments.iter().copied(), &fit.bias);
            motion = detect(&pairs).unwrap_or(motion);
            yaw = yaw_at(&motion, fit.bias);
            fitted = Some(fit);
        }
    }
    Some(PlanarStart {
        yaw,
        motion,
        gyro_bias: fitted,
    })
}

#[cfg(test)]
mod tests;

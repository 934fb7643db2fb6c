//! The LiDAR-IMU pipeline's moving start (issue 11): a recording without a standstill.
//!
//! The filter then needs gravity, velocity and the biases from the motion
//! ([`crate::calibrate::dynamic_init`], shared with pose-IMU and camera-IMU), which needs
//! an odometry of the LiDAR on the IMU's clock. Three steps, all before the filter:
//!
//! 1. **Time offset** ([`time_offset_from_rotations`]): the raw-scan NDT rotation increments
//!    of the hand-eye initialisation, paired with the gyro integrated over the same interval
//!    shifted by `tau`, fit the hand-eye rotation best at the true offset (the residual of a
//!    wrong `tau` is the change of the angular velocity over `tau`). A grid over the prior's
//!    +-3 sigma, then a golden-section search; its sigma from the cost's curvature and
//!    residual scatter. Without it the odometry is `t_d` (up to 20 ms) away from the IMU:
//!    at 2.7 rad/s that turns the odometry by 3 deg against the IMU, and gravity with it
//!    (docs/camera_imu.md, "Moving starts", had the same with the camera).
//! 2. **Odometry** ([`odometry`]): the scans of the initialisation window deskewed in
//!    *rotation* with the gyro (hand-eye rotation, fitted bias, the offset of step 1),
//!    matched scan to scan by NDT, and chained into poses at each scan's last firing. A raw
//!    scan is not a snapshot: during a 0.1 s sweep the sensor turns up to 15 deg, and the
//!    raw increment between two such scans is neither the motion between their mid-sweep
//!    instants nor rigid (under a turn about the spin axis at `w` the scan is the scene
//!    compressed in azimuth by `W / (W + w)`, `W` the spin rate, and consecutive scans see
//!    the same wall at phases `w dt / (W + w)` apart, so the increment spans a shorter
//!    interval than its stamps say: 4 % at 2.7 rad/s). With the rotation removed, what
//!    remains is the translation's distortion, the same in consecutive scans as long as the
//!    velocity is (the increment then refers exactly to the reference stamps). The poses'
//!    orientations are the gyro's (rotated by the hand-eye rotation), so the chain carries
//!    no NDT rotation drift; the translations are NDT's. The deskewed increments have exact
//!    stamps (the last firings), so step 1 is repeated on them and the odometry rebuilt at
//!    the new offset until it settles (the raw increments' offset is off by several ms:
//!    where in the sweep a raw match refers to depends on the scene).
//! 3. **Alignment** (`crate::calibrate::driver::moving_start` on that odometry at that offset), and the
//!    filter starts from it with its time offset at the estimate (and the prior's sigma:
//!    the estimate's own sigma is optimistic, docs/lidar_imu.md "Moving start"). The
//!    filter's measurement floor then anneals no faster than the IMU velocity's sigma
//!    (`LidarFeed::annealed_by_imu_state`): at peak motion the extrinsic sigma alone falls
//!    within a second, before the aligned IMU state has settled, and the filter diverged
//!    on some seeds (docs/lidar_imu.md, "Moving start: the floor and the IMU state").

use crate::calibrate::InputError;
use msreg_estimator::Scalar;
use msreg_estimator::{FilterConfig, PoseImuEkf, SOLE_SENSOR};
use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};

use super::{last_firing_ns, load, LidarImuOptions};
use crate::calibrate::convert;
use crate::calibrate::driver::{
    describe_moving_start, initial_state, moving_start, with_gyro_bias, with_moving_start,
    FilterStart, MovingStart, MovingStartFailure, HAND_EYE_MIN_PAIRS,
};
use crate::calibrate::dynamic_init::{DynamicInitOptions, FilterPrior};
use crate::calibrate::gyro_bias::{hand_eye_with_gyro_bias, GyroBiasEstimate};
use crate::calibrate::init::{self, RotationIncrement, RotationInit};
use crate::calibrate::planar::golden_section;
use crate::dataset::{ImuNoiseYaml, ImuRecord, PoseRecord};
use crate::lidar::{deskew_scan, PoseBuffer, ScanSource};
use crate::ndt::{align, NdtTarget};
use crate::pointcloud::voxel_downsample;

/// The time offset of the LiDAR from its rotation increments.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TimeOffsetEstimate {
    /// `t_d`, s: a scan stamped `t_L` was taken at IMU time `t_L + t_d`.
    pub offset_s: f64,
    /// 1-sigma from the cost's curvature and the residual scatter (increments as
    /// independent), s.
    pub sigma_s: f64,
    /// Increments used.
    pub pairs: usize,
}

/// Grid step of the time-offset search, s.
const GRID_STEP_S: f64 = 1e-3;
/// Step of the finite-difference curvature of the cost, s.
const CURVATURE_STEP_S: f64 = 0.5e-3;

/// Shifts a LiDAR stamp by `tau_ns` onto the IMU clock (`None` below zero).
fn shifted(stamp_ns: u64, tau_ns: i64) -> Option<u64> {
    u64::try_from(i128::from(stamp_ns) + i128::from(tau_ns)).ok()
}

/// Sum over the increments of `|r_I(tau) - R r_L|^2` at the hand-eye rotation `R` that fits
/// them at `tau`; `None` when the hand-eye fails or an increment leaves the IMU data.
fn hand_eye_cost(
    imu: &[ImuRecord],
    increments: &[RotationIncrement],
    gyro_bias: &Vector3<f64>,
    tau_s: f64,
) -> Option<f64> {
    let tau_ns = (tau_s * 1e9).round() as i64;
    let moved: Vec<RotationIncrement> = increments
        .iter()
        .map(|(a, b, q)| Some((shifted(*a, tau_ns)?, shifted(*b, tau_ns)?, *q)))
        .collect::<Option<_>>()?;
    let pairs = init::rotation_pairs(imu, moved, gyro_bias);
    if pairs.len() != increments.len() {
        return None;
    }
    let rotation = init::hand_eye_from_pairs(pairs.iter().copied(), HAND_EYE_MIN_PAIRS)
        .ok()?
        .rotation;
    Some(
        pairs
            .iter()
            .map(|(ri, rl)| (ri - rotation * rl).norm_squared())
            .sum(),
    )
}

/// The time offset in `[-range_s, range_s]` that best aligns the rotation `increments`
/// (LiDAR clock) with the gyro (minus `gyro_bias`); only increments inside the IMU data for
/// every offset in the range take part. `None` with too few of them or no minimum inside.
pub fn time_offset_from_rotations(
    imu: &[ImuRecord],
    increments: &[RotationIncrement],
    gyro_bias: &Vector3<f64>,
    range_s: f64,
) -> Option<TimeOffsetEstimate> {
    let (first, last) = (imu.first()?.stamp_ns, imu.last()?.stamp_ns);
    let margin = (range_s * 1e9).ceil() as u64 + 1;
    let inside: Vec<RotationIncrement> = increments
        .iter()
        .copied()
        .filter(|(a, b, _)| *a >= first.saturating_add(margin) && b.saturating_add(margin) <= last)
        .collect();
    if inside.len() < HAND_EYE_MIN_PAIRS {
        return None;
    }
    let cost = |tau: f64| hand_eye_cost(imu, &inside, gyro_bias, tau).unwrap_or(f64::INFINITY);
    let steps = (range_s / GRID_STEP_S).floor() as i64;
    let (best, best_cost) = (-steps..=steps)
        .map(|k| {
            let tau = k as f64 * GRID_STEP_S;
            (tau, cost(tau))
        })
        .min_by(|a, b| a.1.total_cmp(&b.1))?;
    if !best_cost.is_finite() || best.abs() >= range_s - 0.5 * GRID_STEP_S {
        return None;
    }
    let offset_s = golden_section(cost, best - GRID_STEP_S, best + GRID_STEP_S);
    let h = CURVATURE_STEP_S;
    let c0 = cost(offset_s);
    let curvature = (cost(offset_s + h) - 2.0 * c0 + cost(offset_s - h)) / (h * h);
    // Three residual rows per increment; unknowns: the rotation (3) and the offset.
    let variance = c0 / (3 * inside.len()).saturating_sub(4).max(1) as f64;
    (curvature > 0.0 && c0.is_finite()).then(|| TimeOffsetEstimate {
        offset_s,
        sigma_s: (2.0 * variance / curvature).sqrt(),
        pairs: inside.len(),
    })
}

/// Fewest poses (minus one) of the odometry chain that is preferred (the first one this
/// long); shorter chains are used only when none is (the longest then).
const PREFERRED_CHAIN: usize = 40;

/// `R_G_I` from the gyro alone (minus `gyro_bias`) at every IMU sample up to `until_ns`,
/// as poses without translation (the deskew's buffer).
fn gyro_orientations(imu: &[ImuRecord], gyro_bias: &Vector3<f64>, until_ns: u64) -> PoseBuffer {
    let mut buffer = PoseBuffer::new(u64::MAX);
    let mut q = UnitQuaternion::identity();
    let Some(first) = imu.first() else {
        return buffer;
    };
    buffer.push(first.stamp_ns, Isometry3::identity());
    for w in imu.windows(2) {
        let dt = w[1].stamp_ns.saturating_sub(w[0].stamp_ns) as f64 * 1e-9;
        let rate = 0.5 * (w[0].gyro + w[1].gyro) - gyro_bias;
        q *= UnitQuaternion::from_scaled_axis(rate * dt);
        buffer.push(
            w[1].stamp_ns,
            Isometry3::from_parts(Translation3::identity(), q),
        );
        if w[1].stamp_ns > until_ns {
            break;
        }
    }
    buffer
}

/// The LiDAR odometry of the initialisation window.
#[derive(Debug, Clone, Default)]
pub struct InitOdometry {
    /// `T_O_L` at each scan's last firing (LiDAR clock), one unbroken chain.
    pub poses: Vec<PoseRecord>,
    /// NDT's rotation of every match of the deskewed scans (all chains), stamped at the two
    /// scans' last firings (LiDAR clock).
    pub increments: Vec<RotationIncrement>,
}

/// The LiDAR odometry of the first `window_s` of IMU data, at each scan's last firing
/// (LiDAR clock): scans deskewed in rotation with the gyro, NDT translations, gyro
/// orientations (see the module docs). The first chain of more than 40 increments, else the
/// longest; a failed match breaks a chain.
pub fn odometry(
    imu: &[ImuRecord],
    scans: &dyn ScanSource,
    options: &LidarImuOptions,
    (r_i_l, gyro_bias, td_s): (&UnitQuaternion<f64>, &Vector3<f64>, f64),
    window_s: f64,
) -> Result<InitOdometry, InputError> {
    let (Some(first), Some(last)) = (imu.first(), imu.last()) else {
        return Ok(InitOdometry::default());
    };
    let until = first
        .stamp_ns
        .saturating_add((window_s * 1e9) as u64)
        .min(last.stamp_ns);
    let buffer = gyro_orientations(imu, gyro_bias, until.saturating_add(1_000_000_000));
    let td_ns = (td_s * 1e9).round() as i64;
    let t_i_l = Isometry3::from_parts(Translation3::identity(), *r_i_l);
    let orientation = |imu_ns: u64| -> Option<UnitQuaternion<f64>> {
        Some(r_i_l.inverse() * buffer.at(imu_ns)?.rotation * r_i_l)
    };
    let mut chains: Vec<Vec<PoseRecord>> = Vec::new();
    let mut increments = Vec::new();
    let mut previous: Option<(NdtTarget, UnitQuaternion<f64>, u64)> = None;
    for k in 0..scans.len() {
        let stamp = scans.stamp_ns(k);
        let Some(start) = shifted(stamp, td_ns) else {
            continue;
        };
        if start < first.stamp_ns {
            continue;
        }
        let Some(cloud) = load(scans, k)? else {
            previous = None;
            continue;
        };
        let ref_offset = last_firing_ns(&cloud);
        let Some(end) = shifted(stamp.saturating_add(ref_offset), td_ns) else {
            continue;
        };
        if end > until {
            break;
        }
        let (Some(rotation), Some(deskewed)) = (
            orientation(end),
            deskew_scan(&cloud, stamp, ref_offset, td_ns, &t_i_l, &buffer),
        ) else {
            previous = None;
            continue;
        };
        let points = voxel_downsample(&deskewed.cloud, options.voxel_m).positions();
        let target = (points.len() >= options.min_points)
            .then(|| NdtTarget::build(&points, &options.ndt).ok())
            .flatten();
        let ref_stamp = stamp.saturating_add(ref_offset);
        let step = previous
            .as_ref()
            .and_then(|(prev_target, prev_rotation, prev_stamp)| {
                let turn = prev_rotation.inverse() * rotation;
                let guess = Isometry3::from_parts(Translation3::identity(), turn);
                let r = align(prev_target, &points, &guess, &options.ndt).ok()?;
                (r.converged && r.fitness >= options.min_fitness && r.degenerate.is_none())
                    .then_some((*prev_stamp, r.t_target_source))
            });
        let pose = |position| PoseRecord {
            stamp_ns: ref_stamp,
            position,
            rotation,
        };
        match (step, chains.last_mut()) {
            (Some((prev_stamp, delta)), Some(chain)) => {
                increments.push((prev_stamp, ref_stamp, delta.rotation));
                let prev = chain.last().copied().unwrap_or(pose(Vector3::zeros()));
                chain.push(pose(
                    prev.position + prev.rotation * delta.translation.vector,
                ));
            }
            _ => chains.push(vec![pose(Vector3::zeros())]),
        }
        previous = target.map(|t| (t, rotation, ref_stamp));
    }
    let preferred = chains.iter().position(|c| c.len() > PREFERRED_CHAIN);
    let poses = match preferred {
        Some(i) => chains.swap_remove(i),
        None => chains.into_iter().max_by_key(Vec::len).unwrap_or_default(),
    };
    Ok(InitOdometry { poses, increments })
}

/// Rounds of (time offset at the current bias, hand-eye rotation and bias at that offset).
const OFFSET_ROUNDS: usize = 2;

/// The time offset of the raw `increments` within `+-range_s` and the hand-eye rotation
/// and gyro bias re-fitted with the increments moved onto the IMU clock by it (a wrong
/// offset skews both); the inputs unchanged when no offset is found.
fn at_time_offset(
    imu: &[ImuRecord],
    increments: &[RotationIncrement],
    (mut rotation, mut gyro_bias): (RotationInit, Option<GyroBiasEstimate>),
    range_s: f64,
) -> Alignment {
    let mut estimate = None;
    for _ in 0..OFFSET_ROUNDS {
        let bias = gyro_bias.map_or_else(Vector3::zeros, |g| g.bias);
        let Some(found) = time_offset_from_rotations(imu, increments, &bias, range_s) else {
            break;
        };
        estimate = Some(found);
        let tau_ns = (found.offset_s * 1e9).round() as i64;
        let moved: Vec<RotationIncrement> = increments
            .iter()
            .filter_map(|(a, b, q)| Some((shifted(*a, tau_ns)?, shifted(*b, tau_ns)?, *q)))
            .collect();
        let (refit, bias) = hand_eye_with_gyro_bias(imu, &moved, HAND_EYE_MIN_PAIRS);
        let Ok(refit) = refit else {
            break;
        };
        rotation = refit;
        gyro_bias = bias.or(gyro_bias);
    }
    (rotation, gyro_bias, estimate)
}

/// A hand-eye rotation, the gyro bias and the time offset (when estimated).
type Alignment = (
    RotationInit,
    Option<GyroBiasEstimate>,
    Option<TimeOffsetEstimate>,
);

/// Deskewed passes at most (the first at the raw scans' estimates).
const MAX_DESKEW_PASSES: usize = 4;
/// A pass whose time offset moved less than this is the last, s.
const OFFSET_SETTLED_S: f64 = 0.02e-3;

/// The odometry of the deskewed scans at the raw scans' estimates, then the time offset,
/// hand-eye rotation and bias again from its increments and the odometry once more at
/// those, until the offset settles. A deskewed scan is the snapshot at its last firing,
/// so its increments have exact stamps, while a raw one's effective time depends on where
/// the scene constrains it (raw: several ms off on the simulator). Deskewing with an
/// offset `e` off still gives the snapshot at the true time when the angular velocity is
/// constant over the sweep; what is left scales with `e` (the angular acceleration times
/// `e`), so each pass shrinks the error (seed 7: -4.4 ms raw, -0.76 ms after one pass).
fn deskewed_start(
    (imu, scans): (&[ImuRecord], &dyn ScanSource),
    options: &LidarImuOptions,
    alignment: Alignment,
    window: f64,
) -> Result<(Alignment, InitOdometry), InputError> {
    let pass = |(rotation, gyro_bias, td): &Alignment| {
        let bias = gyro_bias.map_or_else(Vector3::zeros, |g| g.bias);
        let td = td.map_or(0.0, |t| t.offset_s);
        odometry(imu, scans, options, (&rotation.rotation, &bias, td), window)
    };
    let mut alignment = alignment;
    let mut odometry = pass(&alignment)?;
    if !options.filter.estimate_time_offset {
        return Ok((alignment, odometry));
    }
    for _ in 1..MAX_DESKEW_PASSES {
        let (rotation, gyro_bias, refined) = at_time_offset(
            imu,
            &odometry.increments,
            (alignment.0, alignment.1),
            3.0 * options.filter.time_offset_sigma_s,
        );
        let Some(refined) = refined else {
            break;
        };
        let change = alignment
            .2
            .map_or(f64::INFINITY, |t| (t.offset_s - refined.offset_s).abs());
        alignment = (rotation, gyro_bias, Some(refined));
        odometry = pass(&alignment)?;
        if change < OFFSET_SETTLED_S {
            break;
        }
    }
    Ok((alignment, odometry))
}

/// What the moving start found, for the report.
#[derive(Debug, Clone, Default)]
pub struct MovingStartReport {
    /// The time offset from the rotation increments, when estimated.
    pub time_offset: Option<TimeOffsetEstimate>,
    /// Poses of the odometry the alignment used.
    pub odometry_poses: usize,
}

impl MovingStartReport {
    /// The report's words for the moving start with its `prior`.
    pub(crate) fn describe(&self, prior: &Result<FilterPrior, MovingStart>) -> String {
        let offset = self.time_offset.map_or_else(
            || "not estimated".to_string(),
            |t| {
                format!(
                    "{:+.3} ms (sigma {:.3} ms, {} increments)",
                    t.offset_s * 1e3,
                    t.sigma_s * 1e3,
                    t.pairs
                )
            },
        );
        format!(
            "{}; LiDAR time offset from the deskewed scans' rotations {offset}; odometry of {} \
             rotation-deskewed scans",
            describe_moving_start(prior),
            self.odometry_poses
        )
    }
}

/// The filter of a moving start (no standstill, hand-eye rotation found): the time offset,
/// the odometry and the dynamic alignment of the module docs; the filter's time offset
/// starts at the estimate (with the prior's sigma). Falls back to the level start with
/// wide sigmas when the alignment fails (the report says why).
pub(crate) fn start<T: Scalar>(
    (imu, imu_noise, scans): (&[ImuRecord], &ImuNoiseYaml, &dyn ScanSource),
    options: &LidarImuOptions,
    (rotation, gyro_bias): (RotationInit, Option<GyroBiasEstimate>),
    increments: &[RotationIncrement],
) -> Result<(FilterStart<T>, MovingStartReport), InputError> {
    let filter = &options.filter;
    let (rotation, gyro_bias, time_offset) = if filter.estimate_time_offset {
        at_time_offset(
            imu,
            increments,
            (rotation, gyro_bias),
            3.0 * filter.time_offset_sigma_s,
        )
    } else {
        (rotation, gyro_bias, None)
    };
    let window = DynamicInitOptions::default().window_s + 1.0;
    let ((rotation, gyro_bias, time_offset), odometry) = deskewed_start(
        (imu, scans),
        options,
        (rotation, gyro_bias, time_offset),
        window,
    )?;
    let td = time_offset.map_or(0.0, |t| t.offset_s);
    let poses = odometry.poses;
    let prior = if poses.len() > 1 {
        moving_start(
            imu,
            &poses,
            &rotation.rotation,
            (gyro_bias.as_ref(), td),
            imu_noise,
        )
    } else {
        Err(MovingStart::Failed(MovingStartFailure::NoOdometry))
    };
    let initial = initial_state::<T>(imu, None, &rotation.rotation, filter)?;
    let (initial, gyro_bias_init) = with_gyro_bias(initial, None, gyro_bias.as_ref());
    let initial = match &prior {
        Ok(p) => with_moving_start(initial, p),
        Err(_) => initial,
    };
    let initial = if filter.estimate_time_offset {
        initial.with_time_offset(SOLE_SENSOR, T::lit(td), T::lit(filter.time_offset_sigma_s))
    } else {
        initial
    };
    let config = FilterConfig::new(convert::imu_noise::<T>(imu_noise));
    let ekf = PoseImuEkf::<T>::new(&config, &initial)
        .map_err(|error| InputError::InvalidNoise { error })?;
    Ok((
        FilterStart {
            ekf,
            rotation_init: rotation,
            init_problem: None,
            moving_start: prior,
            gyro_bias_init,
        },
        MovingStartReport {
            time_offset,
            odometry_poses: poses.len(),
        },
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// 20 s of a 400 Hz gyro turning about all three axes (no noise).
    fn imu() -> Vec<ImuRecord> {
        (0..8000u64)
            .map(|k| {
                let t = k as f64 / 400.0;
                ImuRecord {
                    stamp_ns: 1_000_000_000 + k * 2_500_000,
                    gyro: Vector3::new(
                        1.5 * (2.0 * std::f64::consts::PI * 0.5 * t).sin(),
                        (2.0 * std::f64::consts::PI * 0.3 * t).cos(),
                        2.0 * (2.0 * std::f64::consts::PI * 0.7 * t + 1.0).sin(),
                    ),
                    accel: Vector3::new(0.0, 0.0, 9.81),
                }
            })
            .collect()
    }

    /// The LiDAR's rotation increments every 0.1 s (LiDAR clock) of a LiDAR at `r_i_l`
    /// whose clock lags the IMU's by `td_s`, from the same gyro.
    fn increments(
        imu: &[ImuRecord],
        r_i_l: &UnitQuaternion<f64>,
        td_s: f64,
    ) -> Vec<RotationIncrement> {
        let td_ns = (td_s * 1e9).round() as i64;
        (0..150u64)
            .filter_map(|k| {
                let (a, b) = (
                    2_000_000_000 + k * 100_000_000,
                    2_100_000_000 + k * 100_000_000,
                );
                let q = init::integrate_gyro(
                    imu,
                    shifted(a, td_ns)?,
                    shifted(b, td_ns)?,
                    &Vector3::zeros(),
                )?;
                Some((a, b, r_i_l.inverse() * q * r_i_l))
            })
            .collect()
    }

    #[test]
    fn time_offset_from_rotations_recovers_the_offset() {
        let imu = imu();
        let r_i_l = UnitQuaternion::from_euler_angles(0.3, -2.0, 1.0);
        for td in [-0.0173, 0.0, 0.0121] {
            let found = time_offset_from_rotations(
                &imu,
                &increments(&imu, &r_i_l, td),
                &Vector3::zeros(),
                0.06,
            )
            .expect("an offset");
            assert!((found.offset_s - td).abs() < 2e-6, "{found:?} against {td}");
            assert!(found.pairs > 100, "{found:?}");
        }
    }

    #[test]
    fn time_offset_outside_the_range_is_not_claimed() {
        let imu = imu();
        let r_i_l = UnitQuaternion::identity();
        let found = time_offset_from_rotations(
            &imu,
            &increments(&imu, &r_i_l, 0.09),
            &Vector3::zeros(),
            0.03,
        );
        assert_eq!(found, None);
    }
}

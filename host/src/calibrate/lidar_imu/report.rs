//! What LiDAR-IMU calibration reports: per-scan records, stage timing, the report.

use crate::calibrate::driver::report::PoseImuReport;
use crate::ndt::NdtResult;
use nalgebra::Isometry3;
use serde::Serialize;

/// One scan's fate, for the report.
#[derive(Debug, Clone, Serialize)]
pub struct ScanRecord {
    /// Scan stamp (LiDAR clock), ns.
    pub stamp_ns: u64,
    /// Reference (measurement) stamp, LiDAR clock, ns.
    pub reference_stamp_ns: u64,
    /// Seconds since the first IMU sample.
    pub t_s: f64,
    /// Points read.
    pub points: usize,
    /// Points after the voxel filter.
    pub points_filtered: usize,
    /// `matched`, `anchor` (first of a chain) or why it was skipped.
    pub status: String,
    /// NDT fitness (mean normalised score per point), when matched.
    pub fitness: Option<f64>,
    /// NDT iterations.
    pub iterations: Option<usize>,
    /// NIS of the update.
    pub nis: Option<f64>,
    /// Measured `T_L(k-1)_L(k)`: rotation vector, rad.
    pub delta_rotation: Option<[f64; 3]>,
    /// Measured `T_L(k-1)_L(k)`: translation, m.
    pub delta_translation: Option<[f64; 3]>,
    /// Measurement 1-sigma (after inflation) [rot x, y, z (rad); trans x, y, z (m)].
    pub sigma: Option<[f64; 6]>,
    /// The NDT result behind the measurement (in-process studies of the noise model).
    #[serde(skip)]
    pub ndt: Option<NdtResult>,
    /// The filter's prediction of `T_L(k-1)_L(k)`, NDT's initial guess (in-process studies).
    #[serde(skip)]
    pub predicted: Option<Isometry3<f64>>,
}

impl ScanRecord {
    /// A scan that has not (or not yet) been matched: no NDT or filter results.
    pub(crate) fn unmatched(
        stamp_ns: u64,
        reference_stamp_ns: u64,
        t_s: f64,
        points: usize,
        status: String,
    ) -> Self {
        Self {
            stamp_ns,
            reference_stamp_ns,
            t_s,
            points,
            points_filtered: 0,
            status,
            fitness: None,
            iterations: None,
            nis: None,
            delta_rotation: None,
            delta_translation: None,
            sigma: None,
            ndt: None,
            predicted: None,
        }
    }
}

/// Wall time per stage, s.
#[derive(Debug, Clone, Copy, Serialize, Default)]
pub struct StageTiming {
    /// Standstill detection, raw NDT and hand-eye rotation.
    pub rotation_init: f64,
    /// Reading scans (filter pass).
    pub load: f64,
    /// Deskewing.
    pub deskew: f64,
    /// Voxel filter and NDT target build.
    pub voxel_and_target: f64,
    /// NDT registration.
    pub ndt: f64,
    /// Filter (propagation and updates), the rest of the filter pass.
    pub filter: f64,
    /// The whole filter pass.
    pub total_filter_pass: f64,
}

/// The JSON report of a LiDAR-IMU calibration.
#[derive(Debug, Clone, Serialize)]
pub struct LidarImuReport {
    /// The filter's report (convergence checks, hand-eye init, history of 6 DoF + sigmas).
    #[serde(flatten)]
    pub filter: PoseImuReport,
    /// Whether scans were deskewed.
    pub deskew: bool,
    /// Scans in the recording.
    pub scans_total: usize,
    /// Scans fused as relative poses.
    pub scans_matched: usize,
    /// Scans skipped, with reasons.
    pub scans_skipped: Vec<String>,
    /// Mean NIS per DoF of the updates after the floor's annealing settled (from update
    /// `3 * anneal_updates` on; 1 when the final noise model is consistent; NaN if none).
    pub settled_nis_per_dof: f64,
    /// Pairs the rotation init dropped as outliers.
    pub hand_eye_outliers: usize,
    /// The measurement noise model: `[covariance scale rotation, covariance scale
    /// translation, rotation floor (deg), translation floor (m)]`.
    pub measurement_noise: [f64; 4],
    /// Effective factor on the NDT covariance at the end (adapted scale times the
    /// correlation inflation; the configured rotation factor when not adapted).
    pub final_covariance_scale: f64,
    /// The inflation for time-correlated NDT errors at the end, `(1 + rho) / (1 - rho)`.
    pub correlation_inflation: f64,
    /// The filter's own time-offset sigma, s, before the front end's systematic time shift
    /// (`LidarImuOptions::time_shift_sigma_s`) is added in quadrature.
    pub time_offset_filter_sigma_s: f64,
    /// Wall time per stage.
    pub stage_timing_s: StageTiming,
    /// Per scan: points, NDT fitness, NIS.
    pub scans: Vec<ScanRecord>,
}

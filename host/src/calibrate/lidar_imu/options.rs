//! The options of LiDAR-IMU calibration: NDT, deskew, the measurement noise and its adaptation.

use crate::calibrate::driver::report::PoseImuOptions;
use crate::ndt::NdtParams;
use serde::Serialize;

/// Tuning of the pipeline.
#[derive(Debug, Clone, PartialEq)]
pub struct LidarImuOptions {
    /// Priors, time offset and standstill options shared with the pose-IMU pipeline.
    pub filter: PoseImuOptions,
    /// Deskew scans (eq. 3.18); `false` matches raw scans stamped at mid-sweep (Fig. 3.11).
    pub deskew: bool,
    /// Voxel-filter leaf after deskewing, m.
    pub voxel_m: f64,
    /// NDT options.
    pub ndt: NdtParams,
    /// Scans from the first this many seconds feed the hand-eye rotation init.
    pub init_duration_s: f64,
    /// Which NDT covariance the measurement noise starts from.
    pub ndt_covariance: NdtCovariance,
    /// Factors on NDT's covariance, `[rotation block, translation block]` (see the module
    /// docs: measured per-increment error variance times the autocorrelation inflation).
    pub covariance_scale: [f64; 2],
    /// Per-axis 1-sigma rotation added to every increment, rad: stands for the part of
    /// NDT's error that is correlated from scan to scan, which the white measurement model
    /// cannot represent; it depends on the matching (see [`LidarImuOptions::scan_to_scan`]).
    pub rotation_floor_rad: f64,
    /// Per-axis 1-sigma translation added to every increment, m.
    pub translation_floor_m: f64,
    /// Per-axis 1-sigma rotation floor of the first update, rad; the floor decays from it to
    /// `rotation_floor_rad` with time constant `anneal_updates` (see the module docs).
    pub initial_rotation_floor_rad: f64,
    /// Per-axis 1-sigma translation floor of the first update, m.
    pub initial_translation_floor_m: f64,
    /// Decay constant of the floor, in updates.
    pub anneal_updates: f64,
    /// Also shrink the floor's excess with the filter's own extrinsic sigma: the excess is
    /// scaled by `min(exp(-updates / anneal_updates), max_i sigma_i / prior_sigma_i)` over
    /// the six extrinsic axes. The floor stands for the linearisation error of an extrinsic
    /// still far from the truth, which the filter's sigma bounds; a well-excited recording
    /// then reaches the final floor within seconds instead of `anneal_updates` updates
    /// (docs/lidar_imu.md, "The floor annealed by the filter's sigma").
    pub anneal_by_sigma: bool,
    /// 1-sigma of the front end's systematic time shift, s: NDT's increments carry a
    /// scene-dependent error along the time-offset direction that does not average out over
    /// a recording (docs/lidar_imu.md, "The time offset's systematic error"). It is
    /// collinear with `t_d`, so the filter attributes all of it to `t_d`; as a consider
    /// parameter it adds in quadrature to the reported time-offset sigma (the extrinsic is
    /// unaffected to first order).
    pub time_shift_sigma_s: f64,
    /// Adapt the factor on NDT's covariance so the NIS matches its expectation
    /// ([`NoiseAdaptation`]); `None` keeps `covariance_scale` fixed.
    pub adapt: Option<NoiseAdaptation>,
    /// Matches with a lower NDT fitness are skipped.
    pub min_fitness: f64,
    /// Scans with fewer points after voxel filtering are skipped.
    pub min_points: usize,
    /// Match each scan against a sliding map of this many recent deskewed scans
    /// (scan-to-local-map) instead of the previous scan; 0 = scan-to-scan. The increment
    /// fused is still `T_L(k-1)_L(k)`, from the two scans' poses in the map. Default 5:
    /// more accurate than scan-to-scan, whose positively correlated increment errors make
    /// the filter overconfident on long, dense recordings (docs/lidar_imu.md). The floor
    /// depends on it: change it through [`LidarImuOptions::for_local_map`].
    pub local_map_scans: usize,
}

impl Default for LidarImuOptions {
    fn default() -> Self {
        Self {
            filter: PoseImuOptions {
                rotation_sigma_rad: 3f64.to_radians(),
                ..PoseImuOptions::default()
            },
            deskew: true,
            voxel_m: 0.15,
            ndt: NdtParams {
                resolutions: vec![2.0, 1.0, 0.5],
                ..NdtParams::default()
            },
            init_duration_s: 15.0,
            ndt_covariance: NdtCovariance::Hessian,
            covariance_scale: [0.2, 0.2],
            // Half the scan-to-scan floor: map-based increments are more accurate and their
            // errors not positively correlated (docs/lidar_imu.md).
            rotation_floor_rad: 0.0025f64.to_radians(),
            translation_floor_m: 0.00025,
            initial_rotation_floor_rad: 0.2f64.to_radians(),
            initial_translation_floor_m: 0.01,
            anneal_updates: 100.0,
            anneal_by_sigma: true,
            time_shift_sigma_s: TIME_SHIFT_SIGMA_S,
            adapt: Some(NoiseAdaptation::default()),
            min_fitness: 0.05,
            min_points: 200,
            local_map_scans: 5,
        }
    }
}

impl LidarImuOptions {
    /// The defaults for matching against `local_map_scans` scans (0 = scan-to-scan), with
    /// that mode's floor.
    pub fn for_local_map(local_map_scans: usize) -> Self {
        if local_map_scans == 0 {
            Self::scan_to_scan()
        } else {
            Self {
                local_map_scans,
                ..Self::default()
            }
        }
    }

    /// Scan-to-scan matching (`local_map_scans = 0`) with its own floor, 0.005 deg / 0.5 mm:
    /// the size of scan-to-scan NDT's per-increment errors on dense scans, whose positive
    /// correlation from scan to scan it stands for (docs/lidar_imu.md, noise model).
    pub fn scan_to_scan() -> Self {
        Self {
            local_map_scans: 0,
            rotation_floor_rad: 0.005f64.to_radians(),
            translation_floor_m: 0.0005,
            ..Self::default()
        }
    }
}

/// Default [`LidarImuOptions::time_shift_sigma_s`], s: the RMS time shift of the NDT
/// increments measured against the simulator's truth on tuning seeds 500-509
/// (docs/lidar_imu.md, "The time offset's systematic error"), validated on other seeds.
pub const TIME_SHIFT_SIGMA_S: f64 = 0.027e-3;

/// Covariance matching of the NDT noise scale (Mehra 1972; Myers and Tapley 1976, with a
/// single scale factor): NDT's inverse Hessian has the right *shape* (which directions the
/// scene constrains) but a scale set by the score's constants, the target cells' eigenvalue
/// floor and unmodelled correlations, none of which the matcher can know. The filter
/// measures it: the NIS of an update falls when `R` is too large and rises when too small,
/// with expectation `dof` when consistent. Every `every` updates, after
/// `start_after_anneals * anneal_updates` updates, the factor is multiplied by
/// `(mean NIS/dof)^(w/2)` over the last `window` updates (each NIS/dof clipped at `clip`, so
/// one wrong match cannot blow it up), `w` the NDT term's mean share of the diagonal of `R`
/// (while the annealed floor dominates, the NIS says little about the NDT scale), the step
/// limited to `[1/max_step, max_step]` and the factor to `bounds`. The exponent 1/2 halves
/// each step: NIS is roughly proportional to `1/scale`, and damping averages the
/// chi-square sampling noise of the window.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NoiseAdaptation {
    /// Updates between adjustments.
    pub every: usize,
    /// Updates whose NIS is averaged.
    pub window: usize,
    /// Adaptation starts after this many `anneal_updates`.
    pub start_after_anneals: f64,
    /// Largest NIS/dof one update contributes.
    pub clip: f64,
    /// Largest factor of one adjustment.
    pub max_step: f64,
    /// Range of the scale factor.
    pub bounds: [f64; 2],
    /// Consecutive innovation pairs over which their lag-1 autocorrelation is measured
    /// (0 = no correlation inflation).
    pub correlation_window: usize,
    /// Largest inflation for correlated errors.
    pub max_inflation: f64,
}

impl Default for NoiseAdaptation {
    fn default() -> Self {
        Self {
            every: 20,
            window: 40,
            start_after_anneals: 1.0,
            clip: 5.0,
            max_step: 1.4,
            bounds: [0.01, 10.0],
            correlation_window: 0,
            max_inflation: 4.0,
        }
    }
}

/// The NDT covariance estimate the measurement noise is built from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum NdtCovariance {
    /// Inverse Hessian of the score (Laplace approximation).
    Hessian,
    /// Sandwich `H^-1 S H^-1` with per-point gradients.
    Sandwich,
    /// Sandwich with gradients summed per target cell.
    Clustered,
}

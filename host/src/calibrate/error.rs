//! The typed error of the IMU pipelines (pose-IMU, camera-IMU, LiDAR-IMU, joint): bad input
//! that stops a run (exit code 2). Every variant carries the file (or option) it concerns
//! and the values a caller can match on; the CLI prefixes the dataset directory.

use crate::lidar::ScanLoadError;
use crate::ndt::NdtError;

/// Why an IMU pipeline could not run.
#[derive(Debug, thiserror::Error)]
pub enum InputError {
    /// `imu0/data.csv` holds no sample.
    #[error("imu0/data.csv: no IMU samples")]
    NoImuSamples,
    /// Fewer records of a sensor than the pipeline needs.
    #[error("{file}: {found} {what}; at least {needed} are needed")]
    TooFew {
        /// The file or directory (`pose0/data.csv`, `lidar0/`).
        file: &'static str,
        /// What is counted (`poses`, `scans`).
        what: &'static str,
        /// How many there are.
        found: usize,
        /// How many are needed.
        needed: usize,
    },
    /// Fewer camera images with a target pose than the pipeline needs.
    #[error("cam0: {found} of {images} images have a target pose; at least {needed} are needed")]
    TooFewTargetPoses {
        /// Images with a target pose.
        found: usize,
        /// Images in `cam0/`.
        images: usize,
        /// How many are needed.
        needed: usize,
    },
    /// More cameras than one camera-IMU filter takes.
    #[error("{found} cameras (cam0..cam{last}); one camera-IMU filter takes at most {max}", last = .found - 1)]
    TooManyCameras {
        /// Cameras given.
        found: usize,
        /// Most one filter takes.
        max: usize,
    },
    /// The filter refused an IMU sample (gap, time going backwards, non-finite value).
    #[error(
        "imu0/data.csv: {error}, ending at the sample stamped {stamp_ns} ns (sample {sample} of \
         the file)"
    )]
    ImuSample {
        /// The estimator's reason.
        error: msreg_estimator::Error,
        /// Stamp of the sample, ns.
        stamp_ns: u64,
        /// 1-based index of the sample in the file.
        sample: usize,
    },
    /// A zero-velocity update during the standstill failed.
    #[error(
        "imu0/data.csv: zero-velocity update at the sample stamped {stamp_ns} ns (sample \
         {sample} of the file): {error}"
    )]
    ZeroVelocity {
        /// The estimator's reason.
        error: msreg_estimator::Error,
        /// Stamp of the sample, ns.
        stamp_ns: u64,
        /// 1-based index of the sample in the file.
        sample: usize,
    },
    /// The mean accelerometer reading at the start is not gravity.
    #[error(
        "imu0/data.csv: mean accelerometer reading {accel_norm:.2} m/s^2 at the start is not \
         gravity"
    )]
    NotGravity {
        /// Norm of the mean reading, m/s^2.
        accel_norm: f64,
    },
    /// The filter refused the noise figures (or the prior built from them).
    #[error("imu0/imu.yaml: invalid noise ({error})")]
    InvalidNoise {
        /// The estimator's reason.
        error: msreg_estimator::Error,
    },
    /// The planar-motion rotation axis could not be held.
    #[error("planar rotation axis: {error}")]
    PlanarAxis {
        /// The estimator's reason.
        error: msreg_estimator::Error,
    },
    /// Invalid NDT options.
    #[error(transparent)]
    Ndt(#[from] NdtError),
    /// A sandwich NDT covariance was asked for without computing it.
    #[error("options: a sandwich NDT covariance needs ndt.sandwich_covariance")]
    SandwichWithoutCovariance,
    /// A scan file could not be read (names the file and line).
    #[error(transparent)]
    Scan(#[from] ScanLoadError),
    /// `target.yaml` lacks the board size the joint calibration needs.
    #[error(
        "target.yaml: the joint calibration needs the board's width_m and height_m (the \
         physical board, centred on the pattern) to find it in the scans"
    )]
    BoardSizeMissing,
    /// The hand-eye rotation of a sensor could not be initialised.
    #[error(
        "{sensor}: hand-eye rotation initialisation failed ({error:?}): the recording needs \
         rotation about at least two axes"
    )]
    HandEyeRotation {
        /// The sensor's directory (`lidar0/`, `pose0/`).
        sensor: &'static str,
        /// The hand-eye solver's reason.
        error: msreg_estimator::HandEyeError<f64>,
    },
}

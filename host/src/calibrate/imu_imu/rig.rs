//! Every `imuN` (N >= 1) of a dataset against `imu0`: the task behind
//! `msreg calibrate imu-imu`. Each pair is calibrated by [`super::calibrate`]; the result file
//! gets one `imuN` section per IMU (`T_imu0_imu`, `timeshift_imu_imu0`).

use nalgebra::{Isometry3, Matrix6, Translation3};
use thiserror::Error;

use super::{calibrate, ImuImuError, ImuImuEstimate, ImuImuOptions, ImuSeries};
use crate::dataset::{
    CalibrationResult, Dataset, DatasetError, Dof, ExtrinsicEstimate, ImuRecord, SectionName,
    SensorId, SensorKind,
};

/// A lever-arm component whose 1-sigma exceeds this (m) is not determined by the recording:
/// it is held at the prior (0: the IMUs co-located along that axis) and listed in `held`.
/// 2 cm is where a lever arm stops mattering for the rate-level models that use it.
pub const LEVER_HELD_SIGMA_M: f64 = 0.02;

/// Why the rig could not be calibrated.
#[derive(Debug, Error)]
pub enum ImuRigError {
    /// The dataset could not be read.
    #[error(transparent)]
    Dataset(#[from] DatasetError),
    /// Only `imu0` is present.
    #[error("{dataset}: no second IMU (imu1/, imu2/, ...) to calibrate against imu0")]
    NoSecondImu {
        /// The dataset directory.
        dataset: String,
    },
    /// One IMU pair failed.
    #[error("{sensor} against imu0: {source}")]
    Pair {
        /// The IMU that failed.
        sensor: SensorId,
        /// Why.
        source: ImuImuError,
    },
}

/// The estimate of one `imuN`.
#[derive(Debug, Clone)]
pub struct ImuPairOutcome {
    /// `imuN`.
    pub sensor: SensorId,
    /// The batch estimate with its sigmas.
    pub estimate: ImuImuEstimate,
    /// Lever-arm axes held at 0 (sigma above [`LEVER_HELD_SIGMA_M`]).
    pub held: Vec<Dof>,
}

/// The rig's calibration: the result file and one outcome per `imuN`.
#[derive(Debug, Clone)]
pub struct ImuRigCalibration {
    /// `imuN` sections.
    pub result: CalibrationResult,
    /// Per IMU, in index order.
    pub pairs: Vec<ImuPairOutcome>,
}

/// Converts records to seconds after `epoch_ns` (integer subtraction first: stamps near
/// 1.7e18 ns do not fit an f64 to the nanosecond).
pub fn series(records: &[ImuRecord], epoch_ns: u64) -> ImuSeries {
    let mut s = ImuSeries::default();
    for r in records {
        s.t.push((i128::from(r.stamp_ns) - i128::from(epoch_ns)) as f64 * 1e-9);
        s.gyro.push(r.gyro);
        s.accel.push(r.accel);
    }
    s
}

/// Calibrates every `imuN` of `dataset` against `imu0`; `progress` is told each IMU's name
/// before it runs.
pub fn calibrate_rig(
    dataset: &Dataset,
    opts: &ImuImuOptions,
    mut progress: impl FnMut(SensorId),
) -> Result<ImuRigCalibration, ImuRigError> {
    let (imu0, _) = dataset.read_imu(0)?;
    let epoch = imu0.first().map_or(0, |r| r.stamp_ns);
    let s0 = series(&imu0, epoch);
    let others: Vec<SensorId> = dataset
        .sensors_of(SensorKind::Imu)?
        .into_iter()
        .filter(|id| id.index > 0)
        .collect();
    if others.is_empty() {
        return Err(ImuRigError::NoSecondImu {
            dataset: dataset.root.display().to_string(),
        });
    }
    let mut result = CalibrationResult::new();
    let mut pairs = Vec::with_capacity(others.len());
    for sensor in others {
        progress(sensor);
        let (records, _) = dataset.read_imu(sensor.index)?;
        let estimate = calibrate(&s0, &series(&records, epoch), opts)
            .map_err(|source| ImuRigError::Pair { sensor, source })?;
        let outcome = pair_outcome(sensor, estimate);
        let section = result.section_mut(SectionName::Sensor(sensor));
        section.extrinsic = Some(extrinsic_of(&outcome));
        for dof in &outcome.held {
            section.hold(*dof);
        }
        pairs.push(outcome);
    }
    Ok(ImuRigCalibration { result, pairs })
}

/// Holds the lever-arm axes the recording did not determine.
fn pair_outcome(sensor: SensorId, mut estimate: ImuImuEstimate) -> ImuPairOutcome {
    let axes = [Dof::TranslationX, Dof::TranslationY, Dof::TranslationZ];
    let mut held = Vec::new();
    for (k, dof) in axes.into_iter().enumerate() {
        if estimate.sigma_translation[k] > LEVER_HELD_SIGMA_M {
            estimate.translation[k] = 0.0;
            held.push(dof);
        }
    }
    ImuPairOutcome {
        sensor,
        estimate,
        held,
    }
}

/// `T_imu0_imu` with its sigmas (rotation right-perturbed, as the result file states).
fn extrinsic_of(outcome: &ImuPairOutcome) -> ExtrinsicEstimate {
    let e = &outcome.estimate;
    let mut cov = Matrix6::zeros();
    cov.fixed_view_mut::<3, 3>(0, 0)
        .copy_from(&e.cov_rot_time.fixed_view::<3, 3>(0, 0));
    cov.fixed_view_mut::<3, 3>(3, 3)
        .copy_from(&e.cov_translation);
    ExtrinsicEstimate::from_covariance(
        Isometry3::from_parts(Translation3::from(e.translation), e.rotation),
        e.timeshift_s,
        &cov,
    )
}

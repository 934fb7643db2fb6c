//! A result file with two generic pose sensors, `pose0` and `pose1` (docs/formats.md: `pose1/`
//! is a second pose sensor with the layout of `pose0/`; its section has the keys of `pose0`:
//! `T_imu_pose`, `timeshift_pose_imu`, `sigma_rot_deg`, `sigma_trans_m`). The calibration a
//! vehicle carries for the monitor (`msreg monitor --initial`), and the drive simulator's
//! ground truth.
//!
//! Both sections are read and written by [`CalibrationResult`].

use std::path::Path;

use super::csv::read_text;
use super::error::DatasetError;
use super::result::{CalibrationResult, ExtrinsicEstimate, SectionName};
use super::yaml::write_text;

/// The calibration of record a vehicle dataset carries for `msreg monitor` (a result file
/// with `pose0` and `pose1`), relative to the dataset root.
pub const CALIBRATION_OF_RECORD_YAML: &str = "calibration.yaml";

/// `pose0` and `pose1` of a result file.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PosePairCalibration {
    /// `pose0`: `T_imu_pose` of the first pose sensor.
    pub pose0: Option<ExtrinsicEstimate>,
    /// `pose1`: `T_imu_pose` of the second.
    pub pose1: Option<ExtrinsicEstimate>,
}

impl PosePairCalibration {
    /// Reads `path` (a result file; other sections are ignored).
    pub fn read(path: impl AsRef<Path>) -> Result<Self, DatasetError> {
        let path = path.as_ref();
        let text = read_text(path)?;
        Self::parse(path, &text)
    }

    /// Parses result-file text; `path` names it in errors.
    pub fn parse(path: &Path, text: &str) -> Result<Self, DatasetError> {
        let result = CalibrationResult::parse(path, text)?;
        Ok(Self {
            pose0: result.extrinsic(&SectionName::pose(0)).copied(),
            pose1: result.extrinsic(&SectionName::pose(1)).copied(),
        })
    }

    /// The result file with the sections present.
    pub fn to_result(&self) -> CalibrationResult {
        let mut result = CalibrationResult::new();
        for (i, e) in [(0, self.pose0), (1, self.pose1)] {
            if let Some(e) = e {
                result.set_extrinsic(SectionName::pose(i), e);
            }
        }
        result
    }

    /// The YAML text: `pose0`, then `pose1`.
    pub fn to_yaml_string(&self) -> String {
        self.to_result().to_yaml_string()
    }

    /// Writes the file.
    pub fn write(&self, path: impl AsRef<Path>) -> Result<(), DatasetError> {
        write_text(path.as_ref(), &self.to_yaml_string())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};

    fn estimate(k: f64) -> ExtrinsicEstimate {
        ExtrinsicEstimate {
            transform: Isometry3::from_parts(
                Translation3::new(0.1 * k, -0.2, 0.3),
                UnitQuaternion::from_euler_angles(0.1, 0.2 * k, -0.3),
            ),
            timeshift_s: 0.001 * k,
            sigma_rot_deg: Vector3::new(0.05, 0.05, 0.06),
            sigma_trans_m: Vector3::new(0.002, 0.003, 0.004),
        }
    }

    #[test]
    fn both_sections_round_trip() {
        let pair = PosePairCalibration {
            pose0: Some(estimate(1.0)),
            pose1: Some(estimate(2.0)),
        };
        let text = pair.to_yaml_string();
        let back = PosePairCalibration::parse(Path::new("x.yaml"), &text).expect("parses");
        for (a, b) in [(pair.pose0, back.pose0), (pair.pose1, back.pose1)] {
            let (a, b) = (a.expect("a"), b.expect("b"));
            assert!((a.transform.to_homogeneous() - b.transform.to_homogeneous()).amax() < 1e-12);
            assert!((a.timeshift_s - b.timeshift_s).abs() < 1e-15);
            assert_eq!(a.sigma_trans_m, b.sigma_trans_m);
        }
    }

    #[test]
    fn a_bad_pose1_names_pose1_and_its_line() {
        let pair = PosePairCalibration {
            pose0: Some(estimate(1.0)),
            pose1: None,
        };
        let text = format!(
            "{}pose1:\n  T_imu_pose: [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 2, 0], [0, 0, 0, 1]]\n",
            pair.to_yaml_string()
        );
        let e = PosePairCalibration::parse(Path::new("x.yaml"), &text).expect_err("bad");
        let msg = e.to_string();
        assert!(msg.contains("pose1") && msg.contains("x.yaml"), "{msg}");
    }
}

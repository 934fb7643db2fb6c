//! A result file with two generic pose sensors, `pose0` and `pose1` (CONVENTIONS.md: `pose1/`
//! is a second pose sensor with the layout of `pose0/`; its section has the keys of `pose0`:
//! `T_imu_pose`, `timeshift_pose_imu`, `sigma_rot_deg`, `sigma_trans_m`). The calibration a
//! vehicle carries for the monitor (`msreg monitor --initial`), and the drive simulator's
//! ground truth.
//!
//! The `pose0` section is read and written by [`CalibrationResult`]; `pose1` by the same code,
//! on the text with the two top-level keys swapped line for line (so errors keep their line).

use std::path::Path;

use super::csv::read_text;
use super::error::DatasetError;
use super::result::{CalibrationResult, ExtrinsicEstimate};
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

/// The text with the top-level keys `from:` and `to:` exchanged (other lines untouched).
fn swap_top_level_keys(text: &str, a: &str, b: &str) -> String {
    let (ka, kb) = (format!("{a}:"), format!("{b}:"));
    text.lines()
        .map(|line| {
            if let Some(rest) = line.strip_prefix(&ka) {
                format!("{kb}{rest}")
            } else if let Some(rest) = line.strip_prefix(&kb) {
                format!("{ka}{rest}")
            } else {
                line.to_string()
            }
        })
        .collect::<Vec<_>>()
        .join("\n")
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
        let pose0 = CalibrationResult::parse(path, text)?.pose0;
        let swapped = swap_top_level_keys(text, "pose0", "pose1");
        let pose1 = CalibrationResult::parse(path, &swapped)
            .map_err(|e| match e {
                DatasetError::InvalidValue { path, message } => DatasetError::InvalidValue {
                    path,
                    message: message.replacen("pose0", "pose1", 1),
                },
                other => other,
            })?
            .pose0;
        Ok(Self { pose0, pose1 })
    }

    /// The YAML text: `pose0`, then `pose1`, each as the result file writes `pose0`.
    pub fn to_yaml_string(&self) -> String {
        let section = |e: &Option<ExtrinsicEstimate>| {
            e.map(|e| {
                CalibrationResult {
                    pose0: Some(e),
                    ..CalibrationResult::default()
                }
                .to_yaml_string()
            })
            .unwrap_or_default()
        };
        let pose1 = swap_top_level_keys(&section(&self.pose1), "pose0", "pose1");
        let mut text = section(&self.pose0);
        if !pose1.is_empty() {
            if !text.is_empty() && !text.ends_with('\n') {
                text.push('\n');
            }
            text.push_str(&pose1);
            text.push('\n');
        }
        text
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

//! The prior file of `msreg calibrate ... --prior prior.yaml` (docs/formats.md "Prior
//! file"): result-file sections and keys, each extrinsic with its 1-sigma per DoF, where a
//! sigma of 0 fixes that parameter (a measured lever arm, say). One reader for every
//! pipeline; a key no prior knows is an error naming its line, never silently ignored.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use nalgebra::{Isometry3, Matrix4, Vector3};
use serde::Deserialize;

use super::error::DatasetError;
use super::result::{isometry_from_matrix, SectionName};
use super::yaml::parse_yaml;

/// Why a prior file was refused.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum PriorError {
    /// The file is missing, unreadable or not YAML of the expected shape (with the line).
    #[error(transparent)]
    Read(#[from] DatasetError),
    /// A value that parses but is not a prior.
    #[error("{}:{line}: {message}", path.display())]
    Invalid {
        /// The prior file.
        path: PathBuf,
        /// 1-based line of the key.
        line: usize,
        /// What is wrong.
        message: String,
    },
}

type Matrix = [[f64; 4]; 4];

/// A section as stored: the result file's extrinsic keys and the prior's sigmas. Other keys
/// a result file may carry are accepted and unused, so a result file reads as a prior.
// The result-file keys a prior does not use are read only to be accepted.
#[allow(dead_code)]
#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct RawPrior {
    #[serde(rename = "T_cam_imu")]
    t_cam_imu: Option<Matrix>,
    #[serde(rename = "T_imu_lidar")]
    t_imu_lidar: Option<Matrix>,
    #[serde(rename = "T_imu_pose")]
    t_imu_pose: Option<Matrix>,
    #[serde(rename = "T_imu0_imu")]
    t_imu0_imu: Option<Matrix>,
    #[serde(rename = "T_cam_lidar")]
    t_cam_lidar: Option<Matrix>,
    timeshift_cam_imu: Option<f64>,
    timeshift_lidar_imu: Option<f64>,
    timeshift_pose_imu: Option<f64>,
    timeshift_imu_imu0: Option<f64>,
    sigma_rot_deg: Option<[f64; 3]>,
    sigma_trans_m: Option<[f64; 3]>,
    sigma_timeshift_s: Option<f64>,
    // Result-file keys a prior does not use.
    held: Option<serde_yaml::Value>,
    #[serde(rename = "T_cn_cnm1")]
    t_cn_cnm1: Option<serde_yaml::Value>,
    sigma_rot_deg_cn_cnm1: Option<serde_yaml::Value>,
    sigma_trans_m_cn_cnm1: Option<serde_yaml::Value>,
    camera_model: Option<serde_yaml::Value>,
    intrinsics: Option<serde_yaml::Value>,
    distortion_model: Option<serde_yaml::Value>,
    distortion_coeffs: Option<serde_yaml::Value>,
    resolution: Option<serde_yaml::Value>,
    sigma_intrinsics: Option<serde_yaml::Value>,
    rostopic: Option<serde_yaml::Value>,
    cam_overlaps: Option<serde_yaml::Value>,
}

impl RawPrior {
    fn transform(&self, key: &str) -> Option<&Matrix> {
        match key {
            "T_cam_imu" => self.t_cam_imu.as_ref(),
            "T_imu_lidar" => self.t_imu_lidar.as_ref(),
            "T_imu_pose" => self.t_imu_pose.as_ref(),
            "T_imu0_imu" => self.t_imu0_imu.as_ref(),
            "T_cam_lidar" => self.t_cam_lidar.as_ref(),
            _ => None,
        }
    }

    fn timeshift(&self, key: &str) -> Option<f64> {
        match key {
            "timeshift_cam_imu" => self.timeshift_cam_imu,
            "timeshift_lidar_imu" => self.timeshift_lidar_imu,
            "timeshift_pose_imu" => self.timeshift_pose_imu,
            "timeshift_imu_imu0" => self.timeshift_imu_imu0,
            _ => None,
        }
    }
}

/// One sensor's (or pair's) prior, in its section's transform (`pose0.T_imu_pose`,
/// `cam0.T_cam_imu`, ...). `None` parts leave the pipeline's own start and prior.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ExtrinsicPrior {
    /// The transform's prior value.
    pub transform: Option<Isometry3<f64>>,
    /// 1-sigma per rotation axis (rad, the result file's axes); 0 fixes the axis.
    pub sigma_rot_rad: Option<Vector3<f64>>,
    /// 1-sigma per translation axis (m); 0 fixes the axis.
    pub sigma_trans_m: Option<Vector3<f64>>,
    /// The time shift's prior value (s).
    pub timeshift_s: Option<f64>,
    /// Its 1-sigma (s); 0 fixes it.
    pub sigma_timeshift_s: Option<f64>,
}

impl ExtrinsicPrior {
    /// True when every translation axis is fixed (sigma 0).
    pub fn translation_fixed(&self) -> bool {
        self.sigma_trans_m
            .is_some_and(|s| s.iter().all(|&v| v == 0.0))
    }

    /// True when every rotation axis is fixed (sigma 0).
    pub fn rotation_fixed(&self) -> bool {
        self.sigma_rot_rad
            .is_some_and(|s| s.iter().all(|&v| v == 0.0))
    }
}

/// A prior file: one [`ExtrinsicPrior`] per section.
#[derive(Debug, Clone, PartialEq)]
pub struct PriorFile {
    path: PathBuf,
    text: String,
    sections: BTreeMap<SectionName, ExtrinsicPrior>,
}

impl PriorFile {
    /// Reads `path`.
    pub fn read(path: impl AsRef<Path>) -> Result<Self, PriorError> {
        let path = path.as_ref();
        let text = super::csv::read_text(path)?;
        Self::parse(path, &text)
    }

    /// Parses prior YAML `text`; `path` names the file in errors.
    pub fn parse(path: impl AsRef<Path>, text: &str) -> Result<Self, PriorError> {
        let path = path.as_ref();
        let raw: BTreeMap<String, Option<RawPrior>> = if text.trim().is_empty() {
            BTreeMap::new()
        } else {
            parse_yaml(path, text)?
        };
        let mut file = Self {
            path: path.to_path_buf(),
            text: text.to_string(),
            sections: BTreeMap::new(),
        };
        for (name, raw) in raw {
            let section: SectionName = name.parse().map_err(|_| {
                file.invalid(&name, None, format!("`{name}` is not a section name"))
            })?;
            let prior = file.convert(&name, section, &raw.unwrap_or_default())?;
            file.sections.insert(section, prior);
        }
        Ok(file)
    }

    /// The file's path.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The prior of section `name`, if the file has it.
    pub fn get(&self, name: &SectionName) -> Option<&ExtrinsicPrior> {
        self.sections.get(name)
    }

    /// The sections of the file.
    pub fn sections(&self) -> impl Iterator<Item = (&SectionName, &ExtrinsicPrior)> {
        self.sections.iter()
    }

    /// A refusal naming the line of `section.key` (of `section` without a key).
    pub fn invalid(&self, section: &str, key: Option<&str>, message: String) -> PriorError {
        PriorError::Invalid {
            path: self.path.clone(),
            line: line_of(&self.text, section, key),
            message,
        }
    }

    fn convert(
        &self,
        name: &str,
        section: SectionName,
        raw: &RawPrior,
    ) -> Result<ExtrinsicPrior, PriorError> {
        let keys = section.keys().ok_or_else(|| {
            self.invalid(
                name,
                None,
                format!("{name} has no extrinsic to give a prior"),
            )
        })?;
        let transform = match raw.transform(keys.transform) {
            Some(m) => Some(
                isometry_from_matrix(&Matrix4::from_fn(|r, c| m[r][c])).map_err(|e| {
                    self.invalid(
                        name,
                        Some(keys.transform),
                        format!("{name}.{}: {e}", keys.transform),
                    )
                })?,
            ),
            None => None,
        };
        let sigmas = |key: &str, v: Option<[f64; 3]>| -> Result<_, PriorError> {
            match v {
                Some(s) if s.iter().any(|x| !(x.is_finite() && *x >= 0.0)) => Err(self.invalid(
                    name,
                    Some(key),
                    format!("{name}.{key}: a sigma must be finite and >= 0 (0 fixes the DoF)"),
                )),
                Some(_) if transform.is_none() => Err(self.invalid(
                    name,
                    Some(key),
                    format!(
                        "{name}.{key}: a sigma needs the prior value `{}`",
                        keys.transform
                    ),
                )),
                other => Ok(other.map(Vector3::from)),
            }
        };
        let sigma_rot_deg = sigmas("sigma_rot_deg", raw.sigma_rot_deg)?;
        let sigma_trans_m = sigmas("sigma_trans_m", raw.sigma_trans_m)?;
        let timeshift_s = keys.timeshift.and_then(|k| raw.timeshift(k));
        if let Some(s) = raw.sigma_timeshift_s {
            if !(s.is_finite() && s >= 0.0) || keys.timeshift.is_none() {
                return Err(self.invalid(
                    name,
                    Some("sigma_timeshift_s"),
                    format!("{name}.sigma_timeshift_s: must be finite and >= 0, in a section with a time shift"),
                ));
            }
        }
        Ok(ExtrinsicPrior {
            transform,
            sigma_rot_rad: sigma_rot_deg.map(|s| s.map(f64::to_radians)),
            sigma_trans_m,
            timeshift_s,
            sigma_timeshift_s: raw.sigma_timeshift_s,
        })
    }
}

/// 1-based line of `key` inside top-level `section` (of the section's line without a key;
/// 1 when not found).
fn line_of(text: &str, section: &str, key: Option<&str>) -> usize {
    let mut in_section = false;
    for (i, line) in text.lines().enumerate() {
        let top = !line.starts_with([' ', '\t', '#', '-']) && !line.trim().is_empty();
        if top {
            in_section = line.trim_end().trim_end_matches(':') == section
                || line.starts_with(&format!("{section}:"));
            if in_section && key.is_none() {
                return i + 1;
            }
        } else if in_section {
            if let Some(k) = key {
                if line.trim_start().starts_with(&format!("{k}:")) {
                    return i + 1;
                }
            }
        }
    }
    1
}

#[cfg(test)]
mod tests {
    use super::*;

    type TestResult = Result<(), Box<dyn std::error::Error>>;

    const GOOD: &str = "pose0:\n  T_imu_pose: [[1,0,0,0.1],[0,1,0,0.2],[0,0,1,0.3],[0,0,0,1]]\n  \
                        sigma_rot_deg: [2, 2, 2]\n  sigma_trans_m: [0, 0, 0]\n  \
                        timeshift_pose_imu: 0.004\n  sigma_timeshift_s: 0\n";

    #[test]
    fn a_prior_reads_values_and_sigmas() -> TestResult {
        let p = PriorFile::parse("prior.yaml", GOOD)?;
        let pose0 = p.get(&SectionName::POSE0).ok_or("pose0")?;
        let t = pose0.transform.ok_or("transform")?;
        assert_eq!(t.translation.vector, Vector3::new(0.1, 0.2, 0.3));
        assert!(pose0.translation_fixed() && !pose0.rotation_fixed());
        assert_eq!(pose0.timeshift_s, Some(0.004));
        assert_eq!(pose0.sigma_timeshift_s, Some(0.0));
        let s = pose0.sigma_rot_rad.ok_or("sigma")?;
        assert!((s.x - 2f64.to_radians()).abs() < 1e-15);
        Ok(())
    }

    #[test]
    fn bad_priors_name_file_and_line() {
        let cases = [
            (
                GOOD.replace("sigma_trans_m: [0, 0, 0]", "sigma_trans_m: [0, -1, 0]"),
                4,
                "sigma",
            ),
            (
                GOOD.replace("sigma_rot_deg", "sigma_rot"),
                3,
                "unknown field",
            ),
            (GOOD.replace("[0,0,1,0.3]", "[0,0,2,0.3]"), 2, "rotation"),
            (
                "pose0:\n  sigma_trans_m: [0, 0, 0]\n".to_string(),
                2,
                "needs the prior value",
            ),
            (
                "camera0:\n  sigma_timeshift_s: 0\n".to_string(),
                1,
                "not a section name",
            ),
        ];
        for (text, line, words) in cases {
            let err = PriorFile::parse("prior.yaml", &text)
                .err()
                .map(|e| e.to_string())
                .unwrap_or_default();
            assert!(
                err.starts_with(&format!("prior.yaml:{line}")) && err.contains(words),
                "{text}: {err}"
            );
        }
    }
}

//! The calibration result file (CONVENTIONS.md "Calibration result"), also
//! used for `groundtruth/extrinsics.yaml` with zero sigmas.
//!
//! Keys follow Kalibr's camchain-imucam where they overlap, so a Kalibr
//! `cam0` section (with intrinsics and other unknown keys) reads too. Only
//! sections present are written. Matrices are written as flow rows and
//! floats in their shortest exact form, readable by serde_yaml and PyYAML.

use std::path::Path;

use nalgebra::{
    Isometry3, Matrix3, Matrix4, Matrix6, Rotation3, Translation3, UnitQuaternion, Vector3,
};
use serde::Deserialize;

use super::error::DatasetError;
use super::yaml::{parse_yaml, write_text, yaml_float, yaml_float_list};

/// Largest deviation of a stored rotation block from orthonormality.
const ORTHONORMAL_TOLERANCE: f64 = 1e-3;
/// Largest deviation of the stored bottom row from `[0, 0, 0, 1]`.
const BOTTOM_ROW_TOLERANCE: f64 = 1e-6;

/// One extrinsic estimate: the transform named by its section's key, its
/// time offset and 1-sigma uncertainties.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ExtrinsicEstimate {
    /// The transform of the section's key (`T_imu_pose`, `T_imu_lidar`,
    /// `T_cam_imu` or `T_cam_lidar`).
    pub transform: Isometry3<f64>,
    /// `timeshift_*_imu` (s): a measurement stamped `t_S` was taken at IMU time
    /// `t_S + timeshift_s`. Not stored for `cam0_lidar0` (always 0 there).
    pub timeshift_s: f64,
    /// 1-sigma rotation uncertainty per axis (deg).
    pub sigma_rot_deg: Vector3<f64>,
    /// 1-sigma translation uncertainty per axis (m).
    pub sigma_trans_m: Vector3<f64>,
}

impl ExtrinsicEstimate {
    /// An estimate with zero sigmas (ground truth).
    pub fn exact(transform: Isometry3<f64>, timeshift_s: f64) -> Self {
        Self {
            transform,
            timeshift_s,
            sigma_rot_deg: Vector3::zeros(),
            sigma_trans_m: Vector3::zeros(),
        }
    }

    /// An estimate with the sigmas of a 6x6 covariance ordered `[rotation (rad, right
    /// perturbation); translation (m)]`, as the filters report it.
    pub fn from_covariance(
        transform: Isometry3<f64>,
        timeshift_s: f64,
        covariance: &Matrix6<f64>,
    ) -> Self {
        let sd = |i: usize| covariance[(i, i)].max(0.0).sqrt();
        Self {
            transform,
            timeshift_s,
            sigma_rot_deg: Vector3::new(sd(0), sd(1), sd(2)).map(f64::to_degrees),
            sigma_trans_m: Vector3::new(sd(3), sd(4), sd(5)),
        }
    }

    /// The 4x4 homogeneous matrix of [`ExtrinsicEstimate::transform`].
    pub fn matrix(&self) -> Matrix4<f64> {
        self.transform.to_homogeneous()
    }
}

/// The pose `cam0.T_world_cam` of a result file (a static camera in a world frame, as
/// `msreg calibrate prior-map` writes it and `groundtruth/extrinsics.yaml` gives it).
pub fn read_t_world_cam(path: &Path) -> Result<Isometry3<f64>, DatasetError> {
    #[derive(serde::Deserialize)]
    struct Cam0 {
        #[serde(rename = "T_world_cam")]
        t: [[f64; 4]; 4],
    }
    #[derive(serde::Deserialize)]
    struct File {
        cam0: Cam0,
    }
    let f: File = super::yaml::read_yaml(path)?;
    let m = Matrix4::from_fn(|i, j| f.cam0.t[i][j]);
    isometry_from_matrix(&m).map_err(|e| DatasetError::InvalidValue {
        path: path.to_path_buf(),
        message: format!("cam0.T_world_cam: {e}"),
    })
}

/// Why a 4x4 matrix is not a rigid transform.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum NotRigid {
    /// An entry is NaN or infinite.
    #[error("matrix has a non-finite entry")]
    NonFinite,
    /// The bottom row is not `[0, 0, 0, 1]`.
    #[error("bottom row is [{}, {}, {}, {}], not [0, 0, 0, 1]", .0[0], .0[1], .0[2], .0[3])]
    BottomRow([f64; 4]),
    /// The 3x3 block is not orthonormal with determinant +1.
    #[error("rotation block is not a rotation (|R^T R - I|max = {deviation:.3e}, det = {determinant:.6})")]
    NotRotation {
        /// Largest entry of `R^T R - I`.
        deviation: f64,
        /// `det R`.
        determinant: f64,
    },
}

/// A homogeneous 4x4 matrix as a rigid transform: the bottom row must be
/// `[0, 0, 0, 1]` and the rotation block orthonormal (within 1e-3, then
/// projected onto SO(3)) with determinant +1.
pub fn isometry_from_matrix(m: &Matrix4<f64>) -> Result<Isometry3<f64>, NotRigid> {
    if m.iter().any(|v| !v.is_finite()) {
        return Err(NotRigid::NonFinite);
    }
    let bottom = m.fixed_view::<1, 4>(3, 0) - nalgebra::RowVector4::new(0.0, 0.0, 0.0, 1.0);
    if bottom.amax() > BOTTOM_ROW_TOLERANCE {
        return Err(NotRigid::BottomRow([
            m[(3, 0)],
            m[(3, 1)],
            m[(3, 2)],
            m[(3, 3)],
        ]));
    }
    let r: Matrix3<f64> = m.fixed_view::<3, 3>(0, 0).into_owned();
    let deviation = (r.transpose() * r - Matrix3::identity()).amax();
    if deviation > ORTHONORMAL_TOLERANCE || r.determinant() <= 0.0 {
        return Err(NotRigid::NotRotation {
            deviation,
            determinant: r.determinant(),
        });
    }
    let guess = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(r));
    let rotation = UnitQuaternion::from_matrix_eps(&r, 1e-15, 20, guess);
    let translation = Vector3::new(m[(0, 3)], m[(1, 3)], m[(2, 3)]);
    Ok(Isometry3::from_parts(
        Translation3::from(translation),
        rotation,
    ))
}

/// The whole result file; `None` sections are neither written nor required.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct CalibrationResult {
    /// `cam0`: `T_cam_imu`, `timeshift_cam_imu`.
    pub cam0: Option<ExtrinsicEstimate>,
    /// `lidar0`: `T_imu_lidar`, `timeshift_lidar_imu`.
    pub lidar0: Option<ExtrinsicEstimate>,
    /// `pose0`: `T_imu_pose`, `timeshift_pose_imu`.
    pub pose0: Option<ExtrinsicEstimate>,
    /// `cam0_lidar0`: `T_cam_lidar` (no time shift).
    pub cam0_lidar0: Option<ExtrinsicEstimate>,
}

/// Key names of one section.
struct Section {
    name: &'static str,
    transform_key: &'static str,
    timeshift_key: Option<&'static str>,
    meaning: &'static str,
}

const CAM0: Section = Section {
    name: "cam0",
    transform_key: "T_cam_imu",
    timeshift_key: Some("timeshift_cam_imu"),
    meaning: "p_cam = T_cam_imu * p_imu",
};
const LIDAR0: Section = Section {
    name: "lidar0",
    transform_key: "T_imu_lidar",
    timeshift_key: Some("timeshift_lidar_imu"),
    meaning: "p_imu = T_imu_lidar * p_lidar",
};
const POSE0: Section = Section {
    name: "pose0",
    transform_key: "T_imu_pose",
    timeshift_key: Some("timeshift_pose_imu"),
    meaning: "p_imu = T_imu_pose * p_pose",
};
const CAM0_LIDAR0: Section = Section {
    name: "cam0_lidar0",
    transform_key: "T_cam_lidar",
    timeshift_key: None,
    meaning: "p_cam = T_cam_lidar * p_lidar",
};

impl CalibrationResult {
    /// True when no section is present.
    pub fn is_empty(&self) -> bool {
        self.sections().iter().all(|(_, s)| s.is_none())
    }

    /// Reads a result file (or `groundtruth/extrinsics.yaml`).
    pub fn read(path: impl AsRef<Path>) -> Result<Self, DatasetError> {
        let path = path.as_ref();
        let text = super::csv::read_text(path)?;
        Self::parse(path, &text)
    }

    /// Parses result YAML `text`; `path` is only used in error messages.
    pub fn parse(path: impl AsRef<Path>, text: &str) -> Result<Self, DatasetError> {
        let path = path.as_ref();
        if text.trim().is_empty() {
            return Ok(Self::default());
        }
        let raw: RawFile = parse_yaml(path, text)?;
        let convert = |section: &Section, raw: Option<RawSection>| {
            raw.map(|r| r.into_estimate(path, section)).transpose()
        };
        Ok(Self {
            cam0: convert(&CAM0, raw.cam0.map(RawSection::from))?,
            lidar0: convert(&LIDAR0, raw.lidar0.map(RawSection::from))?,
            pose0: convert(&POSE0, raw.pose0.map(RawSection::from))?,
            cam0_lidar0: convert(&CAM0_LIDAR0, raw.cam0_lidar0.map(RawSection::from))?,
        })
    }

    /// Writes the sections present.
    pub fn write(&self, path: impl AsRef<Path>) -> Result<(), DatasetError> {
        write_text(path.as_ref(), &self.to_yaml_string())
    }

    /// The YAML text [`CalibrationResult::write`] writes.
    pub fn to_yaml_string(&self) -> String {
        let mut text = String::from(
            "# msreg calibration result; T_a_b is the pose of b in a (p_a = T_a_b * p_b),\n\
             # timeshift_s_imu: a measurement stamped t_s was taken at IMU time t_s + timeshift\n",
        );
        for (section, estimate) in self.sections() {
            if let Some(estimate) = estimate {
                text.push_str(&section_text(section, estimate));
            }
        }
        text
    }

    fn sections(&self) -> [(&'static Section, &Option<ExtrinsicEstimate>); 4] {
        [
            (&CAM0, &self.cam0),
            (&LIDAR0, &self.lidar0),
            (&POSE0, &self.pose0),
            (&CAM0_LIDAR0, &self.cam0_lidar0),
        ]
    }
}

fn section_text(section: &Section, estimate: &ExtrinsicEstimate) -> String {
    let m = estimate.matrix();
    let mut text = format!(
        "{}:\n  {}:  # {}\n",
        section.name, section.transform_key, section.meaning
    );
    for row in 0..4 {
        let values: Vec<f64> = (0..4).map(|col| m[(row, col)]).collect();
        text.push_str(&format!("    - {}\n", yaml_float_list(&values)));
    }
    if let Some(key) = section.timeshift_key {
        text.push_str(&format!(
            "  {key}: {}  # seconds\n",
            yaml_float(estimate.timeshift_s)
        ));
    }
    text.push_str(&format!(
        "  sigma_rot_deg: {}\n  sigma_trans_m: {}\n",
        yaml_float_list(estimate.sigma_rot_deg.as_slice()),
        yaml_float_list(estimate.sigma_trans_m.as_slice())
    ));
    text
}

/// A section as stored, before validation.
struct RawSection {
    matrix: [[f64; 4]; 4],
    timeshift_s: f64,
    sigma_rot_deg: [f64; 3],
    sigma_trans_m: [f64; 3],
}

impl RawSection {
    fn into_estimate(
        self,
        path: &Path,
        section: &Section,
    ) -> Result<ExtrinsicEstimate, DatasetError> {
        let invalid = |e: NotRigid| DatasetError::InvalidValue {
            path: path.to_path_buf(),
            message: format!("{}.{}: {e}", section.name, section.transform_key),
        };
        let m = Matrix4::from_fn(|r, c| self.matrix[r][c]);
        let transform = isometry_from_matrix(&m).map_err(invalid)?;
        let scalars = self
            .sigma_rot_deg
            .iter()
            .chain(&self.sigma_trans_m)
            .chain(std::iter::once(&self.timeshift_s));
        if scalars.into_iter().any(|v| !v.is_finite()) {
            return Err(DatasetError::InvalidValue {
                path: path.to_path_buf(),
                message: format!("{}: timeshift or sigma is not finite", section.name),
            });
        }
        Ok(ExtrinsicEstimate {
            transform,
            timeshift_s: self.timeshift_s,
            sigma_rot_deg: Vector3::from(self.sigma_rot_deg),
            sigma_trans_m: Vector3::from(self.sigma_trans_m),
        })
    }
}

#[derive(Deserialize)]
struct RawFile {
    #[serde(default)]
    cam0: Option<RawCam0>,
    #[serde(default)]
    lidar0: Option<RawLidar0>,
    #[serde(default)]
    pose0: Option<RawPose0>,
    #[serde(default)]
    cam0_lidar0: Option<RawCam0Lidar0>,
}

/// Declares the serde shape of one section and its conversion to [`RawSection`].
macro_rules! raw_section {
    ($name:ident, $transform:literal, $timeshift:literal) => {
        #[derive(Deserialize)]
        struct $name {
            #[serde(rename = $transform)]
            matrix: [[f64; 4]; 4],
            #[serde(rename = $timeshift, default)]
            timeshift_s: f64,
            #[serde(default)]
            sigma_rot_deg: [f64; 3],
            #[serde(default)]
            sigma_trans_m: [f64; 3],
        }

        impl From<$name> for RawSection {
            fn from(raw: $name) -> Self {
                RawSection {
                    matrix: raw.matrix,
                    timeshift_s: raw.timeshift_s,
                    sigma_rot_deg: raw.sigma_rot_deg,
                    sigma_trans_m: raw.sigma_trans_m,
                }
            }
        }
    };
}

raw_section!(RawCam0, "T_cam_imu", "timeshift_cam_imu");
raw_section!(RawLidar0, "T_imu_lidar", "timeshift_lidar_imu");
raw_section!(RawPose0, "T_imu_pose", "timeshift_pose_imu");

/// `cam0_lidar0` has no time shift.
#[derive(Deserialize)]
struct RawCam0Lidar0 {
    #[serde(rename = "T_cam_lidar")]
    matrix: [[f64; 4]; 4],
    #[serde(default)]
    sigma_rot_deg: [f64; 3],
    #[serde(default)]
    sigma_trans_m: [f64; 3],
}

impl From<RawCam0Lidar0> for RawSection {
    fn from(raw: RawCam0Lidar0) -> Self {
        RawSection {
            matrix: raw.matrix,
            timeshift_s: 0.0,
            sigma_rot_deg: raw.sigma_rot_deg,
            sigma_trans_m: raw.sigma_trans_m,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    type TestResult = Result<(), Box<dyn std::error::Error>>;

    fn pose(roll: f64, x: f64) -> Isometry3<f64> {
        Isometry3::from_parts(
            Translation3::new(x, -0.2, 0.05),
            UnitQuaternion::from_euler_angles(roll, 0.1, -2.0),
        )
    }

    fn isometry_distance(a: &Isometry3<f64>, b: &Isometry3<f64>) -> f64 {
        let d = a.inverse() * b;
        d.rotation.angle() + d.translation.vector.norm()
    }

    #[test]
    fn only_present_sections_are_written_and_read_back() -> TestResult {
        let dir = tempfile::tempdir()?;
        let path = dir.path().join("result.yaml");
        let result = CalibrationResult {
            pose0: Some(ExtrinsicEstimate {
                transform: pose(3.1, 0.25),
                timeshift_s: -0.0125,
                sigma_rot_deg: Vector3::new(0.1, 0.2, 0.3),
                sigma_trans_m: Vector3::new(1e-3, 2e-3, 3e-3),
            }),
            cam0_lidar0: Some(ExtrinsicEstimate::exact(pose(0.2, -0.1), 0.0)),
            ..CalibrationResult::default()
        };
        result.write(&path)?;
        let text = std::fs::read_to_string(&path)?;
        assert!(text.contains("T_imu_pose"));
        assert!(text.contains("timeshift_pose_imu: -0.0125"));
        assert!(
            !text.lines().any(|l| l == "cam0:" || l == "lidar0:"),
            "{text}"
        );
        assert!(!text.contains("timeshift_cam"));

        let read = CalibrationResult::read(&path)?;
        assert!(read.cam0.is_none() && read.lidar0.is_none());
        let (a, b) = (read.pose0.ok_or("pose0")?, result.pose0.ok_or("pose0")?);
        assert!(isometry_distance(&a.transform, &b.transform) < 1e-14);
        assert_eq!(a.timeshift_s.to_bits(), b.timeshift_s.to_bits());
        assert_eq!(a.sigma_rot_deg, b.sigma_rot_deg);
        assert_eq!(a.sigma_trans_m, b.sigma_trans_m);
        let c = read.cam0_lidar0.ok_or("cam0_lidar0")?;
        assert!(isometry_distance(&c.transform, &pose(0.2, -0.1)) < 1e-14);
        Ok(())
    }

    #[test]
    fn kalibr_camchain_imucam_section_is_read() -> TestResult {
        let text = "cam0:\n  T_cam_imu:\n  - [0.0148655429818, -0.999880929698, 0.00414029679422, -0.0216401454975]\n  \
                    - [0.999557249008, 0.0149672133247, 0.025715529948, -0.064676986768]\n  \
                    - [-0.0257744366974, 0.00375618835797, 0.999660727178, 0.00981073058949]\n  \
                    - [0.0, 0.0, 0.0, 1.0]\n  camera_model: pinhole\n  intrinsics: [458.6, 457.3, 367.2, 248.3]\n  \
                    timeshift_cam_imu: 5.0e-03\n";
        let read = CalibrationResult::parse("camchain.yaml", text)?;
        let cam0 = read.cam0.ok_or("cam0 missing")?;
        assert!((cam0.timeshift_s - 0.005).abs() < 1e-18);
        assert!((cam0.transform.translation.vector.x + 0.0216401454975).abs() < 1e-15);
        assert!(cam0.sigma_rot_deg.iter().all(|&s| s.abs() < f64::EPSILON));
        Ok(())
    }

    #[test]
    fn bad_result_files_are_rejected_with_location() -> TestResult {
        let not_rigid = "pose0:\n  T_imu_pose: [[2,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]\n";
        let err = CalibrationResult::parse("r.yaml", not_rigid)
            .err()
            .ok_or("expected an error")?;
        assert!(matches!(err, DatasetError::InvalidValue { .. }), "{err}");
        assert!(err.to_string().contains("pose0.T_imu_pose"), "{err}");

        let reflection = "lidar0:\n  T_imu_lidar: [[-1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]\n";
        assert!(CalibrationResult::parse("r.yaml", reflection).is_err());

        let short_row = "lidar0:\n  T_imu_lidar: [[1,0,0,0],[0,1,0],[0,0,1,0],[0,0,0,1]]\n";
        let err = CalibrationResult::parse("r.yaml", short_row)
            .err()
            .ok_or("expected an error")?;
        assert!(
            matches!(err, DatasetError::Yaml { line: Some(2), .. }),
            "{err}"
        );

        let dir = tempfile::tempdir()?;
        let err = CalibrationResult::read(dir.path().join("none.yaml"))
            .err()
            .ok_or("expected an error")?;
        assert!(matches!(err, DatasetError::MissingFile { .. }));
        Ok(())
    }

    #[test]
    fn slightly_non_orthonormal_matrix_is_projected() -> TestResult {
        let rounded = "pose0:\n  T_imu_pose: [[0.7071, -0.7071, 0, 1], [0.7071, 0.7071, 0, 2], [0, 0, 1, 3], [0, 0, 0, 1]]\n";
        let read = CalibrationResult::parse("r.yaml", rounded)?;
        let pose0 = read.pose0.ok_or("pose0")?;
        let angle = pose0.transform.rotation.angle();
        assert!(
            (angle - std::f64::consts::FRAC_PI_4).abs() < 1e-4,
            "{angle}"
        );
        Ok(())
    }
}

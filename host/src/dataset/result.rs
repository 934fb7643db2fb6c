//! The calibration result file (docs/formats.md "Result file"), also used for
//! `groundtruth/extrinsics.yaml` with zero sigmas: one section per sensor or sensor pair
//! of any rig, read and written by one type.
//!
//! A section is named by [`SectionName`]: `camN`, `lidarN`, `poseN`, `imuN` (sensors) or
//! `camN_lidarM` (pairs). Each holds, as present:
//! - its extrinsic under the key of its kind ([`SectionName::keys`]): `camN.T_cam_imu`
//!   (against the reference IMU `imu0`), `lidarN.T_imu_lidar`, `poseN.T_imu_pose`,
//!   `imuN.T_imu0_imu` (N >= 1), `camN_lidarM.T_cam_lidar`, with its time shift and
//!   `sigma_rot_deg` / `sigma_trans_m`;
//! - for `camN` with N >= 1, Kalibr's camera chain `T_cn_cnm1` (p_camN = T_cn_cnm1 *
//!   p_cam(N-1)) with `sigma_rot_deg_cn_cnm1` / `sigma_trans_m_cn_cnm1`;
//! - for cameras, the intrinsics in Kalibr's camchain keys ([`CameraIntrinsics`]);
//! - `held: [...]`, the degrees of freedom held at their prior ([`Dof`]).
//!
//! Keys follow Kalibr's camchain-imucam where they overlap, so a Kalibr camchain (with
//! `rostopic`, `cam_overlaps`) reads too. Keys neither this type nor Kalibr knows are kept
//! by name in [`CalibrationResult::unknown_keys`] for the caller to warn about. Only
//! sections present are written. Matrices are written as flow rows and floats in their
//! shortest exact form, readable by serde_yaml and PyYAML.

mod names;
mod raw;

pub use names::{BadName, Dof, ExtrinsicKeys, SectionName, SensorId, SensorKind};

use std::collections::BTreeMap;
use std::path::Path;

use super::error::DatasetError;
use super::yaml::{write_text, yaml_float, yaml_float_list, yaml_string};
use nalgebra::{
    Isometry3, Matrix3, Matrix4, Matrix6, Rotation3, Translation3, UnitQuaternion, Vector3,
};

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

/// A camera's intrinsics in Kalibr's camchain keys.
#[derive(Debug, Clone, PartialEq)]
pub struct CameraIntrinsics {
    /// `camera_model`: `pinhole`, `omni`, `ds`, `eucm`.
    pub camera_model: String,
    /// `intrinsics`: the projection parameters of the model (`[fu, fv, pu, pv]` for
    /// pinhole; `[xi, fu, fv, pu, pv]` for omni; `[xi, alpha, fu, fv, pu, pv]` for ds;
    /// `[alpha, beta, fu, fv, pu, pv]` for eucm).
    pub intrinsics: Vec<f64>,
    /// `distortion_model`: `radtan`, `equidistant` or `none`.
    pub distortion_model: String,
    /// `distortion_coeffs`.
    pub distortion_coeffs: Vec<f64>,
    /// `resolution`: `[width, height]` in pixels.
    pub resolution: [u32; 2],
    /// `sigma_intrinsics`: 1-sigma of `intrinsics` then `distortion_coeffs`, in that order;
    /// empty where no uncertainty is known.
    pub sigma_intrinsics: Vec<f64>,
}

/// One section of the result file; every part is optional.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ResultSection {
    /// The section's extrinsic (the key of its kind, [`SectionName::keys`]).
    pub extrinsic: Option<ExtrinsicEstimate>,
    /// `T_cn_cnm1` of a camera N >= 1 (its `timeshift_s` is unused and 0).
    pub camera_chain: Option<ExtrinsicEstimate>,
    /// A camera's intrinsics.
    pub intrinsics: Option<CameraIntrinsics>,
    /// `held`: the degrees of freedom held at their prior, in [`Dof`] order.
    pub held: Vec<Dof>,
}

impl ResultSection {
    /// True when the section holds nothing to write.
    pub fn is_empty(&self) -> bool {
        self.extrinsic.is_none()
            && self.camera_chain.is_none()
            && self.intrinsics.is_none()
            && self.held.is_empty()
    }

    /// Marks every one of `dofs` as held.
    pub fn hold_all(&mut self, dofs: impl IntoIterator<Item = Dof>) {
        for dof in dofs {
            self.hold(dof);
        }
    }

    /// Marks `dof` as held (kept sorted and unique).
    pub fn hold(&mut self, dof: Dof) {
        if let Err(at) = self.held.binary_search(&dof) {
            self.held.insert(at, dof);
        }
    }
}

/// The whole result file: any number of sections, in [`SectionName`] order.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct CalibrationResult {
    sections: BTreeMap<SectionName, ResultSection>,
    unknown_keys: Vec<String>,
}

impl CalibrationResult {
    /// An empty result.
    pub fn new() -> Self {
        Self::default()
    }

    /// A result with one extrinsic section.
    pub fn with_extrinsic(mut self, name: SectionName, estimate: ExtrinsicEstimate) -> Self {
        self.set_extrinsic(name, estimate);
        self
    }

    /// True when no section holds anything.
    pub fn is_empty(&self) -> bool {
        self.sections.values().all(ResultSection::is_empty)
    }

    /// The extrinsic of section `name`, if present.
    pub fn extrinsic(&self, name: &SectionName) -> Option<&ExtrinsicEstimate> {
        self.sections.get(name)?.extrinsic.as_ref()
    }

    /// The extrinsic of the section named `name` (`"pose1"`); `None` for an absent section
    /// or a string that is no section name.
    pub fn get(&self, name: &str) -> Option<&ExtrinsicEstimate> {
        self.extrinsic(&name.parse().ok()?)
    }

    /// Sets (replaces) the extrinsic of section `name`.
    pub fn set_extrinsic(&mut self, name: SectionName, estimate: ExtrinsicEstimate) {
        self.section_mut(name).extrinsic = Some(estimate);
    }

    /// Section `name`, if present.
    pub fn section(&self, name: &SectionName) -> Option<&ResultSection> {
        self.sections.get(name)
    }

    /// Section `name`, created empty if absent.
    pub fn section_mut(&mut self, name: SectionName) -> &mut ResultSection {
        self.sections.entry(name).or_default()
    }

    /// Every section, in file order.
    pub fn sections(&self) -> impl Iterator<Item = (&SectionName, &ResultSection)> {
        self.sections.iter()
    }

    /// The names of the sections that hold an extrinsic, in file order.
    pub fn extrinsic_names(&self) -> impl Iterator<Item = SectionName> + '_ {
        self.sections
            .iter()
            .filter(|(_, s)| s.extrinsic.is_some())
            .map(|(n, _)| *n)
    }

    /// Keys of the file read that no msreg or Kalibr section knows (`cam0.distortion_coefs`,
    /// or a top-level `camera0`), for the caller to warn about by name.
    pub fn unknown_keys(&self) -> &[String] {
        &self.unknown_keys
    }

    /// Reads a result file (or `groundtruth/extrinsics.yaml`).
    pub fn read(path: impl AsRef<Path>) -> Result<Self, DatasetError> {
        let path = path.as_ref();
        let text = super::csv::read_text(path)?;
        Self::parse(path, &text)
    }

    /// Parses result YAML `text`; `path` is only used in error messages.
    pub fn parse(path: impl AsRef<Path>, text: &str) -> Result<Self, DatasetError> {
        raw::parse(path.as_ref(), text)
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
        for (name, section) in self.sections.iter().filter(|(_, s)| !s.is_empty()) {
            text.push_str(&section_text(name, section));
        }
        text
    }
}

fn section_text(name: &SectionName, section: &ResultSection) -> String {
    let mut text = format!("{name}:\n");
    if let (Some(estimate), Some(keys)) = (&section.extrinsic, name.keys()) {
        push_transform(&mut text, keys.transform, keys.meaning, estimate);
        if let Some(key) = keys.timeshift {
            text.push_str(&format!(
                "  {key}: {}  # seconds\n",
                yaml_float(estimate.timeshift_s)
            ));
        }
        push_sigmas(&mut text, estimate, "");
    }
    if let Some(chain) = &section.camera_chain {
        let meaning = "p_camN = T_cn_cnm1 * p_cam(N-1)";
        push_transform(&mut text, "T_cn_cnm1", meaning, chain);
        push_sigmas(&mut text, chain, "_cn_cnm1");
    }
    if let Some(k) = &section.intrinsics {
        text.push_str(&format!(
            "  camera_model: {}\n  intrinsics: {}\n  distortion_model: {}\n  \
             distortion_coeffs: {}\n  resolution: [{}, {}]\n",
            yaml_string(&k.camera_model),
            yaml_float_list(&k.intrinsics),
            yaml_string(&k.distortion_model),
            yaml_float_list(&k.distortion_coeffs),
            k.resolution[0],
            k.resolution[1]
        ));
        if !k.sigma_intrinsics.is_empty() {
            let list = yaml_float_list(&k.sigma_intrinsics);
            text.push_str(&format!("  sigma_intrinsics: {list}\n"));
        }
    }
    if !section.held.is_empty() {
        let held: Vec<&str> = section.held.iter().map(|d| d.as_str()).collect();
        text.push_str(&format!(
            "  held: [{}]  # at their prior: not determined by the data\n",
            held.join(", ")
        ));
    }
    text
}

fn push_transform(text: &mut String, key: &str, meaning: &str, estimate: &ExtrinsicEstimate) {
    let m = estimate.matrix();
    text.push_str(&format!("  {key}:  # {meaning}\n"));
    for row in 0..4 {
        let values: Vec<f64> = (0..4).map(|col| m[(row, col)]).collect();
        text.push_str(&format!("    - {}\n", yaml_float_list(&values)));
    }
}

fn push_sigmas(text: &mut String, estimate: &ExtrinsicEstimate, suffix: &str) {
    text.push_str(&format!(
        "  sigma_rot_deg{suffix}: {}\n  sigma_trans_m{suffix}: {}\n",
        yaml_float_list(estimate.sigma_rot_deg.as_slice()),
        yaml_float_list(estimate.sigma_trans_m.as_slice())
    ));
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
        let pose0 = ExtrinsicEstimate {
            transform: pose(3.1, 0.25),
            timeshift_s: -0.0125,
            sigma_rot_deg: Vector3::new(0.1, 0.2, 0.3),
            sigma_trans_m: Vector3::new(1e-3, 2e-3, 3e-3),
        };
        let result = CalibrationResult::new()
            .with_extrinsic(SectionName::POSE0, pose0)
            .with_extrinsic(
                SectionName::CAM0_LIDAR0,
                ExtrinsicEstimate::exact(pose(0.2, -0.1), 0.0),
            );
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
        assert!(read.get("cam0").is_none() && read.get("lidar0").is_none());
        let (a, b) = (read.get("pose0").ok_or("pose0")?, &pose0);
        assert!(isometry_distance(&a.transform, &b.transform) < 1e-14);
        assert_eq!(a.timeshift_s.to_bits(), b.timeshift_s.to_bits());
        assert_eq!(a.sigma_rot_deg, b.sigma_rot_deg);
        assert_eq!(a.sigma_trans_m, b.sigma_trans_m);
        let c = read.get("cam0_lidar0").ok_or("cam0_lidar0")?;
        assert!(isometry_distance(&c.transform, &pose(0.2, -0.1)) < 1e-14);
        Ok(())
    }

    #[test]
    fn kalibr_camchain_imucam_section_is_read() -> TestResult {
        let text = "cam0:\n  T_cam_imu:\n  - [0.0148655429818, -0.999880929698, 0.00414029679422, -0.0216401454975]\n  \
                    - [0.999557249008, 0.0149672133247, 0.025715529948, -0.064676986768]\n  \
                    - [-0.0257744366974, 0.00375618835797, 0.999660727178, 0.00981073058949]\n  \
                    - [0.0, 0.0, 0.0, 1.0]\n  cam_overlaps: [1]\n  camera_model: pinhole\n  \
                    distortion_coeffs: [-0.28, 0.07, 0.0002, 1.8e-05]\n  distortion_model: radtan\n  \
                    intrinsics: [458.6, 457.3, 367.2, 248.3]\n  resolution: [752, 480]\n  \
                    rostopic: /cam0/image_raw\n  timeshift_cam_imu: 5.0e-03\n";
        let read = CalibrationResult::parse("camchain.yaml", text)?;
        let cam0 = read.get("cam0").ok_or("cam0 missing")?;
        assert!(read.unknown_keys().is_empty(), "{:?}", read.unknown_keys());
        assert!((cam0.timeshift_s - 0.005).abs() < 1e-18);
        assert!((cam0.transform.translation.vector.x + 0.0216401454975).abs() < 1e-15);
        assert!(cam0.sigma_rot_deg.iter().all(|&s| s.abs() < f64::EPSILON));
        let k = read
            .section(&SectionName::CAM0)
            .and_then(|s| s.intrinsics.as_ref());
        let k = k.ok_or("intrinsics")?;
        assert_eq!(
            (k.camera_model.as_str(), k.resolution),
            ("pinhole", [752, 480])
        );
        assert_eq!(k.distortion_coeffs.len(), 4);
        Ok(())
    }

    #[test]
    fn any_number_of_sensors_round_trip_with_chain_intrinsics_and_held() -> TestResult {
        let mut result = CalibrationResult::new();
        for (i, name) in ["cam0", "cam1", "lidar2", "pose1", "imu1", "cam1_lidar2"]
            .iter()
            .enumerate()
        {
            let e = ExtrinsicEstimate {
                transform: pose(0.1 * i as f64, 0.01 * i as f64),
                // camN_lidarM has no time shift (written and read as 0).
                timeshift_s: if name.contains('_') {
                    0.0
                } else {
                    1e-3 * i as f64
                },
                sigma_rot_deg: Vector3::new(0.1, 0.2, 0.3),
                sigma_trans_m: Vector3::new(1e-3, 2e-3, 3e-3),
            };
            result.set_extrinsic(name.parse()?, e);
        }
        let cam1 = result.section_mut(SectionName::cam(1));
        cam1.camera_chain = Some(ExtrinsicEstimate::exact(pose(0.01, 0.11), 0.0));
        cam1.intrinsics = Some(CameraIntrinsics {
            camera_model: "ds".into(),
            intrinsics: vec![-0.2, 0.6, 350.0, 351.0, 320.5, 240.25],
            distortion_model: "none".into(),
            distortion_coeffs: vec![],
            resolution: [640, 480],
            sigma_intrinsics: vec![0.01, 0.01, 0.5, 0.5, 0.3, 0.3],
        });
        result
            .section_mut(SectionName::pose(1))
            .hold(Dof::TranslationZ);
        result
            .section_mut(SectionName::pose(1))
            .hold(Dof::Timeshift);
        result
            .section_mut(SectionName::imu(0))
            .hold(Dof::Intrinsics);
        let text = result.to_yaml_string();
        let read = CalibrationResult::parse("r.yaml", &text)?;
        let close = |a: &Option<ExtrinsicEstimate>, b: &Option<ExtrinsicEstimate>| match (a, b) {
            (Some(a), Some(b)) => {
                isometry_distance(&a.transform, &b.transform) < 1e-14
                    && a.timeshift_s.to_bits() == b.timeshift_s.to_bits()
                    && (a.sigma_rot_deg, a.sigma_trans_m) == (b.sigma_rot_deg, b.sigma_trans_m)
            }
            (a, b) => a.is_none() && b.is_none(),
        };
        assert_eq!(read.sections().count(), result.sections().count(), "{text}");
        for ((na, a), (nb, b)) in read.sections().zip(result.sections()) {
            assert_eq!(na, nb);
            assert!(
                close(&a.extrinsic, &b.extrinsic) && close(&a.camera_chain, &b.camera_chain),
                "{na}"
            );
            assert_eq!((&a.intrinsics, &a.held), (&b.intrinsics, &b.held), "{na}");
        }
        assert!(
            text.contains("  held: [translation_z, timeshift]"),
            "{text}"
        );
        assert!(
            text.contains("T_imu0_imu") && text.contains("timeshift_imu_imu0"),
            "{text}"
        );
        let order: Vec<&str> = text
            .lines()
            .filter(|l| !l.starts_with([' ', '#']))
            .collect();
        assert_eq!(
            order,
            [
                "cam0:",
                "cam1:",
                "lidar2:",
                "pose1:",
                "imu0:",
                "imu1:",
                "cam1_lidar2:"
            ]
        );
        Ok(())
    }

    #[test]
    fn unknown_and_misplaced_keys_are_named() -> TestResult {
        let text = "cam0:\n  T_cam_imu: [[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]\n  \
                    distortion_coefs: [0.1]\ncamera1:\n  T_cam_imu: [[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]\n";
        let read = CalibrationResult::parse("r.yaml", text)?;
        assert_eq!(read.unknown_keys(), ["cam0.distortion_coefs", "camera1"]);
        let misplaced = "lidar1:\n  T_cam_imu: [[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]\n";
        let err = CalibrationResult::parse("r.yaml", misplaced)
            .err()
            .ok_or("expected an error")?;
        assert!(err.to_string().contains("lidar1: key `T_cam_imu`"), "{err}");
        let chain_on_cam0 = "cam0:\n  T_cn_cnm1: [[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]\n";
        assert!(CalibrationResult::parse("r.yaml", chain_on_cam0).is_err());
        let bad_held = "pose0:\n  held: [rotation_w]\n";
        let err = CalibrationResult::parse("r.yaml", bad_held)
            .err()
            .ok_or("expected an error")?;
        assert!(err.to_string().contains("rotation_w"), "{err}");
        let partial = "cam0:\n  camera_model: pinhole\n";
        assert!(CalibrationResult::parse("r.yaml", partial).is_err());
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
        let pose0 = read.get("pose0").ok_or("pose0")?;
        let angle = pose0.transform.rotation.angle();
        assert!(
            (angle - std::f64::consts::FRAC_PI_4).abs() < 1e-4,
            "{angle}"
        );
        Ok(())
    }
}

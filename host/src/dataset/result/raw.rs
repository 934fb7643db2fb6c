//! Reading a result file: every section as stored, then validated into
//! [`CalibrationResult`]. Two passes over the text: a typed one (errors carry the line and
//! column) and a key-name one (keys neither msreg nor Kalibr knows, kept for warnings).

use std::collections::BTreeMap;
use std::path::Path;

use nalgebra::{Matrix4, Vector3};
use serde::Deserialize;

use super::names::TRANSFORM_KEYS;
use super::{
    isometry_from_matrix, CalibrationResult, CameraIntrinsics, Dof, ExtrinsicEstimate,
    ResultSection, SectionName,
};
use crate::dataset::error::DatasetError;
use crate::dataset::yaml::parse_yaml;

type Matrix = [[f64; 4]; 4];

/// A section as stored: every key any section kind may carry.
#[derive(Deserialize, Default)]
struct RawSection {
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
    #[serde(rename = "T_cn_cnm1")]
    t_cn_cnm1: Option<Matrix>,
    timeshift_cam_imu: Option<f64>,
    timeshift_lidar_imu: Option<f64>,
    timeshift_pose_imu: Option<f64>,
    timeshift_imu_imu0: Option<f64>,
    sigma_rot_deg: Option<[f64; 3]>,
    sigma_trans_m: Option<[f64; 3]>,
    sigma_rot_deg_cn_cnm1: Option<[f64; 3]>,
    sigma_trans_m_cn_cnm1: Option<[f64; 3]>,
    camera_model: Option<String>,
    intrinsics: Option<Vec<f64>>,
    distortion_model: Option<String>,
    distortion_coeffs: Option<Vec<f64>>,
    resolution: Option<[u32; 2]>,
    sigma_intrinsics: Option<Vec<f64>>,
    held: Option<Vec<String>>,
}

/// Keys a section may carry besides the fields of [`RawSection`]: Kalibr's camchain keys
/// and the static camera pose of `msreg calibrate prior-map` (read by
/// [`super::read_t_world_cam`]).
const OTHER_KNOWN_KEYS: [&str; 3] = ["rostopic", "cam_overlaps", "T_world_cam"];

/// The field names of [`RawSection`] (keep in step with it).
const RAW_KEYS: [&str; 21] = [
    "T_cam_imu",
    "T_imu_lidar",
    "T_imu_pose",
    "T_imu0_imu",
    "T_cam_lidar",
    "T_cn_cnm1",
    "timeshift_cam_imu",
    "timeshift_lidar_imu",
    "timeshift_pose_imu",
    "timeshift_imu_imu0",
    "sigma_rot_deg",
    "sigma_trans_m",
    "sigma_rot_deg_cn_cnm1",
    "sigma_trans_m_cn_cnm1",
    "camera_model",
    "intrinsics",
    "distortion_model",
    "distortion_coeffs",
    "resolution",
    "sigma_intrinsics",
    "held",
];

impl RawSection {
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

/// Parses result YAML `text` that came from `path`.
pub(super) fn parse(path: &Path, text: &str) -> Result<CalibrationResult, DatasetError> {
    if text.trim().is_empty() {
        return Ok(CalibrationResult::default());
    }
    let raw: BTreeMap<String, Option<RawSection>> = parse_yaml(path, text)?;
    let keys: BTreeMap<String, Option<BTreeMap<String, serde_yaml::Value>>> =
        parse_yaml(path, text)?;
    let mut result = CalibrationResult::default();
    for (name, section) in raw {
        let Ok(section_name) = name.parse::<SectionName>() else {
            result.unknown_keys.push(name);
            continue;
        };
        let section = section.unwrap_or_default();
        let converted = convert(path, &section_name, section)?;
        result.sections.insert(section_name, converted);
        let stored = keys.get(&name).cloned().flatten().unwrap_or_default();
        result.unknown_keys.extend(
            stored
                .keys()
                .filter(|k| {
                    !RAW_KEYS.contains(&k.as_str()) && !OTHER_KNOWN_KEYS.contains(&k.as_str())
                })
                .map(|k| format!("{name}.{k}")),
        );
    }
    Ok(result)
}

fn invalid(path: &Path, message: String) -> DatasetError {
    DatasetError::InvalidValue {
        path: path.to_path_buf(),
        message,
    }
}

fn convert(
    path: &Path,
    name: &SectionName,
    raw: RawSection,
) -> Result<ResultSection, DatasetError> {
    let own = name.keys();
    if let Some(misplaced) = TRANSFORM_KEYS
        .iter()
        .find(|k| raw.transform(k).is_some() && own.map(|o| o.transform) != Some(**k))
    {
        let expected = own.map_or("no transform (the reference IMU)".to_string(), |o| {
            format!("`{}`", o.transform)
        });
        return Err(invalid(
            path,
            format!(
                "{name}: key `{misplaced}` does not belong in this section (it takes {expected})"
            ),
        ));
    }
    if raw.t_cn_cnm1.is_some() && !name.has_camera_chain() {
        return Err(invalid(
            path,
            format!("{name}: `T_cn_cnm1` belongs in a camera section camN with N >= 1"),
        ));
    }
    let extrinsic = match own.and_then(|k| Some((k, raw.transform(k.transform)?))) {
        Some((keys, matrix)) => {
            let timeshift = keys.timeshift.and_then(|k| raw.timeshift(k)).unwrap_or(0.0);
            let sigmas = (raw.sigma_rot_deg, raw.sigma_trans_m);
            Some(estimate(
                path,
                name,
                keys.transform,
                matrix,
                timeshift,
                sigmas,
            )?)
        }
        None => None,
    };
    let camera_chain = match &raw.t_cn_cnm1 {
        Some(m) => {
            let sigmas = (raw.sigma_rot_deg_cn_cnm1, raw.sigma_trans_m_cn_cnm1);
            Some(estimate(path, name, "T_cn_cnm1", m, 0.0, sigmas)?)
        }
        None => None,
    };
    let held = held(path, name, raw.held.as_deref().unwrap_or_default())?;
    let intrinsics = intrinsics(path, name, raw)?;
    Ok(ResultSection {
        extrinsic,
        camera_chain,
        intrinsics,
        held,
    })
}

fn estimate(
    path: &Path,
    name: &SectionName,
    key: &str,
    matrix: &Matrix,
    timeshift_s: f64,
    (sigma_rot, sigma_trans): (Option<[f64; 3]>, Option<[f64; 3]>),
) -> Result<ExtrinsicEstimate, DatasetError> {
    let m = Matrix4::from_fn(|r, c| matrix[r][c]);
    let transform =
        isometry_from_matrix(&m).map_err(|e| invalid(path, format!("{name}.{key}: {e}")))?;
    let (sigma_rot, sigma_trans) = (
        sigma_rot.unwrap_or_default(),
        sigma_trans.unwrap_or_default(),
    );
    let scalars = sigma_rot.iter().chain(&sigma_trans).chain([&timeshift_s]);
    if scalars.into_iter().any(|v| !v.is_finite()) {
        return Err(invalid(
            path,
            format!("{name}: timeshift or sigma is not finite"),
        ));
    }
    Ok(ExtrinsicEstimate {
        transform,
        timeshift_s,
        sigma_rot_deg: Vector3::from(sigma_rot),
        sigma_trans_m: Vector3::from(sigma_trans),
    })
}

fn held(path: &Path, name: &SectionName, names: &[String]) -> Result<Vec<Dof>, DatasetError> {
    let mut held = Vec::new();
    for n in names {
        let dof: Dof = n
            .parse()
            .map_err(|e| invalid(path, format!("{name}.held: {e}")))?;
        if !held.contains(&dof) {
            held.push(dof);
        }
    }
    held.sort();
    Ok(held)
}

/// The intrinsics of a section: all of `camera_model`, `intrinsics`, `distortion_model`,
/// `distortion_coeffs` and `resolution`, or none (a Kalibr `camchain-imucam` without
/// intrinsics reads as extrinsics only).
fn intrinsics(
    path: &Path,
    name: &SectionName,
    raw: RawSection,
) -> Result<Option<CameraIntrinsics>, DatasetError> {
    let parts = (
        raw.camera_model,
        raw.intrinsics,
        raw.distortion_model,
        raw.distortion_coeffs,
        raw.resolution,
    );
    let (camera_model, intrinsics, distortion_model, distortion_coeffs, resolution) = match parts {
        (Some(a), Some(b), Some(c), Some(d), Some(e)) => (a, b, c, d, e),
        (None, None, None, None, None) => return Ok(None),
        _ => {
            return Err(invalid(
                path,
                format!(
                    "{name}: camera intrinsics need all of camera_model, intrinsics, \
                     distortion_model, distortion_coeffs and resolution"
                ),
            ))
        }
    };
    let sigma_intrinsics = raw.sigma_intrinsics.unwrap_or_default();
    let values = intrinsics
        .iter()
        .chain(&distortion_coeffs)
        .chain(&sigma_intrinsics);
    if values.into_iter().any(|v| !v.is_finite()) {
        return Err(invalid(
            path,
            format!("{name}: an intrinsic value is not finite"),
        ));
    }
    let expected = intrinsics.len() + distortion_coeffs.len();
    if !sigma_intrinsics.is_empty() && sigma_intrinsics.len() != expected {
        return Err(invalid(
            path,
            format!(
                "{name}: sigma_intrinsics has {} values, intrinsics + distortion_coeffs {expected}",
                sigma_intrinsics.len()
            ),
        ));
    }
    Ok(Some(CameraIntrinsics {
        camera_model,
        intrinsics,
        distortion_model,
        distortion_coeffs,
        resolution,
        sigma_intrinsics,
    }))
}

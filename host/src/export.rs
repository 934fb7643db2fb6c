//! Exports of a [`CalibrationResult`] to the files other tools read (docs/export.md).
//!
//! Every format states the direction of the transforms it writes:
//! - `kalibr`: `camchain-imucam.yaml` with `T_cam_imu` (p_cam = T_cam_imu * p_imu0) and
//!   `T_cn_cnm1`; `imu.yaml` with `T_i_b` (p_imuN = T_i_b * p_imu0) where IMUs beyond
//!   `imu0` are present;
//! - `openvins`: `kalibr_imucam_chain.yaml` with `T_imu_cam` (p_imu0 = T_imu_cam * p_cam,
//!   the inverse of Kalibr's) and `kalibr_imu_chain.yaml` with `T_i_b`;
//! - `vins-fusion`: `vins_config.yaml` with `body_T_camN` (p_imu0 = body_T_cam * p_cam) and
//!   one `camN_<model>.yaml` per camera;
//! - `urdf` and `tf`: the pose of every sensor frame in the parent `imu0`
//!   (p_imu0 = T_imu0_sensor * p_sensor), URDF `rpy` being R = Rz(yaw) Ry(pitch) Rx(roll).
//!
//! A format that needs a key the result lacks is an [`ExportError::MissingKey`] naming
//! it; nothing is defaulted.

mod kalibr;
mod text;
mod tf;
mod urdf;
mod vins;

use std::fmt;
use std::path::{Path, PathBuf};
use std::str::FromStr;

use nalgebra::Isometry3;

use crate::dataset::{CalibrationResult, SectionName, SensorKind};

/// A target tool's format.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ExportFormat {
    /// Kalibr camchain-imucam (+ imu chain).
    Kalibr,
    /// OpenVINS `kalibr_imucam_chain.yaml` (+ `kalibr_imu_chain.yaml`).
    OpenVins,
    /// VINS-Fusion config and per-camera files.
    VinsFusion,
    /// A URDF of fixed joints under `imu0`.
    Urdf,
    /// ROS 2 static transforms: command lines and a YAML list.
    Tf,
}

impl ExportFormat {
    /// Every format, by its CLI name.
    pub const ALL: [ExportFormat; 5] = [
        Self::Kalibr,
        Self::OpenVins,
        Self::VinsFusion,
        Self::Urdf,
        Self::Tf,
    ];

    /// The CLI name (`kalibr`, `openvins`, `vins-fusion`, `urdf`, `tf`).
    pub fn name(self) -> &'static str {
        match self {
            Self::Kalibr => "kalibr",
            Self::OpenVins => "openvins",
            Self::VinsFusion => "vins-fusion",
            Self::Urdf => "urdf",
            Self::Tf => "tf",
        }
    }
}

impl fmt::Display for ExportFormat {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for ExportFormat {
    type Err = ExportError;
    fn from_str(s: &str) -> Result<Self, ExportError> {
        Self::ALL
            .into_iter()
            .find(|f| f.name() == s)
            .ok_or_else(|| ExportError::UnknownFormat(s.to_string()))
    }
}

/// Why an export failed.
#[derive(Debug, thiserror::Error)]
pub enum ExportError {
    /// No such format.
    #[error("unknown export format `{0}` (kalibr, openvins, vins-fusion, urdf, tf)")]
    UnknownFormat(String),
    /// The format needs a key the result lacks.
    #[error("{format} export needs `{key}`, which the result lacks")]
    MissingKey {
        /// The format.
        format: ExportFormat,
        /// The missing key, `section.key`.
        key: String,
    },
    /// The result holds something the format cannot express.
    #[error("{format} export cannot express {what}")]
    Unsupported {
        /// The format.
        format: ExportFormat,
        /// What it cannot express.
        what: String,
    },
    /// Writing a file failed.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
}

/// One file of an export: its file name and text.
#[derive(Debug, Clone, PartialEq)]
pub struct ExportFile {
    /// File name (no directory).
    pub name: String,
    /// Contents.
    pub text: String,
}

/// The files of `result` in `format`, not written.
pub fn render(
    result: &CalibrationResult,
    format: ExportFormat,
) -> Result<Vec<ExportFile>, ExportError> {
    match format {
        ExportFormat::Kalibr => kalibr::kalibr(result),
        ExportFormat::OpenVins => kalibr::openvins(result),
        ExportFormat::VinsFusion => vins::render(result),
        ExportFormat::Urdf => urdf::render(result),
        ExportFormat::Tf => tf::render(result),
    }
}

/// Writes `result` in `format` to `out`: a file when the format has one file and `out`
/// is not a directory, else files in directory `out` (created). Returns the paths written.
pub fn write(
    result: &CalibrationResult,
    format: ExportFormat,
    out: &Path,
) -> Result<Vec<PathBuf>, ExportError> {
    let files = render(result, format)?;
    let io = |path: &Path| {
        let path = path.to_path_buf();
        move |source| ExportError::Io { path, source }
    };
    if files.len() == 1 && !out.is_dir() {
        std::fs::write(out, &files[0].text).map_err(io(out))?;
        return Ok(vec![out.to_path_buf()]);
    }
    std::fs::create_dir_all(out).map_err(io(out))?;
    let mut written = Vec::new();
    for file in files {
        let path = out.join(&file.name);
        std::fs::write(&path, &file.text).map_err(io(&path))?;
        written.push(path);
    }
    Ok(written)
}

/// A sensor's frame in `imu0`: p_imu0 = T * p_sensor, from its section's extrinsic.
/// `None` for `imu0` itself and camera-LiDAR pairs.
pub fn t_imu0_sensor(name: &SectionName, result: &CalibrationResult) -> Option<Isometry3<f64>> {
    let id = name.sensor_id()?;
    let t = result.extrinsic(name)?.transform;
    Some(match id.kind {
        SensorKind::Camera => t.inverse(),
        SensorKind::Lidar | SensorKind::Pose | SensorKind::Imu => t,
    })
}

/// `section.key` missing, for `format`.
fn missing(format: ExportFormat, name: &SectionName, key: &str) -> ExportError {
    ExportError::MissingKey {
        format,
        key: format!("{name}.{key}"),
    }
}

/// The sensor sections of `kind` present in `result`, in index order.
fn sensors(result: &CalibrationResult, kind: SensorKind) -> Vec<SectionName> {
    result
        .sections()
        .filter(|(n, _)| n.sensor_id().is_some_and(|id| id.kind == kind))
        .map(|(n, _)| *n)
        .collect()
}

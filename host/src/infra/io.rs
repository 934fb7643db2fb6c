//! Files of the infrastructure-camera dataset (docs/formats.md, section 2.9): `marker.yaml`, `infra/cameras.yaml`, `infra/<id>/markers.csv`,
//! `cam0/blobs.csv`, and the `infra:` result / ground-truth YAML. Errors name the file and
//! the 1-based line.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use msreg_estimator::camera::Camera;
use nalgebra::{Isometry3, Matrix4, Vector2, Vector3};
use serde::{Deserialize, Serialize};

use crate::camera_yaml::{camera_yaml_string, parse_camera_yaml};
use crate::dataset::isometry_from_matrix;

/// Errors reading or writing the dataset.
#[derive(Debug, thiserror::Error)]
pub enum InfraError {
    /// A file could not be read or written.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// A file's content is invalid (`line` 0: the file as a whole).
    #[error("{}:{line}: {message}", path.display())]
    Parse {
        /// The file.
        path: PathBuf,
        /// 1-based line, 0 when not line-specific.
        line: usize,
        /// What is wrong.
        message: String,
    },
}

fn io_err(path: &Path) -> impl FnOnce(std::io::Error) -> InfraError + '_ {
    move |source| InfraError::Io {
        path: path.to_path_buf(),
        source,
    }
}

fn parse_err(path: &Path, line: usize, message: impl Into<String>) -> InfraError {
    InfraError::Parse {
        path: path.to_path_buf(),
        line,
        message: message.into(),
    }
}

/// `marker.yaml`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct MarkerSpec {
    /// ArUco dictionary name.
    pub dictionary: String,
    /// Marker id on the robot.
    pub id: u32,
    /// Printed side, m.
    pub side_m: f64,
}

impl MarkerSpec {
    /// Corners in `M`, OpenCV ArUco order (SOLVEPNP_IPPE_SQUARE).
    pub fn corners_in_marker(&self) -> [Vector3<f64>; 4] {
        let h = self.side_m / 2.0;
        [
            Vector3::new(-h, h, 0.0),
            Vector3::new(h, h, 0.0),
            Vector3::new(h, -h, 0.0),
            Vector3::new(-h, -h, 0.0),
        ]
    }

    /// Reads `marker.yaml`.
    pub fn read(path: &Path) -> Result<Self, InfraError> {
        let text = std::fs::read_to_string(path).map_err(io_err(path))?;
        let spec: Self = serde_yaml::from_str(&text).map_err(|e| yaml_err(path, &e))?;
        if !(spec.side_m.is_finite() && spec.side_m > 0.0) {
            return Err(parse_err(path, 0, "side_m must be a positive number"));
        }
        Ok(spec)
    }
}

fn yaml_err(path: &Path, e: &serde_yaml::Error) -> InfraError {
    parse_err(path, e.location().map_or(0, |l| l.line()), e.to_string())
}

/// One marker detection: four corners, OpenCV order and pixels.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MarkerDetection {
    /// Camera stamp, ns.
    pub stamp_ns: u64,
    /// Decoded id.
    pub marker_id: u32,
    /// Corners (top-left, top-right, bottom-right, bottom-left of the printed marker).
    pub corners: [Vector2<f64>; 4],
}

/// One unlabelled bright blob in an `F` keyframe.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Blob {
    /// Stamp of the keyframe image, ns.
    pub stamp_ns: u64,
    /// Pixel.
    pub uv: Vector2<f64>,
}

fn csv_fields(
    path: &Path,
    line: usize,
    text: &str,
    n: usize,
) -> Result<(u64, Vec<f64>), InfraError> {
    let f: Vec<&str> = text.split(',').map(str::trim).collect();
    if f.len() != n + 1 {
        return Err(parse_err(
            path,
            line,
            format!("expected {} columns, got {}", n + 1, f.len()),
        ));
    }
    let stamp = f[0].parse::<u64>().map_err(|_| {
        parse_err(
            path,
            line,
            format!("timestamp `{}` is not integer ns", f[0]),
        )
    })?;
    let v = f[1..]
        .iter()
        .map(|s| {
            s.parse::<f64>()
                .ok()
                .filter(|x| x.is_finite())
                .ok_or_else(|| parse_err(path, line, format!("`{s}` is not a finite number")))
        })
        .collect::<Result<Vec<f64>, _>>()?;
    Ok((stamp, v))
}

fn csv_rows(path: &Path, n: usize) -> Result<Vec<(u64, Vec<f64>)>, InfraError> {
    let text = std::fs::read_to_string(path).map_err(io_err(path))?;
    text.lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty() && !l.trim_start().starts_with('#'))
        .map(|(i, l)| csv_fields(path, i + 1, l, n))
        .collect()
}

/// Reads `infra/<id>/markers.csv`.
pub fn read_markers_csv(path: &Path) -> Result<Vec<MarkerDetection>, InfraError> {
    csv_rows(path, 9)?
        .into_iter()
        .map(|(stamp_ns, v)| {
            let c = |i: usize| Vector2::new(v[1 + 2 * i], v[2 + 2 * i]);
            Ok(MarkerDetection {
                stamp_ns,
                marker_id: v[0] as u32,
                corners: [c(0), c(1), c(2), c(3)],
            })
        })
        .collect()
}

/// Writes `infra/<id>/markers.csv`.
pub fn write_markers_csv(path: &Path, detections: &[MarkerDetection]) -> Result<(), InfraError> {
    let mut s = String::from("#timestamp [ns],marker_id,u0,v0,u1,v1,u2,v2,u3,v3\n");
    for d in detections {
        let _ = write!(s, "{},{}", d.stamp_ns, d.marker_id);
        for c in &d.corners {
            let _ = write!(s, ",{},{}", c.x, c.y);
        }
        s.push('\n');
    }
    std::fs::write(path, s).map_err(io_err(path))
}

/// Reads `cam0/blobs.csv`.
pub fn read_blobs_csv(path: &Path) -> Result<Vec<Blob>, InfraError> {
    Ok(csv_rows(path, 2)?
        .into_iter()
        .map(|(stamp_ns, v)| Blob {
            stamp_ns,
            uv: Vector2::new(v[0], v[1]),
        })
        .collect())
}

/// Writes `cam0/blobs.csv`.
pub fn write_blobs_csv(path: &Path, blobs: &[Blob]) -> Result<(), InfraError> {
    let mut s = String::from("#timestamp [ns],u,v\n");
    for b in blobs {
        let _ = writeln!(s, "{},{},{}", b.stamp_ns, b.uv.x, b.uv.y);
    }
    std::fs::write(path, s).map_err(io_err(path))
}

/// Reads `infra/cameras.yaml`: `cameras:` list of `{id, camera.yaml keys}`.
pub fn read_cameras_yaml(path: &Path) -> Result<Vec<(String, Camera<f64>)>, InfraError> {
    let text = std::fs::read_to_string(path).map_err(io_err(path))?;
    let doc: serde_yaml::Value = serde_yaml::from_str(&text).map_err(|e| yaml_err(path, &e))?;
    let Some(list) = doc.get("cameras").and_then(|c| c.as_sequence()) else {
        return Err(parse_err(path, 0, "missing list `cameras`"));
    };
    let mut out: Vec<(String, Camera<f64>)> = Vec::new();
    for (n, entry) in list.iter().enumerate() {
        let id = match entry.get("id") {
            Some(serde_yaml::Value::String(s)) => s.clone(),
            Some(v @ serde_yaml::Value::Number(_)) => serde_yaml::to_string(v)
                .unwrap_or_default()
                .trim()
                .to_string(),
            _ => return Err(parse_err(path, 0, format!("camera entry {n} has no `id`"))),
        };
        if out.iter().any(|(i, _)| *i == id) {
            return Err(parse_err(
                path,
                0,
                format!("camera id `{id}` appears twice"),
            ));
        }
        let sub = serde_yaml::to_string(entry).unwrap_or_default();
        let camera = parse_camera_yaml(path, &sub)
            .map_err(|e| parse_err(path, 0, format!("camera `{id}`: {e}")))?;
        out.push((id, camera));
    }
    Ok(out)
}

/// Writes `infra/cameras.yaml`.
pub fn write_cameras_yaml(
    path: &Path,
    cameras: &[(String, Camera<f64>)],
) -> Result<(), InfraError> {
    let mut s = String::from("cameras:\n");
    for (id, cam) in cameras {
        let _ = writeln!(s, "  - id: {id}");
        for line in camera_yaml_string(cam)
            .lines()
            .filter(|l| !l.starts_with('#'))
        {
            let _ = writeln!(s, "    {line}");
        }
    }
    std::fs::write(path, s).map_err(io_err(path))
}

/// One camera of the `infra:` result.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CameraResult {
    /// `T_<frame>_cam`, row-major 4x4.
    #[serde(rename = "T_world_cam")]
    pub t_world_cam: [[f64; 4]; 4],
    /// 1-sigma rotation (right perturbation), deg.
    pub sigma_rot_deg: [f64; 3],
    /// 1-sigma translation, m.
    pub sigma_trans_m: [f64; 3],
    /// Marker-corner reprojection RMSE, px.
    pub reprojection_rmse_px: f64,
}

/// The `infra:` section.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct InfraSection {
    /// `vo` (estimate) or `world` (ground truth).
    pub frame: String,
    /// Metres per VO unit.
    pub vo_scale: f64,
    /// `T_cam0_marker`.
    #[serde(rename = "T_cam0_marker")]
    pub t_cam0_marker: [[f64; 4]; 4],
    /// Ground truth only: `T_world_vo`.
    #[serde(
        rename = "T_world_vo",
        default,
        skip_serializing_if = "Option::is_none"
    )]
    pub t_world_vo: Option<[[f64; 4]; 4]>,
    /// Cameras by id.
    pub cameras: BTreeMap<String, CameraResult>,
}

/// The result file (`infra:` key).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct InfraResultFile {
    /// The section.
    pub infra: InfraSection,
}

/// Row-major array of a pose.
pub fn matrix_rows(t: &Isometry3<f64>) -> [[f64; 4]; 4] {
    let m = t.to_homogeneous();
    std::array::from_fn(|r| std::array::from_fn(|c| m[(r, c)]))
}

/// A pose of row-major rows (validated).
pub fn pose_of_rows(path: &Path, rows: &[[f64; 4]; 4]) -> Result<Isometry3<f64>, InfraError> {
    let m = Matrix4::from_fn(|r, c| rows[r][c]);
    isometry_from_matrix(&m).map_err(|e| parse_err(path, 0, e.to_string()))
}

impl InfraResultFile {
    /// Reads a result or ground-truth file.
    pub fn read(path: &Path) -> Result<Self, InfraError> {
        let text = std::fs::read_to_string(path).map_err(io_err(path))?;
        serde_yaml::from_str(&text).map_err(|e| yaml_err(path, &e))
    }

    /// Writes it (matrices in flow style, one row per line).
    pub fn write(&self, path: &Path) -> Result<(), InfraError> {
        std::fs::write(path, self.to_yaml_string()).map_err(io_err(path))
    }

    /// The YAML text.
    pub fn to_yaml_string(&self) -> String {
        let m = |rows: &[[f64; 4]; 4], indent: &str| {
            let r: Vec<String> = rows
                .iter()
                .map(|r| format!("[{}, {}, {}, {}]", r[0], r[1], r[2], r[3]))
                .collect();
            format!("[{}]", r.join(&format!(",\n{indent} ")))
        };
        let v = |x: &[f64; 3]| format!("[{}, {}, {}]", x[0], x[1], x[2]);
        let i = &self.infra;
        let mut s = format!(
            "infra:\n  frame: {}\n  vo_scale: {}\n  T_cam0_marker: {}\n",
            i.frame,
            i.vo_scale,
            m(&i.t_cam0_marker, "                ")
        );
        if let Some(t) = &i.t_world_vo {
            let _ = writeln!(s, "  T_world_vo: {}", m(t, "              "));
        }
        s.push_str("  cameras:\n");
        for (id, c) in &i.cameras {
            let _ = writeln!(
                s,
                "    {id}:\n      T_world_cam: {}\n      sigma_rot_deg: {}\n      sigma_trans_m: {}\n      reprojection_rmse_px: {}",
                m(&c.t_world_cam, "                   "),
                v(&c.sigma_rot_deg),
                v(&c.sigma_trans_m),
                c.reprojection_rmse_px
            );
        }
        s
    }
}

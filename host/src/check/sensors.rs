//! The dataset's streams as the checks need them: IMU samples (units unchecked, so the
//! check can name them), pose stamps and rotations, camera stamps and the target's corners
//! per image, LiDAR sweep stamps. A present file that does not read becomes a finding; an
//! absent one is left to the inventory.

use std::path::{Path, PathBuf};

use super::{units, Finding};
use crate::calibrate::camera_imu::{detect_corner_frames, CornerFrame};
use crate::camera_yaml::{read_camera_yaml, read_target_yaml, Target};
use crate::dataset::{
    check_imu_units, list_scans, read_camera_csv, read_imu_csv, read_observed_corners,
    read_pose_csv, ImuRecord, ObservedImage, PoseRecord, CAMERA_CSV, CAMERA_YAML, IMU_CSV,
    LIDAR_DIR, OBSERVED_CORNERS_CSV, POSE_CSV, TARGET_YAML,
};
use crate::vision::{CameraDataset, DetectorParams};
use msreg_estimator::camera::Camera;
use msreg_estimator::CornerObservation;

/// The camera, its target and the corners found per image.
#[derive(Debug, Clone)]
pub struct CameraData {
    /// `cam0/camera.yaml`.
    pub camera: Camera<f64>,
    /// `target.yaml`, when present.
    pub target: Option<Target>,
    /// Images with corners, by stamp.
    pub frames: Vec<CornerFrame>,
    /// Whether the corners' target positions are the x, y, z of `cam0/corners.csv`.
    pub from_corners_csv: bool,
}

/// What the checks read.
#[derive(Debug, Clone, Default)]
pub struct SensorData {
    /// The dataset directory.
    pub root: PathBuf,
    /// `imu0/data.csv`, when it reads and its units are m/s^2 and rad/s.
    pub imu: Option<Vec<ImuRecord>>,
    /// Stamps of `imu0/data.csv` when it reads (whatever its units).
    pub imu_stamps: Option<Vec<u64>>,
    /// `pose0/data.csv`.
    pub pose0: Option<Vec<PoseRecord>>,
    /// Image stamps (`cam0/data.csv`, or `cam0/corners.csv`).
    pub cam0_stamps: Option<Vec<u64>>,
    /// The camera and its corners, when the files read.
    pub camera: Option<CameraData>,
    /// Whether `target.yaml`'s sizes read as metres.
    pub target_in_metres: bool,
    /// LiDAR sweep stamps.
    pub lidar0_stamps: Option<Vec<u64>>,
    /// What reading found.
    pub findings: Vec<Finding>,
}

/// Reads every stream present under `root`.
pub fn load(root: &Path, progress: &(dyn Fn(f64) + Sync)) -> SensorData {
    let mut data = SensorData {
        root: root.to_path_buf(),
        target_in_metres: true,
        ..SensorData::default()
    };
    load_imu(&mut data);
    if root.join(POSE_CSV).exists() {
        data.pose0 = read(&mut data.findings, || read_pose_csv(root.join(POSE_CSV)));
    }
    if root.join(LIDAR_DIR).is_dir() {
        data.lidar0_stamps = read(&mut data.findings, || list_scans(&root.join(LIDAR_DIR)))
            .map(|scans| scans.iter().map(|s| s.stamp_ns).collect());
    }
    let target_path = root.join(TARGET_YAML);
    if target_path.is_file() {
        if let Some(target) = read(&mut data.findings, || read_target_yaml(&target_path)) {
            let mm = units::target_in_millimetres(&target_path, &target);
            data.target_in_metres = mm.is_empty();
            data.findings.extend(mm);
        }
    }
    load_camera(&mut data, progress);
    data
}

fn load_imu(data: &mut SensorData) {
    let path = data.root.join(IMU_CSV);
    if !path.exists() {
        return;
    }
    let Some(records) = read(&mut data.findings, || read_imu_csv(&path)) else {
        return;
    };
    data.imu_stamps = Some(records.iter().map(|r| r.stamp_ns).collect());
    match check_imu_units(&path, &records) {
        Ok(()) => data.imu = Some(records),
        Err(e) => data.findings.push(Finding::ImuUnits {
            message: e.to_string(),
        }),
    }
}

fn load_camera(data: &mut SensorData, progress: &(dyn Fn(f64) + Sync)) {
    let root = data.root.clone();
    let observed = root.join(OBSERVED_CORNERS_CSV);
    let has_yaml = root.join(CAMERA_YAML).is_file();
    if observed.is_file() {
        let Some(images) = read(&mut data.findings, || read_observed_corners(&observed)) else {
            return;
        };
        data.cam0_stamps = Some(images.iter().map(|i| i.stamp_ns).collect());
        if !has_yaml {
            return;
        }
        let camera = read(&mut data.findings, || {
            read_camera_yaml(&root.join(CAMERA_YAML))
        });
        let target_path = root.join(TARGET_YAML);
        let target = target_path
            .is_file()
            .then(|| read_target_yaml(&target_path).ok())
            .flatten();
        if let Some(camera) = camera {
            let frames = images
                .iter()
                .filter_map(|i| placed(i, target.as_ref()))
                .collect();
            let from_corners_csv = images
                .iter()
                .any(|i| i.corners.iter().any(|c| c.point.is_some()));
            data.camera = Some(CameraData {
                camera,
                target,
                frames,
                from_corners_csv,
            });
        }
        return;
    }
    if !root.join(CAMERA_CSV).is_file() {
        return;
    }
    data.cam0_stamps = read(&mut data.findings, || {
        read_camera_csv(root.join(CAMERA_CSV))
    })
    .map(|frames| frames.iter().map(|f| f.stamp_ns).collect());
    if data.cam0_stamps.is_none() || !has_yaml || !root.join(TARGET_YAML).is_file() {
        return;
    }
    // A plain board (LiDAR-camera) has no corners to detect.
    if let Ok(Target::Board(_)) = read_target_yaml(&root.join(TARGET_YAML)) {
        return;
    }
    detect(data, progress);
}

/// Corner detection in the images of `cam0/data.csv`.
fn detect(data: &mut SensorData, progress: &(dyn Fn(f64) + Sync)) {
    let root = data.root.clone();
    let Some(images) = read(&mut data.findings, || CameraDataset::open(&root)) else {
        return;
    };
    let Some((frames, summary)) = read(&mut data.findings, || {
        detect_corner_frames(&images, &DetectorParams::default(), progress)
    }) else {
        return;
    };
    data.findings.push(Finding::TargetFound {
        target: describe(&images.target),
        found: summary.detected,
        images: summary.images,
        rejected: summary.rejected.into_iter().collect(),
    });
    data.camera = Some(CameraData {
        camera: images.camera,
        target: Some(images.target),
        frames,
        from_corners_csv: false,
    });
}

/// One image of `cam0/corners.csv` with its corners placed on the target (from the file's
/// x, y, z, else by id); `None` when a corner cannot be placed.
fn placed(image: &ObservedImage, target: Option<&Target>) -> Option<CornerFrame> {
    let corners = image
        .corners
        .iter()
        .map(|c| {
            let point = match (c.point, target) {
                (Some(p), _) => Some(p),
                (None, Some(Target::Checkerboard(t))) => Some(t.corner_in_target(c.corner_id)),
                (None, Some(Target::AprilGrid(t))) => t.corner(c.corner_id),
                (None, _) => None,
            }?;
            Some(CornerObservation {
                point_in_target: point,
                pixel: c.pixel,
            })
        })
        .collect::<Option<Vec<_>>>()?;
    Some(CornerFrame {
        stamp_ns: image.stamp_ns,
        corners,
    })
}

/// "6x7 checkerboard" (inner corners), "6x5 aprilgrid" (tags).
pub fn describe(target: &Target) -> String {
    match target {
        Target::Checkerboard(t) => format!("{}x{} checkerboard", t.rows, t.cols),
        Target::AprilGrid(t) => format!("{}x{} aprilgrid", t.tag_cols, t.tag_rows),
        Target::Board(_) => "plain board".to_string(),
    }
}

/// `f()`, its error kept as a finding.
fn read<T, E: std::fmt::Display>(
    findings: &mut Vec<Finding>,
    f: impl FnOnce() -> Result<T, E>,
) -> Option<T> {
    match f() {
        Ok(value) => Some(value),
        Err(e) => {
            findings.push(Finding::Unreadable {
                message: e.to_string(),
            });
            None
        }
    }
}

impl SensorData {
    /// The stamps of `pose0/data.csv`.
    pub fn pose0_stamps(&self) -> Option<Vec<u64>> {
        self.pose0
            .as_ref()
            .map(|p| p.iter().map(|r| r.stamp_ns).collect())
    }
}

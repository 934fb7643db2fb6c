//! The infrastructure-camera dataset directory: the loader `msreg calibrate infra` reads and
//! the writer of `msreg simulate infra`.

use std::path::{Path, PathBuf};

use msreg_estimator::camera::Camera;
use nalgebra::{Isometry3, Vector2, Vector3};

use super::colmap::{read_model, write_model, ColmapModel};
use super::detect::{blobs_from_images, markers_from_images};
use super::io::{
    matrix_rows, read_blobs_csv, read_cameras_yaml, read_markers_csv, write_blobs_csv,
    write_cameras_yaml, write_markers_csv, Blob, CameraResult, InfraError, InfraResultFile,
    InfraSection, MarkerDetection, MarkerSpec,
};
use super::render::{blob_frame, marker_frame, RenderLook};
use super::sim::InfraSim;
use crate::camera_yaml::{camera_yaml_string, read_camera_yaml};
use crate::dataset::{
    write_camera_csv, write_groundtruth_csv, CameraFrame, GroundTruthRecord, CAMERA_CSV,
};
use crate::vision::aruco::Dictionary;
use crate::vision::blobs::BlobParams;
use crate::vision::GrayImage;

/// One infrastructure camera's input: its detections, or why they could not be read.
#[derive(Debug)]
pub struct CameraInput {
    /// Id (directory name under `infra/`).
    pub id: String,
    /// Intrinsics.
    pub camera: Camera<f64>,
    /// Marker detections of the robot's marker id, or the reading error.
    pub detections: Result<Vec<MarkerDetection>, InfraError>,
}

/// Everything `msreg calibrate infra` reads.
#[derive(Debug)]
pub struct InfraDataset {
    /// `cam0/camera.yaml`: the robot's fisheye F.
    pub f_camera: Camera<f64>,
    /// `marker.yaml`.
    pub marker: MarkerSpec,
    /// `infra/cameras.yaml` with each camera's detections.
    pub cameras: Vec<CameraInput>,
    /// `cam0/blobs.csv` (empty when absent).
    pub blobs: Vec<Blob>,
    /// `vo/`.
    pub vo: ColmapModel,
}

fn io(path: &Path) -> impl FnOnce(std::io::Error) -> InfraError + '_ {
    move |source| InfraError::Io {
        path: path.to_path_buf(),
        source,
    }
}

impl InfraDataset {
    /// Reads the dataset. Problems of a single camera's detections are kept per camera so
    /// the others can still be solved; anything else fails.
    pub fn open(dir: &Path) -> Result<Self, InfraError> {
        let cam0 = dir.join("cam0/camera.yaml");
        let f_camera = read_camera_yaml(&cam0).map_err(|e| InfraError::Parse {
            path: cam0.clone(),
            line: 0,
            message: e.to_string(),
        })?;
        let marker = MarkerSpec::read(&dir.join("marker.yaml"))?;
        let vo = read_model(&dir.join("vo"))?;
        check_vo_camera(dir, &vo, &f_camera)?;
        let blobs = read_blobs(dir)?;
        let cameras = read_cameras_yaml(&dir.join("infra/cameras.yaml"))?
            .into_iter()
            .map(|(id, camera)| {
                let detections = read_marker_detections(dir, &id, &marker);
                CameraInput {
                    id,
                    camera,
                    detections,
                }
            })
            .collect();
        Ok(Self {
            f_camera,
            marker,
            cameras,
            blobs,
            vo,
        })
    }
}

/// `cam0/blobs.csv`; else the blobs detected in F's images (`cam0/data.csv` + `data/`);
/// else none.
fn read_blobs(dir: &Path) -> Result<Vec<Blob>, InfraError> {
    let csv = dir.join("cam0/blobs.csv");
    let images = dir.join(CAMERA_CSV);
    if csv.exists() {
        read_blobs_csv(&csv)
    } else if images.exists() {
        blobs_from_images(&images, &BlobParams::default())
    } else {
        Ok(Vec::new())
    }
}

/// Camera `id`'s detections of the robot's marker: `infra/<id>/markers.csv`, else detected
/// in its images (`infra/<id>/data.csv` + `data/`). Without either, the CSV's read error.
fn read_marker_detections(
    dir: &Path,
    id: &str,
    marker: &MarkerSpec,
) -> Result<Vec<MarkerDetection>, InfraError> {
    let camera_dir = dir.join("infra").join(id);
    let csv = camera_dir.join("markers.csv");
    let images = camera_dir.join("data.csv");
    if !csv.exists() && images.exists() {
        return markers_from_images(&images, dictionary_of(dir, marker)?, marker.id);
    }
    read_markers_csv(&csv).map(|d| d.into_iter().filter(|m| m.marker_id == marker.id).collect())
}

/// The ArUco dictionary `marker.yaml` of the dataset in `dir` names.
fn dictionary_of(dir: &Path, marker: &MarkerSpec) -> Result<Dictionary, InfraError> {
    marker
        .dictionary
        .parse::<Dictionary>()
        .map_err(|e| InfraError::Parse {
            path: dir.join("marker.yaml"),
            line: 0,
            message: e.to_string(),
        })
}

/// The COLMAP camera must be `cam0/`'s F (resolution and projection of a few rays).
fn check_vo_camera(dir: &Path, vo: &ColmapModel, f: &Camera<f64>) -> Result<(), InfraError> {
    let path = dir.join("vo/cameras.txt");
    let mismatch = |what: String| InfraError::Parse {
        path: path.clone(),
        line: 0,
        message: format!("the VO camera does not match cam0/camera.yaml: {what}"),
    };
    if vo.camera.resolution != f.resolution {
        return Err(mismatch(format!(
            "resolution {:?} vs {:?}",
            vo.camera.resolution, f.resolution
        )));
    }
    for dir in [
        Vector3::new(0.0, 0.0, 1.0),
        Vector3::new(0.5, 0.2, 1.0),
        Vector3::new(-0.3, 0.8, 0.6),
    ] {
        if let (Some(a), Some(b)) = (vo.camera.project(&dir), f.project(&dir)) {
            let d = (a.pixel - b.pixel).norm();
            if d > 0.5 {
                return Err(mismatch(format!("a ray projects {d:.2} px apart")));
            }
        }
    }
    Ok(())
}

fn write_text(path: &Path, text: &str) -> Result<(), InfraError> {
    if let Some(p) = path.parent() {
        std::fs::create_dir_all(p).map_err(io(p))?;
    }
    std::fs::write(path, text).map_err(io(path))
}

impl InfraSim {
    /// Writes the dataset layout of docs/formats.md plus `groundtruth/`, with the detections
    /// as CSV (`cam0/blobs.csv`, `infra/<id>/markers.csv`).
    pub fn write(&self, dir: &Path) -> Result<(), InfraError> {
        self.write_common(dir)?;
        write_blobs_csv(&dir.join("cam0/blobs.csv"), &self.blobs)?;
        for (cam, det) in self.cameras.iter().zip(&self.detections) {
            write_markers_csv(&dir.join("infra").join(&cam.id).join("markers.csv"), det)?;
        }
        Ok(())
    }

    /// [`InfraSim::write`] with rendered images in place of the CSV detections
    /// (`--images`): each camera's frames of the marker and F's keyframes, see
    /// [`super::render`]. `seed` drives the sensor noise.
    pub fn write_with_images(&self, dir: &Path, seed: u64) -> Result<(), InfraError> {
        self.write_common(dir)?;
        let look = RenderLook::default();
        let dictionary = dictionary_of(dir, &self.marker)?;
        for (k, (cam, views)) in self.cameras.iter().zip(&self.marker_views).enumerate() {
            let frames: Vec<(u64, &Isometry3<f64>)> = views.iter().map(|(s, t)| (*s, t)).collect();
            write_frames(
                &dir.join("infra").join(&cam.id),
                &frames,
                |&(stamp, t_c_m)| {
                    let mut rng = image_rng(seed, k as u64 + 1, stamp);
                    let marker = (dictionary, self.marker.id as usize);
                    marker_frame(
                        &cam.camera,
                        t_c_m,
                        self.marker.side_m,
                        marker,
                        &look,
                        &mut rng,
                    )
                },
            )?;
        }
        let keyframes: Vec<(u64, &Vec<Vector2<f64>>)> =
            self.blob_views.iter().map(|(s, v)| (*s, v)).collect();
        write_frames(&dir.join("cam0"), &keyframes, |&(stamp, spots)| {
            blob_frame(&self.f_camera, spots, &look, &mut image_rng(seed, 0, stamp))
        })
    }

    /// Everything but the detections: cameras, VO, marker and ground truth.
    fn write_common(&self, dir: &Path) -> Result<(), InfraError> {
        write_text(
            &dir.join("cam0/camera.yaml"),
            &camera_yaml_string(&self.f_camera),
        )?;
        write_model(&dir.join("vo"), &self.vo)?;
        let marker = serde_yaml::to_string(&self.marker).unwrap_or_default();
        write_text(&dir.join("marker.yaml"), &marker)?;
        let list: Vec<(String, Camera<f64>)> = self
            .cameras
            .iter()
            .map(|c| (c.id.clone(), c.camera))
            .collect();
        let infra = dir.join("infra");
        std::fs::create_dir_all(&infra).map_err(io(&infra))?;
        write_cameras_yaml(&infra.join("cameras.yaml"), &list)?;
        for cam in &self.cameras {
            let d: PathBuf = infra.join(&cam.id);
            std::fs::create_dir_all(&d).map_err(io(&d))?;
        }
        self.write_groundtruth(&dir.join("groundtruth"))
    }

    fn write_groundtruth(&self, gt: &Path) -> Result<(), InfraError> {
        std::fs::create_dir_all(gt).map_err(io(gt))?;
        let cameras = self
            .cameras
            .iter()
            .map(|c| {
                let r = CameraResult {
                    t_world_cam: matrix_rows(&c.t_world_cam),
                    sigma_rot_deg: [0.0; 3],
                    sigma_trans_m: [0.0; 3],
                    reprojection_rmse_px: 0.0,
                };
                (c.id.clone(), r)
            })
            .collect();
        let file = InfraResultFile {
            infra: InfraSection {
                frame: "world".into(),
                vo_scale: self.vo_scale_truth(),
                t_cam0_marker: matrix_rows(&self.t_f_m),
                t_world_vo: Some(matrix_rows(&self.keyframe_truth[0])),
                cameras,
            },
        };
        file.write(&gt.join("infra.yaml"))?;
        let n = self.trajectory.len();
        let records: Vec<GroundTruthRecord> = (0..n)
            .map(|i| {
                let (stamp, pose) = self.trajectory[i];
                let (a, b) = (
                    self.trajectory[i.saturating_sub(1)],
                    self.trajectory[(i + 1).min(n - 1)],
                );
                let dt = (b.0 - a.0) as f64 * 1e-9;
                let v = if dt > 0.0 {
                    (b.1.translation.vector - a.1.translation.vector) / dt
                } else {
                    Vector3::zeros()
                };
                GroundTruthRecord {
                    stamp_ns: stamp,
                    position: pose.translation.vector,
                    rotation: pose.rotation,
                    velocity: v,
                    gyro_bias: Vector3::zeros(),
                    accel_bias: Vector3::zeros(),
                }
            })
            .collect();
        let path = gt.join("trajectory.csv");
        write_groundtruth_csv(&path, &records).map_err(|e| InfraError::Parse {
            path,
            line: 0,
            message: e.to_string(),
        })
    }

    /// The true VO scale: metres per VO unit of the least-squares similarity from the VO
    /// keyframe positions to the true ones (drift makes any single ratio ambiguous; this is
    /// the definition the estimate is judged by).
    pub fn vo_scale_truth(&self) -> f64 {
        let vo: Vec<Vector3<f64>> = self
            .vo
            .images
            .iter()
            .map(|i| i.t_cam_world.inverse().translation.vector)
            .collect();
        let truth: Vec<Vector3<f64>> = self
            .keyframe_truth
            .iter()
            .map(|t| t.translation.vector)
            .collect();
        super::align::similarity_scale(&vo, &truth)
    }
}

/// The noise generator of one rendered image: its own stream per camera, seeded by the
/// stamp, so images can be rendered in any order.
fn image_rng(seed: u64, camera: u64, stamp_ns: u64) -> rand_chacha::ChaCha8Rng {
    use rand::SeedableRng;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed ^ stamp_ns.rotate_left(17));
    rng.set_stream(camera);
    rng
}

/// Renders `frames` in parallel into `<dir>/data/<stamp>.png` and lists them in
/// `<dir>/data.csv`.
fn write_frames<F, V>(dir: &Path, frames: &[(u64, V)], render: F) -> Result<(), InfraError>
where
    F: Fn(&(u64, V)) -> GrayImage + Sync,
    V: Sync,
{
    use rayon::prelude::*;
    let data = dir.join("data");
    std::fs::create_dir_all(&data).map_err(io(&data))?;
    let listed: Vec<CameraFrame> = frames
        .par_iter()
        .map(|frame| {
            let path = data.join(format!("{}.png", frame.0));
            render(frame)
                .to_luma8()
                .save(&path)
                .map_err(|e| InfraError::Io {
                    path: path.clone(),
                    source: std::io::Error::other(e),
                })?;
            Ok(CameraFrame {
                stamp_ns: frame.0,
                path,
            })
        })
        .collect::<Result<_, InfraError>>()?;
    let csv = dir.join("data.csv");
    write_camera_csv(&csv, &listed).map_err(|e| InfraError::Parse {
        path: csv.clone(),
        line: 0,
        message: e.to_string(),
    })
}

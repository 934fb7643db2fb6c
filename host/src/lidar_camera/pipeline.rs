//! From frames to `T_cam_lidar`: pairing each LiDAR scan with the image of nearest stamp,
//! feature extraction on both sides (a frame failing either is rejected with the reason,
//! never aborting the run), the closed-form start, PPC-Cal, edge association, PBPC-Cal,
//! and the MLRE of the result per frame, per edge and overall.

use std::time::Instant;

use msreg_estimator::camera::Camera;
use msreg_estimator::Pose;
use nalgebra::{Matrix6, Vector3};
use rayon::prelude::*;
use serde::Serialize;

use super::camera_features::{
    extract_camera_board, CameraBoardFeatures, CameraFeatureParams, CameraQuality,
};
use super::dataset::{LidarCameraDataset, LidarCameraInputError};
use super::lidar_features::{
    extract_lidar_board, LidarBoardFeatures, LidarFeatureParams, LidarQuality,
};
use super::mlre::{line_distances_px, mean};
use super::solver::{
    associate_edges, plane_alignment, EdgeObservation, PlaneObservation, PointToBackProjectedPlane,
    PointToPlane,
};
use crate::camera_yaml::Board;
use crate::pointcloud::{read_pcd, PointCloud};
use crate::solve::{solve_se3, LmError, LmOptions, LmSummary, Loss};
use crate::vision::GrayImage;

/// Which cost the result minimises.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Method {
    /// Point to plane only (eq. 2.5).
    Ppc,
    /// Point to plane, then point to back-projected plane (eq. 2.7).
    #[default]
    Pbpc,
}

impl Method {
    /// The method's name in the thesis (PPC-Cal, PBPC-Cal).
    pub fn label(self) -> &'static str {
        match self {
            Method::Ppc => "PPC-Cal",
            Method::Pbpc => "PBPC-Cal",
        }
    }
}

/// Options of the whole calibration.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CalibrationOptions {
    /// The cost minimised last.
    pub method: Method,
    /// LiDAR feature thresholds.
    pub lidar: LidarFeatureParams,
    /// Camera feature thresholds.
    pub camera: CameraFeatureParams,
    /// Fewest accepted frames (the plane constraint needs 3 non-parallel boards).
    pub min_views: usize,
    /// Huber threshold in sigmas of the whitened residuals.
    pub huber_sigmas: f64,
    /// Assumed 1-sigma of an edge point from its back-projected plane, m.
    pub edge_sigma_m: f64,
    /// Start of PPC; `None` for the closed-form plane alignment.
    pub start: Option<Pose<f64>>,
    /// Largest scan-to-image stamp gap of a pair, ns.
    pub max_pair_gap_ns: u64,
}

impl Default for CalibrationOptions {
    fn default() -> Self {
        Self {
            method: Method::Pbpc,
            lidar: LidarFeatureParams::default(),
            camera: CameraFeatureParams::default(),
            min_views: 3,
            huber_sigmas: 3.0,
            edge_sigma_m: 0.01,
            start: None,
            max_pair_gap_ns: 100_000_000,
        }
    }
}

/// Both sensors' board features of one accepted frame.
#[derive(Clone, Debug, PartialEq)]
pub struct FrameFeatures {
    /// Frame index (scan order).
    pub frame: usize,
    /// Scan stamp, ns.
    pub scan_stamp_ns: u64,
    /// Image stamp, ns.
    pub image_stamp_ns: u64,
    /// LiDAR side.
    pub lidar: LidarBoardFeatures,
    /// Camera side.
    pub camera: CameraBoardFeatures,
}

/// A frame left out, and why.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct RejectedFrame {
    /// Frame index (scan order).
    pub frame: usize,
    /// Scan stamp, ns.
    pub scan_stamp_ns: u64,
    /// Stamp of the paired image, ns (none when no image was close enough).
    pub image_stamp_ns: Option<u64>,
    /// Why.
    pub reason: String,
}

/// Extracts both sides of one frame; the error is the rejection reason.
pub fn extract_frame(
    cloud: &PointCloud,
    image: &GrayImage,
    camera: &Camera<f64>,
    board: &Board,
    options: &CalibrationOptions,
) -> Result<(LidarBoardFeatures, CameraBoardFeatures), String> {
    let cam =
        extract_camera_board(image, camera, board, &options.camera).map_err(|e| e.to_string())?;
    let lidar = extract_lidar_board(cloud, board, &options.lidar).map_err(|e| e.to_string())?;
    Ok((lidar, cam))
}

/// One LM run, for the report.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct SolverRun {
    /// Iterations.
    pub iterations: usize,
    /// Robust cost at the start.
    pub initial_cost: f64,
    /// Robust cost at the end.
    pub final_cost: f64,
    /// A tolerance was met.
    pub converged: bool,
    /// Scalar residuals.
    pub residuals: usize,
    /// Wall time, s.
    pub time_s: f64,
}

impl SolverRun {
    fn from(summary: &LmSummary, time_s: f64) -> Self {
        Self {
            iterations: summary.iterations,
            initial_cost: summary.initial_cost,
            final_cost: summary.final_cost,
            converged: summary.converged,
            residuals: summary.residual_count,
            time_s,
        }
    }
}

/// One edge of one frame under the result.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct EdgeReport {
    /// LiDAR edge index (cyclic order of the LiDAR side).
    pub lidar_edge: usize,
    /// Image edge it was associated with.
    pub image_edge: usize,
    /// LiDAR edge points.
    pub points: usize,
    /// RMS distance of the points from the back-projected plane, m.
    pub rms_m: f64,
    /// Mean line reprojection error of the edge, px.
    pub mlre_px: f64,
}

/// One accepted frame under the result.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct FrameReport {
    /// Frame index.
    pub frame: usize,
    /// Scan stamp, ns.
    pub scan_stamp_ns: u64,
    /// Image stamp, ns.
    pub image_stamp_ns: u64,
    /// MLRE over the frame's edge points, px.
    pub mlre_px: f64,
    /// RMS of the board points from the camera's board plane, m.
    pub plane_rms_m: f64,
    /// Per edge.
    pub edges: Vec<EdgeReport>,
    /// LiDAR feature quality.
    pub lidar: LidarQuality,
    /// Camera feature quality.
    pub camera: CameraQuality,
}

/// The solution and everything the report needs.
#[derive(Clone, Debug, PartialEq)]
pub struct Solution {
    /// `T_cam_lidar` of the chosen method.
    pub t_cam_lidar: Pose<f64>,
    /// Its covariance, `[d_theta (right), d_p]`.
    pub covariance: Matrix6<f64>,
    /// The closed-form (or given) start.
    pub start: Pose<f64>,
    /// PPC-Cal's result.
    pub t_cam_lidar_ppc: Pose<f64>,
    /// PPC-Cal's run.
    pub ppc: SolverRun,
    /// PBPC-Cal's run (method `pbpc` only).
    pub pbpc: Option<SolverRun>,
    /// Edge association of each frame (LiDAR edge `j` to image edge `perm[j]`).
    pub associations: Vec<[usize; 4]>,
    /// Per frame, under the chosen method's result.
    pub frames: Vec<FrameReport>,
    /// MLRE over all edge points, px, under the chosen method's result.
    pub mlre_px: f64,
    /// MLRE under PPC-Cal's result, px (for comparison).
    pub mlre_ppc_px: f64,
}

/// Why the solve failed (exit code 1).
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum SolveError {
    /// Fewer accepted frames than needed.
    #[error("only {found} usable views, at least {needed} are needed")]
    TooFewViews {
        /// Accepted frames.
        found: usize,
        /// Needed.
        needed: usize,
    },
    /// The boards are (nearly) parallel: no closed-form start.
    #[error("the board normals do not span 3D (boards too similar in orientation)")]
    Degenerate,
    /// The solver failed in one of the two stages.
    #[error("{}: {error}", stage.label())]
    Solver {
        /// The stage (PPC-Cal first, then PBPC-Cal).
        stage: Method,
        /// The solver's reason.
        error: LmError,
    },
}

fn lm_options(loss: Loss) -> LmOptions {
    LmOptions {
        loss,
        ..LmOptions::default()
    }
}

/// Solves for `T_cam_lidar` from the accepted frames.
pub fn solve(
    frames: &[FrameFeatures],
    camera: &Camera<f64>,
    options: &CalibrationOptions,
) -> Result<Solution, SolveError> {
    if frames.len() < options.min_views.max(3) {
        return Err(SolveError::TooFewViews {
            found: frames.len(),
            needed: options.min_views.max(3),
        });
    }
    let planes: Vec<PlaneObservation> = frames
        .iter()
        .map(|f| PlaneObservation {
            points_lidar: f.lidar.plane_points.clone(),
            normal_cam: f.camera.normal,
            offset_cam: f.camera.offset,
        })
        .collect();
    let start = match options.start {
        Some(s) => s,
        None => plane_alignment(&planes).ok_or(SolveError::Degenerate)?,
    };
    let mut rms: Vec<f64> = frames.iter().map(|f| f.lidar.quality.plane_rms_m).collect();
    rms.sort_by(f64::total_cmp);
    let plane_sigma = rms[rms.len() / 2].max(1e-3);
    let ppc_problem = PointToPlane {
        planes: &planes,
        sigma_m: plane_sigma,
    };
    let clock = Instant::now();
    let ppc = solve_se3(
        &ppc_problem,
        start,
        &lm_options(Loss::Huber(options.huber_sigmas)),
    )
    .map_err(|error| SolveError::Solver {
        stage: Method::Ppc,
        error,
    })?;
    let ppc_run = SolverRun::from(&ppc, clock.elapsed().as_secs_f64());
    let associations: Vec<[usize; 4]> = frames
        .iter()
        .map(|f| {
            let pts: Vec<Vec<Vector3<f64>>> =
                f.lidar.edges.iter().map(|e| e.points.clone()).collect();
            let normals: Vec<Vector3<f64>> = f.camera.edges.iter().map(|e| e.normal).collect();
            associate_edges(&ppc.pose, &pts, &normals).unwrap_or([0, 1, 2, 3])
        })
        .collect();
    let (final_pose, covariance, pbpc_run) = match options.method {
        Method::Ppc => (ppc.pose, ppc.covariance, None),
        Method::Pbpc => {
            let edges: Vec<EdgeObservation> = frames
                .iter()
                .zip(&associations)
                .flat_map(|(f, perm)| {
                    (0..4).map(move |j| EdgeObservation {
                        points_lidar: f.lidar.edges[j].points.clone(),
                        normal_cam: f.camera.edges[perm[j]].normal,
                    })
                })
                .collect();
            let problem = PointToBackProjectedPlane {
                edges: &edges,
                sigma_m: options.edge_sigma_m,
            };
            let clock = Instant::now();
            let pbpc = solve_se3(
                &problem,
                ppc.pose,
                &lm_options(Loss::Huber(options.huber_sigmas)),
            )
            .map_err(|error| SolveError::Solver {
                stage: Method::Pbpc,
                error,
            })?;
            let run = SolverRun::from(&pbpc, clock.elapsed().as_secs_f64());
            (pbpc.pose, pbpc.covariance, Some(run))
        }
    };
    let reports = frame_reports(frames, &associations, camera, &final_pose);
    let mlre_px = overall_mlre(frames, &associations, camera, &final_pose);
    let mlre_ppc_px = overall_mlre(frames, &associations, camera, &ppc.pose);
    Ok(Solution {
        t_cam_lidar: final_pose,
        covariance,
        start,
        t_cam_lidar_ppc: ppc.pose,
        ppc: ppc_run,
        pbpc: pbpc_run,
        associations,
        frames: reports,
        mlre_px,
        mlre_ppc_px,
    })
}

/// MLRE over every edge point of every frame under `t_cam_lidar`, px.
pub fn overall_mlre(
    frames: &[FrameFeatures],
    associations: &[[usize; 4]],
    camera: &Camera<f64>,
    t_cam_lidar: &Pose<f64>,
) -> f64 {
    let all: Vec<f64> = frames
        .iter()
        .zip(associations)
        .flat_map(|(f, perm)| {
            (0..4).flat_map(move |j| {
                line_distances_px(
                    camera,
                    t_cam_lidar,
                    &f.camera.edges[perm[j]].normal,
                    &f.lidar.edges[j].points,
                )
            })
        })
        .collect();
    mean(&all)
}

fn frame_reports(
    frames: &[FrameFeatures],
    associations: &[[usize; 4]],
    camera: &Camera<f64>,
    pose: &Pose<f64>,
) -> Vec<FrameReport> {
    frames
        .iter()
        .zip(associations)
        .map(|(f, perm)| {
            let mut all = Vec::new();
            let edges = (0..4)
                .map(|j| {
                    let normal = f.camera.edges[perm[j]].normal;
                    let pts = &f.lidar.edges[j].points;
                    let d = line_distances_px(camera, pose, &normal, pts);
                    let rms_m = (pts
                        .iter()
                        .map(|p| normal.dot(&pose.transform_point(p)).powi(2))
                        .sum::<f64>()
                        / pts.len().max(1) as f64)
                        .sqrt();
                    let report = EdgeReport {
                        lidar_edge: j,
                        image_edge: perm[j],
                        points: pts.len(),
                        rms_m,
                        mlre_px: mean(&d),
                    };
                    all.extend(d);
                    report
                })
                .collect();
            let plane_rms_m = (f
                .lidar
                .plane_points
                .iter()
                .map(|p| (f.camera.normal.dot(&pose.transform_point(p)) - f.camera.offset).powi(2))
                .sum::<f64>()
                / f.lidar.plane_points.len().max(1) as f64)
                .sqrt();
            FrameReport {
                frame: f.frame,
                scan_stamp_ns: f.scan_stamp_ns,
                image_stamp_ns: f.image_stamp_ns,
                mlre_px: mean(&all),
                plane_rms_m,
                edges,
                lidar: f.lidar.quality.clone(),
                camera: f.camera.quality.clone(),
            }
        })
        .collect()
}

/// Every frame of a dataset: accepted features and rejected frames. Unreadable files are
/// bad input (the error names the file).
pub fn extract_dataset(
    data: &LidarCameraDataset,
    options: &CalibrationOptions,
    progress: &(dyn Fn() + Sync),
) -> Result<(Vec<FrameFeatures>, Vec<RejectedFrame>), LidarCameraInputError> {
    type FrameResult = Result<Result<FrameFeatures, RejectedFrame>, LidarCameraInputError>;
    let results: Vec<FrameResult> = data
        .pairs()
        .into_par_iter()
        .map(|(k, i, gap)| {
            let (scan_stamp_ns, scan_path) = &data.scans[k];
            let (image_stamp_ns, image_path) = (&data.images[i].stamp_ns, &data.images[i].path);
            let out = if gap > options.max_pair_gap_ns {
                Err(RejectedFrame {
                    frame: k,
                    scan_stamp_ns: *scan_stamp_ns,
                    image_stamp_ns: None,
                    reason: format!(
                        "no image within {} ms of the scan (nearest {} ms away)",
                        options.max_pair_gap_ns / 1_000_000,
                        gap / 1_000_000
                    ),
                })
            } else {
                let cloud = read_pcd(scan_path).map_err(|source| LidarCameraInputError::Scan {
                    path: scan_path.clone(),
                    source,
                })?;
                let image =
                    GrayImage::load(image_path).map_err(|source| LidarCameraInputError::Image {
                        path: image_path.clone(),
                        source,
                    })?;
                match extract_frame(&cloud, &image, &data.camera, &data.board, options) {
                    Ok((lidar, camera)) => Ok(FrameFeatures {
                        frame: k,
                        scan_stamp_ns: *scan_stamp_ns,
                        image_stamp_ns: *image_stamp_ns,
                        lidar,
                        camera,
                    }),
                    Err(reason) => Err(RejectedFrame {
                        frame: k,
                        scan_stamp_ns: *scan_stamp_ns,
                        image_stamp_ns: Some(*image_stamp_ns),
                        reason,
                    }),
                }
            };
            progress();
            Ok(out)
        })
        .collect();
    let mut accepted = Vec::new();
    let mut rejected = Vec::new();
    for r in results {
        match r? {
            Ok(f) => accepted.push(f),
            Err(j) => rejected.push(j),
        }
    }
    Ok((accepted, rejected))
}

/// Every frame of a simulation, made and extracted in memory (no files): for tests and
/// studies.
pub fn extract_simulation(
    sim: &crate::sim::LidarCameraSim,
    options: &CalibrationOptions,
) -> (Vec<FrameFeatures>, Vec<RejectedFrame>) {
    let results: Vec<Result<FrameFeatures, RejectedFrame>> = (0..sim.frames.len())
        .into_par_iter()
        .map(|k| {
            let f = &sim.frames[k];
            extract_frame(
                &sim.scan(k),
                &sim.image(k),
                &sim.camera,
                &sim.config.board,
                options,
            )
            .map(|(lidar, camera)| FrameFeatures {
                frame: k,
                scan_stamp_ns: f.scan_stamp_ns,
                image_stamp_ns: f.image_stamp_ns,
                lidar,
                camera,
            })
            .map_err(|reason| RejectedFrame {
                frame: k,
                scan_stamp_ns: f.scan_stamp_ns,
                image_stamp_ns: Some(f.image_stamp_ns),
                reason,
            })
        })
        .collect();
    let mut accepted = Vec::new();
    let mut rejected = Vec::new();
    for r in results {
        match r {
            Ok(f) => accepted.push(f),
            Err(j) => rejected.push(j),
        }
    }
    (accepted, rejected)
}

//! `msreg calibrate infra`: the stages of [`super`] in order, per-camera failures kept
//! and reported while the other cameras are solved.

use std::collections::BTreeMap;

use nalgebra::{Isometry3, Matrix6, Vector2, Vector3};
use serde::Serialize;

use super::dataset::InfraDataset;
use super::init::{self, CameraProblem, CornerObs, MarkerPose};
use super::interp::KeyframeTrack;
use super::io::{matrix_rows, pose_of_rows, CameraResult, InfraResultFile, InfraSection};
use super::motion::{self, MotionPair, MotionSolution};
use super::topview::TopView;

/// Fewest accepted marker detections to initialise a camera.
pub const MIN_DETECTIONS: usize = 5;
/// Time between the two detections of a motion pair, s (at least).
const PAIR_SPACING_S: f64 = 1.0;
/// Largest stamp difference for "simultaneous" detections of two cameras (Sampson), s.
const SIMULTANEOUS_S: f64 = 0.01;

/// Per-camera outcome in the report.
#[derive(Clone, Debug, Serialize)]
pub struct CameraReport {
    /// Id.
    pub id: String,
    /// Solved or not.
    pub solved: bool,
    /// Why not.
    pub reason: Option<String>,
    /// Detections in markers.csv with the marker's id.
    pub detections: usize,
    /// Detections passing the PnP gate.
    pub detections_used: usize,
    /// Blobs associated.
    pub blobs_used: usize,
    /// Marker-corner reprojection RMSE, px.
    pub reprojection_rmse_px: f64,
    /// Blob reprojection RMSE, px.
    pub blob_rmse_px: f64,
}

/// Sampson distance of one camera pair over simultaneous marker corners.
#[derive(Clone, Debug, Serialize)]
pub struct PairSampson {
    /// First camera.
    pub a: String,
    /// Second camera.
    pub b: String,
    /// Corner correspondences.
    pub count: usize,
    /// Mean Sampson distance (normalised image coordinates, squared units).
    pub mean: f64,
}

/// The JSON report.
#[derive(Clone, Debug, Serialize)]
pub struct InfraReport {
    /// What was solved (stage names).
    pub stages: Vec<String>,
    /// Scale and T_F_M from motion.
    pub motion: Option<MotionSolution>,
    /// Per camera.
    pub cameras: Vec<CameraReport>,
    /// Per camera pair that saw the marker at once.
    pub sampson: Vec<PairSampson>,
    /// Keyframes and cameras from above (the report's top-view figure).
    pub top_view: TopView,
}

/// The calibration.
#[derive(Clone, Debug)]
pub struct InfraCalibration {
    /// The `infra:` result.
    pub result: InfraResultFile,
    /// The report.
    pub report: InfraReport,
    /// Covariance of each solved camera (`[theta, p]` of `T_vo_C`).
    pub covariances: BTreeMap<String, Matrix6<f64>>,
}

/// Why nothing could be calibrated.
#[derive(Debug, thiserror::Error)]
pub enum InfraCalibrationError {
    /// No camera pair gave motion for the scale.
    #[error(
        "scale and T_cam0_marker need at least 3 motion pairs from marker detections; got {0}"
    )]
    NoScale(usize),
}

struct Prepared {
    poses: Vec<Vec<MarkerPose>>,
    reasons: Vec<Option<String>>,
}

fn prepare(data: &InfraDataset, track: &KeyframeTrack) -> Prepared {
    let mut poses = Vec::new();
    let mut reasons = Vec::new();
    for cam in &data.cameras {
        match &cam.detections {
            Err(e) => {
                poses.push(Vec::new());
                reasons.push(Some(format!("cannot read detections: {e}")));
            }
            Ok(d) => {
                let mp: Vec<MarkerPose> = init::marker_poses(&cam.camera, &data.marker, d)
                    .into_iter()
                    .filter(|m| track.at(m.detection.stamp_ns, 1.0).is_some())
                    .collect();
                let reason = (mp.len() < MIN_DETECTIONS).then(|| {
                    format!("{} usable marker detections inside the VO time span ({} in the file), need {MIN_DETECTIONS}", mp.len(), d.len())
                });
                poses.push(mp);
                reasons.push(reason);
            }
        }
    }
    Prepared { poses, reasons }
}

fn motion_pairs(track: &KeyframeTrack, poses: &[Vec<MarkerPose>]) -> Vec<MotionPair> {
    let mut pairs = Vec::new();
    for cam in poses {
        let mut j = 0;
        for (i, a) in cam.iter().enumerate() {
            let t0 = a.detection.stamp_ns;
            j = j.max(i + 1);
            while j < cam.len() && (cam[j].detection.stamp_ns - t0) as f64 * 1e-9 < PAIR_SPACING_S {
                j += 1;
            }
            let Some(b) = cam.get(j) else { break };
            if let (Some(fa), Some(fb)) = (track.at(t0, 1.0), track.at(b.detection.stamp_ns, 1.0)) {
                pairs.push(MotionPair {
                    a: fa.inverse() * fb,
                    b: a.t_c_m.inverse() * b.t_c_m,
                });
            }
        }
    }
    pairs
}

/// Runs the calibration.
pub fn calibrate(data: &InfraDataset) -> Result<InfraCalibration, InfraCalibrationError> {
    let track = KeyframeTrack::from_model(&data.vo);
    let prepared = prepare(data, &track);
    let pairs = motion_pairs(&track, &prepared.poses);
    let sol = motion::solve(&pairs).ok_or(InfraCalibrationError::NoScale(pairs.len()))?;
    let t_f_m = pose_of_rows(std::path::Path::new("T_F_M"), &sol.t_f_m)
        .unwrap_or_else(|_| Isometry3::identity());
    let s = sol.scale;
    let keyframes: Vec<(u64, Isometry3<f64>)> = (0..track.stamps.len())
        .map(|k| (track.stamps[k], track.keyframe(k, s)))
        .collect();
    let mut blobs = data.blobs.clone();
    blobs.sort_by_key(|b| b.stamp_ns);
    let Solved {
        mut cameras,
        mut covariances,
        reports,
        mut solved_poses,
    } = solve_all(data, &prepared, &track, s, &t_f_m, &keyframes, &blobs);
    let ba = global_ba(
        data,
        &track,
        &keyframes,
        &t_f_m,
        &prepared.poses,
        &solved_poses,
        &blobs,
    );
    let (mut s, mut t_f_m_rows) = (s, sol.t_f_m);
    if let Some((b, ids, rmse)) = &ba {
        let input: Vec<Vector3<f64>> = track
            .unscaled
            .iter()
            .map(|t| t.translation.vector)
            .collect();
        s = super::ba::vo_scale(&input, &b.state);
        t_f_m_rows = matrix_rows(&b.state.t_f_m);
        for (c, &ci) in ids.iter().enumerate() {
            solved_poses[ci] = Some(b.state.cams[c]);
            let id = &data.cameras[ci].id;
            cameras.insert(
                id.clone(),
                camera_result(&b.state.cams[c], &b.camera_covariances[c], rmse[c]),
            );
            covariances.insert(id.clone(), b.camera_covariances[c]);
        }
    }
    let mut reports = reports;
    if let Some((_, ids, rmse)) = &ba {
        for (c, &ci) in ids.iter().enumerate() {
            reports[ci].reprojection_rmse_px = rmse[c];
        }
    }
    let sampson = sampson_pairs(data, &prepared.poses, &solved_poses);
    let top_view = top_view(data, &keyframes, &ba, &solved_poses, &covariances);
    let result = InfraResultFile {
        infra: InfraSection {
            frame: "vo".into(),
            vo_scale: s,
            t_cam0_marker: t_f_m_rows,
            t_world_vo: None,
            cameras,
        },
    };
    let stages = vec![
        "interpolation (eq. 6.3-6.6)".into(),
        "scale and T_F_M by alternation (eq. 6.7-6.9)".into(),
        "camera initialisation (eq. 6.10, Markley average)".into(),
        "per-camera refinement: marker corners + gated blobs, VO keyframes fixed".into(),
    ];
    let mut stages = stages;
    if let Some((b, _, _)) = &ba {
        stages.push(format!(
            "global bundle adjustment (keyframes, points, cameras, T_F_M; VO keypoints, blobs, marker corners, epipolar): cost {:.1} -> {:.1} in {} iterations, variance factor {:.3}",
            b.initial_cost, b.final_cost, b.iterations, b.variance_factor
        ));
    }
    Ok(InfraCalibration {
        result,
        report: InfraReport {
            stages,
            motion: Some(sol),
            cameras: reports,
            sampson,
            top_view,
        },
        covariances,
    })
}

/// The top view of the solved keyframes (the bundle adjustment's, else the scaled VO's)
/// and cameras.
fn top_view(
    data: &InfraDataset,
    keyframes: &[(u64, Isometry3<f64>)],
    ba: &Option<(super::ba_solver::BaSolution, Vec<usize>, Vec<f64>)>,
    solved: &[Option<Isometry3<f64>>],
    covariances: &BTreeMap<String, Matrix6<f64>>,
) -> TopView {
    let kf: Vec<Isometry3<f64>> = match ba {
        Some((b, _, _)) => b.state.kf.clone(),
        None => keyframes.iter().map(|k| k.1).collect(),
    };
    let cameras: Vec<_> = data
        .cameras
        .iter()
        .zip(solved)
        .filter_map(|(c, pose)| {
            let cov = covariances.get(&c.id)?;
            Some((c.id.clone(), &c.camera, (*pose)?, *cov))
        })
        .collect();
    TopView::new(&kf, &cameras)
}

struct Solved {
    cameras: BTreeMap<String, CameraResult>,
    covariances: BTreeMap<String, Matrix6<f64>>,
    reports: Vec<CameraReport>,
    solved_poses: Vec<Option<Isometry3<f64>>>,
}

/// Initialisation and per-camera refinement of every camera that has enough detections.
fn solve_all(
    data: &InfraDataset,
    prepared: &Prepared,
    track: &KeyframeTrack,
    s: f64,
    t_f_m: &Isometry3<f64>,
    keyframes: &[(u64, Isometry3<f64>)],
    blobs: &[super::io::Blob],
) -> Solved {
    let mut cameras = BTreeMap::new();
    let mut covariances = BTreeMap::new();
    let mut reports = Vec::new();
    let mut solved_poses: Vec<Option<Isometry3<f64>>> = Vec::new();
    for ((cam, mp), reason) in data
        .cameras
        .iter()
        .zip(&prepared.poses)
        .zip(&prepared.reasons)
    {
        let n_file = cam.detections.as_ref().map_or(0, Vec::len);
        let mut report = CameraReport {
            id: cam.id.clone(),
            solved: false,
            reason: reason.clone(),
            detections: n_file,
            detections_used: mp.len(),
            blobs_used: 0,
            reprojection_rmse_px: 0.0,
            blob_rmse_px: 0.0,
        };
        let solved = if reason.is_none() {
            solve_camera(
                data,
                cam,
                mp,
                track,
                s,
                t_f_m,
                keyframes,
                blobs,
                &mut report,
            )
        } else {
            None
        };
        if let Some((pose, cov)) = solved {
            cameras.insert(
                cam.id.clone(),
                camera_result(&pose, &cov, report.reprojection_rmse_px),
            );
            covariances.insert(cam.id.clone(), cov);
        }
        solved_poses.push(solved.map(|p| p.0));
        reports.push(report);
    }
    Solved {
        cameras,
        covariances,
        reports,
        solved_poses,
    }
}

fn camera_result(pose: &Isometry3<f64>, cov: &Matrix6<f64>, rmse: f64) -> CameraResult {
    let sd = |i: usize| cov[(i, i)].max(0.0).sqrt();
    CameraResult {
        t_world_cam: matrix_rows(pose),
        sigma_rot_deg: [sd(0).to_degrees(), sd(1).to_degrees(), sd(2).to_degrees()],
        sigma_trans_m: [sd(3), sd(4), sd(5)],
        reprojection_rmse_px: rmse,
    }
}

#[allow(clippy::too_many_arguments)]
fn solve_camera(
    data: &InfraDataset,
    cam: &super::dataset::CameraInput,
    mp: &[MarkerPose],
    track: &KeyframeTrack,
    s: f64,
    t_f_m: &Isometry3<f64>,
    keyframes: &[(u64, Isometry3<f64>)],
    blobs: &[super::io::Blob],
    report: &mut CameraReport,
) -> Option<(Isometry3<f64>, Matrix6<f64>)> {
    let markers: Vec<CornerObs> = mp
        .iter()
        .filter_map(|m| {
            Some(CornerObs {
                t_vo_m: track.at(m.detection.stamp_ns, s)? * t_f_m,
                detection: m.detection,
            })
        })
        .collect();
    let inits: Vec<Isometry3<f64>> = mp
        .iter()
        .zip(&markers)
        .map(|(m, o)| o.t_vo_m * m.t_c_m.inverse())
        .collect();
    let start = init::average_pose(&inits)?;
    let mut problem = CameraProblem {
        camera: &cam.camera,
        f_camera: &data.f_camera,
        corners: data.marker.corners_in_marker(),
        markers,
        blobs: Vec::new(),
    };
    let Some((first, _)) = init::refine(&problem, &start) else {
        report.reason = Some("marker-only refinement failed (degenerate or diverged)".into());
        return None;
    };
    problem.blobs =
        init::associate_blobs(&data.f_camera, &first.translation.vector, keyframes, blobs);
    let Some((pose, cov)) = init::refine(&problem, &first) else {
        report.reason = Some("refinement with blobs failed".into());
        return None;
    };
    report.solved = true;
    report.blobs_used = problem.blobs.len();
    (report.reprojection_rmse_px, report.blob_rmse_px) = rmse(&problem, &pose);
    Some((pose, cov))
}

fn rmse(problem: &CameraProblem<'_>, pose: &Isometry3<f64>) -> (f64, f64) {
    let p = msreg_estimator::Pose::new(pose.rotation, pose.translation.vector);
    let mut out = Vec::new();
    use crate::solve::Se3Problem;
    problem.residuals(&p, &mut out);
    let n_c = 8 * problem.markers.len();
    let sq = |r: &[crate::solve::Residual]| {
        r.iter().map(|x| x.value * x.value).sum::<f64>() / (r.len().max(2) / 2) as f64
    };
    (
        sq(&out[..n_c.min(out.len())]).sqrt(),
        sq(&out[n_c.min(out.len())..]).sqrt(),
    )
}

fn normalised(
    cam: &msreg_estimator::camera::Camera<f64>,
    uv: &Vector2<f64>,
) -> Option<Vector3<f64>> {
    let b = cam.unproject(uv)?;
    (b.z > 1e-6).then(|| b / b.z)
}

/// Sampson distances (eq. 6.13) of simultaneous marker corners for every solved pair.
fn sampson_pairs(
    data: &InfraDataset,
    poses: &[Vec<MarkerPose>],
    solved: &[Option<Isometry3<f64>>],
) -> Vec<PairSampson> {
    let mut out = Vec::new();
    for i in 0..data.cameras.len() {
        for j in i + 1..data.cameras.len() {
            let (Some(ti), Some(tj)) = (solved[i], solved[j]) else {
                continue;
            };
            let t_ij = ti.inverse() * tj;
            let e = msreg_estimator::lie::skew(&t_ij.translation.vector)
                * t_ij.rotation.to_rotation_matrix().matrix();
            let (mut sum, mut count) = (0.0, 0);
            for a in &poses[i] {
                let lo = poses[j].partition_point(|b| {
                    b.detection.stamp_ns + (SIMULTANEOUS_S * 1e9) as u64 <= a.detection.stamp_ns
                });
                for b in poses[j][lo..].iter().take_while(|b| {
                    b.detection.stamp_ns <= a.detection.stamp_ns + (SIMULTANEOUS_S * 1e9) as u64
                }) {
                    for k in 0..4 {
                        let (Some(xi), Some(xj)) = (
                            normalised(&data.cameras[i].camera, &a.detection.corners[k]),
                            normalised(&data.cameras[j].camera, &b.detection.corners[k]),
                        ) else {
                            continue;
                        };
                        let (exj, etxi) = (e * xj, e.transpose() * xi);
                        let num = xi.dot(&exj).powi(2);
                        let den = exj.x.powi(2) + exj.y.powi(2) + etxi.x.powi(2) + etxi.y.powi(2);
                        sum += num / den.max(1e-300);
                        count += 1;
                    }
                }
            }
            if count > 0 {
                out.push(PairSampson {
                    a: data.cameras[i].id.clone(),
                    b: data.cameras[j].id.clone(),
                    count,
                    mean: sum / count as f64,
                });
            }
        }
    }
    out
}

/// The global bundle adjustment over every solved camera; `None` when it fails (the
/// per-camera results are kept and the report says so).
#[allow(clippy::too_many_arguments)]
fn global_ba(
    data: &InfraDataset,
    track: &KeyframeTrack,
    keyframes: &[(u64, Isometry3<f64>)],
    t_f_m: &Isometry3<f64>,
    poses: &[Vec<MarkerPose>],
    solved: &[Option<Isometry3<f64>>],
    blobs: &[super::io::Blob],
) -> Option<(super::ba_solver::BaSolution, Vec<usize>, Vec<f64>)> {
    use super::ba::{BaProblem, BaState, BlobObs, MarkerObs, VoObs};
    let ids: Vec<usize> = (0..solved.len()).filter(|&i| solved[i].is_some()).collect();
    let s = keyframes.get(1).map_or(1.0, |k| {
        k.1.translation.vector.norm() / track.unscaled[1].translation.vector.norm().max(1e-12)
    });
    let first = data.vo.images.first()?.t_cam_world;
    let points: Vec<Vector3<f64>> = data
        .vo
        .points
        .iter()
        .map(|x| (first * nalgebra::Point3::from(*x)).coords * s)
        .collect();
    let mut vo = Vec::new();
    for (k, im) in data.vo.images.iter().enumerate() {
        for (uv, pid) in &im.keypoints {
            if let Some(point) = pid {
                vo.push(VoObs {
                    kf: k,
                    point: *point,
                    uv: *uv,
                });
            }
        }
    }
    let mut markers = Vec::new();
    let mut blob_obs = Vec::new();
    for (c, &ci) in ids.iter().enumerate() {
        for m in &poses[ci] {
            let Some((i, j, alpha)) = track.bracket(m.detection.stamp_ns) else {
                continue;
            };
            markers.push(MarkerObs {
                cam: c,
                i,
                j,
                alpha,
                detection: m.detection,
            });
        }
        let centre = solved[ci]?.translation.vector;
        for (k, kf) in keyframes.iter().enumerate() {
            for b in init::associate_blobs(&data.f_camera, &centre, std::slice::from_ref(kf), blobs)
            {
                blob_obs.push(BlobObs {
                    kf: k,
                    cam: c,
                    uv: b.uv,
                });
            }
        }
    }
    let epipolar = epipolar_obs(data, &ids, poses);
    let problem = BaProblem {
        epipolar,
        f: &data.f_camera,
        cams: ids.iter().map(|&i| &data.cameras[i].camera).collect(),
        corners: data.marker.corners_in_marker(),
        vo,
        markers,
        blobs: blob_obs,
    };
    let start = BaState {
        kf: keyframes.iter().map(|k| k.1).collect(),
        cams: ids.iter().filter_map(|&i| solved[i]).collect(),
        t_f_m: *t_f_m,
        points,
    };
    let b = super::ba_solver::solve(&problem, start, 30)?;
    let rmse = super::ba::marker_rmse(&problem, &b.state);
    Some((b, ids, rmse))
}

/// Simultaneous corners of every pair of cameras in the BA (indices into `ids`).
fn epipolar_obs(
    data: &InfraDataset,
    ids: &[usize],
    poses: &[Vec<MarkerPose>],
) -> Vec<super::ba::EpiObs> {
    let window = (SIMULTANEOUS_S * 1e9) as u64;
    let mut out = Vec::new();
    for (a, &ia) in ids.iter().enumerate() {
        for (b, &ib) in ids.iter().enumerate().skip(a + 1) {
            let (ca, cb) = (&data.cameras[ia].camera, &data.cameras[ib].camera);
            let f = 0.5 * (ca.intrinsics().fu + cb.intrinsics().fu);
            for da in &poses[ia] {
                let t = da.detection.stamp_ns;
                let lo = poses[ib].partition_point(|m| m.detection.stamp_ns + window <= t);
                for db in poses[ib][lo..]
                    .iter()
                    .take_while(|m| m.detection.stamp_ns <= t + window)
                {
                    for k in 0..4 {
                        let (Some(xa), Some(xb)) = (
                            normalised(ca, &da.detection.corners[k]),
                            normalised(cb, &db.detection.corners[k]),
                        ) else {
                            continue;
                        };
                        out.push(super::ba::EpiObs {
                            a,
                            b,
                            xa,
                            xb,
                            sigma: 0.3 / f,
                        });
                    }
                }
            }
        }
    }
    out
}

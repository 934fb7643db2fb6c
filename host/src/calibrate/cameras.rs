//! Intrinsic calibration of any number of cameras and their chain (`msreg calibrate
//! cameras`, issue 33): Kalibr's models ([`ModelKind`]), one batch bundle adjustment over
//! every camera's intrinsics, the extrinsics `T_cn_c0` and the target pose of every view.
//!
//! 1. Views: the frames of all cameras grouped by stamp (within
//!    [`CamerasOptions::sync_tolerance_ns`]); one target pose per view. Cameras whose stamps
//!    differ are refused ([`dataset`]).
//! 2. Start ([`init`]): per camera Zhang's closed form (pinhole) or a focal search (wide
//!    angle), PnP per image, then a bundle adjustment of that camera alone; the extrinsics
//!    from the views two cameras share (rotation mean, median translation).
//! 3. The joint solve ([`crate::solve::ba`]) with a Huber loss, then rounds of rejection:
//!    a corner whose residual exceeds [`CamerasOptions::corner_gate`] robust sigmas, an
//!    image whose median corner residual exceeds [`CamerasOptions::image_gate`] times the
//!    median over its camera's images;
//!    re-solved until no more are rejected (at most 3 rounds). Counts are reported.
//! 4. Sigmas: the marginal covariance of the global parameters (Schur complement) scaled by
//!    the residual variance; `T_cn_cnm1` and its covariance from `T_cn_c0` and
//!    `T_cnm1_c0` with their cross-covariance.
//!
//! Method, measured accuracy and the comparison with OpenCV: docs/cameras.md.

pub mod dataset;
pub mod init;
pub mod output;
pub mod problem;
#[cfg(test)]
mod tests;

use msreg_estimator::camera::model::{CameraModel, ModelKind};
use msreg_estimator::Pose;
use nalgebra::{DMatrix, Matrix6, Vector2, Vector3, Vector6};

use self::init::{initial_camera, mean_pose, model_of, pose_error, Frame};
use self::problem::{Layout, Observation, RigProblem, RigState};
use crate::solve::{solve_schur, Loss, SchurError, SchurOptions};
use crate::vision::solve_pnp;

/// The corners one camera saw in one image.
#[derive(Clone, Debug, PartialEq)]
pub struct ImageCorners {
    /// Image stamp, ns.
    pub stamp_ns: u64,
    /// A name for reports (the file name).
    pub name: String,
    /// Target-frame points (z = 0).
    pub points: Vec<Vector3<f64>>,
    /// Their pixels.
    pub pixels: Vec<Vector2<f64>>,
}

/// One camera's input.
#[derive(Clone, Debug, PartialEq)]
pub struct CameraInput {
    /// `camN`.
    pub name: String,
    /// The model to calibrate.
    pub kind: ModelKind,
    /// Image size.
    pub resolution: (u32, u32),
    /// Images with corners (images without a detection are left out by the caller).
    pub images: Vec<ImageCorners>,
}

/// Settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CamerasOptions {
    /// Frames of different cameras closer than this are one view, ns.
    pub sync_tolerance_ns: u64,
    /// Huber threshold in robust sigmas (`None`: plain least squares).
    pub huber: Option<f64>,
    /// Reject corners and images (off: every corner is used, as OpenCV's calibrateCamera).
    pub reject: bool,
    /// A corner is an outlier beyond this many robust sigmas (4.29: chi2(2) at 0.9999).
    pub corner_gate: f64,
    /// An image is an outlier when its median corner residual exceeds this multiple of the
    /// median of its camera's images.
    pub image_gate: f64,
}

impl Default for CamerasOptions {
    fn default() -> Self {
        Self {
            sync_tolerance_ns: 1_000_000,
            huber: Some(3.0),
            reject: true,
            corner_gate: 4.29,
            image_gate: 3.0,
        }
    }
}

/// Why the calibration failed.
#[derive(Debug, thiserror::Error)]
pub enum CamerasError {
    /// Too few images with corners for a camera.
    #[error("{camera}: {images} images with corners; at least 3 are needed")]
    TooFewImages {
        /// The camera.
        camera: String,
        /// How many it has.
        images: usize,
    },
    /// No starting pose could be found for a camera's images.
    #[error("{camera}: no starting intrinsics fit its corners (PnP failed on every image)")]
    NoStart {
        /// The camera.
        camera: String,
    },
    /// A camera shares no view with the cameras before it.
    #[error(
        "{camera} never sees the target at the same time as {others} (within {tolerance_ms} ms): \
         its extrinsic cannot be determined"
    )]
    NoOverlap {
        /// The camera.
        camera: String,
        /// The cameras already placed.
        others: String,
        /// The stamp tolerance, ms.
        tolerance_ms: f64,
    },
    /// The bundle adjustment failed.
    #[error("bundle adjustment: {0}")]
    Solver(#[from] SchurError),
}

/// One camera's result.
#[derive(Clone, Debug, PartialEq)]
pub struct CameraResult {
    /// `camN`.
    pub name: String,
    /// The intrinsics.
    pub model: CameraModel<f64>,
    /// 1-sigma of every parameter (Kalibr order).
    pub sigma: Vec<f64>,
    /// `T_cn_cnm1` and its covariance `[d_theta, d_p]` (camN, N >= 1).
    pub t_cn_cnm1: Option<(Pose<f64>, Matrix6<f64>)>,
    /// `T_cn_c0` (identity for cam0).
    pub t_cn_c0: Pose<f64>,
    /// RMS reprojection error over the corners used, px (per corner, both axes).
    pub rms_px: f64,
    /// Corners used / rejected.
    pub corners: (usize, usize),
    /// Images used / rejected.
    pub images: (usize, usize),
    /// `(image name, RMS px, used)` of every image.
    pub image_rms: Vec<(String, f64, bool)>,
}

/// The whole result.
#[derive(Clone, Debug, PartialEq)]
pub struct CamerasResult {
    /// Every camera, in input order.
    pub cameras: Vec<CameraResult>,
    /// Views (target poses) solved.
    pub views: usize,
    /// The robust sigma of a corner coordinate, px.
    pub pixel_sigma: f64,
    /// Variance factor of the final solve.
    pub variance_factor: f64,
    /// Solver iterations over every round.
    pub iterations: usize,
    /// The final solve converged.
    pub converged: bool,
    /// Rejection rounds run.
    pub rounds: usize,
    /// Covariance of the global parameters of the final solve.
    pub covariance: DMatrix<f64>,
}

/// Every corner with the view it belongs to and whether it is in use.
struct Corners {
    observations: Vec<Observation>,
    active: Vec<bool>,
    /// `(camera, image index)` of every observation.
    image: Vec<(usize, usize)>,
    /// View of `(camera, image)`.
    view_of: Vec<Vec<usize>>,
    views: usize,
}

/// Groups the images of all cameras into views by stamp.
fn build_corners(inputs: &[CameraInput], tolerance_ns: u64) -> Corners {
    let mut stamps: Vec<(u64, usize, usize)> = inputs
        .iter()
        .enumerate()
        .flat_map(|(c, cam)| {
            cam.images
                .iter()
                .enumerate()
                .map(move |(i, im)| (im.stamp_ns, c, i))
        })
        .collect();
    stamps.sort_unstable();
    let mut view_of: Vec<Vec<usize>> = inputs.iter().map(|c| vec![0; c.images.len()]).collect();
    let (mut views, mut start, mut members) = (0usize, None::<u64>, Vec::<usize>::new());
    for (stamp, c, i) in stamps {
        let new_view = match start {
            None => true,
            Some(s) => stamp - s > tolerance_ns || members.contains(&c),
        };
        if new_view {
            views += 1;
            start = Some(stamp);
            members.clear();
        }
        members.push(c);
        view_of[c][i] = views - 1;
    }
    let mut corners = Corners {
        observations: Vec::new(),
        active: Vec::new(),
        image: Vec::new(),
        view_of,
        views,
    };
    for (c, cam) in inputs.iter().enumerate() {
        for (i, im) in cam.images.iter().enumerate() {
            for (point, pixel) in im.points.iter().zip(&im.pixels) {
                corners.observations.push(Observation {
                    camera: c,
                    view: corners.view_of[c][i],
                    point: *point,
                    pixel: *pixel,
                });
                corners.active.push(true);
                corners.image.push((c, i));
            }
        }
    }
    corners
}

/// `T_c_target` of every image of a camera (`None`: no starting pose).
type ImagePoses = Vec<Option<Pose<f64>>>;

/// Final cost, intrinsics and per-image poses of a one-camera adjustment.
type SoloFit = (f64, CameraModel<f64>, Vec<Pose<f64>>);

/// Starting intrinsics and per-image poses `T_c_target` of one camera, refined by a bundle
/// adjustment of that camera alone. Double sphere has a valley of nearly equivalent
/// `(xi, alpha, f)`: its solo adjustment starts from five `xi` (same central focal length)
/// and keeps the lowest cost.
fn start_camera(input: &CameraInput) -> Result<(CameraModel<f64>, ImagePoses), CamerasError> {
    if input.images.len() < 3 {
        return Err(CamerasError::TooFewImages {
            camera: input.name.clone(),
            images: input.images.len(),
        });
    }
    let step = input.images.len().div_ceil(12).max(1);
    let sample: Vec<Frame> = input
        .images
        .iter()
        .step_by(step)
        .map(|im| Frame {
            points: &im.points,
            pixels: &im.pixels,
        })
        .collect();
    let camera = initial_camera(input.kind, input.resolution, &sample);
    let no_start = || CamerasError::NoStart {
        camera: input.name.clone(),
    };
    let model = model_of(input.kind, &camera).ok_or_else(no_start)?;
    let poses: Vec<Option<Pose<f64>>> = input
        .images
        .iter()
        .map(|im| {
            solve_pnp(&camera, &im.points, &im.pixels)
                .ok()
                .map(|s| s.t_cam_target)
        })
        .collect();
    let solo = CameraInput {
        images: input
            .images
            .iter()
            .zip(&poses)
            .filter(|(_, p)| p.is_some())
            .map(|(im, _)| im.clone())
            .collect(),
        ..input.clone()
    };
    if solo.images.len() < 3 {
        return Err(no_start());
    }
    let starts: Vec<CameraModel<f64>> = if input.kind == ModelKind::DoubleSphere {
        [-0.4, -0.2, 0.0, 0.2, 0.4]
            .iter()
            .filter_map(|&xi| {
                let mut m = model;
                m.params[0] = xi;
                m.params[2] *= 1.0 + xi;
                m.params[3] *= 1.0 + xi;
                m.is_valid().then_some(m)
            })
            .collect()
    } else {
        vec![model]
    };
    let mut best: Option<SoloFit> = None;
    for start in starts {
        let Ok(found) = solo_adjustment(&solo, start, poses.iter().flatten().copied()) else {
            continue;
        };
        if best.as_ref().is_none_or(|b| found.0 < b.0) {
            best = Some(found);
        }
    }
    let (_, model, refined) = best.ok_or_else(no_start)?;
    let mut refined = refined.into_iter();
    let poses = poses
        .iter()
        .map(|p| p.and_then(|_| refined.next()))
        .collect();
    Ok((model, poses))
}

/// The bundle adjustment of one camera from `model` and the images' poses (in image
/// order); returns the final cost, the model and the refined poses in image order.
fn solo_adjustment(
    solo: &CameraInput,
    model: CameraModel<f64>,
    poses: impl Iterator<Item = Pose<f64>>,
) -> Result<SoloFit, CamerasError> {
    let corners = build_corners(std::slice::from_ref(solo), 0);
    let mut views = vec![Pose::identity(); corners.views];
    for (i, p) in poses.enumerate() {
        views[corners.view_of[0][i]] = p;
    }
    let state = RigState {
        cameras: vec![model],
        extrinsics: vec![Pose::identity()],
        views,
    };
    let problem = RigProblem {
        observations: &corners.observations,
        views: corners.views,
        layout: Layout::of(&state.cameras),
        weight: 1.0,
    };
    let options = SchurOptions {
        loss: Loss::Huber(3.0),
        ..SchurOptions::default()
    };
    let sol = solve_schur(&problem, state, &options)?;
    let cost = sol.history.last().copied().unwrap_or(f64::INFINITY);
    let poses = (0..solo.images.len())
        .map(|i| sol.state.views[corners.view_of[0][i]])
        .collect();
    Ok((cost, sol.state.cameras[0], poses))
}

/// `T_cn_c0` of every camera from the views cameras share, placing cameras in order.
fn start_extrinsics(
    inputs: &[CameraInput],
    corners: &Corners,
    poses: &[Vec<Option<Pose<f64>>>],
    tolerance_ns: u64,
) -> Result<Vec<Pose<f64>>, CamerasError> {
    let mut ext: Vec<Option<Pose<f64>>> = vec![None; inputs.len()];
    ext[0] = Some(Pose::identity());
    // T_c_target of camera c in each view.
    let in_view = |c: usize| -> Vec<(usize, Pose<f64>)> {
        poses[c]
            .iter()
            .enumerate()
            .filter_map(|(i, p)| p.map(|p| (corners.view_of[c][i], p)))
            .collect()
    };
    for n in 1..inputs.len() {
        let mine = in_view(n);
        let mut candidates = Vec::new();
        for (m, placed) in ext.iter().enumerate().take(n) {
            let Some(t_m_c0) = placed else { continue };
            for (v, t_m_t) in in_view(m) {
                if let Some((_, t_n_t)) = mine.iter().find(|(w, _)| *w == v) {
                    candidates.push(t_n_t.compose(&t_m_t.inverse()).compose(t_m_c0));
                }
            }
        }
        ext[n] = Some(mean_pose(&candidates).ok_or_else(|| {
            CamerasError::NoOverlap {
                camera: inputs[n].name.clone(),
                others: inputs[..n]
                    .iter()
                    .map(|c| c.name.as_str())
                    .collect::<Vec<_>>()
                    .join(", "),
                tolerance_ms: tolerance_ns as f64 * 1e-6,
            }
        })?);
    }
    Ok(ext.into_iter().flatten().collect())
}

/// `T_c0_target` of every view from the first camera that saw it.
fn start_views(
    corners: &Corners,
    poses: &[Vec<Option<Pose<f64>>>],
    ext: &[Pose<f64>],
) -> Vec<Pose<f64>> {
    let mut views = vec![None; corners.views];
    for (c, cam) in poses.iter().enumerate() {
        for (i, p) in cam.iter().enumerate() {
            let v = corners.view_of[c][i];
            if let (None, Some(p)) = (views[v], p) {
                views[v] = Some(ext[c].inverse().compose(p));
            }
        }
    }
    // A view without a PnP pose has no active corner either (its images are dropped).
    views
        .into_iter()
        .map(|v| v.unwrap_or_else(Pose::identity))
        .collect()
}

/// Calibrates every camera of `inputs` (see the module docs).
pub fn calibrate_cameras(
    inputs: &[CameraInput],
    options: &CamerasOptions,
) -> Result<CamerasResult, CamerasError> {
    let mut starts = Vec::new();
    for input in inputs {
        starts.push(start_camera(input)?);
    }
    let mut corners = build_corners(inputs, options.sync_tolerance_ns);
    let poses: Vec<Vec<Option<Pose<f64>>>> = starts.iter().map(|s| s.1.clone()).collect();
    for (k, &(c, i)) in corners.image.iter().enumerate() {
        if poses[c][i].is_none() {
            corners.active[k] = false;
        }
    }
    let extrinsics = start_extrinsics(inputs, &corners, &poses, options.sync_tolerance_ns)?;
    let state = RigState {
        cameras: starts.iter().map(|s| s.0).collect(),
        views: start_views(&corners, &poses, &extrinsics),
        extrinsics,
    };
    solve_rounds(inputs, &mut corners, state, options)
}

/// Residual norms (px) of every observation at `state` (`NaN` where not projectable).
fn residual_norms(corners: &Corners, state: &RigState) -> Vec<f64> {
    let layout = Layout::of(&state.cameras);
    let problem = RigProblem {
        observations: &[],
        views: corners.views,
        layout,
        weight: 1.0,
    };
    corners
        .observations
        .iter()
        .map(|o| {
            problem
                .residual(state, o)
                .map_or(f64::NAN, |r| r.value.norm())
        })
        .collect()
}

/// Per-coordinate sigma from the median squared residual norm (chi2(2) median 2 ln 2).
fn robust_sigma(norms: impl Iterator<Item = f64>) -> f64 {
    let mut sq: Vec<f64> = norms.filter(|x| x.is_finite()).map(|x| x * x).collect();
    if sq.is_empty() {
        return 1.0;
    }
    sq.sort_by(f64::total_cmp);
    (sq[sq.len() / 2] / (2.0 * std::f64::consts::LN_2))
        .sqrt()
        .max(1e-6)
}

/// Marks outlying corners and images inactive; returns how many corners changed.
fn reject(
    corners: &mut Corners,
    inputs: &[CameraInput],
    norms: &[f64],
    sigma: f64,
    options: &CamerasOptions,
) -> usize {
    let mut changed = 0;
    for (k, n) in norms.iter().enumerate() {
        if corners.active[k] && (n.is_nan() || n / sigma > options.corner_gate) {
            corners.active[k] = false;
            changed += 1;
        }
    }
    for (c, cam) in inputs.iter().enumerate() {
        let medians = image_medians(corners, norms, c, cam.images.len());
        let mut live: Vec<f64> = medians.iter().copied().filter(|m| m.is_finite()).collect();
        if live.is_empty() {
            continue;
        }
        live.sort_by(f64::total_cmp);
        let typical = live[live.len() / 2];
        for (i, m) in medians.iter().enumerate() {
            if *m > options.image_gate * typical {
                for k in 0..corners.observations.len() {
                    if corners.image[k] == (c, i) && corners.active[k] {
                        corners.active[k] = false;
                        changed += 1;
                    }
                }
            }
        }
    }
    changed
}

/// `(RMS over the active corners, has an active corner)` of every image of camera `c`.
fn image_rms(corners: &Corners, norms: &[f64], c: usize, images: usize) -> Vec<(f64, bool)> {
    let mut acc = vec![(0.0, 0usize, false); images];
    for (k, &(cc, i)) in corners.image.iter().enumerate() {
        if cc == c && corners.active[k] {
            acc[i].0 += norms[k] * norms[k];
            acc[i].1 += 1;
            acc[i].2 = true;
        }
    }
    acc.iter()
        .map(|(s, n, a)| ((s / (*n).max(1) as f64).sqrt(), *a))
        .collect()
}

/// Median residual norm over every corner of each image of camera `c` (rejected corners
/// included, so an image whose corners are all poor is not excused by their rejection);
/// `NaN` for an image already out.
fn image_medians(corners: &Corners, norms: &[f64], c: usize, images: usize) -> Vec<f64> {
    let mut per: Vec<Vec<f64>> = vec![Vec::new(); images];
    let mut live = vec![false; images];
    for (k, &(cc, i)) in corners.image.iter().enumerate() {
        if cc == c {
            per[i].push(norms[k]);
            live[i] |= corners.active[k];
        }
    }
    per.iter_mut()
        .zip(live)
        .map(|(v, live)| {
            v.sort_by(f64::total_cmp);
            if live && !v.is_empty() {
                v[v.len() / 2]
            } else {
                f64::NAN
            }
        })
        .collect()
}

/// The joint solve and its rejection rounds.
fn solve_rounds(
    inputs: &[CameraInput],
    corners: &mut Corners,
    mut state: RigState,
    options: &CamerasOptions,
) -> Result<CamerasResult, CamerasError> {
    let mut sigma = robust_sigma(residual_norms(corners, &state).into_iter());
    let (mut iterations, mut rounds) = (0, 0);
    loop {
        rounds += 1;
        let active: Vec<Observation> = corners
            .observations
            .iter()
            .zip(&corners.active)
            .filter_map(|(o, a)| a.then_some(*o))
            .collect();
        let problem = RigProblem {
            observations: &active,
            views: corners.views,
            layout: Layout::of(&state.cameras),
            weight: 1.0 / (sigma * sigma),
        };
        let solve = SchurOptions {
            loss: options.huber.map_or(Loss::Squared, Loss::Huber),
            ..SchurOptions::default()
        };
        let sol = solve_schur(&problem, state, &solve)?;
        iterations += sol.iterations;
        state = sol.state.clone();
        let norms = residual_norms(corners, &state);
        let active_norms = norms
            .iter()
            .zip(&corners.active)
            .filter_map(|(n, a)| a.then_some(*n));
        sigma = robust_sigma(active_norms);
        let changed = if options.reject && rounds < 4 {
            reject(corners, inputs, &norms, sigma, options)
        } else {
            0
        };
        if changed == 0 {
            return Ok(summarise(
                inputs, corners, &state, &norms, sol, &problem, sigma, iterations, rounds,
            ));
        }
    }
}

/// The result of the final solve.
#[allow(clippy::too_many_arguments)]
fn summarise(
    inputs: &[CameraInput],
    corners: &Corners,
    state: &RigState,
    norms: &[f64],
    sol: crate::solve::SchurSummary<RigState>,
    problem: &RigProblem,
    sigma: f64,
    iterations: usize,
    rounds: usize,
) -> CamerasResult {
    let layout = &problem.layout;
    let cov = &sol.covariance;
    let cameras = inputs
        .iter()
        .enumerate()
        .map(|(c, input)| {
            let start = layout.intrinsics[c];
            let n = input.kind.param_count();
            let sigma_p = (0..n)
                .map(|k| cov[(start + k, start + k)].max(0.0).sqrt())
                .collect();
            let rms = image_rms(corners, norms, c, input.images.len());
            let (mut sum, mut used, mut total) = (0.0, 0, 0);
            for (k, &(cc, _)) in corners.image.iter().enumerate() {
                if cc == c {
                    total += 1;
                    if corners.active[k] {
                        sum += norms[k] * norms[k];
                        used += 1;
                    }
                }
            }
            let images_used = rms.iter().filter(|r| r.1).count();
            CameraResult {
                name: input.name.clone(),
                model: state.cameras[c],
                sigma: sigma_p,
                t_cn_cnm1: (c > 0).then(|| chain_link(state, layout, cov, c)),
                t_cn_c0: state.extrinsics[c],
                rms_px: (sum / used.max(1) as f64).sqrt(),
                corners: (used, total - used),
                images: (images_used, input.images.len() - images_used),
                image_rms: input
                    .images
                    .iter()
                    .zip(&rms)
                    .map(|(im, r)| (im.name.clone(), r.0, r.1))
                    .collect(),
            }
        })
        .collect();
    CamerasResult {
        cameras,
        views: corners.views,
        pixel_sigma: sigma,
        variance_factor: sol.variance_factor,
        iterations,
        converged: sol.converged,
        rounds,
        covariance: sol.covariance,
    }
}

/// `T_cn_cnm1 = T_cn_c0 T_cnm1_c0^-1` with its covariance, propagated by central
/// differences of the map from the two extrinsics' perturbations.
fn chain_link(
    state: &RigState,
    layout: &Layout,
    cov: &DMatrix<f64>,
    n: usize,
) -> (Pose<f64>, Matrix6<f64>) {
    let link = |a: &Pose<f64>, b: &Pose<f64>| a.compose(&b.inverse());
    let (tn, tm) = (state.extrinsics[n], state.extrinsics[n - 1]);
    let value = link(&tn, &tm);
    let perturb = |p: &Pose<f64>, d: &Vector6<f64>| {
        p.boxplus(&d.fixed_rows::<3>(0).into(), &d.fixed_rows::<3>(3).into())
    };
    let cols: Vec<usize> = [layout.extrinsic[n], layout.extrinsic[n - 1]]
        .iter()
        .flatten()
        .flat_map(|&e| e..e + 6)
        .collect();
    let mut j = DMatrix::<f64>::zeros(6, cols.len());
    let h = 1e-7;
    for k in 0..cols.len() {
        let mut d = [Vector6::zeros(); 2];
        d[k / 6][k % 6] = h;
        let plus = link(&perturb(&tn, &d[0]), &perturb(&tm, &d[1]));
        d[k / 6][k % 6] = -h;
        let minus = link(&perturb(&tn, &d[0]), &perturb(&tm, &d[1]));
        let diff = (pose_error(&value, &plus) - pose_error(&value, &minus)) / (2.0 * h);
        j.set_column(k, &diff);
    }
    let sub = DMatrix::from_fn(cols.len(), cols.len(), |a, b| cov[(cols[a], cols[b])]);
    let c = &j * sub * j.transpose();
    (value, Matrix6::from_fn(|a, b| c[(a, b)]))
}

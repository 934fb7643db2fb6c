//! A static camera registered in a prior map (dissertation chapter 7): `T_world_cam` of a
//! downward fisheye from a LiDAR map with reflectivity, a satellite ortho image and a
//! coarse GPS prior. Method and measurements: docs/prior_map.md.
//!
//! - [`input`]: the dataset (docs/formats.md section 2.9).
//! - [`orb`]: ORB features; [`init`]: rectification, matching against the satellite crop,
//!   RANSAC and PnP, or PnP on user correspondences.
//! - [`register`] (this file): the MI stage with the engine of [`crate::mi`]: the parallel
//!   coarse-to-fine grid over (x, y, z, yaw), then the 6-DoF refinement on the smoothed
//!   MI with curvature sigmas and per-DoF observability.
//! - [`cli`]: `msreg calibrate prior-map`.

pub mod grid;
pub mod init;
pub mod input;
pub mod orb;
pub mod slices;

use msreg_estimator::camera::Camera;
use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3, Vector6};

use super::scene::{image_order_key, MiScene, PoseParam};
use super::search::{grid_search_batch, refine, GridAxis, GridResult, RefineOptions, Refined};
use crate::vision::GrayImage;
use grid::GridScorer;
use init::{initialise, InitError, InitOptions, Initialisation};
use input::{PriorMapInput, Survey};
use slices::{mi_slices, MiSlice};

/// Settings of the whole registration.
#[derive(Clone, Debug, PartialEq)]
pub struct RegisterOptions {
    /// Initialisation.
    pub init: InitOptions,
    /// Grid half ranges of x, y, z (m) and yaw (rad) around the initial pose.
    pub grid_half: [f64; 4],
    /// Values each side of the centre per axis and level.
    pub grid_steps: usize,
    /// Grid levels.
    pub grid_levels: usize,
    /// Points in the grid (every n-th of those in view).
    pub grid_points: usize,
    /// Image blurs of the grid and the successive refinements (px), coarse to fine.
    pub grid_blur_px: f64,
    /// Refinement blurs (px).
    pub refine_blur_px: Vec<f64>,
    /// Points of each refinement (every n-th of those in view), paired with
    /// `refine_blur_px`; missing entries mean all points.
    pub refine_subsample: Vec<usize>,
    /// Refinement settings.
    pub refine: RefineOptions,
    /// Map points used: at most this far off the optical axis (deg) at the initial pose.
    pub max_view_deg: f64,
    /// Fewest map points in view.
    pub min_points: usize,
    /// Half width of the report's MI slices, as mean image motion (px).
    pub slice_half_px: f64,
    /// Samples each side of the estimate per slice.
    pub slice_steps: usize,
}

impl Default for RegisterOptions {
    fn default() -> Self {
        let grid_half = [0.5, 0.5, 0.3, 2f64.to_radians()];
        let [x, y, z, yaw] = grid_half;
        Self {
            init: InitOptions::default(),
            grid_half,
            grid_steps: 2,
            grid_levels: 3,
            grid_points: 6000,
            grid_blur_px: 4.0,
            refine_blur_px: vec![4.0, 1.0],
            refine_subsample: vec![4, 1],
            // The initial guess's sigma: the grid's half ranges around the initial pose (its
            // yaw range for every rotation); unconstrained DoFs report it.
            refine: RefineOptions {
                prior_sigma: Vector6::new(yaw, yaw, yaw, x, y, z),
                ..RefineOptions::default()
            },
            max_view_deg: 70.0,
            min_points: 2000,
            slice_half_px: 3.0,
            slice_steps: 6,
        }
    }
}

/// Why the registration could not run (beyond bad files).
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum RegisterError {
    /// No initial pose.
    #[error(transparent)]
    Init(#[from] InitError),
    /// Too few map points in view at the initial pose.
    #[error("only {visible} map points are in view at the initial pose (need {needed})")]
    TooFewPoints {
        /// In view.
        visible: usize,
        /// Needed.
        needed: usize,
    },
}

/// The result.
#[derive(Clone, Debug)]
pub struct Registration {
    /// The initial pose and how it was found.
    pub init: Initialisation,
    /// `T_world_cam` after the grid.
    pub after_grid: Isometry3<f64>,
    /// The final refinement (`x` = `T_world_cam`, covariance `[omega_cam; v_world]`).
    pub refined: Refined,
    /// Map points used.
    pub points_used: usize,
    /// Grid candidates evaluated.
    pub grid_evaluations: usize,
    /// MI along each DoF through the optimum.
    pub slices: Vec<MiSlice>,
}

/// The map points within `max_view_deg` of the optical axis and inside the image at
/// `t_world_cam`, with their reflectivity, in image order at that pose
/// ([`image_order_key`]).
pub fn points_in_view(
    input: &PriorMapInput,
    t_world_cam: &Isometry3<f64>,
    max_view_deg: f64,
) -> (Vec<Vector3<f64>>, Vec<f32>) {
    let t_cam_world = t_world_cam.inverse();
    let cos_max = max_view_deg.to_radians().cos();
    let mut keyed: Vec<((i64, f64), Vector3<f64>, f32)> = input
        .map
        .points
        .iter()
        .filter_map(|p| {
            let pc = t_cam_world * nalgebra::Point3::from(p.xyz);
            if pc.z <= cos_max * pc.coords.norm() {
                return None;
            }
            let q = input.camera.project(&pc.coords)?;
            input.camera.in_image(&q.pixel, 2.0).then(|| {
                let key = image_order_key(&q.pixel);
                (key, p.xyz, p.intensity)
            })
        })
        .collect();
    keyed.sort_by(|a, b| a.0 .0.cmp(&b.0 .0).then(a.0 .1.total_cmp(&b.0 .1)));
    keyed.into_iter().map(|(_, p, i)| (p, i)).unzip()
}

/// The MI scene of the registration: the map points in view at `start` (`T_world_cam`)
/// against the fisheye image blurred by the grid's blur.
pub fn mi_scene(
    input: &PriorMapInput,
    start: &Isometry3<f64>,
    options: &RegisterOptions,
) -> Result<MiScene, RegisterError> {
    let (points, intensities) = points_in_view(input, start, options.max_view_deg);
    if points.len() < options.min_points {
        return Err(RegisterError::TooFewPoints {
            visible: points.len(),
            needed: options.min_points,
        });
    }
    Ok(MiScene::new(
        points,
        &intensities,
        &input.image,
        input.camera,
        options.grid_blur_px,
    ))
}

/// `T_world_cam` of grid parameters `[x, y, z, yaw]` around `start`: the translation
/// added in W, the yaw a rotation about W's z axis applied on the left.
pub fn grid_pose(start: &Isometry3<f64>, v: &[f64]) -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::from(start.translation.vector + Vector3::new(v[0], v[1], v[2])),
        UnitQuaternion::from_axis_angle(&Vector3::z_axis(), v[3]) * start.rotation,
    )
}

/// The points of `scene` the grid scores (every n-th, about `options.grid_points`).
pub fn grid_scene(scene: &MiScene, options: &RegisterOptions) -> MiScene {
    scene.subsampled(scene.points.len() / options.grid_points.max(1))
}

/// The coarse-to-fine grid over (x, y, z, yaw) around `start` on the hard-binned MI of
/// the points of `grid_scene` ([`grid::GridScorer`]).
pub fn grid_stage(
    grid_scene: &MiScene,
    image: &GrayImage,
    start: &Isometry3<f64>,
    options: &RegisterOptions,
) -> GridResult {
    let axes = options.grid_half.map(|half_range| GridAxis {
        half_range,
        steps: options.grid_steps,
    });
    let scorer = GridScorer::new(grid_scene, image, options.grid_blur_px, start);
    grid_search_batch(&axes, options.grid_levels, |c| scorer.score_all(c))
}

/// The 6-DoF refinements from `x` (`T_world_cam`), one per blur of
/// `options.refine_blur_px` (coarse to fine, on every `refine_subsample`-th point); the
/// last one's result and scene.
pub fn refine_stage(
    scene: &MiScene,
    image: &GrayImage,
    x: &Isometry3<f64>,
    options: &RegisterOptions,
) -> (Refined, MiScene) {
    let param = PoseParam::SourceFromCam;
    let mut x = *x;
    let mut last = None;
    for (k, &blur) in options.refine_blur_px.iter().enumerate() {
        let step = options.refine_subsample.get(k).copied().unwrap_or(1);
        let level = scene.subsampled(step).with_image(image, blur);
        let r = refine(&level, param, &x, &options.refine);
        x = r.x;
        last = Some((r, level));
    }
    last.unwrap_or_else(|| (refine(scene, param, &x, &options.refine), scene.clone()))
}

/// The MI stage's result.
#[derive(Clone, Debug)]
pub struct MiStage {
    /// `T_world_cam` after the grid.
    pub after_grid: Isometry3<f64>,
    /// The final refinement.
    pub refined: Refined,
    /// The scene of the final refinement (its points and image).
    pub final_scene: MiScene,
    /// Map points in view.
    pub points_used: usize,
    /// Grid candidates evaluated.
    pub grid_evaluations: usize,
}

/// The MI stage from `start` (`T_world_cam`): grid over (x, y, z, yaw), then refinements.
pub fn register_mi(
    input: &PriorMapInput,
    start: &Isometry3<f64>,
    options: &RegisterOptions,
) -> Result<MiStage, RegisterError> {
    let scene = mi_scene(input, start, options)?;
    let grid = grid_stage(&grid_scene(&scene, options), &input.image, start, options);
    let after_grid = grid_pose(start, &grid.best);
    let (refined, final_scene) = refine_stage(&scene, &input.image, &after_grid, options);
    Ok(MiStage {
        after_grid,
        refined,
        final_scene,
        points_used: scene.points.len(),
        grid_evaluations: grid.evaluations,
    })
}

/// Initialisation, then the MI stage, then the MI slices through the optimum.
pub fn register(
    input: &PriorMapInput,
    options: &RegisterOptions,
) -> Result<Registration, RegisterError> {
    let init = initialise(input, &options.init)?;
    let stage = register_mi(input, &init.t_world_cam, options)?;
    let slices = mi_slices(
        &stage.final_scene,
        &stage.refined,
        options.slice_half_px,
        options.slice_steps,
    );
    Ok(Registration {
        init,
        after_grid: stage.after_grid,
        refined: stage.refined,
        points_used: stage.points_used,
        grid_evaluations: stage.grid_evaluations,
        slices,
    })
}

/// Reprojection error (px) of each survey point under `t_world_cam` (NaN where it does not
/// project).
pub fn survey_errors(
    camera: &Camera<f64>,
    t_world_cam: &Isometry3<f64>,
    survey: &[Survey],
) -> Vec<f64> {
    let t = t_world_cam.inverse();
    survey
        .iter()
        .map(|s| {
            let pc = t * nalgebra::Point3::from(s.xyz);
            match camera.project(&pc.coords) {
                Some(q) if pc.z > 0.0 => (q.pixel - s.uv).norm(),
                _ => f64::NAN,
            }
        })
        .collect()
}

/// Median of the finite values (NaN when none).
pub fn median(values: &[f64]) -> f64 {
    let mut v: Vec<f64> = values.iter().copied().filter(|x| x.is_finite()).collect();
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// Rotation about the world z axis taking `truth` to `estimate` (rad): the yaw error.
pub fn yaw_error(estimate: &Isometry3<f64>, truth: &Isometry3<f64>) -> f64 {
    (estimate.rotation * truth.rotation.inverse())
        .scaled_axis()
        .z
}

/// The `cam0` section of a result or ground-truth file: `T_world_cam` with sigmas.
pub fn t_world_cam_yaml(t: &Isometry3<f64>, sigma_rot_deg: [f64; 3], sigma_m: [f64; 3]) -> String {
    let m = t.to_homogeneous();
    let rows: Vec<String> = (0..4)
        .map(|i| {
            format!(
                "[{}, {}, {}, {}]",
                m[(i, 0)],
                m[(i, 1)],
                m[(i, 2)],
                m[(i, 3)]
            )
        })
        .collect();
    let list = |v: [f64; 3]| format!("[{}, {}, {}]", v[0], v[1], v[2]);
    format!(
        "cam0:\n  # p_world = T_world_cam * p_cam\n  T_world_cam: [{}]\n  sigma_rot_deg: {}\n  \
         sigma_trans_m: {}\n",
        rows.join(",\n                "),
        list(sigma_rot_deg),
        list(sigma_m)
    )
}

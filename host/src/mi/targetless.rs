//! Targetless LiDAR-camera calibration: the MI of LiDAR intensity and image intensity
//! over `T_cam_lidar` (Pandey et al.), from a rough initial guess: a coarse-to-fine 6-DoF
//! grid on a blurred image, then the continuous refinement on finer blurs.

use msreg_estimator::camera::Camera;
use nalgebra::{Isometry3, Vector3, Vector6};

use super::scene::{highpass, MiScene, PoseParam};
use super::search::{grid_search, refine, GridAxis, GridScore, RefineOptions, Refined};
use crate::pointcloud::PointCloud;
use crate::vision::GrayImage;

/// Why the targetless calibration could not run.
#[derive(Debug, thiserror::Error)]
pub enum TargetlessError {
    /// Too few LiDAR points project into the image at the initial guess.
    #[error(
        "only {visible} LiDAR points project into the image at the initial guess (need {needed})"
    )]
    TooFewVisible {
        /// Points visible.
        visible: usize,
        /// Minimum.
        needed: usize,
    },
}

/// Settings.
#[derive(Clone, Debug, PartialEq)]
pub struct TargetlessOptions {
    /// Grid half range of each rotation axis (deg).
    pub grid_rot_deg: f64,
    /// Grid half range of each translation axis (m).
    pub grid_trans_m: f64,
    /// Grid levels (3 values per axis each); 0 skips the grid.
    pub grid_levels: usize,
    /// Image blur of the grid (px).
    pub grid_blur_px: f64,
    /// Every n-th point in the grid.
    pub grid_subsample: usize,
    /// Image blurs of the successive refinements (px), coarse to fine.
    pub refine_blur_px: Vec<f64>,
    /// Refinement settings.
    pub refine: RefineOptions,
    /// Points must project this far inside the image at the guess (px, may be negative).
    pub margin_px: f64,
    /// Minimum number of visible points.
    pub min_points: usize,
    /// High-pass the image (subtract a Gaussian blur of this sigma, px) before MI; 0 off.
    pub highpass_px: f64,
    /// Keep only the ground: points within this height (m) of the densest LiDAR-z layer
    /// of the lower half; `None` keeps all points.
    pub ground_band_m: Option<f64>,
}

impl Default for TargetlessOptions {
    fn default() -> Self {
        Self {
            grid_rot_deg: 3.0,
            grid_trans_m: 0.15,
            // The 6-DoF grid finds higher-MI poses degrees away on real single-pair data
            // (docs/prior_map.md); off by default, the refinement stays local.
            grid_levels: 0,
            grid_blur_px: 8.0,
            grid_subsample: 4,
            refine_blur_px: vec![2.0, 1.0],
            refine: RefineOptions::default(),
            margin_px: -50.0,
            min_points: 500,
            highpass_px: 30.0,
            ground_band_m: Some(0.25),
        }
    }
}

/// The outcome.
#[derive(Clone, Debug)]
pub struct TargetlessResult {
    /// The initial guess.
    pub initial: Isometry3<f64>,
    /// After the grid.
    pub after_grid: Isometry3<f64>,
    /// The final refinement (its `x` is `T_cam_lidar`).
    pub refined: Refined,
    /// LiDAR points used.
    pub points_used: usize,
    /// Grid candidates evaluated.
    pub grid_evaluations: usize,
}

/// The LiDAR points in front of the camera that project (with `margin_px`) into the image
/// at `t_cam_lidar`, with their intensities.
pub fn visible_points(
    cloud: &PointCloud,
    camera: &Camera<f64>,
    t_cam_lidar: &Isometry3<f64>,
    margin_px: f64,
) -> (Vec<Vector3<f64>>, Vec<f32>) {
    cloud
        .points
        .iter()
        .filter(|p| {
            let pc = t_cam_lidar * nalgebra::Point3::from(p.xyz);
            pc.z > 0.5
                && camera
                    .project(&pc.coords)
                    .is_some_and(|q| camera.in_image(&q.pixel, margin_px))
        })
        .map(|p| (p.xyz, p.intensity))
        .unzip()
}

/// Centre of the densest 0.2 m layer of z among the lower half of the points (the road
/// surface for a level-mounted LiDAR); `None` for an empty set.
pub fn ground_height(points: &[Vector3<f64>]) -> Option<f64> {
    let mut zs: Vec<f64> = points.iter().map(|p| p.z).collect();
    zs.sort_by(f64::total_cmp);
    let lower = &zs[..zs.len() / 2];
    let mut best = (0, None);
    let mut hi = 0;
    for (lo, &z) in lower.iter().enumerate() {
        while hi < lower.len() && lower[hi] < z + 0.2 {
            hi += 1;
        }
        if hi - lo > best.0 {
            best = (hi - lo, Some(z + 0.1));
        }
    }
    best.1
}

/// The points within `band` (m) of [`ground_height`].
pub fn ground_band(
    points: &[Vector3<f64>],
    intensities: &[f32],
    band: f64,
) -> (Vec<Vector3<f64>>, Vec<f32>) {
    let ground = ground_height(points).unwrap_or(f64::NAN);
    points
        .iter()
        .zip(intensities)
        .filter(|(p, _)| (p.z - ground).abs() < band)
        .map(|(p, v)| (*p, *v))
        .unzip()
}

/// Runs grid + refinement from `initial` (`T_cam_lidar`).
pub fn calibrate_targetless(
    cloud: &PointCloud,
    image: &GrayImage,
    camera: &Camera<f64>,
    initial: &Isometry3<f64>,
    options: &TargetlessOptions,
) -> Result<TargetlessResult, TargetlessError> {
    let (points, intensities) = visible_points(cloud, camera, initial, options.margin_px);
    let (points, intensities) = match options.ground_band_m {
        Some(band) => ground_band(&points, &intensities, band),
        None => (points, intensities),
    };
    let filtered;
    let image = if options.highpass_px > 0.0 {
        filtered = highpass(image, options.highpass_px);
        &filtered
    } else {
        image
    };
    if points.len() < options.min_points {
        return Err(TargetlessError::TooFewVisible {
            visible: points.len(),
            needed: options.min_points,
        });
    }
    let points_used = points.len();
    let scene = MiScene::new(points, &intensities, image, *camera, options.grid_blur_px);
    let param = PoseParam::CamFromSource;
    let r = options.grid_rot_deg.to_radians();
    let t = options.grid_trans_m;
    let axes: Vec<GridAxis> = [r, r, r, t, t, t]
        .iter()
        .map(|&half_range| GridAxis {
            half_range,
            steps: 1,
        })
        .collect();
    let (after_grid, grid_evaluations) = if options.grid_levels == 0 {
        (*initial, 0)
    } else {
        let coarse = scene.subsampled(options.grid_subsample);
        let grid = grid_search(
            &coarse,
            &axes,
            options.grid_levels,
            GridScore::Smoothed,
            |v| param.retract(initial, &Vector6::from_column_slice(v)),
        );
        let x = param.retract(initial, &Vector6::from_column_slice(&grid.best));
        (x, grid.evaluations)
    };
    let mut x = after_grid;
    let mut refined = None;
    for &blur in &options.refine_blur_px {
        let level = scene.with_image(image, blur);
        let r = refine(&level, param, &x, &options.refine);
        x = r.x;
        refined = Some(r);
    }
    let refined = refined.unwrap_or_else(|| refine(&scene, param, &x, &options.refine));
    Ok(TargetlessResult {
        initial: *initial,
        after_grid,
        refined,
        points_used,
        grid_evaluations,
    })
}

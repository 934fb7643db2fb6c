//! Targetless LiDAR-camera calibration: the MI of LiDAR intensity and image intensity
//! over `T_cam_lidar` (Pandey et al.), from a rough initial guess: the wider-basin search
//! of [`super::basin`] (a multi-candidate coarse-to-fine lattice over the three rotations
//! and the two translations across the optical axis, on blurred images; a flatness probe of
//! the optical-axis translation), then the continuous refinement on finer blurs from the
//! best candidates, holding the DoFs the MI does not determine.

use msreg_estimator::camera::Camera;
use nalgebra::{Isometry3, Vector3};

use super::basin::{basin_search, BasinOptions, BasinResult};
use super::scene::{highpass, MiScene, PoseParam};
use super::search::{refine, RefineOptions, Refined};
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
    /// The wider-basin search before the refinement; `None` refines from the guess alone
    /// (all six DoF free).
    pub basin: Option<BasinOptions>,
    /// Refine from this many of the basin search's best candidates and keep the highest
    /// final MI.
    pub refine_candidates: usize,
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
    /// With `ground_band_m`: keep the points off the ground band too, as a second group
    /// with its own joint histogram (`MiScene::grouped`: the score is the
    /// sample-weighted mean of the two groups' MI, their summed log-likelihood ratio).
    pub off_ground_group: bool,
}

impl Default for TargetlessOptions {
    fn default() -> Self {
        Self {
            basin: Some(BasinOptions::default()),
            refine_candidates: 2,
            refine_blur_px: vec![2.0, 1.0],
            refine: RefineOptions::default(),
            // Inside by 100 px at the guess (chosen on seed 7 with the basin): the points
            // stay in view over the basin, so the MI cannot rise by dropping points at the
            // border.
            margin_px: 100.0,
            min_points: 500,
            highpass_px: 30.0,
            ground_band_m: Some(0.25),
            off_ground_group: true,
        }
    }
}

/// The outcome.
#[derive(Clone, Debug)]
pub struct TargetlessResult {
    /// The initial guess.
    pub initial: Isometry3<f64>,
    /// The basin search's best candidate (the guess without it).
    pub after_grid: Isometry3<f64>,
    /// The basin search (candidates, probes, held DoFs), when run.
    pub basin: Option<BasinResult>,
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

/// Group of each point: 0 within `band` (m) of [`ground_height`], else 1.
pub fn ground_groups(points: &[Vector3<f64>], band: f64) -> Vec<u8> {
    let ground = ground_height(points).unwrap_or(f64::NAN);
    points
        .iter()
        .map(|p| u8::from((p.z - ground).abs() >= band || p.z.is_nan()))
        .collect()
}

/// The MI scene of `calibrate_targetless` on `image` (already high-passed when
/// configured): the ground band alone, or ground and off-ground groups, or all points.
pub fn targetless_scene(
    points: Vec<Vector3<f64>>,
    intensities: &[f32],
    image: &GrayImage,
    camera: &Camera<f64>,
    blur_px: f64,
    options: &TargetlessOptions,
) -> MiScene {
    match options.ground_band_m {
        Some(band) if options.off_ground_group => {
            let groups = ground_groups(&points, band);
            MiScene::grouped(points, intensities, groups, image, *camera, blur_px)
        }
        Some(band) => {
            let (p, i) = ground_band(&points, intensities, band);
            MiScene::new(p, &i, image, *camera, blur_px)
        }
        None => MiScene::new(points, intensities, image, *camera, blur_px),
    }
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
    let filtered;
    let image = if options.highpass_px > 0.0 {
        filtered = highpass(image, options.highpass_px);
        &filtered
    } else {
        image
    };
    let first_blur = options.refine_blur_px.first().copied().unwrap_or(1.0);
    // In image order at the guess (cache locality), keeping the lattice's subsample.
    let stride = options.basin.as_ref().map_or(1, |b| b.subsample);
    let scene = targetless_scene(points, &intensities, image, camera, first_blur, options)
        .in_image_order(initial, stride);
    if scene.points.len() < options.min_points {
        return Err(TargetlessError::TooFewVisible {
            visible: scene.points.len(),
            needed: options.min_points,
        });
    }
    let points_used = scene.points.len();
    let param = PoseParam::CamFromSource;
    let basin = options
        .basin
        .as_ref()
        .map(|b| basin_search(&scene, image, param, initial, b, options.refine.cell_px));
    let (starts, held, grid_evaluations) = match &basin {
        Some(b) if !b.candidates.is_empty() => (
            b.candidates
                .iter()
                .take(options.refine_candidates.max(1))
                .copied()
                .collect(),
            b.held,
            b.evaluations,
        ),
        _ => (vec![*initial], [false; 6], 0),
    };
    let refine_options = RefineOptions {
        held,
        ..options.refine
    };
    let levels: Vec<MiScene> = options
        .refine_blur_px
        .iter()
        .map(|&blur| scene.with_image(image, blur))
        .collect();
    let refined = starts
        .iter()
        .map(|start| refine_levels(&scene, &levels, param, start, &refine_options))
        .max_by(|a, b| a.smoothed.mi.total_cmp(&b.smoothed.mi))
        .unwrap_or_else(|| refine(&scene, param, initial, &refine_options));
    Ok(TargetlessResult {
        initial: *initial,
        after_grid: starts[0],
        basin,
        refined,
        points_used,
        grid_evaluations,
    })
}

/// The refinement on each image level in turn from `start` (on `scene` when no levels).
fn refine_levels(
    scene: &MiScene,
    levels: &[MiScene],
    param: PoseParam,
    start: &Isometry3<f64>,
    options: &RefineOptions,
) -> Refined {
    let mut x = *start;
    let mut refined = None;
    for level in levels {
        let r = refine(level, param, &x, options);
        x = r.x;
        refined = Some(r);
    }
    refined.unwrap_or_else(|| refine(scene, param, &x, options))
}

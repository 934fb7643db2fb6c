//! Initialisation of `T_world_cam`: either from user correspondences (`prior.yaml`) by PnP,
//! or automatically:
//!
//! 1. rectify the fisheye into a virtual pinhole view along its optical axis (top-down for
//!    a downward camera), focal `h / m` so that the ground appears at the satellite's
//!    `m` metres per pixel at the prior height `h` (a few height scales are tried);
//! 2. ORB features in that view and in the satellite crop around the GPS prior
//!    (`3 sigma` plus the view's footprint), matched by Hamming distance;
//! 3. RANSAC of the plane-to-plane homography between the two views (4-point DLT);
//! 4. PnP ([`crate::vision::pnp`]) of the inliers: the fisheye pixel of each rectified
//!    keypoint against the map point of its satellite keypoint (ground height from the
//!    LiDAR map), verified by the fisheye reprojection error and solved again.

use msreg_estimator::camera::Camera;
use msreg_estimator::Pose;
use nalgebra::{DMatrix, Isometry3, Matrix3, Translation3, UnitQuaternion, Vector2, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::input::{PriorMapInput, Satellite};
use super::orb::{match_features, orb, OrbOptions};
use crate::vision::pnp::{refine_pnp, solve_pnp, PnpError};
use crate::vision::GrayImage;

/// Settings of the automatic initialisation.
#[derive(Clone, Debug, PartialEq)]
pub struct InitOptions {
    /// Largest off-axis angle of the rectified view (deg).
    pub max_view_deg: f64,
    /// Multipliers of the prior height tried for the rectified scale, in order.
    pub height_scales: Vec<f64>,
    /// RANSAC inlier threshold in satellite pixels.
    pub ransac_px: f64,
    /// RANSAC iterations.
    pub iterations: usize,
    /// Fewest verified matches accepted.
    pub min_inliers: usize,
    /// Fisheye reprojection threshold of the verification (px).
    pub pnp_px: f64,
    /// ORB settings.
    pub orb: OrbOptions,
    /// Largest Hamming distance of a match.
    pub max_hamming: u32,
}

impl Default for InitOptions {
    fn default() -> Self {
        Self {
            max_view_deg: 60.0,
            height_scales: vec![1.0, 0.85, 1.18],
            ransac_px: 3.0,
            iterations: 4000,
            min_inliers: 12,
            pnp_px: 6.0,
            orb: OrbOptions::default(),
            max_hamming: 80,
        }
    }
}

/// Where the initial pose came from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum InitSource {
    /// ORB matching against the satellite image.
    Automatic,
    /// The correspondences of `prior.yaml`.
    UserCorrespondences,
}

/// An initial pose.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Initialisation {
    /// `T_world_cam`.
    #[serde(skip)]
    pub t_world_cam: Isometry3<f64>,
    /// How it was found.
    pub source: InitSource,
    /// Keypoints in the rectified view and in the satellite crop.
    pub keypoints: (usize, usize),
    /// Descriptor matches.
    pub matches: usize,
    /// Matches consistent with the final PnP pose.
    pub inliers: usize,
    /// Their RMS reprojection error (px).
    pub rms_px: f64,
    /// Height scale of the successful rectification.
    pub height_scale: f64,
}

/// Why no initial pose was found.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum InitError {
    /// Neither a position prior nor correspondences.
    #[error("prior.yaml has no position (needed for automatic matching) and fewer than 4 correspondences")]
    NoPrior,
    /// No satellite image for automatic matching.
    #[error("no map/satellite.png for automatic matching and fewer than 4 correspondences in prior.yaml")]
    NoSatellite,
    /// Automatic matching found too few consistent matches.
    #[error(
        "automatic matching failed: {inliers} consistent matches of {matches} (need {needed}); \
         give at least 4 correspondences {{uv, xyz}} in prior.yaml"
    )]
    MatchingFailed {
        /// Descriptor matches (best height scale).
        matches: usize,
        /// Verified matches.
        inliers: usize,
        /// Required.
        needed: usize,
    },
    /// PnP on the user correspondences failed.
    #[error("PnP on the prior.yaml correspondences failed: {0}")]
    Pnp(PnpError),
    /// Automatic matching found a pose whose yaw contradicts the prior's.
    #[error(
        "automatic matching failed: its pose has yaw {found_deg:.1} deg, {off_deg:.1} deg from \
         the prior's {prior_deg:.1} +- {sigma_deg:.1} deg (more than 3 sigma); give at least 4 \
         correspondences {{uv, xyz}} in prior.yaml"
    )]
    YawInconsistent {
        /// Yaw of the matched pose (deg).
        found_deg: f64,
        /// Its difference to the prior (deg, wrapped to +-180).
        off_deg: f64,
        /// `prior.yaml` `yaw_deg`.
        prior_deg: f64,
        /// `prior.yaml` `sigma_yaw_deg` (default [`DEFAULT_SIGMA_YAW_DEG`]).
        sigma_deg: f64,
    },
}

/// `sigma_yaw_deg` when `prior.yaml` gives `yaw_deg` without it.
pub const DEFAULT_SIGMA_YAW_DEG: f64 = 10.0;

/// Heading of the camera's x axis in W (rad, from east towards north), the `yaw_deg` of
/// `prior.yaml`.
pub fn camera_yaw(t_world_cam: &Isometry3<f64>) -> f64 {
    let x = t_world_cam.rotation * Vector3::x();
    x.y.atan2(x.x)
}

/// `Ok` when `prior.yaml` has no yaw or `t_world_cam`'s yaw is within 3 sigma of it.
pub fn check_yaw_prior(
    input: &PriorMapInput,
    t_world_cam: &Isometry3<f64>,
) -> Result<(), InitError> {
    let Some(prior_deg) = input.prior.yaw_deg else {
        return Ok(());
    };
    let sigma_deg = input.prior.sigma_yaw_deg.unwrap_or(DEFAULT_SIGMA_YAW_DEG);
    let found_deg = camera_yaw(t_world_cam).to_degrees();
    let off_deg = (found_deg - prior_deg + 540.0).rem_euclid(360.0) - 180.0;
    if off_deg.abs() <= 3.0 * sigma_deg {
        return Ok(());
    }
    Err(InitError::YawInconsistent {
        found_deg,
        off_deg,
        prior_deg,
        sigma_deg,
    })
}

/// `T_world_cam` and RMS (px) from world points and their pixels (any 3-D layout with a
/// dominant plane): PnP on the points flattened onto their best-fit plane, then the
/// reprojection refinement on the true points.
pub fn pnp_world(
    camera: &Camera<f64>,
    xyz: &[Vector3<f64>],
    uv: &[Vector2<f64>],
) -> Result<(Isometry3<f64>, f64), PnpError> {
    let n = xyz.len().max(1) as f64;
    let centroid = xyz.iter().sum::<Vector3<f64>>() / n;
    let mut scatter = Matrix3::zeros();
    for p in xyz {
        scatter += (p - centroid) * (p - centroid).transpose();
    }
    let eig = nalgebra::SymmetricEigen::new(scatter);
    let k = eig.eigenvalues.imin();
    let normal: Vector3<f64> = eig.eigenvectors.column(k).into_owned();
    let normal = if normal.z < 0.0 { -normal } else { normal };
    let rot = UnitQuaternion::rotation_between(&Vector3::z(), &normal)
        .unwrap_or_else(UnitQuaternion::identity);
    let t_world_plane = Isometry3::from_parts(Translation3::from(centroid), rot);
    let t_plane_world = t_world_plane.inverse();
    let flat: Vec<Vector3<f64>> = xyz
        .iter()
        .map(|p| {
            let q = t_plane_world * nalgebra::Point3::from(*p);
            Vector3::new(q.x, q.y, 0.0)
        })
        .collect();
    let start = solve_pnp(camera, &flat, uv)?.t_cam_target;
    let start = Isometry3::from_parts(Translation3::from(start.translation), start.rotation)
        * t_plane_world;
    let sol = refine_pnp(
        camera,
        xyz,
        uv,
        Pose::new(start.rotation, start.translation.vector),
    )?;
    let t_cam_world = Isometry3::from_parts(
        Translation3::from(sol.t_cam_target.translation),
        sol.t_cam_target.rotation,
    );
    Ok((t_cam_world.inverse(), sol.rms_px))
}

/// The initial pose from the user correspondences of `prior.yaml`.
pub fn from_correspondences(input: &PriorMapInput) -> Result<Initialisation, InitError> {
    let c = &input.prior.correspondences;
    let xyz: Vec<Vector3<f64>> = c.iter().map(|c| Vector3::from(c.xyz)).collect();
    let uv: Vec<Vector2<f64>> = c.iter().map(|c| Vector2::from(c.uv)).collect();
    let (t_world_cam, rms_px) = pnp_world(&input.camera, &xyz, &uv).map_err(InitError::Pnp)?;
    Ok(Initialisation {
        t_world_cam,
        source: InitSource::UserCorrespondences,
        keypoints: (0, 0),
        matches: c.len(),
        inliers: c.len(),
        rms_px,
        height_scale: 1.0,
    })
}

/// Median z of the map points within 15 m of `xy` (all points if none): the ground.
pub fn ground_height(input: &PriorMapInput, xy: &Vector2<f64>) -> f64 {
    let near: Vec<f64> = input
        .map
        .points
        .iter()
        .filter(|p| (p.xyz.xy() - xy).norm() < 15.0)
        .map(|p| p.xyz.z)
        .collect();
    let mut z = if near.is_empty() {
        input.map.points.iter().map(|p| p.xyz.z).collect()
    } else {
        near
    };
    z.sort_by(f64::total_cmp);
    z.get(z.len() / 2).copied().unwrap_or(0.0)
}

/// A virtual pinhole view along the camera's optical axis: the image, its valid mask and
/// the fisheye pixel of each of its pixels' rays.
struct Rectified {
    image: GrayImage,
    valid: Vec<bool>,
    focal: f64,
    centre: f64,
}

impl Rectified {
    fn new(camera: &Camera<f64>, image: &GrayImage, focal: f64, max_view_deg: f64) -> Self {
        let half = (focal * max_view_deg.to_radians().tan())
            .clamp(40.0, 600.0)
            .round() as usize;
        let n = 2 * half + 1;
        let centre = half as f64;
        let mut this = Self {
            image: GrayImage::new(n, n, 0.0),
            valid: vec![false; n * n],
            focal,
            centre,
        };
        for i in 0..n * n {
            let px = Vector2::new((i % n) as f64, (i / n) as f64);
            if let Some(q) = this.fisheye_pixel(camera, &px) {
                this.image.data_mut()[i] = image.sample(q.x, q.y);
                this.valid[i] = true;
            }
        }
        this
    }

    fn fisheye_pixel(&self, camera: &Camera<f64>, px: &Vector2<f64>) -> Option<Vector2<f64>> {
        let b = Vector3::new(
            (px.x - self.centre) / self.focal,
            (px.y - self.centre) / self.focal,
            1.0,
        );
        let q = camera.project(&b)?.pixel;
        camera.in_image(&q, 1.0).then_some(q)
    }
}

/// A window of `image`: `(x0, y0)` and the copy.
fn crop(image: &GrayImage, centre: &Vector2<f64>, half: f64) -> Option<(usize, usize, GrayImage)> {
    let (w, h) = (image.width() as f64, image.height() as f64);
    let x0 = (centre.x - half).clamp(0.0, w) as usize;
    let y0 = (centre.y - half).clamp(0.0, h) as usize;
    let x1 = (centre.x + half).clamp(0.0, w) as usize;
    let y1 = (centre.y + half).clamp(0.0, h) as usize;
    if x1 < x0 + 64 || y1 < y0 + 64 {
        return None;
    }
    let data = (y0..y1)
        .flat_map(|y| (x0..x1).map(move |x| (x, y)))
        .map(|(x, y)| image.at(x, y))
        .collect();
    Some((x0, y0, GrayImage::from_vec(x1 - x0, y1 - y0, data)?))
}

/// Homography `b ~ H a` by the normalised DLT (at least 4 pairs).
pub fn homography(pairs: &[(Vector2<f64>, Vector2<f64>)]) -> Option<Matrix3<f64>> {
    let norm = |pts: &mut dyn Iterator<Item = Vector2<f64>>| {
        let v: Vec<Vector2<f64>> = pts.collect();
        let mean = v.iter().sum::<Vector2<f64>>() / v.len() as f64;
        let spread = v.iter().map(|p| (p - mean).norm()).sum::<f64>() / v.len() as f64;
        let s = std::f64::consts::SQRT_2 / spread.max(1e-12);
        Matrix3::new(s, 0.0, -s * mean.x, 0.0, s, -s * mean.y, 0.0, 0.0, 1.0)
    };
    let na = norm(&mut pairs.iter().map(|p| p.0));
    let nb = norm(&mut pairs.iter().map(|p| p.1));
    let rows = (2 * pairs.len()).max(9);
    let mut m = DMatrix::<f64>::zeros(rows, 9);
    for (i, (a, b)) in pairs.iter().enumerate() {
        let a = na * a.push(1.0);
        let b = nb * b.push(1.0);
        let (x, y) = (b.x / b.z, b.y / b.z);
        for j in 0..3 {
            m[(2 * i, j)] = -a[j];
            m[(2 * i, 6 + j)] = x * a[j];
            m[(2 * i + 1, 3 + j)] = -a[j];
            m[(2 * i + 1, 6 + j)] = y * a[j];
        }
    }
    let svd = m.svd(false, true);
    let v_t = svd.v_t?;
    let k = svd.singular_values.imin();
    let h = v_t.row(k);
    let hn = Matrix3::new(h[0], h[1], h[2], h[3], h[4], h[5], h[6], h[7], h[8]);
    let hm = nb.try_inverse()? * hn * na;
    (hm[(2, 2)].abs() > 1e-12).then(|| hm / hm[(2, 2)])
}

fn apply(h: &Matrix3<f64>, a: &Vector2<f64>) -> Vector2<f64> {
    let p = h * a.push(1.0);
    p.xy() / p.z
}

/// RANSAC of the homography; the inlier indices of the best model that preserves
/// orientation and keeps the scale within [0.6, 1.7] at `centre`.
fn ransac(
    pairs: &[(Vector2<f64>, Vector2<f64>)],
    centre: &Vector2<f64>,
    options: &InitOptions,
) -> Vec<usize> {
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let mut best: Vec<usize> = Vec::new();
    if pairs.len() < 4 {
        return best;
    }
    let plausible = |h: &Matrix3<f64>| {
        let d = 1.0;
        let p0 = apply(h, centre);
        let jx = (apply(h, &(centre + Vector2::new(d, 0.0))) - p0) / d;
        let jy = (apply(h, &(centre + Vector2::new(0.0, d))) - p0) / d;
        let det = jx.x * jy.y - jx.y * jy.x;
        det > 0.36 && det < 2.9
    };
    for _ in 0..options.iterations {
        let idx: [usize; 4] = std::array::from_fn(|_| rng.gen_range(0..pairs.len()));
        if (0..4).any(|a| (a + 1..4).any(|b| idx[a] == idx[b])) {
            continue;
        }
        let sample: Vec<_> = idx.iter().map(|&i| pairs[i]).collect();
        let Some(h) = homography(&sample) else {
            continue;
        };
        if !plausible(&h) {
            continue;
        }
        let inliers: Vec<usize> = (0..pairs.len())
            .filter(|&i| (apply(&h, &pairs[i].0) - pairs[i].1).norm() < options.ransac_px)
            .collect();
        if inliers.len() > best.len() {
            best = inliers;
        }
    }
    best
}

/// One automatic attempt at a given height scale: (pose, stats) or the match counts.
fn attempt(
    input: &PriorMapInput,
    satellite: &Satellite,
    prior: &Vector3<f64>,
    sigma_xy: f64,
    scale: f64,
    options: &InitOptions,
) -> Result<Initialisation, (usize, usize)> {
    let ground = ground_height(input, &prior.xy());
    let height = (prior.z - ground).max(1.0) * scale;
    let m = satellite.geo.metres_per_pixel;
    // A light blur against aliasing where the fisheye is finer than the satellite.
    let view = Rectified::new(
        &input.camera,
        &input.image.gaussian_blur(1.0),
        height / m,
        options.max_view_deg,
    );
    let footprint = height * options.max_view_deg.to_radians().tan();
    let centre = satellite.pixel_of(&prior.xy());
    let (x0, y0, sat) =
        crop(&satellite.image, &centre, (3.0 * sigma_xy + footprint) / m).ok_or((0, 0))?;
    let fa = orb(&view.image, &view.valid, &options.orb);
    let fb = orb(&sat, &vec![true; sat.width() * sat.height()], &options.orb);
    let matches = match_features(&fa, &fb, options.max_hamming, 0.9);
    // Each match as (rectified px, satellite crop px, fisheye px, map point).
    let offset = Vector2::new(x0 as f64, y0 as f64);
    let mut pairs = Vec::with_capacity(matches.len());
    let mut corr = Vec::with_capacity(matches.len());
    for &(i, j) in &matches {
        let (a, b) = (fa.keypoints[i].xy, fb.keypoints[j].xy);
        if let Some(q) = view.fisheye_pixel(&input.camera, &a) {
            let w = satellite.world_of(&(b + offset));
            pairs.push((a, b));
            corr.push((q, Vector3::new(w.x, w.y, ground)));
        }
    }
    let inliers = ransac(&pairs, &Vector2::repeat(view.centre), options);
    let solve = |idx: &[usize]| {
        let uv: Vec<Vector2<f64>> = idx.iter().map(|&i| corr[i].0).collect();
        let xyz: Vec<Vector3<f64>> = idx.iter().map(|&i| corr[i].1).collect();
        pnp_world(&input.camera, &xyz, &uv).ok()
    };
    let fail = (matches.len(), inliers.len());
    if inliers.len() < options.min_inliers {
        return Err(fail);
    }
    let mut idx = inliers;
    let mut result = None;
    for _ in 0..3 {
        let Some((t_world_cam, _)) = solve(&idx) else {
            return Err(fail);
        };
        let t_cam_world = t_world_cam.inverse();
        let verified: Vec<usize> = (0..corr.len())
            .filter(|&i| {
                let pc = t_cam_world * nalgebra::Point3::from(corr[i].1);
                pc.z > 0.0
                    && input
                        .camera
                        .project(&pc.coords)
                        .is_some_and(|q| (q.pixel - corr[i].0).norm() < options.pnp_px)
            })
            .collect();
        if verified.len() < options.min_inliers {
            return Err((matches.len(), verified.len()));
        }
        idx = verified;
        result = Some(t_world_cam);
    }
    let t_world_cam = result.ok_or(fail)?;
    let (t_world_cam, rms_px) = solve(&idx).unwrap_or((t_world_cam, f64::NAN));
    Ok(Initialisation {
        t_world_cam,
        source: InitSource::Automatic,
        keypoints: (fa.keypoints.len(), fb.keypoints.len()),
        matches: matches.len(),
        inliers: idx.len(),
        rms_px,
        height_scale: scale,
    })
}

/// The automatic initialisation (the height scales in turn, the first success wins).
pub fn automatic(
    input: &PriorMapInput,
    options: &InitOptions,
) -> Result<Initialisation, InitError> {
    let satellite = input.satellite.as_ref().ok_or(InitError::NoSatellite)?;
    let prior = Vector3::from(input.prior.position.ok_or(InitError::NoPrior)?);
    let sigma = input.prior.sigma_position_m.unwrap_or([5.0, 5.0, 3.0]);
    let sigma_xy = sigma[0].max(sigma[1]);
    let mut best = (0, 0);
    let mut yaw_error = None;
    for &scale in &options.height_scales {
        match attempt(input, satellite, &prior, sigma_xy, scale, options) {
            Ok(init) => match check_yaw_prior(input, &init.t_world_cam) {
                Ok(()) => return Ok(init),
                Err(e) => yaw_error = Some(e),
            },
            Err(counts) => best = best.max((counts.1, counts.0)),
        }
    }
    if let Some(e) = yaw_error {
        return Err(e);
    }
    Err(InitError::MatchingFailed {
        matches: best.1,
        inliers: best.0,
        needed: options.min_inliers,
    })
}

/// User correspondences when `prior.yaml` has at least 4, else the automatic path.
pub fn initialise(
    input: &PriorMapInput,
    options: &InitOptions,
) -> Result<Initialisation, InitError> {
    if input.prior.correspondences.len() >= 4 {
        from_correspondences(input)
    } else {
        automatic(input, options)
    }
}

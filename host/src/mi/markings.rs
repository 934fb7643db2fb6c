//! Lane-marking crossings: an independent geometric check of a LiDAR-camera extrinsic on a
//! road scene, used to judge the reference extrinsic of the real CalibAnything frame
//! (docs/prior_map.md).
//!
//! Where a LiDAR ring crosses a painted road marking, the ground returns are brighter than
//! their ring neighbours for a short run (2-6 points, < 0.5 m). The reflectivity-weighted
//! centre of that run is a 3-D point on the marking, measured to centimetres along the
//! ring. Projected with `T_cam_lidar`, it should fall on the marking in the image. Along
//! the image row of the projection, the marking is a bright stripe (white top-hat), whose
//! centroid is found to a fraction of a pixel; the local direction of the stripe (principal
//! axis of the top-hat blob) gives the normal. The residual is the distance from the
//! projected LiDAR centre to the image stripe along that normal: a marking constrains only
//! the direction across it. A robust (Huber) least-squares fit of a rotation correction to
//! these residuals, with the analytic projection Jacobian, says how far the extrinsic is
//! from putting the LiDAR markings on the image markings, with a sigma from the scatter.

use msreg_estimator::camera::Camera;
use nalgebra::{Isometry3, Matrix2, Matrix3, Point3, SymmetricEigen, Vector2, Vector3};

use super::scene::PoseParam;
use super::targetless::ground_height;
use crate::pointcloud::{Point, PointCloud};
use crate::vision::GrayImage;

/// Settings of the crossing detector.
#[derive(Clone, Debug, PartialEq)]
pub struct MarkingOptions {
    /// Ground points: within this height (m) of the densest LiDAR-z layer.
    pub ground_band_m: f64,
    /// Points farther than this in front of the camera are ignored (m).
    pub max_depth_m: f64,
    /// Ring-local median window (points) of the reflectivity background.
    pub median_window: usize,
    /// A marking return exceeds its ring-local median by this much (sensor units).
    pub min_excess: f32,
    /// Run length limits (points) of one crossing.
    pub run_points: (usize, usize),
    /// Maximum run width (m): a painted line, not a patch.
    pub max_run_width_m: f64,
    /// Image blur before the top-hat (px).
    pub blur_px: f64,
    /// Width of the horizontal top-hat structuring element (px, odd).
    pub tophat_width_px: usize,
    /// Half width of the search for the image stripe along the row (px).
    pub search_px: usize,
    /// Minimum top-hat peak of an image stripe (grey levels).
    pub min_tophat: f32,
    /// Minimum stripe width along the row (px).
    pub min_stripe_px: usize,
    /// Half size of the window for the stripe direction (px).
    pub direction_window_px: usize,
    /// Minimum eigenvalue ratio of that window (an elongated stripe).
    pub min_elongation: f64,
}

impl Default for MarkingOptions {
    fn default() -> Self {
        Self {
            ground_band_m: 0.3,
            max_depth_m: 50.0,
            median_window: 31,
            min_excess: 15.0,
            run_points: (2, 6),
            max_run_width_m: 0.5,
            blur_px: 1.0,
            tophat_width_px: 61,
            search_px: 45,
            min_tophat: 15.0,
            min_stripe_px: 5,
            direction_window_px: 20,
            min_elongation: 4.0,
        }
    }
}

/// One LiDAR ring crossing a marking, matched to the image stripe.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MarkingCrossing {
    /// Ring of the run.
    pub ring: u16,
    /// Reflectivity-weighted centre of the run, LiDAR frame (m).
    pub point: Vector3<f64>,
    /// Its depth in the camera (m).
    pub depth_m: f64,
    /// Its projection (px).
    pub lidar_px: Vector2<f64>,
    /// Centroid of the image stripe on the same row (px).
    pub image_u: f64,
    /// Unit normal of the image stripe, pointing up (`y <= 0`).
    pub normal: Vector2<f64>,
    /// `normal . (image stripe - projection)` (px): > 0 means the marking is above the
    /// projected LiDAR centre (across the stripe).
    pub residual_px: f64,
}

/// A rotation correction fitted to the crossings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MarkingFit {
    /// Crossings used.
    pub crossings: usize,
    /// Median residual before the correction (px).
    pub median_residual_px: f64,
    /// Mean absolute residual before the correction (px).
    pub mean_abs_residual_px: f64,
    /// Robust scatter (1.4826 MAD) of the residuals after the fit (px).
    pub robust_sigma_px: f64,
    /// Right rotation increment `omega` (rad, LiDAR axes) with `R Exp(omega)` taking the
    /// evaluated `T_cam_lidar` onto the markings (translation held).
    pub correction_rad: Vector3<f64>,
    /// One sigma of `correction_rad` from the residual scatter (rad).
    pub sigma_rad: Vector3<f64>,
}

/// Row-wise white top-hat of the blurred image (`row - opening(row)`), computed per row on
/// demand.
struct TopHat {
    image: GrayImage,
    half: usize,
    rows: Vec<Option<Vec<f32>>>,
}

fn sliding(values: &[f32], half: usize, pick: fn(f32, f32) -> f32) -> Vec<f32> {
    (0..values.len())
        .map(|i| {
            let lo = i.saturating_sub(half);
            let hi = (i + half + 1).min(values.len());
            values[lo..hi].iter().copied().fold(values[i], pick)
        })
        .collect()
}

impl TopHat {
    fn new(image: &GrayImage, options: &MarkingOptions) -> Self {
        Self {
            image: image.gaussian_blur(options.blur_px),
            half: options.tophat_width_px / 2,
            rows: vec![None; image.height()],
        }
    }

    fn row(&mut self, y: usize) -> Option<&[f32]> {
        let w = self.image.width();
        let slot = self.rows.get_mut(y)?;
        if slot.is_none() {
            let row = &self.image.data()[y * w..(y + 1) * w];
            let opened = sliding(&sliding(row, self.half, f32::min), self.half, f32::max);
            *slot = Some(row.iter().zip(&opened).map(|(a, b)| a - b).collect());
        }
        slot.as_deref()
    }
}

/// The stripe on row `y` nearest the profile maximum within `search_px` of `u`:
/// `(centroid, width)`.
fn stripe_on_row(
    tophat: &mut TopHat,
    u: f64,
    y: usize,
    o: &MarkingOptions,
) -> Option<(f64, usize)> {
    let row = tophat.row(y)?;
    let x0 = u as usize;
    let lo = x0.saturating_sub(o.search_px);
    let hi = (x0 + o.search_px + 1).min(row.len());
    let prof = row.get(lo..hi)?;
    let (j, &peak) = prof.iter().enumerate().max_by(|a, b| a.1.total_cmp(b.1))?;
    if peak <= o.min_tophat {
        return None;
    }
    let (mut a, mut b) = (j, j);
    while a > 0 && prof[a - 1] > 0.5 * peak {
        a -= 1;
    }
    while b + 1 < prof.len() && prof[b + 1] > 0.5 * peak {
        b += 1;
    }
    let (sw, swx) = (a..=b).fold((0.0, 0.0), |(s, sx), k| {
        let w = f64::from(prof[k]);
        (s + w, sx + w * (lo + k) as f64)
    });
    let width = b - a + 1;
    (width >= o.min_stripe_px && (swx / sw - u).abs() < o.search_px as f64 - 1.0)
        .then_some((swx / sw, width))
}

/// Unit normal (pointing up) of the top-hat blob around `(u, y)`, if it is elongated.
fn stripe_normal(
    tophat: &mut TopHat,
    u: f64,
    y: usize,
    o: &MarkingOptions,
) -> Option<Vector2<f64>> {
    let (x0, r) = (u.round() as usize, o.direction_window_px);
    let w = tophat.image.width();
    if x0 < r.max(3) || x0 + r >= w || y < r {
        return None;
    }
    let centre = tophat.row(y)?;
    let thr = 0.5
        * centre[x0 - 3..=x0 + 3]
            .iter()
            .copied()
            .fold(f32::MIN, f32::max);
    let mut pts = Vec::new();
    for yy in y - r..=y + r {
        let row = tophat.row(yy)?;
        pts.extend(
            (x0 - r..=x0 + r)
                .filter(|&x| row[x] > thr)
                .map(|x| Vector2::new(x as f64, yy as f64)),
        );
    }
    let mean = pts.iter().sum::<Vector2<f64>>() / pts.len().max(1) as f64;
    let cov = pts
        .iter()
        .map(|p| (p - mean) * (p - mean).transpose())
        .sum::<Matrix2<f64>>();
    let eig = SymmetricEigen::new(cov);
    let (big, small) = if eig.eigenvalues[0] >= eig.eigenvalues[1] {
        (0, 1)
    } else {
        (1, 0)
    };
    if eig.eigenvalues[big] < o.min_elongation * eig.eigenvalues[small].max(1e-9) {
        return None;
    }
    let d = eig.eigenvectors.column(big);
    let n = Vector2::new(-d.y, d.x);
    Some(if n.y > 0.0 { -n } else { n })
}

/// Reflectivity-weighted centres of the marking runs of one ring (points sorted by
/// azimuth).
fn ring_runs(ring: &[Point], o: &MarkingOptions) -> Vec<Vector3<f64>> {
    let half = o.median_window / 2;
    let median: Vec<f32> = (0..ring.len())
        .map(|i| {
            let lo = i.saturating_sub(half);
            let hi = (i + half + 1).min(ring.len());
            let mut w: Vec<f32> = ring[lo..hi].iter().map(|p| p.intensity).collect();
            w.sort_by(f32::total_cmp);
            w[w.len() / 2]
        })
        .collect();
    let bright = |k: usize| ring[k].intensity > median[k] + o.min_excess;
    let mut out = Vec::new();
    let mut k = 0;
    while k < ring.len() {
        if !bright(k) {
            k += 1;
            continue;
        }
        let mut e = k;
        while e + 1 < ring.len() && bright(e + 1) {
            e += 1;
        }
        let n = e - k + 1;
        let width = (ring[e].xyz.xy() - ring[k].xyz.xy()).norm();
        if n >= o.run_points.0 && n <= o.run_points.1 && width < o.max_run_width_m {
            let (sw, sp) = (k..=e).fold((0.0, Vector3::zeros()), |(s, sp), j| {
                let w = f64::from(ring[j].intensity - median[j]);
                (s + w, sp + ring[j].xyz * w)
            });
            out.push(sp / sw);
        }
        k = e + 1;
    }
    out
}

/// The crossings at `t_cam_lidar`.
pub fn marking_crossings(
    cloud: &PointCloud,
    image: &GrayImage,
    camera: &Camera<f64>,
    t_cam_lidar: &Isometry3<f64>,
    o: &MarkingOptions,
) -> Vec<MarkingCrossing> {
    let project = |p: &Vector3<f64>| {
        let pc = t_cam_lidar * Point3::from(*p);
        if pc.z < 0.5 || pc.z > o.max_depth_m {
            return None;
        }
        let q = camera.project(&pc.coords)?;
        camera.in_image(&q.pixel, 0.0).then_some((q.pixel, pc.z))
    };
    let visible: Vec<Point> = cloud
        .points
        .iter()
        .filter(|p| project(&p.xyz).is_some())
        .copied()
        .collect();
    let xyz: Vec<Vector3<f64>> = visible.iter().map(|p| p.xyz).collect();
    let Some(ground) = ground_height(&xyz) else {
        return Vec::new();
    };
    let mut rings: std::collections::BTreeMap<u16, Vec<Point>> = Default::default();
    for p in visible
        .iter()
        .filter(|p| (p.xyz.z - ground).abs() < o.ground_band_m)
    {
        rings.entry(p.ring).or_default().push(*p);
    }
    let mut tophat = TopHat::new(image, o);
    let mut out = Vec::new();
    for (ring, mut pts) in rings {
        pts.sort_by(|a, b| a.xyz.y.atan2(a.xyz.x).total_cmp(&b.xyz.y.atan2(b.xyz.x)));
        for point in ring_runs(&pts, o) {
            let Some((px, depth_m)) = project(&point) else {
                continue;
            };
            let y = px.y.round() as usize;
            let Some((image_u, _)) = stripe_on_row(&mut tophat, px.x, y, o) else {
                continue;
            };
            let Some(normal) = stripe_normal(&mut tophat, image_u, y, o) else {
                continue;
            };
            out.push(MarkingCrossing {
                ring,
                point,
                depth_m,
                lidar_px: px,
                image_u,
                normal,
                residual_px: normal.dot(&Vector2::new(image_u - px.x, 0.0)),
            });
        }
    }
    out
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    match v.len() {
        0 => f64::NAN,
        n if n % 2 == 1 => v[n / 2],
        n => 0.5 * (v[n / 2 - 1] + v[n / 2]),
    }
}

/// Robust fit of the rotation correction that moves the LiDAR crossings onto the image
/// stripes (linearised at `t_cam_lidar`; Huber weights at 1.5 robust sigma, 10
/// iterations). `None` with fewer than 6 crossings.
pub fn fit_rotation(
    crossings: &[MarkingCrossing],
    camera: &Camera<f64>,
    t_cam_lidar: &Isometry3<f64>,
) -> Option<MarkingFit> {
    if crossings.len() < 6 {
        return None;
    }
    let rows: Vec<(Vector3<f64>, f64)> = crossings
        .iter()
        .filter_map(|c| {
            let pc = t_cam_lidar * Point3::from(c.point);
            let q = camera.project(&pc.coords)?;
            let j = q.jacobian
                * PoseParam::CamFromSource.point_jacobian(t_cam_lidar, &c.point, &pc.coords);
            let a = (c.normal.transpose() * j.fixed_columns::<3>(0)).transpose();
            Some((a, c.residual_px))
        })
        .collect();
    let mut weights = vec![1.0; rows.len()];
    let (mut x, mut sigma, mut info) = (Vector3::zeros(), f64::NAN, Matrix3::zeros());
    for _ in 0..10 {
        let (ata, atb) = rows.iter().zip(&weights).fold(
            (Matrix3::zeros(), Vector3::zeros()),
            |(m, v), ((a, r), w)| (m + a * a.transpose() * *w, v + a * (*r * *w)),
        );
        let inv = ata.try_inverse()?;
        x = inv * atb;
        info = ata;
        let res: Vec<f64> = rows.iter().map(|(a, r)| r - a.dot(&x)).collect();
        sigma = (1.4826 * median(res.iter().map(|r| r.abs()).collect())).max(1e-6);
        for (w, r) in weights.iter_mut().zip(&res) {
            *w = (1.5 * sigma / r.abs().max(1e-12)).min(1.0);
        }
    }
    let cov = info.try_inverse()? * sigma * sigma;
    let residuals: Vec<f64> = crossings.iter().map(|c| c.residual_px).collect();
    Some(MarkingFit {
        crossings: crossings.len(),
        median_residual_px: median(residuals.clone()),
        mean_abs_residual_px: residuals.iter().map(|r| r.abs()).sum::<f64>()
            / residuals.len() as f64,
        robust_sigma_px: sigma,
        correction_rad: x,
        sigma_rad: cov.diagonal().map(|v| v.max(0.0).sqrt()),
    })
}

/// The outcome of [`align_rotation`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MarkingAlignment {
    /// `T_cam_lidar` after the rotation corrections (translation unchanged).
    pub t_cam_lidar: Isometry3<f64>,
    /// The fit at the start pose (its residuals are those of the start).
    pub first: MarkingFit,
    /// The fit at the final pose.
    pub last: MarkingFit,
    /// Total right rotation increment from the start (rad, LiDAR axes).
    pub total_rad: Vector3<f64>,
}

/// Re-detects the crossings and applies the fitted rotation `iterations` times (Gauss-Newton
/// with re-association); `None` when a fit has fewer than 6 crossings.
pub fn align_rotation(
    cloud: &PointCloud,
    image: &GrayImage,
    camera: &Camera<f64>,
    start: &Isometry3<f64>,
    options: &MarkingOptions,
    iterations: usize,
) -> Option<MarkingAlignment> {
    let fit_at = |t: &Isometry3<f64>| {
        let c = marking_crossings(cloud, image, camera, t, options);
        fit_rotation(&c, camera, t)
    };
    let first = fit_at(start)?;
    let (mut t, mut fit) = (*start, first);
    for _ in 0..iterations {
        let w = fit.correction_rad;
        t = PoseParam::CamFromSource
            .retract(&t, &nalgebra::Vector6::new(w.x, w.y, w.z, 0.0, 0.0, 0.0));
        fit = fit_at(&t)?;
    }
    Some(MarkingAlignment {
        t_cam_lidar: t,
        first,
        last: fit,
        total_rad: (start.rotation.inverse() * t.rotation).scaled_axis(),
    })
}

#[cfg(test)]
#[path = "markings_tests.rs"]
mod tests;

//! The registration problem: points with normalised intensity, a normalised grey image,
//! a camera model and a pose parametrisation; the smoothed MI and its analytic gradient.

use msreg_estimator::camera::Camera;
use nalgebra::{Isometry3, Matrix3, Matrix3x6, Translation3, UnitQuaternion, Vector3, Vector6};
use rayon::prelude::*;

use super::histogram::{score_of, weighted_score, GroupedHistogram, MiScore};
use crate::vision::GrayImage;

/// Samples per rayon task.
const CHUNK: usize = 4096;

/// How the 6-vector `delta = [omega (rad); v (m)]` moves the state pose `X`:
/// `X (+) delta = (R Exp(omega), t + v)` (docs/formats.md: right rotation perturbation,
/// additive translation). The state is either the camera-from-points transform or its
/// inverse.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PoseParam {
    /// `X = T_cam_src` (LiDAR-camera: `T_cam_lidar`).
    CamFromSource,
    /// `X = T_src_cam` (prior map: `T_world_cam`).
    SourceFromCam,
}

impl PoseParam {
    /// `X (+) delta`.
    pub fn retract(self, x: &Isometry3<f64>, delta: &Vector6<f64>) -> Isometry3<f64> {
        let omega = Vector3::new(delta[0], delta[1], delta[2]);
        let v = Vector3::new(delta[3], delta[4], delta[5]);
        Isometry3::from_parts(
            Translation3::from(x.translation.vector + v),
            x.rotation * UnitQuaternion::from_scaled_axis(omega),
        )
    }

    /// `T_cam_src` of state `X`.
    pub fn t_cam_src(self, x: &Isometry3<f64>) -> Isometry3<f64> {
        match self {
            PoseParam::CamFromSource => *x,
            PoseParam::SourceFromCam => x.inverse(),
        }
    }

    /// `d p_cam / d delta` at `delta = 0` for a point `p_src` imaged at `p_cam`.
    pub fn point_jacobian(
        self,
        x: &Isometry3<f64>,
        p_src: &Vector3<f64>,
        p_cam: &Vector3<f64>,
    ) -> Matrix3x6<f64> {
        let r = x.rotation.to_rotation_matrix().into_inner();
        self.point_jacobian_with(&r, p_src, p_cam)
    }

    /// [`Self::point_jacobian`] with the state's rotation matrix `r` given (hoisted out of
    /// per-point loops).
    #[inline]
    pub fn point_jacobian_with(
        self,
        r: &Matrix3<f64>,
        p_src: &Vector3<f64>,
        p_cam: &Vector3<f64>,
    ) -> Matrix3x6<f64> {
        let mut j = Matrix3x6::zeros();
        match self {
            PoseParam::CamFromSource => {
                j.fixed_view_mut::<3, 3>(0, 0)
                    .copy_from(&(-r * p_src.cross_matrix()));
                j.fixed_view_mut::<3, 3>(0, 3)
                    .copy_from(&Matrix3::identity());
            }
            PoseParam::SourceFromCam => {
                j.fixed_view_mut::<3, 3>(0, 0)
                    .copy_from(&p_cam.cross_matrix());
                j.fixed_view_mut::<3, 3>(0, 3).copy_from(&(-r.transpose()));
            }
        }
        j
    }
}

/// A grey image with values in [0, 1], sampled bilinearly with its exact derivative.
#[derive(Clone, Debug)]
pub struct UnitImage {
    width: usize,
    height: usize,
    data: Vec<f32>,
}

/// Histogram equalisation of a 0..255 image (a monotonic map, so MI is unchanged up to
/// binning, and the bins are equally filled): values in [0, 1].
pub fn equalize(image: &GrayImage) -> GrayImage {
    let mut hist = [0usize; 256];
    for &v in image.data() {
        hist[v.round().clamp(0.0, 255.0) as usize] += 1;
    }
    let n = image.data().len().max(1) as f32;
    let mut cdf = [0.0f32; 256];
    let mut acc = 0usize;
    for (i, h) in hist.iter().enumerate() {
        cdf[i] = (acc as f32 + 0.5 * *h as f32) / n;
        acc += h;
    }
    let data = image
        .data()
        .iter()
        .map(|&v| cdf[v.round().clamp(0.0, 255.0) as usize])
        .collect();
    GrayImage::from_vec(image.width(), image.height(), data).unwrap_or_else(|| image.clone())
}

/// `image - gaussian_blur(image, sigma_px) + 128`: removes shading and large-scale
/// brightness (sky, shadows) so the MI is driven by local texture (markings, edges).
pub fn highpass(image: &GrayImage, sigma_px: f64) -> GrayImage {
    let low = image.gaussian_blur(sigma_px);
    let data = image
        .data()
        .iter()
        .zip(low.data())
        .map(|(a, b)| a - b + 128.0)
        .collect();
    GrayImage::from_vec(image.width(), image.height(), data).unwrap_or_else(|| image.clone())
}

/// Rank-normalised intensities in [0, 1] (ties share their mean rank).
pub fn rank_normalize(values: &[f32]) -> Vec<f32> {
    let mut order: Vec<usize> = (0..values.len()).collect();
    order.sort_by(|&a, &b| values[a].total_cmp(&values[b]));
    let mut out = vec![0.0f32; values.len()];
    let denom = (values.len().max(2) - 1) as f32;
    let mut i = 0;
    while i < order.len() {
        let mut j = i;
        while j + 1 < order.len() && values[order[j + 1]].total_cmp(&values[order[i]]).is_eq() {
            j += 1;
        }
        let rank = 0.5 * (i + j) as f32 / denom;
        for &k in &order[i..=j] {
            out[k] = rank;
        }
        i = j + 1;
    }
    out
}

impl UnitImage {
    /// Equalised and blurred with a Gaussian of `sigma_px`.
    pub fn from_gray(image: &GrayImage, sigma_px: f64) -> Self {
        let eq = equalize(image).gaussian_blur(sigma_px);
        Self {
            width: eq.width(),
            height: eq.height(),
            data: eq.data().to_vec(),
        }
    }

    /// Value and `(d/du, d/dv)` at `(u, v)`; `None` off the image. Always inlined: the
    /// scores that need no derivative then skip computing it.
    #[inline(always)]
    pub fn sample(&self, u: f64, v: f64) -> Option<(f32, f64, f64)> {
        if !(u >= 0.0 && v >= 0.0) {
            return None;
        }
        let (x0, y0) = (u as usize, v as usize);
        if x0 + 1 >= self.width || y0 + 1 >= self.height {
            return None;
        }
        let (fx, fy) = (u - x0 as f64, v - y0 as f64);
        let i = y0 * self.width + x0;
        let a = f64::from(self.data[i]);
        let b = f64::from(self.data[i + 1]);
        let c = f64::from(self.data[i + self.width]);
        let d = f64::from(self.data[i + self.width + 1]);
        let top = a + (b - a) * fx;
        let bottom = c + (d - c) * fx;
        let value = top + (bottom - top) * fy;
        let du = (b - a) * (1.0 - fy) + (d - c) * fy;
        let dv = bottom - top;
        Some((value as f32, du, dv))
    }
}

/// Image band (px) of [`image_order_key`].
pub const BAND_PX: f64 = 16.0;

/// Memory-order key of a pixel: its 16 px band of rows, then its column. Points sorted by
/// it are read from the image along its rows (the image stays in cache; about twice as
/// fast as a scan's or a map's order).
pub fn image_order_key(pixel: &nalgebra::Vector2<f64>) -> (i64, f64) {
    ((pixel.y / BAND_PX).floor() as i64, pixel.x)
}

/// Points (with rank-normalised intensity) against one image.
#[derive(Clone, Debug)]
pub struct MiScene {
    /// Points in the source frame (LiDAR or world).
    pub points: Vec<Vector3<f64>>,
    /// Their intensity in [0, 1].
    pub values: Vec<f32>,
    /// The image, normalised and blurred.
    pub image: UnitImage,
    /// The camera model.
    pub camera: Camera<f64>,
    /// Bins per histogram axis.
    pub bins: usize,
    /// Points closer than this to the camera are ignored (m).
    pub min_depth: f64,
    /// Group of each point (empty: one group); each group has its own joint histogram
    /// ([`GroupedHistogram`]).
    pub groups: Vec<u8>,
    /// Number of groups (>= 1).
    pub group_count: usize,
}

/// One evaluation with its gradient w.r.t. `delta`.
#[derive(Clone, Copy, Debug)]
pub struct Evaluated {
    /// Smoothed MI (and NMI) score.
    pub score: MiScore,
    /// `d MI / d delta`.
    pub gradient: Vector6<f64>,
}

impl MiScene {
    /// A scene; raw point intensities are rank-normalised, the image equalised and blurred.
    pub fn new(
        points: Vec<Vector3<f64>>,
        intensities: &[f32],
        image: &GrayImage,
        camera: Camera<f64>,
        blur_px: f64,
    ) -> Self {
        Self {
            points,
            values: rank_normalize(intensities),
            image: UnitImage::from_gray(image, blur_px),
            camera,
            bins: 24,
            min_depth: 0.5,
            groups: Vec::new(),
            group_count: 1,
        }
    }

    /// A scene whose points fall in groups (`groups[i]` for point `i`), each with its own
    /// joint histogram; intensities are rank-normalised within each group.
    pub fn grouped(
        points: Vec<Vector3<f64>>,
        intensities: &[f32],
        groups: Vec<u8>,
        image: &GrayImage,
        camera: Camera<f64>,
        blur_px: f64,
    ) -> Self {
        let group_count = groups
            .iter()
            .map(|&g| usize::from(g) + 1)
            .max()
            .unwrap_or(1);
        let mut values = vec![0.0f32; intensities.len()];
        for g in 0..group_count {
            let idx: Vec<usize> = (0..intensities.len())
                .filter(|&i| usize::from(groups.get(i).copied().unwrap_or(0)) == g)
                .collect();
            let own: Vec<f32> = idx.iter().map(|&i| intensities[i]).collect();
            for (&i, v) in idx.iter().zip(rank_normalize(&own)) {
                values[i] = v;
            }
        }
        Self {
            values,
            groups,
            group_count,
            ..Self::new(points, &[], image, camera, blur_px)
        }
    }

    /// Group of point `i`.
    #[inline]
    fn group(&self, i: usize) -> u8 {
        self.groups.get(i).copied().unwrap_or(0)
    }

    /// The same points on the image blurred by `blur_px` (coarse-to-fine).
    pub fn with_image(&self, image: &GrayImage, blur_px: f64) -> Self {
        Self {
            image: UnitImage::from_gray(image, blur_px),
            ..self.clone()
        }
    }

    /// Every `step`-th point (coarse grid levels).
    pub fn subsampled(&self, step: usize) -> Self {
        let step = step.max(1);
        Self {
            points: self.points.iter().step_by(step).copied().collect(),
            values: self.values.iter().step_by(step).copied().collect(),
            groups: self.groups.iter().step_by(step).copied().collect(),
            ..self.clone()
        }
    }

    /// The same points reordered for memory locality: by [`image_order_key`] of their
    /// pixel under `t_cam_src` (those not projecting last), sorted within each residue
    /// class of the index modulo `stride`, so that [`MiScene::subsampled`]`(stride)` keeps
    /// the same points (in image order). A pose near `t_cam_src` then reads the image along
    /// its rows, which stays in cache; the scores change only by summation order.
    pub fn in_image_order(&self, t_cam_src: &Isometry3<f64>, stride: usize) -> Self {
        let stride = stride.max(1);
        let n = self.points.len();
        let key = |i: usize| {
            self.project(t_cam_src, i)
                .map_or((i64::MAX, 0.0), |(p, _)| image_order_key(&p.pixel))
        };
        let keys: Vec<(i64, f64)> = (0..n).map(key).collect();
        let mut order: Vec<usize> = (0..n).collect();
        for r in 0..stride.min(n) {
            let mut class: Vec<usize> = (r..n).step_by(stride).collect();
            class.sort_by(|&a, &b| {
                keys[a]
                    .0
                    .cmp(&keys[b].0)
                    .then(keys[a].1.total_cmp(&keys[b].1))
            });
            for (slot, i) in (r..n).step_by(stride).zip(class) {
                order[slot] = i;
            }
        }
        Self {
            points: order.iter().map(|&i| self.points[i]).collect(),
            values: order.iter().map(|&i| self.values[i]).collect(),
            groups: if self.groups.is_empty() {
                Vec::new()
            } else {
                order.iter().map(|&i| self.groups[i]).collect()
            },
            ..self.clone()
        }
    }

    /// Pixel of point `i` under `t_cam_src`, with the camera-frame point.
    #[inline]
    fn project(
        &self,
        t: &Isometry3<f64>,
        i: usize,
    ) -> Option<(msreg_estimator::camera::Projected<f64>, Vector3<f64>)> {
        let pc = t.rotation * self.points[i] + t.translation.vector;
        if pc.z < self.min_depth {
            return None;
        }
        self.camera.project(&pc).map(|p| (p, pc))
    }

    /// `(group, point value, image value)` of every visible point.
    pub fn pairs(&self, t_cam_src: &Isometry3<f64>) -> Vec<(u8, f32, f32)> {
        (0..self.points.len())
            .into_par_iter()
            .with_min_len(CHUNK)
            .filter_map(|i| {
                let (p, _) = self.project(t_cam_src, i)?;
                let (b, _, _) = self.image.sample(p.pixel.x, p.pixel.y)?;
                Some((self.group(i), self.values[i], b))
            })
            .collect()
    }

    /// Smoothed (B-spline) histograms, one per group, under `t_cam_src`.
    pub fn histogram(&self, t_cam_src: &Isometry3<f64>) -> GroupedHistogram {
        let empty = || GroupedHistogram::new(self.group_count, self.bins);
        (0..self.points.len())
            .into_par_iter()
            .with_min_len(CHUNK)
            .fold(empty, |mut h, i| {
                if let Some((p, _)) = self.project(t_cam_src, i) {
                    if let Some((b, _, _)) = self.image.sample(p.pixel.x, p.pixel.y) {
                        h.add(self.group(i), self.values[i], b);
                    }
                }
                h
            })
            .reduce(empty, |a, b| a.merge(&b))
    }

    /// Smoothed histograms on one thread (the grid parallelises over candidates).
    pub fn histogram_serial(&self, t_cam_src: &Isometry3<f64>) -> GroupedHistogram {
        let mut h = GroupedHistogram::new(self.group_count, self.bins);
        for i in 0..self.points.len() {
            if let Some((p, _)) = self.project(t_cam_src, i) {
                if let Some((b, _, _)) = self.image.sample(p.pixel.x, p.pixel.y) {
                    h.add(self.group(i), self.values[i], b);
                }
            }
        }
        h
    }

    /// Hard-binned MI on one thread, without building the pair list (the grid's score;
    /// groups weighted by their samples).
    pub fn hard_serial(&self, t_cam_src: &Isometry3<f64>) -> f64 {
        let bins = self.bins;
        let mut joints = vec![vec![0.0f64; bins * bins]; self.group_count];
        let mut counts = vec![0usize; self.group_count];
        let bin = |x: f32| ((x.clamp(0.0, 1.0) * bins as f32) as usize).min(bins - 1);
        for i in 0..self.points.len() {
            if let Some((p, _)) = self.project(t_cam_src, i) {
                if let Some((b, _, _)) = self.image.sample(p.pixel.x, p.pixel.y) {
                    let g = usize::from(self.group(i)).min(self.group_count - 1);
                    joints[g][bin(self.values[i]) * bins + bin(b)] += 1.0;
                    counts[g] += 1;
                }
            }
        }
        grouped_score(&joints, &counts, bins).mi
    }

    /// Smoothed MI / NMI under `t_cam_src`.
    pub fn smoothed(&self, t_cam_src: &Isometry3<f64>) -> MiScore {
        self.histogram(t_cam_src).score()
    }

    /// Hard-binned MI / NMI under `t_cam_src` (groups weighted by their samples).
    pub fn hard(&self, t_cam_src: &Isometry3<f64>) -> MiScore {
        let bins = self.bins;
        let mut joints = vec![vec![0.0f64; bins * bins]; self.group_count];
        let mut counts = vec![0usize; self.group_count];
        let bin = |x: f32| ((x.clamp(0.0, 1.0) * bins as f32) as usize).min(bins - 1);
        for (g, a, b) in self.pairs(t_cam_src) {
            let g = usize::from(g).min(self.group_count - 1);
            joints[g][bin(a) * bins + bin(b)] += 1.0;
            counts[g] += 1;
        }
        grouped_score(&joints, &counts, bins)
    }

    /// Smoothed MI at state `x` and its analytic gradient w.r.t. `delta` (the visible set
    /// held fixed, so the point marginal is constant). Each point is projected once: its
    /// values and `d image / d delta` are kept for the gradient pass.
    pub fn evaluate(&self, param: PoseParam, x: &Isometry3<f64>) -> Evaluated {
        let t = param.t_cam_src(x);
        let r = x.rotation.to_rotation_matrix().into_inner();
        let samples: Vec<(u8, f32, f32, Vector6<f64>)> = (0..self.points.len())
            .into_par_iter()
            .with_min_len(CHUNK)
            .filter_map(|i| {
                let (p, pc) = self.project(&t, i)?;
                let (b, du, dv) = self.image.sample(p.pixel.x, p.pixel.y)?;
                let j = p.jacobian * param.point_jacobian_with(&r, &self.points[i], &pc);
                Some((
                    self.group(i),
                    self.values[i],
                    b,
                    (j.row(0) * du + j.row(1) * dv).transpose(),
                ))
            })
            .collect();
        let empty = || GroupedHistogram::new(self.group_count, self.bins);
        let hist = samples
            .par_iter()
            .with_min_len(CHUNK)
            .fold(empty, |mut h, &(g, a, b, _)| {
                h.add(g, a, b);
                h
            })
            .reduce(empty, |a, b| a.merge(&b));
        let weights: Vec<Vec<f64>> = hist.groups.iter().map(|h| h.gradient_weights()).collect();
        // d/ddelta of sum_k n_k MI_k / N = (1/N) sum_i d_i dMI_k(i)/db (each group's
        // derivative before its own division by n_k).
        let last = hist.groups.len() - 1;
        let sum = samples
            .par_iter()
            .with_min_len(CHUNK)
            .map(|&(g, a, b, di)| {
                let k = usize::from(g).min(last);
                di * hist.groups[k].sample_derivative(&weights[k], a, b)
            })
            .reduce(Vector6::zeros, |a, b| a + b);
        let n = hist.total().max(1.0);
        Evaluated {
            score: hist.score(),
            gradient: sum / n,
        }
    }

    /// Mean image motion (px) per unit of each DoF of `delta`, over the visible points.
    pub fn pixels_per_unit(&self, param: PoseParam, x: &Isometry3<f64>) -> Vector6<f64> {
        let t = param.t_cam_src(x);
        let (sum, n) = (0..self.points.len())
            .into_par_iter()
            .with_min_len(CHUNK)
            .filter_map(|i| {
                let (p, pc) = self.project(&t, i)?;
                self.image.sample(p.pixel.x, p.pixel.y)?;
                let j = p.jacobian * param.point_jacobian(x, &self.points[i], &pc);
                Some(Vector6::from_fn(|k, _| j.column(k).norm()))
            })
            .fold(|| (Vector6::zeros(), 0usize), |(s, n), v| (s + v, n + 1))
            .reduce(|| (Vector6::zeros(), 0), |a, b| (a.0 + b.0, a.1 + b.1));
        sum / n.max(1) as f64
    }

    /// Number of distinct `cell_px` x `cell_px` image cells the visible points fall in.
    pub fn occupied_cells(&self, t_cam_src: &Isometry3<f64>, cell_px: f64) -> usize {
        let cell = cell_px.max(1.0);
        let mut cells: Vec<(i64, i64)> = (0..self.points.len())
            .filter_map(|i| {
                let (p, _) = self.project(t_cam_src, i)?;
                self.image.sample(p.pixel.x, p.pixel.y)?;
                Some(((p.pixel.x / cell) as i64, (p.pixel.y / cell) as i64))
            })
            .collect();
        cells.sort_unstable();
        cells.dedup();
        cells.len()
    }
}

/// The sample-weighted MI / NMI of hard-binned per-group joint histograms.
fn grouped_score(joints: &[Vec<f64>], counts: &[usize], bins: usize) -> MiScore {
    if let ([joint], [n]) = (joints, counts) {
        return score_of(joint, bins, *n);
    }
    weighted_score(
        joints
            .iter()
            .zip(counts)
            .map(|(j, &n)| score_of(j, bins, n)),
    )
}

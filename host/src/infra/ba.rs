//! The global bundle adjustment (eq. 6.1-6.2, 6.11-6.12 and the marker corners) over the
//! keyframe poses `T_vo_Fk` (k >= 1; keyframe 0 fixes the frame), the ceiling points, the
//! camera poses `T_vo_C` and `T_F_M`, in the metric VO frame. The metric scale comes from
//! the marker; a separate scale parameter would duplicate the global scaling of keyframes
//! and points (a gauge freedom), so the VO scale is read off afterwards
//! ([`super::align::similarity_scale`] of the input VO positions onto the solved ones).
//!
//! Residuals (pixels, whitened by nominal sigmas, Cauchy loss on each 2-vector):
//! - VO keypoints: `pi_F(R_k^T (X - t_k))`, analytic Jacobian;
//! - blobs: `pi_F(R_k^T (t_C - t_k))`, analytic;
//! - marker corners: `pi_C(T_vo_C^-1 T_vo_F(t) T_F_M c)` with `T_vo_F(t)` interpolated between
//!   keyframes (eq. 6.3-6.6), Jacobian by central differences;
//! - epipolar: the square root of the Sampson distance of a marker corner seen by two
//!   cameras within 10 ms (eq. 6.13-6.14), whitened by 0.3 px / focal length, Jacobian by
//!   central differences.
//!
//! Solver: Levenberg-Marquardt; the points are eliminated by the Schur complement and the
//! reduced system (6 per keyframe, camera and `T_F_M`) is solved by faer's dense Cholesky.
//! Perturbations: right on rotations, additive on positions; points additive.

use faer::linalg::solvers::Solve;
use msreg_estimator::camera::Camera;
use msreg_estimator::lie::skew;
use nalgebra::{
    DMatrix, DVector, Isometry3, Matrix2x3, Matrix2x6, Matrix3, Matrix6, Matrix6x3, Point3,
    SMatrix, Translation3, UnitQuaternion, Vector2, Vector3,
};

use super::io::MarkerDetection;
use crate::solve::Loss;

/// A VO keypoint.
#[derive(Clone, Copy, Debug)]
pub struct VoObs {
    /// Keyframe.
    pub kf: usize,
    /// Point.
    pub point: usize,
    /// Pixel.
    pub uv: Vector2<f64>,
}

/// A marker detection by camera `cam` between keyframes `i` and `j`.
#[derive(Clone, Copy, Debug)]
pub struct MarkerObs {
    /// Camera index.
    pub cam: usize,
    /// Keyframe before.
    pub i: usize,
    /// Keyframe after.
    pub j: usize,
    /// Interpolation weight (eq. 6.3).
    pub alpha: f64,
    /// Corners.
    pub detection: MarkerDetection,
}

/// A blob of camera `cam` in keyframe `kf`.
#[derive(Clone, Copy, Debug)]
pub struct BlobObs {
    /// Keyframe.
    pub kf: usize,
    /// Camera index.
    pub cam: usize,
    /// Pixel.
    pub uv: Vector2<f64>,
}

/// A marker corner seen at once (within 10 ms) by cameras `a` and `b` (eq. 6.13).
#[derive(Clone, Copy, Debug)]
pub struct EpiObs {
    /// First camera index.
    pub a: usize,
    /// Second camera index.
    pub b: usize,
    /// Normalised image point in `a` (z = 1).
    pub xa: Vector3<f64>,
    /// Normalised image point in `b`.
    pub xb: Vector3<f64>,
    /// Whitening: 1-sigma of the Sampson distance (normalised units).
    pub sigma: f64,
}

/// Square root of the signed Sampson distance of `x_a^T E_ab x_b` (eq. 6.13).
pub fn epipolar(t_vo_a: &Isometry3<f64>, t_vo_b: &Isometry3<f64>, o: &EpiObs) -> f64 {
    let t_ab = t_vo_a.inverse() * t_vo_b;
    let e = skew(&t_ab.translation.vector) * t_ab.rotation.to_rotation_matrix().matrix();
    let (exb, etxa) = (e * o.xb, e.transpose() * o.xa);
    let den = (exb.x * exb.x + exb.y * exb.y + etxa.x * etxa.x + etxa.y * etxa.y).max(1e-300);
    o.xa.dot(&exb) / den.sqrt()
}

/// Measurements and models.
pub struct BaProblem<'a> {
    /// The robot's fisheye.
    pub f: &'a Camera<f64>,
    /// Infrastructure cameras.
    pub cams: Vec<&'a Camera<f64>>,
    /// Marker corners in M.
    pub corners: [Vector3<f64>; 4],
    /// VO keypoints.
    pub vo: Vec<VoObs>,
    /// Marker detections.
    pub markers: Vec<MarkerObs>,
    /// Blobs.
    pub blobs: Vec<BlobObs>,
    /// Simultaneous marker corners of camera pairs (epipolar residual, eq. 6.13-6.14).
    pub epipolar: Vec<EpiObs>,
}

/// The unknowns.
#[derive(Clone, Debug)]
pub struct BaState {
    /// `T_vo_Fk`.
    pub kf: Vec<Isometry3<f64>>,
    /// `T_vo_C`.
    pub cams: Vec<Isometry3<f64>>,
    /// `T_F_M`.
    pub t_f_m: Isometry3<f64>,
    /// Points in vo.
    pub points: Vec<Vector3<f64>>,
}

/// Nominal sigmas (px) and the Cauchy scale (whitened units).
const SIGMA_VO: f64 = 0.5;
const SIGMA_BLOB: f64 = 1.0;
const SIGMA_CORNER: f64 = 0.3;
const CAUCHY: f64 = 3.0;

fn plus(t: &Isometry3<f64>, d: &[f64]) -> Isometry3<f64> {
    let q = t.rotation * UnitQuaternion::from_scaled_axis(Vector3::new(d[0], d[1], d[2]));
    Isometry3::from_parts(
        Translation3::from(t.translation.vector + Vector3::new(d[3], d[4], d[5])),
        q,
    )
}

/// Pixel of a point in a pose's frame and `d pixel / d [theta, t]` of that pose
/// (`p = R^T (X - t)`), plus `d pixel / d X`.
pub fn project_in(
    cam: &Camera<f64>,
    pose: &Isometry3<f64>,
    x: &Vector3<f64>,
) -> Option<(Vector2<f64>, Matrix2x6<f64>, Matrix2x3<f64>)> {
    let rt: Matrix3<f64> = pose.rotation.to_rotation_matrix().matrix().transpose();
    let p = rt * (x - pose.translation.vector);
    let proj = cam.project(&p)?;
    let mut dp = nalgebra::Matrix3x6::zeros();
    dp.fixed_view_mut::<3, 3>(0, 0).copy_from(&skew(&p));
    dp.fixed_view_mut::<3, 3>(0, 3).copy_from(&(-rt));
    Some((proj.pixel, proj.jacobian * dp, proj.jacobian * rt))
}

/// `T_vo_F` at a marker detection (eq. 6.4-6.6).
pub fn interpolate(a: &Isometry3<f64>, b: &Isometry3<f64>, alpha: f64) -> Isometry3<f64> {
    let p = a.translation.vector * (1.0 - alpha) + b.translation.vector * alpha;
    Isometry3::from_parts(Translation3::from(p), a.rotation.slerp(&b.rotation, alpha))
}

/// The 8 predicted corner pixels of a marker observation.
pub fn marker_pixels(
    problem: &BaProblem<'_>,
    kf_i: &Isometry3<f64>,
    kf_j: &Isometry3<f64>,
    t_f_m: &Isometry3<f64>,
    cam: &Isometry3<f64>,
    m: &MarkerObs,
) -> Option<SMatrix<f64, 8, 1>> {
    let t_c_m = cam.inverse() * interpolate(kf_i, kf_j, m.alpha) * t_f_m;
    let mut out = SMatrix::<f64, 8, 1>::zeros();
    for (k, c) in problem.corners.iter().enumerate() {
        let px = problem.cams[m.cam]
            .project(&(t_c_m * Point3::from(*c)).coords)?
            .pixel;
        out[2 * k] = px.x;
        out[2 * k + 1] = px.y;
    }
    Some(out)
}

/// Marker residual (pred - meas, px) and its Jacobian w.r.t. `[kf_i, kf_j, T_F_M, cam]`
/// (8 x 24) by central differences.
pub fn marker_linearised(
    problem: &BaProblem<'_>,
    s: &BaState,
    m: &MarkerObs,
) -> Option<(SMatrix<f64, 8, 1>, SMatrix<f64, 8, 24>)> {
    let base = [s.kf[m.i], s.kf[m.j], s.t_f_m, s.cams[m.cam]];
    let eval = |p: &[Isometry3<f64>; 4]| marker_pixels(problem, &p[0], &p[1], &p[2], &p[3], m);
    let pred = eval(&base)?;
    let mut meas = SMatrix::<f64, 8, 1>::zeros();
    for k in 0..4 {
        meas[2 * k] = m.detection.corners[k].x;
        meas[2 * k + 1] = m.detection.corners[k].y;
    }
    let mut jac = SMatrix::<f64, 8, 24>::zeros();
    let h = 1e-6;
    for col in 0..24 {
        let mut d = [0.0; 6];
        let (blk, k) = (col / 6, col % 6);
        let mut pp = base;
        let mut pm = base;
        d[k] = h;
        pp[blk] = plus(&base[blk], &d);
        d[k] = -h;
        pm[blk] = plus(&base[blk], &d);
        if m.i == m.j && blk < 2 {
            // Exactly at a keyframe: both slots are that keyframe.
            pp[1 - blk] = pp[blk];
            pm[1 - blk] = pm[blk];
        }
        jac.set_column(col, &((eval(&pp)? - eval(&pm)?) / (2.0 * h)));
    }
    Some((pred - meas, jac))
}

/// Normal equations of one linearisation: reduced-side blocks in `u`/`g`, points apart.
struct Normal {
    u: DMatrix<f64>,
    g: DVector<f64>,
    v: Vec<Matrix3<f64>>,
    gp: Vec<Vector3<f64>>,
    /// Per VO observation: `W = J_pose^T w J_point` (6 x 3).
    w: Vec<Matrix6x3<f64>>,
    cost: f64,
    count: usize,
}

struct Layout {
    kfs: usize,
    cams: usize,
}

impl Layout {
    fn kf(&self, k: usize) -> Option<usize> {
        (k >= 1).then(|| 6 * (k - 1))
    }
    fn cam(&self, c: usize) -> usize {
        6 * (self.kfs - 1) + 6 * c
    }
    fn tfm(&self) -> usize {
        6 * (self.kfs - 1) + 6 * self.cams
    }
    fn size(&self) -> usize {
        self.tfm() + 6
    }
}

/// Adds `w J_a^T J_b` and `w J_a^T r` for pose blocks at offsets `a`, `b`.
fn add_block<const R: usize>(
    n: &mut Normal,
    ja: &SMatrix<f64, R, 6>,
    a: usize,
    jb: &SMatrix<f64, R, 6>,
    b: usize,
) {
    let blk = ja.transpose() * jb;
    let mut view = n.u.view_mut((a, b), (6, 6));
    view += blk;
}

fn robust(r2: f64) -> (f64, f64) {
    let l = Loss::Cauchy(CAUCHY);
    (l.rho(r2), l.weight(r2))
}

fn linearise_vo(p: &BaProblem<'_>, s: &BaState, lay: &Layout, n: &mut Normal) -> bool {
    for (o, obs) in p.vo.iter().enumerate() {
        let Some((px, jp, jx)) = project_in(p.f, &s.kf[obs.kf], &s.points[obs.point]) else {
            return false;
        };
        let r = (px - obs.uv) / SIGMA_VO;
        let (rho, w) = robust(r.norm_squared());
        n.cost += rho;
        n.count += 2;
        let (jp, jx) = (jp * (w.sqrt() / SIGMA_VO), jx * (w.sqrt() / SIGMA_VO));
        let r = r * w.sqrt();
        n.v[obs.point] += jx.transpose() * jx;
        n.gp[obs.point] += jx.transpose() * r;
        if let Some(a) = lay.kf(obs.kf) {
            add_block(n, &jp, a, &jp, a);
            let mut g = n.g.rows_mut(a, 6);
            g += jp.transpose() * r;
            n.w[o] = jp.transpose() * jx;
        }
    }
    true
}

fn linearise_blobs(p: &BaProblem<'_>, s: &BaState, lay: &Layout, n: &mut Normal) {
    for b in &p.blobs {
        let Some((px, jp, jx)) = project_in(p.f, &s.kf[b.kf], &s.cams[b.cam].translation.vector)
        else {
            continue;
        };
        let r = (px - b.uv) / SIGMA_BLOB;
        let (rho, w) = robust(r.norm_squared());
        n.cost += rho;
        n.count += 2;
        let k = w.sqrt() / SIGMA_BLOB;
        let jk = jp * k;
        let mut jc = Matrix2x6::zeros();
        jc.fixed_view_mut::<2, 3>(0, 3).copy_from(&(jx * k));
        let r = r * w.sqrt();
        let blocks: Vec<(Matrix2x6<f64>, usize)> = lay
            .kf(b.kf)
            .map(|a| (jk, a))
            .into_iter()
            .chain([(jc, lay.cam(b.cam))])
            .collect();
        accumulate(n, &blocks, &r);
    }
}

fn linearise_epipolar(p: &BaProblem<'_>, s: &BaState, lay: &Layout, n: &mut Normal) {
    let h = 1e-7;
    for o in &p.epipolar {
        let (ta, tb) = (s.cams[o.a], s.cams[o.b]);
        let r = epipolar(&ta, &tb, o) / o.sigma;
        let (rho, w) = robust(r * r);
        n.cost += rho;
        n.count += 1;
        let sw = w.sqrt() / o.sigma;
        let (mut ja, mut jb) = (SMatrix::<f64, 1, 6>::zeros(), SMatrix::<f64, 1, 6>::zeros());
        for k in 0..6 {
            let mut d = [0.0; 6];
            d[k] = h;
            let up = (
                epipolar(&plus(&ta, &d), &tb, o),
                epipolar(&ta, &plus(&tb, &d), o),
            );
            d[k] = -h;
            let dn = (
                epipolar(&plus(&ta, &d), &tb, o),
                epipolar(&ta, &plus(&tb, &d), o),
            );
            ja[k] = (up.0 - dn.0) / (2.0 * h) * sw;
            jb[k] = (up.1 - dn.1) / (2.0 * h) * sw;
        }
        let blocks = [(ja, lay.cam(o.a)), (jb, lay.cam(o.b))];
        accumulate(n, &blocks, &SMatrix::<f64, 1, 1>::new(r * w.sqrt()));
    }
}

fn accumulate<const R: usize>(
    n: &mut Normal,
    blocks: &[(SMatrix<f64, R, 6>, usize)],
    r: &SMatrix<f64, R, 1>,
) {
    for (ja, a) in blocks {
        for (jb, b) in blocks {
            add_block(n, ja, *a, jb, *b);
        }
        let mut g = n.g.rows_mut(*a, 6);
        g += ja.transpose() * r;
    }
}

fn linearise_markers(p: &BaProblem<'_>, s: &BaState, lay: &Layout, n: &mut Normal) -> bool {
    for m in &p.markers {
        let Some((r, j)) = marker_linearised(p, s, m) else {
            return false;
        };
        let r = r / SIGMA_CORNER;
        for k in 0..4 {
            let rk = Vector2::new(r[2 * k], r[2 * k + 1]);
            let (rho, w) = robust(rk.norm_squared());
            n.cost += rho;
            n.count += 2;
            let sw = w.sqrt() / SIGMA_CORNER;
            let jk: SMatrix<f64, 2, 24> = j.fixed_rows::<2>(2 * k) * sw;
            let mut blocks: Vec<(Matrix2x6<f64>, usize)> = Vec::with_capacity(4);
            let slots = [
                lay.kf(m.i),
                if m.i == m.j { None } else { lay.kf(m.j) },
                Some(lay.tfm()),
                Some(lay.cam(m.cam)),
            ];
            for (b, off) in slots.iter().enumerate() {
                if let Some(off) = off {
                    blocks.push((jk.fixed_columns::<6>(6 * b).into_owned(), *off));
                }
            }
            accumulate(n, &blocks, &(rk * w.sqrt()));
        }
    }
    true
}

fn linearise(p: &BaProblem<'_>, s: &BaState, lay: &Layout) -> Option<Normal> {
    let dim = lay.size();
    let mut n = Normal {
        u: DMatrix::zeros(dim, dim),
        g: DVector::zeros(dim),
        v: vec![Matrix3::zeros(); s.points.len()],
        gp: vec![Vector3::zeros(); s.points.len()],
        w: vec![Matrix6x3::zeros(); p.vo.len()],
        cost: 0.0,
        count: 0,
    };
    if !linearise_vo(p, s, lay, &mut n) || !linearise_markers(p, s, lay, &mut n) {
        return None;
    }
    linearise_blobs(p, s, lay, &mut n);
    linearise_epipolar(p, s, lay, &mut n);
    Some(n)
}

/// Solution of the bundle adjustment.
#[derive(Clone, Debug)]
pub struct BaSolution {
    /// The state at the minimum.
    pub state: BaState,
    /// Covariance of each camera's `[theta, p]` (right perturbation of `T_vo_C`).
    pub camera_covariances: Vec<Matrix6<f64>>,
    /// Robust cost at the start and the end (whitened units).
    pub initial_cost: f64,
    /// See `initial_cost`.
    pub final_cost: f64,
    /// Accepted + rejected iterations.
    pub iterations: usize,
    /// Variance factor (robust cost, i.e. whitened chi-square, per degree of freedom)
    /// applied to the covariances.
    pub variance_factor: f64,
}

fn to_faer(m: &DMatrix<f64>) -> faer::Mat<f64> {
    faer::Mat::from_fn(m.nrows(), m.ncols(), |i, j| m[(i, j)])
}

/// Reduced system `S`, right-hand side, and the damped point blocks' inverses.
fn schur(
    n: &Normal,
    p: &BaProblem<'_>,
    lay: &Layout,
    by_point: &[Vec<usize>],
    lambda: f64,
) -> (DMatrix<f64>, DVector<f64>, Vec<Matrix3<f64>>) {
    let mut s = n.u.clone();
    for k in 0..s.nrows() {
        s[(k, k)] += lambda * n.u[(k, k)].max(1e-9);
    }
    let mut rhs = n.g.clone();
    let mut vinv = Vec::with_capacity(n.v.len());
    for (j, obs) in by_point.iter().enumerate() {
        let mut v = n.v[j];
        for k in 0..3 {
            v[(k, k)] += lambda * v[(k, k)].max(1e-9) + 1e-12;
        }
        let vi = v.try_inverse().unwrap_or_else(Matrix3::zeros);
        vinv.push(vi);
        for &a in obs {
            let Some(ka) = lay.kf(p.vo[a].kf) else {
                continue;
            };
            let wa = n.w[a] * vi;
            let mut r = rhs.rows_mut(ka, 6);
            r -= wa * n.gp[j];
            for &b in obs {
                let Some(kb) = lay.kf(p.vo[b].kf) else {
                    continue;
                };
                let mut view = s.view_mut((ka, kb), (6, 6));
                view -= wa * n.w[b].transpose();
            }
        }
    }
    (s, rhs, vinv)
}

fn apply(s: &BaState, lay: &Layout, d: &DVector<f64>, dx: &[Vector3<f64>]) -> BaState {
    let mut out = s.clone();
    for k in 1..s.kf.len() {
        let o = 6 * (k - 1);
        out.kf[k] = plus(&s.kf[k], d.rows(o, 6).as_slice());
    }
    for c in 0..s.cams.len() {
        out.cams[c] = plus(&s.cams[c], d.rows(lay.cam(c), 6).as_slice());
    }
    out.t_f_m = plus(&s.t_f_m, d.rows(lay.tfm(), 6).as_slice());
    for (x, d) in out.points.iter_mut().zip(dx) {
        *x += d;
    }
    out
}

/// One damped step: `None` when the reduced system is not positive definite.
fn step(
    n: &Normal,
    p: &BaProblem<'_>,
    s: &BaState,
    lay: &Layout,
    by_point: &[Vec<usize>],
    lambda: f64,
) -> Option<BaState> {
    let (sm, rhs, vinv) = schur(n, p, lay, by_point, lambda);
    let llt = to_faer(&sm).llt(faer::Side::Lower).ok()?;
    let b = faer::Mat::from_fn(rhs.len(), 1, |i, _| -rhs[i]);
    let x = llt.solve(&b);
    let d = DVector::from_fn(rhs.len(), |i, _| x[(i, 0)]);
    if d.iter().any(|v| !v.is_finite()) {
        return None;
    }
    let dx: Vec<Vector3<f64>> = by_point
        .iter()
        .enumerate()
        .map(|(j, obs)| {
            let mut acc = n.gp[j];
            for &a in obs {
                if let Some(ka) = lay.kf(p.vo[a].kf) {
                    acc += n.w[a].transpose() * d.rows(ka, 6);
                }
            }
            -(vinv[j] * acc)
        })
        .collect();
    Some(apply(s, lay, &d, &dx))
}

/// Runs Levenberg-Marquardt from `start`.
pub fn solve(p: &BaProblem<'_>, start: BaState, max_iterations: usize) -> Option<BaSolution> {
    let lay = Layout {
        kfs: start.kf.len(),
        cams: start.cams.len(),
    };
    let mut by_point = vec![Vec::new(); start.points.len()];
    for (o, obs) in p.vo.iter().enumerate() {
        by_point[obs.point].push(o);
    }
    let mut s = start;
    let mut n = linearise(p, &s, &lay)?;
    let initial_cost = n.cost;
    let mut lambda = 1e-4;
    let mut iterations = 0;
    while iterations < max_iterations {
        iterations += 1;
        let candidate = step(&n, p, &s, &lay, &by_point, lambda)
            .and_then(|c| linearise(p, &c, &lay).map(|m| (c, m)));
        match candidate {
            Some((c, m)) if m.cost < n.cost => {
                let done = n.cost - m.cost < 1e-7 * n.cost;
                (s, n) = (c, m);
                lambda = (lambda * 0.2).max(1e-10);
                if done {
                    break;
                }
            }
            _ => {
                lambda *= 10.0;
                if lambda > 1e6 {
                    break;
                }
            }
        }
    }
    let unknowns = lay.size() + 3 * s.points.len();
    let variance_factor = (n.cost / n.count.saturating_sub(unknowns).max(1) as f64).max(1e-12);
    let camera_covariances = covariances(&n, p, &lay, &by_point, variance_factor)?;
    Some(BaSolution {
        state: s,
        camera_covariances,
        initial_cost,
        final_cost: n.cost,
        iterations,
        variance_factor,
    })
}

/// Camera blocks of the inverse reduced (undamped) system.
fn covariances(
    n: &Normal,
    p: &BaProblem<'_>,
    lay: &Layout,
    by_point: &[Vec<usize>],
    factor: f64,
) -> Option<Vec<Matrix6<f64>>> {
    let (sm, _, _) = schur(n, p, lay, by_point, 0.0);
    let llt = to_faer(&sm).llt(faer::Side::Lower).ok()?;
    let dim = lay.size();
    let cols = 6 * lay.cams;
    let e = faer::Mat::from_fn(
        dim,
        cols,
        |i, j| if i == lay.cam(0) + j { 1.0 } else { 0.0 },
    );
    let x = llt.solve(&e);
    Some(
        (0..lay.cams)
            .map(|c| Matrix6::from_fn(|i, j| x[(lay.cam(c) + i, 6 * c + j)] * factor))
            .collect(),
    )
}

/// The VO-scale estimate: similarity scale from the input VO keyframe positions (VO units)
/// onto the solved metric ones.
pub fn vo_scale(input: &[Vector3<f64>], solved: &BaState) -> f64 {
    let out: Vec<Vector3<f64>> = solved.kf.iter().map(|k| k.translation.vector).collect();
    super::align::similarity_scale(input, &out)
}

/// Marker-corner reprojection RMSE per camera at `state`, px.
pub fn marker_rmse(p: &BaProblem<'_>, state: &BaState) -> Vec<f64> {
    let mut sum = vec![(0.0, 0usize); p.cams.len()];
    for m in &p.markers {
        let pred = marker_pixels(
            p,
            &state.kf[m.i],
            &state.kf[m.j],
            &state.t_f_m,
            &state.cams[m.cam],
            m,
        );
        if let Some(pred) = pred {
            for k in 0..4 {
                let e = Vector2::new(pred[2 * k], pred[2 * k + 1]) - m.detection.corners[k];
                sum[m.cam].0 += e.norm_squared();
                sum[m.cam].1 += 1;
            }
        }
    }
    sum.iter()
        .map(|(s, n)| (s / (*n).max(1) as f64).sqrt())
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fd_check(cam: &Camera<f64>, pose: &Isometry3<f64>, x: &Vector3<f64>) {
        let (px, jp, jx) = project_in(cam, pose, x).expect("projects");
        let h = 1e-6;
        for k in 0..6 {
            let mut d = [0.0; 6];
            d[k] = h;
            let a = project_in(cam, &plus(pose, &d), x).expect("p").0;
            d[k] = -h;
            let b = project_in(cam, &plus(pose, &d), x).expect("m").0;
            let num = (a - b) / (2.0 * h);
            assert!(
                (num - jp.column(k)).norm() < 1e-4 * (1.0 + num.norm()),
                "pose col {k}: {num} vs {}",
                jp.column(k)
            );
        }
        for k in 0..3 {
            let mut d = Vector3::zeros();
            d[k] = h;
            let num = (project_in(cam, pose, &(x + d)).expect("p").0
                - project_in(cam, pose, &(x - d)).expect("m").0)
                / (2.0 * h);
            assert!(
                (num - jx.column(k)).norm() < 1e-4 * (1.0 + num.norm()),
                "point col {k}"
            );
        }
        assert!(px.iter().all(|v| v.is_finite()));
    }

    #[test]
    fn epipolar_residual_vanishes_for_a_true_correspondence() {
        let a = Isometry3::from_parts(
            Translation3::new(0.0, 0.0, 3.0),
            UnitQuaternion::from_euler_angles(2.5, 0.1, 0.3),
        );
        let b = Isometry3::from_parts(
            Translation3::new(3.0, 1.0, 3.0),
            UnitQuaternion::from_euler_angles(2.3, -0.2, 1.3),
        );
        let x = Vector3::new(1.2, 0.8, 0.5);
        let (pa, pb) = (
            a.inverse_transform_point(&x.into()).coords,
            b.inverse_transform_point(&x.into()).coords,
        );
        let o = EpiObs {
            a: 0,
            b: 1,
            xa: pa / pa.z,
            xb: pb / pb.z,
            sigma: 1.0,
        };
        assert!(epipolar(&a, &b, &o).abs() < 1e-12);
        let moved = plus(&b, &[0.0, 0.0, 0.0, 0.0, 0.0, 0.05]);
        assert!(epipolar(&a, &moved, &o).abs() > 1e-5);
    }

    #[test]
    fn keypoint_and_blob_jacobians_match_finite_differences() {
        let f = super::super::scene::robot_fisheye();
        let pose = Isometry3::from_parts(
            Translation3::new(1.0, -2.0, 0.5),
            UnitQuaternion::from_euler_angles(0.05, -0.03, 0.8),
        );
        for x in [
            Vector3::new(2.0, -1.0, 3.4),
            Vector3::new(-3.0, 4.0, 3.4),
            Vector3::new(1.2, -2.1, 3.0),
        ] {
            fd_check(&f, &pose, &x);
        }
    }
}

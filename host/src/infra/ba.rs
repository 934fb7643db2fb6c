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
//! The solver is [`super::ba_solver`]. Perturbations: right on rotations, additive on
//! positions; points additive.

use msreg_estimator::camera::Camera;
use msreg_estimator::lie::skew;
use nalgebra::{
    Isometry3, Matrix2x3, Matrix2x6, Matrix3, Point3, SMatrix, Translation3, UnitQuaternion,
    Vector2, Vector3,
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
pub(super) const SIGMA_VO: f64 = 0.5;
pub(super) const SIGMA_BLOB: f64 = 1.0;
pub(super) const SIGMA_CORNER: f64 = 0.3;
pub(super) const CAUCHY: f64 = 3.0;

pub(super) fn plus(t: &Isometry3<f64>, d: &[f64]) -> Isometry3<f64> {
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
    project_from(cam, (&rt, &pose.translation.vector), x)
}

/// [`project_in`] with the pose given as `(R^T, t)` (computed once per keyframe by the
/// solver, which projects every keypoint of a keyframe through it).
pub(super) fn project_from(
    cam: &Camera<f64>,
    (rt, t): (&Matrix3<f64>, &Vector3<f64>),
    x: &Vector3<f64>,
) -> Option<(Vector2<f64>, Matrix2x6<f64>, Matrix2x3<f64>)> {
    let rt = *rt;
    let p = rt * (x - t);
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

pub(super) fn robust(r2: f64) -> (f64, f64) {
    let l = Loss::Cauchy(CAUCHY);
    (l.rho(r2), l.weight(r2))
}

/// Whitened, weighted residual, Jacobians w.r.t. keyframe and point, and `rho`.
pub(super) type VoTerm = (Vector2<f64>, Matrix2x6<f64>, Matrix2x3<f64>, f64);
/// Whitened, weighted residual, Jacobians w.r.t. keyframe and camera, and `rho`.
pub(super) type BlobTerm = (Vector2<f64>, Matrix2x6<f64>, Matrix2x6<f64>, f64);

/// Whitened, robust-weighted terms of one VO keypoint: `(r, J_kf, J_point, rho)`.
pub(super) fn vo_term(p: &BaProblem<'_>, s: &BaState, o: &VoObs) -> Option<VoTerm> {
    let pose = &s.kf[o.kf];
    let rt: Matrix3<f64> = pose.rotation.to_rotation_matrix().matrix().transpose();
    let (r, jr, jx, rho) = vo_term_from(
        p,
        (&rt, &pose.translation.vector),
        &s.points[o.point],
        &o.uv,
    )?;
    let mut jp = Matrix2x6::zeros();
    jp.fixed_view_mut::<2, 3>(0, 0).copy_from(&jr);
    jp.fixed_view_mut::<2, 3>(0, 3).copy_from(&(-jx));
    Some((r, jp, jx, rho))
}

/// Whitened, weighted residual, Jacobians w.r.t. the keyframe's rotation and the point,
/// and `rho` (the keyframe's translation columns are `-J_point`, not formed).
pub(super) type VoLean = (Vector2<f64>, Matrix2x3<f64>, Matrix2x3<f64>, f64);

/// [`vo_term`] with the keyframe pose as `(R^T, t)`, the point and the keypoint given, in
/// the lean form [`VoLean`] (`p = R^T (X - t)`: `d p / d t = -R^T = -d p / d X`).
pub(super) fn vo_term_from(
    p: &BaProblem<'_>,
    (rt, t): (&Matrix3<f64>, &Vector3<f64>),
    x: &Vector3<f64>,
    uv: &Vector2<f64>,
) -> Option<VoLean> {
    let pc = rt * (x - t);
    let proj = p.f.project(&pc)?;
    let r = (proj.pixel - uv) / SIGMA_VO;
    let (rho, w) = robust(r.norm_squared());
    let k = w.sqrt() / SIGMA_VO;
    Some((
        r * w.sqrt(),
        proj.jacobian * skew(&pc) * k,
        proj.jacobian * rt * k,
        rho,
    ))
}

/// Whitened, robust-weighted terms of one blob: `(r, J_kf, J_cam, rho)`.
pub(super) fn blob_term(p: &BaProblem<'_>, s: &BaState, b: &BlobObs) -> Option<BlobTerm> {
    let (px, jp, jx) = project_in(p.f, &s.kf[b.kf], &s.cams[b.cam].translation.vector)?;
    let r = (px - b.uv) / SIGMA_BLOB;
    let (rho, w) = robust(r.norm_squared());
    let k = w.sqrt() / SIGMA_BLOB;
    let mut jc = Matrix2x6::zeros();
    jc.fixed_view_mut::<2, 3>(0, 3).copy_from(&(jx * k));
    Some((r * w.sqrt(), jp * k, jc, rho))
}

/// Whitened, robust-weighted terms of one marker detection (Cauchy per corner):
/// `(r, J w.r.t. [kf_i, kf_j, T_F_M, cam], rho)`.
pub(super) fn marker_term(
    p: &BaProblem<'_>,
    s: &BaState,
    m: &MarkerObs,
) -> Option<(SMatrix<f64, 8, 1>, SMatrix<f64, 8, 24>, f64)> {
    let (r, mut j) = marker_linearised(p, s, m)?;
    let mut r = r / SIGMA_CORNER;
    let mut cost = 0.0;
    for k in 0..4 {
        let rk = Vector2::new(r[2 * k], r[2 * k + 1]);
        let (rho, w) = robust(rk.norm_squared());
        cost += rho;
        for row in [2 * k, 2 * k + 1] {
            r[row] *= w.sqrt();
            let mut jr = j.row_mut(row);
            jr *= w.sqrt() / SIGMA_CORNER;
        }
    }
    Some((r, j, cost))
}

/// Whitened, robust-weighted epipolar term (eq. 6.13-6.14): `(r, J w.r.t. [cam a, cam b],
/// rho)`, Jacobian by central differences.
pub(super) fn epipolar_term(s: &BaState, o: &EpiObs) -> (f64, SMatrix<f64, 1, 12>, f64) {
    let h = 1e-7;
    let (ta, tb) = (s.cams[o.a], s.cams[o.b]);
    let r = epipolar(&ta, &tb, o) / o.sigma;
    let (rho, w) = robust(r * r);
    let sw = w.sqrt() / o.sigma;
    let mut j = SMatrix::<f64, 1, 12>::zeros();
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
        j[k] = (up.0 - dn.0) / (2.0 * h) * sw;
        j[6 + k] = (up.1 - dn.1) / (2.0 * h) * sw;
    }
    (r * w.sqrt(), j, rho)
}

/// The robust cost (whitened units) of `state`: the sum [`super::ba_solver::solve`]
/// minimises; `None` when a keypoint or marker corner does not project.
pub fn robust_cost(p: &BaProblem<'_>, s: &BaState) -> Option<f64> {
    use rayon::prelude::*;
    let vo: Option<f64> = p.vo.par_iter().map(|o| vo_term(p, s, o).map(|t| t.3)).sum();
    let markers: Option<f64> = p
        .markers
        .par_iter()
        .map(|m| {
            let pred = marker_pixels(p, &s.kf[m.i], &s.kf[m.j], &s.t_f_m, &s.cams[m.cam], m)?;
            Some(
                (0..4)
                    .map(|k| {
                        let e = Vector2::new(pred[2 * k], pred[2 * k + 1]) - m.detection.corners[k];
                        robust((e / SIGMA_CORNER).norm_squared()).0
                    })
                    .sum::<f64>(),
            )
        })
        .sum();
    let blobs: f64 = p
        .blobs
        .par_iter()
        .filter_map(|b| blob_term(p, s, b).map(|t| t.3))
        .sum();
    let epi: f64 = p
        .epipolar
        .iter()
        .map(|o| robust((epipolar(&s.cams[o.a], &s.cams[o.b], o) / o.sigma).powi(2)).0)
        .sum();
    Some(vo? + markers? + blobs + epi)
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

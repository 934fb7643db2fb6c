//! Starting values for the rig bundle adjustment.
//!
//! - `pinhole-radtan`: Zhang's closed form. A homography per image maps the target plane to
//!   the pixels; each gives two linear constraints on `B = K^-T K^-1`, zero skew a third
//!   row; `K` follows from `B` (Zhang 2000, appendix B). Distortion starts at zero.
//! - The wide-angle kinds (and pinhole when Zhang's form fails): a one-dimensional search
//!   over the focal length with the principal point at the image centre and the model's
//!   neutral shape (equidistant with zero coefficients; the unified sphere `xi = 1` for omni,
//!   which is also `ds` with `xi = 0, alpha = 0.5` and `eucm` with `alpha = 0.5, beta = 1`
//!   at half the focal length). Each candidate is scored by the PnP residual of a sample of
//!   images; the best of a logarithmic grid, refined once on a finer grid, wins.
//! - Target poses: PnP per image through the starting camera.

use msreg_estimator::camera::equidistant::Equidistant;
use msreg_estimator::camera::model::{CameraModel, ModelKind};
use msreg_estimator::camera::radtan::RadTan;
use msreg_estimator::camera::{Camera, Distortion, Intrinsics, Projection};
use msreg_estimator::Pose;
use nalgebra::{DMatrix, Matrix3, UnitQuaternion, Vector2, Vector3, Vector6};

use crate::vision::solve_pnp;

/// One image's corners as the initialisation sees them.
pub struct Frame<'a> {
    /// Target-frame points (z = 0).
    pub points: &'a [Vector3<f64>],
    /// Their pixels.
    pub pixels: &'a [Vector2<f64>],
}

/// Homography `H` with `pixel ~ H [x y 1]` (Hartley-normalised DLT).
pub fn homography(points: &[Vector3<f64>], pixels: &[Vector2<f64>]) -> Option<Matrix3<f64>> {
    if points.len() < 4 || points.len() != pixels.len() {
        return None;
    }
    let (ta, tb) = (
        normaliser(points.iter().map(|p| p.xy())),
        normaliser(pixels.iter().copied()),
    );
    let mut a = DMatrix::<f64>::zeros(2 * points.len(), 9);
    for (i, (p, q)) in points.iter().zip(pixels).enumerate() {
        let x = ta * Vector3::new(p.x, p.y, 1.0);
        let u = tb * Vector3::new(q.x, q.y, 1.0);
        for k in 0..3 {
            a[(2 * i, 3 + k)] = -u.z * x[k];
            a[(2 * i, 6 + k)] = u.y * x[k];
            a[(2 * i + 1, k)] = u.z * x[k];
            a[(2 * i + 1, 6 + k)] = -u.x * x[k];
        }
    }
    let h = null_vector(a)?;
    let hn = Matrix3::new(h[0], h[1], h[2], h[3], h[4], h[5], h[6], h[7], h[8]);
    let hm = tb.try_inverse()? * hn * ta;
    (hm[(2, 2)].abs() > 1e-15).then(|| hm / hm[(2, 2)])
}

fn normaliser(points: impl Iterator<Item = Vector2<f64>> + Clone) -> Matrix3<f64> {
    let n = points.clone().count().max(1) as f64;
    let mean = points.clone().sum::<Vector2<f64>>() / n;
    let spread = (points.map(|p| (p - mean).norm()).sum::<f64>() / n).max(1e-12);
    let s = std::f64::consts::SQRT_2 / spread;
    Matrix3::new(s, 0.0, -s * mean.x, 0.0, s, -s * mean.y, 0.0, 0.0, 1.0)
}

/// The right singular vector of the smallest singular value.
fn null_vector(a: DMatrix<f64>) -> Option<nalgebra::DVector<f64>> {
    let ata = a.tr_mul(&a);
    let eig = ata.symmetric_eigen();
    let k = eig.eigenvalues.argmin().0;
    let v = eig.eigenvectors.column(k).into_owned();
    v.iter().all(|x| x.is_finite()).then_some(v)
}

/// Zhang's closed-form `fu, fv, cu, cv` (zero skew) from per-image homographies.
pub fn zhang(homographies: &[Matrix3<f64>]) -> Option<Intrinsics<f64>> {
    if homographies.len() < 2 {
        return None;
    }
    let v = |h: &Matrix3<f64>, i: usize, j: usize| {
        let (a, b) = (h.column(i), h.column(j));
        [
            a[0] * b[0],
            a[0] * b[1] + a[1] * b[0],
            a[1] * b[1],
            a[2] * b[0] + a[0] * b[2],
            a[2] * b[1] + a[1] * b[2],
            a[2] * b[2],
        ]
    };
    let mut a = DMatrix::<f64>::zeros(2 * homographies.len() + 1, 6);
    for (k, h) in homographies.iter().enumerate() {
        // Conditioning: columns of H scaled to unit norm do not change B's solution.
        let h = h / h.column(0).norm().max(1e-300);
        let (v12, v11, v22) = (v(&h, 0, 1), v(&h, 0, 0), v(&h, 1, 1));
        for c in 0..6 {
            a[(2 * k, c)] = v12[c];
            a[(2 * k + 1, c)] = v11[c] - v22[c];
        }
    }
    let last = 2 * homographies.len();
    a[(last, 1)] = 1.0;
    let b = null_vector(a)?;
    let (b11, b12, b22, b13, b23, b33) = (b[0], b[1], b[2], b[3], b[4], b[5]);
    let den = b11 * b22 - b12 * b12;
    let v0 = (b12 * b13 - b11 * b23) / den;
    let lambda = b33 - (b13 * b13 + v0 * (b12 * b13 - b11 * b23)) / b11;
    let fu = (lambda / b11).sqrt();
    let fv = (lambda * b11 / den).sqrt();
    let u0 = -b13 * fu * fu / lambda;
    let k = Intrinsics {
        fu,
        fv,
        cu: u0,
        cv: v0,
    };
    [fu, fv, u0, v0]
        .iter()
        .all(|x| x.is_finite())
        .then_some(k)
        .filter(|k| k.fu > 0.0 && k.fv > 0.0)
}

/// The neutral camera of `kind` with focal `f` at the image centre, as the estimator's
/// [`Camera`] the PnP runs with (omni `xi = 1` stands for `ds` and `eucm`).
fn neutral(kind: ModelKind, f: f64, centre: (f64, f64), resolution: (u32, u32)) -> Camera<f64> {
    let k = Intrinsics {
        fu: f,
        fv: f,
        cu: centre.0,
        cv: centre.1,
    };
    let zero_radtan = Distortion::RadTan(RadTan {
        k1: 0.0,
        k2: 0.0,
        p1: 0.0,
        p2: 0.0,
        k3: 0.0,
    });
    let (projection, distortion) = match kind {
        ModelKind::PinholeRadtan => (Projection::Pinhole, zero_radtan),
        ModelKind::PinholeEquidistant => (
            Projection::Pinhole,
            Distortion::Equidistant(Equidistant {
                k1: 0.0,
                k2: 0.0,
                k3: 0.0,
                k4: 0.0,
            }),
        ),
        _ => (Projection::Omni { xi: 1.0 }, zero_radtan),
    };
    // A positive focal and finite centre: valid by construction.
    Camera::new(projection, k, distortion, resolution).unwrap_or_else(|_| unreachable!())
}

/// Sum over `frames` of the squared PnP RMS (capped) through `camera`.
fn pnp_score(camera: &Camera<f64>, frames: &[Frame]) -> f64 {
    const CAP: f64 = 50.0;
    frames
        .iter()
        .map(|f| {
            solve_pnp(camera, f.points, f.pixels)
                .map_or(CAP, |s| s.rms_px.min(CAP))
                .powi(2)
        })
        .sum()
}

/// The starting camera of `kind`: Zhang for pinhole-radtan, else (or when Zhang fails) the
/// focal search (module docs). `frames` should be a sample of at most ~10 images.
pub fn initial_camera(kind: ModelKind, resolution: (u32, u32), frames: &[Frame]) -> Camera<f64> {
    let centre = (
        0.5 * f64::from(resolution.0) - 0.5,
        0.5 * f64::from(resolution.1) - 0.5,
    );
    if kind == ModelKind::PinholeRadtan {
        // Pixels scaled to about unit size about the centre: a well-conditioned B.
        let s = f64::from(resolution.0.max(resolution.1));
        let hs: Vec<Matrix3<f64>> = frames
            .iter()
            .filter_map(|f| {
                let scaled: Vec<Vector2<f64>> = f
                    .pixels
                    .iter()
                    .map(|p| Vector2::new((p.x - centre.0) / s, (p.y - centre.1) / s))
                    .collect();
                homography(f.points, &scaled)
            })
            .collect();
        if let Some(k) = zhang(&hs).map(|k| Intrinsics {
            fu: k.fu * s,
            fv: k.fv * s,
            cu: k.cu * s + centre.0,
            cv: k.cv * s + centre.1,
        }) {
            let cam = Camera::new(Projection::Pinhole, k, Distortion::None, resolution);
            if let Ok(cam) = cam {
                return cam;
            }
        }
    }
    let width = f64::from(resolution.0.max(resolution.1));
    let score = |f: f64| pnp_score(&neutral(kind, f, centre, resolution), frames);
    let grid = |lo: f64, hi: f64, n: usize| -> f64 {
        (0..n)
            .map(|i| lo * (hi / lo).powf(i as f64 / (n - 1) as f64))
            .map(|f| (f, score(f)))
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .map_or(lo, |(f, _)| f)
    };
    let coarse = grid(0.1 * width, 3.0 * width, 40);
    let ratio = 30f64.powf(1.0 / 39.0);
    let f = grid(coarse / ratio, coarse * ratio, 9);
    neutral(kind, f, centre, resolution)
}

/// The [`CameraModel`] of `kind` equal to the starting `camera` (the omni `xi = 1` start
/// written as `ds` / `eucm`).
pub fn model_of(kind: ModelKind, camera: &Camera<f64>) -> Option<CameraModel<f64>> {
    let i = camera.intrinsics();
    let r = camera.resolution;
    match kind {
        ModelKind::DoubleSphere | ModelKind::Eucm => {
            let xi = match camera.projection() {
                Projection::Omni { xi } => *xi,
                Projection::Pinhole => 0.0,
            };
            let alpha = xi / (1.0 + xi);
            let s = 1.0 - alpha;
            let shape = if kind == ModelKind::DoubleSphere {
                [0.0, alpha]
            } else {
                [alpha, 1.0]
            };
            let p = [shape[0], shape[1], i.fu * s, i.fv * s, i.cu, i.cv];
            CameraModel::new(kind, &p, r).ok()
        }
        ModelKind::OmniRadtan if matches!(camera.projection(), Projection::Pinhole) => {
            // A pinhole start for omni: xi = 0.
            let p = [0.0, i.fu, i.fv, i.cu, i.cv, 0.0, 0.0, 0.0, 0.0];
            CameraModel::new(kind, &p, r).ok()
        }
        _ => CameraModel::from_camera(camera).filter(|m| m.kind == kind),
    }
}

/// Rotation mean (sign-aligned quaternion average) and component-wise median translation.
pub fn mean_pose(poses: &[Pose<f64>]) -> Option<Pose<f64>> {
    let first = poses.first()?.rotation;
    let mut sum = nalgebra::Vector4::zeros();
    for p in poses {
        let q = p.rotation.into_inner().coords;
        sum += if q.dot(&first.into_inner().coords) < 0.0 {
            -q
        } else {
            q
        };
    }
    let rotation = UnitQuaternion::from_quaternion(nalgebra::Quaternion::from(sum));
    let median = |k: usize| {
        let mut v: Vec<f64> = poses.iter().map(|p| p.translation[k]).collect();
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    Some(Pose::new(
        rotation,
        Vector3::new(median(0), median(1), median(2)),
    ))
}

/// `[rotation (rad), translation]` difference `b [-] a` in the right perturbation.
pub fn pose_error(a: &Pose<f64>, b: &Pose<f64>) -> Vector6<f64> {
    let r = (a.rotation.inverse() * b.rotation).scaled_axis();
    let t = b.translation - a.translation;
    Vector6::new(r.x, r.y, r.z, t.x, t.y, t.z)
}

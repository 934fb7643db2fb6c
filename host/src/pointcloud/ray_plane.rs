//! A plane fitted to range returns whose noise lies along their rays.
//!
//! A LiDAR return is its ray's origin `o_k` plus a noisy range `rho_k` along the unit ray
//! `r_k`; the ray's direction is exact. A least-squares or eigenvector plane fit treats each
//! point's noise as isotropic (or along the normal) and, where the rays share an in-plane
//! direction (a board seen from one side, above or below), the noise's in-plane and normal
//! parts are correlated: the fitted plane tilts by about
//! `sigma^2 E[cos(theta) sin(theta)] / var(in-plane coordinate)` (errors in variables;
//! 0.4-1.3 mrad for 2 cm range noise on a 0.9 m board at 1.5 m, docs/joint.md).
//!
//! Here the residual is the range itself: the plane `n . x + d = 0` predicts
//! `rho_hat_k = -(n . o_k + d) / (n . r_k)`, and `rho_k - rho_hat_k` carries the range noise
//! alone, with a Jacobian built from the exact rays. Gauss-Newton on the plane's three
//! degrees of freedom (two tilts about the current normal, the offset) from an eigenvector
//! fit, then the returns beyond `cut` range sigmas are dropped and the fit repeated.

use nalgebra::{Matrix3, SymmetricEigen, Vector3};

/// Gauss-Newton iterations per fit (a 3-parameter problem started within a few mrad).
const ITERATIONS: usize = 5;

/// A plane fitted along the rays.
#[derive(Debug, Clone, PartialEq)]
pub struct RayPlane {
    /// Unit normal `n` (pointing away from the first ray's origin side is not implied).
    pub normal: Vector3<f64>,
    /// Offset `d` of `n . x + d = 0`, m.
    pub offset: f64,
    /// RMS of the range residuals (`K - 3` degrees of freedom), m.
    pub range_sigma: f64,
    /// The kept returns moved along their rays onto the plane, m.
    pub on_plane: Vec<Vector3<f64>>,
    /// `1 / (n . r_k)^2` of each kept return: a range noise `sigma` is a noise
    /// `sigma |n . r_k|` along the normal.
    pub inverse_cos2: Vec<f64>,
}

/// Why no plane was fitted.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum RayPlaneError {
    /// Fewer returns than `min_points` (after the cut).
    #[error("fewer than {0} returns on the plane")]
    TooFew(usize),
    /// The returns do not span a plane or a ray runs along it.
    #[error("the returns do not determine a plane (collinear, or a ray grazes it)")]
    Degenerate,
}

/// Fits a plane to the returns `points[k]` of rays from `origins[k]` (same frame), keeping
/// the returns within `cut` range sigmas of a first fit; at least `min_points` must remain.
pub fn fit_ray_plane(
    origins: &[Vector3<f64>],
    points: &[Vector3<f64>],
    cut: f64,
    min_points: usize,
) -> Result<RayPlane, RayPlaneError> {
    let min_points = min_points.max(4);
    let rays: Vec<(Vector3<f64>, Vector3<f64>, f64)> = origins
        .iter()
        .zip(points)
        .filter_map(|(o, x)| {
            let v = x - o;
            let range = v.norm();
            (range > 0.0).then(|| (*o, v / range, range))
        })
        .collect();
    if rays.len() < min_points {
        return Err(RayPlaneError::TooFew(min_points));
    }
    let (normal, offset) = eigen_plane(&rays)?;
    let first = gauss_newton(&rays, normal, offset)?;
    let sigma = range_rms(&rays, &first);
    let kept: Vec<_> = rays
        .iter()
        .copied()
        .filter(|ray| residual(ray, &first).is_some_and(|r| r.abs() <= cut * sigma))
        .collect();
    if kept.len() < min_points {
        return Err(RayPlaneError::TooFew(min_points));
    }
    let plane = gauss_newton(&kept, first.0, first.1)?;
    finish(&kept, plane)
}

type Ray = (Vector3<f64>, Vector3<f64>, f64);

/// The eigenvector (total least squares) plane of the returns.
fn eigen_plane(rays: &[Ray]) -> Result<(Vector3<f64>, f64), RayPlaneError> {
    let points = rays.iter().map(|(o, r, rho)| o + r * *rho);
    let centroid = points.clone().sum::<Vector3<f64>>() / rays.len() as f64;
    let scatter = points.fold(Matrix3::zeros(), |m, x| {
        let d = x - centroid;
        m + d * d.transpose()
    });
    let eigen = SymmetricEigen::new(scatter);
    let order = sorted(&eigen.eigenvalues);
    if eigen.eigenvalues[order[1]] <= 0.0 {
        return Err(RayPlaneError::Degenerate);
    }
    let normal = eigen.eigenvectors.column(order[0]).into_owned();
    Ok((normal, -normal.dot(&centroid)))
}

/// Indices of the three eigenvalues, smallest first.
fn sorted(values: &Vector3<f64>) -> [usize; 3] {
    let mut order = [0, 1, 2];
    order.sort_by(|&a, &b| values[a].total_cmp(&values[b]));
    order
}

/// `rho - rho_hat` of one ray against the plane, `None` when the ray runs along it.
fn residual((o, r, rho): &Ray, (n, d): &(Vector3<f64>, f64)) -> Option<f64> {
    let cos = n.dot(r);
    (cos.abs() > 1e-6).then(|| rho + (n.dot(o) + d) / cos)
}

fn range_rms(rays: &[Ray], plane: &(Vector3<f64>, f64)) -> f64 {
    let (sum, n) = rays
        .iter()
        .filter_map(|ray| residual(ray, plane))
        .fold((0.0, 0usize), |(s, n), r| (s + r * r, n + 1));
    (sum / n.saturating_sub(3).max(1) as f64).sqrt()
}

/// Gauss-Newton on `(tilt_1, tilt_2, d)` with `n` re-normalised after each step.
fn gauss_newton(
    rays: &[Ray],
    mut n: Vector3<f64>,
    mut d: f64,
) -> Result<(Vector3<f64>, f64), RayPlaneError> {
    for _ in 0..ITERATIONS {
        let (t1, t2) = tangents(&n);
        let mut normal_matrix = Matrix3::zeros();
        let mut gradient = Vector3::zeros();
        for ray in rays {
            let (o, r, _) = ray;
            let cos = n.dot(r);
            let Some(f) = residual(ray, &(n, d)) else {
                return Err(RayPlaneError::Degenerate);
            };
            // On the plane along the ray: x~ = o + rho_hat r; d rho_hat / d n = -x~ / cos.
            let on_plane = o + r * (-(n.dot(o) + d) / cos);
            let j = Vector3::new(t1.dot(&on_plane), t2.dot(&on_plane), 1.0) / cos;
            normal_matrix += j * j.transpose();
            gradient += j * f;
        }
        let step = normal_matrix
            .cholesky()
            .ok_or(RayPlaneError::Degenerate)?
            .solve(&gradient);
        // f = rho + (n.o + d)/cos: df/dp = j, so the step is -(J^T J)^-1 J^T f.
        n = (n - t1 * step.x - t2 * step.y).normalize();
        d -= step.z;
        if step.norm() < 1e-12 {
            break;
        }
    }
    Ok((n, d))
}

/// Two unit vectors completing `n` to an orthonormal basis.
fn tangents(n: &Vector3<f64>) -> (Vector3<f64>, Vector3<f64>) {
    let seed = if n.x.abs() < 0.9 {
        Vector3::x()
    } else {
        Vector3::y()
    };
    let t1 = n.cross(&seed).normalize();
    (t1, n.cross(&t1))
}

fn finish(rays: &[Ray], (normal, offset): (Vector3<f64>, f64)) -> Result<RayPlane, RayPlaneError> {
    let range_sigma = range_rms(rays, &(normal, offset));
    let mut on_plane = Vec::with_capacity(rays.len());
    let mut inverse_cos2 = Vec::with_capacity(rays.len());
    for (o, r, _) in rays {
        let cos = normal.dot(r);
        if cos.abs() <= 1e-6 {
            return Err(RayPlaneError::Degenerate);
        }
        on_plane.push(o + r * (-(normal.dot(o) + offset) / cos));
        inverse_cos2.push(1.0 / (cos * cos));
    }
    Ok(RayPlane {
        normal,
        offset,
        range_sigma,
        on_plane,
        inverse_cos2,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;
    use rand_distr::StandardNormal;

    /// Returns on the plane `z = 2` (seen from below and to one side, so the rays share an
    /// in-plane direction), with range noise `sigma`.
    fn board(sigma: f64, rng: &mut ChaCha8Rng) -> (Vec<Vector3<f64>>, Vec<Vector3<f64>>) {
        let mut origins = Vec::new();
        let mut points = Vec::new();
        for i in 0..30 {
            for j in 0..30 {
                let o = Vector3::new(-1.2, 0.1 * f64::from(i % 3), 0.0);
                let target = Vector3::new(f64::from(i) * 0.03 - 0.45, f64::from(j) * 0.03, 2.0);
                let r = (target - o).normalize();
                let rho = (target - o).norm() + sigma * rng.sample::<f64, _>(StandardNormal);
                origins.push(o);
                points.push(o + r * rho);
            }
        }
        (origins, points)
    }

    #[test]
    fn noise_free_returns_give_the_plane_exactly() -> Result<(), RayPlaneError> {
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let (origins, points) = board(0.0, &mut rng);
        let plane = fit_ray_plane(&origins, &points, 3.0, 10)?;
        let n = plane.normal * plane.normal.z.signum();
        assert!((n - Vector3::z()).norm() < 1e-9, "{n}");
        assert!((plane.offset * plane.normal.z.signum() + 2.0).abs() < 1e-9);
        assert!(plane.on_plane.iter().all(|x| (x.z - 2.0).abs() < 1e-9));
        Ok(())
    }

    /// Over many noisy boards the ray fit's tilt averages to zero, while the eigenvector
    /// fit of the same returns tilts (the errors-in-variables bias this module removes).
    #[test]
    fn the_ray_fit_is_unbiased_where_the_eigenvector_fit_tilts() -> Result<(), RayPlaneError> {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let (mut ray_tilt, mut eigen_tilt, mut sigma) = (0.0, 0.0, 0.0);
        let runs = 200;
        for _ in 0..runs {
            let (origins, points) = board(0.02, &mut rng);
            let plane = fit_ray_plane(&origins, &points, 5.0, 10)?;
            ray_tilt += plane.normal.x / plane.normal.z;
            let rays: Vec<Ray> = origins
                .iter()
                .zip(&points)
                .map(|(o, x)| (*o, (x - o).normalize(), (x - o).norm()))
                .collect();
            let (n, _) = eigen_plane(&rays)?;
            eigen_tilt += n.x / n.z;
            sigma += plane.range_sigma;
        }
        let (ray_tilt, eigen_tilt) = (ray_tilt / runs as f64, eigen_tilt / runs as f64);
        println!(
            "mean tilt: ray fit {:.3} mrad, eigenvector fit {:.3} mrad; range sigma {:.4} m",
            ray_tilt * 1e3,
            eigen_tilt * 1e3,
            sigma / runs as f64
        );
        // One fit's tilt sigma is about 0.02 / (sqrt(900) * 0.26 m) = 2.6 mrad: over 200
        // runs the mean's standard error is 0.18 mrad.
        assert!(ray_tilt.abs() < 0.55e-3, "ray fit tilt {ray_tilt}");
        assert!(
            eigen_tilt.abs() > 1.5e-3,
            "eigenvector fit tilt {eigen_tilt}"
        );
        assert!((sigma / runs as f64 - 0.02).abs() < 0.001);
        Ok(())
    }

    #[test]
    fn too_few_or_collinear_returns_are_errors() {
        let o = vec![Vector3::zeros(); 5];
        let line: Vec<_> = (0..5)
            .map(|k| Vector3::new(f64::from(k), 0.0, 1.0))
            .collect();
        assert_eq!(
            fit_ray_plane(&o[..3], &line[..3], 3.0, 3),
            Err(RayPlaneError::TooFew(4))
        );
        assert_eq!(
            fit_ray_plane(&o, &line, 3.0, 4),
            Err(RayPlaneError::Degenerate)
        );
    }
}

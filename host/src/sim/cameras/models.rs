//! The simulator's own forward projection of Kalibr's five camera models, written from the
//! published definitions and independent of the estimator's camera code (a simulator that
//! shares the estimator's model cannot find its mistakes):
//!
//! - `pinhole-radtan`: pinhole on the normalised plane `(x/z, y/z)`, then Brown-Conrady
//!   radial-tangential distortion `k1, k2, p1, p2` (Kalibr's `RadialTangentialDistortion`,
//!   OpenCV's first four coefficients).
//! - `pinhole-equidistant`: Kannala-Brandt (2006) with four coefficients, the angle from the
//!   optical axis `theta` mapped to `theta_d = theta (1 + k1 theta^2 + k2 theta^4 + k3 theta^6
//!   + k4 theta^8)`, the point at `theta_d` along its azimuth (Kalibr's `equidistant`,
//!   OpenCV's fisheye model); `theta = atan2(r, z)`, so rays beyond 90 deg project too.
//! - `omni-radtan`: Mei and Rives (2007), the unified model: the point on the unit sphere
//!   `(x_s, y_s, z_s)` projected from `(0, 0, -xi)` to `(x_s, y_s) / (z_s + xi)`, then
//!   radial-tangential distortion; valid where `z_s > -w`, `w = xi` for `xi <= 1`, else `1/xi`.
//! - `ds`: the Double Sphere model of Usenko, Demmel and Cremers (2018), eq. (40)-(45):
//!   `d1 = |p|`, `d2 = |(x, y, xi d1 + z)|`, `m = (x, y) / (alpha d2 + (1 - alpha)(xi d1 + z))`,
//!   valid where `z > -w2 d1`.
//! - `eucm`: the Enhanced Unified Camera Model of Khomutenko, Garcia and Martinet (2016):
//!   `d = sqrt(beta (x^2 + y^2) + z^2)`, `m = (x, y) / (alpha d + (1 - alpha) z)`, valid where
//!   `z > -w d` (Usenko et al. 2018, eq. (19)).
//!
//! Every model ends with `(u, v) = (fu m_x + cu, fv m_y + cv)` (pixel convention of
//! docs/formats.md). A point is refused where its model is not one-to-one: outside the valid
//! set above, or where the radial map stops increasing (a distortion polynomial folding
//! back), so no point far outside the field of view is folded into the image. Unprojection
//! is numerical: bisection on the angle from the axis along the pixel's azimuth, then Newton
//! on this projection, accepted only when it reproduces the pixel to 1e-6 px.

use nalgebra::{Matrix2, Vector2, Vector3};

/// Kalibr's camera models, as `msreg simulate cameras --model` names them.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ModelKind {
    /// `pinhole` + `radtan`.
    PinholeRadtan,
    /// `pinhole` + `equidistant` (Kannala-Brandt).
    PinholeEquidistant,
    /// `omni` + `radtan` (Mei).
    OmniRadtan,
    /// `ds` (Double Sphere).
    DoubleSphere,
    /// `eucm` (Enhanced Unified).
    Eucm,
}

/// The lens part of a camera: the model and its non-linear parameters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Lens {
    /// Pinhole with radial-tangential distortion `[k1, k2, p1, p2]`.
    PinholeRadtan {
        /// `[k1, k2, p1, p2]`.
        k: [f64; 4],
    },
    /// Pinhole with Kannala-Brandt distortion `[k1, k2, k3, k4]`.
    PinholeEquidistant {
        /// `[k1, k2, k3, k4]`.
        k: [f64; 4],
    },
    /// Mei's unified model with radial-tangential distortion.
    OmniRadtan {
        /// Mirror parameter.
        xi: f64,
        /// `[k1, k2, p1, p2]`.
        k: [f64; 4],
    },
    /// Double Sphere.
    DoubleSphere {
        /// Distance between the two sphere centres.
        xi: f64,
        /// Image-plane shift, in [0, 1].
        alpha: f64,
    },
    /// Enhanced Unified Camera Model.
    Eucm {
        /// In [0, 1].
        alpha: f64,
        /// > 0.
        beta: f64,
    },
}

/// A simulated camera: lens, focal lengths and principal point (pixels), resolution.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SimCamera {
    /// Model and non-linear parameters.
    pub lens: Lens,
    /// Focal length along u, px.
    pub fu: f64,
    /// Focal length along v, px.
    pub fv: f64,
    /// Principal point u, px.
    pub cu: f64,
    /// Principal point v, px.
    pub cv: f64,
    /// `[width, height]`, px.
    pub resolution: [u32; 2],
}

/// The radial-tangential map of a normalised point, `None` where the radial part no longer
/// increases with the radius (`d/dr [r (1 + k1 r^2 + k2 r^4)] <= 0`).
fn radtan(m: Vector2<f64>, k: &[f64; 4]) -> Option<Vector2<f64>> {
    let [k1, k2, p1, p2] = *k;
    let (x, y) = (m.x, m.y);
    let r2 = x * x + y * y;
    if 1.0 + 3.0 * k1 * r2 + 5.0 * k2 * r2 * r2 <= 0.0 {
        return None;
    }
    let radial = 1.0 + k1 * r2 + k2 * r2 * r2;
    Some(Vector2::new(
        x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x),
        y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y,
    ))
}

/// `w` of the unified model's valid set `z_s > -w` (Usenko et al. 2018).
fn unified_w(xi: f64) -> f64 {
    if xi <= 1.0 {
        xi
    } else {
        1.0 / xi
    }
}

/// `w1` of the Double Sphere and EUCM valid sets.
fn alpha_w(alpha: f64) -> f64 {
    if alpha <= 0.5 {
        alpha / (1.0 - alpha)
    } else {
        (1.0 - alpha) / alpha
    }
}

impl Lens {
    /// The normalised image point `m` of `p` (before the focal lengths), if `p` is in the
    /// model's valid set.
    fn normalised(&self, p: &Vector3<f64>) -> Option<Vector2<f64>> {
        let (x, y, z) = (p.x, p.y, p.z);
        let m = match *self {
            Lens::PinholeRadtan { k } => {
                if z <= 0.0 {
                    return None;
                }
                radtan(Vector2::new(x / z, y / z), &k)?
            }
            Lens::PinholeEquidistant { k } => {
                let r = x.hypot(y);
                let t = r.atan2(z);
                let t2 = t * t;
                // Increasing: d/dt [t (1 + k1 t^2 + ...)] > 0.
                let slope = 1.0
                    + t2 * (3.0 * k[0] + t2 * (5.0 * k[1] + t2 * (7.0 * k[2] + t2 * 9.0 * k[3])));
                if slope <= 0.0 || p.norm() == 0.0 {
                    return None;
                }
                let td = t * (1.0 + t2 * (k[0] + t2 * (k[1] + t2 * (k[2] + t2 * k[3]))));
                if r < 1e-300 {
                    Vector2::zeros()
                } else {
                    Vector2::new(x, y) * (td / r)
                }
            }
            Lens::OmniRadtan { xi, k } => {
                let n = p.norm();
                if !(n > 0.0 && z > -unified_w(xi) * n) {
                    return None;
                }
                radtan(Vector2::new(x, y) / (z + xi * n), &k)?
            }
            Lens::DoubleSphere { xi, alpha } => {
                let d1 = p.norm();
                let w1 = alpha_w(alpha);
                let w2 = (w1 + xi) / (2.0 * w1 * xi + xi * xi + 1.0).sqrt();
                if !(d1 > 0.0 && z > -w2 * d1) {
                    return None;
                }
                let zz = xi * d1 + z;
                let d2 = (x * x + y * y + zz * zz).sqrt();
                let denom = alpha * d2 + (1.0 - alpha) * zz;
                if denom <= 0.0 {
                    return None;
                }
                Vector2::new(x, y) / denom
            }
            Lens::Eucm { alpha, beta } => {
                let d = (beta * (x * x + y * y) + z * z).sqrt();
                let denom = alpha * d + (1.0 - alpha) * z;
                if !(d > 0.0 && z > -alpha_w(alpha) * d && denom > 0.0) {
                    return None;
                }
                Vector2::new(x, y) / denom
            }
        };
        m.iter().all(|v| v.is_finite()).then_some(m)
    }
}

/// The unit ray at angle `a.norm()` from the optical axis, azimuth along `a`.
fn ray_of_angle(a: &Vector2<f64>) -> Vector3<f64> {
    let t = a.norm();
    if t < 1e-12 {
        return Vector3::new(a.x, a.y, 1.0).normalize();
    }
    let s = t.sin() / t;
    Vector3::new(a.x * s, a.y * s, t.cos())
}

impl SimCamera {
    /// The model of this camera.
    pub fn kind(&self) -> ModelKind {
        match self.lens {
            Lens::PinholeRadtan { .. } => ModelKind::PinholeRadtan,
            Lens::PinholeEquidistant { .. } => ModelKind::PinholeEquidistant,
            Lens::OmniRadtan { .. } => ModelKind::OmniRadtan,
            Lens::DoubleSphere { .. } => ModelKind::DoubleSphere,
            Lens::Eucm { .. } => ModelKind::Eucm,
        }
    }

    /// The pixel of camera-frame point `p`, `None` outside the model's valid set (the
    /// pixel may lie off the image: see [`Self::in_image`]).
    pub fn project(&self, p: &Vector3<f64>) -> Option<Vector2<f64>> {
        let m = self.lens.normalised(p)?;
        Some(Vector2::new(
            self.fu * m.x + self.cu,
            self.fv * m.y + self.cv,
        ))
    }

    /// True when `pixel` lies on the image (pixel centres `0..w-1`, `0..h-1`, each pixel
    /// half a pixel wide on either side).
    pub fn in_image(&self, pixel: &Vector2<f64>) -> bool {
        let [w, h] = self.resolution;
        (-0.5..f64::from(w) - 0.5).contains(&pixel.x)
            && (-0.5..f64::from(h) - 0.5).contains(&pixel.y)
    }

    /// The largest angle from the optical axis (rad, up to 179 deg) up to which the model
    /// projects every ray along the azimuths checked and its radial map keeps increasing.
    pub fn max_angle(&self) -> f64 {
        let step = 0.1_f64.to_radians();
        let mut limit = 179.0_f64.to_radians();
        for k in 0..16 {
            let phi = f64::from(k) * std::f64::consts::PI / 8.0;
            let dir = Vector2::new(phi.cos(), phi.sin());
            let mut last = 0.0;
            let mut t = step;
            while t < limit {
                match self.lens.normalised(&ray_of_angle(&(dir * t))) {
                    Some(m) if m.norm() > last => last = m.norm(),
                    _ => {
                        limit = t - step;
                        break;
                    }
                }
                t += step;
            }
        }
        limit
    }

    /// The unit ray of `pixel`, `None` when no ray within `max_angle` (see
    /// [`Self::max_angle`]) projects onto it to 1e-6 px.
    pub fn unproject_within(&self, pixel: &Vector2<f64>, max_angle: f64) -> Option<Vector3<f64>> {
        let m = Vector2::new((pixel.x - self.cu) / self.fu, (pixel.y - self.cv) / self.fv);
        let radius = |a: &Vector2<f64>| self.lens.normalised(&ray_of_angle(a)).map(|q| q.norm());
        let dir = if m.norm() > 0.0 {
            m / m.norm()
        } else {
            Vector2::x()
        };
        // Bisection on the angle along the pixel's azimuth (the radial map increases).
        let (mut lo, mut hi) = (0.0, max_angle);
        if radius(&(dir * hi))? < m.norm() {
            return None;
        }
        for _ in 0..24 {
            let mid = 0.5 * (lo + hi);
            if radius(&(dir * mid))? < m.norm() {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        let a = self.newton(pixel, dir * (0.5 * (lo + hi)))?;
        let ray = ray_of_angle(&a);
        let err = (self.project(&ray)? - pixel).norm();
        (err < 1e-6 && a.norm() <= max_angle + 1e-9).then_some(ray)
    }

    /// The unit ray of `pixel` (see [`Self::unproject_within`]).
    pub fn unproject(&self, pixel: &Vector2<f64>) -> Option<Vector3<f64>> {
        self.unproject_within(pixel, self.max_angle())
    }

    /// Newton on the angle vector `a` (ray [`ray_of_angle`]) so that the ray projects onto
    /// `pixel`; the Jacobian by central differences.
    fn newton(&self, pixel: &Vector2<f64>, mut a: Vector2<f64>) -> Option<Vector2<f64>> {
        let f = |a: &Vector2<f64>| self.project(&ray_of_angle(a)).map(|p| p - pixel);
        for _ in 0..12 {
            let r = f(&a)?;
            if r.norm() < 1e-10 {
                break;
            }
            let h = 1e-7;
            let mut j = Matrix2::zeros();
            for c in 0..2 {
                let mut d = Vector2::zeros();
                d[c] = h;
                j.set_column(c, &((f(&(a + d))? - f(&(a - d))?) / (2.0 * h)));
            }
            a -= j.try_inverse()? * r;
        }
        Some(a)
    }

    /// Kalibr's `camera_model` key.
    pub fn kalibr_model(&self) -> &'static str {
        match self.lens {
            Lens::PinholeRadtan { .. } | Lens::PinholeEquidistant { .. } => "pinhole",
            Lens::OmniRadtan { .. } => "omni",
            Lens::DoubleSphere { .. } => "ds",
            Lens::Eucm { .. } => "eucm",
        }
    }

    /// Kalibr's `distortion_model` key.
    pub fn kalibr_distortion(&self) -> &'static str {
        match self.lens {
            Lens::PinholeRadtan { .. } | Lens::OmniRadtan { .. } => "radtan",
            Lens::PinholeEquidistant { .. } => "equidistant",
            Lens::DoubleSphere { .. } | Lens::Eucm { .. } => "none",
        }
    }

    /// Kalibr's `intrinsics` list: `[fu, fv, cu, cv]` behind `xi` (omni), `xi, alpha` (ds)
    /// or `alpha, beta` (eucm).
    pub fn kalibr_intrinsics(&self) -> Vec<f64> {
        let k = [self.fu, self.fv, self.cu, self.cv];
        let front: Vec<f64> = match self.lens {
            Lens::PinholeRadtan { .. } | Lens::PinholeEquidistant { .. } => vec![],
            Lens::OmniRadtan { xi, .. } => vec![xi],
            Lens::DoubleSphere { xi, alpha } => vec![xi, alpha],
            Lens::Eucm { alpha, beta } => vec![alpha, beta],
        };
        front.into_iter().chain(k).collect()
    }

    /// Kalibr's `distortion_coeffs` list.
    pub fn kalibr_distortion_coeffs(&self) -> Vec<f64> {
        match self.lens {
            Lens::PinholeRadtan { k }
            | Lens::PinholeEquidistant { k }
            | Lens::OmniRadtan { k, .. } => k.to_vec(),
            Lens::DoubleSphere { .. } | Lens::Eucm { .. } => vec![],
        }
    }
}

#[cfg(test)]
#[path = "models_tests.rs"]
mod tests;

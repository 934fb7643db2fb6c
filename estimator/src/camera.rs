//! Camera models in Kalibr's terms: `pinhole` with `radtan`, `equidistant` (Kannala-Brandt)
//! or no distortion, and `omni` (Mei's unified model) with `radtan` or none. Projection
//! returns the pixel and its Jacobian w.r.t. the point (for reprojection updates, eq. 4.15,
//! A.31-A.36); unprojection returns the unit bearing. [`model`] carries every Kalibr model
//! (also double sphere, [`ds`], and the extended unified model, [`eucm`]) with flat
//! parameters and the Jacobian w.r.t. them, for intrinsic calibration. Pixels: centre of the top-left pixel
//! is (0, 0).

pub mod ds;
pub mod equidistant;
pub mod eucm;
pub mod model;
pub mod omni;
pub mod radtan;

use crate::scalar::Scalar;
use nalgebra::{Matrix2, Matrix2x3, Vector2, Vector3};

/// Focal lengths and principal point, pixels.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Intrinsics<T: Scalar> {
    /// Focal length along u.
    pub fu: T,
    /// Focal length along v.
    pub fv: T,
    /// Principal point u.
    pub cu: T,
    /// Principal point v.
    pub cv: T,
}

/// Lens distortion.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Distortion<T: Scalar> {
    /// No distortion.
    None,
    /// Radial-tangential (Kalibr `radtan`, OpenCV's 4 or 5 coefficients; `k3` zero for 4).
    RadTan(radtan::RadTan<T>),
    /// Equidistant fisheye (Kalibr `equidistant`, Kannala-Brandt with 4 coefficients);
    /// pinhole projection only.
    Equidistant(equidistant::Equidistant<T>),
}

/// Projection onto the normalised plane.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Projection<T: Scalar> {
    /// `(X/Z, Y/Z)`.
    Pinhole,
    /// Mei's unified model (Kalibr `omni`): through the unit sphere, then from `xi` above
    /// its centre.
    Omni {
        /// Mirror parameter.
        xi: T,
    },
}

/// Why a camera could not be built.
#[non_exhaustive]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CameraError {
    /// A parameter is not finite or a focal length is not positive.
    InvalidParameter,
    /// The combination is not a Kalibr model (e.g. omni with equidistant distortion).
    UnsupportedCombination,
}

/// A projected point: pixel and `d pixel / d point`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Projected<T: Scalar> {
    /// Pixel `(u, v)`.
    pub pixel: Vector2<T>,
    /// Jacobian w.r.t. the point in the camera frame.
    pub jacobian: Matrix2x3<T>,
}

/// A calibrated camera.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera<T: Scalar> {
    projection: Projection<T>,
    intrinsics: Intrinsics<T>,
    distortion: Distortion<T>,
    /// Image width and height, pixels.
    pub resolution: (u32, u32),
}

impl<T: Scalar> Camera<T> {
    /// The same camera in scalar type `U` (e.g. the f64 calibration as the f32 model the
    /// firmware runs).
    pub fn cast<U: Scalar>(&self) -> Camera<U> {
        let c = |x: T| U::lit(x.to_f64());
        let i = &self.intrinsics;
        Camera {
            projection: match self.projection {
                Projection::Pinhole => Projection::Pinhole,
                Projection::Omni { xi } => Projection::Omni { xi: c(xi) },
            },
            intrinsics: Intrinsics {
                fu: c(i.fu),
                fv: c(i.fv),
                cu: c(i.cu),
                cv: c(i.cv),
            },
            distortion: match self.distortion {
                Distortion::None => Distortion::None,
                Distortion::RadTan(d) => Distortion::RadTan(radtan::RadTan {
                    k1: c(d.k1),
                    k2: c(d.k2),
                    p1: c(d.p1),
                    p2: c(d.p2),
                    k3: c(d.k3),
                }),
                Distortion::Equidistant(d) => Distortion::Equidistant(equidistant::Equidistant {
                    k1: c(d.k1),
                    k2: c(d.k2),
                    k3: c(d.k3),
                    k4: c(d.k4),
                }),
            },
            resolution: self.resolution,
        }
    }

    /// A camera from its parts, validated.
    pub fn new(
        projection: Projection<T>,
        intrinsics: Intrinsics<T>,
        distortion: Distortion<T>,
        resolution: (u32, u32),
    ) -> Result<Self, CameraError> {
        let i = &intrinsics;
        let finite = [i.fu, i.fv, i.cu, i.cv].iter().all(|x| x.is_finite())
            && match distortion {
                Distortion::None => true,
                Distortion::RadTan(d) => d.is_finite(),
                Distortion::Equidistant(d) => d.is_finite(),
            }
            && match projection {
                Projection::Pinhole => true,
                Projection::Omni { xi } => xi.is_finite() && xi >= T::zero(),
            };
        if !finite || i.fu <= T::zero() || i.fv <= T::zero() {
            return Err(CameraError::InvalidParameter);
        }
        if matches!(
            (projection, distortion),
            (Projection::Omni { .. }, Distortion::Equidistant(_))
        ) {
            return Err(CameraError::UnsupportedCombination);
        }
        Ok(Self {
            projection,
            intrinsics,
            distortion,
            resolution,
        })
    }

    /// The intrinsics.
    pub fn intrinsics(&self) -> &Intrinsics<T> {
        &self.intrinsics
    }

    /// The distortion.
    pub fn distortion(&self) -> &Distortion<T> {
        &self.distortion
    }

    /// The projection.
    pub fn projection(&self) -> &Projection<T> {
        &self.projection
    }

    /// Projects a point in the camera frame; `None` when it cannot be imaged (behind the
    /// camera, outside the model's valid region).
    pub fn project(&self, p: &Vector3<T>) -> Option<Projected<T>> {
        let (m, dm_dp) = match (self.projection, self.distortion) {
            (Projection::Pinhole, Distortion::Equidistant(d)) => d.project(p)?,
            (Projection::Pinhole, distortion) => {
                let (m, dm) = pinhole(p)?;
                apply_distortion(&distortion, m, dm)
            }
            (Projection::Omni { xi }, distortion) => {
                let (m, dm) = omni::project(p, xi)?;
                apply_distortion(&distortion, m, dm)
            }
        };
        let i = &self.intrinsics;
        let k = Matrix2::new(i.fu, T::zero(), T::zero(), i.fv);
        Some(Projected {
            pixel: Vector2::new(i.fu * m.x + i.cu, i.fv * m.y + i.cv),
            jacobian: k * dm_dp,
        })
    }

    /// The unit bearing (camera frame) of a pixel; `None` outside the model's valid region.
    pub fn unproject(&self, pixel: &Vector2<T>) -> Option<Vector3<T>> {
        let i = &self.intrinsics;
        let m_d = Vector2::new((pixel.x - i.cu) / i.fu, (pixel.y - i.cv) / i.fv);
        let bearing = match (self.projection, self.distortion) {
            (Projection::Pinhole, Distortion::Equidistant(d)) => d.unproject(&m_d)?,
            (projection, distortion) => {
                let m = match distortion {
                    Distortion::RadTan(d) => d.undistort(&m_d)?,
                    _ => m_d,
                };
                match projection {
                    Projection::Pinhole => Vector3::new(m.x, m.y, T::one()),
                    Projection::Omni { xi } => omni::lift(&m, xi)?,
                }
            }
        };
        bearing.try_normalize(T::zero())
    }

    /// True when the pixel lies on the image (with `margin` pixels of border).
    pub fn in_image(&self, pixel: &Vector2<T>, margin: T) -> bool {
        let (w, h) = self.resolution;
        let half = T::lit(0.5);
        pixel.x >= margin - half
            && pixel.y >= margin - half
            && pixel.x <= T::lit(w as f64) - half - margin
            && pixel.y <= T::lit(h as f64) - half - margin
    }
}

fn pinhole<T: Scalar>(p: &Vector3<T>) -> Option<(Vector2<T>, Matrix2x3<T>)> {
    if p.z <= T::lit(1e-9) || !p.iter().all(|x| x.is_finite()) {
        return None;
    }
    let iz = T::one() / p.z;
    let m = Vector2::new(p.x * iz, p.y * iz);
    let dm = Matrix2x3::new(iz, T::zero(), -m.x * iz, T::zero(), iz, -m.y * iz);
    Some((m, dm))
}

fn apply_distortion<T: Scalar>(
    distortion: &Distortion<T>,
    m: Vector2<T>,
    dm: Matrix2x3<T>,
) -> (Vector2<T>, Matrix2x3<T>) {
    match distortion {
        Distortion::RadTan(d) => {
            let (md, j) = d.distort(&m);
            (md, j * dm)
        }
        _ => (m, dm),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::{assert_mat_close, central_diff};
    use nalgebra::SVector;

    fn cameras() -> [Camera<f64>; 5] {
        let k = Intrinsics {
            fu: 535.9,
            fv: 533.1,
            cu: 342.3,
            cv: 235.6,
        };
        let radtan = Distortion::RadTan(radtan::RadTan {
            k1: -0.266,
            k2: -0.038,
            p1: 0.0018,
            p2: -0.0003,
            k3: 0.24,
        });
        let eq = Distortion::Equidistant(equidistant::Equidistant {
            k1: -0.030464,
            k2: -0.019695,
            k3: 0.002098,
            k4: 0.001030,
        });
        let fisheye = Intrinsics {
            fu: 290.05,
            fv: 289.39,
            cu: 399.9,
            cv: 273.9,
        };
        let omni_k = Intrinsics {
            fu: 750.0,
            fv: 748.0,
            cu: 640.0,
            cv: 480.0,
        };
        let mild = Distortion::RadTan(radtan::RadTan {
            k1: -0.2,
            k2: 0.05,
            p1: 0.001,
            p2: -0.001,
            k3: 0.0,
        });
        [
            Camera::new(Projection::Pinhole, k, Distortion::None, (640, 480)).unwrap(),
            Camera::new(Projection::Pinhole, k, radtan, (640, 480)).unwrap(),
            Camera::new(Projection::Pinhole, fisheye, eq, (800, 503)).unwrap(),
            Camera::new(Projection::Omni { xi: 0.9 }, omni_k, mild, (1280, 960)).unwrap(),
            Camera::new(
                Projection::Omni { xi: 1.2 },
                omni_k,
                Distortion::None,
                (1280, 960),
            )
            .unwrap(),
        ]
    }

    fn points() -> [Vector3<f64>; 5] {
        [
            Vector3::new(0.1, -0.05, 2.0),
            Vector3::new(-0.4, 0.3, 1.5),
            Vector3::new(0.0, 0.0, 3.0),
            Vector3::new(1e-7, -1e-7, 1.0),
            Vector3::new(0.3, 0.2, 0.8),
        ]
    }

    #[test]
    fn projection_jacobians_match_central_differences() {
        for cam in cameras().iter() {
            for p in points() {
                let proj = cam.project(&p).unwrap();
                let numeric =
                    central_diff::<2, 3>(|d: SVector<f64, 3>| cam.project(&(p + d)).unwrap().pixel);
                // Pixel scale: compare per pixel with a relative tolerance.
                assert_mat_close(&(proj.jacobian / 1000.0), &(numeric / 1000.0), 1e-6);
            }
        }
    }

    #[test]
    fn unprojection_inverts_projection() {
        for cam in cameras() {
            for p in points() {
                let px = cam.project(&p).unwrap().pixel;
                let b = cam.unproject(&px).unwrap();
                assert!((b - p.normalize()).norm() < 1e-9, "{cam:?} {p:?} -> {b:?}");
            }
        }
    }

    #[test]
    fn wide_angles_of_the_fisheye_models() {
        // 80 deg off axis: beyond any pinhole, inside the fisheye and omni models.
        let p = Vector3::new(80f64.to_radians().sin(), 0.0, 80f64.to_radians().cos());
        for cam in &cameras()[2..] {
            let px = cam.project(&p).unwrap().pixel;
            let b = cam.unproject(&px).unwrap();
            assert!((b - p).norm() < 1e-8, "{cam:?}");
        }
    }

    #[test]
    fn invalid_parameters_are_rejected() {
        let k = Intrinsics {
            fu: -1.0,
            fv: 1.0,
            cu: 0.0,
            cv: 0.0,
        };
        assert_eq!(
            Camera::new(Projection::Pinhole, k, Distortion::None, (1, 1)).unwrap_err(),
            CameraError::InvalidParameter
        );
    }

    #[test]
    fn points_behind_a_pinhole_are_not_projected() {
        assert!(cameras()[0]
            .project(&Vector3::new(0.0, 0.0, -1.0))
            .is_none());
    }
}

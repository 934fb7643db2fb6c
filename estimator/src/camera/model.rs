//! The camera models of Kalibr's intrinsic calibration with their parameters as one flat
//! vector, in Kalibr's order (`intrinsics` then `distortion_coeffs`):
//!
//! | kind                  | parameters                               |
//! |-----------------------|------------------------------------------|
//! | `pinhole-radtan`      | `fu fv cu cv k1 k2 p1 p2`                |
//! | `pinhole-equidistant` | `fu fv cu cv k1 k2 k3 k4`                |
//! | `omni-radtan`         | `xi fu fv cu cv k1 k2 p1 p2`             |
//! | `ds`                  | `xi alpha fu fv cu cv`                   |
//! | `eucm`                | `alpha beta fu fv cu cv`                 |
//!
//! [`CameraModel::project`] returns the pixel with its Jacobians w.r.t. the point and w.r.t.
//! the parameters (what a bundle adjustment over intrinsics needs). The first three kinds
//! convert to and from the estimator's [`Camera`]; `ds` and `eucm` exist here only (the
//! runtime [`Camera`] does not carry them yet).

use super::{
    ds, equidistant::Equidistant, eucm, omni, radtan::RadTan, Camera, CameraError, Distortion,
    Intrinsics, Projection,
};
use crate::scalar::Scalar;
use nalgebra::{Matrix2, Matrix2x3, SMatrix, SVector, Vector2, Vector3};

/// The most parameters of any kind (`omni-radtan`).
pub const MAX_PARAMS: usize = 9;

/// A model's parameters (the tail beyond [`ModelKind::param_count`] is zero).
pub type ParamVector<T> = SVector<T, MAX_PARAMS>;

/// `d pixel / d parameters` (columns beyond [`ModelKind::param_count`] are zero).
pub type ParamJacobian<T> = SMatrix<T, 2, MAX_PARAMS>;

/// Which model.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum ModelKind {
    /// Pinhole with radial-tangential distortion (4 coefficients).
    PinholeRadtan,
    /// Pinhole with equidistant (Kannala-Brandt) distortion.
    PinholeEquidistant,
    /// Mei's unified model with radial-tangential distortion.
    OmniRadtan,
    /// Double sphere.
    DoubleSphere,
    /// Extended unified camera model.
    Eucm,
}

impl ModelKind {
    /// Every kind.
    pub const ALL: [ModelKind; 5] = [
        Self::PinholeRadtan,
        Self::PinholeEquidistant,
        Self::OmniRadtan,
        Self::DoubleSphere,
        Self::Eucm,
    ];

    /// Number of parameters.
    pub fn param_count(self) -> usize {
        match self {
            Self::PinholeRadtan | Self::PinholeEquidistant => 8,
            Self::OmniRadtan => 9,
            Self::DoubleSphere | Self::Eucm => 6,
        }
    }

    /// Number of parameters in Kalibr's `intrinsics` (the rest are `distortion_coeffs`).
    pub fn intrinsic_count(self) -> usize {
        match self {
            Self::PinholeRadtan | Self::PinholeEquidistant => 4,
            Self::OmniRadtan => 5,
            Self::DoubleSphere | Self::Eucm => 6,
        }
    }

    /// Index of `fu` (then `fv`, `cu`, `cv`).
    pub fn focal_index(self) -> usize {
        match self {
            Self::PinholeRadtan | Self::PinholeEquidistant => 0,
            Self::OmniRadtan => 1,
            Self::DoubleSphere | Self::Eucm => 2,
        }
    }

    /// Kalibr's `camera_model`.
    pub fn camera_model(self) -> &'static str {
        match self {
            Self::PinholeRadtan | Self::PinholeEquidistant => "pinhole",
            Self::OmniRadtan => "omni",
            Self::DoubleSphere => "ds",
            Self::Eucm => "eucm",
        }
    }

    /// Kalibr's `distortion_model`.
    pub fn distortion_model(self) -> &'static str {
        match self {
            Self::PinholeRadtan | Self::OmniRadtan => "radtan",
            Self::PinholeEquidistant => "equidistant",
            Self::DoubleSphere | Self::Eucm => "none",
        }
    }

    /// The kind of a Kalibr `camera_model` / `distortion_model` pair (`none` distortion
    /// on pinhole or omni maps to radtan, which contains it).
    pub fn from_kalibr(camera_model: &str, distortion_model: &str) -> Option<Self> {
        match (camera_model, distortion_model) {
            ("pinhole", "radtan" | "plumb_bob" | "none") => Some(Self::PinholeRadtan),
            ("pinhole", "equidistant") => Some(Self::PinholeEquidistant),
            ("omni", "radtan" | "none") => Some(Self::OmniRadtan),
            ("ds", "none") => Some(Self::DoubleSphere),
            ("eucm", "none") => Some(Self::Eucm),
            _ => None,
        }
    }

    /// The command-line name (`pinhole-radtan`, `pinhole-equidistant`, `omni-radtan`,
    /// `ds`, `eucm`).
    pub fn name(self) -> &'static str {
        match self {
            Self::PinholeRadtan => "pinhole-radtan",
            Self::PinholeEquidistant => "pinhole-equidistant",
            Self::OmniRadtan => "omni-radtan",
            Self::DoubleSphere => "ds",
            Self::Eucm => "eucm",
        }
    }

    /// The kind of a command-line name (see [`ModelKind::name`]).
    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|k| k.name() == name)
    }
}

/// A camera model with flat parameters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CameraModel<T: Scalar> {
    /// Which model.
    pub kind: ModelKind,
    /// Parameters in Kalibr's order (module docs).
    pub params: ParamVector<T>,
    /// Image width and height, pixels.
    pub resolution: (u32, u32),
}

impl<T: Scalar> CameraModel<T> {
    /// A model from its parameters (exactly [`ModelKind::param_count`] of them), validated:
    /// finite, positive focal lengths, `alpha` in `[0, 1)`, `beta > 0`, `xi >= 0`.
    pub fn new(kind: ModelKind, params: &[T], resolution: (u32, u32)) -> Result<Self, CameraError> {
        if params.len() != kind.param_count() {
            return Err(CameraError::InvalidParameter);
        }
        let mut v = ParamVector::zeros();
        v.rows_mut(0, params.len()).copy_from_slice(params);
        let model = Self {
            kind,
            params: v,
            resolution,
        };
        if model.is_valid() {
            Ok(model)
        } else {
            Err(CameraError::InvalidParameter)
        }
    }

    /// True when the parameters satisfy [`CameraModel::new`]'s rules.
    pub fn is_valid(&self) -> bool {
        let p = &self.params;
        let f = self.kind.focal_index();
        let unit = |a: T| a >= T::zero() && a < T::one();
        p.iter().all(|x| x.is_finite())
            && p[f] > T::zero()
            && p[f + 1] > T::zero()
            && match self.kind {
                ModelKind::PinholeRadtan | ModelKind::PinholeEquidistant => true,
                ModelKind::OmniRadtan => p[0] >= T::zero(),
                ModelKind::DoubleSphere => unit(p[1]) && p[0] > -T::one(),
                ModelKind::Eucm => unit(p[0]) && p[1] > T::zero(),
            }
    }

    /// The parameters actually used (length [`ModelKind::param_count`]).
    pub fn values(&self) -> &[T] {
        &self.params.as_slice()[..self.kind.param_count()]
    }

    /// `fu, fv, cu, cv`.
    pub fn pinhole(&self) -> Intrinsics<T> {
        let f = self.kind.focal_index();
        Intrinsics {
            fu: self.params[f],
            fv: self.params[f + 1],
            cu: self.params[f + 2],
            cv: self.params[f + 3],
        }
    }

    fn radtan(&self, at: usize) -> RadTan<T> {
        let p = &self.params;
        RadTan {
            k1: p[at],
            k2: p[at + 1],
            p1: p[at + 2],
            p2: p[at + 3],
            k3: T::zero(),
        }
    }

    /// Normalised (distorted) point, `d m / d point`, and `d m / d params` in the
    /// columns of the non-pinhole parameters (the focal columns are filled by `project`).
    fn normalised(&self, p: &Vector3<T>) -> Option<(Vector2<T>, Matrix2x3<T>, ParamJacobian<T>)> {
        let mut jm = ParamJacobian::zeros();
        let q = &self.params;
        let (m, jp) = match self.kind {
            ModelKind::PinholeRadtan => {
                let (m0, dm0) = pinhole(p)?;
                let d = self.radtan(4);
                let (m, j) = d.distort(&m0);
                jm.fixed_view_mut::<2, 4>(0, 4)
                    .copy_from(&d.coefficient_jacobian(&m0));
                (m, j * dm0)
            }
            ModelKind::PinholeEquidistant => {
                let d = Equidistant {
                    k1: q[4],
                    k2: q[5],
                    k3: q[6],
                    k4: q[7],
                };
                let (m, j) = d.project(p)?;
                jm.fixed_view_mut::<2, 4>(0, 4)
                    .copy_from(&d.coefficient_jacobian(p));
                (m, j)
            }
            ModelKind::OmniRadtan => {
                let (m0, dm0) = omni::project(p, q[0])?;
                let z = p.z / p.norm() + q[0];
                let d = self.radtan(5);
                let (m, j) = d.distort(&m0);
                jm.set_column(0, &(j * (-m0 / z)));
                jm.fixed_view_mut::<2, 4>(0, 5)
                    .copy_from(&d.coefficient_jacobian(&m0));
                (m, j * dm0)
            }
            ModelKind::DoubleSphere | ModelKind::Eucm => {
                let (m, jp, js) = if self.kind == ModelKind::DoubleSphere {
                    ds::project(p, q[0], q[1])?
                } else {
                    eucm::project(p, q[0], q[1])?
                };
                jm.fixed_view_mut::<2, 2>(0, 0).copy_from(&js);
                (m, jp)
            }
        };
        Some((m, jp, jm))
    }

    /// Pixel of a point in the camera frame with `d pixel / d point` and
    /// `d pixel / d params`; `None` when it cannot be imaged.
    pub fn project(&self, p: &Vector3<T>) -> Option<(Vector2<T>, Matrix2x3<T>, ParamJacobian<T>)> {
        let (m, jp, mut jm) = self.normalised(p)?;
        let k = self.pinhole();
        let fk = Matrix2::new(k.fu, T::zero(), T::zero(), k.fv);
        jm = fk * jm;
        let f = self.kind.focal_index();
        jm[(0, f)] = m.x;
        jm[(1, f + 1)] = m.y;
        jm[(0, f + 2)] = T::one();
        jm[(1, f + 3)] = T::one();
        let px = Vector2::new(k.fu * m.x + k.cu, k.fv * m.y + k.cv);
        Some((px, fk * jp, jm))
    }

    /// The unit bearing of a pixel; `None` outside the model's valid region.
    pub fn unproject(&self, pixel: &Vector2<T>) -> Option<Vector3<T>> {
        let k = self.pinhole();
        let m = Vector2::new((pixel.x - k.cu) / k.fu, (pixel.y - k.cv) / k.fv);
        let q = &self.params;
        match self.kind {
            ModelKind::DoubleSphere => ds::unproject(&m, q[0], q[1]),
            ModelKind::Eucm => eucm::unproject(&m, q[0], q[1]),
            _ => self.to_camera()?.unproject(pixel),
        }
    }

    /// The estimator's [`Camera`] of a pinhole or omni model; `None` for `ds` and `eucm`.
    pub fn to_camera(&self) -> Option<Camera<T>> {
        let q = &self.params;
        let (projection, distortion) = match self.kind {
            ModelKind::PinholeRadtan => (Projection::Pinhole, Distortion::RadTan(self.radtan(4))),
            ModelKind::PinholeEquidistant => (
                Projection::Pinhole,
                Distortion::Equidistant(Equidistant {
                    k1: q[4],
                    k2: q[5],
                    k3: q[6],
                    k4: q[7],
                }),
            ),
            ModelKind::OmniRadtan => (
                Projection::Omni { xi: q[0] },
                Distortion::RadTan(self.radtan(5)),
            ),
            ModelKind::DoubleSphere | ModelKind::Eucm => return None,
        };
        Camera::new(projection, self.pinhole(), distortion, self.resolution).ok()
    }

    /// The model of an estimator [`Camera`]; `None` for radtan with a non-zero `k3`
    /// (OpenCV's fifth coefficient, not a Kalibr parameter).
    pub fn from_camera(camera: &Camera<T>) -> Option<Self> {
        let i = camera.intrinsics();
        let k = [i.fu, i.fv, i.cu, i.cv];
        let z = T::zero();
        let coeffs = match *camera.distortion() {
            Distortion::None => [z; 4],
            Distortion::RadTan(d) if d.k3 == z => [d.k1, d.k2, d.p1, d.p2],
            Distortion::RadTan(_) => return None,
            Distortion::Equidistant(d) => [d.k1, d.k2, d.k3, d.k4],
        };
        let (kind, xi) = match (*camera.projection(), *camera.distortion()) {
            (Projection::Pinhole, Distortion::Equidistant(_)) => {
                (ModelKind::PinholeEquidistant, None)
            }
            (Projection::Pinhole, _) => (ModelKind::PinholeRadtan, None),
            (Projection::Omni { xi }, _) => (ModelKind::OmniRadtan, Some(xi)),
        };
        let mut v = [z; MAX_PARAMS];
        let mut n = 0;
        for x in xi.into_iter().chain(k).chain(coeffs) {
            v[n] = x;
            n += 1;
        }
        Self::new(kind, &v[..n], camera.resolution).ok()
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::{assert_mat_close, central_diff};

    /// One camera of every kind, wide-angle ones with realistic parameters.
    pub(crate) fn models() -> [CameraModel<f64>; 5] {
        let r = (752, 480);
        [
            CameraModel::new(
                ModelKind::PinholeRadtan,
                &[458.6, 457.3, 367.2, 248.4, -0.283, 0.074, 0.0002, 1.8e-5],
                r,
            ),
            CameraModel::new(
                ModelKind::PinholeEquidistant,
                &[290.0, 289.4, 399.9, 273.9, -0.030, -0.020, 0.0021, 0.0010],
                (800, 503),
            ),
            CameraModel::new(
                ModelKind::OmniRadtan,
                &[0.9, 750.0, 748.0, 640.0, 480.0, -0.2, 0.05, 0.001, -0.001],
                (1280, 960),
            ),
            CameraModel::new(
                ModelKind::DoubleSphere,
                &[-0.18, 0.59, 313.2, 313.1, 638.9, 514.0],
                (1280, 1024),
            ),
            CameraModel::new(
                ModelKind::Eucm,
                &[0.63, 1.05, 380.1, 380.0, 640.2, 511.8],
                (1280, 1024),
            ),
        ]
        .map(|m| m.unwrap())
    }

    fn points() -> [Vector3<f64>; 5] {
        [
            Vector3::new(0.1, -0.05, 2.0),
            Vector3::new(-0.4, 0.3, 1.5),
            Vector3::new(0.3, 0.2, 0.8),
            Vector3::new(1e-3, -2e-3, 1.0),
            Vector3::new(0.5, -0.4, 0.6),
        ]
    }

    #[test]
    fn point_jacobians_match_central_differences() {
        for cam in models() {
            for p in points() {
                let (_, jp, _) = cam.project(&p).unwrap();
                let numeric = central_diff::<2, 3>(|d| cam.project(&(p + d)).unwrap().0);
                assert_mat_close(&(jp / 1000.0), &(numeric / 1000.0), 1e-6);
            }
        }
    }

    #[test]
    fn parameter_jacobians_match_central_differences() {
        for cam in models() {
            for p in points() {
                let (_, _, jm) = cam.project(&p).unwrap();
                let numeric = central_diff::<2, MAX_PARAMS>(|d| {
                    let mut c = cam;
                    let n = c.kind.param_count();
                    for k in 0..n {
                        c.params[k] += d[k];
                    }
                    c.project(&p).unwrap().0
                });
                assert_mat_close(&(jm / 1000.0), &(numeric / 1000.0), 1e-6);
            }
        }
    }

    #[test]
    fn unprojection_inverts_projection() {
        for cam in models() {
            for p in points() {
                let (px, _, _) = cam.project(&p).unwrap();
                let b = cam.unproject(&px).unwrap();
                assert!((b - p.normalize()).norm() < 1e-9, "{:?} {p:?}", cam.kind);
            }
        }
    }

    #[test]
    fn the_fisheye_kinds_image_rays_beyond_90_degrees() {
        let p = Vector3::new(100f64.to_radians().sin(), 0.0, 100f64.to_radians().cos());
        for cam in &models()[3..] {
            let (px, _, _) = cam.project(&p).unwrap();
            let b = cam.unproject(&px).unwrap();
            assert!((b - p).norm() < 1e-9, "{:?}", cam.kind);
        }
    }

    #[test]
    fn camera_round_trip_and_invalid_parameters() {
        for cam in &models()[..3] {
            let back = CameraModel::from_camera(&cam.to_camera().unwrap()).unwrap();
            assert_eq!(&back, cam);
        }
        assert!(models()[3].to_camera().is_none());
        let bad =
            CameraModel::<f64>::new(ModelKind::Eucm, &[1.2, 1.0, 300.0, 300.0, 1.0, 1.0], (2, 2));
        assert_eq!(bad.unwrap_err(), CameraError::InvalidParameter);
        let short = CameraModel::<f64>::new(ModelKind::Eucm, &[0.5, 1.0], (2, 2));
        assert_eq!(short.unwrap_err(), CameraError::InvalidParameter);
        for kind in ModelKind::ALL {
            assert_eq!(ModelKind::from_name(kind.name()), Some(kind));
            assert_eq!(
                ModelKind::from_kalibr(kind.camera_model(), kind.distortion_model()),
                Some(kind)
            );
        }
    }

    #[test]
    fn f32_projection_agrees_with_f64() {
        for cam in models() {
            let c32 = CameraModel::<f32> {
                kind: cam.kind,
                params: cam.params.map(|x| x as f32),
                resolution: cam.resolution,
            };
            let p = Vector3::new(0.2f32, -0.1, 1.0);
            let a = c32.project(&p).unwrap().0;
            let b = cam.project(&p.map(f64::from)).unwrap().0;
            assert!((a.map(f64::from) - b).norm() < 1e-2, "{:?}", cam.kind);
        }
    }
}

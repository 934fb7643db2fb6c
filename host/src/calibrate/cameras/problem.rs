//! The rig bundle adjustment as a [`SchurProblem`]: global parameters are every camera's
//! intrinsics (Kalibr order) and, for `camN` with N >= 1, the extrinsic `T_cn_c0` (right
//! perturbation `[d_theta, d_p]`); local blocks are the target poses `T_c0_target` of the
//! views (one per stamp). A residual is `project(T_cn_c0 T_c0_target X) - pixel`.

use msreg_estimator::camera::model::CameraModel;
use msreg_estimator::lie::skew;
use msreg_estimator::Pose;
use nalgebra::{DVector, Matrix2x6, Matrix3, SMatrix, Vector2, Vector3, Vector6};

use crate::solve::{BlockResidual, SchurProblem, MAX_GLOBAL_COLS};

/// One corner seen by one camera in one view.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Observation {
    /// Camera index.
    pub camera: usize,
    /// View (target pose) index.
    pub view: usize,
    /// The corner in the target frame, m.
    pub point: Vector3<f64>,
    /// Its detected pixel.
    pub pixel: Vector2<f64>,
}

/// Parameters of the rig problem.
#[derive(Clone, Debug, PartialEq)]
pub struct RigState {
    /// Intrinsics of every camera.
    pub cameras: Vec<CameraModel<f64>>,
    /// `T_cn_c0` of every camera (identity for cam0).
    pub extrinsics: Vec<Pose<f64>>,
    /// `T_c0_target` of every view.
    pub views: Vec<Pose<f64>>,
}

/// Where each camera's parameters sit in the global vector.
#[derive(Clone, Debug, PartialEq)]
pub struct Layout {
    /// First column of camera `c`'s intrinsics.
    pub intrinsics: Vec<usize>,
    /// First column of camera `c`'s extrinsic (`None` for cam0).
    pub extrinsic: Vec<Option<usize>>,
    /// Total global columns.
    pub dim: usize,
}

impl Layout {
    /// The layout of `cameras` (intrinsics then extrinsic, camera by camera).
    pub fn of(cameras: &[CameraModel<f64>]) -> Self {
        let (mut intrinsics, mut extrinsic, mut dim) = (Vec::new(), Vec::new(), 0);
        for (c, cam) in cameras.iter().enumerate() {
            intrinsics.push(dim);
            dim += cam.kind.param_count();
            extrinsic.push((c > 0).then_some(dim));
            if c > 0 {
                dim += 6;
            }
        }
        Self {
            intrinsics,
            extrinsic,
            dim,
        }
    }
}

/// The problem: observations with a common information weight.
pub struct RigProblem<'a> {
    /// The corners in use.
    pub observations: &'a [Observation],
    /// Number of views.
    pub views: usize,
    /// Global layout.
    pub layout: Layout,
    /// Information of a pixel coordinate, 1 / px^2.
    pub weight: f64,
}

fn split(d: &Vector6<f64>) -> (Vector3<f64>, Vector3<f64>) {
    (d.fixed_rows::<3>(0).into(), d.fixed_rows::<3>(3).into())
}

/// `d (R x + t) / d [d_theta, d_p]` under [`Pose::boxplus`].
fn pose_jacobian(rotation: &Matrix3<f64>, x: &Vector3<f64>) -> SMatrix<f64, 3, 6> {
    let mut j = SMatrix::<f64, 3, 6>::zeros();
    j.fixed_view_mut::<3, 3>(0, 0)
        .copy_from(&-(rotation * skew(x)));
    j.fixed_view_mut::<3, 3>(0, 3)
        .copy_from(&Matrix3::identity());
    j
}

impl RigProblem<'_> {
    /// The residual of one observation, `None` when it cannot be projected.
    pub fn residual(&self, s: &RigState, o: &Observation) -> Option<BlockResidual> {
        let view = &s.views[o.view];
        let p0 = view.transform_point(&o.point);
        let r0 = view.rotation.to_rotation_matrix().into_inner();
        let ext = &s.extrinsics[o.camera];
        let rc = ext.rotation.to_rotation_matrix().into_inner();
        let p = ext.transform_point(&p0);
        let cam = &s.cameras[o.camera];
        let (px, jp, jm) = cam.project(&p)?;
        let n = cam.kind.param_count();
        let mut r = BlockResidual {
            value: px - o.pixel,
            weight: self.weight,
            local: o.view,
            j_local: Matrix2x6::from(jp * rc * pose_jacobian(&r0, &o.point)),
            global_index: [0; MAX_GLOBAL_COLS],
            global_len: n,
            j_global: SMatrix::zeros(),
        };
        let start = self.layout.intrinsics[o.camera];
        for k in 0..n {
            r.global_index[k] = start + k;
            r.j_global.set_column(k, &jm.column(k));
        }
        if let Some(e) = self.layout.extrinsic[o.camera] {
            let je = jp * pose_jacobian(&rc, &p0);
            for k in 0..6 {
                r.global_index[n + k] = e + k;
                r.j_global.set_column(n + k, &je.column(k));
            }
            r.global_len = n + 6;
        }
        Some(r)
    }
}

impl SchurProblem for RigProblem<'_> {
    type State = RigState;

    fn global_dim(&self) -> usize {
        self.layout.dim
    }

    fn local_count(&self) -> usize {
        self.views
    }

    fn residuals(&self, s: &RigState, out: &mut Vec<BlockResidual>) -> bool {
        if !s.cameras.iter().all(|c| c.is_valid()) {
            return false;
        }
        for o in self.observations {
            match self.residual(s, o) {
                Some(r) => out.push(r),
                None => return false,
            }
        }
        true
    }

    fn retract(&self, s: &RigState, global: &DVector<f64>, local: &[Vector6<f64>]) -> RigState {
        let mut next = s.clone();
        for (c, cam) in next.cameras.iter_mut().enumerate() {
            let start = self.layout.intrinsics[c];
            for k in 0..cam.kind.param_count() {
                cam.params[k] += global[start + k];
            }
            if let Some(e) = self.layout.extrinsic[c] {
                let d = global.fixed_rows::<6>(e).into_owned();
                let (dr, dp) = split(&d);
                next.extrinsics[c] = next.extrinsics[c].boxplus(&dr, &dp);
            }
        }
        for (v, d) in next.views.iter_mut().zip(local) {
            let (dr, dp) = split(d);
            *v = v.boxplus(&dr, &dp);
        }
        next
    }
}

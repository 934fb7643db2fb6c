//! MI slices through the optimum (dissertation Fig. 7.8 / 7.9): the smoothed MI along
//! each DoF of `delta = [omega in the camera frame; v in W]` with the others held, beside
//! the parabola of the refinement's Hessian diagonal, the curvature the sigmas come from.

use serde::Serialize;

use crate::mi::scene::{MiScene, PoseParam};
use crate::mi::search::Refined;
use nalgebra::Vector6;

/// Names of the DoFs of `delta`, with the unit of the offsets.
pub const DOF_NAMES: [(&str, &str); 6] = [
    ("rot_x_cam", "deg"),
    ("rot_y_cam", "deg"),
    ("rot_z_cam", "deg"),
    ("x_world", "m"),
    ("y_world", "m"),
    ("z_world", "m"),
];

/// The MI along one DoF through the estimate.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct MiSlice {
    /// DoF name.
    pub dof: &'static str,
    /// Unit of `offsets` (deg or m).
    pub unit: &'static str,
    /// Offsets from the estimate.
    pub offsets: Vec<f64>,
    /// Smoothed MI there (nats).
    pub mi: Vec<f64>,
    /// `MI(0) + H_kk d^2 / 2`: the refinement's curvature along this DoF.
    pub quadratic: Vec<f64>,
    /// Offset of the largest MI of the slice.
    pub peak_offset: f64,
}

/// Slices of the smoothed MI of `scene` through `refined.x` (`T_world_cam`), each over
/// `+-half_px` of mean image motion in `2 steps + 1` samples.
pub fn mi_slices(scene: &MiScene, refined: &Refined, half_px: f64, steps: usize) -> Vec<MiSlice> {
    let param = PoseParam::SourceFromCam;
    let centre = scene.smoothed(&param.t_cam_src(&refined.x)).mi;
    let n = steps.max(1) as isize;
    DOF_NAMES
        .iter()
        .enumerate()
        .map(|(k, &(dof, unit))| {
            let step = half_px / refined.pixels_per_unit[k].max(1e-9) / n as f64;
            let deltas: Vec<f64> = (-n..=n).map(|j| j as f64 * step).collect();
            let mi: Vec<f64> = deltas
                .iter()
                .map(|&d| {
                    if d == 0.0 {
                        return centre;
                    }
                    let mut delta = Vector6::zeros();
                    delta[k] = d;
                    let x = param.retract(&refined.x, &delta);
                    scene.smoothed(&param.t_cam_src(&x)).mi
                })
                .collect();
            let quadratic = deltas
                .iter()
                .map(|d| centre + 0.5 * refined.hessian[(k, k)] * d * d)
                .collect();
            let scale = if unit == "deg" {
                180.0 / std::f64::consts::PI
            } else {
                1.0
            };
            let offsets: Vec<f64> = deltas.iter().map(|d| d * scale).collect();
            let peak = (0..mi.len())
                .max_by(|&a, &b| mi[a].total_cmp(&mi[b]))
                .unwrap_or(n as usize);
            MiSlice {
                dof,
                unit,
                peak_offset: offsets[peak],
                offsets,
                mi,
                quadratic,
            }
        })
        .collect()
}

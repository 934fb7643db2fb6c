//! Frame-free judging of infrastructure-camera poses (docs/formats.md): one rigid transform
//! (least squares over camera centres, no scale) aligns the estimate to the truth; then
//! position RMS, rotation errors and the share of axes inside 3 sigma.

use std::path::Path;

use nalgebra::Vector3;
use serde::Serialize;

use super::align::rigid;
use super::io::{pose_of_rows, InfraError, InfraResultFile};

/// Errors of one estimate against the truth.
#[derive(Clone, Debug, Serialize)]
pub struct InfraErrors {
    /// Cameras in both files.
    pub cameras: usize,
    /// Position RMS after alignment, m.
    pub position_rms_m: f64,
    /// Largest position error, m.
    pub position_max_m: f64,
    /// Largest rotation error, deg.
    pub rotation_max_deg: f64,
    /// Relative VO-scale error.
    pub scale_error: f64,
    /// Fraction of the 6 axes per camera inside 3 reported sigma.
    pub inside_3sigma: f64,
}

/// Compares `estimate` with `truth` (ground-truth `infra.yaml`).
pub fn evaluate(
    estimate: &InfraResultFile,
    truth: &InfraResultFile,
) -> Result<InfraErrors, InfraError> {
    let here = Path::new("result");
    let mut pairs = Vec::new();
    for (id, est) in &estimate.infra.cameras {
        if let Some(t) = truth.infra.cameras.get(id) {
            pairs.push((
                pose_of_rows(here, &est.t_world_cam)?,
                pose_of_rows(here, &t.t_world_cam)?,
                est,
            ));
        }
    }
    let a: Vec<Vector3<f64>> = pairs.iter().map(|p| p.0.translation.vector).collect();
    let b: Vec<Vector3<f64>> = pairs.iter().map(|p| p.1.translation.vector).collect();
    let align = rigid(&a, &b);
    let (mut sq, mut pmax, mut rmax, mut inside) = (0.0, 0.0f64, 0.0f64, 0usize);
    for (est, tru, r) in &pairs {
        let aligned = align * est;
        let dp_vo =
            align.rotation.inverse() * (tru.translation.vector - aligned.translation.vector);
        let dr = (aligned.rotation.inverse() * tru.rotation).scaled_axis();
        sq += dp_vo.norm_squared();
        pmax = pmax.max(dp_vo.norm());
        rmax = rmax.max(dr.norm().to_degrees());
        for k in 0..3 {
            inside += usize::from(dp_vo[k].abs() <= 3.0 * r.sigma_trans_m[k]);
            inside += usize::from(dr[k].abs().to_degrees() <= 3.0 * r.sigma_rot_deg[k]);
        }
    }
    let n = pairs.len().max(1) as f64;
    Ok(InfraErrors {
        cameras: pairs.len(),
        position_rms_m: (sq / n).sqrt(),
        position_max_m: pmax,
        rotation_max_deg: rmax,
        scale_error: estimate.infra.vo_scale / truth.infra.vo_scale - 1.0,
        inside_3sigma: inside as f64 / (6.0 * n),
    })
}

//! What `msreg calibrate cameras` writes: Kalibr's camchain keys per camera (docs/formats.md,
//! "Calibration result") and a JSON report. The camchain text is produced by
//! [`camchain_yaml`] alone, the one place to switch to the shared result type.

use msreg_estimator::Pose;
use nalgebra::Matrix6;
use serde::Serialize;

use super::{CameraResult, CamerasResult};
use crate::camera_yaml::yaml_number;

fn list(values: &[f64]) -> String {
    let items: Vec<String> = values.iter().map(|&v| yaml_number(v)).collect();
    format!("[{}]", items.join(", "))
}

/// `T` as Kalibr's 4x4 rows.
fn matrix_rows(t: &Pose<f64>) -> [[f64; 4]; 4] {
    let r = t.rotation.to_rotation_matrix().into_inner();
    let mut m = [[0.0; 4]; 4];
    for (i, row) in m.iter_mut().enumerate().take(3) {
        for (j, x) in row.iter_mut().enumerate().take(3) {
            *x = r[(i, j)];
        }
        row[3] = t.translation[i];
    }
    m[3][3] = 1.0;
    m
}

/// 1-sigma rotation (deg) and translation (m) of a `[d_theta, d_p]` covariance.
pub fn pose_sigmas(cov: &Matrix6<f64>) -> ([f64; 3], [f64; 3]) {
    let s = |k: usize| cov[(k, k)].max(0.0).sqrt();
    (
        [s(0).to_degrees(), s(1).to_degrees(), s(2).to_degrees()],
        [s(3), s(4), s(5)],
    )
}

fn camera_section(cam: &CameraResult) -> String {
    let m = &cam.model;
    let v = m.values();
    let k = m.kind.intrinsic_count();
    let mut s = format!(
        "{}:\n  camera_model: {}\n  intrinsics: {}\n  distortion_model: {}\n  \
         distortion_coeffs: {}\n  resolution: [{}, {}]\n  sigma_intrinsics: {}\n",
        cam.name,
        m.kind.camera_model(),
        list(&v[..k]),
        m.kind.distortion_model(),
        list(&v[k..]),
        m.resolution.0,
        m.resolution.1,
        list(&cam.sigma)
    );
    if let Some((t, cov)) = &cam.t_cn_cnm1 {
        s.push_str("  T_cn_cnm1:\n");
        for row in matrix_rows(t) {
            s.push_str(&format!("  - {}\n", list(&row)));
        }
        let (rot, trans) = pose_sigmas(cov);
        s.push_str(&format!(
            "  sigma_rot_deg: {}\n  sigma_trans_m: {}\n",
            list(&rot),
            list(&trans)
        ));
    }
    s
}

/// The result YAML: one `camN` section per camera with Kalibr's camchain keys.
pub fn camchain_yaml(result: &CamerasResult) -> String {
    let mut s = String::from("# msreg calibrate cameras (Kalibr camchain keys)\n");
    for cam in &result.cameras {
        s.push_str(&camera_section(cam));
    }
    s
}

/// One image in the report.
#[derive(Clone, Debug, Serialize)]
pub struct ImageReport {
    /// File name.
    pub name: String,
    /// RMS reprojection error, px.
    pub rms_px: f64,
    /// Used in the final solve.
    pub used: bool,
}

/// One camera in the report.
#[derive(Clone, Debug, Serialize)]
pub struct CameraReport {
    /// `camN`.
    pub name: String,
    /// Model name (`pinhole-radtan`, ...).
    pub model: String,
    /// Parameters, Kalibr order.
    pub parameters: Vec<f64>,
    /// Their 1-sigma.
    pub sigma: Vec<f64>,
    /// RMS over the corners used, px.
    pub rms_px: f64,
    /// Corners used.
    pub corners_used: usize,
    /// Corners rejected (outliers, or in rejected images).
    pub corners_rejected: usize,
    /// Images used.
    pub images_used: usize,
    /// Images rejected (outlying RMS or no starting pose).
    pub images_rejected: usize,
    /// `T_cn_cnm1` rows (N >= 1).
    pub t_cn_cnm1: Option<[[f64; 4]; 4]>,
    /// Its 1-sigma rotation, deg.
    pub sigma_rot_deg: Option<[f64; 3]>,
    /// Its 1-sigma translation, m.
    pub sigma_trans_m: Option<[f64; 3]>,
    /// Every image.
    pub images: Vec<ImageReport>,
}

/// The JSON report's calibration part.
#[derive(Clone, Debug, Serialize)]
pub struct CamerasReport {
    /// Per camera.
    pub cameras: Vec<CameraReport>,
    /// Views (target poses).
    pub views: usize,
    /// Robust corner sigma, px.
    pub pixel_sigma: f64,
    /// Variance factor of the final solve.
    pub variance_factor: f64,
    /// Solver iterations.
    pub iterations: usize,
    /// Converged.
    pub converged: bool,
    /// Rejection rounds.
    pub rounds: usize,
}

/// The report of `result`.
pub fn report(result: &CamerasResult) -> CamerasReport {
    CamerasReport {
        cameras: result
            .cameras
            .iter()
            .map(|c| CameraReport {
                name: c.name.clone(),
                model: c.model.kind.name().to_string(),
                parameters: c.model.values().to_vec(),
                sigma: c.sigma.clone(),
                rms_px: c.rms_px,
                corners_used: c.corners.0,
                corners_rejected: c.corners.1,
                images_used: c.images.0,
                images_rejected: c.images.1,
                t_cn_cnm1: c.t_cn_cnm1.as_ref().map(|(t, _)| matrix_rows(t)),
                sigma_rot_deg: c.t_cn_cnm1.as_ref().map(|(_, cov)| pose_sigmas(cov).0),
                sigma_trans_m: c.t_cn_cnm1.as_ref().map(|(_, cov)| pose_sigmas(cov).1),
                images: c
                    .image_rms
                    .iter()
                    .map(|(name, rms_px, used)| ImageReport {
                        name: name.clone(),
                        rms_px: *rms_px,
                        used: *used,
                    })
                    .collect(),
            })
            .collect(),
        views: result.views,
        pixel_sigma: result.pixel_sigma,
        variance_factor: result.variance_factor,
        iterations: result.iterations,
        converged: result.converged,
        rounds: result.rounds,
    }
}

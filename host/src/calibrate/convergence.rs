//! A filter's convergence history as plot series (the 6 extrinsic DoF and the time offset),
//! for `plot::write_convergence_png`.

use crate::calibrate::driver::report::HistoryPoint;
use crate::plot::ConvergenceSeries;

/// The 6 extrinsic DoF and the time offset of a filter's history. Rotation is drawn as the
/// right perturbation from the *final* estimate, `Log(R_final^T R(t))` in deg, whose axes are
/// the ones the filter's sigmas refer to (a rotation vector's components are not, and wrap
/// near 180 deg); translation in mm, time offset in ms. `truth` = (rotation vector rad,
/// translation m, time offset s), drawn in the same coordinates.
pub fn extrinsic_series(
    history: &[HistoryPoint],
    truth: Option<([f64; 3], [f64; 3], f64)>,
) -> Vec<ConvergenceSeries> {
    use nalgebra::{UnitQuaternion, Vector3};
    let rotation = |rv: &[f64; 3]| UnitQuaternion::from_scaled_axis(Vector3::from(*rv));
    let final_inv = history.last().map_or_else(UnitQuaternion::identity, |h| {
        rotation(&h.rotation_vector).inverse()
    });
    let relative = |rv: &[f64; 3]| (final_inv * rotation(rv)).scaled_axis();
    let t_s: Vec<f64> = history.iter().map(|h| h.t_s).collect();
    let series = |label: &str, unit: &str, f: &dyn Fn(&HistoryPoint) -> (f64, f64), truth| {
        let (value, sigma) = history.iter().map(f).unzip();
        ConvergenceSeries {
            label: label.into(),
            unit: unit.into(),
            t_s: t_s.clone(),
            value,
            sigma,
            truth,
        }
    };
    let mut out = Vec::new();
    for (i, axis) in ["x", "y", "z"].iter().enumerate() {
        out.push(series(
            &format!("rotation about {axis} (from the final estimate)"),
            "deg",
            &|h| {
                (
                    relative(&h.rotation_vector)[i].to_degrees(),
                    h.sigma_rot_deg[i],
                )
            },
            truth.map(|t| relative(&t.0)[i].to_degrees()),
        ));
    }
    for (i, axis) in ["x", "y", "z"].iter().enumerate() {
        out.push(series(
            &format!("translation {axis}"),
            "mm",
            &|h| (h.translation_m[i] * 1e3, h.sigma_trans_m[i] * 1e3),
            truth.map(|t| t.1[i] * 1e3),
        ));
    }
    out.push(series(
        "time offset",
        "ms",
        &|h| (h.time_offset_s * 1e3, h.sigma_time_offset_s * 1e3),
        truth.map(|t| t.2 * 1e3),
    ));
    out
}

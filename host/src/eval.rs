//! Errors of a calibration result against the simulator's ground truth.
//!
//! Rotation error per axis is `Log(R_est^T R_true)` (the right perturbation every sigma in
//! the result file refers to); translation error is `p_true - p_est`; time error is
//! `t_d,est - t_d,true`. "Within 3 sigma" means every axis and the time offset are.

use nalgebra::Vector3;
use serde::Serialize;

#[cfg(test)]
use crate::dataset::SectionName;
use crate::dataset::{CalibrationResult, ExtrinsicEstimate};

/// Errors of one result section.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct SectionErrors {
    /// Section name (`pose0`, `lidar1`, `cam0_lidar0`, ...), with `.T_cn_cnm1` for a
    /// camera chain.
    pub section: String,
    /// Rotation error angle, deg.
    pub rotation_deg: f64,
    /// Per-axis rotation error, deg.
    pub rotation_axes_deg: [f64; 3],
    /// Translation error norm, m.
    pub translation_m: f64,
    /// Per-axis translation error, m.
    pub translation_axes_m: [f64; 3],
    /// Time offset error, s.
    pub time_offset_s: f64,
    /// Reported 1-sigma rotation per axis, deg.
    pub sigma_rot_deg: [f64; 3],
    /// Reported 1-sigma translation per axis, m.
    pub sigma_trans_m: [f64; 3],
    /// Every rotation and translation axis inside its reported 3 sigma.
    pub within_3_sigma: bool,
}

/// Compares one estimate with the truth.
pub fn compare(section: &str, est: &ExtrinsicEstimate, truth: &ExtrinsicEstimate) -> SectionErrors {
    let d_rot = (est.transform.rotation.inverse() * truth.transform.rotation).scaled_axis();
    let d_trans = truth.transform.translation.vector - est.transform.translation.vector;
    let rot_deg: Vector3<f64> = d_rot.map(f64::to_degrees);
    let within = (0..3).all(|i| {
        rot_deg[i].abs() <= 3.0 * est.sigma_rot_deg[i]
            && d_trans[i].abs() <= 3.0 * est.sigma_trans_m[i]
    });
    SectionErrors {
        section: section.to_string(),
        rotation_deg: d_rot.norm().to_degrees(),
        rotation_axes_deg: [rot_deg.x, rot_deg.y, rot_deg.z],
        translation_m: d_trans.norm(),
        translation_axes_m: [d_trans.x, d_trans.y, d_trans.z],
        time_offset_s: est.timeshift_s - truth.timeshift_s,
        sigma_rot_deg: [
            est.sigma_rot_deg.x,
            est.sigma_rot_deg.y,
            est.sigma_rot_deg.z,
        ],
        sigma_trans_m: [
            est.sigma_trans_m.x,
            est.sigma_trans_m.y,
            est.sigma_trans_m.z,
        ],
        within_3_sigma: within,
    }
}

/// Hints that a section was written in another convention than the file's key says: the
/// inverse transform (`T_imu_cam` under `T_cam_imu`), or a time shift far beyond any
/// sensor latency (ms or ns where seconds are meant). One line each, for warnings.
pub fn convention_hints(result: &CalibrationResult, truth: &CalibrationResult) -> Vec<String> {
    let mut hints = Vec::new();
    for (name, est, truth) in common_sections(result, truth) {
        if let Some(h) = inverted_hint(&name, est, truth) {
            hints.push(h);
        }
        if est.timeshift_s.abs() > MAX_PLAUSIBLE_TIMESHIFT_S {
            hints.push(format!(
                "{name}: time shift {} s is beyond any sensor latency: seconds are expected \
                 (a value in ms or ns?)",
                est.timeshift_s
            ));
        }
    }
    hints
}

/// The transforms present in both files, in file order: (name, estimate, truth). Each
/// section's extrinsic is named as the section (`lidar1`); a camera chain `T_cn_cnm1` as
/// `cam1.T_cn_cnm1`.
fn common_sections<'a>(
    result: &'a CalibrationResult,
    truth: &'a CalibrationResult,
) -> impl Iterator<Item = (String, &'a ExtrinsicEstimate, &'a ExtrinsicEstimate)> {
    result.sections().flat_map(move |(name, section)| {
        let other = truth.section(name);
        let extrinsic = section
            .extrinsic
            .as_ref()
            .zip(other.and_then(|t| t.extrinsic.as_ref()))
            .map(|(e, t)| (name.to_string(), e, t));
        let chain = section
            .camera_chain
            .as_ref()
            .zip(other.and_then(|t| t.camera_chain.as_ref()))
            .map(|(e, t)| (format!("{name}.T_cn_cnm1"), e, t));
        extrinsic.into_iter().chain(chain)
    })
}

/// Largest time shift (s) taken as a time shift in seconds rather than a unit mistake.
const MAX_PLAUSIBLE_TIMESHIFT_S: f64 = 1.0;

/// `Some` when the inverse of `est` is far closer to `truth` than `est` is.
fn inverted_hint(name: &str, est: &ExtrinsicEstimate, truth: &ExtrinsicEstimate) -> Option<String> {
    let distance = |a: &nalgebra::Isometry3<f64>| {
        let d = a.inverse() * truth.transform;
        d.rotation.angle() + d.translation.vector.norm()
    };
    let (direct, inverse) = (distance(&est.transform), distance(&est.transform.inverse()));
    (direct > 0.05 && inverse < 0.2 * direct).then(|| {
        format!(
            "{name}: the inverse transform matches the reference ({inverse:.3} against \
             {direct:.3} rad + m): the result looks written the other way round \
             (e.g. T_imu_cam under the key T_cam_imu)"
        )
    })
}

/// Errors of every section present in both files.
pub fn evaluate(result: &CalibrationResult, truth: &CalibrationResult) -> Vec<SectionErrors> {
    common_sections(result, truth)
        .map(|(name, e, t)| compare(&name, e, t))
        .collect()
}

/// The header line of [`table`].
pub const TABLE_HEADER: &str =
    "section      rot err [deg]  3-sigma [deg]  trans err [mm]  3-sigma [mm]  time err [ms]  inside 3 sigma\n";

/// A plain-text table of the errors.
pub fn table(errors: &[SectionErrors]) -> String {
    format!("{TABLE_HEADER}{}", table_rows(errors))
}

/// The rows of [`table`], one per section, without the header.
pub fn table_rows(errors: &[SectionErrors]) -> String {
    let mut out = String::new();
    for e in errors {
        let s3r = 3.0 * e.sigma_rot_deg.iter().cloned().fold(0.0, f64::max);
        let s3t = 3.0 * e.sigma_trans_m.iter().cloned().fold(0.0, f64::max) * 1e3;
        out.push_str(&format!(
            "{:<12} {:>13.4}  {:>13.4}  {:>14.2}  {:>12.2}  {:>13.3}  {}\n",
            e.section,
            e.rotation_deg,
            s3r,
            e.translation_m * 1e3,
            s3t,
            e.time_offset_s * 1e3,
            if e.within_3_sigma { "yes" } else { "NO" }
        ));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Isometry3, Translation3, UnitQuaternion};

    #[test]
    fn inverted_section_and_implausible_time_shift_are_hinted() {
        let t = Isometry3::from_parts(
            Translation3::new(0.1, -0.05, 0.02),
            UnitQuaternion::from_euler_angles(1.5, 0.2, -0.3),
        );
        let truth = CalibrationResult::new()
            .with_extrinsic(SectionName::CAM0, ExtrinsicEstimate::exact(t, 0.005));
        let good = truth.clone();
        assert!(convention_hints(&good, &truth).is_empty());
        let swapped = CalibrationResult::new().with_extrinsic(
            SectionName::CAM0,
            ExtrinsicEstimate::exact(t.inverse(), 5e6),
        );
        let hints = convention_hints(&swapped, &truth);
        assert_eq!(hints.len(), 2, "{hints:?}");
        assert!(hints[0].contains("other way round") && hints[1].contains("ms or ns"));
    }

    #[test]
    fn every_section_present_in_both_files_is_scored_chains_included() {
        let t = |x: f64| {
            Isometry3::from_parts(
                Translation3::new(x, 0.0, 0.0),
                UnitQuaternion::from_euler_angles(0.0, 0.0, x),
            )
        };
        let mut truth = CalibrationResult::new();
        let mut estimate = CalibrationResult::new();
        for (name, x) in [("cam0", 0.1), ("cam1", 0.2), ("lidar2", 0.3), ("imu1", 0.4)] {
            let name: SectionName = name.parse().expect("name");
            truth.set_extrinsic(name, ExtrinsicEstimate::exact(t(x), 0.0));
            estimate.set_extrinsic(name, ExtrinsicEstimate::exact(t(x + 0.001), 1e-4));
        }
        truth.section_mut(SectionName::cam(1)).camera_chain =
            Some(ExtrinsicEstimate::exact(t(0.05), 0.0));
        estimate.section_mut(SectionName::cam(1)).camera_chain =
            Some(ExtrinsicEstimate::exact(t(0.05), 0.0));
        estimate.set_extrinsic(SectionName::pose(3), ExtrinsicEstimate::exact(t(0.0), 0.0));
        let errors = evaluate(&estimate, &truth);
        let names: Vec<&str> = errors.iter().map(|e| e.section.as_str()).collect();
        assert_eq!(names, ["cam0", "cam1", "cam1.T_cn_cnm1", "lidar2", "imu1"]);
        assert!((errors[0].translation_m - 0.001).abs() < 1e-12);
        assert!((errors[0].time_offset_s - 1e-4).abs() < 1e-15);
        assert!(errors[2].translation_m < 1e-15);
    }
}

//! Kalibr's camchain-imucam and imu chain, and OpenVINS's copies of them.
//!
//! Kalibr: `camN.T_cam_imu` (p_camN = T_cam_imu * p_imu0), `camN.T_cn_cnm1` (p_camN =
//! T_cn_cnm1 * p_cam(N-1)), `imuN.T_i_b` (p_imuN = T_i_b * p_imu0, `imu0` the body).
//! OpenVINS: the same keys with `T_imu_cam` = T_cam_imu^-1 in place of `T_cam_imu`.

use super::text::{block_rows, float, flow};
use super::{missing, sensors, ExportError, ExportFile, ExportFormat};
use crate::dataset::{CalibrationResult, SectionName, SensorKind};

/// `camchain-imucam.yaml` (+ `imu.yaml`).
pub(super) fn kalibr(result: &CalibrationResult) -> Result<Vec<ExportFile>, ExportError> {
    files(
        result,
        ExportFormat::Kalibr,
        "camchain-imucam.yaml",
        "imu.yaml",
        "",
    )
}

/// `kalibr_imucam_chain.yaml` (+ `kalibr_imu_chain.yaml`).
pub(super) fn openvins(result: &CalibrationResult) -> Result<Vec<ExportFile>, ExportError> {
    files(
        result,
        ExportFormat::OpenVins,
        "kalibr_imucam_chain.yaml",
        "kalibr_imu_chain.yaml",
        "%YAML:1.0\n",
    )
}

fn files(
    result: &CalibrationResult,
    format: ExportFormat,
    cam_file: &str,
    imu_file: &str,
    header: &str,
) -> Result<Vec<ExportFile>, ExportError> {
    let cams = sensors(result, SensorKind::Camera);
    if cams.is_empty() {
        return Err(missing(format, &SectionName::CAM0, "T_cam_imu"));
    }
    let mut text = header.to_string();
    for (i, name) in cams.iter().enumerate() {
        if *name != SectionName::cam(i as u16) {
            return Err(missing(format, &SectionName::cam(i as u16), "T_cam_imu"));
        }
        text += &camera(result, name, i, format)?;
    }
    let mut out = vec![super::ExportFile {
        name: cam_file.into(),
        text,
    }];
    let imus: Vec<_> = sensors(result, SensorKind::Imu);
    if imus.iter().any(|n| *n != SectionName::imu(0)) {
        out.push(ExportFile {
            name: imu_file.into(),
            text: imu_chain(result, format, header)?,
        });
    }
    Ok(out)
}

/// One `camN:` block.
fn camera(
    result: &CalibrationResult,
    name: &SectionName,
    index: usize,
    format: ExportFormat,
) -> Result<String, ExportError> {
    let ext = result
        .extrinsic(name)
        .ok_or_else(|| missing(format, name, "T_cam_imu"))?;
    let section = result.section(name).expect("listed section");
    let k = section
        .intrinsics
        .as_ref()
        .ok_or_else(|| missing(format, name, "intrinsics"))?;
    let mut s = format!("{name}:\n");
    if format == ExportFormat::OpenVins {
        s += "  T_imu_cam: # p_imu0 = T_imu_cam * p_cam\n";
        s += &block_rows(&ext.transform.inverse(), "  ");
    } else {
        s += "  T_cam_imu: # p_cam = T_cam_imu * p_imu0\n";
        s += &block_rows(&ext.transform, "  ");
    }
    if index >= 1 {
        let prev = SectionName::cam(index as u16 - 1);
        let chain = match &section.camera_chain {
            Some(c) => c.transform,
            None => ext.transform * result.extrinsic(&prev).expect("listed").transform.inverse(),
        };
        s += "  T_cn_cnm1: # p_cam = T_cn_cnm1 * p_previous_cam\n";
        s += &block_rows(&chain, "  ");
    }
    let overlaps: Vec<String> = Vec::new();
    s += &format!("  cam_overlaps: [{}]\n", overlaps.join(", "));
    s += &format!("  camera_model: {}\n", k.camera_model);
    s += &format!(
        "  distortion_coeffs: {}\n",
        flow(k.distortion_coeffs.clone())
    );
    s += &format!("  distortion_model: {}\n", k.distortion_model);
    s += &format!("  intrinsics: {}\n", flow(k.intrinsics.clone()));
    s += &format!("  resolution: [{}, {}]\n", k.resolution[0], k.resolution[1]);
    s += &format!("  rostopic: /{name}/image_raw\n");
    s += &format!("  timeshift_cam_imu: {}\n", float(ext.timeshift_s));
    Ok(s)
}

/// The imu chain: `imu0` (the body, identity) then every `imuN` with `T_i_b`.
fn imu_chain(
    result: &CalibrationResult,
    format: ExportFormat,
    header: &str,
) -> Result<String, ExportError> {
    let mut s = format!(
        "{header}imu0:\n  T_i_b: # p_imu = T_i_b * p_imu0 (imu0 is the body)\n{}  rostopic: /imu0\n  time_offset: 0.0\n",
        block_rows(&nalgebra::Isometry3::identity(), "  ")
    );
    for name in sensors(result, SensorKind::Imu) {
        if name == SectionName::imu(0) {
            continue;
        }
        let ext = result
            .extrinsic(&name)
            .ok_or_else(|| missing(format, &name, "T_imu0_imu"))?;
        s += &format!(
            "{name}:\n  T_i_b: # p_imu = T_i_b * p_imu0\n{}  rostopic: /{name}\n  time_offset: {}\n",
            block_rows(&ext.transform.inverse(), "  "),
            float(ext.timeshift_s)
        );
    }
    Ok(s)
}

//! VINS-Fusion: `vins_config.yaml` (`body_T_camN`: p_imu0 = body_T_cam * p_cam, row-major
//! `!!opencv-matrix`; `td`: image stamp + td = IMU time, Kalibr's `timeshift_cam_imu`)
//! and one camodocal file per camera (PINHOLE, KANNALA_BRANDT or MEI).

use super::text::{float, row_major};
use super::{missing, sensors, ExportError, ExportFile, ExportFormat};
use crate::dataset::{CalibrationResult, CameraIntrinsics, SectionName, SensorKind};

const F: ExportFormat = ExportFormat::VinsFusion;

pub(super) fn render(result: &CalibrationResult) -> Result<Vec<ExportFile>, ExportError> {
    let cams = sensors(result, SensorKind::Camera);
    if cams.is_empty() || cams.len() > 2 {
        return Err(ExportError::Unsupported {
            format: F,
            what: format!("{} cameras (it takes 1 or 2)", cams.len()),
        });
    }
    let mut config = format!("%YAML:1.0\n\nimu: 1\nnum_of_cam: {}\n", cams.len());
    let mut files = Vec::new();
    let mut td = None;
    for (i, name) in cams.iter().enumerate() {
        let ext = result
            .extrinsic(name)
            .ok_or_else(|| missing(F, name, "T_cam_imu"))?;
        let k = result
            .section(name)
            .and_then(|s| s.intrinsics.as_ref())
            .ok_or_else(|| missing(F, name, "intrinsics"))?;
        let (model, body) = camera_file(name, k)?;
        let file = format!("{name}_{}.yaml", model.to_lowercase());
        config += &format!("image{i}_topic: \"/{name}/image_raw\"\n");
        config += &format!("cam{i}_calib: \"{file}\"\n");
        config += &format!(
            "body_T_cam{i}: !!opencv-matrix # p_imu0 = body_T_cam * p_cam\n   rows: 4\n   cols: 4\n   dt: d\n   data: [{}]\n",
            row_major(&ext.transform.inverse()).into_iter().map(float).collect::<Vec<_>>().join(", ")
        );
        if i == 0 {
            config += &format!(
                "image_width: {}\nimage_height: {}\n",
                k.resolution[0], k.resolution[1]
            );
        }
        match td {
            None => td = Some(ext.timeshift_s),
            // One `td` for all cameras: time shifts must agree to the nanosecond.
            Some(t) if (t - ext.timeshift_s).abs() > 1e-9 => {
                return Err(ExportError::Unsupported {
                    format: F,
                    what: "different time shifts per camera (one td for all)".into(),
                })
            }
            Some(_) => {}
        }
        files.push(ExportFile {
            name: file,
            text: body,
        });
    }
    config += "imu_topic: \"/imu0\"\nestimate_extrinsic: 0\n";
    config += &format!(
        "estimate_td: 0\ntd: {} # image stamp + td = IMU time\n",
        float(td.unwrap_or(0.0))
    );
    files.insert(
        0,
        ExportFile {
            name: "vins_config.yaml".into(),
            text: config,
        },
    );
    Ok(files)
}

/// The camodocal model name and file of one camera.
fn camera_file(
    name: &SectionName,
    k: &CameraIntrinsics,
) -> Result<(&'static str, String), ExportError> {
    let p = &k.intrinsics;
    let d = &k.distortion_coeffs;
    let head = |model: &str| {
        format!(
            "%YAML:1.0\n---\nmodel_type: {model}\ncamera_name: {name}\nimage_width: {}\nimage_height: {}\n",
            k.resolution[0], k.resolution[1]
        )
    };
    let kv = |keys: &[&str], vals: &[f64]| -> String {
        keys.iter()
            .zip(vals)
            .map(|(k, v)| format!("   {k}: {}\n", float(*v)))
            .collect()
    };
    let shape = |n_p: usize, n_d: usize| p.len() == n_p && d.len() == n_d;
    let unsupported = || ExportError::Unsupported {
        format: F,
        what: format!(
            "{name}: camera_model {} with distortion_model {} ({} intrinsics, {} coefficients)",
            k.camera_model,
            k.distortion_model,
            p.len(),
            d.len()
        ),
    };
    match (k.camera_model.as_str(), k.distortion_model.as_str()) {
        ("pinhole", "radtan") if shape(4, 4) => Ok(("PINHOLE", pinhole(&head, &kv, p, d))),
        ("pinhole", "none") if shape(4, 0) => Ok(("PINHOLE", pinhole(&head, &kv, p, &[0.0; 4]))),
        ("pinhole", "equidistant") if shape(4, 4) => Ok((
            "KANNALA_BRANDT",
            format!(
                "{}projection_parameters:\n{}",
                head("KANNALA_BRANDT"),
                kv(
                    &["k2", "k3", "k4", "k5", "mu", "mv", "u0", "v0"],
                    &[d[0], d[1], d[2], d[3], p[0], p[1], p[2], p[3]]
                )
            ),
        )),
        ("omni", "radtan") if shape(5, 4) => Ok((
            "MEI",
            format!(
                "{}mirror_parameters:\n{}distortion_parameters:\n{}projection_parameters:\n{}",
                head("MEI"),
                kv(&["xi"], &p[..1]),
                kv(&["k1", "k2", "p1", "p2"], d),
                kv(&["gamma1", "gamma2", "u0", "v0"], &p[1..])
            ),
        )),
        _ => Err(unsupported()),
    }
}

fn pinhole(
    head: &dyn Fn(&str) -> String,
    kv: &dyn Fn(&[&str], &[f64]) -> String,
    p: &[f64],
    d: &[f64],
) -> String {
    format!(
        "{}distortion_parameters:\n{}projection_parameters:\n{}",
        head("PINHOLE"),
        kv(&["k1", "k2", "p1", "p2"], d),
        kv(&["fx", "fy", "cx", "cy"], p)
    )
}

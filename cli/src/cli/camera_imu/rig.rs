//! `msreg calibrate camera-imu` on a dataset with several cameras (`cam0..camN-1`): every
//! camera's corners (detected in its images or read from its `corners.csv`), all cameras in
//! one filter ([`calibrate_cameras`]), and the result file with every `camN.T_cam_imu`,
//! `timeshift_cam_imu` and, for `N >= 1`, `camN.T_cn_cnm1`. The report lists every camera;
//! the convergence plot and the overlay are camera 0's.

use anyhow::anyhow;
use serde::Serialize;

use super::{write_overlay, write_plot, CalibrateCameraImu, CameraImuReport, LoadedFrames};
use crate::cli::outcome::{progress_bar, Outcome};
use msreg_host::calibrate::camera_imu::{
    calibrate_cameras, CameraFrames, CameraImuOptions, DetectionSummary, MultiCameraImuCalibration,
    MultiCameraImuInput,
};
use msreg_host::calibrate::driver::report::SectionFrame;
use msreg_host::dataset::{Dataset, SectionName};

/// One camera in the JSON report.
#[derive(Debug, Clone, Serialize)]
pub struct RigCameraReport {
    /// `camN`.
    pub name: String,
    /// Its corner detection.
    pub detection: DetectionSummary,
    /// Its calibration (the single-camera report's fields).
    #[serde(flatten)]
    pub calibration: CameraImuReport,
}

/// One link of the camera chain in the JSON report.
#[derive(Debug, Clone, Serialize)]
pub struct ChainReport {
    /// `camN.T_cn_cnm1`.
    pub name: String,
    /// `T_cn_cnm1`, row by row.
    pub t_cn_cnm1: [[f64; 4]; 4],
    /// 1-sigma of its rotation per axis, deg.
    pub sigma_rot_deg: [f64; 3],
    /// 1-sigma of its translation per axis, m.
    pub sigma_trans_m: [f64; 3],
}

/// The JSON report of a multi-camera run.
#[derive(Debug, Clone, Serialize)]
pub struct RigCliReport {
    /// Every camera, `cam0` first.
    pub cameras: Vec<RigCameraReport>,
    /// `cam1.T_cn_cnm1`, `cam2.T_cn_cnm1`, ...
    pub chain: Vec<ChainReport>,
}

/// Runs the command on the `count` cameras of `dataset`.
pub fn run(
    args: &CalibrateCameraImu,
    dataset: &Dataset,
    count: usize,
    options: &CameraImuOptions,
) -> anyhow::Result<Outcome> {
    let loaded = (0..count)
        .map(|n| super::load_camera_frames(&args.dataset, n as u16, args.opencv_window))
        .collect::<anyhow::Result<Vec<LoadedFrames>>>()?;
    let cameras: Vec<CameraFrames<'_>> = loaded
        .iter()
        .map(|l| CameraFrames {
            camera: &l.camera,
            frames: &l.frames,
        })
        .collect();
    let input = MultiCameraImuInput {
        imu: dataset.require_imu()?,
        imu_noise: dataset.require_imu_noise()?,
        cameras: &cameras,
    };
    let filtering = progress_bar(1000, "{spinner} filtering [{bar:40}] {percent}% {elapsed}");
    let mut progress = |f: f64| filtering.set_position((f * 1000.0) as u64);
    let outcome = if args.f32 {
        calibrate_cameras::<f32>(&input, options, &mut progress)
    } else {
        calibrate_cameras::<f64>(&input, options, &mut progress)
    };
    filtering.finish_and_clear();
    let calibration = outcome.map_err(|e| anyhow!("{}: {e}", args.dataset.display()))?;
    let mut result = calibration.result();
    for (n, c) in calibration.cameras.iter().enumerate() {
        let frame = SectionFrame::SensorImu(c.t_imu_sensor.rotation.to_rotation_matrix());
        result
            .section_mut(SectionName::cam(n as u16))
            .hold_all(c.report.filter.held_dofs(frame));
    }
    crate::cli::outcome::write_outputs(
        &result,
        &args.output,
        args.report.as_deref(),
        &report(&calibration, &loaded),
    )?;
    for (n, c) in calibration.cameras.iter().enumerate() {
        let r = &c.report;
        eprintln!(
            "msreg: cam{n}: {:?}: {} images fused, mean NIS/dof {:.2}; mean reprojection error \
             with the result held: {:.3} px",
            r.update,
            r.filter.updates_accepted,
            r.filter.mean_nis_per_dof,
            r.verification_reprojection_error_px
        );
    }
    eprintln!(
        "msreg: wrote {} ({count} cameras in one filter)",
        args.output.display()
    );
    write_extras(args, dataset, &calibration, loaded)
}

/// The report, camera 0's plot and overlay, and the verdict over every camera.
fn write_extras(
    args: &CalibrateCameraImu,
    dataset: &Dataset,
    calibration: &MultiCameraImuCalibration,
    loaded: Vec<LoadedFrames>,
) -> anyhow::Result<Outcome> {
    let cam0 = &calibration.cameras[0];
    if let Some(path) = &args.plot {
        write_plot(path, dataset, cam0, &args.dataset);
    }
    if let (Some(path), Some(sample), Some(data)) =
        (&args.overlay, &cam0.report.sample, &loaded[0].camera_data)
    {
        let magnification = write_overlay(path, data, sample)?;
        eprintln!(
            "msreg: wrote {} (cam0; error vectors magnified {magnification}x)",
            path.display()
        );
    }
    let reasons: Vec<String> = calibration
        .cameras
        .iter()
        .enumerate()
        .flat_map(|(n, c)| {
            c.report
                .filter
                .reasons
                .iter()
                .map(move |r| format!("cam{n}: {r}"))
        })
        .collect();
    Ok(Outcome::of(calibration.converged(), &reasons))
}

/// The JSON report: every camera's detection and calibration, and the chain.
fn report(calibration: &MultiCameraImuCalibration, loaded: &[LoadedFrames]) -> RigCliReport {
    let cameras = calibration
        .cameras
        .iter()
        .zip(loaded)
        .enumerate()
        .map(|(n, (c, l))| RigCameraReport {
            name: format!("cam{n}"),
            detection: l.detection.clone(),
            calibration: c.report.clone(),
        })
        .collect();
    let chain = calibration
        .chain
        .iter()
        .enumerate()
        .map(|(k, link)| {
            let m = link.t_cn_cnm1.to_homogeneous();
            // The result file's covariance (the larger of the filter's and the data's sigma).
            let covariance = calibration
                .chain_model_error
                .get(k)
                .map_or(link.covariance, |e| e.written);
            let sd = |i: usize| covariance[(i, i)].max(0.0).sqrt();
            ChainReport {
                name: format!("cam{}.T_cn_cnm1", k + 1),
                t_cn_cnm1: std::array::from_fn(|r| std::array::from_fn(|c| m[(r, c)])),
                sigma_rot_deg: std::array::from_fn(|i| sd(i).to_degrees()),
                sigma_trans_m: std::array::from_fn(|i| sd(i + 3)),
            }
        })
        .collect();
    RigCliReport { cameras, chain }
}

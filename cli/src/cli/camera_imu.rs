//! `msreg calibrate camera-imu <dataset>`: detects the checkerboard or Kalibr AprilGrid in
//! every image of `cam0/` (or reads `cam0/corners.csv`), runs RepErrCal (or MoCal) on the
//! corners and the IMU, and writes the result YAML (`cam0`: Kalibr's `T_cam_imu`,
//! `timeshift_cam_imu`), the JSON report, the convergence plot and the reprojection overlay
//! of one image (the dissertation's Fig. 4.4).

mod rig;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{anyhow, Context};
use clap::Args;
use msreg_estimator::CornerObservation;
use serde::Serialize;

use super::outcome::{progress_bar, Outcome};
use msreg_estimator::camera::Camera;
use msreg_host::calibrate::camera_imu::{
    calibrate, CameraImuCalibration, CameraImuInput, CameraImuOptions, CameraImuReport,
    CameraUpdate, CornerFrame, ReprojectionSample,
};
use msreg_host::calibrate::camera_imu::{detect_corner_frames, DetectionSummary};
use msreg_host::calibrate::driver::report::SectionFrame;
use msreg_host::calibrate::InputError;
use msreg_host::camera_yaml::{read_camera_yaml, read_target_yaml, Target};
use msreg_host::dataset::{
    read_camera_csv, read_observed_corners, CalibrationResult, Dataset, ObservedCorner,
    ObservedImage, SectionName, SensorKind, CAMERA_YAML, OBSERVED_CORNERS_CSV, TARGET_YAML,
};
use msreg_host::vision::frames::{CameraDataset, CameraInputError};
use msreg_host::vision::{DetectorParams, GrayImage};

/// `msreg calibrate camera-imu`.
#[derive(Args, Debug)]
pub struct CalibrateCameraImu {
    /// Dataset directory (imu0/, cam0/ with camera.yaml, target.yaml).
    pub dataset: PathBuf,
    /// Measurement model: corner reprojection (RepErrCal) or PnP relative poses (MoCal).
    #[arg(long, value_enum, default_value_t = UpdateArg::Reprojection)]
    pub update: UpdateArg,
    /// Result YAML.
    #[arg(short, long, default_value = "result.yaml")]
    pub output: PathBuf,
    /// JSON report (detections, reprojection error per image, convergence, NIS, events).
    #[arg(long)]
    pub report: Option<PathBuf>,
    /// PNG plot of the extrinsic convergence (6 DoF and time offset, +-1 sigma bands).
    #[arg(long)]
    pub plot: Option<PathBuf>,
    /// PNG of one image with its detected (green) and reprojected (red) corners and the
    /// error vectors magnified (yellow); RepErrCal only.
    #[arg(long)]
    pub overlay: Option<PathBuf>,
    /// Corner noise, 1-sigma per axis, pixels (default: estimated from the PnP residuals).
    #[arg(long)]
    pub pixel_sigma: Option<f64>,
    /// Keep the time offset fixed at zero.
    #[arg(long)]
    pub no_time_offset: bool,
    /// Run the filter in f32, as the firmware does.
    #[arg(long)]
    pub f32: bool,
    /// Refine corners with OpenCV's fixed 23 x 23 window instead of a window capped at half
    /// the corner spacing (docs/checkerboard.md).
    #[arg(long)]
    pub opencv_window: bool,
}

/// `--update`: the library's [`CameraUpdate`] as a command-line value.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum UpdateArg {
    /// Corner reprojection (RepErrCal).
    Reprojection,
    /// Relative poses of PnP (MoCal).
    Motion,
}

impl From<UpdateArg> for CameraUpdate {
    fn from(u: UpdateArg) -> Self {
        match u {
            UpdateArg::Reprojection => CameraUpdate::Reprojection,
            UpdateArg::Motion => CameraUpdate::Motion,
        }
    }
}

/// The JSON report of the command.
#[derive(Debug, Clone, Serialize)]
pub struct CameraImuCliReport {
    /// Corner detection.
    pub detection: DetectionSummary,
    /// The calibration.
    #[serde(flatten)]
    pub calibration: CameraImuReport,
}

/// Fewest images with the full board for a calibration (PnP odometry needs increments).
const MIN_IMAGES: usize = 3;

/// Length the mean error vector is drawn with in the overlay, pixels: sub-pixel errors
/// become visible.
const OVERLAY_MEAN_ERROR_PX: f64 = 12.0;

/// Runs the command.
pub fn run(args: &CalibrateCameraImu) -> anyhow::Result<Outcome> {
    let dataset = Dataset::open(&args.dataset)?;
    if let Some(sigma) = args.pixel_sigma {
        if !(sigma.is_finite() && sigma > 0.0) {
            return Err(anyhow!("--pixel-sigma must be positive, got {sigma}"));
        }
    }
    let mut options = CameraImuOptions {
        update: args.update.into(),
        pixel_sigma: args.pixel_sigma,
        ..CameraImuOptions::default()
    };
    options.prior.estimate_time_offset = !args.no_time_offset;
    let cameras = camera_count(&dataset, &args.dataset)?;
    if cameras > 1 {
        return rig::run(args, &dataset, cameras, &options);
    }
    let LoadedFrames {
        camera,
        frames,
        detection,
        camera_data,
    } = load_corner_frames(&args.dataset, args.opencv_window)?;
    let input = CameraImuInput {
        imu: dataset.require_imu()?,
        imu_noise: dataset.require_imu_noise()?,
        camera: &camera,
        frames: &frames,
    };
    let filtering = progress_bar(1000, "{spinner} filtering [{bar:40}] {percent}% {elapsed}");
    let mut progress = |f: f64| filtering.set_position((f * 1000.0) as u64);
    let outcome = if args.f32 {
        calibrate::<f32>(&input, &options, &mut progress)
    } else {
        calibrate::<f64>(&input, &options, &mut progress)
    };
    filtering.finish_and_clear();
    let calibration =
        outcome.map_err(|e: InputError| anyhow!("{}: {e}", args.dataset.display()))?;
    let mut result =
        CalibrationResult::new().with_extrinsic(SectionName::CAM0, calibration.cam_imu_estimate());
    let frame = SectionFrame::SensorImu(calibration.t_imu_sensor.rotation.to_rotation_matrix());
    result
        .section_mut(SectionName::CAM0)
        .hold_all(calibration.report.filter.held_dofs(frame));
    let report = CameraImuCliReport {
        detection,
        calibration: calibration.report.clone(),
    };
    super::outcome::write_outputs(&result, &args.output, args.report.as_deref(), &report)?;
    let r = &calibration.report;
    eprintln!(
        "msreg: wrote {} ({:?}: {} images fused, mean NIS/dof {:.2}; mean reprojection error \
         with the result held: {:.3} px)",
        args.output.display(),
        r.update,
        r.filter.updates_accepted,
        r.filter.mean_nis_per_dof,
        r.verification_reprojection_error_px
    );
    if let Some(path) = &args.plot {
        write_plot(path, &dataset, &calibration, &args.dataset);
    }
    if let Some(path) = &args.overlay {
        match (&calibration.report.sample, &camera_data) {
            (_, None) => eprintln!(
                "msreg: warning: no overlay: the corners come from {OBSERVED_CORNERS_CSV}, \
                 without images"
            ),
            (Some(sample), Some(camera_data)) => {
                let magnification = write_overlay(path, camera_data, sample)?;
                eprintln!(
                    "msreg: wrote {} (error vectors magnified {magnification}x)",
                    path.display()
                );
            }
            (None, _) => eprintln!("msreg: warning: no reprojection sample (MoCal has none)"),
        }
    }
    let filter = &calibration.report.filter;
    Ok(Outcome::of(filter.converged, &filter.reasons))
}

/// The camera and its corner frames, with how they were found.
pub struct LoadedFrames {
    /// The camera model of `cam0/camera.yaml`.
    pub camera: Camera<f64>,
    /// The corners of each image with the board.
    pub frames: Vec<CornerFrame>,
    /// What the detector found.
    pub detection: DetectionSummary,
    /// The image dataset when the corners were detected here (for the overlay).
    pub camera_data: Option<CameraDataset>,
}

/// The camera, its corner frames and how they were found: `cam0/corners.csv` when the
/// dataset has it (pre-detected corners, any target), else detection in the images of
/// `cam0/data.csv` (then the images are returned too, for the overlay); `opencv_window`
/// refines corners with OpenCV's fixed window.
pub fn load_corner_frames(dataset: &Path, opencv_window: bool) -> anyhow::Result<LoadedFrames> {
    load_camera_frames(dataset, 0, opencv_window)
}

/// [`load_corner_frames`] of camera `cam` (`camN/corners.csv`, else the images of
/// `camN/data.csv` with `camN/camera.yaml`).
pub fn load_camera_frames(
    dataset: &Path,
    cam: u16,
    opencv_window: bool,
) -> anyhow::Result<LoadedFrames> {
    let folder = format!("cam{cam}");
    let observed = if cam == 0 {
        dataset.join(OBSERVED_CORNERS_CSV)
    } else {
        dataset.join(&folder).join("corners.csv")
    };
    if !observed.is_file() {
        let camera_data = camera_dataset(dataset, cam)?;
        let (frames, detection) = detect_for_calibration(dataset, opencv_window, &camera_data)?;
        return Ok(LoadedFrames {
            camera: camera_data.camera,
            frames,
            detection,
            camera_data: Some(camera_data),
        });
    }
    let camera = if cam == 0 {
        read_camera_yaml(&dataset.join(CAMERA_YAML))?
    } else {
        read_camera_yaml(&dataset.join(&folder).join("camera.yaml"))?
    };
    let images = read_observed_corners(&observed)?;
    let target_path = dataset.join(TARGET_YAML);
    let target = target_path
        .is_file()
        .then(|| read_target_yaml(&target_path))
        .transpose()?;
    let started = Instant::now();
    let mut frames = Vec::with_capacity(images.len());
    let mut rejected = BTreeMap::new();
    for image in &images {
        match corner_frame(image, target.as_ref()) {
            Ok(frame) => frames.push(frame),
            Err(why) => *rejected.entry(why.to_string()).or_insert(0) += 1,
        }
    }
    if frames.len() < MIN_IMAGES {
        return Err(anyhow!(
            "{}: {} images with usable corners, at least {MIN_IMAGES} are needed (rejected: \
             {rejected:?})",
            observed.display(),
            frames.len()
        ));
    }
    let detection = DetectionSummary {
        images: images.len(),
        detected: frames.len(),
        rejected,
        time_s: started.elapsed().as_secs_f64(),
    };
    Ok(LoadedFrames {
        camera,
        frames,
        detection,
        camera_data: None,
    })
}

/// The image inputs of camera `cam`: [`CameraDataset::open`] for `cam0`, the same files in
/// `camN/` (and the shared `target.yaml`) for the others.
fn camera_dataset(dataset: &Path, cam: u16) -> anyhow::Result<CameraDataset> {
    if cam == 0 {
        return Ok(CameraDataset::open(dataset)?);
    }
    let folder = dataset.join(format!("cam{cam}"));
    let camera = read_camera_yaml(&folder.join("camera.yaml"))?;
    let target_path = dataset.join(TARGET_YAML);
    let target = read_target_yaml(&target_path)?;
    if let Target::Board { .. } = target {
        return Err(CameraInputError::NotCornerTarget { path: target_path }.into());
    }
    let frames = read_camera_csv(folder.join("data.csv"))?;
    Ok(CameraDataset {
        camera,
        target,
        frames,
    })
}

/// How many cameras the dataset has: its `camN` folders, which must be `cam0..camN-1`.
pub fn camera_count(dataset: &Dataset, dir: &Path) -> anyhow::Result<usize> {
    let cameras = dataset.sensors_of(SensorKind::Camera)?;
    for (n, c) in cameras.iter().enumerate() {
        if usize::from(c.index) != n {
            return Err(anyhow!(
                "{}: camera folders must be cam0..cam{} without a gap; cam{n} is missing \
                 (found {})",
                dir.display(),
                cameras.len() - 1,
                cameras
                    .iter()
                    .map(ToString::to_string)
                    .collect::<Vec<_>>()
                    .join(", ")
            ));
        }
    }
    Ok(cameras.len().max(1))
}

/// One image of `cam0/corners.csv` as filter input: each corner's target point from the
/// file, else from the target by its id.
fn corner_frame(
    image: &ObservedImage,
    target: Option<&Target>,
) -> Result<CornerFrame, &'static str> {
    let point = |c: &ObservedCorner| match (c.point, target) {
        (Some(p), _) => Ok(p),
        (None, Some(Target::Checkerboard(t))) => Ok(t.corner_in_target(c.corner_id)),
        (None, Some(Target::AprilGrid(t))) => {
            t.corner(c.corner_id).ok_or("corner id outside the target")
        }
        (None, _) => {
            Err("no x, y, z and no checkerboard or aprilgrid target.yaml to place the corner")
        }
    };
    let corners = image
        .corners
        .iter()
        .map(|c| {
            Ok(CornerObservation {
                point_in_target: point(c)?,
                pixel: c.pixel,
            })
        })
        .collect::<Result<Vec<_>, &'static str>>()?;
    Ok(CornerFrame {
        stamp_ns: image.stamp_ns,
        corners,
    })
}

/// [`detect_corner_frames`] with a progress bar; fewer than [`MIN_IMAGES`] boards found is
/// bad input, with the rejection reasons.
fn detect_for_calibration(
    dataset: &Path,
    opencv_window: bool,
    camera_data: &CameraDataset,
) -> anyhow::Result<(Vec<CornerFrame>, DetectionSummary)> {
    let detecting = progress_bar(
        1000,
        "{spinner} detecting corners [{bar:40}] {percent}% {elapsed}",
    );
    let params = if opencv_window {
        DetectorParams::opencv_compatible()
    } else {
        DetectorParams::default()
    };
    let (frames, detection) = detect_corner_frames(camera_data, &params, &|f| {
        detecting.set_position((f * 1000.0) as u64)
    })?;
    detecting.finish_and_clear();
    eprintln!(
        "msreg: {} found in {} of {} images ({:.1} s)",
        describe(&camera_data.target),
        detection.detected,
        detection.images,
        detection.time_s
    );
    if frames.len() < MIN_IMAGES {
        let reasons: Vec<String> = detection
            .rejected
            .iter()
            .map(|(why, n)| format!("{n} x {why}"))
            .collect();
        return Err(anyhow!(
            "{}: the {} of target.yaml is found in {} of {} images, at least {MIN_IMAGES} are \
             needed (rejected: {})",
            dataset.display(),
            describe(&camera_data.target),
            frames.len(),
            detection.images,
            reasons.join(", ")
        ));
    }
    Ok((frames, detection))
}

/// The target in a message: "6x7 checkerboard", "6x6 aprilgrid".
fn describe(target: &Target) -> String {
    match target {
        Target::Checkerboard(t) => format!("{}x{} checkerboard", t.rows, t.cols),
        Target::AprilGrid(t) => format!("{}x{} aprilgrid", t.tag_cols, t.tag_rows),
        Target::Board { .. } => "plain board".to_string(),
    }
}

/// The convergence plot of `T_imu_cam` (the filter's state), with the truth when the
/// dataset has it. A plotting failure (no font) is a warning: the calibration succeeded.
pub(crate) fn write_plot(
    path: &Path,
    dataset: &Dataset,
    calibration: &CameraImuCalibration,
    dir: &Path,
) {
    let truth = dataset
        .groundtruth_extrinsics
        .as_ref()
        .and_then(|g| g.extrinsic(&SectionName::CAM0))
        .map(|cam0| {
            let t_imu_cam = cam0.transform.inverse();
            (
                t_imu_cam.rotation.scaled_axis().into(),
                t_imu_cam.translation.vector.into(),
                cam0.timeshift_s,
            )
        });
    let series = msreg_host::calibrate::convergence::extrinsic_series(
        &calibration.report.filter.history,
        truth,
    );
    let name = std::fs::canonicalize(dir).unwrap_or_else(|_| dir.to_path_buf());
    let title = format!("T_imu_cam convergence: {}", name.display());
    match msreg_host::plot::write_convergence_png(path, &title, &series, (1500, 1100)) {
        Ok(()) => eprintln!("msreg: wrote {}", path.display()),
        Err(e) => eprintln!("msreg: warning: {e}"),
    }
}

/// The sample image in colour: detected corners as green crosses, reprojected ones as red
/// dots, and the reprojection error vectors in yellow, magnified so the mean one is about
/// [`OVERLAY_MEAN_ERROR_PX`] long (Fig. 4.4). Returns the magnification.
pub(crate) fn write_overlay(
    path: &Path,
    data: &CameraDataset,
    sample: &ReprojectionSample,
) -> anyhow::Result<f64> {
    let Some(frame) = data.frames.iter().find(|f| f.stamp_ns == sample.stamp_ns) else {
        return Err(anyhow!(
            "cam0/data.csv: no image stamped {}",
            sample.stamp_ns
        ));
    };
    let grey = GrayImage::load(&frame.path)?.to_luma8();
    let mut rgb = image::RgbImage::from_fn(grey.width(), grey.height(), |x, y| {
        let v = grey.get_pixel(x, y).0[0] / 2 + 64;
        image::Rgb([v, v, v])
    });
    let mut put = |x: f64, y: f64, colour: [u8; 3]| {
        let (x, y) = (x.round(), y.round());
        if x >= 0.0 && y >= 0.0 && (x as u32) < rgb.width() && (y as u32) < rgb.height() {
            rgb.put_pixel(x as u32, y as u32, image::Rgb(colour));
        }
    };
    let pairs = || sample.detected.iter().zip(&sample.reprojected);
    let mean_error =
        pairs().map(|(d, r)| (r - d).norm()).sum::<f64>() / pairs().len().max(1) as f64;
    let magnification = round_to_1_2_5((OVERLAY_MEAN_ERROR_PX / mean_error).clamp(1.0, 1000.0));
    for (detected, reprojected) in pairs() {
        let error = (reprojected - detected) * magnification;
        let steps = error.norm().ceil().max(1.0) as usize;
        for k in 0..=steps {
            let p = detected + error * (k as f64 / steps as f64);
            put(p.x, p.y, [255, 220, 0]);
        }
        for d in -4..=4 {
            let d = f64::from(d);
            put(detected.x + d, detected.y, [0, 230, 0]);
            put(detected.x, detected.y + d, [0, 230, 0]);
        }
        for dy in -1..=1 {
            for dx in -1..=1 {
                put(
                    reprojected.x + f64::from(dx),
                    reprojected.y + f64::from(dy),
                    [255, 40, 40],
                );
            }
        }
    }
    rgb.save(path)
        .with_context(|| format!("{}: cannot write overlay", path.display()))?;
    Ok(magnification)
}

/// The largest of 1, 2, 5, 10, 20, ... not above `x` (at least 1).
fn round_to_1_2_5(x: f64) -> f64 {
    let decade = 10f64.powf(x.max(1.0).log10().floor());
    [5.0, 2.0, 1.0]
        .into_iter()
        .map(|m| m * decade)
        .find(|&v| v <= x)
        .unwrap_or(decade)
}

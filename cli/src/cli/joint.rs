//! `msreg calibrate joint <dataset>`: the joint LiDAR-IMU-camera calibration of a dataset
//! with `imu0/`, `lidar0/`, `cam0/` (images or `corners.csv`) and a checkerboard
//! `target.yaml` that gives the physical board's `width_m` / `height_m`. Writes `cam0`,
//! `lidar0` and the derived `cam0_lidar0` (with sigmas from the joint covariance), and with
//! `--compare-pairwise` the loop-consistency comparison with the two pairwise pipelines.

use std::path::{Path, PathBuf};

use anyhow::{anyhow, Context};
use clap::Args;
use serde::Serialize;

use nalgebra::{Isometry3, Point3};

use super::camera_imu::{load_corner_frames, LoadedFrames};
use super::outcome::{progress_bar, Outcome};
use msreg_host::calibrate::camera_imu::invert_with_covariance;
use msreg_host::calibrate::camera_imu::DetectionSummary;
use msreg_host::calibrate::driver::report::{PoseImuReport, SectionFrame};
use msreg_host::calibrate::joint::{
    calibrate, chained_pairwise, JointCalibration, JointInput, JointOptions, LoopConsistency,
    OverlaySample, PlaneStats,
};
use msreg_host::calibrate::InputError;
use msreg_host::camera_yaml::{read_target_yaml, Target};
use msreg_host::dataset::{
    CalibrationResult, Dataset, ExtrinsicEstimate, SectionName, TARGET_YAML,
};
use msreg_host::lidar::FileScans;
use msreg_host::vision::frames::CameraDataset;
use msreg_host::vision::overlay::Canvas;
use msreg_host::vision::GrayImage;

/// `msreg calibrate joint`.
#[derive(Args, Debug)]
pub struct CalibrateJoint {
    /// Dataset directory (imu0/, lidar0/, cam0/ with camera.yaml, target.yaml with the
    /// board's width_m and height_m).
    pub dataset: PathBuf,
    /// Result YAML (cam0, lidar0, cam0_lidar0).
    #[arg(short, long, default_value = "result.yaml")]
    pub output: PathBuf,
    /// JSON report (detection, board planes, both sensors' filter reports, loop
    /// consistency).
    #[arg(long)]
    pub report: Option<PathBuf>,
    /// Also run the camera-IMU and LiDAR-IMU pipelines on their own and compare
    /// `T_cam_lidar` chained from them with the joint one (about doubles the run time).
    #[arg(long)]
    pub compare_pairwise: bool,
    /// Run the filter in f32, as the firmware does.
    #[arg(long)]
    pub f32: bool,
    /// PNG of one image halfway through with the board returns of the nearest scan
    /// projected by the joint `T_cam_lidar` (green) and, with `--compare-pairwise`, by the
    /// chained pairwise one (red). Needs the images (not `corners.csv`).
    #[arg(long)]
    pub overlay: Option<PathBuf>,
}

/// The JSON report of the command.
#[derive(Debug, Clone, Serialize)]
pub struct JointCliReport {
    /// Corner detection.
    pub detection: DetectionSummary,
    /// The board planes fused.
    pub planes: PlaneStats,
    /// The camera's filter report (sensor 1 of the joint filter).
    pub camera: PoseImuReport,
    /// The LiDAR's filter report (sensor 0).
    pub lidar: PoseImuReport,
    /// Joint against chained pairwise `T_cam_lidar` (`--compare-pairwise`).
    pub loop_consistency: Option<LoopConsistency>,
}

/// Runs the command.
pub fn run(args: &CalibrateJoint) -> anyhow::Result<Outcome> {
    let dataset = Dataset::open(&args.dataset)?;
    let target_path = args.dataset.join(TARGET_YAML);
    let Target::Checkerboard(target) = read_target_yaml(&target_path)? else {
        return Err(anyhow!(
            "{}: the joint calibration needs a checkerboard target",
            target_path.display()
        ));
    };
    let LoadedFrames {
        camera,
        frames,
        detection,
        camera_data,
    } = load_corner_frames(&args.dataset, false)?;
    let scans = FileScans {
        files: dataset.lidar0_scans()?,
    };
    let input = JointInput {
        imu: dataset.require_imu()?,
        imu_noise: dataset.require_imu_noise()?,
        scans: &scans,
        camera: &camera,
        frames: &frames,
        target: &target,
    };
    let options = JointOptions::default();
    let bad_input = |e: InputError| anyhow!("{}: {e}", args.dataset.display());
    let bar = progress_bar(
        1000,
        "{spinner} joint filter [{bar:40}] {percent}% {elapsed}",
    );
    let mut progress = |f: f64| bar.set_position((f * 1000.0) as u64);
    let outcome = if args.f32 {
        calibrate::<f32>(&input, &options, &mut progress)
    } else {
        calibrate::<f64>(&input, &options, &mut progress)
    };
    bar.finish_and_clear();
    let joint = outcome.map_err(bad_input)?;
    let result = result(&joint);
    let result_yaml = result.to_yaml_string();
    super::outcome::write_outputs(&result, &args.output, None, &())?;
    print_summary(args, &joint);
    let (loop_consistency, chained) = if args.compare_pairwise {
        let bar = progress_bar(
            1000,
            "{spinner} pairwise runs [{bar:40}] {percent}% {elapsed}",
        );
        let runs = chained_pairwise(&input, &options, &mut |f| {
            bar.set_position((f * 1000.0) as u64)
        });
        bar.finish_and_clear();
        let runs = runs.map_err(bad_input)?;
        let consistency = LoopConsistency::of(&joint, &runs);
        print_consistency(&consistency);
        (Some(consistency), Some(runs.t_cam_lidar().0))
    } else {
        (None, None)
    };
    if let Some(path) = &args.overlay {
        match (&camera_data, &joint.overlay) {
            (Some(images), Some(sample)) => {
                write_overlay(path, images, sample, &joint.t_cam_lidar, chained.as_ref())?;
                eprintln!("msreg: wrote {}", path.display());
            }
            (None, _) => eprintln!("msreg: warning: no overlay: the corners come without images"),
            (_, None) => eprintln!("msreg: warning: no overlay: no board plane after halfway"),
        }
    }
    if let Some(path) = &args.report {
        let report = JointCliReport {
            detection,
            planes: joint.planes.clone(),
            camera: joint.camera.report.clone(),
            lidar: joint.lidar.report.clone(),
            loop_consistency,
        };
        msreg_host::report::write_report_for_result(
            path,
            &report,
            (&args.output, &result_yaml),
            &[],
            &[],
        )?;
    }
    let mut reasons = Vec::new();
    for (name, report) in [
        ("cam0", &joint.camera.report),
        ("lidar0", &joint.lidar.report),
    ] {
        reasons.extend(report.reasons.iter().map(|r| format!("{name}: {r}")));
    }
    Ok(Outcome::of(joint.converged(), &reasons))
}

/// The result file: `cam0` (`T_cam_imu`), `lidar0` (`T_imu_lidar`), `cam0_lidar0`.
pub fn result(joint: &JointCalibration) -> CalibrationResult {
    let camera = &joint.camera;
    let (t_cam_imu, cam_covariance) =
        invert_with_covariance(&camera.t_imu_sensor, &camera.covariance);
    let cam0 = ExtrinsicEstimate::from_covariance(t_cam_imu, camera.time_offset_s, &cam_covariance);
    let cam0_lidar0 =
        ExtrinsicEstimate::from_covariance(joint.t_cam_lidar, 0.0, &joint.cam_lidar_covariance);
    let mut result = CalibrationResult::new()
        .with_extrinsic(SectionName::CAM0, cam0)
        .with_extrinsic(SectionName::LIDAR0, joint.lidar.imu_sensor_estimate())
        .with_extrinsic(SectionName::CAM0_LIDAR0, cam0_lidar0);
    let frame = SectionFrame::SensorImu(camera.t_imu_sensor.rotation.to_rotation_matrix());
    result
        .section_mut(SectionName::CAM0)
        .hold_all(camera.report.held_dofs(frame));
    result
        .section_mut(SectionName::LIDAR0)
        .hold_all(joint.lidar.report.held_dofs(SectionFrame::ImuSensor));
    result
}

fn print_summary(args: &CalibrateJoint, joint: &JointCalibration) {
    let p = &joint.planes;
    eprintln!(
        "msreg: wrote {} ({} board planes fused, {} gated; camera time offset {:+.3} ms, LiDAR \
         {:+.3} ms; {:.1} s)",
        args.output.display(),
        p.fused,
        p.rejected,
        joint.camera.time_offset_s * 1e3,
        joint.lidar.time_offset_s * 1e3,
        joint.timing_s.init + joint.timing_s.filter
    );
}

fn print_consistency(c: &LoopConsistency) {
    let hausman = c
        .hausman
        .map_or("n/a".to_string(), |h| format!("{h:.1} (chi-square, 6 dof)"));
    eprintln!(
        "msreg: T_cam_lidar joint vs chained pairwise: {:.4} deg, {:.2} mm apart; Hausman \
         statistic {hausman}; largest sigma joint {:.4} deg / {:.2} mm, chained {:.4} deg / \
         {:.2} mm{}",
        c.difference_deg,
        c.difference_mm,
        max3(&c.joint.sigma_rotation_deg),
        max3(&c.joint.sigma_translation_m) * 1e3,
        max3(&c.chained.sigma_rotation_deg),
        max3(&c.chained.sigma_translation_m) * 1e3,
        if c.pairwise_converged {
            ""
        } else {
            " (a pairwise run did not pass its checks)"
        }
    );
}

/// The image of `sample` with its board returns projected by the joint `T_cam_lidar`
/// (green) and the chained one (red).
fn write_overlay(
    path: &Path,
    images: &CameraDataset,
    sample: &OverlaySample,
    joint: &Isometry3<f64>,
    chained: Option<&Isometry3<f64>>,
) -> anyhow::Result<()> {
    let frame = images
        .frames
        .iter()
        .find(|f| f.stamp_ns == sample.image_stamp_ns)
        .ok_or_else(|| {
            anyhow!(
                "no image stamped {} in cam0/data.csv",
                sample.image_stamp_ns
            )
        })?;
    let image = GrayImage::load(&frame.path)
        .with_context(|| format!("{}: cannot read image", frame.path.display()))?;
    let mut canvas = Canvas::from_gray(&image);
    let camera = &images.camera;
    for (t_cam_lidar, colour) in chained
        .map(|c| (c, [255, 0, 0]))
        .into_iter()
        .chain([(joint, [0, 220, 0])])
    {
        for p in &sample.returns_in_lidar {
            if let Some(px) = camera.project(&(t_cam_lidar * Point3::from(*p)).coords) {
                canvas.dot(&px.pixel, colour, 1);
            }
        }
    }
    canvas
        .save(path)
        .with_context(|| format!("{}: cannot write overlay", path.display()))
}

fn max3(x: &[f64; 3]) -> f64 {
    x.iter().copied().fold(0.0, f64::max)
}

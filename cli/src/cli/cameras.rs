//! `msreg calibrate cameras <dataset>`: intrinsics of every camera of the dataset
//! (`cam0/`, `cam1/`, ...) and the camera chain `T_cn_cnm1`, from checkerboard or AprilGrid
//! images (issue 33). Writes the Kalibr camchain keys per camera (`-o`), a Kalibr
//! `camera.yaml` per camera beside it (`<stem>.camN.yaml`, readable by every pipeline) and
//! the JSON report (`--report`).

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{anyhow, Context};
use clap::Args;
use msreg_estimator::camera::model::ModelKind;
use serde::Serialize;

use super::outcome::{progress_bar, Outcome};
use msreg_host::calibrate::cameras::dataset::CamerasDataset;
use msreg_host::calibrate::cameras::output::{camchain_yaml, report, CamerasReport};
use msreg_host::calibrate::cameras::{calibrate_cameras, CamerasOptions};
use msreg_host::camera_yaml::{camera_model_yaml_string, read_target_yaml, Target};
use msreg_host::vision::DetectorParams;

/// `msreg calibrate cameras`.
#[derive(Args, Debug)]
pub struct CalibrateCameras {
    /// Dataset directory (cam0/, cam1/, ... with data.csv and images; target.yaml).
    pub dataset: PathBuf,
    /// Result YAML (Kalibr camchain keys per camera).
    #[arg(short, long, default_value = "result.yaml")]
    pub output: PathBuf,
    /// JSON report (per camera and image: RMS, rejections, sigmas).
    #[arg(long)]
    pub report: Option<PathBuf>,
    /// Target file instead of the dataset's target.yaml.
    #[arg(long)]
    pub target: Option<PathBuf>,
    /// Models, overriding camN/camera.yaml: `cam0=pinhole-radtan,cam1=ds` (pinhole-radtan,
    /// pinhole-equidistant, omni-radtan, ds, eucm).
    #[arg(long)]
    pub model: Option<String>,
    /// Frames of two cameras closer than this are taken together, ms.
    #[arg(long, default_value_t = 1.0)]
    pub sync_tolerance_ms: f64,
    /// Keep every corner and image (plain least squares, as OpenCV's calibrateCamera).
    #[arg(long)]
    pub no_reject: bool,
    /// Refine corners with OpenCV's fixed 23 x 23 window (docs/checkerboard.md).
    #[arg(long)]
    pub opencv_window: bool,
}

/// The JSON report.
#[derive(Debug, Serialize)]
struct CliReport {
    /// Per camera: images listed and images with corners.
    detection: Vec<(String, usize, usize)>,
    /// Detection time, s.
    detection_s: f64,
    /// Calibration time, s.
    calibration_s: f64,
    #[serde(flatten)]
    calibration: CamerasReport,
}

/// `cam0=ds,cam1=eucm` as pairs.
fn parse_models(text: &str) -> anyhow::Result<Vec<(String, ModelKind)>> {
    text.split(',')
        .filter(|s| !s.trim().is_empty())
        .map(|item| {
            let (cam, model) = item
                .split_once('=')
                .ok_or_else(|| anyhow!("--model: `{item}` is not camN=<model>"))?;
            let kind = ModelKind::from_name(model.trim()).ok_or_else(|| {
                anyhow!(
                    "--model: unknown model `{model}` (pinhole-radtan, pinhole-equidistant, \
                     omni-radtan, ds, eucm)"
                )
            })?;
            Ok((cam.trim().to_string(), kind))
        })
        .collect()
}

/// `<dir>/<stem>.<camera>.yaml` beside the result.
fn camera_yaml_path(output: &Path, camera: &str) -> PathBuf {
    let stem = output
        .file_stem()
        .map_or("result".into(), |s| s.to_string_lossy());
    output.with_file_name(format!("{stem}.{camera}.yaml"))
}

/// Runs the command.
pub fn run(args: &CalibrateCameras) -> anyhow::Result<Outcome> {
    let models = parse_models(args.model.as_deref().unwrap_or(""))?;
    let mut dataset = CamerasDataset::open(&args.dataset, &models)
        .with_context(|| format!("{}", args.dataset.display()))?;
    if let Some(path) = &args.target {
        dataset.target = read_target_yaml(path)?;
        if let Target::Board(_) = dataset.target {
            return Err(anyhow!(
                "{}: target_type must be checkerboard or aprilgrid",
                path.display()
            ));
        }
    }
    if !(args.sync_tolerance_ms.is_finite() && args.sync_tolerance_ms >= 0.0) {
        return Err(anyhow!("--sync-tolerance-ms must be non-negative"));
    }
    let options = CamerasOptions {
        sync_tolerance_ns: (args.sync_tolerance_ms * 1e6) as u64,
        reject: !args.no_reject,
        huber: (!args.no_reject).then_some(3.0),
        ..CamerasOptions::default()
    };
    dataset.check_sync(options.sync_tolerance_ns)?;
    let params = if args.opencv_window {
        DetectorParams::opencv_compatible()
    } else {
        DetectorParams::default()
    };
    let start = Instant::now();
    let bar = progress_bar(1000, "{spinner} detecting [{bar:40}] {percent}% {elapsed}");
    let (inputs, counts) = dataset.detect(&params, &|f| bar.set_position((f * 1000.0) as u64))?;
    bar.finish_and_clear();
    let detection_s = start.elapsed().as_secs_f64();
    let start = Instant::now();
    let result = calibrate_cameras(&inputs, &options)
        .map_err(|e| anyhow!("{}: {e}", args.dataset.display()))?;
    let calibration_s = start.elapsed().as_secs_f64();
    let result_yaml = camchain_yaml(&result);
    write(&args.output, &result_yaml)?;
    for cam in &result.cameras {
        write(
            &camera_yaml_path(&args.output, &cam.name),
            &camera_model_yaml_string(&cam.model),
        )?;
        let k = cam.model.pinhole();
        eprintln!(
            "msreg: {} {}: fu {:.3} fv {:.3} cu {:.3} cv {:.3}; rms {:.3} px; corners {} used, \
             {} rejected; images {} used, {} rejected",
            cam.name,
            cam.model.kind.name(),
            k.fu,
            k.fv,
            k.cu,
            k.cv,
            cam.rms_px,
            cam.corners.0,
            cam.corners.1,
            cam.images.0,
            cam.images.1
        );
    }
    eprintln!(
        "msreg: wrote {} ({} views, detection {detection_s:.2} s, calibration {calibration_s:.2} s)",
        args.output.display(),
        result.views
    );
    if let Some(path) = &args.report {
        let cli = CliReport {
            detection: dataset
                .cameras
                .iter()
                .zip(&counts)
                .map(|(c, n)| (c.name.clone(), n.0, n.1))
                .collect(),
            detection_s,
            calibration_s,
            calibration: report(&result),
        };
        msreg_host::report::write_report_for_result(
            path,
            &cli,
            (&args.output, &result_yaml),
            &[],
            &[],
        )?;
    }
    let reasons = vec!["the bundle adjustment hit its iteration cap".to_string()];
    Ok(Outcome::of(result.converged, &reasons))
}

fn write(path: &Path, text: &str) -> anyhow::Result<()> {
    std::fs::write(path, text).with_context(|| format!("{}: cannot write", path.display()))
}

//! `msreg simulate lidar-camera` and `msreg calibrate lidar-camera`: argument structs and
//! the commands, so `main.rs` only routes to them.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

use anyhow::{anyhow, Context};
use clap::{Args, ValueEnum};
use indicatif::ProgressBar;
use msreg_estimator::camera::Camera;
use msreg_estimator::Pose;
use nalgebra::{Isometry3, Translation3};
use serde::Serialize;

use super::outcome::{progress_bar, Outcome};
use msreg_host::dataset::{CalibrationResult, ExtrinsicEstimate, SectionName};
use msreg_host::lidar_camera::pipeline::{
    extract_dataset, solve, CalibrationOptions, FrameFeatures, FrameReport, Method, RejectedFrame,
    Solution, SolveError, SolverRun,
};
use msreg_host::lidar_camera::LidarCameraDataset;
use msreg_host::sim::lidar_camera::{simulate_lidar_camera, LidarCameraSimConfig, LidarModel};
use msreg_host::vision::overlay::Canvas;
use msreg_host::vision::GrayImage;

/// LiDAR variant on the command line.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum LidarArg {
    /// Velodyne VLP-32C-like (1 cm range noise).
    Vlp32,
    /// Ouster OS1-64-like (3 cm range noise).
    Ouster,
}

/// Method on the command line.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum MethodArg {
    /// Point to plane, then point to back-projected plane (PBPC-Cal).
    Pbpc,
    /// Point to plane only (PPC-Cal).
    Ppc,
}

/// `msreg simulate lidar-camera`.
#[derive(Args, Debug)]
pub struct SimulateLidarCamera {
    /// Output directory (created).
    pub out_dir: PathBuf,
    /// Random seed.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// LiDAR variant.
    #[arg(long, value_enum, default_value_t = LidarArg::Vlp32)]
    pub lidar: LidarArg,
    /// Board poses.
    #[arg(long, default_value_t = 30)]
    pub poses: usize,
    /// Append three bad frames (board missing, cut by the border, edge-on).
    #[arg(long)]
    pub bad_frames: bool,
}

/// `msreg calibrate lidar-camera`.
#[derive(Args, Debug)]
pub struct CalibrateLidarCamera {
    /// Dataset directory (lidar0/, cam0/, target.yaml).
    pub dataset: PathBuf,
    /// Cost minimised last.
    #[arg(long, value_enum, default_value_t = MethodArg::Pbpc)]
    pub method: MethodArg,
    /// Result YAML.
    #[arg(short, long, default_value = "result.yaml")]
    pub output: PathBuf,
    /// JSON report (MLRE per frame and edge, rejected frames, solver runs).
    #[arg(long)]
    pub report: Option<PathBuf>,
    /// PNG of the LiDAR edge points projected on one image (default: beside the report).
    #[arg(long)]
    pub overlay: Option<PathBuf>,
    /// No board: maximise the mutual information of LiDAR intensity and image intensity
    /// (docs/prior_map.md); needs `--initial`.
    #[arg(long)]
    pub targetless: bool,
    /// Initial guess: a result file with `cam0_lidar0.T_cam_lidar` (with `--targetless`).
    #[arg(long)]
    pub initial: Option<PathBuf>,
}

/// Writes a simulated dataset.
pub fn simulate(args: &SimulateLidarCamera) -> anyhow::Result<()> {
    let config = LidarCameraSimConfig {
        seed: args.seed,
        lidar: match args.lidar {
            LidarArg::Vlp32 => LidarModel::Vlp32,
            LidarArg::Ouster => LidarModel::Ouster,
        },
        poses: args.poses,
        bad_frames: args.bad_frames,
        ..LidarCameraSimConfig::default()
    };
    let sim = simulate_lidar_camera(&config).map_err(|e| anyhow!("simulate: {e}"))?;
    let bar = bar(sim.frames.len() as u64, "writing frames");
    let total = sim.frames.len() as f64;
    sim.write(&args.out_dir, &mut |f| {
        bar.set_position((f * total).round() as u64)
    })?;
    bar.finish_and_clear();
    eprintln!(
        "msreg: wrote {} ({} frames, LiDAR {})",
        args.out_dir.display(),
        sim.frames.len(),
        config.lidar.name()
    );
    Ok(())
}

fn bar(len: u64, what: &str) -> ProgressBar {
    progress_bar(
        len,
        &format!("{{spinner}} {what} [{{bar:40}}] {{pos}}/{{len}} {{elapsed}}"),
    )
}

/// The JSON report.
#[derive(Serialize)]
struct Report<'a> {
    method: Method,
    dataset: String,
    frames_total: usize,
    frames_used: usize,
    converged: bool,
    reason: Option<String>,
    mlre_px: Option<f64>,
    mlre_ppc_px: Option<f64>,
    t_cam_lidar: Option<[[f64; 4]; 4]>,
    sigma_rot_deg: Option<[f64; 3]>,
    sigma_trans_m: Option<[f64; 3]>,
    ppc: Option<SolverRun>,
    pbpc: Option<SolverRun>,
    frames: Vec<FrameReport>,
    rejected: &'a [RejectedFrame],
    extraction_time_s: f64,
}

fn matrix(p: &Pose<f64>) -> [[f64; 4]; 4] {
    let m = isometry(p).to_homogeneous();
    std::array::from_fn(|r| std::array::from_fn(|c| m[(r, c)]))
}

fn isometry(p: &Pose<f64>) -> Isometry3<f64> {
    Isometry3::from_parts(Translation3::from(p.translation), p.rotation)
}

/// Runs the calibration on a dataset directory; `Err` is bad input (exit code 2).
pub fn calibrate(args: &CalibrateLidarCamera) -> anyhow::Result<Outcome> {
    if args.targetless {
        return super::mi::calibrate(&super::mi::TargetlessArgs {
            dataset: &args.dataset,
            initial: args.initial.as_deref(),
            output: &args.output,
            report: args.report.as_deref(),
            overlay: args.overlay.as_deref(),
        });
    }
    let data = LidarCameraDataset::open(&args.dataset)?;
    let options = CalibrationOptions {
        method: match args.method {
            MethodArg::Pbpc => Method::Pbpc,
            MethodArg::Ppc => Method::Ppc,
        },
        ..CalibrationOptions::default()
    };
    let bar = bar(data.scans.len() as u64, "extracting board features");
    let done = AtomicU64::new(0);
    let clock = std::time::Instant::now();
    let (frames, rejected) = extract_dataset(&data, &options, &|| {
        bar.set_position(done.fetch_add(1, Ordering::Relaxed) + 1);
    })?;
    bar.finish_and_clear();
    let extraction_time_s = clock.elapsed().as_secs_f64();
    for r in &rejected {
        eprintln!("msreg: frame {} rejected: {}", r.frame, r.reason);
    }
    let outcome = solve(&frames, &data.camera, &options);
    let mut report = Report {
        method: options.method,
        dataset: args.dataset.display().to_string(),
        frames_total: data.scans.len(),
        frames_used: frames.len(),
        converged: false,
        reason: None,
        mlre_px: None,
        mlre_ppc_px: None,
        t_cam_lidar: None,
        sigma_rot_deg: None,
        sigma_trans_m: None,
        ppc: None,
        pbpc: None,
        frames: Vec::new(),
        rejected: &rejected,
        extraction_time_s,
    };
    let mut result_yaml = None;
    let result = match outcome {
        Ok(solution) => {
            let (outcome, yaml) = finish(args, &data, &frames, &solution, &mut report)?;
            result_yaml = Some(yaml);
            outcome
        }
        Err(e) => {
            let why = match &e {
                SolveError::TooFewViews { .. } => format!(
                    "{e} ({} of {} frames rejected)",
                    rejected.len(),
                    data.scans.len()
                ),
                _ => e.to_string(),
            };
            report.reason = Some(why.clone());
            Outcome::NotConverged(why)
        }
    };
    if let Some(path) = &args.report {
        let overlay = args.overlay.clone().unwrap_or(path.with_extension("png"));
        match &result_yaml {
            Some(yaml) => msreg_host::report::write_report_for_result(
                path,
                &report,
                (&args.output, yaml),
                &[overlay],
                &[],
            )?,
            None => msreg_host::report::write_report_with_images(path, &report, &[overlay])?,
        }
    }
    Ok(result)
}

/// Writes the result and overlay of a solved calibration and fills the report; the
/// outcome and the result file's text.
fn finish(
    args: &CalibrateLidarCamera,
    data: &LidarCameraDataset,
    frames: &[FrameFeatures],
    solution: &Solution,
    report: &mut Report<'_>,
) -> anyhow::Result<(Outcome, String)> {
    let estimate = ExtrinsicEstimate::from_covariance(
        isometry(&solution.t_cam_lidar),
        0.0,
        &solution.covariance,
    );
    let converged = solution.ppc.converged && solution.pbpc.as_ref().is_none_or(|r| r.converged);
    report.converged = converged;
    if !converged {
        report.reason = Some("the solver hit its iteration limit".into());
    }
    report.mlre_px = Some(solution.mlre_px);
    report.mlre_ppc_px = Some(solution.mlre_ppc_px);
    report.t_cam_lidar = Some(matrix(&solution.t_cam_lidar));
    report.sigma_rot_deg = Some(estimate.sigma_rot_deg.into());
    report.sigma_trans_m = Some(estimate.sigma_trans_m.into());
    report.ppc = Some(solution.ppc.clone());
    report.pbpc = solution.pbpc.clone();
    report.frames = solution.frames.clone();
    let result = CalibrationResult::new().with_extrinsic(SectionName::CAM0_LIDAR0, estimate);
    super::outcome::write_outputs(&result, &args.output, None, &())?;
    eprintln!(
        "msreg: wrote {} (MLRE {:.3} px over {} frames; PPC-Cal alone {:.3} px)",
        args.output.display(),
        solution.mlre_px,
        frames.len(),
        solution.mlre_ppc_px
    );
    let overlay = args
        .overlay
        .clone()
        .or_else(|| args.report.as_ref().map(|r| r.with_extension("png")));
    if let (Some(path), Some(first)) = (overlay, frames.first()) {
        write_overlay(&path, data, first, &data.camera, &solution.t_cam_lidar)?;
    }
    let outcome = if converged {
        Outcome::Converged
    } else {
        Outcome::NotConverged("the solver hit its iteration limit".into())
    };
    Ok((outcome, result.to_yaml_string()))
}

/// The image of `frame` in colour with its LiDAR edge points (red) and board points
/// (green, sparse) projected by `t_cam_lidar` through the camera model (Fig. 2.13).
pub fn write_overlay(
    path: &Path,
    data: &LidarCameraDataset,
    frame: &FrameFeatures,
    camera: &Camera<f64>,
    t_cam_lidar: &Pose<f64>,
) -> anyhow::Result<()> {
    let Some(image_path) = data
        .images
        .iter()
        .find(|f| f.stamp_ns == frame.image_stamp_ns)
        .map(|f| &f.path)
    else {
        return Ok(());
    };
    let image = GrayImage::load(image_path)
        .with_context(|| format!("{}: cannot read image", image_path.display()))?;
    let mut canvas = Canvas::from_gray(&image);
    let mut dot = |p: &nalgebra::Vector3<f64>, colour: [u8; 3], radius: i64| {
        if let Some(px) = camera.project(&t_cam_lidar.transform_point(p)) {
            canvas.dot(&px.pixel, colour, radius);
        }
    };
    for p in frame.lidar.plane_points.iter().step_by(3) {
        dot(p, [0, 200, 0], 0);
    }
    for e in &frame.lidar.edges {
        for p in &e.points {
            dot(p, [255, 0, 0], 2);
        }
    }
    canvas
        .save(path)
        .with_context(|| format!("{}: cannot write overlay", path.display()))?;
    Ok(())
}
